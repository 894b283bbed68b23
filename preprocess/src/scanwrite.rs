//! Writers for the scan formats grotto reads (LAS, LAZ, PLY, E57), used by `grotto-pack synth`
//! and point export. Every file is written to a temp file beside its target and renamed into
//! place, so an interrupted run never leaves a half-written scan under a real name.

use std::fs::File;
use std::io::{BufWriter, Write};
use std::path::Path;

use crate::ingest::ScanFormat;
use crate::pose::Pose;
use crate::{Error, Result};

/// Points to write, in the file's frame.
#[derive(Clone, Copy, Debug)]
pub struct ScanData<'a> {
    pub xyz: &'a [[f64; 3]],
    pub rgb: &'a [[u8; 3]],
    /// 0..=65535; may be empty.
    pub intensity: &'a [u16],
    /// Unit normals; may be empty.
    pub normals: &'a [[f32; 3]],
    /// Stored in the file where the format has a place for it (E57).
    pub pose: Option<Pose>,
}

fn write_error(path: &Path, format: ScanFormat, reason: impl std::fmt::Display) -> Error {
    Error::Read { path: path.to_path_buf(), format: format.name(), reason: format!("writing: {reason}") }
}

/// Creates `path` atomically: `fill` writes into a temp file that is renamed on success.
fn atomically(path: &Path, fill: impl FnOnce(File) -> Result<()>) -> Result<()> {
    let io = |source| Error::Io { path: path.to_path_buf(), source };
    let dir = path.parent().filter(|p| !p.as_os_str().is_empty()).unwrap_or(Path::new("."));
    let mut builder = tempfile::Builder::new();
    builder.suffix(".partial");
    // Ordinary file permissions (0666 minus the umask), not tempfile's private 0600.
    #[cfg(unix)]
    builder.permissions(std::os::unix::fs::PermissionsExt::from_mode(0o666));
    let (file, temp) = builder.tempfile_in(dir).map_err(io)?.into_parts();
    fill(file)?;
    temp.persist(path).map_err(|e| io(e.error))?;
    Ok(())
}

/// Writes `data` as one scan in `format` at `path`.
pub fn write_scan(path: &Path, format: ScanFormat, data: &ScanData<'_>) -> Result<()> {
    match format {
        ScanFormat::Las | ScanFormat::Laz => write_las(path, format, data),
        ScanFormat::Ply => write_ply(path, data),
        ScanFormat::E57 => write_e57(path, data),
    }
}

fn write_las(path: &Path, format: ScanFormat, data: &ScanData<'_>) -> Result<()> {
    let err = |e: &dyn std::fmt::Display| write_error(path, format, e);
    // 0.1 mm resolution; offsets centre the coordinates so survey-sized values keep it.
    let mut lo = [f64::INFINITY; 3];
    let mut hi = [f64::NEG_INFINITY; 3];
    for p in data.xyz {
        for a in 0..3 {
            lo[a] = lo[a].min(p[a]);
            hi[a] = hi[a].max(p[a]);
        }
    }
    let centre: [f64; 3] =
        std::array::from_fn(|a| if lo[a].is_finite() { ((lo[a] + hi[a]) / 2.0).round() } else { 0.0 });
    let mut builder = las::Builder::from((1, 2));
    builder.point_format = las::point::Format::new(2).map_err(|e| err(&e))?;
    builder.point_format.is_compressed = format == ScanFormat::Laz;
    let t = |offset| las::Transform { scale: 1e-4, offset };
    builder.transforms = las::Vector { x: t(centre[0]), y: t(centre[1]), z: t(centre[2]) };
    builder.generating_software = "grotto-pack".into();
    let header = builder.into_header().map_err(|e| err(&e))?;
    atomically(path, |file| {
        let mut w = las::Writer::new(BufWriter::new(file), header).map_err(|e| err(&e))?;
        for (i, p) in data.xyz.iter().enumerate() {
            let c = data.rgb[i].map(|v| u16::from(v) * 257);
            w.write_point(las::Point {
                x: p[0],
                y: p[1],
                z: p[2],
                intensity: data.intensity.get(i).copied().unwrap_or(0),
                color: Some(las::Color { red: c[0], green: c[1], blue: c[2] }),
                ..las::Point::default()
            })
            .map_err(|e| err(&e))?;
        }
        w.close().map_err(|e| err(&e))
    })
}

fn write_ply(path: &Path, data: &ScanData<'_>) -> Result<()> {
    let err = |e: &dyn std::fmt::Display| write_error(path, ScanFormat::Ply, e);
    atomically(path, |file| {
        let mut w = BufWriter::with_capacity(1 << 20, file);
        let normals = !data.normals.is_empty();
        let mut header = format!(
            "ply\nformat binary_little_endian 1.0\ncomment written by grotto-pack\nelement vertex {}\nproperty double x\nproperty double y\nproperty double z\n",
            data.xyz.len()
        );
        if normals {
            header += "property float nx\nproperty float ny\nproperty float nz\n";
        }
        header += "property uchar red\nproperty uchar green\nproperty uchar blue\nend_header\n";
        w.write_all(header.as_bytes()).map_err(|e| err(&e))?;
        for (i, p) in data.xyz.iter().enumerate() {
            for v in p {
                w.write_all(&v.to_le_bytes()).map_err(|e| err(&e))?;
            }
            if normals {
                for v in data.normals[i] {
                    w.write_all(&v.to_le_bytes()).map_err(|e| err(&e))?;
                }
            }
            w.write_all(&data.rgb[i]).map_err(|e| err(&e))?;
        }
        w.flush().map_err(|e| err(&e))
    })
}

fn write_e57(path: &Path, data: &ScanData<'_>) -> Result<()> {
    use e57::{Quaternion, Record, RecordValue, Transform, Translation};
    let err = |e: &dyn std::fmt::Display| write_error(path, ScanFormat::E57, e);
    let stem = path.file_stem().map(|s| s.to_string_lossy().into_owned()).unwrap_or_default();
    atomically(path, |file| {
        let mut w = e57::E57Writer::new(file, &format!("grotto-{stem}")).map_err(|e| err(&e))?;
        let prototype = vec![
            Record::CARTESIAN_X_F64,
            Record::CARTESIAN_Y_F64,
            Record::CARTESIAN_Z_F64,
            Record::COLOR_RED_U8,
            Record::COLOR_GREEN_U8,
            Record::COLOR_BLUE_U8,
            Record::INTENSITY_U16,
        ];
        {
            let mut pc = w.add_pointcloud(&format!("grotto-{stem}-scan"), prototype).map_err(|e| err(&e))?;
            pc.set_name(Some(stem.clone()));
            if let Some(pose) = data.pose {
                let q = rotation_to_quaternion(&pose.rotation);
                let t = pose.translation;
                pc.set_transform(Some(Transform {
                    rotation: Quaternion { w: q[0], x: q[1], y: q[2], z: q[3] },
                    translation: Translation { x: t[0], y: t[1], z: t[2] },
                }));
            }
            for (i, p) in data.xyz.iter().enumerate() {
                let c = data.rgb[i];
                pc.add_point(vec![
                    RecordValue::Double(p[0]),
                    RecordValue::Double(p[1]),
                    RecordValue::Double(p[2]),
                    RecordValue::Integer(i64::from(c[0])),
                    RecordValue::Integer(i64::from(c[1])),
                    RecordValue::Integer(i64::from(c[2])),
                    RecordValue::Integer(i64::from(data.intensity.get(i).copied().unwrap_or(0))),
                ])
                .map_err(|e| err(&e))?;
            }
            pc.finalize().map_err(|e| err(&e))?;
        }
        w.finalize().map_err(|e| err(&e))
    })
}

/// Unit quaternion (w, x, y, z), w >= 0, of a rotation matrix (Shepperd's method: the largest
/// diagonal term picks the stable branch).
pub(crate) fn rotation_to_quaternion(r: &[[f64; 3]; 3]) -> [f64; 4] {
    let tr = r[0][0] + r[1][1] + r[2][2];
    let q = if tr > 0.0 {
        let s = (tr + 1.0).sqrt() * 2.0;
        [0.25 * s, (r[2][1] - r[1][2]) / s, (r[0][2] - r[2][0]) / s, (r[1][0] - r[0][1]) / s]
    } else if r[0][0] > r[1][1] && r[0][0] > r[2][2] {
        let s = (1.0 + r[0][0] - r[1][1] - r[2][2]).sqrt() * 2.0;
        [(r[2][1] - r[1][2]) / s, 0.25 * s, (r[0][1] + r[1][0]) / s, (r[0][2] + r[2][0]) / s]
    } else if r[1][1] > r[2][2] {
        let s = (1.0 + r[1][1] - r[0][0] - r[2][2]).sqrt() * 2.0;
        [(r[0][2] - r[2][0]) / s, (r[0][1] + r[1][0]) / s, 0.25 * s, (r[1][2] + r[2][1]) / s]
    } else {
        let s = (1.0 + r[2][2] - r[0][0] - r[1][1]).sqrt() * 2.0;
        [(r[1][0] - r[0][1]) / s, (r[0][2] + r[2][0]) / s, (r[1][2] + r[2][1]) / s, 0.25 * s]
    };
    let n = q.iter().map(|v| v * v).sum::<f64>().sqrt();
    let q = q.map(|v| v / n);
    if q[0] < 0.0 { q.map(|v| -v) } else { q }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn quaternion_round_trips_through_matrices() {
        for q in [[1.0, 0.0, 0.0, 0.0], [0.0, 1.0, 0.0, 0.0], [0.5, 0.5, -0.5, 0.5], [0.1, 0.2, 0.9, -0.37]] {
            let n = q.iter().map(|v: &f64| v * v).sum::<f64>().sqrt();
            let q: [f64; 4] = q.map(|v| v / n);
            let pose = Pose::from_quaternion(q, [0.0; 3]).unwrap();
            let back = rotation_to_quaternion(&pose.rotation);
            let same = q.iter().zip(&back).all(|(a, b)| (a - b).abs() < 1e-12);
            let negated = q.iter().zip(&back).all(|(a, b)| (a + b).abs() < 1e-12);
            assert!(same || negated, "{q:?} -> {back:?}");
        }
    }
}
