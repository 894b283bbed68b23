//! GPU plumbing: the device and its limits, checked buffer and texture creation, error scopes and
//! read-backs ([`device`]), uploads in bounded pieces ([`upload`]), and the structs shared with
//! WGSL, byte for byte ([`types`]).

mod device;
pub mod types;
pub(crate) mod upload;

pub use device::{Gpu, GpuOptions, PendingRead, STORAGE_BUFFERS_NEEDED, default_gpu_memory, human_bytes};
