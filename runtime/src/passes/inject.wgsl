// Light injection: direct light from point and spot lights at every leaf (NDF-weighted diffuse,
// shadowed by the surfel shadow maps), then the leaf's outgoing radiance
// out = emission + direct + env + albedo * gather. Area lights are already emissive leaves.

@compute @workgroup_size(64)
fn inject(@builtin(global_invocation_id) gid: vec3<u32>, @builtin(num_workgroups) nwg: vec3<u32>) {
    let i = linear_index(gid, nwg);
    if i >= params.leaf_count {
        return;
    }
    let leaf = leaves[i];
    let albedo = leaf.albedo_opacity.rgb;
    let p = leaf.center_m.xyz;
    var irradiance = vec3<f32>(0.0);
    for (var k = 0u; k < params.light_count; k++) {
        let light = lights[k];
        let to_light = light.position_kind.xyz - p;
        let dist = max(length(to_light), 1e-4);
        let l = to_light / dist;
        let cos_term = ndf_cos(leaf.normal_mean.xyz, l);
        if cos_term <= 0.0 {
            continue;
        }
        let falloff = spot_factor(light, l);
        if falloff <= 0.0 {
            continue;
        }
        let vis = shadow_visibility(light, p, dist, params.shadow_bias_m);
        irradiance += light.intensity_layer.rgb * (cos_term * falloff * vis / (dist * dist));
    }
    let direct = albedo / PI * irradiance;
    var state = leaf_light[i];
    state.direct = vec4<f32>(direct, 0.0);
    state.out = vec4<f32>(leaf.emission.rgb + direct + state.env.rgb + albedo * state.gather.rgb, 0.0);
    leaf_light[i] = state;
}
