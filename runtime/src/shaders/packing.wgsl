// f32 and unit vectors travel through Rgba8Unorm targets bit-exactly: float colour targets are not
// renderable on every backend (GL), 8-bit unorm ones are. Packed by the splat passes, unpacked by
// shade and the shadow lookups.

fn pack_f32(v: f32) -> vec4<f32> {
    return unpack4x8unorm(bitcast<u32>(v));
}

fn unpack_f32(c: vec4<f32>) -> f32 {
    return bitcast<f32>(pack4x8unorm(c));
}

// Octahedral encoding of a unit vector in two 16-bit halves.
fn pack_normal(n: vec3<f32>) -> vec4<f32> {
    let l1 = abs(n.x) + abs(n.y) + abs(n.z);
    var p = n.xy / l1;
    if n.z < 0.0 {
        p = (vec2<f32>(1.0) - abs(p.yx)) * select(vec2<f32>(-1.0), vec2<f32>(1.0), p >= vec2<f32>(0.0));
    }
    return unpack4x8unorm(pack2x16unorm(p * 0.5 + vec2<f32>(0.5)));
}

fn unpack_normal(c: vec4<f32>) -> vec3<f32> {
    let p = unpack2x16unorm(pack4x8unorm(c)) * 2.0 - vec2<f32>(1.0);
    var n = vec3<f32>(p, 1.0 - abs(p.x) - abs(p.y));
    let t = max(-n.z, 0.0);
    n.x += select(t, -t, n.x >= 0.0);
    n.y += select(t, -t, n.y >= 0.0);
    return normalize(n);
}
