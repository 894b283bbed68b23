//! `grotto bench`: the median GPU time of each pass of one configuration over repetitions,
//! with the scene's size and the work the passes did.

use serde::Serialize;

use crate::engine::{Opened, RenderOptions};
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
    let Opened { scene, cameras, residency, .. } = crate::engine::open(opts, &gpu)?.into_whole()?;
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

/// One light update measured by [`bench_light_edits`]: from the change to convergence.
#[derive(Clone, Debug, Serialize)]
pub struct EditRun {
    /// "first light" (from darkness), "add NAME", "remove NAME", "add NAME, relighting all".
    pub what: String,
    /// How the renderer took it: in place with its scope, or anew (light/edit.rs).
    pub relit: Option<crate::stream::Relit>,
    /// Wall milliseconds from the change to convergence (shadow faces, inject, bounces).
    pub ms: f64,
    pub bounces: u32,
    /// Leaves updated by all the bounces, and shadow faces drawn.
    pub leaves_propagated: u64,
    pub faces_drawn: u64,
    /// Tiles each bounce updated.
    pub tiles_per_bounce: Vec<usize>,
    /// The effect plans of the first two light updates after the change (`--explain`).
    pub plans: Vec<String>,
    /// Milliseconds of each pass summed over the updates (GPU timestamps, or CPU wall time to
    /// the end of each pass's own submit where the adapter has none).
    pub pass_ms: std::collections::BTreeMap<String, f64>,
}

/// What one light edit costs against a full relight (`grotto bench --edit-lights FILE`).
#[derive(Clone, Debug, Serialize)]
pub struct EditBench {
    pub package: String,
    pub device: String,
    pub tiles: usize,
    pub leaves: usize,
    pub lights: usize,
    pub runs: Vec<EditRun>,
}

/// Settles the package's light, then for each light of `edits` (a lighting file's `[[light]]`s,
/// in the package's coordinates) adds it, settles, removes it and settles, each in place where
/// it fits, and adds it again relighting every light as edits did before (every shadow face,
/// every leaf, every tile), for comparison. Each update's wall time, bounces, leaves and shadow
/// faces.
pub fn bench_light_edits(opts: &RenderOptions, edits: &std::path::Path) -> Result<EditBench> {
    use web_time::Instant;
    let gpu = Gpu::new(&opts.gpu)?;
    let Opened { mut scene, .. } = crate::engine::open(opts, &gpu)?.into_whole()?;
    // The scene's lighting (a lighting file's, or the package's own lights).
    let base = match scene.lighting.clone() {
        Some(l) => l,
        None => {
            let world = grotto_format::Package::open(&opts.package)?.scene()?;
            crate::scene::lighting::Relight::of_package(&world.lights, &world.circuits)
        }
    };
    let edit_file = crate::engine::lighting_file::relight_of(&grotto_format::Scene::default(), edits)?;
    let mut r = Renderer::new(&gpu, &scene, opts.settings.clone())?;
    let settle = |r: &mut Renderer, t: Instant, what: String, relit: Option<crate::stream::Relit>| {
        // Light updates to convergence, as `settle` runs them, each pass's time summed; the
        // plans of the first two kept.
        let (mut plans, mut pass_ms) = (Vec::new(), std::collections::BTreeMap::new());
        while !r.light_progress().converged {
            let plan = r.update_light()?;
            for step in plan.steps.iter().filter(|s| s.run) {
                let ms = r.stats().last_ms.get(&step.pass).copied().unwrap_or(0.0);
                *pass_ms.entry(step.pass.name().to_string()).or_insert(0.0) += ms;
            }
            if plans.len() < 2 {
                plans.push(plan.explain());
            }
        }
        let bounces = r.stats().bounces_done;
        let ms = t.elapsed().as_secs_f64() * 1e3;
        let work = r.take_bounce_work();
        Ok(EditRun {
            what,
            relit,
            ms,
            bounces,
            leaves_propagated: work.iter().map(|w| w.leaves).sum(),
            faces_drawn: r.take_shadow_faces_drawn(),
            tiles_per_bounce: work.iter().map(|w| w.tiles).collect(),
            plans,
            pass_ms,
        }) as Result<EditRun>
    };
    let mut runs = vec![settle(&mut r, Instant::now(), "first light".into(), None)?];
    // Each lamp added in place, removed in place, then added as every edit was made before
    // edits in place: every light's shadow faces, every leaf injected, every tile bouncing.
    for light in &edit_file.lights {
        for (what, added, whole) in [("add", true, false), ("remove", false, false), ("add", true, true)] {
            let mut lights = base.lights.clone();
            if added {
                lights.push(light.clone());
            }
            scene.relight(&lights, &base.circuits, &base.baked);
            let t = Instant::now();
            let relit = crate::stream::relit(&gpu, &mut r, &mut scene, |_| Ok(()))?;
            let what = format!("{what} {}", light.name);
            runs.push(if whole {
                r.invalidate_lights();
                settle(&mut r, t, format!("{what}, relighting all"), None)?
            } else {
                settle(&mut r, t, what, Some(relit))?
            });
        }
        scene.relight(&base.lights, &base.circuits, &base.baked);
        crate::stream::relit(&gpu, &mut r, &mut scene, |_| Ok(()))?;
        r.settle(|_, _| {})?;
        r.take_bounce_work();
        r.take_shadow_faces_drawn();
    }
    Ok(EditBench {
        package: opts.package.display().to_string(),
        device: gpu.describe(),
        tiles: scene.tiles.len(),
        leaves: scene.leaves.len(),
        lights: scene.lights.len(),
        runs,
    })
}

impl EditBench {
    /// The report as a table, one line a change, with each change's first plans (`explain`).
    pub fn table(&self, explain: bool) -> String {
        use crate::stream::Relit;
        use std::fmt::Write;
        let mut out = format!(
            "{} on {}: {} tiles, {} leaves, {} lights\n",
            self.package, self.device, self.tiles, self.leaves, self.lights
        );
        let _ = writeln!(
            out,
            "  {:18} {:>9} {:>7} {:>12} {:>5}  {:30}  tiles per bounce",
            "change", "ms", "bounces", "leaves", "faces", "in place: lights, tiles, leaves"
        );
        for run in &self.runs {
            let how = match &run.relit {
                Some(Relit::InPlace(e)) => format!(
                    "{}, {} of {}, {}",
                    e.scope.lights, e.scope.tiles, e.scope.of_tiles, e.scope.leaves
                ),
                Some(Relit::Anew { .. }) => "no: a new renderer".into(),
                None => "-".into(),
            };
            let _ = writeln!(
                out,
                "  {:18} {:>9.0} {:>7} {:>12} {:>5}  {how:30}  {:?}",
                run.what, run.ms, run.bounces, run.leaves_propagated, run.faces_drawn, run.tiles_per_bounce
            );
            let passes: Vec<String> = run.pass_ms.iter().map(|(p, ms)| format!("{p} {ms:.0}")).collect();
            let _ = writeln!(out, "    ms by pass: {}", passes.join(", "));
            for (k, plan) in run.plans.iter().enumerate().filter(|_| explain) {
                let _ = writeln!(out, "    plan {} after \"{}\":\n{plan}", k + 1, run.what);
            }
        }
        out
    }
}
