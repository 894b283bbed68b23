//! Helpers for the end-to-end tests: where the shared third-party test data lives, build
//! parameters for small packages, and the golden-image tolerance.

use std::path::{Path, PathBuf};

use grotto_preprocess::build::{BuildParams, ColorCodec};
use grotto_runtime::gpu::GpuOptions;

/// The adapter the end-to-end renders run on: Mesa's software Vulkan driver (lavapipe), so
/// images compare across machines.
pub fn lavapipe() -> GpuOptions {
    GpuOptions { prefer_software: true, backends: Some(wgpu::Backends::VULKAN), ..Default::default() }
}

/// Build parameters for a small test package: 2 threads, a 64 MiB budget, 12.5 cm leaves, raw
/// colours, tiles of `min_tile_m` to `max_tile_m` and a halo of `halo_m`, working in `work_dir`.
pub fn small_build(work_dir: &Path, min_tile_m: f64, max_tile_m: f64, halo_m: f64) -> BuildParams {
    BuildParams {
        work_dir: work_dir.to_path_buf(),
        memory_budget_bytes: 64 << 20,
        threads: 2,
        // The tile cap these packages were built with when it was 3/4 budget / threads / 256 B.
        max_tile_points: 98_304,
        leaf_m: 0.125,
        colors: ColorCodec::Raw,
        min_tile_extent_m: min_tile_m,
        max_tile_extent_m: max_tile_m,
        halo_m,
        ..BuildParams::default()
    }
}

/// `../shared/data` beside the repository (CI puts `shared/` there), or `$GROTTO_SHARED_DATA`.
///
/// Missing data fails the calling test: a test that read nothing must not pass. Only where
/// `GROTTO_SKIP_SHARED_DATA=1` says so (a checkout without `../shared`) is this `None`, and the
/// caller skips, saying so.
pub fn shared_data_dir() -> Option<PathBuf> {
    let p = match std::env::var_os("GROTTO_SHARED_DATA") {
        Some(p) => PathBuf::from(p),
        None => PathBuf::from(env!("CARGO_MANIFEST_DIR")).join("../../shared/data"),
    };
    if p.is_dir() {
        return Some(p);
    }
    if std::env::var_os("GROTTO_SKIP_SHARED_DATA").is_some_and(|v| v == "1") {
        eprintln!("skipped: {} is missing and GROTTO_SKIP_SHARED_DATA=1", p.display());
        return None;
    }
    panic!(
        "{} is missing: put the shared test data there, point GROTTO_SHARED_DATA at it, or set \
         GROTTO_SKIP_SHARED_DATA=1 to skip the tests that read it",
        p.display()
    );
}

/// Golden images: the one tolerance every image comparison uses.
pub mod golden;
/// A static server with HTTP ranges, for the browser test.
pub mod serve;
