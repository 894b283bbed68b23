//! The cone march against answers known in closed form: a cone through a slab of known
//! opacity, a lit wall seen down an open corridor, and the inside of a closed sphere lit by one
//! lamp, whose one-bounce gather is the same everywhere. Each at steps 0.1 to 1.0 and apertures
//! 0.35 to 1.0; the CPU reference (`cpu_ref`) carries the known answers and the GPU pass is
//! checked against it on the same scenes.

use std::f64::consts::PI;
use std::sync::OnceLock;

use glam::{DVec3, IVec3, Vec3};
use grotto_fixtures::testscenes;
use grotto_runtime::gpu::types::{LeafLightGpu, Params};
use grotto_runtime::gpu::{Gpu, GpuOptions};
use grotto_runtime::passes::cpu_ref::{CpuScene, MarchStep};
use grotto_runtime::render::Renderer;
use grotto_runtime::scene::data::{SceneData, VoxelLeaf};
use grotto_runtime::settings::Settings;

fn gpu() -> &'static Gpu {
    static GPU: OnceLock<Gpu> = OnceLock::new();
    GPU.get_or_init(|| {
        Gpu::new(&GpuOptions { prefer_software: true, ..Default::default() }).unwrap_or_else(|e| {
            panic!("GPU tests need an adapter (scripts/test.sh installs Mesa's lavapipe): {e}")
        })
    })
}

const STEPS: [f32; 5] = [1.0, 0.5, 0.35, 0.2, 0.1];
const LEAF_M: f32 = 0.1;

fn light_where(scene: &SceneData, lit: impl Fn(Vec3) -> f32) -> Vec<LeafLightGpu> {
    scene
        .leaves
        .iter()
        .map(|l| {
            let v = lit(Vec3::from_slice(&l.center_m[..3]) / scene.leaf_size_m);
            LeafLightGpu { out: [v, v, v, 0.0], ..Default::default() }
        })
        .collect()
}

/// The renderer's parameters for `scene` with one cone of half-angle tangent `tan_half` at
/// relative step `step` (the CPU march reads only these).
fn params(scene: &SceneData, step: f32, tan_half: f32) -> Params {
    let settings = Settings { step_scale: step, ..Default::default() };
    let mut p = Renderer::new(gpu(), scene, settings).unwrap().params();
    p.cone_tan_half = tan_half;
    p
}

/// One cone along +z from `origin_leaf` (leaf units), the origin one leaf above its own surface.
fn cone_z(cpu: &CpuScene<'_>, p: &Params, origin_leaf: Vec3) -> f64 {
    let leaf = f64::from(LEAF_M);
    cpu.trace_cone(p, origin_leaf.as_dvec3() * leaf, DVec3::Z, [leaf, 1.0])[0]
}

/// A 64-leaf cube: a probe's floor at z = 4, a slab of `thickness` leaves of opacity `alpha` per
/// leaf from z = 20, and lit rock from z = 50.
fn slab_scene(alpha: f32, thickness: i32) -> SceneData {
    let mut cells = Vec::new();
    let leaf = |cell, opacity, n: Vec3| VoxelLeaf {
        cell,
        albedo: Vec3::splat(0.5),
        opacity,
        normal_mean: n,
        emission: Vec3::ZERO,
    };
    for y in 0..64 {
        for x in 0..64 {
            cells.push(leaf(IVec3::new(x, y, 4), 1.0, Vec3::Z));
            for z in 20..20 + thickness {
                cells.push(leaf(IVec3::new(x, y, z), alpha, Vec3::ZERO));
            }
            for z in 50..64 {
                cells.push(leaf(IVec3::new(x, y, z), 1.0, Vec3::NEG_Z));
            }
        }
    }
    SceneData::from_voxels("slab", LEAF_M, 6, &cells)
}

#[test]
fn a_cone_through_a_slab_keeps_its_transmittance_at_every_step() {
    // Exact: the lit wall behind a non-emitting slab shows through its transmittance (1 - a)^n.
    for (alpha, thickness) in [(0.1f32, 10), (0.3, 4), (0.05, 20)] {
        let scene = slab_scene(alpha, thickness);
        let light = light_where(&scene, |c| if c.z >= 50.0 { 1.0 } else { 0.0 });
        let cpu = CpuScene::mip(&scene, &light);
        let want = f64::from(1.0 - alpha).powi(thickness);
        // The wide cone only through slabs at least 10 leaves thick: a thinner one lies within
        // one of its samples (edge 3.5 leaves there), whose opacity is then spread over the
        // whole sample: 0.2955 against 0.2401 at step 0.1 through 4 leaves of 0.3.
        let cones: &[(f32, f64)] =
            if thickness >= 10 { &[(0.05, 0.07), (0.2, 0.15)] } else { &[(0.05, 0.07)] };
        for &(tan_half, tolerance) in cones {
            let got: Vec<f64> = STEPS
                .iter()
                .map(|&step| cone_z(&cpu, &params(&scene, step, tan_half), Vec3::new(32.0, 32.0, 6.5)))
                .collect();
            eprintln!(
                "slab a={alpha} n={thickness} tan {tan_half}: want {want:.4}, steps {STEPS:?}: {got:.4?}"
            );
            // Stated tolerances, relative to the answer: steps 0.5 and finer within 7% (narrow
            // cone) or 15% (a cone 0.4 wide per unit length, whose samples blur the slab's
            // edges over several leaves), step 1 within 30% (it crosses a 10-leaf slab in one or
            // two samples).
            for (g, step) in got.iter().zip(STEPS) {
                let err = (g - want).abs() / want;
                let allowed = if step > 0.5 { 0.3 } else { tolerance };
                assert!(
                    err < allowed,
                    "slab a={alpha} n={thickness} tan {tan_half} step {step}: {g} against {want}"
                );
            }
        }
    }
}

/// Solid rock around a square corridor along z: 8 leaves wide, open from z = 4 to a lit end
/// wall at z = 52.
fn corridor_scene() -> SceneData {
    let air = |c: IVec3| (28..36).contains(&c.x) && (28..36).contains(&c.y) && (4..52).contains(&c.z);
    testscenes::carved("corridor", LEAF_M, 6, IVec3::splat(64), &air, &|_| Vec3::splat(0.5), Vec3::ZERO, None)
}

#[test]
fn a_lit_wall_down_an_open_corridor_is_seen_whole_by_a_cone_that_fits_through_it() {
    let scene = corridor_scene();
    let light = light_where(&scene, |c| if c.z >= 52.0 { 1.0 } else { 0.0 });
    let cpu = CpuScene::mip(&scene, &light);
    // From the axis one leaf above the floor, the end wall (47 leaves away, 8 wide) fills every
    // direction within atan(4 / 47) = 0.085 of the axis: a cone narrower than that sees only the
    // lit wall, wherever the march samples, as long as the samples' trilinear support (1.5
    // sample edges, a quarter of the cone's diameter each) stays inside the corridor.
    for tan_half in [0.02f32, 0.04] {
        let got: Vec<f64> = STEPS
            .iter()
            .map(|&step| cone_z(&cpu, &params(&scene, step, tan_half), Vec3::new(32.0, 32.0, 5.0)))
            .collect();
        eprintln!("corridor tan {tan_half}: want 1, steps {STEPS:?}: {got:.4?}");
        for (g, step) in got.iter().zip(STEPS) {
            // Stated tolerance: 2% (trilinear support reaching the corridor's walls).
            assert!((g - 1.0).abs() < 0.02, "corridor tan {tan_half} step {step}: {g} against 1");
        }
    }
    // Reported, not asserted: the known limit (docs/runtime.md). A cone wider than the opening
    // should see the lit wall over the opening's share of its solid angle, but the walls along
    // it fill part of every sample, are composited as if in series, and close it.
    let tan_half = 0.2f64;
    let square_sr = |half_width: f64, dist: f64| {
        // A square of half-width w at distance d on its axis: 4 asin(s^2 / (1 + s^2)), s = w / d.
        let s = half_width / dist;
        4.0 * (s * s / (1.0 + s * s)).asin()
    };
    let cone_sr = 2.0 * PI * (1.0 - 1.0 / (1.0 + tan_half * tan_half).sqrt());
    let got: Vec<f64> = STEPS
        .iter()
        .map(|&step| cone_z(&cpu, &params(&scene, step, tan_half as f32), Vec3::new(32.0, 32.0, 5.0)))
        .collect();
    eprintln!(
        "corridor tan {tan_half} (known limit): the opening's share {:.4}, steps {STEPS:?}: {got:.4?}",
        square_sr(4.0, 47.0) / cone_sr
    );
}

/// Inside a closed sphere the form factor between any two points is dA / (4 pi R^2) (both
/// cosines are chord / 2R), so the one-bounce gather (irradiance / pi) is the same everywhere:
/// the mean outgoing radiance over the sphere. Under one lamp of intensity I (W/sr) inside,
/// every watt lands on the wall: mean irradiance 4 pi I / (4 pi R^2), mean radiance that over pi.
struct LitSphere {
    scene: SceneData,
    /// Centre, leaves.
    center: Vec3,
    /// The lamp's direct light on every leaf.
    light: Vec<LeafLightGpu>,
    /// The one-bounce gather everywhere.
    want: f64,
}

const SPHERE_DEPTH: u32 = 6;
const SPHERE_RADIUS_LEAVES: f32 = 26.0;

impl LitSphere {
    /// The sphere (albedo 0.5) with its centre `shift_leaves` off the grid, a lamp 0.6 R above
    /// the centre: the wall's radiance varies 16-fold from top to bottom.
    fn new(shift_leaves: Vec3) -> Self {
        let radius_leaves = SPHERE_RADIUS_LEAVES;
        let scene =
            testscenes::shifted_sphere(SPHERE_DEPTH, radius_leaves, 0.5, 0.0, f32::INFINITY, shift_leaves);
        let center = Vec3::splat((1u32 << SPHERE_DEPTH) as f32 * 0.5) + shift_leaves;
        let lamp = center + Vec3::Z * 0.6 * radius_leaves;
        let radiance = |c: Vec3| {
            let n = (center - c).normalize();
            let d = (lamp - c) * LEAF_M;
            n.dot(d.normalize()).max(0.0) / d.length_squared() / std::f32::consts::PI
        };
        let light = light_where(&scene, radiance);
        let r_m = f64::from((radius_leaves + 0.5) * LEAF_M);
        LitSphere { scene, center, light, want: 1.0 / (r_m * r_m * PI) }
    }

    /// Leaf `i`'s offset from the centre (leaves) where it is on the inner surface.
    fn inner(&self, i: usize) -> Option<Vec3> {
        let c = Vec3::from_slice(&self.scene.leaves[i].center_m[..3]) / LEAF_M - self.center;
        (c.length() < SPHERE_RADIUS_LEAVES + 1.0).then_some(c)
    }

    /// Every leaf's gather after one bounce with `settings`, and the renderer.
    fn one_bounce(&self, settings: Settings) -> (Renderer, Vec<LeafLightGpu>) {
        let mut r = Renderer::new(gpu(), &self.scene, settings).unwrap();
        r.write_leaf_light(&self.light).unwrap();
        r.run_bounce().unwrap();
        let got = r.read_leaf_light().unwrap();
        (r, got)
    }
}

#[test]
fn one_bounce_inside_a_lit_sphere_is_the_same_everywhere_at_every_aperture() {
    let sphere = LitSphere::new(Vec3::ZERO);
    let (scene, light, want) = (&sphere.scene, &sphere.light, sphere.want);
    // Inner surface leaves, by height: the bottom third, the middle, the top third.
    let band = |i: usize| {
        sphere.inner(i).map(|c| {
            if c.z < -c.length() / 3.0 {
                0
            } else if c.z > c.length() / 3.0 {
                2
            } else {
                1
            }
        })
    };
    for aperture in [0.35f32, 0.5, 0.7, 1.0] {
        for step in [0.5f32, 0.2] {
            let settings =
                Settings { cones: 16, cone_aperture_scale: aperture, step_scale: step, ..Default::default() };
            let (r, got) = sphere.one_bounce(settings);
            let mut bands = [(0.0f64, 0usize); 3];
            for (i, l) in got.iter().enumerate() {
                if let Some(b) = band(i) {
                    bands[b].0 += f64::from(l.gather[0]);
                    bands[b].1 += 1;
                }
            }
            let ratio = bands.map(|(s, n)| s / n as f64 / want);
            eprintln!(
                "sphere aperture {aperture} step {step}: gather / answer by height (bottom, middle, top) {ratio:.3?}"
            );
            // Stated tolerance: every band within 6% of the answer (an earlier march was 30% low
            // at the bottom and 39% high at the top at aperture 1).
            for (k, v) in ratio.iter().enumerate() {
                assert!(
                    (v - 1.0).abs() < 0.06,
                    "aperture {aperture} step {step}: band {k} at {v:.3} of the answer"
                );
            }
            if step == 0.5 {
                let (worst, checked) = CpuScene::mip(scene, light).worst_gather_error(&r.params(), &got, 97);
                eprintln!("  GPU against the CPU reference: worst {worst:.1e} over {checked} leaves");
                assert!(worst < 1e-3, "aperture {aperture}: the GPU march differs from the CPU's by {worst}");
            }
        }
    }
}

/// Where the leaf grid falls must not matter much: the lamp-lit sphere moved by fractions of a
/// leaf (walls then cut leaves at other places) keeps its one-bounce gather. An earlier march had
/// the high preset's bias move from -7.3% to -5.2% when a room moved by a few centimetres.
#[test]
fn one_bounce_inside_a_lit_sphere_does_not_depend_on_where_the_grid_falls() {
    let mut means = Vec::new();
    for shift in
        [Vec3::ZERO, Vec3::new(0.25, 0.5, 0.125), Vec3::new(0.5, 0.5, 0.5), Vec3::new(0.75, 0.1, 0.4)]
    {
        let sphere = LitSphere::new(shift);
        // The balanced preset's cones.
        let settings = Settings { cones: 9, cone_aperture_scale: 0.7, step_scale: 0.5, ..Default::default() };
        let (_, got) = sphere.one_bounce(settings);
        let (mut sum, mut n) = (0.0f64, 0usize);
        for (i, l) in got.iter().enumerate() {
            if sphere.inner(i).is_some() {
                sum += f64::from(l.gather[0]);
                n += 1;
            }
        }
        let ratio = sum / n as f64 / sphere.want;
        eprintln!("sphere shifted by {shift:?} leaves: mean gather / answer {ratio:.4} over {n} leaves");
        means.push(ratio);
    }
    let (lo, hi) = means.iter().fold((f64::MAX, f64::MIN), |(a, b), &m| (a.min(m), b.max(m)));
    eprintln!("spread over shifts: {:.2}%", (hi - lo) * 100.0);
    // Stated tolerance: 1.5% of the answer between any two placements.
    assert!(hi - lo < 0.015, "the gather moves by {:.2}% with the grid", (hi - lo) * 100.0);
}

/// A lit floor of 8x8 leaves near the bottom of a 512-leaf cube, and a lit block 150 leaves away
/// and 40 up: the box of the matter holds both and lies within the cube; a cone rising from the
/// floor away from the block stops once its cross-section has left that box (it used to cross the empty cube to its top, reading only coarse levels' blur of the
/// floor behind it), while a cone aimed at the block across the empty space still reaches it.
#[test]
fn a_cone_stops_once_its_cross_section_has_left_the_matter() {
    let leaf = |cell, n: Vec3| VoxelLeaf {
        cell,
        albedo: Vec3::splat(0.5),
        opacity: 1.0,
        normal_mean: n,
        emission: Vec3::ZERO,
    };
    let mut cells: Vec<VoxelLeaf> =
        (100..108).flat_map(|y| (100..108).map(move |x| leaf(IVec3::new(x, y, 4), Vec3::Z))).collect();
    for z in 40..56 {
        for y in 96..112 {
            for x in 250..266 {
                cells.push(leaf(IVec3::new(x, y, z), Vec3::NEG_X));
            }
        }
    }
    let scene = SceneData::from_voxels("floor and block", LEAF_M, 9, &cells);
    let (lo, hi) = scene.occupied_bounds_leaf();
    let (tiles_lo, tiles_hi) = scene.bounds_leaf();
    assert!(
        lo.cmpge(tiles_lo).all() && hi.cmple(tiles_hi).all(),
        "{lo} {hi} outside the tiles {tiles_lo} {tiles_hi}"
    );
    for l in &scene.leaves {
        let c = l.cell(LEAF_M).as_vec3();
        assert!(c.cmpge(lo).all() && (c + 1.0).cmple(hi).all(), "leaf {c} outside the box {lo} .. {hi}");
    }
    assert!(
        hi.z < 100.0 && hi.x < 300.0,
        "the box {lo} .. {hi} should end near the matter, not at the cube's 512"
    );

    let light = light_where(&scene, |_| 1.0);
    let cpu = CpuScene::mip(&scene, &light);
    let p = params(&scene, 0.5, 0.2);
    let leaf_m = f64::from(LEAF_M);
    let origin = DVec3::new(104.0, 104.0, 5.5) * leaf_m;
    // Above the block's top (z 56) and a ball of 0.2 t around the axis clear of it: t = 68
    // leaves; the cube's top is 530 leaves along this axis.
    let mut farthest_leaf = 0.0f64;
    let up =
        cpu.trace_cone_observed(&p, origin, DVec3::new(-0.3, 0.0, 1.0).normalize(), [leaf_m, 0.95], |s| {
            if let MarchStep::Sample { t_m, .. } = s {
                farthest_leaf = farthest_leaf.max(t_m / leaf_m);
            }
        });
    assert!(
        (60.0..110.0).contains(&farthest_leaf),
        "a cone rising from the floor sampled up to {farthest_leaf} leaves: {up:?}"
    );
    assert!(up[3] < 0.05, "nothing lies above the floor, yet the cone is {} opaque", up[3]);

    let to_block = (DVec3::new(250.0, 104.0, 48.0) * leaf_m - origin).normalize();
    let seen = cpu.trace_cone(&p, origin, to_block, [leaf_m, to_block.z]);
    assert!(seen[3] > 0.9 && seen[0] > 0.9, "the cone toward the block across empty space saw {seen:?}");
}
