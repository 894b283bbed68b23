//! A published room as a visitor uses it: labels, measuring, shared view links, touch, lighting
//! circuits and the lux view.

use super::*;

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
    browser.double_tap(160.0, 100.0);
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
