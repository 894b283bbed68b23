// One bounce of propagation: every leaf gathers incoming radiance with cones over the hemisphere of
// its mean normal (cosine-distributed directions, weights summing to 1, so the result is
// irradiance / pi), then out = emission + direct + env + albedo * gather (env: the env pass's
// reflected environment light; a cone's escaped share adds only the constant background here).
// Reads only the mip pyramid, so leaves update independently; records the largest relative change
// for the effect plan, and per tile for the choice of the next bounce's tiles. Runs over the
// active tiles (shaders/activity.wgsl): the leaves of the tiles whose light may still change.
//
// Cones are traced in batches, one dispatch each (passes/mod.rs `cone_batched` says why); the running sum
// lives in the leaf's `pending`, added to cone by cone in the same order as one loop would (the
// result is the same to the bit), and the last batch finishes the leaf: gather = the cones' sum,
// and tail = the estimated gather of the bounces not run (`bounce_tail`).
#import activity
#import cone
#import cone_batch
#import dispatch


@compute @workgroup_size(64)
fn propagate(@builtin(global_invocation_id) gid: vec3<u32>, @builtin(num_workgroups) nwg: vec3<u32>) {
    let k = active_tiles.slice_first + linear_index(gid, nwg);
    if k >= active_tiles.slice_end {
        return;
    }
    let item = active_leaf(k);
    let i = item.x;
    let leaf = leaves[i];
    var state = leaf_light[i];
    var gathered = select(state.pending.rgb, vec3<f32>(0.0), batch.first == 0u);
    let end = batch_end();
    for (var c = batch.first; c < end; c++) {
        let cone = params.cones[c];
        let dir = leaf_cone_dir(leaf, cone.xyz);
        let s = trace_cone(leaf_cone_origin(leaf), dir, params.cone_tan_half, leaf_cone_rise(leaf, dir));
        gathered += cone.w * (s.rgb + (1.0 - s.a) * params.background.rgb);
    }
    if end < params.cone_count {
        state.pending = vec4<f32>(gathered, 0.0);
        leaf_light[i] = state;
        return;
    }
    let before = leaf_shown(leaf, state);
    let residual = gathered - state.gather.rgb;
    state.tail = vec4<f32>(bounce_tail(residual, state.residual.rgb), 0.0);
    state.residual = vec4<f32>(residual, 0.0);
    state.gather = vec4<f32>(gathered, 0.0);
    state.out = leaf_out(leaf, state);
    let after = leaf_shown(leaf, state);
    leaf_light[i] = state;
    let scale = max(max(after.r, max(after.g, after.b)), 1e-6);
    let diff = abs(after - before);
    let change = max(diff.r, max(diff.g, diff.b)) / scale;
    atomicMax(&changes.max_change_bits, bitcast<u32>(change));
    atomicMax(&changes.tiles[item.y], bitcast<u32>(change));
}

// The bounces not run, per channel, as the rest of a geometric series: `residual` is what this
// bounce changed the gather by, `last` what the one before did. Once the light is spread, each
// bounce changes a leaf by the same ratio r of the one before (the dominant eigenvalue of one
// bounce), and the changes still to come add up to residual * r / (1 - r) (Aitken's
// extrapolation). The series itself runs on without the tail (out and the pyramid hold the
// bounces run), so successive changes stay those of plain propagation, all of one sign; only what
// a surface shows adds it (shade, and the change that decides convergence: once the estimate
// stops moving, more bounces would not change the image). Feeding the tail into the next bounce
// instead converges in fewer bounces, but then the changes are no longer a plain series and
// neighbours' estimates compound into overshoot (tried on the colour box, not kept). A ratio
// above the scene's largest albedo (params.tail_ratio_max; zero without the tail) means light is
// still arriving, as in a corridor's far end: it gets the largest ratio trusted, and none from 1
// on.
fn bounce_tail(residual: vec3<f32>, last: vec3<f32>) -> vec3<f32> {
    let ok = abs(last) > vec3<f32>(1e-20);
    let ratio = select(vec3<f32>(0.0), residual / select(vec3<f32>(1.0), last, ok), ok);
    let trusted = (ratio >= vec3<f32>(0.0)) & (ratio <= vec3<f32>(1.0));
    let r = select(vec3<f32>(0.0), min(ratio, params.tail_ratio_max.rgb), trusted);
    return residual * r / (1.0 - r);
}
