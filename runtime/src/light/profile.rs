//! Light profiles (IES candela tables, an area light's cosine) as the GPU reads them: a header
//! record with the profile's axes, then its intensities on a uniform grid (1 degree from the
//! aim, 5 degrees about it, wrapping), 16 to a 64-byte record after the lights and the shadow
//! faces' matrices in the one lights buffer (lights.wgsl `profile_factor`). A uniform grid
//! rather than the file's own angles: the shader indexes it without searching, and a table's
//! usual 2.5, 5 or 10 degree angles fall on it.

use grotto_format::LightProfile;

use crate::gpu::types::LightGpu;

/// Samples from the aim (0) to straight back (180 degrees).
pub(crate) const THETA_SAMPLES: u32 = 181;
/// Samples about the aim (5 degrees each) for a profile that is not the same all round.
pub(crate) const PHI_SAMPLES: u32 = 72;

/// `LightGpu::position_kind.w` of a point light with a profile (0: point, 1: spot).
pub(crate) const KIND_PROFILED: f32 = 2.0;

/// The records of `p`: the header (the 0-degree and 90-degree axes with the grid's sizes, the
/// aim) and the samples.
pub(crate) fn records(p: &LightProfile) -> Vec<LightGpu> {
    let (aim, zero, ninety) = p.frame();
    let n_phi = if p.profile.horizontal_deg.len() == 1 { 1 } else { PHI_SAMPLES };
    let mut values = Vec::with_capacity((THETA_SAMPLES * n_phi) as usize);
    for j in 0..n_phi {
        let phi = (j as f32 * 360.0 / n_phi as f32).to_radians();
        for i in 0..THETA_SAMPLES {
            values.push(p.profile.sample((i as f32).to_radians(), phi));
        }
    }
    values.resize(values.len().div_ceil(16) * 16, 0.0);
    let mut out = vec![LightGpu {
        position_kind: [zero[0], zero[1], zero[2], THETA_SAMPLES as f32],
        intensity_layer: [ninety[0], ninety[1], ninety[2], n_phi as f32],
        direction_cos_outer: [aim[0], aim[1], aim[2], 0.0],
        params: [0.0; 4],
    }];
    out.extend(values.chunks_exact(16).map(|c| LightGpu {
        position_kind: [c[0], c[1], c[2], c[3]],
        intensity_layer: [c[4], c[5], c[6], c[7]],
        direction_cos_outer: [c[8], c[9], c[10], c[11]],
        params: [c[12], c[13], c[14], c[15]],
    }));
    out
}

/// What the shader computes from `records(p)` toward unit direction `d` (a test's reference).
#[cfg(test)]
pub(crate) fn sample_records(r: &[LightGpu], d: glam::Vec3) -> f32 {
    use glam::Vec3;
    let flat: Vec<f32> = r[1..]
        .iter()
        .flat_map(|x| [x.position_kind, x.intensity_layer, x.direction_cos_outer, x.params])
        .flatten()
        .collect();
    let (n_theta, n_phi) = (r[0].position_kind[3] as usize, r[0].intensity_layer[3] as usize);
    let aim = Vec3::from_slice(&r[0].direction_cos_outer[..3]);
    let theta = d.dot(aim).clamp(-1.0, 1.0).acos();
    let ft = theta / std::f32::consts::PI * (n_theta - 1) as f32;
    let i0 = (ft as usize).min(n_theta - 2);
    let wt = (ft - i0 as f32).clamp(0.0, 1.0);
    let row = |j: usize| flat[j * n_theta + i0] * (1.0 - wt) + flat[j * n_theta + i0 + 1] * wt;
    if n_phi == 1 {
        return row(0);
    }
    let (zero, ninety) =
        (Vec3::from_slice(&r[0].position_kind[..3]), Vec3::from_slice(&r[0].intensity_layer[..3]));
    let phi = d.dot(ninety).atan2(d.dot(zero)).rem_euclid(std::f32::consts::TAU);
    let fp = phi / std::f32::consts::TAU * n_phi as f32;
    let j0 = (fp as usize).min(n_phi - 1);
    let wp = (fp - j0 as f32).clamp(0.0, 1.0);
    row(j0) * (1.0 - wp) + row((j0 + 1) % n_phi) * wp
}

#[cfg(test)]
mod tests {
    use super::*;
    use grotto_format::Profile;

    #[test]
    fn the_grid_answers_as_the_profile_does_where_the_table_has_values() {
        // An asymmetric table: brighter toward the profile's 90-degree plane.
        let profile = Profile {
            vertical_deg: vec![0.0, 30.0, 60.0, 90.0, 180.0],
            horizontal_deg: vec![0.0, 90.0, 180.0, 270.0, 360.0],
            relative: [
                [1.0, 0.8, 0.4, 0.1, 0.0],
                [1.0, 0.9, 0.7, 0.3, 0.0],
                [1.0, 0.6, 0.2, 0.0, 0.0],
                [1.0, 0.5, 0.3, 0.2, 0.0],
                [1.0, 0.8, 0.4, 0.1, 0.0],
            ]
            .concat(),
        };
        let p = LightProfile { aim: [0.3, -0.2, -1.0], turn_deg: 25.0, profile, source: String::new() };
        let r = records(&p);
        let (aim, zero, ninety) = p.frame();
        let (aim, zero, ninety) = (glam::Vec3::from(aim), glam::Vec3::from(zero), glam::Vec3::from(ninety));
        for (theta_deg, phi_deg) in
            [(0.0f32, 0.0f32), (30.0, 90.0), (60.0, 180.0), (30.0, 270.0), (45.0, 45.0), (75.0, 300.0)]
        {
            let (t, f) = (theta_deg.to_radians(), phi_deg.to_radians());
            let d = aim * t.cos() + (zero * f.cos() + ninety * f.sin()) * t.sin();
            let (gpu, cpu) = (sample_records(&r, d), p.toward(d.to_array()));
            assert!((gpu - cpu).abs() < 2e-3, "{theta_deg} / {phi_deg} degrees: grid {gpu}, profile {cpu}");
        }
    }
}
