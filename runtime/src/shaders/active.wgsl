// The active tiles (runtime/src/light/activity.rs): the tiles whose light may still change, as a
// list of their leaves. Propagate runs over them (activity.wgsl adds what it changed); inject runs
// over them after a light edit in place (only the tiles an edited light reaches: light/edit.rs).
#import light_state

// Mirrors gpu/types.rs ActiveTile (runtime/tests/layout.rs): the tile's leaves are the bounce's
// invocations first_item .. first_item + leaf_count.
struct ActiveTile {
    tile: u32,
    first_leaf: u32,
    leaf_count: u32,
    first_item: u32,
}

// The tiles and the invocations (their leaves) of the bounce, the slice of them this dispatch
// runs (a viewer splits a bounce over frames: Renderer::update_light_slice), then the tiles in
// order of first_item: one entry per active tile, not per leaf, so the list the CPU writes each
// bounce stays small.
struct ActiveTiles {
    tile_count: u32,
    item_count: u32,
    slice_first: u32,
    slice_end: u32,
    tiles: array<ActiveTile>,
}

@group(1) @binding(3) var<storage, read> active_tiles: ActiveTiles;

// Leaf index (x) and tile index (y) of invocation `k` (< the list's item total): the last active
// tile whose first_item is at most k, by binary search (log2 of the active tiles, a few steps).
fn active_leaf(k: u32) -> vec2<u32> {
    var lo = 0u;
    var hi = active_tiles.tile_count;
    while hi - lo > 1u {
        let mid = (lo + hi) / 2u;
        if active_tiles.tiles[mid].first_item <= k {
            lo = mid;
        } else {
            hi = mid;
        }
    }
    let t = active_tiles.tiles[lo];
    return vec2<u32>(t.first_leaf + (k - t.first_item), t.tile);
}
