//! Survey maps from scans and a survey compiled by Survex's own `cavern` (scripts/test.sh
//! installs the survex package): a straight passage of known elliptical section, scanned and
//! packed with its survey in the package, mapped by `grotto map`'s library. Its widths, heights
//! and areas at the stations, the plan's scale, and the survey's faults (another coordinate
//! system, a station beyond the scans) are checked.

use std::path::{Path, PathBuf};
use std::process::Command;

use glam::DVec3;
use grotto_format::Package;
use grotto_preprocess::ingest::ScanFormat;
use grotto_preprocess::scanwrite::{ScanData, write_scan};
use grotto_runtime::cli::map::{MapOptions, map};

/// The passage's start on its axis, survey coordinates (UTM-like metres).
const START_M: [f64; 3] = [512_345.0, 6_170_123.0, 400.0];
/// Its half-width and half-height, metres: a 4 m by 2.5 m ellipse.
const HALF_WIDTH_M: f64 = 2.0;
const HALF_HEIGHT_M: f64 = 1.25;
/// Its length along bearing 060 (east of north), metres.
const LENGTH_M: f64 = 30.0;
/// Where the stations stand: every 5 m along the axis, this far under it.
const STATION_DROP_M: f64 = 0.6;

/// The passage's direction: bearing 060.
fn along() -> DVec3 {
    let b = 60f64.to_radians();
    DVec3::new(b.sin(), b.cos(), 0.0)
}

fn cavern(dir: &Path, name: &str, svx: &str) -> PathBuf {
    let src = dir.join(format!("{name}.svx"));
    std::fs::write(&src, svx).unwrap();
    let out = Command::new("cavern")
        // A trailing slash: cavern takes a folder whose name has a dot for a file name.
        .arg(format!("--output={}/", dir.display()))
        .arg(&src)
        .output()
        .expect("cavern (Debian package survex; scripts/test.sh installs it)");
    assert!(
        out.status.success(),
        "cavern failed: {}{}",
        String::from_utf8_lossy(&out.stdout),
        String::from_utf8_lossy(&out.stderr)
    );
    dir.join(format!("{name}.3d"))
}

/// The survey as a surveyor would enter it: s0 fixed at the passage's start, six 5 m legs at
/// bearing 060, level; `extra` adds legs.
fn svx(start: [f64; 3], extra: &str) -> String {
    let mut s = format!(
        "*begin tube\n*fix s0 {:.2} {:.2} {:.2}\n*entrance s0\n*data normal from to tape compass clino\n",
        start[0],
        start[1],
        start[2] - STATION_DROP_M
    );
    for k in 0..6 {
        s += &format!("s{k} s{} 5.00 060 0\n", k + 1);
    }
    s += extra;
    s += "*end tube\n";
    s
}

/// Scans of the passage's wall, points every 4 cm each way, split into three scans along it,
/// each seen from its middle.
fn write_scans(dir: &Path) -> String {
    let a = along();
    let side = DVec3::new(a.y, -a.x, 0.0);
    let start = DVec3::from_array(START_M);
    let perimeter = std::f64::consts::TAU * ((HALF_WIDTH_M.powi(2) + HALF_HEIGHT_M.powi(2)) / 2.0).sqrt();
    let ring = (perimeter / 0.04).round() as usize;
    let rings = (LENGTH_M / 0.04).round() as usize;
    let mut manifest = String::new();
    for part in 0..3 {
        let (mut xyz, mut rgb) = (Vec::new(), Vec::new());
        for r in (part * rings / 3)..((part + 1) * rings / 3) {
            let s = (r as f64 + 0.5) * LENGTH_M / rings as f64;
            for k in 0..ring {
                let t = (k as f64 + 0.5) / ring as f64 * std::f64::consts::TAU;
                let p =
                    start + a * s + side * (HALF_WIDTH_M * t.cos()) + DVec3::Z * (HALF_HEIGHT_M * t.sin());
                xyz.push(p.to_array());
                rgb.push([150, 130, 110]);
            }
        }
        let name = format!("tube-{part}.ply");
        let data = ScanData { xyz: &xyz, rgb: &rgb, intensity: &[], normals: &[], pose: None };
        write_scan(&dir.join(&name), ScanFormat::Ply, &data).unwrap();
        let mid = start + a * ((part as f64 + 0.5) * LENGTH_M / 3.0);
        manifest += &format!("[[scan]]\npath = \"{name}\"\norigin = {:?}\n\n", mid.to_array());
    }
    manifest
}

/// Packs the scans with `survey` (a .3d path) in the manifest.
fn pack(dir: &Path, scans: &str, survey: &Path) -> PathBuf {
    use grotto_preprocess::build::{self, BuildParams};
    let manifest_path = dir.join("tube.toml");
    std::fs::write(&manifest_path, format!("{scans}[survey]\npath = {:?}\n", survey.display().to_string()))
        .unwrap();
    let m = grotto_preprocess::manifest::Manifest::load(&manifest_path).unwrap();
    let out = dir.join("tube.grotto");
    let params = BuildParams {
        memory_budget_bytes: 64 << 20,
        threads: 2,
        colors: build::ColorCodec::Raw,
        surfels: build::SurfelCodec::Full,
        min_tile_extent_m: 8.0,
        max_tile_extent_m: 8.0,
        halo_m: 0.5,
        ..BuildParams::with_leaf(dir.join("work"), 0.25)
    };
    build::build(&m, &manifest_path, &out, &params, &|_| {}).unwrap();
    out
}

#[test]
fn a_passage_of_known_section_maps_to_its_width_height_area_and_scale() {
    let dir = tempfile::tempdir().unwrap();
    let scans = write_scans(dir.path());
    let survey_path = cavern(dir.path(), "tube", &svx(START_M, ""));
    let package = pack(dir.path(), &scans, &survey_path);
    let pkg = Package::open(&package).unwrap();
    let survey = pkg.survey().unwrap().expect("the package keeps its survey");
    assert_eq!(survey.stations.iter().filter(|s| s.name.starts_with("tube.s")).count(), 7);
    let out = dir.path().join("map");
    let opts = MapOptions { out_dir: out.clone(), scale: Some(200), ..MapOptions::default() };
    let summary = map(&pkg, &survey, "tube.3d", &opts, &|_, _| {}).unwrap();
    assert!(summary.warnings.is_empty(), "{:?}", summary.warnings);
    assert!((summary.surveyed_length_m - 30.0).abs() < 0.05, "{}", summary.surveyed_length_m);
    let area = std::f64::consts::PI * HALF_WIDTH_M * HALF_HEIGHT_M;
    for k in 1..=5 {
        let name = format!("tube.s{k}");
        let s =
            summary.stations.iter().find(|s| s.station == name).unwrap_or_else(|| panic!("{name} mapped"));
        let (w, h, a) = (s.width_m.unwrap(), s.height_m.unwrap(), s.area_m2.unwrap());
        eprintln!(
            "{name}: width {w:.3} m, height {h:.3} m, area {a:.3} m2, {:.3} m from the middle",
            s.from_middle_m.unwrap()
        );
        assert!((w / (2.0 * HALF_WIDTH_M) - 1.0).abs() < 0.02, "{name}: width {w}");
        assert!((h / (2.0 * HALF_HEIGHT_M) - 1.0).abs() < 0.02, "{name}: height {h}");
        assert!((a / area - 1.0).abs() < 0.02, "{name}: area {a} against {area}");
        // The station stands 0.6 m under the axis: in the air, 0.6 m from the middle.
        assert_eq!(s.inside, Some(true));
        assert!((s.from_middle_m.unwrap() - STATION_DROP_M).abs() < 0.05);
        assert!(Path::new(s.section.as_ref().unwrap()).exists());
    }
    let csv = std::fs::read_to_string(out.join("passages.csv")).unwrap();
    assert!(csv.starts_with("station,x,y,z,width_m,height_m,area_m2"));
    assert!(csv.lines().any(|l| l.starts_with("tube.s3,")) && csv.contains("# surveyed length 30.00 m"));
    // The plan's scale: 1:200 at 150 dpi is 3.387 cm a pixel. The passage's floor, drawn from
    // the points alone, spans 30 m along its axis and 4 m across it.
    let m_per_px = 200.0 * 0.0254 / 150.0;
    assert!((summary.m_per_px - m_per_px).abs() < 1e-9);
    let img = image::open(out.join("plan-image.png")).unwrap().to_rgb8();
    let a = along();
    let (mut lo, mut hi) = ([f64::INFINITY; 2], [f64::NEG_INFINITY; 2]);
    for (x, y, p) in img.enumerate_pixels() {
        if p.0 != [255, 255, 255] {
            // Pixel rows run south: the axis in pixels is (east, -north).
            let (u, v) = (f64::from(x) + 0.5, f64::from(y) + 0.5);
            let on = [u * a.x - v * a.y, u * a.y + v * a.x];
            for k in 0..2 {
                lo[k] = lo[k].min(on[k]);
                hi[k] = hi[k].max(on[k]);
            }
        }
    }
    let (length_px, width_px) = (hi[0] - lo[0], hi[1] - lo[1]);
    eprintln!("plan: {length_px:.1} px along, {width_px:.1} px across");
    assert!((length_px * m_per_px / LENGTH_M - 1.0).abs() < 0.02, "{length_px} px along");
    assert!((width_px * m_per_px / (2.0 * HALF_WIDTH_M) - 1.0).abs() < 0.03, "{width_px} px across");
    for f in ["plan.png", "plan.svg", "elevation.png", "elevation.svg"] {
        assert!(out.join(f).exists(), "{f}");
    }
    let svg = std::fs::read_to_string(out.join("plan.svg")).unwrap();
    assert!(svg.contains("plan-image.png") && svg.contains(">s3<"));

    // A station 40 m past the scans: mapped with a warning naming it.
    let far = cavern(dir.path(), "far", &svx(START_M, "s6 s7 40.00 060 0\n"));
    let survey = grotto_format::survey::read(&far).unwrap();
    let summary = map(&pkg, &survey, "far.3d", &opts, &|_, _| {}).unwrap();
    assert!(
        summary.warnings.iter().any(|w| w.contains("tube.s7") && w.contains("no scanned point")),
        "{:?}",
        summary.warnings
    );
    // The same survey in a local grid (s0 at the origin): refused, naming the likely cause.
    let local = cavern(dir.path(), "local", &svx([0.0, 0.0, STATION_DROP_M], ""));
    let survey = grotto_format::survey::read(&local).unwrap();
    let e = map(&pkg, &survey, "local.3d", &opts, &|_, _| {}).unwrap_err().to_string();
    assert!(e.contains("local.3d") && e.contains("another coordinate system"), "{e}");
}

/// The synthetic cave's centreline (`cave.svx`, with a careful survey's reading noise) compiled by
/// cavern fits its scans: the drift a real traverse has, not more.
#[test]
fn the_synthetic_caves_survey_compiles_and_fits_its_scans() {
    use grotto_preprocess::synth::{self, SynthParams};
    let dir = tempfile::tempdir().unwrap();
    let params = SynthParams { points: 150_000, segments: 12, ..SynthParams::default() };
    let scans = dir.path().join("scans");
    let summary = synth::write_dataset(&scans, &params, &[ScanFormat::Las], &|_, _| {}).unwrap();
    let svx = std::fs::read_to_string(scans.join("cave.svx")).unwrap();
    let compiled = cavern(dir.path(), "cave", &svx);
    // Packed with the survey named in the manifest.
    let manifest_path = PathBuf::from(&summary.manifest);
    let mut text = std::fs::read_to_string(&manifest_path).unwrap();
    text += &format!("[survey]\npath = {:?}\n", compiled.display().to_string());
    std::fs::write(&manifest_path, text).unwrap();
    let manifest = grotto_preprocess::manifest::Manifest::load(&manifest_path).unwrap();
    let out = dir.path().join("cave.grotto");
    let bp = grotto_tests::small_build(&dir.path().join("work"), 2.0, 32.0, 0.25);
    grotto_preprocess::build::build(&manifest, &manifest_path, &out, &bp, &|_| {}).unwrap();
    let pkg = Package::open(&out).unwrap();
    let survey = pkg.survey().unwrap().expect("built with [survey]");
    let opts = MapOptions { out_dir: dir.path().join("map"), ..MapOptions::default() };
    let summary = map(&pkg, &survey, "cave.3d", &opts, &|_, _| {}).unwrap();
    let stations = &summary.stations;
    let traced: Vec<_> = stations.iter().filter(|s| s.section.is_some()).collect();
    let inside = traced.iter().filter(|s| s.inside == Some(true)).count();
    eprintln!(
        "{} stations, {} traced, {inside} inside; warnings {:?}",
        stations.len(),
        traced.len(),
        summary.warnings
    );
    assert!(stations.len() >= 12 && traced.len() * 10 >= stations.len() * 8, "{stations:?}");
    assert!(inside * 10 >= traced.len() * 9, "{inside} of {} stations in the passage", traced.len());
    // Passages 2.6-6 m across (capsules of radius 1.3-3 m, chambers wider).
    for s in &traced {
        let w = s.width_m.unwrap();
        assert!((1.5..=20.0).contains(&w), "{}: width {w}", s.station);
    }
    // The surveyed length is the legs' (4 m each, read with noise).
    let legs = survey.legs.len() as f64;
    assert!((summary.surveyed_length_m / legs - 4.0).abs() < 0.5, "{}", summary.surveyed_length_m);
}
