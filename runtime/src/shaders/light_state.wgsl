// Light transport state, which the passes write (bind group 1, read-write): each leaf's light, the
// anisotropic radiance pyramid (the propagation statistics are activity.wgsl's).
#import scene

struct LeafLight {
    direct: vec4<f32>,
    gather: vec4<f32>,
    out: vec4<f32>,
    // rgb: albedo * E_sh(n) / pi * V; w: sky visibility V (env pass).
    env: vec4<f32>,
    // Irradiance / pi from the lights beyond the shadow-map budget, without albedo (inject).
    far: vec4<f32>,
    // rgb: a bounce's running cone sum until its last batch (propagate).
    pending: vec4<f32>,
    // rgb: the last bounce's change of the gather (propagate's tail estimate).
    residual: vec4<f32>,
    // rgb: the estimated gather of the bounces not run (propagate); shade adds it to gather.
    tail: vec4<f32>,
}

@group(1) @binding(0) var<storage, read_write> leaf_light: array<LeafLight>;
// Six anisotropic values per node (premultiplied radiance, opacity), by travel direction:
// 0 +x, 1 -x, 2 +y, 3 -y, 4 +z, 5 -z. Stored as raw words, 4 per value as f32 or 2 as packed f16
// (`radiance_f16`, set by the renderer's `radiance_f16` setting): halves the pyramid's memory and
// bandwidth; see load_face/store_face.
@group(1) @binding(1) var<storage, read_write> faces: array<u32>;
override radiance_f16: bool = false;
// Largest finite f16: brighter values are clamped rather than turned into infinity.
const F16_MAX: f32 = 65504.0;

fn load_face(i: u32) -> vec4<f32> {
    if radiance_f16 {
        return vec4<f32>(unpack2x16float(faces[2u * i]), unpack2x16float(faces[2u * i + 1u]));
    }
    let b = 4u * i;
    return bitcast<vec4<f32>>(vec4<u32>(faces[b], faces[b + 1u], faces[b + 2u], faces[b + 3u]));
}

fn store_face(i: u32, v: vec4<f32>) {
    if radiance_f16 {
        let c = min(v, vec4<f32>(F16_MAX));
        faces[2u * i] = pack2x16float(c.xy);
        faces[2u * i + 1u] = pack2x16float(c.zw);
        return;
    }
    let u = bitcast<vec4<u32>>(v);
    let b = 4u * i;
    faces[b] = u.x;
    faces[b + 1u] = u.y;
    faces[b + 2u] = u.z;
    faces[b + 3u] = u.w;
}

// What a leaf sends on: out = emission + direct + env + albedo * gather (every pass that changes
// one of the terms recomputes it).
fn leaf_out(leaf: Leaf, s: LeafLight) -> vec4<f32> {
    return vec4<f32>(leaf.emission.rgb + s.direct.rgb + s.env.rgb + leaf.albedo_opacity.rgb * s.gather.rgb, 0.0);
}

// What a leaf shows: out plus the albedo's share of the tail (the bounces not run), as shade adds
// them up; propagate's change is measured on it. LeafLightGpu::shown on the CPU.
fn leaf_shown(leaf: Leaf, s: LeafLight) -> vec3<f32> {
    return s.out.rgb + leaf.albedo_opacity.rgb * s.tail.rgb;
}
