//! The allocation rule: nothing a package claims makes the runtime allocate more than a small
//! multiple of the bytes the package holds. This binary counts every allocation and checks the
//! peak of live heap while a package is loaded into its scene (package bytes -> `SceneData`, the
//! step before any GPU upload, whose buffers are sized from it).

use std::alloc::{GlobalAlloc, Layout, System};
use std::path::Path;
use std::sync::Mutex;
use std::sync::atomic::{AtomicUsize, Ordering};

use grotto_format::spec::{Bc6hBlock, EnvMipLevel};
use grotto_format::{Compression, Environment, Package, PackageWriter, Scene, Scope, SectionKind, TileInfo};
use grotto_preprocess::env::{self, LatLong};
use grotto_runtime::scene::data::SceneData;

struct Counting;

static LIVE: AtomicUsize = AtomicUsize::new(0);
static PEAK: AtomicUsize = AtomicUsize::new(0);

// SAFETY: forwards to the system allocator unchanged; only counts bytes.
#[allow(unsafe_code)]
unsafe impl GlobalAlloc for Counting {
    unsafe fn alloc(&self, layout: Layout) -> *mut u8 {
        let live = LIVE.fetch_add(layout.size(), Ordering::Relaxed) + layout.size();
        PEAK.fetch_max(live, Ordering::Relaxed);
        // SAFETY: same layout contract as the caller's.
        unsafe { System.alloc(layout) }
    }
    unsafe fn dealloc(&self, ptr: *mut u8, layout: Layout) {
        LIVE.fetch_sub(layout.size(), Ordering::Relaxed);
        // SAFETY: ptr came from System.alloc with this layout.
        unsafe { System.dealloc(ptr, layout) }
    }
    unsafe fn realloc(&self, ptr: *mut u8, layout: Layout, new_size: usize) -> *mut u8 {
        let live = LIVE.fetch_add(new_size, Ordering::Relaxed) + new_size;
        PEAK.fetch_max(live, Ordering::Relaxed);
        LIVE.fetch_sub(layout.size(), Ordering::Relaxed);
        // SAFETY: as for dealloc and alloc.
        unsafe { System.realloc(ptr, layout, new_size) }
    }
}

#[global_allocator]
static ALLOCATOR: Counting = Counting;

/// Tests in this binary measure one at a time.
static SERIAL: Mutex<()> = Mutex::new(());

/// Most heap the load may hold at once per byte the package holds (its sections decoded), plus
/// a fixed allowance. Where the multiple comes from: a BC6H texel is one stored byte and an RGBA
/// f32 texel (16 bytes) decoded, in an atlas of at most twice the chain's texels
/// (`spec::MAX_ENV_ATLAS_RATIO`); SVO leaves and surfels grow by less (GPU mirrors, rock table).
const BYTES_PER_HELD_BYTE: usize = 32;
const FIXED_ALLOWANCE: usize = 256 << 10;

/// Peak live heap, above what was live before, while `f` runs.
fn peak_heap<T>(f: impl FnOnce() -> T) -> (T, usize) {
    let before = LIVE.load(Ordering::Relaxed);
    PEAK.store(before, Ordering::Relaxed);
    let out = f();
    (out, PEAK.load(Ordering::Relaxed) - before)
}

/// Bytes the package holds: its sections decoded (what `verify` read and checked).
fn held_bytes(pkg: &Package) -> usize {
    pkg.sections().map(|s| s.raw_len as usize).sum()
}

/// `src`'s tiles and sections, plus environment 0 made of `sky` (SH) and `chain`, into `out`.
fn with_environment(src: &Path, out: &Path, chain: &[EnvMipLevel], blocks: &[Bc6hBlock]) -> Package {
    let from = Package::open(src).unwrap();
    let mut w = PackageWriter::create(out).unwrap();
    for t in from.tiles() {
        let info = TileInfo {
            origin_m: t.origin_m(),
            extent_m: t.extent_m(),
            grid: t.grid(),
            depth: t.depth(),
            point_count: t.point_count(),
        };
        let index = w.add_tile(info).unwrap();
        for s in t.sections() {
            w.copy_section(&from, &s, Scope::Tile(index)).unwrap();
        }
    }
    let mut scene: Scene = from.scene().unwrap();
    scene.environment = Some(Environment { index: 0, intensity: 1.0, source: "test sky".into() });
    w.add_scene(&scene).unwrap();
    let sky = LatLong { width: 64, height: 32, rgb: vec![[0.5, 0.6, 0.9]; 64 * 32] };
    let sh = sky.project_sh9();
    w.add_elements(SectionKind::EnvSh9, Scope::Global, 0, &[sh], Compression::Raw).unwrap();
    w.add_elements(SectionKind::EnvMipLevels, Scope::Global, 0, chain, Compression::Raw).unwrap();
    w.add_elements(SectionKind::EnvMipBc6h, Scope::Global, 0, blocks, Compression::Zstd(3)).unwrap();
    w.finish().unwrap();
    Package::open(out).unwrap()
}

fn small_cave(dir: &Path, points: u64, segments: usize) -> std::path::PathBuf {
    let cave = grotto_fixtures::SmallCave { points, segments, ..Default::default() };
    grotto_fixtures::small_cave_package(dir, &cave).unwrap()
}

#[test]
fn loading_a_package_allocates_a_bounded_multiple_of_what_it_holds() {
    let dir = tempfile::tempdir().unwrap();
    let cave = small_cave(&dir.path().join("cave"), 20_000, 3);
    let tiny = small_cave(&dir.path().join("tiny"), 1_500, 1);
    // The chain preprocess writes for a sky (256 wide, 6 levels): the densest part to decode.
    let sky = LatLong { width: 256, height: 128, rgb: vec![[2.0, 1.5, 1.0]; 256 * 128] };
    let (levels, blocks) = env::encode_chain(&env::prefilter(&sky, 256, 6, 16));
    let (small_levels, small_blocks) = env::encode_chain(&env::prefilter(&sky, 32, 3, 16));
    let _serial = SERIAL.lock().unwrap_or_else(|e| e.into_inner());
    let cases = [
        ("cave", Package::open(&cave).unwrap()),
        ("cave under a sky", with_environment(&cave, &dir.path().join("sky.grotto"), &levels, &blocks)),
        ("tiny cave", Package::open(&tiny).unwrap()),
        (
            "tiny cave under a sky",
            with_environment(&tiny, &dir.path().join("tiny-sky.grotto"), &small_levels, &small_blocks),
        ),
    ];
    // `GROTTO_FUZZ_SEEDS=DIR` keeps the tiny packages as seeds for the load_scene fuzz target
    // (docs/fuzzing.md).
    if let Some(seeds) = std::env::var_os("GROTTO_FUZZ_SEEDS") {
        std::fs::create_dir_all(&seeds).unwrap();
        for (name, pkg) in cases.iter().filter(|(name, _)| name.starts_with("tiny")) {
            std::fs::copy(pkg.path(), Path::new(&seeds).join(format!("{}.grotto", name.replace(' ', "-"))))
                .unwrap();
        }
    }
    for (name, pkg) in cases {
        let held = held_bytes(&pkg);
        let (scene, peak) = peak_heap(|| SceneData::from_package(&pkg).unwrap());
        let limit = BYTES_PER_HELD_BYTE * held + FIXED_ALLOWANCE;
        eprintln!(
            "{name}: holds {held} bytes, loading peaked at {peak} bytes ({:.1} per held byte)",
            peak as f64 / held as f64
        );
        assert!(peak <= limit, "{name}: loading peaked at {peak} bytes for {held} held (limit {limit})");
        assert!(!scene.leaves.is_empty());
        assert_eq!(scene.env_chain.is_some(), name.contains("sky"));
    }
}

#[test]
fn a_chain_claiming_a_huge_atlas_is_refused_before_anything_is_sized_from_it() {
    let dir = tempfile::tempdir().unwrap();
    let cave = small_cave(dir.path(), 20_000, 3);
    // The package: valid section by section, an 8192-wide base and seven levels of
    // 4x4096 (147 KiB of blocks) that a reader stacking them as wide as the base would decode
    // into a 3.8 GB atlas.
    let levels = grotto_format::level_table(
        [(8192u32, 4u32)]
            .into_iter()
            .chain([(4, 4096); 7])
            .enumerate()
            .map(|(k, (w, h))| (w, h, k as f32 / 7.0)),
    );
    let blocks = vec![Bc6hBlock([0; 16]); levels.iter().map(|l| l.block_count as usize).sum()];
    let _serial = SERIAL.lock().unwrap_or_else(|e| e.into_inner());
    let pkg = with_environment(&cave, &dir.path().join("hostile.grotto"), &levels, &blocks);
    let held = held_bytes(&pkg);
    let (result, peak) = peak_heap(|| SceneData::from_package(&pkg));
    let limit = BYTES_PER_HELD_BYTE * held + FIXED_ALLOWANCE;
    assert!(peak <= limit, "loading it peaked at {peak} bytes for {held} held (limit {limit})");
    let Err(err) = result else { panic!("the hostile chain loaded") };
    let err = err.to_string();
    assert!(err.contains("hostile.grotto") && err.contains("larger than level 0"), "{err}");
    // `grotto verify` reports the same problem.
    assert!(pkg.verify().iter().any(|p| p.to_string().contains("larger than level 0")));
}
