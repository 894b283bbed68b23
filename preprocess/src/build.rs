//! `grotto-pack build`: scans + manifest in, one `.grotto` package out.
//!
//! Three steps, each resumable (the brief's plan / build-tile / assemble jobs):
//! 1. plan: resolve scans and tile them out of core ([`crate::tiling`]);
//! 2. build-tile: per tile, in parallel batches of tiles: normals, spread and radii
//!    ([`crate::normals`]), surfels in Morton order, colours -> a one-tile package
//!    `WORK/tiles/NNNNNNN.grotto`, whose provenance carries a fingerprint of the plan and the
//!    build parameters. A tile package with the right fingerprint is kept, not rebuilt, so an
//!    interrupted run resumes where it stopped;
//! 3. assemble: the tile packages' sections are copied as stored (checksums checked) into the
//!    output, in plan order, with scene and provenance; the output is written atomically and is
//!    the same for the same input whatever the thread count.
//!
//! The package depends only on the inputs and the options that change its content (leaf, tile
//! extents, `max_tile_points`, normals, colours...), never on the thread count, the memory budget
//! or how the tiles were split into shards: those change how fast and in how many passes the work
//! runs. Memory: the tiler's buffers take a quarter of the budget; each tile being built costs
//! about [`BUILD_BYTES_PER_POINT`] per point, so the budget bounds how many tiles are built at
//! once ([`BuildParams::tiles_at_once`]), not how large a tile is.

use std::path::{Path, PathBuf};

use grotto_format::spec::{Rgba8, Surfel};
use grotto_format::svo::morton_encode;
use grotto_format::{
    Compression, InputFile, LightShape, Package, PackageWriter, Provenance, Scene, Scope, SectionKind,
    TileInfo,
};
use rayon::prelude::*;
use serde::Serialize;

use crate::bc1;
use crate::bins::{self, FLAG_HALO, TilePlan};
use crate::ingest::ScanFormat;
use crate::manifest::{Manifest, ResolvedScan, SeenFrom};
use crate::normals::{self, NormalStats, Orient, TilePoints};
use crate::orient::{self, CaveGrid, OrientStats};
use crate::profile::{Profile, Stage, StageTime};
use crate::tiling::{self, Progress, TilingParams};
use crate::voxels::{self, Sample, TileSvo};
use crate::{Error, Result};
use grotto_format::compact;

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
pub const MIN_TILE_LEAVES: f64 = 16.0;
pub const MAX_TILE_LEAVES: f64 = 1024.0;
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

    pub fn tiling(&self) -> TilingParams {
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

#[derive(Clone, Debug, Serialize)]
pub struct BuildSummary {
    pub package: String,
    pub scans: usize,
    pub points: u64,
    pub invalid_points: u64,
    pub halo_points: u64,
    pub tiles: usize,
    pub bytes: u64,
    pub seconds: f64,
    /// Whether the tiling was reused from an interrupted or earlier run.
    pub resumed_tiling: bool,
    /// Tiles whose tile package from an earlier run was kept.
    pub reused_tiles: usize,
    /// Points near a tile border whose normal neighbourhood may reach past the halo (raise
    /// `halo_m` if this is large: voxels there can differ from a build with bigger tiles).
    pub seam_limited_points: u64,
    /// Peak resident memory of the process (Linux), bytes.
    pub peak_rss_bytes: Option<u64>,
    /// Leaf voxel edge the package was built with, metres.
    pub leaf_m: f64,
    /// What the package's scene holds: lights, cameras, an environment map.
    pub lights: usize,
    pub cameras: usize,
    pub environment: bool,
    /// Scan files that end inside their last point record, read without it:
    /// "path: N points dropped" (`--strict` refuses them instead).
    pub cut_short: Vec<String>,
    /// Scans with no scanner position (no `origin`, no pose): a merged cloud.
    pub scans_without_scanner: usize,
    /// Of those, the scans seen from outside their surface (`seen_from = "outside"`,
    /// `--seen-from outside`): their normals face away from what the walls enclose.
    pub scans_seen_from_outside: usize,
    /// Points whose file carried a normal, and how many of those were kept (`--normals keep`
    /// keeps those within 60 degrees of the local plane's normal; the rest are estimated).
    pub input_normals: u64,
    pub input_normals_kept: u64,
    pub keep_input_normals: bool,
    /// What orienting their normals by enclosure did (docs/manifest.md, "Scans without scanner
    /// positions").
    pub orientation: Option<OrientStats>,
    /// Wall seconds of the three steps (zero for a step this run did not do).
    pub steps: StepSeconds,
    /// Seconds per stage ([`crate::profile`]); the tile stages' are summed over tiles built at once.
    pub stages: Vec<StageTime>,
}

/// Wall seconds of a build's steps.
#[derive(Clone, Copy, Debug, Default, Serialize)]
pub struct StepSeconds {
    pub plan: f64,
    pub tiles: f64,
    pub assemble: f64,
}

impl BuildSummary {
    /// What the package lacks for a first render, and how to add it (the runtime copes: it frames
    /// the data and carries a headlamp, but says so).
    pub fn hints(&self) -> Vec<String> {
        let mut h = Vec::new();
        if self.lights == 0 && !self.environment {
            h.push(
                "no lights and no environment map: `grotto render` will light the view with a headlamp \
                 at the camera; add [[light]] entries (or [environment]) to a manifest (docs/manifest.md)"
                    .to_string(),
            );
        }
        if self.input_normals > 0 {
            h.push(format!(
                "{} points carried normals in their files: {} kept (they agree with the local plane), the \
                 rest estimated{}",
                self.input_normals,
                self.input_normals_kept,
                if self.keep_input_normals {
                    " (--normals estimate ignores them all)"
                } else {
                    " (--normals estimate)"
                }
            ));
        }
        if let Some(o) = &self.orientation {
            let side = match (self.scans_seen_from_outside, self.scans_without_scanner) {
                (0, _) => "toward the side their walls enclose (seen from inside, as a cave; \
                           --seen-from outside for an object scanned from around it)"
                    .to_string(),
                (o, n) if o == n => "away from what their surface encloses (seen from outside)".to_string(),
                (o, _) => format!(
                    "toward the side their walls enclose, or away from it for the {o} seen from outside"
                ),
            };
            h.push(format!(
                "{} scan(s) have no scanner position (no `origin =`, no pose): the normals of their {} points \
                 were oriented {side} ({} turned away from the scan frame's \
                 origin, {} set by their neighbours against their own votes, {} without evidence turned \
                 up, mean confidence {:.2}); give `origin =` per scan in a manifest where scanner positions \
                 are known (docs/manifest.md)",
                self.scans_without_scanner,
                o.points,
                o.flipped,
                o.corrected,
                o.undecided,
                o.mean_confidence()
            ));
        }
        for c in &self.cut_short {
            h.push(format!(
                "{c}: the file ends inside its last point record (a copy cut short?); the complete \
                 records were read (--strict refuses such files)"
            ));
        }
        if self.cameras == 0 {
            h.push(
                "no cameras: `grotto render` will frame a view on the data and print it; add [[camera]] \
                 entries to a manifest (docs/manifest.md), or render with --eye/--look-at"
                    .to_string(),
            );
        }
        h
    }
}

/// One tile's sections, built off the writer thread.
struct BuiltTile {
    info: TileInfo,
    /// Own points near the border whose k-neighbourhood may reach past the halo.
    seam_limited: u64,
    /// File normals kept and orientation without a scanner in this tile.
    normals: NormalStats,
    surfels: Vec<Surfel>,
    /// Index of each surfel's scan (in the plan's scan order), surfel order.
    scans: Vec<u16>,
    colors: Vec<[u8; 3]>,
    svo: TileSvo,
}

/// Depth of a tile's SVO for the build's leaf size.
fn tile_depth(extent_m: f64, leaf_m: f64) -> Result<u32> {
    let ratio = (extent_m / leaf_m).log2();
    if ratio < 0.0 || ratio.fract() != 0.0 || ratio > f64::from(grotto_format::spec::MAX_SVO_DEPTH) {
        return Err(Error::Parameter {
            name: "leaf_m",
            reason: format!("{leaf_m} m leaves do not divide a {extent_m} m tile into 2^0..2^21 cells"),
        });
    }
    Ok(ratio as u32)
}

/// Emissive samples of the scene's area lights that fall inside a tile, spaced half a leaf apart.
/// A Lambertian emitter of power P and area A has radiance P / (pi A).
fn area_light_samples(scene: &Scene, origin: [f64; 3], extent: f64, leaf_m: f64) -> Vec<Sample> {
    let mut out = Vec::new();
    for light in &scene.lights {
        let LightShape::Area { center_m, normal, size_m } = light.shape else { continue };
        let n = normal.map(f64::from);
        let nl = (n[0] * n[0] + n[1] * n[1] + n[2] * n[2]).sqrt();
        let positive = |v: f64| v.is_finite() && v > 0.0;
        if !positive(nl) || !size_m.iter().all(|&s| positive(f64::from(s))) {
            continue;
        }
        let n = n.map(|c| c / nl);
        let helper = if n[2].abs() < 0.9 { [0.0, 0.0, 1.0] } else { [1.0, 0.0, 0.0] };
        let cross = |a: [f64; 3], b: [f64; 3]| {
            [a[1] * b[2] - a[2] * b[1], a[2] * b[0] - a[0] * b[2], a[0] * b[1] - a[1] * b[0]]
        };
        let t1 = cross(helper, n);
        let l1 = (t1[0] * t1[0] + t1[1] * t1[1] + t1[2] * t1[2]).sqrt();
        let t1 = t1.map(|c| c / l1);
        let t2 = cross(n, t1);
        let area = f64::from(size_m[0]) * f64::from(size_m[1]);
        let radiance = light
            .color
            .map(|c| (f64::from(c) * f64::from(light.power_w) / (std::f64::consts::PI * area)) as f32);
        let step = leaf_m / 2.0;
        let (nu, nv) = (
            (f64::from(size_m[0]) / step).ceil().max(1.0) as usize,
            (f64::from(size_m[1]) / step).ceil().max(1.0) as usize,
        );
        if nu * nv > 4_000_000 {
            continue;
        }
        let (du, dv) = (f64::from(size_m[0]) / nu as f64, f64::from(size_m[1]) / nv as f64);
        for i in 0..nu {
            for j in 0..nv {
                let u = -f64::from(size_m[0]) / 2.0 + (i as f64 + 0.5) * du;
                let v = -f64::from(size_m[1]) / 2.0 + (j as f64 + 0.5) * dv;
                let p: [f64; 3] = std::array::from_fn(|a| center_m[a] + u * t1[a] + v * t2[a] - origin[a]);
                if p.iter().all(|&c| (0.0..extent).contains(&c)) {
                    out.push(Sample {
                        pos_tile_m: p.map(|c| c as f32),
                        normal: n.map(|c| c as f32),
                        area_m2: (du * dv) as f32,
                        albedo_linear: [0.0; 3],
                        emission: radiance,
                    });
                }
            }
        }
    }
    out
}

fn build_tile(
    plan: &TilePlan,
    work_dir: &Path,
    t: usize,
    params: &BuildParams,
    scene: &Scene,
    grid: Option<&CaveGrid>,
    profile: &Profile,
) -> Result<BuiltTile> {
    let tile = &plan.tiles[t];
    let origin = plan.origin_m(tile);
    let extent = plan.extent_m(tile);
    let mut clock = std::time::Instant::now();
    let points = bins::read_bin(work_dir, plan, t)?;
    let quantum = plan.quantum_m;
    let positions: Vec<[f32; 3]> = points.iter().map(|p| p.pos_tile_m(quantum)).collect();
    let own: Vec<bool> = points.iter().map(|p| p.flags & FLAG_HALO == 0).collect();
    let scanner_tile_m: Vec<[f64; 3]> = points
        .iter()
        .map(|p| {
            let s = plan.scanners_world_m[p.scan as usize];
            std::array::from_fn(|a| s[a] - origin[a])
        })
        .collect();
    let input_normals: Vec<[f32; 3]> =
        points.iter().map(|p| p.normal_snorm.map(|c| f32::from(c) / 32767.0)).collect();
    let seen_from: Vec<Option<SeenFrom>> = points.iter().map(|p| plan.seen_from(p.scan as usize)).collect();
    profile.lap(Stage::ReadBins, &mut clock);
    let (estimated, normal_stats) = normals::estimate_with_stats(
        &TilePoints {
            positions: &positions,
            own: &own,
            scanner_tile_m: &scanner_tile_m,
            input_normals: &input_normals,
            isolated_radius_m: 0.5 * params.leaf_m as f32,
            keep_input_normals: params.keep_input_normals,
            orient: grid.map(|grid| Orient { grid, tile_origin_m: origin, seen_from: &seen_from }),
        },
        params.k,
    );
    profile.lap(Stage::Normals, &mut clock);
    let own_points: Vec<&bins::BinPoint> = points.iter().filter(|p| p.flags & FLAG_HALO == 0).collect();
    let q = f64::from(1u32 << 16) / extent;
    let mut order: Vec<(u64, usize)> = own_points
        .iter()
        .enumerate()
        .map(|(i, p)| {
            let c = p.pos_tile_m(quantum).map(|v| (f64::from(v) * q).clamp(0.0, 65_535.0) as u32);
            (morton_encode(c[0], c[1], c[2]), i)
        })
        .collect();
    // Unique keys (index last): the parallel sort gives the one order a single thread would.
    order.par_sort_unstable();
    let surfels = order
        .iter()
        .map(|&(_, i)| Surfel {
            position_tile_m: own_points[i].pos_tile_m(quantum),
            radius_m: estimated[i].radius_m,
            normal: estimated[i].normal,
            spread: estimated[i].spread,
        })
        .collect();
    let colors: Vec<[u8; 3]> = order.iter().map(|&(_, i)| own_points[i].rgb).collect();
    let scans: Vec<u16> = order.iter().map(|&(_, i)| own_points[i].scan).collect();
    // The k-th neighbour distance, undone from the radius; a neighbourhood that reaches past the
    // border by more than the halo may miss points the neighbour tile has (a possible seam).
    let k_reach = |r: f32| f64::from(r) / normals::RADIUS_COVER_FACTOR * (params.k as f64).sqrt();
    let seam_limited = own_points
        .iter()
        .zip(&estimated)
        .filter(|(p, n)| {
            let border = p
                .pos_tile_m(quantum)
                .iter()
                .map(|&c| f64::from(c).min(extent - f64::from(c)))
                .fold(f64::INFINITY, f64::min);
            k_reach(n.radius_m) > border + params.halo_m
        })
        .count() as u64;
    profile.lap(Stage::Surfels, &mut clock);
    let depth = tile_depth(extent, params.leaf_m)?;
    // Each surfel stands for the area its radius was widened from (see normals.rs).
    let cover = normals::RADIUS_COVER_FACTOR;
    let mut samples: Vec<Sample> = order
        .iter()
        .zip(&colors)
        .map(|(&(_, i), c)| {
            let r = f64::from(estimated[i].radius_m) / cover;
            Sample {
                pos_tile_m: own_points[i].pos_tile_m(quantum),
                normal: estimated[i].normal,
                area_m2: (std::f64::consts::PI * r * r) as f32,
                albedo_linear: c.map(grotto_format::color::srgb8_to_linear),
                emission: [0.0; 3],
            }
        })
        .collect();
    samples.extend(area_light_samples(scene, origin, extent, params.leaf_m));
    let svo = voxels::build(&samples, extent, depth);
    profile.lap(Stage::Voxels, &mut clock);
    let grid: [i32; 3] = tile.key.map(|k| i32::try_from(k).unwrap_or(i32::MAX));
    if grid.contains(&i32::MAX) {
        return Err(Error::Parameter {
            name: "tiles",
            reason: format!("tile key {:?} outside the 32-bit grid", tile.key),
        });
    }
    Ok(BuiltTile {
        info: TileInfo { origin_m: origin, extent_m: extent, grid, depth, point_count: tile.points },
        seam_limited,
        normals: normal_stats,
        surfels,
        colors,
        scans,
        svo,
    })
}

/// The one tile of tile package `t`.
fn tile_of_package(package: &Package, t: usize) -> Result<grotto_format::Tile<'_>> {
    package
        .tile(0)
        .ok_or_else(|| Error::Parameter { name: "tiles", reason: format!("tile package {t} has no tile") })
}

pub fn tile_package_path(work_dir: &Path, tile: usize) -> PathBuf {
    work_dir.join("tiles").join(format!("{tile:07}.grotto"))
}

/// How tile packages are written (codecs, sections). Bumped when that changes within one release,
/// so a resumed build does not mix tile packages of two layouts. 2: compact surfels, zstd nodes.
const TILE_PACKAGE_LAYOUT: u32 = 2;

/// What a tile package depends on: the plan (inputs and tiling) and the per-tile parameters.
fn tile_fingerprint(plan: &TilePlan, params: &BuildParams) -> String {
    // Scene lights matter too (area lights become emissive samples); hashed with the parameters.
    format!(
        "{}-k{}-leaf{}-{:?}-{:?}-keep{}-v{}-f{}-t{TILE_PACKAGE_LAYOUT}",
        plan.fingerprint,
        params.k,
        params.leaf_m,
        params.colors,
        params.surfels,
        params.keep_input_normals,
        env!("CARGO_PKG_VERSION"),
        grotto_format::spec::VERSION_MAJOR
    )
}

/// What a finished tile package with this fingerprint recorded (seam-limited points, file normals
/// and orientation), or `None` when it must be built (missing, damaged, other parameters).
fn finished_tile_package(path: &Path, fingerprint: &str) -> Option<(u64, NormalStats)> {
    let prov = Package::open(path).ok()?.provenance().ok()??;
    if prov.parameters.get("tile_fingerprint")?.as_str()? != fingerprint {
        return None;
    }
    let seam = prov.parameters.get("seam_limited_points")?.as_u64()?;
    let normals = serde_json::from_value(prov.parameters.get("normals")?.clone()).ok()?;
    Some((seam, normals))
}

fn write_tile_package(
    path: &Path,
    tile: &BuiltTile,
    fingerprint: &str,
    params: &BuildParams,
    profile: &Profile,
) -> Result<()> {
    let mut clock = std::time::Instant::now();
    let mut w = PackageWriter::create(path)?;
    let index = w.add_tile(tile.info)?;
    let scope = Scope::Tile(index);
    // Surfels are coded in parallel runs (then packed in order) and BC1 blocks in parallel, side
    // by side: a serial compact encoding left a core idle at the end of a batch of tiles. Each
    // stage is timed on its own (summed over tiles, like every tile stage).
    profile.lap(Stage::WriteTiles, &mut clock);
    let leaf_m = tile.info.extent_m / f64::from(1u32 << tile.info.depth);
    let (compact, blocks) = rayon::join(
        || match params.surfels {
            SurfelCodec::Compact => profile.time(Stage::CompactSurfels, || {
                let bound = compact::MAX_POSITION_ERROR_M;
                let mut codes = vec![compact::SurfelCodes::default(); tile.surfels.len()];
                tile.surfels
                    .par_chunks(1 << 16)
                    .zip(codes.par_chunks_mut(1 << 16))
                    .map(|(run, out)| compact::code_surfels(run, leaf_m, tile.info.depth, bound, out))
                    .collect::<Option<Vec<()>>>()?;
                compact::encode_codes(&codes, leaf_m, bound)
            }),
            SurfelCodec::Full => None,
        },
        || match params.colors {
            ColorCodec::Bc1 => {
                Some(profile.time(Stage::Colors, || bc1::encode(&tile.colors, bc1::Bc1Fit::Refined)))
            }
            ColorCodec::Bc1Fast => {
                Some(profile.time(Stage::Colors, || bc1::encode(&tile.colors, bc1::Bc1Fit::Fast)))
            }
            ColorCodec::Bc1Cluster => {
                Some(profile.time(Stage::Colors, || bc1::encode(&tile.colors, bc1::Bc1Fit::Cluster)))
            }
            ColorCodec::Raw => None,
        },
    );
    clock = std::time::Instant::now();
    match compact {
        Some(bytes) => w.add_section(SectionKind::SurfelsCompact, scope, 0, &bytes, Compression::Auto(3))?,
        // Raw: cast in place from the map (zstd saves little on f32s).
        None => w.add_elements(SectionKind::Surfels, scope, 0, &tile.surfels, Compression::Raw)?,
    };
    match blocks {
        Some(blocks) => {
            w.add_elements(SectionKind::SurfelColorsBc1, scope, 0, &blocks, Compression::Auto(3))?;
        }
        None => {
            let rgba: Vec<Rgba8> = tile.colors.iter().map(|c| Rgba8([c[0], c[1], c[2], 255])).collect();
            w.add_elements(SectionKind::SurfelColorsRaw, scope, 0, &rgba, Compression::Auto(3))?;
        }
    }
    // Mostly runs in Morton order (a wall is seen best from one scanner): zstd makes it small.
    w.add_elements(SectionKind::SurfelScans, scope, 0, &tile.scans, Compression::Auto(3))?;
    let svo = &tile.svo;
    // Nodes (Morton codes sorted per level) take a fifth after zstd, NDFs three quarters, BC1
    // blocks half: the runtime copies them into its own buffers anyway, so zero-copy saved
    // nothing there.
    w.add_elements(SectionKind::SvoNodes, scope, 0, &svo.nodes, Compression::Auto(3))?;
    w.add_elements(SectionKind::LeafOpacity, scope, 0, &svo.opacity, Compression::Auto(3))?;
    w.add_elements(SectionKind::LeafAlbedo, scope, 0, &svo.albedo, Compression::Auto(3))?;
    w.add_elements(SectionKind::LeafNdf, scope, 0, &svo.ndf, Compression::Auto(3))?;
    if svo.has_emission() {
        w.add_elements(SectionKind::LeafEmission, scope, 0, &svo.emission, Compression::Auto(3))?;
    }
    w.add_provenance(&Provenance {
        tool: "grotto-pack build-tile".into(),
        tool_version: env!("CARGO_PKG_VERSION").into(),
        inputs: Vec::new(),
        parameters: [
            ("tile_fingerprint".to_string(), serde_json::json!(fingerprint)),
            ("seam_limited_points".to_string(), serde_json::json!(tile.seam_limited)),
            ("normals".to_string(), serde_json::json!(tile.normals)),
        ]
        .into(),
    })?;
    w.finish()?;
    profile.lap(Stage::WriteTiles, &mut clock);
    Ok(())
}

/// The package's scan list (what the surfel-scans sections index): each scan's file name, with
/// `#k` where a file format holds several scans.
fn scan_infos(scans: &[ResolvedScan]) -> Vec<grotto_format::ScanInfo> {
    scans
        .iter()
        .map(|s| {
            let file = s
                .path
                .file_name()
                .map_or_else(|| s.path.display().to_string(), |n| n.to_string_lossy().into());
            let name = if s.format == ScanFormat::E57 { format!("{file}#{}", s.index) } else { file };
            grotto_format::ScanInfo { name }
        })
        .collect()
}

fn hash_file(path: &Path) -> Result<InputFile> {
    use std::io::Read;
    let io = |source| Error::Io { path: path.to_path_buf(), source };
    let mut f = std::fs::File::open(path).map_err(io)?;
    let mut h = xxhash_rust::xxh3::Xxh3::new();
    let mut buf = vec![0u8; 1 << 20];
    let mut bytes = 0u64;
    loop {
        let n = f.read(&mut buf).map_err(io)?;
        if n == 0 {
            break;
        }
        h.update(&buf[..n]);
        bytes += n as u64;
    }
    Ok(InputFile { path: path.display().to_string(), bytes, xxh3: format!("{:016x}", h.digest()) })
}

/// Which tiles a `build-tile` job takes: those with `index % count == shard`.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub struct Shard {
    pub index: usize,
    pub count: usize,
}

impl Shard {
    pub const ALL: Shard = Shard { index: 0, count: 1 };

    fn takes(&self, tile: usize) -> bool {
        tile % self.count.max(1) == self.index
    }
}

/// What the build-tile step did.
#[derive(Clone, Debug, Default, Serialize)]
pub struct TileStage {
    pub built: usize,
    pub reused: usize,
    /// Seconds per stage of the tiles built, summed over tiles built at once ([`crate::profile`]).
    pub stages: Vec<StageTime>,
}

fn check_params(params: &BuildParams) -> Result<()> {
    if !(3..=30).contains(&params.k) {
        return Err(Error::Parameter { name: "k", reason: format!("{} is not in 3..=30", params.k) });
    }
    if !(params.leaf_m > 0.0
        && params.leaf_m.log2().fract() == 0.0
        && params.leaf_m <= params.min_tile_extent_m)
    {
        return Err(Error::Parameter {
            name: "leaf_m",
            reason: format!(
                "{} must be a power of two no larger than the smallest tile ({} m)",
                params.leaf_m, params.min_tile_extent_m
            ),
        });
    }
    Ok(())
}

/// Step 1, plan: resolves the scans and tiles them out of core into the work directory (or finds
/// that an earlier run did). Returns the plan and whether it was reused.
pub fn plan(
    manifest: &Manifest,
    params: &BuildParams,
    progress: &(dyn Fn(Progress) + Sync),
) -> Result<(TilePlan, bool)> {
    check_params(params)?;
    let step = plan_scans(&manifest.resolve()?, params, progress, &Profile::default())?;
    Ok((step.plan, step.reused))
}

/// The scans whose files end inside their last point record (`SourceInfo::dropped_points`), as
/// "path: N points dropped"; with `strict`, the first of them is an error instead.
fn cut_short(scans: &[ResolvedScan], strict: bool) -> Result<Vec<String>> {
    let mut out = Vec::new();
    for s in scans {
        let info = crate::ingest::header(&s.path, s.format, s.index)?;
        if info.dropped_points > 0 {
            if strict {
                return Err(Error::Read {
                    path: s.path.clone(),
                    format: s.format.name(),
                    reason: format!(
                        "the file ends inside its last point record ({} of the {} points its header \
                         claims are complete); without --strict the complete records are read",
                        info.claimed_points,
                        info.claimed_points + info.dropped_points
                    ),
                });
            }
            out.push(format!("{}: {} points dropped", s.path.display(), info.dropped_points));
        }
    }
    Ok(out)
}

/// What the plan step produced.
struct PlanStep {
    plan: TilePlan,
    /// Whether the tiling was an earlier run's.
    reused: bool,
    /// The scans cut short ([`cut_short`]).
    cut: Vec<String>,
    /// The orientation grid, where a scan has no scanner position (also saved in the work
    /// directory for build-tile jobs).
    grid: Option<CaveGrid>,
}

/// Tiles the scans (or finds an earlier tiling) and builds the orientation grid where it is
/// needed; scans cut short are refused first under `--strict`.
fn plan_scans(
    scans: &[ResolvedScan],
    params: &BuildParams,
    progress: &(dyn Fn(Progress) + Sync),
    profile: &Profile,
) -> Result<PlanStep> {
    let cut = cut_short(scans, params.strict)?;
    let tiling_params = params.tiling();
    let earlier = tiling::existing_plan(scans, &params.work_dir, &tiling_params)?;
    let plan = tiling::tile_scans(scans, &params.work_dir, &tiling_params, progress, profile)?;
    let grid = if plan.needs_orientation() {
        progress(Progress { stage: "orientation grid", done: 0, total: 1 });
        let grid = profile
            .time(Stage::OrientationGrid, || orient::load_or_build(&plan, &params.work_dir, params.leaf_m))?;
        progress(Progress { stage: "orientation grid", done: 1, total: 1 });
        Some(grid)
    } else {
        None
    };
    Ok(PlanStep { plan, reused: earlier.is_some(), cut, grid })
}

/// The plan an earlier `plan` step left for these inputs and parameters, and the scans.
fn planned(manifest: &Manifest, params: &BuildParams) -> Result<(TilePlan, Vec<ResolvedScan>)> {
    check_params(params)?;
    let scans = manifest.resolve()?;
    let plan = tiling::existing_plan(&scans, &params.work_dir, &params.tiling())?.ok_or_else(|| Error::Parameter {
        name: "work_dir",
        reason: format!(
            "{} holds no finished plan for these inputs and parameters; run the plan step first (with the same options)",
            params.work_dir.display()
        ),
    })?;
    Ok((plan, scans))
}

/// Step 2, build-tile: builds the shard's tiles that are not already built with these parameters.
/// Jobs for different shards can run at once on different machines sharing the work directory.
pub fn build_tiles(
    manifest: &Manifest,
    manifest_path: &Path,
    params: &BuildParams,
    shard: Shard,
    progress: &(dyn Fn(Progress) + Sync),
) -> Result<TileStage> {
    let (plan, _) = planned(manifest, params)?;
    // The plan step saved the grid; this job reads it once for all its tiles.
    let grid = if plan.needs_orientation() && (0..plan.tiles.len()).any(|t| shard.takes(t)) {
        Some(orient::load_or_build(&plan, &params.work_dir, params.leaf_m)?)
    } else {
        None
    };
    let profile = Profile::default();
    let mut stage =
        tile_stage(&plan, &manifest.scene(manifest_path)?, params, shard, grid.as_ref(), progress, &profile)?;
    stage.stages = profile.report();
    Ok(stage)
}

/// Builds the shard's tiles; `grid` orients the normals of scans without a scanner position.
fn tile_stage(
    plan: &TilePlan,
    scene: &Scene,
    params: &BuildParams,
    shard: Shard,
    grid: Option<&CaveGrid>,
    progress: &(dyn Fn(Progress) + Sync),
    profile: &Profile,
) -> Result<TileStage> {
    let tiles_dir = params.work_dir.join("tiles");
    std::fs::create_dir_all(&tiles_dir).map_err(|source| Error::Io { path: tiles_dir.clone(), source })?;
    let fingerprint = tile_fingerprint(plan, params);
    let mut mine: Vec<usize> = (0..plan.tiles.len()).filter(|&t| shard.takes(t)).collect();
    // Largest first, so that the last tiles to finish are small ones and no core waits long at
    // the end (what each job builds is still the shard's tiles, whatever the order).
    mine.sort_by_key(|&t| std::cmp::Reverse(plan.tiles[t].points));
    // `tiles_at_once` feeders, each taking the next tile as soon as its last one is written, in
    // a pool of its own: the threads shared out between them. Batches of that many tiles in one
    // pool waited for their largest (about 6 s of idle cores at 10^8), and one pool fed by
    // several threads stacked a tile on top of another's waiting work. At most one tile per
    // feeder is in memory, as the budget wants.
    let feeders = params.tiles_at_once().min(mine.len()).max(1);
    let threads = params.threads.max(1);
    let pools = (0..feeders)
        .map(|f| {
            let share = (threads / feeders + usize::from(f < threads % feeders)).max(1);
            rayon::ThreadPoolBuilder::new().num_threads(share).build()
        })
        .collect::<std::result::Result<Vec<_>, _>>()
        .map_err(|e| Error::Parameter { name: "threads", reason: e.to_string() })?;
    let next = std::sync::atomic::AtomicUsize::new(0);
    let failed = std::sync::atomic::AtomicBool::new(false);
    let stage = std::sync::Mutex::new((TileStage::default(), None::<Error>));
    std::thread::scope(|scope| {
        for pool in &pools {
            scope.spawn(|| {
                use std::sync::atomic::Ordering::Relaxed;
                while !failed.load(Relaxed) {
                    let Some(&t) = mine.get(next.fetch_add(1, Relaxed)) else { break };
                    let done = pool.install(|| {
                        let path = tile_package_path(&params.work_dir, t);
                        if finished_tile_package(&path, &fingerprint).is_some() {
                            return Ok(true);
                        }
                        let built = build_tile(plan, &params.work_dir, t, params, scene, grid, profile)?;
                        write_tile_package(&path, &built, &fingerprint, params, profile)?;
                        Ok(false)
                    });
                    // Counted and reported under the lock, so progress only goes up.
                    let mut stage = stage.lock().unwrap_or_else(|poisoned| poisoned.into_inner());
                    match done {
                        Ok(true) => stage.0.reused += 1,
                        Ok(false) => stage.0.built += 1,
                        Err(e) => {
                            failed.store(true, Relaxed);
                            stage.1.get_or_insert(e);
                            break;
                        }
                    }
                    let finished = (stage.0.built + stage.0.reused) as u64;
                    progress(Progress { stage: "tiles", done: finished, total: mine.len() as u64 });
                }
            });
        }
    });
    let (stage, error) = stage.into_inner().unwrap_or_else(|poisoned| poisoned.into_inner());
    if let Some(e) = error {
        return Err(e);
    }
    Ok(stage)
}

/// Builds `out` from the scans of `manifest`: plan, build every tile, assemble. `manifest_path`
/// names the manifest in errors and resolves scene paths. `progress` receives every stage's
/// progress.
pub fn build(
    manifest: &Manifest,
    manifest_path: &Path,
    out: &Path,
    params: &BuildParams,
    progress: &(dyn Fn(Progress) + Sync),
) -> Result<BuildSummary> {
    let start = std::time::Instant::now();
    check_params(params)?;
    // Resolved once for all three steps (E57 poses and headers are read here).
    let scans = manifest.resolve()?;
    let scene = manifest.scene(manifest_path)?;
    let profile = Profile::default();
    let PlanStep { plan, reused: resumed_tiling, cut, grid } =
        plan_scans(&scans, params, progress, &profile)?;
    let plan_s = start.elapsed().as_secs_f64();
    let stage = tile_stage(&plan, &scene, params, Shard::ALL, grid.as_ref(), progress, &profile)?;
    drop(grid);
    let tiles_s = start.elapsed().as_secs_f64() - plan_s;
    let mut summary = assemble_plan(manifest, &plan, &scans, &scene, out, params, progress, &profile)?;
    summary.steps.plan = plan_s;
    summary.steps.tiles = tiles_s;
    summary.stages = profile.report();
    summary.cut_short = cut;
    summary.resumed_tiling = resumed_tiling;
    summary.reused_tiles = stage.reused;
    summary.seconds = start.elapsed().as_secs_f64();
    summary.peak_rss_bytes = crate::profile::peak_rss_bytes();
    Ok(summary)
}

/// Step 3, assemble: copies every tile package into `out` (atomically), with the environment,
/// scene and provenance. Fails, naming them, if tiles are missing or were built with other
/// parameters.
pub fn assemble(
    manifest: &Manifest,
    manifest_path: &Path,
    out: &Path,
    params: &BuildParams,
    progress: &(dyn Fn(Progress) + Sync),
) -> Result<BuildSummary> {
    let (plan, scans) = planned(manifest, params)?;
    let profile = Profile::default();
    let scene = manifest.scene(manifest_path)?;
    let mut summary = assemble_plan(manifest, &plan, &scans, &scene, out, params, progress, &profile)?;
    summary.stages = profile.report();
    summary.cut_short = cut_short(&scans, false)?;
    Ok(summary)
}

// The plan step's results, the output and how to report: bundling them would only rename them.
#[allow(clippy::too_many_arguments)]
fn assemble_plan(
    manifest: &Manifest,
    plan: &TilePlan,
    scans: &[ResolvedScan],
    scene: &Scene,
    out: &Path,
    params: &BuildParams,
    progress: &(dyn Fn(Progress) + Sync),
    profile: &Profile,
) -> Result<BuildSummary> {
    let start = std::time::Instant::now();
    let tiling_params = params.tiling();
    let fingerprint = tile_fingerprint(plan, params);
    let total = plan.tiles.len();
    let mut seam_limited_points = 0u64;
    let mut normals = NormalStats::default();
    let missing: Vec<usize> = (0..total)
        .filter(|&t| finished_tile_package(&tile_package_path(&params.work_dir, t), &fingerprint).is_none())
        .collect();
    if !missing.is_empty() {
        return Err(Error::Parameter {
            name: "tiles",
            reason: format!(
                "{} of {total} tiles are not built with these parameters (first: {:?}); run build-tile for them",
                missing.len(),
                &missing[..missing.len().min(8)]
            ),
        });
    }
    let mut inputs_extra = Vec::new();
    // Each tile's coarse level and rock (format 1.1), so a renderer opening the package reads
    // only the tiles it shows in full. The rock near a border needs the neighbours' walls, so
    // this runs once every tile is built, over every tile package at once (it reads their SVOs
    // only; the maps are dropped before the copy below touches the surfels).
    let mut clock = std::time::Instant::now();
    let levels = {
        let packages = (0..total)
            .map(|t| Package::open(tile_package_path(&params.work_dir, t)))
            .collect::<std::result::Result<Vec<_>, _>>()?;
        let tiles =
            packages.iter().enumerate().map(|(t, p)| tile_of_package(p, t)).collect::<Result<Vec<_>>>()?;
        let grid = grotto_levels::TileGrid::of(&tiles);
        let done = std::sync::atomic::AtomicU64::new(0);
        (0..total)
            .into_par_iter()
            .map(|t| {
                let levels = grotto_levels::tile_levels(&tiles, &grid, t)?;
                let n = done.fetch_add(1, std::sync::atomic::Ordering::Relaxed) + 1;
                progress(Progress { stage: "levels", done: n, total: total as u64 });
                Ok(levels)
            })
            .collect::<Result<Vec<_>>>()?
    };
    profile.lap(Stage::Levels, &mut clock);
    let mut writer = PackageWriter::create(out)?;
    // Two tile packages mapped at a time (copying touches every page of a tile's surfels): the
    // next one's sections are checked (checksums, zstd decoded) on another thread while this one
    // is copied, which was half of the copy's serial time.
    let open_checked = |t: usize| -> Result<Package> {
        let pkg = Package::open(tile_package_path(&params.work_dir, t))?;
        for s in tile_of_package(&pkg, t)?.sections() {
            pkg.check(&s)?;
        }
        Ok(pkg)
    };
    let mut next = (total > 0).then(|| open_checked(0));
    for (t, levels) in levels.iter().enumerate() {
        let path = tile_package_path(&params.work_dir, t);
        if let Some((seam, tile_normals)) = finished_tile_package(&path, &fingerprint) {
            seam_limited_points += seam;
            normals.add(&tile_normals);
        }
        let Some(tile_pkg) = next.take() else { break };
        let tile_pkg = tile_pkg?;
        let tile = tile_of_package(&tile_pkg, t)?;
        let index = writer.add_tile(tile.info())?;
        let scope = Scope::Tile(index);
        let (copied, following) = rayon::join(
            || tile.sections().try_for_each(|s| writer.copy_section(&tile_pkg, &s, scope).map(drop)),
            || (t + 1 < total).then(|| open_checked(t + 1)),
        );
        copied?;
        next = following;
        for (k, coarse) in &levels.coarse {
            writer.add_elements(SectionKind::CoarseNodes, scope, *k, &coarse.nodes, Compression::Auto(3))?;
            writer.add_elements(
                SectionKind::CoarseLeaves,
                scope,
                *k,
                &coarse.leaves,
                Compression::Auto(3),
            )?;
        }
        if let Some(rock) = &levels.rock {
            writer.add_elements(SectionKind::RockBricks, scope, 0, rock, Compression::Auto(3))?;
        }
        progress(Progress { stage: "assemble", done: t as u64 + 1, total: total as u64 });
    }
    profile.lap(Stage::Assemble, &mut clock);
    let mut env_window = None;
    if let Some(env) = &manifest.environment {
        let path = manifest.resolve_path(&env.map);
        progress(Progress { stage: "environment", done: 0, total: 1 });
        let map = crate::env::LatLong::read(&path)?;
        let mut sh = map.project_sh9();
        env_window = Some(if params.sh_window { crate::env::window(&mut sh) } else { 0.0 });
        let (levels, blocks) = crate::env::encode_chain(&crate::env::prefilter(&map, 256, 6, 128));
        writer.add_elements(SectionKind::EnvSh9, Scope::Global, 0, &[sh], Compression::Raw)?;
        writer.add_elements(SectionKind::EnvMipLevels, Scope::Global, 0, &levels, Compression::Raw)?;
        writer.add_elements(SectionKind::EnvMipBc6h, Scope::Global, 0, &blocks, Compression::Raw)?;
        inputs_extra.push(hash_file(&path)?);
        progress(Progress { stage: "environment", done: 1, total: 1 });
        profile.lap(Stage::Environment, &mut clock);
    }
    writer.add_scene(&Scene { scans: scan_infos(scans), ..scene.clone() })?;
    let mut inputs = std::mem::take(&mut inputs_extra);
    let mut seen = std::collections::BTreeSet::new();
    for s in scans {
        if seen.insert(s.path.clone()) {
            inputs.push(hash_file(&s.path)?);
        }
    }
    profile.lap(Stage::HashInputs, &mut clock);
    let mut parameters = std::collections::BTreeMap::new();
    for (k, v) in [
        ("leaf_m", serde_json::json!(params.leaf_m)),
        ("colors", serde_json::json!(params.colors)),
        ("surfels", serde_json::json!(params.surfels)),
        ("k", serde_json::json!(params.k)),
        ("min_tile_extent_m", serde_json::json!(params.min_tile_extent_m)),
        ("max_tile_extent_m", serde_json::json!(params.max_tile_extent_m)),
        ("max_points_per_tile", serde_json::json!(tiling_params.max_points_per_tile)),
        ("halo_m", serde_json::json!(params.halo_m)),
        ("grid_origin_m", serde_json::json!(plan.grid_origin_m())),
        ("quantum_m", serde_json::json!(plan.quantum_m)),
        ("sh_window_strength", serde_json::json!(env_window)),
    ] {
        parameters.insert(k.to_string(), v);
    }
    writer.add_provenance(&Provenance {
        tool: "grotto-pack build".into(),
        tool_version: env!("CARGO_PKG_VERSION").into(),
        inputs,
        parameters,
    })?;
    let path = writer.finish()?;
    profile.lap(Stage::Assemble, &mut clock);
    let bytes = std::fs::metadata(&path).map_err(|source| Error::Io { path: path.clone(), source })?.len();
    Ok(BuildSummary {
        package: path.display().to_string(),
        scans: scans.len(),
        points: plan.points,
        invalid_points: plan.invalid_points,
        halo_points: plan.halo_points,
        tiles: total,
        bytes,
        seconds: start.elapsed().as_secs_f64(),
        resumed_tiling: false,
        reused_tiles: 0,
        seam_limited_points,
        orientation: (normals.orientation.points > 0).then_some(normals.orientation),
        input_normals: normals.input_normals,
        input_normals_kept: normals.input_kept,
        keep_input_normals: params.keep_input_normals,
        scans_without_scanner: plan.scanner_known.iter().filter(|k| !**k).count(),
        scans_seen_from_outside: (0..plan.scanner_known.len())
            .filter(|&s| plan.seen_from(s) == Some(SeenFrom::Outside))
            .count(),
        peak_rss_bytes: crate::profile::peak_rss_bytes(),
        leaf_m: params.leaf_m,
        lights: scene.lights.len(),
        cameras: scene.cameras.len(),
        environment: scene.environment.is_some(),
        cut_short: Vec::new(),
        steps: StepSeconds { assemble: start.elapsed().as_secs_f64(), ..StepSeconds::default() },
        stages: Vec::new(),
    })
}
