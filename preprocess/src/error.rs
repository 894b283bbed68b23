//! The crate's error type: every variant says which file or which step failed.

use std::path::PathBuf;

use serde::Serialize;

#[derive(Debug, thiserror::Error)]
#[non_exhaustive]
/// What can go wrong while packing, each naming the file or parameter at fault.
pub enum Error {
    #[error(transparent)]
    Package(#[from] grotto_format::Error),
    #[error("invalid parameter {name}: {reason}")]
    Parameter { name: &'static str, reason: String },
    /// A scan file that cannot be read as what it claims to be.
    #[error("{path}: {format}: {reason}")]
    Read { path: PathBuf, format: &'static str, reason: String },
    #[error("{path}: manifest: {reason}")]
    Manifest { path: PathBuf, reason: String },
    /// Tile packages in a work directory that `assemble` cannot use, each with its reason.
    #[error(
        "{work_dir}: {} of {total} tiles cannot be assembled; run build-tile for them (it builds \
         exactly these again):{}",
        problems.len(),
        list_tile_problems(problems)
    )]
    Tiles { work_dir: PathBuf, total: usize, problems: Vec<TileProblem> },
    /// The OS error is the `source` (printed by `{:#}` chains).
    #[error("{path}: input/output failed")]
    Io { path: PathBuf, source: std::io::Error },
}

/// A temp file a writer left beside a tile (a job killed before its rename).
#[derive(Clone, Debug, Serialize)]
pub struct PartialFile {
    pub name: String,
    pub bytes: u64,
    /// Seconds since it was last written (None where the filesystem does not say).
    pub age_s: Option<u64>,
}

/// Why a tile cannot be used.
#[derive(Clone, Debug, Serialize)]
#[serde(tag = "kind", rename_all = "snake_case")]
pub enum TileFault {
    /// No package under the tile's name; `partials` are temp files of jobs that did not finish.
    Missing { partials: Vec<PartialFile> },
    /// It does not open, or a section fails its checksum or content check.
    Damaged { detail: String },
    /// Built from another plan (the scans or the tiling changed since).
    OtherPlan { found: String, want: String },
    /// Built from this plan with other parameters (leaf, k, codecs, or another grotto version).
    OtherParameters { found: String, want: String },
}

impl std::fmt::Display for TileFault {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        match self {
            TileFault::Missing { partials } if partials.is_empty() => write!(f, "not built"),
            TileFault::Missing { partials } => {
                write!(f, "not built: only a partial file left by a job that stopped while writing it (")?;
                for (i, p) in partials.iter().enumerate() {
                    let age = p.age_s.map_or(String::new(), |s| format!(", last written {s} s ago"));
                    write!(f, "{}{} of {} bytes{age}", if i > 0 { "; " } else { "" }, p.name, p.bytes)?;
                }
                write!(f, ")")
            }
            TileFault::Damaged { detail } => write!(f, "damaged: {detail}"),
            TileFault::OtherPlan { found, want } => write!(
                f,
                "stale: built for another plan (fingerprint {found}, this plan's {want}): the scans or the \
                 tiling changed since"
            ),
            TileFault::OtherParameters { found, want } => {
                write!(f, "stale: built with other parameters (fingerprint {found}, this build's {want})")
            }
        }
    }
}

/// One tile that cannot be used, with its path and the reason.
#[derive(Clone, Debug, Serialize)]
pub struct TileProblem {
    pub tile: usize,
    pub path: PathBuf,
    pub fault: TileFault,
}

impl std::fmt::Display for TileProblem {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        write!(f, "tile {} ({}): {}", self.tile, self.path.display(), self.fault)
    }
}

/// The tile packages that cannot be used, listed for an error (the first 20, then a count).
pub(crate) fn list_tile_problems(problems: &[TileProblem]) -> String {
    let shown = 20;
    let mut text: String = problems.iter().take(shown).map(|p| format!("\n  {p}")).collect();
    if problems.len() > shown {
        text.push_str(&format!("\n  and {} more", problems.len() - shown));
    }
    text
}

/// The preprocessing result: [`Error`] names the file or parameter and what is wrong.
pub type Result<T, E = Error> = std::result::Result<T, E>;
