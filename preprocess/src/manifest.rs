//! The build manifest (TOML, documented in `docs/manifest.md`): scans with their poses and scanner
//! origins, plus the scene (lights, materials, environment map, cameras). A bare list of files and
//! a Stanford `.conf` registration file are accepted too.
//!
//! Unknown keys are errors: a misspelt `rotaton` must not silently leave a scan unrotated.

use std::path::{Path, PathBuf};

use grotto_format::story::{PoiSpec, StorySpec, TourSpec};
use grotto_format::{Camera, Environment, Light, LightShape, Material, Scene};
use serde::Deserialize;

use crate::ingest::{self, ScanFormat};
use crate::pose::Pose;
use crate::{Error, Result};

#[derive(Clone, Debug, Default, Deserialize)]
#[serde(deny_unknown_fields)]
/// A build's inputs: scans with their poses, and the scene (lights, cameras, materials, environment).
pub struct Manifest {
    #[serde(default, rename = "scan")]
    pub scans: Vec<ScanSpec>,
    #[serde(default, rename = "light")]
    pub(crate) lights: Vec<LightSpec>,
    #[serde(default, rename = "material")]
    pub materials: Vec<MaterialSpec>,
    pub environment: Option<EnvironmentSpec>,
    #[serde(default, rename = "camera")]
    pub(crate) cameras: Vec<CameraSpec>,
    /// Points of interest and guided tours (grotto_format::story; docs/manifest.md).
    #[serde(default, rename = "poi")]
    pub(crate) pois: Vec<PoiSpec>,
    #[serde(default, rename = "tour")]
    pub(crate) tours: Vec<TourSpec>,
    /// The surveyors' centreline (docs/manifest.md, `[survey]`).
    pub survey: Option<SurveySpec>,
    /// The survey read and moved into the scans' world, once the manifest is loaded.
    #[serde(skip)]
    pub(crate) survey_data: Option<grotto_format::survey::Survey>,
    /// Directory relative paths are resolved against (the manifest's own directory).
    #[serde(skip)]
    pub(crate) base_dir: PathBuf,
}

#[derive(Clone, Debug, Default, Deserialize)]
#[serde(deny_unknown_fields)]
/// One scan file and its pose (docs/manifest.md).
pub struct ScanSpec {
    pub(crate) path: PathBuf,
    pub(crate) format: Option<ScanFormat>,
    /// Scan frame -> world translation, metres.
    pub translation: Option<[f64; 3]>,
    /// Unit quaternion w, x, y, z.
    pub rotation: Option<[f64; 4]>,
    /// Row-major 4x4 scan frame -> world matrix (instead of translation + rotation).
    pub(crate) matrix: Option<[f64; 16]>,
    /// Scanner position in the scan frame (default: the frame's origin when the scan has a pose;
    /// with neither, the file is taken as a merged cloud without scanner positions).
    pub origin: Option<[f64; 3]>,
    /// For files with several scans (E57): which one; all when absent.
    pub(crate) scan: Option<usize>,
    /// Which side of its surface a scan without a scanner position was taken from: `inside` (a
    /// cave: normals face the space its walls enclose) or `outside` (an object or a building
    /// scanned from around it: normals face away from what it encloses). Absent: what the
    /// command line says (`--seen-from`), else inside. A scan with a scanner is oriented by it.
    pub seen_from: Option<SeenFrom>,
}

/// Where a merged cloud was scanned from (`seen_from` in a manifest, `--seen-from`).
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq, Deserialize, serde::Serialize, clap::ValueEnum)]
#[serde(rename_all = "snake_case")]
pub enum SeenFrom {
    /// From the space the scanned surfaces enclose (a cave, a room).
    #[default]
    Inside,
    /// From around the surface (an object, a statue, a building's outside).
    Outside,
}

#[derive(Clone, Debug, Deserialize)]
#[serde(deny_unknown_fields)]
pub(crate) struct LightSpec {
    #[serde(default)]
    pub(crate) name: String,
    pub(crate) kind: String,
    pub(crate) position: Option<[f64; 3]>,
    pub(crate) direction: Option<[f32; 3]>,
    pub(crate) inner_angle_deg: Option<f32>,
    pub(crate) outer_angle_deg: Option<f32>,
    pub(crate) center: Option<[f64; 3]>,
    pub(crate) normal: Option<[f32; 3]>,
    pub(crate) size: Option<[f32; 2]>,
    #[serde(default = "white")]
    pub(crate) color: [f32; 3],
    pub(crate) power_w: f32,
}

fn white() -> [f32; 3] {
    [1.0; 3]
}

#[derive(Clone, Debug, Deserialize)]
#[serde(deny_unknown_fields)]
/// A wet-wall material: specular strength, roughness and index of refraction in a region.
pub struct MaterialSpec {
    pub name: String,
    #[serde(default)]
    pub specular: f32,
    #[serde(default = "half")]
    pub roughness: f32,
    /// Index of refraction of the wet film (Fresnel term).
    #[serde(default = "water_ior")]
    pub ior: f32,
    /// Where it applies: `region = { min = [x, y, z], max = [x, y, z], min_normal_z = 0.9 }`
    /// (world metres; `min_normal_z` 1 = level floors, default -1 = any direction).
    pub region: Option<RegionSpec>,
}

#[derive(Clone, Debug, Deserialize)]
#[serde(deny_unknown_fields)]
/// A box in world coordinates where a material applies (to surfels facing up at least `min_normal_z`).
pub struct RegionSpec {
    pub min: [f64; 3],
    pub max: [f64; 3],
    #[serde(default = "minus_one")]
    pub min_normal_z: f32,
}

fn water_ior() -> f32 {
    1.33
}

fn minus_one() -> f32 {
    -1.0
}

fn half() -> f32 {
    0.5
}

#[derive(Clone, Debug, Deserialize)]
#[serde(deny_unknown_fields)]
/// The environment map lighting the openings, and its intensity.
pub struct EnvironmentSpec {
    pub map: PathBuf,
    #[serde(default = "one")]
    pub intensity: f32,
}

fn one() -> f32 {
    1.0
}

#[derive(Clone, Debug, Deserialize)]
#[serde(deny_unknown_fields)]
pub(crate) struct CameraSpec {
    pub(crate) name: String,
    pub(crate) eye: [f64; 3],
    pub(crate) look_at: [f64; 3],
    #[serde(default = "z_up")]
    pub(crate) up: [f64; 3],
    #[serde(default = "sixty")]
    pub(crate) fov_deg: f64,
}

fn z_up() -> [f64; 3] {
    [0.0, 0.0, 1.0]
}

fn sixty() -> f64 {
    60.0
}

/// One scan ready to stream: file, which scan in it, its pose and scanner position in the world.
#[derive(Clone, Debug)]
pub struct ResolvedScan {
    pub path: PathBuf,
    pub format: ScanFormat,
    pub(crate) index: usize,
    pub(crate) world_from_scan: Pose,
    pub(crate) scanner_world_m: [f64; 3],
    /// Whether the pose came from the file (E57) rather than the manifest or identity.
    pub pose_from_file: bool,
    /// Whether `scanner_world_m` is a scanner: the manifest gives an `origin`, or a pose (from the
    /// manifest, a `.conf`, or the file) places the scan frame, whose origin is then its scanner.
    /// A bare file with neither is a merged, registered cloud: its frame origin is a survey datum,
    /// not a scanner, and its normals are oriented by enclosure instead (orient.rs).
    pub scanner_known: bool,
    /// For a scan without a scanner: which side of its surface it was seen from.
    pub(crate) seen_from: SeenFrom,
}

/// The survey a package is built with: a Survex `.3d` or Compass `.plt` file, and where its
/// coordinates lie in the scans' world.
#[derive(Clone, Debug, Default, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct SurveySpec {
    pub(crate) path: PathBuf,
    /// Added to every survey position (metres, east north up) to put it in the scans'
    /// coordinates: for a survey kept in a local grid.
    pub(crate) translation: Option<[f64; 3]>,
}

impl SurveySpec {
    /// The survey at `path` (resolved), moved by `translation`.
    pub(crate) fn read(&self, path: &Path) -> Result<grotto_format::survey::Survey> {
        let mut survey = grotto_format::survey::read(path).map_err(|e| Error::Read {
            path: path.to_path_buf(),
            format: "survey",
            reason: e.problem,
        })?;
        if let Some(t) = self.translation {
            if !t.iter().all(|v| v.is_finite()) {
                return Err(manifest_error(path, format!("[survey] translation {t:?} is not finite")));
            }
            survey.translate(t);
        }
        Ok(survey)
    }
}

fn manifest_error(path: &Path, reason: impl std::fmt::Display) -> Error {
    Error::Manifest { path: path.to_path_buf(), reason: reason.to_string() }
}

impl Manifest {
    pub(crate) fn from_toml_file(path: &Path) -> Result<Self> {
        let text =
            std::fs::read_to_string(path).map_err(|source| Error::Io { path: path.to_path_buf(), source })?;
        let mut m: Manifest = toml::from_str(&text).map_err(|e| manifest_error(path, e))?;
        m.base_dir = path.parent().map(Path::to_path_buf).unwrap_or_default();
        if m.scans.is_empty() {
            return Err(manifest_error(path, "lists no [[scan]]"));
        }
        // Read now, so a survey that cannot be used stops the build before its scans are read.
        if let Some(spec) = &m.survey {
            m.survey_data = Some(spec.read(&m.resolve_path(&spec.path))?);
        }
        Ok(m)
    }

    /// Gives every scan that does not say where it was seen from `seen_from` (the command
    /// line's `--seen-from`); a scan's own `seen_from` wins.
    pub fn default_seen_from(&mut self, seen_from: SeenFrom) {
        for scan in &mut self.scans {
            scan.seen_from.get_or_insert(seen_from);
        }
    }

    /// A bare list of scan files, identity poses.
    pub fn from_files(paths: &[PathBuf]) -> Self {
        Manifest {
            scans: paths.iter().map(|p| ScanSpec { path: p.clone(), ..ScanSpec::default() }).collect(),
            ..Manifest::default()
        }
    }

    /// A Stanford range-data `.conf` (`bmesh FILE tx ty tz qi qj qk qr` lines; `camera` lines are
    /// ignored): each scan's translation and rotation quaternion (scalar last).
    ///
    /// The quaternion in these files rotates the frame rather than the points: the scan-to-world
    /// rotation in this crate's (Hamilton, active) convention is its conjugate. Measured on the
    /// ten bunny scans: conjugated, each scan lies a median 0.23-0.33 mm from the others; taken as
    /// written, 8-108 mm (the `bunny_scans_merge...` test keeps both facts).
    pub(crate) fn from_stanford_conf(path: &Path) -> Result<Self> {
        let text =
            std::fs::read_to_string(path).map_err(|source| Error::Io { path: path.to_path_buf(), source })?;
        let mut scans = Vec::new();
        for (i, line) in text.lines().enumerate() {
            let words: Vec<&str> = line.split_whitespace().collect();
            if words.first() != Some(&"bmesh") {
                continue;
            }
            let bad = || {
                manifest_error(path, format!("line {}: expected `bmesh FILE tx ty tz qi qj qk qr`", i + 1))
            };
            if words.len() != 9 {
                return Err(bad());
            }
            let v: Vec<f64> =
                words[2..].iter().map(|w| w.parse::<f64>()).collect::<Result<_, _>>().map_err(|_| bad())?;
            scans.push(ScanSpec {
                path: PathBuf::from(words[1]),
                translation: Some([v[0], v[1], v[2]]),
                rotation: Some([v[6], -v[3], -v[4], -v[5]]),
                ..ScanSpec::default()
            });
        }
        if scans.is_empty() {
            return Err(manifest_error(path, "has no bmesh lines"));
        }
        Ok(Manifest {
            scans,
            base_dir: path.parent().map(Path::to_path_buf).unwrap_or_default(),
            ..Manifest::default()
        })
    }

    /// Loads a manifest from `path` by its extension (`.toml` or `.conf`).
    pub fn load(path: &Path) -> Result<Self> {
        match path.extension().and_then(|e| e.to_str()) {
            Some("conf") => Self::from_stanford_conf(path),
            _ => Self::from_toml_file(path),
        }
    }

    /// A path from the manifest, relative to its directory.
    pub(crate) fn resolve_path(&self, p: &Path) -> PathBuf {
        if p.is_absolute() { p.to_path_buf() } else { self.base_dir.join(p) }
    }

    /// Expands every entry into scans (E57 files into their point clouds), with poses checked.
    pub fn resolve(&self) -> Result<Vec<ResolvedScan>> {
        let mut out = Vec::new();
        for spec in &self.scans {
            let path = self.resolve_path(&spec.path);
            let format = match spec.format {
                Some(f) => f,
                None => ScanFormat::detect(&path)?,
            };
            let manifest_pose = match (spec.matrix, spec.translation, spec.rotation) {
                (Some(_), Some(_), _) | (Some(_), _, Some(_)) => {
                    return Err(manifest_error(
                        &path,
                        "give either matrix or translation/rotation, not both",
                    ));
                }
                (Some(m), None, None) => Some(Pose::from_matrix(m)),
                (None, None, None) => None,
                (None, t, r) => {
                    Some(Pose::from_quaternion(r.unwrap_or([1.0, 0.0, 0.0, 0.0]), t.unwrap_or([0.0; 3])))
                }
            }
            .transpose()
            .map_err(|reason| manifest_error(&path, reason))?;
            let count = ingest::scan_count(&path, format)?;
            let indices: Vec<usize> = match spec.scan {
                Some(i) if i < count => vec![i],
                Some(i) => return Err(manifest_error(&path, format!("has {count} scans, no scan {i}"))),
                None => (0..count).collect(),
            };
            for index in indices {
                let file_pose = if format == ScanFormat::E57 && manifest_pose.is_none() {
                    ingest::header(&path, format, index)?.file_pose
                } else {
                    None
                };
                let world_from_scan = manifest_pose.or(file_pose).unwrap_or_default();
                let origin = spec.origin.unwrap_or([0.0; 3]);
                if !origin.iter().all(|v| v.is_finite()) {
                    return Err(manifest_error(&path, format!("scanner origin {origin:?} is not finite")));
                }
                out.push(ResolvedScan {
                    path: path.clone(),
                    format,
                    index,
                    world_from_scan,
                    scanner_world_m: world_from_scan.apply(origin),
                    pose_from_file: file_pose.is_some(),
                    scanner_known: spec.origin.is_some() || manifest_pose.is_some() || file_pose.is_some(),
                    seen_from: spec.seen_from.unwrap_or_default(),
                });
            }
        }
        Ok(out)
    }

    /// The scene the package carries.
    pub(crate) fn scene(&self, manifest_path: &Path) -> Result<Scene> {
        let mut lights = Vec::new();
        for l in &self.lights {
            let missing = |what: &str| {
                manifest_error(manifest_path, format!("light '{}' ({}) needs {what}", l.name, l.kind))
            };
            let shape = match l.kind.as_str() {
                "point" => LightShape::Point { position_m: l.position.ok_or_else(|| missing("position"))? },
                "spot" => LightShape::Spot {
                    position_m: l.position.ok_or_else(|| missing("position"))?,
                    direction: l.direction.ok_or_else(|| missing("direction"))?,
                    inner_angle_rad: l.inner_angle_deg.unwrap_or(20.0).to_radians(),
                    outer_angle_rad: l.outer_angle_deg.unwrap_or(30.0).to_radians(),
                },
                "area" => LightShape::Area {
                    center_m: l.center.ok_or_else(|| missing("center"))?,
                    normal: l.normal.ok_or_else(|| missing("normal"))?,
                    size_m: l.size.ok_or_else(|| missing("size"))?,
                },
                other => {
                    return Err(manifest_error(
                        manifest_path,
                        format!("light kind '{other}' is not point, spot or area"),
                    ));
                }
            };
            lights.push(Light {
                name: l.name.clone(),
                shape,
                color: l.color,
                power_w: l.power_w,
                circuit: None,
                profile: None,
            });
        }
        let cameras: Vec<Camera> = self
            .cameras
            .iter()
            .map(|c| Camera {
                name: c.name.clone(),
                eye_m: c.eye,
                look_at_m: c.look_at,
                up: c.up,
                fov_y_deg: c.fov_deg,
            })
            .collect();
        let (pois, tours) = StorySpec { poi: self.pois.clone(), tour: self.tours.clone() }
            .into_story(&cameras.iter().map(|c| c.name.as_str()).collect::<Vec<_>>())
            .map_err(|e| manifest_error(manifest_path, e))?;
        Ok(Scene {
            lights,
            circuits: Vec::new(),
            materials: self
                .materials
                .iter()
                .map(|m| Material {
                    name: m.name.clone(),
                    specular: m.specular,
                    roughness: m.roughness,
                    ior: m.ior,
                    region: m.region.as_ref().map(|r| grotto_format::MaterialRegion {
                        min_m: r.min,
                        max_m: r.max,
                        min_normal_z: r.min_normal_z,
                    }),
                })
                .collect(),
            cameras,
            environment: self.environment.as_ref().map(|e| Environment {
                index: 0,
                intensity: e.intensity,
                source: e.map.display().to_string(),
            }),
            // The build fills in the scans it read.
            scans: Vec::new(),
            pois,
            tours,
        })
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn manifest(dir: &Path, text: &str) -> Result<Manifest> {
        let path = dir.join("m.toml");
        std::fs::write(&path, text).unwrap();
        Manifest::from_toml_file(&path)
    }

    #[test]
    fn seen_from_is_read_per_scan_and_the_command_line_fills_the_rest() {
        let dir = tempfile::tempdir().unwrap();
        let mut m = manifest(
            dir.path(),
            "[[scan]]\npath = \"a.ply\"\nseen_from = \"inside\"\n\n[[scan]]\npath = \"b.ply\"\n\n\
             [[scan]]\npath = \"c.ply\"\nseen_from = \"outside\"\n",
        )
        .unwrap();
        let given: Vec<_> = m.scans.iter().map(|s| s.seen_from).collect();
        assert_eq!(given, [Some(SeenFrom::Inside), None, Some(SeenFrom::Outside)]);
        m.default_seen_from(SeenFrom::Outside);
        let now: Vec<_> = m.scans.iter().map(|s| s.seen_from).collect();
        assert_eq!(now, [Some(SeenFrom::Inside), Some(SeenFrom::Outside), Some(SeenFrom::Outside)]);
        let err = manifest(dir.path(), "[[scan]]\npath = \"a.ply\"\nseen_from = \"above\"\n").unwrap_err();
        let text = err.to_string();
        assert!(text.contains("m.toml") && text.contains("above"), "{text}");
    }
}
