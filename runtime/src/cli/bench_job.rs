//! `grotto bench`: the median GPU time of each pass of one configuration over repetitions,
//! with the scene's size and the work the passes did.

use serde::Serialize;

use crate::cli::render_job::{Prepared, RenderOptions, prepare};
use crate::error::Result;
use crate::gpu::{Gpu, GpuOptions};
use crate::render::Renderer;
use crate::settings::Settings;
use crate::stream::residency;

/// Per-pass GPU times of one configuration (`grotto bench`).
#[derive(Clone, Debug, Serialize)]
pub struct PassBench {
    pub package: String,
    pub device: String,
    pub timestamps: bool,
    pub width: u32,
    pub height: u32,
    pub tiles: usize,
    pub leaves: usize,
    pub nodes: usize,
    pub surfels: usize,
    pub max_depth: u32,
    pub lights: usize,
    /// Lights with shadow maps (the rest are lit per leaf by the shadow fallback).
    pub(crate) shadowed_lights: usize,
    /// Lights in range per light-grid cell: mean and largest.
    pub(crate) lights_in_range: (f32, u32),
    /// Median milliseconds per pass over the repetitions (shadow and inject run once per light
    /// change, mip and propagate once per bounce, gbuffer and shade once per frame).
    pub median_ms: std::collections::BTreeMap<String, f64>,
    /// What each pass did in the last repetition: draws and surfels, and shader invocations
    /// where the adapter has pipeline statistics (render/counters.rs).
    pub work: std::collections::BTreeMap<String, crate::render::PassWork>,
    /// Command buffers submitted and bytes written to GPU buffers by one repetition's frame.
    pub submits: u64,
    pub upload_bytes: u64,
    pub(crate) repetitions: u32,
    /// The splat passes pulled their surfels from a storage buffer (else instanced quads).
    pub splats_pulled: bool,
    pub(crate) settings: Settings,
    /// As in [`RenderSummary`].
    pub(crate) residency: Option<residency::ResidencyTotals>,
    pub(crate) tile_bytes: u64,
}

fn median(mut v: Vec<f64>) -> f64 {
    v.sort_by(f64::total_cmp);
    if v.is_empty() { 0.0 } else { v[v.len() / 2] }
}

/// Times every pass `reps` times on the package's first camera (or a default view).
pub fn bench(opts: &RenderOptions, reps: u32) -> Result<PassBench> {
    use crate::light::plan::Pass;
    let gpu = Gpu::new(&GpuOptions { work_counters: true, ..opts.gpu.clone() })?;
    let Prepared { scene, cameras, residency, .. } = prepare(opts, &gpu)?;
    let cam = cameras[0];
    let mut settings = opts.settings.clone();
    settings.exposure = opts.exposure.unwrap_or(1.0);
    settings.still_samples = opts.samples;
    // Every repetition runs a bounce, unless the caller asked for none (`--bounces 0`: light
    // benchmarks that do not need propagation timed again).
    if settings.bounces > 0 {
        settings.bounces = u32::MAX;
    }
    settings.convergence_tolerance = 0.0;
    let mut r = Renderer::new(&gpu, &scene, settings)?;
    let mut samples: std::collections::BTreeMap<Pass, Vec<f64>> = Default::default();
    let reps = reps.max(1);
    for i in 0..reps {
        if i > 0 {
            r.invalidate_lights();
        }
        // Each repetition: shadow + inject + one bounce, then a frame with a fresh G-buffer.
        r.set_forced(&[Pass::Gbuffer]);
        r.render(&cam, opts.width, opts.height)?;
        for (p, ms) in &r.stats().last_ms {
            samples.entry(*p).or_default().push(*ms);
        }
        if opts.samples > 1 {
            // Anti-aliasing at rest: the pixel centres start the sums, the second sample (jittered:
            // a G-buffer and shade of its own, as above) adds to them. The resolve is timed.
            r.draw_still(&cam, opts.width, opts.height)?;
            r.draw_still(&cam, opts.width, opts.height)?;
            if let Some(ms) = r.stats().last_ms.get(&Pass::Resolve) {
                samples.entry(Pass::Resolve).or_default().push(*ms);
            }
        }
    }
    let median_ms = samples.into_iter().map(|(p, v)| (p.name().to_string(), median(v))).collect();
    let stats = r.stats();
    let work = stats.work.iter().map(|(p, w)| (p.name().to_string(), *w)).collect();
    Ok(PassBench {
        package: opts.package.display().to_string(),
        device: gpu.describe(),
        timestamps: gpu.timestamps,
        width: opts.width,
        height: opts.height,
        tiles: scene.tiles.len(),
        leaves: scene.leaves.len(),
        nodes: scene.nodes.len(),
        surfels: scene.surfels.len(),
        max_depth: scene.tiles.iter().map(|t| t.depth).max().unwrap_or(0),
        lights: scene.lights.len(),
        shadowed_lights: r.shadowed_lights(),
        lights_in_range: r.lights_in_range(),
        median_ms,
        work,
        submits: stats.last_submits,
        upload_bytes: stats.last_upload_bytes,
        repetitions: reps,
        splats_pulled: r.splats_pulled(),
        tile_bytes: scene.tile_bytes(r.settings().radiance_f16),
        settings: r.settings().clone(),
        residency: residency.as_ref().map(|r| r.totals),
    })
}
