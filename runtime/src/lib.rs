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

/// The crate's one error type, each variant naming what failed and where.
pub mod error;
/// Quality knobs, the fast/balanced/high presets, view modes, the clip box.
pub mod settings;
/// The device, its limits, checked buffers and textures, read-backs; structs shared with WGSL.
pub mod gpu;
/// A package loaded into one f32 frame; rock, coarse levels and the tile index.
pub mod scene;
/// Cameras and camera paths; default views and the headlamp for a bare package; points of
/// interest, flights, tours and view links.
pub mod view;
/// Shared WGSL by subsystem and the `#import` composer.
pub mod shaders;
/// One module per pass, its WGSL beside it; the CPU reference of mip and the gather.
pub mod passes;
/// The light setup, the effect plan and which tiles' light may still change.
pub mod light;
/// The renderer: its state, the per-frame order of passes, light state, tile pools, present.
pub mod render;
/// Residency, streaming for every shell, and the loader thread.
pub mod stream;
/// The frame both viewers draw: light first within the shell's pacing, then the frame, a still
/// sample at rest.
pub mod viewer;
/// A viewer's story and tools (labels, flights, tours, measuring), the window's and the page's.
pub mod guide;
/// Opening a package for rendering: the options, the scene under the budgets, the cameras, the
/// story and lighting files.
pub mod engine;
/// The command line's jobs: render and bench, inspect and verify, export, images, publish.
#[cfg(not(target_arch = "wasm32"))]
pub mod cli;
/// `grotto view`: the window, its panel and frame pacing.
#[cfg(not(target_arch = "wasm32"))]
pub mod window;

pub use error::{Error, Result};
