//! The demo scene goes through the package and comes back to the millimetre: f64 tile origins plus
//! f32 tile-local offsets reproduce survey-sized coordinates of an analytic surface.

use grotto_format::spec::Rgba8;
use grotto_format::{Package, SectionKind};
use grotto_preprocess::demo::{self, DemoParams};

#[test]
fn demo_points_survive_the_package_at_survey_coordinates() {
    let dir = tempfile::tempdir().unwrap();
    let out = dir.path().join("demo.grotto");
    let params = DemoParams { points: 20_000, ..DemoParams::default() };
    let summary = demo::build(&out, &params).unwrap();
    let pkg = Package::open(&out).unwrap();
    assert!(pkg.verify().is_empty());
    assert_eq!(summary.tiles, pkg.tile_count());
    assert!(pkg.tile_count() > 1, "the chamber spans several tiles");

    let mut seen = 0u64;
    let mut worst_radius_err_m = 0f64;
    for tile in pkg.tiles() {
        let surfels = tile.surfels().unwrap().unwrap();
        let colors = tile.read::<Rgba8>(SectionKind::SurfelColorsRaw).unwrap().unwrap();
        assert_eq!(surfels.len() as u64, tile.point_count());
        assert_eq!(colors.len(), surfels.len());
        let o = tile.origin_m();
        for s in surfels.iter() {
            for a in 0..3 {
                assert!((0.0..=tile.extent_m() as f32).contains(&s.position_tile_m[a]));
            }
            let world: [f64; 3] = std::array::from_fn(|a| o[a] + f64::from(s.position_tile_m[a]));
            let d: [f64; 3] = std::array::from_fn(|a| world[a] - params.center_m[a]);
            let r = (d[0] * d[0] + d[1] * d[1] + d[2] * d[2]).sqrt();
            worst_radius_err_m = worst_radius_err_m.max((r - params.radius_m).abs());
            // Normals point into the chamber.
            let dot: f64 = (0..3).map(|a| d[a] * f64::from(s.normal[a])).sum();
            assert!(dot < 0.0);
        }
        seen += surfels.len() as u64;
    }
    assert_eq!(seen, params.points);
    assert!(worst_radius_err_m < 1e-3, "worst radius error {worst_radius_err_m} m");

    let scene = pkg.scene().unwrap();
    assert_eq!((scene.lights.len(), scene.cameras.len()), (1, 1));
    assert_eq!(pkg.provenance().unwrap().unwrap().parameters["points"], 20_000);
}

#[test]
fn demo_is_deterministic_and_refuses_bad_parameters() {
    let dir = tempfile::tempdir().unwrap();
    let (a, b) = (dir.path().join("a.grotto"), dir.path().join("b.grotto"));
    let params = DemoParams { points: 3_000, ..DemoParams::default() };
    demo::build(&a, &params).unwrap();
    demo::build(&b, &params).unwrap();
    assert_eq!(std::fs::read(&a).unwrap(), std::fs::read(&b).unwrap(), "same input, same bytes");

    for bad in [
        DemoParams { points: 0, ..DemoParams::default() },
        DemoParams { tile_extent_m: 6.0, ..DemoParams::default() },
        DemoParams { depth: 30, ..DemoParams::default() },
        DemoParams { center_m: [1e12, 0.0, 0.0], ..DemoParams::default() },
    ] {
        let out = dir.path().join("bad.grotto");
        assert!(demo::build(&out, &bad).is_err(), "{bad:?}");
        assert!(!out.exists(), "a refused build leaves nothing behind");
    }
}
