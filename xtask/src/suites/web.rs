//! The published page in headless Chromium (SwiftShader WebGPU): bytes before the first frame,
//! the bundle's size, frame times while moving and memory over a long visit. The browser is
//! driven by the measuring tests in `tests/tests/browser/measure.rs` (they share the suite's
//! WebDriver and server helpers); each writes its figures as JSON where `GROTTO_BENCH_JSON`
//! says.

use std::path::Path;
use std::process::Command;

use anyhow::{Context, Result};
use serde_json::Value;

use crate::figures::{Figure, root};
use crate::runner::{Ctx, num, thousands};

const BROWSER: &str = "browser";

fn build_bundle(ctx: &Ctx) -> Result<()> {
    ctx.run(Command::new(root().join("scripts/build-web.sh")).current_dir(root()))
}

/// Runs the ignored measuring test `name` with `env` and returns the JSON it wrote.
fn measure(ctx: &Ctx, name: &str, pkg: &Path, env: &[(&str, String)]) -> Result<Value> {
    let json = ctx.out.join(format!("json/{name}.json"));
    let _ = std::fs::remove_file(&json);
    let mut cmd = Command::new("cargo");
    cmd.current_dir(root())
        .args([
            "test",
            "--release",
            "--locked",
            "-p",
            "grotto-tests",
            "--test",
            "browser",
            "--",
            "--ignored",
            "--exact",
            "--nocapture",
        ])
        .arg(format!("measure::{name}"))
        .env("GROTTO_WEB_BENCH_PACKAGE", pkg)
        .env("GROTTO_BENCH_JSON", &json);
    for (k, v) in env {
        cmd.env(k, v);
    }
    ctx.run(&mut cmd)?;
    serde_json::from_slice(
        &std::fs::read(&json).with_context(|| format!("{name} wrote no figures ({})", json.display()))?,
    )
    .with_context(|| format!("{}: not JSON", json.display()))
}

/// What the demo page fetches before its first frame, and the bundle's size.
pub(crate) fn bytes(ctx: &Ctx) -> Result<Vec<Figure>> {
    build_bundle(ctx)?;
    let pkg = ctx.demo()?;
    let r = measure(ctx, "bytes_before_the_first_frame", &pkg, &[])?;
    let (first, total) = (num(&r, "first_frame_bytes"), num(&r, "package_bytes"));
    let wasm_bytes = std::fs::metadata(root().join("target/web/grotto_web_bg.wasm"))
        .context("the built bundle's wasm")?
        .len();
    let bundle: u64 = std::fs::read_dir(root().join("target/web"))?
        .filter_map(|e| e.ok()?.metadata().ok())
        .filter(|m| m.is_file())
        .map(|m| m.len())
        .sum();
    let gz = Command::new("gzip")
        .arg("-9c")
        .arg(root().join("target/web/grotto_web_bg.wasm"))
        .output()?
        .stdout
        .len();
    ctx.table(&format!(
        "| package bytes | before the first frame | requests | first frame | bundle | wasm | wasm gzip -9 |\n|---:|---:|---:|---:|---:|---:|---:|\n| {} | {} | {} | {:.1} s | {} | {} | {} |",
        thousands(total as u64),
        thousands(first as u64),
        r["requests"],
        num(&r, "first_frame_ms") / 1e3,
        thousands(bundle),
        thousands(wasm_bytes),
        thousands(gz as u64)
    ))?;
    Ok(vec![
        ctx.figure(
            "web-first-bytes",
            BROWSER,
            "bytes before the first frame, demo",
            format!(
                "{} of {} ({:.2}%), {} requests",
                thousands(first as u64),
                thousands(total as u64),
                100.0 * first / total,
                r["requests"]
            ),
            "web.md, \"What a visitor downloads before the first frame\"",
        ),
        ctx.figure(
            "web-bundle",
            BROWSER,
            "the viewer bundle (wasm + JS)",
            format!("{:.2} MB; the wasm {:.2} MB with `gzip -9`", bundle as f64 / 1e6, gz as f64 / 1e6),
            "web.md, the same",
        ),
    ])
}

/// The demo page at 800x600 with a 60 fps target, W held for 60 s after its first frames.
pub(crate) fn frames(ctx: &Ctx) -> Result<Vec<Figure>> {
    build_bundle(ctx)?;
    let pkg = ctx.demo()?;
    let env = [("GROTTO_WEB_BENCH_SIZE", "800x600".to_owned()), ("GROTTO_WEB_BENCH_MOVE_S", "60".to_owned())];
    let r = measure(ctx, "frame_times_while_moving", &pkg, &env)?;
    ctx.table(&format!(
        "| frames | median ms | p95 ms | worst ms | traded at the end |\n|---:|---:|---:|---:|---|\n| {} | {:.0} | {:.0} | {:.0} | {} |",
        r["frames"],
        num(&r, "median_ms"),
        num(&r, "p95_ms"),
        num(&r, "worst_ms"),
        r["traded"]
    ))?;
    Ok(vec![ctx.figure(
        "web-moving",
        BROWSER,
        "moving frames, demo cave at 800x600, 60 fps target",
        format!("median {:.0} ms, p95 {:.0} ms", num(&r, "median_ms"), num(&r, "p95_ms")),
        "\"Surfel chunks, level of detail and a frame-time target\"",
    )])
}

/// The demo page's memory over 30 minutes of its tour played round and round
/// (`GROTTO_WEB_BENCH_MINUTES` shortens it for a try).
pub(crate) fn memory(ctx: &Ctx) -> Result<Vec<Figure>> {
    build_bundle(ctx)?;
    let pkg = ctx.demo()?;
    let minutes = std::env::var("GROTTO_WEB_BENCH_MINUTES").unwrap_or_else(|_| "30".into());
    let r = measure(ctx, "memory_over_a_tour_loop", &pkg, &[("GROTTO_WEB_BENCH_MINUTES", minutes)])?;
    let pair = |k: &str| {
        format!("{:.0} / {:.0}", num(&r, &format!("{k}.first_loop")), num(&r, &format!("{k}.largest_after")))
    };
    ctx.table(&format!(
        "| minutes | loops | JS heap MB, first loop / largest after | wasm MB | GPU MB |\n|---:|---:|---|---|---|\n| {} | {} | {} | {} | {} |",
        r["minutes"],
        r["loops"],
        pair("js_heap_mb"),
        pair("wasm_mb"),
        pair("gpu_mb")
    ))?;
    Ok(vec![ctx.figure(
        "web-long-visit",
        BROWSER,
        "memory over a long visit, demo (tour loop)",
        format!("wasm {} MB, GPU {} MB (first loop / largest after)", pair("wasm_mb"), pair("gpu_mb")),
        "web.md, \"A long visit\"",
    )])
}
