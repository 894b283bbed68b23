//! `grotto-pack`: builds `.grotto` packages from registered scans.

use std::path::{Path, PathBuf};
use std::sync::Mutex;
use std::time::Duration;

use anyhow::{Context, bail};
use clap::{Args, Parser, Subcommand};
use grotto_preprocess::build::{self, BuildParams, BuildSummary, ColorCodec, SurfelCodec};
use grotto_preprocess::ingest::ScanFormat;
use grotto_preprocess::manifest::{Manifest, SeenFrom};
use grotto_preprocess::profile::{Stage, StageTime};
use grotto_preprocess::synth::{self, SynthParams};
use grotto_preprocess::tiling::Progress;
use indicatif::{MultiProgress, ProgressBar, ProgressDrawTarget, ProgressStyle};

#[derive(Parser, Debug)]
#[command(name = "grotto-pack", version, about = "Build .grotto cave packages from registered scans")]
struct Cli {
    #[command(subcommand)]
    command: Command,
}

#[derive(Subcommand, Debug)]
enum Command {
    /// Build a package from a manifest (.toml, or a Stanford .conf) or from scan files (identity poses).
    Build {
        /// MANIFEST.toml | registration.conf | FILE...
        #[arg(required = true)]
        inputs: Vec<PathBuf>,
        /// Output package.
        #[arg(short, long)]
        out: PathBuf,
        #[command(flatten)]
        opts: BuildOpts,
    },
    /// Cluster step 1 of 3: tile the scans into the work directory (same options as build).
    Plan {
        #[arg(required = true)]
        inputs: Vec<PathBuf>,
        #[command(flatten)]
        opts: BuildOpts,
    },
    /// Cluster step 2 of 3: build the tiles of one shard (run one job per shard, e.g. a Slurm array).
    BuildTile {
        #[arg(required = true)]
        inputs: Vec<PathBuf>,
        /// This job's share, I/N: tiles whose index % N == I (default 0/1: all tiles).
        #[arg(long, default_value = "0/1")]
        shard: String,
        #[command(flatten)]
        opts: BuildOpts,
    },
    /// Cluster step 3 of 3: assemble the built tiles into the package.
    Assemble {
        #[arg(required = true)]
        inputs: Vec<PathBuf>,
        #[arg(short, long)]
        out: PathBuf,
        #[command(flatten)]
        opts: BuildOpts,
    },
    /// Write a synthetic cave (scans in LAS, LAZ, PLY and E57, and DIR/manifest.toml).
    Synth {
        /// Output directory.
        #[arg(long)]
        out: PathBuf,
        #[command(flatten)]
        synth: SynthOpts,
        /// Print the summary as JSON.
        #[arg(long)]
        json: bool,
    },
    /// Measure ingest throughput per format on one synthetic scan (written once into DIR).
    BenchIngest {
        /// Directory for the test files (about 100 bytes per point over the four formats).
        #[arg(long)]
        dir: PathBuf,
        #[arg(long, default_value_t = 10_000_000)]
        points: u64,
        #[arg(long)]
        json: bool,
    },
    /// Measure normal accuracy (against the synthetic cave's analytic surface) and the speed of
    /// normal estimation and SVO construction.
    BenchNormals {
        /// Directory for the synthetic scans (kept and reused).
        #[arg(long)]
        dir: PathBuf,
        #[arg(long, default_value_t = 1_000_000)]
        points: u64,
        /// Range-noise multipliers to test.
        #[arg(long, value_delimiter = ',', default_value = "1")]
        noise: Vec<f64>,
        /// Neighbour counts to test.
        #[arg(long, value_delimiter = ',', default_value = "16")]
        k: Vec<usize>,
        #[arg(long)]
        threads: Option<usize>,
        /// Also write the cloud with its true normals (PLY) for other tools.
        #[arg(long)]
        export: Option<PathBuf>,
        /// Also time and score orientation without scanner positions (the scans taken as one
        /// merged cloud): the occupancy grid and the enclosure votes.
        #[arg(long)]
        bare: bool,
        #[arg(long)]
        json: bool,
    },
    /// Measure BC1 colours against raw ones on packages built with --colors raw: each encoder
    /// (bc1, the default; bc1-fast; bc1-cluster), its PSNR, largest error and encoding time.
    BenchBc1 {
        packages: Vec<PathBuf>,
        #[arg(long)]
        json: bool,
    },
    /// Measure format 2.0's compact surfels on packages built with --surfels full: bytes per point,
    /// the position, normal, radius and spread errors, and the time to encode and decode them.
    BenchEncoding {
        packages: Vec<PathBuf>,
        #[arg(long)]
        json: bool,
    },
    /// The main job on the built-in demo scene: synthesise a cave into DIR/demo-scans and build DIR/demo.grotto
    /// (with 6.25 cm leaves unless --leaf-m gives a number).
    Demo {
        /// Output directory.
        #[arg(long, default_value = "out")]
        out: PathBuf,
        #[command(flatten)]
        synth: SynthOpts,
        #[command(flatten)]
        opts: BuildOpts,
    },
}

#[derive(Args, Debug)]
struct SynthOpts {
    /// Approximate number of points over all scans (10^4 to 10^8 and more).
    #[arg(long, default_value_t = 400_000)]
    points: u64,
    /// Seed of the cave layout and the scanner noise.
    #[arg(long, default_value_t = 7)]
    seed: u64,
    /// Main passage segments (4 m each).
    #[arg(long, default_value_t = 24)]
    segments: usize,
    /// Scan formats, assigned to scans in turn.
    #[arg(long, value_delimiter = ',', default_value = "las,laz,ply,e57")]
    formats: Vec<String>,
}

#[derive(Args, Debug)]
struct BuildOpts {
    /// Work directory for tile bins (kept for resume). Default: OUT's name + ".work".
    #[arg(long)]
    work_dir: Option<PathBuf>,
    /// Memory budget, e.g. 2G, 512M.
    #[arg(long, default_value = "2G")]
    memory_budget: String,
    /// Worker threads (default: all cores). Changes how fast the build runs, never the package.
    #[arg(long)]
    threads: Option<usize>,
    /// Split a tile while it holds more points than this (down to --min-tile-m). Part of the
    /// package's content, with the same default everywhere; the memory budget bounds how many
    /// tiles are built at once (each takes about 256 bytes a point).
    #[arg(long, default_value_t = grotto_preprocess::build::DEFAULT_MAX_TILE_POINTS)]
    max_tile_points: u64,
    /// Leaf voxel edge, metres (a power of two, at most --min-tile-m), or "auto": the smallest
    /// power of two at or above the median point spacing of the scans, at least 0.0625.
    #[arg(long, default_value = "auto")]
    leaf_m: String,
    /// Surfel colour storage: bc1 (0.5 byte per point: Intel's ISPC kernel, then cluster fit for
    /// the blocks it leaves visibly off), bc1-fast (ISPC alone: fastest, 0.3-0.6 dB less PSNR),
    /// bc1-cluster (cluster fit alone: best PSNR, slowest) or raw (4 bytes).
    #[arg(long, default_value = "bc1", value_parser = ["bc1", "bc1-fast", "bc1-cluster", "raw"])]
    colors: String,
    /// Surfel storage: compact (format 2.0, about 6 bytes a point: positions within 1 mm, normals
    /// within 0.05 degrees) or full (f32, 32 bytes a point; the package stays format 1.2).
    #[arg(long, default_value = "compact", value_parser = ["compact", "full"])]
    surfels: String,
    /// Neighbours for normal estimation.
    #[arg(long, default_value_t = 16)]
    k: usize,
    /// Normals the scan files carry (PLY nx/ny/nz, LAS extra bytes NormalX/nx...): keep them where they agree with the points'
    /// local plane (within 60 degrees; oriented like estimated ones), or estimate every normal.
    #[arg(long, default_value = "keep", value_parser = ["keep", "estimate"])]
    normals: String,
    /// Where scans without a scanner position (bare files, merged clouds) were taken from: inside
    /// (a cave: normals face the passage its walls enclose) or outside (an object scanned from
    /// around it). A manifest's `seen_from` for a scan wins; scans with a scanner use it.
    #[arg(long, value_enum, default_value_t = SeenFrom::Inside)]
    seen_from: SeenFrom,
    /// Smallest tile edge, metres (power of two; default 16 leaves: 1 m at 6.25 cm leaves).
    #[arg(long)]
    min_tile_m: Option<f64>,
    /// Largest tile edge, metres (power of two; default 1024 leaves: 64 m at 6.25 cm leaves).
    #[arg(long)]
    max_tile_m: Option<f64>,
    /// Halo shared with neighbour tiles, metres (default 4 leaves: 0.25 m at 6.25 cm leaves).
    #[arg(long)]
    halo_m: Option<f64>,
    /// Keep the environment's SH unwindowed even where a bright source makes irradiance ring negative.
    #[arg(long)]
    no_sh_window: bool,
    /// Refuse a LAS file that ends inside its last point record (by default its complete records
    /// are read and the summary warns).
    #[arg(long)]
    strict: bool,
    /// Decode every scan twice (count, then distribute) rather than keeping the count pass's
    /// posed points in WORK/spill (15-21 bytes a point, removed once the bins are written): for a
    /// work disk too small to hold them beside the bins.
    #[arg(long)]
    no_spill: bool,
    /// Remove the work directory after a successful build.
    #[arg(long)]
    clean: bool,
    /// Print the summary as JSON (no progress bars).
    #[arg(long)]
    json: bool,
}

fn parse_bytes(s: &str) -> anyhow::Result<u64> {
    grotto_format::parse_bytes(s).map_err(|e| anyhow::anyhow!("memory budget {e}"))
}

fn parse_formats(names: &[String]) -> anyhow::Result<Vec<ScanFormat>> {
    names
        .iter()
        .map(|n| match n.to_ascii_lowercase().as_str() {
            "las" => Ok(ScanFormat::Las),
            "laz" => Ok(ScanFormat::Laz),
            "ply" => Ok(ScanFormat::Ply),
            "e57" => Ok(ScanFormat::E57),
            other => bail!("unknown format '{other}' (las, laz, ply, e57)"),
        })
        .collect()
}

/// Progress bars per stage, hidden for --json or when stderr is not a terminal.
struct Bars {
    multi: MultiProgress,
    bars: Mutex<Vec<(&'static str, ProgressBar)>>,
}

impl Bars {
    fn new(hidden: bool) -> Self {
        let multi = MultiProgress::with_draw_target(if hidden {
            ProgressDrawTarget::hidden()
        } else {
            ProgressDrawTarget::stderr()
        });
        Self { multi, bars: Mutex::new(Vec::new()) }
    }

    fn update(&self, p: Progress) {
        let mut bars = self.bars.lock().expect("progress lock");
        if let Some((_, bar)) = bars.iter().find(|(s, _)| *s == p.stage) {
            bar.set_length(p.total.max(p.done));
            bar.set_position(p.done);
            return;
        }
        let unit = if matches!(p.stage, "tiles" | "levels" | "assemble") { "tiles" } else { "points" };
        let bar = self.multi.add(ProgressBar::new(p.total.max(p.done)));
        bar.set_style(
            ProgressStyle::with_template(&format!(
                "{{prefix:>10}} [{{bar:30}}] {{human_pos}}/{{human_len}} {unit} {{per_sec}} {{eta}}"
            ))
            .expect("template")
            .progress_chars("=> "),
        );
        bar.set_prefix(p.stage);
        bar.enable_steady_tick(Duration::from_millis(200));
        bar.set_position(p.done);
        bars.push((p.stage, bar));
    }

    fn finish(&self) {
        for (_, b) in self.bars.lock().expect("progress lock").iter() {
            b.finish();
        }
    }
}

/// The manifest and build parameters the build, plan, build-tile and assemble commands share.
fn setup(
    inputs: &[PathBuf],
    out: Option<&Path>,
    opts: &BuildOpts,
) -> anyhow::Result<(Manifest, PathBuf, BuildParams)> {
    let (mut manifest, manifest_path) = match inputs {
        [one] if matches!(one.extension().and_then(|e| e.to_str()), Some("toml" | "conf")) => {
            (Manifest::load(one)?, one.clone())
        }
        files => (Manifest::from_files(files), PathBuf::from("<command line>")),
    };
    manifest.default_seen_from(opts.seen_from);
    let work_dir = match (&opts.work_dir, out) {
        (Some(dir), _) => dir.clone(),
        (None, Some(out)) => {
            let mut name = out.file_name().map(|n| n.to_os_string()).unwrap_or_default();
            name.push(".work");
            out.with_file_name(name)
        }
        (None, None) => bail!("--work-dir is required for the plan and build-tile steps"),
    };
    let leaf_m = match opts.leaf_m.as_str() {
        "auto" => {
            let auto = build::auto_leaf(&manifest.resolve()?)?;
            if !opts.json {
                match auto.spacing_m {
                    Some(s) => println!(
                        "leaf {} m (auto: median point spacing {s:.4} m over {} points; --leaf-m to choose)",
                        auto.leaf_m, auto.sampled_points
                    ),
                    None => {
                        println!("leaf {} m (auto: too few points to measure their spacing)", auto.leaf_m)
                    }
                }
            }
            auto.leaf_m
        }
        v => v
            .parse::<f64>()
            .map_err(|e| anyhow::anyhow!("--leaf-m {v:?}: a number of metres or auto ({e})"))?,
    };
    let defaults = BuildParams::with_leaf(work_dir, leaf_m);
    let params = BuildParams {
        memory_budget_bytes: parse_bytes(&opts.memory_budget)?,
        threads: opts.threads.unwrap_or(defaults.threads),
        max_tile_points: opts.max_tile_points,
        colors: match opts.colors.as_str() {
            "raw" => ColorCodec::Raw,
            "bc1-fast" => ColorCodec::Bc1Fast,
            "bc1-cluster" => ColorCodec::Bc1Cluster,
            _ => ColorCodec::Bc1,
        },
        surfels: if opts.surfels == "full" { SurfelCodec::Full } else { SurfelCodec::Compact },
        sh_window: !opts.no_sh_window,
        k: opts.k,
        min_tile_extent_m: opts.min_tile_m.unwrap_or(defaults.min_tile_extent_m),
        max_tile_extent_m: opts.max_tile_m.unwrap_or(defaults.max_tile_extent_m),
        halo_m: opts.halo_m.unwrap_or(defaults.halo_m),
        strict: opts.strict,
        spill: !opts.no_spill,
        keep_input_normals: opts.normals == "keep",
        ..defaults
    };
    Ok((manifest, manifest_path, params))
}

fn run_build(inputs: &[PathBuf], out: &Path, opts: &BuildOpts) -> anyhow::Result<BuildSummary> {
    let clock = std::time::Instant::now();
    let (manifest, manifest_path, params) = setup(inputs, Some(out), opts)?;
    // Part of what a user waits for (`--leaf-m auto` samples every scan), so part of the profile.
    let setup_s = clock.elapsed().as_secs_f64();
    let work_dir = params.work_dir.clone();
    let bars = Bars::new(opts.json);
    let mut summary = build::build(&manifest, &manifest_path, out, &params, &|p| bars.update(p))
        .with_context(|| format!("building {}", out.display()))?;
    bars.finish();
    summary.stages.insert(0, StageTime::of(Stage::Setup, setup_s));
    summary.steps.plan += setup_s;
    summary.seconds += setup_s;
    if opts.clean {
        std::fs::remove_dir_all(&work_dir).with_context(|| format!("removing {}", work_dir.display()))?;
    }
    Ok(summary)
}

fn print_build(summary: &BuildSummary, json: bool) -> anyhow::Result<()> {
    if json {
        println!("{}", serde_json::to_string_pretty(summary)?);
    } else {
        println!(
            "wrote {}: {} points from {} scans in {} tiles ({} halo copies, {} invalid points dropped), {:.2} MB in {:.1} s, peak memory {}{}",
            summary.package,
            summary.points,
            summary.scans,
            summary.tiles,
            summary.halo_points,
            summary.invalid_points,
            summary.bytes as f64 / 1e6,
            summary.seconds,
            summary.peak_rss_bytes.map_or_else(|| "unknown".into(), |b| format!("{:.0} MB", b as f64 / 1e6)),
            match (summary.resumed_tiling, summary.reused_tiles) {
                (false, 0) => String::new(),
                (r, n) =>
                    format!(" (resumed: tiling {}, {n} tiles kept)", if r { "reused" } else { "redone" }),
            }
        );
        let st = &summary.steps;
        println!(
            "time: plan {:.1} s, tiles {:.1} s, assemble {:.1} s; by stage:",
            st.plan, st.tiles, st.assemble
        );
        print_stages(&summary.stages);
        for hint in summary.hints() {
            println!("note: {hint}");
        }
    }
    Ok(())
}

/// The profile as an indented table; tile stages are summed over the tiles built at once.
fn print_stages(stages: &[StageTime]) {
    for s in stages {
        let per = if s.summed_over_tiles { " (summed over tiles)" } else { "" };
        println!("  {:<26} {:>9.2} s{per}", s.stage, s.seconds);
    }
}

fn run_synth(dir: &Path, s: &SynthOpts, quiet: bool) -> anyhow::Result<synth::SynthSummary> {
    let params =
        SynthParams { seed: s.seed, points: s.points, segments: s.segments, ..SynthParams::default() };
    let formats = parse_formats(&s.formats)?;
    let bar = if quiet { ProgressBar::hidden() } else { ProgressBar::new(0) };
    bar.set_style(
        ProgressStyle::with_template("{prefix:>10} [{bar:30}] {pos}/{len} scans {elapsed}")
            .expect("template"),
    );
    bar.set_prefix("synth");
    let summary = synth::write_dataset(dir, &params, &formats, &|done, total| {
        bar.set_length(total as u64);
        bar.set_position(done as u64);
    })
    .with_context(|| format!("writing the synthetic cave to {}", dir.display()))?;
    bar.finish();
    Ok(summary)
}

fn main() -> std::process::ExitCode {
    match run(Cli::parse()) {
        Ok(()) => std::process::ExitCode::SUCCESS,
        Err(e) => {
            // The error chain, not a backtrace: these are messages for people.
            eprintln!("error: {e:#}");
            std::process::ExitCode::FAILURE
        }
    }
}

fn run(cli: Cli) -> anyhow::Result<()> {
    match cli.command {
        Command::Build { inputs, out, opts } => {
            let summary = run_build(&inputs, &out, &opts)?;
            print_build(&summary, opts.json)?;
        }
        Command::Plan { inputs, opts } => run_plan(&inputs, &opts)?,
        Command::BuildTile { inputs, shard, opts } => run_build_tile(&inputs, &shard, &opts)?,
        Command::Assemble { inputs, out, opts } => {
            let (manifest, manifest_path, params) = setup(&inputs, Some(&out), &opts)?;
            let bars = Bars::new(opts.json);
            let summary = build::assemble(&manifest, &manifest_path, &out, &params, &|p| bars.update(p))
                .with_context(|| format!("assembling {}", out.display()))?;
            bars.finish();
            print_build(&summary, opts.json)?;
        }
        Command::Synth { out, synth, json } => {
            let summary = run_synth(&out, &synth, json)?;
            if json {
                println!("{}", serde_json::to_string_pretty(&summary)?);
            } else {
                println!(
                    "wrote {} scans, {} points, manifest {}",
                    summary.scans, summary.points, summary.manifest
                );
            }
        }
        Command::BenchIngest { dir, points, json } => {
            let figures = grotto_preprocess::bench::ingest(&dir, points, &|stage| {
                if !json {
                    eprintln!("{stage}...");
                }
            })?;
            print_ingest(&figures, json)?;
        }
        Command::BenchNormals { dir, points, noise, k, threads, export, bare, json } => {
            let threads =
                threads.unwrap_or_else(|| std::thread::available_parallelism().map_or(1, usize::from));
            let mut figures = Vec::new();
            for n in noise {
                figures.extend(grotto_preprocess::bench::normals(
                    &dir,
                    points,
                    n,
                    &k,
                    threads,
                    export.as_deref(),
                    bare,
                )?);
            }
            print_normals(&figures, json)?;
        }
        Command::BenchBc1 { packages, json } => {
            let figures =
                packages.iter().map(|p| grotto_preprocess::bench::bc1(p)).collect::<Result<Vec<_>, _>>()?;
            print_bc1(&figures, json)?;
        }
        Command::BenchEncoding { packages, json } => {
            let figures = packages
                .iter()
                .map(|p| grotto_preprocess::bench::encoding(p))
                .collect::<Result<Vec<_>, _>>()?;
            print_encoding(&figures, json)?;
        }
        Command::Demo { out, synth, opts } => run_demo(&out, &synth, opts)?,
    }
    Ok(())
}

/// `grotto-pack plan`: the plan step alone.
fn run_plan(inputs: &[PathBuf], opts: &BuildOpts) -> anyhow::Result<()> {
    let (manifest, _, params) = setup(inputs, None, opts)?;
    let bars = Bars::new(opts.json);
    let (plan, reused) = build::plan(&manifest, &params, &|p| bars.update(p))?;
    bars.finish();
    let summary = serde_json::json!({
        "work_dir": params.work_dir, "tiles": plan.tiles.len(), "points": plan.points,
        "halo_points": plan.halo_points, "invalid_points": plan.invalid_points, "reused": reused,
    });
    if opts.json {
        println!("{}", serde_json::to_string_pretty(&summary)?);
    } else {
        println!(
            "planned {} tiles for {} points in {}{}",
            plan.tiles.len(),
            plan.points,
            params.work_dir.display(),
            if reused { " (reused)" } else { "" }
        );
    }
    Ok(())
}

/// `grotto-pack build-tile --shard I/N`: the tiles of one shard.
fn run_build_tile(inputs: &[PathBuf], shard: &str, opts: &BuildOpts) -> anyhow::Result<()> {
    let (manifest, manifest_path, params) = setup(inputs, None, opts)?;
    let shard = match shard.split_once('/').map(|(i, n)| (i.parse::<usize>(), n.parse::<usize>())) {
        Some((Ok(index), Ok(count))) if index < count => build::Shard { index, count },
        _ => bail!("--shard '{shard}' is not I/N with I < N"),
    };
    let bars = Bars::new(opts.json);
    let stage = build::build_tiles(&manifest, &manifest_path, &params, shard, &|p| bars.update(p))?;
    bars.finish();
    if opts.json {
        println!("{}", serde_json::to_string_pretty(&stage)?);
    } else {
        println!(
            "shard {}/{} on {}: built {} tiles{}, {} already built, peak memory {} MB",
            shard.index,
            shard.count,
            stage.host,
            stage.built,
            match stage.built_tiles.len() {
                1..=16 => format!(
                    " ({})",
                    stage.built_tiles.iter().map(|t| t.to_string()).collect::<Vec<_>>().join(", ")
                ),
                _ => String::new(),
            },
            stage.reused,
            stage.peak_rss_bytes / 1_000_000
        );
        print_stages(&stage.stages);
    }
    Ok(())
}

/// `grotto-pack demo`: the demo cave's scans, then its package.
fn run_demo(out: &Path, synth: &SynthOpts, mut opts: BuildOpts) -> anyhow::Result<()> {
    // The demo keeps the 6.25 cm leaves its figures (README, docs) were measured with:
    // its simulated scans are spaced about 9 cm, so `auto` would choose 12.5 cm.
    if opts.leaf_m == "auto" {
        opts.leaf_m = build::DEFAULT_LEAF_M.to_string();
    }
    let scans = out.join("demo-scans");
    let s = run_synth(&scans, synth, opts.json)?;
    if !opts.json {
        println!("wrote {} scans, {} points, manifest {}", s.scans, s.points, s.manifest);
    }
    let summary = run_build(&[PathBuf::from(&s.manifest)], &out.join("demo.grotto"), &opts)?;
    print_build(&summary, opts.json)?;
    Ok(())
}

fn print_ingest(figures: &[grotto_preprocess::bench::IngestFigure], json: bool) -> anyhow::Result<()> {
    if json {
        println!("{}", serde_json::to_string_pretty(&figures)?);
    } else {
        println!("| reader | points | file MB | seconds | points/s |\n|---|---:|---:|---:|---:|");
        for f in figures {
            println!(
                "| {} | {} | {:.1} | {:.2} | {:.2e} |",
                f.reader,
                f.points,
                f.file_bytes as f64 / 1e6,
                f.seconds,
                f.points_per_second
            );
        }
    }
    Ok(())
}

fn print_normals(figures: &[grotto_preprocess::bench::NormalFigure], json: bool) -> anyhow::Result<()> {
    if json {
        println!("{}", serde_json::to_string_pretty(&figures)?);
    } else {
        println!(
            "| noise | orientation | k | points | mean error deg | p95 deg | flipped % | threads | grid s | grid cells | normals/s | SVO points/s |\n|---:|---|---:|---:|---:|---:|---:|---:|---:|---:|---:|---:|"
        );
        for f in figures {
            println!(
                "| {} | {} | {} | {} | {:.2} | {:.2} | {:.3} | {} | {:.2} | {} | {:.3e} | {:.3e} |",
                f.noise_scale,
                if f.bare { "enclosure (no scanner)" } else { "toward scanner" },
                f.k,
                f.points,
                f.mean_deg,
                f.p95_deg,
                f.flipped_percent,
                f.threads,
                f.grid_seconds,
                f.grid_cells,
                f.normals_per_second,
                f.svo_points_per_second
            );
        }
    }
    Ok(())
}

fn print_bc1(figures: &[grotto_preprocess::bench::Bc1Figure], json: bool) -> anyhow::Result<()> {
    if json {
        println!("{}", serde_json::to_string_pretty(&figures)?);
    } else {
        println!(
            "| package | points | --colors | PSNR dB | max error | encode s | raw bytes | raw+zstd bytes | BC1 bytes | BC1 / raw |\n|---|---:|---|---:|---:|---:|---:|---:|---:|---:|"
        );
        for f in figures {
            for e in &f.encoders {
                println!(
                    "| {} | {} | {} | {:.2} | {} | {:.3} | {} | {} | {} | {:.3} |",
                    f.package,
                    f.points,
                    e.colors,
                    e.psnr_db,
                    e.max_error,
                    e.encode_seconds,
                    f.raw_bytes,
                    f.raw_zstd_bytes,
                    f.bc1_bytes,
                    f.bc1_bytes as f64 / f.raw_bytes as f64
                );
            }
        }
    }
    Ok(())
}

fn print_encoding(figures: &[grotto_preprocess::bench::EncodingFigure], json: bool) -> anyhow::Result<()> {
    if json {
        println!("{}", serde_json::to_string_pretty(&figures)?);
    } else {
        for f in figures {
            println!(
                "{}: {} points in {} leaf runs, position bits {:?}, {} tiles kept at full precision; position error max {:.3} mm mean {:.3} mm, normal max {:.4} deg mean {:.4} deg, radius max {:.2}%, spread max {:.4}; one thread: encode {:.2} s, zstd {:.2} s, decode {:.2} s",
                f.package,
                f.points,
                f.runs,
                f.position_bits,
                f.full_precision_tiles,
                f.position_error_max_mm,
                f.position_error_mean_mm,
                f.normal_error_max_deg,
                f.normal_error_mean_deg,
                100.0 * f.radius_error_max_rel,
                f.spread_error_max,
                f.encode_seconds,
                f.zstd_seconds,
                f.decode_seconds
            );
            println!("| encoding | surfel bytes | per point | package per point |\n|---|---:|---:|---:|");
            for r in &f.rows {
                println!(
                    "| {} | {} | {:.2} | {:.2} |",
                    r.encoding, r.surfel_bytes, r.surfel_bytes_per_point, r.package_bytes_per_point
                );
            }
        }
    }
    Ok(())
}
