//! The cluster steps killed with SIGKILL at any point (issue 20): a `build-tile` job killed while
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

/// Spawns `cmd`, kills it (SIGKILL) as soon as `ready` holds or after `limit`, and says whether it
/// was still running then.
fn kill_when(mut cmd: Command, ready: impl Fn() -> bool, limit: Duration) -> bool {
    let mut child =
        cmd.stdout(std::process::Stdio::null()).stderr(std::process::Stdio::null()).spawn().unwrap();
    let start = Instant::now();
    loop {
        if let Some(_status) = child.try_wait().unwrap() {
            return false;
        }
        if ready() || start.elapsed() > limit {
            child.kill().unwrap();
            child.wait().unwrap();
            return true;
        }
        std::thread::sleep(Duration::from_millis(2));
    }
}

#[test]
fn a_killed_shard_and_a_killed_assemble_rerun_to_the_same_package() {
    let dir = tempfile::tempdir().unwrap();
    let scans = dir.path().join("scans");
    ok(
        pack()
            .args(["synth", "--points", "80000", "--segments", "4", "--formats", "ply", "--out"])
            .arg(&scans)
            .output()
            .unwrap(),
        "synth",
    );
    let manifest = scans.join("manifest.toml");
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
    // Killed once the first tile is written, while the others are being built.
    let mut c = pack();
    c.arg("build-tile");
    common(&mut c, &work);
    let killed = kill_when(c, || finished_tiles(&work) >= 1, Duration::from_secs(120));
    let done = finished_tiles(&work);
    eprintln!("build-tile killed: {killed}, with {done} tiles finished");
    // The shard has dozens of tiles and is killed at its first: it must not have finished.
    assert!(killed, "build-tile finished before it could be killed: the kill path went untested");
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
