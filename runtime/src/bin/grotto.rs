//! `grotto`: inspect, verify (and, as the runtime grows, render) .grotto packages.

use std::path::PathBuf;
use std::process::ExitCode;

use clap::{Parser, Subcommand};
use grotto_format::Package;
use grotto_runtime::inspect;

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
    /// Check a package's structure and every checksum and section; exits non-zero on any problem.
    Verify {
        package: PathBuf,
        /// Machine-readable output.
        #[arg(long)]
        json: bool,
    },
}

fn main() -> ExitCode {
    match run(Cli::parse()) {
        Ok(code) => code,
        Err(e) => {
            eprintln!("error: {e:#}");
            ExitCode::FAILURE
        }
    }
}

fn run(cli: Cli) -> anyhow::Result<ExitCode> {
    match cli.command {
        Command::Inspect { package, sections, json } => {
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
            let summary = grotto_runtime::export::export_points(&pkg, &points)?;
            if json {
                println!("{}", serde_json::to_string_pretty(&summary)?);
            } else {
                println!("wrote {}: {} points from {} tiles", summary.path, summary.points, summary.tiles);
            }
            Ok(ExitCode::SUCCESS)
        }
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
