//! Opening a package for rendering: the scene under the budgets (whole where it fits, else every
//! tile at its far level and the first camera's tiles in full), the story and lighting files
//! applied, the cameras resolved (a view framed where the package has none) and a headlamp where
//! the scene has no light, with notes saying what was chosen on the user's behalf.

use std::path::Path;

use glam::{DVec3, Vec3};
use grotto_format::Package;

use crate::engine::lighting_file;
use crate::engine::options::{Headlamp, RenderOptions, clip_in_frame};
use crate::engine::scene::{self, Load, SceneRequest, Story, non_empty};
use crate::error::{Error, Result};
use crate::gpu::{Gpu, default_gpu_memory};
use crate::scene::data::SceneData;
use crate::settings::ClipBox;
use crate::stream::Streaming;
use crate::stream::residency::{Budget, Residency};
use crate::view::camera::{self, Camera};
use crate::view::framing::{CameraChoice, Framing, resolve_camera};

/// The package file opened under the job's budgets with its story and lighting files read
/// ([`scene::open_scene`]: whole where it fits, else far-first; the cameras are resolved on the
/// far scene before [`open`] chooses each tile's level, so a package over budget is never
/// loaded whole).
fn open_scene(opts: &RenderOptions, gpu: &Gpu) -> Result<(SceneData, Option<Streaming>)> {
    let pkg = Package::open(&opts.package)?;
    let world = pkg.scene()?;
    // A story file amends the package's points of interest and tours (`--story`).
    let story = match &opts.story {
        Some(path) => {
            let (pois, tours) = crate::engine::story_file::story_of(&world, Some(path))?;
            Some(Story { pois, tours, cameras: world.cameras.clone() })
        }
        None => None,
    };
    let relight = opts.lights.as_ref().map(|p| lighting_file::relight_of(&world, p)).transpose()?;
    let relight = lighting_file::with_circuits(&world, relight, &opts.circuits)?;
    let request = SceneRequest {
        settings: &opts.settings,
        aspect: opts.width as f32 / opts.height.max(1) as f32,
        budget: Budget {
            gpu_bytes: opts.gpu_memory.unwrap_or_else(|| default_gpu_memory(gpu)),
            points: opts.point_budget.unwrap_or(u64::MAX),
            pools: None,
        },
        relight,
        lamp_string: opts.lamp_string,
        story,
        load: Load::WholeWhereItFits,
    };
    scene::open_scene(pkg, &request)
}

/// What `framing` chose, in world coordinates a user can pass back as options.
fn framing_note(scene: &SceneData, f: &Framing) -> String {
    let frame = DVec3::from_array(scene.frame_origin_m);
    let world = |p: Vec3| (p.as_dvec3() + frame).to_array().map(|v| format!("{v:.3}")).join(",");
    format!(
        "camera: the package has none; framed from {} the data (about {:.0}% of the image \
         sees a surface, median distance {:.2} m): --eye={} --look-at={} --up={}",
        f.kind,
        f.estimate.coverage * 100.0,
        f.estimate.median_distance_m,
        world(f.camera.eye_m),
        world(f.camera.look_at_m),
        [f.camera.up.x, f.camera.up.y, f.camera.up.z].map(|v| format!("{v}")).join(","),
    )
}

/// The scene and cameras a job renders: the package's scene (with `--lamps` applied), the cameras
/// of the choice or path, and a headlamp at the first camera where the options or a lightless
/// scene call for one; with notes saying what was chosen.
pub fn open(opts: &RenderOptions, gpu: &Gpu) -> Result<Opened> {
    let (mut scene, streaming) = open_scene(opts, gpu)?;
    let aspect = opts.width as f32 / opts.height.max(1) as f32;
    let splat = opts.settings.splat_scale;
    let mut notes = Vec::new();
    let mut framed = None;
    let cameras: Vec<Camera> = if let Some(name) = &opts.tour {
        let tour = scene.tours.iter().find(|t| &t.name == name).ok_or_else(|| {
            let names: Vec<&str> = scene.tours.iter().map(|t| t.name.as_str()).collect();
            Error::Camera(format!(
                "no tour named {name:?} in {} (it has: {})",
                scene.name,
                if names.is_empty() { "none".into() } else { names.join(", ") }
            ))
        })?;
        crate::view::story::tour_cameras(tour, opts.tour_fps)
    } else if opts.path.is_empty() {
        let (c, f) = resolve_camera(&scene, &opts.camera, aspect, splat)?;
        notes.extend(f.as_ref().map(|f| framing_note(&scene, f)));
        framed = f;
        vec![c]
    } else if camera::path_file::is_file(&opts.path) {
        // A path recorded by `grotto view` (or written by hand): keyframes in world metres.
        let keys = camera::path_file::read(Path::new(&opts.path[0]), scene.frame_origin_m)?;
        camera::path(&keys, opts.frames.max(1))
    } else {
        let keys = opts
            .path
            .iter()
            .map(|n| resolve_camera(&scene, &CameraChoice::Named(n.clone()), aspect, splat).map(|c| c.0))
            .collect::<Result<Vec<_>>>()?;
        camera::path(&keys, opts.frames.max(1))
    };
    for c in &cameras {
        c.validate()?;
    }
    let clip = opts.clip_world_m.map(|b| clip_in_frame(b, scene.frame_origin_m)).transpose()?;
    // Over budget: the tiles the first camera needs in full, the others stay coarse. The scene
    // stays the far one: the renderer reads the residency's tiles a few at a time
    // (stream::follow::start), or `Opened::into_whole` reads them at once.
    let residency = match &streaming {
        Some(st) => Some(st.choose(&cameras[0], clip)?),
        None => None,
    };
    let want = match opts.headlamp {
        Headlamp::On => true,
        Headlamp::Off => false,
        Headlamp::Auto => !scene.has_own_light(),
    };
    if want {
        // A framed view was estimated already; a given one is estimated here, from the surfels
        // the first camera sees in full (read for that alone, then let go).
        let seen = match (&framed, &streaming, &residency) {
            (Some(f), _, _) => Some(f.estimate),
            (None, Some(st), Some(r)) => {
                let whole = st.load(r, Vec::new(), false)?;
                crate::view::framing::estimate(&whole, &cameras[0], aspect, splat)
            }
            _ => None,
        };
        let own_light = scene.has_own_light();
        let (intensity_w_sr, distance_m) = scene::add_headlamp(&mut scene, &cameras[0], aspect, splat, seen);
        notes.push(format!(
            "light: {}; a headlamp at the camera, {intensity_w_sr:.3} W/sr (1 W/m^2 at {distance_m:.2} m){}",
            if own_light {
                "--headlamp on"
            } else {
                "the scene has no lights, emission or environment map (--headlamp off for none)"
            },
            if cameras.len() > 1 { ", fixed at the path's first camera" } else { "" }
        ));
    }
    if let Some(r) = &residency {
        notes.push(format!(
            "residency: {} of {} tiles in full, {} at their coarse level, {} at their far level; {} of \
             tile data (budget {}: --gpu-memory less the pools' headroom), {} surfels drawn{}",
            r.totals.full_tiles,
            r.decisions.len(),
            r.totals.coarse_tiles,
            r.totals.far_tiles,
            crate::gpu::human_bytes(r.totals.resident_bytes),
            crate::gpu::human_bytes(r.totals.budget.gpu_bytes),
            r.totals.surfels,
            if r.totals.visible_coarse > 0 {
                format!(
                    "; {} tiles in view not held in full (raise --memory, --gpu-memory or --point-budget)",
                    r.totals.visible_coarse
                )
            } else {
                String::new()
            }
        ));
    }
    Ok(Opened { scene, cameras, notes, residency, streaming, clip })
}

impl Opened {
    /// The opened scene with the first residency's tiles read at once, where [`open`] left the
    /// far scene for the renderer to fill a few tiles at a time: for jobs that need the scene's
    /// data whole (pass and light-edit benchmarks).
    pub fn into_whole(mut self) -> Result<Self> {
        if let (Some(st), Some(r)) = (&self.streaming, &self.residency) {
            let mut whole = st.load(r, Vec::new(), false)?;
            whole.take_lights_and_story(&mut self.scene);
            self.scene = whole;
        }
        Ok(self)
    }
}

/// What [`open`] gives a job or a viewer.
#[derive(Debug)]
pub struct Opened {
    pub scene: SceneData,
    pub cameras: Vec<Camera>,
    /// What was chosen on the user's behalf (framing, headlamp, residency).
    pub notes: Vec<String>,
    /// `None` where the whole package fits the budgets.
    pub residency: Option<Residency>,
    /// Where it did not: how to choose again for another camera.
    pub streaming: Option<Streaming>,
    /// `--clip` in the scene's frame.
    pub clip: Option<ClipBox>,
}

/// Opens a package and reads its scene; an empty package is an error (nothing to render).
pub fn load_scene(package: &Path) -> Result<SceneData> {
    non_empty(SceneData::from_package(&Package::open(package)?)?)
}
