//! IES LM-63 photometric files (1986, 1991, 1995, 2002 and 2019 editions): the candela table
//! luminaire makers publish, read into a [`Profile`] a light can carry.
//!
//! Hand-written rather than taken from a crate: a lighting designer's file must be refused with
//! the line and the problem (a count of angles that lies, a value that is not a number), and a
//! header's counts must not size an allocation before the data proves them; the Rust readers
//! (lidrs, unmaintained since 2022; eulumdat, anyhow errors without lines) do neither. The format
//! is a keyword header, a TILT line, then whitespace- or comma-separated numbers.

use crate::profile::Profile;

/// Most vertical angles (0.25 degree steps over 180) and horizontal angles (over 360) a file may
/// declare: finer than any goniophotometer, so a larger count is a damaged header.
pub const MAX_VERTICAL: usize = 721;
pub const MAX_HORIZONTAL: usize = 1441;

/// What an IES file says.
#[derive(Clone, Debug, PartialEq)]
pub struct Ies {
    pub lamps: u32,
    /// Lumens of each lamp; -1: absolute photometry (an LED luminaire measured whole).
    pub lumens_per_lamp: f64,
    /// 1 = C (architectural; the only type grotto places), 2 = B, 3 = A.
    pub photometric_type: u32,
    /// Ascending; type C: degrees from the nadir.
    pub vertical_deg: Vec<f64>,
    /// Ascending; type C: degrees about the vertical axis.
    pub horizontal_deg: Vec<f64>,
    /// Candela per (horizontal, vertical), horizontal-major, with the file's multiplier and
    /// ballast factor applied.
    pub candela: Vec<f64>,
}

/// A problem at a line of an IES file (1-based).
#[derive(Clone, Debug, PartialEq, Eq)]
pub struct IesError {
    pub line: usize,
    pub problem: String,
}

impl std::fmt::Display for IesError {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        write!(f, "line {}: {}", self.line, self.problem)
    }
}

/// The numbers after the TILT line, each with its line.
struct Numbers<'a> {
    tokens: Vec<(usize, &'a str)>,
    next: usize,
    last_line: usize,
}

impl Numbers<'_> {
    fn take(&mut self, what: &str) -> Result<(usize, f64), IesError> {
        let Some(&(line, token)) = self.tokens.get(self.next) else {
            return Err(IesError { line: self.last_line, problem: format!("the file ends before {what}") });
        };
        self.next += 1;
        match token.parse::<f64>() {
            Ok(v) if v.is_finite() => Ok((line, v)),
            _ => Err(IesError { line, problem: format!("{what}: {token:?} is not a number") }),
        }
    }

    /// A count: a whole number in `1..=max`.
    fn count(&mut self, what: &str, max: usize) -> Result<usize, IesError> {
        let (line, v) = self.take(what)?;
        if v.fract() != 0.0 || v < 1.0 || v > max as f64 {
            return Err(IesError { line, problem: format!("{what} is {v}: a whole number from 1 to {max}") });
        }
        Ok(v as usize)
    }

    fn left(&self) -> usize {
        self.tokens.len() - self.next
    }
}

/// Reads an IES file's text.
pub fn parse(text: &str) -> Result<Ies, IesError> {
    let lines: Vec<&str> = text.lines().collect();
    let tilt = lines.iter().position(|l| l.trim_start().to_ascii_uppercase().starts_with("TILT")).ok_or(
        IesError { line: lines.len().max(1), problem: "no TILT= line: not an IES LM-63 file".into() },
    )?;
    let tilt_value = lines[tilt].trim_start()[4..].trim_start_matches([' ', '=']).trim().to_ascii_uppercase();
    let tokens: Vec<(usize, &str)> = lines[tilt + 1..]
        .iter()
        .enumerate()
        .flat_map(|(i, l)| {
            l.split(|c: char| c.is_whitespace() || c == ',')
                .filter(|t| !t.is_empty())
                .map(move |t| (tilt + 2 + i, t))
        })
        .collect();
    let mut n = Numbers { tokens, next: 0, last_line: lines.len() };
    match tilt_value.as_str() {
        "NONE" => {}
        // Lamp-to-luminaire geometry, then a table of tilt angles and factors: read past it (a
        // lamp's output against its tilt; grotto's luminaires hang as measured).
        "INCLUDE" => {
            n.take("the TILT geometry")?;
            let k = n.count("the number of tilt angles", MAX_HORIZONTAL)?;
            for _ in 0..2 * k {
                n.take("the tilt table")?;
            }
        }
        other => {
            return Err(IesError {
                line: tilt + 1,
                problem: format!("TILT={other}: a tilt file beside it is not read; use TILT=NONE or INCLUDE"),
            });
        }
    }
    let (lamps_line, lamps) = n.take("the number of lamps")?;
    let (_, lumens_per_lamp) = n.take("the lumens per lamp")?;
    let (mult_line, multiplier) = n.take("the candela multiplier")?;
    let nv = n.count("the number of vertical angles", MAX_VERTICAL)?;
    let nh = n.count("the number of horizontal angles", MAX_HORIZONTAL)?;
    let (type_line, photometric_type) = n.take("the photometric type")?;
    for what in ["the units type", "the width", "the length", "the height"] {
        n.take(what)?;
    }
    let (ballast_line, ballast) = n.take("the ballast factor")?;
    n.take("the ballast-lamp factor")?;
    n.take("the input watts")?;
    if !(lamps >= 1.0 && lamps.fract() == 0.0) {
        return Err(IesError { line: lamps_line, problem: format!("{lamps} lamps: a whole number from 1") });
    }
    if multiplier <= 0.0 || ballast <= 0.0 {
        return Err(IesError {
            line: if multiplier > 0.0 { ballast_line } else { mult_line },
            problem: format!(
                "the candela multiplier ({multiplier}) and ballast factor ({ballast}) must be positive"
            ),
        });
    }
    if ![1.0, 2.0, 3.0].contains(&photometric_type) {
        return Err(IesError {
            line: type_line,
            problem: format!("photometric type {photometric_type}: 1 (C), 2 (B) or 3 (A)"),
        });
    }
    // The counts are checked against what the file holds before anything is sized by them.
    if n.left() < nv + nh + nv * nh {
        return Err(IesError {
            line: n.last_line,
            problem: format!(
                "the header declares {nv} vertical and {nh} horizontal angles ({} numbers with the \
                 candela table) but only {} numbers follow",
                nv + nh + nv * nh,
                n.left()
            ),
        });
    }
    let vertical_deg = angles(&mut n, nv, "vertical", 0.0..=180.0)?;
    let horizontal_deg = angles(&mut n, nh, "horizontal", 0.0..=360.0)?;
    let mut candela = Vec::with_capacity(nv * nh);
    for i in 0..nv * nh {
        let (line, c) = n.take("the candela table")?;
        if c < 0.0 {
            return Err(IesError {
                line,
                problem: format!("candela value {} of {} is {c}: negative", i + 1, nv * nh),
            });
        }
        candela.push(c * multiplier * ballast);
    }
    if let Some(&(line, _)) = n.tokens.get(n.next) {
        return Err(IesError {
            line,
            problem: format!(
                "{} numbers follow the candela table: the header's {nv} vertical x {nh} horizontal \
                 angles do not describe this data",
                n.left()
            ),
        });
    }
    Ok(Ies {
        lamps: lamps as u32,
        lumens_per_lamp,
        photometric_type: photometric_type as u32,
        vertical_deg,
        horizontal_deg,
        candela,
    })
}

fn angles(
    n: &mut Numbers<'_>,
    count: usize,
    which: &str,
    range: std::ops::RangeInclusive<f64>,
) -> Result<Vec<f64>, IesError> {
    let mut out: Vec<f64> = Vec::with_capacity(count);
    for _ in 0..count {
        let (line, a) = n.take(&format!("the {which} angles"))?;
        if !range.contains(&a) || out.last().is_some_and(|&p| a <= p) {
            return Err(IesError {
                line,
                problem: format!(
                    "{which} angle {a} after {:?}: the {count} {which} angles must rise within {}..{} degrees \
                     (does the header's count of angles lie?)",
                    out.last(),
                    range.start(),
                    range.end()
                ),
            });
        }
        out.push(a);
    }
    Ok(out)
}

impl Ies {
    /// The luminaire's total candela table as a light's profile: type C only, the vertical angles
    /// completed to 0..180 with darkness, the horizontal ones one of LM-63's symmetries (0; 0..90;
    /// 0..180; 0..360). Returns the profile and the luminaire's luminous flux in lumens (the
    /// table integrated over the sphere).
    pub fn profile(&self) -> Result<(Profile, f64), String> {
        if self.photometric_type != 1 {
            return Err(format!(
                "photometric type {} ({}): only type C (architectural luminaires) is placed",
                self.photometric_type,
                if self.photometric_type == 2 { "B" } else { "A" }
            ));
        }
        let h_last = *self.horizontal_deg.last().unwrap_or(&0.0);
        if self.horizontal_deg[0] != 0.0 || ![0.0, 90.0, 180.0, 360.0].contains(&h_last) {
            return Err(format!(
                "horizontal angles {}..{h_last}: type C files run from 0 to 0, 90, 180 or 360",
                self.horizontal_deg[0]
            ));
        }
        let nv = self.vertical_deg.len();
        let mut vertical: Vec<f32> = Vec::with_capacity(nv + 2);
        let mut rows: Vec<Vec<f32>> = vec![Vec::with_capacity(nv + 2); self.horizontal_deg.len()];
        let pad = |v: &mut Vec<f32>, rows: &mut Vec<Vec<f32>>, at: f64| {
            v.push(at as f32);
            rows.iter_mut().for_each(|r| r.push(0.0));
        };
        if self.vertical_deg[0] > 0.0 {
            // An uplight's table starts at 90: dark below, and just short of its first angle.
            pad(&mut vertical, &mut rows, 0.0);
            if self.vertical_deg[0] > 1e-3 {
                pad(&mut vertical, &mut rows, self.vertical_deg[0] - 1e-3);
            }
        }
        for (i, &v) in self.vertical_deg.iter().enumerate() {
            vertical.push(v as f32);
            for (h, row) in rows.iter_mut().enumerate() {
                row.push(self.candela[h * nv + i] as f32);
            }
        }
        let v_last = self.vertical_deg[nv - 1];
        if v_last < 180.0 {
            if v_last < 180.0 - 1e-3 {
                pad(&mut vertical, &mut rows, v_last + 1e-3);
            }
            pad(&mut vertical, &mut rows, 180.0);
        }
        let peak = rows.iter().flatten().fold(0.0f32, |m, &c| m.max(c));
        if peak <= 0.0 {
            return Err("every candela value is 0: the luminaire gives no light".into());
        }
        let profile = Profile {
            vertical_deg: vertical,
            horizontal_deg: self.horizontal_deg.iter().map(|&h| h as f32).collect(),
            relative: rows.into_iter().flatten().map(|c| c / peak).collect(),
        };
        let lumens = profile.integral_sr() * f64::from(peak);
        Ok((profile, lumens))
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    /// A downlight (type C, round symmetric) as makers write them.
    pub(crate) const DOWNLIGHT: &str = "IESNA:LM-63-2002\n[TEST] grotto test\n[MANUFAC] none\nTILT=NONE\n\
        1 1000 1.0 5 1 1 2 0.1 0.1 0.05\n1.0 1.0 12\n0 22.5 45 67.5 90\n0\n\
        400 350, 200 50\n0\n";

    #[test]
    fn a_downlight_reads_and_becomes_a_profile_whose_flux_is_its_table_integrated() {
        let ies = parse(DOWNLIGHT).unwrap();
        assert_eq!(ies.vertical_deg, [0.0, 22.5, 45.0, 67.5, 90.0]);
        assert_eq!(ies.candela, [400.0, 350.0, 200.0, 50.0, 0.0]);
        let (p, lumens) = ies.profile().unwrap();
        assert_eq!(p.vertical_deg.last(), Some(&180.0), "completed to the zenith with darkness");
        assert_eq!(p.sample(0.0, 0.0), 1.0);
        assert!((p.sample(22.5f32.to_radians(), 1.0) - 350.0 / 400.0).abs() < 1e-6);
        assert!(p.sample(120f32.to_radians(), 0.0) == 0.0);
        // Trapezoid in theta of 2 pi I(theta) sin(theta): a check by hand of the integral.
        let mut want = 0.0;
        let c = [400.0, 350.0, 200.0, 50.0, 0.0f64];
        for i in 0..4 {
            let (a, b) = ((i as f64 * 22.5).to_radians(), ((i + 1) as f64 * 22.5).to_radians());
            // Piecewise linear I against theta, integrated with sin(theta) finely.
            for k in 0..1000 {
                let t = a + (b - a) * (k as f64 + 0.5) / 1000.0;
                let i_t = c[i] + (c[i + 1] - c[i]) * (t - a) / (b - a);
                want += 2.0 * std::f64::consts::PI * i_t * t.sin() * (b - a) / 1000.0;
            }
        }
        assert!((lumens - want).abs() / want < 1e-3, "{lumens} lm against {want}");
    }

    #[test]
    fn lying_headers_and_bad_numbers_are_refused_with_their_line() {
        // One vertical angle more than the data: the horizontal angle is read as a vertical one.
        let more = DOWNLIGHT.replace("1 1000 1.0 5 1", "1 1000 1.0 6 1");
        let e = parse(&more).unwrap_err();
        assert!(e.problem.contains("declares 6 vertical"), "{e}");
        // One fewer: numbers are left after the table.
        let fewer = DOWNLIGHT.replace("1 1000 1.0 5 1", "1 1000 1.0 4 1");
        let e = parse(&fewer).unwrap_err();
        assert!(e.problem.contains("angle") || e.problem.contains("follow"), "{e}");
        let e = parse(&DOWNLIGHT.replace("1 1000 1.0 5 1", "1 1000 1.0 5000000 1")).unwrap_err();
        assert!(e.problem.contains("from 1 to 721") && e.line == 5, "{e}");
        let e = parse(&DOWNLIGHT.replace("400 350", "400 x50")).unwrap_err();
        assert!(e.problem.contains("\"x50\"") && e.line == 9, "{e}");
        let e = parse(&DOWNLIGHT.replace("400 350", "400 -350")).unwrap_err();
        assert!(e.problem.contains("negative") && e.line == 9, "{e}");
        let e = parse(&DOWNLIGHT.replace("0 22.5 45", "0 45 22.5")).unwrap_err();
        assert!(e.problem.contains("must rise") && e.line == 7, "{e}");
        let e = parse("not a photometric file\n").unwrap_err();
        assert!(e.problem.contains("TILT"), "{e}");
        let e = parse(&DOWNLIGHT.replace("TILT=NONE", "TILT=lamp.tlt")).unwrap_err();
        assert!(e.problem.contains("TILT=LAMP.TLT"), "{e}");
        let b = parse(&DOWNLIGHT.replace("5 1 1 2", "5 1 2 2")).unwrap();
        assert!(b.profile().unwrap_err().contains("type C"));
    }

    #[test]
    fn quadrant_symmetric_and_uplight_tables_unfold() {
        let text = "IESNA91\nTILT=INCLUDE\n1\n2\n0 90\n1 1\n1 -1 2 3 3 1 2 0 0 0\n1 1 10\n\
                    90 135 180\n0 45 90\n10 5 0\n20 10 0\n30 15 0\n";
        let ies = parse(text).unwrap();
        assert_eq!(ies.candela[0], 20.0, "the multiplier applies");
        let (p, _) = ies.profile().unwrap();
        // Dark below the horizon; at 90 degrees up from the nadir the table's values by azimuth.
        assert_eq!(p.sample(45f32.to_radians(), 0.0), 0.0);
        let at = |phi_deg: f32| p.sample(90f32.to_radians(), phi_deg.to_radians());
        assert!((at(0.0) - 20.0 / 60.0).abs() < 1e-6 && (at(90.0) - 1.0).abs() < 1e-6);
        // Quadrant symmetry: 180 - phi, 180 + phi and 360 - phi mirror phi.
        for phi in [30.0, 150.0, 210.0, 330.0] {
            assert!((at(phi) - at(30.0)).abs() < 1e-6, "{phi}: {} against {}", at(phi), at(30.0));
        }
    }
}
