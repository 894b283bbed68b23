//! `grotto bench`: every pass timed on a package, or light edits redone in place.

use std::path::PathBuf;
use std::process::ExitCode;

use crate::render::{RenderArgs, options};

#[derive(clap::Args, Debug)]
pub(crate) struct BenchArgs {
    #[command(flatten)]
    pub(crate) render: RenderArgs,
    /// Repetitions (the median is reported).
    #[arg(long, default_value_t = 3)]
    pub(crate) reps: u32,
    /// Instead of pass times: what light edits cost. Each `[[light]]` of this lighting file is
    /// added to the scene's lights and removed again, each change settled (in place where it
    /// fits), then every light is relit for comparison: wall time, bounces, leaves, faces.
    #[arg(long, value_name = "FILE.toml")]
    pub(crate) edit_lights: Option<PathBuf>,
}

pub(crate) fn bench(b: BenchArgs) -> anyhow::Result<ExitCode> {
    anyhow::ensure!(
        b.render.supersample == 1,
        "--supersample is for grotto render (bench the larger --size instead)"
    );
    anyhow::ensure!(
        b.render.time_budget.is_none(),
        "--time-budget is for grotto render; bench times a preset's passes (--quality)"
    );
    let opts = options(&b.render)?;
    if let Some(file) = &b.edit_lights {
        return bench_edits(&opts, file, (b.render.json, b.render.explain));
    }
    let report = grotto_runtime::cli::bench_job::bench(&opts, b.reps)?;
    if b.render.json {
        println!("{}", serde_json::to_string_pretty(&report)?);
    } else {
        println!(
            "{} on {} ({}): {} tiles, depth {}, {} leaves, {} nodes, {} surfels, {} lights, {}x{}",
            report.package,
            report.device,
            if report.timestamps { "GPU timestamps" } else { "CPU wall" },
            report.tiles,
            report.max_depth,
            report.leaves,
            report.nodes,
            report.surfels,
            report.lights,
            report.width,
            report.height
        );
        let count = |v: Option<u64>| v.map_or_else(|| "-".to_string(), |n| n.to_string());
        println!(
            "  {:10} {:>10}  {:>6} {:>10} {:>12} {:>12} {:>12} {:>12}",
            "pass", "ms", "draws", "surfels", "vertices", "primitives", "fragments", "invocations"
        );
        for (pass, ms) in &report.median_ms {
            let w = report.work.get(pass).copied().unwrap_or_default();
            println!(
                "  {pass:10} {ms:10.2}  {:>6} {:>10} {:>12} {:>12} {:>12} {:>12}",
                w.draws,
                w.surfels,
                count(w.vertex_invocations),
                count(w.primitives_out),
                count(w.fragment_invocations),
                count(w.compute_invocations)
            );
        }
        println!(
            "  a repetition: {} submits, {} bytes written to GPU buffers",
            report.submits, report.upload_bytes
        );
    }
    Ok(ExitCode::SUCCESS)
}

fn bench_edits(
    opts: &grotto_runtime::engine::RenderOptions,
    file: &std::path::Path,
    (json, explain): (bool, bool),
) -> anyhow::Result<ExitCode> {
    let report = grotto_runtime::cli::bench_job::bench_light_edits(opts, file)?;
    if json {
        println!("{}", serde_json::to_string_pretty(&report)?);
    } else {
        print!("{}", report.table(explain));
    }
    Ok(ExitCode::SUCCESS)
}
