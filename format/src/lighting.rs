//! Lighting files: a package's lights changed without a rebuild (`--lights FILE.toml` of
//! `grotto render`, `view` and `publish`; docs/lighting.md). The syntax is the
//! manifest's `[[light]]` grown by what a lighting designer writes: power in watts or luminous
//! flux in lumens, colour as linear RGB or a colour temperature, a spot's cone and softness, an
//! IES LM-63 profile aimed and turned, and circuits switched together:
//!
//! ```toml
//! replace = false                # true: the package's lights go (its area lights' glow too)
//! [[circuit]]
//! name = "show"
//! title = "Show lighting"
//! [[light]]
//! name = "altar-wash"
//! kind = "point"                 # point | spot | area
//! position = [512344.0, 5123452.0, 341.0]
//! lumens = 1800.0                # or power_w
//! kelvin = 3000.0                # or color = [r, g, b]
//! ies = "wash.ies"               # relative to this file
//! aim_at = [512344.0, 5123452.0, 339.0]
//! circuit = "show"
//! ```
//!
//! Parsing is I/O-free (IES files are read through a closure the caller gives), so the browser's
//! build shares it. Every problem names its line.

use serde::Deserialize;
use toml::Spanned;

use crate::ies;
use crate::photometry;
use crate::profile::LightProfile;
use crate::scene::{Circuit, Light, LightShape};

/// A lighting file as written.
#[derive(Debug, Default, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct LightingSpec {
    #[serde(default)]
    pub replace: bool,
    /// The package's lights (by name) this file takes away.
    #[serde(default)]
    pub remove: Vec<String>,
    #[serde(default)]
    pub circuit: Vec<Spanned<CircuitSpec>>,
    #[serde(default)]
    pub light: Vec<Spanned<LightSpec>>,
}

/// `[[circuit]]`: `name`, `title`, `on` (default true).
#[derive(Debug, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct CircuitSpec {
    pub name: String,
    #[serde(default)]
    pub title: String,
    #[serde(default = "yes")]
    pub on: bool,
}

fn yes() -> bool {
    true
}

fn point() -> String {
    "point".into()
}

/// `[[light]]` (module docs). Angles in degrees, positions in world metres.
#[derive(Debug, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct LightSpec {
    pub name: String,
    #[serde(default = "point")]
    pub kind: String,
    pub position: Option<[f64; 3]>,
    pub direction: Option<[f64; 3]>,
    pub aim_at: Option<[f64; 3]>,
    pub inner_angle_deg: Option<f64>,
    pub outer_angle_deg: Option<f64>,
    /// 0: a hard-edged cone; 1: soft from the axis out (the inner angle is `outer * (1 - softness)`).
    pub softness: Option<f64>,
    pub center: Option<[f64; 3]>,
    pub normal: Option<[f64; 3]>,
    pub size: Option<[f64; 2]>,
    pub color: Option<[f64; 3]>,
    pub kelvin: Option<f64>,
    pub power_w: Option<f64>,
    pub lumens: Option<f64>,
    pub ies: Option<String>,
    pub turn_deg: Option<f64>,
    pub circuit: Option<String>,
}

/// A lighting file read: lights in the scene's form (world metres, watts, linear RGB).
#[derive(Clone, Debug, Default, PartialEq)]
pub struct Lighting {
    pub replace: bool,
    /// Names of the package's lights taken away.
    pub remove: Vec<String>,
    pub lights: Vec<Light>,
    pub circuits: Vec<Circuit>,
}

/// A problem with a lighting file, or with an IES file it names (`file`), at `line` (1-based).
#[derive(Clone, Debug, PartialEq, Eq)]
pub struct LightingError {
    pub file: Option<String>,
    pub line: Option<usize>,
    pub problem: String,
}

impl std::fmt::Display for LightingError {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        if let Some(file) = &self.file {
            write!(f, "{file}: ")?;
        }
        if let Some(line) = self.line {
            write!(f, "line {line}: ")?;
        }
        write!(f, "{}", self.problem)
    }
}

fn line_of(text: &str, byte: usize) -> usize {
    text[..byte.min(text.len())].matches('\n').count() + 1
}

/// Reads a lighting file's `text`; `read_ies` returns the text of an IES file named in it.
pub fn parse(
    text: &str,
    mut read_ies: impl FnMut(&str) -> Result<String, String>,
) -> Result<Lighting, LightingError> {
    let spec: LightingSpec = toml::from_str(text).map_err(|e| LightingError {
        file: None,
        line: e.span().map(|s| line_of(text, s.start)),
        problem: e.message().trim().to_string(),
    })?;
    let mut lighting = Lighting { replace: spec.replace, remove: spec.remove, ..Default::default() };
    for c in spec.circuit {
        let line = line_of(text, c.span().start);
        let c = c.into_inner();
        if lighting.circuits.iter().any(|o| o.name == c.name) {
            return Err(LightingError {
                file: None,
                line: Some(line),
                problem: format!("circuit {:?} is defined twice", c.name),
            });
        }
        lighting.circuits.push(Circuit { name: c.name, title: c.title, on: c.on });
    }
    for l in spec.light {
        let line = line_of(text, l.span().start);
        let at = |problem: String| LightingError { file: None, line: Some(line), problem };
        let l = l.into_inner();
        if lighting.lights.iter().any(|o| o.name == l.name) {
            return Err(at(format!("light {:?} is defined twice", l.name)));
        }
        let light = light_of(l, &mut read_ies).map_err(|e| match e {
            Problem::Here(p) => at(p),
            Problem::InIes(e) => e,
        })?;
        lighting.lights.push(light);
    }
    Ok(lighting)
}

enum Problem {
    Here(String),
    InIes(LightingError),
}

impl From<String> for Problem {
    fn from(p: String) -> Self {
        Problem::Here(p)
    }
}

fn finite3(what: &str, v: Option<[f64; 3]>) -> Result<Option<[f64; 3]>, String> {
    match v {
        Some(v) if !v.iter().all(|c| c.is_finite()) => Err(format!("{what} {v:?} is not finite")),
        v => Ok(v),
    }
}

fn unit(what: &str, v: [f64; 3]) -> Result<[f32; 3], String> {
    let len = (v[0] * v[0] + v[1] * v[1] + v[2] * v[2]).sqrt();
    if len.is_nan() || len <= 1e-9 {
        return Err(format!("{what} {v:?} has no direction"));
    }
    Ok(v.map(|c| (c / len) as f32))
}

fn light_of(
    l: LightSpec,
    read_ies: &mut impl FnMut(&str) -> Result<String, String>,
) -> Result<Light, Problem> {
    let name = l.name.clone();
    let needs = |what: &str| format!("light {name:?} ({}) needs {what}", l.kind);
    let position = finite3("position", l.position)?;
    let aim_at = finite3("aim_at", l.aim_at)?;
    let direction = finite3("direction", l.direction)?;
    // Where it points: `direction`, or from its position to `aim_at`.
    let aim = match (direction, aim_at, position) {
        (Some(_), Some(_), _) => return Err(format!("light {name:?} has both direction and aim_at").into()),
        (Some(d), None, _) => Some(unit("direction", d)?),
        (None, Some(t), Some(p)) => Some(unit("aim_at - position", [t[0] - p[0], t[1] - p[1], t[2] - p[2]])?),
        (None, Some(_), None) => return Err(needs("a position to aim from").into()),
        (None, None, _) => None,
    };
    let color = match (l.color, l.kelvin) {
        (Some(_), Some(_)) => return Err(format!("light {name:?} has both color and kelvin").into()),
        (Some(c), None) => {
            if !c.iter().all(|v| v.is_finite() && *v >= 0.0) || photometry::luminance(c) <= 0.0 {
                return Err(format!("color {c:?}: linear RGB, each >= 0, not black").into());
            }
            c
        }
        (None, Some(k)) => photometry::kelvin_rgb(k).ok_or_else(|| {
            format!(
                "kelvin {k}: a colour temperature from {} to {} K",
                photometry::KELVIN_RANGE.start(),
                photometry::KELVIN_RANGE.end()
            )
        })?,
        (None, None) => [1.0; 3],
    };
    let profile = match &l.ies {
        None => None,
        Some(_) if l.kind != "point" => {
            return Err(format!(
                "light {name:?}: an IES profile shapes a point light's beam (kind = \"point\")"
            )
            .into());
        }
        Some(file) => {
            let in_file = |line: Option<usize>, problem: String| {
                Problem::InIes(LightingError { file: Some(file.clone()), line, problem })
            };
            let text = read_ies(file).map_err(|e| in_file(None, e))?;
            let parsed = ies::parse(&text).map_err(|e| in_file(Some(e.line), e.problem))?;
            let (profile, lumens) = parsed.profile().map_err(|e| in_file(None, e))?;
            let turn = l.turn_deg.unwrap_or(0.0);
            if !turn.is_finite() {
                return Err(format!("turn_deg {turn} is not finite").into());
            }
            let placed = LightProfile {
                aim: aim.unwrap_or([0.0, 0.0, -1.0]),
                turn_deg: turn as f32,
                profile,
                source: file.clone(),
            };
            Some((placed, lumens))
        }
    };
    // The spot's cone, degrees from the axis.
    let cone = if l.kind == "spot" {
        let outer = l.outer_angle_deg.unwrap_or(30.0);
        let inner = match (l.inner_angle_deg, l.softness) {
            (Some(_), Some(_)) => {
                return Err(format!("light {name:?} has both inner_angle_deg and softness").into());
            }
            (Some(i), None) => i,
            (None, Some(s)) if (0.0..=1.0).contains(&s) => outer * (1.0 - s),
            (None, Some(s)) => return Err(format!("softness {s}: from 0 (hard) to 1 (soft)").into()),
            (None, None) => outer * 2.0 / 3.0,
        };
        if !(outer > 0.0 && outer <= 90.0 && inner >= 0.0 && inner <= outer) {
            return Err(format!("spot cone {inner}..{outer} degrees: 0 <= inner <= outer <= 90").into());
        }
        Some((inner.to_radians(), outer.to_radians()))
    } else {
        None
    };
    let power_w = power_of(&l, color, profile.as_ref().map(|p| p.1), cone)?;
    let shape = match l.kind.as_str() {
        "point" => LightShape::Point { position_m: position.ok_or_else(|| needs("a position"))? },
        "spot" => {
            let (inner, outer) = cone.unwrap_or_default();
            LightShape::Spot {
                position_m: position.ok_or_else(|| needs("a position"))?,
                direction: aim.ok_or_else(|| needs("a direction or aim_at"))?,
                inner_angle_rad: inner as f32,
                outer_angle_rad: outer as f32,
            }
        }
        "area" => {
            let size = l.size.ok_or_else(|| needs("a size"))?;
            if !size.iter().all(|s| s.is_finite() && *s > 0.0) {
                return Err(format!("size {size:?}: metres, each > 0").into());
            }
            LightShape::Area {
                center_m: finite3("center", l.center)?.ok_or_else(|| needs("a center"))?,
                normal: unit("normal", finite3("normal", l.normal)?.ok_or_else(|| needs("a normal"))?)?,
                size_m: size.map(|s| s as f32),
            }
        }
        other => return Err(format!("light kind {other:?} is not point, spot or area").into()),
    };
    Ok(Light {
        name: l.name,
        shape,
        color: color.map(|c| c as f32),
        power_w: power_w as f32,
        circuit: l.circuit,
        profile: profile.map(|p| p.0),
    })
}

/// Watts of a light from `power_w` or `lumens` (or its IES table's flux): with a profile or as
/// an area light, the flux of the whole; a spot keeps grotto's convention (its intensity is the
/// point light's of the same watts), so its lumens, those inside its cone, scale up by 4 pi over
/// the cone's solid angle.
fn power_of(
    l: &LightSpec,
    color: [f64; 3],
    ies_lumens: Option<f64>,
    cone: Option<(f64, f64)>,
) -> Result<f64, String> {
    let lumens = match (l.power_w, l.lumens) {
        (Some(_), Some(_)) => return Err(format!("light {:?} has both power_w and lumens", l.name)),
        (Some(w), None) => {
            return if w.is_finite() && w >= 0.0 {
                Ok(w)
            } else {
                Err(format!("power_w {w}: watts, finite and >= 0"))
            };
        }
        (None, Some(lm)) if lm.is_finite() && lm >= 0.0 => lm,
        (None, Some(lm)) => return Err(format!("lumens {lm}: finite and >= 0")),
        (None, None) => ies_lumens.ok_or_else(|| format!("light {:?} needs power_w or lumens", l.name))?,
    };
    let w = photometry::watts_of_lumens(lumens, color).ok_or("a colour without luminance")?;
    Ok(match cone {
        Some((inner, outer)) => w * 4.0 * std::f64::consts::PI / spot_solid_angle_sr(inner, outer),
        None => w,
    })
}

/// Solid angle of a spot's smoothstep falloff between `inner` and `outer` (radians from the axis)
/// integrated over the sphere: what the runtime's spot_factor lets through.
pub fn spot_solid_angle_sr(inner_rad: f64, outer_rad: f64) -> f64 {
    let (co, ci) = (outer_rad.cos(), inner_rad.cos().max(outer_rad.cos() + 1e-4));
    let n = 4000;
    let mut sum = 0.0;
    for i in 0..n {
        // d(omega) = 2 pi d(cos theta) over cos theta in [cos outer, 1].
        let c = co + (1.0 - co) * (i as f64 + 0.5) / n as f64;
        let t = ((c - co) / (ci - co)).clamp(0.0, 1.0);
        sum += t * t * (3.0 - 2.0 * t);
    }
    2.0 * std::f64::consts::PI * (1.0 - co) * sum / n as f64
}

/// Lights and circuits as merged: `base` (a package's) with `file`'s added, one of the same name
/// replacing it, or `file`'s alone where it says `replace`. Checked whole: every light's circuit
/// exists and every circuit has a light.
pub fn merged(base: (&[Light], &[Circuit]), file: &Lighting) -> Result<(Vec<Light>, Vec<Circuit>), String> {
    if let Some(gone) = file.remove.iter().find(|n| !base.0.iter().any(|l| &l.name == *n)) {
        return Err(format!("remove: the package has no light named {gone:?}"));
    }
    let kept: Vec<Light> = base.0.iter().filter(|l| !file.remove.contains(&l.name)).cloned().collect();
    let (lights, circuits) = if file.replace {
        (file.lights.clone(), file.circuits.clone())
    } else {
        (
            crate::story::merged(&kept, &file.lights, |l| &l.name),
            crate::story::merged(base.1, &file.circuits, |c| &c.name),
        )
    };
    crate::scene::check_lights(&lights, &circuits)?;
    Ok((lights, circuits))
}

/// A lighting file that, read back ([`parse`]) and merged with the package's lights, gives
/// `lighting`'s lights exactly: colours as linear RGB and powers in watts (what they became),
/// profiles by the IES file they were read from. What a viewer saves after editing.
pub fn to_toml(lighting: &Lighting) -> String {
    use std::fmt::Write;
    let v3 = |v: [f64; 3]| format!("[{:?}, {:?}, {:?}]", v[0], v[1], v[2]);
    let f3 = |v: [f32; 3]| v3(v.map(f64::from));
    let q = |s: &str| toml::Value::String(s.to_string()).to_string();
    let mut out = String::from("# grotto lighting file (docs/lighting.md)\n");
    let _ = writeln!(out, "replace = {}", lighting.replace);
    if !lighting.remove.is_empty() {
        let names: Vec<String> = lighting.remove.iter().map(|n| q(n)).collect();
        let _ = writeln!(out, "remove = [{}]", names.join(", "));
    }
    for c in &lighting.circuits {
        let _ = write!(out, "\n[[circuit]]\nname = {}\ntitle = {}\non = {}\n", q(&c.name), q(&c.title), c.on);
    }
    for l in &lighting.lights {
        let _ = write!(out, "\n[[light]]\nname = {}\n", q(&l.name));
        match &l.shape {
            LightShape::Point { position_m } => {
                let _ = writeln!(out, "kind = \"point\"\nposition = {}", v3(*position_m));
            }
            LightShape::Spot { position_m, direction, inner_angle_rad, outer_angle_rad } => {
                let _ = writeln!(
                    out,
                    "kind = \"spot\"\nposition = {}\ndirection = {}\ninner_angle_deg = {:?}\nouter_angle_deg = {:?}",
                    v3(*position_m),
                    f3(*direction),
                    f64::from(*inner_angle_rad).to_degrees(),
                    f64::from(*outer_angle_rad).to_degrees()
                );
            }
            LightShape::Area { center_m, normal, size_m } => {
                let _ = writeln!(
                    out,
                    "kind = \"area\"\ncenter = {}\nnormal = {}\nsize = [{:?}, {:?}]",
                    v3(*center_m),
                    f3(*normal),
                    f64::from(size_m[0]),
                    f64::from(size_m[1])
                );
            }
        }
        let _ = writeln!(out, "color = {}\npower_w = {:?}", f3(l.color), f64::from(l.power_w));
        if let Some(p) = &l.profile {
            let _ = writeln!(
                out,
                "ies = {}\ndirection = {}\nturn_deg = {:?}",
                q(&p.source),
                f3(p.aim),
                f64::from(p.turn_deg)
            );
        }
        if let Some(c) = &l.circuit {
            let _ = writeln!(out, "circuit = {}", q(c));
        }
    }
    out
}

#[cfg(test)]
mod tests {
    use super::*;

    const DOWNLIGHT: &str =
        "IESNA:LM-63-2002\nTILT=NONE\n1 -1 1.0 3 1 1 2 0 0 0\n1 1 10\n0 45 90\n0\n100 50 0\n";

    fn read(name: &str) -> Result<String, String> {
        match name {
            "down.ies" => Ok(DOWNLIGHT.into()),
            "lying.ies" => Ok(DOWNLIGHT.replace("1 -1 1.0 3 1", "1 -1 1.0 9 1")),
            _ => Err("no such file".into()),
        }
    }

    #[test]
    fn a_designers_file_reads_into_the_scenes_units() {
        let text = r#"
[[circuit]]
name = "show"
[[light]]
name = "wash"
position = [10.0, 20.0, 5.0]
lumens = 683.0
kelvin = 3000.0
ies = "down.ies"
aim_at = [10.0, 20.0, 0.0]
circuit = "show"
[[light]]
name = "spot"
kind = "spot"
position = [0.0, 0.0, 3.0]
direction = [0.0, 0.0, -1.0]
outer_angle_deg = 30.0
softness = 0.5
power_w = 10.0
"#;
        let l = parse(text, read).unwrap();
        assert_eq!(l.circuits[0].name, "show");
        let wash = &l.lights[0];
        // 683 lm of luminance-1 colour: 1 W.
        assert!((wash.power_w - 1.0).abs() < 1e-6, "{}", wash.power_w);
        let y = photometry::luminance(wash.color.map(f64::from));
        assert!((y - 1.0).abs() < 1e-6 && wash.color[0] > wash.color[2], "warm, luminance 1");
        let p = wash.profile.as_ref().unwrap();
        assert_eq!(p.aim, [0.0, 0.0, -1.0]);
        assert_eq!(p.toward([0.0, 0.0, -1.0]), 1.0);
        assert!((p.toward([1.0, 0.0, -1.0].map(|c: f32| c / 2f32.sqrt())) - 0.5).abs() < 1e-5);
        let spot = &l.lights[1];
        let LightShape::Spot { inner_angle_rad, outer_angle_rad, .. } = spot.shape else { panic!() };
        assert!(
            (inner_angle_rad.to_degrees() - 15.0).abs() < 1e-4
                && (outer_angle_rad.to_degrees() - 30.0).abs() < 1e-4
        );
        assert_eq!(spot.power_w, 10.0, "watts stay as written");
        // Merged with a package: same name replaces, the circuit must hold a light.
        let (lights, _) = merged((&[], &[]), &l).unwrap();
        assert_eq!(lights.len(), 2);
        // Written out and read back: the same lights, to the bit.
        let back = parse(&to_toml(&l), read).unwrap();
        assert_eq!(back, l, "{}", to_toml(&l));
        // `remove` takes a package light away; one it does not have is refused.
        let package = [Light { name: "old".into(), ..l.lights[1].clone() }];
        let gone = parse("remove = [\"old\"]\n", read).unwrap();
        assert!(merged((&package, &[]), &gone).unwrap().0.is_empty());
        let wrong = parse("remove = [\"nope\"]\n", read).unwrap();
        assert!(merged((&package, &[]), &wrong).unwrap_err().contains("\"nope\""));
    }

    #[test]
    fn bad_files_are_refused_with_the_line_and_the_problem() {
        let cases: [(&str, usize, &str); 9] = [
            ("[[light]]\nname = \"a\"\nposition = [0.0, 0.0, 0.0]\npower_w = -5.0\n", 1, "power_w -5"),
            ("[[light]]\nname = \"a\"\nposition = [0.0, nan, 0.0]\npower_w = 5.0\n", 1, "not finite"),
            (
                "\n[[light]]\nname = \"a\"\nposition = [0.0, 0.0, 0.0]\nwatts = 5.0\n",
                5,
                "unknown field `watts`",
            ),
            ("[[light]]\nname = \"a\"\nposition = [0.0, 0.0, 0.0]\n", 1, "needs power_w or lumens"),
            (
                "[[light]]\nname = \"a\"\nposition = [0.0, 0.0, 0.0]\nlumens = 100.0\nkelvin = 90.0\n",
                1,
                "kelvin 90",
            ),
            (
                "[[light]]\nname = \"a\"\nkind = \"spot\"\nposition = [0.0, 0.0, 0.0]\ndirection = [0.0, 0.0, 0.0]\npower_w = 1.0\n",
                1,
                "no direction",
            ),
            ("[[light]]\nname = \"a\"\nposition = [0.0, 0.0, 0.0]\nies = \"gone.ies\"\n", 0, "no such file"),
            (
                "[[light]]\nname = \"a\"\nposition = [0.0, 0.0, 0.0]\npower_w = 1.0\n[[light]]\nname = \"a\"\nposition = [0.0, 0.0, 0.0]\npower_w = 1.0\n",
                5,
                "defined twice",
            ),
            (
                "[[light]]\nname = \"a\"\nkind = \"tube\"\nposition = [0.0, 0.0, 0.0]\npower_w = 1.0\n",
                1,
                "not point, spot or area",
            ),
        ];
        for (text, line, says) in cases {
            let e = parse(text, read).unwrap_err();
            assert!(e.to_string().contains(says), "{text}: {e}");
            if line > 0 {
                assert_eq!(e.line, Some(line), "{text}: {e}");
            }
        }
        // The IES file's own line, and its name.
        let e = parse("[[light]]\nname = \"a\"\nposition = [0.0, 0.0, 0.0]\nies = \"lying.ies\"\n", read)
            .unwrap_err();
        assert_eq!(e.file.as_deref(), Some("lying.ies"), "{e}");
        assert!(e.problem.contains("declares 9 vertical"), "{e}");
        // An empty circuit, and a light on a circuit nobody defined.
        let empty = parse("[[circuit]]\nname = \"work\"\n", read).unwrap();
        assert!(merged((&[], &[]), &empty).unwrap_err().contains("circuit \"work\" has no lights"));
        let stray = parse(
            "[[light]]\nname = \"a\"\nposition = [0.0, 0.0, 0.0]\npower_w = 1.0\ncircuit = \"x\"\n",
            read,
        )
        .unwrap();
        assert!(merged((&[], &[]), &stray).unwrap_err().contains("no [[circuit]] defines"));
    }

    #[test]
    fn a_spots_lumens_are_those_inside_its_cone() {
        // A hard 60-degree cone (half-angle) covers 2 pi (1 - cos 60) = pi sr.
        let hard = spot_solid_angle_sr(60f64.to_radians(), 60f64.to_radians());
        assert!((hard - std::f64::consts::PI).abs() < 1e-2, "{hard}");
        let text = "[[light]]\nname = \"s\"\nkind = \"spot\"\nposition = [0.0, 0.0, 0.0]\ndirection = [0.0, 0.0, -1.0]\n\
                    outer_angle_deg = 60.0\ninner_angle_deg = 60.0\nlumens = 683.0\n";
        let s = &parse(text, read).unwrap().lights[0];
        // Its intensity (power / 4 pi) times the cone's pi sr is 1 W of luminance-1 light.
        let flux_w = f64::from(s.power_w) / (4.0 * std::f64::consts::PI) * hard;
        assert!((flux_w - 1.0).abs() < 1e-3, "{flux_w}");
    }
}
