//! What the page and the viewer say to each other: the options the page passes in (viewer.json's,
//! under the address's query and hash) and the status each frame hands back (the panel, the
//! ready marker, a test's checks).

use grotto_runtime::engine::memory::{DeviceHints, MemoryBudget, MemoryPlan};
use grotto_runtime::scene::data::TileMode;
use grotto_runtime::scene::lighting::Relight;
use grotto_runtime::settings::{Quality, Settings, ViewMode};
use grotto_runtime::view::frame_target::{FrameTarget, Traded};
use serde::{Deserialize, Serialize};

use crate::error::Error;

use grotto_runtime::guide::{LabelStatus, MeasureStatus, TourStatus};

/// What the page asks for (JSON; every field optional): the query string's values, over
/// `viewer.json`'s.
#[derive(Clone, Debug, Default, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct Options {
    /// A camera named in the package (default: its first, else a view framed on the data).
    pub camera: Option<String>,
    /// The rendered image's size (default: the canvas's).
    pub width: Option<u32>,
    pub height: Option<u32>,
    /// fast, balanced, high (as `grotto render --quality`).
    pub quality: Option<String>,
    pub bounces: Option<u32>,
    /// Fixed exposure (default: automatic, from the frame once the light has converged).
    pub exposure: Option<f32>,
    /// Tile budget on the GPU in MB (default: half the largest buffer the adapter allows, at
    /// most 2 GiB, as natively).
    pub gpu_memory_mb: Option<u64>,
    /// The memory budget, the page's and the GPU's together (engine/memory.rs): `phone`,
    /// `laptop`, `desktop` or a size (`768M`). Default: picked from `device`. The tile pools,
    /// surfels drawn, shadow maps, image scale, streaming steps and fetched bytes kept follow
    /// from it; `gpu_memory_mb` and `step_mb` given as well win.
    pub budget: Option<String>,
    /// What the page knows of its device, from which it picks a budget.
    pub device: Option<DeviceHints>,
    /// Most bytes of finer tiles one streaming step uploads (default: a sixteenth of the
    /// budget's share for the page).
    pub step_mb: Option<u64>,
    /// lit, albedo, normals, light, level, scan.
    pub view: Option<String>,
    /// Shadow maps for the brightest lights (default true, as natively).
    pub shadows: Option<bool>,
    /// Draw the convergence bar along the bottom (default true; a screenshot compared with
    /// `grotto render` turns it off).
    pub bar: Option<bool>,
    /// Frames a second to hold while the camera moves, by drawing at a smaller scale and then
    /// thinning far surfels harder (view/frame_target.rs; default 60, 0: none).
    pub target_fps: Option<f64>,
    /// Milliseconds a frame may spend on shadow faces out of date after tiles arrive (default 8;
    /// 0: every face at once): the rest follow over the next frames (render/shadow_queue.rs).
    pub shadow_ms: Option<f32>,
    /// Blend the discs of the front surface at each pixel (default true, as natively; false:
    /// the front-most disc alone).
    pub splat_blend: Option<bool>,
    /// Samples a pixel gathered at rest, one a frame, each jittered within the pixel and
    /// averaged (anti-aliasing; default 8 as natively, 1: none).
    pub samples: Option<u32>,
    /// Longest frame at rest in milliseconds (default 100, as natively): at rest the light gets
    /// what the draw leaves of it, and at least the draw's own time where the draw alone takes
    /// longer. A page that wants the converged light sooner than it wants quick answers while
    /// the light converges (a kiosk's screen, a screenshot, a test on a software adapter)
    /// raises it.
    pub rest_ms: Option<f64>,
    /// The camera to open on as a view link carries it (`x,y,z,heading,pitch,fov`: world
    /// metres and degrees, grotto_runtime::view::story::view_link), over `camera`: what a shared
    /// address restores.
    pub at: Option<String>,
    /// Points of interest and tours (`{"pois": [...], "tours": [...]}`, the package scene's
    /// shape), instead of the package's: what `grotto publish --story` writes to viewer.json.
    pub story: Option<serde_json::Value>,
    /// The lights (`{"lights": [...], "circuits": [...], "baked": [...]}`,
    /// grotto_runtime::scene::lighting::Relight), instead of the package's: what `grotto publish
    /// --lights` writes to viewer.json.
    pub lighting: Option<serde_json::Value>,
}

/// The status of a frame, for the page's panel and the ready marker (JSON).
#[derive(Clone, Debug, Serialize)]
pub struct Status {
    /// "converging", or "ready": the light has converged, the tiles the view wants are resident,
    /// no fetch is under way and the still frame's anti-aliasing samples are all in (what a test
    /// waits for).
    pub state: &'static str,
    pub adapter: String,
    pub package_bytes: u64,
    /// Bytes fetched so far, and before the first frame.
    pub fetched_bytes: u64,
    pub first_frame_bytes: u64,
    pub requests: u32,
    pub fetching: bool,
    /// Tiles full, coarse, far, not held.
    pub tiles: [usize; 4],
    pub bounces_done: u32,
    pub bounce_budget: u32,
    pub light_fraction: f32,
    pub converged: bool,
    pub frames: u32,
    pub camera: String,
    pub view: &'static str,
    pub exposure: f32,
    pub width: u32,
    pub height: u32,
    /// The server sent the whole file to a range request.
    pub no_ranges: bool,
    /// Milliseconds from opening to the first frame, and to "ready".
    pub first_frame_ms: f64,
    pub ready_ms: Option<f64>,
    /// What the effect plan says of propagation.
    pub light_plan: String,
    /// GPU milliseconds of the last plain frame (no shadow maps or injection), and what the
    /// frame-time target trades while moving (None: no target).
    pub frame_ms: Option<f64>,
    pub traded: Option<Traded>,
    /// Points of interest in view (canvas pixels), whether rock hides each, and whether that is
    /// known for this very view (a probe of its G-buffer has arrived).
    pub labels: Vec<LabelStatus>,
    pub labels_current: bool,
    pub measure: MeasureStatus,
    pub tour: Option<TourStatus>,
    /// The camera as a view link (the page's address carries it).
    pub link: String,
    /// GPU memory the renderer holds, and the viewer's own (wasm) memory: what the page states
    /// and a long visit's benchmark samples.
    pub gpu_bytes: u64,
    /// The device's largest storage binding: WebGPU's default (128 MiB) unless the budget's pools
    /// are larger and the adapter offers more.
    pub binding_bytes: u64,
    /// How streaming fares (health.rs): "ok", "retrying", "stopped" or "replaced"; what the
    /// page tells the visitor of it; tiles held back as damaged; failed steps so far.
    pub streaming: &'static str,
    pub notice: Option<String>,
    pub damaged_tiles: usize,
    pub stream_failures: u32,
    pub wasm_bytes: u64,
    /// The memory budget ("phone (512 MiB)"), its bytes in all and the GPU's share of them, and
    /// the fetched package bytes the page holds.
    pub budget: String,
    pub budget_bytes: u64,
    pub budget_gpu_bytes: u64,
    pub held_package_bytes: u64,
}

pub(crate) fn parse_options(json: &str) -> Result<Options, Error> {
    if json.trim().is_empty() {
        return Ok(Options::default());
    }
    serde_json::from_str(json).map_err(|e| Error::Setting(format!("viewer options {json}: {e}")))
}

/// The longest frame at rest (ms): the page's `rest_ms`, else `default_ms`.
pub(crate) fn rest_ms_of(o: &Options, default_ms: f64) -> Result<f64, Error> {
    match o.rest_ms {
        None => Ok(default_ms),
        Some(ms) if ms.is_finite() && ms > 0.0 => Ok(ms),
        Some(ms) => Err(Error::Setting(format!(
            "rest_ms {ms}: the longest frame at rest must be a positive number of milliseconds"
        ))),
    }
}

/// viewer.json's lighting (what `grotto publish --lights` writes: the package's lights and
/// circuits merged with the lighting file), checked; None where it has none.
pub(crate) fn relight_of(o: &Options) -> Result<Option<Relight>, Error> {
    let Some(v) = &o.lighting else { return Ok(None) };
    let r: Relight = serde_json::from_value(v.clone())
        .map_err(|e| Error::Setting(format!("viewer.json lighting: {e}")))?;
    r.check().map_err(|e| Error::Setting(format!("viewer.json lighting: {e}")))?;
    Ok(Some(r))
}

pub(crate) fn settings_of(o: &Options) -> Result<Settings, Error> {
    let quality = match &o.quality {
        Some(p) => Quality::parse(p)
            .ok_or_else(|| Error::Setting(format!("unknown quality {p:?} (fast, balanced, high)")))?,
        None => Quality::Balanced,
    };
    let mut s = Settings::preset(quality);
    if let Some(b) = o.bounces {
        s.bounces = b;
    }
    if let Some(on) = o.shadows {
        s.shadows = on;
    }
    if let Some(v) = &o.view {
        s.view = ViewMode::parse(v).ok_or_else(|| Error::Setting(format!("unknown view {v:?}")))?;
    }
    s.exposure = o.exposure.unwrap_or(1.0);
    s.shadow_frame_ms = o.shadow_ms.unwrap_or(8.0);
    // Circuits switch lights on in place: room for one more point light's faces.
    s.light_room_faces = 6;
    s.splat_blend = o.splat_blend.unwrap_or(true);
    s.still_samples = o.samples.unwrap_or(grotto_runtime::passes::resolve::DEFAULT_STILL_SAMPLES);
    s.validate()?;
    Ok(s)
}

/// The page's memory plan for an image of `pixels`: its `budget`, else the one its device calls
/// for, split under `settings`.
/// The budget's split, applied to `settings`; pools given in the address (`gpu_memory_mb`) win
/// over the budget's, and so also size the storage binding the page asks for.
pub(crate) fn memory_plan(o: &Options, pixels: u64, settings: &mut Settings) -> Result<MemoryPlan, Error> {
    let budget = match &o.budget {
        Some(b) => MemoryBudget::parse(b).map_err(|e| Error::Setting(format!("budget {b:?}: {e}")))?,
        None => MemoryBudget::for_device(&o.device.unwrap_or_default()),
    };
    let mut plan = budget.plan(pixels, settings);
    plan.apply(settings);
    if let Some(mb) = o.gpu_memory_mb {
        plan.pool_bytes = mb << 20;
    }
    Ok(plan)
}

/// The frame-time target while moving: `target_fps` (60 when not given; none when not positive).
pub(crate) fn frame_target_of(o: &Options) -> Option<FrameTarget> {
    match o.target_fps {
        Some(f) if !(f.is_finite() && f > 0.0) => None,
        f => Some(FrameTarget::new(1000.0 / f.unwrap_or(60.0))),
    }
}

/// Tiles full, coarse, far and not held, of a residency's modes (the status's `tiles`).
pub(crate) fn tile_counts(modes: &[TileMode]) -> [usize; 4] {
    let mut tiles = [0usize; 4];
    for m in modes {
        tiles[match m {
            TileMode::Full => 0,
            TileMode::Coarse => 1,
            TileMode::Far => 2,
            TileMode::Skip => 3,
        }] += 1;
    }
    tiles
}
