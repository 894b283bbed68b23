//! Tiles for a camera: which tiles are held full, coarse or far ([`residency`]), the same
//! streaming for every shell ([`Streaming`]), and a loader thread that reads the next residency
//! while frames render ([`follow`], native only).

#[cfg(not(target_arch = "wasm32"))]
pub mod follow;
pub mod residency;
mod streaming;

pub use streaming::{
    DamagedTile, Relit, Streaming, Swapped, damaged_tiles, relit, renderer_for, sections_for, swap_tiles,
};
