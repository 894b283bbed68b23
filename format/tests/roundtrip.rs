//! Everything written comes back: every section kind with both codecs, tiles, scene, provenance,
//! and random packages (proptest).

mod common;

use std::borrow::Cow;

use common::*;
use grotto_format::spec::*;
use grotto_format::*;
use proptest::prelude::*;

fn check_all_content(pkg: &Package) {
    for kind in SectionKind::ALL {
        let scopes: Vec<(Scope, u32)> = if kind.is_per_tile() {
            vec![(Scope::Tile(0), 0), (Scope::Tile(1), 1)]
        } else {
            vec![(Scope::Global, 9)]
        };
        for (scope, seed) in scopes {
            if let Scope::Tile(t) = scope
                && !holds(kind, t)
            {
                assert!(pkg.find(kind, scope, 0).is_none());
                continue;
            }
            let s =
                pkg.find(kind, scope, item_of(kind)).unwrap_or_else(|| panic!("{kind:?} {scope:?} missing"));
            assert_eq!(&*pkg.read_bytes(&s).unwrap(), content(kind, seed).as_slice(), "{kind:?} {scope:?}");
        }
    }
}

#[test]
fn every_kind_round_trips_with_each_codec() {
    for (name, codec) in [
        ("raw", (|_, _| Compression::Raw) as fn(SectionKind, u32) -> Compression),
        ("zstd", |_, _| Compression::Zstd(3)),
        ("auto", |_, _| Compression::Auto(19)),
        ("mixed", alternating),
    ] {
        let dir = tempfile::tempdir().unwrap();
        let path = sample_package(dir.path(), codec);
        // `GROTTO_FUZZ_SEEDS=DIR` keeps these packages as seeds for the fuzzer (docs/fuzzing.md).
        if let Some(seeds) = std::env::var_os("GROTTO_FUZZ_SEEDS") {
            std::fs::create_dir_all(&seeds).unwrap();
            std::fs::copy(&path, std::path::Path::new(&seeds).join(format!("sample-{name}.grotto"))).unwrap();
        }
        let pkg = Package::open(&path).unwrap();
        // Compact surfels make it a 2.0 package.
        assert_eq!(pkg.version(), (VERSION_MAJOR, VERSION_MINOR));
        check_all_content(&pkg);
        assert!(pkg.verify().is_empty(), "{name}: {:?}", pkg.verify());
        if name == "zstd" {
            assert!(pkg.sections().filter(|s| s.kind.is_some()).all(|s| s.codec == Some(Codec::Zstd)));
        }
        if name == "raw" {
            assert!(pkg.sections().all(|s| s.codec == Some(Codec::Raw)));
        }
        // Same bytes through the in-memory path.
        let mem = Package::from_bytes("mem", &std::fs::read(&path).unwrap()).unwrap();
        check_all_content(&mem);
    }
}

#[test]
fn typed_reads_cast_raw_sections_in_place_and_check_types() {
    let dir = tempfile::tempdir().unwrap();
    let pkg = Package::open(sample_package(dir.path(), |_, _| Compression::Raw)).unwrap();
    let tile = pkg.tile(0).unwrap();
    let nodes = tile.read::<SvoNode>(SectionKind::SvoNodes).unwrap().unwrap();
    assert!(matches!(nodes, Cow::Borrowed(_)), "raw sections are zero-copy");
    assert_eq!(bytemuck::cast_slice::<SvoNode, u8>(&nodes), content(SectionKind::SvoNodes, 0).as_slice());
    let surfels = tile.read::<Surfel>(SectionKind::Surfels).unwrap().unwrap();
    assert_eq!(surfels[0].normal, [0.0, 0.0, 1.0]);
    // Reading a section as the wrong type is a typed error, not a reinterpretation.
    let s = tile.find(SectionKind::Surfels, 0).unwrap();
    let err = pkg.read::<f32>(&s).unwrap_err();
    assert!(matches!(err.problem(), Some(Problem::WrongElementType { .. })), "{err}");
    assert!(tile.read::<f32>(SectionKind::LeafOpacity).unwrap().is_some());
    assert!(pkg.tile(0).unwrap().read::<f32>(SectionKind::LeafOpacity).unwrap().is_some());
}

#[test]
fn tiles_scene_and_provenance_round_trip() {
    let dir = tempfile::tempdir().unwrap();
    let pkg = Package::open(sample_package(dir.path(), alternating)).unwrap();
    assert_eq!(pkg.tile_count(), 2);
    let t = pkg.tile(1).unwrap();
    assert_eq!(t.origin_m(), [512_344.0, 5_123_448.0, 336.0]);
    assert_eq!((t.extent_m(), t.depth(), t.point_count(), t.grid()), (8.0, 3, 1001, [64_043, 640_431, 42]));
    assert_eq!(t.leaf_size_m(), 1.0);
    // Every per-tile kind but full surfels (tile 1 has compact ones), and one unknown kind.
    assert_eq!(t.sections().len(), SectionKind::ALL.iter().filter(|k| k.is_per_tile()).count());
    assert!(t.sections().all(|s| s.scope == Scope::Tile(1)));
    assert_eq!(pkg.scene().unwrap(), sample_scene());
    let prov = pkg.provenance().unwrap().unwrap();
    assert_eq!(prov.parameters["depth"], 7);
}

#[test]
fn unknown_kinds_are_listed_and_skipped() {
    let dir = tempfile::tempdir().unwrap();
    let pkg = Package::open(sample_package(dir.path(), alternating)).unwrap();
    let unknown: Vec<_> = pkg.sections().filter(|s| s.kind.is_none()).collect();
    assert_eq!(unknown.len(), 1);
    assert_eq!(unknown[0].kind_name(), "unknown(4000)");
    assert_eq!(&*pkg.read_bytes(&unknown[0]).unwrap(), b"from the future");
    assert!(pkg.verify().is_empty());
    let summary = pkg.summary();
    assert!(summary.kinds.iter().any(|k| k.kind == "unknown(4000)"));
}

#[test]
fn auto_compression_keeps_incompressible_sections_raw() {
    let dir = tempfile::tempdir().unwrap();
    let path = dir.path().join("a.grotto");
    let mut w = PackageWriter::create(&path).unwrap();
    w.add_tile(TileInfo { origin_m: [0.0; 3], extent_m: 1.0, grid: [0; 3], depth: 0, point_count: 0 })
        .unwrap();
    // xorshift noise does not compress; zeros do.
    let mut x = 0x9e37_79b9_7f4a_7c15u64;
    let noise: Vec<u8> = (0..4096)
        .map(|_| {
            x ^= x << 13;
            x ^= x >> 7;
            x ^= x << 17;
            x as u8
        })
        .collect();
    w.add_section(SectionKind::LeafAlbedo, Scope::Tile(0), 0, &noise, Compression::Auto(3)).unwrap();
    w.add_section(SectionKind::SurfelColorsRaw, Scope::Tile(0), 0, &[0u8; 4096], Compression::Auto(3))
        .unwrap();
    let pkg = Package::open(w.finish().unwrap()).unwrap();
    let t = pkg.tile(0).unwrap();
    assert_eq!(t.find(SectionKind::LeafAlbedo, 0).unwrap().codec, Some(Codec::Raw));
    let zeros = t.find(SectionKind::SurfelColorsRaw, 0).unwrap();
    assert_eq!(zeros.codec, Some(Codec::Zstd));
    assert!(zeros.stored_len < 100);
    assert!(pkg.summary().compression_ratio > 1.5);
}

#[test]
fn empty_package_and_empty_tiles_are_valid() {
    let dir = tempfile::tempdir().unwrap();
    let path = dir.path().join("empty.grotto");
    let pkg = Package::open(PackageWriter::create(&path).unwrap().finish().unwrap()).unwrap();
    assert_eq!((pkg.tile_count(), pkg.section_count()), (0, 0));
    assert_eq!(pkg.scene().unwrap(), Scene::default());
    assert!(pkg.provenance().unwrap().is_none());

    let mut w = PackageWriter::create(&path).unwrap();
    w.add_tile(TileInfo { origin_m: [0.0; 3], extent_m: 4.0, grid: [0; 3], depth: 2, point_count: 0 })
        .unwrap();
    w.add_section(SectionKind::SvoNodes, Scope::Tile(0), 0, &[], Compression::Zstd(1)).unwrap();
    w.add_section(SectionKind::Surfels, Scope::Tile(0), 0, &[], Compression::Raw).unwrap();
    let pkg = Package::open(w.finish().unwrap()).unwrap();
    assert_eq!(pkg.tile(0).unwrap().read::<SvoNode>(SectionKind::SvoNodes).unwrap().unwrap().len(), 0);
    assert!(pkg.verify().is_empty());
}

#[derive(Debug, Clone)]
struct RandomSection {
    kind: u32,
    tile: Option<u8>,
    item: u32,
    len: usize,
    seed: u8,
    codec: u8,
}

fn random_bytes(kind: u32, len: usize, seed: u8) -> Vec<u8> {
    match SectionKind::from_u32(kind) {
        Some(SectionKind::LeafOpacity) => bytemuck::cast_slice(
            &(0..len).map(|i| ((i * 31 + seed as usize) % 101) as f32 / 100.0).collect::<Vec<_>>(),
        )
        .to_vec(),
        Some(k) => content(k, u32::from(seed) + len as u32),
        None => (0..len).map(|i| (i as u8).wrapping_mul(seed)).collect(),
    }
}

proptest! {
    #![proptest_config(ProptestConfig { cases: 64, failure_persistence: None, ..ProptestConfig::default() })]

    #[test]
    fn random_packages_round_trip(
        tiles in prop::collection::vec((any::<[i32; 3]>(), prop_oneof![Just(3u32), 0u32..=MAX_SVO_DEPTH], any::<u64>()), 0..6),
        sections in prop::collection::vec(
            (prop_oneof![Just(1u32), Just(2), Just(3), Just(7), Just(8), Just(12), Just(13), 100u32..200],
             any::<Option<u8>>(), 0u32..3, 0usize..3000, any::<u8>(), 0u8..3)
                .prop_map(|(kind, tile, item, len, seed, codec)| RandomSection { kind, tile, item, len, seed, codec }),
            0..24),
    ) {
        let dir = tempfile::tempdir().unwrap();
        let path = dir.path().join("p.grotto");
        let mut w = PackageWriter::create(&path).unwrap();
        for (grid, depth, points) in &tiles {
            let origin_m = grid.map(|g| f64::from(g) * 16.0 + 0.5);
            w.add_tile(TileInfo { origin_m, extent_m: 16.0, grid: *grid, depth: *depth, point_count: *points }).unwrap();
        }
        let mut written = Vec::new();
        for s in &sections {
            let kind = SectionKind::from_u32(s.kind);
            let scope = match (kind.map(SectionKind::is_per_tile), s.tile) {
                (Some(false), _) => Scope::Global,
                (_, Some(t)) if !tiles.is_empty() => Scope::Tile(u32::from(t) % tiles.len() as u32),
                (Some(true), _) => continue,
                (None, _) => Scope::Global,
            };
            // The fixture SVO is depth 3: only valid in tiles of that depth.
            if kind == Some(SectionKind::SvoNodes) && !matches!(scope, Scope::Tile(t) if tiles[t as usize].1 == 3) {
                continue;
            }
            let bytes = random_bytes(s.kind, s.len, s.seed);
            let codec = [Compression::Raw, Compression::Zstd(1), Compression::Auto(3)][s.codec as usize];
            if w.add_raw_section(s.kind, scope, s.item, &bytes, codec).is_ok() {
                written.push((s.kind, scope, s.item, bytes));
            }
        }
        let pkg = Package::open(w.finish().unwrap()).unwrap();
        prop_assert_eq!(pkg.tile_count() as usize, tiles.len());
        for (t, (grid, depth, points)) in pkg.tiles().zip(&tiles) {
            prop_assert_eq!((t.grid(), t.depth(), t.point_count()), (*grid, *depth, *points));
        }
        prop_assert_eq!(pkg.section_count() as usize, written.len());
        for (kind, scope, item, bytes) in &written {
            let s = pkg.sections().find(|s| s.kind_raw == *kind && s.scope == *scope && s.item == *item).unwrap();
            prop_assert_eq!(&*pkg.read_bytes(&s).unwrap(), bytes.as_slice());
        }
        prop_assert!(pkg.verify().is_empty());
    }
}

#[test]
fn sections_copy_between_packages_as_stored() {
    let dir = tempfile::tempdir().unwrap();
    let src = Package::open(sample_package(dir.path(), alternating)).unwrap();
    let out = dir.path().join("copy.grotto");
    let mut w = PackageWriter::create(&out).unwrap();
    let t = src.tile(1).unwrap();
    let tile = w.add_tile(t.info()).unwrap();
    for s in t.sections().filter(|s| s.kind.is_some()) {
        w.copy_section(&src, &s, Scope::Tile(tile)).unwrap();
    }
    for s in src.sections().filter(|s| s.scope == Scope::Global) {
        w.copy_section(&src, &s, Scope::Global).unwrap();
    }
    let copy = Package::open(w.finish().unwrap()).unwrap();
    assert!(copy.verify().is_empty());
    for s in t.sections().filter(|s| s.kind.is_some()) {
        let c = copy.find(s.kind.unwrap(), Scope::Tile(0), s.item).unwrap();
        assert_eq!((c.codec, c.stored_len, c.checksum), (s.codec, s.stored_len, s.checksum));
        assert_eq!(copy.read_bytes(&c).unwrap(), src.read_bytes(&s).unwrap());
    }
    assert_eq!(copy.scene().unwrap(), src.scene().unwrap());
    // A damaged source section is not carried over.
    let mut bytes = std::fs::read(src.path()).unwrap();
    let victim = t.find(SectionKind::SurfelsCompact, 0).unwrap();
    bytes[victim.offset as usize] ^= 1;
    let damaged = Package::from_bytes("damaged", &bytes).unwrap();
    let mut w = PackageWriter::create(dir.path().join("x.grotto")).unwrap();
    w.add_tile(TileInfo { origin_m: [0.0; 3], extent_m: 1.0, grid: [0; 3], depth: 3, point_count: 0 })
        .unwrap();
    assert!(w.copy_section(&damaged, &victim, Scope::Tile(0)).is_err());
    // `check` finds the same damage, and says so again when asked again (it is kept, not lost).
    assert!(damaged.check(&victim).is_err());
    assert!(damaged.check(&victim).is_err());
    let intact = t.find(SectionKind::SurfelsCompact, 0).unwrap();
    assert!(src.check(&intact).is_ok());
}

#[test]
fn svo_view_checks_that_leaf_attributes_fit_the_nodes() {
    use grotto_format::svo::{morton_encode, nodes_from_leaves};
    let dir = tempfile::tempdir().unwrap();
    let path = dir.path().join("svo.grotto");
    let leaves: Vec<u64> = vec![morton_encode(0, 0, 0), morton_encode(1, 2, 3), morton_encode(3, 3, 3)];
    let nodes = nodes_from_leaves(&leaves, 2).unwrap();
    let mut w = PackageWriter::create(&path).unwrap();
    for (t, n_attr) in [(0u32, 3usize), (1, 2)] {
        w.add_tile(TileInfo {
            origin_m: [f64::from(t) * 4.0, 0.0, 0.0],
            extent_m: 4.0,
            grid: [t as i32, 0, 0],
            depth: 2,
            point_count: 3,
        })
        .unwrap();
        let scope = Scope::Tile(t);
        w.add_elements(SectionKind::SvoNodes, scope, 0, &nodes, Compression::Raw).unwrap();
        w.add_elements(SectionKind::LeafOpacity, scope, 0, &vec![1.0f32; n_attr], Compression::Raw).unwrap();
        w.add_elements(SectionKind::LeafAlbedo, scope, 0, &[Rgba8([1, 2, 3, 255]); 3], Compression::Zstd(1))
            .unwrap();
        w.add_elements(
            SectionKind::LeafNdf,
            scope,
            0,
            &[LeafNdf { mean: [0.0, 0.0, 1.0], weight: 1.0 }; 3],
            Compression::Raw,
        )
        .unwrap();
    }
    let pkg = Package::open(w.finish().unwrap()).unwrap();
    let svo = pkg.tile(0).unwrap().svo().unwrap().unwrap();
    assert_eq!((svo.leaf_count(), svo.nodes.len()), (3, nodes.len()));
    assert!(svo.emission.is_none());
    let err = pkg.tile(1).unwrap().svo().unwrap_err();
    assert!(err.to_string().contains("3 leaves but 2 entries"), "{err}");
}

#[test]
fn coarse_levels_and_rock_read_back_checked() {
    let dir = tempfile::tempdir().unwrap();
    let pkg = Package::open(sample_package(dir.path(), alternating)).unwrap();
    for t in 0..2 {
        let tile = pkg.tile(t).unwrap();
        let coarse = tile.coarse(1).unwrap().expect("level 1 stored");
        assert_eq!(bytemuck::cast_slice::<SvoNode, u8>(&coarse.nodes), content(SectionKind::CoarseNodes, t));
        assert_eq!(coarse.leaves.len(), coarse.nodes.iter().filter(|n| n.level == 2).count());
        assert!(tile.coarse(2).unwrap().is_none(), "a level the writer did not make");
        assert_eq!(tile.rock().unwrap().unwrap().len(), 5);
    }
}

#[test]
fn coarse_levels_that_do_not_fit_their_tile_are_refused() {
    // Level 0 (that is the tile itself), a level deeper than the tile, nodes of the wrong depth
    // for their level, a leaf count that does not match, and rock far outside the tile.
    let nodes2 = content(SectionKind::CoarseNodes, 0);
    let leaves2 = content(SectionKind::CoarseLeaves, 0);
    let far = bytemuck::bytes_of(&RockBrick { brick: [0, 2, 0], reserved: 0, bits: [1, 0] }).to_vec();
    type Sections = Vec<(SectionKind, u32, Vec<u8>)>;
    let cases: [(&str, Sections); 5] = [
        ("level 0", vec![(SectionKind::CoarseNodes, 0, content(SectionKind::SvoNodes, 0))]),
        ("deeper than the tile", vec![(SectionKind::CoarseNodes, 4, nodes2.clone())]),
        ("wrong depth", vec![(SectionKind::CoarseNodes, 2, nodes2.clone())]),
        (
            "leaf count",
            vec![
                (SectionKind::CoarseNodes, 1, nodes2),
                (SectionKind::CoarseLeaves, 1, leaves2[48..].to_vec()),
            ],
        ),
        ("rock outside", vec![(SectionKind::RockBricks, 0, far)]),
    ];
    for (name, sections) in cases {
        let dir = tempfile::tempdir().unwrap();
        let path = dir.path().join("c.grotto");
        let mut w = PackageWriter::create(&path).unwrap();
        w.add_tile(TileInfo { origin_m: [0.0; 3], extent_m: 8.0, grid: [0; 3], depth: 3, point_count: 1 })
            .unwrap();
        for (kind, item, bytes) in &sections {
            w.add_section(*kind, Scope::Tile(0), *item, bytes, Compression::Raw).unwrap();
        }
        let pkg = Package::open(w.finish().unwrap()).unwrap();
        let tile = pkg.tile(0).unwrap();
        let (kind, item, _) = &sections[0];
        let err = match kind {
            SectionKind::RockBricks => tile.rock().map(drop).unwrap_err(),
            _ if sections.len() == 2 => tile.coarse(*item).map(drop).unwrap_err(),
            _ => pkg.read_bytes(&tile.find(*kind, *item).unwrap()).map(drop).unwrap_err(),
        };
        assert!(matches!(err.problem(), Some(Problem::BadContent { .. })), "{name}: {err}");
        assert!(!pkg.verify().is_empty(), "{name}: verify finds it too");
    }
}

#[test]
fn compact_surfels_decode_within_their_bounds_and_make_the_package_2_0() {
    let dir = tempfile::tempdir().unwrap();
    let pkg = Package::open(sample_package(dir.path(), alternating)).unwrap();
    let full: Vec<Surfel> = bytemuck::pod_collect_to_vec(&content(SectionKind::Surfels, 1));
    let t = pkg.tile(1).unwrap();
    let compact = t.surfels().unwrap().unwrap();
    assert!(matches!(compact, Cow::Owned(_)), "compact surfels are decoded");
    assert_eq!(compact.len(), full.len());
    for (a, b) in full.iter().zip(compact.iter()) {
        let moved = (0..3).map(|i| (a.position_tile_m[i] - b.position_tile_m[i]).powi(2)).sum::<f32>().sqrt();
        assert!(moved <= 0.001, "{a:?} -> {b:?}");
        assert!(a.normal.iter().zip(b.normal).map(|(x, y)| x * y).sum::<f32>() > 0.05f32.to_radians().cos());
    }
    assert_eq!(t.surfel_count_from_table(), Some(full.len() as u64));
    // Full surfels come in place from the map (raw) or decoded (zstd) as before.
    assert_eq!(
        pkg.tile(0).unwrap().surfels().unwrap().unwrap().len(),
        content(SectionKind::Surfels, 0).len() / 32
    );

    // A package without compact surfels stays 1.2, which 1.x readers open.
    let path = dir.path().join("full.grotto");
    let mut w = PackageWriter::create(&path).unwrap();
    w.add_tile(t.info()).unwrap();
    w.add_section(
        SectionKind::Surfels,
        Scope::Tile(0),
        0,
        &content(SectionKind::Surfels, 1),
        Compression::Raw,
    )
    .unwrap();
    // One encoding per tile.
    let compact_bytes = content(SectionKind::SurfelsCompact, 1);
    let err = w.add_section(SectionKind::SurfelsCompact, Scope::Tile(0), 0, &compact_bytes, Compression::Raw);
    assert!(err.unwrap_err().to_string().contains("other encoding"));
    let old = Package::open(w.finish().unwrap()).unwrap();
    assert_eq!(old.version(), (1, 2));
    assert_eq!(old.tile(0).unwrap().surfels().unwrap().unwrap().len(), full.len());
}
