//! Step 2 for one tile: its points' normals, surfels, SVO and colours into a one-tile package
//! `WORK/tiles/NNNNNNN.grotto` whose provenance fingerprints the plan and the parameters.

use std::path::{Path, PathBuf};

use grotto_format::spec::{Rgba8, Surfel};
use grotto_format::svo::morton_encode;
use grotto_format::{
    Compression, LightShape, Package, PackageWriter, Provenance, Scene, Scope, SectionKind, TileInfo,
};
use rayon::prelude::*;

use crate::bc1;
use crate::bins::{self, FLAG_HALO, TilePlan};
use crate::build::params::BuildParams;
use crate::build::params::ColorCodec;
use crate::build::params::SurfelCodec;
use crate::manifest::SeenFrom;
use crate::normals::{self, NormalStats, Orient, TilePoints};
use crate::orient::CaveGrid;
use crate::profile::{Profile, Stage};
use crate::voxels::{self, Sample, TileSvo};
use crate::{Error, Result};
use grotto_format::compact;

/// One tile's sections, built off the writer thread.
pub(crate) struct BuiltTile {
    pub(crate) info: TileInfo,
    /// Own points near the border whose k-neighbourhood may reach past the halo.
    pub(crate) seam_limited: u64,
    /// File normals kept and orientation without a scanner in this tile.
    pub(crate) normals: NormalStats,
    pub(crate) surfels: Vec<Surfel>,
    /// Index of each surfel's scan (in the plan's scan order), surfel order.
    pub(crate) scans: Vec<u16>,
    pub(crate) colors: Vec<[u8; 3]>,
    pub(crate) svo: TileSvo,
}

/// Depth of a tile's SVO for the build's leaf size.
pub(crate) fn tile_depth(extent_m: f64, leaf_m: f64) -> Result<u32> {
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
pub(crate) fn area_light_samples(scene: &Scene, origin: [f64; 3], extent: f64, leaf_m: f64) -> Vec<Sample> {
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

pub(crate) fn build_tile(
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
pub(crate) fn tile_of_package(package: &Package, t: usize) -> Result<grotto_format::Tile<'_>> {
    package
        .tile(0)
        .ok_or_else(|| Error::Parameter { name: "tiles", reason: format!("tile package {t} has no tile") })
}

/// Where the one-tile package of `tile` lives in the work directory.
pub fn tile_package_path(work_dir: &Path, tile: usize) -> PathBuf {
    work_dir.join("tiles").join(format!("{tile:07}.grotto"))
}

/// How tile packages are written (codecs, sections). Bumped when that changes within one release,
/// so a resumed build does not mix tile packages of two layouts. 2: compact surfels, zstd nodes.
pub(crate) const TILE_PACKAGE_LAYOUT: u32 = 2;

/// What a tile package depends on: the plan (inputs and tiling) and the per-tile parameters.
pub(crate) fn tile_fingerprint(plan: &TilePlan, params: &BuildParams) -> String {
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

pub(crate) fn write_tile_package(
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
    hold_first_tile_for_test();
    w.finish()?;
    profile.lap(Stage::WriteTiles, &mut clock);
    Ok(())
}

/// The cluster test's hook (scripts/test-slurm.sh, the node-loss case): with
/// `GROTTO_PACK_HOLD_TILE_MS=N` the first tile package this process writes stays open under its
/// temp name N ms (at most a minute) before it is finished, so a node can be lost while it writes.
/// Without it a tile's write takes about 20 ms, which a script polling /proc catches only by luck.
/// Later tiles are not held, and unset (every real build) it costs one lookup per process.
fn hold_first_tile_for_test() {
    use std::sync::atomic::{AtomicBool, Ordering};
    static HELD: AtomicBool = AtomicBool::new(false);
    if HELD.swap(true, Ordering::Relaxed) {
        return;
    }
    let ms = std::env::var("GROTTO_PACK_HOLD_TILE_MS").ok().and_then(|v| v.trim().parse::<u64>().ok());
    if let Some(ms) = ms {
        std::thread::sleep(std::time::Duration::from_millis(ms.min(60_000)));
    }
}
