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

mod hostile;
mod measure;
mod phone;
mod room;
mod site;

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
        self.touch_at(steps, None);
    }

    /// Two taps at canvas pixel `(x, y)`, stamped 150 ms apart whatever the driver's delays: a
    /// loaded machine's round trips must not make them two single taps.
    fn double_tap(&self, x: f64, y: f64) {
        let t0 = std::time::SystemTime::now().duration_since(std::time::UNIX_EPOCH).unwrap().as_secs_f64();
        self.touch_at(&[&[(x, y)]], Some((t0, 0.05)));
        self.touch_at(&[&[(x, y)]], Some((t0 + 0.15, 0.05)));
    }

    /// Touch steps as [`Browser::touch`], each stamped `(first, step)` seconds since the epoch
    /// where given (CDP's `timestamp`, the events' `timeStamp` in the page).
    fn touch_at(&self, steps: &[&[(f64, f64)]], stamps: Option<(f64, f64)>) {
        let r = self.eval(
            "const r = document.getElementById('canvas').getBoundingClientRect(); return [r.left, r.top]",
        );
        let (left, top) = (r[0].as_f64().unwrap(), r[1].as_f64().unwrap());
        let points = |s: &[(f64, f64)]| -> Vec<Value> {
            s.iter().enumerate().map(|(i, (x, y))| json!({"x": left + x, "y": top + y, "id": i})).collect()
        };
        let event = |k: usize, kind: &str, touch_points: Vec<Value>| {
            let mut e = json!({"type": kind, "touchPoints": touch_points});
            if let Some((first, step)) = stamps {
                e["timestamp"] = json!(first + step * k as f64);
            }
            self.cdp("Input.dispatchTouchEvent", e);
        };
        for (k, s) in steps.iter().enumerate() {
            event(k, if k == 0 { "touchStart" } else { "touchMove" }, points(s));
        }
        event(steps.len(), "touchEnd", Vec::new());
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
