//! Data a package's tiles imply but a renderer should not have to derive at open: each tile's
//! coarse level (its SVO cut a few levels above the leaves, [`coarse`]) and the rock behind its
//! scanned walls ([`rock`]). `grotto-pack` stores both in the package (format 1.1), so opening a
//! large package reads only what it shows; the runtime derives them with the same functions for
//! packages that lack them (format 1.0, hand-built scenes).

/// A tile's SVO cut a few levels above its leaves.
pub mod coarse;
/// The rock behind a tile's scanned walls, as bricks of rock bits.
pub mod rock;
/// What the packer stores with each tile, worked out over all tiles at once.
mod tiles;

pub use tiles::{TileGrid, TileLevels, origin_leaf, tile_levels};
