//! A package read by byte ranges, as a browser reads one over HTTP: the head, then the directory,
//! then the sections a view needs. It validates as a whole file does, reads the same content,
//! names what has not arrived, and refuses fetched bytes that are damaged or misplaced.

mod common;

use common::*;
use grotto_format::*;

fn sample_bytes() -> Vec<u8> {
    let dir = tempfile::tempdir().unwrap();
    std::fs::read(sample_package(dir.path(), alternating)).unwrap()
}

/// The package as a reader over HTTP first sees it: two requests, head then directory.
/// Also the byte range of the second request.
fn directory_only(bytes: &[u8]) -> (Package, std::ops::Range<u64>) {
    let len = bytes.len() as u64;
    let head = &bytes[..(Package::HEAD_BYTES.min(len)) as usize];
    let dir = Package::directory_range("r.grotto", head, len).unwrap();
    let pkg = Package::from_directory(
        "r.grotto",
        len,
        head,
        dir.start,
        &bytes[dir.start as usize..dir.end as usize],
    )
    .unwrap();
    (pkg, dir)
}

#[test]
fn sections_fetched_by_range_read_as_from_the_whole_file() {
    let bytes = sample_bytes();
    let whole = Package::from_bytes("w.grotto", &bytes).unwrap();
    let (mut ranged, dir) = directory_only(&bytes);
    assert_eq!(ranged.tile_count(), whole.tile_count());
    assert_eq!(ranged.sections().collect::<Vec<_>>(), whole.sections().collect::<Vec<_>>());
    // Opening fetched the directory and no section with it, and holds no section bytes.
    for s in whole.sections().filter(|s| s.stored_len > 0) {
        assert!(
            s.offset + s.stored_len <= dir.start || s.offset >= dir.end,
            "section {} in {dir:?}",
            s.index
        );
    }
    assert_eq!(ranged.held_bytes(), 0);

    // Before its bytes arrive, a section is named as not fetched (not as damaged).
    let s = whole.sections().find(|s| s.stored_len > 0).unwrap();
    match ranged.read_bytes(&s) {
        Err(Error::NotFetched { section, offset, len, .. }) => {
            assert_eq!((section, offset, len), (s.index, s.offset, s.stored_len));
        }
        other => panic!("expected NotFetched, got {other:?}"),
    }

    // One tile's sections: the ranges to fetch are 64-aligned and cover exactly what is missing.
    let tile0: Vec<SectionInfo> = ranged.tile(0).unwrap().sections().collect();
    let ranges = ranged.missing(tile0.iter().copied(), 0);
    assert!(!ranges.is_empty());
    for r in &ranges {
        assert_eq!(r.start % 64, 0);
        ranged.insert(r.start, &bytes[r.start as usize..r.end as usize]).unwrap();
    }
    assert!(ranged.missing(tile0.iter().copied(), 0).is_empty());
    for s in &tile0 {
        assert_eq!(ranged.read_bytes(s).unwrap(), whole.read_bytes(s).unwrap(), "section {}", s.index);
    }
    // The other tiles are still missing; the scene and every other section arrive in one request
    // when gaps of any size may be merged.
    let all = ranged.missing(ranged.sections(), u64::MAX);
    assert_eq!(all.len(), 1, "{all:?}");
    let r = &all[0];
    ranged.insert(r.start, &bytes[r.start as usize..r.end as usize]).unwrap();
    assert!(ranged.missing(ranged.sections(), 0).is_empty());
    assert_eq!(ranged.scene().unwrap(), whole.scene().unwrap());
    assert!(ranged.verify().is_empty(), "{:?}", ranged.verify());
}

#[test]
fn nearby_ranges_merge_within_the_gap_and_not_beyond() {
    let bytes = sample_bytes();
    let (ranged, _) = directory_only(&bytes);
    let sections: Vec<SectionInfo> = ranged.sections().filter(|s| s.stored_len > 0).collect();
    let apart = ranged.missing(sections.iter().copied(), 0);
    let merged = ranged.missing(sections.iter().copied(), 1 << 20);
    assert!(apart.len() > 1 && merged.len() == 1, "{} and {} ranges", apart.len(), merged.len());
    // Merging never asks for less than each section.
    for s in &sections {
        assert!(merged.iter().any(|r| r.start <= s.offset && s.offset + s.stored_len <= r.end));
        assert!(apart.iter().any(|r| r.start <= s.offset && s.offset + s.stored_len <= r.end));
    }
}

#[test]
fn damaged_or_misplaced_fetches_are_refused() {
    let bytes = sample_bytes();
    let len = bytes.len() as u64;
    let (mut ranged, _) = directory_only(&bytes);
    let s = ranged.sections().find(|s| s.stored_len > 8).unwrap();
    // A flipped byte in what arrived is a checksum error naming the section, as in a file.
    let mut bad = bytes[s.offset as usize..(s.offset + s.stored_len) as usize].to_vec();
    bad[3] ^= 0x40;
    ranged.insert(s.offset, &bad).unwrap();
    match ranged.read_bytes(&s) {
        Err(Error::Invalid { problem: Problem::SectionChecksum { section, .. }, .. }) => {
            assert_eq!(section, s.index)
        }
        other => panic!("expected a checksum error, got {other:?}"),
    }
    // Misaligned or past the end of the file: refused, nothing stored.
    let held = ranged.held_bytes();
    assert!(ranged.insert(s.offset + 1, &bytes[..10]).is_err());
    assert!(ranged.insert(len - len % 64, &[0u8; 128]).is_err());
    assert_eq!(ranged.held_bytes(), held);

    // A directory that does not cover the table, or a head from another file, is refused.
    let head = &bytes[..(Package::HEAD_BYTES.min(len)) as usize];
    let dir = Package::directory_range("r.grotto", head, len).unwrap();
    let short = &bytes[dir.start as usize..(dir.end - 8) as usize];
    assert!(matches!(
        Package::from_directory("r.grotto", len, head, dir.start, short),
        Err(Error::Invalid { problem: Problem::OutOfBounds { .. }, .. })
    ));
    assert!(matches!(
        Package::directory_range("r.grotto", head, len + 64),
        Err(Error::Invalid { problem: Problem::Truncated { .. }, .. })
    ));
    assert!(matches!(
        Package::directory_range("r.grotto", &head[..40], len),
        Err(Error::Invalid { problem: Problem::TooShort { .. }, .. })
    ));
}

#[test]
fn fetched_bytes_outside_what_is_kept_are_let_go_and_checked_again_when_fetched_again() {
    let bytes = sample_bytes();
    let whole = Package::from_bytes("w.grotto", &bytes).unwrap();
    let (mut ranged, _) = directory_only(&bytes);
    let all = ranged.missing(ranged.sections(), 0);
    for r in &all {
        ranged.insert(r.start, &bytes[r.start as usize..r.end as usize]).unwrap();
    }
    let held = ranged.held_bytes();
    let tile0: Vec<SectionInfo> = ranged.tile(0).unwrap().sections().filter(|s| s.stored_len > 0).collect();
    let others: Vec<SectionInfo> =
        ranged.sections().filter(|s| s.stored_len > 0 && !tile0.iter().any(|t| t.index == s.index)).collect();
    assert!(!tile0.is_empty() && !others.is_empty());
    for s in others.iter().chain(&tile0) {
        ranged.check(s).unwrap();
    }

    // Keeping tile 0: its sections stay readable, every other piece is let go.
    let released = ranged.release_fetched(tile0.iter().copied());
    assert!(released > 0);
    assert_eq!(ranged.held_bytes(), held - released);
    assert!(ranged.missing(tile0.iter().copied(), 0).is_empty());
    for s in &tile0 {
        assert_eq!(ranged.read_bytes(s).unwrap(), whole.read_bytes(s).unwrap());
    }
    let gone = ranged.missing(others.iter().copied(), 0);
    assert!(!gone.is_empty());
    match ranged.read_bytes(&others[0]) {
        Err(Error::NotFetched { section, .. }) => assert_eq!(section, others[0].index),
        other => panic!("expected NotFetched, got {other:?}"),
    }
    // Fetched again damaged, a section let go is checked again rather than trusted.
    let s = others.iter().find(|s| s.stored_len > 8).unwrap();
    let mut bad = bytes[s.offset as usize..(s.offset + s.stored_len) as usize].to_vec();
    bad[3] ^= 0x40;
    ranged.insert(s.offset, &bad).unwrap();
    assert!(ranged.read_bytes(s).is_err(), "a damaged refetch of section {} was trusted", s.index);

    // Keeping nothing lets go of everything; a whole file lets go of nothing.
    ranged.release_fetched(std::iter::empty());
    assert_eq!(ranged.held_bytes(), 0);
    let mut copy = Package::from_bytes("copy.grotto", &bytes).unwrap();
    assert_eq!(copy.release_fetched(std::iter::empty()), 0);
    assert_eq!(copy.held_bytes(), bytes.len() as u64);
}

/// The resident bytes of this process's maps of `path` (Linux's `/proc/self/smaps`).
#[cfg(target_os = "linux")]
fn resident_bytes_of_map(path: &std::path::Path) -> u64 {
    let smaps = std::fs::read_to_string("/proc/self/smaps").unwrap();
    let name = path.canonicalize().unwrap();
    let mut ours = false;
    let mut kb = 0;
    for line in smaps.lines() {
        let first = line.split_whitespace().next().unwrap_or("");
        if first.contains('-') && first.chars().all(|c| c.is_ascii_hexdigit() || c == '-') {
            ours = line.trim_end().ends_with(name.to_str().unwrap());
        } else if ours && let Some(v) = line.strip_prefix("Rss:") {
            kb += v.trim().trim_end_matches("kB").trim().parse::<u64>().unwrap();
        }
    }
    kb * 1024
}

#[cfg(target_os = "linux")]
#[test]
fn a_mapped_package_hands_its_pages_back_and_reads_the_same_after() {
    let dir = tempfile::tempdir().unwrap();
    let path = sample_package(dir.path(), alternating);
    let bytes = std::fs::read(&path).unwrap();
    let pkg = Package::open(&path).unwrap();
    let sections: Vec<SectionInfo> = pkg.sections().filter(|s| s.stored_len > 0).collect();
    let before: Vec<Vec<u8>> = sections.iter().map(|s| pkg.read_bytes(s).unwrap().to_vec()).collect();
    assert!(resident_bytes_of_map(&path) > 0, "reading every section touched no page of the map");

    assert!(pkg.release_mapped());
    assert_eq!(resident_bytes_of_map(&path), 0, "the map's pages still count as resident");
    for (s, was) in sections.iter().zip(&before) {
        assert_eq!(&pkg.read_bytes(s).unwrap()[..], &was[..], "section {} reads otherwise", s.index);
    }
    // A copy holds its bytes: nothing to hand back.
    assert!(!Package::from_bytes("copy.grotto", &bytes).unwrap().release_mapped());
}
