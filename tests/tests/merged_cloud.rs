//! A merged, registered cloud with no scanner positions: the synthetic cave's scans
//! merged into one bare PLY at survey coordinates, its entrance opened to the outside, built with
//! no manifest. Normals must face the open passage, against the cave's analytic surface, and as
//! well at tile borders as inside tiles.

use std::path::Path;

use grotto_format::Package;
use grotto_format::spec::Surfel;
use grotto_preprocess::build::{self, BuildParams};
use grotto_preprocess::ingest::ScanFormat;
use grotto_preprocess::manifest::Manifest;
use grotto_preprocess::scanwrite::{ScanData, write_scan};
use grotto_preprocess::synth::{self, SynthCave, SynthParams};
use grotto_runtime::cli::render_job;
use grotto_runtime::engine::RenderOptions;
use grotto_runtime::settings::Settings;
use grotto_runtime::view::framing::CameraChoice;
use grotto_tests::{golden, small_build};

/// Each station's scan in world (survey) coordinates with its station, less the points of the
/// main passage's first end cap: the cave's entrance, open to the outside.
/// One station's scan: the station and its points (world) with their colours.
type StationScan = ([f64; 3], Vec<[f64; 3]>, Vec<[u8; 3]>);

fn station_scans(cave: &SynthCave, params: &SynthParams) -> Vec<StationScan> {
    let rays = params.points.div_ceil(cave.stations.len() as u64);
    let (a, b) = (cave.path[0], cave.path[1]);
    let axis: [f64; 3] = std::array::from_fn(|i| b[i] - a[i]);
    (0..cave.stations.len())
        .map(|s| {
            let sc = synth::scan(cave, params, s, rays);
            let (mut xyz, mut rgb) = (Vec::new(), Vec::new());
            for (p, c) in sc.xyz.iter().zip(&sc.rgb) {
                let w = sc.world_from_scan.apply(*p);
                let d: [f64; 3] = std::array::from_fn(|i| w[i] - params.offset_m[i] - a[i]);
                let behind = (0..3).map(|i| d[i] * axis[i]).sum::<f64>() < 0.0;
                if behind && (0..3).map(|i| d[i] * d[i]).sum::<f64>() < 16.0 {
                    continue;
                }
                xyz.push(w);
                rgb.push(*c);
            }
            (sc.station_world_m, xyz, rgb)
        })
        .collect()
}

/// Every station's points in one cloud, with their colours.
fn merged(scans: &[StationScan]) -> (Vec<[f64; 3]>, Vec<[u8; 3]>) {
    (
        scans.iter().flat_map(|s| s.1.iter().copied()).collect(),
        scans.iter().flat_map(|s| s.2.iter().copied()).collect(),
    )
}

/// Every surfel of `pkg` with its tile's extent and the cosine between its normal and the cave's
/// true normal at it (positive: it faces the passage).
fn against_truth(pkg: &Package, cave: &SynthCave, synth: &SynthParams) -> Vec<(Surfel, f64, f64)> {
    let mut out = Vec::new();
    for tile in pkg.tiles() {
        let origin = tile.origin_m();
        let extent = tile.info().extent_m;
        for s in tile.surfels().unwrap().unwrap().iter() {
            let local: [f64; 3] =
                std::array::from_fn(|a| origin[a] + f64::from(s.position_tile_m[a]) - synth.offset_m[a]);
            let truth = cave.normal(local);
            out.push((*s, extent, (0..3).map(|a| truth[a] * f64::from(s.normal[a])).sum()));
        }
    }
    out
}

/// Tiles of 2 to 8 m, so that the cave spans many tile borders.
fn params(work: &Path) -> BuildParams {
    small_build(work, 2.0, 8.0, 0.25)
}

/// One 160x120 frame from inside the passage (headlamp at the camera: the packages have no
/// lights), at `exposure` (None: automatic).
fn render(
    package: &Path,
    out: &Path,
    eye_m: [f64; 3],
    look_at_m: [f64; 3],
    exposure: Option<f32>,
) -> (f32, Vec<[u8; 4]>) {
    let opts = RenderOptions {
        camera: CameraChoice::Explicit { eye_m, look_at_m, up: [0.0, 0.0, 1.0], fov_y_deg: 70.0 },
        width: 160,
        height: 120,
        settings: Settings { bounces: 2, shadow_map_size: 256, ..Settings::default() },
        exposure,
        gpu: grotto_tests::lavapipe(),
        ..RenderOptions::defaults(package.to_path_buf(), out.to_path_buf())
    };
    let summary = render_job::run(&opts, |_| {}).unwrap();
    let (_, _, pixels) = grotto_runtime::cli::image_out::read_png(out).unwrap();
    (summary.exposure, pixels)
}

#[test]
fn a_bare_merged_cloud_gets_normals_that_face_the_passage() {
    let dir = tempfile::tempdir().unwrap();
    let synth = SynthParams { points: 120_000, segments: 10, ..SynthParams::default() };
    let cave = SynthCave::new(&synth);
    let scans = station_scans(&cave, &synth);
    let (xyz, rgb) = merged(&scans);
    let ply = dir.path().join("merged.ply");
    write_scan(
        &ply,
        ScanFormat::Ply,
        &ScanData { xyz: &xyz, rgb: &rgb, intensity: &[], normals: &[], pose: None },
    )
    .unwrap();
    let manifest = Manifest::from_files(std::slice::from_ref(&ply));
    assert!(manifest.resolve().unwrap().iter().all(|s| !s.scanner_known), "a bare file has no scanner");
    let out = dir.path().join("merged.grotto");
    let bp = params(&dir.path().join("work"));
    let built = build::build(&manifest, &ply, &out, &bp, &|_| {}).unwrap();
    assert_eq!(built.points, xyz.len() as u64);
    assert!(built.tiles > 8, "{} tiles", built.tiles);
    let o = built.orientation.expect("orientation without a scanner ran");
    assert_eq!(o.points, built.points);
    assert!(built.hints().iter().any(|h| h.contains("no scanner position")), "{:?}", built.hints());

    let pkg = Package::open(&out).unwrap();
    let (mut n, mut wrong, mut border, mut border_wrong) = (0u64, 0u64, 0u64, 0u64);
    for (s, extent, cos) in against_truth(&pkg, &cave, &synth) {
        let faces = cos > 0.0;
        // Within two leaves of a tile face: the neighbourhood and the votes straddle tiles.
        let near_border =
            s.position_tile_m.iter().any(|&c| f64::from(c).min(extent - f64::from(c)) < 2.0 * bp.leaf_m);
        n += 1;
        wrong += u64::from(!faces);
        border += u64::from(near_border);
        border_wrong += u64::from(near_border && !faces);
    }
    let share = 1.0 - wrong as f64 / n as f64;
    let border_share = 1.0 - border_wrong as f64 / border.max(1) as f64;
    eprintln!(
        "bare merged cloud: {n} surfels in {} tiles, {:.2}% face the passage ({:.2}% of {border} within two leaves \
         of a tile border); summary: {o:?}, mean confidence {:.2}",
        built.tiles,
        share * 100.0,
        border_share * 100.0,
        o.mean_confidence()
    );
    assert!(border > n / 20, "the test must cover borders: {border} of {n}");
    assert!(share >= 0.99, "{:.2}% face the passage", share * 100.0);
    assert!(border_share >= 0.99, "{:.2}% at tile borders", border_share * 100.0);

    // The same points as scans with their scanner positions (one file per station, `origin =`),
    // rendered from inside the passage: the bare build must look the same.
    let mut manifest_text = String::new();
    for (i, (station, xyz, rgb)) in scans.iter().enumerate() {
        let path = dir.path().join(format!("station-{i:02}.ply"));
        write_scan(&path, ScanFormat::Ply, &ScanData { xyz, rgb, intensity: &[], normals: &[], pose: None })
            .unwrap();
        manifest_text += &format!(
            "[[scan]]\npath = \"{}\"\norigin = [{}, {}, {}]\n",
            path.display(),
            station[0],
            station[1],
            station[2]
        );
    }
    let manifest_path = dir.path().join("stations.toml");
    std::fs::write(&manifest_path, manifest_text).unwrap();
    let stations = Manifest::load(&manifest_path).unwrap();
    assert!(stations.resolve().unwrap().iter().all(|s| s.scanner_known));
    let with_scanners = dir.path().join("stations.grotto");
    let built_s =
        build::build(&stations, &manifest_path, &with_scanners, &params(&dir.path().join("work-s")), &|_| {})
            .unwrap();
    assert!(built_s.orientation.is_none() && built_s.points == built.points);
    let at = |p: [f64; 3]| -> [f64; 3] { std::array::from_fn(|a| p[a] + synth.offset_m[a]) };
    for (name, eye, look) in
        [("passage", cave.path[2], cave.path[4]), ("entrance", cave.path[3], cave.path[0])]
    {
        let (exposure, want) =
            render(&with_scanners, &dir.path().join(format!("{name}-s.png")), at(eye), at(look), None);
        let (_, got) =
            render(&out, &dir.path().join(format!("{name}-bare.png")), at(eye), at(look), Some(exposure));
        let d = golden::diff(&got, &want);
        eprintln!("{name}: bare against scanner positions {d:?}");
        assert!(golden::within_tolerance(&d), "{name}: {d:?}");
    }
}

#[test]
fn normals_a_file_carries_are_kept_and_oriented_or_re_estimated_on_request() {
    let dir = tempfile::tempdir().unwrap();
    let synth = SynthParams { points: 30_000, segments: 5, ..SynthParams::default() };
    let cave = SynthCave::new(&synth);
    let scans = station_scans(&cave, &synth);
    let (xyz, rgb) = merged(&scans);
    // Registration software writes unoriented normals: the true ones, every third turned around.
    let given: Vec<[f32; 3]> = xyz
        .iter()
        .enumerate()
        .map(|(i, w)| {
            let n = cave.normal(std::array::from_fn(|a| w[a] - synth.offset_m[a]));
            let s = if i % 3 == 0 { -1.0 } else { 1.0 };
            n.map(|c| (s * c) as f32)
        })
        .collect();
    let ply = dir.path().join("with-normals.ply");
    write_scan(
        &ply,
        ScanFormat::Ply,
        &ScanData { xyz: &xyz, rgb: &rgb, intensity: &[], normals: &given, pose: None },
    )
    .unwrap();
    let manifest = Manifest::from_files(std::slice::from_ref(&ply));
    for keep in [true, false] {
        let bp = BuildParams { keep_input_normals: keep, ..params(&dir.path().join(format!("work-{keep}"))) };
        let out = dir.path().join(format!("keep-{keep}.grotto"));
        let built = build::build(&manifest, &ply, &out, &bp, &|_| {}).unwrap();
        assert_eq!(built.input_normals, built.points, "every point carried one");
        let pkg = Package::open(&out).unwrap();
        let (mut n, mut facing, mut exact) = (0u64, 0u64, 0u64);
        for (_, _, d) in against_truth(&pkg, &cave, &synth) {
            n += 1;
            facing += u64::from(d > 0.0);
            exact += u64::from(d > 0.99999);
        }
        eprintln!(
            "--normals {}: {} of {} kept; {facing} of {n} face the passage, {exact} equal to the file's (up to sign)",
            if keep { "keep" } else { "estimate" },
            built.input_normals_kept,
            built.input_normals
        );
        assert!(facing as f64 >= 0.99 * n as f64, "oriented consistently: {facing} of {n}");
        if keep {
            assert!(built.input_normals_kept as f64 >= 0.99 * built.input_normals as f64);
            assert!(exact as f64 >= 0.95 * n as f64, "the file's normals are kept: {exact} of {n}");
            assert!(built.hints().iter().any(|h| h.contains("carried normals")));
        } else {
            assert_eq!(built.input_normals_kept, 0);
            assert!(exact * 10 < n, "re-estimated normals differ from the file's: {exact} of {n}");
        }
    }
}

/// The Stanford bunny's zippered mesh: its vertices and their area-weighted normals from the
/// faces (the mesh is wound outward). Read here, not by grotto's PLY reader, which streams points
/// and skips faces: the faces are the truth this test needs.
fn bunny_with_normals(path: &Path) -> (Vec<[f64; 3]>, Vec<[f64; 3]>) {
    let text = std::fs::read_to_string(path).unwrap();
    let (header, body) = text.split_once("end_header\n").unwrap();
    let count = |element: &str| -> usize {
        header
            .lines()
            .find_map(|l| l.strip_prefix(&format!("element {element} ")))
            .and_then(|n| n.trim().parse().ok())
            .unwrap()
    };
    let (nv, nf) = (count("vertex"), count("face"));
    let mut lines = body.lines();
    let vertices: Vec<[f64; 3]> = (&mut lines)
        .take(nv)
        .map(|l| {
            let mut w = l.split_whitespace().map(|x| x.parse::<f64>().unwrap());
            std::array::from_fn(|_| w.next().unwrap())
        })
        .collect();
    let mut normals = vec![[0.0f64; 3]; nv];
    for l in lines.take(nf) {
        let idx: Vec<usize> = l.split_whitespace().skip(1).map(|x| x.parse().unwrap()).collect();
        let [a, b, c] = [idx[0], idx[1], idx[2]].map(|i| vertices[i]);
        let (u, v): ([f64; 3], [f64; 3]) =
            (std::array::from_fn(|k| b[k] - a[k]), std::array::from_fn(|k| c[k] - a[k]));
        let n = [u[1] * v[2] - u[2] * v[1], u[2] * v[0] - u[0] * v[2], u[0] * v[1] - u[1] * v[0]];
        for &i in &idx[..3] {
            for k in 0..3 {
                normals[i][k] += n[k];
            }
        }
    }
    (vertices, normals)
}

#[test]
fn an_object_scanned_from_outside_faces_out_when_the_build_is_told_so() {
    use grotto_preprocess::manifest::SeenFrom;
    use kiddo::{KdTree, SquaredEuclidean};
    let Some(data) = grotto_tests::shared_data_dir() else { return };
    let file = data.join("ply/stanford-bunny/reconstruction/bun_zipper.ply");
    let (vertices, normals) = bunny_with_normals(&file);
    let centre: [f64; 3] =
        std::array::from_fn(|a| vertices.iter().map(|v| v[a]).sum::<f64>() / vertices.len() as f64);
    let outward = vertices
        .iter()
        .zip(&normals)
        .filter(|(v, n)| (0..3).map(|a| (v[a] - centre[a]) * n[a]).sum::<f64>() > 0.0)
        .count();
    assert!(outward * 10 > vertices.len() * 8, "the mesh's own normals face out: {outward}");
    // The truth: vertices some face uses (the zippered mesh leaves a few out).
    let mut tree: KdTree<f64, 3> = KdTree::new();
    for (i, v) in vertices.iter().enumerate() {
        if normals[i] != [0.0; 3] {
            tree.add(v, i as u64);
        }
    }
    let dir = tempfile::tempdir().unwrap();
    let mut facing_out = Vec::new();
    for seen_from in [SeenFrom::Outside, SeenFrom::Inside] {
        let mut manifest = Manifest::from_files(std::slice::from_ref(&file));
        manifest.scans[0].seen_from = Some(seen_from);
        let out = dir.path().join(format!("bunny-{seen_from:?}.grotto"));
        // A 16 cm object: 4 mm leaves (orientation cells of 8 mm), one 25 cm tile.
        let bp = BuildParams {
            leaf_m: 1.0 / 256.0,
            ..small_build(&dir.path().join(format!("work-{seen_from:?}")), 0.25, 0.25, 1.0 / 64.0)
        };
        let built = build::build(&manifest, &file, &out, &bp, &|_| {}).unwrap();
        assert_eq!(built.scans_seen_from_outside, usize::from(seen_from == SeenFrom::Outside));
        let pkg = Package::open(&out).unwrap();
        let (mut agree, mut total) = (0usize, 0usize);
        for tile in pkg.tiles() {
            let origin = tile.origin_m();
            let Some(surfels) = tile.surfels().unwrap() else { continue };
            for s in surfels.iter() {
                let p: [f64; 3] = std::array::from_fn(|a| origin[a] + f64::from(s.position_tile_m[a]));
                let i = tree.nearest_one::<SquaredEuclidean>(&p).item as usize;
                agree +=
                    usize::from((0..3).map(|a| normals[i][a] * f64::from(s.normal[a])).sum::<f64>() > 0.0);
                total += 1;
            }
        }
        let share = agree as f64 / total as f64;
        eprintln!(
            "bunny seen from {seen_from:?}: {:.2}% of {total} normals face out of the mesh",
            share * 100.0
        );
        facing_out.push(share);
    }
    assert!(facing_out[0] > 0.97, "told it was seen from outside: {:.4}", facing_out[0]);
    assert!(facing_out[1] < 0.03, "a bare file is a cave by default: {:.4}", facing_out[1]);
}
