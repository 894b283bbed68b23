//! The crate's error type: every variant says which file or which step failed.

use std::path::PathBuf;

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
        crate::build::list_tile_problems(problems)
    )]
    Tiles { work_dir: PathBuf, total: usize, problems: Vec<crate::build::TileProblem> },
    /// The OS error is the `source` (printed by `{:#}` chains).
    #[error("{path}: input/output failed")]
    Io { path: PathBuf, source: std::io::Error },
}

/// The preprocessing result: [`Error`] names the file or parameter and what is wrong.
pub type Result<T, E = Error> = std::result::Result<T, E>;
