//! grotto's offline preprocessing: registered scans in, one `.grotto` package out.
//!
//! Today this holds the built-in demo scene ([`demo`]); ingest, tiling, normals, SVO and encoding
//! follow the design brief (`../shared/DESIGN.md`) and land module by module.

pub mod bc1;
pub mod bench;
pub mod build;
pub mod demo;
pub mod env;
mod error;
pub mod ingest;
pub mod manifest;
pub mod normals;
pub mod orient;
pub mod pose;
pub mod scanwrite;
pub mod synth;
pub mod tiling;
pub mod voxels;

pub use error::{Error, Result};

// The BC6H encoder's prebuilt objects need the C++ runtime.
use link_cplusplus as _;
