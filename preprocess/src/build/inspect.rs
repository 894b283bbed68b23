//! Whether a tile package in the work directory may be used, and if not, why. The work directory
//! may be shared by jobs on many nodes, so nothing found there is trusted: a tile counts as built
//! only when a package sits under its final name, opens and validates, carries this build's
//! fingerprint in its provenance, and every section's checksum and content check out. A job
//! killed while writing leaves only its temp file (`.NNNNNNN.grotto.XXXXXX.partial`, renamed
//! into place only when whole), which is named in the reason but never taken for the tile.

use std::path::Path;
use std::time::SystemTime;

use crate::build::tile::tile_package_path;
use crate::error::{PartialFile, TileFault, TileProblem};
use crate::normals::NormalStats;
use grotto_format::Package;

/// What a finished tile package recorded in its provenance.
#[derive(Clone, Debug)]
pub(crate) struct Finished {
    /// Own points near the border whose neighbourhood may reach past the halo.
    pub(crate) seam_limited: u64,
    /// File normals kept and orientation without a scanner.
    pub(crate) normals: NormalStats,
}

/// Tile `t`'s package in `work_dir`, checked against `fingerprint` (the tile fingerprint, which
/// starts with the plan's `plan_fingerprint`); `Ok` with its record when it may be used.
pub(crate) fn inspect(
    work_dir: &Path,
    t: usize,
    plan_fingerprint: &str,
    fingerprint: &str,
) -> Result<Finished, TileProblem> {
    let path = tile_package_path(work_dir, t);
    let fail = |fault| TileProblem { tile: t, path: path.clone(), fault };
    let pkg = match Package::open(&path) {
        Ok(pkg) => pkg,
        Err(grotto_format::Error::Io { source, .. }) if source.kind() == std::io::ErrorKind::NotFound => {
            return Err(fail(TileFault::Missing { partials: partials(&path) }));
        }
        Err(e) => return Err(fail(TileFault::Damaged { detail: detail(&e) })),
    };
    // The fingerprint first (a stale tile says so even when it is also damaged), then every byte.
    let prov = match pkg.provenance() {
        Ok(Some(prov)) => prov,
        Ok(None) => return Err(fail(TileFault::Damaged { detail: "it has no provenance".into() })),
        Err(e) => return Err(fail(TileFault::Damaged { detail: detail(&e) })),
    };
    let found = prov.parameters.get("tile_fingerprint").and_then(|v| v.as_str()).unwrap_or("(none)");
    if found != fingerprint {
        let (found, want) = (found.to_owned(), fingerprint.to_owned());
        return Err(fail(if found.starts_with(&format!("{plan_fingerprint}-")) {
            TileFault::OtherParameters { found, want }
        } else {
            TileFault::OtherPlan { found, want }
        }));
    }
    if let Some(problem) = pkg.verify().first() {
        return Err(fail(TileFault::Damaged { detail: problem.to_string() }));
    }
    let seam_limited = prov.parameters.get("seam_limited_points").and_then(|v| v.as_u64());
    let normals = prov.parameters.get("normals").and_then(|v| serde_json::from_value(v.clone()).ok());
    match (seam_limited, normals) {
        (Some(seam_limited), Some(normals)) => Ok(Finished { seam_limited, normals }),
        _ => Err(fail(TileFault::Damaged { detail: "its provenance lacks the tile's record".into() })),
    }
}

/// What is wrong, without the path the problem already names.
fn detail(e: &grotto_format::Error) -> String {
    match e {
        grotto_format::Error::Invalid { problem, .. } => problem.to_string(),
        grotto_format::Error::Io { op, source, .. } => format!("cannot {op}: {source}"),
        other => other.to_string(),
    }
}

/// Temp files a package writer left beside `path` (its `.NAME.XXXXXX.partial`), oldest first.
fn partials(path: &Path) -> Vec<PartialFile> {
    let (Some(dir), Some(name)) = (path.parent(), path.file_name()) else { return Vec::new() };
    let prefix = format!(".{}.", name.to_string_lossy());
    let Ok(entries) = std::fs::read_dir(dir) else { return Vec::new() };
    let mut found: Vec<PartialFile> = entries
        .filter_map(|e| e.ok())
        .filter_map(|e| {
            let name = e.file_name().to_string_lossy().into_owned();
            if !(name.starts_with(&prefix) && name.ends_with(".partial")) {
                return None;
            }
            let meta = e.metadata().ok()?;
            let age_s = meta
                .modified()
                .ok()
                .and_then(|m| SystemTime::now().duration_since(m).ok())
                .map(|d| d.as_secs());
            Some(PartialFile { name, bytes: meta.len(), age_s })
        })
        .collect();
    found.sort_by_key(|p| std::cmp::Reverse(p.age_s));
    found
}
