//! The part of opening a package every shell shares, whatever it reads the package from (a file
//! mapped natively, byte ranges a browser fetched): the scene under the budgets with the lights
//! and story the shell was given, and the headlamp a lightless view gets. [`super::open`] reads
//! its files and its options into a [`SceneRequest`]; the browser's viewer reads viewer.json.

use grotto_format::{Camera as WorldCamera, Package, Poi, Tour};

use crate::error::{Error, Result};
use crate::scene::data::SceneData;
use crate::scene::lighting::Relight;
use crate::settings::Settings;
use crate::stream::Streaming;
use crate::stream::residency::{self, Budget};
use crate::view::camera::Camera;
use crate::view::framing::{ViewEstimate, scene_headlamp};

/// Watts of one lamp of `--lamps` (the synthetic cave's lamp string uses the same).
pub const STRING_LAMP_W: f32 = 8.0;
/// Height of a `--lamps` lamp above its floor, metres.
pub const STRING_LAMP_LIFT_M: f32 = 0.6;

/// Points of interest and tours in place of a package's, as a story file or viewer.json gives
/// them (world coordinates; the scene's frame is applied when the scene is made), with the
/// package's cameras their tours may stop at.
#[derive(Clone, Debug)]
pub struct Story {
    pub pois: Vec<Poi>,
    pub tours: Vec<Tour>,
    pub cameras: Vec<WorldCamera>,
}

/// How much of the package the shell has, and so how its scene is first made.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum Load {
    /// All of it (a file): the whole scene where it fits the budgets, else every tile at its far
    /// level with a [`Streaming`] to choose the rest.
    WholeWhereItFits,
    /// Its head, directory and far levels only (a browser fetches the rest when a view needs
    /// it): every tile at its far level, always with a [`Streaming`].
    FarFirst,
}

/// What a shell opens a package's scene with.
#[derive(Clone, Debug)]
pub struct SceneRequest<'a> {
    pub settings: &'a Settings,
    /// Width over height of the image: residency's screen-space detail follows it.
    pub aspect: f32,
    pub budget: Budget,
    /// A lighting file's lights and circuits (or viewer.json's), in place of the package's.
    pub relight: Option<Relight>,
    /// `--lamps N`: a string of N lamps along the passage in place of whatever is lit (a
    /// measurement's stand-in).
    pub lamp_string: Option<u32>,
    /// Points of interest and tours in place of the package's (a story file's merged with them,
    /// or viewer.json's), already checked against the package's cameras.
    pub story: Option<Story>,
    pub load: Load,
}

/// The package's scene as `req` asks: its lights replaced (the lighting, then the lamp string),
/// its story replaced, held whole or far-first (see [`Load`]). An empty package is an error
/// naming it (nothing to render).
pub fn open_scene(pkg: Package, req: &SceneRequest<'_>) -> Result<(SceneData, Option<Streaming>)> {
    let with_story = |mut scene: SceneData| {
        if let Some(s) = &req.story {
            (scene.pois, scene.tours) =
                crate::scene::story::in_frame(scene.frame_origin_m, &s.pois, &s.tours, &s.cameras);
        }
        scene
    };
    // The lighting first; a lamp string replaces whatever is lit.
    let lights = |s: &mut SceneData| {
        if let Some(r) = &req.relight {
            r.apply(s);
        }
        if let Some(n) = req.lamp_string {
            s.lights = s.lamp_string(n as usize, STRING_LAMP_W, STRING_LAMP_LIFT_M);
        }
    };
    let tiles = residency::footprints(&pkg, req.settings.radiance_f16)?;
    if req.load == Load::WholeWhereItFits {
        let full_bytes: u64 = tiles.iter().map(|t| t.full.bytes).sum();
        let full_surfels: u64 = tiles.iter().map(|t| t.full.surfels).sum();
        if full_bytes <= req.budget.gpu_bytes && full_surfels <= req.budget.points {
            let mut scene = with_story(non_empty(SceneData::from_package(&pkg)?)?);
            lights(&mut scene);
            return Ok((scene, None));
        }
    }
    let (far, streaming) = Streaming::far_first(pkg, tiles, req.budget, req.aspect, req.settings, lights)?;
    Ok((with_story(non_empty(far)?), Some(streaming)))
}

/// A scene with no voxels is an error (nothing to render).
pub(super) fn non_empty(scene: SceneData) -> Result<SceneData> {
    if scene.leaves.is_empty() {
        return Err(Error::Scene {
            package: scene.name.clone(),
            problem: "no voxels to render (empty package)".into(),
        });
    }
    Ok(scene)
}

/// Puts a headlamp at `camera` in `scene`, sized for what it sees (`seen`: the estimate a framed
/// view already made; else made here): 1 W/m^2 at the median distance of the surfaces in view.
/// Returns its intensity (W/sr) and the distance it was sized for (m), which a shell reports.
pub fn add_headlamp(
    scene: &mut SceneData,
    camera: &Camera,
    aspect: f32,
    splat_scale: f32,
    seen: Option<ViewEstimate>,
) -> (f32, f32) {
    let lamp = scene_headlamp(scene, camera, aspect, splat_scale, seen);
    let said = (lamp.light.intensity_w_sr.max_element(), lamp.sized_for_m);
    scene.lights.push(lamp.light);
    scene.headlamp = true;
    said
}
