//! Measurements behind `docs/benchmarks.md`: ingest throughput per format, and peak memory.
//!
//! `ingest`: one synthetic scan of N points is written as LAS, LAZ, binary PLY and E57, then each
//! file is streamed through its [`crate::ingest::PointSource`] (chunks of 64 Ki points) and timed.
//! The same PLY file is also parsed with `ply-rs-bw`'s own body reader, which is why the PLY body
//! is streamed by hand (see `ingest/ply.rs`).

use std::path::{Path, PathBuf};
use std::time::Instant;

use serde::Serialize;

use crate::ingest::{self, PointChunk, ScanFormat};
use crate::scanwrite::{ScanData, write_scan};
use crate::synth::{SynthCave, SynthParams, scan};
use crate::{Error, Result};

#[derive(Clone, Debug, Serialize)]
/// Read throughput of one scan reader.
pub struct IngestFigure {
    pub reader: String,
    pub points: u64,
    pub file_bytes: u64,
    pub seconds: f64,
    pub points_per_second: f64,
}

fn stream(path: &Path, format: ScanFormat) -> Result<u64> {
    let mut n = 0u64;
    for i in 0..ingest::scan_count(path, format)? {
        let mut src = ingest::open(path, format, i)?;
        let mut chunk = PointChunk::new(ingest::DEFAULT_CHUNK);
        while src.fill_chunk(&mut chunk)? > 0 {
            n += chunk.len() as u64;
        }
    }
    Ok(n)
}

/// Writes the test scan into `dir` (once; reused when present) and times every reader.
pub fn ingest(dir: &Path, points: u64, progress: &dyn Fn(&str)) -> Result<Vec<IngestFigure>> {
    std::fs::create_dir_all(dir).map_err(|source| Error::Io { path: dir.to_path_buf(), source })?;
    let params = SynthParams { points, segments: 12, ..SynthParams::default() };
    let formats = [
        (ScanFormat::Las, "las"),
        (ScanFormat::Laz, "laz"),
        (ScanFormat::Ply, "ply"),
        (ScanFormat::E57, "e57"),
    ];
    let path_of = |ext: &str| dir.join(format!("bench-{points}.{ext}"));
    if formats.iter().any(|(_, ext)| !path_of(ext).exists()) {
        progress("simulating the scan");
        let cave = SynthCave::new(&params);
        let sc = scan(&cave, &params, 0, points);
        for (format, ext) in formats {
            progress(&format!("writing {ext}"));
            let data = ScanData {
                xyz: &sc.xyz,
                rgb: &sc.rgb,
                intensity: &sc.intensity,
                normals: &[],
                pose: Some(sc.world_from_scan),
            };
            write_scan(&path_of(ext), format, &data)?;
        }
    }
    let mut out = Vec::new();
    let mut time = |reader: String, path: &Path, f: &dyn Fn() -> Result<u64>| -> Result<()> {
        progress(&format!("reading {reader}"));
        let start = Instant::now();
        let n = f()?;
        let seconds = start.elapsed().as_secs_f64();
        let file_bytes =
            std::fs::metadata(path).map_err(|source| Error::Io { path: path.to_path_buf(), source })?.len();
        out.push(IngestFigure {
            reader,
            points: n,
            file_bytes,
            seconds,
            points_per_second: n as f64 / seconds,
        });
        Ok(())
    };
    for (format, ext) in formats {
        let p = path_of(ext);
        time(format!("{} (grotto)", format.name()), &p, &|| stream(&p, format))?;
    }
    let p = path_of("ply");
    time("PLY (ply-rs-bw read_ply)".into(), &p, &|| {
        use ply_rs_bw::parser::Parser;
        use ply_rs_bw::ply::DefaultElement;
        let file = std::fs::File::open(&p).map_err(|source| Error::Io { path: p.clone(), source })?;
        let ply = Parser::<DefaultElement>::new()
            .read_ply(&mut std::io::BufReader::new(file))
            .map_err(|e| Error::Read { path: p.clone(), format: "PLY", reason: e.to_string() })?;
        Ok(ply.payload.get("vertex").map_or(0, |v| v.len() as u64))
    })?;
    Ok(out)
}

/// Normal accuracy and speed for one configuration.
#[derive(Clone, Debug, Serialize)]
pub struct NormalFigure {
    pub noise_scale: f64,
    pub k: usize,
    pub points: u64,
    /// Angle between estimated and true (analytic) normal, degrees.
    pub mean_deg: f64,
    pub p95_deg: f64,
    /// Estimated normals pointing into the rock, percent.
    pub flipped_percent: f64,
    pub threads: usize,
    /// Oriented without scanner positions (the enclosure votes) rather than toward the scanner.
    pub bare: bool,
    /// Building the orientation grid over every point (bare only; 0 otherwise).
    pub grid_seconds: f64,
    /// Its occupied cells (12 bytes each on disk; about twice that in memory with the column maps).
    pub grid_cells: usize,
    /// Normals over all tiles, the enclosure votes included when bare.
    pub(crate) normals_seconds: f64,
    pub normals_per_second: f64,
    pub(crate) svo_seconds: f64,
    pub svo_points_per_second: f64,
}

/// One tile of the normals bench, loaded before anything is timed (timed work excludes I/O).
struct BenchTile {
    positions: Vec<[f32; 3]>,
    own: Vec<bool>,
    scanners: Vec<[f64; 3]>,
    inputs: Vec<[f32; 3]>,
    origin: [f64; 3],
    extent: f64,
}

/// The normals bench's leaf edge (the build default), metres.
const BENCH_LEAF_M: f64 = crate::build::DEFAULT_LEAF_M;

/// Synthesises a cave of `points` with `noise_scale`, tiles it, then times normal estimation and
/// SVO construction over all tiles (`threads` workers) and scores the normals against the
/// analytic surface. With `export`, also writes the cloud (cave frame, metres) with its true
/// normals as binary PLY, for comparison with other tools. With `bare`, the same tiles are run
/// again as one merged cloud without scanner positions: the orientation grid is built (timed) and
/// every normal is oriented by the enclosure votes.
pub fn normals(
    dir: &Path,
    points: u64,
    noise_scale: f64,
    ks: &[usize],
    threads: usize,
    export: Option<&Path>,
    bare: bool,
) -> Result<Vec<NormalFigure>> {
    let params = SynthParams { points, noise_scale, ..SynthParams::default() };
    let scans = dir.join(format!("normals-{points}-{noise_scale}"));
    // Written once per size and noise, then reused.
    if !scans.join("manifest.toml").exists() {
        crate::synth::write_dataset(&scans, &params, &[ScanFormat::Las], &|_, _| {})?;
    }
    let (plan, work) = tile_bench_scans(&scans)?;
    let cave = SynthCave::new(&params);
    let pool = rayon::ThreadPoolBuilder::new()
        .num_threads(threads.max(1))
        .build()
        .map_err(|e| Error::Parameter { name: "threads", reason: e.to_string() })?;
    let tiles = load_bench_tiles(&plan, &work)?;
    let mut out = Vec::new();
    for by_enclosure in [false, true].into_iter().filter(|&b| !b || bare) {
        let start = Instant::now();
        let grid = if by_enclosure {
            Some(pool.install(|| {
                crate::orient::CaveGrid::from_plan(&plan, &work, crate::orient::CELL_LEAVES * BENCH_LEAF_M)
            })?)
        } else {
            None
        };
        let grid_seconds = if by_enclosure { start.elapsed().as_secs_f64() } else { 0.0 };
        let side = by_enclosure.then_some(crate::manifest::SeenFrom::Inside);
        let seen_from: Vec<Vec<_>> = tiles.iter().map(|t| vec![side; t.positions.len()]).collect();
        for &k in ks {
            let start = Instant::now();
            let normals = estimate_bench_normals(&pool, &tiles, &seen_from, grid.as_ref(), k);
            let normals_seconds = start.elapsed().as_secs_f64();
            let start = Instant::now();
            let leaves = build_bench_svos(&pool, &tiles, &normals);
            let svo_seconds = start.elapsed().as_secs_f64();
            // Keeps the timed SVO work observable to the optimiser.
            std::hint::black_box(leaves);
            let export = export.filter(|_| k == ks[0] && !by_enclosure);
            let (errors, flipped) = score_normals(&tiles, &normals, &cave, params.offset_m, export)?;
            let n = errors.len().max(1);
            out.push(NormalFigure {
                noise_scale,
                k,
                points: errors.len() as u64,
                mean_deg: errors.iter().sum::<f64>() / n as f64,
                p95_deg: errors.get(n * 95 / 100).copied().unwrap_or(0.0),
                flipped_percent: 100.0 * flipped as f64 / n as f64,
                threads,
                bare: by_enclosure,
                grid_seconds,
                grid_cells: grid.as_ref().map_or(0, |g| g.cells),
                normals_seconds,
                normals_per_second: errors.len() as f64 / normals_seconds,
                svo_seconds,
                svo_points_per_second: errors.len() as f64 / svo_seconds,
            });
        }
    }
    Ok(out)
}

/// Tiles the bench's scans (their manifest in `scans`) into `scans/work`.
fn tile_bench_scans(scans: &Path) -> Result<(crate::bins::TilePlan, PathBuf)> {
    use crate::manifest::Manifest;
    use crate::tiling::{TilingParams, tile_scans};
    let manifest = Manifest::load(&scans.join("manifest.toml"))?;
    let resolved = manifest.resolve()?;
    let tiling = TilingParams {
        quantum_m: 1.0 / 32_768.0,
        min_tile_extent_m: 4.0,
        max_tile_extent_m: 16.0,
        ..TilingParams::default()
    };
    let work = scans.join("work");
    let plan = tile_scans(&resolved, &work, &tiling, &|_| {}, &Default::default())?;
    Ok((plan, work))
}

/// Every tile of `plan`, read from its bins.
fn load_bench_tiles(plan: &crate::bins::TilePlan, work: &Path) -> Result<Vec<BenchTile>> {
    use crate::bins::{FLAG_HALO, read_bin};
    (0..plan.tiles.len())
        .map(|t| -> Result<BenchTile> {
            let bin = read_bin(work, plan, t)?;
            let origin = plan.origin_m(&plan.tiles[t]);
            Ok(BenchTile {
                positions: bin.iter().map(|p| p.pos_tile_m(plan.quantum_m)).collect(),
                own: bin.iter().map(|p| p.flags & FLAG_HALO == 0).collect(),
                scanners: bin
                    .iter()
                    .map(|p| {
                        let s = plan.scanners_world_m[p.scan as usize];
                        std::array::from_fn(|a| s[a] - origin[a])
                    })
                    .collect(),
                inputs: vec![[0.0; 3]; bin.len()],
                origin,
                extent: plan.extent_m(&plan.tiles[t]),
            })
        })
        .collect()
}

/// The normals of every tile's own points with `k` neighbours (the timed work).
fn estimate_bench_normals(
    pool: &rayon::ThreadPool,
    tiles: &[BenchTile],
    seen_from: &[Vec<Option<crate::manifest::SeenFrom>>],
    grid: Option<&crate::orient::CaveGrid>,
    k: usize,
) -> Vec<Vec<crate::normals::PointNormal>> {
    use crate::normals::{Orient, TilePoints, estimate};
    use rayon::prelude::*;
    pool.install(|| {
        tiles
            .par_iter()
            .zip(seen_from)
            .map(|(t, seen_from)| {
                estimate(
                    &TilePoints {
                        positions: &t.positions,
                        own: &t.own,
                        scanner_tile_m: &t.scanners,
                        input_normals: &t.inputs,
                        isolated_radius_m: 0.5 * BENCH_LEAF_M as f32,
                        keep_input_normals: true,
                        orient: grid.map(|grid| Orient { grid, tile_origin_m: t.origin, seen_from }),
                    },
                    k,
                )
            })
            .collect()
    })
}

/// Every tile's SVO from its own points and their normals (the timed work); the leaves built.
fn build_bench_svos(
    pool: &rayon::ThreadPool,
    tiles: &[BenchTile],
    normals: &[Vec<crate::normals::PointNormal>],
) -> usize {
    use crate::voxels::{self, Sample};
    use rayon::prelude::*;
    pool.install(|| {
        tiles
            .par_iter()
            .zip(normals)
            .map(|(t, n)| {
                let samples: Vec<Sample> = t
                    .positions
                    .iter()
                    .zip(&t.own)
                    .filter(|(_, own)| **own)
                    .zip(n)
                    .map(|((p, _), n)| Sample {
                        pos_tile_m: *p,
                        normal: n.normal,
                        area_m2: n.radius_m * n.radius_m,
                        albedo_linear: [0.5; 3],
                        emission: [0.0; 3],
                    })
                    .collect();
                voxels::build(&samples, t.extent, (t.extent / BENCH_LEAF_M).log2() as u32).leaf_count()
            })
            .sum()
    })
}

/// Each own point's angle to the analytic normal in degrees (sorted) and how many point into the
/// rock; with `export`, the cloud and its true normals are written there as PLY.
fn score_normals(
    tiles: &[BenchTile],
    normals: &[Vec<crate::normals::PointNormal>],
    cave: &SynthCave,
    offset_m: [f64; 3],
    export: Option<&Path>,
) -> Result<(Vec<f64>, usize)> {
    let (mut errors, mut flipped) = (Vec::new(), 0usize);
    let mut export_rows: Vec<([f64; 3], [f64; 3])> = Vec::new();
    for (t, n) in tiles.iter().zip(normals) {
        for (p, est) in t.positions.iter().zip(&t.own).filter(|(_, own)| **own).map(|(p, _)| p).zip(n) {
            let local: [f64; 3] = std::array::from_fn(|a| t.origin[a] + f64::from(p[a]) - offset_m[a]);
            let truth = cave.normal(local);
            let dot: f64 = (0..3).map(|a| truth[a] * f64::from(est.normal[a])).sum();
            flipped += usize::from(dot < 0.0);
            errors.push(dot.abs().min(1.0).acos().to_degrees());
            if export.is_some() {
                export_rows.push((local, truth));
            }
        }
    }
    if let (Some(path), false) = (export, export_rows.is_empty()) {
        let xyz: Vec<[f64; 3]> = export_rows.iter().map(|r| r.0).collect();
        let nrm: Vec<[f32; 3]> = export_rows.iter().map(|r| r.1.map(|v| v as f32)).collect();
        let rgb = vec![[128u8; 3]; xyz.len()];
        write_scan(
            path,
            ScanFormat::Ply,
            &ScanData { xyz: &xyz, rgb: &rgb, intensity: &[], normals: &nrm, pose: None },
        )?;
    }
    errors.sort_by(f64::total_cmp);
    Ok((errors, flipped))
}

/// BC1 against raw colours on a package built with `--colors raw`, one row per encoder.
#[derive(Clone, Debug, Serialize)]
pub struct Bc1Figure {
    pub package: String,
    pub points: u64,
    pub encoders: Vec<Bc1EncoderFigure>,
    /// sRGB bytes as stored raw (4 per point), zstd-compressed raw, and BC1.
    pub raw_bytes: u64,
    pub raw_zstd_bytes: u64,
    pub bc1_bytes: u64,
}

/// One BC1 encoder on a package's colours.
#[derive(Clone, Debug, Serialize)]
pub struct Bc1EncoderFigure {
    /// The `--colors` value that selects it.
    pub colors: &'static str,
    pub psnr_db: f64,
    pub max_error: u8,
    /// Wall time to encode every tile's colours (the current rayon pool).
    pub encode_seconds: f64,
}

/// BC1 against raw colours for the package at `package` (built with `--colors raw`), one row per encoder.
pub fn bc1(package: &Path) -> Result<Bc1Figure> {
    use crate::bc1::Bc1Fit;
    use grotto_format::spec::Rgba8;
    use grotto_format::{Package, SectionKind};
    const FITS: [(&str, Bc1Fit); 3] =
        [("bc1", Bc1Fit::Refined), ("bc1-fast", Bc1Fit::Fast), ("bc1-cluster", Bc1Fit::Cluster)];
    let pkg = Package::open(package)?;
    let mut all = Vec::new();
    let mut decoded: [Vec<[u8; 3]>; 3] = Default::default();
    let mut seconds = [0f64; 3];
    let (mut raw_bytes, mut zstd_bytes, mut bc1_bytes) = (0u64, 0u64, 0u64);
    for t in pkg.tiles() {
        let s = t.find(SectionKind::SurfelColorsRaw, 0).ok_or_else(|| Error::Parameter {
            name: "package",
            reason: format!("{} has no raw colours; build it with --colors raw", package.display()),
        })?;
        let raw = pkg.read::<Rgba8>(&s)?;
        let rgb: Vec<[u8; 3]> = raw.iter().map(|c| [c.0[0], c.0[1], c.0[2]]).collect();
        for (f, &(_, fit)) in FITS.iter().enumerate() {
            let start = Instant::now();
            let blocks = crate::bc1::encode(&rgb, fit);
            seconds[f] += start.elapsed().as_secs_f64();
            decoded[f].extend(crate::bc1::decode(&blocks, rgb.len()));
            if f == 0 {
                bc1_bytes += (blocks.len() * 8) as u64;
            }
        }
        raw_bytes += s.raw_len;
        zstd_bytes += s.stored_len;
        all.extend(rgb);
    }
    let encoders = FITS
        .iter()
        .zip(&decoded)
        .zip(seconds)
        .map(|((&(colors, _), decoded), encode_seconds)| {
            let (psnr_db, max_error) = crate::bc1::psnr(&all, decoded);
            Bc1EncoderFigure { colors, psnr_db, max_error, encode_seconds }
        })
        .collect();
    Ok(Bc1Figure {
        package: package.display().to_string(),
        points: all.len() as u64,
        encoders,
        raw_bytes,
        raw_zstd_bytes: zstd_bytes,
        bc1_bytes,
    })
}

/// One surfel encoding's size (`grotto-pack bench-encoding`).
#[derive(Clone, Debug, Serialize)]
pub struct EncodingRow {
    pub encoding: &'static str,
    pub surfel_bytes: u64,
    pub surfel_bytes_per_point: f64,
    /// The whole package with its surfels stored this way, per point.
    pub package_bytes_per_point: f64,
}

/// What format 2.0's compact surfels ([`grotto_format::compact`]) cost on a package: sizes, the
/// errors of the compact surfels against the package's own (run it on a package built with
/// `--surfels full`), and the time to encode and to decode them.
#[derive(Clone, Debug, Serialize)]
pub struct EncodingFigure {
    pub package: String,
    pub points: u64,
    pub(crate) package_bytes: u64,
    /// Leaf sizes in the package, and the position bits each gets for a 1 mm bound.
    pub position_bits: Vec<(f64, u32)>,
    /// Runs of surfels sharing a leaf (one per leaf when they come grouped, as in Morton order).
    pub runs: u64,
    /// Tiles whose surfels the bounds cannot hold, which a build keeps at full precision.
    pub full_precision_tiles: u64,
    pub rows: Vec<EncodingRow>,
    pub position_error_max_mm: f64,
    pub position_error_mean_mm: f64,
    pub normal_error_max_deg: f64,
    pub normal_error_mean_deg: f64,
    pub radius_error_max_rel: f64,
    pub spread_error_max: f64,
    /// Quantising every surfel, one thread (zstd not included).
    pub encode_seconds: f64,
    /// Decoding every compact section after zstd, one thread: what loading a tile costs on top of
    /// reading it.
    pub decode_seconds: f64,
    /// zstd of the compact sections, one thread.
    pub zstd_seconds: f64,
}

/// Surfel encodings of the package at `package`: sizes per point and the compact encoding's errors and
/// times.
pub fn encoding(package: &Path) -> Result<EncodingFigure> {
    use grotto_format::compact::{self, Header};
    use grotto_format::{Package, SectionKind};
    let pkg = Package::open(package)?;
    let package_bytes =
        std::fs::metadata(package).map_err(|source| Error::Io { path: package.into(), source })?.len();
    let (mut points, mut stored_surfel_bytes, mut runs, mut full_tiles) = (0u64, 0u64, 0u64, 0u64);
    let mut bits_by_leaf: Vec<(f64, u32)> = Vec::new();
    let (mut pos_max, mut pos_sum, mut n_max, mut n_sum, mut r_max, mut s_max) =
        (0f64, 0f64, 0f64, 0f64, 0f64, 0f64);
    let (mut compact_raw, mut compact_zstd) = (0u64, 0u64);
    let (mut encode_seconds, mut decode_seconds, mut zstd_seconds) = (0f64, 0f64, 0f64);
    // Bytes just encoded that do not decode would be a codec bug; reported, not unwrapped.
    let invalid = |reason: String| Error::Read { path: package.into(), format: "compact surfels", reason };
    for tile in pkg.tiles() {
        let Some(surfels) = tile.surfels()? else { continue };
        for kind in [SectionKind::Surfels, SectionKind::SurfelsCompact] {
            stored_surfel_bytes += tile.find(kind, 0).map_or(0, |s| s.stored_len);
        }
        let (leaf_m, depth) = (tile.leaf_size_m(), tile.depth());
        points += surfels.len() as u64;
        let start = Instant::now();
        let encoded = compact::encode(&surfels, leaf_m, depth, compact::MAX_POSITION_ERROR_M);
        encode_seconds += start.elapsed().as_secs_f64();
        let Some(bytes) = encoded else {
            full_tiles += 1;
            compact_raw += 32 * surfels.len() as u64;
            compact_zstd += 32 * surfels.len() as u64;
            continue;
        };
        let header = Header::read(&bytes).map_err(&invalid)?;
        if !bits_by_leaf.iter().any(|&(l, _)| l == leaf_m) {
            bits_by_leaf.push((leaf_m, header.position_bits));
        }
        runs += u64::from(header.run_count);
        let start = Instant::now();
        let packed =
            zstd::bulk::compress(&bytes, 3).map_err(|source| Error::Io { path: package.into(), source })?;
        zstd_seconds += start.elapsed().as_secs_f64();
        compact_raw += bytes.len() as u64;
        compact_zstd += packed.len().min(bytes.len()) as u64;
        let start = Instant::now();
        let back = compact::decode(&bytes, leaf_m, depth).map_err(&invalid)?;
        decode_seconds += start.elapsed().as_secs_f64();
        for (sf, d) in surfels.iter().zip(&back) {
            let e =
                (0..3).map(|a| f64::from(d.position_tile_m[a] - sf.position_tile_m[a]).powi(2)).sum::<f64>();
            let e = e.sqrt() * 1e3;
            pos_max = pos_max.max(e);
            pos_sum += e;
            // atan2(|a x b|, a . b): stored normals are unit only to f32 rounding, which an acos
            // of the dot product near 1 would count as several thousandths of a degree.
            let (a, b) = (d.normal.map(f64::from), sf.normal.map(f64::from));
            let cross = [a[1] * b[2] - a[2] * b[1], a[2] * b[0] - a[0] * b[2], a[0] * b[1] - a[1] * b[0]];
            let sin = (cross[0] * cross[0] + cross[1] * cross[1] + cross[2] * cross[2]).sqrt();
            let deg = sin.atan2(a[0] * b[0] + a[1] * b[1] + a[2] * b[2]).to_degrees();
            n_max = n_max.max(deg);
            n_sum += deg;
            if sf.radius_m > 0.0 {
                r_max = r_max.max(f64::from((d.radius_m / sf.radius_m - 1.0).abs()));
            }
            s_max = s_max.max(f64::from((d.spread - sf.spread).abs()));
        }
    }
    let per_point = |b: u64| b as f64 / points.max(1) as f64;
    let rest = package_bytes - stored_surfel_bytes;
    let row = |encoding, surfel_bytes: u64| EncodingRow {
        encoding,
        surfel_bytes,
        surfel_bytes_per_point: per_point(surfel_bytes),
        package_bytes_per_point: per_point(rest + surfel_bytes),
    };
    Ok(EncodingFigure {
        package: package.display().to_string(),
        points,
        package_bytes,
        position_bits: bits_by_leaf,
        runs,
        full_precision_tiles: full_tiles,
        rows: vec![
            row("stored in the package", stored_surfel_bytes),
            row("f32 (format 1.2, --surfels full)", 32 * points),
            row("compact, before zstd", compact_raw),
            row("compact, zstd 3 (format 2.0)", compact_zstd),
        ],
        position_error_max_mm: pos_max,
        position_error_mean_mm: pos_sum / points.max(1) as f64,
        normal_error_max_deg: n_max,
        normal_error_mean_deg: n_sum / points.max(1) as f64,
        radius_error_max_rel: r_max,
        spread_error_max: s_max,
        encode_seconds,
        decode_seconds,
        zstd_seconds,
    })
}
