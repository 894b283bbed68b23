//! Rendering from the command line: per-pass times of the cave paper's configurations, the cost
//! of many lights, the first frame of a large survey under a memory budget, and a fly-through's
//! per-frame streaming figures.

use std::process::Stdio;

use anyhow::{Context, Result};
use serde_json::Value;

use crate::figures::Figure;
use crate::runner::{Ctx, num, thousands};

pub(super) const PASSES: [&str; 6] = ["shadow", "inject", "mip", "propagate", "gbuffer", "shade"];

/// Which section of the figures page a rendering figure belongs in: software adapters give
/// ratios only.
pub(super) fn section_of(report: &Value) -> &'static str {
    let device = report["device"].as_str().unwrap_or_default().to_lowercase();
    if ["llvmpipe", "lavapipe", "swiftshader", "software"].iter().any(|s| device.contains(s)) {
        "software"
    } else {
        "gpu"
    }
}

/// `grotto bench` of the paper's 1.4 M-point cave with 64 m tiles at SVO depth 7 (0.5 m leaves)
/// and 8 (0.25 m), at 800x600 and 1600x900, its 14 shadowed lamps, 6 cones: (depth, report).
pub(super) fn paper_runs(ctx: &Ctx) -> Result<Vec<(u32, Value)>> {
    let manifest = ctx.synth("paper", 1_400_000, &[])?;
    let mut runs = Vec::new();
    for (depth, leaf) in [(7, "0.5"), (8, "0.25")] {
        let pkg = ctx.package(
            &format!("paper-d{depth}"),
            &manifest,
            &["--leaf-m", leaf, "--min-tile-m", "64", "--max-tile-m", "64", "--halo-m", "1"],
        )?;
        for size in ["800x600", "1600x900"] {
            runs.push((depth, ctx.bench(&format!("paper-d{depth}-{size}"), &pkg, &["--size", size])?));
        }
    }
    Ok(runs)
}

/// Per-pass times of the paper's configurations ([`paper_runs`]); the figure is one bounce at
/// depth 8, 800x600.
pub(crate) fn passes(ctx: &Ctx) -> Result<Vec<Figure>> {
    let mut table = format!(
        "| depth | size | leaves | surfels | {} | all (ms) |\n|---|---|---:|---:|{}---:|",
        PASSES.join(" | "),
        "---:|".repeat(PASSES.len())
    );
    let runs = paper_runs(ctx)?;
    for (depth, r) in &runs {
        let ms: Vec<f64> = PASSES.iter().map(|p| num(r, &format!("median_ms.{p}"))).collect();
        table += &format!(
            "\n| {depth} | {}x{} | {} | {} | {} | {:.1} |",
            r["width"],
            r["height"],
            thousands(num(r, "leaves") as u64),
            thousands(num(r, "surfels") as u64),
            ms.iter().map(|m| format!("{m:.1}")).collect::<Vec<_>>().join(" | "),
            ms.iter().sum::<f64>()
        );
    }
    let d8 = &runs.iter().find(|(d, r)| *d == 8 && r["width"] == 800).context("no depth-8 run")?.1;
    ctx.table(&format!("device: {}, median of {}\n\n{table}", d8["device"], ctx.reps))?;
    let bounce_s = (num(d8, "median_ms.mip") + num(d8, "median_ms.propagate")) / 1e3;
    Ok(vec![ctx.figure(
        "passes-bounce",
        section_of(d8),
        "1.4 M-point cave, depth 8, 800x600: one bounce (mip + propagate)",
        format!("{bounce_s:.2} s"),
        "\"Runtime passes\"",
    )])
}

/// The small synthetic cave (80k points) relit by N 8 W lamps, N = 1 to 1024, the 16 brightest
/// with shadow maps and the rest shadowed by cones or not at all; light work only.
pub(crate) fn lights(ctx: &Ctx) -> Result<Vec<Figure>> {
    let manifest = ctx.synth("lights", 80_000, &["--segments", "6"])?;
    let pkg = ctx.package("lights", &manifest, &["--leaf-m", "0.25"])?;
    let mut runs: Vec<(String, Vec<String>)> = Vec::new();
    for n in [1, 16, 64, 256, 1024] {
        for fallback in ["cone", "none"] {
            runs.push((
                format!("{n}-{fallback}"),
                vec![n.to_string(), "--shadow-fallback".into(), fallback.into()],
            ));
        }
    }
    for cutoff in ["2e-3", "2e-2"] {
        runs.push((
            format!("1024-cone-cutoff{cutoff}"),
            vec!["1024".into(), "--light-cutoff".into(), cutoff.into()],
        ));
    }
    let mut table = "| lights | with shadow maps | run | in range per cell (mean / max) | shadow | inject | shade | frame: gbuffer + shade (ms) |\n|---:|---:|---|---|---:|---:|---:|---:|".to_owned();
    let mut shadow16 = Vec::new();
    let mut last = Value::Null;
    for (name, lamps) in runs {
        let mut args = vec!["--size", "320x240", "--bounces", "0", "--exposure", "8", "--lamps"];
        args.extend(lamps.iter().map(String::as_str));
        let r = ctx.bench(&format!("lights-{name}"), &pkg, &args)?;
        let m = |p: &str| num(&r, &format!("median_ms.{p}"));
        table += &format!(
            "\n| {} | {} | {name} | {:.1} / {} | {:.1} | {:.1} | {:.1} | {:.1} |",
            r["lights"],
            r["shadowed_lights"],
            r["lights_in_range"][0].as_f64().unwrap_or(0.0),
            r["lights_in_range"][1],
            m("shadow"),
            m("inject"),
            m("shade"),
            m("gbuffer") + m("shade")
        );
        if name.starts_with("16-") {
            shadow16.push(m("shadow"));
        }
        last = r;
    }
    ctx.table(&format!("device: {}, median of {}\n\n{table}", last["device"], ctx.reps))?;
    let (lo, hi) = shadow16.iter().fold((f64::MAX, 0.0f64), |(l, h), &v| (l.min(v), h.max(v)));
    let range = if (hi - lo) * 10.0 < hi {
        format!("{:.2} s", hi / 1e3)
    } else {
        format!("{:.2}-{:.2} s", lo / 1e3, hi / 1e3)
    };
    Ok(vec![ctx.figure(
        "lights-16",
        section_of(&last),
        "lights: shadow pass, 16 lamps with maps (80k points)",
        range,
        "\"Many lights\"",
    )])
}

/// The first frame of a 10^8-point survey under 64 MiB of GPU memory and a 400k point budget,
/// 160x120, fast preset: what opening a large package costs before anything is shown.
pub(crate) fn first_frame(ctx: &Ctx) -> Result<Vec<Figure>> {
    let manifest = ctx.synth("survey-1e8", 100_000_000, &[])?;
    let pkg = ctx.package("first-frame-1e8", &manifest, &["--memory-budget", "1G"])?;
    let mut cmd = ctx.grotto();
    cmd.arg("render").arg(&pkg).args(["--camera", "entrance", "--size", "160x120", "--quality", "fast"]);
    cmd.args(["--gpu-memory", "64M", "--point-budget", "400000", "--json", "-o"])
        .arg(ctx.out.join("first.png"));
    let t = std::time::Instant::now();
    let r = ctx.json("first-frame", &mut cmd)?;
    let wall = t.elapsed().as_secs_f64();
    let f = &r["frames"][0];
    ctx.table(&format!(
        "| package | tiles | full / coarse / far | leaves | surfels | load s | settle s | wall |\n|---|---:|---|---:|---:|---:|---:|---:|\n\
         | {} | {} | {} / {} / {} | {} | {} | {:.3} | {:.1} | {wall:.1} s |",
        pkg.file_name().unwrap_or_default().to_string_lossy(),
        r["tiles"],
        f["full_tiles"],
        f["coarse_tiles"],
        f["far_tiles"],
        thousands(num(&r, "leaves") as u64),
        thousands(num(&r, "surfels") as u64),
        num(&r, "load_s"),
        num(&r, "settle_s")
    ))?;
    Ok(vec![ctx.figure(
        "first-frame-1e8",
        section_of(&r),
        "first frame of 10^8 points under 64 MiB (`--point-budget 400000`)",
        format!("{wall:.1} s (load {:.3} s)", num(&r, "load_s")),
        "\"Opening a package and time to first frame\"",
    )])
}

/// A 10^6-point cave cut into 4 m tiles flown along its entrance -> chamber path under 64 MiB:
/// tiles loaded and evicted, bytes uploaded and pass times, frame by frame. A table, no figure.
pub(crate) fn flythrough(ctx: &Ctx) -> Result<Vec<Figure>> {
    let manifest = ctx.synth("fly", 1_000_000, &[])?;
    let pkg = ctx.package("fly-t4", &manifest, &["--max-tile-m", "4"])?;
    let mut cmd = ctx.grotto();
    cmd.arg("render").arg(&pkg).args(["--path", "entrance,chamber", "--frames", "6", "--size", "160x120"]);
    cmd.args(["--bounces", "2", "--gpu-memory", "64M", "--exposure", "8", "--json", "-o"])
        .arg(ctx.out.join("fly.png"));
    let r = ctx.json("flythrough", cmd.stdin(Stdio::null()))?;
    let mut table = format!(
        "device: {}, {} tiles\n\n| frame | tile MiB | full | coarse | far | loaded | evicted | surfels drawn | bounces | uploaded MiB | shadow faces | load wait | {} (ms) |\n|{}",
        r["device"],
        r["tiles"],
        PASSES.join(" | "),
        "---:|".repeat(12 + PASSES.len())
    );
    for f in r["frames"].as_array().context("no frames")? {
        let ms: Vec<String> =
            PASSES.iter().map(|p| format!("{:.0}", num(f, &format!("pass_ms.{p}")))).collect();
        table += &format!(
            "\n| {} | {:.1} | {} | {} | {} | {} | {} | {} | {} | {:.1} | {} of {} | {:.0} | {} |",
            f["frame"],
            num(f, "tile_bytes") / 1048576.0,
            f["full_tiles"],
            f["coarse_tiles"],
            f["far_tiles"],
            f["loaded"],
            f["evicted"],
            thousands(num(f, "surfels") as u64),
            f["bounces"],
            num(f, "update.upload_bytes") / 1048576.0,
            f["shadow_faces"],
            f["shadow_faces_total"],
            num(f, "load_wait_ms"),
            ms.join(" | ")
        );
    }
    ctx.table(&table)?;
    Ok(Vec::new())
}
