//! A description of a package for people and scripts (`grotto inspect`): version, tiles, bounds,
//! and per-kind sizes and compression ratios. Built from the table and directory alone, so it costs
//! what opening costs.

use std::collections::BTreeMap;

use serde::Serialize;

use crate::reader::Package;
use crate::spec::{Codec, Scope};

#[derive(Clone, Debug, Serialize)]
/// What `grotto inspect` prints of a package: version, size, tiles, sections by kind.
pub struct Summary {
    pub path: String,
    pub version: String,
    pub file_size: u64,
    pub tiles: TileSummary,
    /// One row per section kind (unknown kinds by number).
    pub kinds: Vec<KindSummary>,
    pub sections: Vec<SectionSummary>,
    /// Bytes the sections would take uncompressed / bytes they take in the file.
    pub compression_ratio: f64,
}

#[derive(Clone, Debug, Serialize)]
/// One tile of a [`Summary`].
pub struct TileSummary {
    pub count: u32,
    pub points: u64,
    pub min_depth: Option<u32>,
    pub max_depth: Option<u32>,
    /// World-space bounds of all tiles, metres.
    pub bounds_min_m: Option<[f64; 3]>,
    pub bounds_max_m: Option<[f64; 3]>,
}

#[derive(Clone, Debug, Serialize)]
/// The sections of one kind, added up.
pub struct KindSummary {
    pub kind: String,
    pub sections: u32,
    pub zstd_sections: u32,
    pub stored_bytes: u64,
    pub raw_bytes: u64,
    pub ratio: f64,
}

#[derive(Clone, Debug, Serialize)]
/// One section of a [`Summary`], as `grotto inspect --sections` lists it.
pub struct SectionSummary {
    pub index: u32,
    pub kind: String,
    /// "global" or the tile index.
    pub scope: String,
    pub item: u32,
    pub codec: String,
    pub offset: u64,
    pub stored_bytes: u64,
    pub raw_bytes: u64,
}

fn ratio(raw: u64, stored: u64) -> f64 {
    if stored == 0 { 1.0 } else { raw as f64 / stored as f64 }
}

impl Package {
    /// The package described from its tables, without reading any payload.
    pub fn summary(&self) -> Summary {
        let mut kinds: BTreeMap<(u32, String), KindSummary> = BTreeMap::new();
        let mut sections = Vec::with_capacity(self.section_count() as usize);
        let (mut stored_total, mut raw_total) = (0u64, 0u64);
        for s in self.sections() {
            let name = s.kind_name();
            let k = kinds.entry((s.kind_raw, name.clone())).or_insert_with(|| KindSummary {
                kind: name.clone(),
                sections: 0,
                zstd_sections: 0,
                stored_bytes: 0,
                raw_bytes: 0,
                ratio: 1.0,
            });
            k.sections += 1;
            k.zstd_sections += u32::from(s.codec == Some(Codec::Zstd));
            k.stored_bytes += s.stored_len;
            k.raw_bytes += s.raw_len;
            stored_total += s.stored_len;
            raw_total += s.raw_len;
            sections.push(SectionSummary {
                index: s.index,
                kind: name,
                scope: match s.scope {
                    Scope::Global => "global".into(),
                    Scope::Tile(t) => t.to_string(),
                },
                item: s.item,
                codec: s.codec.map_or_else(|| "unknown".into(), |c| c.name().into()),
                offset: s.offset,
                stored_bytes: s.stored_len,
                raw_bytes: s.raw_len,
            });
        }
        let kinds = kinds
            .into_values()
            .map(|mut k| {
                k.ratio = ratio(k.raw_bytes, k.stored_bytes);
                k
            })
            .collect();
        let mut tiles = TileSummary {
            count: self.tile_count(),
            points: 0,
            min_depth: None,
            max_depth: None,
            bounds_min_m: None,
            bounds_max_m: None,
        };
        for t in self.tiles() {
            tiles.points += t.point_count();
            tiles.min_depth = Some(tiles.min_depth.map_or(t.depth(), |d| d.min(t.depth())));
            tiles.max_depth = Some(tiles.max_depth.map_or(t.depth(), |d| d.max(t.depth())));
            let lo = t.origin_m();
            let hi = lo.map(|v| v + t.extent_m());
            let min = tiles.bounds_min_m.get_or_insert(lo);
            let max = tiles.bounds_max_m.get_or_insert(hi);
            for a in 0..3 {
                min[a] = min[a].min(lo[a]);
                max[a] = max[a].max(hi[a]);
            }
        }
        let (major, minor) = self.version();
        Summary {
            path: self.path().display().to_string(),
            version: format!("{major}.{minor}"),
            file_size: self.file_size(),
            tiles,
            kinds,
            sections,
            compression_ratio: ratio(raw_total, stored_total),
        }
    }
}

/// A size as people write it on a command line ("2G", "512M", "64k", "1.5G", "4096"; binary
/// multiples), for the budgets both binaries take (`--memory-budget`, `--gpu-memory`).
pub fn parse_bytes(s: &str) -> Result<u64, String> {
    let s = s.trim();
    let (num, mult) = match s.chars().last() {
        Some('k' | 'K') => (&s[..s.len() - 1], 1u64 << 10),
        Some('m' | 'M') => (&s[..s.len() - 1], 1 << 20),
        Some('g' | 'G') => (&s[..s.len() - 1], 1 << 30),
        Some('t' | 'T') => (&s[..s.len() - 1], 1 << 40),
        _ => (s, 1),
    };
    let v: f64 = num.parse().map_err(|_| format!("'{s}' is not a size like 2G or 512M"))?;
    if !(v > 0.0 && v * (mult as f64) < 2f64.powi(63)) {
        return Err(format!("'{s}' must be a positive size"));
    }
    Ok((v * mult as f64) as u64)
}

#[cfg(test)]
mod size_tests {
    #[test]
    fn sizes_parse_as_written() {
        assert_eq!(super::parse_bytes("512M"), Ok(512 << 20));
        assert_eq!(super::parse_bytes("1.5g"), Ok(3 << 29));
        assert_eq!(super::parse_bytes("4096"), Ok(4096));
        assert!(super::parse_bytes("-1G").is_err());
        assert!(super::parse_bytes("lots").is_err());
        assert!(super::parse_bytes("NaNG").is_err());
    }
}
