//! Shared by the package targets: mutations get past the checksums to the checks behind them.

use grotto_format::spec::RawHeader;
use xxhash_rust::xxh3::{Xxh3, xxh3_64};

/// Recomputes the table checksum (where the claimed ranges are in the file) and the header checksum.
pub fn reseal(data: &[u8]) -> Option<Vec<u8>> {
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
