//! Scan to image: the synthetic demo cave is built into a package and rendered with global
//! illumination on the Vulkan and the GL backend (Mesa's software drivers in CI); both must match
//! the same golden images within the shared tolerance (grotto_tests::golden).

use std::path::Path;

use grotto_runtime::cli::render_job;
use grotto_runtime::engine::RenderOptions;
use grotto_runtime::gpu::GpuOptions;
use grotto_runtime::settings::Settings;
use grotto_runtime::view::framing::CameraChoice;
use grotto_tests::golden;

/// A 160x120 single frame of `camera` to `out` on the software Vulkan adapter, default settings;
/// callers override what they vary.
fn view(package: &Path, camera: &str, out: std::path::PathBuf) -> RenderOptions {
    RenderOptions {
        camera: CameraChoice::Named(camera.into()),
        width: 160,
        height: 120,
        settings: Settings::default(),
        gpu: grotto_tests::lavapipe(),
        ..RenderOptions::defaults(package.to_path_buf(), out)
    }
}

fn build_small_cave(dir: &Path) -> std::path::PathBuf {
    grotto_fixtures::small_cave_package(dir, &grotto_fixtures::SmallCave::default()).unwrap()
}

#[test]
fn demo_cave_renders_the_same_on_vulkan_and_gl() {
    let dir = tempfile::tempdir().unwrap();
    let package = build_small_cave(dir.path());
    for (backend, name) in [(wgpu::Backends::VULKAN, "vulkan"), (wgpu::Backends::GL, "gl")] {
        for camera in ["chamber", "entrance"] {
            let out = dir.path().join(format!("{camera}-{name}.png"));
            let opts = RenderOptions {
                settings: Settings { bounces: 3, shadow_map_size: 256, ..Settings::default() },
                exposure: Some(8.0),
                gpu: GpuOptions { prefer_software: true, backends: Some(backend), ..Default::default() },
                ..view(&package, camera, out.clone())
            };
            let summary = render_job::run(&opts, |_| {}).unwrap_or_else(|e| panic!("{name}: {e}"));
            assert!(summary.tiles > 1, "the demo cave must span several tiles");
            let (w, h, pixels) = grotto_runtime::cli::image_out::read_png(&out).unwrap();
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
        width: 640,
        height: 480,
        settings: Settings { bounces: 1, shadow_map_size: 256, ..Settings::default() },
        exposure: Some(8.0),
        ..view(&package, "chamber", exr_path.clone())
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
            let opts =
                RenderOptions { settings, exposure: Some(8.0), ..view(&package, "chamber", out.clone()) };
            render_job::run(&opts, |_| {}).unwrap();
            let (w, h, pixels) = grotto_runtime::cli::image_out::read_png(&out).unwrap();
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

/// Golden images of the demo cave lit by an environment map through its entrance, with wet walls
/// (the first chamber) and a pool (level floors of the passage's middle third), relit by a lamp
/// string of 64 lamps: 16 with shadow maps, 48 per leaf with SVO cone shadows. Vulkan only (the
/// GL path is covered by the dry goldens above).
#[test]
fn wet_demo_cave_under_a_sky_with_a_lamp_string_matches_its_golden_images() {
    use grotto_runtime::render::Renderer;
    use grotto_runtime::settings::ShadowFallback;
    let Some(data) = grotto_tests::shared_data_dir() else { return };
    let dir = tempfile::tempdir().unwrap();
    let cave = grotto_fixtures::SmallCave {
        sky: Some(data.join("envmaps/probulator_ennis.hdr")),
        wet: true,
        ..grotto_fixtures::SmallCave::default()
    };
    let package = grotto_fixtures::small_cave_package(dir.path(), &cave).unwrap();
    let pkg = grotto_format::Package::open(&package).unwrap();
    let scene = grotto_runtime::scene::data::SceneData::from_package(&pkg).unwrap();
    assert_eq!(scene.materials.len(), 2, "wet walls and a pool");
    assert!(scene.materials.iter().all(|m| m.surfels > 100), "{:?}", scene.materials);
    assert!(scene.env_chain.is_some(), "the sky's prefiltered chain is loaded");
    let settings = Settings {
        bounces: 2,
        shadow_map_size: 256,
        shadowed_lights: 16,
        shadow_fallback: ShadowFallback::Cone,
        ..Settings::default()
    };
    let mut frames = Vec::new();
    for camera in ["chamber", "entrance"] {
        let out = dir.path().join(format!("wet-{camera}.png"));
        let opts = RenderOptions {
            settings: settings.clone(),
            exposure: Some(1.0),
            lamp_string: Some(64),
            ..view(&package, camera, out.clone())
        };
        let summary = render_job::run(&opts, |_| {}).unwrap();
        let explain = summary.first_plan.explain() + &summary.last_plan.explain();
        assert!(explain.contains("specular cones for 2 specular materials"), "{explain}");
        assert!(explain.contains("48 more lit per leaf with SVO cone shadows"), "{explain}");
        assert!(explain.contains("run   env"), "{explain}");
        let (w, h, pixels) = grotto_runtime::cli::image_out::read_png(&out).unwrap();
        let d = golden::check(&format!("demo-wet-{camera}"), w, h, &pixels);
        eprintln!("wet {camera}: {d:?}");
        assert!(golden::within_tolerance(&d), "wet {camera} differs from the golden image: {d:?}");
        frames.push(pixels);
    }
    // Every pass (shadow maps, cone shadows, env, specular cones, shade) fits the limits a browser
    // grants without asking (WebGPU's defaults: 8 storage buffers a stage), and the
    // image does not depend on them.
    let out = dir.path().join("wet-webgpu-limits.png");
    let opts = RenderOptions {
        settings: settings.clone(),
        exposure: Some(1.0),
        lamp_string: Some(64),
        gpu: GpuOptions { webgpu_limits: true, ..view(&package, "chamber", out.clone()).gpu },
        ..view(&package, "chamber", out.clone())
    };
    render_job::run(&opts, |_| {}).unwrap_or_else(|e| panic!("under WebGPU's default limits: {e:#}"));
    let (_, _, pixels) = grotto_runtime::cli::image_out::read_png(&out).unwrap();
    assert!(pixels == frames[0], "under WebGPU's default limits: {:?}", golden::diff(&pixels, &frames[0]));
    // The wet walls must show: the same view without specular reflection leaves the tolerance.
    if std::env::var_os("GROTTO_BLESS").is_none() {
        let gpu = grotto_runtime::gpu::Gpu::new(&grotto_tests::lavapipe()).unwrap();
        let mut scene = scene;
        scene.lights = scene.lamp_string(
            64,
            grotto_runtime::engine::STRING_LAMP_W,
            grotto_runtime::engine::STRING_LAMP_LIFT_M,
        );
        let cam = grotto_runtime::view::framing::resolve_camera(
            &scene,
            &CameraChoice::Named("chamber".into()),
            4.0 / 3.0,
            2.0,
        )
        .unwrap()
        .0;
        let mut r =
            Renderer::new(&gpu, &scene, Settings { specular: false, exposure: 1.0, ..settings }).unwrap();
        r.settle(|_, _| {}).unwrap();
        let (frame, plan) = r.render(&cam, 160, 120).unwrap();
        assert!(plan.explain().contains("no specular cones"), "{}", plan.explain());
        // Wet walls are a few percent of reflection (Fresnel at water's 1.33) with lamp highlights:
        // the change is local, so count the pixels it moves by more than 8 levels.
        let moved =
            frame.ldr.iter().zip(&frames[0]).filter(|(a, b)| (0..3).any(|k| a[k].abs_diff(b[k]) > 8)).count();
        eprintln!(
            "chamber without specular: {:?}, {moved} pixels moved by > 8",
            golden::diff(&frame.ldr, &frames[0])
        );
        assert!(
            moved * 200 >= frame.ldr.len(),
            "specular reflection must change the wet chamber: {moved} pixels"
        );
    }
}

/// Culling by surfel chunks draws the same image as drawing whole tiles, with less work: surfel chunks
/// culled per shadow face (frustum and the light's range) and per view give the same bytes; the
/// level of detail (far chunks thinned) stays within the golden tolerance and draws fewer
/// surfels. The counts come from the renderer's own counters (render/counters.rs).
#[test]
fn culled_and_thinned_draws_match_whole_tiles_with_less_work() {
    use grotto_runtime::light::plan::Pass;
    let dir = tempfile::tempdir().unwrap();
    let package = build_small_cave(dir.path());
    let run = |name: &str, cull_chunks: bool, splat_lod: bool| {
        let out = dir.path().join(format!("{name}.png"));
        let settings =
            Settings { bounces: 0, shadow_map_size: 128, cull_chunks, splat_lod, ..Settings::default() };
        let opts = RenderOptions {
            settings,
            exposure: Some(8.0),
            width: 96,
            height: 72,
            ..view(&package, "entrance", out.clone())
        };
        let summary = render_job::run(&opts, |_| {}).unwrap();
        let (_, _, pixels) = grotto_runtime::cli::image_out::read_png(&out).unwrap();
        let drawn = |p: Pass| summary.stats.work.get(&p).map_or(0, |w| w.surfels);
        (pixels, drawn(Pass::Shadow), drawn(Pass::Gbuffer), summary.surfels as u64)
    };
    let (tiles, tiles_shadow, tiles_gbuffer, surfels) = run("tiles", false, false);
    let (chunks, chunks_shadow, chunks_gbuffer, _) = run("chunks", true, false);
    let (thin, thin_shadow, thin_gbuffer, _) = run("thin", true, true);
    eprintln!(
        "{surfels} surfels; shadow maps drew {tiles_shadow} / {chunks_shadow} / {thin_shadow}, \
         the G-buffer {tiles_gbuffer} / {chunks_gbuffer} / {thin_gbuffer} (tiles / chunks / thinned)"
    );
    assert!(tiles == chunks, "culling by chunks changed the image");
    // A cube face sees about a sixth of the directions around its lamp; chunks straddle faces
    // and the small cave's lamps see most of it (measured: half the surfels of whole tiles).
    assert!(chunks_shadow * 3 < tiles_shadow * 2, "chunks must cut the shadow maps' draws");
    assert!(chunks_gbuffer <= tiles_gbuffer && chunks_gbuffer > 0);
    let d = golden::diff(&thin, &chunks);
    eprintln!("thinned against every surfel: {d:?}");
    assert!(golden::within_tolerance(&d), "the level of detail left the tolerance: {d:?}");
    assert!(thin_gbuffer < chunks_gbuffer, "at 96x72 far chunks must thin");
    assert!(thin_shadow <= chunks_shadow);
}
