//! Helpers for the end-to-end tests: where the shared third-party test data lives.

use std::path::PathBuf;

/// `../shared/data` beside the repository (CI puts `shared/` there), or `$GROTTO_SHARED_DATA`.
pub fn shared_data_dir() -> Option<PathBuf> {
    if let Some(p) = std::env::var_os("GROTTO_SHARED_DATA") {
        return Some(PathBuf::from(p));
    }
    let p = PathBuf::from(env!("CARGO_MANIFEST_DIR")).join("../../shared/data");
    p.is_dir().then_some(p)
}
