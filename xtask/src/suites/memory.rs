//! What a viewer's process holds: `grotto render` and `grotto view` of a 10^7- or 10^8-point survey under a
//! GPU memory budget, their peak resident memory (on a software adapter the GPU's buffers are in
//! the process too), for one frame, along a path that streams tiles in and out, and over a flight
//! in the window.

use anyhow::{Context, Result};

use crate::figures::Figure;
use crate::runner::{Ctx, num};

const MIB: f64 = 1048576.0;

/// `grotto render` of the 10^7-point survey at 320x240, fast preset, its entrance camera alone and
/// the entrance -> chamber path in 6 frames, and `grotto view` flown through it: under
/// `--gpu-memory 256M` (the tile pools alone), then under `--memory phone` (one budget for the
/// process and the GPU together, 512 MiB: on a software adapter the GPU's buffers are the
/// process's, as on a phone's shared memory).
pub(crate) fn render(ctx: &Ctx) -> Result<Vec<Figure>> {
    peaks(ctx, 10_000_000, "1e7")
}

/// As [`render`], of the 10^8-point survey: the same budgets hold at ten times the points.
pub(crate) fn render_1e8(ctx: &Ctx) -> Result<Vec<Figure>> {
    peaks(ctx, 100_000_000, "1e8")
}

fn peaks(ctx: &Ctx, points: u64, size: &str) -> Result<Vec<Figure>> {
    let pkg = super::gpu::survey(ctx, points, &format!("survey-{size}"))?;
    let mut table = "| budget | run | frames | tiles full / coarse / far (last frame) | tiles loaded | GPU pools MiB | process peak MiB | wall s |\n|---|---|---:|---|---:|---:|---:|---:|".to_owned();
    let mut figures = Vec::new();
    for (key, budget) in
        [("memory-render", &["--gpu-memory", "256M"][..]), ("memory-phone", &["--memory", "phone"][..])]
    {
        let flag = budget.join(" ");
        let mut peaks = Vec::new();
        for (name, view) in [
            ("one frame", &["--camera", "entrance"][..]),
            ("6-frame path", &["--path", "entrance,chamber", "--frames", "6"][..]),
        ] {
            let mut cmd = ctx.grotto();
            cmd.arg("render").arg(&pkg).args(view).args(budget).args([
                "--size",
                "320x240",
                "--quality",
                "fast",
                "--json",
                "-o",
            ]);
            let label = format!("{size}-{}-{}", budget[1], name.replace(' ', "-"));
            cmd.arg(ctx.out.join(format!("{label}.png")));
            let t = std::time::Instant::now();
            let (r, peak) = ctx.json_peak(&format!("render-{label}"), &mut cmd)?;
            let wall = t.elapsed().as_secs_f64();
            let frames = r["frames"].as_array().context("no frames")?;
            let last = frames.last().context("no frames")?;
            let loaded: u64 = frames.iter().map(|f| f["loaded"].as_u64().unwrap_or(0)).sum();
            table += &format!(
                "\n| `{flag}` | {name} | {} | {} / {} / {} | {loaded} | {:.0} | {:.0} | {wall:.1} |",
                frames.len(),
                last["full_tiles"],
                last["coarse_tiles"],
                last["far_tiles"],
                num(&frames[0], "pool_bytes") / MIB,
                peak as f64 / MIB
            );
            peaks.push(peak as f64 / MIB);
        }
        // The window at 640x480 under the same budget, flown through the tiles.
        let mut extra = budget.to_vec();
        extra.extend(["--quality", "fast"]);
        let (view, view_peak) =
            super::window::flight_peak(ctx, &pkg, &format!("view-{size}-{}", budget[1]), &extra)?;
        let moving = view["log"]["moving_ms"].as_array().map_or(0, Vec::len);
        table += &format!(
            "\n| `{flag}` | `grotto view` 640x480, 40 s of flight | {moving} moving | | {} swaps | | {:.0} | |",
            view["tile_swaps"],
            view_peak as f64 / MIB
        );
        let points_label = if size == "1e7" { "10^7" } else { "10^8" };
        figures.push(ctx.figure(
            &format!("{key}-{size}"),
            "software",
            &format!(
                "`grotto render` (320x240) and `grotto view` (640x480, 40 s of flight) of {points_label} points under `{flag}`: process peak"
            ),
            format!(
                "render {:.0} MiB one frame, {:.0} MiB along a 6-frame path; view {:.0} MiB",
                peaks[0],
                peaks[1],
                view_peak as f64 / MIB
            ),
            "\"A viewer's process memory\"",
        ));
    }
    ctx.table(&table)?;
    Ok(figures)
}
