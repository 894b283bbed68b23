//! Fuzzes the scan readers (LAS, LAZ, PLY, E57): the first byte picks the format, the rest is
//! written to a file on tmpfs and every point is read. Errors are fine; a panic that escapes,
//! a hang, or an allocation beyond the limit is a finding.
//!
//! Third-party decoders may panic on corrupt data; grotto catches that (`ingest::guard`) and turns
//! it into a typed error. libFuzzer's panic hook would abort even on a caught panic, so this target
//! installs a silent hook: a panic caught by grotto is then what it is in production (an error),
//! and any other panic still unwinds into libFuzzer's handler and is reported.
#![no_main]

use std::sync::Once;

use grotto_preprocess::ingest::{self, PointChunk, ScanFormat};
use libfuzzer_sys::fuzz_target;

static HOOK: Once = Once::new();

fuzz_target!(|data: &[u8]| {
    HOOK.call_once(|| std::panic::set_hook(Box::new(|_| {})));
    let Some((&pick, body)) = data.split_first() else { return };
    let (format, ext) = [
        (ScanFormat::Las, "las"),
        (ScanFormat::Laz, "laz"),
        (ScanFormat::Ply, "ply"),
        (ScanFormat::E57, "e57"),
    ][usize::from(pick) % 4];
    let dir = std::env::temp_dir();
    let path = dir.join(format!("grotto-fuzz-{}.{ext}", std::process::id()));
    if std::fs::write(&path, body).is_err() {
        return;
    }
    let Ok(count) = ingest::scan_count(&path, format) else { return };
    for i in 0..count.min(4) {
        let Ok(mut source) = ingest::open(&path, format, i) else { continue };
        let mut chunk = PointChunk::new(4096);
        // Bounded: a file this small cannot legitimately hold more points than this.
        let mut total = 0usize;
        while let Ok(n) = source.fill_chunk(&mut chunk) {
            total += n;
            if n == 0 || total > 1 << 24 {
                break;
            }
        }
    }
});
