//! Fuzzes the package reader: any bytes may fail to open, but opening, reading every section,
//! verifying and summarising must never panic, hang, or allocate beyond what the input justifies.
//!
//! Each input is tried twice: as is, and with its header and table checksums recomputed, so that
//! mutations reach the structural checks behind the checksums instead of stopping at them.
#![no_main]

use grotto_format::spec::{RawHeader, Surfel, SvoNode};
use grotto_format::{Package, SectionKind};
use libfuzzer_sys::fuzz_target;
use xxhash_rust::xxh3::{Xxh3, xxh3_64};

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
        let _ = t.read::<Surfel>(SectionKind::Surfels);
        let _ = t.read::<f32>(SectionKind::LeafOpacity);
        let _ = t.svo();
    }
}

/// Recomputes the table checksum (where the claimed ranges are in the file) and the header checksum.
fn reseal(data: &[u8]) -> Option<Vec<u8>> {
    let hs = size_of::<RawHeader>();
    let mut h: RawHeader = bytemuck::pod_read_unaligned(data.get(..hs)?);
    let range = |off: u64, count: u64, size: u64| {
        let end = off.checked_add(count.checked_mul(size)?)?;
        (end <= data.len() as u64).then_some(off as usize..end as usize)
    };
    let mut out = data.to_vec();
    if let (Some(t), Some(d)) =
        (range(h.section_table_offset, h.section_count, 48), range(h.tile_directory_offset, h.tile_count, 64))
    {
        let mut x = Xxh3::new();
        x.update(&data[t]);
        x.update(&data[d]);
        h.table_checksum = x.digest();
    }
    h.header_checksum = 0;
    out[..hs].copy_from_slice(bytemuck::bytes_of(&h));
    let end = (h.header_size as usize).clamp(hs, out.len());
    h.header_checksum = xxh3_64(&out[..end]);
    out[..hs].copy_from_slice(bytemuck::bytes_of(&h));
    Some(out)
}
