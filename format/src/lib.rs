//! The `.grotto` package: one file holding a cave's sparse voxel octree tiles, surfels, compressed
//! colours, environment lighting, scene and provenance (spec: `docs/format.md`).
//!
//! - [`spec`]: raw `#[repr(C)]` mirrors of the on-disk structures.
//! - [`Package`]: opens a file (memory map) or bytes, validates the header, section table and tile
//!   directory once with checked arithmetic, then hands out views that cannot fail; section
//!   checksums and contents are checked lazily on first read, all of them by [`Package::verify`].
//! - [`PackageWriter`]: streams sections to a temp file and renames it into place atomically.
//!
//! This is a leaf crate: no GPU, threading or CLI dependencies. Its only `unsafe` is the memory map
//! in `source.rs`.

pub mod color;
pub mod compact;
pub mod ies;
pub mod lighting;
pub mod photometry;
pub mod profile;
mod env_chain;
mod error;
mod reader;
mod scene;
mod section;
mod source;
pub mod spec;
pub mod story;
pub mod survey;
mod summary;
pub mod svo;
mod validate;
#[cfg(not(target_arch = "wasm32"))]
mod writer;

pub use env_chain::{EnvChain, level_table};
pub use error::{Error, Problem, Region, Result, scan_format};
pub use profile::{LightProfile, Profile};
pub use reader::{CoarseData, Element, Package, SvoData, Tile};
pub use scene::{
    Camera, Circuit, Environment, InputFile, Light, LightShape, Material, MaterialRegion, Provenance,
    ScanInfo, Scene, check_lights,
};
pub use section::{SectionInfo, TileInfo};
pub use spec::{Codec, Scope, SectionKind};
pub use story::{Poi, Tour, TourStop};
pub use summary::{KindSummary, SectionSummary, Summary, TileSummary, parse_bytes};
#[cfg(not(target_arch = "wasm32"))]
pub use writer::{Compression, PackageWriter};
