//! `grotto view`: a package in a window.

use std::path::PathBuf;
use std::process::ExitCode;

use crate::render::{RenderArgs, options};

#[derive(clap::Args, Debug)]
pub(crate) struct ViewArgs {
    #[command(flatten)]
    pub(crate) render: RenderArgs,
    /// Draw at the window's size times this (software adapters are slow per pixel).
    #[arg(long, default_value_t = 0.5)]
    pub(crate) render_scale: f32,
    /// Where P writes its screenshot (default grotto-view-N.png). With --after-frames the viewer
    /// writes it by itself and exits.
    #[arg(long)]
    pub(crate) screenshot: Option<PathBuf>,
    /// Write the screenshot after this many frames, once the camera rests and the light has
    /// converged (so it matches grotto render of the same camera), and exit (scripts, tests).
    #[arg(long)]
    pub(crate) after_frames: Option<u32>,
    /// Record a camera path from the start and write it here on exit (K starts and stops a
    /// recording by hand); grotto render --path FILE.toml flies along it.
    #[arg(long)]
    pub(crate) record_path: Option<PathBuf>,
    /// Milliseconds a frame at rest may take: the light gets the bounces that fit beside the
    /// frame (while the camera moves, bounces wait).
    #[arg(long, default_value_t = 33.0)]
    pub(crate) frame_budget_ms: f64,
    /// Frames a second to hold while the camera moves, by drawing at a smaller render scale and
    /// then thinning far surfels harder (the panel shows what was traded; at rest the frame is
    /// drawn in full). 0: no target, moving frames draw at --render-scale whatever they cost.
    #[arg(long, default_value_t = 60.0)]
    pub(crate) target_fps: f64,
    /// Start with the panel hidden (H toggles it).
    #[arg(long)]
    pub(crate) no_panel: bool,
}

/// The viewer's shadow budget unless `--shadow-ms` says otherwise: half a 60 fps frame.
const VIEW_SHADOW_MS: f32 = 8.0;

pub(crate) fn view(v: ViewArgs) -> anyhow::Result<ExitCode> {
    anyhow::ensure!(
        v.render.supersample == 1,
        "--supersample is for grotto render (the viewer draws at --render-scale)"
    );
    anyhow::ensure!(
        v.render.time_budget.is_none(),
        "--time-budget is for grotto render's picture; the viewer converges its light over frames (--quality)"
    );
    let mut render = options(&v.render)?;
    // A scan's default budget is render's: the viewer starts at its preset and converges over frames.
    render.time_budget_s = None;
    if let Some(m) = &render.memory {
        eprintln!("{}", m.describe());
    }
    render.settings.still_samples =
        v.render.samples.unwrap_or(grotto_runtime::passes::resolve::DEFAULT_STILL_SAMPLES);
    render.settings.validate()?;
    render.settings.shadow_frame_ms = v.render.shadow_ms.unwrap_or(VIEW_SHADOW_MS);
    // A designer adds lamps in lighting mode: room for one more point light's faces.
    render.settings.light_room_faces = 6;
    let a = &v.render;
    // The panel names the preset only where no knob changed it.
    let knobs_set = crate::render::march_knobs_set(a);
    let quality = grotto_runtime::settings::Quality::parse(a.quality.as_deref().unwrap_or("balanced"))
        .filter(|_| !knobs_set);
    let summary = grotto_runtime::window::run(grotto_runtime::window::ViewOptions {
        render,
        quality,
        render_scale: v.render_scale,
        screenshot: v.screenshot,
        after_frames: v.after_frames,
        record_path: v.record_path,
        frame_budget_ms: v.frame_budget_ms,
        frame_target_ms: (v.target_fps.is_finite() && v.target_fps > 0.0).then(|| 1000.0 / v.target_fps),
        panel: !v.no_panel,
        after_swap: Some(crate::trim_heap),
    })?;
    // --json: frames, frame times moving and at rest, frames the light took to converge.
    if v.render.json {
        println!("{}", serde_json::to_string_pretty(&summary)?);
        return Ok(ExitCode::SUCCESS);
    }
    let log = &summary.log;
    let ms = |v: &[f64]| {
        grotto_runtime::window::FrameLog::percentiles(v)
            .map_or("none".to_string(), |(m, p)| format!("median {m:.1} ms, p95 {p:.1} ms"))
    };
    println!(
        "{} frames in {:.1} s on {}; moving: {} frames, {}; at rest: {} frames, {}; light converged \
         {} times, after {:?} frames ({:.1?} s){}{}",
        summary.frames,
        summary.seconds,
        summary.device,
        log.moving_ms.len(),
        ms(&log.moving_ms),
        log.rest_ms.len(),
        ms(&log.rest_ms),
        log.converge_frames.len(),
        log.converge_frames,
        log.converge_s,
        if summary.screenshots.is_empty() {
            String::new()
        } else {
            format!("; wrote {}", summary.screenshots.join(", "))
        },
        summary.paths.iter().map(|(p, n)| format!("; camera path {p} ({n} keys)")).collect::<String>(),
    );
    Ok(ExitCode::SUCCESS)
}
