//! Survex `.3d` files as Survex's own `cavern` writes them (Debian's `survex` package, which
//! scripts/test.sh installs): a survey written here, compiled by cavern, read back. Damaged and
//! foreign files are errors, never panics.

use std::path::Path;
use std::process::Command;

use grotto_format::survey::{self, Survey};

/// Compiles `svx` (the text of a Survex data file) with cavern in `dir`; returns the `.3d` path.
fn cavern(dir: &Path, svx: &str) -> std::path::PathBuf {
    let src = dir.join("survey.svx");
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
    dir.join("survey.3d")
}

const SVX: &str = "\
*begin cave
*cs EPSG:32633
*cs out EPSG:32633
*fix 1 reference 400000.00 5000000.00 500.00
*entrance 1
*data normal from to tape compass clino
1 2 10.00 090 0
2 3 5.00 000 -10
*flags splay
3 - 2.0 045 0
*flags not splay
*flags duplicate
3 4 3.00 000 0
*flags not duplicate
*data passage station left right up down
2 1.0 1.5 2.0 0.5
3 0.8 0.7 1.0 0.3
*end cave
";

fn read(path: &Path) -> Survey {
    survey::read(path).unwrap_or_else(|e| panic!("{e}"))
}

#[test]
fn a_survey_compiled_by_cavern_reads_back_with_its_stations_legs_flags_and_dimensions() {
    let dir = tempfile::tempdir().unwrap();
    let s = read(&cavern(dir.path(), SVX));
    assert_eq!(s.crs.as_deref(), Some("EPSG:32633"));
    let at = |name: &str| s.station(name).unwrap_or_else(|| panic!("no {name} in {:?}", s.stations)).clone();
    let (one, two, three) = (at("cave.1"), at("cave.2"), at("cave.3"));
    assert_eq!(one.position_m, [400000.0, 5000000.0, 500.0]);
    assert!(one.flags.fixed && one.flags.entrance && one.flags.underground);
    // 10 m due east, then 5 m north at -10 degrees: cavern's own reduction, to its centimetre.
    assert_eq!(two.position_m, [400010.0, 5000000.0, 500.0]);
    let (dz, dy) = (-5.0 * 10f64.to_radians().sin(), 5.0 * 10f64.to_radians().cos());
    for (got, want) in three.position_m.iter().zip([400010.0, 5000000.0 + dy, 500.0 + dz]) {
        assert!((got - want).abs() <= 0.005 + 1e-9, "{:?}", three.position_m);
    }
    let splays: Vec<_> = s.legs.iter().filter(|l| l.flags.splay).collect();
    assert_eq!(splays.len(), 1, "{:?}", s.legs);
    assert!(s.legs.iter().filter(|l| l.flags.duplicate).count() == 1);
    assert!(s.legs.iter().all(|l| l.survey == "cave"), "{:?}", s.legs);
    // Legs join the stations at their ends.
    let leg = s.legs.iter().find(|l| l.to_m == two.position_m).unwrap();
    assert_eq!(leg.from.map(|i| s.stations[i].name.as_str()), Some("cave.1"));
    // Length: the two legs, not the splay nor the duplicate.
    assert!((s.surveyed_length_m() - 15.0).abs() < 0.01, "{}", s.surveyed_length_m());
    let x = s.cross_sections.iter().find(|c| c.station == "cave.2").unwrap();
    assert_eq!(x.lrud_m, [Some(1.0), Some(1.5), Some(2.0), Some(0.5)]);
}

#[test]
fn truncated_damaged_and_foreign_files_are_errors_naming_the_file() {
    let dir = tempfile::tempdir().unwrap();
    let path = cavern(dir.path(), SVX);
    let bytes = std::fs::read(&path).unwrap();
    // Every truncation: an error, never a panic (the end marker is the last byte).
    for n in 0..bytes.len() {
        let e = survey::parse(&bytes[..n], "cut.3d").unwrap_err();
        assert!(e.to_string().starts_with("cut.3d: "), "{e}");
    }
    // Every byte changed to every value: an answer or an error, never a panic or a hang.
    for i in 0..bytes.len() {
        for v in [0x00, 0x05, 0x20, 0x34, 0x3f, 0x7f, 0xff] {
            let mut b = bytes.clone();
            b[i] = v;
            let _ = survey::parse(&b, "damaged.3d");
        }
    }
    let v7 = [&b"Survex 3D Image File\nv7\n"[..], &bytes[24..]].concat();
    let e = survey::parse(&v7, "old.3d").unwrap_err().to_string();
    assert!(e.contains("version 8") && e.contains("cavern"), "{e}");
    let e = survey::parse(b"LASF....", "scan.las").unwrap_err().to_string();
    assert!(e.contains("scan.las") && e.contains("not a survey"), "{e}");
    let e = survey::read(&dir.path().join("missing.3d")).unwrap_err().to_string();
    assert!(e.contains("missing.3d") && e.contains("cannot read"), "{e}");
}

#[test]
fn a_package_keeps_its_survey_and_one_without_a_survey_has_none() {
    use grotto_format::{Package, PackageWriter, SectionKind};
    let dir = tempfile::tempdir().unwrap();
    let s = read(&cavern(dir.path(), SVX));
    let with = dir.path().join("with.grotto");
    let mut w = PackageWriter::create(&with).unwrap();
    w.add_survey(&s).unwrap();
    let pkg = Package::open(w.finish().unwrap()).unwrap();
    assert!(pkg.verify().is_empty(), "{:?}", pkg.verify());
    assert_eq!(pkg.survey().unwrap().as_ref(), Some(&s));
    assert_eq!(pkg.sections().filter(|x| x.kind == Some(SectionKind::Survey)).count(), 1);
    let without = dir.path().join("without.grotto");
    let pkg = Package::open(PackageWriter::create(&without).unwrap().finish().unwrap()).unwrap();
    assert_eq!(pkg.survey().unwrap(), None);
    // A survey whose positions are not finite is refused when written, naming the station.
    let mut bad = s.clone();
    bad.stations[1].position_m[2] = f64::NAN;
    let mut w = PackageWriter::create(dir.path().join("bad.grotto")).unwrap();
    let e = w.add_survey(&bad).unwrap_err().to_string();
    assert!(e.contains(&bad.stations[1].name), "{e}");
}
