//! What the runtime's cones see, direction by direction, from three floor leaves of the dogleg's
//! lit room (at the wall's edge, one leaf in, in the middle), against the path tracer's first hit
//! (the direct light it sees), per band of elevation, cosine-weighted (where the room's
//! extra light per bounce comes from; docs/reference.md). The cones march the CPU reference
//! (`cpu_ref`, the same march as the GPU's) over the pyramid of the direct light.
//!
//! `cargo run --release -p grotto-reference --example edge_cones [x,y,z ...]` (leaf cells; TAN=0.05
//! for narrow cones; LIFT=k for cones starting k leaves off the surface; SCENE=passage for the
//! scanned long passage, whose floor, wall and ceiling leaves ALONG=a,b metres down it are taken
//! when no cells are given; SCENE="colour box" for the colour box, whose red wall half way up and
//! under the ceiling and floor's middle are taken; HIT=1 adds the runtime's radiance of the leaves
//! the path tracer's rays hit, to tell a cone meeting other leaves from a leaf with the wrong
//! radiance; CONE=1 spreads the path tracer's rays evenly over each cone's solid angle, what the
//! cone stands for, instead of along its axis; PLANES=1 marches with cone planes; DIRS=1 prints
//! every direction: the cone's and the ray's light, where the cone reaches half its opacity and
//! where the ray meets a disc; ONE=e,a prints the march of one cone, step by step: elevation band
//! e (0-8) and azimuth a (0-23)).
use glam::{IVec3, Vec3};
use grotto_fixtures::testscenes;
use grotto_reference::accuracy::breakdown::{balanced_cut, settled};
use grotto_reference::{PathSettings, SurfelScene};
use grotto_runtime::gpu::types::Params;
use grotto_runtime::gpu::{Gpu, GpuOptions};
use grotto_runtime::passes::cpu_ref::{CpuScene, MarchStep};
use grotto_runtime::scene::data::SceneData;
use grotto_runtime::settings::{Quality, Settings};
use rand::{Rng, SeedableRng};

fn env_f32(name: &str) -> Option<f32> {
    std::env::var(name).ok().and_then(|v| v.parse().ok())
}

/// A flat floor, wall and ceiling leaf ALONG=a,b metres down the scanned passage (default 4.5-5,
/// 3.5-4 m past the lamp).
fn passage_cells(data: &SceneData) -> Vec<IVec3> {
    let range: Vec<f32> = std::env::var("ALONG")
        .unwrap_or_else(|_| "4.5,5".into())
        .split(',')
        .filter_map(|x| x.parse().ok())
        .collect();
    let (a0, a1) = (range.first().copied().unwrap_or(4.5), range.get(1).copied().unwrap_or(5.0));
    [Vec3::Z, Vec3::Y, -Vec3::Z]
        .into_iter()
        .filter_map(|want| {
            data.leaves.iter().find(|l| {
                let own = grotto_fixtures::scanned_passage::passage_frame_m(
                    data,
                    Vec3::from_slice(&l.center_m[..3]),
                );
                let along = testscenes::passage_position_m(own).1;
                let mean = Vec3::from_slice(&l.normal_mean[..3]);
                // A flat leaf (normals agree) facing the way wanted.
                (a0..a1).contains(&along)
                    && mean.length() >= 0.99
                    && mean.normalize_or_zero().dot(want) > 0.95
            })
        })
        .map(|l| l.cell(data.leaf_size_m))
        .collect()
}

/// The leaf whose light the path tracer's ray from `o` along `d` first meets: the leaf nearest
/// the disc it hits (a package's surfel lies in or beside its leaf's cell).
fn hit_leaf(scene: &SurfelScene, data: &SceneData, o: Vec3, d: Vec3) -> Option<(f32, usize)> {
    let (t, k) = scene.intersect(o, d, f32::INFINITY)?;
    let c = scene.discs()[k].center_m();
    let dist =
        |l: &grotto_runtime::gpu::types::LeafGpu| (Vec3::from_slice(&l.center_m[..3]) - c).length_squared();
    let nearest = data.leaves.iter().enumerate().min_by(|a, b| dist(a.1).total_cmp(&dist(b.1)))?;
    Some((t, nearest.0))
}

/// Where a cone from `origin` along `d` reaches half its opacity (bisection on the march's length).
fn half_opacity_m(cpu: &CpuScene<'_>, p: &Params, origin: Vec3, d: Vec3, rise: [f64; 2]) -> f32 {
    let (mut lo, mut hi) = (0.0f32, p.max_distance_m);
    for _ in 0..20 {
        let mid = 0.5 * (lo + hi);
        let q = Params { max_distance_m: mid, ..*p };
        if cpu.trace_cone(&q, origin.as_dvec3(), d.as_dvec3(), rise)[3] >= 0.5 {
            hi = mid;
        } else {
            lo = mid;
        }
    }
    hi
}

/// One step of a cone's march (`ONE=`), in the green channel.
fn print_step(step: MarchStep) {
    match step {
        MarchStep::Sample { t_m, diameter_m, edge_m, step, acc } => println!(
            "      {t_m:.3} m: footprint {diameter_m:.3} m read at edge {edge_m:.3} m, radiance {:.3} opacity {:.3}; the cone so far {:.3} opacity {:.3}",
            step[1] / step[3].max(1e-9),
            step[3],
            acc[1],
            acc[3]
        ),
        MarchStep::Rock { t_m, last, acc } => println!(
            "      {t_m:.3} m: the axis enters rock; the rest filled with {:.3}: the cone {:.3}",
            last[1], acc[1]
        ),
    }
}

fn main() -> anyhow::Result<()> {
    let gpu = Gpu::new(&GpuOptions { prefer_software: true, ..Default::default() })?;
    // Leaves on their surfels, as in a package: the cones start one leaf off the surface.
    let scene_name = std::env::var("SCENE").unwrap_or_default();
    let (passage, colour_box) = (scene_name == "passage", scene_name == "colour box");
    let mut data = if passage {
        grotto_reference::accuracy::scanned_passage().map_err(anyhow::Error::msg)?
    } else if colour_box {
        testscenes::colour_box()
    } else {
        testscenes::dogleg()
    };
    if !passage {
        testscenes::leaves_on_surfels(&mut data);
    }
    let leaf = data.leaf_size_m;
    let r = settled(&gpu, &data, balanced_cut(0))?;
    let light = r.read_leaf_light()?;
    // The GPU's own gather after one bounce (8 interleaved cones), for comparison.
    let light1 = settled(&gpu, &data, balanced_cut(1))?.read_leaf_light()?;
    let mut p = r.params();
    p.cone_tan_half = env_f32("TAN").unwrap_or(p.cone_tan_half);
    if std::env::var("PLANES").is_ok() {
        p.flags |= grotto_runtime::gpu::types::flags::CONE_PLANES;
    }
    let cpu = CpuScene::mip(&data, &light);
    let scene = SurfelScene::from_scene(&data, Settings::preset(Quality::Balanced).splat_scale);
    let ps = PathSettings { max_bounces: 1, ..PathSettings::for_scene(&data) };
    let mut rng = rand::rngs::SmallRng::seed_from_u64(5);
    let (hit, dirs) = (std::env::var("HIT").is_ok(), std::env::var("DIRS").is_ok());
    let spread = std::env::var("CONE").is_ok();
    let one = std::env::var("ONE").ok();
    // CONE=1: the rays spread evenly over the cone's solid angle (what the cone stands for)
    // instead of along its axis.
    let cos_max = 1.0 / (1.0 + p.cone_tan_half * p.cone_tan_half).sqrt();
    // Cells from the command line (`x,y,z` each), else the passage's or the room's three leaves.
    let mut cells: Vec<IVec3> = std::env::args()
        .skip(1)
        .filter_map(|a| {
            let v: Vec<i32> = a.split(',').filter_map(|x| x.trim().parse().ok()).collect();
            (v.len() == 3).then(|| IVec3::new(v[0], v[1], v[2]))
        })
        .collect();
    if cells.is_empty() {
        cells = if passage {
            passage_cells(&data)
        } else if colour_box {
            // The red wall half way up and under the ceiling, the floor's middle.
            let m = testscenes::COLOUR_BOX_CELLS / 2;
            vec![IVec3::new(0, m, m), IVec3::new(0, m, testscenes::COLOUR_BOX_CELLS - 3), IVec3::new(m, m, 0)]
        } else {
            vec![IVec3::new(2, 5, 1), IVec3::new(3, 5, 1), IVec3::new(6, 5, 1)]
        };
    }
    for cell in cells {
        let Some(i) = data.leaves.iter().position(|l| l.cell(leaf) == cell) else { continue };
        let l = &data.leaves[i];
        let n = Vec3::from_slice(&l.normal_mean[..3]).normalize();
        let centre = Vec3::from_slice(&l.center_m[..3]);
        // LIFT: the cone origin's height above the surface in leaves (the runtime's is 1).
        let lift = env_f32("LIFT").unwrap_or(1.0) * leaf;
        let origin = centre + n * lift;
        // The path tracer's rays start on the surface.
        let ray_o = centre + n * (0.01 * leaf + 2e-3);
        let (t1, t2) = n.any_orthonormal_pair();
        println!("leaf {cell} centre {centre} normal {n}");
        let (mut tot_rt, mut tot_ref, mut tot_w, mut tot_hit, mut hit_w) = (0.0, 0.0, 0.0, 0.0, 0.0);
        for e in 0..9 {
            let elev = (5.0 + 10.0 * e as f32).to_radians();
            let (mut band_rt, mut band_ref, mut w_sum) = (0.0, 0.0, 0.0);
            for a in 0..24 {
                let az = (a as f32 + 0.5) * std::f32::consts::TAU / 24.0;
                let d = (t1 * az.cos() + t2 * az.sin()) * elev.cos() + n * elev.sin();
                let w = f64::from(elev.sin() * elev.cos());
                let rise = [f64::from(lift), f64::from(d.dot(n))];
                let rt = if one.as_deref() == Some(&format!("{e},{a}")) {
                    println!("    the cone along {d}, step by step (green):");
                    cpu.trace_cone_observed(&p, origin.as_dvec3(), d.as_dvec3(), rise, print_step)[1]
                } else {
                    cpu.trace_cone(&p, origin.as_dvec3(), d.as_dvec3(), rise)[1]
                };
                let rays = 64;
                let (u1, u2) = d.any_orthonormal_pair();
                let rf: f64 = (0..rays)
                    .map(|_| {
                        let r = if spread {
                            let c = 1.0 - rng.random::<f32>() * (1.0 - cos_max);
                            let s = (1.0f32 - c * c).max(0.0).sqrt();
                            let phi = rng.random::<f32>() * std::f32::consts::TAU;
                            d * c + (u1 * phi.cos() + u2 * phi.sin()) * s
                        } else {
                            d
                        };
                        if r.dot(n) <= 0.0 {
                            return 0.0;
                        }
                        f64::from(scene.trace(ray_o, r, &ps, &mut rng).y)
                    })
                    .sum::<f64>()
                    / rays as f64;
                let first = if hit || dirs { hit_leaf(&scene, &data, ray_o, d) } else { None };
                if let Some((_, k)) = first.filter(|_| hit) {
                    tot_hit += w * f64::from(light[k].out[1]);
                    hit_w += w;
                }
                if dirs {
                    println!(
                        "    elevation {:>2} azimuth {a:>2}: cone {rt:.3} ray {rf:.3}; the cone reaches half opacity {:.2} m from its origin, the ray meets a disc at {:.2} m",
                        5 + 10 * e,
                        half_opacity_m(&cpu, &p, origin, d, rise),
                        first.map_or(f32::NAN, |f| f.0)
                    );
                }
                band_rt += w * rt;
                band_ref += w * rf;
                w_sum += w;
            }
            println!(
                "  elevation {:>2}: runtime {:.3} reference {:.3} ratio {:.3}",
                5 + 10 * e,
                band_rt / w_sum,
                band_ref / w_sum,
                band_rt / band_ref
            );
            tot_w += w_sum;
            tot_rt += band_rt;
            tot_ref += band_ref;
        }
        println!(
            "  all: ratio {:.3} (dense cones {:.3}, path tracer {:.3}, the GPU's 8-cone gather {:.3}, leaves the rays hit {:.3})",
            tot_rt / tot_ref,
            tot_rt / tot_w,
            tot_ref / tot_w,
            light1[i].gather[1],
            tot_hit / hit_w.max(1e-12)
        );
    }
    Ok(())
}
