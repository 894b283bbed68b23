//! Where the reference's bounce rays go first, on the surfels the accuracy report path traces: the
//! share that meets the back of a disc within that disc's own radius (a ray that has just left the
//! surface meeting an overlapping neighbour that stands in front of its start: scanned surfels are
//! drawn at `splat_scale` times their radius so that they close, and where the surface bends
//! away or its points are noisy a neighbour's plane passes in front of the front-most one), the
//! share that meets a back face farther away, and the share that leaves every disc: a
//! check that the reference does not lose (or find) light between its own discs.
//!
//! `cargo run --release -p grotto-reference --example self_hits [scene ...]` (scenes: passage,
//! bunny, demo cave, furnace, colour box, dogleg; all of them by default).
//!
//! Each ray starts where a ray coming down a random disc's normal from a leaf above first meets
//! the surfels (the front-most disc there, as a camera ray or a bounce finds it), a hair off the
//! surface along the normal that faces that ray, as the path tracer starts its bounces, and goes
//! out cosine-distributed about that normal.
use grotto_reference::accuracy;
use grotto_reference::{SurfelScene, cosine_sample};
use grotto_runtime::scene::data::SceneData;
use grotto_runtime::settings::{Quality, Settings};
use rand::{Rng, SeedableRng};

const RAYS: usize = 200_000;

fn scene(name: &str) -> anyhow::Result<SceneData> {
    accuracy::scene_named(name).map_err(|e| anyhow::anyhow!("{name}: {e}"))
}

fn main() -> anyhow::Result<()> {
    let args: Vec<String> = std::env::args().skip(1).collect();
    let names: Vec<&str> = if args.is_empty() {
        vec!["passage", "bunny", "demo cave", "furnace", "colour box", "dogleg"]
    } else {
        args.iter().map(String::as_str).collect()
    };
    println!("| scene | discs | rays | back within its radius | back farther | left every disc |");
    println!("|---|---:|---:|---:|---:|---:|");
    for name in names {
        let data = scene(name)?;
        let traced = SurfelScene::from_scene(&data, Settings::preset(Quality::Balanced).splat_scale);
        let discs = traced.discs();
        let leaf = data.leaf_size_m;
        let hair = 1e-3 * leaf;
        let mut rng = rand::rngs::SmallRng::seed_from_u64(1);
        let (mut rays, mut own_back, mut far_back, mut left) = (0usize, 0usize, 0usize, 0usize);
        for _ in 0..RAYS {
            let seed = &discs[rng.random_range(0..discs.len())];
            let above = seed.center_m() + seed.normal * leaf;
            let Some((t0, j)) = traced.intersect(above, -seed.normal, 2.0 * leaf) else { continue };
            let n = if discs[j].normal.dot(seed.normal) >= 0.0 { discs[j].normal } else { -discs[j].normal };
            let o = above - seed.normal * t0 + n * hair;
            let d = cosine_sample(n, rng.random(), rng.random());
            rays += 1;
            match traced.intersect(o, d, f32::INFINITY) {
                None => left += 1,
                Some((t, k)) if discs[k].normal.dot(d) > 0.0 => {
                    if t < discs[k].radius_m() {
                        own_back += 1;
                    } else {
                        far_back += 1;
                    }
                }
                Some(_) => {}
            }
        }
        let share = |k: usize| format!("{:.2}%", 100.0 * k as f64 / rays.max(1) as f64);
        println!(
            "| {name} | {} | {rays} | {} | {} | {} |",
            discs.len(),
            share(own_back),
            share(far_back),
            share(left)
        );
    }
    Ok(())
}
