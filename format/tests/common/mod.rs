//! Shared fixtures for the format tests: a package with every section kind, and a way to patch a
//! package's header, table and directory while keeping its checksums valid (so a test reaches the
//! check it means to reach, not the checksum in front of it).
#![allow(dead_code)]

use std::path::{Path, PathBuf};

use grotto_format::spec::*;
use grotto_format::svo::{morton_encode, nodes_from_leaves};
use grotto_format::*;
use xxhash_rust::xxh3::{Xxh3, xxh3_64};

/// The `item` a kind's sample section has: coarse levels are numbered from 1.
pub(crate) fn item_of(kind: SectionKind) -> u32 {
    match kind {
        SectionKind::CoarseNodes | SectionKind::CoarseLeaves => 1,
        _ => 0,
    }
}

/// Leaf Morton codes of the coarse level 1 of the sample tiles (depth 3): depth 2.
fn coarse_codes(seed: u32) -> Vec<u64> {
    let n = 40 + seed as usize % 7;
    let mut leaves: Vec<u64> =
        (0..n as u32).map(|i| morton_encode(i % 8, (i * 3) % 8, (i * 5 + seed) % 8) >> 3).collect();
    leaves.sort_unstable();
    leaves.dedup();
    leaves
}

/// Whether sample tile `t` holds a section of `kind`: tile 0 keeps full surfels, tile 1 compact
/// ones (a tile holds one or the other).
pub(crate) fn holds(kind: SectionKind, t: u32) -> bool {
    !matches!((kind, t), (SectionKind::Surfels, 1) | (SectionKind::SurfelsCompact, 0))
}

/// Valid content for every known kind (JSON kinds get real documents).
pub(crate) fn content(kind: SectionKind, seed: u32) -> Vec<u8> {
    let n = 40 + seed as usize % 7;
    let f = |i: usize| ((i as u32).wrapping_mul(2_654_435_761).wrapping_add(seed) % 1000) as f32 / 1000.0;
    match kind {
        SectionKind::CoarseNodes => {
            bytemuck::cast_slice(&nodes_from_leaves(&coarse_codes(seed), 2).unwrap()).to_vec()
        }
        SectionKind::CoarseLeaves => bytemuck::cast_slice(
            &(0..coarse_codes(seed).len())
                .map(|i| CoarseLeaf {
                    centroid_tile_m: [f(i) * 8.0, 1.0, 2.0],
                    opacity: f(i),
                    ndf: LeafNdf { mean: [0.0, 0.0, f(i)], weight: 2.0 },
                    emission: [0.0, f(i), 0.0],
                    albedo: Rgba8([i as u8, 2, 3, 255]),
                })
                .collect::<Vec<_>>(),
        )
        .to_vec(),
        SectionKind::RockBricks => bytemuck::cast_slice(
            &(0..5)
                .map(|i| RockBrick { brick: [i % 3 - 1, 0, 1], reserved: 0, bits: [seed + i as u32, 1 << i] })
                .collect::<Vec<_>>(),
        )
        .to_vec(),
        SectionKind::SvoNodes => {
            let mut leaves: Vec<u64> =
                (0..n as u32).map(|i| morton_encode(i % 8, (i * 3) % 8, (i * 5 + seed) % 8)).collect();
            leaves.sort_unstable();
            leaves.dedup();
            bytemuck::cast_slice(&nodes_from_leaves(&leaves, 3).unwrap()).to_vec()
        }
        SectionKind::LeafOpacity => bytemuck::cast_slice(&(0..n).map(f).collect::<Vec<f32>>()).to_vec(),
        SectionKind::LeafAlbedo | SectionKind::SurfelColorsRaw => {
            (0..n * 4).map(|i| (i as u32 + seed) as u8).collect()
        }
        SectionKind::LeafNdf => bytemuck::cast_slice(
            &(0..n).map(|i| LeafNdf { mean: [0.0, f(i) * 0.9, 0.1], weight: 3.0 }).collect::<Vec<_>>(),
        )
        .to_vec(),
        SectionKind::LeafEmission => bytemuck::cast_slice(
            &(0..n).map(|i| LeafEmission { radiance: [f(i), 2.0, 0.0], reserved: 0.0 }).collect::<Vec<_>>(),
        )
        .to_vec(),
        SectionKind::Surfels => bytemuck::cast_slice(
            &(0..n)
                .map(|i| Surfel {
                    position_tile_m: [f(i), 1.0, 2.0],
                    radius_m: 0.01,
                    normal: [0.0, 0.0, 1.0],
                    spread: 0.1,
                })
                .collect::<Vec<_>>(),
        )
        .to_vec(),
        SectionKind::SurfelsCompact => {
            let surfels: Vec<Surfel> = bytemuck::pod_collect_to_vec(&content(SectionKind::Surfels, seed));
            // The sample tiles: 8 m, depth 3.
            compact::encode(&surfels, 1.0, 3, 0.001).unwrap()
        }
        SectionKind::SurfelScans => {
            bytemuck::cast_slice(&(0..n).map(|i| (i / 3) as u16 + seed as u16).collect::<Vec<u16>>()).to_vec()
        }
        SectionKind::SurfelColorsBc1 => (0..n * 8).map(|i| (i as u32 * 7 + seed) as u8).collect(),
        SectionKind::EnvSh9 => {
            bytemuck::bytes_of(&ShRgb9 { coeffs: [[f(seed as usize), 0.5, 0.25]; 9] }).to_vec()
        }
        SectionKind::EnvMipLevels => {
            let levels =
                [(8u32, 4u32, 0u32, 2u32), (4, 2, 2, 1)].map(|(width, height, first_block, block_count)| {
                    EnvMipLevel {
                        width,
                        height,
                        first_block,
                        block_count,
                        roughness: first_block as f32 / 2.0,
                        reserved: [0; 3],
                    }
                });
            bytemuck::cast_slice(&levels).to_vec()
        }
        SectionKind::EnvMipBc6h => (0..3 * 16).map(|i| i as u8 ^ seed as u8).collect(),
        SectionKind::Scene => serde_json::to_vec(&sample_scene()).unwrap(),
        SectionKind::Provenance => serde_json::to_vec(&Provenance {
            tool: "grotto-test".into(),
            tool_version: "0".into(),
            inputs: vec![InputFile { path: "a.las".into(), bytes: 10, xxh3: "00".into() }],
            parameters: [("depth".to_string(), serde_json::json!(7))].into(),
        })
        .unwrap(),
        SectionKind::Survey => serde_json::to_vec(&sample_survey(seed)).unwrap(),
    }
}

/// A centreline of two stations and a leg between them.
pub(crate) fn sample_survey(seed: u32) -> survey::Survey {
    use grotto_format::survey::{Leg, Station, Survey};
    let a = [400_000.0, 5_000_000.0, 500.0 + f64::from(seed)];
    let b = [400_010.0, 5_000_000.0, 499.0];
    Survey {
        title: "sample".into(),
        stations: [("cave.1", a), ("cave.2", b)]
            .map(|(name, position_m)| Station { name: name.into(), position_m, flags: Default::default() })
            .to_vec(),
        legs: vec![Leg {
            from_m: a,
            to_m: b,
            from: Some(0),
            to: Some(1),
            survey: "cave".into(),
            flags: Default::default(),
        }],
        ..Default::default()
    }
}

pub(crate) fn sample_scene() -> Scene {
    Scene {
        lights: vec![Light {
            name: "lamp".into(),
            shape: LightShape::Spot {
                position_m: [512_340.25, 5_123_450.5, 340.125],
                direction: [0.0, 0.0, -1.0],
                inner_angle_rad: 0.3,
                outer_angle_rad: 0.5,
            },
            color: [1.0, 0.85, 0.7],
            power_w: 40.0,
            circuit: None,
            profile: None,
        }],
        materials: vec![Material {
            name: "wet".into(),
            specular: 0.4,
            roughness: 0.2,
            ior: 1.33,
            region: Some(MaterialRegion {
                min_m: [0.0, 0.0, -5.0],
                max_m: [10.0, 10.0, 5.0],
                min_normal_z: 0.5,
            }),
        }],
        cameras: vec![Camera {
            name: "entrance".into(),
            eye_m: [512_341.0, 5_123_449.0, 341.0],
            look_at_m: [512_350.0, 5_123_455.0, 340.0],
            up: [0.0, 0.0, 1.0],
            fov_y_deg: 60.0,
        }],
        environment: Some(Environment { index: 0, intensity: 1.5, source: "sky.hdr".into() }),
        scans: vec![ScanInfo { name: "a.las".into() }, ScanInfo { name: "site.e57#1".into() }],
        pois: vec![Poi {
            name: "altar".into(),
            title: "The altar".into(),
            text: "A flowstone altar.".into(),
            position_m: [512_344.0, 5_123_452.0, 339.5],
            eye_m: [512_342.0, 5_123_450.0, 340.5],
            look_at_m: [512_344.0, 5_123_452.0, 339.5],
            fov_y_deg: 50.0,
        }],
        tours: vec![Tour {
            name: "visit".into(),
            title: "A short visit".into(),
            stops: vec![
                TourStop { camera: Some("entrance".into()), dwell_s: 3.0, ..Default::default() },
                TourStop {
                    poi: Some("altar".into()),
                    dwell_s: 5.0,
                    flight_s: Some(4.0),
                    ..Default::default()
                },
            ],
        }],
        circuits: Vec::new(),
    }
}

/// Writes a package with two tiles, every per-tile kind in each, every global kind, and one
/// unknown kind; codecs alternate. Returns its path.
pub(crate) fn sample_package(dir: &Path, codec_for: impl Fn(SectionKind, u32) -> Compression) -> PathBuf {
    let path = dir.join("sample.grotto");
    let mut w = PackageWriter::create(&path).unwrap();
    for t in 0..2u32 {
        w.add_tile(TileInfo {
            origin_m: [512_336.0 + 8.0 * f64::from(t), 5_123_448.0, 336.0],
            extent_m: 8.0,
            grid: [64_042 + t as i32, 640_431, 42],
            depth: 3,
            point_count: 1000 + u64::from(t),
        })
        .unwrap();
    }
    for kind in SectionKind::ALL {
        if kind.is_per_tile() {
            for t in (0..2).filter(|&t| holds(kind, t)) {
                w.add_section(kind, Scope::Tile(t), item_of(kind), &content(kind, t), codec_for(kind, t))
                    .unwrap();
            }
        } else {
            w.add_section(kind, Scope::Global, 0, &content(kind, 9), codec_for(kind, 9)).unwrap();
        }
    }
    w.add_raw_section(4000, Scope::Tile(1), 0, b"from the future", Compression::Raw).unwrap();
    w.finish().unwrap()
}

pub(crate) fn alternating(kind: SectionKind, t: u32) -> Compression {
    if (kind as u32 + t).is_multiple_of(2) { Compression::Zstd(3) } else { Compression::Raw }
}

pub(crate) fn header(bytes: &[u8]) -> RawHeader {
    bytemuck::pod_read_unaligned(&bytes[..size_of::<RawHeader>()])
}

/// Recomputes the header checksum in place.
pub(crate) fn reseal_header(bytes: &mut [u8]) {
    let mut h = header(bytes);
    let hs = (h.header_size as usize).min(bytes.len());
    h.header_checksum = 0;
    bytes[..size_of::<RawHeader>()].copy_from_slice(bytemuck::bytes_of(&h));
    h.header_checksum = xxh3_64(&bytes[..hs.max(size_of::<RawHeader>())]);
    bytes[..size_of::<RawHeader>()].copy_from_slice(bytemuck::bytes_of(&h));
}

/// Lets `edit` change the header, the section table and the tile directory (same counts), then
/// rewrites them and recomputes both checksums.
pub(crate) fn patch(
    bytes: &mut [u8],
    edit: impl FnOnce(&mut RawHeader, &mut [RawSectionEntry], &mut [RawTileEntry]),
) {
    let mut h = header(bytes);
    let t0 = h.section_table_offset as usize;
    let t1 = t0 + h.section_count as usize * size_of::<RawSectionEntry>();
    let d0 = h.tile_directory_offset as usize;
    let d1 = d0 + h.tile_count as usize * size_of::<RawTileEntry>();
    let mut table: Vec<RawSectionEntry> = bytemuck::pod_collect_to_vec(&bytes[t0..t1]);
    let mut tiles: Vec<RawTileEntry> = bytemuck::pod_collect_to_vec(&bytes[d0..d1]);
    edit(&mut h, &mut table, &mut tiles);
    bytes[t0..t1].copy_from_slice(bytemuck::cast_slice(&table));
    bytes[d0..d1].copy_from_slice(bytemuck::cast_slice(&tiles));
    let mut x = Xxh3::new();
    x.update(bytemuck::cast_slice(&table));
    x.update(bytemuck::cast_slice(&tiles));
    h.table_checksum = x.digest();
    bytes[..size_of::<RawHeader>()].copy_from_slice(bytemuck::bytes_of(&h));
    reseal_header(bytes);
}

/// Opens `bytes` and returns the structural problem, panicking if it opened.
pub(crate) fn open_problem(bytes: &[u8]) -> Problem {
    match Package::from_bytes("test.grotto", bytes) {
        Ok(_) => panic!("package opened but should not have"),
        Err(e) => {
            assert!(e.to_string().starts_with("test.grotto: "), "error must name the file: {e}");
            e.problem().cloned().expect("a structural problem")
        }
    }
}
