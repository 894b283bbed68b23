//! `grotto render`: open a package, plan, settle the light (bounces until converged or the budget
//! is spent), then render one image or a camera path, writing PNG or EXR atomically. The binary
//! only parses arguments and draws progress; everything else is here so tests run the same code.

use std::path::{Path, PathBuf};
use web_time::Instant;

use serde::Serialize;

use crate::cli::{image_out, labels};
use crate::engine::{Opened, RenderOptions, time_budget};
use crate::error::{Error, Result};
use crate::gpu::Gpu;
use crate::light::plan::EffectPlan;
use crate::render::{Frame, SceneUpdate};
use crate::render::{PassStats, Renderer};
use crate::scene::data::{SceneData, TileMode};
use crate::settings::{ClipBox, Quality, Settings};
use crate::stream::Streaming;
use crate::stream::follow::Follow;
use crate::stream::residency::Residency;
use crate::view::camera::Camera;

/// Largest `--supersample`: 16 samples a pixel; beyond, the G-buffer of a 1080p frame outgrows
/// what most adapters allow in one texture.
pub const MAX_SUPERSAMPLE: u32 = 4;

/// One frame of a job, for `--json` and the fly-through tables.
#[derive(Clone, Debug, Serialize)]
pub struct FrameReport {
    pub frame: u32,
    /// GPU bytes of tile data held for this frame.
    pub tile_bytes: u64,
    pub full_tiles: usize,
    pub coarse_tiles: usize,
    pub far_tiles: usize,
    /// Tiles that became full (loaded) and coarse (evicted) for this frame.
    pub loaded: usize,
    pub evicted: usize,
    pub surfels: usize,
    /// Bounces run for this frame (after a change of tiles the light is settled again, at most
    /// `--frame-bounces` of them; one per frame until it has converged).
    pub bounces: u32,
    /// Leaves whose light was carried over from the previous frame's tiles (tiles resident in
    /// both, in the same form): only the rest starts from darkness.
    pub carried_leaves: usize,
    /// Tiles and leaves the frame's propagation bounces updated, summed over its bounces: a bounce
    /// updates only the tiles whose light may still change (activity.rs), so after a change of
    /// tiles this follows what changed, not the size of the scene.
    pub(crate) propagated_tiles: usize,
    pub propagated_leaves: u64,
    /// Each of the frame's bounces: which tiles it updated and why (`--explain`).
    pub bounce_work: Vec<crate::light::activity::BounceWork>,
    /// GPU bytes of the renderer's tile pools (allocated once, from `--gpu-memory`; what the
    /// budget bounds). `tile_bytes` is the part the frame's tiles use.
    pub pool_bytes: u64,
    /// How the frame's change of tiles reached the GPU (pool.rs): tiles written, bytes written,
    /// whether the pools were repacked; None where the tiles did not change. A change the pools
    /// could not take in place (a scene whose lights or bounds differ) makes a new renderer and
    /// reports `made_anew`.
    pub update: Option<SceneUpdate>,
    pub made_anew: bool,
    /// Changes of tile form left for later frames by `--upload-per-frame`.
    pub deferred: usize,
    /// Shadow faces drawn for the frame (0 where the shadow pass did not run): after a change of
    /// tiles, only the faces that see a changed tile, of `shadow_faces_total`.
    pub shadow_faces: u64,
    pub shadow_faces_total: usize,
    /// Wall milliseconds of the frame's work before its image is read back: waiting for its tiles,
    /// swapping them in and settling their light, then drawing (which waits for the GPU where the
    /// adapter has timestamps): what a viewer's frame would take.
    pub frame_ms: f64,
    /// Milliseconds this frame waited for the loader thread (which chose and read its tiles while
    /// the previous frame rendered).
    pub(crate) load_wait_ms: f64,
    /// Milliseconds of each pass that ran for this frame.
    pub(crate) pass_ms: std::collections::BTreeMap<String, f64>,
    /// The points of interest in view and whether their labels were drawn (`--labels`).
    #[serde(skip_serializing_if = "Vec::is_empty")]
    pub labels: Vec<labels::LabelReport>,
}

/// What a render did, for `--json` and the summary line.
#[derive(Clone, Debug, Serialize)]
pub struct RenderSummary {
    pub(crate) package: String,
    pub device: String,
    pub timestamps: bool,
    pub images: Vec<String>,
    pub width: u32,
    pub height: u32,
    pub leaves: usize,
    pub surfels: usize,
    pub tiles: usize,
    pub bounces: u32,
    pub last_change: Option<f32>,
    pub exposure: f32,
    /// Most pixels any frame left uncovered (background showing through: holes, or openings).
    pub uncovered_pixels: usize,
    /// Most pixels any frame showed black (a surface, but no light reaching it).
    pub black_pixels: usize,
    /// Tiles held in full and coarse under the budgets (for the last frame: each tile's mode,
    /// relevance and distance, and the totals); None where the whole package fit.
    pub residency: Option<Residency>,
    /// GPU bytes of the tile data the renderer holds (nodes, leaves, light, pyramid, surfels).
    pub tile_bytes: u64,
    /// Per frame: tile bytes, tiles loaded and evicted, surfels drawn, pass times.
    pub frames: Vec<FrameReport>,
    /// How the camera and light were chosen where the package did not say (framing, headlamp).
    pub notes: Vec<String>,
    /// What looks wrong with the image and why: most of it uncovered, or black.
    pub warnings: Vec<String>,
    /// The memory budget's split (`--memory`), where one was given.
    #[serde(skip_serializing_if = "Option::is_none")]
    pub memory: Option<crate::engine::memory::MemoryPlan>,
    /// Seconds to open the package and load the scene (residency included), before the GPU work.
    pub(crate) load_s: f64,
    pub settle_s: f64,
    pub render_s: f64,
    pub first_plan: EffectPlan,
    pub last_plan: EffectPlan,
    pub stats: PassStats,
    pub(crate) settings: Settings,
    /// What `--time-budget` chose and gave up, where one was given.
    #[serde(skip_serializing_if = "Option::is_none")]
    pub time_budget: Option<time_budget::BudgetChoice>,
}

/// Progress events for the binary's bars.
#[derive(Clone, Copy, Debug)]
pub enum Progress {
    Bounce { done: u32, budget: u32, change: Option<f32> },
    Frame { done: u32, total: u32 },
}

/// Pixels at most this bright (max of sRGB channels, 0..=255) count as black: no light at all,
/// not a dark corner (the demo's entrance passage, dark by design, has 8% of its pixels at <= 1
/// and 52% at <= 4).
const BLACK_LDR: u8 = 1;

/// Warnings for a rendered image: most of it shows no surface, or most of what it shows is black.
pub(crate) fn image_warnings(
    scene: &SceneData,
    uncovered: usize,
    black: usize,
    pixels: usize,
) -> Vec<String> {
    let mut w = Vec::new();
    if uncovered * 2 > pixels {
        w.push(format!(
            "{:.0}% of the image shows no surface: the camera looks past the scan or from too far; \
             leave out --camera/--eye to frame the data, or move the eye",
            100.0 * uncovered as f64 / pixels as f64
        ));
    }
    let covered = pixels - uncovered;
    if covered > 0 && black * 2 > covered {
        let why = if !scene.has_own_light() {
            "the scene has no lights, emission or environment map (add [[light]] to the manifest, or \
             render with --headlamp on)"
        } else {
            "no light reaches what the camera sees (lights out of range, shadowed, or culled by \
             --light-cutoff; or a fixed --exposure too low)"
        };
        w.push(format!(
            "{:.0}% of the surfaces in view are black: {why}",
            100.0 * black as f64 / covered as f64
        ));
    }
    w
}

/// Parses an image size `WIDTHxHEIGHT` (each 1..=16384), for both command lines.
pub fn parse_size(s: &str) -> std::result::Result<(u32, u32), String> {
    let (w, h) = s.split_once(['x', 'X']).ok_or_else(|| format!("expected WIDTHxHEIGHT, got {s:?}"))?;
    let w: u32 = w.parse().map_err(|e| format!("width {w:?}: {e}"))?;
    let h: u32 = h.parse().map_err(|e| format!("height {h:?}: {e}"))?;
    if w == 0 || h == 0 || w > 16384 || h > 16384 {
        return Err(format!("size {w}x{h} is outside 1..=16384"));
    }
    Ok((w, h))
}

/// `out` for frame `i` of `n`: `name_0007.png` when n > 1.
pub(crate) fn frame_path(out: &Path, i: u32, n: u32) -> PathBuf {
    if n <= 1 {
        return out.to_path_buf();
    }
    let stem = out.file_stem().and_then(|s| s.to_str()).unwrap_or("frame");
    let ext = out.extension().and_then(|s| s.to_str()).unwrap_or("png");
    out.with_file_name(format!("{stem}_{i:04}.{ext}"))
}

use crate::render::auto_exposure;

/// A bad `still_samples` is the command line's `--samples`.
fn as_samples(e: Error) -> Error {
    match e {
        Error::Setting { name: "still_samples", problem } => Error::Setting { name: "samples", problem },
        e => e,
    }
}

/// What a job's options can be refused for before any work.
fn check_options(opts: &RenderOptions) -> Result<()> {
    let kind = image_out::kind_of(&opts.out)?;
    if !(1..=MAX_SUPERSAMPLE).contains(&opts.supersample) {
        return Err(Error::Setting {
            name: "supersample",
            problem: format!("{} is outside 1..={MAX_SUPERSAMPLE}", opts.supersample),
        });
    }
    if let Some(b) = opts.time_budget_s {
        time_budget::check_budget(b)?;
    }
    if opts.labels && kind == image_out::ImageKind::Exr {
        return Err(Error::Setting {
            name: "labels",
            problem: "labels are drawn into .png and .jpg images; an .exr keeps the radiance as rendered"
                .into(),
        });
    }
    Ok(())
}

/// Runs a render job.
pub fn run(opts: &RenderOptions, mut progress: impl FnMut(Progress)) -> Result<RenderSummary> {
    check_options(opts)?;
    let (w_px, h_px) = (opts.width * opts.supersample, opts.height * opts.supersample);
    let gpu = Gpu::new(&opts.gpu)?;
    let t_load = Instant::now();
    let Opened { mut scene, cameras, notes, residency, streaming, clip } = crate::engine::open(opts, &gpu)?;
    let load_s = t_load.elapsed().as_secs_f64();
    let mut settings = opts.settings.clone();
    settings.exposure = opts.exposure.unwrap_or(1.0);
    settings.still_samples = opts.samples;
    settings.validate().map_err(as_samples)?;
    let first_cam = (&cameras[0], w_px, h_px);
    let Started { mut r, mut follow, first_plan, budget_choice } =
        start(opts, &gpu, &mut scene, &mut settings, (streaming, residency, clip), first_cam, &mut progress)?;
    let t0 = Instant::now();
    // The GPU holds the tiles now; a change of tiles brings a scene loaded anew.
    scene.release_tile_data();
    let budget = r.settings().bounces;
    r.settle(|done, change| progress(Progress::Bounce { done, budget, change }))?;
    // The probe of a time budget was the light's first update.
    let settle_s = t0.elapsed().as_secs_f64() + budget_choice.as_ref().map_or(0.0, |c| c.probe_s);
    let t1 = Instant::now();
    let mut images = Vec::new();
    let mut exposure = settings.exposure;
    let mut last_plan = first_plan.clone();
    let n = cameras.len() as u32;
    let mut uncovered_pixels = 0;
    let mut black_pixels = 0;
    let mut frames = Vec::new();
    // The next frame's tiles are chosen and read on a loader thread while this frame renders.
    for (i, cam) in cameras.iter().enumerate() {
        let t_frame = Instant::now();
        let mut change = TileChange::default();
        if i == 0 {
            change.bounces = r.stats().bounces_done;
        } else if let Some(f) = &mut follow {
            change =
                follow_tiles(f, &gpu, &mut r, &mut scene, (cam, clip), opts.frame_bounces, &mut progress)?;
        }
        if let (Some(f), Some(next_cam)) = (&mut follow, cameras.get(i + 1)) {
            f.request(next_cam, clip, (scene.lights.clone(), scene.headlamp), scene.held_tiles());
        }
        let current = follow.as_ref().map(|f| f.current());
        let before_render = r.stats().bounces_done;
        let plan = r.draw(cam, w_px, h_px)?;
        let frame_ms = t_frame.elapsed().as_secs_f64() * 1e3;
        let mut frame = r.read_frame()?;
        // A progressive bounce run by the frame itself.
        change.bounces += r.stats().bounces_done - before_render;
        last_plan = plan;
        // Views without light are not exposed.
        if opts.exposure.is_none() && i == 0 && settings.view.exposed() {
            exposure = expose_from(&mut r, &mut frame, opts.samples)?;
        }
        // The still frame draws its own first sample, at the exposure just set.
        if opts.samples > 1 {
            (frame, last_plan) = r.render_still(cam, w_px, h_px)?;
        }
        let pois = if opts.labels { &scene.pois[..] } else { &[] };
        let labels = labels::find(&gpu, &r, pois, cam, (w_px, h_px), opts.supersample)?;
        if opts.supersample > 1 {
            frame = frame.downsampled(opts.supersample);
        }
        let (uncovered, black) = uncovered_and_black(&frame);
        uncovered_pixels = uncovered_pixels.max(uncovered);
        black_pixels = black_pixels.max(black);
        labels::draw(&mut frame, &labels, settings.view == crate::settings::ViewMode::Lux);
        frames.push(FrameReport {
            labels,
            ..frame_report(i as u32, &scene, current, change, frame_ms, &mut r)
        });
        let path = frame_path(&opts.out, i as u32, n);
        image_out::write_frame(&frame, &path)?;
        images.push(path.display().to_string());
        progress(Progress::Frame { done: i as u32 + 1, total: n });
    }
    Ok(RenderSummary {
        package: opts.package.display().to_string(),
        device: gpu.describe(),
        timestamps: gpu.timestamps,
        images,
        width: opts.width,
        height: opts.height,
        leaves: scene.counts().leaves,
        surfels: scene.counts().surfels,
        tiles: scene.tiles.len(),
        bounces: r.stats().bounces_done,
        last_change: r.stats().last_change,
        exposure,
        uncovered_pixels,
        black_pixels,
        tile_bytes: scene.tile_bytes(settings.radiance_f16),
        frames,
        warnings: image_warnings(
            &scene,
            // A clip box shows the background where it cuts: that is no sign of a lost camera.
            if clip.is_some() { 0 } else { uncovered_pixels },
            black_pixels,
            opts.width as usize * opts.height as usize,
        )
        .into_iter()
        .chain(follow.as_mut().map(|f| f.take_notices()).unwrap_or_default())
        .chain(budget_choice.as_ref().filter(|c| c.too_small).map(time_budget::BudgetChoice::describe))
        .collect(),
        residency: follow.map(|f| f.current().clone()),
        notes: notes
            .into_iter()
            .chain(budget_choice.as_ref().filter(|c| !c.too_small).map(time_budget::BudgetChoice::describe))
            .collect(),
        memory: opts.memory,
        load_s,
        settle_s,
        render_s: t1.elapsed().as_secs_f64(),
        first_plan,
        last_plan,
        stats: r.stats().clone(),
        settings: r.settings().clone(),
        time_budget: budget_choice,
    })
}

/// The renderer a job starts with, its tiles following the camera where the package is over
/// budget, and what `--time-budget` chose.
struct Started {
    r: Renderer,
    follow: Option<Follow>,
    first_plan: EffectPlan,
    budget_choice: Option<time_budget::BudgetChoice>,
}

/// Makes the job's renderer for `settings`. With a time budget, the light is first probed at the
/// fast preset and a preset chosen from it: where that is another, the renderer is made anew for
/// it (`settings` become its), else the probe's goes on with its bounces cut to what fits.
fn start(
    opts: &RenderOptions,
    gpu: &Gpu,
    scene: &mut SceneData,
    settings: &mut Settings,
    (streaming, residency, clip): (Option<Streaming>, Option<Residency>, Option<ClipBox>),
    first_cam: (&Camera, u32, u32),
    progress: &mut impl FnMut(Progress),
) -> Result<Started> {
    let shadow_cap = opts.memory.map(|m| m.shadow_map_size);
    if opts.time_budget_s.is_some() {
        *settings = time_budget::rung_settings(settings, Quality::Fast, shadow_cap);
    }
    let (mut r, follow) = crate::stream::follow::start(
        gpu,
        scene,
        settings.clone(),
        streaming,
        residency,
        opts.loader_steps(),
    )?;
    r.set_clip(clip);
    let mut first_plan = r.plan(Some(first_cam));
    let Some(budget_s) = opts.time_budget_s else {
        return Ok(Started { r, follow, first_plan, budget_choice: None });
    };
    let budget = settings.bounces;
    let probe = time_budget::Probe::run(gpu, &mut r, |done, change| {
        progress(Progress::Bounce { done, budget, change })
    })?;
    let choice = time_budget::choose(budget_s, &probe);
    if choice.made_anew {
        *settings = time_budget::rung_settings(settings, choice.chosen, shadow_cap);
        r = remake(gpu, r, scene, follow.as_ref(), settings.clone())?;
        first_plan = r.plan(Some(first_cam));
    } else {
        r.set_bounces(choice.bounces);
    }
    Ok(Started { r, follow, first_plan, budget_choice: Some(choice) })
}

/// A renderer with `settings` for the scene `old` renders, made after `old` has let go of its
/// GPU memory: its pools sized as `old`'s were, its clip box kept, its light from dark. Where tiles
/// follow the camera, the scene gets its tile data again for it (`Follow::reload_into`).
fn remake(
    gpu: &Gpu,
    old: Renderer,
    scene: &mut SceneData,
    follow: Option<&Follow>,
    settings: Settings,
) -> Result<Renderer> {
    let (caps, clip) = (old.pool_caps(), old.clip());
    drop(old);
    let mut r = match follow {
        Some(f) => {
            f.reload_into(scene)?;
            Renderer::with_pools(gpu, scene, settings, caps)?
        }
        None => Renderer::new(gpu, scene, settings)?,
    };
    r.set_clip(clip);
    Ok(r)
}

/// Auto exposure from `frame`, the first, kept for the sequence so it does not flicker; a frame of
/// one sample is exposed again at once (a still frame draws its own first sample).
fn expose_from(r: &mut Renderer, frame: &mut Frame, samples: u32) -> Result<f32> {
    let exposure = auto_exposure(&frame.hdr);
    r.set_exposure(exposure);
    if samples == 1 {
        *frame = r.expose()?;
    }
    Ok(exposure)
}

/// What the tiles' loader brought before a frame, and what the renderer did with it.
#[derive(Debug, Default)]
struct TileChange {
    loaded: usize,
    evicted: usize,
    bounces: u32,
    carried_leaves: usize,
    load_wait_ms: f64,
    update: Option<SceneUpdate>,
    made_anew: bool,
    deferred: usize,
}

/// Waits for the residency the loader thread was asked for; where its tiles differ, the new scene
/// replaces the old one in the renderer's pools (only the new tile forms are written; the others
/// keep their place and light), and its light is settled again from there. A change larger than
/// a loader step arrives in steps ([`crate::stream::follow::Arrived::rest`]): the rest is asked
/// for again for the same view (`view`) and written before the light is settled, so the frame
/// has every tile its view wants while the CPU holds one step's tiles at a time.
fn follow_tiles(
    f: &mut Follow,
    gpu: &Gpu,
    r: &mut Renderer,
    scene: &mut SceneData,
    view: (&Camera, Option<ClipBox>),
    frame_bounces: Option<u32>,
    progress: &mut impl FnMut(Progress),
) -> Result<TileChange> {
    let full = |r: &Residency| -> std::collections::BTreeSet<usize> {
        r.decisions.iter().filter(|d| d.mode == TileMode::Full).map(|d| d.tile).collect()
    };
    let mut change = TileChange::default();
    let t_wait = Instant::now();
    let Some(mut arrived) = f.wait()? else { return Ok(change) };
    change.load_wait_ms = t_wait.elapsed().as_secs_f64() * 1e3;
    change.deferred = arrived.deferred;
    let before = full(f.current());
    let mut swapped_any = false;
    loop {
        if let Some(new_scene) = arrived.scene.take() {
            let swapped = crate::stream::swap_tiles(gpu, r, scene, (new_scene, f.package()), || {
                f.load_whole(&arrived.residency)
            })?;
            scene.release_tile_data();
            if !swapped_any {
                change.carried_leaves = swapped.carried_leaves;
            }
            change.update = match (change.update.take(), swapped.update) {
                (Some(a), Some(b)) => Some(a.then(b)),
                (a, b) => b.or(a),
            };
            change.made_anew |= swapped.made_anew;
            swapped_any = true;
        }
        let rest = arrived.rest;
        f.accept(arrived.residency);
        if rest == 0 {
            break;
        }
        f.request(view.0, view.1, (scene.lights.clone(), scene.headlamp), scene.held_tiles());
        arrived = f.wait()?.ok_or(Error::Internal {
            what: "tile loader",
            message: "a step asked for did not come".into(),
        })?;
    }
    let after = full(f.current());
    change.loaded = after.difference(&before).count();
    change.evicted = before.difference(&after).count();
    if swapped_any {
        let budget = r.settings().bounces;
        let report = |done, change| progress(Progress::Bounce { done, budget, change });
        change.bounces = match frame_bounces {
            Some(n) => r.settle_at_most(n, report)?,
            None => r.settle(report)?,
        };
    }
    Ok(change)
}

/// Pixels no surfel covers, and covered pixels tonemapped to black.
fn uncovered_and_black(frame: &Frame) -> (usize, usize) {
    let uncovered = frame.hdr.iter().filter(|p| p[3] < 0.5).count();
    let black = frame
        .hdr
        .iter()
        .zip(&frame.ldr)
        .filter(|(h, l)| h[3] >= 0.5 && l[0].max(l[1]).max(l[2]) <= BLACK_LDR)
        .count();
    (uncovered, black)
}

/// What a frame of a path did: the tiles held and loaded, the bounces run, what was uploaded and
/// drawn, and its passes' times.
fn frame_report(
    frame: u32,
    scene: &SceneData,
    current: Option<&Residency>,
    change: TileChange,
    frame_ms: f64,
    r: &mut Renderer,
) -> FrameReport {
    let bounce_work = r.take_bounce_work();
    FrameReport {
        frame,
        tile_bytes: scene.tile_bytes(r.settings().radiance_f16),
        full_tiles: current.map_or(scene.tiles.len(), |r| r.totals.full_tiles),
        coarse_tiles: current.map_or(0, |r| r.totals.coarse_tiles),
        far_tiles: current.map_or(0, |r| r.totals.far_tiles),
        loaded: change.loaded,
        evicted: change.evicted,
        surfels: scene.counts().surfels,
        bounces: change.bounces,
        carried_leaves: change.carried_leaves,
        propagated_tiles: bounce_work.iter().map(|w| w.tiles).sum(),
        propagated_leaves: bounce_work.iter().map(|w| w.leaves).sum(),
        bounce_work,
        pool_bytes: r.pool_bytes(),
        update: change.update,
        made_anew: change.made_anew,
        deferred: change.deferred,
        shadow_faces: r.take_shadow_faces_drawn(),
        shadow_faces_total: r.shadow_face_count(),
        frame_ms,
        load_wait_ms: change.load_wait_ms,
        pass_ms: r.stats().last_ms.iter().map(|(p, ms)| (p.name().to_string(), *ms)).collect(),
        labels: Vec::new(),
    }
}
