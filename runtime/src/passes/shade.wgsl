// Deferred shading of the surfel G-buffer: emission + direct (analytic point and spot lights with
// shadow maps) + indirect (albedo * gathered leaf radiance, trilinear or tricubic over leaves),
// then exposure, ACES tonemap and sRGB. Writes linear HDR (for EXR) and packed sRGB8 (for PNG).

@group(1) @binding(0) var gb_distance: texture_2d<f32>;
@group(1) @binding(1) var gb_normal: texture_2d<f32>;
@group(1) @binding(2) var gb_albedo: texture_2d<f32>;
@group(1) @binding(3) var<storage, read_write> out_hdr: array<vec4<f32>>;
@group(1) @binding(4) var<storage, read_write> out_ldr: array<u32>;

// Leaf gather, emission and sky visibility (x of the third) at `p_m`, interpolated over the leaves
// around it with weights renormalised over the leaves that exist (empty cells carry no light).
fn leaf_light_at(p_m: vec3<f32>) -> array<vec3<f32>, 3> {
    let u = p_m / params.leaf_size_m - vec3<f32>(0.5);
    let base = floor(u);
    let f = u - base;
    let i0 = vec3<i32>(base);
    var gather = vec3<f32>(0.0);
    var emission = vec3<f32>(0.0);
    var sky = 0.0;
    var wsum = 0.0;
    let cubic = (params.flags & FLAG_TRICUBIC) != 0u;
    let lo = select(0, -1, cubic);
    let hi = select(1, 2, cubic);
    for (var z = lo; z <= hi; z++) {
        for (var y = lo; y <= hi; y++) {
            for (var x = lo; x <= hi; x++) {
                let o = vec3<f32>(f32(x), f32(y), f32(z));
                var w3: vec3<f32>;
                if cubic {
                    w3 = vec3<f32>(bspline(o.x - f.x), bspline(o.y - f.y), bspline(o.z - f.z));
                } else {
                    w3 = max(vec3<f32>(1.0) - abs(o - f), vec3<f32>(0.0));
                }
                let w = w3.x * w3.y * w3.z;
                if w <= 0.0 {
                    continue;
                }
                let leaf = find_leaf(i0 + vec3<i32>(x, y, z));
                if leaf != EMPTY {
                    gather += w * leaf_light[leaf].gather.rgb;
                    emission += w * leaves[leaf].emission.rgb;
                    sky += w * leaf_light[leaf].env.w;
                    wsum += w;
                }
            }
        }
    }
    let inv = select(0.0, 1.0 / wsum, wsum > 1e-6);
    return array<vec3<f32>, 3>(gather * inv, emission * inv, vec3<f32>(sky * inv, 0.0, 0.0));
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
        let p = params.camera_eye_m.xyz + ray * d;
        let n = unpack_normal(textureLoad(gb_normal, src, 0));
        let albedo = textureLoad(gb_albedo, src, 0).rgb;
        var color = vec3<f32>(0.0);
        if (params.flags & FLAG_DIRECT) != 0u {
            var irradiance = vec3<f32>(0.0);
            for (var k = 0u; k < params.light_count; k++) {
                let light = lights[k];
                let to_light = light.position_kind.xyz - p;
                let dist = max(length(to_light), 1e-4);
                let l = to_light / dist;
                let c = dot(n, l);
                if c <= 0.0 {
                    continue;
                }
                let falloff = spot_factor(light, l);
                if falloff <= 0.0 {
                    continue;
                }
                // Normal offset: the shadow maps hold the same discs, so look up a little in front.
                let q = p + n * (0.25 * params.leaf_size_m);
                let vis = shadow_visibility(light, q, distance(light.position_kind.xyz, q), params.shadow_bias_m * 0.5);
                irradiance += light.intensity_layer.rgb * (c * falloff * vis / (dist * dist));
            }
            color += albedo / PI * irradiance;
        }
        if (params.flags & (FLAG_INDIRECT | FLAG_EMISSION | FLAG_ENV)) != 0u {
            // A quarter leaf behind the surface: inside the leaf the surfel belongs to, so the
            // trilinear weights land on leaves, not on the empty cells in front (measured: looking
            // up in front lost the gather wherever a surfel sat on a cell face).
            let l = leaf_light_at(p - n * (0.25 * params.leaf_size_m));
            if (params.flags & FLAG_INDIRECT) != 0u {
                color += albedo * l[0];
            }
            if (params.flags & FLAG_EMISSION) != 0u {
                color += l[1];
            }
            if (params.flags & FLAG_ENV) != 0u {
                // Environment light at the surfel's own normal (Ramamoorthi-Hanrahan), times the
                // sky visibility the env pass found for the leaves around it.
                color += albedo * sh_irradiance_ndf_over_pi(n) * l[2].x;
            }
        }
        hdr = color;
    }
    out_hdr[idx] = vec4<f32>(hdr, coverage);
    let ldr = tonemap(hdr * params.exposure);
    out_ldr[idx] = pack4x8unorm(vec4<f32>(ldr, 1.0));
}
