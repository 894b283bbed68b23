//! A published site: the package streamed by ranges and shown as `grotto render` shows it, and
//! the picture and points of interest where the browser has no WebGPU.

use super::*;

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
    let picture_shown = |browser: &Browser| {
        browser.wait_for(
            "const i = document.getElementById('picture'); return i && i.complete && i.naturalWidth ? \
             JSON.stringify([i.naturalWidth, i.naturalHeight]) : null",
            Duration::from_secs(30),
        )
    };
    assert_eq!(picture_shown(&browser), json!([160, 120]));
    let log = server.log.lock().unwrap().clone();
    assert!(log.iter().all(|s| s.path != "room.grotto"), "the package was fetched: {log:?}");
    assert!(log.iter().any(|s| s.path == publish::PICTURE_FILE && s.status == 200), "{log:?}");
    drop(browser);

    // With WebGPU, a page that cannot show the cave (here a memory budget that is not one) says
    // why beside the same picture, never a blank or crashed page.
    let browser = Browser::start(&chromium, &driver, true);
    let url = format!("http://127.0.0.1:{}/?budget=tiny", server.port);
    browser.call("POST", "/url", Some(&json!({"url": url})));
    let (state, _) = browser.wait_for_marker(READY_LIMIT);
    assert_eq!(state, "error");
    let text = browser.eval("return document.getElementById('message').innerText");
    assert!(text.as_str().unwrap().contains("budget \"tiny\""), "{text}");
    assert_eq!(picture_shown(&browser), json!([160, 120]));

    // Tile pools smaller than every tile at its coarsest level: the page says what the far levels
    // need and what to raise, beside the picture.
    let far_bytes: u64 = grotto_runtime::stream::residency::footprints(
        &grotto_format::Package::open(&package).unwrap(),
        false,
    )
    .unwrap()
    .iter()
    .map(|t| t.far.bytes)
    .sum();
    assert!(far_bytes > 0);
    let mb = (far_bytes - 1) >> 20;
    let url = format!("http://127.0.0.1:{}/?gpu_memory_mb={mb}", server.port);
    browser.call("POST", "/url", Some(&json!({"url": url})));
    let (state, _) = browser.wait_for_marker(READY_LIMIT);
    assert_eq!(state, "error");
    let text = browser.eval("return document.getElementById('message').innerText");
    let text = text.as_str().unwrap();
    assert!(text.contains("far levels") && text.contains("gpu_memory_mb="), "{text}");
    assert_eq!(picture_shown(&browser), json!([160, 120]));
}
