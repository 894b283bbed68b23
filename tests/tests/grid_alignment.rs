//! Where the leaf grid falls: a scanned room built twice, once with its walls on leaf
//! boundaries and once moved by a fraction of a leaf, should give the same light. The issue
//! measured the high preset's bias moving from -7.3% to -5.2% for such a move.
//!
//! The move chosen (0.3-0.5 leaf) keeps every wall's points in the same leaves, so what changes
//! is where the surface sits inside its leaves. With leaf light evaluated, and cones started, at
//! the cell's centre, the first bounce moved by 4.03%; with the leaf at its surfels' centroid
//! (scene/data.rs, `move_leaves_to_surfels`) it moves by 0.17%.

use std::path::Path;

use glam::Vec3;
use grotto_format::Package;
use grotto_preprocess::build::{self, BuildParams};
use grotto_preprocess::ingest::ScanFormat;
use grotto_preprocess::manifest::Manifest;
use grotto_preprocess::scanwrite::{ScanData, write_scan};
use grotto_runtime::gpu::{Gpu, GpuOptions};
use grotto_runtime::render::Renderer;
use grotto_runtime::scene::data::SceneData;
use grotto_runtime::settings::Settings;
use grotto_runtime::view::camera::Camera;
use grotto_tests::small_build;

/// The room: 4 x 3 x 2.5 m.
const ROOM_M: [f64; 3] = [4.0, 3.0, 2.5];

/// Points on the room's six walls every 2.5 cm, the room's low corner at `corner`.
fn room_points(corner: [f64; 3]) -> Vec<[f64; 3]> {
    let s = 0.025;
    let mut pts = Vec::new();
    for axis in 0..3 {
        let (u, v) = ((axis + 1) % 3, (axis + 2) % 3);
        let (nu, nv) = ((ROOM_M[u] / s) as usize, (ROOM_M[v] / s) as usize);
        for side in [0.0, ROOM_M[axis]] {
            for i in 0..=nu {
                for j in 0..=nv {
                    let mut p = [0.0; 3];
                    p[axis] = side;
                    p[u] = i as f64 * s;
                    p[v] = j as f64 * s;
                    pts.push(std::array::from_fn(|a| corner[a] + p[a]));
                }
            }
        }
    }
    pts
}

/// Builds the room with its corner at `corner` and a lamp and scanner at its centre; returns the
/// package.
fn build_room(dir: &Path, name: &str, corner: [f64; 3]) -> std::path::PathBuf {
    let pts = room_points(corner);
    let rgb = vec![[200u8, 190, 180]; pts.len()];
    let ply = dir.join(format!("{name}.ply"));
    write_scan(
        &ply,
        ScanFormat::Ply,
        &ScanData { xyz: &pts, rgb: &rgb, intensity: &[], normals: &[], pose: None },
    )
    .unwrap();
    let c: [f64; 3] = std::array::from_fn(|a| corner[a] + ROOM_M[a] * 0.5);
    let manifest_path = dir.join(format!("{name}.toml"));
    std::fs::write(
        &manifest_path,
        format!(
            "[[scan]]\npath = \"{}\"\norigin = [{}, {}, {}]\n\n[[light]]\nkind = \"point\"\nposition = [{}, {}, {}]\npower_w = 40.0\n",
            ply.display(),
            c[0],
            c[1],
            c[2],
            c[0] - 0.7,
            c[1] + 0.4,
            c[2] + 0.6
        ),
    )
    .unwrap();
    let manifest = Manifest::load(&manifest_path).unwrap();
    let out = dir.join(format!("{name}.grotto"));
    // One 8 m tile holds the room.
    let bp = BuildParams {
        memory_budget_bytes: 256 << 20,
        ..small_build(&dir.join(format!("{name}.work")), 8.0, 8.0, 0.5)
    };
    build::build(&manifest, &manifest_path, &out, &bp, &|_| {}).unwrap();
    out
}

#[test]
fn moving_the_leaf_grid_under_a_room_changes_its_first_bounce_by_under_one_percent() {
    let gpu = Gpu::new(&GpuOptions { prefer_software: true, ..Default::default() }).unwrap();
    let dir = tempfile::tempdir().unwrap();
    let base = [1.0, 1.0, 1.0];
    let mut results = Vec::new();
    // On leaf boundaries, then moved by 0.4, 0.5 and 0.3 of a leaf per axis.
    for (name, shift) in [("aligned", [0.0; 3]), ("moved", [0.05, 0.0625, 0.0375])] {
        let corner: [f64; 3] = std::array::from_fn(|a| base[a] + shift[a]);
        let pkg = Package::open(build_room(dir.path(), name, corner)).unwrap();
        let scene = SceneData::from_package(&pkg).unwrap();
        let c = Vec3::from_array(std::array::from_fn(|a| (corner[a] + ROOM_M[a] * 0.5) as f32));
        let cam = Camera { eye_m: c, look_at_m: c + Vec3::new(1.0, 0.3, -0.2), up: Vec3::Z, fov_y_deg: 80.0 };
        let mut row = Vec::new();
        for bounces in [0u32, 1] {
            let settings = Settings {
                bounces,
                exposure: 1.0,
                ..Settings::preset(grotto_runtime::settings::Quality::High)
            };
            let mut r = Renderer::new(&gpu, &scene, settings).unwrap();
            r.settle(|_, _| {}).unwrap();
            let (frame, _) = r.render(&cam, 96, 72).unwrap();
            let mean =
                frame.hdr.iter().map(|p| f64::from(p[0] + p[1] + p[2])).sum::<f64>() / frame.hdr.len() as f64;
            row.push(mean);
        }
        eprintln!(
            "room {name}: mean radiance direct {:.5}, direct + one bounce {:.5}, indirect share {:.3}",
            row[0],
            row[1],
            (row[1] - row[0]) / row[1]
        );
        results.push(row);
    }
    let indirect = |r: &Vec<f64>| r[1] - r[0];
    let direct_change = (results[1][0] / results[0][0] - 1.0).abs();
    let indirect_change = (indirect(&results[1]) / indirect(&results[0]) - 1.0).abs();
    eprintln!(
        "moving the grid changes direct light by {:.2}%, the first bounce by {:.2}%",
        direct_change * 100.0,
        indirect_change * 100.0
    );
    // Direct light comes from shadow maps and surfels, which do not depend on the grid.
    assert!(direct_change < 0.005, "direct light moved by {:.2}%", direct_change * 100.0);
    // Measured 0.17% (4.03% with leaves at their cells' centres).
    assert!(indirect_change < 0.01, "the first bounce moved by {:.2}%", indirect_change * 100.0);
}
