//! Checked views of a package's section table and tile directory entries.

use crate::spec::*;

/// Tile directory fields the caller provides; section references are filled in by the writer (`PackageWriter`).
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct TileInfo {
    pub origin_m: [f64; 3],
    pub extent_m: f64,
    pub grid: [i32; 3],
    pub depth: u32,
    pub point_count: u64,
}

/// A validated section-table entry.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub struct SectionInfo {
    /// Position in the section table.
    pub index: u32,
    /// `None` for kinds this reader does not know (they are skipped, not errors).
    pub kind: Option<SectionKind>,
    pub kind_raw: u32,
    /// Always `Some` for known kinds.
    pub codec: Option<Codec>,
    pub scope: Scope,
    pub item: u32,
    pub offset: u64,
    pub stored_len: u64,
    pub raw_len: u64,
    pub checksum: u64,
}

impl SectionInfo {
    pub(crate) fn from_raw(index: u32, e: &RawSectionEntry) -> Self {
        Self {
            index,
            kind: SectionKind::from_u32(e.kind),
            kind_raw: e.kind,
            codec: Codec::from_u32(e.codec),
            scope: if e.tile == GLOBAL { Scope::Global } else { Scope::Tile(e.tile) },
            item: e.item,
            offset: e.offset,
            stored_len: e.stored_len,
            raw_len: e.raw_len,
            checksum: e.checksum,
        }
    }

    /// Human-readable kind, `unknown(N)` for kinds from a newer writer.
    pub fn kind_name(&self) -> String {
        self.kind.map_or_else(|| format!("unknown({})", self.kind_raw), |k| k.name().to_owned())
    }
}
