//! What a viewer's process holds: `grotto render` and `grotto view` of a 10^7-point survey under a
//! GPU memory budget, their peak resident memory (on a software adapter the GPU's buffers are in
//! the process too), for one frame, along a path that streams tiles in and out, and over a flight
//! in the window.

use anyhow::{Context, Result};

use crate::figures::Figure;
use crate::runner::{Ctx, num};

const MIB: f64 = 1048576.0;

/// `grotto render` of the 10^7-point survey under `--gpu-memory 256M` at 320x240, fast preset:
/// its entrance camera alone, and the entrance -> chamber path in 6 frames.
pub(crate) fn render(ctx: &Ctx) -> Result<Vec<Figure>> {
    let manifest = ctx.synth("survey-1e7", 10_000_000, &[])?;
    let work = ctx.work.join("build-survey-1e7");
    let pkg = ctx.package("survey-1e7", &manifest, &["--work-dir", work.to_str().context("work folder")?])?;
    let mut table = "| run | frames | tiles full / coarse / far (last frame) | tiles loaded | GPU pools MiB | process peak MiB | wall s |\n|---|---:|---|---:|---:|---:|---:|".to_owned();
    let mut peaks = Vec::new();
    for (name, view) in [
        ("one frame", &["--camera", "entrance"][..]),
        ("6-frame path", &["--path", "entrance,chamber", "--frames", "6"][..]),
    ] {
        let mut cmd = ctx.grotto();
        cmd.arg("render").arg(&pkg).args(view).args([
            "--size",
            "320x240",
            "--quality",
            "fast",
            "--gpu-memory",
            "256M",
            "--json",
            "-o",
        ]);
        cmd.arg(ctx.out.join(format!("{}.png", name.replace(' ', "-"))));
        let t = std::time::Instant::now();
        let (r, peak) = ctx.json_peak(&format!("render-{}", name.replace(' ', "-")), &mut cmd)?;
        let wall = t.elapsed().as_secs_f64();
        let frames = r["frames"].as_array().context("no frames")?;
        let last = frames.last().context("no frames")?;
        let loaded: u64 = frames.iter().map(|f| f["loaded"].as_u64().unwrap_or(0)).sum();
        table += &format!(
            "\n| {name} | {} | {} / {} / {} | {loaded} | {:.0} | {:.0} | {wall:.1} |",
            frames.len(),
            last["full_tiles"],
            last["coarse_tiles"],
            last["far_tiles"],
            num(&frames[0], "pool_bytes") / MIB,
            peak as f64 / MIB
        );
        peaks.push(peak as f64 / MIB);
    }
    ctx.table(&table)?;
    // The window at 640x480 under the same budget, flown through the tiles.
    let (view, view_peak) =
        super::window::flight_peak(ctx, &pkg, "view", &["--gpu-memory", "256M", "--quality", "fast"])?;
    let moving = view["log"]["moving_ms"].as_array().map_or(0, Vec::len);
    ctx.table(&format!(
        "`grotto view` under --gpu-memory 256M, 640x480, 40 s of flight: {moving} moving frames, {} tile swaps, process peak {:.0} MiB",
        view["tile_swaps"],
        view_peak as f64 / MIB
    ))?;
    Ok(vec![ctx.figure(
        "memory-render-1e7",
        "software",
        "`grotto render` (320x240) and `grotto view` (640x480, 40 s of flight) of 10^7 points under `--gpu-memory 256M`: process peak",
        format!(
            "render {:.0} MiB one frame, {:.0} MiB along a 6-frame path; view {:.0} MiB",
            peaks[0],
            peaks[1],
            view_peak as f64 / MIB
        ),
        "\"A viewer's process memory\"",
    )])
}
