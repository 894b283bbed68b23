//! The viewer's one error type, shown in the page as it is.

use wasm_bindgen::JsError;

/// What can go wrong in the viewer, shown in the page as it is.
#[derive(Debug, thiserror::Error)]
pub enum Error {
    /// A request failed; `transient`: asking again may work (a 5xx, a dropped connection, a
    /// deadline passed, a short body).
    #[error("fetching {url}: {problem}")]
    Fetch { url: String, problem: String, transient: bool },
    /// The package on the server is not the one the visit began with.
    #[error(
        "{url} was replaced on the server while it was shown ({problem}): reload the page to see the new version"
    )]
    Replaced { url: String, problem: String },
    #[error(transparent)]
    Runtime(#[from] grotto_runtime::Error),
    #[error(transparent)]
    Package(#[from] grotto_format::Error),
    #[error("{0}")]
    Setting(String),
}

pub(crate) fn to_js(e: Error) -> JsError {
    JsError::new(&e.to_string())
}
