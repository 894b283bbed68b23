//! What a build reports: counts, sizes, times by step and stage, warnings.

use serde::Serialize;

use crate::orient::OrientStats;
use crate::profile::StageTime;

#[derive(Clone, Debug, Serialize)]
/// What a build made and what it cost, printed by `grotto-pack build` (`--json` for scripts).
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
    pub(crate) leaf_m: f64,
    /// What the package's scene holds: lights, cameras, an environment map.
    pub(crate) lights: usize,
    pub(crate) cameras: usize,
    pub(crate) environment: bool,
    /// Scan files that end inside their last point record, read without it:
    /// "path: N points dropped" (`--strict` refuses them instead).
    pub cut_short: Vec<String>,
    /// Scans with no scanner position (no `origin`, no pose): a merged cloud.
    pub(crate) scans_without_scanner: usize,
    /// Of those, the scans seen from outside their surface (`seen_from = "outside"`,
    /// `--seen-from outside`): their normals face away from what the walls enclose.
    pub scans_seen_from_outside: usize,
    /// Points whose file carried a normal, and how many of those were kept (`--normals keep`
    /// keeps those within 60 degrees of the local plane's normal; the rest are estimated).
    pub input_normals: u64,
    pub input_normals_kept: u64,
    pub(crate) keep_input_normals: bool,
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
