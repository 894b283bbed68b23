//! Merging registered scans through the out-of-core tiler: the Stanford bunny's ten range scans
//! overlap to below a millimetre with the poses of bun.conf (and do not with the conjugate
//! rotations, so a convention error fails), and a cloud shifted by survey-sized offsets tiles
//! identically.

use std::num::NonZero;
use std::path::Path;

use grotto_preprocess::bins::{self, FLAG_HALO, TilePlan};
use grotto_preprocess::manifest::{Manifest, ResolvedScan};
use grotto_preprocess::profile::{Profile, Stage};
use grotto_preprocess::tiling::{self, TilingParams};
use grotto_tests::shared_data_dir;
use kiddo::{ImmutableKdTree, SquaredEuclidean};

fn bunny_params() -> TilingParams {
    TilingParams {
        min_tile_extent_m: 1.0 / 32.0,
        max_tile_extent_m: 0.25,
        max_points_per_tile: 60_000,
        halo_m: 0.004,
        ..TilingParams::default()
    }
}

/// World points of every scan, read back from the bins (halo copies skipped).
fn world_points_by_scan(plan: &TilePlan, work: &Path, scans: usize) -> Vec<Vec<[f64; 3]>> {
    let mut out = vec![Vec::new(); scans];
    for (t, tile) in plan.tiles.iter().enumerate() {
        let o = plan.origin_m(tile);
        for p in bins::read_bin(work, plan, t).unwrap() {
            if p.flags & FLAG_HALO == 0 {
                let local = p.pos_tile_m(plan.quantum_m);
                out[p.scan as usize].push(std::array::from_fn(|a| o[a] + f64::from(local[a])));
            }
        }
    }
    out
}

/// Per scan: median distance from its points to the nearest point of any other scan.
fn median_overlap_m(scans: &[Vec<[f64; 3]>]) -> Vec<f64> {
    (0..scans.len())
        .map(|i| {
            let others: Vec<[f64; 3]> =
                scans.iter().enumerate().filter(|(j, _)| *j != i).flat_map(|(_, s)| s.clone()).collect();
            let tree: ImmutableKdTree<f64, 3> = ImmutableKdTree::new_from_slice(&others);
            // Every 7th point is plenty for a median.
            let mut d: Vec<f64> = scans[i]
                .iter()
                .step_by(7)
                .map(|p| tree.nearest_one::<SquaredEuclidean>(p).distance.sqrt())
                .collect();
            d.sort_by(f64::total_cmp);
            d[d.len() / 2]
        })
        .collect()
}

fn tile(scans: &[ResolvedScan], params: &TilingParams) -> (tempfile::TempDir, TilePlan) {
    let work = tempfile::tempdir().unwrap();
    let plan = tiling::tile_scans(scans, work.path(), params, &|_| {}, &Default::default()).unwrap();
    (work, plan)
}

#[test]
fn bunny_scans_merge_below_a_millimetre_and_the_conjugate_pose_does_not() {
    let Some(data) = shared_data_dir() else { return };
    let conf = data.join("ply/stanford-bunny/data/bun.conf");
    let manifest = Manifest::load(&conf).unwrap();
    let scans = manifest.resolve().unwrap();
    assert_eq!(scans.len(), 10);
    let (work, plan) = tile(&scans, &bunny_params());
    assert!(plan.tiles.len() > 1, "the bunny should need several tiles at this budget");
    assert_eq!(plan.points, 362_272);
    let by_scan = world_points_by_scan(&plan, work.path(), scans.len());
    assert_eq!(by_scan.iter().map(Vec::len).sum::<usize>() as u64, plan.points);
    let medians = median_overlap_m(&by_scan);
    for (s, m) in scans.iter().zip(&medians) {
        assert!(*m < 1e-3, "{}: median distance to the other scans {:.3} mm", s.path.display(), m * 1e3);
    }

    // The conjugate quaternion (the classic convention error; here: the .conf values taken as
    // written) misregisters the rotated scans.
    let mut wrong = manifest.clone();
    for s in &mut wrong.scans {
        let r = s.rotation.as_mut().unwrap();
        for c in &mut r[1..] {
            *c = -*c;
        }
    }
    let wrong_scans = wrong.resolve().unwrap();
    let (work, plan) = tile(&wrong_scans, &bunny_params());
    let medians = median_overlap_m(&world_points_by_scan(&plan, work.path(), wrong_scans.len()));
    let misregistered = medians.iter().filter(|m| **m >= 1e-3).count();
    assert!(misregistered >= 5, "conjugate poses should misregister most scans: {medians:?}");
}

#[test]
fn a_cloud_shifted_to_survey_coordinates_tiles_identically() {
    let Some(data) = shared_data_dir() else { return };
    let files: Vec<_> =
        ["bun000.ply", "bun045.ply"].iter().map(|f| data.join("ply/stanford-bunny/data").join(f)).collect();
    let at_origin = Manifest::from_files(&files);
    let mut shifted = at_origin.clone();
    for s in &mut shifted.scans {
        s.translation = Some([500_000.0, 5_000_000.0, 1000.0]);
    }
    let params = bunny_params();
    let (wa, a) = tile(&at_origin.resolve().unwrap(), &params);
    let (wb, b) = tile(&shifted.resolve().unwrap(), &params);
    assert_eq!(a.tiles, b.tiles, "same tiles (levels, keys, counts)");
    assert_eq!(a.halo_points, b.halo_points);
    let mut worst = 0f64;
    for t in 0..a.tiles.len() {
        let (pa, pb) = (bins::read_bin(wa.path(), &a, t).unwrap(), bins::read_bin(wb.path(), &b, t).unwrap());
        assert_eq!(pa.len(), pb.len());
        for (x, y) in pa.iter().zip(&pb) {
            assert_eq!((x.scan, x.flags), (y.scan, y.flags));
            for k in 0..3 {
                worst =
                    worst.max(f64::from((x.pos_tile_m(a.quantum_m)[k] - y.pos_tile_m(b.quantum_m)[k]).abs()));
            }
        }
    }
    assert!(worst < 1e-3, "local coordinates differ by {worst} m");
    let (ga, gb) = (a.grid_origin_m(), b.grid_origin_m());
    assert_eq!([gb[0] - ga[0], gb[1] - ga[1], gb[2] - ga[2]], [500_000.0, 5_000_000.0, 1000.0]);
}

/// Four of the bunny's range scans, unposed.
fn four_bunny_scans(data: &Path) -> Vec<ResolvedScan> {
    let files: Vec<_> = ["bun000.ply", "bun045.ply", "bun090.ply", "bun180.ply"]
        .iter()
        .map(|f| data.join("ply/stanford-bunny/data").join(f))
        .collect();
    Manifest::from_files(&files).resolve().unwrap()
}

#[test]
fn bins_read_the_same_whatever_the_number_of_distribute_workers() {
    let Some(data) = shared_data_dir() else { return };
    let scans = four_bunny_scans(&data);
    // Small tiles and buffers: many tiles with halo copies, several flushes per worker.
    let params = TilingParams { max_points_per_tile: 3_000, buffer_bytes: 1 << 16, ..bunny_params() };
    let in_pool = |threads: usize| {
        let pool = rayon::ThreadPoolBuilder::new().num_threads(threads).build().unwrap();
        pool.install(|| tile(&scans, &params))
    };
    let (w1, one) = in_pool(1);
    assert_eq!(one.bin_writers, 1);
    for threads in [2, 3] {
        let (wn, many) = in_pool(threads);
        assert_eq!(many.bin_writers, threads);
        assert_eq!(TilePlan { bin_writers: 1, ..many.clone() }, one);
        for t in 0..one.tiles.len() {
            let (a, b) =
                (bins::read_bin(w1.path(), &one, t).unwrap(), bins::read_bin(wn.path(), &many, t).unwrap());
            assert!(a == b, "tile {t}: {} and {} points, or another order", a.len(), b.len());
        }
    }
}

#[test]
fn distribute_makes_the_same_bins_from_the_spill_as_from_the_scans() {
    let Some(data) = shared_data_dir() else { return };
    let scans = four_bunny_scans(&data);
    let params = TilingParams { max_points_per_tile: 3_000, buffer_bytes: 1 << 16, ..bunny_params() };
    assert!(params.spill, "spilling is the default");
    let spilled_dir = tempfile::tempdir().unwrap();
    let profile = Profile::default();
    let spilled = tiling::tile_scans(&scans, spilled_dir.path(), &params, &|_| {}, &profile).unwrap();
    assert!(profile.seconds(Stage::Spill) > 0.0, "the count pass wrote the spill");
    let (decoded_dir, decoded) = tile(&scans, &TilingParams { spill: false, ..params.clone() });
    assert_eq!(spilled, decoded);
    // The spill is gone once the bins are written.
    assert!(!spilled_dir.path().join("spill").exists());
    for t in 0..spilled.tiles.len() {
        assert!(
            bins::read_bin(spilled_dir.path(), &spilled, t).unwrap()
                == bins::read_bin(decoded_dir.path(), &decoded, t).unwrap(),
            "tile {t}"
        );
    }
}

#[test]
fn tiles_respect_the_budget_halo_reaches_neighbours_and_runs_resume() {
    let Some(data) = shared_data_dir() else { return };
    let files = vec![data.join("ply/stanford-bunny/reconstruction/bun_zipper.ply")];
    let scans = Manifest::from_files(&files).resolve().unwrap();
    let params = TilingParams { max_points_per_tile: 5_000, ..bunny_params() };
    let work = tempfile::tempdir().unwrap();
    let plan = tiling::tile_scans(&scans, work.path(), &params, &|_| {}, &Default::default()).unwrap();
    for t in &plan.tiles {
        assert!(t.points <= params.max_points_per_tile || t.level == 0, "{t:?}");
    }
    assert_eq!(plan.tiles.iter().map(|t| t.points).sum::<u64>(), 35_947);
    assert!(plan.halo_points > 0);
    // Every halo copy lies within halo_m outside its tile.
    for (i, t) in plan.tiles.iter().enumerate() {
        let e = plan.extent_m(t) as f32;
        let h = params.halo_m as f32 + 1e-6;
        for p in bins::read_bin(work.path(), &plan, i).unwrap() {
            let c = p.pos_tile_m(plan.quantum_m);
            if p.flags & FLAG_HALO == 0 {
                assert!(
                    c.iter().all(|&v| (-1e-6..=e + 1e-6).contains(&v)),
                    "own point outside its tile: {c:?}"
                );
            } else {
                // A halo copy belongs to a neighbour: outside this tile in some axis, within the halo in all.
                assert!(c.iter().all(|&v| (-h..=e + h).contains(&v)), "halo copy too far: {c:?}");
                assert!(c.iter().any(|&v| v <= 1e-6 || v >= e - 1e-6), "halo copy inside the tile: {c:?}");
            }
        }
    }
    // A second run with the same inputs reuses the plan and bins.
    let before = std::fs::metadata(bins::bin_path(work.path(), 0, 0)).unwrap().modified().unwrap();
    let again = tiling::tile_scans(&scans, work.path(), &params, &|_| {}, &Default::default()).unwrap();
    assert_eq!(again, plan);
    assert_eq!(std::fs::metadata(bins::bin_path(work.path(), 0, 0)).unwrap().modified().unwrap(), before);
    // Interrupted while distributing (plan written, bins incomplete and one damaged): only pass 2
    // runs again, and the bins come back identical.
    let plan_json = work.path().join("plan.json");
    let text = std::fs::read_to_string(&plan_json)
        .unwrap()
        .replace("\"bins_complete\": true", "\"bins_complete\": false");
    std::fs::write(&plan_json, text).unwrap();
    let bin0 = std::fs::read(bins::bin_path(work.path(), 0, 0)).unwrap();
    std::fs::write(bins::bin_path(work.path(), 0, 0), &bin0[..bin0.len() / 2]).unwrap();
    let stages = std::sync::Mutex::new(std::collections::BTreeSet::new());
    let profile = Profile::default();
    let resumed = tiling::tile_scans(
        &scans,
        work.path(),
        &params,
        &|p| {
            stages.lock().unwrap().insert(p.stage);
        },
        &profile,
    )
    .unwrap();
    assert_eq!(resumed, plan);
    assert_eq!(stages.into_inner().unwrap().into_iter().collect::<Vec<_>>(), vec!["distribute"]);
    // The profile says the same: no count pass, a distribute pass that read the scans again.
    assert_eq!(profile.seconds(Stage::CountRead) + profile.seconds(Stage::Count), 0.0);
    assert!(profile.seconds(Stage::DistributeRead) > 0.0 && profile.seconds(Stage::Distribute) > 0.0);
    assert_eq!(std::fs::read(bins::bin_path(work.path(), 0, 0)).unwrap(), bin0);
    // Changed parameters redo the work.
    let other = TilingParams { max_points_per_tile: 9_000, ..params };
    let redone = tiling::tile_scans(&scans, work.path(), &other, &|_| {}, &Default::default()).unwrap();
    assert_ne!(redone.fingerprint, plan.fingerprint);
    // Neighbour search helper sanity: kd-tree over a tile finds itself.
    let pts: Vec<[f64; 3]> = bins::read_bin(work.path(), &plan, 0)
        .unwrap()
        .iter()
        .map(|p| p.pos_tile_m(plan.quantum_m).map(f64::from))
        .collect();
    let tree: ImmutableKdTree<f64, 3> = ImmutableKdTree::new_from_slice(&pts);
    assert_eq!(tree.nearest_n::<SquaredEuclidean>(&pts[0], NonZero::new(1).unwrap())[0].distance, 0.0);
}
