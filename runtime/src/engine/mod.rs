//! The engine's face for opening a package to render it (native only: it opens files by path):
//! [`open`] takes [`RenderOptions`] and gives the scene, the cameras, the residency and the
//! streaming a shell renders with ([`Opened`]). The command line's render and bench jobs, the
//! window, the reference and the tests all open packages through it; the story files
//! (`--story`) and lighting files (`--lights`) it applies are read here too.

pub mod lighting_file;
mod open;
mod options;
pub mod story_file;

pub use open::{Opened, load_scene, open};
pub use options::{Headlamp, RenderOptions, STRING_LAMP_LIFT_M, STRING_LAMP_W, clip_in_frame};
