// Environment light as 9 real SH coefficients (Ramamoorthi & Hanrahan 2001).
#import scene
#import ndf

// Real SH basis constants (same order and signs as preprocess/src/env.rs, which projects the map).
const SH_Y0: f32 = 0.282094791773878;
const SH_Y1: f32 = 0.488602511902920;
const SH_Y2: f32 = 1.092548430592079;
const SH_Y20: f32 = 0.315391565252520;
const SH_Y22: f32 = 0.546274215296040;

// Environment SH convolved per band: sum_l band[l] sum_m L_lm Y_lm(d). band = (1, 1, 1) is the
// radiance itself; (1, 2/3, 1/4) is irradiance / pi (Ramamoorthi & Hanrahan 2001); a cone of
// half-angle t averages band l by the mean of P_l over its cap: (1, (1+c)/2, c(1+c)/2), c = cos t.
fn sh_eval(d: vec3<f32>, band: vec3<f32>) -> vec3<f32> {
    let s = params.env_sh;
    var e = s[0].rgb * (SH_Y0 * band.x);
    e += (s[1].rgb * d.y + s[2].rgb * d.z + s[3].rgb * d.x) * (SH_Y1 * band.y);
    e += (s[4].rgb * (SH_Y2 * d.x * d.y) + s[5].rgb * (SH_Y2 * d.y * d.z)
        + s[6].rgb * (SH_Y20 * (3.0 * d.z * d.z - 1.0)) + s[7].rgb * (SH_Y2 * d.x * d.z)
        + s[8].rgb * (SH_Y22 * (d.x * d.x - d.y * d.y))) * band.z;
    return e;
}

// Mean environment radiance over a cone around unit `d` whose half-angle has cosine `c`.
fn sh_cone_radiance(d: vec3<f32>, c: f32) -> vec3<f32> {
    return max(sh_eval(d, vec3<f32>(1.0, 0.5 * (1.0 + c), 0.5 * c * (1.0 + c))), vec3<f32>(0.0));
}

// Irradiance / pi from the environment alone for a leaf or surfel whose normals have mean vector
// `mean` (|mean| = r in 0..=1, Toksvig): the NDF mixture of ndf_cos, a share r of clamped cosine
// at the mean normal (bands pi, 2pi/3, pi/4) and 1 - r of (1 + cos) / 4 (bands pi, pi/3, 0).
// r = 1 is Ramamoorthi & Hanrahan's formula.
fn sh_irradiance_ndf_over_pi(mean: vec3<f32>) -> vec3<f32> {
    let r = clamp(length(mean), 0.0, 1.0);
    let n = leaf_normal(mean);
    let band = vec3<f32>(1.0, r * (2.0 / 3.0) + (1.0 - r) / 3.0, 0.25 * r);
    return max(sh_eval(n, band), vec3<f32>(0.0));
}
