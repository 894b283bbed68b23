//! Building packages: the demo end to end, opening a package, the readers, normals, and a
//! survey-scale build.

use std::process::Command;

use anyhow::{Context, Result};
use serde_json::Value;

use crate::figures::{Figure, root};
use crate::runner::{Ctx, num};

const BUILD: &str = "build";

/// `scripts/demo.sh` (the README's first command) from start to end, its release build done.
pub(crate) fn demo(ctx: &Ctx) -> Result<Vec<Figure>> {
    let out = ctx.work.join("demo-run");
    let s = ctx.timed(Command::new(root().join("scripts/demo.sh")).arg(&out))?;
    ctx.table(&format!("`scripts/demo.sh {}`: {s:.0} s", out.display()))?;
    let value = format!("{} min {:02.0} s", (s / 60.0).floor(), s % 60.0);
    Ok(vec![ctx.figure(
        "demo-end-to-end",
        BUILD,
        "demo, end to end (release build already done)",
        value,
        "\"The demo, end to end\"",
    )])
}

/// `Package::open` on a 10 MB and a 2 GB package (criterion, `format/benches/open.rs`).
pub(crate) fn format(ctx: &Ctx) -> Result<Vec<Figure>> {
    ctx.run(Command::new("cargo").current_dir(root()).args([
        "bench",
        "--locked",
        "-p",
        "grotto-format",
        "--bench",
        "open",
    ]))?;
    let median_us = |id: &str| -> Result<f64> {
        let path = root().join(format!("target/criterion/open/{id}/new/estimates.json"));
        let v: Value = serde_json::from_slice(
            &std::fs::read(&path).with_context(|| format!("reading {}", path.display()))?,
        )?;
        Ok(num(&v, "median.point_estimate") / 1e3)
    };
    let (small, large) = (median_us("10MB")?, median_us("2048MB")?);
    ctx.table(&format!(
        "| package | median open |\n|---|---|\n| 10 MB | {small:.1} us |\n| 2 GB | {large:.1} us |"
    ))?;
    Ok(vec![ctx.figure(
        "format-open",
        BUILD,
        "`Package::open` (map + structural validation)",
        format!("{small:.1} us at 10 MB, {large:.1} us at 2 GB"),
        "\"Package format\"",
    )])
}

/// Points a second per reader on one 10^7-point scan in each format, read from the page cache.
pub(crate) fn ingest(ctx: &Ctx) -> Result<Vec<Figure>> {
    let dir = ctx.work.join("ingest");
    let v = ctx.json(
        "ingest",
        ctx.pack().args(["bench-ingest", "--points", "10000000", "--json", "--dir"]).arg(&dir),
    )?;
    let rows = v.as_array().context("bench-ingest: a list of readers")?;
    let mut table = "| reader | points | points/s |\n|---|---:|---:|".to_owned();
    let mut value = Vec::new();
    for r in rows {
        let reader = r["reader"].as_str().unwrap_or("?");
        table += &format!("\n| {reader} | {} | {:.3e} |", num(r, "points"), num(r, "points_per_second"));
        value.push(format!("{} {:.2e}", reader.to_uppercase(), num(r, "points_per_second")));
    }
    ctx.table(&table)?;
    Ok(vec![ctx.figure(
        "ingest-readers",
        BUILD,
        "readers, points a second (page cache)",
        value.join(", "),
        "\"Ingest throughput\"",
    )])
}

/// Normal accuracy against the synthetic cave's analytic surface, with scanner positions (10^6
/// points) and without them (10^7 points).
pub(crate) fn normals(ctx: &Ctx) -> Result<Vec<Figure>> {
    let seen = ctx.json(
        "normals-1e6",
        ctx.pack()
            .args(["bench-normals", "--points", "1000000", "--k", "16", "--json", "--dir"])
            .arg(ctx.work.join("normals-1e6")),
    )?;
    let bare = ctx.json(
        "normals-1e7-bare",
        ctx.pack()
            .args(["bench-normals", "--points", "10000000", "--bare", "--json", "--dir"])
            .arg(ctx.work.join("normals-1e7")),
    )?;
    // `--bare` reports the run with scanner positions too, then the bare one.
    let pick = |v: &Value, bare: bool| {
        v.as_array()
            .and_then(|a| a.iter().find(|f| f["bare"].as_bool() == Some(bare)))
            .cloned()
            .context("bench-normals: no such figure")
    };
    let (seen, bare) = (pick(&seen, false)?, pick(&bare, true)?);
    let mut table = "| points | bare | mean error (deg) | p95 (deg) | flipped | normals/s |\n|---:|---|---:|---:|---:|---:|".to_owned();
    for r in [&seen, &bare] {
        table += &format!(
            "\n| {} | {} | {:.2} | {:.2} | {:.3}% | {:.3e} |",
            num(r, "points"),
            r["bare"],
            num(r, "mean_deg"),
            num(r, "p95_deg"),
            num(r, "flipped_percent"),
            num(r, "normals_per_second")
        );
    }
    ctx.table(&table)?;
    Ok(vec![
        ctx.figure(
            "normals-1e6",
            BUILD,
            "normals, mean error (10^6 points, noise x1, k = 16)",
            format!("{:.2} degrees, {:.3}% flipped", num(&seen, "mean_deg"), num(&seen, "flipped_percent")),
            "\"Normals and SVO build\"",
        ),
        ctx.figure(
            "normals-bare-1e7",
            BUILD,
            "normals without scanner positions (10^7 points)",
            format!(
                "{:.2e} normals/s, {:.3}% flipped",
                num(&bare, "normals_per_second"),
                num(&bare, "flipped_percent")
            ),
            "\"Orientation without scanner positions\"",
        ),
    ])
}

/// A 10^8-point survey built end to end (about 12 GB of scans and work files), and the package
/// bytes per input point at 10^8 and 10^7 and for the demo.
pub(crate) fn build(ctx: &Ctx) -> Result<Vec<Figure>> {
    let mut table = "| package | points | build s | M points/s | peak GB | bytes per point |\n|---|---:|---:|---:|---:|---:|".to_owned();
    let mut per_point = Vec::new();
    let mut big = None;
    for (name, points, label) in [("survey-1e8", 100_000_000u64, "10^8"), ("survey-1e7", 10_000_000, "10^7")]
    {
        let manifest = ctx.synth(name, points, &[])?;
        // Built afresh: the build's own time is the figure.
        let _ = std::fs::remove_file(ctx.work.join(format!("{name}.grotto")));
        let work = ctx.work.join(format!("build-{name}"));
        ctx.package(name, &manifest, &["--work-dir", work.to_str().context("work folder")?])?;
        let summary: Value =
            serde_json::from_slice(&std::fs::read(ctx.out.join(format!("json/build-{name}.json")))?)?;
        let (secs, bytes, peak) =
            (num(&summary, "seconds"), num(&summary, "bytes"), num(&summary, "peak_rss_bytes"));
        table += &format!(
            "\n| {name} | {points} | {secs:.1} | {:.3} | {:.2} | {:.2} |",
            points as f64 / secs / 1e6,
            peak / 1e9,
            bytes / points as f64
        );
        per_point.push(format!("{:.2} B ({label})", bytes / points as f64));
        big.get_or_insert(summary);
    }
    let demo = ctx.demo_summary()?;
    per_point.push(format!("{:.2} B (demo)", num(&demo, "bytes") / num(&demo, "points")));
    ctx.table(&table)?;
    let big = big.context("no 10^8 build")?;
    let secs = num(&big, "seconds");
    Ok(vec![
        ctx.figure(
            "build-1e8",
            BUILD,
            "10^8 points, end to end",
            format!(
                "{secs:.1} s, {:.2} M points/s, peak {:.2} GB",
                1e8 / secs / 1e6,
                num(&big, "peak_rss_bytes") / 1e9
            ),
            "\"Where a build's time goes\"",
        ),
        ctx.figure(
            "package-bytes",
            BUILD,
            "package bytes per input point",
            per_point.join(", "),
            "\"Compact packages\"",
        ),
    ])
}
