// Light work only where something changed (runtime/src/activity.rs): the leaves a propagation
// bounce updates, tile by tile, and the largest relative change each tile's leaves made. With the
// light state in bind group 1; only propagate imports it.
#import light_state

// Mirrors the renderer's active-leaf buffer: a count, then (leaf index, tile index) pairs.
struct ActiveLeaves {
    count: u32,
    pad0: u32,
    pad1: u32,
    pad2: u32,
    items: array<vec2<u32>>,
}

@group(1) @binding(3) var<storage, read> active_leaves: ActiveLeaves;
// Largest relative change per tile in this bounce, as f32 bits (see Stats::max_change_bits).
@group(1) @binding(4) var<storage, read_write> tile_change: array<atomic<u32>>;
