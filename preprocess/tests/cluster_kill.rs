//! The cluster steps killed with SIGKILL at any point: a `build-tile` job killed while
//! it writes tiles, and an `assemble` killed midway, leave nothing a rerun or a later assemble
//! takes for finished. Tile packages and the output are written to a temp file and renamed into
//! place (grotto-format's writer), and a tile counts as built only when a package with the plan's
//! fingerprint sits under its final name, so a rerun redoes exactly what is missing and the
//! package comes out byte for byte as one uninterrupted build.

use std::path::{Path, PathBuf};
use std::process::{Command, Output};
use std::time::{Duration, Instant};

fn pack() -> Command {
    Command::new(env!("CARGO_BIN_EXE_grotto-pack"))
}

fn ok(out: Output, what: &str) -> String {
    let text = format!("{}{}", String::from_utf8_lossy(&out.stdout), String::from_utf8_lossy(&out.stderr));
    assert!(out.status.success(), "{what} failed: {text}");
    text
}

/// Finished tile packages (`NNNNNNN.grotto`) in the work directory; temp files do not count.
fn finished_tiles(work: &Path) -> usize {
    std::fs::read_dir(work.join("tiles")).map_or(0, |d| {
        d.filter_map(|e| e.ok())
            .filter(|e| {
                let name = e.file_name();
                let name = name.to_string_lossy();
                name.len() == 14 && name.ends_with(".grotto") && name[..7].bytes().all(|b| b.is_ascii_digit())
            })
            .count()
    })
}

/// Temp files of unfinished tile packages (`.NNNNNNN.grotto.XXXXXX.partial`).
fn partial_tiles(work: &Path) -> Vec<String> {
    std::fs::read_dir(work.join("tiles")).map_or(Vec::new(), |d| {
        d.filter_map(|e| e.ok())
            .map(|e| e.file_name().to_string_lossy().into_owned())
            .filter(|name| name.starts_with('.') && name.ends_with(".partial"))
            .collect()
    })
}

/// Sends `signal` (STOP, CONT) to process `pid` with kill(1).
fn signal(pid: u32, signal: &str) {
    let status = Command::new("kill").arg(format!("-{signal}")).arg(pid.to_string()).status().unwrap();
    assert!(status.success(), "kill -{signal} {pid}");
}

/// Spawns `cmd`, kills it (SIGKILL) as soon as `ready` holds or after `limit`, and says whether it
/// was still running then. `ready` is asked again once the process is stopped (SIGSTOP), so what
/// it saw (a temp file being written) is what the kill leaves; if it no longer holds, the process
/// goes on and is watched again.
fn kill_when(mut cmd: Command, ready: impl Fn() -> bool, limit: Duration) -> bool {
    let mut child =
        cmd.stdout(std::process::Stdio::null()).stderr(std::process::Stdio::null()).spawn().unwrap();
    let start = Instant::now();
    loop {
        if let Some(_status) = child.try_wait().unwrap() {
            return false;
        }
        let timed_out = start.elapsed() > limit;
        if timed_out || ready() {
            signal(child.id(), "STOP");
            if timed_out || ready() {
                child.kill().unwrap();
                child.wait().unwrap();
                return true;
            }
            signal(child.id(), "CONT");
        }
        std::thread::sleep(Duration::from_millis(2));
    }
}

/// A synthetic survey of `points` points in four PLY scans under `dir`/scans; its manifest.
fn synth_manifest(dir: &Path, points: u32) -> PathBuf {
    let scans = dir.join("scans");
    ok(
        pack()
            .args(["synth", "--points", &points.to_string(), "--segments", "4", "--formats", "ply", "--out"])
            .arg(&scans)
            .output()
            .unwrap(),
        "synth",
    );
    scans.join("manifest.toml")
}

#[test]
fn a_killed_shard_and_a_killed_assemble_rerun_to_the_same_package() {
    let dir = tempfile::tempdir().unwrap();
    let manifest = synth_manifest(dir.path(), 80_000);
    let common = |c: &mut Command, work: &PathBuf| {
        c.arg(&manifest)
            .args(["--threads", "1", "--leaf-m", "0.125", "--min-tile-m", "2", "--max-tile-m", "4"])
            .arg("--work-dir")
            .arg(work);
    };
    let whole = dir.path().join("whole.grotto");
    let mut c = pack();
    c.arg("build");
    common(&mut c, &dir.path().join("w1"));
    ok(c.arg("-o").arg(&whole).output().unwrap(), "build");
    let want = std::fs::read(&whole).unwrap();

    let work = dir.path().join("w2");
    let mut c = pack();
    c.arg("plan");
    common(&mut c, &work);
    ok(c.output().unwrap(), "plan");
    // Killed once the first tile is written, while the next one is being written (one thread:
    // one tile in flight, its temp file there from the writer's start to its rename).
    let mut c = pack();
    c.arg("build-tile");
    common(&mut c, &work);
    let ready = || finished_tiles(&work) >= 1 && !partial_tiles(&work).is_empty();
    let killed = kill_when(c, ready, Duration::from_secs(120));
    let done = finished_tiles(&work);
    let partials = partial_tiles(&work);
    eprintln!("build-tile killed: {killed}, with {done} tiles finished, partial files {partials:?}");
    // The shard has dozens of tiles and is killed at its first: it must not have finished.
    assert!(killed, "build-tile finished before it could be killed: the kill path went untested");
    assert!(!partials.is_empty(), "build-tile was not killed while it wrote a tile");
    // What the dead job left is refused by name: assemble lists the tile whose temp file is there
    // as not built, with the partial file, and writes nothing.
    let early = dir.path().join("early.grotto");
    let mut c = pack();
    c.arg("assemble");
    common(&mut c, &work);
    let refused = c.arg("-o").arg(&early).output().unwrap();
    let text = String::from_utf8_lossy(&refused.stderr);
    assert!(!refused.status.success() && !early.exists(), "assemble took a killed build: {text}");
    for name in &partials {
        let tile: usize = name[1..8].parse().unwrap();
        let line = text.lines().find(|l| l.contains(&format!("tile {tile} ("))).unwrap_or_default();
        assert!(line.contains("not built: only a partial file") && line.contains(name.as_str()), "{text}");
    }
    let mut c = pack();
    c.arg("build-tile");
    common(&mut c, &work);
    let rerun = ok(c.output().unwrap(), "build-tile rerun");
    eprintln!("{rerun}");
    if killed {
        assert!(rerun.contains(&format!("{done} already built")), "{rerun}");
    }

    // Assemble killed as soon as its temp file appears (or at once): no package under the final
    // name, or (killed too late) the whole one; the rerun gives the same bytes.
    let out = dir.path().join("out").join("cave.grotto");
    std::fs::create_dir_all(out.parent().unwrap()).unwrap();
    let parent = out.parent().unwrap().to_path_buf();
    let mut c = pack();
    c.arg("assemble");
    common(&mut c, &work);
    c.arg("-o").arg(&out);
    let started = || std::fs::read_dir(&parent).is_ok_and(|d| d.count() > 0);
    let killed = kill_when(c, started, Duration::from_secs(120));
    eprintln!("assemble killed: {killed}");
    if killed {
        assert!(
            !out.exists() || std::fs::read(&out).unwrap() == want,
            "a half-written package under the final name"
        );
    }
    let mut c = pack();
    c.arg("assemble");
    common(&mut c, &work);
    ok(c.arg("-o").arg(&out).output().unwrap(), "assemble rerun");
    assert!(std::fs::read(&out).unwrap() == want, "the rerun assemble differs from one build");
}

/// A work directory shared by nodes is not trusted: a tile that is missing with only a
/// dead job's partial file, one cut short by a copy, one from another plan, one built with other
/// parameters and one with a flipped byte are each refused by `assemble`, in one list naming the
/// tile and the reason; `build-tile` then builds exactly those again, and the package is byte for
/// byte one build's.
#[test]
fn assemble_refuses_partial_stale_and_damaged_tiles_by_name() {
    let dir = tempfile::tempdir().unwrap();
    let manifest = synth_manifest(dir.path(), 30_000);
    let run = |step: &str, work: &Path, extra: &[&str]| {
        let mut c = pack();
        c.arg(step).arg(&manifest).args(["--threads", "2", "--leaf-m", "0.125"]);
        if !extra.contains(&"--min-tile-m") {
            c.args(["--min-tile-m", "2", "--max-tile-m", "4"]);
        }
        c.arg("--work-dir").arg(work).args(extra);
        c.output().unwrap()
    };
    let whole = dir.path().join("whole.grotto");
    ok(run("build", &dir.path().join("w1"), &["-o", whole.to_str().unwrap()]), "build");
    let want = std::fs::read(&whole).unwrap();
    let work = dir.path().join("w2");
    ok(run("plan", &work, &[]), "plan");
    ok(run("build-tile", &work, &[]), "build-tile");
    // Other tilings and parameters, for their tiles.
    let other_plan = dir.path().join("w-plan");
    ok(run("plan", &other_plan, &["--min-tile-m", "4", "--max-tile-m", "8"]), "other plan");
    ok(run("build-tile", &other_plan, &["--min-tile-m", "4", "--max-tile-m", "8"]), "other plan's tiles");
    let other_k = dir.path().join("w-k");
    ok(run("plan", &other_k, &["--k", "10"]), "other k");
    ok(run("build-tile", &other_k, &["--k", "10", "--shard", "3/7"]), "other k's tile");

    let tile = |w: &Path, t: usize| w.join("tiles").join(format!("{t:07}.grotto"));
    // 1: a node died writing it: only its temp file, cut short.
    let bytes = std::fs::read(tile(&work, 1)).unwrap();
    std::fs::remove_file(tile(&work, 1)).unwrap();
    let partial = ".0000001.grotto.Xq3ZkA.partial";
    std::fs::write(work.join("tiles").join(partial), &bytes[..bytes.len() / 3]).unwrap();
    // 2: copied by hand and cut short (not atomically renamed).
    let bytes = std::fs::read(tile(&work, 2)).unwrap();
    std::fs::write(tile(&work, 2), &bytes[..bytes.len() - 100]).unwrap();
    // 3: from another plan; 10: built with another k.
    std::fs::copy(tile(&other_plan, 0), tile(&work, 3)).unwrap();
    std::fs::copy(tile(&other_k, 10), tile(&work, 10)).unwrap();
    // 5: one byte flipped inside a section's stored bytes.
    let pkg = grotto_format::Package::open(tile(&work, 5)).unwrap();
    let section = pkg.sections().max_by_key(|s| s.stored_len).unwrap();
    let at = (section.offset + section.stored_len / 2) as usize;
    drop(pkg);
    let mut bytes = std::fs::read(tile(&work, 5)).unwrap();
    bytes[at] ^= 0x10;
    std::fs::write(tile(&work, 5), &bytes).unwrap();
    // 6: gone without a trace.
    std::fs::remove_file(tile(&work, 6)).unwrap();

    let out = dir.path().join("cluster.grotto");
    let refused = run("assemble", &work, &["-o", out.to_str().unwrap()]);
    let text = String::from_utf8_lossy(&refused.stderr).into_owned();
    eprintln!("{text}");
    assert!(!refused.status.success() && !out.exists(), "{text}");
    assert!(text.contains("6 of "), "{text}");
    let line = |t: usize| {
        let name = format!("tile {t} ({}", tile(&work, t).display());
        text.lines().find(|l| l.contains(&name)).unwrap_or_else(|| panic!("tile {t} not listed: {text}"))
    };
    assert!(line(1).contains("not built: only a partial file") && line(1).contains(partial), "{text}");
    assert!(line(2).contains("damaged") && line(2).contains("truncated"), "{text}");
    assert!(line(3).contains("stale: built for another plan"), "{text}");
    assert!(line(10).contains("stale: built with other parameters") && line(10).contains("-k10-"), "{text}");
    assert!(line(5).contains("damaged") && line(5).contains("checksum mismatch"), "{text}");
    assert!(line(6).ends_with("not built"), "{text}");
    for t in [0, 4, 7, 8, 9] {
        assert!(!text.contains(&format!("tile {t} (")), "tile {t} is fine: {text}");
    }

    // build-tile trusts nothing either: exactly those six are built again.
    let rerun = ok(run("build-tile", &work, &[]), "build-tile after the damage");
    assert!(rerun.contains("built 6 tiles (1, 2, 3, 5, 6, 10)"), "{rerun}");
    ok(run("assemble", &work, &["-o", out.to_str().unwrap()]), "assemble");
    assert!(std::fs::read(&out).unwrap() == want, "the repaired build differs from one build");
}
