//! The furnace and multiple bounces: closed rock converges to E / (1 - albedo) with every march
//! option and precision, the bounce tail, the dogleg's regions bounce by bounce, the hidden chamber.

use super::*;

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
