//! The `grotto` binary as a user runs it: inspect (text and JSON) and verify (exit codes), and the
//! window of `grotto view` under Xvfb (which scripts/test.sh installs) and without a display.

use std::process::Command;

use grotto_preprocess::demo::{self, DemoParams};

fn grotto(args: &[&str]) -> std::process::Output {
    Command::new(env!("CARGO_BIN_EXE_grotto")).args(args).output().unwrap()
}

#[test]
fn inspect_and_verify_a_demo_package() {
    let dir = tempfile::tempdir().unwrap();
    let path = dir.path().join("demo.grotto");
    demo::build(&path, &DemoParams { points: 5_000, ..DemoParams::default() }).unwrap();
    let p = path.to_str().unwrap();

    let out = grotto(&["inspect", p, "--sections"]);
    assert!(out.status.success());
    let text = String::from_utf8(out.stdout).unwrap();
    // The hand-made demo package keeps full-precision surfels, so it stays a 1.x package.
    let (major, minor) = grotto_format::spec::VERSION_1;
    let version = format!("{major}.{minor}");
    assert!(
        text.contains(&format!("grotto package {version}")) && text.contains("surfel-colors-raw"),
        "{text}"
    );
    assert!(text.contains("cameras [centre]"), "{text}");

    let out = grotto(&["inspect", p, "--json"]);
    assert!(out.status.success());
    let json: serde_json::Value = serde_json::from_slice(&out.stdout).unwrap();
    assert_eq!(json["version"], version.as_str());
    assert_eq!(json["tiles"]["points"], 5_000);
    assert_eq!(json["scene"]["lights"][0]["name"], "lantern");
    assert!(json["sections"].as_array().unwrap().len() >= 3);

    let out = grotto(&["verify", p]);
    assert!(out.status.success(), "{}", String::from_utf8_lossy(&out.stderr));

    // One flipped payload byte: verify fails and names the section.
    let mut bytes = std::fs::read(&path).unwrap();
    let mid = bytes.len() / 2;
    bytes[mid] ^= 0xff;
    std::fs::write(&path, &bytes).unwrap();
    let out = grotto(&["verify", p, "--json"]);
    assert!(!out.status.success());
    let json: serde_json::Value = serde_json::from_slice(&out.stdout).unwrap();
    let problem = json["problems"][0].as_str().unwrap();
    assert!(problem.contains("checksum mismatch") && problem.contains("section"), "{problem}");

    // Truncated: the package does not open, verify says why.
    std::fs::write(&path, &bytes[..bytes.len() - 100]).unwrap();
    let out = grotto(&["verify", p]);
    assert!(!out.status.success());
    let err = String::from_utf8(out.stderr).unwrap();
    assert!(err.contains("truncated") && err.contains("demo.grotto"), "{err}");

    let out = grotto(&["inspect", "/nonexistent.grotto"]);
    assert!(!out.status.success());
    assert!(String::from_utf8(out.stderr).unwrap().contains("/nonexistent.grotto"));
}

#[test]
fn export_writes_points_other_tools_read() {
    use grotto_preprocess::ingest::{self, ScanFormat};
    let dir = tempfile::tempdir().unwrap();
    let scans = dir.path().join("scans");
    let params = grotto_preprocess::synth::SynthParams { points: 8_000, segments: 3, ..Default::default() };
    let s = grotto_preprocess::synth::write_dataset(&scans, &params, &[ScanFormat::Ply], &|_, _| {}).unwrap();
    let pkg_path = dir.path().join("c.grotto");
    let out = Command::new(env!("CARGO_BIN_EXE_grotto")).args(["--help"]).output().unwrap();
    assert!(String::from_utf8(out.stdout).unwrap().contains("export"));
    let manifest = grotto_preprocess::manifest::Manifest::load(std::path::Path::new(&s.manifest)).unwrap();
    let bp = grotto_preprocess::build::BuildParams {
        work_dir: dir.path().join("w"),
        memory_budget_bytes: 64 << 20,
        threads: 2,
        max_tile_points: 98_304,
        leaf_m: 0.125,
        min_tile_extent_m: 4.0,
        max_tile_extent_m: 16.0,
        halo_m: 0.25,
        ..grotto_preprocess::build::BuildParams::default()
    };
    grotto_preprocess::build::build(&manifest, std::path::Path::new(&s.manifest), &pkg_path, &bp, &|_| {})
        .unwrap();
    let p = pkg_path.to_str().unwrap();
    for ext in ["ply", "las"] {
        let target = dir.path().join(format!("points.{ext}"));
        let out = grotto(&["export", p, "--points", target.to_str().unwrap(), "--json"]);
        assert!(out.status.success(), "{}", String::from_utf8_lossy(&out.stderr));
        let json: serde_json::Value = serde_json::from_slice(&out.stdout).unwrap();
        assert_eq!(json["points"], s.points);
        // Read back with the project's own readers (same parsers as for any scan).
        let format = if ext == "ply" { ScanFormat::Ply } else { ScanFormat::Las };
        let mut src = ingest::open(&target, format, 0).unwrap();
        // PLY normals as properties, LAS ones as extra bytes named NormalX/Y/Z: both read back.
        assert!(src.info().has_normals, "{ext}");
        let all = ingest::read_all(src.as_mut()).unwrap();
        assert_eq!(all.xyz.len() as u64, s.points);
        assert!(all.xyz.iter().all(|p| p[0] > 511_000.0 && p[1] > 5_122_000.0), "world coordinates");
        assert_eq!(all.normal.len(), all.xyz.len(), "{ext}");
        assert!(
            all.normal.iter().all(|n| (n.iter().map(|c| c * c).sum::<f32>() - 1.0).abs() < 1e-3),
            "{ext}"
        );
    }
    // LAS extra bytes carry the normals under their names.
    let reader = las::Reader::from_path(dir.path().join("points.las")).unwrap();
    let vlr = reader.header().vlrs().iter().find(|v| v.record_id == 4).unwrap();
    assert_eq!(vlr.data.len(), 5 * 192);
    assert_eq!(&vlr.data[4..11], b"NormalX");
    assert!(
        grotto(&["export", p, "--points", dir.path().join("x.xyz").to_str().unwrap()]).status.code()
            != Some(0)
    );
}

/// A small cave of 5,000 points in two segments, in a folder of its own.
fn tiny_cave() -> (tempfile::TempDir, std::path::PathBuf) {
    let dir = tempfile::tempdir().unwrap();
    let path = grotto_fixtures::small_cave_package(
        dir.path(),
        &grotto_fixtures::SmallCave { points: 5_000, segments: 2, ..Default::default() },
    )
    .unwrap();
    (dir, path)
}

#[test]
fn negative_vectors_parse_as_written_and_gpu_memory_is_reported() {
    let (dir, path) = tiny_cave();
    let p = path.to_str().unwrap();
    let out_png = dir.path().join("neg.png");
    let out = grotto(&[
        "render",
        p,
        "--eye",
        "-0.6,-2.6,-1.0",
        "--look-at",
        "-0.5,0.5,-0.2",
        "--up",
        "0,0,1",
        "--size",
        "16x12",
        "--bounces",
        "0",
        "--software",
        "-o",
        out_png.to_str().unwrap(),
    ]);
    assert!(out.status.success(), "{}", String::from_utf8_lossy(&out.stderr));
    assert!(out_png.is_file());

    let out = grotto(&["inspect", p, "--gpu-memory", "--json"]);
    assert!(out.status.success(), "{}", String::from_utf8_lossy(&out.stderr));
    let json: serde_json::Value = serde_json::from_slice(&out.stdout).unwrap();
    let leaves = json["leaves"].as_u64().unwrap();
    assert!(leaves > 0);
    assert_eq!(json["bytes"]["leaves"].as_u64().unwrap(), leaves * 64);
    assert!(json["total_bytes"].as_u64().unwrap() > json["bytes"]["surfels"].as_u64().unwrap());
}

#[test]
fn one_memory_budget_sets_the_pools_surfels_and_shadow_maps_and_a_knob_given_wins() {
    let (dir, path) = tiny_cave();
    let p = path.to_str().unwrap();
    let png = dir.path().join("m.png");
    let render = |extra: &[&str]| {
        let mut args = vec!["render", p, "--size", "32x24", "--bounces", "1", "--lamps", "20", "--software"];
        args.extend(extra);
        args.extend(["--json", "-o", png.to_str().unwrap()]);
        grotto(&args)
    };
    let out = render(&["--memory", "phone"]);
    assert!(out.status.success(), "{}", String::from_utf8_lossy(&out.stderr));
    let json: serde_json::Value = serde_json::from_slice(&out.stdout).unwrap();
    let m = &json["memory"];
    assert_eq!(m["budget"]["name"], "phone");
    assert_eq!(m["budget"]["total_bytes"], 512u64 << 20);
    // 20 lamps' shadow maps at 512 px would take 100 MiB: the phone's quarter of 256 MiB keeps
    // them for fewer lights, at the preset's size.
    let lights = m["shadowed_lights"].as_u64().unwrap();
    assert!((4..16).contains(&lights), "{m}");
    assert_eq!(json["settings"]["shadowed_lights"].as_u64(), Some(lights));
    assert_eq!(json["settings"]["shadow_map_size"], m["shadow_map_size"]);
    let split = ["pool_bytes", "atlas_bytes", "target_bytes"].map(|k| m[k].as_u64().unwrap());
    assert!(split.iter().sum::<u64>() <= m["gpu_bytes"].as_u64().unwrap(), "{m}");
    assert!(json["frames"][0]["pool_bytes"].as_u64().unwrap() <= split[0]);

    // A knob given as well wins over the budget's.
    let out = render(&["--memory", "phone", "--shadowed-lights", "15"]);
    assert!(out.status.success(), "{}", String::from_utf8_lossy(&out.stderr));
    let json: serde_json::Value = serde_json::from_slice(&out.stdout).unwrap();
    assert_eq!(json["settings"]["shadowed_lights"], 15);

    // Too small a budget, or no budget at all, is refused before anything is opened.
    for bad in ["64M", "pocket"] {
        let out = render(&["--memory", bad]);
        assert!(!out.status.success());
        let err = String::from_utf8_lossy(&out.stderr);
        assert!(err.contains("--memory") && (err.contains("128M") || err.contains("phone")), "{err}");
    }
}

/// The one tolerance every image comparison uses (the end-to-end tests' helper, shared by path).
// Its items are public where the tests crate exports them; here they are this file's.
#[allow(dead_code, unreachable_pub)]
#[path = "../../tests/src/golden.rs"]
mod golden;

/// Runs `grotto view ARGS --json` in a real window on Xvfb's display, driven by real X input
/// (xdotool, XTEST: `input` is its command chain), and returns the session's JSON summary. Focus
/// is set by hand (no window manager), retried until the server reports it; every step has a time
/// limit, so a lost event fails the test with the viewer's log instead of hanging.
fn view_under_xvfb(dir: &std::path::Path, args: &str, input: &str) -> serde_json::Value {
    // One window at a time: the input is timed with sleeps, and three viewers drawing in software
    // on two cores at once ran late enough to lose clicks.
    static ONE_AT_A_TIME: std::sync::Mutex<()> = std::sync::Mutex::new(());
    let _turn = ONE_AT_A_TIME.lock().unwrap_or_else(std::sync::PoisonError::into_inner);
    // The input starts once the first frame is drawn (GROTTO_VIEW_TRACE logs each frame): on a
    // cold shader cache or a loaded machine the window shows seconds before it can pick a point.
    let script = format!(
        "GROTTO_VIEW_TRACE=1 timeout 300 {bin} view {args} --json > {dir}/view.json 2> {dir}/view.err & pid=$!; \
         wid=$(timeout 120 xdotool search --sync --onlyvisible --name 'grotto view') || exit 3; \
         for i in $(seq 600); do grep -q '^frame ' {dir}/view.err 2>/dev/null && break; sleep 0.2; done; \
         for i in $(seq 100); do xdotool windowfocus $wid 2>/dev/null; \
         [ \"$(xdotool getwindowfocus 2>/dev/null)\" = \"$wid\" ] && break; sleep 0.2; done; \
         timeout 60 xdotool {input} || exit 4; wait $pid",
        bin = env!("CARGO_BIN_EXE_grotto"),
        dir = dir.display(),
    );
    let xvfb = Command::new("timeout")
        .args(["600", "xvfb-run", "-a", "-s", "-screen 0 640x480x24", "bash", "-c", &script])
        .env_remove("WAYLAND_DISPLAY")
        .output()
        .unwrap_or_else(|e| panic!("xvfb-run (scripts/test.sh installs xvfb and xdotool): {e}"));
    let log = std::fs::read_to_string(dir.join("view.err")).unwrap_or_default();
    assert!(
        xvfb.status.success(),
        "{}{}\n{log}",
        String::from_utf8_lossy(&xvfb.stdout),
        String::from_utf8_lossy(&xvfb.stderr)
    );
    serde_json::from_str(&std::fs::read_to_string(dir.join("view.json")).unwrap()).unwrap()
}

#[test]
fn view_flies_the_cave_under_xvfb_matches_grotto_render_and_says_so_clearly_without_a_display() {
    let dir = tempfile::tempdir().unwrap();
    let path =
        grotto_fixtures::small_cave_package(dir.path(), &grotto_fixtures::SmallCave::default()).unwrap();
    let p = path.to_str().unwrap();
    let (shot, walk, reference) =
        (dir.path().join("shot.png"), dir.path().join("walk.toml"), dir.path().join("chamber.png"));
    // The viewer anti-aliases at rest (4 samples a pixel here); grotto render gathers as many.
    let common = ["--size", "160x120", "--quality", "fast", "--software", "--samples", "4"];

    // No display: a clear message and a non-zero exit, not a panic.
    let out = Command::new(env!("CARGO_BIN_EXE_grotto"))
        .args(["view", p])
        .args(common)
        .env_remove("DISPLAY")
        .env_remove("WAYLAND_DISPLAY")
        .env_remove("WAYLAND_SOCKET")
        .output()
        .unwrap();
    let err = String::from_utf8_lossy(&out.stderr);
    assert!(!out.status.success() && err.contains("no display"), "{err}");
    assert!(!err.contains("panicked"), "{err}");

    // What grotto render makes of the second named camera, and its exposure.
    let out = grotto(
        &["render", p, "--camera", "chamber", "--out", reference.to_str().unwrap(), "--json"]
            .into_iter()
            .chain(common)
            .collect::<Vec<_>>(),
    );
    assert!(out.status.success(), "{}", String::from_utf8_lossy(&out.stderr));
    let rendered: serde_json::Value = serde_json::from_slice(&out.stdout).unwrap();
    let exposure = rendered["exposure"].as_f64().unwrap().to_string();

    // Hide the panel, fly forward, drag the view, jump to the next camera (the chamber), look at
    // the albedo and back, ask for a screenshot (written once the light has converged) and quit.
    let summary = view_under_xvfb(
        dir.path(),
        &format!(
            "{p} {} --render-scale 1 --exposure {exposure} --screenshot {} --record-path {}",
            common.join(" "),
            shot.display(),
            walk.display()
        ),
        "key h mousemove 80 60 keydown w sleep 2 keyup w mousedown 1 mousemove_relative --sync 60 0 \
         mouseup 1 sleep 0.5 key Tab key 2 sleep 0.3 key 1 key p key Escape",
    );
    assert!(!summary["log"]["moving_ms"].as_array().unwrap().is_empty(), "W flew the camera: {summary}");
    assert!(!summary["log"]["converge_frames"].as_array().unwrap().is_empty(), "{summary}");

    // The screenshot is the chamber camera as grotto render sees it, through the golden tolerance.
    let (a, b) = (image::open(&shot).unwrap().to_rgba8(), image::open(&reference).unwrap().to_rgba8());
    assert_eq!(a.dimensions(), (160, 120));
    let px = |i: &image::RgbaImage| i.pixels().map(|p| p.0).collect::<Vec<[u8; 4]>>();
    let d = golden::diff(&px(&a), &px(&b));
    assert!(golden::within_tolerance(&d), "viewer against grotto render: {d:?}");

    // The recorded path ends at the chamber and flies again in grotto render.
    let keys = summary["paths"][0][1].as_u64().unwrap();
    assert!(keys >= 3, "start, flown, chamber: {keys} keys");
    let frames = dir.path().join("walk.png");
    let out = grotto(
        &["render", p, "--path", walk.to_str().unwrap(), "--frames", "3", "--out", frames.to_str().unwrap()]
            .into_iter()
            .chain(common)
            .collect::<Vec<_>>(),
    );
    assert!(out.status.success(), "{}", String::from_utf8_lossy(&out.stderr));
    let last = image::open(dir.path().join("walk_0002.png")).unwrap().to_rgba8();
    assert_eq!(last.dimensions(), (160, 120));

    // A section at the chamber camera's eye height, in a view without light (normals: smooth,
    // where the scan view's patches flip with the last bit of the camera, tested against the
    // palette in tests/tests/sections.rs). Such a view rests at once; the scripted screenshot
    // still comes after its frames, and matches grotto render's through the golden tolerance.
    let pkg = grotto_format::Package::open(&path).unwrap();
    let eye_z = pkg.scene().unwrap().cameras.iter().find(|c| c.name == "chamber").unwrap().eye_m[2];
    let (mut lo, mut hi) = ([f64::MAX; 3], [f64::MIN; 3]);
    for t in pkg.tiles() {
        for a in 0..3 {
            lo[a] = lo[a].min(t.origin_m()[a]);
            hi[a] = hi[a].max(t.origin_m()[a] + t.extent_m());
        }
    }
    let clip = format!("{},{},{},{},{},{eye_z}", lo[0], lo[1], lo[2], hi[0], hi[1]);
    let survey = ["--camera", "chamber", "--view", "normals", "--clip", &clip];
    let (cut_view, cut_render) = (dir.path().join("cut-view.png"), dir.path().join("cut-render.png"));
    let out = grotto(
        &["render", p, "--out", cut_render.to_str().unwrap()]
            .into_iter()
            .chain(survey)
            .chain(common)
            .collect::<Vec<_>>(),
    );
    assert!(out.status.success(), "{}", String::from_utf8_lossy(&out.stderr));
    let script = format!(
        "timeout 120 {bin} view {p} {common} {survey} --render-scale 1 --no-panel --after-frames 3 \
         --screenshot {shot}",
        bin = env!("CARGO_BIN_EXE_grotto"),
        common = common.join(" "),
        survey = survey.join(" "),
        shot = cut_view.display(),
    );
    let xvfb = Command::new("timeout")
        .args(["300", "xvfb-run", "-a", "-s", "-screen 0 640x480x24", "bash", "-c", &script])
        .env_remove("WAYLAND_DISPLAY")
        .output()
        .unwrap();
    assert!(xvfb.status.success(), "{}", String::from_utf8_lossy(&xvfb.stderr));
    let (a, b) = (image::open(&cut_view).unwrap().to_rgba8(), image::open(&cut_render).unwrap().to_rgba8());
    let d = golden::diff(&px(&a), &px(&b));
    assert!(golden::within_tolerance(&d), "normals with a clip box, viewer against grotto render: {d:?}");
    // The cut shows: the top rows (the chamber's ceiling) are background, the bottom rows rock.
    let row_lit = |y: u32| (0..160).filter(|&x| a.get_pixel(x, y).0[..3] != [0, 0, 0]).count();
    assert!(row_lit(2) < 16 && row_lit(117) > 144, "top row {} lit, bottom row {}", row_lit(2), row_lit(117));
}

/// A stand-in viewer bundle in `dir`: publish copies it, the browser test runs the real one.
fn stand_in_bundle(dir: &std::path::Path) -> std::path::PathBuf {
    let bundle = dir.join("bundle");
    std::fs::create_dir(&bundle).unwrap();
    for f in grotto_runtime::cli::publish::BUNDLE_FILES {
        std::fs::write(bundle.join(f), f).unwrap();
    }
    bundle
}

#[test]
fn publish_writes_a_site_replaces_it_whole_and_refuses_what_it_cannot_serve() {
    let dir = tempfile::tempdir().unwrap();
    let path = dir.path().join("demo.grotto");
    demo::build(&path, &DemoParams { points: 3_000, ..DemoParams::default() }).unwrap();
    let bundle = stand_in_bundle(dir.path());
    let site = dir.path().join("site");
    let (p, s, b) = (path.to_str().unwrap(), site.to_str().unwrap(), bundle.to_str().unwrap());
    let out = grotto(&[
        "publish",
        p,
        "--out",
        s,
        "--bundle",
        b,
        "--camera",
        "centre",
        "--quality",
        "fast",
        "--no-picture",
        "--json",
    ]);
    assert!(out.status.success(), "{}", String::from_utf8_lossy(&out.stderr));
    let summary: serde_json::Value = serde_json::from_slice(&out.stdout).unwrap();
    assert_eq!(summary["package_bytes"], std::fs::metadata(&path).unwrap().len());
    assert_eq!(std::fs::read(site.join("demo.grotto")).unwrap(), std::fs::read(&path).unwrap());
    let config: serde_json::Value =
        serde_json::from_str(&std::fs::read_to_string(site.join("viewer.json")).unwrap()).unwrap();
    assert_eq!(config["package"], "demo.grotto");
    assert_eq!(config["options"]["camera"], "centre");
    assert_eq!(config["options"]["quality"], "fast");
    // Published again, the site is replaced whole: a stray file of the old one is gone.
    std::fs::write(site.join("stray.txt"), "old").unwrap();
    assert!(grotto(&["publish", p, "--out", s, "--bundle", b, "--no-picture"]).status.success());
    assert!(!site.join("stray.txt").exists() && site.join("index.html").is_file());

    // No bundle: a clear error, and the site that was there stays.
    std::fs::write(site.join("stray.txt"), "kept").unwrap();
    let missing = dir.path().join("no-bundle");
    let out = grotto(&["publish", p, "--out", s, "--bundle", missing.to_str().unwrap()]);
    let err = String::from_utf8_lossy(&out.stderr);
    assert!(!out.status.success() && err.contains("scripts/build-web.sh"), "{err}");
    assert_eq!(std::fs::read_to_string(site.join("stray.txt")).unwrap(), "kept");
    // A damaged package is refused before anything is written.
    let mut bytes = std::fs::read(&path).unwrap();
    let n = bytes.len();
    bytes[n - 100] ^= 0xff;
    let bad = dir.path().join("bad.grotto");
    std::fs::write(&bad, bytes).unwrap();
    let other = dir.path().join("other-site");
    let out = grotto(&["publish", bad.to_str().unwrap(), "--out", other.to_str().unwrap(), "--bundle", b]);
    assert!(!out.status.success(), "a damaged package was published");
    assert!(!other.exists());
    // Nothing left beside the sites.
    let leftovers: Vec<_> = std::fs::read_dir(dir.path())
        .unwrap()
        .filter_map(|e| e.ok())
        .filter(|e| e.file_name().to_string_lossy().starts_with(".grotto-publish"))
        .collect();
    assert!(leftovers.is_empty(), "{leftovers:?}");
}

#[test]
fn publish_adds_a_story_file_to_the_package_and_refuses_one_that_does_not_hold_together() {
    let dir = tempfile::tempdir().unwrap();
    let path = dir.path().join("demo.grotto");
    let params = DemoParams { points: 3_000, ..DemoParams::default() };
    demo::build(&path, &params).unwrap();
    let bundle = stand_in_bundle(dir.path());
    let c = params.center_m;
    let story = dir.path().join("story.toml");
    std::fs::write(
        &story,
        format!(
            "[[poi]]\nname = \"wall\"\ntitle = \"The wall\"\nposition = [{}, {}, {}]\neye = [{}, {}, {}]\n\n\
             [[tour]]\nname = \"round\"\n[[tour.stop]]\ncamera = \"centre\"\ndwell_s = 2\n[[tour.stop]]\npoi = \"wall\"\n",
            c[0] + params.radius_m,
            c[1],
            c[2],
            c[0],
            c[1],
            c[2]
        ),
    )
    .unwrap();
    let site = dir.path().join("site");
    let (p, s, b) = (path.to_str().unwrap(), site.to_str().unwrap(), bundle.to_str().unwrap());
    let out = grotto(&[
        "publish",
        p,
        "--out",
        s,
        "--bundle",
        b,
        "--story",
        story.to_str().unwrap(),
        "--no-picture",
        "--json",
    ]);
    assert!(out.status.success(), "{}", String::from_utf8_lossy(&out.stderr));
    let summary: serde_json::Value = serde_json::from_slice(&out.stdout).unwrap();
    assert_eq!((summary["pois"].as_u64(), summary["tours"].as_u64()), (Some(1), Some(1)));
    let config: serde_json::Value =
        serde_json::from_str(&std::fs::read_to_string(site.join("viewer.json")).unwrap()).unwrap();
    assert_eq!(config["story"]["pois"][0]["name"], "wall");
    // Survey coordinates reach the page whole.
    assert_eq!(config["story"]["pois"][0]["position_m"][0].as_f64(), Some(c[0] + params.radius_m));
    assert_eq!(config["story"]["tours"][0]["stops"][1]["poi"], "wall");

    // A stop at a place that does not exist, or a misspelt key: refused, naming the file, and
    // the site that was there stays.
    for (text, expected) in [
        (
            "[[tour]]\nname = \"t\"\n[[tour.stop]]\npoi = \"nowhere\"\n",
            "no point of interest named 'nowhere'",
        ),
        ("[[tour]]\nname = \"t\"\n[[tour.stop]]\ncamera = \"centre\"\ndwel_s = 3\n", "dwel_s"),
    ] {
        std::fs::write(&story, text).unwrap();
        let out = grotto(&[
            "publish",
            p,
            "--out",
            s,
            "--bundle",
            b,
            "--story",
            story.to_str().unwrap(),
            "--no-picture",
        ]);
        let err = String::from_utf8_lossy(&out.stderr);
        assert!(!out.status.success() && err.contains("story.toml") && err.contains(expected), "{err}");
        let kept: serde_json::Value =
            serde_json::from_str(&std::fs::read_to_string(site.join("viewer.json")).unwrap()).unwrap();
        assert_eq!(kept["story"]["pois"][0]["name"], "wall");
    }
}

#[test]
fn view_labels_measures_and_tours_the_room_under_xvfb() {
    use grotto_fixtures::room;
    let dir = tempfile::tempdir().unwrap();
    let package = room::room_package(dir.path()).unwrap();
    let walk = dir.path().join("walk.toml");
    // Real X input on Xvfb (as above): with the panel hidden (H) the clicks reach the cave. M and
    // two clicks measure from a floor pixel to a ceiling pixel of the hall camera (window pixels
    // of a frame drawn at half the window's size: the guide scales them once); T marks a tour
    // stop on the path --record-path records from the start, K ends that recording; G plays the room's tour; Escape ends the session, whose --json
    // says what the story was doing then.
    let summary = view_under_xvfb(
        dir.path(),
        &format!(
            "{} --camera hall --size 320x240 --quality fast --bounces 0 --software --render-scale 0.5 \
             --samples 1 --record-path {}",
            package.display(),
            walk.display()
        ),
        "sleep 3 key h sleep 0.5 key m sleep 0.3 mousemove --window $wid 167 228 click 1 sleep 1 \
         mousemove --window $wid 149 10 click 1 sleep 2 key t sleep 0.3 key k sleep 0.3 key g sleep 1 key Escape",
    );
    let story = &summary["story"];
    eprintln!("{story:#}");
    // The labels were probed in the hall's view before anything moved.
    assert_eq!(story["labels"][0], serde_json::json!(["niche", true]), "{story}");
    // Measured floor to ceiling: the room is 2.5 m high.
    let height = story["measure"]["result"]["height_m"].as_f64().unwrap();
    assert!((height - room::SIZE_M[2]).abs() < 0.01, "measured {height} m");
    // The tour started at its first stop; the marked stop was written beside the path.
    assert_eq!(story["tour"]["name"], "walk", "{story}");
    assert_eq!(story["tour"]["stop"], 0);
    assert_eq!(summary["tours"][0][1], 1, "{}", summary["tours"]);
    let tour = std::fs::read_to_string(dir.path().join("walk-tour.toml")).unwrap();
    assert!(tour.contains("[[tour.stop]]"), "{tour}");
}

#[test]
fn view_places_a_lamp_in_lighting_mode_and_saves_a_file_render_reads() {
    use grotto_fixtures::room;
    let dir = tempfile::tempdir().unwrap();
    let package = room::room_package(dir.path()).unwrap();
    let lights = dir.path().join("show.toml");
    // The niche's pixel in the hall camera's 320 x 240 frame: a click there finds the far wall.
    let (rel, hall) = (room::local, room::hall_camera());
    let at = grotto_runtime::view::story::project(&hall, 320, 240, rel(room::NICHE_M)).unwrap();
    // The session starts from a file with a lamp on a circuit; L (lighting mode), a click at the
    // niche (a lamp 0.5 m off the wall toward the eye), V saves at once: the click is answered
    // before the file is written, however slow the frame drawing then (a loaded CI machine).
    std::fs::write(
        &lights,
        format!(
            "[[circuit]]\nname = \"show\"\n[[light]]\nname = \"first\"\nposition = {:?}\nlumens = 500.0\ncircuit = \"show\"\n",
            room::world([1.0, 1.0, 2.0])
        ),
    )
    .unwrap();
    let summary = view_under_xvfb(
        dir.path(),
        &format!(
            "{} --camera hall --size 320x240 --quality fast --bounces 0 --software --render-scale 1 \
             --samples 1 --lights {}",
            package.display(),
            lights.display()
        ),
        &format!(
            "sleep 3 key h sleep 0.3 key l sleep 0.3 mousemove --window $wid {} {} click 1 key v key Escape",
            at.x_px as u32, at.y_px as u32
        ),
    );
    assert_eq!(
        summary["lights_saved"][0].as_str(),
        Some(lights.to_str().unwrap()),
        "{}",
        summary["lights_saved"]
    );
    let text = std::fs::read_to_string(&lights).unwrap();
    let saved = grotto_format::lighting::parse(&text, |_| Err("no IES".into())).unwrap();
    let names: Vec<&str> = saved.lights.iter().map(|l| l.name.as_str()).collect();
    assert_eq!(names, ["first", "lamp-1"], "{text}");
    let grotto_format::LightShape::Point { position_m } = saved.lights[1].shape else { panic!("{text}") };
    let local = [0, 1, 2].map(|a| position_m[a] - room::ORIGIN_M[a]);
    // 0.5 m in front of the far wall (x = 6) along the ray through the niche's pixel.
    assert!((5.3..5.75).contains(&local[0]) && (2.6..3.4).contains(&local[1]), "lamp at {local:?}\n{text}");
    // grotto render reads the saved file.
    let out = grotto(&[
        "render",
        package.to_str().unwrap(),
        "--lights",
        lights.to_str().unwrap(),
        "--size",
        "64x48",
        "--quality",
        "fast",
        "--software",
        "--out",
        dir.path().join("lit.png").to_str().unwrap(),
    ]);
    assert!(out.status.success(), "{}", String::from_utf8_lossy(&out.stderr));
}

/// `grotto-pack` beside the `grotto` under test (`cargo test --workspace` builds both; a run of this
/// crate's tests alone builds it here).
fn grotto_pack_beside_grotto() -> std::path::PathBuf {
    let exe = std::path::Path::new(env!("CARGO_BIN_EXE_grotto"));
    let pack = exe.with_file_name(format!("grotto-pack{}", std::env::consts::EXE_SUFFIX));
    if !pack.is_file() {
        let cargo = std::env::var("CARGO").unwrap_or_else(|_| "cargo".into());
        let built = Command::new(cargo)
            .args(["build", "-p", "grotto-preprocess", "--bin", "grotto-pack"])
            .status()
            .unwrap();
        assert!(built.success() && pack.is_file(), "grotto-pack not built at {}", pack.display());
    }
    pack
}

/// A user's first try: `grotto render scan.las` packs the scan with the grotto-pack beside it into
/// the cache, renders it, and opens that package again the next time instead of packing again;
/// without grotto-pack the error names the scan and the command that packs it.
#[test]
fn a_scan_given_to_render_is_packed_once_then_rendered() {
    grotto_pack_beside_grotto();
    let dir = tempfile::tempdir().unwrap();
    let scan = concat!(env!("CARGO_MANIFEST_DIR"), "/../../shared/data/las/laspy_simple.las");
    let cache = dir.path().join("cache");
    let png = dir.path().join("scan.png");
    let render = |pack: Option<&str>| {
        let mut c = Command::new(env!("CARGO_BIN_EXE_grotto"));
        c.args(["render", scan, "--out", png.to_str().unwrap(), "--size", "64x48", "--quality", "fast"])
            .args(["--software", "--json"])
            .env("GROTTO_CACHE_DIR", &cache);
        if let Some(p) = pack {
            c.env("GROTTO_PACK", p);
        }
        c.output().unwrap()
    };
    let missing = render(Some("/nonexistent/grotto-pack"));
    let err = String::from_utf8_lossy(&missing.stderr);
    assert!(!missing.status.success(), "{err}");
    assert!(
        err.contains("laspy_simple.las") && err.contains("grotto-pack build FILE -o FILE.grotto"),
        "{err}"
    );
    assert!(!err.contains("panicked"), "{err}");

    let first = render(None);
    let err = String::from_utf8_lossy(&first.stderr);
    assert!(first.status.success(), "{err}");
    assert!(err.contains("a LAS/LAZ scan; packing it"), "{err}");
    let summary: serde_json::Value = serde_json::from_slice(&first.stdout).expect("stdout is the JSON alone");
    assert!(summary["surfels"].as_u64().unwrap_or(0) > 0 || png.is_file(), "{summary}");
    assert!(png.is_file());
    let packed = || std::fs::read_dir(&cache).unwrap().filter_map(|e| e.ok()).count();
    assert_eq!(packed(), 1, "one package in the cache");

    let again = render(None);
    let err = String::from_utf8_lossy(&again.stderr);
    assert!(again.status.success(), "{err}");
    assert!(err.contains("packed from it before"), "{err}");
    assert_eq!(packed(), 1, "packed once");
    let summary: serde_json::Value = serde_json::from_slice(&again.stdout).unwrap();
    assert!(summary.get("time_budget").is_none(), "a preset asked for is kept: {summary}");

    // With no preset asked for, a scan's light is bought with the default time.
    let default = Command::new(env!("CARGO_BIN_EXE_grotto"))
        .args(["render", scan, "--out", png.to_str().unwrap(), "--size", "64x48", "--software", "--json"])
        .env("GROTTO_CACHE_DIR", &cache)
        .output()
        .unwrap();
    assert!(default.status.success(), "{}", String::from_utf8_lossy(&default.stderr));
    let summary: serde_json::Value = serde_json::from_slice(&default.stdout).unwrap();
    assert_eq!(summary["time_budget"]["budget_s"].as_f64(), Some(30.0), "{summary}");
}

/// `--time-budget`: a generous budget buys the most accurate preset, one too small for any renders
/// the cheapest light and says so, and a budget that is no time is refused before any work.
#[test]
fn a_time_budget_buys_the_best_preset_that_fits_and_nonsense_is_refused() {
    let (dir, path) = tiny_cave();
    let p = path.to_str().unwrap();
    let png = dir.path().join("budget.png");
    let render = |extra: &[&str]| {
        let mut args =
            vec!["render", p, "--size", "32x24", "--software", "--json", "-o", png.to_str().unwrap()];
        args.extend_from_slice(extra);
        grotto(&args)
    };
    let json = |out: &std::process::Output| -> serde_json::Value {
        assert!(out.status.success(), "{}", String::from_utf8_lossy(&out.stderr));
        serde_json::from_slice(&out.stdout).unwrap()
    };

    let tiny = render(&["--time-budget", "0.000001"]);
    let summary = json(&tiny);
    let choice = &summary["time_budget"];
    assert_eq!(choice["too_small"], true, "{summary}");
    assert_eq!((choice["chosen"].as_str(), choice["bounces"].as_u64()), (Some("fast"), Some(1)), "{choice}");
    assert_eq!(summary["bounces"].as_u64(), Some(1), "the cheapest light: one bounce");
    assert_eq!(summary["settings"]["cones"].as_u64(), Some(4), "fast's cones");
    let err = String::from_utf8_lossy(&tiny.stderr);
    assert!(err.contains("warning: time budget") && err.contains("too small for any preset"), "{err}");

    let generous = json(&render(&["--time-budget", "100000"]));
    let choice = &generous["time_budget"];
    assert_eq!(
        (choice["chosen"].as_str(), choice["too_small"].as_bool()),
        (Some("high"), Some(false)),
        "{choice}"
    );
    assert_eq!(choice["made_anew"], true);
    let high = grotto_runtime::settings::Settings::preset(grotto_runtime::settings::Quality::High);
    assert_eq!(generous["settings"]["bounces"].as_u64(), Some(u64::from(high.bounces)), "high's bounces");
    assert_eq!(generous["settings"]["shadow_map_size"].as_u64(), Some(u64::from(high.shadow_map_size)));
    assert!(choice["predicted_s"].as_f64().unwrap() > choice["probe_s"].as_f64().unwrap());

    let text = grotto(&[
        "render",
        p,
        "--size",
        "32x24",
        "--software",
        "--time-budget",
        "100000",
        "-o",
        png.to_str().unwrap(),
    ]);
    let said = String::from_utf8_lossy(&text.stdout);
    assert!(text.status.success() && said.contains("time budget 100000.0 s: high"), "{said}");

    for bad in ["NaN", "-1", "0", "inf", "soon"] {
        let out = render(&["--time-budget", bad]);
        let err = String::from_utf8_lossy(&out.stderr);
        assert!(!out.status.success(), "--time-budget {bad} was taken");
        assert!(err.contains("--time-budget") && !err.contains("panicked"), "{bad}: {err}");
    }
    let both = render(&["--time-budget", "5", "--quality", "high"]);
    assert!(String::from_utf8_lossy(&both.stderr).contains("cannot be used with"), "a preset and a budget");
}

/// The subcommands `help` lists (the lines under "Commands:", `help` itself left out).
fn subcommands(help: &str) -> Vec<String> {
    help.lines()
        .skip_while(|l| !l.starts_with("Commands:"))
        .skip(1)
        .take_while(|l| !l.trim().is_empty())
        .filter_map(|l| l.split_whitespace().next())
        .filter(|name| *name != "help")
        .map(str::to_owned)
        .collect()
}

/// `program`'s reference in markdown: its help, then each subcommand's, as the program prints them.
fn help_reference(program: &std::path::Path, name: &str) -> String {
    let help = |args: &[&str]| {
        let out = Command::new(program).args(args).arg("--help").output().unwrap();
        assert!(out.status.success(), "{name} {args:?} --help: {}", String::from_utf8_lossy(&out.stderr));
        String::from_utf8(out.stdout).unwrap()
    };
    let top = help(&[]);
    let mut md = format!("## {name}\n\n```text\n{}\n```\n", top.trim_end());
    for sub in subcommands(&top) {
        md += &format!("\n### {name} {sub}\n\n```text\n{}\n```\n", help(&[&sub]).trim_end());
    }
    md
}

/// docs/cli.md is the commands' own help, generated: it cannot drift from the definitions. With
/// `GROTTO_BLESS=1` the test writes it again instead of comparing.
#[test]
fn the_command_line_reference_is_the_commands_own_help() {
    let pack = grotto_pack_beside_grotto();
    let grotto = std::path::Path::new(env!("CARGO_BIN_EXE_grotto"));
    let listed = |program: &std::path::Path| {
        subcommands(&String::from_utf8(Command::new(program).arg("--help").output().unwrap().stdout).unwrap())
    };
    let (of_grotto, of_pack) = (listed(grotto), listed(&pack));
    for (list, sub) in
        [(&of_grotto, "render"), (&of_grotto, "view"), (&of_grotto, "publish"), (&of_pack, "build")]
    {
        assert!(list.iter().any(|s| s == sub), "no {sub} in {list:?}");
    }
    let want = format!(
        "# Command-line reference\n\nEvery command and option of `grotto` and `grotto-pack`, as their \
         `--help` prints them. Generated: `GROTTO_BLESS=1 cargo test -p grotto-runtime --test cli \
         the_command_line_reference` writes it again, and the test fails while it differs from the \
         commands. Do not edit by hand; the user's guide (guide.md) says when to use which.\n\n{}\n{}",
        help_reference(grotto, "grotto"),
        help_reference(&pack, "grotto-pack"),
    );
    let path = concat!(env!("CARGO_MANIFEST_DIR"), "/../docs/cli.md");
    if std::env::var_os("GROTTO_BLESS").is_some() {
        std::fs::write(path, &want).unwrap();
    }
    let have = std::fs::read_to_string(path).unwrap_or_default();
    assert!(
        have == want,
        "docs/cli.md differs from the commands' help: run GROTTO_BLESS=1 cargo test -p grotto-runtime \
         --test cli the_command_line_reference, and commit it"
    );
}
