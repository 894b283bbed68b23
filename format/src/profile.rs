//! Photometric profiles: how a light's intensity varies with direction (an IES LM-63 type C
//! candela table, ies.rs), and where a light points it.

use serde::{Deserialize, Serialize};

/// A light's photometric profile placed in the world.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub struct LightProfile {
    /// Where the profile's 0 degrees points (type C: the nadir of a luminaire hanging straight).
    pub aim: [f32; 3],
    /// Turn of the profile's 0-degree plane about the aim, degrees, from the reference direction
    /// ([`LightProfile::frame`]).
    #[serde(default)]
    pub turn_deg: f32,
    pub profile: Profile,
    /// The file it was read from, as given.
    #[serde(default)]
    pub source: String,
}

impl LightProfile {
    /// Unit axes `(aim, zero, ninety)` of the profile: the aim, the direction of its 0-degree
    /// horizontal plane (the aim crossed with world up, or world +x where the aim is vertical,
    /// turned by `turn_deg`), and the 90-degree one.
    pub fn frame(&self) -> ([f32; 3], [f32; 3], [f32; 3]) {
        let n = |v: [f32; 3]| {
            let l = (v[0] * v[0] + v[1] * v[1] + v[2] * v[2]).sqrt();
            if l > 0.0 { v.map(|c| c / l) } else { [0.0, 0.0, -1.0] }
        };
        let cross = |a: [f32; 3], b: [f32; 3]| {
            [a[1] * b[2] - a[2] * b[1], a[2] * b[0] - a[0] * b[2], a[0] * b[1] - a[1] * b[0]]
        };
        let aim = n(self.aim);
        let side = cross(aim, [0.0, 0.0, 1.0]);
        let x0 = if side.iter().map(|c| c * c).sum::<f32>() > 1e-6 {
            n(side)
        } else {
            n(cross(cross(aim, [1.0, 0.0, 0.0]), aim))
        };
        let y0 = cross(aim, x0);
        let (s, c) = self.turn_deg.to_radians().sin_cos();
        let zero = [0, 1, 2].map(|i| x0[i] * c + y0[i] * s);
        let ninety = cross(aim, zero);
        (aim, zero, ninety)
    }

    /// Relative intensity toward unit direction `d` (world axes).
    pub fn toward(&self, d: [f32; 3]) -> f32 {
        let (aim, zero, ninety) = self.frame();
        let dot = |a: [f32; 3], b: [f32; 3]| a[0] * b[0] + a[1] * b[1] + a[2] * b[2];
        let theta = dot(d, aim).clamp(-1.0, 1.0).acos();
        let phi = dot(d, ninety).atan2(dot(d, zero));
        self.profile.sample(theta, phi)
    }
}

/// A luminaire's relative intensity by direction, LM-63 type C: vertical angles from the aim,
/// horizontal angles about it.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub struct Profile {
    /// Degrees from the aim, ascending, 0 to 180.
    pub vertical_deg: Vec<f32>,
    /// Degrees about the aim, ascending from 0; the last is 0 (the same all round), 90 (each
    /// quadrant mirrors the first), 180 (the two halves mirror) or 360.
    pub horizontal_deg: Vec<f32>,
    /// Intensity per (horizontal, vertical), horizontal-major, the peak 1.
    pub relative: Vec<f32>,
}

impl Profile {
    /// Whether the sizes and angles hold together (what a package's reader checks).
    pub fn check(&self) -> Result<(), String> {
        let (nv, nh) = (self.vertical_deg.len(), self.horizontal_deg.len());
        let rising = |a: &[f32]| a.windows(2).all(|w| w[0] < w[1]) && a.iter().all(|x| x.is_finite());
        if nv < 2 || nh < 1 || self.relative.len() != nv * nh {
            return Err(format!(
                "{nv} vertical x {nh} horizontal angles hold {} values",
                self.relative.len()
            ));
        }
        if !rising(&self.vertical_deg) || self.vertical_deg[0] != 0.0 || self.vertical_deg[nv - 1] != 180.0 {
            return Err("vertical angles must rise from 0 to 180".into());
        }
        let last = self.horizontal_deg[nh - 1];
        if !rising(&self.horizontal_deg)
            || self.horizontal_deg[0] != 0.0
            || ![0.0, 90.0, 180.0, 360.0].contains(&last)
        {
            return Err("horizontal angles must rise from 0 to 0, 90, 180 or 360".into());
        }
        if !self.relative.iter().all(|v| v.is_finite() && *v >= 0.0) {
            return Err("intensities must be finite and >= 0".into());
        }
        Ok(())
    }

    /// Intensity `theta_rad` from the aim and `phi_rad` about it, bilinear in the table.
    pub fn sample(&self, theta_rad: f32, phi_rad: f32) -> f32 {
        let theta = theta_rad.to_degrees().clamp(0.0, 180.0);
        let last = *self.horizontal_deg.last().unwrap_or(&0.0);
        let mut phi = phi_rad.to_degrees().rem_euclid(360.0);
        if last <= 180.0 && phi > 180.0 {
            phi = 360.0 - phi;
        }
        if last <= 90.0 && phi > 90.0 {
            phi = 180.0 - phi;
        }
        let (v0, v1, tv) = bracket(&self.vertical_deg, theta);
        let (h0, h1, th) = bracket(&self.horizontal_deg, phi);
        let nv = self.vertical_deg.len();
        let at = |h: usize, v: usize| self.relative[h * nv + v];
        let row = |h: usize| at(h, v0) + (at(h, v1) - at(h, v0)) * tv;
        row(h0) + (row(h1) - row(h0)) * th
    }

    /// The intensity integrated over the sphere, steradians (4 pi for an even light).
    pub fn integral_sr(&self) -> f64 {
        let (n_theta, n_phi) = (720, if self.horizontal_deg.len() == 1 { 1 } else { 720 });
        let d_theta = std::f64::consts::PI / n_theta as f64;
        let d_phi = 2.0 * std::f64::consts::PI / n_phi as f64;
        let mut sum = 0.0;
        for i in 0..n_theta {
            let t = (i as f64 + 0.5) * d_theta;
            let ring: f64 =
                (0..n_phi).map(|j| f64::from(self.sample(t as f32, ((j as f64 + 0.5) * d_phi) as f32))).sum();
            sum += ring * t.sin() * d_theta * d_phi;
        }
        sum
    }
}

/// The table cells around `x` in ascending `at`: indices and the weight of the second.
fn bracket(at: &[f32], x: f32) -> (usize, usize, f32) {
    let n = at.len();
    if n == 1 || x <= at[0] {
        return (0, 0, 0.0);
    }
    if x >= at[n - 1] {
        return (n - 1, n - 1, 0.0);
    }
    let i = at.partition_point(|&a| a <= x) - 1;
    (i, i + 1, (x - at[i]) / (at[i + 1] - at[i]))
}
