//! The scene as the GPU will hold it, built on the CPU: a package's tiles, nodes, leaves, surfels,
//! lights and environment in one f32 frame ([`data`]), the rock behind the walls ([`rock`]), each
//! tile's coarse and far levels ([`coarse`]), the constant-time tile lookup ([`tile_index`]) and
//! the points of interest and tours ([`story`]), and what a scene knows of the tiles a renderer
//! holds for it (summary.rs).

pub mod coarse;
pub mod data;
pub mod lighting;
mod load;
pub mod rock;
pub mod story;
mod summary;
pub mod surfels;
pub mod tile_index;
