//! A tiny analytic package: a spherical chamber at survey coordinates, sampled directly (no scans,
//! no tiling), used by tests as a fast, exactly known fixture. The README's demo is the synthetic
//! cave (`grotto-pack demo`, see `synth.rs`).
//!
//! Points lie on a sphere of `radius_m` around a centre with UTM-sized coordinates (the hard case
//! for precision), spread evenly by a Fibonacci lattice, with normals pointing into the chamber
//! (towards the scanner at the centre) and banded limestone colours. They are binned into cubic
//! tiles of a global power-of-two grid, stored tile-relative in f32 and sorted in Morton order.
//! Because the surface is known exactly, tests can check what survives the package to the
//! millimetre.

use std::collections::BTreeMap;
use std::path::Path;

use grotto_format::spec::{Rgba8, Surfel};
use grotto_format::svo::morton_encode;
use grotto_format::*;

use crate::{Error, Result};

/// What to build.
#[derive(Clone, Debug)]
pub struct DemoParams {
    pub points: u64,
    pub radius_m: f64,
    pub center_m: [f64; 3],
    /// Edge of a tile: a power of two, metres.
    pub tile_extent_m: f64,
    /// SVO depth declared for each tile.
    pub depth: u32,
}

impl Default for DemoParams {
    fn default() -> Self {
        Self {
            points: 50_000,
            radius_m: 6.0,
            center_m: [512_345.25, 5_123_456.75, 345.5],
            tile_extent_m: 8.0,
            depth: 7,
        }
    }
}

/// What was built.
#[derive(Clone, Debug, serde::Serialize)]
pub struct DemoSummary {
    pub(crate) path: String,
    pub(crate) points: u64,
    pub tiles: u32,
    pub(crate) bytes: u64,
}

/// The exact surface point `i` of `n`, its inward unit normal, and its sRGB colour.
pub(crate) fn sample(params: &DemoParams, i: u64, n: u64) -> ([f64; 3], [f64; 3], [u8; 4]) {
    let golden = std::f64::consts::PI * (3.0 - 5f64.sqrt());
    let z = 1.0 - 2.0 * (i as f64 + 0.5) / n as f64;
    let r = (1.0 - z * z).sqrt();
    let phi = golden * i as f64;
    let dir = [r * phi.cos(), r * phi.sin(), z];
    let p = std::array::from_fn(|a| params.center_m[a] + params.radius_m * dir[a]);
    // Sediment bands by height, a little variation along the azimuth.
    let band = ((z * 9.0).sin() * 0.5 + 0.5) * 0.6 + 0.4 * (phi * 3.0).cos().abs();
    let grey = 120.0 + 90.0 * band;
    let color = [grey as u8, (grey * 0.92) as u8, (grey * 0.8) as u8, 255];
    (p, dir.map(|d| -d), color)
}

/// Builds the demo package at `out` (atomically).
pub fn build(out: &Path, params: &DemoParams) -> Result<DemoSummary> {
    if params.points == 0 || params.points > 100_000_000 {
        return Err(Error::Parameter {
            name: "points",
            reason: format!("{} is not in 1..=1e8", params.points),
        });
    }
    let e = params.tile_extent_m;
    if !(e > 0.0 && e.log2().fract() == 0.0) {
        return Err(Error::Parameter { name: "tile_extent_m", reason: format!("{e} is not a power of two") });
    }
    if params.depth > spec::MAX_SVO_DEPTH {
        return Err(Error::Parameter {
            name: "depth",
            reason: format!("{} exceeds {}", params.depth, spec::MAX_SVO_DEPTH),
        });
    }
    // Area per point -> disc radius that covers it.
    let radius_m = (2.0 * params.radius_m / (params.points as f64).sqrt()) as f32;
    let mut tiles: BTreeMap<[i64; 3], Vec<(u64, Surfel, Rgba8)>> = BTreeMap::new();
    for i in 0..params.points {
        let (p, n, c) = sample(params, i, params.points);
        let key = p.map(|v| (v / e).floor() as i64);
        // f64 until the point is inside its tile; only the tile-local offset becomes f32.
        let local = std::array::from_fn(|a| p[a] - key[a] as f64 * e);
        let q = local.map(|v| ((v / e) * f64::from(1u32 << 16)).clamp(0.0, 65_535.0) as u32);
        let surfel = Surfel {
            position_tile_m: local.map(|v| v as f32),
            radius_m,
            normal: n.map(|v| v as f32),
            spread: 0.0,
        };
        tiles.entry(key).or_default().push((morton_encode(q[0], q[1], q[2]), surfel, Rgba8(c)));
    }
    let mut w = PackageWriter::create(out)?;
    for (key, mut points) in tiles {
        points.sort_by_key(|p| p.0);
        let tile = w.add_tile(TileInfo {
            origin_m: key.map(|k| k as f64 * e),
            extent_m: e,
            grid: grid_of(key)?,
            depth: params.depth,
            point_count: points.len() as u64,
        })?;
        let surfels: Vec<Surfel> = points.iter().map(|p| p.1).collect();
        let colors: Vec<Rgba8> = points.iter().map(|p| p.2).collect();
        w.add_elements(SectionKind::Surfels, Scope::Tile(tile), 0, &surfels, Compression::Raw)?;
        w.add_elements(SectionKind::SurfelColorsRaw, Scope::Tile(tile), 0, &colors, Compression::Auto(3))?;
    }
    let c = params.center_m;
    w.add_scene(&Scene {
        lights: vec![Light {
            name: "lantern".into(),
            shape: LightShape::Point { position_m: [c[0] + 1.0, c[1] - 0.5, c[2] + 1.5] },
            color: [1.0, 0.85, 0.7],
            power_w: 40.0,
            circuit: None,
            profile: None,
        }],
        cameras: vec![Camera {
            name: "centre".into(),
            eye_m: [c[0] - 0.5 * params.radius_m, c[1], c[2]],
            look_at_m: [c[0] + params.radius_m, c[1], c[2] - 0.2 * params.radius_m],
            up: [0.0, 0.0, 1.0],
            fov_y_deg: 70.0,
        }],
        ..Scene::default()
    })?;
    w.add_provenance(&Provenance {
        tool: "grotto-pack demo".into(),
        tool_version: env!("CARGO_PKG_VERSION").into(),
        inputs: Vec::new(),
        parameters: [
            ("points".to_string(), serde_json::json!(params.points)),
            ("radius_m".to_string(), serde_json::json!(params.radius_m)),
            ("center_m".to_string(), serde_json::json!(params.center_m)),
            ("tile_extent_m".to_string(), serde_json::json!(params.tile_extent_m)),
            ("depth".to_string(), serde_json::json!(params.depth)),
        ]
        .into(),
    })?;
    let path = w.finish()?;
    let pkg = Package::open(&path)?;
    Ok(DemoSummary {
        path: path.display().to_string(),
        points: params.points,
        tiles: pkg.tile_count(),
        bytes: pkg.file_size(),
    })
}

fn grid_of(key: [i64; 3]) -> Result<[i32; 3]> {
    let conv = |k: i64| {
        i32::try_from(k).map_err(|_| Error::Parameter {
            name: "center_m",
            reason: format!("tile index {k} is outside the grid"),
        })
    };
    Ok([conv(key[0])?, conv(key[1])?, conv(key[2])?])
}
