//! The count pass's posed points on disk (`WORK/spill/SCAN.spill`), which distribute reads
//! instead of decoding a scan again, and the posed chunk both passes share ([`Posed`]).

use std::fs::File;
use std::io::Write;
use std::path::{Path, PathBuf};

use bytemuck::{Pod, Zeroable};

use crate::ingest::PointChunk;
use crate::{Error, Result};

/// A chunk's valid points as both passes use them: global quanta (the one rounding every later
/// decision shares), the file normal as snorm16 (zero: none; the vector is empty where the chunk
/// has no normals) and the colour; and how many points of the chunk were invalid.
#[derive(Debug, Default)]
pub(crate) struct Posed {
    pub(crate) q: Vec<[i64; 3]>,
    pub(crate) normal_snorm: Vec<[i16; 3]>,
    pub(crate) rgb: Vec<[u8; 3]>,
    pub(crate) invalid: u64,
}

impl Posed {
    pub(crate) fn len(&self) -> usize {
        self.q.len()
    }

    pub(crate) fn clear(&mut self) {
        self.q.clear();
        self.normal_snorm.clear();
        self.rgb.clear();
        self.invalid = 0;
    }

    /// The valid points of a chunk already posed into the world.
    pub(crate) fn fill(&mut self, chunk: &PointChunk, inv_quantum: f64, with_normals: bool) {
        self.clear();
        let with_normals = with_normals && !chunk.normal.is_empty();
        for (i, p) in chunk.xyz.iter().enumerate() {
            if !valid_world(p) {
                self.invalid += 1;
                continue;
            }
            self.q.push(quantise(p, inv_quantum));
            self.rgb.push(chunk.rgb[i]);
            if with_normals {
                self.normal_snorm.push(chunk.normal.get(i).map_or([0; 3], |n| {
                    let len = n.iter().map(|c| c * c).sum::<f32>().sqrt();
                    if len.is_finite() && len > 1e-6 {
                        n.map(|c| (c / len * 32767.0).round() as i16)
                    } else {
                        [0; 3]
                    }
                }));
            }
        }
    }

    pub(crate) fn normal(&self, i: usize) -> [i16; 3] {
        self.normal_snorm.get(i).copied().unwrap_or([0; 3])
    }
}

/// The spill file of one scan: the count pass's posed points, which distribute reads instead of
/// decoding the scan again (LAZ and E57 decoding was a quarter of the plan step's CPU at 10^8).
pub(crate) fn spill_path(work_dir: &Path, scan: usize) -> PathBuf {
    work_dir.join("spill").join(format!("{scan:05}.spill"))
}

/// One block of a spill file: a chunk's valid points, then `points` positions (`[i32; 3]` offsets
/// from `base`, or `[i64; 3]` quanta where `SPILL_WIDE`: the chunk spans over 2^31 quanta),
/// `points` colours, and `points` snorm normals where `SPILL_NORMALS`.
#[repr(C)]
#[derive(Clone, Copy, Debug, Pod, Zeroable)]
pub(crate) struct SpillBlock {
    base: [i64; 3],
    points: u32,
    invalid: u32,
    flags: u32,
    reserved: u32,
}

pub(crate) const SPILL_NORMALS: u32 = 1;
pub(crate) const SPILL_WIDE: u32 = 2;
/// Most points one block holds (a reader allocates no more than this, whatever the file says).
pub(crate) const SPILL_MAX_BLOCK: usize = 1 << 22;

/// Writes one scan's spill file, under a temporary name until it is complete.
pub(crate) struct SpillWriter {
    pub(crate) scan: usize,
    tmp: PathBuf,
    path: PathBuf,
    out: std::io::BufWriter<File>,
}

impl SpillWriter {
    pub(crate) fn create(work_dir: &Path, scan: usize) -> Result<Self> {
        let path = spill_path(work_dir, scan);
        let tmp = path.with_extension("spill.tmp");
        let file = File::create(&tmp).map_err(|source| Error::Io { path: tmp.clone(), source })?;
        Ok(Self { scan, tmp, path, out: std::io::BufWriter::with_capacity(1 << 20, file) })
    }

    pub(crate) fn write(&mut self, posed: &Posed) -> Result<()> {
        let io = |source| Error::Io { path: self.tmp.clone(), source };
        for start in (0..posed.len().max(1)).step_by(SPILL_MAX_BLOCK) {
            let end = (start + SPILL_MAX_BLOCK).min(posed.len());
            let q = &posed.q[start..end];
            let base = q.first().copied().unwrap_or([0; 3]);
            let narrow: Option<Vec<[i32; 3]>> = q
                .iter()
                .map(|p| {
                    let d: [Option<i32>; 3] = std::array::from_fn(|a| i32::try_from(p[a] - base[a]).ok());
                    Some([d[0]?, d[1]?, d[2]?])
                })
                .collect();
            let normals = !posed.normal_snorm.is_empty();
            let block = SpillBlock {
                base,
                points: (end - start) as u32,
                invalid: if start == 0 { posed.invalid.min(u64::from(u32::MAX)) as u32 } else { 0 },
                flags: if normals { SPILL_NORMALS } else { 0 }
                    | if narrow.is_none() { SPILL_WIDE } else { 0 },
                reserved: 0,
            };
            self.out.write_all(bytemuck::bytes_of(&block)).map_err(io)?;
            match &narrow {
                Some(offsets) => self.out.write_all(bytemuck::cast_slice(offsets)).map_err(io)?,
                None => self.out.write_all(bytemuck::cast_slice(q)).map_err(io)?,
            }
            self.out.write_all(bytemuck::cast_slice(&posed.rgb[start..end])).map_err(io)?;
            if normals {
                self.out.write_all(bytemuck::cast_slice(&posed.normal_snorm[start..end])).map_err(io)?;
            }
        }
        Ok(())
    }

    /// Flushes the file and gives it its final name.
    pub(crate) fn finish(self) -> Result<()> {
        let file = self
            .out
            .into_inner()
            .map_err(|e| Error::Io { path: self.tmp.clone(), source: e.into_error() })?;
        drop(file);
        std::fs::rename(&self.tmp, &self.path).map_err(|source| Error::Io { path: self.path.clone(), source })
    }
}

/// Reads a spill file back block by block, checking every length against the file's.
pub(crate) struct SpillReader {
    path: PathBuf,
    input: std::io::BufReader<File>,
    left: u64,
    offsets: Vec<[i32; 3]>,
}

impl SpillReader {
    pub(crate) fn open(path: &Path) -> Result<Self> {
        let io = |source| Error::Io { path: path.to_path_buf(), source };
        let file = File::open(path).map_err(io)?;
        let left = file.metadata().map_err(io)?.len();
        Ok(Self {
            path: path.to_path_buf(),
            input: std::io::BufReader::with_capacity(1 << 20, file),
            left,
            offsets: Vec::new(),
        })
    }

    /// The next block into `posed`; false at the end of the file.
    pub(crate) fn read(&mut self, posed: &mut Posed) -> Result<bool> {
        use std::io::Read;
        posed.clear();
        if self.left == 0 {
            return Ok(false);
        }
        let corrupt = |what: String| Error::Read {
            path: self.path.clone(),
            format: "spill",
            reason: format!("corrupt spill file (delete WORK/spill to decode the scans again): {what}"),
        };
        let mut block = SpillBlock::zeroed();
        let header = size_of::<SpillBlock>() as u64;
        if self.left < header {
            return Err(corrupt(format!("{} trailing bytes", self.left)));
        }
        let io = |source| Error::Io { path: self.path.clone(), source };
        self.input.read_exact(bytemuck::bytes_of_mut(&mut block)).map_err(io)?;
        self.left -= header;
        let n = block.points as usize;
        let wide = block.flags & SPILL_WIDE != 0;
        let normals = block.flags & SPILL_NORMALS != 0;
        let per_point = if wide { 24 } else { 12 } + 3 + if normals { 6 } else { 0 };
        if n > SPILL_MAX_BLOCK
            || block.flags & !(SPILL_WIDE | SPILL_NORMALS) != 0
            || (n * per_point) as u64 > self.left
        {
            return Err(corrupt(format!(
                "block of {n} points, flags {:#x}, {} bytes left",
                block.flags, self.left
            )));
        }
        self.left -= (n * per_point) as u64;
        posed.invalid = u64::from(block.invalid);
        if wide {
            posed.q.resize(n, [0; 3]);
            self.input.read_exact(bytemuck::cast_slice_mut(&mut posed.q)).map_err(io)?;
        } else {
            self.offsets.resize(n, [0; 3]);
            self.input.read_exact(bytemuck::cast_slice_mut(&mut self.offsets)).map_err(io)?;
            let base = block.base;
            posed.q.extend(self.offsets.iter().map(|d| std::array::from_fn(|a| base[a] + i64::from(d[a]))));
        }
        posed.rgb.resize(n, [0; 3]);
        self.input.read_exact(bytemuck::cast_slice_mut(&mut posed.rgb)).map_err(io)?;
        if normals {
            posed.normal_snorm.resize(n, [0; 3]);
            self.input.read_exact(bytemuck::cast_slice_mut(&mut posed.normal_snorm)).map_err(io)?;
        }
        Ok(true)
    }
}

/// Whether a posed point is kept: both passes must drop the same points, or the counts the plan
/// was made from would not be the points distributed.
pub(crate) fn valid_world(p: &[f64; 3]) -> bool {
    p.iter().all(|v| v.is_finite() && v.abs() < 1e15)
}

/// The point in global quanta: the one rounding every later decision shares.
pub(crate) fn quantise(p: &[f64; 3], inv_quantum: f64) -> [i64; 3] {
    p.map(|v| (v * inv_quantum).floor() as i64)
}

#[cfg(test)]
mod tests {
    use super::*;

    fn posed(q: Vec<[i64; 3]>, normals: bool, invalid: u64) -> Posed {
        let n = q.len();
        Posed {
            normal_snorm: if normals {
                (0..n).map(|i| [i as i16, -(i as i16), 32767]).collect()
            } else {
                Vec::new()
            },
            rgb: (0..n).map(|i| [i as u8, 7, 255]).collect(),
            q,
            invalid,
        }
    }

    #[test]
    fn spill_files_read_back_what_was_written() {
        let work = tempfile::tempdir().unwrap();
        std::fs::create_dir_all(work.path().join("spill")).unwrap();
        // Survey-scale quanta, a chunk spanning more than 2^31 quanta (stored wide), one with
        // normals, and one with only invalid points.
        let chunks = [
            posed(vec![[5_000_000 << 16, 1 << 40, -3], [(5_000_000 << 16) + 9, (1 << 40) - 4, 12]], false, 2),
            posed(vec![[0, 0, 0], [1 << 33, -(1 << 33), 5]], true, 0),
            posed(Vec::new(), false, 4),
        ];
        let mut writer = SpillWriter::create(work.path(), 3).unwrap();
        for c in &chunks {
            writer.write(c).unwrap();
        }
        assert!(!spill_path(work.path(), 3).exists(), "complete only once finished");
        writer.finish().unwrap();
        let mut reader = SpillReader::open(&spill_path(work.path(), 3)).unwrap();
        let mut got = Posed::default();
        for c in &chunks {
            assert!(reader.read(&mut got).unwrap());
            assert_eq!(
                (&got.q, &got.normal_snorm, &got.rgb, got.invalid),
                (&c.q, &c.normal_snorm, &c.rgb, c.invalid)
            );
        }
        assert!(!reader.read(&mut got).unwrap());
    }

    fn anyhow_like(e: Error) -> String {
        let mut s = e.to_string();
        let mut src = std::error::Error::source(&e);
        while let Some(c) = src {
            s += &format!(": {c}");
            src = c.source();
        }
        s
    }

    #[test]
    fn a_damaged_spill_file_is_an_error_naming_it() {
        let work = tempfile::tempdir().unwrap();
        std::fs::create_dir_all(work.path().join("spill")).unwrap();
        let mut writer = SpillWriter::create(work.path(), 0).unwrap();
        writer.write(&posed(vec![[1, 2, 3]; 100], true, 0)).unwrap();
        writer.finish().unwrap();
        let path = spill_path(work.path(), 0);
        let bytes = std::fs::read(&path).unwrap();
        // Cut short, and a header claiming more points than a block may hold.
        let mut huge = bytes.clone();
        huge[24..28].copy_from_slice(&u32::MAX.to_le_bytes());
        for damaged in [bytes[..bytes.len() - 5].to_vec(), huge, bytes[..10].to_vec()] {
            std::fs::write(&path, damaged).unwrap();
            let mut reader = SpillReader::open(&path).unwrap();
            let err = anyhow_like(reader.read(&mut Posed::default()).unwrap_err());
            assert!(err.contains("00000.spill") && err.contains("corrupt spill"), "{err}");
        }
    }
}
