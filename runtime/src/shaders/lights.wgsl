// Point and spot lights: the light list, the light grid of the lights in range, and the shadow
// maps' atlas (runtime/src/light/setup.rs, passes/shadow.rs).
#import scene
#import packing
#import lookup

struct Light {
    position_kind: vec4<f32>,
    intensity_layer: vec4<f32>,
    direction_cos_outer: vec4<f32>,
    // x: cos(inner angle); y: range in metres; z: LIGHT_MAP, LIGHT_CONE or LIGHT_NONE; w: the
    // irradiance cutoff, W/m^2.
    params: vec4<f32>,
}

// The lights, then the shadow faces' view-projection matrices (64 bytes each, like a Light: one
// buffer for both because WebGPU allows 8 storage buffers per shader stage by default); face k is
// record light_count + k (shadow_view_proj).
@group(0) @binding(4) var<storage, read> lights: array<Light>;
// Shadow atlas: distance from the light to the nearest surfel (packed f32), one square face per
// cube face of a point light or per spot light, `shadow_cols` faces per row. A 2D atlas rather
// than an array texture: wgpu's GL backend neither renders nor copies into array layers.
@group(0) @binding(6) var shadow_dist: texture_2d<f32>;
// The light grid, per-cell lists of the lights in range (runtime/src/light/setup.rs), lives in the
// lookup buffer (light_grid_word): cells + 1 offsets (word indices into the grid), then the light
// indices.

// View-projection of shadow face `layer` (stored after the lights, column by column).
fn shadow_view_proj(layer: u32) -> mat4x4<f32> {
    let m = lights[params.light_count + layer];
    return mat4x4<f32>(m.position_kind, m.intensity_layer, m.direction_cos_outer, m.params);
}

// Fraction of a light's shadow map that sees past `p` (3x3 percentage-closer filter).
fn shadow_visibility(light: Light, p: vec3<f32>, dist: f32, bias_m: f32) -> f32 {
    let first = light.intensity_layer.w;
    if first < 0.0 || (params.flags & FLAG_SHADOWS) == 0u {
        return 1.0;
    }
    let d = p - light.position_kind.xyz;
    var face = 0u;
    // Point lights, profiled or not, have six faces; a spot (kind 1) one.
    if abs(light.position_kind.w - 1.0) > 0.5 {
        let a = abs(d);
        if a.x >= a.y && a.x >= a.z {
            face = select(1u, 0u, d.x >= 0.0);
        } else if a.y >= a.z {
            face = select(3u, 2u, d.y >= 0.0);
        } else {
            face = select(5u, 4u, d.z >= 0.0);
        }
    }
    let layer = u32(first) + face;
    let clip = shadow_view_proj(layer) * vec4<f32>(p, 1.0);
    if clip.w <= 0.0 {
        return 1.0;
    }
    let ndc = clip.xy / clip.w;
    let uv = vec2<f32>(ndc.x * 0.5 + 0.5, 0.5 - ndc.y * 0.5);
    if any(uv < vec2<f32>(0.0)) || any(uv > vec2<f32>(1.0)) {
        return 1.0;
    }
    let size = i32(params.shadow_size);
    let tile = vec2<i32>(i32(layer % params.shadow_cols), i32(layer / params.shadow_cols)) * size;
    let texel = clamp(vec2<i32>(uv * f32(size)), vec2<i32>(0), vec2<i32>(size - 1));
    var lit = 0.0;
    for (var dy = -1; dy <= 1; dy++) {
        for (var dx = -1; dx <= 1; dx++) {
            let q = clamp(texel + vec2<i32>(dx, dy), vec2<i32>(0), vec2<i32>(size - 1));
            let stored = unpack_f32(textureLoad(shadow_dist, tile + q, 0));
            lit += select(0.0, 1.0, dist - bias_m <= stored);
        }
    }
    return lit / 9.0;
}

// Index of the light-grid cell holding `p_m` (clamped into the grid); its lights are
// light_grid_word(light_grid_word(c) .. light_grid_word(c + 1)).
fn light_cell(p_m: vec3<f32>) -> u32 {
    let dims = vec3<i32>(i32(params.light_grid_x), i32(params.light_grid_y), i32(params.light_grid_z));
    let f = floor((p_m - params.light_grid_min_m.xyz) / params.light_grid_min_m.w);
    let c = clamp(vec3<i32>(f), vec3<i32>(0), dims - vec3<i32>(1));
    return u32(c.x + dims.x * (c.y + dims.y * c.z));
}

fn light_shadow_kind(light: Light) -> u32 {
    return u32(light.params.z + 0.5);
}

// A light as seen from `p`: unit direction `l` to it, distance (at least 0.1 mm) and spot falloff
// in 0..=1, which is 0 beyond the light's range (it bounds culling) or outside its spot.
struct LightSeen {
    l: vec3<f32>,
    dist: f32,
    falloff: f32,
}

fn light_seen(light: Light, p: vec3<f32>) -> LightSeen {
    let to_light = light.position_kind.xyz - p;
    let dist = max(length(to_light), 1e-4);
    let l = to_light / dist;
    if dist > light.params.y {
        return LightSeen(l, dist, 0.0);
    }
    return LightSeen(l, dist, spot_factor(light, l));
}


// Spot falloff or profile of a light toward unit direction `l` from the lit point (1 for point
// lights).
fn spot_factor(light: Light, l: vec3<f32>) -> f32 {
    let kind = light.position_kind.w;
    if kind < 0.5 {
        return 1.0;
    }
    if kind > 1.5 {
        return profile_factor(light, -l);
    }
    let c = dot(-l, light.direction_cos_outer.xyz);
    let outer = light.direction_cos_outer.w;
    let inner = light.params.x;
    return smoothstep(outer, max(inner, outer + 1e-4), c);
}

// Value k of the profile block at record `base` (its samples start at the next record, 16 a
// record: runtime/src/light/profile.rs).
fn profile_value(base: u32, k: u32) -> f32 {
    let r = lights[base + 1u + k / 16u];
    var v = r.params;
    switch (k % 16u) / 4u {
        case 0u: { v = r.position_kind; }
        case 1u: { v = r.intensity_layer; }
        case 2u: { v = r.direction_cos_outer; }
        default: {}
    }
    return v[k % 4u];
}

// A profiled light's relative intensity toward unit direction `d` (from the light): bilinear in
// its grid, 1 degree from the aim (the light's direction), 5 degrees about it from the header's
// 0-degree axis, wrapping; one column where it is the same all round.
fn profile_factor(light: Light, d: vec3<f32>) -> f32 {
    let base = u32(light.params.x);
    let head = lights[base];
    let n_theta = u32(head.position_kind.w);
    let n_phi = u32(head.intensity_layer.w);
    let theta = acos(clamp(dot(d, light.direction_cos_outer.xyz), -1.0, 1.0));
    let ft = theta / PROFILE_PI * f32(n_theta - 1u);
    let i0 = min(u32(ft), n_theta - 2u);
    let wt = clamp(ft - f32(i0), 0.0, 1.0);
    let a = mix(profile_value(base, i0), profile_value(base, i0 + 1u), wt);
    if n_phi <= 1u {
        return a;
    }
    var phi = atan2(dot(d, head.intensity_layer.xyz), dot(d, head.position_kind.xyz));
    if phi < 0.0 {
        phi += 2.0 * PROFILE_PI;
    }
    let fp = phi / (2.0 * PROFILE_PI) * f32(n_phi);
    let j0 = min(u32(fp), n_phi - 1u);
    let wp = clamp(fp - f32(j0), 0.0, 1.0);
    let j1 = (j0 + 1u) % n_phi;
    let row0 = mix(profile_value(base, j0 * n_theta + i0), profile_value(base, j0 * n_theta + i0 + 1u), wt);
    let row1 = mix(profile_value(base, j1 * n_theta + i0), profile_value(base, j1 * n_theta + i0 + 1u), wt);
    return mix(row0, row1, wp);
}

const PROFILE_PI: f32 = 3.14159265;
