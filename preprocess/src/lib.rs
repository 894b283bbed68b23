//! grotto's offline preprocessing: registered scans in, one `.grotto` package out.
//!
//! Ingest ([`ingest`]), out-of-core tiling ([`tiling`]), normals ([`normals`]), SVO tiles
//! ([`voxels`]) and the package build ([`build`]), with the built-in demo scene ([`demo`]) and the
//! synthetic survey ([`synth`]) the benchmarks run on; [`profile`] says where a build's time goes.

pub mod bc1;
pub mod bench;
pub mod bins;
pub mod build;
pub mod demo;
pub mod env;
mod error;
pub mod ingest;
pub mod knn;
pub mod manifest;
pub mod normals;
pub mod orient;
pub mod pose;
pub mod profile;
pub mod scanwrite;
pub mod spacing;
pub mod spill;
pub mod synth;
pub mod tiling;
pub mod voxels;

pub use error::{Error, Result};

// The BC6H encoder's prebuilt objects need the C++ runtime.
use link_cplusplus as _;
