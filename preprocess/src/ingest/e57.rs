//! E57 through the `e57` crate: several scans per file, each with its pose; cartesian or spherical
//! coordinates (converted by the crate); points flagged invalid are dropped; colour, else
//! intensity as grey; surface normals where the scan carries the normals extension
//! (`nor:normalX/Y/Z`, as libE57Format and CloudCompare write it).
//!
//! The crate's point iterator borrows its reader, so a decoding thread owns both and hands filled
//! chunks over a bounded channel; empty chunks come back for reuse. That keeps memory at a few
//! chunks, overlaps decoding with the caller's work, and contains a panic inside the decoder: the
//! channel closes early and the caller gets a typed error instead of a crash.

use std::path::{Path, PathBuf};
use std::sync::mpsc::{Receiver, SyncSender, sync_channel};
use std::thread::JoinHandle;

use e57::{CartesianCoordinate, E57Reader, PointCloud, RecordName};

use crate::Result;
use crate::ingest::source::{
    NEUTRAL_GREY, PointChunk, PointSource, ScanFormat, SourceInfo, guard, read_error,
};
use crate::pose::Pose;

pub(super) fn scan_count(path: &Path) -> Result<usize> {
    guard(path, ScanFormat::E57, || {
        let reader = E57Reader::from_file(path).map_err(|e| read_error(path, ScanFormat::E57, e))?;
        Ok(reader.pointclouds().len())
    })
}

type Filled = std::result::Result<PointChunk, String>;

pub(super) struct E57Source {
    info: SourceInfo,
    filled: Receiver<Filled>,
    empty: SyncSender<PointChunk>,
    worker: Option<JoinHandle<()>>,
    delivered: u64,
}

/// What the file says about scan `index` (pose, count, attributes), without decoding points.
pub(super) fn header_info(path: &Path, index: usize) -> Result<SourceInfo> {
    guard(path, ScanFormat::E57, || header_unguarded(path, index).map(|(info, _)| info))
}

/// Where the scan's records hold the normals extension's three components, if it has all three.
/// Matched by local name: the extension's namespace URI differs between writers
/// (`E57_EXT_surface_normals`, CloudCompare's `E57_NOR_surface_normals`) and its prefix is free.
fn normal_records(pc: &PointCloud) -> Option<[usize; 3]> {
    let find = |want: &str| {
        pc.prototype.iter().position(|r| matches!(&r.name, RecordName::Unknown { name, .. } if name == want))
    };
    Some([find("normalX")?, find("normalY")?, find("normalZ")?])
}

/// The scan's info and whether it has intensity.
fn header_unguarded(path: &Path, index: usize) -> Result<(SourceInfo, bool)> {
    let err = |e: &dyn std::fmt::Display| read_error(path, ScanFormat::E57, e);
    let reader = E57Reader::from_file(path).map_err(|e| err(&e))?;
    let clouds = reader.pointclouds();
    let pc = clouds.get(index).ok_or_else(|| err(&format!("has {} scans, no scan {index}", clouds.len())))?;
    let file_pose = match &pc.transform {
        Some(t) => {
            let q = &t.rotation;
            let tr = &t.translation;
            Some(
                Pose::from_quaternion([q.w, q.x, q.y, q.z], [tr.x, tr.y, tr.z])
                    .map_err(|m| err(&format!("scan {index} pose: {m}")))?,
            )
        }
        None => None,
    };
    if !(pc.has_cartesian() || pc.has_spherical()) {
        return Err(err(&format!("scan {index} has neither cartesian nor spherical coordinates")));
    }
    let info = SourceInfo {
        path: path.to_path_buf(),
        format: ScanFormat::E57,
        name: pc.name.clone().unwrap_or_else(|| format!("scan {index}")),
        claimed_points: pc.records,
        has_color: pc.has_color(),
        has_normals: normal_records(pc).is_some(),
        dropped_points: 0,
        file_pose,
    };
    Ok((info, pc.has_intensity()))
}

impl E57Source {
    pub(super) fn open(path: &Path, index: usize) -> Result<Self> {
        guard(path, ScanFormat::E57, || Self::open_unguarded(path, index))
    }

    fn open_unguarded(path: &Path, index: usize) -> Result<Self> {
        let (info, has_intensity) = header_unguarded(path, index)?;
        let has_color = info.has_color;
        let (fill_tx, filled) = sync_channel::<Filled>(2);
        let (empty, empty_rx) = sync_channel::<PointChunk>(3);
        let owned_path: PathBuf = path.to_path_buf();
        let worker = std::thread::Builder::new()
            .name(format!("e57 {}", path.display()))
            .spawn(move || decode(owned_path, index, has_color, has_intensity, fill_tx, empty_rx))
            .map_err(|e| read_error(path, ScanFormat::E57, e))?;
        Ok(Self { info, filled, empty, worker: Some(worker), delivered: 0 })
    }
}

/// Runs on the decoding thread.
fn decode(
    path: PathBuf,
    index: usize,
    has_color: bool,
    has_intensity: bool,
    filled: SyncSender<Filled>,
    empty: Receiver<PointChunk>,
) {
    let run = || -> std::result::Result<(), String> {
        let mut reader = E57Reader::from_file(&path).map_err(|e| e.to_string())?;
        let pc = reader.pointclouds().into_iter().nth(index).ok_or("scan vanished")?;
        let mut points = reader.pointcloud_simple(&pc).map_err(|e| e.to_string())?;
        // Poses are applied by the caller, in f64, together with manifest overrides.
        points.apply_pose(false);
        points.spherical_to_cartesian(true);
        points.intensity_to_color(true);
        // The crate's simple points have no extension fields: the normals come from a second,
        // raw reading of the same scan, record for record (both yield every record in order).
        let normal_at = normal_records(&pc);
        let mut raw_reader =
            normal_at.map(|_| E57Reader::from_file(&path)).transpose().map_err(|e| e.to_string())?;
        let mut raw =
            raw_reader.as_mut().map(|r| r.pointcloud_raw(&pc)).transpose().map_err(|e| e.to_string())?;
        let mut chunk = PointChunk::new(super::DEFAULT_CHUNK);
        for p in points {
            let p = p.map_err(|e| e.to_string())?;
            let normal = match (&mut raw, normal_at) {
                (Some(raw), Some(at)) => {
                    let values =
                        raw.next().ok_or("fewer raw records than points")?.map_err(|e| e.to_string())?;
                    let component = |k: usize| -> std::result::Result<f32, String> {
                        let (v, r) =
                            values.get(at[k]).zip(pc.prototype.get(at[k])).ok_or("short raw record")?;
                        Ok(v.to_f64(&r.data_type).map_err(|e| e.to_string())? as f32)
                    };
                    Some([component(0)?, component(1)?, component(2)?])
                }
                _ => None,
            };
            let CartesianCoordinate::Valid { x, y, z } = p.cartesian else { continue };
            chunk.xyz.push([x, y, z]);
            // Tiling treats a zero or non-finite normal as missing (estimated instead).
            chunk.normal.extend(normal);
            chunk.rgb.push(match (p.color, has_color || has_intensity) {
                (Some(c), true) => {
                    [c.red, c.green, c.blue].map(|v| (v * 255.0).round().clamp(0.0, 255.0) as u8)
                }
                _ => NEUTRAL_GREY,
            });
            if chunk.len() == chunk.limit() {
                // Blocks while two chunks wait, which bounds memory; reuse a returned chunk if any.
                let next = empty.try_recv().unwrap_or_else(|_| PointChunk::new(super::DEFAULT_CHUNK));
                filled.send(Ok(std::mem::replace(&mut chunk, next))).map_err(|_| "reader dropped")?;
            }
        }
        if !chunk.is_empty() {
            filled.send(Ok(chunk)).map_err(|_| "reader dropped")?;
        }
        Ok(())
    };
    if let Err(e) = run() {
        let _ = filled.send(Err(e));
    }
}

impl PointSource for E57Source {
    fn info(&self) -> &SourceInfo {
        &self.info
    }

    fn fill_chunk(&mut self, chunk: &mut PointChunk) -> Result<usize> {
        chunk.clear();
        match self.filled.recv() {
            Ok(Ok(mut got)) => {
                // Points flagged invalid were dropped, so a chunk may be smaller than the limit.
                std::mem::swap(chunk, &mut got);
                got.clear();
                let _ = self.empty.try_send(got);
                self.delivered += chunk.len() as u64;
                Ok(chunk.len())
            }
            Ok(Err(message)) => Err(read_error(
                &self.info.path,
                ScanFormat::E57,
                format!("scan '{}' after {} points: {message}", self.info.name, self.delivered),
            )),
            Err(_) => {
                // Channel closed: either the scan is complete or the decoder died.
                match self.worker.take().map(JoinHandle::join) {
                    Some(Err(_)) => Err(read_error(
                        &self.info.path,
                        ScanFormat::E57,
                        format!(
                            "decoder failed in scan '{}' after {} points",
                            self.info.name, self.delivered
                        ),
                    )),
                    _ => Ok(0),
                }
            }
        }
    }
}

impl Drop for E57Source {
    fn drop(&mut self) {
        // Closing the channel makes the worker's next send fail, so it stops instead of decoding
        // the rest of the scan.
        let (_, closed) = sync_channel(0);
        drop(std::mem::replace(&mut self.filled, closed));
        if let Some(w) = self.worker.take() {
            let _ = w.join();
        }
    }
}
