//! A scene's lights as the renderer takes them, from the package's or a lighting file's
//! (grotto_format::lighting): only those whose circuit is on, profiles kept, and a lighting
//! file's area lights made into a grid of point lights with a cosine profile (a package's own
//! area lights glow from its leaves, baked at build time).

use std::sync::Arc;

use glam::{DVec3, Vec3};
use grotto_format::lighting::Lighting;
use grotto_format::{Circuit, Light, LightProfile, LightShape, Profile};

pub use crate::scene::data::Relight;
use crate::scene::data::{SceneData, SceneLight, Spot};

/// Point lights an area light becomes along each side, at most (16 in all).
const AREA_GRID_MAX: usize = 4;
/// About this far apart, metres.
const AREA_GRID_STEP_M: f64 = 0.5;

/// Whether `light` is switched on among `circuits` (a light on no circuit always is).
pub fn switched_on(light: &Light, circuits: &[Circuit]) -> bool {
    light.circuit.as_ref().is_none_or(|c| circuits.iter().any(|k| &k.name == c && k.on))
}

/// The renderer's lights of `lights` in the frame at `frame_origin_m`. Area lights `baked`
/// answers true for are skipped (a package's: their leaves glow already).
pub fn scene_lights(
    lights: &[Light],
    circuits: &[Circuit],
    frame_origin_m: [f64; 3],
    baked: impl Fn(&Light) -> bool,
) -> Vec<SceneLight> {
    let origin = DVec3::from_array(frame_origin_m);
    let to_frame = |p: [f64; 3]| (DVec3::from_array(p) - origin).as_vec3();
    let mut out = Vec::new();
    for l in lights.iter().filter(|l| switched_on(l, circuits)) {
        let color = Vec3::from_array(l.color);
        let profile = l.profile.clone().map(Arc::new);
        // With a profile the power is the flux of the whole distribution; without, the even
        // point light's (a spot keeps it: narrowing a spot does not brighten it).
        let per_sr = match &profile {
            Some(p) => l.power_w / p.profile.integral_sr() as f32,
            None => l.power_w / (4.0 * std::f32::consts::PI),
        };
        match &l.shape {
            LightShape::Point { position_m } => out.push(SceneLight {
                name: l.name.clone(),
                position_m: to_frame(*position_m),
                intensity_w_sr: color * per_sr,
                spot: None,
                profile,
            }),
            LightShape::Spot { position_m, direction, inner_angle_rad, outer_angle_rad } => {
                out.push(SceneLight {
                    name: l.name.clone(),
                    position_m: to_frame(*position_m),
                    intensity_w_sr: color * per_sr,
                    spot: Some(Spot {
                        direction: Vec3::from_array(*direction).normalize_or(Vec3::NEG_Z),
                        inner_angle_rad: *inner_angle_rad,
                        outer_angle_rad: *outer_angle_rad,
                    }),
                    profile,
                })
            }
            LightShape::Area { .. } if baked(l) => {}
            LightShape::Area { center_m, normal, size_m } => {
                area_grid(l, to_frame(*center_m), Vec3::from_array(*normal), *size_m, &mut out)
            }
        }
    }
    out
}

/// An area light as a grid of point lights on its rectangle, each emitting on the normal's side
/// with a cosine (Lambertian) profile and its share of the power; the rectangle's axes as the
/// build's (preprocess build/tile.rs `area_light_samples`).
fn area_grid(l: &Light, center_m: Vec3, normal: Vec3, size_m: [f32; 2], out: &mut Vec<SceneLight>) {
    let n = normal.normalize_or(Vec3::NEG_Z);
    let helper = if n.z.abs() < 0.9 { Vec3::Z } else { Vec3::X };
    let t1 = helper.cross(n).normalize();
    let t2 = n.cross(t1);
    let count = |s: f32| ((f64::from(s) / AREA_GRID_STEP_M).ceil() as usize).clamp(1, AREA_GRID_MAX);
    let (nu, nv) = (count(size_m[0]), count(size_m[1]));
    let cosine = Arc::new(LightProfile {
        aim: n.to_array(),
        turn_deg: 0.0,
        profile: lambertian(),
        source: "area light (cosine)".into(),
    });
    // A cosine lobe integrates to pi sr.
    let per_sr = l.power_w / (nu * nv) as f32 / std::f32::consts::PI;
    for i in 0..nu {
        for j in 0..nv {
            let u = -size_m[0] / 2.0 + (i as f32 + 0.5) * size_m[0] / nu as f32;
            let v = -size_m[1] / 2.0 + (j as f32 + 0.5) * size_m[1] / nv as f32;
            out.push(SceneLight {
                name: format!("{}#{}", l.name, i * nv + j),
                // A hair in front of the rectangle, so the wall it is set in does not shadow it.
                position_m: center_m + t1 * u + t2 * v + n * 0.01,
                intensity_w_sr: Vec3::from_array(l.color) * per_sr,
                spot: None,
                profile: Some(cosine.clone()),
            });
        }
    }
}

/// The cosine lobe of a flat emitter, 0 behind it.
fn lambertian() -> Profile {
    let vertical_deg: Vec<f32> = (0..=36).map(|i| i as f32 * 5.0).collect();
    let relative = vertical_deg.iter().map(|&t| t.to_radians().cos().max(0.0)).collect();
    Profile { vertical_deg, horizontal_deg: vec![0.0], relative }
}

/// The names of the area lights among `lights`.
fn area_names(lights: &[Light]) -> Vec<String> {
    lights.iter().filter(|l| matches!(l.shape, LightShape::Area { .. })).map(|l| l.name.clone()).collect()
}

/// A package's lights and circuits with a lighting file's merged in
/// (grotto_format::lighting::merged), and the names of the package's area lights that still glow
/// from its leaves. A file's light may not take the name of such an area light: its glow is
/// baked into the scan and would stay.
pub fn merged(package: (&[Light], &[Circuit]), file: &Lighting) -> Result<Relight, String> {
    let baked = if file.replace { Vec::new() } else { area_names(package.0) };
    if let Some(name) = file.remove.iter().find(|n| baked.contains(n)) {
        return Err(format!(
            "remove: {name:?} is an area light whose glow is baked into the scan's leaves; set replace = true to \
             turn every baked glow off"
        ));
    }
    if let Some(l) = file.lights.iter().find(|l| baked.contains(&l.name)) {
        return Err(format!(
            "light {:?} would replace the package's area light of that name, whose glow is baked into \
             the scan's leaves: give it another name, or set replace = true",
            l.name
        ));
    }
    let (lights, circuits) = grotto_format::lighting::merged(package, file)?;
    Ok(Relight { lights, circuits, baked })
}

impl Relight {
    /// A package's own lights and circuits, as they are: its area lights glow from the leaves.
    pub fn of_package(lights: &[Light], circuits: &[Circuit]) -> Self {
        Relight { lights: lights.to_vec(), circuits: circuits.to_vec(), baked: area_names(lights) }
    }

    /// Checked whole (a page's viewer.json is not trusted): circuits and profiles hold together.
    pub fn check(&self) -> Result<(), String> {
        grotto_format::check_lights(&self.lights, &self.circuits)
    }

    pub fn apply(&self, scene: &mut SceneData) {
        scene.relight(&self.lights, &self.circuits, &self.baked);
    }
}

impl SceneData {
    /// Lights the scene by `lights` and `circuits` in place of what it had (a package's lights
    /// with a lighting file's, [`merged`]); the area lights named in `baked` glow from the leaves
    /// already, and where there are none (a file that replaces the package's lights) the leaves'
    /// glow goes too.
    pub fn relight(&mut self, lights: &[Light], circuits: &[Circuit], baked: &[String]) {
        self.lights = scene_lights(lights, circuits, self.frame_origin_m, |l| baked.contains(&l.name));
        if baked.is_empty() {
            for leaf in &mut self.leaves {
                leaf.emission = [0.0; 4];
            }
        }
        self.lighting =
            Some(Relight { lights: lights.to_vec(), circuits: circuits.to_vec(), baked: baked.to_vec() });
    }

    /// The scene's circuits (none without a lighting file or a package that has them).
    pub fn circuits(&self) -> &[Circuit] {
        self.lighting.as_ref().map_or(&[], |l| &l.circuits)
    }

    /// Switches circuit `name` on or off: the lights are made again from the lighting (a
    /// headlamp added for a scene without light stays). Returns whether anything changed; an
    /// error names a circuit the scene does not have.
    pub fn switch_circuit(&mut self, name: &str, on: bool) -> Result<bool, String> {
        let Some(lighting) = self.lighting.as_mut() else {
            return Err(format!("no circuit named {name:?}: the scene has no circuits"));
        };
        let known = lighting.circuits.iter().map(|c| c.name.clone()).collect::<Vec<_>>().join(", ");
        let Some(c) = lighting.circuits.iter_mut().find(|c| c.name == name) else {
            return Err(format!("no circuit named {name:?} (the scene has: {known})"));
        };
        if c.on == on {
            return Ok(false);
        }
        c.on = on;
        let lighting = lighting.clone();
        let headlamp = if self.headlamp { self.lights.pop() } else { None };
        self.lights = scene_lights(&lighting.lights, &lighting.circuits, self.frame_origin_m, |l| {
            lighting.baked.contains(&l.name)
        });
        self.lights.extend(headlamp);
        Ok(true)
    }
}
