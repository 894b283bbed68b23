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

use serde::Serialize;

use crate::bins::{BinPoint, FLAG_HALO, PlannedTile, TilePlan, bin_path};
use crate::ingest::{self, PointChunk};
use crate::manifest::ResolvedScan;
use crate::manifest::SeenFrom;
use crate::profile::{Profile, Stage};
use crate::spill::{Posed, SpillReader, SpillWriter, spill_path};
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

/// Progress of a long step, for a bar in the binary.
#[derive(Clone, Copy, Debug)]
pub struct Progress {
    pub stage: &'static str,
    pub done: u64,
    pub total: u64,
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

/// How many workers `par_scans` runs: one per thread of the current pool, at most one per scan
/// (distribute records it as the plan's `bin_writers`).
fn scan_workers(scans: &[ResolvedScan]) -> usize {
    rayon::current_num_threads().clamp(1, scans.len().max(1))
}

/// Fine cell of a quantised point (`shift` = log2(min extent / quantum); arithmetic shifts floor).
fn fine_key(q: [i64; 3], shift: u32) -> [i64; 3] {
    q.map(|v| v >> shift)
}

/// The complete plan in `work_dir` if it was made from exactly these scans and parameters.
pub(crate) fn existing_plan(
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
