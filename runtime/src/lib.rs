//! The grotto runtime: opens `.grotto` packages, keeps their tiles on the GPU and renders them with
//! global illumination (wgpu, headless). Per frame it runs only the passes the effect plan asks
//! for: shadow maps and light injection, anisotropic mipmapping, environment light through the
//! openings (SH), cone-traced propagation (one bounce per light update; cones stop in the rock
//! behind scanned walls), the surfel G-buffer and deferred shading.
//!
//! Also: describing and verifying packages ([`cli::inspect`]) and exporting their points
//! ([`cli::export`]).
//!
//! The library builds for the browser too (wasm32, WebGPU): there, what needs files, threads, a
//! window or blocking on the GPU (the command line's jobs, the window viewer, export, images) is
//! left out, and the package arrives by HTTP ranges (`grotto_format::Package::from_directory`).
//!
//! The modules, lowest layer first; each imports only from those above it in this list
//! (`tests/tests/layering.rs` checks it):

#[cfg(not(target_arch = "wasm32"))]
pub mod cli;
pub mod error;
pub mod gpu;
pub mod light;
pub mod passes;
pub mod render;
pub mod scene;
pub mod settings;
pub mod shaders;
pub mod stream;
pub mod view;
#[cfg(not(target_arch = "wasm32"))]
pub mod window;

pub use error::{Error, Result};
