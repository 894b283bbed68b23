// Frames without bindings, shared by compute and render passes.

// Orthonormal basis around unit `n` (Duff et al. 2017, branchless).
fn basis(n: vec3<f32>) -> mat3x3<f32> {
    let s = select(-1.0, 1.0, n.z >= 0.0);
    let a = -1.0 / (s + n.z);
    let b = n.x * n.y * a;
    let t1 = vec3<f32>(1.0 + s * n.x * n.x * a, s * b, -s * n.x);
    let t2 = vec3<f32>(b, s + n.y * n.y * a, -n.y);
    return mat3x3<f32>(t1, t2, n);
}
