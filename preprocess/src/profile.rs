//! Where a build's time goes: seconds per stage (read scans, count, distribute, normals, voxels,
//! ...), for `grotto-pack build`'s summary and the per-stage table in docs/benchmarks.md.
//!
//! The tile stages are timed per tile and summed over the tiles, which are built several at once
//! where the memory budget allows (`BuildParams::tiles_at_once`): their sum can exceed the tile
//! step's wall time. Each tile's normals, surfel and voxel sorts and colour blocks are themselves
//! parallel. The tiling passes run one scan per worker, so their rows are summed over the workers
//! too. Timing costs two clock reads per stage and tile or per chunk of 64 Ki
//! points: nothing.

use std::sync::atomic::{AtomicU64, Ordering};
use std::time::{Duration, Instant};

use serde::Serialize;

/// A stage of a build, in the order they run.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum Stage {
    /// Before the build proper (`grotto-pack`): reading the manifest and the scans' headers, and
    /// sampling point spacing for `--leaf-m auto`.
    Setup,
    /// Pass 1 of tiling: decoding scan files and posing their points (count pass).
    CountRead,
    /// Pass 1: counting points per fine cell, and choosing the tiles.
    Count,
    /// Pass 1: writing the posed points for pass 2 (`TilingParams::spill`).
    Spill,
    /// Pass 2 of tiling: decoding and posing again (distribute pass).
    DistributeRead,
    /// Pass 2: each point (and its halo copies) into its tile's bin, and the bins' writes.
    Distribute,
    /// The occupancy grid that orients scans without a scanner position.
    OrientationGrid,
    /// Per tile: reading the bin and preparing positions, scanners and file normals.
    ReadBins,
    /// Per tile: k nearest neighbours, PCA, orientation, spread and radii.
    Normals,
    /// Per tile: Morton order, surfels and the seam count.
    Surfels,
    /// Per tile: splatting samples into leaves and the SVO node layout.
    Voxels,
    /// Per tile: BC1 colour blocks.
    Colors,
    /// Per tile: quantising the surfels into the compact encoding (format 2.0).
    CompactSurfels,
    /// Per tile: encoding (zstd) and writing the tile package.
    WriteTiles,
    /// Assemble: every tile package checked whole (fingerprint, checksums, content).
    CheckTiles,
    /// Assemble: every tile's coarse levels and rock.
    Levels,
    /// Assemble: copying the tile packages' sections into the output and writing it.
    Assemble,
    /// Assemble: the environment map's SH and prefiltered mip chain.
    Environment,
    /// Assemble: hashing every input file for the provenance.
    HashInputs,
}

impl Stage {
    pub(crate) const ALL: [Stage; 19] = [
        Stage::Setup,
        Stage::CountRead,
        Stage::Count,
        Stage::Spill,
        Stage::DistributeRead,
        Stage::Distribute,
        Stage::OrientationGrid,
        Stage::ReadBins,
        Stage::Normals,
        Stage::Surfels,
        Stage::Voxels,
        Stage::Colors,
        Stage::CompactSurfels,
        Stage::WriteTiles,
        Stage::CheckTiles,
        Stage::Levels,
        Stage::Assemble,
        Stage::Environment,
        Stage::HashInputs,
    ];

    pub(crate) fn name(self) -> &'static str {
        match self {
            Stage::Setup => "setup: scans and leaf size",
            Stage::CountRead => "count: read scans",
            Stage::Count => "count: cells and plan",
            Stage::Spill => "count: spill points",
            Stage::DistributeRead => "distribute: read scans",
            Stage::Distribute => "distribute: bins",
            Stage::OrientationGrid => "orientation grid",
            Stage::ReadBins => "tiles: read bins",
            Stage::Normals => "tiles: normals",
            Stage::Surfels => "tiles: surfels",
            Stage::Voxels => "tiles: voxels",
            Stage::Colors => "tiles: colours",
            Stage::CompactSurfels => "tiles: compact surfels",
            Stage::WriteTiles => "tiles: encode and write",
            Stage::CheckTiles => "assemble: check tiles",
            Stage::Levels => "assemble: levels",
            Stage::Assemble => "assemble: copy and write",
            Stage::Environment => "assemble: environment",
            Stage::HashInputs => "assemble: hash inputs",
        }
    }

    /// Whether the stage is timed per tile and summed over tiles built at once.
    pub(crate) fn summed_over_tiles(self) -> bool {
        matches!(
            self,
            Stage::ReadBins
                | Stage::Normals
                | Stage::Surfels
                | Stage::Voxels
                | Stage::Colors
                | Stage::CompactSurfels
                | Stage::WriteTiles
        )
    }
}

/// Seconds per stage, shared by the threads of a build.
#[derive(Debug, Default)]
pub struct Profile {
    nanos: [AtomicU64; Stage::ALL.len()],
}

/// One stage's time in a summary.
#[derive(Clone, Debug, PartialEq, Serialize)]
pub struct StageTime {
    pub stage: &'static str,
    pub seconds: f64,
    /// Summed over tiles built at once (may exceed the wall time).
    pub summed_over_tiles: bool,
}

impl StageTime {
    /// `seconds` spent in `stage`.
    pub fn of(stage: Stage, seconds: f64) -> Self {
        StageTime { stage: stage.name(), seconds, summed_over_tiles: stage.summed_over_tiles() }
    }
}

impl Profile {
    pub(crate) fn add(&self, stage: Stage, elapsed: Duration) {
        let nanos = u64::try_from(elapsed.as_nanos()).unwrap_or(u64::MAX);
        self.nanos[stage as usize].fetch_add(nanos, Ordering::Relaxed);
    }

    /// Runs `f`, adding its time to `stage`.
    pub(crate) fn time<T>(&self, stage: Stage, f: impl FnOnce() -> T) -> T {
        let start = Instant::now();
        let out = f();
        self.add(stage, start.elapsed());
        out
    }

    /// Adds the time since `since` to `stage` and restarts `since`: consecutive stages of one
    /// piece of code, timed by one clock.
    pub(crate) fn lap(&self, stage: Stage, since: &mut Instant) {
        let now = Instant::now();
        self.add(stage, now - *since);
        *since = now;
    }

    /// Seconds spent in `stage` (0 where it did not run).
    pub fn seconds(&self, stage: Stage) -> f64 {
        self.nanos[stage as usize].load(Ordering::Relaxed) as f64 * 1e-9
    }

    /// The stages that took any time, in the order they run.
    pub fn report(&self) -> Vec<StageTime> {
        Stage::ALL
            .iter()
            .filter(|&&s| self.nanos[s as usize].load(Ordering::Relaxed) > 0)
            .map(|&s| StageTime::of(s, self.seconds(s)))
            .collect()
    }
}

/// Peak resident memory of this process so far (Linux `VmHWM`), in bytes.
pub(crate) fn peak_rss_bytes() -> Option<u64> {
    let status = std::fs::read_to_string("/proc/self/status").ok()?;
    let line = status.lines().find(|l| l.starts_with("VmHWM:"))?;
    let kb: u64 = line.split_whitespace().nth(1)?.parse().ok()?;
    Some(kb * 1024)
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn stages_add_up_and_unused_ones_are_left_out() {
        let p = Profile::default();
        p.add(Stage::Normals, Duration::from_millis(1500));
        p.add(Stage::Normals, Duration::from_millis(500));
        let v = p.time(Stage::Count, || 7);
        assert_eq!(v, 7);
        let mut clock = Instant::now() - Duration::from_secs(1);
        p.lap(Stage::Count, &mut clock);
        assert!(p.seconds(Stage::Count) >= 1.0 && clock.elapsed() < Duration::from_secs(1));
        let report = p.report();
        assert_eq!(report.len(), 2);
        assert_eq!(report[0].stage, "count: cells and plan");
        assert!(!report[0].summed_over_tiles);
        assert_eq!(report[1], StageTime { stage: "tiles: normals", seconds: 2.0, summed_over_tiles: true });
    }

    #[test]
    fn every_stage_has_its_own_slot_and_name() {
        for (i, s) in Stage::ALL.iter().enumerate() {
            assert_eq!(*s as usize, i);
        }
        let names: std::collections::BTreeSet<_> = Stage::ALL.iter().map(|s| s.name()).collect();
        assert_eq!(names.len(), Stage::ALL.len());
    }
}
