//! Opening a package must cost time independent of its size: it validates the header, section table
//! and tile directory and maps the rest. Two packages with the same structure (64 tiles, 4 sections
//! each, plus scene and provenance) but 10 MB and 2 GB of payload are opened; `verify` of the small
//! one is there for contrast (it reads every byte).
//!
//! `cargo bench -p grotto-format --bench open`; `GROTTO_BENCH_LARGE_MB` changes the large size
//! (default 2048). The packages are written to a temp dir and removed afterwards.

use std::hint::black_box;
use std::path::{Path, PathBuf};

use criterion::{Criterion, criterion_group, criterion_main};
use grotto_format::spec::Surfel;
use grotto_format::*;

const TILES: u32 = 64;

fn write_package(path: &Path, total_bytes: u64) -> PathBuf {
    let per_section = (total_bytes / u64::from(TILES) / 4).next_multiple_of(32) as usize;
    let surfels =
        vec![
            Surfel { position_tile_m: [1.0, 2.0, 3.0], radius_m: 0.01, normal: [0.0, 0.0, 1.0], spread: 0.0 };
            per_section / 32
        ];
    let bytes: &[u8] = bytemuck::cast_slice(&surfels);
    let mut w = PackageWriter::create(path).unwrap();
    for t in 0..TILES {
        let tile = w
            .add_tile(TileInfo {
                origin_m: [512_000.0 + 32.0 * f64::from(t), 5_123_000.0, 300.0],
                extent_m: 32.0,
                grid: [16_000 + t as i32, 160_093, 9],
                depth: 8,
                point_count: surfels.len() as u64,
            })
            .unwrap();
        w.add_section(SectionKind::Surfels, Scope::Tile(tile), 0, bytes, Compression::Raw).unwrap();
        w.add_section(SectionKind::SurfelColorsRaw, Scope::Tile(tile), 0, bytes, Compression::Raw).unwrap();
        w.add_section(SectionKind::LeafAlbedo, Scope::Tile(tile), 0, bytes, Compression::Raw).unwrap();
        w.add_section(
            SectionKind::LeafEmission,
            Scope::Tile(tile),
            0,
            &bytes[..bytes.len() / 16 * 16],
            Compression::Raw,
        )
        .unwrap();
    }
    w.add_scene(&Scene::default()).unwrap();
    w.add_provenance(&Provenance::default()).unwrap();
    w.finish().unwrap()
}

fn bench_open(c: &mut Criterion) {
    let dir = tempfile::tempdir().unwrap();
    let large_mb: u64 =
        std::env::var("GROTTO_BENCH_LARGE_MB").ok().and_then(|v| v.parse().ok()).unwrap_or(2048);
    let small = write_package(&dir.path().join("small.grotto"), 10 << 20);
    let large = write_package(&dir.path().join("large.grotto"), large_mb << 20);
    let mut group = c.benchmark_group("open");
    for (name, path) in [("10MB", &small), (&*format!("{large_mb}MB"), &large)] {
        let size = std::fs::metadata(path).unwrap().len();
        println!("{name}: {size} bytes");
        group.bench_function(name, |b| {
            b.iter(|| {
                let pkg = Package::open(black_box(path)).unwrap();
                black_box(pkg.tile(TILES - 1).unwrap().origin_m())
            })
        });
    }
    group.finish();
    let mut group = c.benchmark_group("open+verify");
    group.sample_size(10);
    group.bench_function("10MB", |b| {
        b.iter(|| {
            let pkg = Package::open(black_box(&small)).unwrap();
            assert!(pkg.verify().is_empty());
        })
    });
    group.finish();
}

criterion_group!(benches, bench_open);
criterion_main!(benches);
