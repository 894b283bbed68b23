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

mod assemble;
mod inspect;
mod params;
mod plan;
mod summary;
mod tile;
mod tiles;

pub use crate::error::{PartialFile, TileFault, TileProblem};
pub use assemble::assemble;
pub use params::{
    AutoLeaf, BUILD_BYTES_PER_POINT, BuildParams, ColorCodec, DEFAULT_LEAF_M, DEFAULT_MAX_TILE_POINTS,
    HALO_LEAVES, MAX_TILE_LEAVES, MIN_TILE_LEAVES, SPACING_SAMPLE_POINTS, SurfelCodec, auto_leaf,
};
pub use plan::plan;
pub use summary::{BuildSummary, StepSeconds};
pub use tile::tile_package_path;
pub use tiles::{Shard, TileStage, build_tiles};

use std::path::Path;

use crate::Result;
use crate::build::assemble::assemble_plan;
use crate::build::plan::PlanStep;
use crate::build::plan::check_params;
use crate::build::plan::plan_scans;
use crate::build::tiles::tile_stage;
use crate::manifest::Manifest;
use crate::profile::Profile;
use crate::tiling::Progress;

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
