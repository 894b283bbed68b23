//! What the runtime's cones see, direction by direction, from three floor leaves of the dogleg's
//! lit room (at the wall's edge, one leaf in, in the middle), against the path tracer's first hit
//! (the direct light it sees), per band of elevation, cosine-weighted (issue 47: where the room's
//! extra light per bounce comes from; docs/reference.md). The cones march the CPU reference
//! (`cpu_ref`, the same march as the GPU's) over the pyramid of the direct light.
//!
//! `cargo run --release -p grotto-reference --example edge_cones [x,y,z ...]` (leaf cells; TAN=0.05
//! for narrow cones; LIFT=k for cones starting k leaves off the surface; SCENE=passage for the
//! scanned long passage, whose floor, wall and ceiling leaves ALONG=a,b metres down it are taken
//! when no cells are given; HIT=1 adds the runtime's radiance of the leaves the path tracer's rays
//! hit, to tell a cone meeting other leaves from a leaf with the wrong radiance).
use glam::{IVec3, Vec3};
use grotto_fixtures::testscenes;
use grotto_reference::{PathSettings, SurfelScene};
use grotto_runtime::gpu::{Gpu, GpuOptions};
use grotto_runtime::passes::cpu_ref::CpuScene;
use grotto_runtime::render::Renderer;
use grotto_runtime::settings::{Quality, Settings};
use rand::SeedableRng;

fn main() -> anyhow::Result<()> {
    let gpu = Gpu::new(&GpuOptions { prefer_software: true, ..Default::default() })?;
    // Leaves on their surfels, as in a package: the cones start one leaf off the surface.
    let passage = std::env::var("SCENE").is_ok_and(|s| s == "passage");
    let mut data = if passage {
        grotto_reference::accuracy::scanned_passage().map_err(anyhow::Error::msg)?
    } else {
        testscenes::dogleg()
    };
    if !passage {
        testscenes::leaves_on_surfels(&mut data);
    }
    let leaf = data.leaf_size_m;
    let base = Settings::preset(Quality::Balanced);
    let mut r = Renderer::new(&gpu, &data, Settings { bounces: 0, bounce_tail: false, ..base.clone() })?;
    r.settle(|_, _| {})?;
    let light = r.read_leaf_light()?;
    // The GPU's own gather after one bounce (8 interleaved cones), for comparison.
    let mut r1 = Renderer::new(&gpu, &data, Settings { bounces: 1, bounce_tail: false, ..base.clone() })?;
    r1.settle(|_, _| {})?;
    let light1 = r1.read_leaf_light()?;
    let mut p = r.params();
    let narrow: f32 = std::env::var("TAN").ok().and_then(|v| v.parse().ok()).unwrap_or(p.cone_tan_half);
    p.cone_tan_half = narrow;
    let cpu = CpuScene::mip(&data, &light);
    let scene = SurfelScene::from_scene(&data, base.splat_scale);
    let ps = PathSettings { max_bounces: 1, ..PathSettings::for_scene(&data) };
    let mut rng = rand::rngs::SmallRng::seed_from_u64(5);
    // Cells from the command line (`x,y,z` each), else the room's three floor leaves.
    let mut cells: Vec<IVec3> = std::env::args()
        .skip(1)
        .filter_map(|a| {
            let v: Vec<i32> = a.split(',').filter_map(|x| x.trim().parse().ok()).collect();
            (v.len() == 3).then(|| IVec3::new(v[0], v[1], v[2]))
        })
        .collect();
    if cells.is_empty() && passage {
        // A floor, a wall and a ceiling leaf ALONG=a,b metres down the scanned passage (default
        // 4.5-5, 3.5-4 m past the lamp).
        let along_range: Vec<f32> = std::env::var("ALONG")
            .unwrap_or_else(|_| "4.5,5".into())
            .split(',')
            .filter_map(|x| x.parse().ok())
            .collect();
        let (a0, a1) =
            (along_range.first().copied().unwrap_or(4.5), along_range.get(1).copied().unwrap_or(5.0));
        for want in [Vec3::Z, Vec3::Y, -Vec3::Z] {
            let found = data.leaves.iter().find(|l| {
                let world = glam::DVec3::from_array(data.frame_origin_m)
                    + Vec3::from_slice(&l.center_m[..3]).as_dvec3();
                let own = (world - grotto_fixtures::scanned_passage::origin_m()).as_vec3();
                let along = testscenes::passage_position_m(own).1;
                let n = Vec3::from_slice(&l.normal_mean[..3]).normalize_or_zero();
                (a0..a1).contains(&along)
                    && n.dot(want) > 0.95
                    && (0.99..).contains(&Vec3::from_slice(&l.normal_mean[..3]).length())
            });
            cells.extend(found.map(|l| l.cell(leaf)));
        }
    } else if cells.is_empty() {
        cells = vec![IVec3::new(2, 5, 1), IVec3::new(3, 5, 1), IVec3::new(6, 5, 1)];
    }
    for cell in cells {
        let Some(i) = data.leaves.iter().position(|l| l.cell(leaf) == cell) else { continue };
        let l = &data.leaves[i];
        let n = Vec3::from_slice(&l.normal_mean[..3]).normalize();
        let centre = Vec3::from_slice(&l.center_m[..3]);
        // LIFT: the cone origin's height above the surface in leaves (the runtime's is 1).
        let lift: f32 = std::env::var("LIFT").ok().and_then(|v| v.parse().ok()).unwrap_or(1.0) * leaf;
        let origin = centre + n * lift;
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
                let c = cpu.trace_cone(
                    &p,
                    origin.as_dvec3(),
                    d.as_dvec3(),
                    [f64::from(lift), f64::from(d.dot(n))],
                );
                let rt = c[1];
                let mut rf = 0.0;
                let rays = 64;
                for _ in 0..rays {
                    rf += f64::from(scene.trace(centre + n * (0.01 * leaf + 2e-3), d, &ps, &mut rng).y)
                        / rays as f64;
                }
                // HIT: the runtime's radiance of the leaf the path tracer's first hit lies in
                // (brute force over the discs): whether a cone meets other leaves than the ray
                // does, or the same leaves with a radiance other than the point's.
                if std::env::var("HIT").is_ok() {
                    let o = centre + n * (0.01 * leaf + 2e-3);
                    let mut best: Option<(f32, Vec3)> = None;
                    for sf in &data.surfels {
                        let c = Vec3::from_slice(&sf.position_radius[..3]);
                        let sn = Vec3::from_slice(&sf.normal_spread[..3]);
                        let r = sf.position_radius[3] * base.splat_scale;
                        let denom = sn.dot(d);
                        if denom.abs() < 1e-8 {
                            continue;
                        }
                        let t = sn.dot(c - o) / denom;
                        if t > 1e-3
                            && best.is_none_or(|b| t < b.0)
                            && (o + d * t - c).length_squared() <= r * r
                        {
                            best = Some((t, c));
                        }
                    }
                    if let Some((_, c)) = best {
                        // The disc's leaf: the nearest leaf centre (a package's surfel lies in or
                        // beside its leaf's cell).
                        let k = data.leaves.iter().enumerate().min_by(|a, b| {
                            let da = (Vec3::from_slice(&a.1.center_m[..3]) - c).length_squared();
                            let db = (Vec3::from_slice(&b.1.center_m[..3]) - c).length_squared();
                            da.total_cmp(&db)
                        });
                        if let Some((k, _)) = k {
                            tot_hit += w * f64::from(light[k].out[1]);
                            hit_w += w;
                        }
                    }
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
