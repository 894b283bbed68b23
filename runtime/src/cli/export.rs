//! `grotto export PACKAGE --points OUT`: the merged points with their estimated normals, colours,
//! radii and spread, in world coordinates, so CloudCompare, PDAL or any other tool can check and
//! reuse them.
//!
//! - PLY (binary little endian): `double x y z`, `float nx ny nz radius spread`, `uchar red green
//!   blue`.
//! - LAS 1.4, point format 7 (RGB), 0.1 mm resolution around the package's centre; normals,
//!   radius and spread as Extra Bytes (float32) described in the standard Extra Bytes VLR, which
//!   PDAL and CloudCompare read as named dimensions.
//!
//! The output appears atomically (temp file + rename). Colours stored as BC1 are decoded.

use std::fs::File;
use std::io::{BufWriter, Write};
use std::path::Path;

use grotto_format::Package;
use grotto_format::spec::Surfel;

use crate::Error;

/// What was exported.
#[derive(Debug, serde::Serialize)]
pub struct ExportSummary {
    pub path: String,
    pub points: u64,
    pub tiles: u32,
}

struct Point {
    world: [f64; 3],
    surfel: Surfel,
    rgb: [u8; 3],
}

fn points(pkg: &Package) -> Result<Vec<Point>, Error> {
    let mut out = Vec::new();
    for tile in pkg.tiles() {
        let Some(surfels) = tile.surfels()? else { continue };
        let mut colors = crate::scene::data::tile_colors(&tile, surfels.len())?;
        colors.resize(surfels.len(), [180; 3]);
        let o = tile.origin_m();
        for (s, c) in surfels.iter().zip(colors) {
            out.push(Point {
                world: std::array::from_fn(|a| o[a] + f64::from(s.position_tile_m[a])),
                surfel: *s,
                rgb: c,
            });
        }
    }
    Ok(out)
}

/// The typed error for an output file that could not be written.
pub fn output_error(path: &Path, e: impl std::fmt::Display) -> Error {
    Error::Output { path: path.display().to_string(), reason: e.to_string() }
}

/// Writes `bytes` to `out` atomically (see [`atomically`]).
pub fn write_atomically(out: &Path, bytes: &[u8]) -> Result<(), Error> {
    atomically(out, |mut f| f.write_all(bytes).map_err(|e| output_error(out, e)))
}

/// Writes `out` by `fill` into a temp file beside it, then renames it into place. Every output
/// of the runtime and the reference goes through here.
pub(crate) fn atomically(out: &Path, fill: impl FnOnce(File) -> Result<(), Error>) -> Result<(), Error> {
    let dir = out.parent().filter(|p| !p.as_os_str().is_empty()).unwrap_or(Path::new("."));
    let mut builder = tempfile::Builder::new();
    builder.suffix(".partial");
    #[cfg(unix)]
    builder.permissions(std::os::unix::fs::PermissionsExt::from_mode(0o666));
    let (file, temp) = builder.tempfile_in(dir).map_err(|e| output_error(out, e))?.into_parts();
    fill(file)?;
    temp.persist(out).map_err(|e| output_error(out, e.error))?;
    Ok(())
}

/// Writes every surfel of `pkg` to `out` (PLY or LAS by extension) in world coordinates.
pub fn export_points(pkg: &Package, out: &Path) -> Result<ExportSummary, Error> {
    let ext = out.extension().and_then(|e| e.to_str()).map(str::to_ascii_lowercase);
    if !matches!(ext.as_deref(), Some("ply" | "las")) {
        return Err(Error::Extension { path: out.display().to_string() });
    }
    let pts = points(pkg)?;
    match ext.as_deref() {
        Some("ply") => atomically(out, |f| write_ply(out, f, &pts))?,
        _ => atomically(out, |f| write_las(out, f, &pts))?,
    }
    Ok(ExportSummary { path: out.display().to_string(), points: pts.len() as u64, tiles: pkg.tile_count() })
}

fn write_ply(path: &Path, file: File, pts: &[Point]) -> Result<(), Error> {
    let err = |e: std::io::Error| output_error(path, e);
    let mut w = BufWriter::with_capacity(1 << 20, file);
    write!(
        w,
        "ply\nformat binary_little_endian 1.0\ncomment exported by grotto {}\nelement vertex {}\n\
         property double x\nproperty double y\nproperty double z\n\
         property float nx\nproperty float ny\nproperty float nz\nproperty float radius\nproperty float spread\n\
         property uchar red\nproperty uchar green\nproperty uchar blue\nend_header\n",
        env!("CARGO_PKG_VERSION"),
        pts.len()
    )
    .map_err(err)?;
    for p in pts {
        for v in p.world {
            w.write_all(&v.to_le_bytes()).map_err(err)?;
        }
        let s = &p.surfel;
        for v in [s.normal[0], s.normal[1], s.normal[2], s.radius_m, s.spread] {
            w.write_all(&v.to_le_bytes()).map_err(err)?;
        }
        w.write_all(&p.rgb).map_err(err)?;
    }
    w.flush().map_err(err)
}

/// One Extra Bytes descriptor (LAS 1.4 R15, table 24): a named float32 dimension.
fn extra_bytes_descriptor(name: &str, description: &str) -> [u8; 192] {
    let mut d = [0u8; 192];
    d[2] = 9; // data type 9: float
    d[4..4 + name.len().min(32)].copy_from_slice(&name.as_bytes()[..name.len().min(32)]);
    d[160..160 + description.len().min(32)]
        .copy_from_slice(&description.as_bytes()[..description.len().min(32)]);
    d
}

const EXTRA: [(&str, &str); 5] = [
    ("NormalX", "unit normal, x"),
    ("NormalY", "unit normal, y"),
    ("NormalZ", "unit normal, z"),
    ("Radius", "surfel radius, metres"),
    ("Spread", "1 - |mean of unit normals|"),
];

fn write_las(path: &Path, file: File, pts: &[Point]) -> Result<(), Error> {
    let err = |e: las::Error| output_error(path, e);
    let mut lo = [f64::INFINITY; 3];
    let mut hi = [f64::NEG_INFINITY; 3];
    for p in pts {
        for a in 0..3 {
            lo[a] = lo[a].min(p.world[a]);
            hi[a] = hi[a].max(p.world[a]);
        }
    }
    let centre: [f64; 3] =
        std::array::from_fn(|a| if lo[a].is_finite() { ((lo[a] + hi[a]) / 2.0).round() } else { 0.0 });
    let mut builder = las::Builder::from((1, 4));
    builder.point_format = las::point::Format::new(7).map_err(err)?;
    builder.point_format.extra_bytes = (EXTRA.len() * 4) as u16;
    let t = |offset| las::Transform { scale: 1e-4, offset };
    builder.transforms = las::Vector { x: t(centre[0]), y: t(centre[1]), z: t(centre[2]) };
    builder.generating_software = format!("grotto {}", env!("CARGO_PKG_VERSION"));
    builder.vlrs.push(las::Vlr {
        user_id: "LASF_Spec".into(),
        record_id: 4,
        description: "Extra bytes".into(),
        data: EXTRA.iter().flat_map(|(n, d)| extra_bytes_descriptor(n, d)).collect(),
    });
    let header = builder.into_header().map_err(err)?;
    let mut w = las::Writer::new(BufWriter::with_capacity(1 << 20, file), header).map_err(err)?;
    for p in pts {
        let s = &p.surfel;
        let extra: Vec<u8> = [s.normal[0], s.normal[1], s.normal[2], s.radius_m, s.spread]
            .iter()
            .flat_map(|v| v.to_le_bytes())
            .collect();
        w.write_point(las::Point {
            x: p.world[0],
            y: p.world[1],
            z: p.world[2],
            color: Some(las::Color {
                red: u16::from(p.rgb[0]) * 257,
                green: u16::from(p.rgb[1]) * 257,
                blue: u16::from(p.rgb[2]) * 257,
            }),
            gps_time: Some(0.0),
            extra_bytes: extra,
            ..las::Point::default()
        })
        .map_err(err)?;
    }
    w.close().map_err(err)
}
