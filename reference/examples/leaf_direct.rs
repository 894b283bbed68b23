//! The leaves whose direct light (no bounce) the runtime gets most wrong against the reference's
//! (mean over the leaf's surfels), with their surfels' normals, and for the worst three the discs
//! that stand between each of their surfels and the lamp. This is how the carved long
//! passage's fins (discs standing past convex edges) and unit normals on edges showed up.
//!
//! `cargo run --release -p grotto-reference --example leaf_direct [passage|dogleg] [surfels]`
//! (`passage`: the carved `testscenes::passage`; `surfels`: leaves on their surfels' centroid, as
//! packages have them; CELLS=`x,y,z;...` lists those leaves instead of the worst).
use glam::Vec3;
use grotto_fixtures::testscenes;
use grotto_reference::accuracy::breakdown::{balanced_cut, settled};
use grotto_reference::{PathSettings, SurfelScene};
use grotto_runtime::gpu::types::SurfelGpu;
use grotto_runtime::gpu::{Gpu, GpuOptions};
use grotto_runtime::settings::{Quality, Settings};

fn main() -> anyhow::Result<()> {
    let args: Vec<String> = std::env::args().collect();
    let gpu = Gpu::new(&GpuOptions { prefer_software: true, ..Default::default() })?;
    let mut data = if args.get(1).map(String::as_str) == Some("dogleg") {
        testscenes::dogleg()
    } else {
        testscenes::passage()
    };
    if args.get(2).map(String::as_str) == Some("surfels") {
        testscenes::leaves_on_surfels(&mut data);
    }
    let leaf = data.leaf_size_m;
    let light = settled(&gpu, &data, balanced_cut(0))?.read_leaf_light()?;
    let scene = SurfelScene::from_scene(&data, Settings::preset(Quality::Balanced).splat_scale);
    // A carved scene's surfel lies on a face of its leaf's cell (the reference's rule, a quarter
    // leaf behind the surface).
    let in_cell = |s: &SurfelGpu, cell: glam::IVec3| {
        let p = Vec3::from_slice(&s.position_radius[..3]);
        let sn = Vec3::from_slice(&s.normal_spread[..3]);
        ((p - sn * 0.25 * leaf) / leaf).floor().as_ivec3() == cell
    };
    let ps = PathSettings { max_bounces: 0, ..PathSettings::for_scene(&data) };
    let reference = scene.leaf_radiance(&data, 16, &ps, 1);
    let lum = |v: [f32; 3]| (v[0] + v[1] + v[2]) / 3.0;
    let mut rows = Vec::new();
    for (i, l) in data.leaves.iter().enumerate() {
        let Some(e) = &reference[i] else { continue };
        let want = lum(e.mean.to_array());
        let got = lum(light[i].shown(l));
        rows.push((i, got, want));
    }
    let total_got: f32 = rows.iter().map(|r| r.1).sum();
    let total_want: f32 = rows.iter().map(|r| r.2).sum();
    println!("sum runtime {total_got:.3} reference {total_want:.3}");
    rows.sort_by(|a, b| (b.1 - b.2).abs().total_cmp(&(a.1 - a.2).abs()));
    // Cells named in CELLS (`x,y,z;x,y,z`) first.
    if let Ok(cells) = std::env::var("CELLS") {
        let want: Vec<glam::IVec3> = cells
            .split(';')
            .filter_map(|c| {
                let v: Vec<i32> = c.split(',').filter_map(|x| x.trim().parse().ok()).collect();
                (v.len() == 3).then(|| glam::IVec3::new(v[0], v[1], v[2]))
            })
            .collect();
        rows.retain(|r| want.contains(&data.leaves[r.0].cell(leaf)));
    }
    for &(i, got, want) in rows.iter().take(25) {
        let l = &data.leaves[i];
        let n = Vec3::from_slice(&l.normal_mean[..3]);
        let c = Vec3::from_slice(&l.center_m[..3]);
        let cell = l.cell(leaf);
        let surfels: Vec<String> = data
            .surfels
            .iter()
            .filter(|s| in_cell(s, cell))
            .map(|s| format!("{:?}", Vec3::from_slice(&s.normal_spread[..3])))
            .collect();
        println!(
            "leaf {i} cell {cell} centre {c:.3} normal {n:.2} |n| {:.2} runtime {got:.3} reference {want:.3} surfels {}",
            n.length(),
            surfels.join(" ")
        );
    }
    let lamp = data.lights[0].position_m;
    for &(i, _, _) in rows.iter().take(3) {
        let l = &data.leaves[i];
        let cell = l.cell(leaf);
        for s in data.surfels.iter().filter(|s| in_cell(s, cell)) {
            let p = Vec3::from_slice(&s.position_radius[..3]);
            let sn = Vec3::from_slice(&s.normal_spread[..3]);
            println!("surfel {p:.3} n {sn} to lamp {lamp:.3}:");
            // Every disc (as drawn and path traced) the shadow ray crosses, not only the first.
            let a = p + sn * 0.25 * leaf;
            let len = (lamp - a).length();
            let d = (lamp - a) / len;
            for disc in scene.discs() {
                if let Some(t) = disc.hit(a, d, 1e-3, len - 1e-3) {
                    println!(
                        "   disc at {:.3} n {} hit t {t:.3} at {:.3}",
                        disc.center_m(),
                        disc.normal,
                        a + d * t
                    );
                }
            }
        }
    }
    Ok(())
}
