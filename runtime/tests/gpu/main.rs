//! GPU passes on the shared test device (software adapter first), one binary with a module a
//! subsystem: the gather against the CPU reference, the furnace and bounces, the frame and its
//! plan, environment light, many lights.

mod environment;
mod frame;
mod furnace;
mod gather;
mod lights;

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
