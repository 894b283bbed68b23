//! How far the runtime's gather cones march on a package, in samples: for every k-th leaf (about
//! 2,000 leaves in all), each cone of the preset's set at the leaf's interleave, the samples its
//! march takes on the CPU reference (`cpu_ref`, the GPU's march step for step) and the rock cells
//! it reads on the way (`rock_on_segment`: one a rock cell, at most 64 a step), stopped where its
//! cross-section leaves the box of the matter (`SceneData::occupied_bounds_leaf`, as the runtime
//! does) and, as before that box, only where it leaves the tiles' cubes. A count of work that
//! does not depend on how busy the machine is (docs/benchmarks.md, "Cones over open ground").
//!
//! `cargo run --release -p grotto-reference --example march_steps -- PACKAGE [fast|balanced|high]`
//! (MAX_DISTANCE=m: `grotto render --max-distance`).
use grotto_runtime::gpu::types::LeafLightGpu;
use grotto_runtime::gpu::{Gpu, GpuOptions};
use grotto_runtime::passes::cpu_ref::{CpuScene, MarchStep};
use grotto_runtime::render::Renderer;
use grotto_runtime::scene::data::SceneData;
use grotto_runtime::settings::{Quality, Settings};

fn main() -> anyhow::Result<()> {
    let mut args = std::env::args().skip(1);
    let path =
        args.next().ok_or_else(|| anyhow::anyhow!("usage: march_steps PACKAGE [fast|balanced|high]"))?;
    let quality = args.next().unwrap_or_else(|| "balanced".into());
    let q = Quality::ALL
        .into_iter()
        .find(|q| q.name() == quality)
        .ok_or_else(|| anyhow::anyhow!("no preset {quality}"))?;
    let pkg = grotto_format::Package::open(&path)?;
    let scene = SceneData::from_package(&pkg)?;
    let gpu = Gpu::new(&GpuOptions { prefer_software: true, ..Default::default() })?;
    let max_distance_m = std::env::var("MAX_DISTANCE").ok().and_then(|v| v.parse().ok());
    let settings = Settings { max_distance_m, ..Settings::preset(q) };
    let now = Renderer::new(&gpu, &scene, settings)?.params();
    let mut before = now;
    (before.occupied_min_leaf, before.occupied_max_leaf) = (before.scene_min_leaf, before.scene_max_leaf);
    let light = vec![LeafLightGpu::default(); scene.leaves.len()];
    let cpu = CpuScene::mip(&scene, &light);
    let stride = (scene.leaves.len() / 2000).max(1);
    let leaf_m = f64::from(scene.leaf_size_m);
    let (lo, hi) = scene.occupied_bounds_leaf();
    let (tiles_lo, tiles_hi) = scene.bounds_leaf();
    println!(
        "{path}: {} leaves of {:.3} m, every {stride}th; {} cones; box of the matter {:.0?} m of the tiles' {:.0?} m",
        scene.leaves.len(),
        leaf_m,
        now.cone_count,
        ((hi - lo) * scene.leaf_size_m).to_array(),
        ((tiles_hi - tiles_lo) * scene.leaf_size_m).to_array()
    );
    for (name, p) in [("tiles' cubes (before)", before), ("box of the matter (now)", now)] {
        let (mut samples, mut rock_reads, mut cones, mut farthest) = (0u64, 0u64, 0u64, Vec::new());
        let rock_cell_m = leaf_m * f64::from(1u32 << grotto_runtime::scene::rock::ROCK_LEVEL);
        for i in (0..scene.leaves.len()).step_by(stride) {
            cpu.gather_with(&p, i, |origin, dir, _, rise| {
                let mut far = 0.0f64;
                let out = cpu.trace_cone_observed(&p, origin, dir, rise, |s| {
                    if let MarchStep::Sample { t_m, .. } = s {
                        samples += 1;
                        // rock_on_segment's reads since the last sample (at most 64).
                        rock_reads += ((t_m - far) / rock_cell_m).ceil().clamp(1.0, 64.0) as u64;
                        far = far.max(t_m);
                    }
                });
                cones += 1;
                farthest.push(far);
                out
            });
        }
        farthest.sort_by(f64::total_cmp);
        let at = |q: f64| farthest.get(((farthest.len() as f64 - 1.0) * q) as usize).copied().unwrap_or(0.0);
        println!(
            "stopped at the {name}: {:.1} samples and {:.1} rock reads a cone; farthest sample median {:.1} m, 90% {:.1} m, max {:.1} m",
            samples as f64 / cones.max(1) as f64,
            rock_reads as f64 / cones.max(1) as f64,
            at(0.5),
            at(0.9),
            at(1.0)
        );
    }
    Ok(())
}
