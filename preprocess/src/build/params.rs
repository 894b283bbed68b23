//! The build's parameters and their defaults: leaf and tile sizes, the memory budget, the codecs.

use std::path::PathBuf;

use serde::Serialize;

use crate::Result;
use crate::manifest::ResolvedScan;
use crate::tiling::TilingParams;

/// Upper bound of what building one tile holds per input point: bin (24), the kNN's sorted
/// points, codes, order and cell tables (~28), neighbour lists (k=16: 64), normals, radii and
/// scores in f64 (40), surfels and colours (36), SVO samples (48) and sort keys (16); peak
/// memory is measured in docs/benchmarks.md.
pub const BUILD_BYTES_PER_POINT: u64 = 256;

/// Default of [`BuildParams::max_tile_points`]: 2^21 points, 512 MiB to build at
/// [`BUILD_BYTES_PER_POINT`]. A content option with the same default on every machine (it was
/// the budget divided by the thread count, so two machines built different packages).
pub const DEFAULT_MAX_TILE_POINTS: u64 = 1 << 21;

#[derive(Clone, Debug, Serialize)]
/// What a build makes and how: content options (leaf, tiles, codecs) and resources (threads, memory).
pub struct BuildParams {
    pub work_dir: PathBuf,
    pub memory_budget_bytes: u64,
    pub threads: usize,
    /// A tile is split while it holds more points than this (down to the smallest tile edge):
    /// content, recorded in provenance and in every fingerprint.
    pub max_tile_points: u64,
    /// Edge of a leaf voxel, metres; a power of two <= the smallest tile. Every tile's SVO depth is
    /// `log2(tile extent / leaf)`, so all tiles share one voxel grid.
    pub leaf_m: f64,
    /// How surfel colours are stored.
    pub colors: ColorCodec,
    /// How surfels are stored.
    pub surfels: SurfelCodec,
    /// Window the environment's SH where a bright source would make irradiance negative.
    pub sh_window: bool,
    /// Neighbours for normals.
    pub k: usize,
    pub min_tile_extent_m: f64,
    pub max_tile_extent_m: f64,
    pub halo_m: f64,
    /// Refuse a scan file that ends inside its last point record instead of reading its complete
    /// records and warning (`--strict`).
    pub strict: bool,
    /// Keep the count pass's posed points for the distribute pass (`TilingParams::spill`).
    pub spill: bool,
    /// Keep normals the files carry where they agree with the local plane (`--normals keep`), or
    /// estimate every normal (`--normals estimate`).
    pub keep_input_normals: bool,
}

/// Leaf edge of the cave default, metres; tile extents and halo below are in its leaves (1 m and
/// 64 m tiles, a 0.25 m halo at 6.25 cm leaves).
pub const DEFAULT_LEAF_M: f64 = 0.0625;
/// Smallest tile edge, in leaves (the default `--min-tile-m` is this many leaves).
pub const MIN_TILE_LEAVES: f64 = 16.0;
/// Largest tile edge, in leaves (the default `--max-tile-m`).
pub const MAX_TILE_LEAVES: f64 = 1024.0;
/// Halo around a tile, in leaves (the default `--halo-m`).
pub const HALO_LEAVES: f64 = 4.0;
/// Points per scan the automatic leaf size samples.
pub const SPACING_SAMPLE_POINTS: usize = 100_000;

/// The leaf size chosen from the data (`grotto-pack build --leaf-m auto`).
#[derive(Clone, Copy, Debug, PartialEq, serde::Serialize)]
pub struct AutoLeaf {
    pub leaf_m: f64,
    /// Median nearest-neighbour spacing it was chosen from, and the points sampled.
    pub spacing_m: Option<f64>,
    pub sampled_points: usize,
}

/// The leaf edge for `scans`: the smallest power of two of metres at or above their median point
/// spacing (about one point per leaf face, as the demo cave's 1.2 points per leaf), and never
/// finer than [`DEFAULT_LEAF_M`] (finer leaves cost GI time and memory for detail the surfels
/// already draw). Sparse clouds (airborne strips at metres) get leaves that hold their points
/// together, instead of one isolated point per 6 cm voxel and one per tile.
pub fn auto_leaf(scans: &[ResolvedScan]) -> Result<AutoLeaf> {
    let sample = crate::spacing::sample_spacing_m(scans, SPACING_SAMPLE_POINTS)?;
    let leaf_m = match sample {
        Some((s, _)) if s.is_finite() && s > DEFAULT_LEAF_M => 2f64.powi(s.log2().ceil() as i32),
        _ => DEFAULT_LEAF_M,
    };
    Ok(AutoLeaf { leaf_m, spacing_m: sample.map(|s| s.0), sampled_points: sample.map_or(0, |s| s.1) })
}

/// `grotto-pack build`'s defaults at the default leaf size, working in `./grotto-work`.
impl Default for BuildParams {
    fn default() -> Self {
        Self::with_leaf(PathBuf::from("grotto-work"), DEFAULT_LEAF_M)
    }
}

impl BuildParams {
    /// `grotto-pack build`'s defaults for leaves of `leaf_m`: a 2 GiB memory budget, every core,
    /// BC1 colours, 16 neighbours, tiles of 16 to 1024 leaves and a halo of 4 leaves.
    pub fn with_leaf(work_dir: PathBuf, leaf_m: f64) -> Self {
        BuildParams {
            work_dir,
            memory_budget_bytes: 2 << 30,
            threads: std::thread::available_parallelism().map_or(1, usize::from),
            max_tile_points: DEFAULT_MAX_TILE_POINTS,
            leaf_m,
            colors: ColorCodec::Bc1,
            surfels: SurfelCodec::Compact,
            sh_window: true,
            k: 16,
            min_tile_extent_m: MIN_TILE_LEAVES * leaf_m,
            max_tile_extent_m: MAX_TILE_LEAVES * leaf_m,
            halo_m: HALO_LEAVES * leaf_m,
            strict: false,
            spill: true,
            keep_input_normals: true,
        }
    }

    /// Tiles built at once: the threads, fewer where three quarters of the memory budget do not
    /// hold that many tiles of `max_tile_points` (at least one). How fast, not what.
    pub fn tiles_at_once(&self) -> usize {
        let budget = self.memory_budget_bytes.max(64 << 20);
        let per_tile = self.max_tile_points.max(1).saturating_mul(BUILD_BYTES_PER_POINT);
        ((budget * 3 / 4 / per_tile) as usize).clamp(1, self.threads.max(1))
    }

    pub(crate) fn tiling(&self) -> TilingParams {
        let budget = self.memory_budget_bytes.max(64 << 20);
        TilingParams {
            min_tile_extent_m: self.min_tile_extent_m,
            max_tile_extent_m: self.max_tile_extent_m,
            max_points_per_tile: self.max_tile_points,
            halo_m: self.halo_m,
            // Voxel faces fall on quanta, so voxel cells are exact integer shifts (see tiling.rs).
            quantum_m: self.leaf_m / 2048.0,
            chunk_points: crate::ingest::DEFAULT_CHUNK,
            buffer_bytes: (budget / 4) as usize,
            spill: self.spill,
        }
    }
}

/// Surfel colour storage.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Serialize)]
#[serde(rename_all = "lowercase")]
pub enum ColorCodec {
    /// BC1 blocks of 16 surfels: 0.5 byte per surfel (Intel's ISPC kernel, then texpresso's
    /// cluster fit for the blocks it leaves visibly off: `bc1::Bc1Fit::Refined`).
    Bc1,
    /// The same blocks by the ISPC kernel alone: fastest, 0.3-0.6 dB less PSNR than `Bc1`.
    #[serde(rename = "bc1-fast")]
    Bc1Fast,
    /// The same blocks by the cluster fit alone: the best PSNR, about 40 times slower than ISPC.
    #[serde(rename = "bc1-cluster")]
    Bc1Cluster,
    /// sRGB bytes: 4 bytes per surfel (zstd where it pays).
    Raw,
}

/// Surfel storage.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Serialize)]
#[serde(rename_all = "lowercase")]
pub enum SurfelCodec {
    /// Format 2.0's compact encoding (`grotto_format::compact`, about 6 bytes a surfel after
    /// zstd): positions within 1 mm, normals within 0.05 degrees, radius within 2.2%. A tile whose
    /// surfels those bounds cannot hold (leaves over 75 m) keeps them at full precision.
    Compact,
    /// f32 positions, normals, radius and spread: 32 bytes a surfel, cast in place on load; the
    /// package stays format 1.2 for older readers.
    Full,
}
