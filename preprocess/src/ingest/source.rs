//! What every scan reader shares: the reusable chunk it fills, the reader trait, what a source

//! says about itself, the scan formats, and how a reader's failures become typed errors.
use std::path::{Path, PathBuf};

use serde::{Deserialize, Serialize};

use crate::pose::Pose;
use crate::{Error, Result};

/// Points per chunk unless the caller asks otherwise: large enough to amortise per-call costs and
/// to let the parallel LAZ decoder use several chunks, small enough (~2.4 MB) to stay in cache.
pub const DEFAULT_CHUNK: usize = 1 << 16;

/// A reusable batch of points, in the scan's frame. `rgb` always has one entry per point (grey
/// from intensity, or a neutral grey, when the file has no colour); `normal` is empty unless the
/// source provides normals.
#[derive(Debug, Default, Clone)]
pub struct PointChunk {
    pub xyz: Vec<[f64; 3]>,
    /// sRGB, 8 bits per channel.
    pub rgb: Vec<[u8; 3]>,
    pub normal: Vec<[f32; 3]>,
    limit: usize,
}

impl PointChunk {
    /// An empty chunk that holds up to `limit` points.
    pub fn new(limit: usize) -> Self {
        let limit = limit.max(1);
        Self { xyz: Vec::with_capacity(limit), rgb: Vec::with_capacity(limit), normal: Vec::new(), limit }
    }

    /// Most points one fill may put in.
    pub(crate) fn limit(&self) -> usize {
        self.limit
    }

    /// Points in the chunk.
    pub fn len(&self) -> usize {
        self.xyz.len()
    }

    /// Whether the chunk holds no points.
    pub fn is_empty(&self) -> bool {
        self.xyz.is_empty()
    }

    pub(crate) fn clear(&mut self) {
        self.xyz.clear();
        self.rgb.clear();
        self.normal.clear();
    }
}

/// File formats grotto reads.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Hash, Serialize, Deserialize)]
#[serde(rename_all = "lowercase")]
pub enum ScanFormat {
    Las,
    Laz,
    Ply,
    E57,
}

impl ScanFormat {
    /// From the file's first bytes, falling back to its extension.
    pub fn detect(path: &Path) -> Result<Self> {
        use std::io::Read;
        let mut magic = [0u8; 4];
        let n = std::fs::File::open(path)
            .and_then(|mut f| f.read(&mut magic))
            .map_err(|source| Error::Io { path: path.to_path_buf(), source })?;
        let ext = path.extension().and_then(|e| e.to_str()).map(str::to_ascii_lowercase);
        match (&magic[..n], ext.as_deref()) {
            (b"LASF", Some("laz")) => Ok(Self::Laz),
            (b"LASF", _) => Ok(Self::Las),
            // Writers put spaces after the magic word (PDAL's simple_text.ply has "ply \n").
            (b"ply\n" | b"ply\r" | b"ply " | b"ply\t", _) => Ok(Self::Ply),
            (b"ASTM", _) => Ok(Self::E57),
            _ => Err(Error::Read {
                path: path.to_path_buf(),
                format: "scan",
                reason: format!("not a LAS/LAZ, PLY or E57 file (starts with {:02x?})", &magic[..n]),
            }),
        }
    }

    /// The format's name (`las`, `laz`, `ply`, `e57`).
    pub fn name(self) -> &'static str {
        match self {
            Self::Las => "LAS",
            Self::Laz => "LAZ",
            Self::Ply => "PLY",
            Self::E57 => "E57",
        }
    }
}

/// What a source knows about itself before reading points.
#[derive(Clone, Debug)]
pub struct SourceInfo {
    pub(crate) path: PathBuf,
    pub(crate) format: ScanFormat,
    /// Scan name (E57 point cloud name, or the file stem).
    pub name: String,
    /// Points the header claims (already checked against what the file can hold where possible),
    /// less `dropped_points`: the points a reader delivers.
    pub claimed_points: u64,
    /// Points the header claims that the file cuts short: an uncompressed LAS file that ends
    /// inside its last point record has that record dropped (the complete ones are read; the
    /// build warns, and `--strict` refuses the file). Zero for every other file.
    pub(crate) dropped_points: u64,
    pub has_color: bool,
    pub has_normals: bool,
    /// Pose stored in the file (E57), scan frame -> world.
    pub file_pose: Option<Pose>,
}

/// A stream of points from one scan.
pub trait PointSource {
    /// What the source is (format, points, colours, normals, pose).
    fn info(&self) -> &SourceInfo;

    /// Clears `chunk` and fills it with up to `chunk.limit()` points. Returns how many; 0 means
    /// the scan is exhausted.
    fn fill_chunk(&mut self, chunk: &mut PointChunk) -> Result<usize>;
}

/// Grey used for points of files without colour or intensity.
pub const NEUTRAL_GREY: [u8; 3] = [180, 180, 180];

pub(crate) fn read_error(path: &Path, format: ScanFormat, reason: impl std::fmt::Display) -> Error {
    Error::Read { path: path.to_path_buf(), format: format.name(), reason: reason.to_string() }
}

/// Runs third-party decoder code, turning a panic into a typed error. The `las`/`laz` and `e57`
/// crates assert on some corrupt inputs (seen on damaged LAZ streams and lying point counts); a
/// bad file must give the user a message naming it, not abort a batch run. State touched by a
/// panicking call is not used again: callers poison their source.
pub(crate) fn guard<T>(path: &Path, format: ScanFormat, f: impl FnOnce() -> Result<T>) -> Result<T> {
    std::panic::catch_unwind(std::panic::AssertUnwindSafe(f)).unwrap_or_else(|payload| {
        let detail = payload
            .downcast_ref::<&str>()
            .map(|s| (*s).to_owned())
            .or_else(|| payload.downcast_ref::<String>().cloned())
            .unwrap_or_else(|| "unknown failure".into());
        Err(read_error(path, format, format!("corrupt data (the decoder failed: {detail})")))
    })
}
