//! The browser viewer end to end, in a real browser: a demo cave published with
//! `grotto publish` (the library call the command makes), served on 127.0.0.1 by a static server
//! that answers range requests (tests/src/serve.rs), opened in headless Chromium on its software
//! WebGPU adapter (SwiftShader) driven by chromedriver (WebDriver). The test waits for the ready
//! marker the page sets (light converged on the tiles the view wants), takes a screenshot of the
//! canvas and compares it with `grotto render` of the same camera (lavapipe) through the golden
//! tolerance helper. It also checks how the package arrived: by ranges only, the first frame after
//! a small part of it, nothing fetched twice. A page in a browser without WebGPU must say so.
//!
//! Needs Debian's `chromium` and `chromium-driver` and the viewer bundle (`scripts/build-web.sh`,
//! target/web): `scripts/test.sh` installs and builds them. Without them these tests fail, naming
//! what is missing, unless `GROTTO_SKIP_BROWSER=1` says to skip them.

use std::io::{BufRead, Read, Write};
use std::net::TcpStream;
use std::path::{Path, PathBuf};
use std::process::{Child, Command, Stdio};
use std::sync::Mutex;
use std::time::{Duration, Instant};

use base64::Engine;
use grotto_preprocess::build;
use grotto_preprocess::ingest::ScanFormat;
use grotto_preprocess::manifest::Manifest;
use grotto_preprocess::synth::{self, SynthParams};
use grotto_runtime::cli::publish::{self, PublishOptions};
use grotto_runtime::cli::render_job;
use grotto_runtime::engine::RenderOptions;
use grotto_runtime::settings::{Quality, Settings};
use grotto_runtime::view::framing::CameraChoice;
use grotto_tests::{golden, serve};
use serde_json::{Value, json};

/// One browser at a time: two would share the machine's 2 cores and slow each other past their
/// timeouts.
static BROWSER: Mutex<()> = Mutex::new(());

const W: u32 = 320;
const H: u32 = 240;
/// How long a page may take to converge and gather its still samples: SwiftShader drew a 320x240
/// frame in 3.7 s on the 2-core machine under load, and a page at 59 frames was still gathering
/// after 300 s there. A guard against a page that never settles, not a speed test.
const READY_LIMIT: Duration = Duration::from_secs(600);

/// The browser, its driver and the viewer bundle, or None where the tests are to be skipped.
fn tools() -> Option<(PathBuf, PathBuf, PathBuf)> {
    if std::env::var_os("GROTTO_SKIP_BROWSER").is_some_and(|v| v == "1") {
        eprintln!("GROTTO_SKIP_BROWSER=1: browser test skipped");
        return None;
    }
    let root = Path::new(env!("CARGO_MANIFEST_DIR")).parent().unwrap();
    let bundle = std::env::var_os("GROTTO_WEB_BUNDLE").map_or_else(|| root.join("target/web"), PathBuf::from);
    let chromium = PathBuf::from(std::env::var_os("GROTTO_CHROMIUM").unwrap_or("/usr/bin/chromium".into()));
    let driver =
        PathBuf::from(std::env::var_os("GROTTO_CHROMEDRIVER").unwrap_or("/usr/bin/chromedriver".into()));
    for (what, p) in [("chromium", &chromium), ("chromedriver", &driver)] {
        assert!(
            p.is_file(),
            "{what} not found at {}: run scripts/test.sh (installs Debian's chromium and chromium-driver), \
             or set GROTTO_SKIP_BROWSER=1 to skip the browser tests",
            p.display()
        );
    }
    assert!(
        bundle.join("grotto_web_bg.wasm").is_file(),
        "no viewer bundle in {}: run scripts/build-web.sh (scripts/test.sh does), or set GROTTO_SKIP_BROWSER=1",
        bundle.display()
    );
    Some((chromium, driver, bundle))
}

/// One HTTP/1.1 exchange with chromedriver (JSON in and out).
fn http(port: u16, method: &str, path: &str, body: Option<&Value>) -> Value {
    let body = body.map(Value::to_string).unwrap_or_default();
    let mut s = TcpStream::connect(("127.0.0.1", port)).unwrap();
    s.set_read_timeout(Some(Duration::from_secs(300))).unwrap();
    write!(
        s,
        "{method} {path} HTTP/1.1\r\nHost: 127.0.0.1:{port}\r\nContent-Type: application/json\r\n\
         Content-Length: {}\r\nConnection: close\r\n\r\n{body}",
        body.len()
    )
    .unwrap();
    // chromedriver keeps the connection open: read the head, then Content-Length bytes.
    let mut reader = std::io::BufReader::new(s);
    let mut len = 0usize;
    loop {
        let mut line = String::new();
        reader.read_line(&mut line).unwrap();
        if line.trim().is_empty() {
            break;
        }
        if let Some((k, v)) = line.split_once(':')
            && k.eq_ignore_ascii_case("content-length")
        {
            len = v.trim().parse().unwrap();
        }
    }
    let mut out = vec![0; len];
    reader.read_exact(&mut out).unwrap();
    let text = String::from_utf8_lossy(&out);
    serde_json::from_str(&text).unwrap_or_else(|e| panic!("chromedriver {method} {path}: {e}: {text}"))
}

/// A chromedriver with one headless Chromium session; both end on drop.
struct Browser {
    driver: Child,
    port: u16,
    session: String,
}

impl Browser {
    fn start(chromium: &Path, driver: &Path, webgpu: bool) -> Self {
        let port = std::net::TcpListener::bind("127.0.0.1:0").unwrap().local_addr().unwrap().port();
        let driver = Command::new(driver)
            .arg(format!("--port={port}"))
            .stdout(Stdio::null())
            .stderr(Stdio::null())
            .spawn()
            .unwrap();
        let t0 = Instant::now();
        while TcpStream::connect(("127.0.0.1", port)).is_err() {
            assert!(t0.elapsed() < Duration::from_secs(30), "chromedriver did not start");
            std::thread::sleep(Duration::from_millis(100));
        }
        // The flags the issue gives for WebGPU on SwiftShader; without WebGPU, the page's API
        // is switched off as in a browser that lacks it.
        let mut args =
            vec!["--headless=new", "--no-sandbox", "--window-size=640,480", "--force-device-scale-factor=1"];
        if webgpu {
            args.extend([
                "--enable-unsafe-webgpu",
                "--enable-features=Vulkan",
                "--use-vulkan=swiftshader",
                "--use-angle=swiftshader",
            ]);
        } else {
            args.push("--disable-blink-features=WebGPU");
        }
        let caps = json!({"capabilities": {"alwaysMatch": {
            "goog:chromeOptions": {"binary": chromium, "args": args},
        }}});
        let mut b = Self { driver, port, session: String::new() };
        let v = http(port, "POST", "/session", Some(&caps));
        b.session = v["value"]["sessionId"].as_str().unwrap_or_else(|| panic!("no session: {v}")).to_owned();
        b
    }

    fn call(&self, method: &str, path: &str, body: Option<&Value>) -> Value {
        let v = http(self.port, method, &format!("/session/{}{path}", self.session), body);
        assert!(v["value"].get("error").is_none(), "WebDriver {method} {path}: {v}");
        v["value"].clone()
    }

    fn eval(&self, script: &str) -> Value {
        self.call("POST", "/execute/sync", Some(&json!({"script": script, "args": []})))
    }

    /// The canvas as the renderer drew it (PNG through WebDriver's element screenshot), without
    /// the page's labels, caption and measuring line drawn over it.
    fn screenshot_canvas(&self) -> image::RgbaImage {
        let id = self.canvas();
        let overlays = "['labels', 'caption', 'overlay', 'notice'].forEach(id => \
                        document.getElementById(id).style.visibility = VALUE); return 0";
        self.eval(&overlays.replace("VALUE", "'hidden'"));
        let png = self.call("GET", &format!("/element/{id}/screenshot"), None);
        self.eval(&overlays.replace("VALUE", "''"));
        let png = base64::engine::general_purpose::STANDARD.decode(png.as_str().unwrap()).unwrap();
        image::load_from_memory(&png).unwrap().to_rgba8()
    }

    /// A DevTools protocol command through chromedriver (touch emulation, touch events).
    fn cdp(&self, cmd: &str, params: Value) -> Value {
        self.call("POST", "/goog/cdp/execute", Some(&json!({"cmd": cmd, "params": params})))
    }

    /// The canvas element's WebDriver id.
    fn canvas(&self) -> String {
        let canvas =
            self.call("POST", "/element", Some(&json!({"using": "css selector", "value": "#canvas"})));
        canvas.as_object().and_then(|o| o.values().next()).and_then(Value::as_str).unwrap().to_owned()
    }

    /// A mouse click at canvas pixel `(x, y)` (CSS pixels = rendered pixels), as a visitor's.
    fn click_canvas(&self, x: u32, y: u32) {
        let id = self.canvas();
        let origin = json!({"element-6066-11e4-a52e-4f735466cecf": id});
        // WebDriver offsets are from the element's centre.
        let (dx, dy) = (x as i64 - i64::from(W / 2), y as i64 - i64::from(H / 2));
        let actions = json!({"actions": [{"type": "pointer", "id": "mouse", "parameters": {"pointerType": "mouse"},
        "actions": [
            {"type": "pointerMove", "duration": 0, "origin": origin, "x": dx, "y": dy},
            {"type": "pointerDown", "button": 0},
            {"type": "pointerUp", "button": 0},
        ]}]});
        self.call("POST", "/actions", Some(&actions));
    }

    /// Keys typed into the canvas (as `KeyboardEvent`s with their codes).
    fn type_into_canvas(&self, text: &str) {
        let id = self.canvas();
        self.call("POST", &format!("/element/{id}/value"), Some(&json!({"text": text})));
    }

    /// Touches: each step is the fingers down now (canvas pixels), through the DevTools
    /// protocol's touch events (the page sees touch pointer events, as on a phone); the last
    /// step lifts them.
    fn touch(&self, steps: &[&[(f64, f64)]]) {
        let r = self.eval(
            "const r = document.getElementById('canvas').getBoundingClientRect(); return [r.left, r.top]",
        );
        let (left, top) = (r[0].as_f64().unwrap(), r[1].as_f64().unwrap());
        let points = |s: &[(f64, f64)]| -> Vec<Value> {
            s.iter().enumerate().map(|(i, (x, y))| json!({"x": left + x, "y": top + y, "id": i})).collect()
        };
        for (k, s) in steps.iter().enumerate() {
            let kind = if k == 0 { "touchStart" } else { "touchMove" };
            self.cdp("Input.dispatchTouchEvent", json!({"type": kind, "touchPoints": points(s)}));
        }
        self.cdp("Input.dispatchTouchEvent", json!({"type": "touchEnd", "touchPoints": []}));
    }

    /// Waits until `script` (returning a JSON string or null) gives something other than null.
    fn wait_for(&self, script: &str, limit: Duration) -> Value {
        let t0 = Instant::now();
        loop {
            let v = self.eval(script);
            let v: Value = serde_json::from_str(v.as_str().unwrap_or("null")).unwrap_or(Value::Null);
            if !v.is_null() {
                return v;
            }
            assert!(t0.elapsed() < limit, "nothing after {limit:?} from {script}");
            std::thread::sleep(Duration::from_millis(200));
        }
    }

    /// The page's status (`window.grottoStatus`), null before the viewer's first frame.
    fn status(&self) -> Value {
        let v = self.eval("return JSON.stringify(window.grottoStatus || null)");
        serde_json::from_str(v.as_str().unwrap_or("null")).unwrap_or(Value::Null)
    }

    /// Waits until the page has drawn `n` frames; returns its status then.
    fn wait_for_frames(&self, n: u64, limit: Duration) -> Value {
        let t0 = Instant::now();
        loop {
            let s = self.status();
            if s["frames"].as_u64().unwrap_or(0) >= n {
                return s;
            }
            assert!(t0.elapsed() < limit, "fewer than {n} frames after {limit:?}");
            std::thread::sleep(Duration::from_millis(200));
        }
    }

    /// Waits for the page's marker to leave loading/converging; returns it and the status.
    fn wait_for_marker(&self, limit: Duration) -> (String, Value) {
        let t0 = Instant::now();
        loop {
            let v = self.eval(
                "return [document.documentElement.dataset.grotto || '', \
                 JSON.stringify(window.grottoStatus || null), document.getElementById('message').innerText]",
            );
            let state = v[0].as_str().unwrap_or_default().to_owned();
            let status: Value = serde_json::from_str(v[1].as_str().unwrap_or("null")).unwrap_or(Value::Null);
            if !matches!(state.as_str(), "" | "loading" | "converging") {
                if state != "ready" {
                    eprintln!("page says: {}", v[2]);
                }
                return (state, status);
            }
            assert!(t0.elapsed() < limit, "not ready after {limit:?}: {state} {status}");
            std::thread::sleep(Duration::from_millis(500));
        }
    }
}

impl Drop for Browser {
    fn drop(&mut self) {
        if !self.session.is_empty() {
            let _ = http(self.port, "DELETE", &format!("/session/{}", self.session), None);
        }
        let _ = self.driver.kill();
        let _ = self.driver.wait();
    }
}

/// A demo cave small enough for a software GPU in a browser: 60k points over 8 segments, cut
/// into many tiles so the viewer has tiles to stream.
fn small_demo(dir: &Path) -> PathBuf {
    let params = SynthParams { points: 60_000, segments: 8, ..SynthParams::default() };
    let formats = [ScanFormat::Las, ScanFormat::Ply];
    let summary = synth::write_dataset(&dir.join("scans"), &params, &formats, &|_, _| {}).unwrap();
    let manifest_path = PathBuf::from(&summary.manifest);
    let manifest = Manifest::load(&manifest_path).unwrap();
    let out = dir.join("demo.grotto");
    let bp = build::BuildParams {
        max_tile_points: 16_384,
        ..build::BuildParams::with_leaf(dir.join("work"), 0.0625)
    };
    build::build(&manifest, &manifest_path, &out, &bp, &|_| {}).unwrap();
    out
}

/// `package` published with `bundle` into `dir/site`, served on 127.0.0.1.
fn published(
    dir: &Path,
    package: &Path,
    bundle: PathBuf,
    viewer_options: Value,
) -> (publish::PublishSummary, serve::Server) {
    published_lit(dir, package, bundle, viewer_options, None)
}

/// [`published`] with a lighting file (`grotto publish --lights`).
fn published_lit(
    dir: &Path,
    package: &Path,
    bundle: PathBuf,
    viewer_options: Value,
    lights: Option<PathBuf>,
) -> (publish::PublishSummary, serve::Server) {
    let site = dir.join("site");
    let summary = publish::publish(&PublishOptions {
        package: package.to_path_buf(),
        out: site.clone(),
        bundle: Some(bundle),
        title: None,
        viewer_options: serde_json::from_value(viewer_options).unwrap(),
        story: None,
        lights,
        picture: None,
    })
    .unwrap();
    (summary, serve::serve(&site).unwrap())
}

fn settings() -> Settings {
    Settings { bounces: 1, ..Settings::preset(Quality::Fast) }
}

#[test]
fn a_published_site_streams_the_package_by_ranges_and_shows_what_grotto_render_shows() {
    let Some((chromium, driver, bundle)) = tools() else { return };
    let _one = BROWSER.lock().unwrap_or_else(|e| e.into_inner());
    let dir = tempfile::tempdir().unwrap();
    let package = small_demo(dir.path());
    let pkg = grotto_format::Package::open(&package).unwrap();
    assert!(pkg.tile_count() >= 4, "{} tiles", pkg.tile_count());
    let package_bytes = pkg.file_size();
    drop(pkg);

    let (summary, server) = published(dir.path(), &package, bundle, json!({"camera": "chamber"}));
    assert!(summary.files.iter().any(|f| f == "demo.grotto"));
    let browser = Browser::start(&chromium, &driver, true);
    let url = format!(
        "http://127.0.0.1:{}/index.html?width={W}&height={H}&quality=fast&bounces=1&panel=hidden&bar=hidden",
        server.port
    );
    browser.call("POST", "/url", Some(&json!({"url": url})));
    let (state, status) = browser.wait_for_marker(READY_LIMIT);
    assert_eq!(state, "ready", "{status}");
    eprintln!("viewer status: {status}");
    let shot = browser.screenshot_canvas();
    drop(browser);
    assert_eq!(shot.dimensions(), (W, H), "the canvas shows the frame pixel for pixel");

    // How the package arrived: by ranges only, the first frame after a small part of it, and
    // every byte the page counted is one the server sent.
    let log = server.log.lock().unwrap().clone();
    let package_requests: Vec<_> = log.iter().filter(|s| s.path == "demo.grotto").collect();
    assert!(package_requests.iter().all(|s| s.status == 206 && s.range.is_some()), "{package_requests:?}");
    let served: u64 = package_requests.iter().map(|s| s.bytes).sum();
    assert_eq!(served, status["fetched_bytes"].as_u64().unwrap());
    assert_eq!(status["requests"].as_u64().unwrap(), package_requests.len() as u64);
    // The first frame reads the head, the directory and every tile's far level, nothing more:
    // the same ranges the viewer asks for, worked out here from the file (its 64 KiB merge gap).
    let first = status["first_frame_bytes"].as_u64().unwrap();
    let file = std::fs::read(&package).unwrap();
    let head = &file[..(grotto_format::Package::HEAD_BYTES as usize).min(file.len())];
    let dir_range = grotto_format::Package::directory_range("p", head, package_bytes).unwrap();
    let sparse = grotto_format::Package::from_directory(
        "p",
        package_bytes,
        head,
        dir_range.start,
        &file[dir_range.start as usize..dir_range.end as usize],
    )
    .unwrap();
    let far = grotto_runtime::stream::sections_for(
        &sparse,
        &vec![grotto_runtime::scene::data::TileMode::Far; sparse.tile_count() as usize],
        false,
    );
    let far_bytes: u64 = sparse.missing(far, 64 << 10).iter().map(|r| r.end - r.start).sum();
    let expected = head.len() as u64 + (dir_range.end - dir_range.start) + far_bytes;
    eprintln!("first frame after {first} of {package_bytes} bytes");
    assert_eq!(first, expected, "first frame after {first} bytes, the far levels are {expected}");
    assert!(first * 4 < package_bytes, "first frame after {first} of {package_bytes} bytes");
    // Merged ranges may carry a few bytes twice or between sections, never much.
    assert!(served <= package_bytes + package_bytes / 20, "served {served} of {package_bytes}");
    assert_eq!(
        status["tiles"][0].as_u64().unwrap() as u32,
        grotto_format::Package::open(&package).unwrap().tile_count()
    );

    // The same camera through `grotto render` (lavapipe), compared through the one tolerance.
    let exposure = status["exposure"].as_f64().unwrap_or(0.0);
    assert_matches_render(
        &shot,
        &package,
        CameraChoice::Named("chamber".into()),
        grotto_runtime::passes::resolve::DEFAULT_STILL_SAMPLES,
        exposure,
        None,
        "browser",
    );
}

/// `shot` (a canvas screenshot, W x H) against `grotto render` of `camera` on lavapipe with the
/// test's settings and `samples` a pixel, through the golden tolerance per 2 x 2 block (two
/// rasterisers resolve depth ties between overlapping surfels differently pixel by pixel;
/// `golden::block_mean` has the measurements). On failure both images are kept as `name`.
fn assert_matches_render(
    shot: &image::RgbaImage,
    package: &Path,
    camera: CameraChoice,
    samples: u32,
    page_exposure: f64,
    exposure: Option<f32>,
    name: &str,
) {
    let keep = Path::new(env!("CARGO_TARGET_TMPDIR"));
    let native = keep.join(format!("{name}-native.png"));
    let opts = RenderOptions {
        camera,
        width: W,
        height: H,
        settings: settings(),
        gpu: grotto_tests::lavapipe(),
        samples,
        exposure,
        ..RenderOptions::defaults(package.to_path_buf(), native.clone())
    };
    let rendered = render_job::run(&opts, |_| {}).unwrap();
    let expected = image::open(&native).unwrap().to_rgba8();
    let px = |img: &image::RgbaImage| img.pixels().map(|p| p.0).collect::<Vec<[u8; 4]>>();
    let per_pixel = golden::diff(&px(shot), &px(&expected));
    let d =
        golden::diff(&golden::block_mean(&px(shot), W, H, 2), &golden::block_mean(&px(&expected), W, H, 2));
    eprintln!(
        "{name}: browser vs grotto render: per 2x2 block mean {:.2}, p99 {}, max {}; per pixel mean {:.2}, \
         p99 {}; exposure {page_exposure} vs {}",
        d.mean_abs, d.p99_abs, d.max_abs, per_pixel.mean_abs, per_pixel.p99_abs, rendered.exposure
    );
    if !golden::within_tolerance(&d) {
        shot.save(keep.join(format!("{name}.png"))).unwrap();
        panic!(
            "{name}: the browser's frame differs from grotto render's: {d:?} (both in {})",
            keep.display()
        );
    }
}

#[test]
fn a_browser_without_webgpu_gets_the_picture_and_the_points_of_interest_not_a_blank_page() {
    let Some((chromium, driver, bundle)) = tools() else { return };
    let _one = BROWSER.lock().unwrap_or_else(|e| e.into_inner());
    let dir = tempfile::tempdir().unwrap();
    let package = grotto_fixtures::room::room_package(dir.path()).unwrap();
    let site = dir.path().join("site");
    let summary = publish::publish(&PublishOptions {
        package: package.clone(),
        out: site.clone(),
        bundle: Some(bundle),
        title: Some("The room".into()),
        viewer_options: serde_json::Map::new(),
        story: None,
        lights: None,
        picture: Some(publish::Picture { width: 160, height: 120, gpu: grotto_tests::lavapipe() }),
    })
    .unwrap();
    assert_eq!(summary.picture.as_deref(), Some(publish::PICTURE_FILE));
    // The picture is the tour's first stop (the niche), as grotto render draws it.
    let picture = image::open(site.join(publish::PICTURE_FILE)).unwrap().to_rgb8();
    assert_eq!(picture.dimensions(), (160, 120));
    let server = serve::serve(&site).unwrap();
    let browser = Browser::start(&chromium, &driver, false);
    browser.call("POST", "/url", Some(&json!({"url": format!("http://127.0.0.1:{}/", server.port)})));
    let (state, _) = browser.wait_for_marker(Duration::from_secs(60));
    assert_eq!(state, "no-webgpu");
    let text = browser.eval("return document.getElementById('message').innerText");
    let text = text.as_str().unwrap();
    assert!(
        text.contains("no WebGPU") && text.contains("The niche") && text.contains("Behind the pillar"),
        "{text}"
    );
    // The picture arrived and shows (decoded at its size).
    let shown = browser.wait_for(
        "const i = document.getElementById('picture'); return i && i.complete && i.naturalWidth ? \
         JSON.stringify([i.naturalWidth, i.naturalHeight]) : null",
        Duration::from_secs(30),
    );
    assert_eq!(shown, json!([160, 120]));
    let log = server.log.lock().unwrap().clone();
    assert!(log.iter().all(|s| s.path != "room.grotto"), "the package was fetched: {log:?}");
    assert!(log.iter().any(|s| s.path == publish::PICTURE_FILE && s.status == 200), "{log:?}");
}

/// What the page fetched before its first frame, on a package of your choice: the figures in
/// docs/web.md ("What a visitor downloads"). Run by `scripts/bench-web.sh PACKAGE`; ignored in
/// the suite (it needs a large package).
#[test]
#[ignore = "a measurement: scripts/bench-web.sh PACKAGE"]
fn bytes_before_the_first_frame() {
    let Some((chromium, driver, bundle)) = tools() else { return };
    let package =
        PathBuf::from(std::env::var_os("GROTTO_WEB_BENCH_PACKAGE").expect("GROTTO_WEB_BENCH_PACKAGE"));
    let _one = BROWSER.lock().unwrap_or_else(|e| e.into_inner());
    let dir = tempfile::tempdir().unwrap();
    let (summary, server) = published(dir.path(), &package, bundle, json!({}));
    let browser = Browser::start(&chromium, &driver, true);
    let url = format!("http://127.0.0.1:{}/index.html?width={W}&height={H}&quality=fast", server.port);
    browser.call("POST", "/url", Some(&json!({"url": url})));
    let status = browser.wait_for_frames(1, Duration::from_secs(600));
    let name = package.file_name().unwrap().to_string_lossy().into_owned();
    let served: Vec<_> = server.log.lock().unwrap().clone();
    let site_bytes: u64 = served.iter().filter(|s| s.path != name).map(|s| s.bytes).sum();
    let first = status["first_frame_bytes"].as_u64().unwrap();
    let total = status["package_bytes"].as_u64().unwrap();
    println!(
        "| package | bytes | fetched before the first frame | share | requests | viewer (HTML, JS, wasm) | first frame |"
    );
    println!(
        "| {name} | {total} | {first} | {:.3}% | {} | {site_bytes} ({} wasm) | {:.1} s |",
        100.0 * first as f64 / total as f64,
        status["requests"],
        summary.wasm_bytes,
        status["first_frame_ms"].as_f64().unwrap_or(0.0) / 1e3
    );
    assert!(first * 10 < total, "the first frame waited for {first} of {total} bytes");
}

/// Frame times of the viewer while the camera moves: PACKAGE (GROTTO_WEB_BENCH_PACKAGE)
/// published and opened at 800x600 (GROTTO_WEB_BENCH_SIZE) on SwiftShader; after its first frames
/// W is held for GROTTO_WEB_BENCH_MOVE_S seconds (default 60) while the page's frames are timed
/// (a timestamp each time the status counts a new frame). GROTTO_WEB_BENCH_QUERY adds to the
/// page's query (e.g. `&target_fps=0`; a viewer without a frame-time target refuses that option). Prints
/// a row: frames, median, p95 and worst milliseconds between frames, and what the frame-time
/// target traded at the end.
#[test]
#[ignore = "a measurement: scripts/bench-web-frames.sh PACKAGE"]
fn frame_times_while_moving() {
    let Some((chromium, driver, bundle)) = tools() else { return };
    let package =
        PathBuf::from(std::env::var_os("GROTTO_WEB_BENCH_PACKAGE").expect("GROTTO_WEB_BENCH_PACKAGE"));
    let size = std::env::var("GROTTO_WEB_BENCH_SIZE").unwrap_or_else(|_| "800x600".into());
    let (w, h) = size.split_once('x').expect("SIZE as WxH");
    let move_s: f64 =
        std::env::var("GROTTO_WEB_BENCH_MOVE_S").ok().and_then(|s| s.parse().ok()).unwrap_or(60.0);
    let query = std::env::var("GROTTO_WEB_BENCH_QUERY").unwrap_or_default();
    let _one = BROWSER.lock().unwrap_or_else(|e| e.into_inner());
    let dir = tempfile::tempdir().unwrap();
    let (_, server) = published(dir.path(), &package, bundle, json!({}));
    let browser = Browser::start(&chromium, &driver, true);
    let url = format!("http://127.0.0.1:{}/index.html?width={w}&height={h}&quality=fast{query}", server.port);
    browser.call("POST", "/url", Some(&json!({"url": url})));
    browser.wait_for_frames(3, Duration::from_secs(900));
    browser.eval(
        "window.grottoTimes = []; let last = -1; const tick = () => { const s = window.grottoStatus; \
         if (s && s.frames !== last) { last = s.frames; window.grottoTimes.push(performance.now()); \
         (window.grottoSeen = window.grottoSeen || []).push([s.frames, s.fetching, s.bounces_done, s.light_fraction, s.tiles, s.frame_ms]); } \
         requestAnimationFrame(tick); }; requestAnimationFrame(tick); \
         document.getElementById('canvas').dispatchEvent(new KeyboardEvent('keydown', {code: 'KeyW'})); \
         return 0",
    );
    std::thread::sleep(Duration::from_secs_f64(move_s));
    let v = browser.eval(
        "document.getElementById('canvas').dispatchEvent(new KeyboardEvent('keyup', {code: 'KeyW'})); \
         return JSON.stringify(window.grottoTimes)",
    );
    let status = browser.status();
    let times: Vec<f64> = serde_json::from_str(v.as_str().unwrap_or("[]")).unwrap_or_default();
    if std::env::var_os("GROTTO_WEB_BENCH_TRACE").is_some() {
        // What the page said at each frame: frames, fetching, bounces, light fraction, tiles, ms.
        let seen = browser.eval("return JSON.stringify(window.grottoSeen || [])");
        let seen: Vec<Value> = serde_json::from_str(seen.as_str().unwrap_or("[]")).unwrap_or_default();
        for (i, (t, s)) in times.iter().zip(&seen).enumerate() {
            let gap = if i > 0 { t - times[i - 1] } else { 0.0 };
            if gap > 500.0 || i < 3 {
                eprintln!("frame at {t:.0} ms after {gap:.0} ms: {s}");
            }
        }
    }
    let mut gaps: Vec<f64> = times.windows(2).map(|p| p[1] - p[0]).collect();
    gaps.sort_by(f64::total_cmp);
    let at = |q: f64| gaps.get(((gaps.len().max(1) - 1) as f64 * q).round() as usize).copied().unwrap_or(0.0);
    let name = package.file_name().unwrap().to_string_lossy().into_owned();
    println!(
        "| package | size | query | frames in {move_s} s | median ms | p95 ms | worst ms | traded at the end |"
    );
    println!(
        "| {name} | {size} | {query} | {} | {:.0} | {:.0} | {:.0} | {} |",
        times.len(),
        at(0.5),
        at(0.95),
        gaps.last().copied().unwrap_or(0.0),
        status.get("traded").map_or_else(|| "-".into(), Value::to_string)
    );
    assert!(times.len() >= 2, "no frames while moving");
}

/// The numbers of a view link (`x,y,z,heading,pitch,fov`).
fn link_numbers(link: &str) -> Vec<f64> {
    link.split(',').map(|v| v.parse().unwrap()).collect()
}

/// Points of interest and tours in the browser, on the scanned room of known size (grotto_fixtures::room): labels of
/// points of interest where the camera projects them, the one behind the pillar hidden; a
/// measurement of the room's height by two clicks within a centimetre; the address's view link
/// following the camera and a shared link restoring it to the centimetre; touch gestures (one
/// finger looks, two pinch and pan, a double tap flies to the wall) through the DevTools
/// protocol's touch events.
#[test]
fn a_published_room_labels_measures_shares_and_answers_touch() {
    use grotto_fixtures::room;
    use grotto_runtime::view::story;
    let Some((chromium, driver, bundle)) = tools() else { return };
    let _one = BROWSER.lock().unwrap_or_else(|e| e.into_inner());
    let dir = tempfile::tempdir().unwrap();
    let package = room::room_package(dir.path()).unwrap();
    let (summary, server) = published(dir.path(), &package, bundle, json!({"camera": "hall"}));
    assert_eq!((summary.pois, summary.tours), (2, 1));
    let browser = Browser::start(&chromium, &driver, true);
    let base = format!(
        "http://127.0.0.1:{}/index.html?width={W}&height={H}&quality=fast&bounces=1&panel=hidden&bar=hidden&samples=1",
        server.port
    );
    browser.call("POST", "/url", Some(&json!({"url": base})));
    let (state, status) = browser.wait_for_marker(READY_LIMIT);
    assert_eq!(state, "ready", "{status}");
    browser.wait_for(
        "const s = window.grottoStatus; return s && s.labels_current ? JSON.stringify(s.labels) : null",
        Duration::from_secs(60),
    );

    // Labels: where the camera projects each point of interest, hidden where the pillar is.
    let (rel, hall) = (room::local, room::hall_camera());
    let labels = browser.eval(
        "return JSON.stringify([...document.querySelectorAll('.poi')].map(e => [e.dataset.poi, \
         parseFloat(e.style.left), parseFloat(e.style.top), e.classList.contains('hidden')]))",
    );
    let labels: Vec<(String, f32, f32, bool)> = serde_json::from_str(labels.as_str().unwrap()).unwrap();
    eprintln!("labels: {labels:?}");
    for (name, at, hidden) in [("niche", room::NICHE_M, false), ("behind", room::BEHIND_M, true)] {
        let expected = story::project(&hall, W, H, rel(at)).unwrap();
        let l = labels.iter().find(|l| l.0 == name).unwrap();
        assert!(
            (l.1 - expected.x_px).abs() < 1.0 && (l.2 - expected.y_px).abs() < 1.0,
            "label {name} at ({}, {}), the camera projects it to ({}, {})",
            l.1,
            l.2,
            expected.x_px,
            expected.y_px
        );
        assert_eq!(l.3, hidden, "label {name}: hidden {}", l.3);
    }

    // The address carries the camera, to the millimetre.
    let hash = browser.wait_for(
        "return location.hash.includes('at=') ? JSON.stringify(location.hash) : null",
        Duration::from_secs(10),
    );
    let at = hash.as_str().unwrap().split("at=").nth(1).unwrap().split('&').next().unwrap().to_owned();
    let n = link_numbers(&at);
    let eye = room::world(room::HALL_EYE_M);
    assert!((0..3).all(|a| (n[a] - eye[a]).abs() < 0.002), "hash {at}, the hall's eye is {eye:?}");

    // Measuring: M, then a click on the floor and one on the ceiling.
    browser.type_into_canvas("m");
    browser.click_canvas(W / 2 + 7, H - 12);
    std::thread::sleep(Duration::from_millis(500));
    browser.click_canvas(W / 2 - 11, 10);
    let m = browser.wait_for(
        "const s = window.grottoStatus; return s && s.measure.result ? JSON.stringify(s.measure) : null",
        Duration::from_secs(60),
    );
    eprintln!("measured: {m}");
    let height = m["result"]["height_m"].as_f64().unwrap();
    assert!((height - room::SIZE_M[2]).abs() < 0.01, "the room is 2.5 m high, measured {height} m");
    let a = &m["points"][0];
    assert!((a[2].as_f64().unwrap() - room::ORIGIN_M[2]).abs() < 0.01, "first point not on the floor: {a}");
    let text = browser.eval("return document.getElementById('measuring').textContent");
    assert!(text.as_str().unwrap().contains("height +2.50"), "{text}");

    // A shared link opens on its camera, to the centimetre.
    let shared =
        [room::ORIGIN_M[0] + 2.0, room::ORIGIN_M[1] + 1.0, room::ORIGIN_M[2] + 1.2, 30.0, -10.0, 55.0];
    let link = shared.map(|v| format!("{v:.3}")).join(",");
    browser.call("POST", "/url", Some(&json!({"url": format!("{base}&shared=1#at={link}")})));
    let (state, status) = browser.wait_for_marker(READY_LIMIT);
    assert_eq!(state, "ready", "{status}");
    let got = link_numbers(status["link"].as_str().unwrap());
    eprintln!("shared {link}, opened at {}", status["link"]);
    assert!((0..3).all(|a| (got[a] - shared[a]).abs() < 0.01), "eye {got:?} vs {shared:?}");
    assert!((3..6).all(|a| (got[a] - shared[a]).abs() < 0.01), "angles {got:?} vs {shared:?}");

    // Touch: one finger to the right turns the view left by 0.005 rad a pixel (Nav::look).
    browser.cdp("Emulation.setTouchEmulationEnabled", json!({"enabled": true, "maxTouchPoints": 5}));
    let link_now = |b: &Browser| link_numbers(b.status()["link"].as_str().unwrap());
    let before = link_now(&browser);
    browser.touch(&[&[(160.0, 120.0)], &[(180.0, 120.0)], &[(200.0, 120.0)]]);
    std::thread::sleep(Duration::from_millis(400));
    let after = link_now(&browser);
    let turned = after[3] - before[3];
    assert!(
        (turned - (-40.0 * 0.005f64).to_degrees()).abs() < 0.5,
        "one finger turned the view {turned} deg"
    );
    // Two fingers spreading to twice their distance fly forward a second's flight (Nav::pinch).
    let before = link_now(&browser);
    browser.touch(&[
        &[(140.0, 120.0), (180.0, 120.0)],
        &[(130.0, 120.0), (190.0, 120.0)],
        &[(120.0, 120.0), (200.0, 120.0)],
    ]);
    std::thread::sleep(Duration::from_millis(400));
    let after = link_now(&browser);
    let (yaw, pitch) = (before[3].to_radians(), before[4].to_radians());
    let forward = [yaw.cos() * pitch.cos(), yaw.sin() * pitch.cos(), pitch.sin()];
    let moved: f64 = (0..3).map(|a| (after[a] - before[a]) * forward[a]).sum();
    assert!(moved > 0.3, "spreading two fingers moved the eye {moved} m forward");
    // A double tap on the far wall flies toward it.
    let before = link_now(&browser);
    let frames = browser.status()["frames"].as_u64().unwrap();
    browser.touch(&[&[(160.0, 100.0)]]);
    browser.touch(&[&[(160.0, 100.0)]]);
    browser.wait_for_frames(frames + 3, Duration::from_secs(60));
    let (state, status) = browser.wait_for_marker(READY_LIMIT);
    assert_eq!(state, "ready", "{status}");
    let after = link_numbers(status["link"].as_str().unwrap());
    let flown: f64 = (0..3).map(|a| (after[a] - before[a]).powi(2)).sum::<f64>().sqrt();
    eprintln!("double tap: {before:?} -> {after:?}");
    assert!(flown > 0.5, "a double tap flew {flown} m");

    // The tour, played to its end from the panel's buttons: at each stop, once the light has
    // converged (the dwell has begun), paused, and the canvas compared with `grotto render` of
    // the stop's camera.
    let click = |id: &str| browser.eval(&format!("document.getElementById('{id}').click(); return 0"));
    click("tourplay");
    for (stop, camera) in [(0u64, "niche"), (1, "hall")] {
        let t = browser.wait_for(
            &format!(
                "const t = window.grottoStatus && window.grottoStatus.tour; \
                 return t && t.stop === {stop} && t.phase === 'dwelling' ? JSON.stringify(t) : null"
            ),
            Duration::from_secs(300),
        );
        click("tourplay");
        browser.wait_for(
            "const t = window.grottoStatus && window.grottoStatus.tour; return t && t.paused ? '1' : null",
            Duration::from_secs(30),
        );
        let (state, status) = browser.wait_for_marker(READY_LIMIT);
        assert_eq!(state, "ready", "{status}");
        assert_eq!(status["tour"]["stop"], stop, "paused at the stop: {status}");
        let caption = browser.eval("return document.getElementById('caption').innerText");
        eprintln!("tour at stop {stop}: {t}; caption {caption}");
        assert!(caption.as_str().unwrap().contains(&format!("stop {} of 2", stop + 1)), "{caption}");
        // The page keeps its exposure as the view changes (automatic exposure is set as tiles
        // arrive): the render takes the page's.
        let shot = browser.screenshot_canvas();
        let exposure = status["exposure"].as_f64().unwrap_or(0.0);
        let choice = CameraChoice::Named(camera.into());
        assert_matches_render(&shot, &package, choice, 1, exposure, Some(exposure as f32), camera);
        click("tourplay");
    }
    browser.wait_for(
        "const t = window.grottoStatus && window.grottoStatus.tour; \
         return t && t.phase === 'finished' ? JSON.stringify(t) : null",
        Duration::from_secs(120),
    );
    drop(browser);
}

/// Package requests the page makes before its first frame: the head, the directory and the
/// merged ranges of every tile's far level (worked out from the file as the viewer does).
#[test]
fn a_visitor_switches_lighting_circuits_and_reads_the_lux_view() {
    use grotto_fixtures::room;
    let Some((chromium, driver, bundle)) = tools() else { return };
    let _one = BROWSER.lock().unwrap_or_else(|e| e.into_inner());
    let dir = tempfile::tempdir().unwrap();
    let package = room::room_package(dir.path()).unwrap();
    // A spot on the far wall on a circuit that starts switched off.
    let lights = dir.path().join("show.toml");
    std::fs::write(
        &lights,
        format!(
            "[[circuit]]\nname = \"wash\"\ntitle = \"Wall wash\"\non = false\n[[light]]\nname = \"wash\"\nkind = \"spot\"\n\
             position = {:?}\naim_at = {:?}\nouter_angle_deg = 25.0\nlumens = 20000.0\nkelvin = 2700.0\ncircuit = \"wash\"\n",
            room::world([1.0, 2.0, 2.2]),
            room::world(room::NICHE_M)
        ),
    )
    .unwrap();
    let (_, server) =
        published_lit(dir.path(), &package, bundle, json!({"camera": "hall", "exposure": 2.0}), Some(lights));
    let browser = Browser::start(&chromium, &driver, true);
    let url = format!(
        "http://127.0.0.1:{}/index.html?width=160&height=120&quality=fast&bounces=4&bar=hidden&samples=1\
         &rest_ms=5000",
        server.port
    );
    // Four bounces: a switch is taken in place, the light converging from what it was (render/
    // edit.rs), so the light switched off again matches the first image once both are near the
    // fixed point, not after a single bounce from different starts (eight took this test 379 s
    // on SwiftShader, four 182 s; each bounce of the room is about 11 s there). Frames at rest
    // of up to 5 s: at the default 100 ms the page gives the light only as long as each draw.
    browser.call("POST", "/url", Some(&json!({"url": url})));
    assert_eq!(browser.wait_for_marker(READY_LIMIT).0, "ready");
    let boxes = browser.eval(
        "return JSON.stringify([...document.querySelectorAll('#circuits input')].map(b => \
         [b.dataset.circuit, b.checked, b.parentElement.textContent.trim()]))",
    );
    assert_eq!(boxes.as_str(), Some(r#"[["wash",false,"Wall wash"]]"#), "the panel lists the circuit");
    // Each change: `act`, then the page draws again (its frame count moves on: at rest and ready
    // it draws nothing) and converges.
    let settle = |b: &Browser, act: &str| {
        let f = b.status()["frames"].as_u64().unwrap_or(0);
        b.eval(act);
        b.wait_for_frames(f + 1, Duration::from_secs(60));
        let (state, status) = b.wait_for_marker(READY_LIMIT);
        assert_eq!(state, "ready", "{status}");
        b.screenshot_canvas()
    };
    let switch = "document.querySelector('#circuits input').click(); return 0";
    let off = browser.screenshot_canvas();
    let on = settle(&browser, switch);
    let px = |i: &image::RgbaImage| i.pixels().map(|p| p.0).collect::<Vec<[u8; 4]>>();
    let lum = |i: &image::RgbaImage| i.pixels().map(|p| u64::from(p.0[0]) + u64::from(p.0[1])).sum::<u64>();
    eprintln!("canvas brightness: wash off {}, on {}", lum(&off), lum(&on));
    assert!(lum(&on) > lum(&off) * 11 / 10, "the wall wash brightens the view");
    let again = settle(&browser, switch);
    let d = golden::diff(&px(&again), &px(&off));
    assert!(golden::within_tolerance(&d), "switched off again: {d:?}");
    // The lux view and its legend.
    let lux = settle(
        &browser,
        "const v = document.getElementById('viewmode'); v.value = 'lux'; \
         v.dispatchEvent(new Event('change')); return 0",
    );
    assert_eq!(
        browser.eval("return String(document.getElementById('luxlegend').hidden)").as_str(),
        Some("false")
    );
    assert_eq!(browser.status()["view"], "lux");
    assert!(
        !golden::within_tolerance(&golden::diff(&px(&lux), &px(&off))),
        "false colours, not the lit view"
    );
}

fn first_frame_requests(package: &Path) -> usize {
    let (sparse, _) = sparse_package(package);
    let far = grotto_runtime::stream::sections_for(
        &sparse,
        &vec![grotto_runtime::scene::data::TileMode::Far; sparse.tile_count() as usize],
        false,
    );
    2 + sparse.missing(far, 64 << 10).len()
}

/// The package as the viewer first sees it (head and directory only), and the file's bytes.
fn sparse_package(package: &Path) -> (grotto_format::Package, Vec<u8>) {
    let file = std::fs::read(package).unwrap();
    let size = file.len() as u64;
    let head = &file[..(grotto_format::Package::HEAD_BYTES as usize).min(file.len())];
    let dir = grotto_format::Package::directory_range("p", head, size).unwrap();
    let sparse = grotto_format::Package::from_directory(
        "p",
        size,
        head,
        dir.start,
        &file[dir.start as usize..dir.end as usize],
    )
    .unwrap();
    (sparse, file)
}

/// The largest section a tile needs in `mode` and not at its far level (`finer`), or the largest
/// one of the far level (`!finer`): where a damaged byte is felt late, or at once.
fn section_to_damage(package: &Path, finer: bool) -> std::ops::Range<u64> {
    use grotto_runtime::scene::data::TileMode;
    let (sparse, _) = sparse_package(package);
    let n = sparse.tile_count() as usize;
    let far = grotto_runtime::stream::sections_for(&sparse, &vec![TileMode::Far; n], false);
    let pool = if finer {
        let full = grotto_runtime::stream::sections_for(&sparse, &vec![TileMode::Full; n], false);
        full.into_iter().filter(|s| !far.iter().any(|f| f.offset == s.offset)).collect()
    } else {
        far
    };
    let s = pool.into_iter().max_by_key(|s| s.stored_len).unwrap();
    s.offset..s.offset + s.stored_len
}

/// A hostile web: a published room opened through a server that misbehaves after the
/// page's first frame (ranges ignored, short bodies, a lying Content-Range, 404, a 500 that
/// passes, a slow server, the package replaced mid-visit) and from packages damaged inside
/// sections (a finer tile section, a far-level one). Each time the page says what happened in
/// words, never a blank tab or a hang, and answers afterwards: a view key changes the view (or,
/// on the error page, "try again" reloads it).
#[test]
fn a_page_survives_hostile_servers_and_damaged_packages() {
    use grotto_tests::serve::{Fault, FaultKind};
    let Some((chromium, driver, bundle)) = tools() else { return };
    let _one = BROWSER.lock().unwrap_or_else(|e| e.into_inner());
    let dir = tempfile::tempdir().unwrap();
    let package = grotto_fixtures::room::room_package(dir.path()).unwrap();
    let tiles = grotto_format::Package::open(&package).unwrap().tile_count() as u64;
    let (_, server) = published(dir.path(), &package, bundle, json!({"camera": "hall"}));
    let site_package = dir.path().join("site/room.grotto");
    let original = std::fs::read(&site_package).unwrap();
    let first = first_frame_requests(&package);
    let browser = Browser::start(&chromium, &driver, true);
    let mut visit = 0;
    let mut open = |b: &Browser| {
        visit += 1;
        let url = format!(
            "http://127.0.0.1:{}/index.html?width=160&height=120&quality=fast&bounces=1&panel=hidden&bar=hidden\
             &samples=1&visit={visit}",
            server.port
        );
        b.call("POST", "/url", Some(&json!({"url": url})));
    };
    // Faults count requests from when they are set: the next visit's first frame is answered
    // right, what comes after is not.
    let set_fault = |kind: Option<(FaultKind, Option<usize>)>| {
        let served = server.log.lock().unwrap().iter().filter(|s| s.path == "room.grotto").count();
        *server.fault.lock().unwrap() = kind.map(|(kind, times)| Fault {
            path: "room.grotto".into(),
            after: served + first,
            times,
            kind,
        });
    };
    // The page answers: a view key changes the view.
    let answers = |b: &Browser, key: &str, view: &str| {
        b.type_into_canvas(key);
        b.wait_for(
            &format!("return window.grottoStatus && window.grottoStatus.view === '{view}' ? '1' : null"),
            Duration::from_secs(60),
        );
    };
    let settle = |b: &Browser, what: &str| -> Value {
        let (state, status) = b.wait_for_marker(READY_LIMIT);
        eprintln!("{what}: page {state}, streaming {}, notice {}", status["streaming"], status["notice"]);
        assert_eq!(state, "ready", "{what}: {status}");
        status
    };

    // A damaged finer section: the tile stays at its far level, the rest streams on.
    let mut damaged = original.clone();
    let r = section_to_damage(&package, true);
    let mid = ((r.start + r.end) / 2) as usize;
    damaged[mid..mid + 16].iter_mut().for_each(|b| *b ^= 0x5a);
    std::fs::write(&site_package, &damaged).unwrap();
    open(&browser);
    let s = settle(&browser, "a damaged finer section");
    assert!(s["damaged_tiles"].as_u64().unwrap() >= 1, "{s}");
    assert!(s["notice"].as_str().unwrap().contains("damaged"), "{s}");
    answers(&browser, "2", "albedo");

    // A damaged far-level section: nothing to show; the page says why and can try again.
    let mut damaged = original.clone();
    let r = section_to_damage(&package, false);
    let mid = ((r.start + r.end) / 2) as usize;
    damaged[mid..mid + 16].iter_mut().for_each(|b| *b ^= 0x5a);
    std::fs::write(&site_package, &damaged).unwrap();
    open(&browser);
    let (state, _) = browser.wait_for_marker(Duration::from_secs(120));
    let text = browser.eval("return document.getElementById('message').innerText");
    eprintln!("a damaged far section: page {state}: {text}");
    assert_eq!(state, "error");
    assert!(text.as_str().unwrap().contains("room.grotto"), "{text}");
    std::fs::write(&site_package, &original).unwrap();
    let before = server.log.lock().unwrap().iter().filter(|s| s.path == "viewer.json").count();
    browser.eval("document.getElementById('retry').click(); return 0");
    settle(&browser, "tried again, the package whole");
    let after = server.log.lock().unwrap().iter().filter(|s| s.path == "viewer.json").count();
    assert!(after > before, "try again did not reload the page");

    // Servers that misbehave after the first frame.
    let all_full = |s: &Value| s["tiles"][0].as_u64() == Some(tiles);
    set_fault(Some((FaultKind::IgnoreRanges, None)));
    open(&browser);
    let s = settle(&browser, "ranges ignored");
    assert!(s["no_ranges"].as_bool().unwrap() && all_full(&s), "{s}");
    answers(&browser, "2", "albedo");

    set_fault(Some((FaultKind::ShortBody, None)));
    open(&browser);
    let s = settle(&browser, "short bodies");
    assert_eq!(s["streaming"], "stopped", "{s}");
    assert!(s["notice"].as_str().unwrap().contains("arrived"), "{s}");
    assert_eq!(s["stream_failures"], 4, "tried four times: {s}");
    answers(&browser, "2", "albedo");

    set_fault(Some((FaultKind::WrongContentRange, None)));
    open(&browser);
    let s = settle(&browser, "a lying Content-Range");
    assert_eq!(s["streaming"], "stopped", "{s}");
    assert!(s["notice"].as_str().unwrap().contains("Content-Range"), "{s}");
    answers(&browser, "2", "albedo");

    set_fault(Some((FaultKind::Status(404), None)));
    open(&browser);
    let s = settle(&browser, "404 mid-visit");
    assert!(s["notice"].as_str().unwrap().contains("404"), "{s}");
    answers(&browser, "2", "albedo");

    set_fault(Some((FaultKind::Status(500), Some(1))));
    open(&browser);
    let s = settle(&browser, "one 500 mid-visit");
    assert!(s["streaming"] == "ok" && all_full(&s) && s["stream_failures"] == 1, "{s}");
    answers(&browser, "2", "albedo");

    // A slow server: the page answers while a step is on its way.
    set_fault(Some((FaultKind::DelayMs(4000), None)));
    open(&browser);
    browser.wait_for(
        "const s = window.grottoStatus; return s && s.fetching ? '1' : null",
        Duration::from_secs(120),
    );
    answers(&browser, "3", "normals");
    let fetching = browser.status()["fetching"].as_bool().unwrap();
    assert!(fetching, "the view changed only after the slow step arrived");
    let s = settle(&browser, "a slow server");
    assert!(all_full(&s), "{s}");

    // The package replaced on the server mid-visit (its next step held back 3 s).
    set_fault(Some((FaultKind::DelayMs(3000), None)));
    open(&browser);
    browser.wait_for_frames(1, Duration::from_secs(120));
    let other = dir.path().join("other.grotto");
    grotto_preprocess::demo::build(
        &other,
        &grotto_preprocess::demo::DemoParams { points: 2_000, ..Default::default() },
    )
    .unwrap();
    std::fs::copy(&other, &site_package).unwrap();
    let s = settle(&browser, "the package replaced");
    assert_eq!(s["streaming"], "replaced", "{s}");
    assert!(s["notice"].as_str().unwrap().contains("replaced"), "{s}");
    let reload = browser.eval("return !document.getElementById('reload').hidden");
    assert_eq!(reload, true, "no reload button");
    answers(&browser, "2", "albedo");
    set_fault(None);
    std::fs::write(&site_package, &original).unwrap();
    drop(browser);
}

/// The page's memory over a long visit: PACKAGE (GROTTO_WEB_BENCH_PACKAGE) published
/// with a tour through its named cameras (each held GROTTO_WEB_BENCH_DWELL_S, default 5 s),
/// opened at GROTTO_WEB_BENCH_SIZE (default 320x240; GROTTO_WEB_BENCH_QUERY adds to the query,
/// default `&bounces=1&samples=1`) on SwiftShader, the tour played round and round for
/// GROTTO_WEB_BENCH_MINUTES (default 30). Every 10 s: the JS heap (DevTools
/// `Runtime.getHeapUsage`), the viewer's wasm memory and the renderer's GPU bytes. Prints every
/// sample, then a row: each figure at the end of the first loop and the largest after it.
#[test]
#[ignore = "a measurement: scripts/bench-web-memory.sh PACKAGE"]
fn memory_over_a_tour_loop() {
    let Some((chromium, driver, bundle)) = tools() else { return };
    let package =
        PathBuf::from(std::env::var_os("GROTTO_WEB_BENCH_PACKAGE").expect("GROTTO_WEB_BENCH_PACKAGE"));
    let env = |k: &str, d: f64| std::env::var(k).ok().and_then(|v| v.parse().ok()).unwrap_or(d);
    let (minutes, dwell_s) = (env("GROTTO_WEB_BENCH_MINUTES", 30.0), env("GROTTO_WEB_BENCH_DWELL_S", 5.0));
    let size = std::env::var("GROTTO_WEB_BENCH_SIZE").unwrap_or_else(|_| "320x240".into());
    let (w, h) = size.split_once('x').expect("SIZE as WxH");
    // A software adapter takes seconds a frame on 10^7 points: one bounce and one sample a
    // pixel keep a loop within minutes (the memory, not the light, is measured).
    let query = std::env::var("GROTTO_WEB_BENCH_QUERY").unwrap_or_else(|_| "&bounces=1&samples=1".into());
    let _one = BROWSER.lock().unwrap_or_else(|e| e.into_inner());
    let dir = tempfile::tempdir().unwrap();
    let cameras: Vec<String> = grotto_format::Package::open(&package)
        .unwrap()
        .scene()
        .unwrap()
        .cameras
        .into_iter()
        .map(|c| c.name)
        .collect();
    assert!(cameras.len() >= 2, "the package needs two named cameras for a tour: {cameras:?}");
    let mut story = "[[tour]]\nname = \"loop\"\n".to_owned();
    for c in &cameras {
        story += &format!("[[tour.stop]]\ncamera = \"{c}\"\ndwell_s = {dwell_s}\n");
    }
    let story_path = dir.path().join("story.toml");
    std::fs::write(&story_path, story).unwrap();
    let site = dir.path().join("site");
    publish::publish(&PublishOptions {
        package: package.clone(),
        out: site.clone(),
        bundle: Some(bundle),
        title: None,
        viewer_options: serde_json::Map::new(),
        story: Some(story_path),
        lights: None,
        picture: None,
    })
    .unwrap();
    let server = serve::serve(&site).unwrap();
    let browser = Browser::start(&chromium, &driver, true);
    let url = format!(
        "http://127.0.0.1:{}/index.html?width={w}&height={h}&quality=fast&panel=hidden{query}",
        server.port
    );
    browser.call("POST", "/url", Some(&json!({"url": url})));
    browser.wait_for_frames(1, Duration::from_secs(900));
    // Played round and round: restarted whenever it finishes, loops counted.
    browser.eval(
        "window.grottoLoops = 0; const go = () => document.getElementById('tourplay').click(); go(); \
         const watch = () => { const t = window.grottoStatus && window.grottoStatus.tour; \
         if (t && t.phase === 'finished') { window.grottoLoops++; go(); } setTimeout(watch, 250); }; watch(); return 0",
    );
    let t0 = Instant::now();
    let mut samples: Vec<(f64, u64, f64, f64, f64)> = Vec::new();
    println!("| s | loops | frames | JS heap MB | wasm MB | GPU MB |");
    while t0.elapsed().as_secs_f64() < minutes * 60.0 {
        std::thread::sleep(Duration::from_secs(10));
        let heap = browser.cdp("Runtime.getHeapUsage", json!({}));
        let s = browser.status();
        let loops = browser.eval("return window.grottoLoops").as_u64().unwrap_or(0);
        let mb = |v: &Value| v.as_f64().unwrap_or(0.0) / 1e6;
        let row = (
            t0.elapsed().as_secs_f64(),
            loops,
            mb(&heap["usedSize"]),
            mb(&s["wasm_bytes"]),
            mb(&s["gpu_bytes"]),
        );
        println!(
            "| {:.0} | {} | {} | {:.1} | {:.1} | {:.1} |",
            row.0, row.1, s["frames"], row.2, row.3, row.4
        );
        samples.push(row);
    }
    drop(browser);
    let first_loop = samples.iter().position(|s| s.1 >= 1).expect("the tour never finished a loop");
    let after = &samples[first_loop..];
    let max = |f: fn(&(f64, u64, f64, f64, f64)) -> f64| after.iter().map(f).fold(0.0, f64::max);
    let at = &samples[first_loop];
    let name = package.file_name().unwrap().to_string_lossy().into_owned();
    println!("| package | minutes | loops | JS heap MB, first loop / largest after | wasm MB | GPU MB |");
    println!(
        "| {name} | {minutes} | {} | {:.1} / {:.1} | {:.1} / {:.1} | {:.1} / {:.1} |",
        samples.last().map_or(0, |s| s.1),
        at.2,
        max(|s| s.2),
        at.3,
        max(|s| s.3),
        at.4,
        max(|s| s.4)
    );
}

/// The screenshots of docs/web.md: PACKAGE (GROTTO_WEB_BENCH_PACKAGE) published and
/// opened at 640x480 with its panel, once at rest with its points of interest labelled
/// (`web-pois.png`), once at its first tour's second stop with the caption (`web-tour.png`),
/// and once on a 390x844 phone screen (`web-phone.png`), into GROTTO_WEB_DOCS_OUT.
#[test]
#[ignore = "docs: scripts/web-screenshots.sh PACKAGE"]
fn screenshots_for_the_docs() {
    let Some((chromium, driver, bundle)) = tools() else { return };
    let package =
        PathBuf::from(std::env::var_os("GROTTO_WEB_BENCH_PACKAGE").expect("GROTTO_WEB_BENCH_PACKAGE"));
    let out = PathBuf::from(std::env::var_os("GROTTO_WEB_DOCS_OUT").expect("GROTTO_WEB_DOCS_OUT"));
    let _one = BROWSER.lock().unwrap_or_else(|e| e.into_inner());
    let dir = tempfile::tempdir().unwrap();
    let (_, server) = published(dir.path(), &package, bundle, json!({"quality": "fast"}));
    let browser = Browser::start(&chromium, &driver, true);
    // Headless Chromium's window is ~140 px taller than its viewport: room for the 640 x 480 canvas.
    browser.call("POST", "/window/rect", Some(&json!({"width": 680, "height": 640})));
    let page = |b: &Browser, name: &str| {
        let png = b.call("GET", "/screenshot", None);
        let png = base64::engine::general_purpose::STANDARD.decode(png.as_str().unwrap()).unwrap();
        std::fs::write(out.join(name), png).unwrap();
    };
    let url = format!("http://127.0.0.1:{}/index.html?width=640&height=480&bar=hidden", server.port);
    browser.call("POST", "/url", Some(&json!({"url": url})));
    browser.wait_for_marker(Duration::from_secs(900));
    browser.wait_for(
        "const s = window.grottoStatus; return s && s.labels_current ? '1' : null",
        Duration::from_secs(60),
    );
    page(&browser, "web-pois.png");
    browser.eval("document.getElementById('tourplay').click(); return 0");
    browser.wait_for(
        "const t = window.grottoStatus && window.grottoStatus.tour; \
         return t && t.stop === 1 && t.phase === 'dwelling' ? '1' : null",
        Duration::from_secs(1800),
    );
    browser.eval("document.getElementById('tourplay').click(); return 0");
    browser.wait_for_marker(Duration::from_secs(900));
    page(&browser, "web-tour.png");
    // A phone: the page fits the canvas to the screen and the panel along the bottom.
    browser.call("POST", "/window/rect", Some(&json!({"width": 390, "height": 844})));
    let url = format!("http://127.0.0.1:{}/index.html?bar=hidden&phone=1", server.port);
    browser.call("POST", "/url", Some(&json!({"url": url})));
    browser.wait_for_marker(Duration::from_secs(900));
    page(&browser, "web-phone.png");
}
