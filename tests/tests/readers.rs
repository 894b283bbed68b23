//! Every scan file in ../shared/data reads with the right point count and bounds, or fails with a
//! typed error naming the file; hostile variants (lying counts, truncation, flipped bytes) never
//! panic or allocate for what the file cannot hold.

use std::path::{Path, PathBuf};

use grotto_preprocess::Error;
use grotto_preprocess::ingest::{self, PointChunk, ScanFormat};
use grotto_tests::shared_data_dir;

struct Read {
    scans: Vec<(u64, [f64; 3], [f64; 3])>,
    has_color: bool,
}

fn read(path: &Path) -> grotto_preprocess::Result<Read> {
    let format = ScanFormat::detect(path)?;
    let mut scans = Vec::new();
    let mut has_color = false;
    for i in 0..ingest::scan_count(path, format)? {
        let mut src = ingest::open(path, format, i)?;
        has_color |= src.info().has_color;
        let mut chunk = PointChunk::new(1000);
        let (mut n, mut lo, mut hi) = (0u64, [f64::INFINITY; 3], [f64::NEG_INFINITY; 3]);
        while src.fill_chunk(&mut chunk)? > 0 {
            assert_eq!(chunk.rgb.len(), chunk.len());
            assert!(chunk.normal.is_empty() || chunk.normal.len() == chunk.len());
            n += chunk.len() as u64;
            for p in &chunk.xyz {
                for a in 0..3 {
                    lo[a] = lo[a].min(p[a]);
                    hi[a] = hi[a].max(p[a]);
                }
            }
        }
        assert!(n <= src.info().claimed_points, "{}: read more than claimed", path.display());
        scans.push((n, lo, hi));
    }
    Ok(Read { scans, has_color })
}

fn files(data: &Path) -> Vec<PathBuf> {
    let mut out = Vec::new();
    let mut stack = vec![data.join("las"), data.join("ply"), data.join("e57")];
    while let Some(dir) = stack.pop() {
        for e in std::fs::read_dir(&dir).unwrap() {
            let p = e.unwrap().path();
            if p.is_dir() {
                stack.push(p);
            } else if matches!(p.extension().and_then(|e| e.to_str()), Some("las" | "laz" | "ply" | "e57")) {
                out.push(p);
            }
        }
    }
    out.sort();
    out
}

/// (file name, points per scan) for files whose counts are known from their provenance, and the
/// files that must fail (with a word the message must contain).
const EXPECTED: &[(&str, &[u64])] = &[
    ("e57rs_bunnyDouble.e57", &[30571]),
    ("e57rs_bunnyInt19.e57", &[30571]),
    // Two of its three points are flagged invalid.
    ("e57rs_cartesian_invalid_state_single.e57", &[1]),
    ("e57rs_empty.e57", &[]),
    ("e57rs_tinyCartesianFloatRgb.e57", &[2090]),
    ("pdal_A_B.e57", &[2, 4]),
    ("pdal_A_B_different_dims.e57", &[1, 1]),
    ("pye57_translationWithoutRotation.e57", &[4]),
    ("laspy_simple.las", &[1065]),
    ("laspy_simple.laz", &[1065]),
    ("laspy_1_4_w_evlr.las", &[1000]),
    ("laspy_simple1_4.las", &[22600]),
    ("pdal_autzen_trim.laz", &[110000]),
    ("pdal_no-points.las", &[0]),
    ("bun000.ply", &[40256]),
    ("bun_zipper.ply", &[35947]),
    ("greg_turk_example2_ok_ascii.ply", &[8]),
    ("house_2_ok_little_endian.ply", &[5]),
    ("empty_2_ok_little_endian.ply", &[0]),
    ("trimesh_points_ascii_with_lists.ply", &[5]),
];
const MUST_FAIL: &[(&str, &str)] = &[
    ("libe57fmt_ZeroPointsInvalid.e57", "E57"),
    ("lazrs_point-version-1-point-wise.laz", "point-wise"),
    ("sized_dims.ply", "no z"),
    ("all_atomic_types_ok_ascii.ply", "no vertex element"),
    ("single_elements_err_ascii.ply", "no vertex element"),
];

#[test]
fn every_shared_scan_reads_or_fails_with_a_typed_error() {
    let Some(data) = shared_data_dir() else { return };
    let all = files(&data);
    assert!(all.len() > 40, "expected the shared data set, found {} files", all.len());
    for path in &all {
        let name = path.file_name().unwrap().to_str().unwrap();
        match (read(path), MUST_FAIL.iter().find(|f| f.0 == name)) {
            (Ok(r), None) => {
                if let Some((_, counts)) = EXPECTED.iter().find(|e| e.0 == name) {
                    let got: Vec<u64> = r.scans.iter().map(|s| s.0).collect();
                    assert_eq!(&got, counts, "{name}");
                }
                if path.extension().unwrap() != "e57" {
                    assert_eq!(r.scans.len(), 1, "{name}");
                }
            }
            (Err(e), Some((_, word))) => {
                let msg = e.to_string();
                assert!(matches!(e, Error::Read { .. }), "{name}: {e:?}");
                assert!(msg.contains(name) && msg.contains(word), "{name}: {msg}");
            }
            (Ok(_), Some(_)) => panic!("{name} should have failed"),
            (Err(e), None) => panic!("{name}: {e}"),
        }
    }
}

#[test]
fn las_points_lie_within_their_header_bounds_and_colours_scale() {
    let Some(data) = shared_data_dir() else { return };
    for name in ["laspy_simple.las", "laspy_simple1_4.las", "pdal_autzen_trim.laz", "lazrs_point-color.las"] {
        let path = data.join("las").join(name);
        let header = las::Reader::from_path(&path).unwrap().header().bounds();
        let r = read(&path).unwrap();
        let (_, lo, hi) = r.scans[0];
        let eps = 0.01;
        assert!(lo[0] >= header.min.x - eps && hi[0] <= header.max.x + eps, "{name} x");
        assert!(lo[1] >= header.min.y - eps && hi[1] <= header.max.y + eps, "{name} y");
        assert!(lo[2] >= header.min.z - eps && hi[2] <= header.max.z + eps, "{name} z");
        assert!(r.has_color, "{name}");
    }
    // 16-bit colours are scaled down, not clipped: a 16-bit file has mid-range values.
    let path = data.join("las/pdal_autzen_trim.laz");
    let mut src = ingest::open(&path, ScanFormat::Laz, 0).unwrap();
    let all = ingest::read_all(src.as_mut()).unwrap();
    let mean: f64 = all.rgb.iter().map(|c| f64::from(c[0])).sum::<f64>() / all.rgb.len() as f64;
    let saturated = all.rgb.iter().filter(|c| c[0] == 255).count() as f64 / all.rgb.len() as f64;
    assert!(mean > 30.0 && mean < 230.0 && saturated < 0.05, "mean {mean}, saturated {saturated}");
    // Read in small chunks the probe is still the first 2^20 points, not the first chunk: a file
    // whose 16-bit colours start after its first chunk (a probe of one chunk would take it as
    // 8-bit); and a source opened for positions alone (no probe) reads the same positions.
    let dir = tempfile::tempdir().unwrap();
    let late = dir.path().join("late-16-bit.las");
    let mut builder = las::Builder::from((1, 2));
    builder.point_format = las::point::Format::new(2).unwrap();
    let mut w = las::Writer::from_path(&late, builder.into_header().unwrap()).unwrap();
    for i in 0..3000u16 {
        let c = if i < 2000 { 100 } else { 100 * 257 };
        let color = Some(las::Color { red: c, green: c, blue: c });
        w.write_point(las::Point { x: f64::from(i), color, ..las::Point::default() }).unwrap();
    }
    w.close().unwrap();
    let whole = ingest::read_all(ingest::open(&late, ScanFormat::Las, 0).unwrap().as_mut()).unwrap();
    let mut small = ingest::open(&late, ScanFormat::Las, 0).unwrap();
    let mut chunk = PointChunk::new(1000);
    let mut rgb = Vec::new();
    while small.fill_chunk(&mut chunk).unwrap() > 0 {
        rgb.extend_from_slice(&chunk.rgb);
    }
    assert_eq!(rgb, whole.rgb);
    assert_eq!(whole.rgb[2999], [100; 3], "16-bit colours scaled down");
    let positions =
        ingest::read_all(ingest::open_positions(&path, ScanFormat::Laz, 0).unwrap().as_mut()).unwrap();
    assert_eq!(positions.xyz, all.xyz);
}

#[test]
fn las_and_laz_pairs_read_identically() {
    let Some(data) = shared_data_dir() else { return };
    for stem in ["laspy_simple", "laspy_1_4_w_evlr", "lazrs_extra-bytes"] {
        let las = data.join(format!("las/{stem}.las"));
        let laz = data.join(format!("las/{stem}.laz"));
        let a = ingest::read_all(ingest::open(&las, ScanFormat::Las, 0).unwrap().as_mut()).unwrap();
        let b = ingest::read_all(ingest::open(&laz, ScanFormat::Laz, 0).unwrap().as_mut()).unwrap();
        assert_eq!(a.xyz, b.xyz, "{stem}");
        assert_eq!(a.rgb, b.rgb, "{stem}");
    }
}

fn scratch(dir: &Path, name: &str, bytes: &[u8]) -> PathBuf {
    let p = dir.join(name);
    std::fs::write(&p, bytes).unwrap();
    p
}

#[test]
fn lying_point_counts_are_refused_without_allocating_for_them() {
    let Some(data) = shared_data_dir() else { return };
    let dir = tempfile::tempdir().unwrap();
    // LAS 1.2: legacy point count at byte 107; 1.4 also has a 64-bit count at 247.
    let mut las = std::fs::read(data.join("las/laspy_simple.las")).unwrap();
    las[107..111].copy_from_slice(&1_000_000_000u32.to_le_bytes());
    let p = scratch(dir.path(), "billion.las", &las);
    let e = read(&p).err().expect("a billion points in a small file");
    assert!(e.to_string().contains("billion.las") && e.to_string().contains("holds at most"), "{e}");

    // An EVLR whose length field claims 7e18 bytes (found by fuzzing: the las crate would try to
    // allocate it and abort). LAS 1.4: start of first EVLR at byte 235, its length at +20.
    let mut evlr = std::fs::read(data.join("las/laspy_1_4_w_evlr.las")).unwrap();
    let start = u64::from_le_bytes(evlr[235..243].try_into().unwrap()) as usize;
    evlr[start + 20..start + 28].copy_from_slice(&7_277_819_231_498_939_031u64.to_le_bytes());
    let e = read(&scratch(dir.path(), "evlr.las", &evlr)).err().expect("lying EVLR length");
    assert!(e.to_string().contains("EVLR 0 claims") && e.to_string().contains("evlr.las"), "{e}");
    let mut vlr = std::fs::read(data.join("las/pdal_lots_of_vlr.las")).unwrap();
    let header_size = usize::from(u16::from_le_bytes(vlr[94..96].try_into().unwrap()));
    vlr[header_size + 20..header_size + 22].copy_from_slice(&u16::MAX.to_le_bytes());
    assert!(read(&scratch(dir.path(), "vlr.las", &vlr)).is_err());

    // A LAZ chunk table claiming 3.7e9 chunks (found by fuzzing: 58 GB allocation in laz).
    let mut chunks = std::fs::read(data.join("las/laspy_simple.laz")).unwrap();
    let points_at = u32::from_le_bytes(chunks[96..100].try_into().unwrap()) as usize;
    let table = i64::from_le_bytes(chunks[points_at..points_at + 8].try_into().unwrap()) as usize;
    chunks[table + 4..table + 8].copy_from_slice(&3_669_783_654u32.to_le_bytes());
    let e = read(&scratch(dir.path(), "chunks.laz", &chunks)).err().expect("lying chunk count");
    assert!(e.to_string().contains("chunk table claims"), "{e}");

    // A layered (LAS 1.4) LAZ chunk declaring a 4 GB layer (found by fuzzing: laz allocated it
    // before reading). The chunk starts after the 8-byte table offset with the first point raw
    // (the record length), then a u32 point count, then the layer sizes.
    let mut layered = std::fs::read(data.join("las/laspy_1_4_w_evlr.laz")).unwrap();
    let points_at = u32::from_le_bytes(layered[96..100].try_into().unwrap()) as usize;
    let record = usize::from(u16::from_le_bytes(layered[105..107].try_into().unwrap()));
    let first_layer = points_at + 8 + record + 4;
    layered[first_layer..first_layer + 4].copy_from_slice(&0xFFFF_FFF0u32.to_le_bytes());
    let e = read(&scratch(dir.path(), "layered.laz", &layered)).err().expect("lying layer size");
    assert!(e.to_string().contains("bytes of layers"), "{e}");

    // A LASzip VLR declaring 4e9-point chunks (found by fuzzing: laz allocated 142 GB for the
    // output of one chunk). The chunk size is at byte 12 of the VLR's data.
    let mut big_chunks = std::fs::read(data.join("las/laspy_simple.laz")).unwrap();
    let user_id = big_chunks.windows(14).position(|w| w == b"laszip encoded").unwrap();
    let chunk_size_at = user_id - 2 + 54 + 12;
    big_chunks[chunk_size_at..chunk_size_at + 4].copy_from_slice(&4_177_576_784u32.to_le_bytes());
    let e = read(&scratch(dir.path(), "big-chunks.laz", &big_chunks)).err().expect("lying chunk size");
    assert!(e.to_string().contains("chunk size"), "{e}");

    let mut laz = std::fs::read(data.join("las/laspy_simple.laz")).unwrap();
    laz[107..111].copy_from_slice(&1_000_000_000u32.to_le_bytes());
    let p = scratch(dir.path(), "billion.laz", &laz);
    assert!(read(&p).is_err());

    let ply = b"ply\nformat binary_little_endian 1.0\nelement vertex 1000000000\nproperty float x\nproperty float y\nproperty float z\nend_header\n\0\0\0\0\0\0\0\0\0\0\0\0";
    let p = scratch(dir.path(), "billion.ply", ply);
    let e = read(&p).err().unwrap();
    assert!(e.to_string().contains("more than the"), "{e}");
    let ply = b"ply\nformat ascii 1.0\nelement vertex 1000000000\nproperty float x\nproperty float y\nproperty float z\nend_header\n1 2 3\n4 5 6\n";
    let e = read(&scratch(dir.path(), "billion-ascii.ply", ply)).err().unwrap();
    assert!(e.to_string().contains("vertex 2 of 1000000000"), "{e}");
}

#[test]
fn damaged_files_never_panic() {
    let Some(data) = shared_data_dir() else { return };
    let dir = tempfile::tempdir().unwrap();
    let picks = [
        "las/laspy_simple.las",
        "las/laspy_simple.laz",
        "las/laspy_1_4_w_evlr.laz",
        "ply/pdal/simple_binary.ply",
        "ply/ply-rs/house_ok_ascii.ply",
        "ply/assimp_points.ply",
        "e57/e57rs_tinyCartesianFloatRgb.e57",
        "e57/pdal_A_B.e57",
    ];
    let mut x = 0x2545_f491_4f6c_dd1du64;
    let mut rand = move || {
        x ^= x << 13;
        x ^= x >> 7;
        x ^= x << 17;
        x
    };
    for pick in picks {
        let original = std::fs::read(data.join(pick)).unwrap();
        let ext = Path::new(pick).extension().unwrap().to_str().unwrap();
        for case in 0..40 {
            let mut bytes = original.clone();
            if case % 2 == 0 {
                bytes.truncate((rand() as usize) % bytes.len());
            } else {
                for _ in 0..4 {
                    let i = (rand() as usize) % bytes.len();
                    bytes[i] = rand() as u8;
                }
            }
            let p = scratch(dir.path(), &format!("damaged.{ext}"), &bytes);
            let outcome = std::panic::catch_unwind(|| read(&p).map(|_| ()));
            assert!(outcome.is_ok(), "{pick} case {case} panicked");
        }
    }
}

#[test]
fn every_las_point_format_reads_with_colours_scaled_by_the_writers_depth() {
    let dir = tempfile::tempdir().unwrap();
    for format_id in 0u8..=10 {
        for eight_bit in [false, true] {
            let mut builder = las::Builder::from((1, 4));
            builder.point_format = las::point::Format::new(format_id).unwrap();
            builder.transforms = las::Vector {
                x: las::Transform { scale: 0.001, offset: 500_000.0 },
                y: las::Transform { scale: 0.001, offset: 5_000_000.0 },
                z: las::Transform { scale: 0.001, offset: 0.0 },
            };
            let has_color = builder.point_format.has_color;
            let header = builder.into_header().unwrap();
            let path = dir.path().join(format!("f{format_id}-{eight_bit}.las"));
            let mut w = las::Writer::from_path(&path, header).unwrap();
            let pts = [
                [500_001.5, 5_000_002.25, 12.125],
                [500_003.0, 5_000_001.0, -4.5],
                [499_999.0, 4_999_999.5, 0.0],
            ];
            let colour = |i: usize| -> [u8; 3] { [10 + i as u8 * 100, 200 - i as u8 * 50, 77] };
            for (i, p) in pts.iter().enumerate() {
                let c = colour(i).map(|v| if eight_bit { u16::from(v) } else { u16::from(v) * 257 });
                let mut point = las::Point {
                    x: p[0],
                    y: p[1],
                    z: p[2],
                    intensity: 1000 * i as u16,
                    ..las::Point::default()
                };
                if has_color {
                    point.color = Some(las::Color { red: c[0], green: c[1], blue: c[2] });
                }
                if w.header().point_format().has_gps_time {
                    point.gps_time = Some(1.0);
                }
                if w.header().point_format().has_nir {
                    point.nir = Some(0);
                }
                if w.header().point_format().has_waveform {
                    point.waveform = Some(las::raw::point::Waveform::default());
                }
                w.write_point(point).unwrap();
            }
            w.close().unwrap();
            let got = ingest::read_all(ingest::open(&path, ScanFormat::Las, 0).unwrap().as_mut()).unwrap();
            assert_eq!(got.xyz.len(), 3, "format {format_id}");
            for (i, p) in pts.iter().enumerate() {
                for (got, want) in got.xyz[i].iter().zip(p) {
                    assert!((got - want).abs() < 1e-6, "format {format_id}");
                }
                if has_color {
                    assert_eq!(got.rgb[i], colour(i), "format {format_id}, 8-bit {eight_bit}");
                }
            }
        }
    }
}

#[test]
fn ply_headers_as_people_write_them_read() {
    // Spaces after the magic word and after property names (PDAL's simple_text.ply writes
    // "ply \n" and "property float z \n"), comments and obj_info lines anywhere in the header,
    // CRLF line ends, tabs, and data lines with leading and trailing blanks: all the same three
    // points.
    let dir = tempfile::tempdir().unwrap();
    let variants: [(&str, &[u8]); 4] = [
        (
            "trailing-spaces.ply",
            b"ply \nformat ascii 1.0\nelement vertex 3\nproperty float x\nproperty float y\nproperty float z \n\
              end_header\n-1 0 0\n 0 1 0\n 1 0 2 \n",
        ),
        (
            "comments.ply",
            b"ply\ncomment written by hand\nformat ascii 1.0\nobj_info scanner: none\nelement vertex 3\n\
              comment between element and properties\nproperty float x  \nproperty float y\t\nproperty float z\n\
              comment right before the end\nend_header\n-1 0 0\n0 1 0\n1 0 2\n",
        ),
        (
            "crlf.ply",
            b"ply\r\nformat ascii 1.0\r\nelement vertex 3\r\nproperty double x\r\nproperty double y\r\n\
              property double z\r\nend_header\r\n-1 0 0\r\n0 1 0\r\n1 0 2\r\n",
        ),
        (
            "tabs.ply",
            b"ply\t\nformat ascii 1.0\nelement vertex 3\nproperty\tfloat\tx\nproperty float y\nproperty float z\n\
              end_header\n-1\t0\t0\n0\t1\t0\n1\t0\t2\n",
        ),
    ];
    for (name, bytes) in variants {
        let path = scratch(dir.path(), name, bytes);
        let r = read(&path).unwrap_or_else(|e| panic!("{name}: {e}"));
        assert_eq!(r.scans.len(), 1, "{name}");
        let (n, lo, hi) = r.scans[0];
        assert_eq!((n, lo, hi), (3, [-1.0, 0.0, 0.0], [1.0, 1.0, 2.0]), "{name}");
    }
    // Lenient only where writers differ: a header that is not PLY is still refused, by name.
    let bad = scratch(dir.path(), "plywood.ply", b"plywood\nformat ascii 1.0\nend_header\n");
    let e = read(&bad).err().expect("not a PLY file");
    assert!(e.to_string().contains("plywood.ply"), "{e}");
}

#[test]
fn e57_surface_normals_extension_reads_as_normals() {
    // Two writers of the extension: libE57Format's test file (the e57 crate's copy) and
    // CloudCompare's, whose namespace URI differs (pye57's test data). Each point's normal is a
    // unit vector distinct from its position, so reading coordinates or a wrong record fails.
    let Some(data) = shared_data_dir() else { return };
    for (name, points) in [("e57rs_tiny_pc_with_extension.e57", 1), ("pye57_testWithNormals.e57", 2)] {
        let path = data.join("e57").join(name);
        let mut src = ingest::open(&path, ScanFormat::E57, 0).unwrap();
        assert!(src.info().has_normals, "{name}: the header announces normals");
        let mut chunk = PointChunk::new(16);
        let (mut xyz, mut normals) = (Vec::new(), Vec::new());
        while src.fill_chunk(&mut chunk).unwrap() > 0 {
            xyz.extend_from_slice(&chunk.xyz);
            normals.extend_from_slice(&chunk.normal);
        }
        eprintln!("{name}: points {xyz:?}, normals {normals:?}");
        assert_eq!((xyz.len(), normals.len()), (points, points), "{name}");
        for (p, n) in xyz.iter().zip(&normals) {
            let len = n.iter().map(|c| c * c).sum::<f32>().sqrt();
            assert!((len - 1.0).abs() < 1e-3, "{name}: normal {n:?} is not unit length");
            assert!(
                p.iter().zip(n).any(|(a, b)| (*a as f32 - b).abs() > 1e-3),
                "{name}: normal equals position"
            );
        }
    }
    // A scan without the extension has none.
    let src = ingest::open(&data.join("e57/e57rs_bunnyInt19.e57"), ScanFormat::E57, 0).unwrap();
    assert!(!src.info().has_normals);
}
