// Specular terms of the point-sampled environment lighting paper (Liu et al. 2006, after Cook and
// Torrance 1982), with no bindings so that a GPU test can evaluate them alone against their
// closed forms (runtime/tests/gpu.rs). Composed first into every compute pass (shaders.rs).

const PI: f32 = 3.14159265358979;

// Fresnel reflectance of a dielectric of index of refraction `ior` for unpolarised light, exact
// (the paper's F): F = 1/2 (g - c)^2 / (g + c)^2 (1 + (c (g + c) - 1)^2 / (c (g - c) + 1)^2) with
// c = cos of the angle to the normal and g^2 = ior^2 + c^2 - 1. F(1) = ((ior - 1) / (ior + 1))^2,
// F(0) = 1.
fn fresnel_dielectric(cos_in: f32, ior: f32) -> f32 {
    let c = clamp(cos_in, 0.0, 1.0);
    let g2 = ior * ior + c * c - 1.0;
    if g2 <= 0.0 {
        return 1.0;
    }
    let g = sqrt(g2);
    let a = (g - c) / (g + c);
    let b = (c * (g + c) - 1.0) / (c * (g - c) + 1.0);
    return 0.5 * a * a * (1.0 + b * b);
}

// The paper's distribution term D3 = (c3 / (cos^2 (c3 - 1) + 1))^2 is Trowbridge-Reitz (GGX) with
// c3 = alpha^2; here normalised so that the integral of D (n.h) over the hemisphere is 1:
// D = alpha^2 / (pi ((n.h)^2 (alpha^2 - 1) + 1)^2), i.e. D3 / (pi alpha^2).
fn ggx_d(n_dot_h: f32, alpha: f32) -> f32 {
    let a2 = max(alpha * alpha, 1e-8);
    let c = clamp(n_dot_h, 0.0, 1.0);
    let d = c * c * (a2 - 1.0) + 1.0;
    return a2 / (PI * d * d);
}

// Height-correlated Smith masking-shadowing for GGX divided by 4 (n.l)(n.v) (Heitz 2014), so
// that the specular BRDF is F D V.
fn ggx_visibility(n_dot_l: f32, n_dot_v: f32, alpha: f32) -> f32 {
    let a2 = alpha * alpha;
    let gv = n_dot_l * sqrt(n_dot_v * n_dot_v * (1.0 - a2) + a2);
    let gl = n_dot_v * sqrt(n_dot_l * n_dot_l * (1.0 - a2) + a2);
    return 0.5 / max(gv + gl, 1e-6);
}
