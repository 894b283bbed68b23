//! Readers for registered scans. Every format streams through one trait, [`PointSource`], that
//! fills a reusable [`PointChunk`] (so memory stays bounded by the chunk, not the file), in the
//! scan's own frame and f64. Poses are applied by the caller (`tiling`), in one place.
//!
//! Every reader refuses input it cannot trust with an [`crate::Error::Read`] naming the file: a header
//! claiming more points than the file can hold is caught before anything is allocated for it.

mod e57;
mod las;
pub use las::LAZ_BATCH;
mod ply;
mod source;

pub use source::{DEFAULT_CHUNK, NEUTRAL_GREY, PointChunk, PointSource, ScanFormat, SourceInfo};

use std::path::Path;

use crate::Result;

/// Scans (point clouds) in a file: 1 except for E57, which may hold several.
pub fn scan_count(path: &Path, format: ScanFormat) -> Result<usize> {
    match format {
        ScanFormat::E57 => e57::scan_count(path),
        _ => Ok(1),
    }
}

/// Opens scan `index` of `path`.
pub fn open(path: &Path, format: ScanFormat, index: usize) -> Result<Box<dyn PointSource>> {
    open_with(path, format, index, true)
}

/// [`open`] for a caller that reads positions only (the `--leaf-m auto` sample): LAS and LAZ
/// colours and intensities come back as stored, without the probe that tells 8-bit from 16-bit
/// values (which decodes 2^20 points first).
pub fn open_positions(path: &Path, format: ScanFormat, index: usize) -> Result<Box<dyn PointSource>> {
    open_with(path, format, index, false)
}

fn open_with(
    path: &Path,
    format: ScanFormat,
    index: usize,
    probe_colors: bool,
) -> Result<Box<dyn PointSource>> {
    Ok(match format {
        ScanFormat::Las | ScanFormat::Laz => Box::new(las::LasSource::open(path, format, probe_colors)?),
        ScanFormat::Ply => Box::new(ply::PlySource::open(path)?),
        ScanFormat::E57 => Box::new(e57::E57Source::open(path, index)?),
    })
}

/// What scan `index` of `path` says about itself (point count, attributes, stored pose), read from
/// its header alone: no points are decoded and no decoder is started.
pub(crate) fn header(path: &Path, format: ScanFormat, index: usize) -> Result<SourceInfo> {
    match format {
        ScanFormat::Las | ScanFormat::Laz => las::header_info(path, format),
        // Opening a PLY source parses only the header (and skips elements before the vertices).
        ScanFormat::Ply => Ok(ply::PlySource::open(path)?.info().clone()),
        ScanFormat::E57 => e57::header_info(path, index),
    }
}

/// Reads every point of a source into memory (tests and small inputs only).
pub fn read_all(source: &mut dyn PointSource) -> Result<PointChunk> {
    let mut all = PointChunk::new(DEFAULT_CHUNK);
    let mut chunk = PointChunk::new(DEFAULT_CHUNK);
    while source.fill_chunk(&mut chunk)? > 0 {
        all.xyz.extend_from_slice(&chunk.xyz);
        all.rgb.extend_from_slice(&chunk.rgb);
        all.normal.extend_from_slice(&chunk.normal);
    }
    Ok(all)
}
