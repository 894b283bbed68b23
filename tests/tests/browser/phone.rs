//! A phone: Chromium's device emulation (390x844 CSS pixels at pixel ratio 3, touch, a phone's
//! user agent) opens a published cave. The page picks the phone budget itself, says so in its
//! panel and keeps within it: its GPU bytes within the GPU's share, its wasm memory within the
//! page's. A budget in the address wins over the device's (one that is not a budget: site.rs).

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
