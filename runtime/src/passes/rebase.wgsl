// Re-indexes tile nodes the pools moved (passes/rebase.rs): a node's first child is a global
// index, into the node pool for inner nodes and into the leaf pool for the nodes at its tile's
// leaf level, so a tile moved within the pools adds its moves to each. u32 sums wrap, as the
// CPU's `wrapping_add` of the deltas does.
#import dispatch

struct Job {
    // The tile's nodes at their new place in the node pool.
    start: u32,
    count: u32,
    leaf_level: u32,
    // new - old offsets, wrapping.
    node_delta: u32,
    leaf_delta: u32,
    // Nodes of the jobs before this one: the job of invocation i is the last with before <= i.
    before: u32,
    pad0: u32,
    pad1: u32,
}

@group(0) @binding(0) var<storage, read> jobs: array<Job>;
// NodeGpu: first_child, then child_mask | level << 8.
@group(0) @binding(1) var<storage, read_write> nodes: array<vec2<u32>>;

@compute @workgroup_size(64)
fn rebase(@builtin(global_invocation_id) gid: vec3<u32>, @builtin(num_workgroups) nwg: vec3<u32>) {
    let i = linear_index(gid, nwg);
    let last = arrayLength(&jobs) - 1u;
    if i >= jobs[last].before + jobs[last].count {
        return;
    }
    var lo = 0u;
    var hi = last;
    while lo < hi {
        let mid = (lo + hi + 1u) / 2u;
        if jobs[mid].before <= i {
            lo = mid;
        } else {
            hi = mid - 1u;
        }
    }
    let job = jobs[lo];
    let k = job.start + (i - job.before);
    let node = nodes[k];
    if (node.y >> 8u) == job.leaf_level {
        nodes[k].x = node.x + job.leaf_delta;
    } else {
        nodes[k].x = node.x + job.node_delta;
    }
}
