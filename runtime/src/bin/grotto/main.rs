//! `grotto`: the command line over the runtime library, a module a subcommand: inspect, verify
//! and export here; render, bench, view and publish beside it. Each parses its arguments into the
//! library's options and draws progress; the work is the library's.

mod bench;
mod map;
mod publish;
mod render;
mod view;

use std::path::PathBuf;
use std::process::ExitCode;

use clap::{Parser, Subcommand};
use grotto_format::Package;
use grotto_runtime::cli::inspect;

use bench::BenchArgs;
use map::MapArgs;
use publish::PublishArgs;
use render::RenderArgs;
use view::ViewArgs;

#[derive(Parser, Debug)]
#[command(name = "grotto", version, about = "Inspect, verify and render .grotto cave packages")]
struct Cli {
    #[command(subcommand)]
    command: Command,
}

#[derive(Subcommand, Debug)]
enum Command {
    /// Describe a package: version, tiles, sections, sizes, compression ratios, scene.
    Inspect {
        package: PathBuf,
        /// List every section.
        #[arg(long)]
        sections: bool,
        /// Load the scene as the renderer does and report the GPU bytes of every buffer whose
        /// size follows the content (nodes, leaves, surfels, rock...), no GPU needed.
        #[arg(long)]
        gpu_memory: bool,
        /// Machine-readable output.
        #[arg(long)]
        json: bool,
    },
    /// Export the merged points with normals, colours, radii and spread (PLY or LAS, by extension).
    Export {
        package: PathBuf,
        /// Output point file: .ply or .las.
        #[arg(long)]
        points: PathBuf,
        /// Machine-readable output.
        #[arg(long)]
        json: bool,
    },
    /// Render a package with global illumination to PNG (tonemapped) or EXR (linear radiance).
    ///
    /// Plans the passes from the scene (see --explain), propagates light until it converges or the
    /// bounce budget is spent, then renders the camera (or a path through named cameras).
    Render(Box<RenderArgs>),
    /// Time every pass (GPU timestamps where the adapter has them) on a package: shadow maps,
    /// injection, one bounce (mip + propagate), G-buffer and shading, repeated; median per pass.
    Bench(Box<BenchArgs>),
    /// Explore a package in a window with a panel (quality, bounces, exposure, shadows, view; the
    /// effect plan, fps and pass times, resident tiles). Mouse drag looks, WASD flies (Q/E
    /// down/up), the wheel sets the speed; a right click orbits the point under the cursor, O the
    /// centre (O again: fly); Tab next named camera, R the first; 1-7 views (lit, albedo, normals,
    /// light, level, scan, lux); C clip box; M measure; G / N / B tours; L lighting mode; H panel;
    /// K records a camera path; P screenshot; F11 full screen; Esc quits.
    /// Tiles follow the camera; the light waits while it moves and converges when it rests. Takes
    /// the render options (--size is the window's size).
    View(Box<ViewArgs>),
    /// Write a static web site that shows a package in the browser (WebGPU): the viewer, the
    /// package as it is, and viewer.json. The viewer fetches the package by HTTP range requests
    /// (directory first, then the tiles the view needs), so any static host that answers ranges
    /// serves it (docs/web.md). Needs the viewer bundle scripts/build-web.sh builds.
    Publish(Box<PublishArgs>),
    /// Draw survey maps: plan, extended elevation, cross-sections and passage dimensions from the
    /// scans and a cave survey (Survex .3d, Compass .plt).
    Map(Box<MapArgs>),
    /// Check a package's structure and every checksum and section; exits non-zero on any problem.
    Verify {
        package: PathBuf,
        /// Machine-readable output.
        #[arg(long)]
        json: bool,
    },
}

fn main() -> ExitCode {
    lean_malloc();
    match run(Cli::parse()) {
        Ok(code) => code,
        Err(e) => {
            eprintln!("error: {e:#}");
            ExitCode::FAILURE
        }
    }
}

/// glibc's allocator keeps what a process frees where a viewer needs it returned: each thread
/// that allocates gets an arena of its own (the tile loaders decode in threads), whose freed
/// middle stays resident, and a freed large block raises the size below which blocks come from
/// those arenas instead of their own pages. A viewer frees a decoded scene once its GPU holds it
/// (docs/benchmarks.md, "A viewer's process memory": 828 -> 754 MiB along the measured path with
/// these settings given through glibc's environment).
/// Two arenas, and a fixed 128 KiB above which a block has its own pages and goes back when
/// freed.
#[cfg(all(target_os = "linux", target_env = "gnu"))]
#[allow(unsafe_code)]
fn lean_malloc() {
    // SAFETY: mallopt only sets the allocator's parameters; it is called first thing in main,
    // before any other thread exists or any memory was handed out under other settings.
    unsafe {
        libc::mallopt(libc::M_ARENA_MAX, 2);
        libc::mallopt(libc::M_MMAP_THRESHOLD, 128 << 10);
        libc::mallopt(libc::M_TRIM_THRESHOLD, 128 << 10);
    }
}

#[cfg(not(all(target_os = "linux", target_env = "gnu")))]
fn lean_malloc() {}

/// Hands the allocator's free pages back to the system: between frames, what a change of tiles
/// decoded and freed would otherwise stay in the process's resident memory wherever it left a
/// hole in the heap (glibc trims only the heap's top by itself).
#[cfg(all(target_os = "linux", target_env = "gnu"))]
#[allow(unsafe_code)]
pub(crate) fn trim_heap() {
    // SAFETY: malloc_trim only returns free memory to the system; it takes the allocator's own
    // locks and touches no memory in use.
    unsafe {
        libc::malloc_trim(0);
    }
}

#[cfg(not(all(target_os = "linux", target_env = "gnu")))]
pub(crate) fn trim_heap() {}

fn run(cli: Cli) -> anyhow::Result<ExitCode> {
    match cli.command {
        Command::Inspect { package, gpu_memory: true, json, .. } => {
            let t0 = std::time::Instant::now();
            let scene = grotto_runtime::engine::load_scene(&package)?;
            let bytes = scene.buffer_bytes(false);
            let load_s = t0.elapsed().as_secs_f64();
            if json {
                let report = serde_json::json!({
                    "package": package.display().to_string(),
                    "tiles": scene.tiles.len(), "nodes": scene.nodes.len(),
                    "leaves": scene.leaves.len(), "surfels": scene.surfels.len(),
                    "rock_bricks": scene.rock.bricks(),
                    "bytes": bytes, "total_bytes": bytes.total(), "load_s": load_s,
                });
                println!("{}", serde_json::to_string_pretty(&report)?);
            } else {
                let mib = |b: u64| b as f64 / f64::from(1u32 << 20);
                println!(
                    "{}: {} tiles, {} nodes, {} leaves, {} surfels (scene loaded in {load_s:.1} s)",
                    package.display(),
                    scene.tiles.len(),
                    scene.nodes.len(),
                    scene.leaves.len(),
                    scene.surfels.len()
                );
                for (name, b) in [
                    ("tiles", bytes.tile_buffers.tiles),
                    ("nodes", bytes.tile_buffers.nodes),
                    ("leaves", bytes.tile_buffers.leaves),
                    ("leaf light", bytes.tile_buffers.leaf_light),
                    ("radiance pyramid", bytes.tile_buffers.faces),
                    ("mip order", bytes.tile_buffers.mip_order),
                    ("surfels", bytes.tile_buffers.surfels),
                    ("rock", bytes.rock),
                ] {
                    println!("  {name:18} {:10.2} MiB", mib(b));
                }
                println!("  {:18} {:10.2} MiB", "total", mib(bytes.total()));
                println!(
                    "  rock: {} bricks; as dense per-tile grids it took {:.2} MiB",
                    scene.rock.bricks(),
                    mib(bytes.rock_dense_grid)
                );
            }
            Ok(ExitCode::SUCCESS)
        }
        Command::Inspect { package, sections, json, .. } => {
            let pkg = Package::open(&package)?;
            let report = inspect::inspect(&pkg);
            if json {
                println!("{}", serde_json::to_string_pretty(&report)?);
            } else {
                print!("{}", inspect::render_text(&report, sections));
            }
            Ok(ExitCode::SUCCESS)
        }
        Command::Export { package, points, json } => {
            let pkg = Package::open(&package)?;
            let summary = grotto_runtime::cli::export::export_points(&pkg, &points)?;
            if json {
                println!("{}", serde_json::to_string_pretty(&summary)?);
            } else {
                println!("wrote {}: {} points from {} tiles", summary.path, summary.points, summary.tiles);
            }
            Ok(ExitCode::SUCCESS)
        }
        Command::Render(args) => render::render(*args),
        Command::Bench(args) => bench::bench(*args),
        Command::View(args) => view::view(*args),
        Command::Publish(args) => publish::publish(*args),
        Command::Map(args) => map::run(*args),
        Command::Verify { package, json } => {
            let report = match Package::open(&package) {
                Ok(pkg) => inspect::verify(&pkg),
                // Structural damage: the package does not open; report it the same way.
                Err(e) => inspect::Verification {
                    path: package.display().to_string(),
                    sections: 0,
                    bytes_checked: 0,
                    problems: vec![match &e {
                        grotto_format::Error::Invalid { problem, .. } => problem.to_string(),
                        grotto_format::Error::Io { op, source, .. } => format!("cannot {op}: {source}"),
                        other => other.to_string(),
                    }],
                },
            };
            if json {
                println!("{}", serde_json::to_string_pretty(&report)?);
            } else if report.problems.is_empty() {
                println!(
                    "{}: ok ({} sections, {} bytes checked)",
                    report.path, report.sections, report.bytes_checked
                );
            } else {
                for p in &report.problems {
                    eprintln!("{}: {p}", report.path);
                }
                eprintln!("{}: INVALID ({} problems)", report.path, report.problems.len());
            }
            Ok(if report.problems.is_empty() { ExitCode::SUCCESS } else { ExitCode::FAILURE })
        }
    }
}
