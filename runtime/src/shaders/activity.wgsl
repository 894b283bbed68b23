// Light work only where something changed (runtime/src/activity.rs): the tiles a propagation
// bounce updates, and the largest relative change each tile's leaves made. With the light state
// in bind group 1; only propagate imports it.
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

// What a bounce changed: the largest relative change of any leaf's outgoing radiance, then that
// of each tile's leaves, as f32 bits (non-negative floats order like their bit patterns, so
// atomicMax works). One buffer for both: WebGPU allows 8 storage buffers per stage by default.
struct Changes {
    max_change_bits: atomic<u32>,
    pad0: u32,
    pad1: u32,
    pad2: u32,
    tiles: array<atomic<u32>>,
}

@group(1) @binding(3) var<storage, read> active_tiles: ActiveTiles;
@group(1) @binding(4) var<storage, read_write> changes: Changes;

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
