// The cones one dispatch of a cone-batched pass (env, propagate) traces: `first .. first + count`
// of the cone set (passes/mod.rs `cone_batched` says why). The pass's own group.

// Mirrors gpu/types.rs ConeBatch (runtime/tests/layout.rs).
struct ConeBatch {
    first: u32,
    count: u32,
    pad0: u32,
    pad1: u32,
}

@group(2) @binding(0) var<uniform> batch: ConeBatch;

// The end of this dispatch's cones, and whether it is the last batch.
fn batch_end() -> u32 {
    return min(batch.first + batch.count, params.cone_count);
}
