//! The sweep's rows as docs/accuracy.md: tables, the Pareto front, the presets' and knobs'
//! monotonicity checks, and SVG plots.

use std::fmt::Write as _;

use grotto_runtime::settings::{Quality, Settings};

use crate::accuracy::configs::CUT_BOUNCES;
use crate::accuracy::configs::MARCH_APERTURES;
use crate::accuracy::configs::MARCH_STEPS;
use crate::accuracy::configs::ONE_BOUNCE_APERTURE;
use crate::accuracy::configs::ONE_BOUNCE_STEP;
use crate::accuracy::configs::Row;
use crate::accuracy::configs::judged_cut;
use crate::accuracy::configs::one_bounce_knob;
use crate::accuracy::configs::slug;
use crate::accuracy::configs::swept_name;
use crate::accuracy::scenes::SweepScene;
use crate::accuracy::sweep::SUPERSAMPLE;
use crate::accuracy::sweep::SUPERSAMPLE_CHECK;

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
/// A finer preset may tie a coarser one (within [`MONOTONE_SLACK`]) only where it is at the
/// reference's own noise ([`NOISE_FLOOR`] times it): no preset can measure better than that
/// (the furnace, where the bounce tail makes every preset exact).
pub fn presets_monotone(rows: &[Row]) -> Option<bool> {
    let get = |q: Quality| rows.iter().find(|r| r.knob == "preset" && r.config == q.name());
    let (f, b, h) = (get(Quality::Fast)?, get(Quality::Balanced)?, get(Quality::High)?);
    let t = |r: &Row| r.light_ms + r.frame_ms;
    let better = |coarse: &Row, fine: &Row| {
        fine.rel_rmse < coarse.rel_rmse
            || (fine.rel_rmse <= coarse.rel_rmse + MONOTONE_SLACK
                && fine.rel_rmse <= NOISE_FLOOR * fine.reference_noise)
    };
    Some(t(f) < t(b) && t(b) < t(h) && better(f, b) && better(b, h))
}

/// An error within this factor of the reference's own noise is as low as the reference can judge.
pub const NOISE_FLOOR: f64 = 1.1;

/// How much worse (in relative RMSE or |bias|) a finer row may be than the coarser one before a
/// knob's rows count as not monotone. Every row is judged against the same reference image, so its noise moves
/// all rows alike; what is left is the runtime's own rounding, far below this.
pub const MONOTONE_SLACK: f64 = 0.002;

/// A knob's rows from coarse to fine (config names), the full-transport ones around the balanced
/// preset and the one-bounce ones.
pub fn knob_series(knob: &str) -> Vec<String> {
    let base = Settings::preset(Quality::Balanced);
    match knob {
        "step" => MARCH_STEPS.iter().map(|&s| swept_name(knob, s, base.step_scale)).collect(),
        "aperture" => {
            MARCH_APERTURES.iter().map(|&a| swept_name(knob, a, base.cone_aperture_scale)).collect()
        }
        ONE_BOUNCE_STEP => MARCH_STEPS.iter().map(|s| format!("step {s}, 1 bounce")).collect(),
        ONE_BOUNCE_APERTURE => MARCH_APERTURES.iter().map(|a| format!("aperture {a}, 1 bounce")).collect(),
        _ => Vec::new(),
    }
}

/// The error of `knob`'s rows on one scene from coarse to fine (against the cut reference for the
/// one-bounce knobs), or None where a row is missing. For the step it is the relative RMSE. For the
/// aperture it is |bias|: with the cone count fixed, a narrower cone covers less of the hemisphere
/// (9 cones at `--aperture` 0.35 cover 12% of it), so its RMSE grows with the gaps between cones;
/// what the aperture must not change is the energy: wide cones should blur, not darken.
pub fn knob_errors(rows: &[Row], knob: &str) -> Option<Vec<f64>> {
    let aperture = knob == "aperture" || knob == ONE_BOUNCE_APERTURE;
    knob_series(knob)
        .iter()
        .map(|name| {
            let r = rows.iter().find(|r| &r.config == name)?;
            let (e, b) = if judged_cut(knob) { r.truncated? } else { (r.rel_rmse, r.bias) };
            Some(if aperture { b.abs() } else { e })
        })
        .collect()
}

/// Whether each finer row of `knob` is at least as accurate as the coarser one (`knob_errors`),
/// within `MONOTONE_SLACK`.
pub fn knob_monotone(rows: &[Row], knob: &str) -> Option<bool> {
    let e = knob_errors(rows, knob)?;
    Some(e.windows(2).all(|w| w[1] <= w[0] + MONOTONE_SLACK))
}

/// The knobs whose rows must get more accurate as they get finer.
pub const MONOTONE_KNOBS: [&str; 4] = ["step", "aperture", ONE_BOUNCE_STEP, ONE_BOUNCE_APERTURE];

/// A monotone check in the report: yes, **no**, or `missing` where rows were not measured.
pub(crate) fn verdict(v: Option<bool>, missing: &'static str) -> &'static str {
    match v {
        Some(true) => "yes",
        Some(false) => "**no**",
        None => missing,
    }
}

/// docs/accuracy.md; each scene's plot is linked as `plots`/SLUG.svg (beside the report).
pub fn report(
    scenes: &[SweepScene],
    rows: &[Row],
    device: &str,
    width: u32,
    height: u32,
    command: &str,
    plots: &str,
) -> String {
    let mut s = String::new();
    report_intro(&mut s, device, width, height, command);
    report_presets(&mut s, scenes, rows);
    report_supersampling(&mut s, scenes, rows);
    report_march_knobs(&mut s, scenes, rows);
    for sc in scenes {
        report_scene(&mut s, sc, rows, plots);
    }
    s
}

/// `report` with the true-surface benchmark's headline after its introduction: the light judged
/// on grotto's own discs (this report) beside the picture judged against the cave itself
/// (accuracy-truth.md, from `truth`: scripts/truth-check.py's JSON rows).
pub fn with_truth(report: &str, truth: &serde_json::Value) -> String {
    let mut t = String::from(
        "## The picture against the cave\n\nEverything below compares grotto with a path tracer on the same discs: how right the light is on \
         grotto's model of the surface. [accuracy-truth.md](accuracy-truth.md) compares grotto's picture of the scanned \
         points with Mitsuba 3 rendering the synthetic cave's exact surface (a mesh far finer than a leaf) with the same \
         lamps and cameras, over every pixel at 640x480: how close the picture is to the cave. Mean FLIP, before \
         (front-most disc) and after blended splats, and the truth's own noise:\n\n\
         | camera | light | FLIP before | FLIP after | rel. RMSE before | rel. RMSE after | truth noise (FLIP) |\n\
         |---|---|---:|---:|---:|---:|---:|\n",
    );
    let rows = truth["rows"].as_array().map(Vec::as_slice).unwrap_or_default();
    let find = |cam: &serde_json::Value, light: &serde_json::Value, mode: &str| {
        rows.iter().find(|r| &r["camera"] == cam && &r["transport"] == light && r["mode"] == mode)
    };
    for r in rows.iter().filter(|r| r["mode"] == "after") {
        if let Some(b) = find(&r["camera"], &r["transport"], "before") {
            let f = |v: &serde_json::Value| v.as_f64().unwrap_or(f64::NAN);
            let _ = writeln!(
                t,
                "| {} | {} | {:.4} | {:.4} | {:.4} | {:.4} | {:.4} |",
                r["camera"].as_str().unwrap_or("?"),
                r["transport"].as_str().unwrap_or("?"),
                f(&b["flip"]),
                f(&r["flip"]),
                f(&b["rel_rmse"]),
                f(&r["rel_rmse"]),
                f(&r["noise_flip"])
            );
        }
    }
    t.push('\n');
    // After the introduction: the first section heading.
    match report.find("\n## ") {
        Some(i) => format!("{}\n{t}{}", &report[..i], &report[i + 1..]),
        None => format!("{report}\n{t}"),
    }
}

/// The report's title and how it was measured.
fn report_intro(s: &mut String, device: &str, width: u32, height: u32, command: &str) {
    let _ = writeln!(s, "# Accuracy against time\n");
    let _ = writeln!(
        s,
        "Generated by `{command}` (do not edit by hand). Device for the runtime's GPU times: {device}. \
         Images {width}x{height}. Reference: `grotto-reference`, Monte Carlo path tracing on the same surfels, \
         lights and albedo, each pixel integrated over its area; the runtime is rendered at {SUPERSAMPLE}x{SUPERSAMPLE} \
         samples per pixel and box-filtered so both estimate the same pixel values (the frame time is for one \
         frame at {width}x{height}). Error over the pixels the runtime covers: relative RMSE of linear radiance \
         (the reference's own noise on the same scale is listed so it can be seen to be far below the errors \
         it judges), bias = sum(runtime) / sum(reference) - 1, and mean FLIP (NVIDIA's perceptual metric, \
         `nv-flip`, 67 pixels per degree) of both images tonemapped at the reference's auto-exposure. Time: \
         milliseconds of the passes (timestamp queries on a hardware adapter, CPU wall time per pass on a \
         software one: docs/runtime.md, \"Per-pass GPU times\") to converge the light (shadow maps, injection, every bounce until \
         converged or the budget is spent) and to draw one frame. Memory: GPU buffers and textures the \
         renderer holds. Knobs vary one at a time around the balanced preset; package knobs (SVO depth, \
         colour codec, compact surfels) rebuild the scene's package and run the balanced preset on it, against the same \
         reference. Pareto-optimal rows (no other row is both faster and more accurate) are marked *. \
         Where the error sits, region by region and bounce by bounce (`breakdown`): the dogleg's \
         [accuracy-passages.md](accuracy-passages.md) (and from when the hand-built scenes' rock cells were dark leaves \
         [accuracy-passages-before.md](accuracy-passages-before.md)), the passage's stretches \
         [accuracy-passage-long.md](accuracy-passage-long.md), the colour box's faces \
         [accuracy-colour-box.md](accuracy-colour-box.md) (docs/reference.md, \"Where the light goes wrong\").\n"
    );
}

/// The presets' error and time per scene, and whether they are monotone.
fn report_presets(s: &mut String, scenes: &[SweepScene], rows: &[Row]) {
    let _ = writeln!(s, "## Presets (`grotto render --quality fast|balanced|high`)\n");
    let _ = writeln!(s, "Relative RMSE / GPU ms to converge and draw one frame, per scene.\n");
    let _ = writeln!(
        s,
        "| preset | {} |",
        scenes.iter().map(|sc| sc.name.as_str()).collect::<Vec<_>>().join(" | ")
    );
    let _ = writeln!(s, "|---|{}", "---:|".repeat(scenes.len()));
    for q in Quality::ALL {
        let cells: Vec<String> = scenes
            .iter()
            .map(|sc| {
                rows.iter()
                    .find(|r| r.scene == sc.name && r.knob == "preset" && r.config == q.name())
                    .map_or("-".into(), |r| format!("{:.4} / {:.0}", r.rel_rmse, r.light_ms + r.frame_ms))
            })
            .collect();
        let _ = writeln!(s, "| {} | {} |", q.name(), cells.join(" | "));
    }
    let monotone: Vec<&str> = scenes
        .iter()
        .filter(|sc| {
            let mine: Vec<Row> = rows.iter().filter(|r| r.scene == sc.name).cloned().collect();
            presets_monotone(&mine) != Some(true)
        })
        .map(|sc| sc.name.as_str())
        .collect();
    let _ = writeln!(
        s,
        "\nEach preset slower and more accurate than the one below it on every scene (or as accurate \
         where both are within {NOISE_FLOOR} times the reference's own noise): {}\n",
        if monotone.is_empty() { "yes".to_string() } else { format!("**no** ({})", monotone.join(", ")) }
    );
    report_yardstick(s, scenes, rows);
}

/// The balanced preset's error beyond the reference's own noise, at most this on every scene.
pub(crate) const YARDSTICK_ERROR: f64 = 0.05;

/// The balanced preset's bias, within plus or minus this on every scene.
pub(crate) const YARDSTICK_BIAS: f64 = 0.03;

/// An error with the reference's own noise taken out: sqrt(rmse^2 - noise^2), 0 where the noise
/// is larger.
pub(crate) fn beyond_noise(rel_rmse: f64, noise: f64) -> f64 {
    (rel_rmse * rel_rmse - noise * noise).max(0.0).sqrt()
}

/// The balanced preset against the yardstick, per scene.
fn report_yardstick(s: &mut String, scenes: &[SweepScene], rows: &[Row]) {
    let balanced: Vec<Option<&Row>> = scenes
        .iter()
        .map(|sc| rows.iter().find(|r| r.scene == sc.name && r.knob == "preset" && r.config == "balanced"))
        .collect();
    if balanced.iter().all(Option::is_none) {
        return;
    }
    let _ = writeln!(
        s,
        "The yardstick: the balanced preset's error beyond the reference's own noise, \
         sqrt(rmse^2 - noise^2), at most {YARDSTICK_ERROR} on every scene, and its bias within \
         +-{:.0}%.\n",
        100.0 * YARDSTICK_BIAS
    );
    let _ = writeln!(
        s,
        "| balanced | {} |",
        scenes.iter().map(|sc| sc.name.as_str()).collect::<Vec<_>>().join(" | ")
    );
    let _ = writeln!(s, "|---|{}", "---:|".repeat(scenes.len()));
    let line = |what: &str, cell: &dyn Fn(&Row) -> String| {
        let cells: Vec<String> = balanced.iter().map(|r| r.map_or("-".into(), cell)).collect();
        format!("| {what} | {} |\n", cells.join(" | "))
    };
    s.push_str(&line("error beyond noise", &|r| {
        format!("{:.4}", beyond_noise(r.rel_rmse, r.reference_noise))
    }));
    s.push_str(&line("reference noise", &|r| format!("{:.4}", r.reference_noise)));
    s.push_str(&line("bias", &|r| format!("{:+.1}%", 100.0 * r.bias)));
    s.push_str(&line("met", &|r| yardstick_verdict(r).into()));
    s.push('\n');
}

/// Whether a balanced row meets the yardstick, and if not which half it fails.
pub(crate) fn yardstick_verdict(r: &Row) -> &'static str {
    let error = beyond_noise(r.rel_rmse, r.reference_noise) <= YARDSTICK_ERROR;
    let bias = r.bias.abs() <= YARDSTICK_BIAS;
    match (error, bias) {
        (true, true) => "yes",
        (false, true) => "**no** (error)",
        (true, false) => "**no** (bias)",
        (false, false) => "**no** (error, bias)",
    }
}

/// The comparison's own error: the balanced preset at several supersampling rates.
fn report_supersampling(s: &mut String, scenes: &[SweepScene], rows: &[Row]) {
    let checked: Vec<&Row> = scenes
        .iter()
        .filter_map(|sc| rows.iter().find(|r| r.scene == sc.name && !r.supersample_errors.is_empty()))
        .collect();
    if !checked.is_empty() {
        let _ = writeln!(
            s,
            "The comparison's own error: the balanced preset's relative RMSE with the runtime sampled at k x k \
             points per pixel before the box filter (the report uses {SUPERSAMPLE}x{SUPERSAMPLE}), beside the \
             reference's noise. A regular grid aliases on thin bright features that the reference integrates \
             exactly; where two columns agree, the comparison no longer adds error of its own.\n"
        );
        let heads: Vec<String> = SUPERSAMPLE_CHECK.iter().map(|k| format!("{k}x{k}")).collect();
        let _ = writeln!(s, "| scene | {} | reference noise |", heads.join(" | "));
        let _ = writeln!(s, "|---|{}---:|", "---:|".repeat(heads.len()));
        for r in checked {
            let cells: Vec<String> = r.supersample_errors.iter().map(|(_, e)| format!("{e:.4}")).collect();
            let _ = writeln!(s, "| {} | {} | {:.4} |", r.scene, cells.join(" | "), r.reference_noise);
        }
        let _ = writeln!(s);
    }
}

/// Whether the finer march knobs are more accurate, per scene.
fn report_march_knobs(s: &mut String, scenes: &[SweepScene], rows: &[Row]) {
    let _ = writeln!(
        s,
        "Finer march knobs more accurate: `step` 1 > 0.5 > 0.25 > 0.1 in relative RMSE, `aperture` \
         1 > 0.7 > 0.5 > 0.35 in |bias| (with the cone count fixed a narrower cone leaves gaps between cones, \
         which raises the RMSE; the aperture must change blur, not energy), each finer row at most \
         {MONOTONE_SLACK} above the coarser one; with the balanced preset's {} bounces against full \
         transport, and with 1 bounce against the reference cut after one bounce:\n",
        Settings::preset(Quality::Balanced).bounces
    );
    let _ = writeln!(
        s,
        "| knob | {} |",
        scenes.iter().map(|sc| sc.name.as_str()).collect::<Vec<_>>().join(" | ")
    );
    let _ = writeln!(s, "|---|{}", ":-:|".repeat(scenes.len()));
    for knob in MONOTONE_KNOBS {
        let cells: Vec<&str> = scenes
            .iter()
            .map(|sc| {
                let mine: Vec<Row> = rows.iter().filter(|r| r.scene == sc.name).cloned().collect();
                verdict(knob_monotone(&mine, knob), "-")
            })
            .collect();
        let _ = writeln!(s, "| {knob} | {} |", cells.join(" | "));
    }
    let _ = writeln!(s);
}

/// One scene's section: its rows, the Pareto front, the one-bounce march and the cut bounces.
fn report_scene(s: &mut String, sc: &SweepScene, rows: &[Row], plots: &str) {
    let all: Vec<Row> = rows.iter().filter(|r| r.scene == sc.name).cloned().collect();
    // The one-bounce march rows are judged against the cut reference, in their own table.
    let (march, mine): (Vec<Row>, Vec<Row>) = all.iter().cloned().partition(|r| one_bounce_knob(&r.knob));
    let front = pareto(&mine);
    let noise = mine.first().map_or(0.0, |r| r.reference_noise);
    let _ = writeln!(s, "## {}\n", sc.name);
    let _ = writeln!(s, "![{} error against time]({plots}/{}.svg)\n", sc.name, slug(&sc.name));
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
    let _ = writeln!(
        s,
        "| config | knob | rel. RMSE | bias | FLIP | light ms | frame ms | bounces | GPU MiB | Pareto |"
    );
    let _ = writeln!(s, "|---|---|---:|---:|---:|---:|---:|---:|---:|:-:|");
    let mut order: Vec<usize> = (0..mine.len()).collect();
    order.sort_by(|&a, &b| {
        (mine[a].light_ms + mine[a].frame_ms).total_cmp(&(mine[b].light_ms + mine[b].frame_ms))
    });
    for i in order {
        let r = &mine[i];
        let _ = writeln!(
            s,
            "| {} | {} | {:.4} | {:+.3} | {:.4} | {:.1} | {:.1} | {} | {:.1} | {} |",
            r.config,
            r.knob,
            r.rel_rmse,
            r.bias,
            r.flip,
            r.light_ms,
            r.frame_ms,
            r.bounces,
            r.gpu_bytes as f64 / (1 << 20) as f64,
            if front[i] { "*" } else { "" }
        );
    }
    let _ = writeln!(
        s,
        "\nPresets monotone (each slower and more accurate than the one below): {}\n",
        verdict(presets_monotone(&mine), "not measured")
    );
    if !march.is_empty() {
        let _ = writeln!(
            s,
            "The march alone: the balanced preset at one bounce, `--step` and `--aperture` varied, against \
             the reference cut after one bounce (so the bounces not run do not hide what the march does).\n"
        );
        let _ = writeln!(s, "| config | rel. RMSE (cut reference) | bias (cut reference) | light ms |");
        let _ = writeln!(s, "|---|---:|---:|---:|");
        for knob in [ONE_BOUNCE_STEP, ONE_BOUNCE_APERTURE] {
            for name in knob_series(knob) {
                if let Some(r) = march.iter().find(|r| r.config == name) {
                    let (e, b) = r.truncated.unwrap_or((f64::NAN, f64::NAN));
                    let _ = writeln!(s, "| {} | {e:.4} | {b:+.3} | {:.1} |", r.config, r.light_ms);
                }
            }
        }
        let _ = writeln!(s);
    }
    let mono_line = |knob: &str| verdict(knob_monotone(&all, knob), "not measured");
    let _ = writeln!(
        s,
        "Finer is more accurate: step {}, aperture {}; at one bounce against the cut reference: step {}, aperture {}.\n",
        mono_line("step"),
        mono_line("aperture"),
        mono_line(ONE_BOUNCE_STEP),
        mono_line(ONE_BOUNCE_APERTURE)
    );
    let cut: Vec<&Row> = mine.iter().filter(|r| r.knob == CUT_BOUNCES && r.truncated.is_some()).collect();
    if !cut.is_empty() {
        let _ = writeln!(
            s,
            "Propagation alone: the runtime after k bounces without the tail estimate, against the \
             reference cut after the same k bounces (the rows above compare with full transport, so they \
             also count the bounces not run).\n"
        );
        let _ = writeln!(s, "| bounces | rel. RMSE (cut reference) | bias (cut reference) |");
        let _ = writeln!(s, "|---:|---:|---:|");
        for r in cut {
            let (e, b) = r.truncated.unwrap_or_default();
            let _ = writeln!(s, "| {} | {e:.4} | {b:+.3} |", r.bounces);
        }
        let _ = writeln!(s);
    }
}

/// An SVG of error against total GPU time (log-log) for one scene's rows: every run as a point, the
/// Pareto front as a line, the presets labelled.
pub fn plot_svg(scene: &str, rows: &[Row]) -> String {
    use plotters::prelude::*;
    // Full-transport rows only: the one-bounce march rows answer another question.
    let mine: Vec<&Row> = rows.iter().filter(|r| r.scene == scene && !one_bounce_knob(&r.knob)).collect();
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

pub(crate) fn svg_fallback(scene: &str) -> String {
    format!("<svg xmlns=\"http://www.w3.org/2000/svg\"><text x=\"10\" y=\"20\">{scene}: no data</text></svg>")
}

/// Markdown for [`lights_sweep`]'s rows.
pub fn lights_report(
    s: &SweepScene,
    rows: &[Row],
    device: &str,
    width: u32,
    height: u32,
    command: &str,
) -> String {
    let mut md = String::new();
    let _ = writeln!(md, "# Many lights: the shadow-map budget and the light cutoff against the reference\n");
    let _ = writeln!(md, "Generated by `{command}` on {device}; do not edit by hand.\n");
    let _ = writeln!(
        md,
        "Scene: {}. Reference: {} paths per pixel at {width}x{height}, every lamp sampled with a shadow ray at every path vertex ({:.0} s). \
         The runtime runs the balanced preset until converged, rendered at {SUPERSAMPLE}x{SUPERSAMPLE} samples per pixel and box-filtered; \
         error = relative RMSE against the reference, bias = relative error of the mean. Light ms = shadow maps + injection + mip + env + \
         propagation to convergence; frame ms = G-buffer + shade of one frame.\n",
        s.description, s.spp, s.reference_s
    );
    let _ = writeln!(
        md,
        "| configuration | error | bias | FLIP | light (ms) | frame (ms) | shadow (ms) | inject (ms) |"
    );
    let _ = writeln!(md, "|---|---:|---:|---:|---:|---:|---:|---:|");
    for r in rows {
        let _ = writeln!(
            md,
            "| {} | {:.4} | {:+.4} | {:.4} | {:.0} | {:.0} | {:.0} | {:.0} |",
            r.config,
            r.rel_rmse,
            r.bias,
            r.flip,
            r.light_ms,
            r.frame_ms,
            r.pass_ms.get("shadow").copied().unwrap_or(0.0),
            r.pass_ms.get("inject").copied().unwrap_or(0.0)
        );
    }
    let _ = writeln!(
        md,
        "\nBudget rows use the default cutoff ({:e} W/m^2); cutoff rows the default budget ({} lamps with shadow maps, the rest with SVO cone shadows).",
        Settings::default().light_cutoff_w_m2,
        Settings::default().shadowed_lights
    );
    md
}

#[cfg(test)]
mod tests {
    use super::*;
    use std::collections::BTreeMap;

    fn row(config: &str, knob: &str, rel_rmse: f64, bias: f64, cut: Option<(f64, f64)>) -> Row {
        Row {
            scene: "s".into(),
            config: config.into(),
            knob: knob.into(),
            rel_rmse,
            reference_noise: 0.01,
            bias,
            flip: 0.0,
            truncated: cut,
            light_ms: 1.0,
            frame_ms: 1.0,
            bounces: 4,
            gpu_bytes: 0,
            pass_ms: BTreeMap::new(),
            supersample_errors: Vec::new(),
        }
    }

    #[test]
    fn the_yardstick_takes_the_references_noise_out_and_names_what_failed() {
        assert!((beyond_noise(0.05, 0.03) - 0.04).abs() < 1e-12);
        assert_eq!(beyond_noise(0.02, 0.03), 0.0);
        // The rows' reference noise is 0.01: 0.0509 is 0.05 beyond it.
        assert_eq!(yardstick_verdict(&row("balanced", "preset", 0.0509, 0.03, None)), "yes");
        assert_eq!(yardstick_verdict(&row("balanced", "preset", 0.052, -0.01, None)), "**no** (error)");
        assert_eq!(yardstick_verdict(&row("balanced", "preset", 0.02, -0.031, None)), "**no** (bias)");
        assert_eq!(yardstick_verdict(&row("balanced", "preset", 0.06, 0.04, None)), "**no** (error, bias)");
    }

    #[test]
    fn march_knobs_are_judged_coarse_to_fine_on_their_own_measure() {
        let steps = |errors: [f64; 3]| {
            vec![
                row("balanced", "preset", 0.20, -0.1, None),
                row("step 1", "step", errors[0], -0.1, None),
                row("step 0.25", "step", errors[1], -0.1, None),
                row("step 0.1", "step", errors[2], -0.1, None),
            ]
        };
        // step 1 > balanced (0.5) > 0.25 > 0.1, within the slack.
        assert_eq!(knob_monotone(&steps([0.25, 0.19, 0.1915]), "step"), Some(true));
        assert_eq!(knob_monotone(&steps([0.25, 0.19, 0.195]), "step"), Some(false));
        assert_eq!(knob_monotone(&steps([0.18, 0.17, 0.16]), "step"), Some(false));
        assert_eq!(knob_monotone(&steps([0.25, 0.19, 0.18])[1..], "step"), None, "balanced missing");
        // The aperture is judged by |bias|: a narrow cone's larger RMSE (gaps) does not count.
        let ap: Vec<Row> = MARCH_APERTURES
            .iter()
            .zip([(0.15, -0.04), (0.14, -0.03), (0.15, -0.02), (0.30, 0.01)])
            .map(|(a, cut)| {
                row(&format!("aperture {a}, 1 bounce"), ONE_BOUNCE_APERTURE, 0.5, -0.3, Some(cut))
            })
            .collect();
        assert_eq!(knob_errors(&ap, ONE_BOUNCE_APERTURE), Some(vec![0.04, 0.03, 0.02, 0.01]));
        assert_eq!(knob_monotone(&ap, ONE_BOUNCE_APERTURE), Some(true));
        // One-bounce runs are judged against the cut reference, not full transport.
        let st: Vec<Row> = MARCH_STEPS
            .iter()
            .zip([0.2, 0.15, 0.14, 0.13])
            .map(|(s, e)| row(&format!("step {s}, 1 bounce"), ONE_BOUNCE_STEP, 0.9 - e, -0.3, Some((e, 0.0))))
            .collect();
        assert_eq!(knob_monotone(&st, ONE_BOUNCE_STEP), Some(true));
        assert!(judged_cut(ONE_BOUNCE_STEP) && judged_cut(CUT_BOUNCES) && !judged_cut("step"));
        // The bounce sweep runs with the tail, so it is judged against full transport.
        assert!(!judged_cut("bounces"));
    }

    #[test]
    fn presets_may_tie_only_at_the_reference_noise() {
        let presets = |e: [f64; 3], ms: [f64; 3]| -> Vec<Row> {
            ["fast", "balanced", "high"]
                .iter()
                .zip(e.iter().zip(ms))
                .map(|(name, (&e, ms))| Row { light_ms: ms, ..row(name, "preset", e, 0.0, None) })
                .collect()
        };
        // Reference noise 0.01 (row()): strictly better, or tied at 0.011 and below.
        assert_eq!(presets_monotone(&presets([0.3, 0.2, 0.1], [1.0, 2.0, 3.0])), Some(true));
        assert_eq!(presets_monotone(&presets([0.0105, 0.0105, 0.0105], [1.0, 2.0, 3.0])), Some(true));
        assert_eq!(presets_monotone(&presets([0.2, 0.2, 0.1], [1.0, 2.0, 3.0])), Some(false));
        assert_eq!(presets_monotone(&presets([0.3, 0.2, 0.1], [1.0, 3.0, 2.0])), Some(false));
        assert_eq!(presets_monotone(&presets([0.3, 0.2, 0.1], [1.0, 2.0, 3.0])[..2]), None);
    }

    #[test]
    fn the_truth_table_goes_after_the_introduction() {
        let report = "# Accuracy\n\nintro\n\n## Presets\n\nrows\n";
        let row = |mode: &str, flip: f64| {
            serde_json::json!({"camera": "chamber", "transport": "direct", "mode": mode, "flip": flip,
                "rel_rmse": 0.5, "noise_flip": 0.01})
        };
        let truth = serde_json::json!({"rows": [row("before", 0.3), row("after", 0.2)]});
        let out = with_truth(report, &truth);
        let (truth_at, presets_at) =
            (out.find("## The picture against the cave").unwrap(), out.find("## Presets").unwrap());
        assert!(out.find("intro").unwrap() < truth_at && truth_at < presets_at, "{out}");
        assert!(out.contains("| chamber | direct | 0.3000 | 0.2000 | 0.5000 | 0.5000 | 0.0100 |"), "{out}");
    }
}
