//! Damaged and hostile packages: every case gives a typed error naming the file and what is wrong,
//! and nothing panics.

mod common;

use common::*;
use grotto_format::spec::*;
use grotto_format::*;
use proptest::prelude::*;

fn sample_bytes() -> Vec<u8> {
    let dir = tempfile::tempdir().unwrap();
    std::fs::read(sample_package(dir.path(), alternating)).unwrap()
}

fn sections_of(bytes: &[u8]) -> Vec<SectionInfo> {
    Package::from_bytes("ok", bytes).unwrap().sections().collect()
}

#[test]
fn truncation_at_every_boundary_and_mid_section_is_detected() {
    let bytes = sample_bytes();
    let h = header(&bytes);
    let mut cuts =
        vec![0, 1, 8, 71, 72, h.section_table_offset, h.section_table_offset + 20, h.tile_directory_offset];
    cuts.push(h.tile_directory_offset + 10);
    cuts.push(bytes.len() as u64 - 1);
    for s in sections_of(&bytes) {
        cuts.extend([s.offset, s.offset + s.stored_len / 2, s.offset + s.stored_len]);
    }
    for cut in cuts {
        let cut = cut as usize;
        if cut >= bytes.len() {
            continue;
        }
        match open_problem(&bytes[..cut]) {
            Problem::Truncated { expected, actual } => {
                assert_eq!((expected, actual), (bytes.len() as u64, cut as u64));
            }
            Problem::TooShort { len, .. } => assert!(cut < 72 && len == cut as u64),
            other => panic!("cut at {cut}: unexpected {other}"),
        }
    }
    // Extra bytes appended are also refused: the header pins the length.
    let mut longer = bytes.clone();
    longer.extend_from_slice(&[0; 10]);
    assert!(matches!(open_problem(&longer), Problem::Truncated { .. }));
}

#[test]
fn a_flipped_byte_in_a_section_names_that_section() {
    let bytes = sample_bytes();
    for s in sections_of(&bytes) {
        if s.stored_len == 0 {
            continue;
        }
        let mut bad = bytes.clone();
        bad[(s.offset + s.stored_len / 2) as usize] ^= 0x10;
        // Open stays cheap and succeeds: payload checksums are lazy.
        let pkg = Package::from_bytes("flip.grotto", &bad).unwrap();
        let err = pkg.read_bytes(&s).unwrap_err();
        let msg = err.to_string();
        match err.problem() {
            Some(Problem::SectionChecksum { section, kind, .. }) => {
                assert_eq!((*section, kind.as_str()), (s.index, s.kind_name().as_str()));
                assert!(
                    msg.contains(&format!("section {}", s.index)) && msg.contains(&s.kind_name()),
                    "{msg}"
                );
            }
            other => panic!("section {}: {other:?}", s.index),
        }
        // The failure is cached and verify reports exactly this section.
        assert!(pkg.read_bytes(&s).is_err());
        let problems = pkg.verify();
        assert_eq!(problems.len(), 1, "{problems:?}");
        assert!(matches!(problems[0], Problem::SectionChecksum { section, .. } if section == s.index));
    }
}

#[test]
fn flipped_bytes_in_header_table_and_directory_are_detected() {
    let bytes = sample_bytes();
    let h = header(&bytes);
    for at in [9usize, 12, 20, 40, 56, 66] {
        let mut bad = bytes.clone();
        bad[at] ^= 0x01;
        let p = open_problem(&bad);
        assert!(
            matches!(
                p,
                Problem::HeaderChecksum { .. }
                    | Problem::UnsupportedVersion { .. }
                    | Problem::BadHeaderSize { .. }
            ),
            "byte {at}: {p}"
        );
    }
    for at in [h.section_table_offset + 3, h.section_table_offset + 50, h.tile_directory_offset + 9] {
        let mut bad = bytes.clone();
        bad[at as usize] ^= 0x80;
        assert!(matches!(open_problem(&bad), Problem::TableChecksum { .. }));
    }
    let mut bad = bytes.clone();
    bad[1] = b'g';
    assert!(matches!(open_problem(&bad), Problem::BadMagic { .. }));
}

#[test]
fn sections_outside_the_file_overflowing_or_overlapping_are_refused() {
    let bytes = sample_bytes();
    let len = bytes.len() as u64;

    let mut b = bytes.clone();
    patch(&mut b, |_, t, _| t[3].offset = len - 64);
    let p = open_problem(&b);
    assert!(
        matches!(p, Problem::OutOfBounds { region: Region::Section(3), .. } | Problem::Overlap { .. }),
        "{p}"
    );

    let mut b = bytes.clone();
    patch(&mut b, |_, t, _| t[2].offset = len.next_multiple_of(64) + 64);
    assert!(matches!(open_problem(&b), Problem::OutOfBounds { region: Region::Section(2), .. }));

    let mut b = bytes.clone();
    patch(&mut b, |_, t, _| {
        t[1].offset = u64::MAX - 63;
        t[1].stored_len = 128;
    });
    assert!(matches!(open_problem(&b), Problem::Overflow { .. }));

    let mut b = bytes.clone();
    patch(&mut b, |_, t, _| t[5].offset = t[4].offset);
    assert!(matches!(open_problem(&b), Problem::Overlap { .. }));

    // A section claiming the header's or table's bytes.
    let mut b = bytes.clone();
    patch(&mut b, |h, t, _| t[0].offset = h.section_table_offset);
    assert!(matches!(open_problem(&b), Problem::Overlap { .. }));
    // (The unknown-kind section: no element-size check stands in front of the overlap check.)
    let unknown = sections_of(&bytes).iter().find(|s| s.kind.is_none()).unwrap().index as usize;
    let mut b = bytes.clone();
    patch(&mut b, |_, t, _| {
        t[unknown].offset = 0;
        t[unknown].stored_len = 8;
        t[unknown].raw_len = 8;
    });
    let p = open_problem(&b);
    assert!(
        matches!(p, Problem::Overlap { first, second } if first == Region::Header || second == Region::Header),
        "{p}"
    );

    let mut b = bytes.clone();
    patch(&mut b, |_, t, _| t[6].offset += 8);
    assert!(matches!(open_problem(&b), Problem::Misaligned { region: Region::Section(6), align: 64, .. }));
}

#[test]
fn table_and_directory_outside_the_file_are_refused() {
    let bytes = sample_bytes();
    let mut b = bytes.clone();
    patch(&mut b, |_, _, _| {});
    let mut h = header(&b);
    h.section_table_offset = u64::MAX - 8;
    b[..72].copy_from_slice(bytemuck::bytes_of(&h));
    reseal_header(&mut b);
    assert!(matches!(open_problem(&b), Problem::Overflow { .. }));

    let mut h = header(&bytes);
    let mut b = bytes.clone();
    h.tile_directory_offset = bytes.len() as u64 - 8;
    b[..72].copy_from_slice(bytemuck::bytes_of(&h));
    reseal_header(&mut b);
    assert!(matches!(open_problem(&b), Problem::OutOfBounds { region: Region::TileDirectory, .. }));

    let mut h = header(&bytes);
    let mut b = bytes.clone();
    h.section_table_offset += 4;
    b[..72].copy_from_slice(bytemuck::bytes_of(&h));
    reseal_header(&mut b);
    let p = open_problem(&b);
    assert!(
        matches!(p, Problem::Misaligned { region: Region::SectionTable, .. } | Problem::OutOfBounds { .. }),
        "{p}"
    );
}

#[test]
fn absurd_counts_are_refused_before_allocating() {
    // A tile count of 2^40 in a tiny file: bounds arithmetic refuses it (the alloc_bounds test
    // shows nothing big is allocated on the way).
    let dir = tempfile::tempdir().unwrap();
    let path = dir.path().join("small.grotto");
    let mut bytes = std::fs::read(PackageWriter::create(&path).unwrap().finish().unwrap()).unwrap();
    assert!(bytes.len() < 1024);
    let mut h = header(&bytes);
    h.tile_count = 1 << 40;
    bytes[..72].copy_from_slice(bytemuck::bytes_of(&h));
    reseal_header(&mut bytes);
    let p = open_problem(&bytes);
    assert!(
        matches!(p, Problem::OutOfBounds { region: Region::TileDirectory, len, .. } if len == 64 << 40),
        "{p}"
    );

    h.tile_count = 0;
    h.section_count = u64::MAX / 2;
    bytes[..72].copy_from_slice(bytemuck::bytes_of(&h));
    reseal_header(&mut bytes);
    assert!(matches!(open_problem(&bytes), Problem::Overflow { .. }));
}

#[test]
fn lying_lengths_and_codecs_are_refused() {
    let bytes = sample_bytes();
    let secs = sections_of(&bytes);
    let zstd = secs.iter().find(|s| s.codec == Some(Codec::Zstd)).unwrap().index as usize;
    let raw = secs.iter().find(|s| s.codec == Some(Codec::Raw) && s.kind.is_some()).unwrap().index as usize;

    // zstd claiming more than it can expand to: refused at open, nothing allocated.
    let mut b = bytes.clone();
    patch(&mut b, |_, t, _| t[zstd].raw_len = 1 << 50);
    assert!(matches!(open_problem(&b), Problem::ImplausibleLength { .. }));

    // zstd claiming a plausible but wrong length: decode error on read.
    let mut b = bytes.clone();
    let whole = secs[zstd].kind.unwrap().element().size() as u64;
    patch(&mut b, |_, t, _| t[zstd].raw_len += whole);
    let pkg = Package::from_bytes("lie.grotto", &b).unwrap();
    let err = pkg.read_bytes(&pkg.section(zstd as u32).unwrap()).unwrap_err();
    assert!(matches!(err.problem(), Some(Problem::Decompress { .. })), "{err}");

    // Garbage zstd payload with a matching checksum.
    let mut b = bytes.clone();
    let s = secs[zstd];
    for i in s.offset..s.offset + s.stored_len {
        b[i as usize] = 0xAB;
    }
    let sum = xxhash_rust::xxh3::xxh3_64(&b[s.offset as usize..(s.offset + s.stored_len) as usize]);
    patch(&mut b, |_, t, _| t[zstd].checksum = sum);
    let pkg = Package::from_bytes("garbage.grotto", &b).unwrap();
    let err = pkg.read_bytes(&pkg.section(zstd as u32).unwrap()).unwrap_err();
    assert!(matches!(err.problem(), Some(Problem::Decompress { .. })), "{err}");

    let mut b = bytes.clone();
    patch(&mut b, |_, t, _| t[raw].raw_len += 1);
    assert!(matches!(open_problem(&b), Problem::RawLengthMismatch { .. }));

    let mut b = bytes.clone();
    patch(&mut b, |_, t, _| t[raw].codec = 7);
    assert!(matches!(open_problem(&b), Problem::UnknownCodec { .. }));

    // A surfel section whose length is not whole surfels.
    let surfels = secs.iter().find(|s| s.kind == Some(SectionKind::Surfels)).unwrap();
    let mut b = bytes.clone();
    patch(&mut b, |_, t, _| {
        if surfels.codec == Some(Codec::Raw) {
            t[surfels.index as usize].stored_len -= 4;
        }
        t[surfels.index as usize].raw_len -= 4;
    });
    let p = open_problem(&b);
    assert!(matches!(p, Problem::BadElementLength { element_size: 32, .. }), "{p}");
}

#[test]
fn scopes_tiles_and_duplicates_are_checked() {
    let bytes = sample_bytes();
    let secs = sections_of(&bytes);
    let global = secs.iter().find(|s| s.kind == Some(SectionKind::Scene)).unwrap().index as usize;
    let tile_sec = secs.iter().find(|s| s.kind == Some(SectionKind::Surfels)).unwrap().index as usize;

    let mut b = bytes.clone();
    patch(&mut b, |_, t, _| t[tile_sec].tile = 99);
    assert!(matches!(open_problem(&b), Problem::NoSuchTile { tile: 99, .. }));

    let mut b = bytes.clone();
    patch(&mut b, |_, t, _| t[tile_sec].tile = GLOBAL);
    let p = open_problem(&b);
    assert!(matches!(p, Problem::WrongScope { .. } | Problem::BadTile { .. }), "{p}");

    let mut b = bytes.clone();
    patch(&mut b, |_, t, _| t[global].tile = 0);
    assert!(matches!(open_problem(&b), Problem::WrongScope { .. } | Problem::BadTile { .. }));

    // Two scenes.
    let mut b = bytes.clone();
    let prov = secs.iter().find(|s| s.kind == Some(SectionKind::Provenance)).unwrap().index as usize;
    patch(&mut b, |_, t, _| t[prov].kind = SectionKind::Scene as u32);
    assert!(matches!(open_problem(&b), Problem::DuplicateSection { .. }));

    // A tile with its surfels both ways (tile 0's scan indices relabelled as compact surfels).
    let mut b = bytes.clone();
    let scans = secs
        .iter()
        .find(|s| s.kind == Some(SectionKind::SurfelScans) && s.scope == Scope::Tile(0))
        .unwrap()
        .index as usize;
    patch(&mut b, |_, t, _| t[scans].kind = SectionKind::SurfelsCompact as u32);
    let p = open_problem(&b);
    assert!(matches!(p, Problem::BadTile { tile: 0, .. }) && p.to_string().contains("both"), "{p}");
    // Compact surfels that lie about their count, caught when first read.
    let mut b = bytes.clone();
    let compact = secs
        .iter()
        .find(|s| s.kind == Some(SectionKind::SurfelsCompact) && s.codec == Some(Codec::Raw))
        .unwrap();
    let at = compact.offset as usize;
    b[at..at + 4].copy_from_slice(&1_000_000u32.to_le_bytes());
    let sum = xxhash_rust::xxh3::xxh3_64(&b[at..at + compact.stored_len as usize]);
    patch(&mut b, |_, t, _| t[compact.index as usize].checksum = sum);
    let pkg = Package::from_bytes("lying-compact.grotto", &b).unwrap();
    let err = pkg.tile(1).unwrap().surfels().unwrap_err();
    assert!(matches!(err.problem(), Some(Problem::BadContent { .. })), "{err}");
    assert!(err.to_string().contains("lying-compact.grotto"), "{err}");

    // Tile runs that lie.
    let mut b = bytes.clone();
    patch(&mut b, |_, _, d| d[0].section_count += 100);
    assert!(matches!(open_problem(&b), Problem::BadTile { tile: 0, .. }));
    let mut b = bytes.clone();
    patch(&mut b, |_, _, d| d[1].section_count -= 1);
    assert!(matches!(open_problem(&b), Problem::SectionOutsideTileRun { tile: 1, .. }));
    for edit in [
        (|d: &mut [RawTileEntry]| d[1].origin_m[2] = f64::NAN) as fn(&mut [RawTileEntry]),
        |d| d[0].extent_m = -1.0,
        |d| d[0].extent_m = f64::INFINITY,
        |d| d[1].depth = 40,
    ] {
        let mut b = bytes.clone();
        patch(&mut b, |_, _, d| edit(d));
        assert!(matches!(open_problem(&b), Problem::BadTile { .. }));
    }
}

#[test]
fn versions_newer_minor_opens_newer_major_is_refused_with_both_versions() {
    let bytes = sample_bytes();
    let mut b = bytes.clone();
    patch(&mut b, |h, _, _| h.version_minor = VERSION_MINOR + 3);
    let pkg = Package::from_bytes("newer-minor.grotto", &b).unwrap();
    assert_eq!(pkg.version(), (VERSION_MAJOR, VERSION_MINOR + 3));
    assert!(pkg.verify().is_empty());

    // A newer minor with a longer header (the padding before the first section).
    let mut b = bytes.clone();
    patch(&mut b, |h, _, _| h.header_size = 96);
    b[72..96].fill(0x5a);
    reseal_header(&mut b);
    assert!(Package::from_bytes("longer-header.grotto", &b).is_ok());

    let mut b = bytes.clone();
    patch(&mut b, |h, _, _| {
        h.version_major = VERSION_MAJOR + 1;
        h.version_minor = 2;
    });
    let err = Package::from_bytes("newer-major.grotto", &b).unwrap_err();
    let msg = err.to_string();
    assert!(matches!(
        err.problem(),
        Some(Problem::UnsupportedVersion { found_major: 3, found_minor: 2, .. })
    ));
    assert!(
        msg.contains("3.2")
            && msg.contains(&format!("{VERSION_MAJOR}.{VERSION_MINOR}"))
            && msg.contains("newer-major.grotto"),
        "{msg}"
    );
}

#[test]
fn bad_content_with_valid_checksums_is_refused_on_read() {
    // Write packages whose content is wrong but whose checksums are right.
    let dir = tempfile::tempdir().unwrap();
    let path = dir.path().join("c.grotto");
    let bad_surfel =
        Surfel { position_tile_m: [f32::NAN, 0.0, 0.0], radius_m: 0.1, normal: [0.0, 0.0, 1.0], spread: 0.0 };
    let bad_node = SvoNode { morton: 0, first_child: 5, child_mask: 1, level: 0, reserved: 0 };
    let mut w = PackageWriter::create(&path).unwrap();
    w.add_tile(TileInfo { origin_m: [0.0; 3], extent_m: 2.0, grid: [0; 3], depth: 1, point_count: 1 })
        .unwrap();
    w.add_elements(SectionKind::Surfels, Scope::Tile(0), 0, &[bad_surfel], Compression::Raw).unwrap();
    w.add_elements(SectionKind::SvoNodes, Scope::Tile(0), 0, &[bad_node], Compression::Zstd(1)).unwrap();
    w.add_elements(SectionKind::LeafOpacity, Scope::Tile(0), 0, &[1.5f32], Compression::Raw).unwrap();
    w.add_section(
        SectionKind::Scene,
        Scope::Global,
        0,
        br#"{"cameras":[{"name":"c","eye_m":[1e999,0,0],"look_at_m":[0,0,0],"fov_y_deg":60}]}"#,
        Compression::Raw,
    )
    .unwrap();
    w.add_section(SectionKind::Provenance, Scope::Global, 0, b"{not json", Compression::Raw).unwrap();
    let pkg = Package::open(w.finish().unwrap()).unwrap();
    let problems = pkg.verify();
    assert_eq!(problems.len(), 5, "{problems:?}");
    assert!(problems.iter().all(|p| matches!(p, Problem::BadContent { .. })), "{problems:?}");
    assert!(pkg.scene().is_err() && pkg.provenance().is_err());
    let t = pkg.tile(0).unwrap();
    assert!(t.read::<Surfel>(SectionKind::Surfels).is_err());
    assert!(t.read::<SvoNode>(SectionKind::SvoNodes).is_err());
}

#[test]
fn writer_refuses_what_the_format_cannot_hold_and_leaves_no_file() {
    let dir = tempfile::tempdir().unwrap();
    let path = dir.path().join("w.grotto");
    let mut w = PackageWriter::create(&path).unwrap();
    assert!(w.add_section(SectionKind::Surfels, Scope::Global, 0, &[], Compression::Raw).is_err());
    assert!(w.add_section(SectionKind::Scene, Scope::Tile(0), 0, b"{}", Compression::Raw).is_err());
    // A tour whose stop names no point of interest would break a viewer's tour mid-way.
    let dangling = Scene {
        tours: vec![Tour {
            name: "t".into(),
            title: String::new(),
            stops: vec![TourStop { poi: Some("gone".into()), ..Default::default() }],
        }],
        ..Scene::default()
    };
    let err = w.add_scene(&dangling).unwrap_err().to_string();
    assert!(err.contains("no point of interest named 'gone'"), "{err}");
    assert!(w.add_section(SectionKind::Surfels, Scope::Tile(3), 0, &[0; 32], Compression::Raw).is_err());
    assert!(
        w.add_tile(TileInfo {
            origin_m: [f64::NAN; 3],
            extent_m: 1.0,
            grid: [0; 3],
            depth: 1,
            point_count: 0
        })
        .is_err()
    );
    w.add_tile(TileInfo { origin_m: [0.0; 3], extent_m: 1.0, grid: [0; 3], depth: 1, point_count: 0 })
        .unwrap();
    assert!(w.add_section(SectionKind::Surfels, Scope::Tile(0), 0, &[0; 33], Compression::Raw).is_err());
    w.add_section(SectionKind::LeafAlbedo, Scope::Tile(0), 0, &[0; 4], Compression::Raw).unwrap();
    let err =
        w.add_section(SectionKind::LeafAlbedo, Scope::Tile(0), 0, &[0; 4], Compression::Raw).unwrap_err();
    assert!(err.to_string().contains("w.grotto"), "{err}");
    // Dropped without finish: no package and no temp file remain.
    drop(w);
    assert_eq!(std::fs::read_dir(dir.path()).unwrap().count(), 0);
}

#[test]
fn an_unfinished_rewrite_keeps_the_previous_package() {
    let dir = tempfile::tempdir().unwrap();
    let path = sample_package(dir.path(), alternating);
    let before = std::fs::read(&path).unwrap();
    let mut w = PackageWriter::create(&path).unwrap();
    w.add_tile(TileInfo { origin_m: [0.0; 3], extent_m: 1.0, grid: [0; 3], depth: 1, point_count: 0 })
        .unwrap();
    w.add_section(SectionKind::LeafAlbedo, Scope::Tile(0), 0, &[1; 4096], Compression::Raw).unwrap();
    // The partial file is beside the target, never at it.
    assert_eq!(std::fs::read(&path).unwrap(), before);
    drop(w);
    assert_eq!(std::fs::read(&path).unwrap(), before);
    assert_eq!(std::fs::read_dir(dir.path()).unwrap().count(), 1);
}

#[test]
fn io_errors_name_the_file() {
    let err = Package::open("/nonexistent/dir/x.grotto").unwrap_err();
    assert!(
        matches!(err, Error::Io { .. }) && err.to_string().contains("/nonexistent/dir/x.grotto"),
        "{err}"
    );
    let err = PackageWriter::create("/nonexistent/dir/x.grotto").unwrap_err();
    assert!(err.to_string().contains("/nonexistent/dir/x.grotto"), "{err}");
    let dir = tempfile::tempdir().unwrap();
    let empty = dir.path().join("empty.grotto");
    std::fs::write(&empty, b"").unwrap();
    assert!(matches!(Package::open(&empty).unwrap_err().problem(), Some(Problem::TooShort { len: 0, .. })));
}

proptest! {
    #![proptest_config(ProptestConfig { cases: 400, failure_persistence: None, ..ProptestConfig::default() })]

    /// Random damage anywhere: open, read every section, verify and summarise; never panic.
    #[test]
    fn random_damage_never_panics(edits in prop::collection::vec((any::<prop::sample::Index>(), any::<u8>()), 1..8),
                                  cut in any::<Option<prop::sample::Index>>(), reseal in any::<bool>()) {
        let bytes = SAMPLE.with(|s| s.clone());
        let mut b = bytes.clone();
        for (at, v) in &edits {
            let i = at.index(b.len());
            b[i] = *v;
        }
        if let Some(c) = cut {
            b.truncate(c.index(b.len()));
        }
        if reseal && b.len() >= 72 {
            // Keep the header checksum valid so damage reaches the deeper checks.
            reseal_header(&mut b);
        }
        if let Ok(pkg) = Package::from_bytes("fuzz.grotto", &b) {
            for s in pkg.sections().collect::<Vec<_>>() {
                let _ = pkg.read_bytes(&s);
            }
            let _ = pkg.verify();
            let _ = pkg.summary();
            let _ = pkg.scene();
            for t in pkg.tiles() {
                let _ = t.read::<SvoNode>(SectionKind::SvoNodes);
                let _ = t.read::<Surfel>(SectionKind::Surfels);
            }
        }
    }
}

thread_local! {
    static SAMPLE: Vec<u8> = sample_bytes();
}
