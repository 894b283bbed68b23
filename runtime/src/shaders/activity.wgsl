// Light work only where something changed (runtime/src/light/activity.rs): the largest relative
// change each tile's leaves made in a propagation bounce, over the active tiles (active.wgsl).
// With the light state in bind group 1; only propagate and tail import it.
#import active

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

@group(1) @binding(4) var<storage, read_write> changes: Changes;
