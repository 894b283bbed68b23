//! `cargo xtask`: the project's own tasks. `bench SUITE...` measures (every figure the docs
//! state comes from a suite here or names the command that measured it by hand) and records the
//! suites' rows in docs/figures.json; `figures` renders docs/figures.md from that file.

mod figures;
mod runner;
mod suites;

use std::path::PathBuf;
use std::process::Command;

use anyhow::{Context, Result, bail};
use clap::{Parser, Subcommand};

use figures::Figures;
use runner::Ctx;

#[derive(Parser, Debug)]
#[command(name = "cargo xtask", about = "The project's own tasks: benchmarks and the figures page.")]
struct Cli {
    #[command(subcommand)]
    command: Task,
}

#[derive(Subcommand, Debug)]
enum Task {
    /// Run benchmark suites (`list` shows them), print their tables, keep their reports in
    /// OUT/SUITE/ and record their figures in docs/figures.json and docs/figures.md.
    Bench {
        /// Suites or groups to run, in order (`cargo xtask bench list` names them).
        #[arg(required = true)]
        suites: Vec<String>,
        /// Where tables, commands, raw reports and the shared scans and packages go.
        #[arg(long, default_value = "out/bench")]
        out: PathBuf,
        /// Folder with `grotto` and `grotto-pack` already built (else `GROTTO_BIN`, else
        /// `cargo build --release` here).
        #[arg(long)]
        bin: Option<PathBuf>,
        /// The machine's name on the figures page (default: the GPU's model, or `dev` without one).
        #[arg(long)]
        machine: Option<String>,
        /// Repetitions of each `grotto bench`.
        #[arg(long, default_value_t = 3)]
        reps: u32,
        /// Print and keep the tables but leave docs/figures.* as they are.
        #[arg(long)]
        no_record: bool,
    },
    /// Render docs/figures.md from docs/figures.json (`--check`: fail where they differ).
    Figures {
        #[arg(long)]
        check: bool,
    },
}

fn main() -> Result<()> {
    match Cli::parse().command {
        Task::Figures { check } => {
            let f = Figures::load(&figures::json_path())?;
            if check {
                let page = std::fs::read_to_string(figures::page_path())?;
                if page != f.render() {
                    bail!("docs/figures.md differs from docs/figures.json: run `cargo xtask figures`");
                }
                return Ok(());
            }
            f.save(&figures::json_path(), &figures::page_path())
        }
        Task::Bench { suites, out, bin, machine, reps, no_record } => {
            if suites == ["list"] {
                list();
                return Ok(());
            }
            let chosen = suites::resolve(&suites).map_err(|n| {
                anyhow::anyhow!("no suite or group {n:?}: `cargo xtask bench list` names them")
            })?;
            let bin = match bin.or_else(|| std::env::var_os("GROTTO_BIN").map(PathBuf::from)) {
                Some(b) => b,
                None => {
                    let status = Command::new("cargo")
                        .current_dir(figures::root())
                        .args([
                            "build",
                            "--release",
                            "--locked",
                            "-p",
                            "grotto-preprocess",
                            "-p",
                            "grotto-runtime",
                        ])
                        .status()?;
                    if !status.success() {
                        bail!("cargo build --release failed");
                    }
                    // Where cargo put them: CARGO_TARGET_DIR, as cargo reads it, else target/.
                    let target = std::env::var_os("CARGO_TARGET_DIR")
                        .map_or_else(|| figures::root().join("target"), PathBuf::from);
                    target.join("release")
                }
            };
            let machine = machine.unwrap_or_else(gpu_name);
            let out = if out.is_absolute() { out } else { figures::root().join(out) };
            let mut failed = Vec::new();
            for s in chosen {
                eprintln!("== {}: {} (about {} on the 2-core machine)", s.name, s.about, s.dev_time);
                let ctx = Ctx::new(s.name, &out, &bin, &machine, reps)?;
                match (s.run)(&ctx) {
                    Ok(rows) if !no_record && !rows.is_empty() => {
                        let mut f = Figures::load(&figures::json_path())?;
                        f.merge(rows);
                        f.save(&figures::json_path(), &figures::page_path())
                            .context("recording the figures")?;
                        eprintln!("== {}: recorded in docs/figures.json and docs/figures.md", s.name);
                    }
                    Ok(_) => {}
                    Err(e) => {
                        eprintln!("== {} failed: {e:#}", s.name);
                        failed.push(s.name);
                    }
                }
            }
            if !failed.is_empty() {
                bail!("suites that failed: {}", failed.join(", "));
            }
            Ok(())
        }
    }
}

fn list() {
    println!("| suite | measures | needs | time on 2 cores |\n|---|---|---|---|");
    for s in suites::SUITES {
        println!("| {} | {} | {:?} | {} |", s.name, s.about, s.needs, s.dev_time);
    }
    for (g, members) in suites::GROUPS {
        println!("\n{g}: {}", members.join(", "));
    }
}

/// The GPU's model from `nvidia-smi`, shortened as the figures page writes it (`H100`), or
/// `dev` on a machine without one.
fn gpu_name() -> String {
    let out = Command::new("nvidia-smi").args(["--query-gpu=name", "--format=csv,noheader"]).output();
    let name = out
        .ok()
        .filter(|o| o.status.success())
        .map(|o| String::from_utf8_lossy(&o.stdout).lines().next().unwrap_or_default().to_owned());
    match name {
        Some(n) if !n.is_empty() => n
            .split_whitespace()
            .find(|w| {
                w.chars().any(|c| c.is_ascii_digit())
                    && w.chars().next().is_some_and(|c| c.is_ascii_uppercase())
            })
            .unwrap_or(&n)
            .to_owned(),
        _ => "dev".into(),
    }
}
