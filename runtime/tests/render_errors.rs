//! Bad requests to `grotto render` fail with a typed error naming what is wrong, before any GPU
//! work; survey-sized coordinates reach the GPU as small frame coordinates.

use std::path::PathBuf;

use glam::Vec3;
use grotto_format::Package;
use grotto_preprocess::build::ColorCodec;
use grotto_runtime::Error;
use grotto_runtime::cli::render_job;
use grotto_runtime::engine::RenderOptions;
use grotto_runtime::passes::cpu_ref::CpuScene;
use grotto_runtime::scene::data::SceneData;
use grotto_runtime::settings::Settings;
use grotto_runtime::view::framing::CameraChoice;

/// A small synthetic cave at UTM-sized coordinates, several tiles.
fn fixture(dir: &std::path::Path) -> PathBuf {
    grotto_fixtures::small_cave_package(
        dir,
        &grotto_fixtures::SmallCave {
            points: 20_000,
            segments: 4,
            colors: ColorCodec::Raw,
            max_tile_extent_m: 8.0,
            ..Default::default()
        },
    )
    .unwrap()
}

fn opts(package: PathBuf, camera: CameraChoice, out: PathBuf) -> RenderOptions {
    RenderOptions {
        camera,
        frames: 1,
        width: 32,
        height: 24,
        settings: Settings::default(),
        ..RenderOptions::defaults(package, out)
    }
}

#[test]
fn bad_requests_are_typed_errors() {
    let dir = tempfile::tempdir().unwrap();
    let pkg = fixture(dir.path());
    let out = dir.path().join("x.png");

    let e = render_job::run(&opts(pkg.clone(), CameraChoice::Named("nowhere".into()), out.clone()), |_| {})
        .unwrap_err();
    assert!(matches!(e, Error::Camera(_)) && e.to_string().contains("nowhere"), "{e}");

    let e = render_job::run(&opts(pkg.clone(), CameraChoice::Default, dir.path().join("x.tif")), |_| {})
        .unwrap_err();
    assert!(matches!(e, Error::Output { .. }) && e.to_string().contains("x.tif"), "{e}");

    let same = [512_345.0, 5_123_456.0, 345.0];
    let cam = CameraChoice::Explicit { eye_m: same, look_at_m: same, up: [0.0, 0.0, 1.0], fov_y_deg: 60.0 };
    let e = render_job::run(&opts(pkg.clone(), cam, out.clone()), |_| {}).unwrap_err();
    assert!(matches!(e, Error::Camera(_)), "{e}");

    let bytes = std::fs::read(&pkg).unwrap();
    let broken = dir.path().join("broken.grotto");
    std::fs::write(&broken, &bytes[..bytes.len() / 2]).unwrap();
    let e = render_job::run(&opts(broken, CameraChoice::Default, out.clone()), |_| {}).unwrap_err();
    assert!(matches!(e, Error::Package(_)) && e.to_string().contains("broken.grotto"), "{e}");
    assert!(!out.exists(), "nothing written on failure");

    let bad = Settings { cones: 0, ..Settings::default() };
    assert!(matches!(bad.validate(), Err(Error::Setting { name: "cones", .. })));
    let bad = Settings { exposure: f32::NAN, ..Settings::default() };
    assert!(bad.validate().is_err());
}

#[test]
fn survey_coordinates_become_small_frame_coordinates() {
    let dir = tempfile::tempdir().unwrap();
    let pkg_path = fixture(dir.path());
    let pkg = Package::open(&pkg_path).unwrap();
    let scene = SceneData::from_package(&pkg).unwrap();
    assert!(scene.tiles.len() > 1);
    assert!(scene.frame_origin_m[1] > 5e6, "frame origin keeps the survey position in f64");
    let (lo, hi) = scene.bounds_leaf();
    let (lo, hi) = (lo * scene.leaf_size_m, hi * scene.leaf_size_m);
    assert!(hi.max_element() < 64.0 && lo.min_element() > -64.0, "{lo} .. {hi}");
    // Every surfel lies in a leaf of the SVO (both went through the same f64 -> frame shift).
    let cpu = CpuScene { scene: &scene, faces: Vec::new() };
    let leaf = scene.leaf_size_m;
    let missing = scene
        .surfels
        .iter()
        .filter(|s| {
            let cell = (Vec3::from_slice(&s.position_radius[..3]) / leaf).floor().as_ivec3();
            cpu.find_node(cell, 0).is_none()
        })
        .count();
    assert!(
        missing * 1000 <= scene.surfels.len(),
        "{missing} of {} surfels outside every leaf",
        scene.surfels.len()
    );
}

#[test]
fn resources_over_the_adapters_limits_are_typed_errors_not_panics() {
    let dir = tempfile::tempdir().unwrap();
    let pkg = fixture(dir.path());
    let out = dir.path().join("x.png");
    // An adapter that binds at most 64 KiB per storage buffer (the fixture's leaf light alone is
    // several times that): the first buffer over it stops the render with what to change.
    let mut small = opts(pkg.clone(), CameraChoice::Default, out.clone());
    small.gpu.max_storage_binding_bytes = Some(64 << 10);
    let e = render_job::run(&small, |_| {}).unwrap_err();
    let text = e.to_string();
    assert!(matches!(e, Error::TooLarge { .. }), "{e}");
    assert!(text.contains("storage-buffer binding, 65536 bytes"), "{text}");
    assert!(text.contains("--leaf-m"), "the hint names the leaf size: {text}");
    assert!(!out.exists(), "nothing written on failure");
    // An image larger than the largest buffer: refused before any allocation.
    let mut huge = opts(pkg, CameraChoice::Default, out.clone());
    (huge.width, huge.height) = (16384, 16384);
    huge.gpu.max_storage_binding_bytes = Some(1 << 30);
    let e = render_job::run(&huge, |_| {}).unwrap_err();
    assert!(matches!(e, Error::TooLarge { .. }) && e.to_string().contains("--size"), "{e}");
}
