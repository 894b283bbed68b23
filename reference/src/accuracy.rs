//! The accuracy-vs-time sweep: each scene is rendered once by the reference (with its standard
//! error) and then by the runtime under each quality knob alone and the presets; every run records
//! its error against the reference, its GPU time per pass and its GPU memory. `report` turns the
//! rows into docs/accuracy.md (table, Pareto front, preset check).

use std::collections::BTreeMap;
use std::fmt::Write as _;

use glam::Vec3;
use grotto_runtime::camera::Camera;
use grotto_runtime::gpu::Gpu;
use grotto_runtime::plan::Pass;
use grotto_runtime::renderer::{IndirectFilter, Quality, Renderer, Settings};
use grotto_runtime::scene_data::SceneData;
use grotto_runtime::testscenes;
use serde::Serialize;

use crate::{Estimate, PathSettings, SurfelScene};

/// A scene of the sweep and its reference image.
#[derive(Debug)]
pub struct SweepScene {
    pub name: String,
    pub description: String,
    pub data: SceneData,
    pub camera: Camera,
    pub reference: Vec<Estimate>,
    pub reference_s: f64,
    pub spp: u32,
}

/// One runtime configuration.
#[derive(Clone, Debug, Serialize)]
pub struct Config {
    pub name: String,
    /// Which knob it varies ("preset" for the presets, "baseline").
    pub knob: String,
    pub settings: Settings,
}

/// One measured run.
#[derive(Clone, Debug, Serialize)]
pub struct Row {
    pub scene: String,
    pub config: String,
    pub knob: String,
    /// sqrt(sum |runtime - reference|^2 / sum |reference|^2) over the pixels both see.
    pub rel_rmse: f64,
    /// The reference's own noise on the same scale: sqrt(sum se^2 / sum |reference|^2).
    pub reference_noise: f64,
    /// GPU milliseconds to converge the light (shadow + inject + every bounce) and to draw a
    /// frame (gbuffer + shade).
    pub light_ms: f64,
    pub frame_ms: f64,
    pub bounces: u32,
    pub gpu_bytes: u64,
    pub pass_ms: BTreeMap<String, f64>,
}

/// The built-in scenes: the furnace shell, the colour box, the hidden-chamber dogleg and the
/// synthetic demo cave; `only` keeps the one with that name.
pub fn scenes(width: u32, height: u32, spp: u32, only: Option<&str>) -> Vec<SweepScene> {
    let mut out = Vec::new();
    let mut furnace = testscenes::furnace_sphere(5, 11.0, 0.8, 1.0);
    let c = Vec3::splat(1.6);
    furnace.cameras.push(grotto_runtime::scene_data::SceneCamera {
        name: "inside".into(),
        eye_m: c,
        look_at_m: c + Vec3::new(1.0, 0.3, -0.2),
        up: Vec3::Z,
        fov_y_deg: 70.0,
    });
    let defs: Vec<(&str, &str, SceneData)> = vec![
        ("furnace", "closed shell, emission 1, albedo 0.8 (exact radiance 5 everywhere)", furnace),
        (
            "colour box",
            "closed box, red and green walls, one 30 W lamp: colour bleeding",
            testscenes::colour_box(),
        ),
        (
            "dogleg",
            "rock, a lit room and a chamber behind three right-angle corridors, one 200 W lamp",
            testscenes::dogleg(),
        ),
    ];
    let mut defs: Vec<_> = defs.into_iter().filter(|d| only.is_none_or(|o| o == d.0)).collect();
    match only.is_none_or(|o| o == "demo cave").then(demo_cave).transpose() {
        Ok(None) => {}
        Ok(Some(data)) => defs.push((
            "demo cave",
            "the synthetic demo cave (80k points, 0.25 m leaves, 14 lamps), camera at the entrance: a passage lit mostly indirectly",
            data,
        )),
        Err(e) => eprintln!("demo cave scene skipped: {e}"),
    }
    for (name, description, data) in defs {
        let camera = Camera::from_scene(&data.cameras[0]);
        let scene = SurfelScene::from_scene(&data, Settings::default().splat_scale);
        let t0 = std::time::Instant::now();
        let reference = scene.render(&camera, width, height, spp, &PathSettings::default(), 1);
        let reference_s = t0.elapsed().as_secs_f64();
        out.push(SweepScene {
            name: name.into(),
            description: description.into(),
            data,
            camera,
            reference,
            reference_s,
            spp,
        });
    }
    out
}

/// A small synthetic cave built through the whole pipeline (synth -> package -> scene).
pub fn demo_cave() -> Result<SceneData, String> {
    let dir = tempfile::tempdir().map_err(|e| e.to_string())?;
    let out = grotto_preprocess::synth::small_cave_package(
        dir.path(),
        80_000,
        6,
        grotto_preprocess::build::ColorCodec::Bc1,
        16.0,
    )
    .map_err(|e| e.to_string())?;
    let pkg = grotto_format::Package::open(&out).map_err(|e| e.to_string())?;
    let mut scene = SceneData::from_package(&pkg).map_err(|e| e.to_string())?;
    // The entrance camera first: it looks down a passage the lamps light mostly indirectly.
    scene.cameras.sort_by_key(|c| c.name != "entrance");
    Ok(scene)
}

/// Each knob alone around the balanced preset, and the three presets.
pub fn configs() -> Vec<Config> {
    let base = Settings::preset(Quality::Balanced);
    let mut v = Vec::new();
    let mut add = |knob: &str, name: String, settings: Settings| {
        v.push(Config { name, knob: knob.into(), settings });
    };
    for q in Quality::ALL {
        add("preset", q.name().into(), Settings::preset(q));
    }
    for cones in [4u32, 9, 16] {
        add("cones", format!("cones {cones}"), Settings { cones, ..base.clone() });
    }
    for a in [0.7f32, 1.4] {
        add("aperture", format!("aperture {a}"), Settings { cone_aperture_scale: a, ..base.clone() });
    }
    for s in [0.25f32, 1.0] {
        add("step", format!("step {s}"), Settings { step_scale: s, ..base.clone() });
    }
    for b in [0u32, 1, 2, 8, 16] {
        add("bounces", format!("bounces {b}"), Settings { bounces: b, ..base.clone() });
    }
    add("filter", "tricubic".into(), Settings { indirect: IndirectFilter::Tricubic, ..base.clone() });
    for m in [128u32, 1024] {
        add("shadow map", format!("shadow map {m}"), Settings { shadow_map_size: m, ..base.clone() });
    }
    v
}

fn rel_rmse(got: &[[f32; 4]], reference: &[Estimate]) -> (f64, f64) {
    let (mut num, mut den, mut noise) = (0.0f64, 0.0f64, 0.0f64);
    for (g, r) in got.iter().zip(reference) {
        if g[3] < 0.5 {
            continue;
        }
        for (k, &v) in g[..3].iter().enumerate() {
            let d = f64::from(v - r.mean[k]);
            num += d * d;
            den += f64::from(r.mean[k]).powi(2);
            noise += f64::from(r.std_err[k]).powi(2);
        }
    }
    let den = den.max(1e-30);
    ((num / den).sqrt(), (noise / den).sqrt())
}

/// Runs every config on every scene.
pub fn sweep(
    gpu: &Gpu,
    scenes: &[SweepScene],
    configs: &[Config],
    width: u32,
    height: u32,
    mut progress: impl FnMut(&str, &str),
) -> grotto_runtime::Result<Vec<Row>> {
    let mut rows = Vec::new();
    for s in scenes {
        // Warm-up: the first run on a device compiles pipelines inside the driver; not measured.
        if let Some(c) = configs.first() {
            let mut r = Renderer::new(gpu, &s.data, c.settings.clone())?;
            r.settle(|_, _| {})?;
            r.render(&s.camera, width, height)?;
        }
        for c in configs {
            progress(&s.name, &c.name);
            let mut settings = c.settings.clone();
            settings.exposure = 1.0;
            let mut r = Renderer::new(gpu, &s.data, settings)?;
            let mut light_ms = 0.0;
            let mut pass_ms: BTreeMap<String, f64> = BTreeMap::new();
            // Light until converged or the budget is spent, summing each pass's GPU time.
            loop {
                let plan = r.update_light()?;
                for step in plan.steps.iter().filter(|st| st.run) {
                    let ms = r.stats().last_ms.get(&step.pass).copied().unwrap_or(0.0);
                    light_ms += ms;
                    *pass_ms.entry(step.pass.name().into()).or_default() += ms;
                }
                if !plan.runs(Pass::Propagate) {
                    break;
                }
            }
            let (frame, _) = r.render(&s.camera, width, height)?;
            let frame_ms: f64 = [Pass::Gbuffer, Pass::Shade]
                .iter()
                .map(|p| {
                    let ms = r.stats().last_ms.get(p).copied().unwrap_or(0.0);
                    *pass_ms.entry(p.name().into()).or_default() += ms;
                    ms
                })
                .sum();
            let (err, noise) = rel_rmse(&frame.hdr, &s.reference);
            rows.push(Row {
                scene: s.name.clone(),
                config: c.name.clone(),
                knob: c.knob.clone(),
                rel_rmse: err,
                reference_noise: noise,
                light_ms,
                frame_ms,
                bounces: r.stats().bounces_done,
                gpu_bytes: r.gpu_bytes(),
                pass_ms,
            });
        }
    }
    Ok(rows)
}

/// Rows on the Pareto front of (total time, error) within one scene.
pub fn pareto(rows: &[Row]) -> Vec<bool> {
    rows.iter()
        .map(|a| {
            let ta = a.light_ms + a.frame_ms;
            !rows.iter().any(|b| {
                let tb = b.light_ms + b.frame_ms;
                (tb <= ta && b.rel_rmse < a.rel_rmse) || (tb < ta && b.rel_rmse <= a.rel_rmse)
            })
        })
        .collect()
}

/// Whether fast < balanced < high in time and fast > balanced > high in error on `rows` (one scene).
pub fn presets_monotone(rows: &[Row]) -> Option<bool> {
    let get = |q: Quality| rows.iter().find(|r| r.knob == "preset" && r.config == q.name());
    let (f, b, h) = (get(Quality::Fast)?, get(Quality::Balanced)?, get(Quality::High)?);
    let t = |r: &Row| r.light_ms + r.frame_ms;
    Some(t(f) < t(b) && t(b) < t(h) && f.rel_rmse > b.rel_rmse && b.rel_rmse > h.rel_rmse)
}

/// File-name form of a scene name.
pub fn slug(name: &str) -> String {
    name.chars().map(|c| if c.is_ascii_alphanumeric() { c.to_ascii_lowercase() } else { '-' }).collect()
}

/// docs/accuracy.md.
pub fn report(
    scenes: &[SweepScene],
    rows: &[Row],
    device: &str,
    width: u32,
    height: u32,
    command: &str,
) -> String {
    let mut s = String::new();
    let _ = writeln!(s, "# Accuracy against time\n");
    let _ = writeln!(
        s,
        "Generated by `{command}` (do not edit by hand). Device for the runtime's GPU times: {device}. \
         Images {width}x{height}. Error: relative RMSE of the runtime's linear radiance against the Monte Carlo \
         reference (`grotto-reference`, path tracing on the same surfels, lights and albedo), over the pixels \
         the runtime covers; the reference's own noise on the same scale is listed so it can be seen to be far \
         below the errors it judges. Time: GPU milliseconds (timestamp queries) to converge the light \
         (shadow maps, injection, every bounce until converged or the budget is spent) and to draw one frame. \
         Memory: GPU buffers and textures the renderer holds. Knobs vary one at a time around the balanced \
         preset. Pareto-optimal rows (no other row is both faster and more accurate) are marked *.\n"
    );
    for sc in scenes {
        let mine: Vec<Row> = rows.iter().filter(|r| r.scene == sc.name).cloned().collect();
        let front = pareto(&mine);
        let noise = mine.first().map_or(0.0, |r| r.reference_noise);
        let _ = writeln!(s, "## {}\n", sc.name);
        let _ = writeln!(s, "![{} error against time](accuracy/{}.svg)\n", sc.name, slug(&sc.name));
        let _ = writeln!(
            s,
            "{}. Reference: {} paths per pixel in {:.1} s, own noise {:.4} (relative RMSE scale). {} leaves, {} surfels.\n",
            sc.description,
            sc.spp,
            sc.reference_s,
            noise,
            sc.data.leaves.len(),
            sc.data.surfels.len()
        );
        let _ =
            writeln!(s, "| config | knob | rel. RMSE | light ms | frame ms | bounces | GPU MiB | Pareto |");
        let _ = writeln!(s, "|---|---|---:|---:|---:|---:|---:|:-:|");
        let mut order: Vec<usize> = (0..mine.len()).collect();
        order.sort_by(|&a, &b| {
            (mine[a].light_ms + mine[a].frame_ms).total_cmp(&(mine[b].light_ms + mine[b].frame_ms))
        });
        for i in order {
            let r = &mine[i];
            let _ = writeln!(
                s,
                "| {} | {} | {:.4} | {:.1} | {:.1} | {} | {:.1} | {} |",
                r.config,
                r.knob,
                r.rel_rmse,
                r.light_ms,
                r.frame_ms,
                r.bounces,
                r.gpu_bytes as f64 / (1 << 20) as f64,
                if front[i] { "*" } else { "" }
            );
        }
        let mono = presets_monotone(&mine);
        let _ = writeln!(
            s,
            "\nPresets monotone (each slower and more accurate than the one below): {}\n",
            match mono {
                Some(true) => "yes",
                Some(false) => "**no**",
                None => "not measured",
            }
        );
    }
    s
}

/// An SVG of error against total GPU time (log-log) for one scene's rows: every run as a point, the
/// Pareto front as a line, the presets labelled.
pub fn plot_svg(scene: &str, rows: &[Row]) -> String {
    use plotters::prelude::*;
    let mine: Vec<&Row> = rows.iter().filter(|r| r.scene == scene).collect();
    let t = |r: &Row| (r.light_ms + r.frame_ms).max(0.1);
    let (t_lo, t_hi) = mine.iter().fold((f64::MAX, f64::MIN), |(a, b), r| (a.min(t(r)), b.max(t(r))));
    let (e_lo, e_hi) =
        mine.iter().fold((f64::MAX, f64::MIN), |(a, b), r| (a.min(r.rel_rmse), b.max(r.rel_rmse)));
    let mut svg = String::new();
    {
        let root = SVGBackend::with_string(&mut svg, (640, 420)).into_drawing_area();
        let _ = root.fill(&WHITE);
        let chart = ChartBuilder::on(&root)
            .caption(format!("{scene}: error against GPU time"), ("sans-serif", 18))
            .margin(12)
            .x_label_area_size(40)
            .y_label_area_size(56)
            .build_cartesian_2d(
                (t_lo * 0.8..t_hi * 1.25).log_scale(),
                (e_lo.max(1e-4) * 0.8..e_hi * 1.25).log_scale(),
            );
        let Ok(mut chart) = chart else { return svg_fallback(scene) };
        let _ = chart
            .configure_mesh()
            .x_desc("GPU time to converge + one frame (ms)")
            .y_desc("relative RMSE")
            .draw();
        let _ = chart.draw_series(mine.iter().map(|r| Circle::new((t(r), r.rel_rmse), 3, BLUE.filled())));
        let owned: Vec<Row> = mine.iter().map(|r| (*r).clone()).collect();
        let front = pareto(&owned);
        let mut pts: Vec<(f64, f64)> =
            owned.iter().zip(&front).filter(|(_, f)| **f).map(|(r, _)| (t(r), r.rel_rmse)).collect();
        pts.sort_by(|a, b| a.0.total_cmp(&b.0));
        let _ = chart.draw_series(LineSeries::new(pts, &RED));
        for r in mine.iter().filter(|r| r.knob == "preset") {
            let _ = chart.draw_series(std::iter::once(Text::new(
                r.config.clone(),
                (t(r), r.rel_rmse),
                ("sans-serif", 14).into_font().color(&BLACK),
            )));
        }
        let _ = root.present();
    }
    svg
}

fn svg_fallback(scene: &str) -> String {
    format!("<svg xmlns=\"http://www.w3.org/2000/svg\"><text x=\"10\" y=\"20\">{scene}: no data</text></svg>")
}
