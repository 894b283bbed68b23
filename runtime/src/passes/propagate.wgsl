// One bounce of propagation: every leaf gathers incoming radiance with cones (or, with
// Settings::cone_rays, each cone as rays: cone_rays.wgsl) over the hemisphere of its mean normal
// (cosine-distributed directions, weights summing to 1, so the result is irradiance / pi), then
// out = emission + direct + env + albedo * gather (env: the env pass's reflected environment
// light; a cone's escaped share adds only the constant background here).
// Reads only the mip pyramid, so leaves update independently. Runs over the active tiles
// (shaders/activity.wgsl): the leaves of the tiles whose light may still change.
//
// Cones are traced in batches, one dispatch each (passes/mod.rs `cone_batched` says why); the running sum
// lives in the leaf's `pending`, added to cone by cone in the same order as one loop would (the
// result is the same to the bit), and the last batch finishes the leaf: gather = the cones' sum,
// residual = what that changed. The tail of the bounces not run, and the change the effect plan
// reads, need the whole tile's residuals: tail.wgsl computes them once the bounce has run every
// leaf. Until then the last batch leaves `pending` = the bounce before's residual (the tail
// pass's ratio) and takes the residual off the tail, so that gather + tail, what shade shows, stays
// as it was while a viewer spreads the bounce over frames.
#import activity
#import cone
#import cone_batch
#import cone_rays
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
    let n = leaf_normal(leaf.normal_mean.xyz);
    for (var c = batch.first; c < end; c++) {
        let cone = params.cones[c];
        let dir = leaf_cone_dir(leaf, cone.xyz);
        var s: vec4<f32>;
        if cone_rays {
            s = trace_cone_rays(leaf_cone_origin(leaf), dir, n, params.cone_tan_half, leaf_cone_lift(leaf));
        } else {
            s = trace_cone(leaf_cone_origin(leaf), dir, params.cone_tan_half, leaf_cone_rise(leaf, dir));
        }
        gathered += cone.w * (s.rgb + (1.0 - s.a) * params.background.rgb);
    }
    if end < params.cone_count {
        state.pending = vec4<f32>(gathered, 0.0);
        leaf_light[i] = state;
        return;
    }
    let residual = gathered - state.gather.rgb;
    state.pending = vec4<f32>(state.residual.rgb, 0.0);
    state.tail = vec4<f32>(state.tail.rgb - residual, 0.0);
    state.residual = vec4<f32>(residual, 0.0);
    state.gather = vec4<f32>(gathered, 0.0);
    state.out = leaf_out(leaf, state);
    leaf_light[i] = state;
}
