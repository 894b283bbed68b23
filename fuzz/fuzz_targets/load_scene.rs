//! Fuzzes the runtime's loading of a package into its scene (package bytes -> `SceneData`, no
//! GPU): SVO views, surfel colours, lights, materials, the environment chain and the rock table.
//! Any bytes may fail; none may panic, hang, or allocate beyond what the input justifies.
//! Each input is tried as is and with its checksums recomputed (reseal.rs).
#![no_main]

use grotto_format::Package;
use grotto_runtime::scene_data::SceneData;
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
    }
}
