//! Points of interest, tours and measuring on the scanned room of known size
//! (grotto_fixtures::room), natively on lavapipe: the manifest's story survives the package at
//! survey coordinates; a label on the far wall in view shows and the one behind the pillar is
//! hidden, decided from G-buffer distances read back without blocking (render/probe.rs, what the
//! browser does); a floor and a ceiling point picked that way are 2.5 m apart in height within a
//! centimetre, each on its plane. The browser's own checks of the same are in tests/tests/browser/room.rs.

use glam::{DVec3, Vec2};
use grotto_fixtures::room;
use grotto_runtime::gpu::Gpu;
use grotto_runtime::render::Renderer;
use grotto_runtime::render::probe::Probe;
use grotto_runtime::scene::data::SceneData;
use grotto_runtime::settings::{Quality, Settings};
use grotto_runtime::view::camera::Camera;
use grotto_runtime::view::story::{self, Measurement};

const W: u32 = 320;
const H: u32 = 240;

/// The distances a probe read, waiting for the GPU (a test may block).
fn distances(gpu: &Gpu, probe: &Probe) -> Vec<Option<f32>> {
    loop {
        gpu.device.poll(wgpu::PollType::wait_indefinitely()).unwrap();
        if let Some(d) = probe.take() {
            return d.unwrap();
        }
    }
}

#[test]
fn labels_hide_behind_rock_and_picked_points_measure_the_room() {
    let dir = tempfile::tempdir().unwrap();
    let package = room::room_package(dir.path()).unwrap();
    let pkg = grotto_format::Package::open(&package).unwrap();
    let stored = pkg.scene().unwrap();
    assert_eq!(stored.pois.iter().map(|p| p.name.as_str()).collect::<Vec<_>>(), ["niche", "behind"]);
    assert_eq!(stored.pois[0].position_m, room::world(room::NICHE_M), "survey coordinates kept to the bit");
    assert_eq!(stored.tours[0].stops.len(), 2);
    let scene = SceneData::from_package(&pkg).unwrap();
    assert_eq!(scene.pois.len(), 2);
    let tour = &scene.tours[0];
    assert_eq!(tour.stops[0].title, "The niche");
    assert_eq!(
        tour.stops[0].text, "A niche in the far wall.",
        "a stop at a point of interest takes its text"
    );
    assert_eq!(tour.stops[1].text, "Back in the hall.");

    let gpu = Gpu::new(&grotto_tests::lavapipe()).unwrap();
    let settings = Settings { bounces: 0, ..Settings::preset(Quality::Fast) };
    let mut r = Renderer::new(&gpu, &scene, settings).unwrap();
    let hall = scene.cameras.iter().find(|c| c.name == "hall").unwrap();
    let cam = story::stop_camera(hall);
    r.draw(&cam, W, H).unwrap();

    // Labels: both project into the view; rock hides only the one behind the pillar.
    let at: Vec<_> = scene.pois.iter().map(|p| story::project(&cam, W, H, p.position_m).unwrap()).collect();
    let pixels: Vec<(u32, u32)> = at.iter().map(|a| (a.x_px as u32, a.y_px as u32)).collect();
    let probe = r.start_probe(&pixels).unwrap().unwrap();
    let d = distances(&gpu, &probe);
    let hidden: Vec<bool> = at.iter().zip(&d).map(|(a, d)| story::hidden(a.distance_m, *d)).collect();
    eprintln!("labels at {at:?}, surfaces at {d:?}");
    assert_eq!(hidden, [false, true]);
    // The pillar's front face is 2.8 m from the eye along x; the far wall 5.2 m.
    let pillar = d[1].unwrap();
    assert!((pillar - (room::PILLAR_MIN_M[0] - room::HALL_EYE_M[0]) as f32).abs() < 0.1, "{pillar}");

    // Measuring: a floor point and a ceiling point picked from the frame.
    let (floor_px, ceiling_px) = ((W / 2 + 7, H - 12), (W / 2 - 11, 10));
    let probe = r.start_probe(&[floor_px, ceiling_px]).unwrap().unwrap();
    let d = distances(&gpu, &probe);
    let origin = DVec3::from_array(scene.frame_origin_m);
    let world = |i: usize| origin + probe.point(i, d[i].unwrap()).as_dvec3();
    let (floor, ceiling) = (world(0), world(1));
    let m = Measurement::between(floor, ceiling);
    eprintln!("floor {floor}, ceiling {ceiling}: {m:?}");
    let z0 = room::ORIGIN_M[2];
    assert!((floor.z - z0).abs() < 0.01, "the floor point is {} m off the floor", floor.z - z0);
    assert!((ceiling.z - z0 - room::SIZE_M[2]).abs() < 0.01, "the ceiling point is off the ceiling");
    assert!((m.height_m - room::SIZE_M[2]).abs() < 0.01, "height {} m, the room is 2.5 m", m.height_m);
    // Each point is on its pixel's ray (within a pixel's width at its distance).
    for (i, px) in [floor_px, ceiling_px].into_iter().enumerate() {
        let p = world(i) - origin;
        let back = story::project(&cam, W, H, p.as_vec3()).unwrap();
        let miss = Vec2::new(back.x_px - px.0 as f32 - 0.5, back.y_px - px.1 as f32 - 0.5).length();
        assert!(miss < 0.01, "point {i} reprojects {miss} px from its pixel's centre");
    }
    // A click on nothing (outside the frame) reads as nothing, not as a point at the eye.
    let probe = r.start_probe(&[(W + 5, 3)]).unwrap().unwrap();
    assert_eq!(distances(&gpu, &probe), [None]);
}

#[test]
fn a_camera_of_a_view_link_renders_what_the_named_camera_does() {
    // A shared link's camera (eye, heading, pitch, fov) must give the same picture as the view
    // it was taken from: the matrices agree to float precision.
    let origin = room::ORIGIN_M;
    let named = Camera {
        eye_m: glam::Vec3::new(0.8, 2.0, 1.5),
        look_at_m: glam::Vec3::new(6.0, 2.0, 1.2),
        up: glam::Vec3::Z,
        fov_y_deg: 60.0,
    };
    let shown = story::stop_camera(&grotto_runtime::scene::data::SceneCamera {
        name: "hall".into(),
        eye_m: named.eye_m,
        look_at_m: named.look_at_m,
        up: named.up,
        fov_y_deg: named.fov_y_deg,
    });
    let back = story::parse_view_link(&story::view_link(&shown, origin), origin).unwrap();
    let (a, b) = (named.view_proj(W, H, 0.05, 100.0), back.view_proj(W, H, 0.05, 100.0));
    let p = glam::Vec3::new(6.0, 3.2, 1.4);
    let (qa, qb) = (a.project_point3(p), b.project_point3(p));
    let px = Vec2::new((qa.x - qb.x) * W as f32 / 2.0, (qa.y - qb.y) * H as f32 / 2.0).length();
    assert!(px < 0.02, "a point on the far wall moves {px} px between the named camera and its link");
}

#[test]
fn grotto_render_draws_a_tour_a_frame_a_stop_or_as_a_film() {
    use grotto_runtime::cli::render_job;
    use grotto_runtime::engine::RenderOptions;
    let dir = tempfile::tempdir().unwrap();
    let package = room::room_package(dir.path()).unwrap();
    let render = |fps: Option<f32>, out: &str| {
        let opts = RenderOptions {
            tour: Some("walk".into()),
            tour_fps: fps,
            width: 64,
            height: 48,
            settings: Settings { bounces: 0, ..Settings::preset(Quality::Fast) },
            gpu: grotto_tests::lavapipe(),
            ..RenderOptions::defaults(package.clone(), dir.path().join(out))
        };
        render_job::run(&opts, |_| {})
    };
    let stops = render(None, "stop.png").unwrap();
    assert_eq!(stops.images.len(), 2, "{:?}", stops.images);
    // At 4 frames a second: the niche held 3 s (12), a 1.5 s flight (5 between), the hall 3 s (12).
    let film = render(Some(4.0), "film.png").unwrap();
    assert_eq!(film.images.len(), 12 + 5 + 12);
    // The first stop's image is the niche's, as `--camera niche` (a point of interest) draws it.
    let niche = RenderOptions {
        camera: grotto_runtime::view::framing::CameraChoice::Named("niche".into()),
        width: 64,
        height: 48,
        settings: Settings { bounces: 0, ..Settings::preset(Quality::Fast) },
        gpu: grotto_tests::lavapipe(),
        ..RenderOptions::defaults(package.clone(), dir.path().join("niche.png"))
    };
    render_job::run(&niche, |_| {}).unwrap();
    let a = image::open(&stops.images[0]).unwrap().to_rgba8();
    let b = image::open(dir.path().join("niche.png")).unwrap().to_rgba8();
    assert!(a.as_raw() == b.as_raw(), "the tour's first stop is the niche's view");
    // A story file adds a point of interest and a tour that stops at it and at the package's.
    let story = dir.path().join("story.toml");
    let corner = room::world([0.2, 0.2, 2.3]);
    std::fs::write(
        &story,
        format!(
            "[[poi]]\nname = \"corner\"\nposition = {corner:?}\neye = {:?}\n\n             [[tour]]\nname = \"short\"\n[[tour.stop]]\npoi = \"corner\"\n[[tour.stop]]\npoi = \"niche\"\n",
            room::world(room::HALL_EYE_M)
        ),
    )
    .unwrap();
    let short = RenderOptions {
        tour: Some("short".into()),
        story: Some(story),
        width: 64,
        height: 48,
        settings: Settings { bounces: 0, ..Settings::preset(Quality::Fast) },
        gpu: grotto_tests::lavapipe(),
        // A sequence keeps its first frame's automatic exposure: fixed here, to compare.
        exposure: Some(3.0),
        ..RenderOptions::defaults(package.clone(), dir.path().join("short.png"))
    };
    let short_run = render_job::run(&short, |_| {}).unwrap();
    assert_eq!(short_run.images.len(), 2);
    let niche_fixed = RenderOptions { exposure: Some(3.0), ..niche.clone() };
    render_job::run(&niche_fixed, |_| {}).unwrap();
    let b2 = image::open(&short_run.images[1]).unwrap().to_rgba8();
    let b3 = image::open(dir.path().join("niche.png")).unwrap().to_rgba8();
    assert!(b2.as_raw() == b3.as_raw(), "the story file's tour stops at the package's niche");
    let err = render_job::run(
        &RenderOptions {
            tour: Some("nope".into()),
            ..RenderOptions::defaults(package, dir.path().join("x.png"))
        },
        |_| {},
    )
    .unwrap_err();
    assert!(err.to_string().contains("no tour named \"nope\"") && err.to_string().contains("walk"), "{err}");
}

#[test]
fn grotto_render_draws_the_labels_rock_does_not_hide() {
    use grotto_runtime::cli::render_job;
    use grotto_runtime::engine::RenderOptions;
    let dir = tempfile::tempdir().unwrap();
    let package = room::room_package(dir.path()).unwrap();
    let opts = |labels: bool, supersample: u32, out: &str| RenderOptions {
        camera: grotto_runtime::view::framing::CameraChoice::Named("hall".into()),
        width: W,
        height: H,
        supersample,
        labels,
        settings: Settings { bounces: 0, ..Settings::preset(Quality::Fast) },
        gpu: grotto_tests::lavapipe(),
        exposure: Some(3.0),
        ..RenderOptions::defaults(package.clone(), dir.path().join(out))
    };
    let plain = render_job::run(&opts(false, 1, "plain.png"), |_| {}).unwrap();
    assert!(plain.frames[0].labels.is_empty(), "no labels unless asked");
    let labelled = render_job::run(&opts(true, 1, "labels.png"), |_| {}).unwrap();
    let labels = &labelled.frames[0].labels;
    let names: Vec<(&str, bool)> = labels.iter().map(|l| (l.poi.as_str(), l.visible)).collect();
    assert_eq!(names, [("niche", true), ("behind", false)], "the pillar hides the label behind it");
    let a = image::open(dir.path().join("plain.png")).unwrap().to_rgba8();
    let b = image::open(dir.path().join("labels.png")).unwrap().to_rgba8();
    let changed = |x0: f32, y0: f32, r: f32| {
        a.enumerate_pixels()
            .filter(|(x, y, p)| (*x as f32 - x0).hypot(*y as f32 - y0) < r && b.get_pixel(*x, *y) != *p)
            .count()
    };
    let (niche, behind) = (&labels[0], &labels[1]);
    assert_eq!(b.get_pixel(niche.x_px as u32, niche.y_px as u32).0, [255, 207, 64, 255], "the dot");
    assert!(changed(niche.x_px, niche.y_px - 15.0, 12.0) > 40, "the title's box above the niche");
    assert_eq!(changed(behind.x_px, behind.y_px, 4.0), 0, "the hidden label leaves its pixels alone");
    // Supersampled, the labels land at the same place in the written image.
    let big = render_job::run(&opts(true, 2, "labels2.png"), |_| {}).unwrap();
    let n2 = &big.frames[0].labels[0];
    assert!((n2.x_px - niche.x_px).abs() < 1.0 && (n2.y_px - niche.y_px).abs() < 1.0, "{n2:?} vs {niche:?}");
    let err = render_job::run(&opts(true, 1, "labels.exr"), |_| {}).unwrap_err();
    assert!(err.to_string().contains(".exr"), "{err}");
}
