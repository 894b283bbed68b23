//! `grotto-pack build`: scans + manifest in, one `.grotto` package out.
//!
//! Three steps, each resumable (the brief's plan / build-tile / assemble jobs):
//! 1. plan: resolve scans and tile them out of core ([`crate::tiling`]);
//! 2. build-tile: per tile, in parallel batches of `threads` tiles: normals, spread and radii
//!    ([`crate::normals`]), surfels in Morton order, colours -> a one-tile package
//!    `WORK/tiles/NNNNNNN.grotto`, whose provenance carries a fingerprint of the plan and the
//!    build parameters. A tile package with the right fingerprint is kept, not rebuilt, so an
//!    interrupted run resumes where it stopped;
//! 3. assemble: the tile packages' sections are copied as stored (checksums checked) into the
//!    output, in plan order, with scene and provenance; the output is written atomically and is
//!    the same for the same input whatever the thread count.
//!
//! Memory: the tiler's buffers take a quarter of the budget; each tile being built costs about
//! [`BUILD_BYTES_PER_POINT`] per point, so `max_points_per_tile = 3/4 budget / threads / that`.

use std::path::{Path, PathBuf};

use grotto_format::spec::{Rgba8, Surfel};
use grotto_format::svo::morton_encode;
use grotto_format::{
    Compression, InputFile, Package, PackageWriter, Provenance, Scope, SectionKind, TileInfo,
};
use rayon::prelude::*;
use serde::Serialize;

use crate::manifest::Manifest;
use crate::normals::{self, TilePoints};
use crate::tiling::{self, FLAG_HALO, Progress, TilePlan, TilingParams};
use crate::{Error, Result};

/// Measured upper bound of what building one tile holds per input point: bin (24), kd-tree
/// (~24), neighbour lists (k=16: 64), normals and radii in f64 (32), surfels and colours (36),
/// sort keys (16), plus allocator slack.
pub const BUILD_BYTES_PER_POINT: u64 = 256;

#[derive(Clone, Debug, Serialize)]
pub struct BuildParams {
    pub work_dir: PathBuf,
    pub memory_budget_bytes: u64,
    pub threads: usize,
    /// SVO depth declared for each tile.
    pub depth: u32,
    /// Neighbours for normals.
    pub k: usize,
    pub min_tile_extent_m: f64,
    pub max_tile_extent_m: f64,
    pub halo_m: f64,
}

impl BuildParams {
    pub fn tiling(&self) -> TilingParams {
        let budget = self.memory_budget_bytes.max(64 << 20);
        TilingParams {
            min_tile_extent_m: self.min_tile_extent_m,
            max_tile_extent_m: self.max_tile_extent_m,
            max_points_per_tile: (budget * 3 / 4 / self.threads.max(1) as u64 / BUILD_BYTES_PER_POINT)
                .max(1000),
            halo_m: self.halo_m,
            chunk_points: crate::ingest::DEFAULT_CHUNK,
            buffer_bytes: (budget / 4) as usize,
        }
    }
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
    /// Peak resident memory of the process (Linux), bytes.
    pub peak_rss_bytes: Option<u64>,
}

/// One tile's sections, built off the writer thread.
struct BuiltTile {
    info: TileInfo,
    surfels: Vec<Surfel>,
    colors: Vec<Rgba8>,
}

fn build_tile(plan: &TilePlan, work_dir: &Path, t: usize, params: &BuildParams) -> Result<BuiltTile> {
    let tile = &plan.tiles[t];
    let origin = plan.origin_m(tile);
    let extent = plan.extent_m(tile);
    let points = tiling::read_bin(work_dir, t)?;
    let positions: Vec<[f32; 3]> = points.iter().map(|p| p.pos_tile_m).collect();
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
    let estimated = normals::estimate(
        &TilePoints {
            positions: &positions,
            own: &own,
            scanner_tile_m: &scanner_tile_m,
            input_normals: &input_normals,
        },
        params.k,
    );
    let own_points: Vec<&tiling::BinPoint> = points.iter().filter(|p| p.flags & FLAG_HALO == 0).collect();
    let q = f64::from(1u32 << 16) / extent;
    let mut order: Vec<(u64, usize)> = own_points
        .iter()
        .enumerate()
        .map(|(i, p)| {
            let c = p.pos_tile_m.map(|v| (f64::from(v) * q).clamp(0.0, 65_535.0) as u32);
            (morton_encode(c[0], c[1], c[2]), i)
        })
        .collect();
    order.sort_unstable();
    let surfels = order
        .iter()
        .map(|&(_, i)| Surfel {
            position_tile_m: own_points[i].pos_tile_m,
            radius_m: estimated[i].radius_m,
            normal: estimated[i].normal,
            spread: estimated[i].spread,
        })
        .collect();
    let colors = order.iter().map(|&(_, i)| {
        let c = own_points[i].rgb;
        Rgba8([c[0], c[1], c[2], 255])
    });
    let grid: [i32; 3] = tile.key.map(|k| i32::try_from(k).unwrap_or(i32::MAX));
    if grid.contains(&i32::MAX) {
        return Err(Error::Parameter {
            name: "tiles",
            reason: format!("tile key {:?} outside the 32-bit grid", tile.key),
        });
    }
    Ok(BuiltTile {
        info: TileInfo {
            origin_m: origin,
            extent_m: extent,
            grid,
            depth: params.depth,
            point_count: tile.points,
        },
        surfels,
        colors: colors.collect(),
    })
}

pub fn tile_package_path(work_dir: &Path, tile: usize) -> PathBuf {
    work_dir.join("tiles").join(format!("{tile:07}.grotto"))
}

/// What a tile package depends on: the plan (inputs and tiling) and the per-tile parameters.
fn tile_fingerprint(plan: &TilePlan, params: &BuildParams) -> String {
    format!("{}-k{}-d{}-v{}", plan.fingerprint, params.k, params.depth, env!("CARGO_PKG_VERSION"))
}

fn tile_package_matches(path: &Path, fingerprint: &str) -> bool {
    // Any problem (missing, damaged, other parameters) means: build it again.
    Package::open(path).ok().and_then(|p| p.provenance().ok().flatten()).is_some_and(|prov| {
        prov.parameters.get("tile_fingerprint").and_then(|v| v.as_str()) == Some(fingerprint)
    })
}

fn write_tile_package(path: &Path, tile: &BuiltTile, fingerprint: &str) -> Result<()> {
    let mut w = PackageWriter::create(path)?;
    let index = w.add_tile(tile.info)?;
    w.add_elements(SectionKind::Surfels, Scope::Tile(index), 0, &tile.surfels, Compression::Raw)?;
    w.add_elements(SectionKind::SurfelColorsRaw, Scope::Tile(index), 0, &tile.colors, Compression::Auto(3))?;
    w.add_provenance(&Provenance {
        tool: "grotto-pack build-tile".into(),
        tool_version: env!("CARGO_PKG_VERSION").into(),
        inputs: Vec::new(),
        parameters: [("tile_fingerprint".to_string(), serde_json::json!(fingerprint))].into(),
    })?;
    w.finish()?;
    Ok(())
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

/// Builds `out` from the scans of `manifest`. `manifest_path` names the manifest in errors and
/// resolves scene paths. `progress` receives every stage's progress.
pub fn build(
    manifest: &Manifest,
    manifest_path: &Path,
    out: &Path,
    params: &BuildParams,
    progress: &(dyn Fn(Progress) + Sync),
) -> Result<BuildSummary> {
    let start = std::time::Instant::now();
    if !(3..=30).contains(&params.k) {
        return Err(Error::Parameter { name: "k", reason: format!("{} is not in 3..=30", params.k) });
    }
    if params.depth > grotto_format::spec::MAX_SVO_DEPTH {
        return Err(Error::Parameter { name: "depth", reason: format!("{} exceeds 21", params.depth) });
    }
    let scans = manifest.resolve()?;
    let scene = manifest.scene(manifest_path)?;
    let tiling_params = params.tiling();
    let plan_file = params.work_dir.join("plan.json");
    let existed = std::fs::read_to_string(&plan_file).ok();
    let plan = tiling::tile_scans(&scans, &params.work_dir, &tiling_params, progress)?;
    let resumed_tiling =
        existed.is_some_and(|old| serde_json::from_str::<TilePlan>(&old).is_ok_and(|p| p == plan));

    let pool = rayon::ThreadPoolBuilder::new()
        .num_threads(params.threads.max(1))
        .build()
        .map_err(|e| Error::Parameter { name: "threads", reason: e.to_string() })?;
    let tiles_dir = params.work_dir.join("tiles");
    std::fs::create_dir_all(&tiles_dir).map_err(|source| Error::Io { path: tiles_dir.clone(), source })?;
    let fingerprint = tile_fingerprint(&plan, params);
    let total = plan.tiles.len();
    let batch = params.threads.max(1);
    let mut reused_tiles = 0usize;
    for first in (0..total).step_by(batch) {
        let done: Vec<Result<bool>> = pool.install(|| {
            (first..(first + batch).min(total))
                .into_par_iter()
                .map(|t| {
                    let path = tile_package_path(&params.work_dir, t);
                    if tile_package_matches(&path, &fingerprint) {
                        return Ok(true);
                    }
                    let built = build_tile(&plan, &params.work_dir, t, params)?;
                    write_tile_package(&path, &built, &fingerprint)?;
                    Ok(false)
                })
                .collect()
        });
        for (i, d) in done.into_iter().enumerate() {
            reused_tiles += usize::from(d?);
            progress(Progress { stage: "tiles", done: (first + i + 1) as u64, total: total as u64 });
        }
    }
    let mut writer = PackageWriter::create(out)?;
    for t in 0..total {
        let tile_pkg = Package::open(tile_package_path(&params.work_dir, t))?;
        let tile = tile_pkg.tile(0).ok_or_else(|| Error::Parameter {
            name: "tiles",
            reason: format!("tile package {t} has no tile"),
        })?;
        let index = writer.add_tile(TileInfo {
            origin_m: tile.origin_m(),
            extent_m: tile.extent_m(),
            grid: tile.grid(),
            depth: tile.depth(),
            point_count: tile.point_count(),
        })?;
        for s in tile.sections() {
            writer.copy_section(&tile_pkg, &s, Scope::Tile(index))?;
        }
        progress(Progress { stage: "assemble", done: t as u64 + 1, total: total as u64 });
    }
    writer.add_scene(&scene)?;
    let mut inputs = Vec::new();
    let mut seen = std::collections::BTreeSet::new();
    for s in &scans {
        if seen.insert(s.path.clone()) {
            inputs.push(hash_file(&s.path)?);
        }
    }
    let mut parameters = std::collections::BTreeMap::new();
    for (k, v) in [
        ("depth", serde_json::json!(params.depth)),
        ("k", serde_json::json!(params.k)),
        ("min_tile_extent_m", serde_json::json!(params.min_tile_extent_m)),
        ("max_tile_extent_m", serde_json::json!(params.max_tile_extent_m)),
        ("max_points_per_tile", serde_json::json!(tiling_params.max_points_per_tile)),
        ("halo_m", serde_json::json!(params.halo_m)),
        ("grid_origin_m", serde_json::json!(plan.grid_origin_m())),
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
        resumed_tiling,
        reused_tiles,
        peak_rss_bytes: crate::bench::peak_rss_bytes(),
    })
}
