//! Step 2, build-tile: the tiles of a shard, built by feeder threads that each take the next
//! tile (largest first) in a rayon pool of their share of the threads.

use std::path::Path;

use grotto_format::Scene;
use serde::Serialize;

use crate::bins::TilePlan;
use crate::build::inspect;
use crate::build::params::BuildParams;
use crate::build::plan::planned;
use crate::build::tile::build_tile;
use crate::build::tile::tile_fingerprint;
use crate::build::tile::tile_package_path;
use crate::build::tile::write_tile_package;
use crate::manifest::Manifest;
use crate::orient::{self, CaveGrid};
use crate::profile::{Profile, StageTime};
use crate::tiling::Progress;
use crate::{Error, Result};

/// Which tiles a `build-tile` job takes: those with `index % count == shard`.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub struct Shard {
    pub index: usize,
    pub count: usize,
}

impl Shard {
    /// Every tile: one job.
    pub const ALL: Shard = Shard { index: 0, count: 1 };

    fn takes(&self, tile: usize) -> bool {
        tile % self.count.max(1) == self.index
    }
}

/// What the build-tile step did.
#[derive(Clone, Debug, Default, Serialize)]
pub struct TileStage {
    /// The host the job ran on (a cluster's logs say which node built which shard).
    pub host: String,
    /// How many tiles this job built: `built_tiles.len()`, kept for the JSON summary.
    pub built: usize,
    pub reused: usize,
    /// The tiles this job built (not those it found built), in tile order.
    pub built_tiles: Vec<usize>,
    /// The job's peak resident memory, bytes (0 where the OS does not say): what a scheduler's
    /// memory request per task must cover.
    pub peak_rss_bytes: u64,
    /// Seconds per stage of the tiles built, summed over tiles built at once ([`crate::profile`]).
    pub stages: Vec<StageTime>,
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
    stage.host = gethostname::gethostname().to_string_lossy().into_owned();
    stage.peak_rss_bytes = crate::profile::peak_rss_bytes().unwrap_or(0);
    Ok(stage)
}

/// Builds the shard's tiles; `grid` orients the normals of scans without a scanner position.
pub(crate) fn tile_stage(
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
                        // Checked whole (another node may have written it, or died writing it).
                        if inspect::inspect(&params.work_dir, t, &plan.fingerprint, &fingerprint).is_ok() {
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
                        Ok(false) => stage.0.built_tiles.push(t),
                        Err(e) => {
                            failed.store(true, Relaxed);
                            stage.1.get_or_insert(e);
                            break;
                        }
                    }
                    let finished = (stage.0.built_tiles.len() + stage.0.reused) as u64;
                    progress(Progress { stage: "tiles", done: finished, total: mine.len() as u64 });
                }
            });
        }
    });
    let (mut stage, error) = stage.into_inner().unwrap_or_else(|poisoned| poisoned.into_inner());
    if let Some(e) = error {
        return Err(e);
    }
    stage.built_tiles.sort_unstable();
    stage.built = stage.built_tiles.len();
    Ok(stage)
}
