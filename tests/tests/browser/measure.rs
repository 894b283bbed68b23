//! Measurements run by `cargo xtask bench web|web-frames|web-memory`, ignored in the suite:
//! bytes before the first frame, frame times while moving, memory over a tour loop, and the
//! docs' screenshots. Each prints its table and writes its figures as JSON where
//! `GROTTO_BENCH_JSON` names a file (the harness reads them from there).

use super::*;

/// Writes `figures` where the harness asked for them.
fn report(figures: &Value) {
    if let Some(path) = std::env::var_os("GROTTO_BENCH_JSON") {
        std::fs::write(&path, serde_json::to_vec_pretty(figures).unwrap()).unwrap();
    }
}

/// What the page fetched before its first frame, on a package of your choice: the figures in
/// docs/web.md ("What a visitor downloads"). Run by `cargo xtask bench web`; ignored in the
/// suite.
#[test]
#[ignore = "a measurement: cargo xtask bench web"]
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
    report(&json!({
        "package": name, "package_bytes": total, "first_frame_bytes": first,
        "requests": status["requests"], "site_bytes": site_bytes, "wasm_bytes": summary.wasm_bytes,
        "first_frame_ms": status["first_frame_ms"],
    }));
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
#[ignore = "a measurement: cargo xtask bench web-frames"]
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
    report(&json!({
        "package": name, "size": size, "query": query, "move_s": move_s, "frames": times.len(),
        "median_ms": at(0.5), "p95_ms": at(0.95), "worst_ms": gaps.last().copied().unwrap_or(0.0),
        "traded": status.get("traded").cloned().unwrap_or(Value::Null),
    }));
    assert!(times.len() >= 2, "no frames while moving");
}

/// The page's memory over a long visit: PACKAGE (GROTTO_WEB_BENCH_PACKAGE) published
/// with a tour through its named cameras (each held GROTTO_WEB_BENCH_DWELL_S, default 5 s),
/// opened at GROTTO_WEB_BENCH_SIZE (default 320x240; GROTTO_WEB_BENCH_QUERY adds to the query,
/// default `&bounces=1&samples=1`) on SwiftShader, the tour played round and round for
/// GROTTO_WEB_BENCH_MINUTES (default 30). Every 10 s: the JS heap (DevTools
/// `Runtime.getHeapUsage`), the viewer's wasm memory and the renderer's GPU bytes. Prints every
/// sample, then a row: each figure at the end of the first loop and the largest after it.
#[test]
#[ignore = "a measurement: cargo xtask bench web-memory"]
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
        // A page that failed draws no more frames: its figures would be of nothing.
        let state = browser.eval(
            "return [document.documentElement.dataset.grotto || '', document.getElementById('message').innerText]",
        );
        assert_ne!(
            state[0],
            "error",
            "the page failed after {:.0} s: {}",
            t0.elapsed().as_secs_f64(),
            state[1]
        );
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
    let pair = |first: f64, largest: f64| json!({"first_loop": first, "largest_after": largest});
    report(&json!({
        "package": name, "minutes": minutes, "loops": samples.last().map_or(0, |s| s.1),
        "js_heap_mb": pair(at.2, max(|s| s.2)), "wasm_mb": pair(at.3, max(|s| s.3)),
        "gpu_mb": pair(at.4, max(|s| s.4)),
        "samples": samples.iter().map(|s| json!([s.0, s.1, s.2, s.3, s.4])).collect::<Vec<_>>(),
    }));
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
