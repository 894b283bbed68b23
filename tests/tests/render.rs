//! Scan to image: the synthetic demo cave is built into a package and rendered with global
//! illumination on the Vulkan and the GL backend (Mesa's software drivers in CI); both must match
//! the same golden images within the shared tolerance (grotto_tests::golden).

use std::path::Path;

use grotto_preprocess::synth;
use grotto_runtime::gpu::GpuOptions;
use grotto_runtime::render_job::{self, CameraChoice, RenderOptions};
use grotto_runtime::renderer::Settings;
use grotto_tests::golden;

fn build_small_cave(dir: &Path) -> std::path::PathBuf {
    synth::small_cave_package(dir, &synth::SmallCave::default()).unwrap()
}

#[test]
fn demo_cave_renders_the_same_on_vulkan_and_gl() {
    let dir = tempfile::tempdir().unwrap();
    let package = build_small_cave(dir.path());
    for (backend, name) in [(wgpu::Backends::VULKAN, "vulkan"), (wgpu::Backends::GL, "gl")] {
        for camera in ["chamber", "entrance"] {
            let out = dir.path().join(format!("{camera}-{name}.png"));
            let opts = RenderOptions {
                package: package.clone(),
                camera: CameraChoice::Named(camera.into()),
                path: Vec::new(),
                frames: 1,
                width: 160,
                height: 120,
                out: out.clone(),
                settings: Settings { bounces: 3, shadow_map_size: 256, ..Settings::default() },
                exposure: Some(8.0),
                gpu: GpuOptions { prefer_software: true, backends: Some(backend) },
            };
            let summary = render_job::run(&opts, |_| {}).unwrap_or_else(|e| panic!("{name}: {e}"));
            assert!(summary.tiles > 1, "the demo cave must span several tiles");
            let (w, h, pixels) = grotto_runtime::image_out::read_png(&out).unwrap();
            // No holes: every pixel of an enclosed cave view sees a wall.
            let lit = pixels.iter().filter(|p| p[0] > 0 || p[1] > 0 || p[2] > 0).count();
            assert!(
                lit * 1000 >= pixels.len() * 995,
                "{camera} on {name}: {lit} of {} pixels lit",
                pixels.len()
            );
            let d = golden::check(&format!("demo-{camera}"), w, h, &pixels);
            eprintln!("{camera} on {} ({}): {d:?}", name, summary.device);
            assert!(golden::within_tolerance(&d), "{camera} on {name} differs from the golden image: {d:?}");
        }
    }
    // No holes at the demo's resolution, and linear radiance as EXR.
    let exr_path = dir.path().join("chamber.exr");
    let opts = RenderOptions {
        package: package.clone(),
        camera: CameraChoice::Named("chamber".into()),
        path: Vec::new(),
        frames: 1,
        width: 640,
        height: 480,
        out: exr_path.clone(),
        settings: Settings { bounces: 1, shadow_map_size: 256, ..Settings::default() },
        exposure: Some(8.0),
        gpu: GpuOptions { prefer_software: true, backends: Some(wgpu::Backends::VULKAN) },
    };
    render_job::run(&opts, |_| {}).unwrap();
    let img = exr::prelude::read_first_rgba_layer_from_file(
        &exr_path,
        |res, _| vec![[0f32; 4]; res.width() * res.height()],
        |px: &mut Vec<[f32; 4]>, pos, (r, g, b, a): (f32, f32, f32, f32)| {
            px[pos.y() * 640 + pos.x()] = [r, g, b, a]
        },
    )
    .unwrap();
    let px = &img.layer_data.channel_data.pixels;
    assert_eq!(px.len(), 640 * 480);
    let covered = px.iter().filter(|p| p[3] > 0.5).count();
    let holes = px.len() - covered;
    eprintln!("640x480 chamber: {holes} uncovered pixels");
    assert!(holes * 10_000 <= px.len(), "{holes} holes at 640x480");
    assert!(px.iter().all(|p| p.iter().all(|v| v.is_finite() && *v >= 0.0)));
    assert!(px.iter().map(|p| f64::from(p[1])).sum::<f64>() > 0.0);

    // The comparison can fail: dropping the bounces or the shadows leaves the tolerance.
    if std::env::var_os("GROTTO_BLESS").is_none() {
        for (what, settings) in [
            ("no bounces", Settings { bounces: 0, shadow_map_size: 256, ..Settings::default() }),
            (
                "no shadows",
                Settings { bounces: 3, shadows: false, shadow_map_size: 256, ..Settings::default() },
            ),
        ] {
            let out = dir.path().join("wrong.png");
            let opts = RenderOptions {
                package: package.clone(),
                camera: CameraChoice::Named("chamber".into()),
                path: Vec::new(),
                frames: 1,
                width: 160,
                height: 120,
                out: out.clone(),
                settings,
                exposure: Some(8.0),
                gpu: GpuOptions { prefer_software: true, backends: Some(wgpu::Backends::VULKAN) },
            };
            render_job::run(&opts, |_| {}).unwrap();
            let (w, h, pixels) = grotto_runtime::image_out::read_png(&out).unwrap();
            let d = golden::diff(&pixels, &golden_pixels("demo-chamber", w, h));
            eprintln!("{what}: {d:?}");
            assert!(!golden::within_tolerance(&d), "{what} must not pass as the golden image");
        }
    }
}

fn golden_pixels(name: &str, w: u32, h: u32) -> Vec<[u8; 4]> {
    let img = image::open(golden::path(name)).unwrap().to_rgba8();
    assert_eq!(img.dimensions(), (w, h));
    img.as_raw().chunks_exact(4).map(|c| [c[0], c[1], c[2], c[3]]).collect()
}
