//! Out-of-core tiling in two streaming passes, as the fastest point-cloud converters do.
//!
//! 1. **Count**: every scan is streamed once; each point is posed into the world (f64) and counted
//!    into a fine grid of cells `min_tile_extent_m` wide. Memory grows with occupied cells, not
//!    points.
//! 2. **Plan**: counts are summed up a power-of-two pyramid; from the coarsest level
//!    (`max_tile_extent_m`) down, a cell with at most `max_points_per_tile` points (or at the finest
//!    level) becomes a tile, otherwise its occupied children are considered. Tiles are cubes of one
//!    grid anchored at the lowest occupied fine cell, so the tiling of a cloud shifted by a multiple
//!    of the fine cell (survey offsets are whole metres) is the same, tile for tile.
//! 3. **Distribute**: every scan is streamed again; each point goes to its tile's bin on disk as
//!    tile-local f32 (the f64 world position never leaves this module), and to neighbouring tiles
//!    within `halo_m` as a halo copy, so normals and filtering see across tile borders. Per-tile
//!    buffers are flushed when together they exceed `buffer_bytes`, which bounds memory.
//!
//! The plan is written to `WORK/plan.json` with a fingerprint of inputs and parameters; a run
//! that finds a complete plan with the same fingerprint reuses the bins (resume).

use std::collections::HashMap;
use std::fs::{File, OpenOptions};
use std::io::Write;
use std::path::{Path, PathBuf};
use std::time::Instant;

use bytemuck::{Pod, Zeroable};
use rayon::prelude::*;
use serde::{Deserialize, Serialize};

use crate::ingest::{self, PointChunk};
use crate::manifest::ResolvedScan;
use crate::manifest::SeenFrom;
use crate::profile::{Profile, Stage};
use crate::{Error, Result};

/// Tiling knobs.
#[derive(Clone, Debug, Serialize)]
pub struct TilingParams {
    /// Finest tile edge, metres; a power of two.
    pub min_tile_extent_m: f64,
    /// Coarsest tile edge, metres; a power of two >= the finest.
    pub max_tile_extent_m: f64,
    /// A tile is split while it holds more points than this (unless it is at the finest level).
    pub max_points_per_tile: u64,
    /// Points this close to a tile's border are copied into the neighbour; <= the finest extent.
    pub halo_m: f64,
    /// Positions are quantised to this (a power of two, metres) once, from world coordinates:
    /// tiles, halos and voxel cells all derive from the same integers, so they agree whatever the
    /// tiling. The build sets it to leaf / 2^11.
    pub quantum_m: f64,
    /// Points per read.
    pub chunk_points: usize,
    /// Bin buffers are flushed to disk when they hold this many bytes together.
    pub buffer_bytes: usize,
    /// Keep the count pass's posed points on disk (`WORK/spill`, about 15-21 bytes a point,
    /// deleted once the bins are written) so that distribute reads them rather than decoding
    /// every scan again. How the bins are made, not what they hold: out of the fingerprint.
    #[serde(skip)]
    pub spill: bool,
}

impl Default for TilingParams {
    fn default() -> Self {
        Self {
            min_tile_extent_m: 1.0,
            max_tile_extent_m: 256.0,
            max_points_per_tile: 4_000_000,
            halo_m: 0.25,
            quantum_m: 1.0 / 65_536.0,
            chunk_points: ingest::DEFAULT_CHUNK,
            buffer_bytes: 256 << 20,
            spill: true,
        }
    }
}

/// One point in a tile bin. 24 bytes; keep in sync with `docs/architecture.md`.
#[repr(C)]
#[derive(Clone, Copy, Debug, PartialEq, Pod, Zeroable)]
pub struct BinPoint {
    /// Position relative to the tile origin, in quanta (`TilePlan::quantum_m`); negative or past
    /// the extent only for halo copies.
    pub pos_q: [i32; 3],
    /// Input normal in the world frame as snorm16, or zero when the scan had none.
    pub normal_snorm: [i16; 3],
    /// sRGB colour.
    pub rgb: [u8; 3],
    /// Bit 0: halo copy (belongs to a neighbour tile).
    pub flags: u8,
    /// Index of the scan the point came from (for its scanner position).
    pub scan: u16,
}

const _: () = assert!(size_of::<BinPoint>() == 24);

pub const FLAG_HALO: u8 = 1;

impl BinPoint {
    /// Tile-local position in metres (exact: quanta are powers of two and tiles < 2^24 quanta).
    pub fn pos_tile_m(&self, quantum_m: f64) -> [f32; 3] {
        self.pos_q.map(|q| (f64::from(q) * quantum_m) as f32)
    }
}

#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub struct PlannedTile {
    /// Extent = min_extent * 2^level.
    pub level: u32,
    /// Cell index at that level, relative to the grid anchor.
    pub key: [i64; 3],
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
    pub fn needs_orientation(&self) -> bool {
        self.scanner_known.iter().any(|k| !k)
    }

    /// How scan `scan`'s normals are oriented: `None` toward its scanner (known, or a scan index
    /// from before `scanner_known` was stored), else by enclosure, from the side it was seen from.
    pub fn seen_from(&self, scan: usize) -> Option<SeenFrom> {
        let known = self.scanner_known.get(scan).copied().unwrap_or(true);
        let outside = self.seen_from_outside.get(scan).copied().unwrap_or(false);
        (!known).then_some(if outside { SeenFrom::Outside } else { SeenFrom::Inside })
    }

    pub fn extent_m(&self, tile: &PlannedTile) -> f64 {
        self.min_extent_m * f64::from(1u32 << tile.level)
    }

    /// World position of the grid origin.
    pub fn grid_origin_m(&self) -> [f64; 3] {
        self.anchor.map(|a| a as f64 * self.min_extent_m)
    }

    pub fn origin_m(&self, tile: &PlannedTile) -> [f64; 3] {
        let g = self.grid_origin_m();
        let e = self.extent_m(tile);
        std::array::from_fn(|a| g[a] + tile.key[a] as f64 * e)
    }
}

/// Progress of a long step, for a bar in the binary.
#[derive(Clone, Copy, Debug)]
pub struct Progress {
    pub stage: &'static str,
    pub done: u64,
    pub total: u64,
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

fn check_params(p: &TilingParams) -> Result<()> {
    let pow2 = |v: f64| v > 0.0 && v.is_finite() && v.log2().fract() == 0.0;
    let bad = |name: &'static str, reason: String| Err(Error::Parameter { name, reason });
    if !pow2(p.min_tile_extent_m) || !pow2(p.max_tile_extent_m) || p.max_tile_extent_m < p.min_tile_extent_m {
        return bad(
            "tile extents",
            format!("{} .. {} m must be powers of two, min <= max", p.min_tile_extent_m, p.max_tile_extent_m),
        );
    }
    if (p.max_tile_extent_m / p.min_tile_extent_m).log2() > 20.0 {
        return bad("tile extents", "more than 20 levels between min and max".into());
    }
    if !(p.halo_m >= 0.0 && p.halo_m <= p.min_tile_extent_m) {
        return bad("halo_m", format!("{} must be in 0..=min tile extent {}", p.halo_m, p.min_tile_extent_m));
    }
    let steps = (p.min_tile_extent_m / p.quantum_m).log2();
    if !pow2(p.quantum_m) || steps < 0.0 || (p.max_tile_extent_m / p.quantum_m).log2() > 24.0 {
        return bad(
            "quantum_m",
            format!("{} m must be a power of two with tiles of at most 2^24 quanta", p.quantum_m),
        );
    }
    if p.max_points_per_tile == 0 || p.chunk_points == 0 {
        return bad("max_points_per_tile", "must be positive".into());
    }
    Ok(())
}

/// Fingerprint of the inputs (path, size, modification time, scan, pose) and the parameters.
fn fingerprint(scans: &[ResolvedScan], params: &TilingParams) -> Result<String> {
    let mut h = xxhash_rust::xxh3::Xxh3::new();
    for s in scans {
        let meta = std::fs::metadata(&s.path).map_err(|source| Error::Io { path: s.path.clone(), source })?;
        let mtime = meta
            .modified()
            .ok()
            .and_then(|t| t.duration_since(std::time::UNIX_EPOCH).ok())
            .map(|d| d.as_nanos());
        h.update(
            format!(
                "{}|{}|{:?}|{}|{:?}|{:?}|{}{}\n",
                s.path.display(),
                meta.len(),
                mtime,
                s.index,
                s.world_from_scan,
                s.scanner_world_m,
                s.scanner_known,
                // Only where it differs from before the field, so older plans still resume.
                if s.seen_from == SeenFrom::Outside { "|outside" } else { "" }
            )
            .as_bytes(),
        );
    }
    // The buffer and chunk sizes follow the memory budget: how many passes, not what the bins
    // hold, so they stay out of the fingerprint (a plan made under one budget serves another).
    let content = TilingParams { chunk_points: 0, buffer_bytes: 0, ..params.clone() };
    h.update(serde_json::to_string(&content).unwrap_or_default().as_bytes());
    Ok(format!("{:016x}", h.digest()))
}

fn write_json_atomic(path: &Path, value: &impl Serialize) -> Result<()> {
    let io = |source| Error::Io { path: path.to_path_buf(), source };
    let dir = path.parent().unwrap_or(Path::new("."));
    let mut tmp = tempfile::NamedTempFile::new_in(dir).map_err(io)?;
    serde_json::to_writer_pretty(&mut tmp, value).map_err(|e| io(e.into()))?;
    tmp.as_file().sync_all().map_err(io)?;
    tmp.persist(path).map_err(|e| io(e.error))?;
    Ok(())
}

/// The median distance from a point to its nearest distinct neighbour, in metres, over the first
/// `per_scan` points of each scan (posed into the world), with the number of points it was taken
/// over; None with fewer than two distinct points. Consecutive points of a scan lie together (a
/// scan line, a flight strip), so a scan's first points measure its spacing where a random sample
/// of a large survey would be too sparse to.
pub fn sample_spacing_m(scans: &[ResolvedScan], per_scan: usize) -> Result<Option<(f64, usize)>> {
    // Scans in parallel (each decoder is one thread's work), in order for the same median.
    let per_scan_spacings: Vec<(Vec<f64>, usize)> = scans
        .par_iter()
        .map(|scan| -> Result<(Vec<f64>, usize)> {
            // The LAZ reader decodes LAZ_BATCH requests' worth at once: requests of a full chunk
            // made a 10^5-point sample decode 5 * 10^5 points of each LAZ scan (half the time of
            // `--leaf-m auto` at 10^8).
            let mut chunk =
                PointChunk::new(per_scan.div_ceil(ingest::LAZ_BATCH).clamp(1, ingest::DEFAULT_CHUNK));
            let mut source = ingest::open_positions(&scan.path, scan.format, scan.index)?;
            let mut pts: Vec<[f64; 3]> = Vec::new();
            while pts.len() < per_scan && source.fill_chunk(&mut chunk)? > 0 {
                pts.extend(
                    chunk
                        .xyz
                        .iter()
                        .map(|p| scan.world_from_scan.apply(*p))
                        .filter(|p| p.iter().all(|c| c.is_finite()))
                        .take(per_scan - pts.len()),
                );
            }
            let Some(first) = pts.first().copied() else { return Ok((Vec::new(), 0)) };
            // Centred before the cast: survey coordinates in f32 would round to decimetres.
            let local: Vec<[f32; 3]> =
                pts.iter().map(|p| [0, 1, 2].map(|a| (p[a] - first[a]) as f32)).collect();
            let (_, knn) = crate::knn::Knn::new(&local);
            // The nearest neighbour at a non-zero distance (duplicates say nothing of spacing)
            // is the smallest of the 8 nearest; queries in Morton order reuse the kNN's cells.
            let mut cache = crate::knn::CellCache::default();
            let mut nbs = Vec::with_capacity(8);
            let mut spacing = Vec::with_capacity(local.len());
            // The previous query's 8th distance, widened, as the guess of this one's (exact
            // whatever the guess; a good one skips most candidates, as in normals.rs).
            let mut guess_d2 = f32::INFINITY;
            for j in 0..local.len() {
                knn.nearest(j, 8, guess_d2, &mut cache, &mut nbs);
                let d2 = nbs.iter().map(|nb| nb.0).fold(0.0f32, f32::max);
                guess_d2 = if d2 > 0.0 { d2 * crate::normals::KNN_BOUND_FACTOR } else { f32::INFINITY };
                if let Some(d2) = nbs.iter().map(|nb| nb.0).filter(|&d2| d2 > 0.0).reduce(f32::min) {
                    spacing.push(f64::from(d2).sqrt());
                }
            }
            Ok((spacing, pts.len()))
        })
        .collect::<Result<_>>()?;
    let sampled: usize = per_scan_spacings.iter().map(|s| s.1).sum();
    let mut spacings: Vec<f64> = per_scan_spacings.into_iter().flat_map(|s| s.0).collect();
    if spacings.is_empty() {
        return Ok(None);
    }
    let mid = spacings.len() / 2;
    let median = *spacings.select_nth_unstable_by(mid, f64::total_cmp).1;
    Ok(Some((median, sampled)))
}

/// Streams the scans through `workers` threads, one scan per worker at a time, claimed in index
/// order (so each worker meets its scans in increasing order). Each worker keeps its own state,
/// made by `init(worker)`; `work(state, scan, posed)` sees every chunk's valid points posed into
/// the world and quantised (their normals too when `pose_normals`). A scan with a spill file in
/// `spill_from` is read from it rather than decoded. Decoding, posing and spill reads add to
/// `stages.0` of `profile`, `work` to `stages.1`, each summed over the workers; the workers report
/// points done to `progress` on this thread. The first error stops every worker and is
/// returned; else the states, by worker.
#[allow(clippy::too_many_arguments)]
fn par_scans<S: Send>(
    scans: &[ResolvedScan],
    chunk_points: usize,
    inv_quantum: f64,
    pose_normals: bool,
    spill_from: Option<&Path>,
    profile: &Profile,
    stages: (Stage, Stage),
    progress: &dyn Fn(u64),
    init: impl Fn(usize) -> S + Sync,
    work: impl Fn(&mut S, usize, &Posed) -> Result<()> + Sync,
) -> Result<Vec<S>> {
    use std::sync::atomic::{AtomicBool, AtomicUsize, Ordering};
    let workers = scan_workers(scans);
    let next = AtomicUsize::new(0);
    let failed = AtomicBool::new(false);
    let (done_tx, done_rx) = std::sync::mpsc::channel::<u64>();
    std::thread::scope(|scope| {
        let handles: Vec<_> = (0..workers)
            .map(|w| {
                let done_tx = done_tx.clone();
                let (next, failed, init, work) = (&next, &failed, &init, &work);
                scope.spawn(move || -> Result<S> {
                    let mut state = init(w);
                    let mut chunk = PointChunk::new(chunk_points);
                    let mut posed = Posed::default();
                    while !failed.load(Ordering::Relaxed) {
                        let si = next.fetch_add(1, Ordering::Relaxed);
                        let Some(scan) = scans.get(si) else { break };
                        let spilled = spill_from.map(|dir| spill_path(dir, si)).filter(|p| p.is_file());
                        let mut one_scan = || -> Result<()> {
                            if let Some(path) = &spilled {
                                let mut reader = profile.time(stages.0, || SpillReader::open(path))?;
                                while !failed.load(Ordering::Relaxed) {
                                    if !profile.time(stages.0, || reader.read(&mut posed))? {
                                        break;
                                    }
                                    profile.time(stages.1, || work(&mut state, si, &posed))?;
                                    let _ = done_tx.send(posed.len() as u64 + posed.invalid);
                                }
                                return Ok(());
                            }
                            let mut source = profile
                                .time(stages.0, || ingest::open(&scan.path, scan.format, scan.index))?;
                            while !failed.load(Ordering::Relaxed) {
                                let clock = Instant::now();
                                if source.fill_chunk(&mut chunk)? == 0 {
                                    break;
                                }
                                let pose = &scan.world_from_scan;
                                for p in &mut chunk.xyz {
                                    *p = pose.apply(*p);
                                }
                                if pose_normals {
                                    for n in &mut chunk.normal {
                                        *n = pose.rotate(n.map(f64::from)).map(|v| v as f32);
                                    }
                                }
                                posed.fill(&chunk, inv_quantum, pose_normals);
                                profile.add(stages.0, clock.elapsed());
                                profile.time(stages.1, || work(&mut state, si, &posed))?;
                                let _ = done_tx.send(chunk.len() as u64);
                            }
                            Ok(())
                        };
                        if let Err(e) = one_scan() {
                            failed.store(true, Ordering::Relaxed);
                            return Err(e);
                        }
                    }
                    Ok(state)
                })
            })
            .collect();
        // The workers hold the only senders left: the loop ends when they all have.
        drop(done_tx);
        let mut done = 0u64;
        for n in done_rx {
            done += n;
            progress(done);
        }
        let mut states = Vec::with_capacity(workers);
        let mut first_error = None;
        for handle in handles {
            match handle.join().unwrap_or_else(|panic| std::panic::resume_unwind(panic)) {
                Ok(state) => states.push(state),
                Err(e) => {
                    first_error.get_or_insert(e);
                }
            }
        }
        first_error.map_or(Ok(states), Err)
    })
}

/// A chunk's valid points as both passes use them: global quanta (the one rounding every later
/// decision shares), the file normal as snorm16 (zero: none; the vector is empty where the chunk
/// has no normals) and the colour; and how many points of the chunk were invalid.
#[derive(Debug, Default)]
struct Posed {
    q: Vec<[i64; 3]>,
    normal_snorm: Vec<[i16; 3]>,
    rgb: Vec<[u8; 3]>,
    invalid: u64,
}

impl Posed {
    fn len(&self) -> usize {
        self.q.len()
    }

    fn clear(&mut self) {
        self.q.clear();
        self.normal_snorm.clear();
        self.rgb.clear();
        self.invalid = 0;
    }

    /// The valid points of a chunk already posed into the world.
    fn fill(&mut self, chunk: &PointChunk, inv_quantum: f64, with_normals: bool) {
        self.clear();
        let with_normals = with_normals && !chunk.normal.is_empty();
        for (i, p) in chunk.xyz.iter().enumerate() {
            if !valid_world(p) {
                self.invalid += 1;
                continue;
            }
            self.q.push(quantise(p, inv_quantum));
            self.rgb.push(chunk.rgb[i]);
            if with_normals {
                self.normal_snorm.push(chunk.normal.get(i).map_or([0; 3], |n| {
                    let len = n.iter().map(|c| c * c).sum::<f32>().sqrt();
                    if len.is_finite() && len > 1e-6 {
                        n.map(|c| (c / len * 32767.0).round() as i16)
                    } else {
                        [0; 3]
                    }
                }));
            }
        }
    }

    fn normal(&self, i: usize) -> [i16; 3] {
        self.normal_snorm.get(i).copied().unwrap_or([0; 3])
    }
}

/// The spill file of one scan: the count pass's posed points, which distribute reads instead of
/// decoding the scan again (LAZ and E57 decoding was a quarter of the plan step's CPU at 10^8).
fn spill_path(work_dir: &Path, scan: usize) -> PathBuf {
    work_dir.join("spill").join(format!("{scan:05}.spill"))
}

/// One block of a spill file: a chunk's valid points, then `points` positions (`[i32; 3]` offsets
/// from `base`, or `[i64; 3]` quanta where `SPILL_WIDE`: the chunk spans over 2^31 quanta),
/// `points` colours, and `points` snorm normals where `SPILL_NORMALS`.
#[repr(C)]
#[derive(Clone, Copy, Debug, Pod, Zeroable)]
struct SpillBlock {
    base: [i64; 3],
    points: u32,
    invalid: u32,
    flags: u32,
    reserved: u32,
}

const SPILL_NORMALS: u32 = 1;
const SPILL_WIDE: u32 = 2;
/// Most points one block holds (a reader allocates no more than this, whatever the file says).
const SPILL_MAX_BLOCK: usize = 1 << 22;

/// Writes one scan's spill file, under a temporary name until it is complete.
struct SpillWriter {
    scan: usize,
    tmp: PathBuf,
    path: PathBuf,
    out: std::io::BufWriter<File>,
}

impl SpillWriter {
    fn create(work_dir: &Path, scan: usize) -> Result<Self> {
        let path = spill_path(work_dir, scan);
        let tmp = path.with_extension("spill.tmp");
        let file = File::create(&tmp).map_err(|source| Error::Io { path: tmp.clone(), source })?;
        Ok(Self { scan, tmp, path, out: std::io::BufWriter::with_capacity(1 << 20, file) })
    }

    fn write(&mut self, posed: &Posed) -> Result<()> {
        let io = |source| Error::Io { path: self.tmp.clone(), source };
        for start in (0..posed.len().max(1)).step_by(SPILL_MAX_BLOCK) {
            let end = (start + SPILL_MAX_BLOCK).min(posed.len());
            let q = &posed.q[start..end];
            let base = q.first().copied().unwrap_or([0; 3]);
            let narrow: Option<Vec<[i32; 3]>> = q
                .iter()
                .map(|p| {
                    let d: [Option<i32>; 3] = std::array::from_fn(|a| i32::try_from(p[a] - base[a]).ok());
                    Some([d[0]?, d[1]?, d[2]?])
                })
                .collect();
            let normals = !posed.normal_snorm.is_empty();
            let block = SpillBlock {
                base,
                points: (end - start) as u32,
                invalid: if start == 0 { posed.invalid.min(u64::from(u32::MAX)) as u32 } else { 0 },
                flags: if normals { SPILL_NORMALS } else { 0 }
                    | if narrow.is_none() { SPILL_WIDE } else { 0 },
                reserved: 0,
            };
            self.out.write_all(bytemuck::bytes_of(&block)).map_err(io)?;
            match &narrow {
                Some(offsets) => self.out.write_all(bytemuck::cast_slice(offsets)).map_err(io)?,
                None => self.out.write_all(bytemuck::cast_slice(q)).map_err(io)?,
            }
            self.out.write_all(bytemuck::cast_slice(&posed.rgb[start..end])).map_err(io)?;
            if normals {
                self.out.write_all(bytemuck::cast_slice(&posed.normal_snorm[start..end])).map_err(io)?;
            }
        }
        Ok(())
    }

    /// Flushes the file and gives it its final name.
    fn finish(self) -> Result<()> {
        let file = self
            .out
            .into_inner()
            .map_err(|e| Error::Io { path: self.tmp.clone(), source: e.into_error() })?;
        drop(file);
        std::fs::rename(&self.tmp, &self.path).map_err(|source| Error::Io { path: self.path.clone(), source })
    }
}

/// Reads a spill file back block by block, checking every length against the file's.
struct SpillReader {
    path: PathBuf,
    input: std::io::BufReader<File>,
    left: u64,
    offsets: Vec<[i32; 3]>,
}

impl SpillReader {
    fn open(path: &Path) -> Result<Self> {
        let io = |source| Error::Io { path: path.to_path_buf(), source };
        let file = File::open(path).map_err(io)?;
        let left = file.metadata().map_err(io)?.len();
        Ok(Self {
            path: path.to_path_buf(),
            input: std::io::BufReader::with_capacity(1 << 20, file),
            left,
            offsets: Vec::new(),
        })
    }

    /// The next block into `posed`; false at the end of the file.
    fn read(&mut self, posed: &mut Posed) -> Result<bool> {
        use std::io::Read;
        posed.clear();
        if self.left == 0 {
            return Ok(false);
        }
        let corrupt = |what: String| Error::Read {
            path: self.path.clone(),
            format: "spill",
            reason: format!("corrupt spill file (delete WORK/spill to decode the scans again): {what}"),
        };
        let mut block = SpillBlock::zeroed();
        let header = size_of::<SpillBlock>() as u64;
        if self.left < header {
            return Err(corrupt(format!("{} trailing bytes", self.left)));
        }
        let io = |source| Error::Io { path: self.path.clone(), source };
        self.input.read_exact(bytemuck::bytes_of_mut(&mut block)).map_err(io)?;
        self.left -= header;
        let n = block.points as usize;
        let wide = block.flags & SPILL_WIDE != 0;
        let normals = block.flags & SPILL_NORMALS != 0;
        let per_point = if wide { 24 } else { 12 } + 3 + if normals { 6 } else { 0 };
        if n > SPILL_MAX_BLOCK
            || block.flags & !(SPILL_WIDE | SPILL_NORMALS) != 0
            || (n * per_point) as u64 > self.left
        {
            return Err(corrupt(format!(
                "block of {n} points, flags {:#x}, {} bytes left",
                block.flags, self.left
            )));
        }
        self.left -= (n * per_point) as u64;
        posed.invalid = u64::from(block.invalid);
        if wide {
            posed.q.resize(n, [0; 3]);
            self.input.read_exact(bytemuck::cast_slice_mut(&mut posed.q)).map_err(io)?;
        } else {
            self.offsets.resize(n, [0; 3]);
            self.input.read_exact(bytemuck::cast_slice_mut(&mut self.offsets)).map_err(io)?;
            let base = block.base;
            posed.q.extend(self.offsets.iter().map(|d| std::array::from_fn(|a| base[a] + i64::from(d[a]))));
        }
        posed.rgb.resize(n, [0; 3]);
        self.input.read_exact(bytemuck::cast_slice_mut(&mut posed.rgb)).map_err(io)?;
        if normals {
            posed.normal_snorm.resize(n, [0; 3]);
            self.input.read_exact(bytemuck::cast_slice_mut(&mut posed.normal_snorm)).map_err(io)?;
        }
        Ok(true)
    }
}

/// How many workers `par_scans` runs: one per thread of the current pool, at most one per scan
/// (distribute records it as the plan's `bin_writers`).
fn scan_workers(scans: &[ResolvedScan]) -> usize {
    rayon::current_num_threads().clamp(1, scans.len().max(1))
}

/// Whether a posed point is kept: both passes must drop the same points, or the counts the plan
/// was made from would not be the points distributed.
fn valid_world(p: &[f64; 3]) -> bool {
    p.iter().all(|v| v.is_finite() && v.abs() < 1e15)
}

/// The point in global quanta: the one rounding every later decision shares.
fn quantise(p: &[f64; 3], inv_quantum: f64) -> [i64; 3] {
    p.map(|v| (v * inv_quantum).floor() as i64)
}

/// Fine cell of a quantised point (`shift` = log2(min extent / quantum); arithmetic shifts floor).
fn fine_key(q: [i64; 3], shift: u32) -> [i64; 3] {
    q.map(|v| v >> shift)
}

/// The complete plan in `work_dir` if it was made from exactly these scans and parameters.
pub fn existing_plan(
    scans: &[ResolvedScan],
    work_dir: &Path,
    params: &TilingParams,
) -> Result<Option<TilePlan>> {
    check_params(params)?;
    let fingerprint = fingerprint(scans, params)?;
    Ok(std::fs::read_to_string(work_dir.join("plan.json"))
        .ok()
        .and_then(|text| serde_json::from_str::<TilePlan>(&text).ok())
        .filter(|plan| plan.fingerprint == fingerprint && plan.bins_complete))
}

/// Runs (or resumes) the tiling of `scans` into `work_dir`.
pub fn tile_scans(
    scans: &[ResolvedScan],
    work_dir: &Path,
    params: &TilingParams,
    progress: &dyn Fn(Progress),
    profile: &Profile,
) -> Result<TilePlan> {
    check_params(params)?;
    if scans.len() > usize::from(u16::MAX) {
        return Err(Error::Parameter {
            name: "scans",
            reason: format!("{} scans; at most 65535 per build", scans.len()),
        });
    }
    let io = |path: &Path| {
        let path = path.to_path_buf();
        move |source| Error::Io { path, source }
    };
    std::fs::create_dir_all(work_dir.join("bins")).map_err(io(work_dir))?;
    let fingerprint = fingerprint(scans, params)?;
    let plan_path = work_dir.join("plan.json");
    let earlier = std::fs::read_to_string(&plan_path)
        .ok()
        .and_then(|text| serde_json::from_str::<TilePlan>(&text).ok())
        .filter(|plan| plan.fingerprint == fingerprint);
    let mut plan = match earlier {
        Some(plan) if plan.bins_complete => return Ok(plan),
        // Interrupted while distributing: the plan stands, only the bins are redone.
        Some(plan) => plan,
        None => {
            // Spill files of an earlier run may be of other scans: made afresh.
            let spill_dir = work_dir.join("spill");
            let _ = std::fs::remove_dir_all(&spill_dir);
            if params.spill {
                std::fs::create_dir_all(&spill_dir).map_err(io(&spill_dir))?;
            }
            let spill_to = params.spill.then_some(work_dir);
            let plan = count_and_plan(scans, params, spill_to, fingerprint, progress, profile)?;
            write_json_atomic(&plan_path, &plan)?;
            plan
        }
    };
    distribute(scans, work_dir, params, &mut plan, progress, profile)?;
    plan.bins_complete = true;
    write_json_atomic(&plan_path, &plan)?;
    // Only now: an interrupted distribute reads the spill again on resume.
    let _ = std::fs::remove_dir_all(work_dir.join("spill"));
    Ok(plan)
}

/// Pass 1: the points of every fine cell, with the valid and invalid points. Scans are decoded,
/// posed and counted in parallel (counts add up the same in any order); with `spill_to`, each
/// scan's posed points are written there for pass 2.
#[allow(clippy::too_many_arguments)]
fn count_cells(
    scans: &[ResolvedScan],
    chunk_points: usize,
    inv_quantum: f64,
    shift: u32,
    claimed: u64,
    spill_to: Option<&Path>,
    progress: &dyn Fn(Progress),
    profile: &Profile,
) -> Result<(foldhash::HashMap<[i64; 3], u64>, u64, u64)> {
    type Counts = (foldhash::HashMap<[i64; 3], u64>, u64, u64);
    let states = par_scans(
        scans,
        chunk_points,
        inv_quantum,
        spill_to.is_some(),
        None,
        profile,
        (Stage::CountRead, Stage::Count),
        &|done| progress(Progress { stage: "count", done, total: claimed }),
        |_| -> (Counts, Option<SpillWriter>) { ((foldhash::HashMap::default(), 0, 0), None) },
        |((fine, points, invalid), spill), si, posed| {
            // Scan order keeps runs of points in one fine cell: one hash update per run.
            let mut run: Option<([i64; 3], u64)> = None;
            for &q in &posed.q {
                let key = fine_key(q, shift);
                match &mut run {
                    Some((k, n)) if *k == key => *n += 1,
                    _ => {
                        if let Some((k, n)) = run.replace((key, 1)) {
                            *fine.entry(k).or_default() += n;
                        }
                    }
                }
            }
            if let Some((k, n)) = run {
                *fine.entry(k).or_default() += n;
            }
            *points += posed.len() as u64;
            *invalid += posed.invalid;
            if let Some(dir) = spill_to {
                profile.time(Stage::Spill, || -> Result<()> {
                    // A worker's scans come one after another: the previous one is complete.
                    if spill.as_ref().is_none_or(|w| w.scan != si) {
                        if let Some(done) = spill.take() {
                            done.finish()?;
                        }
                        *spill = Some(SpillWriter::create(dir, si)?);
                    }
                    spill.as_mut().map_or(Ok(()), |w| w.write(posed))
                })?;
            }
            Ok(())
        },
    )?;
    let mut total: Counts = (foldhash::HashMap::default(), 0, 0);
    for ((fine, points, invalid), spill) in states {
        if let Some(done) = spill {
            profile.time(Stage::Spill, || done.finish())?;
        }
        for (k, n) in fine {
            *total.0.entry(k).or_default() += n;
        }
        total.1 += points;
        total.2 += invalid;
    }
    Ok(total)
}

/// Pass 1 and the plan.
fn count_and_plan(
    scans: &[ResolvedScan],
    params: &TilingParams,
    spill_to: Option<&Path>,
    fingerprint: String,
    progress: &dyn Fn(Progress),
    profile: &Profile,
) -> Result<TilePlan> {
    // Pass 1: count.
    let claimed: u64 = profile.time(Stage::CountRead, || {
        scans
            .iter()
            .map(|s| ingest::header(&s.path, s.format, s.index).map(|info| info.claimed_points))
            .sum::<Result<u64>>()
    })?;
    let inv = 1.0 / params.quantum_m;
    let shift = (params.min_tile_extent_m / params.quantum_m).log2() as u32;
    let (fine, points, invalid) =
        count_cells(scans, params.chunk_points, inv, shift, claimed, spill_to, progress, profile)?;

    // Plan: pyramid of counts relative to the anchor, tiles chosen top-down.
    let planning = Instant::now();
    let anchor = fine.keys().fold([i64::MAX; 3], |a, k| std::array::from_fn(|i| a[i].min(k[i])));
    let top = (params.max_tile_extent_m / params.min_tile_extent_m).log2() as u32;
    let mut levels: Vec<HashMap<[i64; 3], u64>> = Vec::with_capacity(top as usize + 1);
    levels.push(fine.iter().map(|(k, &n)| (std::array::from_fn(|i| k[i] - anchor[i]), n)).collect());
    drop(fine);
    for l in 1..=top as usize {
        let mut up: HashMap<[i64; 3], u64> = HashMap::new();
        for (k, &n) in &levels[l - 1] {
            *up.entry(k.map(|v| v >> 1)).or_default() += n;
        }
        levels.push(up);
    }
    let mut tiles = Vec::new();
    let mut stack: Vec<(u32, [i64; 3])> = levels[top as usize].keys().map(|k| (top, *k)).collect();
    stack.sort_unstable();
    while let Some((level, key)) = stack.pop() {
        let n = levels[level as usize][&key];
        if n <= params.max_points_per_tile || level == 0 {
            tiles.push(PlannedTile { level, key, points: n });
        } else {
            for o in 0..8i64 {
                let child = [key[0] * 2 + (o & 1), key[1] * 2 + (o >> 1 & 1), key[2] * 2 + (o >> 2 & 1)];
                if levels[level as usize - 1].contains_key(&child) {
                    stack.push((level - 1, child));
                }
            }
        }
    }
    // Deterministic order: coarse first, then by position.
    tiles.sort_unstable_by_key(|t| (std::cmp::Reverse(t.level), t.key));
    drop(levels);
    profile.add(Stage::Count, planning.elapsed());
    Ok(TilePlan {
        fingerprint,
        min_extent_m: params.min_tile_extent_m,
        quantum_m: params.quantum_m,
        anchor: if tiles.is_empty() { [0; 3] } else { anchor },
        tiles,
        points,
        invalid_points: invalid,
        halo_points: 0,
        scanners_world_m: scans.iter().map(|s| s.scanner_world_m).collect(),
        scanner_known: scans.iter().map(|s| s.scanner_known).collect(),
        seen_from_outside: scans.iter().map(|s| s.seen_from == SeenFrom::Outside).collect(),
        bin_writers: 0,
        bins_complete: false,
    })
}

/// Pass 2: every point into its tile's bin (and halo copies into neighbours'). Scans are
/// distributed in parallel, each worker into its own bin files with its share of the buffer
/// budget; `read_bin` puts a tile's points back in scan order, so the bins read the same
/// whatever the number of workers.
fn distribute(
    scans: &[ResolvedScan],
    work_dir: &Path,
    params: &TilingParams,
    plan: &mut TilePlan,
    progress: &dyn Fn(Progress),
    profile: &Profile,
) -> Result<()> {
    let inv = 1.0 / params.quantum_m;
    let shift = (params.min_tile_extent_m / params.quantum_m).log2() as u32;
    let top = (params.max_tile_extent_m / params.min_tile_extent_m).log2() as u32;
    let total = plan.points + plan.invalid_points;
    // Every bin of an earlier, interrupted run, whatever its number of workers.
    let bins_dir = work_dir.join("bins");
    let entries =
        std::fs::read_dir(&bins_dir).map_err(|source| Error::Io { path: bins_dir.clone(), source })?;
    for entry in entries.flatten() {
        if entry.path().extension().is_some_and(|e| e == "bin") {
            let _ = std::fs::remove_file(entry.path());
        }
    }
    let workers = scan_workers(scans);
    let frozen: &TilePlan = plan;
    // Tile origins and extents in quanta.
    let origins: Vec<[i64; 3]> = frozen
        .tiles
        .iter()
        .map(|t| std::array::from_fn(|a| (frozen.anchor[a] + (t.key[a] << t.level)) << shift))
        .collect();
    let extents: Vec<i64> = frozen.tiles.iter().map(|t| 1i64 << (t.level + shift)).collect();
    let h = (params.halo_m * inv).round() as i64;
    let states = par_scans(
        scans,
        params.chunk_points,
        inv,
        true,
        Some(work_dir),
        profile,
        (Stage::DistributeRead, Stage::Distribute),
        &|done| progress(Progress { stage: "distribute", done, total }),
        |w| {
            let bins = Bins::new(work_dir, frozen.tiles.len(), params.buffer_bytes / workers, w);
            (Routes::new(frozen, shift, top, h), bins, 0u64)
        },
        |(routes, bins, halo), si, posed| {
            for (i, &q) in posed.q.iter().enumerate() {
                let Some(t) = routes.tile(fine_key(q, shift)) else { continue };
                // In range: tiles are < 2^24 quanta and halos < one fine cell.
                let local =
                    |tile: usize| -> [i32; 3] { std::array::from_fn(|a| (q[a] - origins[tile][a]) as i32) };
                let point = BinPoint {
                    pos_q: local(t),
                    normal_snorm: posed.normal(i),
                    rgb: posed.rgb[i],
                    flags: 0,
                    scan: si as u16,
                };
                bins.push(t, point)?;
                // Halo: only points near their tile's border can reach a neighbour.
                let near = point.pos_q.iter().any(|&c| i64::from(c) < h || i64::from(c) >= extents[t] - h);
                if h > 0 && near {
                    for &n in routes.halo(q, t) {
                        bins.push(n, BinPoint { pos_q: local(n), flags: FLAG_HALO, ..point })?;
                        *halo += 1;
                    }
                }
            }
            Ok(())
        },
    )?;
    let mut halo = 0;
    for (_, mut bins, worker_halo) in states {
        profile.time(Stage::Distribute, || bins.flush_all())?;
        halo += worker_halo;
    }
    plan.halo_points = halo;
    plan.bin_writers = workers;
    Ok(())
}

/// Where the points of each fine cell go: the cell's tile, and for a point within the halo of
/// some of the cell's faces, the other tiles its halo probes reach. Both depend only on the cell
/// and on which of its faces the point is near (tiles are unions of fine cells and the halo is at
/// most one cell, so a probe lands in the cell itself or the next one along each axis it moves),
/// so they are worked out once per cell and face set, and a point costs one lookup, or none when
/// it shares the previous point's cell, as scan order mostly does.
/// A fine cell and which of its faces a point lies within the halo of (bits 2a and 2a + 1: the
/// low and high face on axis a).
type NearFaces = ([i64; 3], u8);

struct Routes<'a> {
    plan: &'a TilePlan,
    lookup: HashMap<(u32, [i64; 3]), usize>,
    shift: u32,
    top: u32,
    halo_q: i64,
    /// Fine cell -> its tile (`None` outside every tile).
    tile_of_cell: foldhash::HashMap<[i64; 3], Option<usize>>,
    last_cell: Option<([i64; 3], Option<usize>)>,
    /// (fine cell, near-face bits) -> the range of `neighbours` holding its halo tiles.
    halo_of_cell: foldhash::HashMap<NearFaces, (u32, u32)>,
    last_halo: Option<(NearFaces, (u32, u32))>,
    neighbours: Vec<usize>,
}

impl<'a> Routes<'a> {
    fn new(plan: &'a TilePlan, shift: u32, top: u32, halo_q: i64) -> Self {
        Self {
            plan,
            lookup: plan.tiles.iter().enumerate().map(|(i, t)| ((t.level, t.key), i)).collect(),
            shift,
            top,
            halo_q,
            tile_of_cell: foldhash::HashMap::default(),
            last_cell: None,
            halo_of_cell: foldhash::HashMap::default(),
            last_halo: None,
            neighbours: Vec::new(),
        }
    }

    /// The tile of fine cell `cell`.
    fn tile(&mut self, cell: [i64; 3]) -> Option<usize> {
        if let Some((k, t)) = self.last_cell
            && k == cell
        {
            return t;
        }
        let (plan, lookup, top) = (self.plan, &self.lookup, self.top);
        let t = *self.tile_of_cell.entry(cell).or_insert_with(|| {
            let rel: [i64; 3] = std::array::from_fn(|i| cell[i] - plan.anchor[i]);
            (0..=top).find_map(|l| lookup.get(&(l, rel.map(|v| v >> l))).copied())
        });
        self.last_cell = Some((cell, t));
        t
    }

    /// The tiles other than `own` within the halo of quantised point `q` (the tiles of the 26
    /// probes `q + d * halo`, d in {-1, 0, 1}^3, as if each were looked up).
    fn halo(&mut self, q: [i64; 3], own: usize) -> &[usize] {
        let cell = q.map(|v| v >> self.shift);
        let cell_q = 1i64 << self.shift;
        let mut near = 0u8;
        for a in 0..3 {
            let r = q[a] - (cell[a] << self.shift);
            near |= u8::from(r < self.halo_q) << (2 * a) | u8::from(r >= cell_q - self.halo_q) << (2 * a + 1);
        }
        let key = (cell, near);
        let range = match self.last_halo {
            Some((k, range)) if k == key => range,
            _ => {
                let range = match self.halo_of_cell.get(&key) {
                    Some(&range) => range,
                    None => {
                        let start = self.neighbours.len();
                        for o in 0..27i64 {
                            let d = [o % 3 - 1, o / 3 % 3 - 1, o / 9 - 1];
                            let step: [i64; 3] = std::array::from_fn(|a| match d[a] {
                                -1 if near >> (2 * a) & 1 == 1 => -1,
                                1 if near >> (2 * a + 1) & 1 == 1 => 1,
                                _ => 0,
                            });
                            if step == [0; 3] {
                                continue;
                            }
                            if let Some(n) = self.tile(std::array::from_fn(|a| cell[a] + step[a]))
                                && n != own
                                && !self.neighbours[start..].contains(&n)
                            {
                                self.neighbours.push(n);
                            }
                        }
                        let range = (start as u32, (self.neighbours.len() - start) as u32);
                        self.halo_of_cell.insert(key, range);
                        range
                    }
                };
                self.last_halo = Some((key, range));
                range
            }
        };
        &self.neighbours[range.0 as usize..(range.0 + range.1) as usize]
    }
}

/// Per-tile append buffers with a shared byte budget.
struct Bins {
    dir: PathBuf,
    writer: usize,
    /// Indexed by tile; the tiles with points buffered are in `touched`.
    buffers: Vec<Vec<BinPoint>>,
    touched: Vec<usize>,
    buffered: usize,
    budget: usize,
}

impl Bins {
    fn new(work_dir: &Path, tiles: usize, budget: usize, writer: usize) -> Self {
        Self {
            dir: work_dir.to_path_buf(),
            writer,
            buffers: vec![Vec::new(); tiles],
            touched: Vec::new(),
            buffered: 0,
            budget: budget.max(1 << 16),
        }
    }

    fn push(&mut self, tile: usize, p: BinPoint) -> Result<()> {
        let buffer = &mut self.buffers[tile];
        if buffer.is_empty() {
            self.touched.push(tile);
        }
        buffer.push(p);
        self.buffered += size_of::<BinPoint>();
        if self.buffered >= self.budget { self.flush_all() } else { Ok(()) }
    }

    /// Appends every buffer to its tile's bin; the buffers are freed, so the budget bounds the
    /// memory held between flushes.
    fn flush_all(&mut self) -> Result<()> {
        for tile in self.touched.drain(..) {
            let points = std::mem::take(&mut self.buffers[tile]);
            let path = bin_path(&self.dir, tile, self.writer);
            let io = |source| Error::Io { path: path.clone(), source };
            let mut f: File = OpenOptions::new().create(true).append(true).open(&path).map_err(io)?;
            f.write_all(bytemuck::cast_slice(&points)).map_err(io)?;
        }
        self.buffered = 0;
        Ok(())
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn posed(q: Vec<[i64; 3]>, normals: bool, invalid: u64) -> Posed {
        let n = q.len();
        Posed {
            normal_snorm: if normals {
                (0..n).map(|i| [i as i16, -(i as i16), 32767]).collect()
            } else {
                Vec::new()
            },
            rgb: (0..n).map(|i| [i as u8, 7, 255]).collect(),
            q,
            invalid,
        }
    }

    #[test]
    fn spill_files_read_back_what_was_written() {
        let work = tempfile::tempdir().unwrap();
        std::fs::create_dir_all(work.path().join("spill")).unwrap();
        // Survey-scale quanta, a chunk spanning more than 2^31 quanta (stored wide), one with
        // normals, and one with only invalid points.
        let chunks = [
            posed(vec![[5_000_000 << 16, 1 << 40, -3], [(5_000_000 << 16) + 9, (1 << 40) - 4, 12]], false, 2),
            posed(vec![[0, 0, 0], [1 << 33, -(1 << 33), 5]], true, 0),
            posed(Vec::new(), false, 4),
        ];
        let mut writer = SpillWriter::create(work.path(), 3).unwrap();
        for c in &chunks {
            writer.write(c).unwrap();
        }
        assert!(!spill_path(work.path(), 3).exists(), "complete only once finished");
        writer.finish().unwrap();
        let mut reader = SpillReader::open(&spill_path(work.path(), 3)).unwrap();
        let mut got = Posed::default();
        for c in &chunks {
            assert!(reader.read(&mut got).unwrap());
            assert_eq!(
                (&got.q, &got.normal_snorm, &got.rgb, got.invalid),
                (&c.q, &c.normal_snorm, &c.rgb, c.invalid)
            );
        }
        assert!(!reader.read(&mut got).unwrap());
    }

    fn anyhow_like(e: Error) -> String {
        let mut s = e.to_string();
        let mut src = std::error::Error::source(&e);
        while let Some(c) = src {
            s += &format!(": {c}");
            src = c.source();
        }
        s
    }

    #[test]
    fn a_damaged_spill_file_is_an_error_naming_it() {
        let work = tempfile::tempdir().unwrap();
        std::fs::create_dir_all(work.path().join("spill")).unwrap();
        let mut writer = SpillWriter::create(work.path(), 0).unwrap();
        writer.write(&posed(vec![[1, 2, 3]; 100], true, 0)).unwrap();
        writer.finish().unwrap();
        let path = spill_path(work.path(), 0);
        let bytes = std::fs::read(&path).unwrap();
        // Cut short, and a header claiming more points than a block may hold.
        let mut huge = bytes.clone();
        huge[24..28].copy_from_slice(&u32::MAX.to_le_bytes());
        for damaged in [bytes[..bytes.len() - 5].to_vec(), huge, bytes[..10].to_vec()] {
            std::fs::write(&path, damaged).unwrap();
            let mut reader = SpillReader::open(&path).unwrap();
            let err = anyhow_like(reader.read(&mut Posed::default()).unwrap_err());
            assert!(err.contains("00000.spill") && err.contains("corrupt spill"), "{err}");
        }
    }
}
