//! `grotto map` at survey scale: the synthetic survey's centreline (`cave.svx`, written by
//! `grotto-pack synth`) compiled by Survex's `cavern`, and the maps drawn from the 10^7- and
//! 10^8-point packages: wall time, process peak, what was drawn and how the stations fit.

use std::process::{Command, Stdio};

use anyhow::{Context, Result, bail};

use crate::figures::Figure;
use crate::runner::{Ctx, num};

const MIB: f64 = 1048576.0;

/// The maps of the 10^7- and 10^8-point surveys.
pub(crate) fn survey(ctx: &Ctx) -> Result<Vec<Figure>> {
    let mut table = "| points | tiles | stations | cross-sections | plan px | elevation px | scale | wall s | process peak MiB | stations outside the passage |\n|---:|---:|---:|---:|---|---|---|---:|---:|---:|".to_owned();
    let mut figures = Vec::new();
    for (points, size, label) in [(10_000_000u64, "1e7", "10^7"), (100_000_000, "1e8", "10^8")] {
        let name = format!("survey-{size}");
        let pkg = super::gpu::survey(ctx, points, &name)?;
        let svx = ctx.work.join(&name).join("cave.svx");
        let compiled = ctx.work.join(&name).join("cave.3d");
        if !svx.exists() {
            bail!(
                "{}: no cave.svx (written by an older grotto-pack synth); remove {} to write the survey again",
                svx.display(),
                ctx.work.join(&name).display()
            );
        }
        if !compiled.exists() {
            let out = Command::new("cavern")
                .arg(format!("--output={}/", ctx.work.join(&name).display()))
                .arg(&svx)
                .stdout(Stdio::null())
                .output()
                .context("cavern (Debian package survex; scripts/test.sh installs it)")?;
            if !out.status.success() {
                bail!("cavern {}: {}", svx.display(), String::from_utf8_lossy(&out.stderr));
            }
        }
        let mut cmd = ctx.grotto();
        cmd.arg("map")
            .arg(&pkg)
            .arg("--survey")
            .arg(&compiled)
            .arg("--out")
            .arg(ctx.out.join(format!("map-{size}")));
        cmd.arg("--json");
        let t = std::time::Instant::now();
        let (r, peak) = ctx.json_peak(&format!("map-{size}"), &mut cmd)?;
        let wall = t.elapsed().as_secs_f64();
        let stations = r["stations"].as_array().context("no stations")?;
        let traced = stations.iter().filter(|s| !s["section"].is_null()).count();
        let outside = stations.iter().filter(|s| s["inside"] == serde_json::Value::Bool(false)).count();
        table += &format!(
            "\n| {label} | {} | {} | {traced} | {} x {} | {} x {} | 1:{} | {wall:.1} | {:.0} | {outside} |",
            r["tiles"],
            stations.len(),
            r["plan"]["width_px"],
            r["plan"]["height_px"],
            r["elevation"]["width_px"],
            r["elevation"]["height_px"],
            r["scale"],
            peak as f64 / MIB
        );
        figures.push(ctx.figure(
            &format!("map-{size}"),
            "software",
            &format!(
                "`grotto map` of {label} points (plan, extended elevation, cross-sections, passages.csv)"
            ),
            format!(
                "{wall:.1} s, peak {:.0} MiB, {:.1} M points/s",
                peak as f64 / MIB,
                num(&r, "points") / wall / 1e6
            ),
            "\"Survey maps\"",
        ));
    }
    ctx.table(&table)?;
    Ok(figures)
}
