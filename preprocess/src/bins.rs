//! What tiling leaves on disk for the tile builds: the plan (`WORK/plan.json`: tiles, scanner
//! positions, a fingerprint of inputs and parameters) and each tile's bin files of
//! [`BinPoint`]s, one per distribute worker, merged back into scan order by [`read_bin`].

use std::path::{Path, PathBuf};

use bytemuck::{Pod, Zeroable};
use serde::{Deserialize, Serialize};

use crate::manifest::SeenFrom;
use crate::{Error, Result};

/// One point in a tile bin. 24 bytes; keep in sync with `docs/architecture.md`.
#[repr(C)]
#[derive(Clone, Copy, Debug, PartialEq, Pod, Zeroable)]
pub struct BinPoint {
    /// Position relative to the tile origin, in quanta (`TilePlan::quantum_m`); negative or past
    /// the extent only for halo copies.
    pub(crate) pos_q: [i32; 3],
    /// Input normal in the world frame as snorm16, or zero when the scan had none.
    pub(crate) normal_snorm: [i16; 3],
    /// sRGB colour.
    pub(crate) rgb: [u8; 3],
    /// Bit 0: halo copy (belongs to a neighbour tile).
    pub flags: u8,
    /// Index of the scan the point came from (for its scanner position).
    pub scan: u16,
}

const _: () = assert!(size_of::<BinPoint>() == 24);

/// [`BinPoint::flags`] bit of a halo copy (a neighbour tile's point).
pub const FLAG_HALO: u8 = 1;

impl BinPoint {
    /// Tile-local position in metres (exact: quanta are powers of two and tiles < 2^24 quanta).
    pub fn pos_tile_m(&self, quantum_m: f64) -> [f32; 3] {
        self.pos_q.map(|q| (f64::from(q) * quantum_m) as f32)
    }
}

#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
/// One tile of the plan.
pub struct PlannedTile {
    /// Extent = min_extent * 2^level.
    pub level: u32,
    /// Cell index at that level, relative to the grid anchor.
    pub(crate) key: [i64; 3],
    /// Points owned by the tile (halo excluded).
    pub points: u64,
}

/// The result of tiling: what the tiles are and where their bins are.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub struct TilePlan {
    pub fingerprint: String,
    pub min_extent_m: f64,
    pub quantum_m: f64,
    /// Fine-grid cell of the grid origin.
    pub anchor: [i64; 3],
    pub tiles: Vec<PlannedTile>,
    pub points: u64,
    /// Points dropped for non-finite coordinates.
    pub invalid_points: u64,
    /// Halo copies written.
    pub halo_points: u64,
    /// Scanner positions (world), by scan index in the bins.
    pub scanners_world_m: Vec<[f64; 3]>,
    /// Whether each scan's scanner position is known (`ResolvedScan::scanner_known`); normals of
    /// the others are oriented by enclosure. Empty in plans from before this field: all known.
    #[serde(default)]
    pub scanner_known: Vec<bool>,
    /// Whether each scan without a scanner was seen from outside its surface
    /// (`ResolvedScan::seen_from`). Empty in plans from before this field: all inside.
    #[serde(default)]
    pub seen_from_outside: Vec<bool>,
    /// How many workers wrote the bins, each its own file per tile (`bin_path`); a tile's points
    /// are the files' points in scan order. 0 in plans from before this field: one file.
    #[serde(default)]
    pub bin_writers: usize,
    pub bins_complete: bool,
}

impl TilePlan {
    /// Whether any scan lacks a scanner position (its normals need the orientation grid).
    pub(crate) fn needs_orientation(&self) -> bool {
        self.scanner_known.iter().any(|k| !k)
    }

    /// How scan `scan`'s normals are oriented: `None` toward its scanner (known, or a scan index
    /// from before `scanner_known` was stored), else by enclosure, from the side it was seen from.
    pub(crate) fn seen_from(&self, scan: usize) -> Option<SeenFrom> {
        let known = self.scanner_known.get(scan).copied().unwrap_or(true);
        let outside = self.seen_from_outside.get(scan).copied().unwrap_or(false);
        (!known).then_some(if outside { SeenFrom::Outside } else { SeenFrom::Inside })
    }

    /// Edge of `tile`'s cube, metres.
    pub fn extent_m(&self, tile: &PlannedTile) -> f64 {
        self.min_extent_m * f64::from(1u32 << tile.level)
    }

    /// World position of the grid origin.
    pub fn grid_origin_m(&self) -> [f64; 3] {
        self.anchor.map(|a| a as f64 * self.min_extent_m)
    }

    /// The world position (f64, metres) of `tile`'s origin.
    pub fn origin_m(&self, tile: &PlannedTile) -> [f64; 3] {
        let g = self.grid_origin_m();
        let e = self.extent_m(tile);
        std::array::from_fn(|a| g[a] + tile.key[a] as f64 * e)
    }
}

/// The bin of `tile` written by distribute worker `writer` (the first worker's is the only one
/// in work directories from before there were several).
pub fn bin_path(work_dir: &Path, tile: usize, writer: usize) -> PathBuf {
    let name = if writer == 0 { format!("{tile:07}.bin") } else { format!("{tile:07}.w{writer}.bin") };
    work_dir.join("bins").join(name)
}

/// Reads one tile's points: every worker's file, in scan order (each scan was distributed by one
/// worker, in file order, so this is the order one worker would have written).
pub fn read_bin(work_dir: &Path, plan: &TilePlan, tile: usize) -> Result<Vec<BinPoint>> {
    let mut points = Vec::new();
    for writer in 0..plan.bin_writers.max(1) {
        let path = bin_path(work_dir, tile, writer);
        let bytes = match std::fs::read(&path) {
            Ok(b) => b,
            Err(e) if e.kind() == std::io::ErrorKind::NotFound => continue,
            Err(source) => return Err(Error::Io { path, source }),
        };
        if bytes.len() % size_of::<BinPoint>() != 0 {
            return Err(Error::Io {
                path,
                source: std::io::Error::new(
                    std::io::ErrorKind::InvalidData,
                    "bin is not whole points (interrupted write?)",
                ),
            });
        }
        points.extend(bytemuck::pod_collect_to_vec::<u8, BinPoint>(&bytes));
    }
    if plan.bin_writers > 1 {
        // Stable, and each file is already in scan order: a merge of a few runs.
        points.sort_by_key(|p| p.scan);
    }
    Ok(points)
}
