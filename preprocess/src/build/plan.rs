//! Step 1, plan: the parameters checked, the scans resolved and tiled out of core, and the plan a
//! later step finds in the work directory.

use crate::bins::TilePlan;
use crate::build::params::BuildParams;
use crate::manifest::{Manifest, ResolvedScan};
use crate::orient::{self, CaveGrid};
use crate::profile::{Profile, Stage};
use crate::tiling::{self, Progress};
use crate::{Error, Result};

pub(crate) fn check_params(params: &BuildParams) -> Result<()> {
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
pub(crate) fn cut_short(scans: &[ResolvedScan], strict: bool) -> Result<Vec<String>> {
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
pub(crate) struct PlanStep {
    pub(crate) plan: TilePlan,
    /// Whether the tiling was an earlier run's.
    pub(crate) reused: bool,
    /// The scans cut short ([`cut_short`]).
    pub(crate) cut: Vec<String>,
    /// The orientation grid, where a scan has no scanner position (also saved in the work
    /// directory for build-tile jobs).
    pub(crate) grid: Option<CaveGrid>,
}

/// Tiles the scans (or finds an earlier tiling) and builds the orientation grid where it is
/// needed; scans cut short are refused first under `--strict`.
pub(crate) fn plan_scans(
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
pub(crate) fn planned(manifest: &Manifest, params: &BuildParams) -> Result<(TilePlan, Vec<ResolvedScan>)> {
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
