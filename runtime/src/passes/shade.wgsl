// Deferred shading of the surfel G-buffer: emission + direct (analytic point and spot lights with
// shadow maps) + indirect (albedo * gathered leaf radiance, trilinear or tricubic over leaves),
// then exposure, ACES tonemap and sRGB. Writes linear HDR (for EXR) and packed sRGB8 (for PNG).
#import lights
#import cone
#import sh
#import brdf
#import color
#import packing

@group(2) @binding(0) var gb_distance: texture_2d<f32>;
@group(2) @binding(1) var gb_normal: texture_2d<f32>;
@group(2) @binding(2) var gb_albedo: texture_2d<f32>;
// The frame, one buffer (WebGPU allows 8 storage buffers per stage by default): linear HDR and
// coverage as 4 f32 words a pixel, then packed sRGB8 one word a pixel (shade.rs `Outputs`).
@group(2) @binding(3) var<storage, read_write> out: array<u32>;

fn write_pixel(idx: u32, hdr: vec4<f32>, ldr: vec3<f32>) {
    let b = 4u * idx;
    let bits = bitcast<vec4<u32>>(hdr);
    out[b] = bits.x;
    out[b + 1u] = bits.y;
    out[b + 2u] = bits.z;
    out[b + 3u] = bits.w;
    out[4u * params.width * params.height + idx] = pack4x8unorm(vec4<f32>(ldr, 1.0));
}
// The environment's GGX-prefiltered lat-long levels stacked top to bottom (Params::env_levels);
// a 1x1 placeholder without a chain.
@group(2) @binding(5) var env_atlas: texture_2d<f32>;
// Blended splats' sums (passes/gbuffer.rs, FLAG_BLEND): (w n, w) and (w albedo, unused).
@group(2) @binding(6) var gb_normal_weight: texture_2d<f32>;
@group(2) @binding(7) var gb_albedo_sum: texture_2d<f32>;

// Level k of the env atlas along unit `d`, bilinear (lat-long as preprocess/src/env.rs: theta
// from +z, phi = atan2(y, x), wrapping in phi).
fn env_level(k: u32, d: vec3<f32>) -> vec3<f32> {
    let lv = params.env_levels[k];
    let row0 = i32(lv.x);
    let w = i32(lv.y);
    let h = i32(lv.z);
    let theta = acos(clamp(d.z, -1.0, 1.0));
    var phi = atan2(d.y, d.x);
    if phi < 0.0 {
        phi += 2.0 * PI;
    }
    let x = phi / (2.0 * PI) * f32(w) - 0.5;
    let y = clamp(theta / PI * f32(h) - 0.5, 0.0, f32(h - 1));
    let x0 = floor(x);
    let y0 = floor(y);
    let fx = x - x0;
    let fy = y - y0;
    let xa = ((i32(x0) % w) + w) % w;
    let xb = (xa + 1) % w;
    let ya = min(i32(y0), h - 1);
    let yb = min(ya + 1, h - 1);
    let a = textureLoad(env_atlas, vec2<i32>(xa, row0 + ya), 0).rgb;
    let b = textureLoad(env_atlas, vec2<i32>(xb, row0 + ya), 0).rgb;
    let c = textureLoad(env_atlas, vec2<i32>(xa, row0 + yb), 0).rgb;
    let e = textureLoad(env_atlas, vec2<i32>(xb, row0 + yb), 0).rgb;
    return mix(mix(a, b, fx), mix(c, e, fx), fy);
}

// Glossy environment radiance along unit `r` for GGX `roughness`: the two prefiltered levels
// around it (levels ascend in roughness), blended; without a chain, the SH radiance averaged over
// a cone of half-angle tangent `tan_half`.
fn env_glossy(r: vec3<f32>, roughness: f32, tan_half: f32) -> vec3<f32> {
    let n = params.env_chain.x;
    if n == 0u {
        return sh_cone_radiance(r, 1.0 / sqrt(1.0 + tan_half * tan_half));
    }
    var k = 0u;
    for (var i = 1u; i < n; i++) {
        if params.env_levels[i].w <= roughness {
            k = i;
        }
    }
    if k + 1u >= n {
        return env_level(k, r);
    }
    let r0 = params.env_levels[k].w;
    let r1 = params.env_levels[k + 1u].w;
    let t = clamp((roughness - r0) / max(r1 - r0, 1e-6), 0.0, 1.0);
    return mix(env_level(k, r), env_level(k + 1u, r), t);
}

// Weighted sums of the leaf light around a point (leaf_light_sum). The cone-traced light (gather
// and sky visibility) has its own weight: with interleaved cone sets it is filtered wider.
struct LeafSum {
    gather: vec3<f32>,
    emission: vec3<f32>,
    far: vec3<f32>,
    sky: f32,
    weight: f32,
    weight_traced: f32,
    // The traced light under the near weights too: where no leaf of the wide tent faces the
    // surface's way (a surfel at a thin pillar's silhouette), the filter falls back to it.
    gather_near: vec3<f32>,
    sky_near: f32,
}

// Sums the leaves of the cells i0 + lo ..= i0 + hi (each axis) with separable weights at
// fractional position `f`: 0 trilinear, 1 tricubic B-spline, 2 a tent twice as wide, 3 trilinear
// with the cone-traced light under the tent twice as wide (interleaved cone sets: that tent is
// two boxes of two leaves, so it averages each 2x2x2 block's eight cone sets at every point,
// where trilinear would show each leaf's own set at its centre as a mottle of leaf-sized dots).
fn leaf_light_sum(i0: vec3<i32>, f: vec3<f32>, lo: i32, hi: i32, kernel: u32, n: vec3<f32>) -> LeafSum {
    var sum = LeafSum(vec3<f32>(0.0), vec3<f32>(0.0), vec3<f32>(0.0), 0.0, 0.0, 0.0, vec3<f32>(0.0), 0.0);
    // The window's blocks (svo.wgsl, `BLOCK_LOD`): at most 2 an axis, each found once.
    let anchor = tile_anchor();
    let by_block = blocks_usable();
    let first = i0 + vec3<i32>(lo) - anchor;
    let base = first >> vec3<u32>(BLOCK_LOD);
    let span = ((first + vec3<i32>(hi - lo)) >> vec3<u32>(BLOCK_LOD)) - base;
    var blocks: array<vec2<u32>, 8>;
    if by_block {
        for (var bz = 0; bz <= span.z; bz++) {
            for (var by = 0; by <= span.y; by++) {
                for (var bx = 0; bx <= span.x; bx++) {
                    let b = vec3<i32>(bx, by, bz);
                    blocks[bx + 2 * by + 4 * bz] = find_node_at(anchor + ((base + b) << vec3<u32>(BLOCK_LOD)), BLOCK_LOD);
                }
            }
        }
    }
    for (var z = lo; z <= hi; z++) {
        for (var y = lo; y <= hi; y++) {
            for (var x = lo; x <= hi; x++) {
                let o = vec3<f32>(f32(x), f32(y), f32(z));
                let wide3 = max(vec3<f32>(1.0) - 0.5 * abs(o - f), vec3<f32>(0.0));
                var w3: vec3<f32>;
                if kernel == 2u {
                    w3 = wide3;
                } else if kernel == 1u {
                    w3 = vec3<f32>(bspline(o.x - f.x), bspline(o.y - f.y), bspline(o.z - f.z));
                } else {
                    w3 = max(vec3<f32>(1.0) - abs(o - f), vec3<f32>(0.0));
                }
                let w = w3.x * w3.y * w3.z;
                let wt = select(w, wide3.x * wide3.y * wide3.z, kernel == 3u);
                if w <= 0.0 && wt <= 0.0 {
                    continue;
                }
                let cell = i0 + vec3<i32>(x, y, z);
                var leaf: u32;
                if by_block {
                    let rel = cell - anchor;
                    let b = (rel >> vec3<u32>(BLOCK_LOD)) - base;
                    leaf = leaf_in_block(blocks[b.x + 2 * b.y + 4 * b.z], rel);
                } else {
                    leaf = find_leaf(cell);
                }
                if leaf != EMPTY {
                    var wt_leaf = wt;
                    if kernel == 3u {
                        // The wider tent reaches past corners and thin walls: there a leaf facing
                        // another way (another wall) counts by how far its normal agrees.
                        wt_leaf *= max(dot(leaf_normal(leaves[leaf].normal_mean.xyz), n), 0.0);
                    }
                    let traced = leaf_light[leaf].gather.rgb + leaf_light[leaf].tail.rgb;
                    sum.gather += wt_leaf * traced;
                    sum.sky += wt_leaf * leaf_light[leaf].env.w;
                    sum.weight_traced += wt_leaf;
                    sum.gather_near += w * traced;
                    sum.sky_near += w * leaf_light[leaf].env.w;
                    sum.emission += w * leaves[leaf].emission.rgb;
                    sum.far += w * leaf_light[leaf].far.rgb;
                    sum.weight += w;
                }
            }
        }
    }
    return sum;
}

// Leaf gather, emission, sky visibility (x of the third) and the light of the lights beyond the
// shadow-map budget (`far`) at `p_m`, interpolated over the leaves around it with weights
// renormalised over the leaves that exist (empty cells carry no light).
fn leaf_light_at(p_m: vec3<f32>, n: vec3<f32>) -> array<vec3<f32>, 4> {
    let u = p_m / params.leaf_size_m - vec3<f32>(0.5);
    let base = floor(u);
    let f = u - base;
    let i0 = vec3<i32>(base);
    let cubic = (params.flags & FLAG_TRICUBIC) != 0u;
    let interleaved = (params.flags & FLAG_CONE_INTERLEAVE) != 0u;
    // Tricubic already takes each 2x2x2 block's sets down to a third per axis; it stays as is.
    let kernel = select(select(0u, 3u, interleaved), 1u, cubic);
    let wide = kernel != 0u;
    var sum = leaf_light_sum(i0, f, select(0, -1, wide), select(1, 2, wide), kernel, n);
    if sum.weight <= 1e-6 {
        // A surfel at the rim of its leaf can have none of the 8 nearest leaf cells occupied:
        // then the 4x4x4 cells around it with a tent twice as wide (measured: black speckles in
        // the per-leaf lamp light otherwise).
        sum = leaf_light_sum(i0, f, -1, 2, 2u, n);
    }
    let inv = select(0.0, 1.0 / sum.weight, sum.weight > 1e-6);
    var gather = sum.gather_near * inv;
    var sky = sum.sky_near * inv;
    if sum.weight_traced > 1e-6 {
        gather = sum.gather / sum.weight_traced;
        sky = sum.sky / sum.weight_traced;
    }
    return array<vec3<f32>, 4>(gather, sum.emission * inv, vec3<f32>(sky, 0.0, 0.0), sum.far * inv);
}

// Cubic B-spline kernel (support 2): smooth, non-negative, sums to 1 over the 4 taps.
fn bspline(x: f32) -> f32 {
    let a = abs(x);
    if a < 1.0 {
        return (4.0 - 6.0 * a * a + 3.0 * a * a * a) / 6.0;
    }
    if a < 2.0 {
        let t = 2.0 - a;
        return t * t * t / 6.0;
    }
    return 0.0;
}

// Of the 24 neighbours in a 5x5 window, how many must be covered for a gap to be filled (15: a
// true silhouette against open background has at most about half).
const HOLE_MIN_COVERED: i32 = 15;

@compute @workgroup_size(8, 8)
fn shade(@builtin(global_invocation_id) gid: vec3<u32>) {
    if gid.x >= params.width || gid.y >= params.height {
        return;
    }
    let xy = vec2<i32>(gid.xy);
    let idx = gid.y * params.width + gid.x;
    var d = unpack_f32(textureLoad(gb_distance, xy, 0));
    var src = xy;
    if d <= 0.0 {
        // Hole filling: an uncovered pixel whose 5x5 neighbourhood is mostly covered is a gap
        // between discs, not background; it takes the nearest covered neighbour's surface.
        var covered = 0;
        var best = 1e9;
        let size = vec2<i32>(i32(params.width), i32(params.height));
        for (var dy = -2; dy <= 2; dy++) {
            for (var dx = -2; dx <= 2; dx++) {
                let q = xy + vec2<i32>(dx, dy);
                if (dx == 0 && dy == 0) || any(q < vec2<i32>(0)) || any(q >= size) {
                    continue;
                }
                let dq = unpack_f32(textureLoad(gb_distance, q, 0));
                if dq > 0.0 {
                    covered += 1;
                    let r = f32(dx * dx + dy * dy);
                    if r < best {
                        best = r;
                        src = q;
                        d = dq;
                    }
                }
            }
        }
        if covered < HOLE_MIN_COVERED {
            d = 0.0;
            src = xy;
        }
    }
    // Ray through the pixel centre, the same point the rasteriser interpolated.
    let ndc = vec2<f32>(
        (f32(gid.x) + 0.5) / f32(params.width) * 2.0 - 1.0,
        1.0 - (f32(gid.y) + 0.5) / f32(params.height) * 2.0,
    );
    let t = params.camera_forward.w;
    let ray = normalize(
        params.camera_forward.xyz + params.camera_right.xyz * (ndc.x * t * params.camera_right.w)
            + params.camera_up.xyz * (ndc.y * t),
    );
    var hdr = params.background.rgb;
    if (params.flags & FLAG_ENV) != 0u {
        // The sky behind the geometry: the environment's SH radiance (band-limited).
        hdr += max(sh_eval(ray, vec3<f32>(1.0)), vec3<f32>(0.0));
    }
    // Alpha: 1 where a surfel covers the pixel, 0 where the background shows (hole checks).
    var coverage = 0.0;
    if d > 0.0 {
        coverage = 1.0;
        var n = unpack_normal(textureLoad(gb_normal, src, 0));
        var albedo_slot = textureLoad(gb_albedo, src, 0);
        if (params.flags & FLAG_BLEND) != 0u && (params.flags & FLAG_VIEWS_WITHOUT_LIGHT) == 0u {
            // The surface's blended normal and albedo, at the front disc's point (the material
            // stays the front disc's too). The views without light show each disc's own data
            // (albedo, normals, level, scan): they are for judging the data, disc by disc.
            let nw = textureLoad(gb_normal_weight, src, 0);
            let albedo_sum = textureLoad(gb_albedo_sum, src, 0);
            if nw.w > 0.0 && dot(nw.xyz, nw.xyz) > 1e-12 {
                n = normalize(nw.xyz);
                albedo_slot = vec4<f32>(albedo_sum.rgb / nw.w, albedo_slot.a);
            }
        }
        let p = params.camera_eye_m.xyz + ray * d;
        // The light view lights every surface as if it were white.
        let albedo = select(albedo_slot.rgb, vec3<f32>(1.0), (params.flags & FLAG_VIEW_LIGHT) != 0u);
        let plain = params.flags & FLAG_VIEWS_WITHOUT_LIGHT;
        if plain != 0u {
            // Views without light (settings.rs ViewMode): the value as an sRGB colour, no exposure.
            var shown = albedo_slot.rgb;
            if plain == FLAG_VIEW_NORMALS {
                shown = srgb_to_linear(0.5 + 0.5 * n);
            } else if plain == FLAG_VIEW_LEVEL {
                let q = p - n * (0.25 * params.leaf_size_m);
                let t = find_tile(vec3<i32>(floor(q / params.leaf_size_m)));
                var level = vec3<f32>(1.0, 0.0, 1.0);
                if t != EMPTY {
                    let lod = tiles[t].leaf_lod;
                    level = select(select(vec3<f32>(0.9, 0.15, 0.1), vec3<f32>(0.95, 0.8, 0.1), lod <= COARSE_LEVELS), vec3<f32>(0.15, 0.75, 0.2), lod == 0u);
                }
                shown = level * (0.35 + 0.65 * max(dot(n, -ray), 0.0));
            } else if plain == FLAG_VIEW_SCAN {
                // The G-buffer's albedo is the scan colour (splat.wgsl).
                shown = albedo_slot.rgb * (0.35 + 0.65 * max(dot(n, -ray), 0.0));
            }
            write_pixel(idx, vec4<f32>(shown, coverage), linear_to_srgb(clamp(shown, vec3<f32>(0.0), vec3<f32>(1.0))));
            return;
        }
        // Material slot from the albedo's alpha: 0 diffuse, 1..=7 specular (Params::materials).
        let slot = min(u32(round(albedo_slot.a * 255.0)), 7u);
        // The lux view wants the light arriving: no reflection off wet surfaces, no emission.
        let lux_view = (params.flags & FLAG_VIEW_LUX) != 0u;
        let specular = (params.flags & FLAG_SPECULAR) != 0u && slot > 0u && !lux_view;
        let mat = params.materials[slot];
        let v = -ray;
        let nv = max(dot(n, v), 1e-3);
        var highlight = vec3<f32>(0.0);
        var color = vec3<f32>(0.0);
        if (params.flags & FLAG_DIRECT) != 0u {
            // Per pixel: the lights with shadow maps (and, shadows off, every light) in range;
            // the lights beyond the budget come from the leaves (`far`, below).
            var irradiance = vec3<f32>(0.0);
            let cell = light_cell(p);
            let last = light_grid_word(cell + 1u);
            for (var j = light_grid_word(cell); j < last; j++) {
                let light = lights[light_grid_word(j)];
                if light_shadow_kind(light) != LIGHT_MAP {
                    // Lists hold the lights with shadow maps first (light/setup.rs): the rest are
                    // per leaf.
                    break;
                }
                let seen = light_seen(light, p);
                if seen.falloff <= 0.0 {
                    continue;
                }
                let l = seen.l;
                let dist = seen.dist;
                let falloff = seen.falloff;
                let c = dot(n, l);
                if c <= 0.0 {
                    continue;
                }
                // Normal offset: the shadow maps hold the same discs, so look up a little in front.
                let q = p + n * (0.25 * params.leaf_size_m);
                let vis = shadow_visibility(light, q, distance(light.position_kind.xyz, q), params.shadow_bias_m * 0.5);
                let e = light.intensity_layer.rgb * (c * falloff * vis / (dist * dist));
                irradiance += e;
                if specular {
                    // The lamp's highlight on a wet surface: F D V (GGX, Smith), F at the half
                    // vector; lamps beyond the shadow-map budget make none (they are per leaf).
                    let h = normalize(l + v);
                    let f_h = fresnel_dielectric(dot(v, h), mat.z);
                    highlight += e * (f_h * ggx_d(dot(n, h), mat.y) * ggx_visibility(c, nv, mat.y));
                }
            }
            color += albedo / PI * irradiance;
        }
        if (params.flags & (FLAG_INDIRECT | FLAG_EMISSION | FLAG_ENV | FLAG_FAR_LIGHTS)) != 0u {
            // A quarter leaf behind the surface: inside the leaf the surfel belongs to, so the
            // trilinear weights land on leaves, not on the empty cells in front (measured: looking
            // up in front lost the gather wherever a surfel sat on a cell face).
            let l = leaf_light_at(p - n * (0.25 * params.leaf_size_m), n);
            if (params.flags & FLAG_INDIRECT) != 0u {
                color += albedo * l[0];
            }
            if (params.flags & FLAG_EMISSION) != 0u && !lux_view {
                color += l[1];
            }
            if (params.flags & FLAG_FAR_LIGHTS) != 0u {
                color += albedo * l[3];
            }
            if (params.flags & FLAG_ENV) != 0u {
                // Environment light at the surfel's own normal (Ramamoorthi-Hanrahan), times the
                // sky visibility the env pass found for the leaves around it.
                color += albedo * sh_irradiance_ndf_over_pi(n) * l[2].x;
            }
        }
        if specular {
            // Wet walls and water: the diffuse layer under a Fresnel-weighted mirror-like layer of
            // weight Ks (Liu et al. 2006: Kd diffuse + Ks F specular). What the surface reflects
            // is a cone along the reflection vector through the SVO (the cave paper's specular
            // cone), its width from the roughness; where the cone escapes, the environment
            // prefiltered for that roughness, and the constant background.
            let r = reflect(ray, n);
            let f = fresnel_dielectric(nv, mat.z);
            let tan_half = clamp(1.3 * mat.y, 0.02, 1.0);
            let cone = trace_cone(p + n * params.leaf_size_m, r, tan_half, vec2<f32>(params.leaf_size_m, dot(r, n)));
            var reflected = cone.rgb + (1.0 - cone.a) * params.background.rgb;
            if (params.flags & FLAG_ENV) != 0u {
                reflected += (1.0 - cone.a) * env_glossy(r, mat.w, tan_half);
            }
            color = color * (1.0 - mat.x * f) + mat.x * (f * reflected + highlight);
        }
        hdr = color;
        if lux_view {
            // With every albedo 1, `color` is the irradiance over pi per channel: lux is 683 lm/W
            // times its luminance (grotto_format::photometry).
            let lux = 683.0 * PI * dot(color, vec3<f32>(0.2126, 0.7152, 0.0722));
            write_pixel(idx, vec4<f32>(vec3<f32>(lux), coverage), lux_color(lux));
            return;
        }
    }
    if d <= 0.0 && (params.flags & (FLAG_VIEWS_WITHOUT_LIGHT | FLAG_VIEW_LUX)) != 0u {
        hdr = vec3<f32>(0.0);
    }
    write_pixel(idx, vec4<f32>(hdr, coverage), tonemap(hdr * params.exposure));
}
