//! GPU passes on the shared test device (software adapter first): mip and cone gather against the
//! CPU reference, the furnace, multiple bounces, and the effect plan's skipped passes.

use std::sync::OnceLock;

use glam::Vec3;
use grotto_runtime::cpu_ref::CpuScene;
use grotto_runtime::gpu::{Gpu, GpuOptions};
use grotto_runtime::gpu_types::LeafLightGpu;
use grotto_runtime::renderer::{Renderer, Settings};
use grotto_runtime::testscenes;

fn gpu() -> &'static Gpu {
    static GPU: OnceLock<Gpu> = OnceLock::new();
    GPU.get_or_init(|| {
        let g = Gpu::new(&GpuOptions { prefer_software: true, ..Default::default() }).unwrap_or_else(|e| {
            panic!("GPU tests need an adapter (scripts/test.sh installs Mesa's lavapipe): {e}")
        });
        eprintln!("test device: {}", g.describe());
        g
    })
}

/// Deterministic pseudo-random radiance per leaf.
fn random_light(n: usize, seed: u32) -> Vec<LeafLightGpu> {
    let mut s = seed.wrapping_mul(747_796_405).wrapping_add(2_891_336_453);
    let mut next = move || {
        s ^= s << 13;
        s ^= s >> 17;
        s ^= s << 5;
        (s >> 8) as f32 / (1u32 << 24) as f32
    };
    (0..n)
        .map(|_| LeafLightGpu { out: [next() * 3.0, next(), next() * 0.5, 0.0], ..Default::default() })
        .collect()
}

#[test]
fn mip_matches_cpu_reference() {
    let scene = testscenes::dogleg();
    assert!(scene.tiles.len() >= 4, "the scene must span several tiles");
    let mut r = Renderer::new(gpu(), &scene, Settings::default()).unwrap();
    let light = random_light(scene.leaves.len(), 7);
    r.write_leaf_light(&light).unwrap();
    r.run_mip().unwrap();
    let got = r.read_faces().unwrap();
    let want = CpuScene::mip(&scene, &light).faces;
    assert_eq!(got.len(), want.len());
    let mut worst = 0.0f64;
    for (g, w) in got.iter().zip(&want) {
        for k in 0..4 {
            worst = worst.max((f64::from(g[k]) - w[k]).abs() / w[k].abs().max(1.0));
        }
    }
    eprintln!("mip: worst error {worst:.2e} over {} node values", got.len());
    // Stated tolerance: f32 sums of at most 8 terms per level, relative to max(|value|, 1).
    assert!(worst < 1e-5, "mip differs from the CPU reference by {worst}");
}

#[test]
fn f16_radiance_pyramid_matches_cpu_within_half_precision_and_stays_finite() {
    let scene = testscenes::dogleg();
    let settings = Settings { radiance_f16: true, ..Default::default() };
    let mut r = Renderer::new(gpu(), &scene, settings.clone()).unwrap();
    let light = random_light(scene.leaves.len(), 7);
    r.write_leaf_light(&light).unwrap();
    r.run_mip().unwrap();
    let got = r.read_faces().unwrap();
    let want = CpuScene::mip(&scene, &light).faces;
    let mut worst = 0.0f64;
    for (g, w) in got.iter().zip(&want) {
        for k in 0..4 {
            worst = worst.max((f64::from(g[k]) - w[k]).abs() / w[k].abs().max(1.0));
        }
    }
    eprintln!("mip (f16): worst error {worst:.2e} over {} node values", got.len());
    // Stated tolerance: one f16 rounding (2^-11 relative) per level stored, the tile depth being 5.
    assert!(worst > 1e-6, "f16 storage must round: {worst}");
    assert!(worst < 6.0 * 2f64.powi(-11), "f16 mip differs from the CPU reference by {worst}");

    // Radiance beyond f16's range (a very bright lamp) is clamped, never infinite or NaN.
    let bright: Vec<LeafLightGpu> =
        light.iter().map(|l| LeafLightGpu { out: [1e7, l.out[1], 1e5, 0.0], ..*l }).collect();
    let mut r = Renderer::new(gpu(), &scene, settings).unwrap();
    r.write_leaf_light(&bright).unwrap();
    r.run_mip().unwrap();
    r.run_bounce().unwrap();
    let faces = r.read_faces().unwrap();
    assert!(faces.iter().flatten().all(|v| v.is_finite()), "f16 pyramid overflowed");
    assert!(faces.iter().any(|f| f[0] == 65504.0), "bright radiance should clamp at the f16 maximum");
    assert!(r.read_leaf_light().unwrap().iter().all(|l| l.gather.iter().all(|v| v.is_finite())));
}

#[test]
fn cone_gather_matches_cpu_reference() {
    let scene = testscenes::dogleg();
    for cones in [4u32, 16] {
        let settings = Settings { cones, ..Default::default() };
        let mut r = Renderer::new(gpu(), &scene, settings).unwrap();
        let light = random_light(scene.leaves.len(), 11);
        r.write_leaf_light(&light).unwrap();
        r.run_bounce().unwrap();
        let got = r.read_leaf_light().unwrap();
        let cpu = CpuScene::mip(&scene, &light);
        let params = r.params();
        let mut worst = 0.0f64;
        let mut checked = 0;
        for i in (0..scene.leaves.len()).step_by(7) {
            // Surface leaves only: rock interiors gather trivially.
            if scene.leaves[i].normal_mean[..3].iter().all(|&v| v == 0.0) {
                continue;
            }
            let want = cpu.gather(&params, i);
            let g = got[i].gather;
            for k in 0..3 {
                worst = worst.max((f64::from(g[k]) - want[k]).abs() / want[k].abs().max(0.05));
            }
            checked += 1;
        }
        eprintln!("gather ({cones} cones): worst error {worst:.2e} over {checked} leaves");
        assert!(checked > 100);
        // Stated tolerance 1e-3: f32 vs f64 marching, pow/log2 approximations on the GPU.
        assert!(worst < 1e-3, "gather differs from the CPU reference by {worst}");
    }
}

fn furnace(albedo: f32, bounces: u32) -> (f32, f32, bool) {
    furnace_with(albedo, Settings { bounces, convergence_tolerance: 1e-7, ..Default::default() })
}

fn furnace_with(albedo: f32, settings: Settings) -> (f32, f32, bool) {
    let scene = testscenes::furnace_sphere(5, 11.0, albedo, 1.0);
    let mut r = Renderer::new(gpu(), &scene, settings).unwrap();
    r.settle(|_, _| {}).unwrap();
    let light = r.read_leaf_light().unwrap();
    let finite = light.iter().all(|l| l.out.iter().all(|v| v.is_finite()));
    let (mut lo, mut hi) = (f32::MAX, f32::MIN);
    for l in &light {
        lo = lo.min(l.out[0]);
        hi = hi.max(l.out[0]);
    }
    (lo, hi, finite)
}

#[test]
fn furnace_converges_to_e_over_one_minus_albedo() {
    for (albedo, bounces) in [(0.5f32, 60u32), (0.9, 200)] {
        let exact = 1.0 / (1.0 - albedo);
        let (lo, hi, finite) = furnace(albedo, bounces);
        eprintln!("furnace albedo {albedo}: radiance {lo:.4} .. {hi:.4}, exact {exact:.4}");
        assert!(finite);
        assert!((lo - exact).abs() / exact < 0.02 && (hi - exact).abs() / exact < 0.02);
    }
}

#[test]
fn furnace_with_f16_radiance_converges_within_two_percent() {
    let settings =
        Settings { bounces: 200, convergence_tolerance: 1e-7, radiance_f16: true, ..Default::default() };
    let (lo, hi, finite) = furnace_with(0.9, settings);
    eprintln!("furnace albedo 0.9, f16 radiance: {lo:.4} .. {hi:.4}, exact 10");
    assert!(finite);
    assert!((lo - 10.0).abs() / 10.0 < 0.02 && (hi - 10.0).abs() / 10.0 < 0.02);
}

#[test]
fn furnace_at_albedo_099_stays_bounded() {
    let (lo, hi, finite) = furnace(0.99, 500);
    eprintln!("furnace albedo 0.99 after 500 bounces: {lo:.3} .. {hi:.3} (limit 100)");
    assert!(finite);
    // After 500 bounces the exact partial sum is (1 - 0.99^501) / 0.01 = 99.35.
    assert!(hi <= 100.0 * 1.001 && lo > 90.0);
}

#[test]
fn hidden_chamber_needs_several_bounces() {
    let scene = testscenes::dogleg();
    let chamber: Vec<usize> = scene
        .leaves
        .iter()
        .enumerate()
        .filter(|(_, l)| {
            let c = (Vec3::from_slice(&l.center_m[..3]) / scene.leaf_size_m).floor().as_ivec3();
            testscenes::dogleg_chamber(c) && l.normal_mean[..3].iter().any(|&v| v != 0.0)
        })
        .map(|(i, _)| i)
        .collect();
    let room: Vec<usize> = scene
        .leaves
        .iter()
        .enumerate()
        .filter(|(_, l)| {
            let c = (Vec3::from_slice(&l.center_m[..3]) / scene.leaf_size_m).floor().as_ivec3();
            c.y < 10 && c.x < 11 && l.normal_mean[..3].iter().any(|&v| v != 0.0)
        })
        .map(|(i, _)| i)
        .collect();
    assert!(chamber.len() > 100 && room.len() > 100);
    let mean = |light: &[LeafLightGpu], set: &[usize]| {
        set.iter().map(|&i| light[i].out[1]).sum::<f32>() / set.len() as f32
    };
    let mut results = Vec::new();
    for bounces in [1u32, 16] {
        let settings = Settings { bounces, cones: 16, convergence_tolerance: 0.0, ..Default::default() };
        let mut r = Renderer::new(gpu(), &scene, settings).unwrap();
        r.settle(|_, _| {}).unwrap();
        let light = r.read_leaf_light().unwrap();
        results.push((mean(&light, &chamber), mean(&light, &room)));
    }
    eprintln!("chamber / room radiance: 1 bounce {:?}, 16 bounces {:?}", results[0], results[1]);
    let (one, many) = (results[0], results[1]);
    // One bounce: black at any exposure that shows the lit room (what reaches C is the blur of
    // wide cones over coarse voxels, not a light path).
    assert!(one.0 < 1e-4 * one.1, "one bounce must leave the chamber black");
    // Several bounces carry light around the three bends.
    assert!(many.0 > 10.0 * one.0, "several bounces must light the chamber");
}

fn max_abs_diff(a: &[[f32; 4]], b: &[[f32; 4]]) -> f32 {
    a.iter().zip(b).flat_map(|(p, q)| (0..3).map(move |k| (p[k] - q[k]).abs())).fold(0.0, f32::max)
}

#[test]
fn skipped_passes_are_not_dispatched_and_change_nothing() {
    use grotto_runtime::camera::Camera;
    use grotto_runtime::plan::Pass;
    // Emission only: no point or spot lights, so no shadow maps and no injection.
    let scene = testscenes::furnace_sphere(4, 5.0, 0.5, 1.0);
    let cam =
        Camera { eye_m: Vec3::splat(0.8), look_at_m: Vec3::new(1.2, 0.9, 0.7), up: Vec3::Z, fov_y_deg: 70.0 };
    let settings = Settings { bounces: 64, exposure: 0.1, ..Default::default() };
    let mut r = Renderer::new(gpu(), &scene, settings.clone()).unwrap();
    let explained = r.plan(Some((&cam, 64, 48))).explain();
    assert!(explained.contains("skip  shadow") && explained.contains("skip  inject"), "{explained}");
    r.settle(|_, _| {}).unwrap();
    let bounces = r.stats().bounces_done;
    assert!(bounces < 64, "propagation must stop once converged, ran {bounces}");
    let (a, plan) = r.render(&cam, 64, 48).unwrap();
    assert!(!plan.runs(Pass::Propagate) && !plan.runs(Pass::Mip), "{}", plan.explain());
    // The same frame again: the G-buffer is kept too.
    let (b, plan) = r.render(&cam, 64, 48).unwrap();
    assert!(!plan.runs(Pass::Gbuffer));
    assert_eq!(a.hdr, b.hdr);
    let d = &r.stats().dispatches;
    assert_eq!(d.get(&Pass::Shadow), None);
    assert_eq!(d.get(&Pass::Inject), None);
    assert_eq!(d.get(&Pass::Mip).copied(), Some(u64::from(bounces)));
    assert_eq!(d.get(&Pass::Propagate).copied(), Some(u64::from(bounces)));
    assert_eq!(d.get(&Pass::Gbuffer).copied(), Some(1));
    assert_eq!(d.get(&Pass::Shade).copied(), Some(2));

    // Forcing the skipped passes: shadow, inject, gbuffer and one more bounce.
    r.set_forced(&[Pass::Shadow, Pass::Inject, Pass::Gbuffer, Pass::Mip, Pass::Env, Pass::Propagate]);
    let (c, plan) = r.render(&cam, 64, 48).unwrap();
    assert!(plan.steps.iter().all(|s| s.run));
    let d = &r.stats().dispatches;
    assert_eq!(d.get(&Pass::Shadow).copied(), Some(1));
    assert_eq!(d.get(&Pass::Inject).copied(), Some(1));
    // Shadow and inject with no lights change nothing; the extra bounce changes the converged
    // radiance by less than the convergence tolerance.
    let scale = a.hdr.iter().map(|p| p[0]).fold(0.0, f32::max);
    let diff = max_abs_diff(&a.hdr, &c.hdr);
    eprintln!("forced passes changed the image by {diff:.2e} (peak {scale:.3})");
    assert!(diff <= settings.convergence_tolerance * scale);
}

#[test]
fn lights_and_shadows_run_once_for_static_lights() {
    use grotto_runtime::plan::Pass;
    let scene = testscenes::dogleg();
    let mut r = Renderer::new(gpu(), &scene, Settings { bounces: 2, ..Default::default() }).unwrap();
    let cam = grotto_runtime::camera::Camera::from_scene(&scene.cameras[0]);
    let (first, plan) = r.render(&cam, 64, 48).unwrap();
    assert!(plan.runs(Pass::Shadow) && plan.runs(Pass::Inject));
    let (_, plan) = r.render(&cam, 64, 48).unwrap();
    assert!(!plan.runs(Pass::Shadow) && !plan.runs(Pass::Inject) && plan.runs(Pass::Propagate));
    let (third, plan) = r.render(&cam, 64, 48).unwrap();
    assert!(!plan.runs(Pass::Propagate), "bounce budget of 2 spent: {}", plan.explain());
    assert_eq!(r.stats().dispatches.get(&Pass::Shadow).copied(), Some(1));
    // Shadowed direct light: room A is lit, the hidden chamber is not; bounces add light.
    let sum = |f: &grotto_runtime::renderer::Frame| f.hdr.iter().map(|p| p[1] as f64).sum::<f64>();
    assert!(sum(&third) > sum(&first));
    r.invalidate_lights();
    let (_, plan) = r.render(&cam, 64, 48).unwrap();
    assert!(plan.runs(Pass::Shadow) && plan.runs(Pass::Inject));
}

#[test]
fn spot_light_lights_only_its_cone() {
    use grotto_runtime::scene_data::{SceneLight, Spot};
    let mut scene = testscenes::dogleg();
    let leaf = scene.leaf_size_m;
    // Room A spans cells x 2..10, y 1..9, z 2..10; aim at its -x wall (cells x = 1).
    scene.lights = vec![SceneLight {
        name: "spot".into(),
        position_m: Vec3::new(8.0, 5.0, 6.0) * leaf,
        intensity_w_sr: Vec3::splat(10.0),
        spot: Some(Spot { direction: Vec3::NEG_X, inner_angle_rad: 0.2, outer_angle_rad: 0.3 }),
    }];
    let mut r = Renderer::new(gpu(), &scene, Settings { bounces: 0, ..Default::default() }).unwrap();
    r.update_light().unwrap();
    let light = r.read_leaf_light().unwrap();
    let apex = Vec3::new(8.0, 5.0, 6.0) * leaf;
    let (mut inside, mut outside, mut inside_lit, mut outside_lit) = (0, 0, 0, 0);
    for (l, s) in scene.leaves.iter().zip(&light) {
        let c = Vec3::from_slice(&l.center_m[..3]);
        let cell = (c / leaf).floor();
        if cell.x != 1.0 || cell.y < 1.0 || cell.y > 8.0 || cell.z < 2.0 || cell.z > 9.0 {
            continue; // only room A's -x wall
        }
        let angle = (c - apex).normalize().dot(Vec3::NEG_X).acos();
        let lit = s.direct[1] > 0.0;
        if angle < 0.18 {
            inside += 1;
            inside_lit += usize::from(lit);
        } else if angle > 0.35 {
            outside += 1;
            outside_lit += usize::from(lit);
        }
    }
    eprintln!("spot: {inside_lit}/{inside} lit inside the cone, {outside_lit}/{outside} outside");
    assert!(inside > 0 && inside_lit == inside);
    assert!(outside > 0 && outside_lit == 0);
}

/// A pseudo-random environment (9 RGB SH coefficients) whose irradiance stays positive: a strong
/// constant term under random higher bands.
fn random_sky(seed: u32) -> [[f32; 3]; 9] {
    let light = random_light(9, seed);
    let mut sh = [[0.0f32; 3]; 9];
    for (i, c) in sh.iter_mut().enumerate() {
        for k in 0..3 {
            let v = light[i].out[k] / [3.0, 1.0, 0.5][k] - 0.5;
            c[k] = if i == 0 { 4.0 + v } else { 0.8 * v };
        }
    }
    sh
}

#[test]
fn sh_irradiance_on_the_gpu_matches_the_cpu_for_ten_thousand_normals() {
    use grotto_runtime::scene_data::{SceneData, VoxelLeaf};
    // Isolated leaves on a sparse grid with random unit normals; cones end at once (max distance
    // below a leaf), so every leaf sees the whole sky (V = 1) and gets exactly albedo * E(n) / pi.
    let normals = random_light(10_000, 5);
    let cells: Vec<VoxelLeaf> = normals
        .iter()
        .enumerate()
        .map(|(i, l)| {
            let i = i as i32;
            let v = Vec3::new(l.out[0] / 3.0 - 0.5, l.out[1] - 0.5, l.out[2] * 2.0 - 0.5);
            VoxelLeaf {
                cell: glam::IVec3::new(i % 32, (i / 32) % 32, i / 1024) * 3,
                albedo: Vec3::new(0.8, 0.5, 0.3),
                opacity: 1.0,
                normal_mean: v.normalize_or(Vec3::Z),
                emission: Vec3::ZERO,
            }
        })
        .collect();
    let mut scene = SceneData::from_voxels("sh probes", 0.1, 7, &cells);
    let sky = random_sky(3);
    scene.environment_sh = Some(sky);
    let settings = Settings { max_distance_m: Some(0.05), bounces: 1, ..Default::default() };
    let mut r = Renderer::new(gpu(), &scene, settings).unwrap();
    let plan = r.update_light().unwrap();
    assert!(plan.runs(grotto_runtime::plan::Pass::Env), "{}", plan.explain());
    let light = r.read_leaf_light().unwrap();
    let sh = grotto_format::spec::ShRgb9 { coeffs: sky };
    let mut worst = 0.0f64;
    for (leaf, state) in scene.leaves.iter().zip(&light) {
        let n = Vec3::from_slice(&leaf.normal_mean[..3]).normalize().as_dvec3().to_array();
        let e = grotto_preprocess::env::irradiance(&sh, n);
        assert!(e.iter().all(|&v| v > 0.0), "the test sky must stay positive");
        for (k, e_k) in e.iter().enumerate() {
            let want = f64::from(leaf.albedo_opacity[k]) * e_k / std::f64::consts::PI;
            worst = worst.max((f64::from(state.env[k]) - want).abs() / want);
        }
        assert_eq!(state.env[3], 1.0, "an unoccluded leaf sees all of the sky");
    }
    eprintln!("SH irradiance, {} normals: worst relative error {worst:.2e}", light.len());
    assert!(worst < 1e-4, "GPU SH irradiance differs from the CPU by {worst}");
}

#[test]
fn constant_environment_equals_an_equal_ambient_term() {
    use grotto_runtime::camera::Camera;
    use grotto_runtime::scene_data::SceneCamera;
    let ambient = [0.3f32, 0.45, 0.6];
    // The shell with an opening, seen from inside with the opening in view: walls lit through it
    // and sky behind it.
    let plain = testscenes::open_sphere(5, 11.0, 0.6, 0.0, 0.8);
    let mut with_env = plain.clone();
    // A constant map: only L00, with L00 * Y00 = the radiance.
    let mut sh = [[0.0f32; 3]; 9];
    sh[0] = ambient.map(|a| a / 0.282_094_8);
    with_env.environment_sh = Some(sh);
    let c = Vec3::splat(1.6);
    let camera = Camera::from_scene(&SceneCamera {
        name: "up".into(),
        eye_m: c,
        look_at_m: c + Vec3::new(0.5, 0.2, 1.0),
        up: Vec3::Y,
        fov_y_deg: 80.0,
    });
    let (w, h) = (64, 48);
    let base = Settings { bounces: 3, convergence_tolerance: 0.0, exposure: 1.0, ..Default::default() };
    let render = |scene, settings: Settings| {
        let mut r = Renderer::new(gpu(), scene, settings).unwrap();
        r.settle(|_, _| {}).unwrap();
        r.render(&camera, w, h).unwrap().0.hdr
    };
    let a = render(&with_env, base.clone());
    let b = render(&plain, Settings { background: ambient, ..base });
    let (mut worst, mut peak) = (0.0f32, 0.0f32);
    for (p, q) in a.iter().zip(&b) {
        for k in 0..3 {
            worst = worst.max((p[k] - q[k]).abs());
            peak = peak.max(q[k]);
        }
    }
    eprintln!("constant env vs ambient: worst difference {worst:.2e} of peak {peak:.3}");
    let sky_pixels = a.iter().filter(|p| p[3] < 0.5).count();
    assert!(peak > 0.1 && sky_pixels > 100 && sky_pixels < a.len() / 2, "{sky_pixels} sky pixels");
    assert!(worst < 1e-4 * peak, "constant environment and ambient differ by {worst}");
}

#[test]
fn a_closed_cave_stays_dark_under_a_sky_and_an_opening_lets_it_in() {
    use grotto_runtime::renderer::Quality;
    let sky = {
        let mut sh = [[0.0f32; 3]; 9];
        sh[0] = [1.0 / 0.282_094_8; 3];
        sh
    };
    // Sky visibility of the shell's inner surface: from any point inside a sphere, the
    // cosine-weighted share of the hemisphere that a patch of the sphere fills is that patch's
    // share of the sphere's area, so an opening of cap cosine c is seen by (1 - c) / 2 of every
    // inner leaf's hemisphere.
    let inside = |depth: u32, radius: f32, cap_cos: f32, q: Quality| {
        let mut scene = testscenes::open_sphere(depth, radius, 0.6, 0.0, cap_cos);
        scene.environment_sh = Some(sky);
        let centre = Vec3::splat((1u32 << depth) as f32 * 0.5 * scene.leaf_size_m);
        let inner: Vec<bool> = scene
            .leaves
            .iter()
            .map(|l| Vec3::from_slice(&l.center_m[..3]).distance(centre) < (radius + 1.0) * scene.leaf_size_m)
            .collect();
        let mut r = Renderer::new(gpu(), &scene, Settings { bounces: 2, ..Settings::preset(q) }).unwrap();
        r.settle(|_, _| {}).unwrap();
        let light = r.read_leaf_light().unwrap();
        let v: Vec<f32> = light.iter().zip(&inner).filter(|(_, i)| **i).map(|(l, _)| l.env[3]).collect();
        let out_max = light.iter().map(|l| l.out[1]).fold(0.0f32, f32::max);
        (v.iter().sum::<f32>() / v.len() as f32, out_max)
    };
    let (closed_v, closed_out) = inside(6, 24.0, f32::INFINITY, Quality::Balanced);
    let (v8, _) = inside(6, 24.0, 0.8, Quality::Balanced);
    let (v5, _) = inside(6, 24.0, 0.5, Quality::Balanced);
    eprintln!(
        "sky on a shell (balanced): closed: mean sky visibility {closed_v:.1e}, brightest leaf \
         {closed_out:.1e}; opening of cap cosine 0.8: {v8:.4} (exact 0.1); 0.5: {v5:.4} (exact 0.25)"
    );
    assert!(closed_v == 0.0 && closed_out == 0.0, "light leaked through the closed shell");
    // Cones wider than the opening see its rim as partly opaque, so VCT underestimates it; the
    // bounds say it lets the sky in, in proportion to its size, and never more than it should.
    assert!(v5 > 0.35 * 0.25 && v5 < 1.05 * 0.25, "cap 0.5: {v5}");
    assert!(v8 > 0.2 * 0.1 && v8 < v5, "cap 0.8: {v8}");
}
