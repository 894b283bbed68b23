//! Hostile counts and lengths must not make the reader allocate for them: this binary counts every
//! allocation and checks the largest one made while opening and reading damaged packages.

mod common;

use std::alloc::{GlobalAlloc, Layout, System};
use std::sync::atomic::{AtomicUsize, Ordering};

use common::*;
use grotto_format::spec::*;
use grotto_format::*;

struct Largest;

static LARGEST: AtomicUsize = AtomicUsize::new(0);

// SAFETY: forwards to the system allocator unchanged; only records sizes.
#[allow(unsafe_code)]
unsafe impl GlobalAlloc for Largest {
    unsafe fn alloc(&self, layout: Layout) -> *mut u8 {
        LARGEST.fetch_max(layout.size(), Ordering::Relaxed);
        // SAFETY: same contract as the caller's.
        unsafe { System.alloc(layout) }
    }
    unsafe fn dealloc(&self, ptr: *mut u8, layout: Layout) {
        // SAFETY: same contract as the caller's.
        unsafe { System.dealloc(ptr, layout) }
    }
    unsafe fn realloc(&self, ptr: *mut u8, layout: Layout, new_size: usize) -> *mut u8 {
        LARGEST.fetch_max(new_size, Ordering::Relaxed);
        // SAFETY: same contract as the caller's.
        unsafe { System.realloc(ptr, layout, new_size) }
    }
}

#[global_allocator]
static ALLOC: Largest = Largest;

/// Largest single allocation made by `f`.
fn largest_allocation(f: impl FnOnce()) -> usize {
    LARGEST.store(0, Ordering::Relaxed);
    f();
    LARGEST.load(Ordering::Relaxed)
}

#[test]
fn lying_counts_and_lengths_allocate_nothing_big() {
    let dir = tempfile::tempdir().unwrap();
    let bytes = std::fs::read(sample_package(dir.path(), |_, _| Compression::Zstd(3))).unwrap();
    let path = dir.path().join("hostile.grotto");
    let limit = 64 * 1024;

    let mut cases: Vec<Vec<u8>> = Vec::new();
    for (tiles, sections) in
        [(1u64 << 40, None), (u64::MAX, None), (0, Some(1u64 << 40)), (0, Some(u64::MAX / 48))]
    {
        let mut b = bytes.clone();
        let mut h = header(&b);
        h.tile_count = if tiles == 0 { h.tile_count } else { tiles };
        if let Some(s) = sections {
            h.section_count = s;
        }
        b[..72].copy_from_slice(bytemuck::bytes_of(&h));
        reseal_header(&mut b);
        cases.push(b);
    }
    // A zstd section claiming a huge decoded size (refused at open).
    let mut b = bytes.clone();
    patch(&mut b, |_, t, _| t[3].raw_len = 1 << 45);
    cases.push(b);
    // A header_size claiming the whole file.
    let mut b = bytes.clone();
    patch(&mut b, |h, _, _| h.header_size = u32::MAX);
    cases.push(b);

    for (i, case) in cases.iter().enumerate() {
        std::fs::write(&path, case).unwrap();
        let big = largest_allocation(|| {
            let r = Package::open(&path);
            assert!(r.is_err(), "case {i} opened");
        });
        assert!(big < limit, "case {i}: opening allocated {big} bytes");
    }

    // A valid package opens with allocations proportional to its table, not its payload.
    std::fs::write(&path, &bytes).unwrap();
    let big = largest_allocation(|| {
        let pkg = Package::open(&path).unwrap();
        assert!(pkg.tile(0).unwrap().find(SectionKind::Surfels, 0).is_some());
    });
    assert!(big < limit, "open allocated {big} bytes");
}
