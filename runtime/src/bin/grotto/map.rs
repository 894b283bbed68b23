//! `grotto map`: the command line over [`grotto_runtime::cli::map`].

use std::path::PathBuf;
use std::process::ExitCode;

use grotto_format::Package;
use grotto_runtime::cli::map::{MapOptions, map};

/// Draw survey maps from a package (or a scan) and a cave survey: a plan and an extended
/// elevation of the scanned walls with the centreline, station names, a grid in survey
/// coordinates, a scale bar and a north arrow (PNG, and SVG with the overlay as vectors); a
/// cross-section at each station (SVG); and DIR/passages.csv with each station's position,
/// passage width, height and area, and the surveyed length. Each station is checked against the
/// scans (in the passage or not, how far from its middle).
#[derive(clap::Args, Debug)]
pub(crate) struct MapArgs {
    /// A .grotto package, or a scan (LAS/LAZ, PLY, E57), packed first as `grotto render` does.
    package: PathBuf,
    /// The survey: a Survex .3d file (cavern writes one) or a Compass .plt file. Default: the
    /// survey stored in the package (`[survey]` in its manifest).
    #[arg(long)]
    survey: Option<PathBuf>,
    /// The folder to write into (created where missing).
    #[arg(long)]
    out: PathBuf,
    /// The map scale, 1:N (`1:200`) or N. Default: the largest of 1:50, 1:100, 1:200, 1:250,
    /// 1:500, 1:1000... whose plan fits --max-px.
    #[arg(long, value_parser = parse_scale)]
    scale: Option<u32>,
    /// Printed resolution: at 1:200 and 150 dpi a pixel is 3.4 cm of cave.
    #[arg(long, default_value_t = 150.0)]
    dpi: f64,
    /// The longest side a picture may have, pixels.
    #[arg(long, default_value_t = 8192)]
    max_px: u32,
    /// Half the thickness of the slab of scanned points a cross-section is traced from, metres.
    #[arg(long, default_value_t = 0.1)]
    slab: f64,
    /// How far from the centreline a scanned point may lie and still belong to its passage, metres.
    #[arg(long, default_value_t = 10.0)]
    reach: f64,
    /// Machine-readable output.
    #[arg(long)]
    json: bool,
}

fn parse_scale(s: &str) -> Result<u32, String> {
    let n = s.strip_prefix("1:").unwrap_or(s).trim();
    match n.parse::<u32>() {
        Ok(n) if n > 0 => Ok(n),
        _ => Err(format!("{s:?} is not a map scale: give 1:N, for example 1:200")),
    }
}

pub(crate) fn run(a: MapArgs) -> anyhow::Result<ExitCode> {
    let package = grotto_runtime::cli::scan_input::package_for(&a.package, |m| eprintln!("{m}"))?;
    let pkg = Package::open(&package)?;
    let (survey, from) = match &a.survey {
        Some(path) => (grotto_format::survey::read(path)?, path.display().to_string()),
        None => match pkg.survey()? {
            Some(s) => (s, format!("{} (its survey)", package.display())),
            None => anyhow::bail!(
                "{}: holds no survey; give one with --survey FILE (.3d or .plt), or build the package with [survey] in its manifest",
                package.display()
            ),
        },
    };
    let opts = MapOptions {
        out_dir: a.out.clone(),
        scale: a.scale,
        dpi: a.dpi,
        max_px: a.max_px,
        slab_m: a.slab,
        reach_m: a.reach,
    };
    let bar = indicatif::ProgressBar::new(u64::from(pkg.tile_count())).with_style(
        indicatif::ProgressStyle::with_template("{spinner} reading tiles {pos}/{len} [{elapsed_precise}]")
            .unwrap_or_else(|_| indicatif::ProgressStyle::default_bar()),
    );
    let summary = map(&pkg, &survey, &from, &opts, &|done, _| bar.set_position(u64::from(done)))?;
    bar.finish_and_clear();
    if a.json {
        println!("{}", serde_json::to_string_pretty(&summary)?);
    } else {
        println!(
            "{} points from {} tiles in {:.1} s; plan {} x {} px and extended elevation {} x {} px at 1:{} ({:.1} cm a pixel)",
            summary.points,
            summary.tiles,
            summary.seconds,
            summary.plan.width_px,
            summary.plan.height_px,
            summary.elevation.width_px,
            summary.elevation.height_px,
            summary.scale,
            summary.m_per_px * 100.0
        );
        let traced = summary.stations.iter().filter(|s| s.section.is_some()).count();
        println!(
            "{} stations, {traced} cross-sections; surveyed length {:.1} m; wrote {}, {}, {}",
            summary.stations.len(),
            summary.surveyed_length_m,
            summary.plan.svg,
            summary.elevation.svg,
            summary.passages_csv
        );
        for w in &summary.warnings {
            eprintln!("warning: {w}");
        }
        let untraced: Vec<_> =
            summary.stations.iter().filter_map(|s| Some((&s.station, s.no_section.as_ref()?))).collect();
        for (name, why) in untraced.iter().take(10) {
            println!("no cross-section at {name}: {why}");
        }
        if untraced.len() > 10 {
            println!("... and at {} more stations (--json has each)", untraced.len() - 10);
        }
    }
    Ok(ExitCode::SUCCESS)
}
