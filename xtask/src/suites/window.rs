//! The window under a virtual X server, flown by XTEST key and mouse events as a person would:
//! its frame times while moving and at rest, and its memory over a long scripted flight.

use std::path::Path;
use std::process::{Child, Command, Stdio};
use std::time::{Duration, Instant};

use anyhow::{Context, Result, bail};
use serde_json::Value;

use crate::figures::Figure;
use crate::runner::{Ctx, PeakSampler, proc_kib, quantiles};

const SIZE: (u32, u32) = (640, 480);
const SOFTWARE: &str = "software";

/// A virtual X server on a free display, stopped when dropped.
struct Xvfb {
    server: Child,
    display: String,
}

impl Xvfb {
    fn start() -> Result<Self> {
        for tool in ["Xvfb", "xdotool"] {
            if Command::new("sh")
                .args(["-c", &format!("command -v {tool}")])
                .stdout(Stdio::null())
                .status()?
                .code()
                != Some(0)
            {
                bail!("needs {tool} (apt-get install xvfb xdotool)");
            }
        }
        let n = (99..200)
            .find(|n| !Path::new(&format!("/tmp/.X{n}-lock")).exists())
            .context("no free X display")?;
        let display = format!(":{n}");
        let screen = format!("{}x{}x24", SIZE.0 + 16, SIZE.1 + 16);
        let server = Command::new("Xvfb")
            .args([&display, "-screen", "0", &screen, "-nolisten", "tcp"])
            .stderr(Stdio::null())
            .spawn()?;
        let x = Xvfb { server, display };
        let t = Instant::now();
        while !Path::new(&format!("/tmp/.X11-unix/X{n}")).exists() {
            if t.elapsed() > Duration::from_secs(20) {
                bail!("Xvfb did not start on {}", x.display);
            }
            std::thread::sleep(Duration::from_millis(100));
        }
        Ok(x)
    }

    /// `xdotool ARGS` on this display; a failed event is not an error (focus can come and go).
    fn xdotool(&self, args: &[&str]) -> String {
        Command::new("xdotool")
            .args(args)
            .env("DISPLAY", &self.display)
            .output()
            .map(|o| String::from_utf8_lossy(&o.stdout).trim().to_owned())
            .unwrap_or_default()
    }

    /// Waits for the viewer's window and gives it the focus (there is no window manager).
    fn focus_viewer(&self) -> Result<String> {
        let wid = self.xdotool(&["search", "--sync", "--name", "grotto view"]);
        let wid = wid.lines().next().context("the viewer's window never appeared")?.to_owned();
        for _ in 0..100 {
            self.xdotool(&["windowfocus", &wid]);
            if self.xdotool(&["getwindowfocus"]) == wid {
                break;
            }
            std::thread::sleep(Duration::from_millis(200));
        }
        Ok(wid)
    }
}

impl Drop for Xvfb {
    /// SIGTERM first, so the server removes its lock file and the display is free again.
    fn drop(&mut self) {
        let _ = Command::new("kill").arg(self.server.id().to_string()).status();
        for _ in 0..50 {
            if matches!(self.server.try_wait(), Ok(Some(_))) {
                return;
            }
            std::thread::sleep(Duration::from_millis(100));
        }
        let _ = self.server.kill();
        let _ = self.server.wait();
    }
}

/// Starts `grotto view PACKAGE --json` in the server's window, its report to `json/NAME.json`.
fn viewer(ctx: &Ctx, x: &Xvfb, pkg: &Path, name: &str, extra: &[&str]) -> Result<Child> {
    let size = format!("{}x{}", SIZE.0, SIZE.1);
    let json = std::fs::File::create(ctx.out.join(format!("json/{name}.json")))?;
    let err = std::fs::File::create(ctx.out.join(format!("{name}.err")))?;
    let mut cmd = ctx.grotto();
    cmd.arg("view").arg(pkg).args(["--size", &size, "--json"]).args(extra).env("DISPLAY", &x.display);
    ctx.log_command(&cmd)?;
    Ok(cmd.stdout(json).stderr(err).spawn()?)
}

fn report(ctx: &Ctx, name: &str) -> Result<Value> {
    let path = ctx.out.join(format!("json/{name}.json"));
    serde_json::from_slice(&std::fs::read(&path)?)
        .with_context(|| format!("{}: the viewer printed no report", path.display()))
}

/// The demo cave at 640x480 (render scale 0.5): 30 s at rest, W held 5 s, then at rest until
/// the light has converged, a screenshot (P) and Escape. The rest lets the shadow faces be drawn
/// first (about 25 frames on dev): moving frames that still draw them are not what moving costs,
/// and the frame-time target does not learn from them.
pub(crate) fn view(ctx: &Ctx) -> Result<Vec<Figure>> {
    let pkg = ctx.demo()?;
    let x = Xvfb::start()?;
    let shot = ctx.out.join("view.png");
    let mut child = viewer(ctx, &x, &pkg, "view", &["--screenshot", shot.to_str().context("path")?])?;
    x.focus_viewer()?;
    std::thread::sleep(Duration::from_secs(30));
    x.xdotool(&[
        "mousemove",
        "600",
        "400",
        "keydown",
        "w",
        "sleep",
        "5",
        "keyup",
        "w",
        "key",
        "p",
        "key",
        "Escape",
    ]);
    let status = child.wait()?;
    if !status.success() {
        bail!("grotto view failed ({status}); see {}", ctx.out.join("view.err").display());
    }
    let r = report(ctx, "view")?;
    // `grotto view --json`: the session, its frames under `log`.
    let ms = |k: &str| -> Vec<f64> {
        r["log"][k].as_array().map(|a| a.iter().filter_map(Value::as_f64).collect()).unwrap_or_default()
    };
    let (moving, rest) = (ms("moving_ms"), ms("rest_ms"));
    let (median, p95) = quantiles(&moving, 0.95).context("no moving frames")?;
    let converge_s = ms("converge_s");
    let converge_frames = ms("converge_frames");
    ctx.table(&format!(
        "moving: {} frames, median {median:.0} ms, p95 {p95:.0} ms; at rest: {} frames; converged after {converge_s:?} s ({converge_frames:?} frames)",
        moving.len(),
        rest.len()
    ))?;
    let mut figures = vec![ctx.figure(
        "view-moving",
        SOFTWARE,
        "the window, demo cave at 640x480 (render scale 0.5): moving frames",
        format!("median {median:.0} ms, p95 {p95:.0} ms"),
        "\"The viewer's frame loop\"",
    )];
    if let (Some(s), Some(f)) = (converge_s.first(), converge_frames.first()) {
        figures.push(ctx.figure(
            "view-converged",
            SOFTWARE,
            "the window: light converged at rest",
            format!("{s:.0} s ({f:.0} frames)"),
            "\"The viewer's frame loop\"",
        ));
    }
    Ok(figures)
}

/// `grotto view PACKAGE ARGS` flown for about 40 s (forward 20 s, a turn, forward 10 s, back 10 s)
/// and closed: its frame log and the process's peak resident memory in bytes (`VmHWM`, read
/// every 20 ms until it exits).
pub(super) fn flight_peak(ctx: &Ctx, pkg: &Path, name: &str, extra: &[&str]) -> Result<(Value, u64)> {
    let x = Xvfb::start()?;
    let mut child = viewer(ctx, &x, pkg, name, extra)?;
    let wid = x.focus_viewer()?;
    let pid = child.id();
    let sampler = PeakSampler::start(pid);
    let (cx, cy) = ((SIZE.0 / 2).to_string(), (SIZE.1 / 2).to_string());
    x.xdotool(&["keydown", "w", "sleep", "20", "keyup", "w"]);
    x.xdotool(&[
        "mousemove",
        &cx,
        &cy,
        "mousedown",
        "1",
        "mousemove_relative",
        "--",
        "300",
        "0",
        "mouseup",
        "1",
    ]);
    x.xdotool(&["keydown", "w", "sleep", "10", "keyup", "w", "keydown", "s", "sleep", "10", "keyup", "s"]);
    // Escape until the viewer has gone: a frame can be long on a software adapter.
    while child.try_wait()?.is_none() {
        x.xdotool(&["windowfocus", &wid]);
        x.xdotool(&["key", "Escape"]);
        std::thread::sleep(Duration::from_secs(2));
    }
    let status = child.wait()?;
    let peak = sampler.finish();
    if !status.success() {
        bail!("grotto view failed ({status}); see {}", ctx.out.join(format!("{name}.err")).display());
    }
    Ok((report(ctx, name)?, peak))
}

/// The process's resident and data memory in MiB, from /proc.
fn memory_mib(pid: u32) -> Option<(u64, u64)> {
    let v = proc_kib(pid, &["VmRSS:", "VmData:"])?;
    Some((v[0] / 1024, v[1] / 1024))
}

/// The demo cave in the window for 30 minutes of a scripted flight in a loop (camera switch,
/// forward, turn, forward, turn back, backward, rest), its memory sampled every 10 s: the
/// largest in the first third against the last third (a viewer that keeps nothing it does not
/// need grows by nothing). `GROTTO_SOAK_MINUTES` shortens it for a try.
pub(crate) fn soak(ctx: &Ctx) -> Result<Vec<Figure>> {
    let pkg = ctx.demo()?;
    soak_of(ctx, &pkg, &[], ("view-soak", "the window's memory over a scripted flight (demo cave)", "soak"))
}

/// As [`soak`], of the 10^7-point survey under `--memory phone`: tiles stream in and out
/// all along, within one budget of 512 MiB for the process and the GPU together.
pub(crate) fn soak_phone(ctx: &Ctx) -> Result<Vec<Figure>> {
    let pkg = super::gpu::survey(ctx, 10_000_000, "survey-1e7")?;
    soak_of(
        ctx,
        &pkg,
        &["--memory", "phone", "--quality", "fast"],
        (
            "view-soak-phone",
            "the window's memory over a scripted flight (10^7 points, `--memory phone`, tiles streaming)",
            "soak-phone",
        ),
    )
}

/// The soak of `pkg` with `extra` arguments: (figure key, figure, output name).
fn soak_of(
    ctx: &Ctx,
    pkg: &Path,
    extra: &[&str],
    (key, what, name): (&str, &str, &str),
) -> Result<Vec<Figure>> {
    let minutes: f64 = std::env::var("GROTTO_SOAK_MINUTES").ok().and_then(|m| m.parse().ok()).unwrap_or(30.0);
    let x = Xvfb::start()?;
    let mut child = viewer(ctx, &x, pkg, name, extra)?;
    let wid = x.focus_viewer()?;
    let pid = child.id();
    let start = Instant::now();
    let mut samples: Vec<(f64, u32, u64, u64)> = Vec::new();
    let mut next_sample = 0.0;
    let mut sample = |loop_n: u32, samples: &mut Vec<_>| {
        let t = start.elapsed().as_secs_f64();
        if t >= next_sample {
            if let Some((rss, data)) = memory_mib(pid) {
                samples.push((t, loop_n, rss, data));
            }
            next_sample = t + 10.0;
        }
    };
    let (cx, cy) = ((SIZE.0 / 2).to_string(), (SIZE.1 / 2).to_string());
    let mut loop_n = 0;
    while start.elapsed().as_secs_f64() < minutes * 60.0 {
        loop_n += 1;
        x.xdotool(&["windowfocus", &wid]);
        x.xdotool(&["key", "Tab"]);
        // Each step in pieces of about a second, so the samples keep their 10 s.
        let steps: [(&str, i32, u32); 5] =
            [("w", 0, 15), ("", 300, 1), ("w", 0, 10), ("", -600, 1), ("s", 0, 10)];
        for (key, drag, secs) in steps {
            if drag != 0 {
                x.xdotool(&["mousemove", &cx, &cy, "mousedown", "1"]);
                for _ in 0..10 {
                    x.xdotool(&["mousemove_relative", "--", &(drag / 10).to_string(), "0"]);
                    std::thread::sleep(Duration::from_millis(50));
                }
                x.xdotool(&["mouseup", "1"]);
            } else {
                x.xdotool(&["keydown", key]);
                for _ in 0..secs {
                    std::thread::sleep(Duration::from_secs(1));
                    sample(loop_n, &mut samples);
                }
                x.xdotool(&["keyup", key]);
            }
        }
        for _ in 0..10 {
            std::thread::sleep(Duration::from_secs(1));
            sample(loop_n, &mut samples);
        }
    }
    // Escape until the viewer has gone: a frame at rest can be long on a software adapter.
    while child.try_wait()?.is_none() {
        x.xdotool(&["windowfocus", &wid]);
        x.xdotool(&["key", "Escape"]);
        std::thread::sleep(Duration::from_secs(5));
    }
    let csv: String = std::iter::once("t_s,loop,rss_mib,data_mib".to_owned())
        .chain(samples.iter().map(|(t, l, r, d)| format!("{t:.0},{l},{r},{d}")))
        .collect::<Vec<_>>()
        .join("\n");
    std::fs::write(ctx.out.join(format!("{name}-memory.csv")), csv + "\n")?;
    let end = samples.last().context("no memory samples")?.0;
    let max = |from: f64, to: f64| {
        samples.iter().filter(|s| s.0 >= from && s.0 <= to).map(|s| s.2).max().unwrap_or(0)
    };
    let (first, last) = (max(0.0, end / 3.0), max(end * 2.0 / 3.0, end));
    ctx.table(&format!(
        "resident memory: first third max {first} MiB, last third max {last} MiB, growth {:+} MiB ({} samples over {end:.0} s, {loop_n} loops)",
        last as i64 - first as i64,
        samples.len()
    ))?;
    Ok(vec![ctx.figure(
        key,
        SOFTWARE,
        what,
        format!("RSS {last} MiB at the end, {:+} MiB after the first third", last as i64 - first as i64),
        "\"Surfel chunks, level of detail and a frame-time target\"",
    )])
}
