//! What a bounce costs run whole and in slices (the viewer's light at rest): opens a
//! package, runs its first light update (shadow maps, injection, a bounce), times the next bounce
//! whole, then the same bounce from a fresh renderer in slices of 4,096, 16,384 and 65,536 leaves.
//! `cargo run --release -p grotto-runtime --example bench_slices -- PACKAGE [fast|balanced|high]`
//! (docs/benchmarks.md, "The viewer's frame loop").

use std::time::Instant;

use grotto_runtime::gpu::{Gpu, GpuOptions};
use grotto_runtime::render::Renderer;
use grotto_runtime::settings::{Quality, Settings};

fn main() -> anyhow::Result<()> {
    let mut args = std::env::args().skip(1);
    let path = args.next().ok_or_else(|| anyhow::anyhow!("usage: bench_slices PACKAGE [QUALITY]"))?;
    let quality = args.next().and_then(|q| Quality::parse(&q)).unwrap_or(Quality::Balanced);
    let gpu = Gpu::new(&GpuOptions::default())?;
    let scene = grotto_runtime::engine::load_scene(std::path::Path::new(&path))?;
    let settings = Settings { bounces: 2, convergence_tolerance: 0.0, ..Settings::preset(quality) };
    println!("{path} on {}: {} leaves, {} preset", gpu.describe(), scene.leaves.len(), quality.name());
    let mut r = Renderer::new(&gpu, &scene, settings.clone())?;
    let t = Instant::now();
    r.update_light()?;
    println!("first update (shadow maps, injection, bounce 1): {:.2} s", t.elapsed().as_secs_f64());
    let t = Instant::now();
    r.update_light()?;
    println!("bounce 2 whole: {:.2} s", t.elapsed().as_secs_f64());
    for slice in [4096u32, 16384, 65536] {
        let mut r = Renderer::new(&gpu, &scene, settings.clone())?;
        r.update_light()?;
        let (t, mut calls) = (Instant::now(), 0u32);
        while r.stats().bounces_done < 2 {
            r.update_light_slice(slice)?;
            calls += 1;
        }
        println!("bounce 2 in slices of {slice} leaves: {:.2} s in {calls} calls", t.elapsed().as_secs_f64());
    }
    Ok(())
}
