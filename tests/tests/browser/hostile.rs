//! A page against hostile servers and damaged packages: every failure named on the page, nothing
//! fetched twice, no hang.

use super::*;

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
