//! Survey views on a built package: each point's source scan, stored compactly (format 1.2) and
//! shown as a colour (the scan view), and the clip box, which cuts what is drawn but not the
//! light.

use std::sync::OnceLock;

use glam::Vec3;
use grotto_format::{Package, SectionKind};
use grotto_runtime::gpu::{Gpu, GpuOptions};
use grotto_runtime::render::Renderer;
use grotto_runtime::scene::data::SceneData;
use grotto_runtime::settings::{ClipBox, Settings, ViewMode, scan_color};
use grotto_runtime::view::camera::Camera;

fn gpu() -> &'static Gpu {
    static GPU: OnceLock<Gpu> = OnceLock::new();
    GPU.get_or_init(|| {
        Gpu::new(&GpuOptions { prefer_software: true, ..Default::default() }).unwrap_or_else(|e| {
            panic!("GPU tests need an adapter (scripts/test.sh installs Mesa's lavapipe): {e}")
        })
    })
}

const W: u32 = 96;
const H: u32 = 72;

/// The chamber camera, levelled: its look-at moved to the eye's height, so rows below the middle
/// of the image see only points below the eye.
fn level_chamber(scene: &SceneData) -> Camera {
    let c = scene.cameras.iter().find(|c| c.name == "chamber").map(Camera::from_scene).unwrap();
    Camera { look_at_m: Vec3::new(c.look_at_m.x, c.look_at_m.y, c.eye_m.z), ..c }
}

#[test]
fn the_scan_view_shows_each_points_scan_and_the_package_stores_it_compactly() {
    let dir = tempfile::tempdir().unwrap();
    let path =
        grotto_fixtures::small_cave_package(dir.path(), &grotto_fixtures::SmallCave::default()).unwrap();
    let pkg = Package::open(&path).unwrap();
    let scans = pkg.scene().unwrap().scans;
    assert!(scans.len() >= 2, "the synthetic cave has several scans: {scans:?}");
    assert!(scans.iter().all(|s| s.name.ends_with(".las")), "{scans:?}");
    // Every tile with surfels has one scan index per surfel, each naming a listed scan.
    let (mut surfels, mut stored) = (0u64, 0u64);
    let mut seen = vec![0u64; scans.len()];
    for tile in pkg.tiles() {
        let Some(s) = tile.surfels().unwrap() else { continue };
        let section = tile.find(SectionKind::SurfelScans, 0).expect("a surfel-scans section");
        let idx = tile.read::<u16>(SectionKind::SurfelScans).unwrap().unwrap();
        assert_eq!(idx.len(), s.len());
        for &i in idx.iter() {
            seen[usize::from(i)] += 1;
        }
        surfels += s.len() as u64;
        stored += section.stored_len;
    }
    let bytes_per_surfel = stored as f64 / surfels as f64;
    eprintln!(
        "{} scans, {surfels} surfels: scan indices take {stored} bytes stored ({bytes_per_surfel:.3} per surfel, \
         2 raw); points per scan {seen:?}",
        scans.len()
    );
    assert!(seen.iter().filter(|&&n| n > 0).count() >= 2);
    assert!(bytes_per_surfel < 1.0, "zstd must pay on scan runs: {bytes_per_surfel:.3} bytes a surfel");

    // A package whose scan indices do not fit its surfels or its scan list is refused by name.
    for (what, damage) in [("one index short", 0u16), ("a scan past the list", 1)] {
        let bad = dir.path().join("bad-scans.grotto");
        let mut w = grotto_format::PackageWriter::create(&bad).unwrap();
        for tile in pkg.tiles() {
            let t = w.add_tile(tile.info()).unwrap();
            for s in tile.sections() {
                if s.kind == Some(SectionKind::SurfelScans) && tile.index() == 0 {
                    let mut idx = tile.read::<u16>(SectionKind::SurfelScans).unwrap().unwrap().into_owned();
                    match damage {
                        0 => drop(idx.pop()),
                        _ => idx[0] = scans.len() as u16,
                    }
                    w.add_elements(
                        SectionKind::SurfelScans,
                        grotto_format::Scope::Tile(t),
                        0,
                        &idx,
                        grotto_format::Compression::Raw,
                    )
                    .unwrap();
                } else {
                    w.copy_section(&pkg, &s, grotto_format::Scope::Tile(t)).unwrap();
                }
            }
        }
        w.add_scene(&pkg.scene().unwrap()).unwrap();
        w.finish().unwrap();
        let e = SceneData::from_package(&Package::open(&bad).unwrap()).unwrap_err();
        eprintln!("{what}: {e}");
        assert!(
            matches!(e, grotto_runtime::Error::Scene { .. })
                && e.to_string().contains("bad-scans.grotto")
                && e.to_string().contains("tile 0"),
            "{what}: {e}"
        );
    }

    // The scan view: each covered pixel is one scan's colour (WGSL's scan_color agrees with the
    // CPU's), shaded by the angle to the eye; several scans show.
    let scene = SceneData::from_package(&pkg).unwrap();
    assert_eq!(scene.scan_names.len(), scans.len());
    let settings = Settings { view: ViewMode::Scan, ..Settings::default() };
    let mut r = Renderer::new(gpu(), &scene, settings).unwrap();
    let cam = level_chamber(&scene);
    let (frame, plan) = r.render(&cam, W, H).unwrap();
    assert!(!plan.runs(grotto_runtime::light::plan::Pass::Propagate), "the scan view needs no light");
    let mut pixels_per_scan = vec![0usize; scans.len()];
    let mut covered = 0;
    for p in frame.hdr.iter().filter(|p| p[3] >= 0.5) {
        covered += 1;
        let px = Vec3::new(p[0], p[1], p[2]);
        let fit = (0..scans.len() as u32)
            .map(|i| {
                let c = Vec3::from_array(scan_color(i));
                let k = px.dot(c) / c.dot(c);
                (i, k, (px - c * k).length())
            })
            .min_by(|a, b| a.2.total_cmp(&b.2))
            .unwrap();
        assert!(
            fit.2 < 2e-3 && (0.34..=1.001).contains(&fit.1),
            "pixel {px:?} is no scan's colour (nearest: scan {} x {:.3}, off by {:.4})",
            fit.0,
            fit.1,
            fit.2
        );
        pixels_per_scan[fit.0 as usize] += 1;
    }
    eprintln!("scan view: {covered} pixels covered, by scan {pixels_per_scan:?}");
    assert!(covered * 10 > (W * H) as usize * 9);
    assert!(
        pixels_per_scan.iter().filter(|&&n| n * 50 > covered).count() >= 2,
        "at least two scans show in the chamber: {pixels_per_scan:?}"
    );
}

#[test]
fn a_clip_box_cuts_what_is_drawn_but_not_the_light() {
    let dir = tempfile::tempdir().unwrap();
    let cave = grotto_fixtures::SmallCave { points: 40_000, segments: 4, ..Default::default() };
    let path = grotto_fixtures::small_cave_package(dir.path(), &cave).unwrap();
    let pkg = Package::open(&path).unwrap();
    let scene = SceneData::from_package(&pkg).unwrap();
    let settings = Settings { bounces: 2, shadow_map_size: 256, exposure: 4.0, ..Settings::default() };
    let splat_scale = settings.splat_scale;
    let mut r = Renderer::new(gpu(), &scene, settings).unwrap();
    r.settle(|_, _| {}).unwrap();
    let cam = level_chamber(&scene);
    let whole = r.render(&cam, W, H).unwrap().0;

    // A section at eye height: everything above the eye cut away.
    let (lo, hi) = scene.bounds_leaf();
    let (lo, hi) = (lo * scene.leaf_size_m, hi * scene.leaf_size_m);
    let clip = ClipBox { min_m: lo, max_m: Vec3::new(hi.x, hi.y, cam.eye_m.z) };
    r.set_clip(Some(clip));
    let cut = r.render(&cam, W, H).unwrap().0;

    // Every surface point still drawn lies in the box, but for the disc around a surfel inside
    // it (radius times the splat scale; the largest disc bounds them all).
    let reach_m = scene.surfels.iter().map(|s| s.position_radius[3]).fold(0.0, f32::max) * splat_scale;
    let inv = cam.view_proj(W, H, 0.01, 1000.0).inverse();
    let mut checked = 0;
    for y in (0..H).step_by(3) {
        for x in (0..W).step_by(3) {
            let Some(d) = r.distance_at(x, y).unwrap() else { continue };
            let ndc = glam::Vec2::new(
                (x as f32 + 0.5) / W as f32 * 2.0 - 1.0,
                1.0 - (y as f32 + 0.5) / H as f32 * 2.0,
            );
            let dir = (inv.project_point3(ndc.extend(1.0)) - cam.eye_m).normalize();
            let p = cam.eye_m + dir * d;
            assert!(
                p.z <= clip.max_m.z + reach_m + 1e-3,
                "pixel ({x}, {y}) shows a point at z {} above the cut at {} (+ {reach_m} m of disc)",
                p.z,
                clip.max_m.z
            );
            checked += 1;
        }
    }
    // The ceiling is gone: the top rows show the background where they showed rock.
    let covered = |f: &grotto_runtime::render::Frame, rows: std::ops::Range<u32>| {
        rows.flat_map(|y| (0..W).map(move |x| (x, y)))
            .filter(|&(x, y)| f.hdr[(y * W + x) as usize][3] >= 0.5)
            .count()
    };
    let top = 0..H / 5;
    let (top_whole, top_cut) = (covered(&whole, top.clone()), covered(&cut, top));
    eprintln!("clip: {checked} points checked inside; top rows covered {top_whole} whole, {top_cut} cut");
    assert!(top_whole as u32 > W * (H / 5) * 9 / 10, "the chamber's ceiling fills the top rows");
    assert!(top_cut * 4 < top_whole, "cut away: {top_cut} of {top_whole} top pixels still covered");
    // Below the eye nothing changed, light included: the rock cut away still shadows and bounces
    // light (rows well below the middle see only points under the eye, so the same surfels).
    let mut worst = 0.0f32;
    for y in H * 3 / 5..H {
        for x in 0..W {
            let (a, b) = (whole.hdr[(y * W + x) as usize], cut.hdr[(y * W + x) as usize]);
            assert_eq!(a[3], b[3], "coverage at ({x}, {y})");
            for k in 0..3 {
                worst = worst.max((a[k] - b[k]).abs() / a[k].abs().max(1e-3));
            }
        }
    }
    eprintln!("clip: lower rows differ by at most {worst:.2e} (relative)");
    assert!(worst < 1e-4, "the light below the cut changed: {worst}");
}
