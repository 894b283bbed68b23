//! What a job or a viewer opens a package with ([`RenderOptions`]): the package, the camera or
//! path, the story and lighting files, the budgets, the quality settings and the image asked for.

use std::path::PathBuf;

use glam::DVec3;
use serde::Serialize;

use crate::error::{Error, Result};
use crate::gpu::GpuOptions;
use crate::settings::{ClipBox, Settings};
use crate::view::framing::CameraChoice;

/// Whether to light the view with a headlamp at the camera.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Serialize)]
#[serde(rename_all = "snake_case")]
pub enum Headlamp {
    /// Only when the scene has no light of its own (no lights, emission or environment map).
    Auto,
    On,
    Off,
}

impl Headlamp {
    /// The headlamp setting `--headlamp` names, if it names one.
    pub fn parse(s: &str) -> Option<Self> {
        match s {
            "auto" => Some(Headlamp::Auto),
            "on" => Some(Headlamp::On),
            "off" => Some(Headlamp::Off),
            _ => None,
        }
    }
}

/// Everything `grotto render` can be asked.
#[derive(Clone, Debug)]
pub struct RenderOptions {
    pub package: PathBuf,
    pub camera: CameraChoice,
    /// Named cameras to fly through; with `frames`, renders a sequence.
    pub path: Vec<String>,
    /// A tour of the package (`--tour NAME`): an image a stop, or with `tour_fps` the tour as a
    /// film (view/story.rs [`crate::view::story::tour_cameras`]).
    pub tour: Option<String>,
    pub tour_fps: Option<f32>,
    /// Points of interest and tours added to the package's (`--story FILE`, engine/story_file.rs).
    pub story: Option<PathBuf>,
    /// A lighting file changing the package's lights (`--lights FILE`, engine/lighting_file.rs).
    pub lights: Option<PathBuf>,
    /// Circuits switched on or off (`--circuits NAME=on|off`), the lighting file's or the
    /// package's.
    pub circuits: Vec<(String, bool)>,
    pub frames: u32,
    pub width: u32,
    pub height: u32,
    pub out: PathBuf,
    pub settings: Settings,
    /// `None`: automatic exposure (mean log luminance to middle grey).
    pub exposure: Option<f32>,
    pub gpu: GpuOptions,
    /// Replace the package's lights by a lamp string of this many 8 W lamps
    /// ([`SceneData::lamp_string`]): how cost and error grow with the number of lights.
    pub lamp_string: Option<u32>,
    /// A headlamp at the (first) camera ([`crate::view::framing::headlamp`]).
    pub headlamp: Headlamp,
    /// GPU bytes for tiles (`--gpu-memory`); `None`: [`default_gpu_memory`].
    pub gpu_memory: Option<u64>,
    /// Most surfels drawn (`--point-budget`); `None`: no limit.
    pub point_budget: Option<u64>,
    /// The memory budget's split (`--memory`, engine/memory.rs), where one was given: the pools,
    /// surfels and shadow maps above follow from it unless given as well. Reported, not applied.
    pub memory: Option<crate::engine::memory::MemoryPlan>,
    /// Along a path, most bounces run before a frame whose tiles changed (`--frame-bounces`);
    /// the rest runs one bounce per frame, so light converges over frames. `None`: settle.
    pub frame_bounces: Option<u32>,
    /// Along a path, most tile bytes uploaded before a frame (`--upload-per-frame`,
    /// [`residency::limit_uploads`]); `None`: no limit.
    pub upload_per_frame: Option<u64>,
    /// Cut the view to this box, world metres `[min, max]` (`--clip`): see [`ClipBox`].
    pub clip_world_m: Option<[[f64; 3]; 2]>,
    /// Render at this many times the width and height and average each block (`--supersample`,
    /// 1..=4): anti-aliased edges and silhouettes at its square in G-buffer and shade work.
    pub supersample: u32,
    /// Samples a pixel, each jittered within it, averaged (`--samples`, anti-aliasing as the
    /// viewers do at rest: passes/resolve.rs): anti-aliased at that many frames' G-buffer and
    /// shade work, no more memory. 1: the pixel centres.
    pub samples: u32,
    /// Draw the labels of the points of interest in view into the image (`--labels`, as the
    /// page shows them; cli/labels.rs). PNG and JPEG only.
    pub labels: bool,
    /// Seconds the first picture's light may take (`--time-budget`, engine/time_budget.rs): the
    /// most accurate preset that fits on this device, over the preset in `settings`.
    pub time_budget_s: Option<f64>,
}

/// A box in world metres `[min, max]` in a scene's frame; an error where it is empty or not
/// finite.
pub fn clip_in_frame(world_m: [[f64; 3]; 2], frame_origin_m: [f64; 3]) -> Result<ClipBox> {
    let [lo, hi] = world_m;
    if !lo.iter().chain(&hi).all(|v| v.is_finite()) || (0..3).any(|a| lo[a] > hi[a]) {
        return Err(Error::Setting {
            name: "clip",
            problem: format!(
                "the box {lo:?} .. {hi:?} is empty or not finite: give min x,y,z then max x,y,z"
            ),
        });
    }
    let frame = DVec3::from_array(frame_origin_m);
    Ok(ClipBox {
        min_m: (DVec3::from_array(lo) - frame).as_vec3(),
        max_m: (DVec3::from_array(hi) - frame).as_vec3(),
    })
}

impl RenderOptions {
    /// `--upload-per-frame`, and the tile bytes a loader step reads at most: the memory budget's
    /// (`MemoryPlan::step_bytes`), else 64 MiB (`stream::follow::STEP_BYTES`).
    pub(crate) fn loader_steps(&self) -> (Option<u64>, u64) {
        let step = self.memory.as_ref().map_or(crate::stream::follow::STEP_BYTES, |m| m.step_bytes);
        (self.upload_per_frame, step)
    }

    /// `grotto render PACKAGE -o OUT` with every other option at its command-line default: the
    /// package's first camera or a framed view, 800x600, the balanced preset, automatic exposure
    /// and headlamp, the best adapter.
    pub fn defaults(package: PathBuf, out: PathBuf) -> Self {
        RenderOptions {
            package,
            camera: CameraChoice::Default,
            path: Vec::new(),
            tour: None,
            tour_fps: None,
            story: None,
            lights: None,
            circuits: Vec::new(),
            frames: 30,
            width: 800,
            height: 600,
            out,
            settings: Settings::preset(crate::settings::Quality::Balanced),
            exposure: None,
            gpu: GpuOptions::default(),
            lamp_string: None,
            headlamp: Headlamp::Auto,
            gpu_memory: None,
            point_budget: None,
            memory: None,
            frame_bounces: None,
            upload_per_frame: None,
            clip_world_m: None,
            supersample: 1,
            samples: 1,
            labels: false,
            time_budget_s: None,
        }
    }
}

#[cfg(test)]
mod tests {
    use glam::Vec3;

    use super::*;

    #[test]
    fn a_clip_box_at_survey_coordinates_reaches_the_frame_exactly_and_an_empty_one_is_refused() {
        let frame = [512_300.0, 5_123_400.0, 300.0];
        let c = clip_in_frame([[512_310.25, 5_123_401.5, 299.0], [512_320.0, 5_123_410.0, 305.125]], frame)
            .unwrap();
        assert_eq!(c.min_m, Vec3::new(10.25, 1.5, -1.0));
        assert_eq!(c.max_m, Vec3::new(20.0, 10.0, 5.125));
        let (inside, above) = (Vec3::new(15.0, 5.0, 0.0), Vec3::new(15.0, 5.0, 6.0));
        assert!(c.meets(inside, inside) && !c.meets(above, above));
        for bad in [[[1.0, 0.0, 0.0], [0.0, 1.0, 1.0]], [[f64::NAN, 0.0, 0.0], [1.0, 1.0, 1.0]]] {
            let e = clip_in_frame(bad, frame).unwrap_err();
            assert!(matches!(e, Error::Setting { name: "clip", .. }), "{e}");
        }
    }
}
