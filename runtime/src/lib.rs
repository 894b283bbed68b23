//! The grotto runtime: opens `.grotto` packages, keeps their tiles on the GPU and renders them with
//! global illumination (wgpu, headless). Per frame it runs only the passes the effect plan asks
//! for: shadow maps and light injection, anisotropic mipmapping, environment light through the
//! openings (SH), cone-traced propagation (one bounce per light update; cones stop in the rock
//! behind scanned walls), the surfel G-buffer and deferred shading.
//!
//! Also: describing and verifying packages ([`inspect`]) and exporting their points ([`export`]).
//!
//! The library builds for the browser too (wasm32, WebGPU): there, what needs files, threads, a
//! window or blocking on the GPU (the command line's job, the window viewer, export, images) is
//! left out, and the package arrives by HTTP ranges (`grotto_format::Package::from_directory`).

pub mod activity;
pub mod camera;
pub mod coarse;
pub mod cpu_ref;
pub mod error;
#[cfg(not(target_arch = "wasm32"))]
pub mod export;
#[cfg(not(target_arch = "wasm32"))]
pub mod follow;
pub mod framing;
pub mod gpu;
pub mod gpu_types;
#[cfg(not(target_arch = "wasm32"))]
pub mod image_out;
#[cfg(not(target_arch = "wasm32"))]
pub mod inspect;
pub mod lights;
pub mod passes;
pub mod plan;
pub mod pool;
pub mod present;
#[cfg(not(target_arch = "wasm32"))]
pub mod publish;
#[cfg(not(target_arch = "wasm32"))]
pub mod render_job;
pub mod renderer;
pub mod residency;
pub mod rock;
pub mod scene_data;
pub mod settings;
pub mod shaders;
pub mod stream;
pub mod tile_index;
#[cfg(not(target_arch = "wasm32"))]
pub mod window;

pub use error::{Error, Result};
