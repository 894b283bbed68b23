//! The runtime's one error type: every variant names what failed and, for GPU problems, what the
//! user can do about it.

/// Why a runtime operation failed.
#[derive(Debug, thiserror::Error)]
#[non_exhaustive]
pub enum Error {
    #[error(transparent)]
    Package(#[from] grotto_format::Error),
    #[error("{path}: {reason}")]
    Output { path: String, reason: String },
    #[error("{path}: unknown point format (use .ply or .las)")]
    Extension { path: String },
    /// A scan given where a package is expected that could not be packed (cli/scan_input.rs).
    #[error("{path}: {problem}")]
    Scan { path: String, problem: String },
    #[error(
        "no GPU adapter found (tried {tried}); install a Vulkan driver (on Debian: apt-get install \
         mesa-vulkan-drivers libvulkan1 for the software rasteriser) or set WGPU_BACKEND=gl"
    )]
    NoAdapter { tried: String },
    #[error("{adapter}: {what}; {hint}")]
    Unsupported { adapter: String, what: String, hint: String },
    /// A buffer or texture the scene needs is over what the adapter allows; `hint` says what to
    /// change (leaf size, image size, shadow budget...).
    #[error("{resource} is over the adapter's limit ({adapter}: {limit}); {hint}")]
    TooLarge { resource: String, limit: String, adapter: String, hint: String },
    #[error("GPU device: {0}")]
    Device(String),
    #[error("GPU error in {pass}: {message}")]
    Gpu { pass: &'static str, message: String },
    /// Something the renderer relies on itself did not hold (a bug in grotto, not in the input or
    /// the GPU): reported, never a panic.
    #[error("internal error in {what}: {message} (a bug in grotto; please report it)")]
    Internal { what: &'static str, message: String },
    #[error("{package}: {problem}")]
    Scene { package: String, problem: String },
    /// The GPU memory or point budget cannot hold what residency must keep (residency.rs).
    #[error("{what}; {hint}")]
    Budget { what: String, hint: String },
    #[error("camera: {0}")]
    Camera(String),
    /// A camera path file (`grotto render --path FILE.toml`, `grotto view --record-path`).
    #[error("{path}: {problem}")]
    CameraPath { path: String, problem: String },
    /// A story file (`grotto publish --story`, `grotto view --story`): points of interest and
    /// tours that do not read or do not hold together.
    #[error("{path}: {problem}")]
    Story { path: String, problem: String },
    /// A lighting file (`--lights`) or an IES file it names that does not read or hold together.
    #[error("{path}{}: {problem}", line.map(|l| format!(", line {l}")).unwrap_or_default())]
    Lighting { path: String, line: Option<usize>, problem: String },
    #[error("setting {name}: {problem}")]
    Setting { name: &'static str, problem: String },
    /// A cave survey (`--survey`, or the one a package holds) that does not read or does not fit
    /// the scans.
    #[error("{path}: {problem}")]
    Survey { path: String, problem: String },
    /// `grotto view` found no display to open its window on.
    #[error(
        "no display to open a window on ({0}); set DISPLAY or WAYLAND_DISPLAY (under Xvfb: \
         xvfb-run grotto view ...), or write images with grotto render"
    )]
    NoDisplay(String),
}

/// The runtime's result: [`Error`] names the pass, file or setting at fault.
pub type Result<T, E = Error> = std::result::Result<T, E>;
