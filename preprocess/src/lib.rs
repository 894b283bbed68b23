//! grotto's offline preprocessing: registered scans in, one `.grotto` package out.
//!
//! Ingest ([`ingest`]), out-of-core tiling ([`tiling`]), normals ([`normals`]), SVO tiles
//! ([`voxels`]) and the package build ([`build`]), with the built-in demo scene ([`demo`]) and the
//! synthetic survey ([`synth`]) the benchmarks run on; [`profile`] says where a build's time goes.

/// Scan readers behind one chunked trait: LAS/LAZ, PLY, E57.
pub mod ingest;
/// Scanner poses (rigid transforms) from manifests and files.
pub mod pose;
/// The manifest: scans, poses, lights, cameras, materials, environment.
pub mod manifest;
/// Out-of-core tiling: count, plan, distribute.
pub mod tiling;
/// The count pass's posed points on disk, read back by distribute.
mod spill;
/// The plan and the tile bins tiling leaves for the tile builds.
pub mod bins;
/// The point spacing `--leaf-m auto` measures.
mod spacing;
/// Exact k nearest neighbours over a tile and its halo.
mod knn;
/// Per-point normals, spread and surfel radius.
mod normals;
/// Orientation by enclosure for clouds without scanner positions.
pub mod orient;
/// Surfels splatted into SVO leaves: opacity, albedo, NDF, emission.
mod voxels;
/// BC1 colour encoders.
mod bc1;
/// Environment maps: SH9 irradiance and the prefiltered BC6H chain.
pub mod env;
/// The build: plan, build-tile and assemble, each resumable.
pub mod build;
/// Where a build's time and memory go.
pub mod profile;
/// Synthetic caves with a known surface (`grotto-pack synth`).
pub mod synth;
/// Scan writers: LAS/LAZ, PLY, E57.
pub mod scanwrite;
/// The tiny analytic demo fixture.
pub mod demo;
/// Benchmarks of readers, normals, BC1 and surfel encoding.
pub mod bench;
mod error;

pub use error::{Error, Result};

// The BC6H encoder's prebuilt objects need the C++ runtime.
use link_cplusplus as _;
