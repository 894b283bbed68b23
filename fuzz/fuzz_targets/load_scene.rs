//! Fuzzes the runtime's loading of a package into its scene (package bytes -> `SceneData`, no
//! GPU): SVO views, surfel colours, lights, materials, the environment chain and the rock table;
//! residency's per-tile costs and choice, coarse tiles, and the tile index.
//! Any bytes may fail; none may panic, hang, or allocate beyond what the input justifies.
//! Each input is tried as is and with its checksums recomputed (reseal.rs).
#![no_main]

use grotto_format::Package;
use grotto_runtime::stream::residency::{self, Budget, View};
use grotto_runtime::scene::data::{SceneData, TileMode};
use grotto_runtime::scene::tile_index::TileIndex;
use libfuzzer_sys::fuzz_target;

#[path = "reseal.rs"]
mod reseal;
use reseal::reseal;

fuzz_target!(|data: &[u8]| {
    load(data);
    if let Some(resealed) = reseal(data) {
        load(&resealed);
    }
});

fn load(data: &[u8]) {
    let Ok(pkg) = Package::from_bytes("fuzz.grotto", data) else { return };
    if let Ok(scene) = SceneData::from_package(&pkg) {
        // What the renderer sizes its buffers from.
        let _ = scene.buffer_bytes(false);
        let _ = scene.nodes_by_height();
        let _ = TileIndex::build("fuzz", &scene.tiles);
    }
    // Residency over a budget of half the package: every other tile coarse or full as chosen.
    let Ok(tiles) = residency::footprints(&pkg, false) else { return };
    let full: u64 = tiles.iter().map(|t| t.full.bytes).sum();
    let view = View {
        eye_m: glam::Vec3::ZERO,
        forward: glam::Vec3::X,
        up: glam::Vec3::Z,
        fov_y_rad: 1.0,
        aspect: 1.5,
        lights_m: Vec::new(),
        light_reach_m: 4.0,
        clip: None,
    };
    if let Ok(r) =
        residency::choose(&tiles, &view, Budget { gpu_bytes: full / 2, points: u64::MAX, pools: None })
    {
        if let Ok(scene) = SceneData::from_package_with(&pkg, r.mode_of()) {
            let _ = scene.nodes_by_height();
            let _ = TileIndex::build("fuzz", &scene.tiles);
        }
    }
    let _ = SceneData::from_package_with(&pkg, |i| match i % 3 {
        0 => TileMode::Coarse,
        1 => TileMode::Far,
        _ => TileMode::Skip,
    });
}
