//! `grotto-pack`: builds `.grotto` packages.

use std::path::PathBuf;

use anyhow::Context;
use clap::{Parser, Subcommand};
use grotto_preprocess::demo;

#[derive(Parser, Debug)]
#[command(name = "grotto-pack", version, about = "Build .grotto cave packages from registered scans")]
struct Cli {
    #[command(subcommand)]
    command: Command,
}

#[derive(Subcommand, Debug)]
enum Command {
    /// Build the built-in demo scene: a spherical chamber at survey coordinates.
    Demo {
        /// Output package.
        #[arg(short, long, default_value = "demo.grotto")]
        out: PathBuf,
        /// Number of surface points.
        #[arg(long, default_value_t = 50_000)]
        points: u64,
        /// Tile edge in metres (a power of two).
        #[arg(long, default_value_t = 8.0)]
        tile_extent_m: f64,
        /// SVO depth per tile.
        #[arg(long, default_value_t = 7)]
        depth: u32,
        /// Print the summary as JSON.
        #[arg(long)]
        json: bool,
    },
}

fn main() -> anyhow::Result<()> {
    match Cli::parse().command {
        Command::Demo { out, points, tile_extent_m, depth, json } => {
            let params = demo::DemoParams { points, tile_extent_m, depth, ..Default::default() };
            let start = std::time::Instant::now();
            let summary =
                demo::build(&out, &params).with_context(|| format!("building {}", out.display()))?;
            if json {
                println!("{}", serde_json::to_string_pretty(&summary)?);
            } else {
                println!(
                    "wrote {}: {} points in {} tiles, {:.2} MB, {:.2} s",
                    summary.path,
                    summary.points,
                    summary.tiles,
                    summary.bytes as f64 / 1e6,
                    start.elapsed().as_secs_f64()
                );
            }
        }
    }
    Ok(())
}
