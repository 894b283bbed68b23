// Environment light through openings: every leaf traces its cone set over the hemisphere of its
// mean normal against the opacity of the radiance pyramid and keeps its sky visibility
// V = sum_c w_c (1 - a_c) L_c / sum_c w_c L_c, where L_c is the environment's mean radiance over
// cone c (SH, cap-filtered): the radiance-weighted share of the hemisphere that sees out of the
// scene. The reflected environment light is albedo * E_sh / pi * V, with E_sh the exact
// Ramamoorthi-Hanrahan irradiance of the 9 coefficients (for the leaf's normal distribution, see
// sh_irradiance_ndf_over_pi): unoccluded leaves get exactly that, a leaf whose cones all end on
// rock gets nothing. Runs once per environment (geometry is static).
//
// Cones are traced in batches, one dispatch each (passes/mod.rs `cone_batched`); the running sums
// of the numerator and denominator live in the leaf's `env` (x, y) until the last batch, added to
// in the same order as one loop would.
#import cone
#import cone_batch
#import sh
#import dispatch

@compute @workgroup_size(64)
fn env(@builtin(global_invocation_id) gid: vec3<u32>, @builtin(num_workgroups) nwg: vec3<u32>) {
    let i = linear_index(gid, nwg);
    if i >= params.leaf_count {
        return;
    }
    let leaf = leaves[i];
    let cos_half = 1.0 / sqrt(1.0 + params.cone_tan_half * params.cone_tan_half);
    var state = leaf_light[i];
    var open = select(state.env.x, 0.0, batch.first == 0u);
    var all = select(state.env.y, 0.0, batch.first == 0u);
    let end = batch_end();
    for (var c = batch.first; c < end; c++) {
        let cone = params.cones[c];
        let dir = leaf_cone_dir(leaf, cone.xyz);
        let sky = dot(sh_cone_radiance(dir, cos_half), vec3<f32>(0.2126, 0.7152, 0.0722));
        let s = trace_cone(leaf_cone_origin(leaf), dir, params.cone_tan_half, leaf_cone_rise(leaf, dir));
        open += cone.w * (1.0 - s.a) * sky;
        all += cone.w * sky;
    }
    if end < params.cone_count {
        state.env = vec4<f32>(open, all, 0.0, state.env.w);
        leaf_light[i] = state;
        return;
    }
    let v = select(0.0, clamp(open / all, 0.0, 1.0), all > 1e-12);
    let albedo = leaf.albedo_opacity.rgb;
    let env_light = albedo * sh_irradiance_ndf_over_pi(leaf.normal_mean.xyz) * v;
    state.env = vec4<f32>(env_light, v);
    // New environment light starts a new series (propagate's tail); a forced re-run keeps it.
    if (params.flags & FLAG_NEW_SERIES) != 0u {
        state.residual = vec4<f32>(0.0);
    }
    state.out = leaf_out(leaf, state);
    leaf_light[i] = state;
}
