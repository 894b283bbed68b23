//! What every suite needs: the built binaries, a folder for its reports, the commands it ran
//! (logged, so each figure can be measured again by hand), tables written as they come (a run cut
//! short keeps what it measured) and the rows for the figures page.

use std::fs::OpenOptions;
use std::io::Write;
use std::path::{Path, PathBuf};
use std::process::{Command, Stdio};
use std::time::Instant;

use anyhow::{Context, Result, bail};
use serde_json::Value;

use crate::figures::Figure;

/// One suite's run.
#[derive(Debug)]
pub(crate) struct Ctx {
    /// The suite's folder: `tables.md`, `commands.txt`, `json/`.
    pub(crate) out: PathBuf,
    /// Scans and packages, shared by the suites and reused between runs.
    pub(crate) work: PathBuf,
    /// Folder holding `grotto` and `grotto-pack`.
    pub(crate) bin: PathBuf,
    pub(crate) machine: String,
    pub(crate) date: String,
    pub(crate) commit: Option<String>,
    pub(crate) suite: &'static str,
    /// Repetitions of each `grotto bench`.
    pub(crate) reps: u32,
}

impl Ctx {
    pub(crate) fn new(suite: &'static str, out: &Path, bin: &Path, machine: &str, reps: u32) -> Result<Self> {
        let ctx = Ctx {
            out: out.join(suite),
            work: out.join("work"),
            bin: bin.to_path_buf(),
            machine: machine.to_owned(),
            date: today()?,
            commit: commit(),
            suite,
            reps,
        };
        std::fs::create_dir_all(ctx.out.join("json"))?;
        std::fs::create_dir_all(&ctx.work)?;
        std::fs::write(ctx.out.join("tables.md"), "")?;
        std::fs::write(ctx.out.join("commands.txt"), "")?;
        Ok(ctx)
    }

    pub(crate) fn grotto(&self) -> Command {
        with_runtime_dir(Command::new(self.bin.join("grotto")))
    }

    pub(crate) fn pack(&self) -> Command {
        with_runtime_dir(Command::new(self.bin.join("grotto-pack")))
    }

    /// Runs `cmd` to completion, its output passed through; logs it first.
    pub(crate) fn run(&self, cmd: &mut Command) -> Result<()> {
        let shown = self.log_command(cmd)?;
        let status = cmd.status().with_context(|| format!("starting {shown}"))?;
        if !status.success() {
            bail!("{shown} failed ({status})");
        }
        Ok(())
    }

    /// Runs `cmd` and parses its standard output as JSON, kept as `json/NAME.json`.
    pub(crate) fn json(&self, name: &str, cmd: &mut Command) -> Result<Value> {
        Ok(self.json_peak(name, cmd)?.0)
    }

    /// Runs `cmd` and parses its standard output as JSON, kept as `json/NAME.json`; also returns
    /// the process's peak resident memory in bytes (its `VmHWM`, read every 20 ms while it runs: the peak it reached before the last
    /// read).
    pub(crate) fn json_peak(&self, name: &str, cmd: &mut Command) -> Result<(Value, u64)> {
        let shown = self.log_command(cmd)?;
        let path = self.out.join("json").join(format!("{name}.json"));
        let mut child = cmd
            .stdout(std::fs::File::create(&path)?)
            .stderr(Stdio::inherit())
            .spawn()
            .with_context(|| format!("starting {shown}"))?;
        let sampler = PeakSampler::start(child.id());
        let status = child.wait()?;
        let peak = sampler.finish();
        if !status.success() {
            bail!("{shown} failed ({status})");
        }
        let v = serde_json::from_slice(&std::fs::read(&path)?)
            .with_context(|| format!("{shown}: its output is not JSON"))?;
        Ok((v, peak))
    }

    /// Runs `cmd` and returns its wall time in seconds.
    pub(crate) fn timed(&self, cmd: &mut Command) -> Result<f64> {
        let t = Instant::now();
        self.run(cmd)?;
        Ok(t.elapsed().as_secs_f64())
    }

    /// Logs `cmd` (stderr and `commands.txt`) as a shell would run it; returns that text.
    pub(crate) fn log_command(&self, cmd: &Command) -> Result<String> {
        let mut shown = cmd.get_program().to_string_lossy().into_owned();
        for a in cmd.get_args() {
            let a = a.to_string_lossy();
            if a.is_empty() || a.contains([' ', '"', '\'', '&', '$']) {
                shown += &format!(" '{}'", a.replace('\'', "'\\''"));
            } else {
                shown += &format!(" {a}");
            }
        }
        for (k, v) in cmd.get_envs() {
            if let Some(v) = v {
                shown = format!("{}={} {shown}", k.to_string_lossy(), v.to_string_lossy());
            }
        }
        eprintln!("[{}] {shown}", clock());
        let mut f = OpenOptions::new().append(true).open(self.out.join("commands.txt"))?;
        writeln!(f, "{shown}")?;
        Ok(shown)
    }

    /// Prints a markdown table (or any text) and appends it to `tables.md`.
    pub(crate) fn table(&self, md: &str) -> Result<()> {
        println!("{md}");
        let mut f = OpenOptions::new().append(true).open(self.out.join("tables.md"))?;
        writeln!(f, "{md}")?;
        Ok(())
    }

    /// A row for the figures page, measured now by this suite.
    pub(crate) fn figure(&self, id: &str, section: &str, figure: &str, value: String, log: &str) -> Figure {
        Figure {
            id: id.into(),
            section: section.into(),
            figure: figure.into(),
            value,
            command: format!("`cargo xtask bench {}`", self.suite),
            machine: self.machine.clone(),
            date: self.date.clone(),
            commit: self.commit.clone(),
            log: log.into(),
            suite: Some(self.suite.into()),
        }
    }

    /// A synthetic survey of `points` points (LAS scans) in the work folder, written once.
    pub(crate) fn synth(&self, name: &str, points: u64, extra: &[&str]) -> Result<PathBuf> {
        let dir = self.work.join(name);
        let manifest = dir.join("manifest.toml");
        if !manifest.exists() {
            self.run(
                self.pack()
                    .args(["synth", "--out"])
                    .arg(&dir)
                    .args(["--points", &points.to_string(), "--formats", "las"])
                    .args(extra)
                    .stdout(Stdio::null()),
            )?;
        }
        Ok(manifest)
    }

    /// A package built from `manifest` with `args`, written once; its build summary is kept in
    /// `json/build-NAME.json` where this run built it.
    pub(crate) fn package(&self, name: &str, manifest: &Path, args: &[&str]) -> Result<PathBuf> {
        let pkg = self.work.join(format!("{name}.grotto"));
        if !pkg.exists() {
            self.json(
                &format!("build-{name}"),
                self.pack()
                    .arg("build")
                    .arg(manifest)
                    .arg("-o")
                    .arg(&pkg)
                    .args(args)
                    .args(["--clean", "--json"]),
            )?;
        }
        Ok(pkg)
    }

    /// The demo package (`grotto-pack demo`), written once.
    pub(crate) fn demo(&self) -> Result<PathBuf> {
        let pkg = self.work.join("demo/demo.grotto");
        if !pkg.exists() {
            self.demo_summary()?;
        }
        Ok(pkg)
    }

    /// Builds the demo package afresh and returns its build summary (`json/build-demo.json`).
    pub(crate) fn demo_summary(&self) -> Result<Value> {
        self.json("build-demo", self.pack().args(["demo", "--json", "--out"]).arg(self.work.join("demo")))
    }

    /// `grotto bench PACKAGE --camera chamber --reps REPS --json ARGS`, kept as `json/NAME.json`.
    pub(crate) fn bench(&self, name: &str, pkg: &Path, args: &[&str]) -> Result<Value> {
        let reps = self.reps.to_string();
        self.json(
            name,
            self.grotto()
                .arg("bench")
                .arg(pkg)
                .args(["--camera", "chamber", "--reps", &reps, "--json"])
                .args(args),
        )
    }
}

/// Fields of a process's `/proc/PID/status` in KiB (`VmHWM:`, `VmRSS:`...), `None` once it is gone.
pub(crate) fn proc_kib(pid: u32, fields: &[&str]) -> Option<Vec<u64>> {
    let status = std::fs::read_to_string(format!("/proc/{pid}/status")).ok()?;
    let field = |name: &str| -> Option<u64> {
        status.lines().find(|l| l.starts_with(name))?.split_whitespace().nth(1)?.parse().ok()
    };
    fields.iter().map(|f| field(f)).collect()
}

/// A process's peak resident memory: its `VmHWM`, read every 20 ms on a thread of its own until
/// the process has gone (the peak it reached before the last read).
#[derive(Debug)]
pub(crate) struct PeakSampler {
    peak_kib: std::sync::Arc<std::sync::atomic::AtomicU64>,
    thread: std::thread::JoinHandle<()>,
}

impl PeakSampler {
    pub(crate) fn start(pid: u32) -> Self {
        let peak_kib = std::sync::Arc::new(std::sync::atomic::AtomicU64::new(0));
        let seen = peak_kib.clone();
        let thread = std::thread::spawn(move || {
            // A process that has exited but is not yet waited for has no VmHWM line.
            while Path::new(&format!("/proc/{pid}")).exists() {
                if let Some(v) = proc_kib(pid, &["VmHWM:"]) {
                    seen.fetch_max(v[0], std::sync::atomic::Ordering::Relaxed);
                }
                std::thread::sleep(std::time::Duration::from_millis(20));
            }
        });
        Self { peak_kib, thread }
    }

    /// The peak in bytes, once the process has been waited for.
    pub(crate) fn finish(self) -> u64 {
        let _ = self.thread.join();
        self.peak_kib.load(std::sync::atomic::Ordering::Relaxed) * 1024
    }
}

/// The field `key` of a report as a number (0 where absent: a pass that did not run).
pub(crate) fn num(v: &Value, key: &str) -> f64 {
    key.split('.').fold(v, |v, k| &v[k]).as_f64().unwrap_or(0.0)
}

/// Median and the value at quantile `q` of `v` (nearest rank), or `None` for no samples.
pub(crate) fn quantiles(v: &[f64], q: f64) -> Option<(f64, f64)> {
    if v.is_empty() {
        return None;
    }
    let mut s = v.to_vec();
    s.sort_by(f64::total_cmp);
    let at = |q: f64| s[((s.len() - 1) as f64 * q).round() as usize];
    Some((at(0.5), at(q)))
}

/// A count with thousands separators, as the docs write them.
pub(crate) fn thousands(n: u64) -> String {
    let s = n.to_string();
    let mut out = String::new();
    for (i, c) in s.chars().enumerate() {
        if i > 0 && (s.len() - i).is_multiple_of(3) {
            out.push(',');
        }
        out.push(c);
    }
    out
}

/// wgpu's Vulkan loader wants `XDG_RUNTIME_DIR`; a bare shell (cron, a batch job) has none.
pub(crate) fn with_runtime_dir(mut cmd: Command) -> Command {
    if std::env::var_os("XDG_RUNTIME_DIR").is_none() {
        let dir = std::env::temp_dir().join("grotto-xtask-runtime");
        if std::fs::create_dir_all(&dir).is_ok() {
            cmd.env("XDG_RUNTIME_DIR", dir);
        }
    }
    cmd
}

fn today() -> Result<String> {
    let out = Command::new("date").args(["-u", "+%F"]).output().context("running date")?;
    Ok(String::from_utf8_lossy(&out.stdout).trim().to_owned())
}

fn clock() -> String {
    Command::new("date")
        .arg("+%T")
        .output()
        .map(|o| String::from_utf8_lossy(&o.stdout).trim().to_owned())
        .unwrap_or_default()
}

/// The commit measured, `+` where the tree had changes to the code (docs/ and out/ aside): the
/// figure is then of the commit that lands them.
fn commit() -> Option<String> {
    let git = |args: &[&str]| {
        let out = Command::new("git").args(args).current_dir(crate::figures::root()).output().ok()?;
        out.status.success().then(|| String::from_utf8_lossy(&out.stdout).trim().to_owned())
    };
    let head = git(&["rev-parse", "--short", "HEAD"])?;
    let changed =
        git(&["status", "--porcelain", "--", ".", ":!docs", ":!out"]).is_some_and(|s| !s.is_empty());
    Some(if changed { format!("{head}+") } else { head })
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn the_peak_of_a_process_is_read_until_it_has_gone() {
        let mut child = Command::new("sleep").arg("0.3").spawn().unwrap();
        let sampler = PeakSampler::start(child.id());
        assert!(child.wait().unwrap().success());
        let peak = sampler.finish();
        assert!(peak > 0 && peak < 1 << 30, "{peak} bytes for `sleep`");
        assert_eq!(proc_kib(child.id(), &["VmHWM:"]), None, "gone");
    }

    #[test]
    fn counts_and_quantiles_read_as_the_docs_write_them() {
        assert_eq!(thousands(0), "0");
        assert_eq!(thousands(999), "999");
        assert_eq!(thousands(1000), "1,000");
        assert_eq!(thousands(1_476_000), "1,476,000");
        assert_eq!(quantiles(&[], 0.95), None);
        assert_eq!(quantiles(&[3.0, 1.0, 2.0], 0.95), Some((2.0, 3.0)));
        let v = serde_json::json!({"median_ms": {"mip": 2.5}});
        assert_eq!(num(&v, "median_ms.mip"), 2.5);
        assert_eq!(num(&v, "median_ms.shadow"), 0.0, "a pass that did not run");
    }
}
