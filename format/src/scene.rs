//! The two JSON sections: the scene (lights, materials, cameras, environment) and provenance (what
//! built the package from what). They are small, read once, and change shape more often than the
//! binary sections, so they are self-describing JSON rather than fixed records; unknown fields are
//! ignored, which keeps them forward compatible within a major version.
//!
//! World positions are f64 metres in the package's world frame (survey coordinates can be ~5e6 m).

use std::collections::BTreeMap;

use serde::{Deserialize, Serialize};

use crate::profile::LightProfile;
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
        check_lights(&self.lights, &self.circuits)
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

/// Circuits named by lights exist, and each circuit has a light.
pub fn check_lights(lights: &[Light], circuits: &[Circuit]) -> Result<(), String> {
    for l in lights {
        if let Some(c) = &l.circuit
            && !circuits.iter().any(|k| &k.name == c)
        {
            return Err(format!("light {:?} is on circuit {c:?}, which no [[circuit]] defines", l.name));
        }
        if let Some(p) = &l.profile {
            p.profile.check().map_err(|e| format!("light {:?}'s profile: {e}", l.name))?;
        }
    }
    for c in circuits {
        if !lights.iter().any(|l| l.circuit.as_deref() == Some(c.name.as_str())) {
            return Err(format!("circuit {:?} has no lights", c.name));
        }
    }
    Ok(())
}
