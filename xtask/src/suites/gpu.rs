//! Every GPU figure the project states, for a machine with a GPU (`cargo xtask bench gpu` runs
//! the four parts in turn): the demo cave per preset, the cave paper's configurations, a 10^7-point
//! survey with every tile held, and a 10^8-point survey streamed under a GPU memory budget. On a
//! software adapter they run too, slowly, and their rows go to the software section.

use anyhow::{Context, Result};
use serde_json::Value;

use super::frames::section_of;
use crate::figures::Figure;
use crate::runner::{Ctx, num, quantiles, thousands};

const PASSES: [&str; 7] = ["shadow", "inject", "mip", "propagate", "gbuffer", "shade", "resolve"];
const HD: &str = "1920x1080";

/// A table of per-pass medians, one row per (label, report).
fn bench_table(ctx: &Ctx, title: &str, runs: &[(String, Value)]) -> Result<()> {
    let first = &runs.first().context("no runs")?.1;
    let splats = if first["splats_pulled"].as_bool() == Some(true) { "pulled" } else { "instanced" };
    let mut md = format!(
        "{title} ({}, timestamps: {}, splats {splats}, median of {}, ms)\n\n| run | size | leaves | surfels | {} | frame (gbuffer + shade) |\n|---|---|---:|---:|{}---:|",
        first["device"],
        first["timestamps"],
        first["repetitions"],
        PASSES.join(" | "),
        "---:|".repeat(PASSES.len())
    );
    for (label, r) in runs {
        let m = |p: &str| num(r, &format!("median_ms.{p}"));
        md += &format!(
            "\n| {label} | {}x{} | {} | {} | {} | {:.2} |",
            r["width"],
            r["height"],
            thousands(num(r, "leaves") as u64),
            thousands(num(r, "surfels") as u64),
            PASSES.iter().map(|p| format!("{:.2}", m(p))).collect::<Vec<_>>().join(" | "),
            m("gbuffer") + m("shade")
        );
    }
    ctx.table(&md)
}

/// The splat passes' work drawn whole (whole tiles, every surfel) and as the viewers draw them
/// (chunks and level of detail): draws, surfels, shader invocations from statistics queries.
fn work_pair(ctx: &Ctx, name: &str, pkg: &std::path::Path) -> Result<()> {
    let whole = ctx.bench(
        &format!("work-{name}-tiles"),
        pkg,
        &["--size", HD, "--bounces", "0", "--cull", "tiles", "--no-splat-lod"],
    )?;
    let viewer = ctx.bench(&format!("work-{name}-chunks"), pkg, &["--size", HD, "--bounces", "0"])?;
    let mut md = format!(
        "The {name} splat passes: whole tiles against chunks and level of detail ({})\n\n| draws as | pass | ms | draws | surfels drawn | vertices | fragments | submits | bytes written |\n|---|---|---:|---:|---:|---:|---:|---:|---:|",
        whole["device"]
    );
    let n = |v: &Value| v.as_u64().map_or_else(|| "-".to_owned(), thousands);
    for (how, r) in [("tiles", &whole), ("chunks+lod", &viewer)] {
        for p in ["shadow", "gbuffer"] {
            let w = &r["work"][p];
            md += &format!(
                "\n| {how} | {p} | {:.2} | {} | {} | {} | {} | {} | {} |",
                num(r, &format!("median_ms.{p}")),
                n(&w["draws"]),
                n(&w["surfels"]),
                n(&w["vertex_invocations"]),
                n(&w["fragment_invocations"]),
                r["submits"],
                n(&r["upload_bytes"])
            );
        }
    }
    ctx.table(&md)
}

/// The demo cave per preset at 640x480 and 1920x1080, its splat work, and blended splats
/// against the front-most disc (and a still frame's resolve).
pub(crate) fn demo(ctx: &Ctx) -> Result<Vec<Figure>> {
    let pkg = ctx.demo()?;
    let mut runs = Vec::new();
    for q in ["fast", "balanced", "high"] {
        for size in ["640x480", HD] {
            runs.push((
                q.to_owned(),
                ctx.bench(&format!("demo-{q}-{size}"), &pkg, &["--size", size, "--quality", q])?,
            ));
        }
    }
    bench_table(ctx, "The demo cave (grotto-pack demo), chamber camera", &runs)?;
    work_pair(ctx, "demo", &pkg)?;
    let mut splats = Vec::new();
    for (mode, extra) in
        [("front", Some("--no-splat-blend")), ("blend", None), ("blend-aa", Some("--samples"))]
    {
        let mut args = vec!["--size", HD, "--bounces", "0"];
        match (mode, extra) {
            ("blend-aa", Some(a)) => args.extend([a, "8"]),
            (_, Some(a)) => args.push(a),
            _ => {}
        }
        splats.push((mode.to_owned(), ctx.bench(&format!("demo-splats-{mode}"), &pkg, &args)?));
    }
    bench_table(
        ctx,
        "The demo cave at 1920x1080: front-most disc against blended splats, and a still frame's resolve",
        &splats,
    )?;
    let balanced =
        &runs.iter().find(|(l, r)| l == "balanced" && r["width"] == 1920).context("balanced run")?.1;
    let m = |r: &Value, p: &str| num(r, &format!("median_ms.{p}"));
    let shadow: Vec<f64> =
        runs.iter().filter(|(_, r)| r["width"] == 1920).map(|(_, r)| m(r, "shadow")).collect();
    let (lo, hi) = shadow.iter().fold((f64::MAX, 0.0f64), |(l, h), &v| (l.min(v), h.max(v)));
    let section = section_of(balanced);
    Ok(vec![
        ctx.figure(
            "gpu-demo-frame",
            section,
            "demo cave, balanced, 1920x1080: G-buffer + shade",
            format!("{:.2} ms", m(balanced, "gbuffer") + m(balanced, "shade")),
            "\"Runtime passes\", the GPU runs",
        ),
        ctx.figure(
            "gpu-demo-bounce",
            section,
            "demo cave, balanced: one bounce (mip + propagate)",
            format!("{:.1} ms", m(balanced, "mip") + m(balanced, "propagate")),
            "\"Runtime passes\", the GPU runs",
        ),
        ctx.figure(
            "gpu-demo-shadow",
            section,
            "demo cave: shadow pass, 1920x1080",
            format!("{lo:.0}-{hi:.0} ms by preset"),
            "\"Runtime passes\", the GPU runs",
        ),
    ])
}

/// The cave paper's 1.4 M points with 64 m tiles at depth 7 and 8, 800x600 and 1600x900.
pub(crate) fn paper(ctx: &Ctx) -> Result<Vec<Figure>> {
    let runs: Vec<(String, Value)> =
        super::frames::paper_runs(ctx)?.into_iter().map(|(d, r)| (format!("depth {d}"), r)).collect();
    bench_table(ctx, "The cave paper's configurations (1.4 M points, 64 m tiles, depth 7 and 8)", &runs)?;
    Ok(Vec::new())
}

/// A synthetic survey built with the defaults.
pub(crate) fn survey(ctx: &Ctx, points: u64, name: &str) -> Result<std::path::PathBuf> {
    let manifest = ctx.synth(name, points, &[])?;
    let work = ctx.work.join(format!("build-{name}"));
    ctx.package(name, &manifest, &["--work-dir", work.to_str().context("work folder")?])
}

/// A 10^7-point survey with every tile held, at 1920x1080, and its splat work.
pub(crate) fn survey_1e7(ctx: &Ctx) -> Result<Vec<Figure>> {
    let pkg = survey(ctx, 10_000_000, "survey-1e7")?;
    let r = ctx.bench("survey-1e7", &pkg, &["--size", HD])?;
    bench_table(ctx, "A 10^7-point survey, every tile held", &[("10^7".into(), r.clone())])?;
    work_pair(ctx, "survey-1e7", &pkg)?;
    Ok(vec![ctx.figure(
        "gpu-1e7-frame",
        section_of(&r),
        "10^7 points, every tile held, 1920x1080: frame",
        format!("{:.1} ms", num(&r, "median_ms.gbuffer") + num(&r, "median_ms.shade")),
        "\"Runtime passes\", the GPU runs",
    )])
}

/// A 10^8-point survey streamed along entrance -> chamber, 30 frames at 1920x1080 under 512 MiB
/// of GPU memory: as it is and with point budgets, settled before each frame (batch) and as a
/// viewer runs it (no bounce before a frame whose tiles changed, shadow faces within 8 ms).
pub(crate) fn survey_1e8(ctx: &Ctx) -> Result<Vec<Figure>> {
    let pkg = survey(ctx, 100_000_000, "survey-1e8")?;
    let mut md = "A 10^8-point survey streamed along entrance -> chamber, 30 frames at 1920x1080, --gpu-memory 512M\n\
                  (frame 0 after the first settle; median, p99 and worst over the frames after it; stalls: frames over 50 ms)\n\n\
                  | run | frames | frame 0 ms | median ms | p99 ms | worst ms | stalls | surfels drawn (most) | uploaded MiB | first settle s |\n\
                  |---|---:|---:|---:|---:|---:|---:|---:|---:|---:|"
        .to_owned();
    let mut medians = std::collections::HashMap::new();
    let mut section = "gpu";
    for (budget, viewer) in [
        (None, false),
        (Some("5000000"), false),
        (Some("1000000"), false),
        (Some("5000000"), true),
        (Some("1000000"), true),
    ] {
        let mut cmd = ctx.grotto();
        cmd.arg("render").arg(&pkg).args([
            "--path",
            "entrance,chamber",
            "--frames",
            "30",
            "--size",
            HD,
            "--gpu-memory",
            "512M",
        ]);
        let mut label =
            budget.map_or_else(|| "no point budget".to_owned(), |b| format!("--point-budget {b}"));
        if let Some(b) = budget {
            cmd.args(["--point-budget", b]);
        }
        if viewer {
            cmd.args(["--frame-bounces", "0", "--shadow-ms", "8"]);
            label += ", viewer-like";
        }
        let name =
            format!("fly-1e8-{}-{}", budget.unwrap_or("none"), if viewer { "viewer" } else { "batch" });
        cmd.args(["--json", "-o"]).arg(ctx.work.join(format!("{name}.png")));
        let r = ctx.json(&name, &mut cmd)?;
        section = section_of(&r);
        let frames = r["frames"].as_array().context("no frames")?;
        let ms: Vec<f64> = frames.iter().skip(1).map(|f| num(f, "frame_ms")).collect();
        let (median, p99) = quantiles(&ms, 0.99).unwrap_or((num(&frames[0], "frame_ms"), 0.0));
        let worst = ms.iter().copied().fold(0.0, f64::max);
        let surfels = frames.iter().map(|f| num(f, "surfels") as u64).max().unwrap_or(0);
        let uploaded: f64 = frames.iter().map(|f| num(f, "update.upload_bytes")).sum::<f64>() / 1048576.0;
        md += &format!(
            "\n| {label} | {} | {:.1} | {median:.1} | {p99:.1} | {worst:.1} | {} | {} | {uploaded:.0} | {:.2} |",
            frames.len(),
            num(&frames[0], "frame_ms"),
            ms.iter().filter(|&&m| m > 50.0).count(),
            thousands(surfels),
            num(&r, "settle_s")
        );
        if !viewer {
            medians.insert(budget.unwrap_or("none"), median);
        }
    }
    ctx.table(&md)?;
    let (none, one) = (medians["none"], medians["1000000"]);
    Ok(vec![ctx.figure(
        "gpu-1e8-fly",
        section,
        "10^8 points streamed under 512 MiB, 1920x1080, median frame",
        format!("{:.2} s ({one:.0} ms with `--point-budget 1000000`)", none / 1e3),
        "\"Runtime passes\", the GPU runs",
    )])
}
