//! The two JSON sections: the scene (lights, materials, cameras, environment) and provenance (what
//! built the package from what). They are small, read once, and change shape more often than the
//! binary sections, so they are self-describing JSON rather than fixed records; unknown fields are
//! ignored, which keeps them forward compatible within a major version.
//!
//! World positions are f64 metres in the package's world frame (survey coordinates can be ~5e6 m).

use std::collections::BTreeMap;

use serde::{Deserialize, Serialize};

use crate::story::{Poi, Tour};

/// Everything in a package that is not geometry.
#[derive(Clone, Debug, Default, PartialEq, Serialize, Deserialize)]
#[serde(default)]
pub struct Scene {
    pub lights: Vec<Light>,
    pub materials: Vec<Material>,
    pub cameras: Vec<Camera>,
    pub environment: Option<Environment>,
    /// The scans the points came from (format 1.2), indexed by the surfel-scans sections.
    #[serde(skip_serializing_if = "Vec::is_empty")]
    pub scans: Vec<ScanInfo>,
    /// Points of interest and guided tours (story.rs; readers before them ignore them).
    #[serde(skip_serializing_if = "Vec::is_empty")]
    pub pois: Vec<Poi>,
    #[serde(skip_serializing_if = "Vec::is_empty")]
    pub tours: Vec<Tour>,
    /// Circuits the lights belong to, switched together (lighting.rs; readers before them
    /// ignore them and light everything).
    #[serde(skip_serializing_if = "Vec::is_empty")]
    pub circuits: Vec<Circuit>,
}

/// Lights switched together (show lighting, work lighting...).
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub struct Circuit {
    pub name: String,
    #[serde(default)]
    pub title: String,
    /// Whether it is switched on when the package opens.
    #[serde(default = "switched_on")]
    pub on: bool,
}

fn switched_on() -> bool {
    true
}

/// One input scan of a package.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub struct ScanInfo {
    /// The file's name, with `#k` for the k-th scan of a file that holds several (E57).
    pub name: String,
}

/// A light source. Colours are linear RGB; `power_w` is radiant power in watts.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub struct Light {
    #[serde(default)]
    pub name: String,
    #[serde(flatten)]
    pub shape: LightShape,
    pub color: [f32; 3],
    pub power_w: f32,
    /// The circuit it is on (None: always on).
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub circuit: Option<String>,
    /// How its intensity varies with direction (an IES file's candela table); None: evenly.
    /// With a profile, `power_w` is the flux of the whole distribution.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub profile: Option<LightProfile>,
}

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

#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
#[serde(tag = "kind", rename_all = "snake_case")]
/// Where a light is and how it spreads its power.
pub enum LightShape {
    Point {
        position_m: [f64; 3],
    },
    Spot {
        position_m: [f64; 3],
        direction: [f32; 3],
        inner_angle_rad: f32,
        outer_angle_rad: f32,
    },
    /// A rectangle emitting on the side its normal faces; its samples are emissive leaves.
    Area {
        center_m: [f64; 3],
        normal: [f32; 3],
        size_m: [f32; 2],
    },
}

/// Surface response for a named set of points (scans or regions chosen by the manifest).
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub struct Material {
    pub name: String,
    /// 0 = purely diffuse. Wet walls and water are specular.
    #[serde(default)]
    pub specular: f32,
    /// GGX roughness of the specular lobe (alpha = roughness^2).
    #[serde(default = "default_roughness")]
    pub roughness: f32,
    /// Index of refraction of the reflecting film for the Fresnel term (water 1.33).
    #[serde(default = "default_ior")]
    pub ior: f32,
    /// Where the material applies; `None`: nowhere yet (a name other sections may refer to).
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub region: Option<MaterialRegion>,
}

/// The points a material covers: inside a world-space box and, optionally, facing up at least
/// `min_normal_z` (1 = level floors only: pools; -1 = any direction: wet walls).
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub struct MaterialRegion {
    pub min_m: [f64; 3],
    pub max_m: [f64; 3],
    #[serde(default = "any_direction")]
    pub min_normal_z: f32,
}

fn default_roughness() -> f32 {
    0.5
}

fn default_ior() -> f32 {
    1.33
}

fn any_direction() -> f32 {
    -1.0
}

/// A named viewpoint.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub struct Camera {
    pub name: String,
    pub eye_m: [f64; 3],
    pub look_at_m: [f64; 3],
    #[serde(default = "default_up")]
    pub up: [f64; 3],
    pub fov_y_deg: f64,
}

fn default_up() -> [f64; 3] {
    [0.0, 0.0, 1.0]
}

/// Environment light; its SH and prefiltered sections carry `item` = `index`.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub struct Environment {
    pub index: u32,
    pub intensity: f32,
    /// The map it was computed from, as the manifest named it.
    pub source: String,
}

/// How the package was made: enough to rebuild it and to tell two builds apart.
#[derive(Clone, Debug, Default, PartialEq, Serialize, Deserialize)]
#[serde(default)]
pub struct Provenance {
    pub tool: String,
    pub tool_version: String,
    pub inputs: Vec<InputFile>,
    /// Build parameters (depth, budgets, codecs, ...), by name.
    pub parameters: BTreeMap<String, serde_json::Value>,
}

/// One input of a build.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub struct InputFile {
    pub path: String,
    pub bytes: u64,
    /// XXH3-64 of the file, hex.
    pub xxh3: String,
}

impl Scene {
    /// The first problem, if any, as a message: a non-finite number (JSON cannot hold NaN, but it
    /// can hold 1e400, which parses to infinity), or a story that does not hold together
    /// ([`crate::story::check`]).
    pub(crate) fn check(&self) -> Result<(), String> {
        self.check_finite()?;
        crate::story::check(&self.pois, &self.tours, &self.camera_names())?;
        crate::lighting::check(&self.lights, &self.circuits)
    }

    /// The names of the scene's cameras (what a tour's stops may name).
    pub fn camera_names(&self) -> Vec<&str> {
        self.cameras.iter().map(|c| c.name.as_str()).collect()
    }

    fn check_finite(&self) -> Result<(), String> {
        let bad = |what: &str, v: &[f64]| {
            if v.iter().all(|x| x.is_finite()) { Ok(()) } else { Err(format!("{what} is not finite: {v:?}")) }
        };
        let widen = |v: &[f32]| v.iter().map(|&x| f64::from(x)).collect::<Vec<_>>();
        for l in &self.lights {
            let name = format!("light '{}'", l.name);
            bad(&name, &widen(&l.color))?;
            bad(&name, &[f64::from(l.power_w)])?;
            match &l.shape {
                LightShape::Point { position_m } => bad(&name, position_m)?,
                LightShape::Spot { position_m, direction, inner_angle_rad, outer_angle_rad } => {
                    bad(&name, position_m)?;
                    bad(&name, &widen(direction))?;
                    bad(&name, &widen(&[*inner_angle_rad, *outer_angle_rad]))?;
                }
                LightShape::Area { center_m, normal, size_m } => {
                    bad(&name, center_m)?;
                    bad(&name, &widen(normal))?;
                    bad(&name, &widen(size_m))?;
                }
            }
        }
        for l in self.lights.iter().filter_map(|l| l.profile.as_ref()) {
            bad("a light profile's aim", &widen(&l.aim))?;
            bad("a light profile's turn", &widen(&[l.turn_deg]))?;
        }
        for c in &self.cameras {
            let name = format!("camera '{}'", c.name);
            bad(&name, &c.eye_m)?;
            bad(&name, &c.look_at_m)?;
            bad(&name, &c.up)?;
            bad(&name, &[c.fov_y_deg])?;
        }
        for m in &self.materials {
            let name = format!("material '{}'", m.name);
            bad(&name, &widen(&[m.specular, m.roughness, m.ior]))?;
            if let Some(r) = &m.region {
                bad(&name, &r.min_m)?;
                bad(&name, &r.max_m)?;
                bad(&name, &widen(&[r.min_normal_z]))?;
            }
        }
        if let Some(e) = &self.environment {
            bad("environment intensity", &[f64::from(e.intensity)])?;
        }
        Ok(())
    }
}
