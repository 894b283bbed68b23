//! The engine's face for opening a package to render it. [`scene`] is what every shell shares,
//! whatever it reads the package from: the scene under the budgets with the lights and story it
//! was given, far-first where it does not fit, and a lightless view's headlamp; the browser's
//! viewer opens its fetched package through it. Natively, [`open`] takes [`RenderOptions`], reads
//! the package file, the story file (`--story`) and the lighting file (`--lights`), resolves the
//! cameras, loads the first camera's tiles and gives the scene, cameras, residency and streaming
//! a shell renders with ([`Opened`]): the command line's render and bench jobs, the window and
//! the tests open packages through it.

#[cfg(not(target_arch = "wasm32"))]
pub mod lighting_file;
pub mod memory;
#[cfg(not(target_arch = "wasm32"))]
mod open;
#[cfg(not(target_arch = "wasm32"))]
mod options;
pub mod scene;
#[cfg(not(target_arch = "wasm32"))]
pub mod story_file;
#[cfg(not(target_arch = "wasm32"))]
pub mod time_budget;

#[cfg(not(target_arch = "wasm32"))]
pub use open::{Opened, load_scene, open};
#[cfg(not(target_arch = "wasm32"))]
pub use options::{Headlamp, RenderOptions, clip_in_frame};
pub use scene::{Load, STRING_LAMP_LIFT_M, STRING_LAMP_W, SceneRequest, Story, add_headlamp, open_scene};
