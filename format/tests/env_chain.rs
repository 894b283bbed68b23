//! The environment chain's rules (docs/format.md, "EnvMipLevel"): a level table that is valid
//! section by section but would make a reader build a huge atlas is refused by `verify` and by
//! `Package::env_chain`, with the problem named.

use grotto_format::spec::{Bc6hBlock, EnvMipLevel};
use grotto_format::{Compression, Package, PackageWriter, Problem, Scope, SectionKind};

/// A level's width, height and roughness.
type Dims = (u32, u32, f32);

/// Level (width, height, roughness) list -> consecutive levels.
fn levels(dims: &[Dims]) -> Vec<EnvMipLevel> {
    grotto_format::level_table(dims.iter().copied())
}

/// A package holding environment 0's levels and `blocks` blocks (None: as many as the levels cover).
fn package(dir: &std::path::Path, table: &[EnvMipLevel], blocks: Option<u32>) -> Package {
    let path = dir.join("env.grotto");
    let mut w = PackageWriter::create(&path).unwrap();
    w.add_elements(SectionKind::EnvMipLevels, Scope::Global, 0, table, Compression::Raw).unwrap();
    let n = blocks.unwrap_or_else(|| table.iter().map(|l| l.block_count).sum());
    let b = vec![Bc6hBlock([3; 16]); n as usize];
    w.add_elements(SectionKind::EnvMipBc6h, Scope::Global, 0, &b, Compression::Zstd(3)).unwrap();
    w.finish().unwrap();
    Package::open(&path).unwrap()
}

fn reason(p: &Problem) -> &str {
    match p {
        Problem::BadContent { reason, .. } => reason,
        other => panic!("expected bad content, got {other}"),
    }
}

#[test]
fn a_chain_that_would_stack_into_a_huge_atlas_is_refused_and_verify_says_why() {
    let dir = tempfile::tempdir().unwrap();
    // The package: an 8192-wide base and seven levels of 4x4096 (147 KiB of blocks); a
    // reader stacking them as wide as the base would need a 3.8 GB atlas.
    let mut dims = vec![(8192, 4, 0.0)];
    dims.extend((1..8).map(|k| (4, 4096, k as f32 / 7.0)));
    let pkg = package(dir.path(), &levels(&dims), None);
    let problems = pkg.verify();
    assert_eq!(problems.len(), 1, "{problems:?}");
    assert!(reason(&problems[0]).contains("larger than level 0"), "{}", problems[0]);
    let err = pkg.env_chain(0).unwrap_err();
    assert!(err.to_string().contains("env.grotto"), "the error names the file: {err}");

    // Each level no larger than the one before, but far narrower than the atlas: the texel rule.
    let dims: Vec<_> = [(8192, 8)].into_iter().chain([(8, 8); 7]).map(|(w, h)| (w, h, 0.5)).collect();
    let pkg = package(dir.path(), &levels(&dims), None);
    let problems = pkg.verify();
    assert!(reason(&problems[0]).contains("atlas"), "{}", problems[0]);
}

#[test]
fn each_rule_of_the_level_table_is_checked() {
    let dir = tempfile::tempdir().unwrap();
    let cases: Vec<(Vec<Dims>, &str)> = vec![
        (vec![(16, 8, 0.0); 9], "9 levels"),
        (vec![(16384, 8192, 0.0)], "larger than 8192x4096"),
        (vec![(16, 8, 0.5), (8, 4, 0.25)], "roughness 0.25 is below"),
        (vec![(16, 8, 1.5)], "outside 0..=1"),
        (vec![(16, 8, 0.0), (32, 4, 0.5)], "larger than level 0"),
    ];
    for (dims, expected) in cases {
        let pkg = package(dir.path(), &levels(&dims), None);
        let problems = pkg.verify();
        assert!(
            problems.iter().any(|p| reason(p).contains(expected)),
            "{dims:?}: expected '{expected}', got {problems:?}"
        );
        assert!(pkg.env_chain(0).is_err());
    }
    // Blocks the levels do not cover, or too few: a cross-section problem, reported once.
    for blocks in [7, 9] {
        let pkg = package(dir.path(), &levels(&[(16, 8, 0.0), (8, 4, 1.0)]), Some(blocks));
        let problems = pkg.verify();
        assert_eq!(problems.len(), 1, "{problems:?}");
        assert!(reason(&problems[0]).contains("levels cover 10"), "{}", problems[0]);
    }
}

#[test]
fn a_chain_that_halves_each_level_reads_back() {
    let dir = tempfile::tempdir().unwrap();
    // The shape preprocess writes: halving to at least 8x4, roughness ascending.
    let dims = [(256, 128, 0.0), (128, 64, 0.2), (64, 32, 0.4), (32, 16, 0.6), (16, 8, 0.8), (8, 4, 1.0)];
    let pkg = package(dir.path(), &levels(&dims), None);
    assert!(pkg.verify().is_empty(), "{:?}", pkg.verify());
    let chain = pkg.env_chain(0).unwrap().unwrap();
    assert_eq!((chain.atlas_width(), chain.atlas_height()), (256, 252));
    assert_eq!(chain.level_rows().collect::<Vec<_>>(), [0, 128, 192, 224, 240, 248]);
    assert_eq!(chain.blocks.len(), chain.levels.iter().map(|l| l.block_count as usize).sum::<usize>());
}
