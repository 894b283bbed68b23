//! Fuzzes the package reader: any bytes may fail to open, but opening, reading every section,
//! verifying and summarising must never panic, hang, or allocate beyond what the input justifies.
//!
//! Each input is tried twice: as is, and with its header and table checksums recomputed, so that
//! mutations reach the structural checks behind the checksums instead of stopping at them.
#![no_main]

use grotto_format::spec::SvoNode;
use grotto_format::{Package, SectionKind};
use libfuzzer_sys::fuzz_target;

#[path = "reseal.rs"]
mod reseal;
use reseal::reseal;

fuzz_target!(|data: &[u8]| {
    exercise(data);
    if let Some(resealed) = reseal(data) {
        exercise(&resealed);
    }
});

fn exercise(data: &[u8]) {
    let Ok(pkg) = Package::from_bytes("fuzz.grotto", data) else { return };
    let sections: Vec<_> = pkg.sections().collect();
    for s in &sections {
        let _ = pkg.read_bytes(s);
    }
    let _ = pkg.verify();
    let _ = pkg.summary();
    let _ = pkg.scene();
    let _ = pkg.provenance();
    for t in pkg.tiles() {
        let _ = t.read::<SvoNode>(SectionKind::SvoNodes);
        let _ = t.surfels();
        let _ = t.surfel_count_from_table();
        let _ = t.read::<f32>(SectionKind::LeafOpacity);
        let _ = t.svo();
        for k in 0..8 {
            let _ = t.coarse(k);
        }
        let _ = t.rock();
    }
}
