//! A phone: Chromium's device emulation (390x844 CSS pixels at pixel ratio 3, touch, a phone's
//! user agent) opens a published cave. The page picks the phone budget itself, says so in its
//! panel and keeps within it: its GPU bytes within the GPU's share, its wasm memory within the
//! page's. A budget in the address wins over the device's (one that is not a budget: site.rs).
//! And a device with only WebGPU's default limits opens, draws and streams 10^7 points.

use super::*;

const PHONE_UA: &str = "Mozilla/5.0 (Linux; Android 14; Pixel 8) AppleWebKit/537.36 (KHTML, like Gecko) \
                        Chrome/120.0.0.0 Mobile Safari/537.36";

#[test]
fn a_phone_gets_the_phone_budget_and_the_page_keeps_within_it() {
    let Some((chromium, driver, bundle)) = tools() else { return };
    let _one = BROWSER.lock().unwrap_or_else(|e| e.into_inner());
    let dir = tempfile::tempdir().unwrap();
    let package = small_demo(dir.path());
    let tiles = grotto_format::Package::open(&package).unwrap().tile_count();
    let (_, server) = published(dir.path(), &package, bundle, json!({"camera": "chamber"}));
    let browser = Browser::start(&chromium, &driver, true);
    browser.cdp(
        "Emulation.setDeviceMetricsOverride",
        json!({"width": 390, "height": 844, "deviceScaleFactor": 3, "mobile": true,
               "screenWidth": 390, "screenHeight": 844}),
    );
    browser.cdp("Emulation.setTouchEmulationEnabled", json!({"enabled": true, "maxTouchPoints": 5}));
    browser.cdp("Emulation.setUserAgentOverride", json!({"userAgent": PHONE_UA, "platform": "Android"}));
    let base =
        format!("http://127.0.0.1:{}/index.html?quality=fast&bounces=1&bar=hidden&samples=1", server.port);
    browser.call("POST", "/url", Some(&json!({"url": base})));
    let (state, status) = browser.wait_for_marker(READY_LIMIT);
    assert_eq!(state, "ready", "{status}");
    eprintln!("phone status: {status}");

    let n = |k: &str| status[k].as_u64().unwrap_or_else(|| panic!("no {k} in {status}"));
    assert_eq!(status["budget"], "phone (512 MiB)", "{status}");
    assert_eq!(n("budget_bytes"), 512 << 20);
    // The canvas fills the phone's screen (CSS pixels).
    assert_eq!((n("width"), n("height")), (390, 844));
    // Within the budget: the GPU's share, and the page's own memory within the rest.
    let (gpu, wasm, gpu_share) = (n("gpu_bytes"), n("wasm_bytes"), n("budget_gpu_bytes"));
    assert!(gpu > 0 && gpu <= gpu_share, "GPU {gpu} bytes of a {gpu_share}-byte share");
    assert!(wasm <= n("budget_bytes") - gpu_share, "wasm {wasm} bytes");
    // The small cave fits the phone's pools whole.
    assert_eq!(status["tiles"][0].as_u64().unwrap() as u32, tiles, "{status}");
    let panel = browser.eval("return document.getElementById('memory').textContent");
    let panel = panel.as_str().unwrap();
    assert!(panel.contains("phone (512 MiB) budget") && panel.contains(" of "), "{panel}");

    // The address names another budget: it wins over the device's.
    browser.call("POST", "/url", Some(&json!({"url": format!("{base}&budget=laptop")})));
    let status = browser.wait_for_frames(1, READY_LIMIT);
    assert_eq!(status["budget"], "laptop (1.5 GiB)", "{status}");
}

/// The adapter's limits as a device with only WebGPU's defaults has them (128 MiB a storage
/// binding, 256 MiB a buffer), whatever the software adapter offers: set before the page's
/// script runs, so the page sees what a phone's browser shows it.
const DEFAULT_LIMITS: &str = "const d = Object.getOwnPropertyDescriptor(GPUAdapter.prototype, 'limits'); \
    Object.defineProperty(GPUAdapter.prototype, 'limits', { get() { const l = d.get.call(this); \
    return new Proxy(l, { get(t, k) { \
      if (k === 'maxStorageBufferBindingSize') return 134217728; \
      if (k === 'maxBufferSize') return 268435456; \
      const v = Reflect.get(t, k, t); return typeof v === 'function' ? v.bind(t) : v; } }); } });";

/// A 10^7-point cave (the synthetic survey `grotto-pack synth --points 10000000` writes, built
/// with the defaults: 77 MB, 11 tiles) on a device with WebGPU's default limits under the
/// laptop's budget, whose pools alone would take more than one binding: the page asks for no
/// larger binding than the defaults, its pools fit one each, and it opens, draws, and streams
/// finer tiles in as the camera goes to another view.
#[test]
fn ten_million_points_open_draw_and_stream_on_webgpus_default_limits() {
    let Some((chromium, driver, bundle)) = tools() else { return };
    let dir = tempfile::tempdir().unwrap();
    let params = SynthParams { points: 10_000_000, ..SynthParams::default() };
    let summary =
        synth::write_dataset(&dir.path().join("scans"), &params, &[ScanFormat::Las], &|_, _| {}).unwrap();
    let manifest_path = PathBuf::from(&summary.manifest);
    let manifest = Manifest::load(&manifest_path).unwrap();
    let package = dir.path().join("survey.grotto");
    let bp = build::BuildParams::with_leaf(dir.path().join("work"), 0.0625);
    build::build(&manifest, &manifest_path, &package, &bp, &|_| {}).unwrap();
    std::fs::remove_dir_all(dir.path().join("scans")).unwrap();
    let _one = BROWSER.lock().unwrap_or_else(|e| e.into_inner());
    let (_, server) = published(dir.path(), &package, bundle, json!({"camera": "entrance"}));
    let browser = Browser::start(&chromium, &driver, true);
    browser.cdp("Page.enable", json!({}));
    browser.cdp("Page.addScriptToEvaluateOnNewDocument", json!({"source": DEFAULT_LIMITS}));
    let url = format!(
        "http://127.0.0.1:{}/index.html?width={W}&height={H}&quality=fast&bounces=1&samples=1&budget=laptop",
        server.port
    );
    browser.call("POST", "/url", Some(&json!({"url": url})));
    let first = browser.wait_for_frames(1, READY_LIMIT);
    eprintln!("first frame: {first}");
    let n = |s: &Value, k: &str| s[k].as_u64().unwrap_or_else(|| panic!("no {k} in {s}"));
    assert_eq!(
        n(&first, "binding_bytes"),
        128 << 20,
        "the device took a larger binding than WebGPU's default"
    );
    assert_eq!(first["budget"], "laptop (1.5 GiB)");
    assert!(n(&first, "gpu_bytes") > 0);
    assert!(
        n(&first, "first_frame_bytes") < 4 << 20,
        "the first frame waited for {} bytes",
        n(&first, "first_frame_bytes")
    );

    // The first view's tiles arrive; then the next camera's (Tab): finer tiles stream in.
    let settled = |what: &str| {
        let t0 = Instant::now();
        loop {
            let s = browser.status();
            let marker = browser.eval("return document.documentElement.dataset.grotto || ''");
            assert_ne!(marker, "error", "{what}: the page failed: {s}");
            if s["fetching"] == false && s["tiles"][0].as_u64().unwrap_or(0) > 0 && s["streaming"] == "ok" {
                return s;
            }
            assert!(t0.elapsed() < READY_LIMIT, "{what}: no full tiles after {READY_LIMIT:?}: {s}");
            std::thread::sleep(Duration::from_millis(500));
        }
    };
    let entrance = settled("the entrance");
    eprintln!("entrance: {entrance}");
    browser.eval(
        "document.getElementById('canvas').dispatchEvent(new KeyboardEvent('keydown', {code: 'Tab'})); \
         document.getElementById('canvas').dispatchEvent(new KeyboardEvent('keyup', {code: 'Tab'})); return 0",
    );
    let t0 = Instant::now();
    while browser.status()["camera"] == entrance["camera"] {
        assert!(t0.elapsed() < Duration::from_secs(60), "Tab went to no other camera");
        std::thread::sleep(Duration::from_millis(200));
    }
    // A frame on SwiftShader takes seconds: wait until the page has drawn the new view twice, so
    // that its tiles were asked for, before waiting for them to settle.
    let t0 = Instant::now();
    while n(&browser.status(), "frames") < n(&entrance, "frames") + 2 {
        assert!(t0.elapsed() < READY_LIMIT, "the page drew no frame of the new view in {READY_LIMIT:?}");
        std::thread::sleep(Duration::from_millis(500));
    }
    let next = settled("the next camera");
    eprintln!("next camera: {next}");
    assert!(n(&next, "fetched_bytes") > n(&entrance, "fetched_bytes"), "no tiles fetched for the new view");
    assert_ne!(next["tiles"], entrance["tiles"], "the new view holds the same tiles");
    assert!(n(&next, "frames") > n(&entrance, "frames"));
    assert_eq!(n(&next, "binding_bytes"), 128 << 20);
    assert!(n(&next, "gpu_bytes") <= n(&next, "budget_gpu_bytes"), "{next}");
    assert_eq!(n(&next, "damaged_tiles"), 0);
}
