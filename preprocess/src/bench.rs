//! Measurements behind `docs/benchmarks.md`: ingest throughput per format, and peak memory.
//!
//! `ingest`: one synthetic scan of N points is written as LAS, LAZ, binary PLY and E57, then each
//! file is streamed through its [`crate::ingest::PointSource`] (chunks of 64 Ki points) and timed.
//! The same PLY file is also parsed with `ply-rs-bw`'s own body reader, which is why the PLY body
//! is streamed by hand (see `ingest/ply.rs`).

use std::path::Path;
use std::time::Instant;

use serde::Serialize;

use crate::ingest::{self, PointChunk, ScanFormat};
use crate::scanwrite::{ScanData, write_scan};
use crate::synth::{SynthCave, SynthParams, scan};
use crate::{Error, Result};

#[derive(Clone, Debug, Serialize)]
pub struct IngestFigure {
    pub reader: String,
    pub points: u64,
    pub file_bytes: u64,
    pub seconds: f64,
    pub points_per_second: f64,
}

/// Peak resident memory of this process so far (Linux `VmHWM`), in bytes.
pub fn peak_rss_bytes() -> Option<u64> {
    let status = std::fs::read_to_string("/proc/self/status").ok()?;
    let line = status.lines().find(|l| l.starts_with("VmHWM:"))?;
    let kb: u64 = line.split_whitespace().nth(1)?.parse().ok()?;
    Some(kb * 1024)
}

fn stream(path: &Path, format: ScanFormat) -> Result<u64> {
    let mut n = 0u64;
    for i in 0..ingest::scan_count(path, format)? {
        let mut src = ingest::open(path, format, i)?;
        let mut chunk = PointChunk::new(ingest::DEFAULT_CHUNK);
        while src.fill_chunk(&mut chunk)? > 0 {
            n += chunk.len() as u64;
        }
    }
    Ok(n)
}

/// Writes the test scan into `dir` (once; reused when present) and times every reader.
pub fn ingest(dir: &Path, points: u64, progress: &dyn Fn(&str)) -> Result<Vec<IngestFigure>> {
    std::fs::create_dir_all(dir).map_err(|source| Error::Io { path: dir.to_path_buf(), source })?;
    let params = SynthParams { points, segments: 12, ..SynthParams::default() };
    let formats = [
        (ScanFormat::Las, "las"),
        (ScanFormat::Laz, "laz"),
        (ScanFormat::Ply, "ply"),
        (ScanFormat::E57, "e57"),
    ];
    let path_of = |ext: &str| dir.join(format!("bench-{points}.{ext}"));
    if formats.iter().any(|(_, ext)| !path_of(ext).exists()) {
        progress("simulating the scan");
        let cave = SynthCave::new(&params);
        let sc = scan(&cave, &params, 0, points);
        for (format, ext) in formats {
            progress(&format!("writing {ext}"));
            let data = ScanData {
                xyz: &sc.xyz,
                rgb: &sc.rgb,
                intensity: &sc.intensity,
                normals: &[],
                pose: Some(sc.world_from_scan),
            };
            write_scan(&path_of(ext), format, &data)?;
        }
    }
    let mut out = Vec::new();
    let mut time = |reader: String, path: &Path, f: &dyn Fn() -> Result<u64>| -> Result<()> {
        progress(&format!("reading {reader}"));
        let start = Instant::now();
        let n = f()?;
        let seconds = start.elapsed().as_secs_f64();
        let file_bytes =
            std::fs::metadata(path).map_err(|source| Error::Io { path: path.to_path_buf(), source })?.len();
        out.push(IngestFigure {
            reader,
            points: n,
            file_bytes,
            seconds,
            points_per_second: n as f64 / seconds,
        });
        Ok(())
    };
    for (format, ext) in formats {
        let p = path_of(ext);
        time(format!("{} (grotto)", format.name()), &p, &|| stream(&p, format))?;
    }
    let p = path_of("ply");
    time("PLY (ply-rs-bw read_ply)".into(), &p, &|| {
        use ply_rs_bw::parser::Parser;
        use ply_rs_bw::ply::DefaultElement;
        let file = std::fs::File::open(&p).map_err(|source| Error::Io { path: p.clone(), source })?;
        let ply = Parser::<DefaultElement>::new()
            .read_ply(&mut std::io::BufReader::new(file))
            .map_err(|e| Error::Read { path: p.clone(), format: "PLY", reason: e.to_string() })?;
        Ok(ply.payload.get("vertex").map_or(0, |v| v.len() as u64))
    })?;
    Ok(out)
}
