//! Human and JSON descriptions of a package (`grotto inspect`) and the report of a full check
//! (`grotto verify`). Everything here reads the table and directory, except `verify`, which reads
//! and checks every section.

use std::fmt::Write as _;

use grotto_format::spec::ShRgb9;
use grotto_format::{Package, Problem, Provenance, Scene, SectionKind, Summary};
use serde::Serialize;

/// `grotto inspect --json`: the summary plus scene and provenance.
#[derive(Debug, Serialize)]
pub struct Inspection {
    #[serde(flatten)]
    pub(crate) summary: Summary,
    /// `None` when the scene section is damaged (`verify` says how).
    pub(crate) scene: Option<Scene>,
    pub(crate) provenance: Option<Provenance>,
    /// Each environment map's 9 RGB SH coefficients of radiance (L00, L1-1, L10, L11, L2-2, L2-1,
    /// L20, L21, L22).
    pub(crate) environment_sh: Vec<EnvironmentSh>,
}

#[derive(Debug, Serialize)]
pub(crate) struct EnvironmentSh {
    pub(crate) item: u32,
    pub(crate) coeffs: [[f32; 3]; 9],
}

/// What `grotto inspect` prints of `pkg`.
pub fn inspect(pkg: &Package) -> Inspection {
    let environment_sh = pkg
        .sections()
        .filter(|s| s.kind == Some(SectionKind::EnvSh9))
        .filter_map(|s| {
            let sh = pkg.read::<ShRgb9>(&s).ok()?;
            Some(EnvironmentSh { item: s.item, coeffs: sh.first()?.coeffs })
        })
        .collect();
    Inspection {
        summary: pkg.summary(),
        scene: pkg.scene().ok(),
        provenance: pkg.provenance().ok().flatten(),
        environment_sh,
    }
}

fn human_bytes(n: u64) -> String {
    match n {
        n if n >= 1 << 30 => format!("{:.2} GiB", n as f64 / f64::from(1u32 << 30)),
        n if n >= 1 << 20 => format!("{:.2} MiB", n as f64 / f64::from(1u32 << 20)),
        n if n >= 1 << 10 => format!("{:.1} KiB", n as f64 / 1024.0),
        n => format!("{n} B"),
    }
}

/// The text `grotto inspect` prints.
pub fn render_text(i: &Inspection, list_sections: bool) -> String {
    let s = &i.summary;
    let mut out = String::new();
    let _ = writeln!(out, "{}: grotto package {}, {}", s.path, s.version, human_bytes(s.file_size));
    let t = &s.tiles;
    let _ = write!(out, "tiles: {}, {} points", t.count, t.points);
    if let (Some(lo), Some(hi), Some(d0), Some(d1)) =
        (t.bounds_min_m, t.bounds_max_m, t.min_depth, t.max_depth)
    {
        let depth = if d0 == d1 { d0.to_string() } else { format!("{d0}..{d1}") };
        let _ = write!(
            out,
            ", SVO depth {depth}, bounds [{:.3}, {:.3}, {:.3}] .. [{:.3}, {:.3}, {:.3}] m",
            lo[0], lo[1], lo[2], hi[0], hi[1], hi[2]
        );
    }
    out.push('\n');
    let _ = writeln!(
        out,
        "{:<20} {:>8} {:>6} {:>12} {:>12} {:>7}",
        "kind", "sections", "zstd", "stored", "raw", "ratio"
    );
    for k in &s.kinds {
        let _ = writeln!(
            out,
            "{:<20} {:>8} {:>6} {:>12} {:>12} {:>7.2}",
            k.kind,
            k.sections,
            k.zstd_sections,
            human_bytes(k.stored_bytes),
            human_bytes(k.raw_bytes),
            k.ratio
        );
    }
    let _ = writeln!(out, "overall compression ratio {:.2}", s.compression_ratio);
    match &i.scene {
        Some(sc) => {
            let env = sc
                .environment
                .as_ref()
                .map_or_else(|| "no environment".to_string(), |e| format!("environment {}", e.source));
            let cams: Vec<&str> = sc.cameras.iter().map(|c| c.name.as_str()).collect();
            let _ = writeln!(
                out,
                "scene: {} lights, {} materials, cameras [{}], {env}",
                sc.lights.len(),
                sc.materials.len(),
                cams.join(", ")
            );
        }
        None => out.push_str("scene: damaged (run grotto verify)\n"),
    }
    for e in &i.environment_sh {
        let c = e.coeffs[0];
        let _ = writeln!(
            out,
            "environment {}: SH L00 = [{:.4}, {:.4}, {:.4}] (9 RGB coefficients in --json)",
            e.item, c[0], c[1], c[2]
        );
    }
    if let Some(p) = &i.provenance {
        let _ = writeln!(out, "built by {} {} from {} inputs", p.tool, p.tool_version, p.inputs.len());
    }
    if list_sections {
        let _ = writeln!(
            out,
            "{:>5} {:<20} {:>6} {:>4} {:>5} {:>12} {:>10} {:>10}",
            "#", "kind", "scope", "item", "codec", "offset", "stored", "raw"
        );
        for x in &s.sections {
            let _ = writeln!(
                out,
                "{:>5} {:<20} {:>6} {:>4} {:>5} {:>12} {:>10} {:>10}",
                x.index, x.kind, x.scope, x.item, x.codec, x.offset, x.stored_bytes, x.raw_bytes
            );
        }
    }
    out
}

/// Result of `grotto verify`.
#[derive(Debug, Serialize)]
pub struct Verification {
    pub path: String,
    pub sections: u32,
    pub bytes_checked: u64,
    /// Empty when the package is valid.
    pub problems: Vec<String>,
}

/// Checks every section of `pkg` (checksums, decoding, content); what `grotto verify` prints.
pub fn verify(pkg: &Package) -> Verification {
    let problems: Vec<Problem> = pkg.verify();
    Verification {
        path: pkg.path().display().to_string(),
        sections: pkg.section_count(),
        bytes_checked: pkg.sections().map(|s| s.stored_len).sum(),
        problems: problems.iter().map(ToString::to_string).collect(),
    }
}
