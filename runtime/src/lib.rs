//! The grotto runtime: opens `.grotto` packages, keeps their tiles on the GPU and renders them with
//! global illumination (wgpu, headless). Per frame it runs only the passes the effect plan asks
//! for: shadow maps and light injection, anisotropic mipmapping, environment light through the
//! openings (SH), cone-traced propagation (one bounce per light update; cones stop in the rock
//! behind scanned walls), the surfel G-buffer and deferred shading.
//!
//! Also: describing and verifying packages ([`inspect`]) and exporting their points ([`export`]).

pub mod activity;
pub mod camera;
pub mod coarse;
pub mod cpu_ref;
pub mod error;
pub mod export;
pub mod follow;
pub mod framing;
pub mod gpu;
pub mod gpu_types;
pub mod image_out;
pub mod inspect;
pub mod lights;
pub mod passes;
pub mod plan;
pub mod pool;
pub mod render_job;
pub mod renderer;
pub mod residency;
pub mod rock;
pub mod scene_data;
pub mod settings;
pub mod shaders;
pub mod tile_index;
pub mod window;

pub use error::{Error, Result};
