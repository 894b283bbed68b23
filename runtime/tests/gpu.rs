//! GPU passes on the shared test device (software adapter first): mip and cone gather against the
//! CPU reference, the furnace, multiple bounces, and the effect plan's skipped passes.

use std::sync::OnceLock;

use glam::Vec3;
use grotto_fixtures::testscenes;
use grotto_runtime::gpu::types::LeafLightGpu;
use grotto_runtime::gpu::{Gpu, GpuOptions};
use grotto_runtime::light::plan::Pass;
use grotto_runtime::passes::cpu_ref::CpuScene;
use grotto_runtime::render::Renderer;
use grotto_runtime::scene::data::SceneData;
use grotto_runtime::settings::Settings;

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
        let (worst, checked) = cpu.worst_gather_error(&r.params(), &got, 7);
        eprintln!("gather ({cones} cones): worst error {worst:.2e} over {checked} leaves");
        assert!(checked > 100);
        // Stated tolerance 1e-3: f32 vs f64 marching, pow/log2 approximations on the GPU.
        assert!(worst < 1e-3, "gather differs from the CPU reference by {worst}");
    }
}

/// One bounce over the dogleg with its leaves on their surfels (as packages have them) and random
/// light seeded `seed`, with 8 cones and with `knob` on: its gather agrees with the CPU
/// reference's leaf by leaf, and the knob reaches the march (a good share of leaves gather
/// differently than with it off). `what` names the knob in the log and the messages.
fn assert_knob_gather_matches_cpu(what: &str, scene: &SceneData, seed: u32, knob: fn(&mut Settings)) {
    let light = random_light(scene.leaves.len(), seed);
    let gather = |on: bool| {
        let mut settings = Settings { cones: 8, ..Default::default() };
        if on {
            knob(&mut settings);
        }
        let mut r = Renderer::new(gpu(), scene, settings).unwrap();
        r.write_leaf_light(&light).unwrap();
        r.run_bounce().unwrap();
        let got = r.read_leaf_light().unwrap();
        let (worst, checked) = CpuScene::mip(scene, &light).worst_gather_error(&r.params(), &got, 7);
        (got, worst, checked)
    };
    let (off, _, _) = gather(false);
    let (on, worst, checked) = gather(true);
    let changed = off.iter().zip(&on).filter(|(a, b)| (a.gather[0] - b.gather[0]).abs() > 1e-3).count();
    eprintln!("gather with {what}: worst error {worst:.2e} over {checked} leaves, {changed} leaves moved");
    assert!(checked > 100);
    assert!(worst < 1e-3, "gather with {what} differs from the CPU reference by {worst}");
    assert!(changed * 10 > off.len(), "only {changed} of {} leaves changed", off.len());
}

#[test]
fn cone_gather_with_cone_planes_matches_cpu_reference() {
    // The leaves on their surfels so the planes cut the cubes where the surface is; the march
    // still has to agree with the CPU's, leaf by leaf.
    assert_knob_gather_matches_cpu("cone planes", &dogleg_on_surfels(), 13, |s| s.cone_planes = true);
}

fn dogleg_on_surfels() -> SceneData {
    let mut scene = testscenes::dogleg();
    testscenes::leaves_on_surfels(&mut scene);
    scene
}

#[test]
fn cone_gather_with_cone_rays_matches_cpu_reference() {
    // The rays' ends are decisions (which cell, which side of a plane) that f32 and f64 could
    // take differently where a ray passes within rounding of a cell's face or a plane; they must
    // agree as the cones do.
    assert_knob_gather_matches_cpu("cone rays", &dogleg_on_surfels(), 17, |s| s.cone_rays = true);
}

#[test]
fn cone_rays_cross_empty_space_where_the_cpu_walks_every_cell() {
    // The GPU's rays cross boxes proved empty (a missing node cut to rock-free space) in one step;
    // the CPU's walk every cell. In an open shell most rays cross its hollow, and those through the
    // opening leave the scene: both must end where the CPU's do.
    let scene = testscenes::open_sphere(5, 11.0, 0.6, 0.0, 0.8);
    assert_knob_gather_matches_cpu("cone rays (open shell)", &scene, 19, |s| s.cone_rays = true);
}

#[test]
fn the_cone_march_is_step_invariant_where_every_surface_sends_the_same_light() {
    // Inside closed rock every cone ends on a surface, so with every leaf sending 1 the gather is 1
    // whatever the step (the rim of each cone's hemisphere leaks a little into the rock: 0.999).
    // On lavapipe 16 cones at step 0.1 gathered 0.944 when one invocation traced them
    // all (its loop budget ran out; passes/propagate.rs); the CPU reference never lost it.
    let scene = testscenes::dogleg();
    let ones = vec![LeafLightGpu { out: [1.0, 1.0, 1.0, 0.0], ..Default::default() }; scene.leaves.len()];
    for step_scale in [1.0f32, 0.5, 0.35, 0.2, 0.1, 0.06] {
        let settings = Settings { cones: 16, cone_aperture_scale: 0.7, step_scale, ..Default::default() };
        let mut r = Renderer::new(gpu(), &scene, settings).unwrap();
        r.write_leaf_light(&ones).unwrap();
        r.run_bounce().unwrap();
        let got = r.read_leaf_light().unwrap();
        let mean = got.iter().map(|l| f64::from(l.gather[0])).sum::<f64>() / got.len() as f64;
        let (worst, checked) = CpuScene::mip(&scene, &ones).worst_gather_error(&r.params(), &got, 7);
        eprintln!(
            "step {step_scale}: mean gather {mean:.4}, worst error against the CPU {worst:.1e} ({checked} leaves)"
        );
        assert!((mean - 1.0).abs() < 5e-3, "step {step_scale}: mean gather {mean}, expected 1 within 0.5%");
        assert!(worst < 1e-3, "step {step_scale}: gather differs from the CPU reference by {worst}");
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
    let shown: Vec<f32> = light.iter().zip(&scene.leaves).map(|(l, leaf)| l.shown(leaf)[0]).collect();
    let finite = light.iter().all(|l| l.out.iter().chain(&l.tail).all(|v| v.is_finite()));
    let (mut lo, mut hi) = (f32::MAX, f32::MIN);
    for v in shown {
        lo = lo.min(v);
        hi = hi.max(v);
    }
    (lo, hi, finite)
}

#[test]
fn the_bounce_tail_brings_the_furnace_to_its_limit_in_a_few_bounces() {
    // Albedo 0.8, emission 1: exact radiance 5. Four bounces alone reach
    // 1 + 0.8 + ... + 0.8^4 = 3.36; with the tail, the second bounce's ratio (0.8) gives the rest
    // of the series, and the light counts as converged once the estimate stops moving.
    let scene = testscenes::furnace_sphere(5, 11.0, 0.8, 1.0);
    let run = |bounce_tail: bool| {
        let settings =
            Settings { bounces: 4, bounce_tail, convergence_tolerance: 1e-3, ..Default::default() };
        let mut r = Renderer::new(gpu(), &scene, settings).unwrap();
        r.settle(|_, _| {}).unwrap();
        let light = r.read_leaf_light().unwrap();
        let shown: Vec<f32> = light.iter().zip(&scene.leaves).map(|(l, leaf)| l.shown(leaf)[0]).collect();
        let mean = shown.iter().sum::<f32>() / shown.len() as f32;
        let worst = shown.iter().map(|v| (v - 5.0).abs() / 5.0).fold(0.0f32, f32::max);
        (mean, worst, r.stats().bounces_done, r.light_progress().converged)
    };
    let (plain, _, plain_bounces, _) = run(false);
    let (tailed, worst, bounces, converged) = run(true);
    eprintln!(
        "furnace 0.8 after at most 4 bounces: {plain:.4} without the tail ({plain_bounces} bounces), \
         {tailed:.4} with it ({bounces} bounces, converged {converged}, worst leaf {:.2}% off), exact 5",
        worst * 100.0
    );
    assert!((plain - 3.36).abs() < 0.05, "four plain bounces should stop at 3.36, got {plain}");
    assert!(worst < 0.01, "with the tail every leaf should be within 1% of 5");
    assert!(converged && bounces <= 3, "the estimate should settle after 3 bounces, took {bounces}");
}

#[test]
fn the_bounce_tail_matches_its_cpu_statement() {
    // Bounces from random light: the third's residual is the change of the gather, and its tail
    // what LeafLightGpu::tile_ratio and tail_of (the CPU statement of tail.wgsl) say from the
    // sums of the residuals of the tile's settling leaves. The dogleg has several tiles, so each
    // must use its own.
    let scene = testscenes::dogleg();
    let settings = Settings { cones: 4, ..Default::default() };
    let mut r = Renderer::new(gpu(), &scene, settings).unwrap();
    let max_albedo = (0..3)
        .map(|k| scene.leaves.iter().map(|l| l.albedo_opacity[k]).fold(0.0f32, f32::max).min(0.95))
        .collect::<Vec<_>>();
    let ratio_max = r.params().tail_ratio_max;
    assert_eq!(&ratio_max[..3], &max_albedo[..], "the trusted ratio is the largest albedo per channel");
    r.write_leaf_light(&random_light(scene.leaves.len(), 5)).unwrap();
    r.run_bounce().unwrap();
    let zeroth = r.read_leaf_light().unwrap();
    // The first bounce has no ratio yet: no tail.
    assert!(zeroth.iter().all(|l| l.tail[..3] == [0.0; 3]));
    // Light written at random is not one a bounce makes; from the second bounce on it is.
    r.run_bounce().unwrap();
    let first = r.read_leaf_light().unwrap();
    r.run_bounce().unwrap();
    let second = r.read_leaf_light().unwrap();
    let (mut checked, mut tailed, mut worst) = (0usize, 0usize, 0.0f32);
    let mut ratios = Vec::new();
    for tile in &scene.tiles {
        let range = tile.leaf_offset as usize..(tile.leaf_offset + tile.leaf_count) as usize;
        let (mut sum, mut last) = ([0.0f32; 3], [0.0f32; 3]);
        for (a, b) in first[range.clone()].iter().zip(&second[range.clone()]) {
            for k in 0..3 {
                let residual = b.gather[k] - a.gather[k];
                if LeafLightGpu::settling(residual, a.residual[k]) {
                    sum[k] += residual;
                    last[k] += a.residual[k];
                }
            }
        }
        let ratio = LeafLightGpu::tile_ratio(sum, last, max_albedo[..].try_into().unwrap());
        ratios.push(ratio[0]);
        for (a, b) in first[range.clone()].iter().zip(&second[range]) {
            let residual: [f32; 3] = std::array::from_fn(|k| b.gather[k] - a.gather[k]);
            let want = LeafLightGpu::tail_of(residual, ratio);
            for k in 0..3 {
                let scale = residual[k].abs().max(1e-3);
                worst = worst.max((b.residual[k] - residual[k]).abs() / scale);
                // The sums run in another order on the GPU: the ratio agrees to rounding.
                worst = worst.max((b.tail[k] - want[k]).abs() / (want[k].abs().max(1e-3)) * 0.1);
            }
            checked += 1;
            tailed += usize::from(want.iter().any(|t| t.abs() > 1e-4));
        }
    }
    eprintln!(
        "bounce tail: {tailed} of {checked} leaves with a tail, tile ratios (red) {ratios:.3?}, worst error {worst:.2e}"
    );
    assert!(tailed * 2 > checked, "most leaves should get a tail after three bounces");
    assert!(ratios.iter().any(|r| (r - ratios[0]).abs() > 1e-3), "every tile got the same ratio: {ratios:?}");
    assert!(worst < 1e-4, "the tail differs from its CPU statement by {worst}");
}

/// The furnace with `settings` at `albedo` ends within 2% of its exact radiance 1 / (1 - albedo)
/// on every leaf, and finite; `what` names the run in the log.
fn assert_furnace_exact(what: &str, albedo: f32, settings: Settings) {
    let exact = 1.0 / (1.0 - albedo);
    let (lo, hi, finite) = furnace_with(albedo, settings);
    eprintln!("furnace albedo {albedo}, {what}: radiance {lo:.4} .. {hi:.4}, exact {exact:.4}");
    assert!(finite);
    assert!((lo - exact).abs() / exact < 0.02 && (hi - exact).abs() / exact < 0.02);
}

#[test]
fn furnace_converges_to_e_over_one_minus_albedo() {
    // Budgets, not counts: the light stops once a bounce changes it by under 1e-5 (with the
    // bounce tail, a few bounces; at 1e-7, f32 rounding kept both runs going to their budgets,
    // 260 bounces and 187 s of CI's time, to end at the same radiance).
    for (albedo, bounces) in [(0.5f32, 60u32), (0.9, 200)] {
        let settings = Settings { bounces, convergence_tolerance: 1e-5, ..Default::default() };
        assert_furnace_exact("f32 radiance", albedo, settings);
    }
}

#[test]
fn furnace_with_f16_radiance_converges_within_two_percent() {
    let settings =
        Settings { bounces: 200, convergence_tolerance: 1e-7, radiance_f16: true, ..Default::default() };
    assert_furnace_exact("f16 radiance", 0.9, settings);
}

#[test]
fn furnace_with_cone_planes_converges_to_e_over_one_minus_albedo() {
    // Cones that stop at the surface instead of its cube still end on it: the furnace stays exact.
    let settings =
        Settings { bounces: 60, convergence_tolerance: 1e-7, cone_planes: true, ..Default::default() };
    assert_furnace_exact("cone planes", 0.5, settings);
}

#[test]
fn furnace_with_cone_rays_converges_to_e_over_one_minus_albedo() {
    // Inside a closed shell every ray ends on a surface sending the same light: still exact.
    let settings =
        Settings { bounces: 60, convergence_tolerance: 1e-7, cone_rays: true, ..Default::default() };
    assert_furnace_exact("cone rays", 0.5, settings);
}

#[test]
fn furnace_at_albedo_099_stays_bounded() {
    // All 200 bounces run (f32 rounding never meets a 1e-7 change): light bounced again and
    // again at albedo 0.99, with the bounce tail's estimate on, must neither drift nor blow up.
    let (lo, hi, finite) = furnace(0.99, 200);
    eprintln!("furnace albedo 0.99 after 200 bounces: {lo:.3} .. {hi:.3} (limit 100)");
    assert!(finite);
    // Between what the bounces alone sum to, (1 - 0.99^201) / 0.01 = 86.7 (measured 89.28: the
    // tail adds its guarded share), and the limit 100.
    let bounces_alone = (1.0 - 0.99f32.powi(201)) / 0.01;
    assert!(hi <= 100.0 * 1.001 && lo > bounces_alone * 0.995, "{lo} .. {hi}: not in {bounces_alone} .. 100");
}

/// The dogleg as a furnace: every surface leaf (one with a surfel) emits 1 with albedo 0.8 and no
/// lamp, so after k bounces the exact radiance on the surface is sum 0.8^j, j <= k, in the room,
/// the corridors and the chamber alike. Any other leaf stays dark: hand-built scenes
/// that had the rock behind their walls as dark opaque leaves lost about 11% of every
/// gather (coarse voxels beside a wall mixed it with dark rock).
#[test]
fn the_dogleg_furnace_keeps_every_bounce_in_every_region() {
    let mut scene = testscenes::dogleg();
    scene.lights.clear();
    let leaf_m = scene.leaf_size_m;
    // A carved scene's surfel lies on the face its leaf's cell shares with the air along its normal.
    let surface: std::collections::HashSet<glam::IVec3> = scene
        .surfels
        .iter()
        .map(|s| {
            let p = Vec3::from_slice(&s.position_radius[..3]);
            let n = Vec3::from_slice(&s.normal_spread[..3]);
            ((p - n * 0.5 * leaf_m) / leaf_m).floor().as_ivec3()
        })
        .collect();
    for l in &mut scene.leaves {
        let e = if surface.contains(&l.cell(leaf_m)) { 1.0 } else { 0.0 };
        l.emission = [e, e, e, 0.0];
    }
    let bounces = 4u32;
    let exact: f32 = (0..=bounces).map(|j| 0.8f32.powi(j as i32)).sum();
    let settings = Settings { bounces, bounce_tail: false, convergence_tolerance: 0.0, ..Default::default() };
    let mut r = Renderer::new(gpu(), &scene, settings).unwrap();
    r.settle(|_, _| {}).unwrap();
    let light = r.read_leaf_light().unwrap();
    let mut sums = vec![(0.0f64, 0usize); testscenes::DOGLEG_REGIONS.len()];
    for (l, leaf) in light.iter().zip(&scene.leaves) {
        let c = leaf.cell(leaf_m);
        if let Some(k) = testscenes::dogleg_region(c).filter(|_| surface.contains(&c)) {
            sums[k].0 += f64::from(l.out[1]);
            sums[k].1 += 1;
        }
    }
    for ((name, _, _), (sum, n)) in testscenes::DOGLEG_REGIONS.iter().zip(sums) {
        let ratio = sum / n as f64 / f64::from(exact);
        eprintln!("{name}: {n} leaves, mean radiance / exact {ratio:.4}");
        assert!(
            (0.99..=1.01).contains(&ratio),
            "{name}: {ratio:.4} of the exact radiance after {bounces} bounces"
        );
    }
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

#[test]
fn a_bounce_in_slices_ends_where_the_whole_bounce_ends_to_the_bit() {
    // The viewer splits a bounce over frames (Renderer::update_light_slice); every leaf gathers
    // from the pyramid the bounce's mip made, so the slices give the same light as one dispatch.
    let scene = testscenes::dogleg();
    let settings = Settings { bounces: 3, cones: 9, convergence_tolerance: 0.0, ..Default::default() };
    let mut whole = Renderer::new(gpu(), &scene, settings.clone()).unwrap();
    whole.settle(|_, _| {}).unwrap();
    let mut sliced = Renderer::new(gpu(), &scene, settings).unwrap();
    let leaves = scene.leaves.len() as u32;
    let slice = leaves / 5 + 7;
    let mut calls = 0;
    while !sliced.light_progress().converged {
        let before = sliced.stats().bounces_done;
        let ran = sliced.update_light_slice(slice).unwrap();
        assert!(ran <= slice, "a slice runs at most its leaves");
        calls += 1;
        // Mid-bounce the plan keeps the pyramid and says where the bounce stands.
        if sliced.stats().bounces_done == before && !sliced.light_progress().converged {
            let p = sliced.plan(None);
            assert!(!p.runs(Pass::Mip) && p.explain().contains("continued"), "{}", p.explain());
        }
        assert!(calls < 100, "the sliced bounces end");
    }
    assert_eq!(sliced.stats().bounces_done, 3);
    assert!(calls >= 3 * 5, "each bounce took several slices ({calls} calls)");
    let (a, b) = (whole.read_leaf_light().unwrap(), sliced.read_leaf_light().unwrap());
    let first_diff = a.iter().zip(&b).position(|(p, q)| p.out != q.out);
    assert_eq!(first_diff, None, "leaf light differs");
    assert_eq!(whole.stats().last_change, sliced.stats().last_change);
    // A held renderer runs no bounce, and says why.
    let mut held = Renderer::new(gpu(), &scene, Settings { bounces: 3, ..Default::default() }).unwrap();
    held.hold_light(Some("the camera is moving"));
    let p = held.update_light().unwrap();
    assert!(p.runs(Pass::Inject) && !p.runs(Pass::Propagate), "{}", p.explain());
    assert!(p.explain().contains("the camera is moving: bounce 1 waits"));
    assert_eq!(held.stats().bounces_done, 0);
}

fn max_abs_diff(a: &[[f32; 4]], b: &[[f32; 4]]) -> f32 {
    a.iter().zip(b).flat_map(|(p, q)| (0..3).map(move |k| (p[k] - q[k]).abs())).fold(0.0, f32::max)
}

#[test]
fn skipped_passes_are_not_dispatched_and_change_nothing() {
    use grotto_runtime::view::camera::Camera;
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
    // A new exposure (auto exposure sets it after settling) changes the tonemapped frame only.
    r.set_exposure(0.4);
    let (brighter, _) = r.render(&cam, 64, 48).unwrap();
    r.set_exposure(settings.exposure);
    assert_eq!(brighter.hdr, a.hdr);
    let mean = |f: &grotto_runtime::render::Frame| {
        f.ldr.iter().map(|p| f64::from(p[0])).sum::<f64>() / f.ldr.len() as f64
    };
    assert!(
        mean(&brighter) > mean(&a) + 10.0,
        "exposure 0.4 against 0.1: {} vs {}",
        mean(&brighter),
        mean(&a)
    );
    let d = &r.stats().dispatches;
    assert_eq!(d.get(&Pass::Shadow), None);
    assert_eq!(d.get(&Pass::Inject), None);
    assert_eq!(d.get(&Pass::Mip).copied(), Some(u64::from(bounces)));
    assert_eq!(d.get(&Pass::Propagate).copied(), Some(u64::from(bounces)));
    assert_eq!(d.get(&Pass::Gbuffer).copied(), Some(1));
    assert_eq!(d.get(&Pass::Shade).copied(), Some(3));

    // Forcing the skipped passes: shadow, inject, gbuffer and one more bounce.
    r.set_forced(&[Pass::Shadow, Pass::Inject, Pass::Gbuffer, Pass::Mip, Pass::Env, Pass::Propagate]);
    let (c, plan) = r.render(&cam, 64, 48).unwrap();
    // All but the resolve, which only a still frame's samples have to add (draw_still).
    assert!(plan.steps.iter().filter(|s| s.pass != Pass::Resolve).all(|s| s.run), "{}", plan.explain());
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
fn a_frame_exposed_again_is_the_frame_drawn_at_that_exposure() {
    use grotto_runtime::settings::ViewMode;
    use grotto_runtime::view::camera::Camera;
    let scene = testscenes::furnace_sphere(4, 5.0, 0.5, 1.0);
    let cam =
        Camera { eye_m: Vec3::splat(0.8), look_at_m: Vec3::new(1.2, 0.9, 0.7), up: Vec3::Z, fov_y_deg: 70.0 };
    let mut r = Renderer::new(gpu(), &scene, Settings { exposure: 0.1, ..Default::default() }).unwrap();
    r.settle(|_, _| {}).unwrap();
    let (dim, _) = r.render(&cam, 64, 48).unwrap();
    let shades = r.stats().dispatches.get(&Pass::Shade).copied();
    r.set_exposure(0.4);
    let exposed = r.expose().unwrap();
    assert_eq!(r.stats().dispatches.get(&Pass::Shade).copied(), shades, "exposing must not shade again");
    let (drawn, _) = r.render(&cam, 64, 48).unwrap();
    assert_eq!(exposed.hdr, drawn.hdr);
    assert_eq!(exposed.ldr, drawn.ldr, "the tone map again must give the pixels a frame drawn at 0.4 has");
    assert_ne!(exposed.ldr, dim.ldr);
    // A view without light does not take the exposure: exposing it leaves its pixels, also once
    // the lit view is chosen again but not yet drawn (the frame is still the normals').
    r.set_view(ViewMode::Normals);
    let (normals, _) = r.render(&cam, 64, 48).unwrap();
    r.set_exposure(1.6);
    assert_eq!(r.expose().unwrap().ldr, normals.ldr);
    r.set_view(ViewMode::Lit);
    assert_eq!(r.expose().unwrap().ldr, normals.ldr);
}

#[test]
fn lights_and_shadows_run_once_for_static_lights() {
    let scene = testscenes::dogleg();
    let mut r = Renderer::new(gpu(), &scene, Settings { bounces: 2, ..Default::default() }).unwrap();
    let cam = grotto_runtime::view::camera::Camera::from_scene(&scene.cameras[0]);
    let (first, plan) = r.render(&cam, 64, 48).unwrap();
    assert!(plan.runs(Pass::Shadow) && plan.runs(Pass::Inject));
    let (_, plan) = r.render(&cam, 64, 48).unwrap();
    assert!(!plan.runs(Pass::Shadow) && !plan.runs(Pass::Inject) && plan.runs(Pass::Propagate));
    let (third, plan) = r.render(&cam, 64, 48).unwrap();
    assert!(!plan.runs(Pass::Propagate), "bounce budget of 2 spent: {}", plan.explain());
    assert_eq!(r.stats().dispatches.get(&Pass::Shadow).copied(), Some(1));
    // Shadowed direct light: room A is lit, the hidden chamber is not; bounces add light.
    let sum = |f: &grotto_runtime::render::Frame| f.hdr.iter().map(|p| p[1] as f64).sum::<f64>();
    assert!(sum(&third) > sum(&first));
    r.invalidate_lights();
    let (_, plan) = r.render(&cam, 64, 48).unwrap();
    assert!(plan.runs(Pass::Shadow) && plan.runs(Pass::Inject));
}

#[test]
fn spot_light_lights_only_its_cone() {
    use grotto_runtime::scene::data::{SceneLight, Spot};
    let mut scene = testscenes::dogleg();
    let leaf = scene.leaf_size_m;
    // Room A spans cells x 2..10, y 1..9, z 2..10; aim at its -x wall (cells x = 1).
    scene.lights = vec![SceneLight {
        name: "spot".into(),
        position_m: Vec3::new(8.0, 5.0, 6.0) * leaf,
        intensity_w_sr: Vec3::splat(10.0),
        spot: Some(Spot { direction: Vec3::NEG_X, inner_angle_rad: 0.2, outer_angle_rad: 0.3 }),
        profile: None,
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
    use grotto_runtime::scene::data::VoxelLeaf;
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
    assert!(plan.runs(Pass::Env), "{}", plan.explain());
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
    use grotto_runtime::scene::data::SceneCamera;
    use grotto_runtime::view::camera::Camera;
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
    use grotto_runtime::settings::Quality;
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

/// Runs `kernel` (WGSL using shaders/brdf.wgsl, reading and writing `io` at group 0 binding 0)
/// once per element of `io` and returns `io` afterwards.
fn run_brdf_kernel(kernel: &str, io: &[[f32; 4]]) -> Vec<[f32; 4]> {
    let g = gpu();
    let src = grotto_runtime::shaders::compose(&format!(
        "#import brdf\n@group(0) @binding(0) var<storage, read_write> io: array<vec4<f32>>;\n{kernel}"
    ))
    .unwrap();
    let module = g.device.create_shader_module(wgpu::ShaderModuleDescriptor {
        label: Some("brdf probe"),
        source: wgpu::ShaderSource::Wgsl(src.into()),
    });
    let pipeline = g.device.create_compute_pipeline(&wgpu::ComputePipelineDescriptor {
        label: Some("brdf probe"),
        layout: None,
        module: &module,
        entry_point: Some("probe"),
        compilation_options: Default::default(),
        cache: None,
    });
    let buf = g
        .buffer_init(
            "brdf io",
            bytemuck::cast_slice(io),
            wgpu::BufferUsages::STORAGE | wgpu::BufferUsages::COPY_SRC,
        )
        .expect("a few bytes fit any adapter");
    let group = g.device.create_bind_group(&wgpu::BindGroupDescriptor {
        label: Some("brdf io"),
        layout: &pipeline.get_bind_group_layout(0),
        entries: &[wgpu::BindGroupEntry { binding: 0, resource: buf.as_entire_binding() }],
    });
    let mut enc = g.device.create_command_encoder(&Default::default());
    {
        let mut pass = enc.begin_compute_pass(&Default::default());
        pass.set_pipeline(&pipeline);
        pass.set_bind_group(0, &group, &[]);
        pass.dispatch_workgroups((io.len() as u32).div_ceil(64), 1, 1);
    }
    g.queue.submit([enc.finish()]);
    let bytes = g.read_buffer(&buf, (io.len() * 16) as u64).unwrap();
    bytemuck::pod_collect_to_vec(&bytes[..io.len() * 16])
}

#[test]
fn fresnel_and_distribution_terms_match_their_closed_forms() {
    // x: cos of incidence, y: index of refraction, z: n.h, w: GGX alpha. Out: x = F, y = D,
    // z = the hemisphere integral of D (n.h) for that alpha (must be 1).
    let kernel = "
@compute @workgroup_size(64)
fn probe(@builtin(global_invocation_id) gid: vec3<u32>) {
    let i = gid.x;
    if i >= arrayLength(&io) {
        return;
    }
    let q = io[i];
    // Integral over mu = n.h of D(mu) mu 2 pi dmu, midpoint rule.
    let steps = 20000u;
    var sum = 0.0;
    for (var k = 0u; k < steps; k++) {
        let mu = (f32(k) + 0.5) / f32(steps);
        sum += ggx_d(mu, q.w) * mu;
    }
    io[i] = vec4<f32>(fresnel_dielectric(q.x, q.y), ggx_d(q.z, q.w), sum * 2.0 * PI / f32(steps), 0.0);
}";
    // Full Fresnel for unpolarised light, in f64 (Cook & Torrance's form).
    let fresnel = |c: f64, n: f64| {
        let g = (n * n + c * c - 1.0).sqrt();
        let a = (g - c) / (g + c);
        let b = (c * (g + c) - 1.0) / (c * (g - c) + 1.0);
        0.5 * a * a * (1.0 + b * b)
    };
    let mut io = Vec::new();
    for &n in &[1.33f32, 1.5, 2.4] {
        for &c in &[1.0f32, 0.0, 0.5, 0.1, 0.9] {
            for &alpha in &[0.1f32, 0.3, 0.7, 1.0] {
                for &nh in &[1.0f32, 0.0, 0.8] {
                    io.push([c, n, nh, alpha]);
                }
            }
        }
    }
    let out = run_brdf_kernel(kernel, &io);
    let (mut worst_f, mut worst_d, mut worst_int) = (0.0f64, 0.0f64, 0.0f64);
    for (q, o) in io.iter().zip(&out) {
        let (c, n, nh, alpha) = (f64::from(q[0]), f64::from(q[1]), f64::from(q[2]), f64::from(q[3]));
        // Closed forms at normal and grazing incidence; the full formula elsewhere.
        let f_want = if c == 1.0 {
            ((n - 1.0) / (n + 1.0)).powi(2)
        } else if c == 0.0 {
            1.0
        } else {
            fresnel(c, n)
        };
        let a2 = alpha * alpha;
        let d_want = if nh == 1.0 {
            1.0 / (std::f64::consts::PI * a2)
        } else if nh == 0.0 {
            a2 / std::f64::consts::PI
        } else {
            let d = nh * nh * (a2 - 1.0) + 1.0;
            a2 / (std::f64::consts::PI * d * d)
        };
        worst_f = worst_f.max((f64::from(o[0]) - f_want).abs() / f_want);
        worst_d = worst_d.max((f64::from(o[1]) - d_want).abs() / d_want);
        worst_int = worst_int.max((f64::from(o[2]) - 1.0).abs());
    }
    eprintln!("Fresnel {worst_f:.2e}, GGX D {worst_d:.2e} relative; |integral of D cos - 1| {worst_int:.2e}");
    assert!(worst_f < 1e-5, "Fresnel differs from its closed form by {worst_f}");
    assert!(worst_d < 1e-5, "D differs from its closed form by {worst_d}");
    assert!(worst_int < 2e-3, "D is not normalised: {worst_int}");
}

/// Mean of channel 1 of `field` over the leaves in `set`.
fn mean_of(light: &[LeafLightGpu], set: &[usize], field: fn(&LeafLightGpu) -> [f32; 4]) -> f32 {
    set.iter().map(|&i| field(&light[i])[1]).sum::<f32>() / set.len() as f32
}

#[test]
fn lights_beyond_the_budget_are_shadowed_by_svo_cones_not_lit_through_rock() {
    use grotto_runtime::settings::ShadowFallback;
    // The dogleg: one lamp in a room, a chamber behind three right-angle corridors in rock.
    let scene = testscenes::dogleg();
    let select = |want: &dyn Fn(glam::IVec3) -> bool| -> Vec<usize> {
        scene
            .leaves
            .iter()
            .enumerate()
            .filter(|(_, l)| {
                let c = (Vec3::from_slice(&l.center_m[..3]) / scene.leaf_size_m).floor().as_ivec3();
                want(c) && l.normal_mean[..3].iter().any(|&v| v != 0.0)
            })
            .map(|(i, _)| i)
            .collect()
    };
    let chamber = select(&|c| testscenes::dogleg_chamber(c));
    let room = select(&|c| c.y < 10 && c.x < 11);
    let direct = |budget: u32, fallback: ShadowFallback| {
        let settings =
            Settings { bounces: 0, shadowed_lights: budget, shadow_fallback: fallback, ..Default::default() };
        let mut r = Renderer::new(gpu(), &scene, settings).unwrap();
        let plan = r.update_light().unwrap();
        assert_eq!(plan.runs(Pass::Shadow), budget > 0, "{}", plan.explain());
        let light = r.read_leaf_light().unwrap();
        (
            mean_of(&light, &chamber, |l| l.direct),
            mean_of(&light, &room, |l| l.direct),
            mean_of(&light, &room, |l| l.far),
        )
    };
    let map = direct(1, ShadowFallback::Cone);
    let cone = direct(0, ShadowFallback::Cone);
    let none = direct(0, ShadowFallback::None);
    eprintln!("chamber / room direct: shadow map {map:?}, SVO cone {cone:?}, unshadowed {none:?}");
    assert_eq!(map.2, 0.0, "a light with a shadow map leaves nothing to the per-leaf share");
    assert!(cone.2 > 0.0 && none.2 > 0.0, "lights beyond the budget are in the per-leaf share");
    assert!(none.0 > 1e-3 * none.1, "unshadowed, the lamp shines through the rock into the chamber");
    assert!(cone.0 <= 1e-6 * cone.1, "cone shadows keep the chamber dark: {cone:?}");
    assert!(map.0 <= 1e-6 * map.1);
    // In the lit room cone shadows and the shadow map agree to within the cone's blur.
    assert!((cone.1 - map.1).abs() < 0.2 * map.1, "room: cone {} vs map {}", cone.1, map.1);
}

#[test]
fn a_scene_with_256_lights_renders_and_culling_drops_only_light_under_the_cutoff() {
    use grotto_runtime::scene::data::SceneLight;
    use grotto_runtime::settings::ShadowFallback;
    use grotto_runtime::view::camera::Camera;
    // The colour box with 256 lamps of random power on a grid inside it.
    let mut scene = testscenes::colour_box();
    let (lo, hi) = scene.bounds_leaf();
    let (lo, hi) = (lo * scene.leaf_size_m, hi * scene.leaf_size_m);
    let weights = random_light(256, 11);
    scene.lights = weights
        .iter()
        .enumerate()
        .map(|(i, w)| {
            let f = Vec3::new((i % 8) as f32 + 0.5, ((i / 8) % 8) as f32 + 0.5, (i / 64) as f32 + 0.5)
                / Vec3::new(8.0, 8.0, 4.0);
            SceneLight {
                name: format!("lamp-{i}"),
                position_m: lo + (hi - lo) * (0.3 + 0.4 * f),
                intensity_w_sr: Vec3::splat(0.05 + w.out[1] * 0.5),
                spot: None,
                profile: None,
            }
        })
        .collect();
    // Every light per leaf and unshadowed, so the injected light is a plain sum to compare.
    let per_leaf = |cutoff: f32| {
        let settings = Settings {
            bounces: 0,
            shadowed_lights: 0,
            shadow_fallback: ShadowFallback::None,
            light_cutoff_w_m2: cutoff,
            ..Default::default()
        };
        let mut r = Renderer::new(gpu(), &scene, settings).unwrap();
        r.update_light().unwrap();
        (r.read_leaf_light().unwrap(), r.lights_in_range())
    };
    let (all, in_range_all) = per_leaf(0.0);
    assert_eq!(in_range_all, (256.0, 256), "no cutoff: every light everywhere");
    // CPU sum of the per-leaf irradiance / pi (the NDF-weighted cosine as in common.wgsl).
    let mut worst = 0.0f32;
    for (leaf, state) in scene.leaves.iter().zip(&all) {
        let p = Vec3::from_slice(&leaf.center_m[..3]);
        let mean = Vec3::from_slice(&leaf.normal_mean[..3]);
        let r = mean.length().min(1.0);
        let n = if r < 1e-4 { Vec3::Z } else { mean / mean.length() };
        let mut e = 0.0f32;
        for l in &scene.lights {
            let to = l.position_m - p;
            let d = to.length().max(1e-4);
            let c = n.dot(to / d);
            let cos = r * c.max(0.0) + (1.0 - r) * (1.0 + c).max(0.0) * 0.25;
            e += l.intensity_w_sr.y * cos / (d * d);
        }
        let want = e / std::f32::consts::PI;
        worst = worst.max((state.far[1] - want).abs() / want.max(1e-6));
    }
    eprintln!("256 lights per leaf: worst relative difference from the CPU sum {worst:.2e}");
    assert!(worst < 1e-3, "{worst}");
    // A cutoff culls lights but drops at most `cutoff` of irradiance per culled light.
    // Chosen so that the brightest lamp reaches a third of the box.
    let cutoff = 0.55 / (0.33 * (hi - lo).max_element()).powi(2);
    let (culled, in_range) = per_leaf(cutoff);
    eprintln!("cutoff {cutoff} W/m^2: lights in range per cell (mean, max) {in_range:?}");
    assert!(in_range.0 < 0.5 * 256.0, "the grid must cull: {in_range:?}");
    for (a, b) in all.iter().zip(&culled) {
        let lost = (a.far[1] - b.far[1]) * std::f32::consts::PI;
        assert!(lost >= -1e-4 && lost <= 256.0 * cutoff, "lost {lost} W/m^2");
    }
    // And the whole scene renders with a budget: 16 shadow maps, 240 lights per leaf.
    let settings = Settings { bounces: 1, shadow_map_size: 128, ..Default::default() };
    let mut r = Renderer::new(gpu(), &scene, settings).unwrap();
    let c = (lo + hi) * 0.5;
    let cam = Camera {
        eye_m: c - Vec3::Y * 0.3 * (hi - lo).y,
        look_at_m: c + Vec3::Y,
        up: Vec3::Z,
        fov_y_deg: 70.0,
    };
    let (frame, plan) = r.render(&cam, 64, 48).unwrap();
    assert!(plan.explain().contains("16 of 256 point, 0 spot lights get shadow maps"), "{}", plan.explain());
    assert!(frame.hdr.iter().all(|p| p.iter().all(|v| v.is_finite() && *v >= 0.0)));
    assert!(frame.hdr.iter().filter(|p| p[3] > 0.5 && p[1] > 0.0).count() > 64 * 48 / 2, "the box is lit");
}

#[test]
fn many_cone_shadowed_lamps_add_up_like_the_same_lamps_in_small_groups() {
    use grotto_runtime::scene::data::SceneLight;
    use grotto_runtime::settings::ShadowFallback;
    // 48 lamps along the dogleg's air (room, corridors, chamber), all beyond the shadow-map budget:
    // each leaf traces one SVO shadow cone per lamp. Mesa's software drivers end every loop of an
    // invocation once all of them together pass 65535 iterations, which dropped the last lamps of
    // a long list before inject ran in batches (passes/inject.rs).
    let mut scene = testscenes::dogleg();
    let air: Vec<glam::IVec3> = (0..12)
        .flat_map(|z| (0..42).flat_map(move |y| (0..24).map(move |x| glam::IVec3::new(x, y, z))))
        .filter(|&c| {
            testscenes::dogleg_air(c) && (-1..=1).all(|d| testscenes::dogleg_air(c + glam::IVec3::splat(d)))
        })
        .collect();
    let step = air.len() / 48;
    scene.lights = (0..48)
        .map(|k| SceneLight {
            name: format!("lamp-{k}"),
            position_m: (air[k * step].as_vec3() + 0.5) * scene.leaf_size_m,
            intensity_w_sr: Vec3::splat(0.5),
            spot: None,
            profile: None,
        })
        .collect();
    let far = |lights: &[SceneLight]| {
        let mut s = scene.clone();
        s.lights = lights.to_vec();
        let settings = Settings {
            bounces: 0,
            shadowed_lights: 0,
            shadow_fallback: ShadowFallback::Cone,
            light_cutoff_w_m2: 0.0,
            ..Default::default()
        };
        let mut r = Renderer::new(gpu(), &s, settings).unwrap();
        r.update_light().unwrap();
        r.read_leaf_light().unwrap().iter().map(|l| l.far[1]).collect::<Vec<f32>>()
    };
    let together = far(&scene.lights);
    // The sum of small groups: each group's loop stays far below the drivers' limit (one lamp a
    // run cost 48 renderers and 149 s of CI's time for the same check).
    let mut in_groups = vec![0.0f32; together.len()];
    for group in scene.lights.chunks(6) {
        for (s, v) in in_groups.iter_mut().zip(far(group)) {
            *s += v;
        }
    }
    let worst =
        together.iter().zip(&in_groups).map(|(a, b)| (a - b).abs() / b.max(1e-3)).fold(0.0f32, f32::max);
    eprintln!("48 cone-shadowed lamps together vs in groups of six: worst relative difference {worst:.2e}");
    assert!(in_groups.iter().any(|&v| v > 0.0));
    assert!(worst < 1e-4, "lamps together differ from their sum: {worst}");
}

#[test]
fn a_validation_error_names_the_pass_whose_scope_caught_it() {
    let g = gpu();
    // MAP_READ goes only with COPY_DST: wgpu reports this buffer as a validation error, which the
    // scope turns into an error naming the pass.
    let err = g
        .scoped("probe", || {
            Ok(g.device.create_buffer(&wgpu::BufferDescriptor {
                label: Some("invalid"),
                size: 16,
                usage: wgpu::BufferUsages::MAP_READ | wgpu::BufferUsages::STORAGE,
                mapped_at_creation: false,
            }))
        })
        .unwrap_err();
    assert!(matches!(err, grotto_runtime::Error::Gpu { pass: "probe", .. }), "{err}");
    // Nothing leaks to the device-wide check, and a clean scope passes.
    g.check("after").unwrap();
    assert!(g.scoped("clean", || Ok(())).is_ok());
}

#[test]
fn views_without_light_skip_the_light_passes_and_show_albedo_normals_and_level() {
    use grotto_runtime::render::Frame;
    use grotto_runtime::settings::ViewMode;
    use grotto_runtime::view::camera::Camera;
    let scene = testscenes::dogleg();
    let cam = Camera::from_scene(&scene.cameras[0]);
    let render = |view| {
        let settings = Settings { bounces: 2, exposure: 4.0, view, ..Default::default() };
        let mut r = Renderer::new(gpu(), &scene, settings).unwrap();
        r.settle(|_, _| {}).unwrap();
        let (f, plan) = r.render(&cam, 64, 48).unwrap();
        (f, plan, r.stats().dispatches.clone())
    };
    let covered = |f: &Frame| -> Vec<[u8; 4]> {
        f.hdr.iter().zip(&f.ldr).filter(|(h, _)| h[3] >= 0.5).map(|(_, l)| *l).collect()
    };
    for view in [ViewMode::Albedo, ViewMode::Normals, ViewMode::Level] {
        let (f, plan, d) = render(view);
        for pass in [Pass::Shadow, Pass::Inject, Pass::Mip, Pass::Propagate] {
            assert!(!plan.runs(pass) && !d.contains_key(&pass), "{view:?}: {}", plan.explain());
        }
        let px = covered(&f);
        assert!(px.len() > 64 * 48 / 4, "{view:?}: {} pixels covered", px.len());
        match view {
            // Every pixel shows a surfel's own colour (sRGB, through the 8-bit G-buffer).
            ViewMode::Albedo => {
                let mut colors: Vec<[u8; 4]> = scene.surfels.iter().map(|s| s.color).collect();
                colors.sort();
                colors.dedup();
                let near = |p: &[u8; 4]| {
                    colors.iter().any(|c| (0..3).all(|k| (i32::from(p[k]) - i32::from(c[k])).abs() <= 3))
                };
                assert!(px.iter().all(near), "albedo view shows colours no surfel has");
            }
            // 0.5 + 0.5 n: unit normals.
            ViewMode::Normals => {
                let n =
                    |p: &[u8; 4]| Vec3::from_array([0, 1, 2].map(|k| f32::from(p[k]) / 255.0 * 2.0 - 1.0));
                assert!(
                    px.iter().all(|p| (n(p).length() - 1.0).abs() < 0.05),
                    "normals view: not unit normals"
                );
                let first = n(&px[0]);
                assert!(px.iter().any(|p| n(p).dot(first) < 0.5), "normals view: walls of every direction");
            }
            // Every tile is held in full: green, shaded.
            ViewMode::Level => {
                assert!(px.iter().all(|p| p[1] > p[0] && p[1] > p[2]), "level view: full tiles are green");
            }
            _ => unreachable!(),
        }
    }
    // The light view: the same light on white walls, so at least as bright as the lit view.
    let (lit, _, _) = render(ViewMode::Lit);
    let (light, plan, _) = render(ViewMode::Light);
    let sum = |f: &Frame| f.hdr.iter().map(|p| f64::from(p[0] + p[1] + p[2])).sum::<f64>();
    assert!(plan.steps.iter().all(|s| s.pass != Pass::Propagate || !s.reason.contains("view")));
    assert!(sum(&light) > sum(&lit), "light view {} against lit {}", sum(&light), sum(&lit));
}

/// 64 shadowed lamps are 384 shadow faces, each with its own 256-byte splat uniform: 96 KiB in
/// one buffer, over the 64 KiB a uniform binding may hold on lavapipe and in WebGPU by default.
/// Each draw binds one face's slot, so the renderer must accept it (it refused, naming the
/// whole buffer, until the limit was checked per slot); in the convex colour box every lamp sees
/// every wall, so the shadow-mapped light must equal the unshadowed sum.
#[test]
fn sixty_four_shadowed_lamps_fit_the_uniform_binding_limit_and_shadow_nothing_in_a_convex_box() {
    use grotto_runtime::scene::data::SceneLight;
    use grotto_runtime::settings::ShadowFallback;
    let mut scene = testscenes::colour_box();
    let (lo, hi) = scene.bounds_leaf();
    let (lo, hi) = (lo * scene.leaf_size_m, hi * scene.leaf_size_m);
    scene.lights = (0..64)
        .map(|i| {
            let f = Vec3::new((i % 4) as f32 + 0.5, ((i / 4) % 4) as f32 + 0.5, (i / 16) as f32 + 0.5) / 4.0;
            SceneLight {
                name: format!("lamp-{i}"),
                position_m: lo + (hi - lo) * (0.3 + 0.4 * f),
                intensity_w_sr: Vec3::splat(0.1),
                spot: None,
                profile: None,
            }
        })
        .collect();
    let faces_bytes = 64 * 6 * size_of::<grotto_runtime::gpu::types::SplatUniform>() as u64;
    eprintln!(
        "splat uniforms {faces_bytes} bytes, uniform binding limit {}",
        gpu().device.limits().max_uniform_buffer_binding_size
    );
    let direct = |shadowed_lights: u32, shadow_fallback: ShadowFallback| {
        let settings = Settings {
            bounces: 0,
            shadowed_lights,
            shadow_fallback,
            shadow_map_size: 64,
            light_cutoff_w_m2: 0.0,
            ..Default::default()
        };
        let mut r = Renderer::new(gpu(), &scene, settings).unwrap();
        let plan = r.update_light().unwrap();
        assert_eq!(plan.runs(Pass::Shadow), shadowed_lights > 0, "{}", plan.explain());
        let light = r.read_leaf_light().unwrap();
        light.iter().map(|l| l.direct[1]).sum::<f32>() / light.len() as f32
    };
    let mapped = direct(64, ShadowFallback::None);
    let open = direct(0, ShadowFallback::None);
    eprintln!("mean direct: 64 shadow-mapped lamps {mapped}, unshadowed {open}");
    assert!(open > 0.0);
    assert!((mapped - open).abs() < 0.03 * open, "shadow maps darken a convex box: {mapped} vs {open}");
}
