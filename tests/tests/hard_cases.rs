//! Hard cases of the build, each with the bound it must keep: tile seams, survey-sized
//! coordinates, degenerate neighbourhoods, NaN input, one-point and empty inputs.

use std::collections::HashMap;
use std::path::{Path, PathBuf};

use grotto_format::Package;
use grotto_format::spec::Surfel;
use grotto_preprocess::build::{self, BuildParams, BuildSummary, SurfelCodec};
use grotto_preprocess::ingest::ScanFormat;
use grotto_preprocess::manifest::Manifest;
use grotto_preprocess::scanwrite::{ScanData, write_scan};
use grotto_preprocess::synth::{self, SynthParams};
use grotto_tests::small_build;

fn build_into(manifest: &Manifest, dir: &Path, name: &str, p: &BuildParams) -> (Package, BuildSummary) {
    let out = dir.join(name);
    let summary = build::build(manifest, Path::new("test.toml"), &out, p, &|_| {}).unwrap();
    let pkg = Package::open(&out).unwrap();
    assert!(pkg.verify().is_empty(), "{name}: {:?}", pkg.verify());
    (pkg, summary)
}

/// World voxel index -> (opacity, albedo, NDF mean) over all tiles.
fn voxels(pkg: &Package) -> HashMap<[i64; 3], (f32, [u8; 4], [f32; 3])> {
    let mut out = HashMap::new();
    for t in pkg.tiles() {
        let svo = t.svo().unwrap().unwrap();
        let leaf = t.leaf_size_m();
        let o = t.origin_m();
        for (li, n) in svo.nodes.iter().filter(|n| u32::from(n.level) == t.depth()).enumerate() {
            let c = grotto_format::svo::morton_decode(n.morton);
            let key: [i64; 3] = std::array::from_fn(|a| ((o[a] / leaf).round() as i64) + i64::from(c[a]));
            out.insert(key, (svo.opacity[li], svo.albedo[li].0, svo.ndf[li].mean));
        }
    }
    out
}

#[test]
fn tiles_meet_without_seams() {
    let dir = tempfile::tempdir().unwrap();
    let sp = SynthParams { points: 40_000, segments: 4, ..SynthParams::default() };
    let s = synth::write_dataset(&dir.path().join("scans"), &sp, &[ScanFormat::Ply], &|_, _| {}).unwrap();
    let manifest = Manifest::load(Path::new(&s.manifest)).unwrap();
    // This sparse scan (40k points) needs 2 m of halo for every 16-neighbourhood near a border;
    // the build reports points whose neighbourhood reaches past the halo, and there are none.
    let (small, small_summary) = build_into(
        &manifest,
        dir.path(),
        "small.grotto",
        &BuildParams { halo_m: 2.0, ..small_build(&dir.path().join("w1"), 4.0, 4.0, 0.5) },
    );
    assert_eq!(small_summary.seam_limited_points, 0);
    let (big, big_summary) = build_into(
        &manifest,
        dir.path(),
        "big.grotto",
        &small_build(&dir.path().join("w2"), 64.0, 64.0, 0.5),
    );
    assert!(
        small_summary.tiles > 8 && big_summary.tiles <= 2,
        "{} vs {}",
        small_summary.tiles,
        big_summary.tiles
    );
    let (a, b) = (voxels(&small), voxels(&big));
    assert_eq!(a.len(), b.len(), "same voxels");
    let mut worst_ndf = 0f32;
    let mut differing = 0;
    for (k, va) in &a {
        let vb = b.get(k).expect("voxel present in both");
        if (va.0 - vb.0).abs() > 1e-4 || va.1 != vb.1 {
            differing += 1;
        }
        for i in 0..3 {
            worst_ndf = worst_ndf.max((va.2[i] - vb.2[i]).abs());
        }
    }
    // Opacity and albedo are sums over the same points; normals see across borders via the halo.
    assert_eq!(differing, 0);
    assert!(worst_ndf < 1e-5, "NDF differs by {worst_ndf} across the seam");
    // With a halo too small for the sparse parts, the build says so.
    let (_, limited) = build_into(
        &manifest,
        dir.path(),
        "thin.grotto",
        &BuildParams { halo_m: 0.125, ..small_build(&dir.path().join("w3"), 4.0, 4.0, 0.5) },
    );
    assert!(limited.seam_limited_points > 0);
}

fn write_ply(path: &Path, pts: &[[f64; 3]]) -> PathBuf {
    let rgb = vec![[120u8, 110, 100]; pts.len()];
    write_scan(
        path,
        ScanFormat::Ply,
        &ScanData { xyz: pts, rgb: &rgb, intensity: &[], normals: &[], pose: None },
    )
    .unwrap();
    path.to_path_buf()
}

fn surfels(pkg: &Package) -> Vec<(usize, Surfel, [f64; 3])> {
    let mut out = Vec::new();
    for t in pkg.tiles() {
        let o = t.origin_m();
        for s in t.surfels().unwrap().unwrap().iter() {
            out.push((
                t.index() as usize,
                *s,
                std::array::from_fn(|a| o[a] + f64::from(s.position_tile_m[a])),
            ));
        }
    }
    out
}

#[test]
fn survey_coordinates_give_the_same_normals() {
    let dir = tempfile::tempdir().unwrap();
    let sp = SynthParams { points: 20_000, segments: 3, offset_m: [0.0; 3], ..SynthParams::default() };
    let s =
        synth::write_dataset(&dir.path().join("scans"), &sp, &[ScanFormat::Las, ScanFormat::Ply], &|_, _| {})
            .unwrap();
    let at_origin = Manifest::load(Path::new(&s.manifest)).unwrap();
    let mut shifted = at_origin.clone();
    for scan in &mut shifted.scans {
        let t = scan.translation.as_mut().unwrap();
        t[0] += 500_000.0;
        t[1] += 5_000_000.0;
        t[2] += 1000.0;
    }
    // The build's own numbers: full-precision surfels, since the compact ones round each normal
    // to its nearest code (within 0.05 degrees), so two builds that agree to 1e-6 can still differ
    // by a code.
    let full = |work: &str| BuildParams {
        surfels: SurfelCodec::Full,
        ..small_build(&dir.path().join(work), 2.0, 16.0, 0.5)
    };
    let (a, _) = build_into(&at_origin, dir.path(), "a.grotto", &full("w1"));
    let (b, _) = build_into(&shifted, dir.path(), "b.grotto", &full("w2"));
    // Match surfels by position: the quantisation of a point within f64 rounding (~1e-10 m at
    // 5e6 m) of a quantum boundary can differ by one quantum, which may reorder it.
    let key = |w: [f64; 3], shift: [f64; 3]| -> [i64; 3] {
        std::array::from_fn(|i| ((w[i] - shift[i]) * 1e3).round() as i64)
    };
    let shift = [500_000.0, 5_000_000.0, 1000.0];
    let by_pos: HashMap<[i64; 3], [f32; 3]> =
        surfels(&a).into_iter().map(|(_, s, w)| (key(w, [0.0; 3]), s.normal)).collect();
    let sb = surfels(&b);
    let mut worst = 0f64;
    let mut unmatched = 0;
    for (_, s, w) in &sb {
        let Some(n) = by_pos.get(&key(*w, shift)) else {
            unmatched += 1;
            continue;
        };
        let dot: f64 = (0..3).map(|i| f64::from(n[i]) * f64::from(s.normal[i])).sum();
        worst = worst.max(dot.clamp(-1.0, 1.0).acos());
    }
    assert!(unmatched <= sb.len() / 5000, "{unmatched} of {} surfels moved", sb.len());
    assert!(worst < 1e-3, "normals differ by {worst} rad");
}

#[test]
fn degenerate_inputs_build_valid_packages_without_nan() {
    let dir = tempfile::tempdir().unwrap();
    let d = dir.path();
    // Exact duplicates, a collinear run, a perfect plane, two lone points far from everything,
    // and a NaN point: all in one scan.
    let mut pts = vec![[1.0, 1.0, 1.0]; 30];
    pts.extend((0..30).map(|i| [3.0 + f64::from(i) * 0.01, 3.0, 3.0]));
    pts.extend((0..100).map(|i| [5.0 + f64::from(i % 10) * 0.02, 5.0 + f64::from(i / 10) * 0.02, 5.0]));
    pts.push([9.5, 9.5, 9.5]);
    pts.push([20.5, 0.5, 0.5]);
    pts.push([f64::NAN, 0.0, 0.0]);
    pts.push([0.0, f64::INFINITY, 0.0]);
    let scan = write_ply(&d.join("degenerate.ply"), &pts);
    // The scanner at the scan origin (a bare file would be a merged cloud without one).
    let mut manifest = Manifest::from_files(&[scan]);
    manifest.scans[0].origin = Some([0.0; 3]);
    let (pkg, summary) =
        build_into(&manifest, d, "degenerate.grotto", &small_build(&d.join("w"), 1.0, 16.0, 0.5));
    assert_eq!(summary.invalid_points, 2);
    assert_eq!(summary.points, pts.len() as u64 - 2);
    let all = surfels(&pkg);
    assert_eq!(all.len() as u64, summary.points);
    for (_, s, _) in &all {
        let len: f32 = s.normal.iter().map(|c| c * c).sum::<f32>().sqrt();
        assert!((len - 1.0).abs() < 1e-4 && s.radius_m.is_finite() && s.spread.is_finite(), "{s:?}");
    }
    // The plane's interior normals are exactly +-z; the lone points' are toward the scanner
    // (at the scan origin, identity pose).
    // The package's surfels are compact: positions within 1 mm, normals within 0.05 degrees
    // (8.7e-4 rad; the octahedral codes hold +-z exactly).
    let plane = all.iter().find(|(_, _, w)| (w[0] - 5.1).abs() < 1e-3 && (w[1] - 5.1).abs() < 1e-3).unwrap();
    assert!((plane.1.normal[2].abs() - 1.0).abs() < 1e-6);
    let lone = all.iter().find(|(_, _, w)| (w[0] - 20.5).abs() < 1e-3).unwrap();
    let toward = [-20.5f32, -0.5, -0.5];
    let l = toward.iter().map(|c| c * c).sum::<f32>().sqrt();
    for (got, want) in lone.1.normal.iter().zip(toward) {
        assert!((got - want / l).abs() < 9e-4, "{:?}", lone.1.normal);
    }
    for t in pkg.tiles() {
        let svo = t.svo().unwrap().unwrap();
        assert!(svo.ndf.iter().all(|n| n.mean.iter().all(|c| c.is_finite())));
    }

    // One point alone.
    let one = write_ply(&d.join("one.ply"), &[[512_000.25, 5_123_000.5, 300.75]]);
    let (pkg, summary) = build_into(
        &Manifest::from_files(&[one]),
        d,
        "one.grotto",
        &small_build(&d.join("w1"), 1.0, 16.0, 0.5),
    );
    assert_eq!((summary.tiles, summary.points), (1, 1));
    assert_eq!(pkg.tile(0).unwrap().svo().unwrap().unwrap().leaf_count(), 1);

    // No points at all: a valid package with no tiles.
    let empty = write_ply(&d.join("empty.ply"), &[]);
    let (pkg, summary) = build_into(
        &Manifest::from_files(&[empty]),
        d,
        "empty.grotto",
        &small_build(&d.join("w2"), 1.0, 16.0, 0.5),
    );
    assert_eq!((summary.tiles, pkg.tile_count()), (0, 0));
}

#[test]
fn a_las_file_cut_inside_its_last_record_keeps_its_complete_records() {
    // A copy that stopped a few bytes short: the complete records are read and the summary says
    // what was dropped; --strict refuses the file; a file missing whole records (or a header
    // that lies about its count) is refused either way.
    let dir = tempfile::tempdir().unwrap();
    let d = dir.path();
    let pts: Vec<[f64; 3]> =
        (0..400).map(|i| [f64::from(i % 20) * 0.05, f64::from(i / 20) * 0.05, 1.0]).collect();
    let rgb = vec![[90u8, 80, 70]; pts.len()];
    let whole = d.join("whole.las");
    write_scan(
        &whole,
        ScanFormat::Las,
        &ScanData { xyz: &pts, rgb: &rgb, intensity: &[], normals: &[], pose: None },
    )
    .unwrap();
    let bytes = std::fs::read(&whole).unwrap();
    let cut = d.join("cut.las");
    std::fs::write(&cut, &bytes[..bytes.len() - 5]).unwrap();
    let built = build_into(
        &Manifest::from_files(std::slice::from_ref(&cut)),
        d,
        "cut.grotto",
        &small_build(&d.join("w1"), 1.0, 16.0, 0.5),
    )
    .1;
    assert_eq!(built.points, 399, "every complete record");
    assert_eq!(built.cut_short.len(), 1, "{:?}", built.cut_short);
    assert!(built.cut_short[0].contains("cut.las") && built.cut_short[0].contains("1 points dropped"));
    assert!(built.hints().iter().any(|h| h.contains("--strict")), "{:?}", built.hints());

    let strict = BuildParams { strict: true, ..small_build(&d.join("w2"), 1.0, 16.0, 0.5) };
    let err = build::build(
        &Manifest::from_files(&[cut]),
        Path::new("t.toml"),
        &d.join("s.grotto"),
        &strict,
        &|_| {},
    )
    .unwrap_err()
    .to_string();
    assert!(err.contains("cut.las") && err.contains("last point record"), "{err}");
    assert!(!d.join("s.grotto").exists());

    // Whole records missing (the file stops at a record boundary, or several records short).
    // Point data offset (u32 at byte 96) and record length (u16 at byte 105) of the LAS header.
    let offset = u32::from_le_bytes(bytes[96..100].try_into().unwrap()) as usize;
    let record = usize::from(u16::from_le_bytes(bytes[105..107].try_into().unwrap()));
    assert_eq!(offset + 400 * record, bytes.len(), "a LAS file without EVLRs");
    for (name, len) in [("boundary.las", bytes.len() - record), ("short.las", bytes.len() - 3 * record - 5)] {
        let p = d.join(name);
        std::fs::write(&p, &bytes[..len]).unwrap();
        let err = build::build(
            &Manifest::from_files(&[p]),
            Path::new("t.toml"),
            &d.join("x.grotto"),
            &small_build(&d.join("w3"), 1.0, 16.0, 0.5),
            &|_| {},
        )
        .unwrap_err()
        .to_string();
        assert!(err.contains(name) && err.contains("header claims 400 points"), "{name}: {err}");
    }
}
