//! The synthetic cave end to end: synth writes LAS, LAZ, PLY and E57 scans and a manifest; build
//! merges them into a package whose surfels lie on the analytic wall with normals that agree with
//! it (oriented into the open cave).

use grotto_format::{Package, SectionKind};
use grotto_preprocess::build::{self, BuildParams};
use grotto_preprocess::ingest::ScanFormat;
use grotto_preprocess::manifest::Manifest;
use grotto_preprocess::synth::{self, SynthCave, SynthParams};

#[test]
fn synthetic_cave_builds_with_accurate_oriented_normals() {
    let dir = tempfile::tempdir().unwrap();
    let params = SynthParams { points: 60_000, segments: 8, ..SynthParams::default() };
    let formats = [ScanFormat::Las, ScanFormat::Laz, ScanFormat::Ply, ScanFormat::E57];
    let summary = synth::write_dataset(&dir.path().join("scans"), &params, &formats, &|_, _| {}).unwrap();
    assert!(summary.scans >= 4, "every format is used");
    let manifest_path = std::path::PathBuf::from(&summary.manifest);
    // An environment map, when the shared data is there.
    let env_map = grotto_tests::shared_data_dir().map(|d| d.join("envmaps/probulator_pisa.hdr"));
    if let Some(map) = &env_map {
        let mut text = std::fs::read_to_string(&manifest_path).unwrap();
        text += &format!("[environment]\nmap = \"{}\"\nintensity = 1.5\n", map.display());
        std::fs::write(&manifest_path, text).unwrap();
    }
    let manifest = Manifest::load(&manifest_path).unwrap();
    let scans = manifest.resolve().unwrap();
    // E57 poses come from the files; the others from the manifest.
    for s in &scans {
        assert_eq!(s.pose_from_file, s.format == ScanFormat::E57);
    }
    let out = dir.path().join("cave.grotto");
    let bp = grotto_tests::small_build(&dir.path().join("work"), 2.0, 32.0, 0.25);
    let built = build::build(&manifest, &manifest_path, &out, &bp, &|_| {}).unwrap();
    assert_eq!(built.points, summary.points);
    assert!(built.tiles > 1);

    let pkg = Package::open(&out).unwrap();
    assert!(pkg.verify().is_empty());
    if env_map.is_some() {
        use grotto_format::Scope;
        use grotto_format::spec::{EnvMipLevel, ShRgb9};
        let sh = pkg.read::<ShRgb9>(&pkg.find(SectionKind::EnvSh9, Scope::Global, 0).unwrap()).unwrap();
        assert!(sh[0].coeffs[0].iter().all(|c| *c > 0.0));
        let levels =
            pkg.read::<EnvMipLevel>(&pkg.find(SectionKind::EnvMipLevels, Scope::Global, 0).unwrap()).unwrap();
        assert_eq!((levels.len(), levels[0].width, levels[5].roughness), (6, 256, 1.0));
        let env = pkg.scene().unwrap().environment.unwrap();
        assert_eq!((env.index, env.intensity), (0, 1.5));
    }
    for t in pkg.tiles() {
        let svo = t.svo().unwrap().unwrap();
        assert!(svo.leaf_count() > 0 && svo.emission.is_none());
    }
    let cave = SynthCave::new(&params);
    // Normal errors against the analytic wall: (angles, flipped, off the wall).
    let normal_errors = |pkg: &Package| {
        let (mut flipped, mut errors, mut off_wall) = (0usize, Vec::new(), 0usize);
        for tile in pkg.tiles() {
            let o = tile.origin_m();
            for s in tile.surfels().unwrap().unwrap().iter() {
                let local: [f64; 3] =
                    std::array::from_fn(|a| o[a] + f64::from(s.position_tile_m[a]) - params.offset_m[a]);
                if cave.eval(local).abs() > 0.03 {
                    off_wall += 1;
                }
                let truth = cave.normal(local);
                let dot: f64 = (0..3).map(|a| truth[a] * f64::from(s.normal[a])).sum();
                if dot < 0.0 {
                    flipped += 1;
                }
                errors.push(dot.abs().min(1.0).acos());
            }
        }
        errors.sort_by(f64::total_cmp);
        (errors, flipped, off_wall)
    };
    let (errors, flipped, off_wall) = normal_errors(&pkg);
    let n = errors.len();
    assert_eq!(n as u64, summary.points);
    let mean = errors.iter().sum::<f64>() / n as f64;
    let p95 = errors[n * 95 / 100];
    let flipped_share = flipped as f64 / n as f64;
    eprintln!(
        "normals: mean {:.2} deg, p95 {:.2} deg, flipped {:.3}%, off-wall {off_wall}",
        mean.to_degrees(),
        p95.to_degrees(),
        flipped_share * 100.0
    );
    assert!(off_wall as f64 / (n as f64) < 0.001, "surfels must lie on the wall: {off_wall}");
    assert!(mean.to_degrees() < 4.0 && p95.to_degrees() < 15.0, "mean {mean}, p95 {p95}");
    assert!(flipped_share < 0.005, "wrongly oriented: {flipped_share}");

    // The same build with full-precision surfels (format 1.2): the compact package's surfels are
    // the same ones, each within 1 mm and a twentieth of a degree, their normals as accurate
    // against the wall within 0.1 degree on mean, and the package is smaller.
    assert_eq!(pkg.version(), (2, 0));
    let full_out = dir.path().join("cave-full.grotto");
    let full_params = BuildParams { surfels: build::SurfelCodec::Full, ..bp };
    build::build(&manifest, &manifest_path, &full_out, &full_params, &|_| {}).unwrap();
    let full = Package::open(&full_out).unwrap();
    assert_eq!(full.version(), (1, 2));
    let (full_errors, _, _) = normal_errors(&full);
    let full_mean = full_errors.iter().sum::<f64>() / n as f64;
    eprintln!(
        "normals, full precision: mean {:.4} deg, compact {:.4} deg",
        full_mean.to_degrees(),
        mean.to_degrees()
    );
    assert!((mean - full_mean).to_degrees().abs() <= 0.1);
    for (a, b) in full.tiles().zip(pkg.tiles()) {
        let (a, b) = (a.surfels().unwrap().unwrap(), b.surfels().unwrap().unwrap());
        assert_eq!(a.len(), b.len());
        for (x, y) in a.iter().zip(b.iter()) {
            let moved =
                (0..3).map(|i| (x.position_tile_m[i] - y.position_tile_m[i]).powi(2)).sum::<f32>().sqrt();
            let cos: f32 = (0..3).map(|i| x.normal[i] * y.normal[i]).sum();
            assert!(moved <= 0.001 + 1e-5 && cos >= 0.05f32.to_radians().cos(), "{x:?} -> {y:?}");
        }
    }
    let (full_bytes, bytes) =
        (std::fs::metadata(&full_out).unwrap().len(), std::fs::metadata(&out).unwrap().len());
    assert!(bytes < full_bytes * 2 / 3, "compact {bytes} B, full {full_bytes} B");
    // bench-encoding measures the same on the full package.
    let enc = grotto_preprocess::bench::encoding(&full_out).unwrap();
    assert_eq!(enc.points, summary.points);
    assert_eq!(enc.full_precision_tiles, 0);
    assert!(enc.position_error_max_mm <= 1.0 + 1e-2, "{}", enc.position_error_max_mm);
    assert!(enc.normal_error_max_deg < 0.05, "{}", enc.normal_error_max_deg);
    assert!(enc.radius_error_max_rel < 0.022 && enc.spread_error_max <= 0.5 / 255.0 + 1e-6);
    let sizes: Vec<u64> = enc.rows.iter().map(|r| r.surfel_bytes).collect();
    assert!(sizes[1] == 32 * enc.points && sizes[2] < sizes[1] / 2 && sizes[3] < sizes[1] / 4, "{sizes:?}");
}

#[test]
fn an_interrupted_build_resumes_and_gives_the_same_bytes() {
    let dir = tempfile::tempdir().unwrap();
    let params = SynthParams { points: 20_000, segments: 6, ..SynthParams::default() };
    let summary = synth::write_dataset(
        &dir.path().join("scans"),
        &params,
        &[ScanFormat::Laz, ScanFormat::Ply],
        &|_, _| {},
    )
    .unwrap();
    let manifest_path = std::path::PathBuf::from(&summary.manifest);
    let manifest = Manifest::load(&manifest_path).unwrap();
    let bp = BuildParams {
        work_dir: dir.path().join("work"),
        memory_budget_bytes: 64 << 20,
        threads: 2,
        leaf_m: 0.25,
        k: 12,
        min_tile_extent_m: 4.0,
        max_tile_extent_m: 16.0,
        halo_m: 0.25,
        ..BuildParams::default()
    };
    let first = build::build(&manifest, &manifest_path, &dir.path().join("a.grotto"), &bp, &|_| {}).unwrap();
    assert!(!first.resumed_tiling && first.reused_tiles == 0 && first.tiles >= 3);
    // Simulate an interruption: one tile package missing, one damaged.
    std::fs::remove_file(build::tile_package_path(&bp.work_dir, 0)).unwrap();
    let damaged = build::tile_package_path(&bp.work_dir, 1);
    let mut bytes = std::fs::read(&damaged).unwrap();
    let n = bytes.len();
    bytes.truncate(n - 10);
    std::fs::write(&damaged, bytes).unwrap();
    let second = build::build(&manifest, &manifest_path, &dir.path().join("b.grotto"), &bp, &|_| {}).unwrap();
    assert!(second.resumed_tiling);
    assert_eq!(second.reused_tiles, first.tiles - 2);
    // The profile names every stage that ran, in order: the first build all of them (no
    // environment, every scan with its scanner), the resumed one no tiling passes.
    let names = |s: &build::BuildSummary| s.stages.iter().map(|t| t.stage).collect::<Vec<_>>();
    assert_eq!(
        names(&first),
        [
            "count: read scans",
            "count: cells and plan",
            "count: spill points",
            "distribute: read scans",
            "distribute: bins",
            "tiles: read bins",
            "tiles: normals",
            "tiles: surfels",
            "tiles: voxels",
            "tiles: colours",
            "tiles: compact surfels",
            "tiles: encode and write",
            "assemble: check tiles",
            "assemble: levels",
            "assemble: copy and write",
            "assemble: hash inputs",
        ]
    );
    assert!(names(&second).iter().all(|n| !n.starts_with("count") && !n.starts_with("distribute")));
    assert!(names(&second).contains(&"tiles: normals"));
    for s in [&first, &second] {
        let steps = s.steps.plan + s.steps.tiles + s.steps.assemble;
        assert!(
            steps <= s.seconds + 1e-6 && steps > 0.5 * s.seconds,
            "{:?} against {} s",
            s.steps,
            s.seconds
        );
    }
    assert_eq!(
        std::fs::read(dir.path().join("a.grotto")).unwrap(),
        std::fs::read(dir.path().join("b.grotto")).unwrap()
    );
    // Other per-tile parameters rebuild every tile.
    let third = build::build(
        &manifest,
        &manifest_path,
        &dir.path().join("c.grotto"),
        &BuildParams { k: 10, ..bp },
        &|_| {},
    )
    .unwrap();
    assert_eq!(third.reused_tiles, 0);
}

/// The package at `path` has exactly the bytes `want` (a failure says where they part, not all
/// of them).
fn same_bytes(path: &std::path::Path, want: &[u8], what: &str) {
    let got = std::fs::read(path).unwrap();
    let first = got.iter().zip(want).position(|(a, b)| a != b);
    assert!(got == want, "{what}: {} bytes against {}, first difference at {first:?}", got.len(), want.len());
}

#[test]
fn plan_shards_and_assemble_give_the_same_package_as_build() {
    let dir = tempfile::tempdir().unwrap();
    let params = SynthParams { points: 15_000, segments: 5, ..SynthParams::default() };
    let summary =
        synth::write_dataset(&dir.path().join("scans"), &params, &[ScanFormat::Ply], &|_, _| {}).unwrap();
    let manifest_path = std::path::PathBuf::from(&summary.manifest);
    let manifest = Manifest::load(&manifest_path).unwrap();
    let bp = |work: &str| BuildParams {
        work_dir: dir.path().join(work),
        memory_budget_bytes: 64 << 20,
        threads: 1,
        leaf_m: 0.25,
        k: 12,
        min_tile_extent_m: 4.0,
        max_tile_extent_m: 8.0,
        halo_m: 0.25,
        ..BuildParams::default()
    };
    let whole = build::build(&manifest, &manifest_path, &dir.path().join("whole.grotto"), &bp("w1"), &|_| {})
        .unwrap();
    assert!(whole.tiles >= 4);
    let whole_bytes = std::fs::read(dir.path().join("whole.grotto")).unwrap();

    // The thread count and the memory budget change how the work runs, never the package. With
    // 16 threads under 64 MiB the old per-tile cap (3/4 budget / threads / 256 B = 12,288 points)
    // split this cloud's tiles differently, so this fails if either leaks into the tiling.
    let many = BuildParams { threads: 16, ..bp("w16") };
    assert!(many.tiles_at_once() <= 16);
    build::build(&manifest, &manifest_path, &dir.path().join("many.grotto"), &many, &|_| {}).unwrap();
    same_bytes(&dir.path().join("many.grotto"), &whole_bytes, "16 threads");
    let big = BuildParams { threads: 2, memory_budget_bytes: 1 << 30, ..bp("w2g") };
    build::build(&manifest, &manifest_path, &dir.path().join("big.grotto"), &big, &|_| {}).unwrap();
    same_bytes(&dir.path().join("big.grotto"), &whole_bytes, "2 threads, 1 GiB");
    // The tile size cap is content: honoured, and recorded.
    let small = BuildParams { max_tile_points: 2_000, ..bp("wsmall") };
    let split =
        build::build(&manifest, &manifest_path, &dir.path().join("small.grotto"), &small, &|_| {}).unwrap();
    assert!(split.tiles > whole.tiles, "{} tiles at 2,000 points against {}", split.tiles, whole.tiles);
    let prov = Package::open(dir.path().join("small.grotto")).unwrap().provenance().unwrap().unwrap();
    assert_eq!(prov.parameters["max_points_per_tile"], serde_json::json!(2_000));

    // The cluster steps with a different thread count and budget each, as on a login node and
    // compute nodes of other sizes.
    let cluster = BuildParams { threads: 2, memory_budget_bytes: 256 << 20, ..bp("w2") };
    let shard_a = BuildParams { threads: 1, ..bp("w2") };
    let shard_b = BuildParams { threads: 3, memory_budget_bytes: 128 << 20, ..bp("w2") };
    let assembler = BuildParams { threads: 4, ..bp("w2") };
    let err =
        build::build_tiles(&manifest, &manifest_path, &cluster, build::Shard::ALL, &|_| {}).unwrap_err();
    assert!(err.to_string().contains("run the plan step first"), "{err}");
    let (plan, reused) = build::plan(&manifest, &cluster, &|_| {}).unwrap();
    assert!(!reused && plan.tiles.len() == whole.tiles);
    let first =
        build::build_tiles(&manifest, &manifest_path, &shard_a, build::Shard { index: 0, count: 2 }, &|_| {})
            .unwrap();
    let err =
        build::assemble(&manifest, &manifest_path, &dir.path().join("early.grotto"), &assembler, &|_| {})
            .unwrap_err();
    assert!(err.to_string().contains("run build-tile"), "{err}");
    assert!(!dir.path().join("early.grotto").exists());
    let second =
        build::build_tiles(&manifest, &manifest_path, &shard_b, build::Shard { index: 1, count: 2 }, &|_| {})
            .unwrap();
    assert_eq!(first.built + second.built, whole.tiles);
    let out = dir.path().join("cluster.grotto");
    let assembled = build::assemble(&manifest, &manifest_path, &out, &assembler, &|_| {}).unwrap();
    assert_eq!(assembled.tiles, whole.tiles);
    same_bytes(&out, &whole_bytes, "plan, shards and assemble with mixed threads");
}
