// Light injection, one batch of lights per dispatch (passes/inject.rs says why): direct light from point and spot lights at every leaf (NDF-weighted diffuse),
// only the lights the light grid lists in range; lights with shadow maps are shadowed by them,
// lights beyond the budget by an SVO shadow cone (or not at all), and their share is kept apart in
// `far` for shade. Then the leaf's outgoing radiance out = emission + direct + env +
// albedo * gather. Area lights are already emissive leaves.
#import lights
#import active
#import cone
#import dispatch
#import brdf

// Mirrors gpu/types.rs InjectBatch (runtime/tests/layout.rs).
struct InjectBatch {
    first: u32,
    count: u32,
    reset: u32,
    last: u32,
}

@group(2) @binding(0) var<uniform> batch: InjectBatch;

@compute @workgroup_size(64)
fn inject(@builtin(global_invocation_id) gid: vec3<u32>, @builtin(num_workgroups) nwg: vec3<u32>) {
    // After a light edit in place, only the active tiles' leaves (those an edited light
    // reaches: runtime/src/light/edit.rs); else every leaf.
    let k = linear_index(gid, nwg);
    var i = k;
    if (params.flags & FLAG_INJECT_ACTIVE) != 0u {
        if k >= active_tiles.item_count {
            return;
        }
        i = active_leaf(k).x;
    } else if i >= params.leaf_count {
        return;
    }
    let leaf = leaves[i];
    let albedo = leaf.albedo_opacity.rgb;
    let p = leaf.center_m.xyz;
    var irradiance = vec3<f32>(0.0);
    var far = vec3<f32>(0.0);
    // Shadow cones start one leaf off the surface, like the gather cones.
    let o = leaf_cone_origin(leaf);
    let cell = light_cell(p);
    let start = light_grid_word(cell) + batch.first;
    let last = min(light_grid_word(cell + 1u), start + batch.count);
    for (var j = start; j < last; j++) {
        let light = lights[light_grid_word(j)];
        let seen = light_seen(light, p);
        if seen.falloff <= 0.0 {
            continue;
        }
        let dist = seen.dist;
        let cos_term = ndf_cos(leaf.normal_mean.xyz, seen.l);
        if cos_term <= 0.0 {
            continue;
        }
        let e_lit = light.intensity_layer.rgb * (cos_term * seen.falloff / (dist * dist));
        if max(e_lit.r, max(e_lit.g, e_lit.b)) < light.params.w {
            // Under the cutoff once the cosine and the spot are counted: culled like out of range.
            continue;
        }
        let kind = light_shadow_kind(light);
        var vis = 1.0;
        if kind == LIGHT_MAP {
            // The leaf sits on its surface (its surfels' centroid), and the shadow maps hold the
            // same discs: look up a little in front, as shade does for a surfel.
            let q = p + leaf_normal(leaf.normal_mean.xyz) * (0.25 * params.leaf_size_m);
            vis = shadow_visibility(light, q, distance(light.position_kind.xyz, q), params.shadow_bias_m);
        } else if kind == LIGHT_CONE {
            let to = light.position_kind.xyz - o;
            let d = length(to);
            vis = select(1.0, cone_visibility(o, to / d, d), d > 1e-4);
        }
        let e = e_lit * vis;
        irradiance += e;
        if kind != LIGHT_MAP {
            far += e;
        }
    }
    var state = leaf_light[i];
    let edit = (params.flags & FLAG_INJECT_ACTIVE) != 0u;
    if batch.reset == 1u {
        if edit {
            // The direct light before the edit, to measure what it changed (the last batch);
            // `pending` is free outside a propagation bounce.
            state.pending = vec4<f32>(state.direct.rgb, 0.0);
        }
        state.direct = vec4<f32>(0.0);
        state.far = vec4<f32>(0.0);
    }
    let direct = state.direct.rgb + albedo / PI * irradiance;
    state.direct = vec4<f32>(direct, 0.0);
    state.far = vec4<f32>(state.far.rgb + far / PI, 0.0);
    // New direct light starts a new series: the last bounce's change says nothing of the next
    // (a forced re-run over the same lights keeps it, and so changes nothing).
    if (params.flags & FLAG_NEW_SERIES) != 0u {
        state.residual = vec4<f32>(0.0);
    }
    state.out = leaf_out(leaf, state);
    if edit && batch.last == 1u {
        // Relative to what the leaf shows, as propagate measures a bounce's change: the tiles
        // where this exceeds the tolerance start the bounces (inject_tally.wgsl).
        let shown = leaf_shown(leaf, state);
        let d = abs(state.direct.rgb - state.pending.rgb);
        state.pending.w = max(d.r, max(d.g, d.b)) / max(max(shown.r, max(shown.g, shown.b)), 1e-6);
    }
    leaf_light[i] = state;
}
