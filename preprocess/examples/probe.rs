//! Reads every scan file given and prints its point count, bounds and attributes, or the error.
//! `cargo run -p grotto-preprocess --example probe -- FILE...`

use grotto_preprocess::ingest::{self, PointChunk, ScanFormat};

fn main() {
    for arg in std::env::args().skip(1) {
        let path = std::path::Path::new(&arg);
        let result = (|| -> grotto_preprocess::Result<String> {
            let format = ScanFormat::detect(path)?;
            let mut out = String::new();
            for i in 0..ingest::scan_count(path, format)? {
                let mut src = ingest::open(path, format, i)?;
                let mut chunk = PointChunk::new(ingest::DEFAULT_CHUNK);
                let (mut n, mut lo, mut hi) = (0u64, [f64::INFINITY; 3], [f64::NEG_INFINITY; 3]);
                while src.fill_chunk(&mut chunk)? > 0 {
                    n += chunk.len() as u64;
                    for p in &chunk.xyz {
                        for a in 0..3 {
                            lo[a] = lo[a].min(p[a]);
                            hi[a] = hi[a].max(p[a]);
                        }
                    }
                }
                let info = src.info();
                out += &format!(
                    "{} scan {i} '{}': {n} points (claims {}), color {}, normals {}, pose {}, bounds {lo:.3?}..{hi:.3?}; ",
                    format.name(),
                    info.name,
                    info.claimed_points,
                    info.has_color,
                    info.has_normals,
                    info.file_pose.is_some()
                );
            }
            Ok(out)
        })();
        match result {
            Ok(s) => println!("OK   {arg}: {s}"),
            Err(e) => println!("ERR  {e}"),
        }
    }
}
