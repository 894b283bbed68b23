//! Pinhole cameras in frame coordinates and camera paths between named viewpoints.

use glam::{Mat4, Vec2, Vec3, Vec4};

use crate::error::{Error, Result};
use crate::scene::data::SceneCamera;

/// A perspective camera (right-handed, depth 0..1 as wgpu expects).
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Camera {
    pub eye_m: Vec3,
    pub look_at_m: Vec3,
    pub up: Vec3,
    pub fov_y_deg: f32,
}

impl Camera {
    /// The camera of a named package view.
    pub fn from_scene(c: &SceneCamera) -> Self {
        Self { eye_m: c.eye_m, look_at_m: c.look_at_m, up: c.up, fov_y_deg: c.fov_y_deg }
    }

    /// Rejects what would give NaN matrices: eye on the target, up along the view, bad fov.
    pub fn validate(&self) -> Result<()> {
        let f = self.look_at_m - self.eye_m;
        if !(self.eye_m.is_finite() && self.look_at_m.is_finite() && self.up.is_finite()) {
            return Err(Error::Camera("eye, look-at and up must be finite".into()));
        }
        if f.length() < 1e-6 {
            return Err(Error::Camera("eye and look-at coincide".into()));
        }
        if f.normalize().cross(self.up.normalize_or_zero()).length() < 1e-4 {
            return Err(Error::Camera("up is parallel to the view direction".into()));
        }
        if !(self.fov_y_deg > 0.1 && self.fov_y_deg < 179.0) {
            return Err(Error::Camera(format!(
                "vertical field of view {} deg is outside 0.1..179",
                self.fov_y_deg
            )));
        }
        Ok(())
    }

    /// Projection * view for a `width x height` image, clipping at `near_m .. far_m`.
    pub fn view_proj(&self, width: u32, height: u32, near_m: f32, far_m: f32) -> Mat4 {
        let aspect = width as f32 / height.max(1) as f32;
        Mat4::perspective_rh(self.fov_y_deg.to_radians(), aspect, near_m, far_m)
            * Mat4::look_at_rh(self.eye_m, self.look_at_m, self.up)
    }

    /// Linear blend of eye, target and fov (`t` in 0..=1).
    pub fn lerp(&self, other: &Camera, t: f32) -> Camera {
        Camera {
            eye_m: self.eye_m.lerp(other.eye_m, t),
            look_at_m: self.look_at_m.lerp(other.look_at_m, t),
            up: self.up.lerp(other.up, t).normalize_or(self.up),
            fov_y_deg: self.fov_y_deg + (other.fov_y_deg - self.fov_y_deg) * t,
        }
    }
}

/// Fly or orbit: eye, heading and pitch (z up), speed in metres a second; in orbit, the eye
/// circles `pivot_m` at `distance_m`. The window's and the browser's controls move it.
#[derive(Clone, Copy, Debug)]
pub struct Nav {
    pub(crate) eye_m: Vec3,
    pub(crate) yaw_rad: f32,
    pub(crate) pitch_rad: f32,
    pub speed_m_s: f32,
    pub(crate) fov_y_deg: f32,
    pub(crate) orbit: Option<(Vec3, f32)>,
}

impl Nav {
    /// Fly controls starting at `c`, moving at `speed_m_s`.
    pub fn from_camera(c: &Camera, speed_m_s: f32) -> Self {
        let d = (c.look_at_m - c.eye_m).normalize_or(Vec3::X);
        Self {
            eye_m: c.eye_m,
            yaw_rad: d.y.atan2(d.x),
            pitch_rad: d.z.clamp(-1.0, 1.0).asin(),
            speed_m_s,
            fov_y_deg: c.fov_y_deg,
            orbit: None,
        }
    }

    /// At `c`, flying a twentieth of `scene`'s largest extent a second (at least 0.5 m/s).
    pub fn for_scene(c: &Camera, scene: &crate::scene::data::SceneData) -> Self {
        let (lo, hi) = scene.bounds_leaf();
        let size_m = ((hi - lo) * scene.leaf_size_m).max_element();
        Self::from_camera(c, (size_m / 20.0).max(0.5))
    }

    pub(crate) fn forward(&self) -> Vec3 {
        let (sy, cy) = self.yaw_rad.sin_cos();
        let (sp, cp) = self.pitch_rad.sin_cos();
        Vec3::new(cy * cp, sy * cp, sp)
    }

    /// The camera the controls are at.
    pub fn camera(&self) -> Camera {
        let f = self.forward();
        let (eye_m, look_at_m) = match self.orbit {
            Some((pivot, distance)) => (pivot - f * distance, pivot),
            None => (self.eye_m, self.eye_m + f),
        };
        Camera { eye_m, look_at_m, up: Vec3::Z, fov_y_deg: self.fov_y_deg }
    }

    /// Orbits `pivot_m` from where the eye is now.
    pub fn orbit_around(&mut self, pivot_m: Vec3) {
        let eye = self.camera().eye_m;
        let d = pivot_m - eye;
        let distance = d.length().max(1e-3);
        let f = d / distance;
        self.yaw_rad = f.y.atan2(f.x);
        self.pitch_rad = f.z.clamp(-1.0, 1.0).asin();
        self.orbit = Some((pivot_m, distance));
    }

    /// Flies on from where the orbit put the eye.
    pub(crate) fn fly(&mut self) {
        self.eye_m = self.camera().eye_m;
        self.orbit = None;
    }

    /// Flies for `dt_s` with these keys held (forward, left, back, right, down, up: W A S D Q
    /// E); an orbit ends where a key moves the eye.
    pub fn step(&mut self, held: [bool; 6], dt_s: f32) {
        let f = self.forward();
        let right = f.cross(Vec3::Z).normalize_or(Vec3::X);
        let axes = [f, -right, -f, right, -Vec3::Z, Vec3::Z];
        let step: Vec3 = held.iter().zip(axes).filter(|(h, _)| **h).map(|(_, a)| a).sum();
        if step != Vec3::ZERO {
            if self.orbit.is_some() {
                self.fly();
            }
            self.eye_m += step * self.speed_m_s * dt_s;
        }
    }

    /// Looks around by a drag of (dx, dy) pixels.
    pub fn look(&mut self, dx: f32, dy: f32) {
        let k = 0.005;
        self.yaw_rad -= dx * k;
        self.pitch_rad = (self.pitch_rad - dy * k).clamp(-1.5, 1.5);
    }

    /// A two-finger gesture on a touch screen: fingers spread by `scale` (2: twice as far
    /// apart) move the eye forward, as far as a second's flight for each doubling; the fingers'
    /// midpoint moving by `(dx, dy)` pixels of a `height_px` tall view pans the eye with them
    /// (a full view's height: a second's flight), right and up as the fingers go left and down,
    /// as a map under the fingers would.
    pub fn pinch(&mut self, scale: f32, dx: f32, dy: f32, height_px: f32) {
        if !(scale.is_finite() && scale > 0.0 && dx.is_finite() && dy.is_finite()) {
            return;
        }
        if self.orbit.is_some() {
            self.fly();
        }
        let f = self.forward();
        let right = f.cross(Vec3::Z).normalize_or(Vec3::X);
        let up = right.cross(f);
        let per_px = self.speed_m_s / height_px.max(1.0);
        self.eye_m += f * (scale.log2() * self.speed_m_s) - right * (dx * per_px) + up * (dy * per_px);
    }

    /// A turn of the wheel by `lines` (up positive): flying speed, or in orbit, the distance.
    pub fn wheel(&mut self, lines: f32) {
        match &mut self.orbit {
            Some((_, distance)) => *distance = (*distance * 1.25f32.powf(-lines)).clamp(0.05, 1e4),
            None => self.speed_m_s = (self.speed_m_s * 1.25f32.powf(lines)).clamp(0.01, 1000.0),
        }
    }
}

/// `frames` cameras along the polyline through `keys` (each segment gets frames in proportion to
/// its length in eye distance, so speed is steady).
pub fn path(keys: &[Camera], frames: u32) -> Vec<Camera> {
    if keys.len() < 2 || frames < 2 {
        return keys.iter().copied().take(frames.max(1) as usize).collect();
    }
    let lengths: Vec<f32> = keys.windows(2).map(|w| (w[1].eye_m - w[0].eye_m).length().max(1e-3)).collect();
    let total: f32 = lengths.iter().sum();
    (0..frames)
        .map(|i| {
            let mut s = total * i as f32 / (frames - 1) as f32;
            for (k, len) in lengths.iter().enumerate() {
                if s <= *len || k == lengths.len() - 1 {
                    return keys[k].lerp(&keys[k + 1], (s / len).min(1.0));
                }
                s -= len;
            }
            keys[keys.len() - 1]
        })
        .collect()
}

/// Whether the box `lo..hi` (frame metres) may show in a view of `view_proj` (wgpu clip space: z
/// in 0..=w): false only where all eight corners lie outside one clip plane, so it never culls
/// what shows. Shadow faces and the G-buffer cull tiles with it; residency's `in_frustum` is the
/// same test from view parameters, with no far plane.
pub(crate) fn sees_box(view_proj: &Mat4, lo: Vec3, hi: Vec3) -> bool {
    sees_box_grown(view_proj, lo, hi, Vec2::ZERO)
}

/// [`sees_box`] with the side planes moved out by `grow_ndc` (NDC units in x and y): for what
/// may reach past the viewport's edges by a margin the box does not hold (discs grown to a pixel
/// floor).
pub(crate) fn sees_box_grown(view_proj: &Mat4, lo: Vec3, hi: Vec3, grow_ndc: Vec2) -> bool {
    let corners: [Vec4; 8] = std::array::from_fn(|i| {
        let c = Vec3::new(
            if i & 1 == 0 { lo.x } else { hi.x },
            if i & 2 == 0 { lo.y } else { hi.y },
            if i & 4 == 0 { lo.z } else { hi.z },
        );
        *view_proj * c.extend(1.0)
    });
    let (gx, gy) = (1.0 + grow_ndc.x.max(0.0), 1.0 + grow_ndc.y.max(0.0));
    let outside = |plane: &dyn Fn(Vec4) -> f32| corners.iter().all(|&c| plane(c) < 0.0);
    !(outside(&|c| gx * c.w + c.x)
        || outside(&|c| gx * c.w - c.x)
        || outside(&|c| gy * c.w + c.y)
        || outside(&|c| gy * c.w - c.y)
        || outside(&|c| c.z)
        || outside(&|c| c.w - c.z))
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn spreading_two_fingers_moves_forward_and_dragging_them_pans() {
        let c = Camera { eye_m: Vec3::ZERO, look_at_m: Vec3::X, up: Vec3::Z, fov_y_deg: 60.0 };
        let mut n = Nav::from_camera(&c, 2.0);
        n.pinch(2.0, 0.0, 0.0, 600.0);
        assert!((n.camera().eye_m - Vec3::new(2.0, 0.0, 0.0)).length() < 1e-5, "{}", n.camera().eye_m);
        n.pinch(0.5, 0.0, 0.0, 600.0);
        assert!(n.camera().eye_m.length() < 1e-5, "pinching in comes back");
        // Fingers to the left and down by a full view: the eye goes right (-y when looking
        // along +x) and up by a second's flight.
        n.pinch(1.0, -600.0, 600.0, 600.0);
        assert!((n.camera().eye_m - Vec3::new(0.0, -2.0, 2.0)).length() < 1e-4, "{}", n.camera().eye_m);
        let before = n.camera();
        n.pinch(f32::NAN, 1.0, 1.0, 600.0);
        assert_eq!(n.camera(), before, "a NaN gesture changes nothing");
    }

    #[test]
    fn a_box_is_culled_only_when_wholly_outside_the_view() {
        let proj = Mat4::perspective_rh(90f32.to_radians(), 1.0, 0.1, 100.0);
        let view = Mat4::look_at_rh(Vec3::ZERO, Vec3::NEG_Z, Vec3::Y);
        let m = proj * view;
        let sees = |lo: [f32; 3], hi: [f32; 3]| sees_box(&m, Vec3::from(lo), Vec3::from(hi));
        assert!(sees([-1.0, -1.0, -6.0], [1.0, 1.0, -4.0]), "ahead");
        assert!(!sees([-1.0, -1.0, 4.0], [1.0, 1.0, 6.0]), "behind");
        assert!(!sees([20.0, -1.0, -6.0], [22.0, 1.0, -4.0]), "right of the 90 degree cone");
        assert!(!sees([-1.0, -1.0, -300.0], [1.0, 1.0, -200.0]), "past the far plane");
        assert!(sees([-100.0, -100.0, -50.0], [100.0, 100.0, 50.0]), "around the eye");
        assert!(sees([4.0, -1.0, -6.0], [8.0, 1.0, -4.0]), "across the edge");
    }
}

/// A camera path file: `[[camera]]` tables as the build manifest writes them (world metres, f64),
/// in order. The manifest's reader (`grotto_preprocess::manifest::CameraSpec`) is not reused: the
/// runtime does not depend on the build crate, and here a keyframe's name is optional. `grotto view` records one (K, or `--record-path`); `grotto render --path FILE.toml`
/// flies along it; its tables can be pasted into a manifest as named cameras.
#[cfg(not(target_arch = "wasm32"))]
pub(crate) mod path_file {
    use std::path::Path;

    use glam::{DVec3, Vec3};
    use serde::{Deserialize, Serialize};

    use super::Camera;
    use crate::error::{Error, Result};

    #[derive(Debug, Deserialize, Serialize)]
    #[serde(deny_unknown_fields)]
    struct File {
        camera: Vec<Key>,
    }

    #[derive(Debug, Deserialize, Serialize)]
    #[serde(deny_unknown_fields)]
    struct Key {
        #[serde(default)]
        name: String,
        eye: [f64; 3],
        look_at: [f64; 3],
        #[serde(default = "z_up")]
        up: [f64; 3],
        #[serde(default = "sixty")]
        fov_deg: f64,
    }

    fn z_up() -> [f64; 3] {
        [0.0, 0.0, 1.0]
    }

    fn sixty() -> f64 {
        60.0
    }

    /// Whether `--path` names a file rather than cameras: one value ending in `.toml`.
    pub(crate) fn is_file(path: &[String]) -> bool {
        matches!(path, [one] if one.ends_with(".toml"))
    }

    /// The cameras of a path file, in the frame whose origin is `frame_origin_m` (world metres).
    pub(crate) fn read(file: &Path, frame_origin_m: [f64; 3]) -> Result<Vec<Camera>> {
        let err = |problem: String| Error::CameraPath { path: file.display().to_string(), problem };
        let text = std::fs::read_to_string(file).map_err(|e| err(e.to_string()))?;
        let parsed: File = toml::from_str(&text).map_err(|e| err(e.to_string()))?;
        if parsed.camera.is_empty() {
            return Err(err("no [[camera]] in the file".into()));
        }
        let origin = DVec3::from(frame_origin_m);
        parsed
            .camera
            .iter()
            .enumerate()
            .map(|(i, k)| {
                let c = Camera {
                    eye_m: (DVec3::from(k.eye) - origin).as_vec3(),
                    look_at_m: (DVec3::from(k.look_at) - origin).as_vec3(),
                    up: DVec3::from(k.up).as_vec3(),
                    fov_y_deg: k.fov_deg as f32,
                };
                c.validate().map_err(|e| err(format!("camera {} ({:?}): {e}", i + 1, k.name)))?;
                Ok(c)
            })
            .collect()
    }

    /// The text of a path file for `cameras` (frame coordinates; `frame_origin_m` makes them
    /// world coordinates again).
    pub(crate) fn to_text(cameras: &[Camera], frame_origin_m: [f64; 3]) -> String {
        let origin = DVec3::from(frame_origin_m);
        let world = |v: Vec3| (origin + v.as_dvec3()).to_array();
        let file = File {
            camera: cameras
                .iter()
                .enumerate()
                .map(|(i, c)| Key {
                    name: format!("key-{i:03}"),
                    eye: world(c.eye_m),
                    look_at: world(c.look_at_m),
                    up: c.up.as_dvec3().to_array(),
                    fov_deg: f64::from(c.fov_y_deg),
                })
                .collect(),
        };
        let body = toml::to_string(&file).unwrap_or_default();
        format!(
            "# A camera path recorded by grotto view (world metres). Fly along it with\n\
             # grotto render PACKAGE --path THIS.toml --frames N\n{body}"
        )
    }

    /// Writes a path file atomically (a temporary file renamed into place).
    pub(crate) fn write(file: &Path, cameras: &[Camera], frame_origin_m: [f64; 3]) -> Result<()> {
        let err = |problem: String| Error::CameraPath { path: file.display().to_string(), problem };
        let dir = file.parent().filter(|d| !d.as_os_str().is_empty()).unwrap_or(Path::new("."));
        let mut tmp = tempfile::NamedTempFile::new_in(dir).map_err(|e| err(e.to_string()))?;
        std::io::Write::write_all(&mut tmp, to_text(cameras, frame_origin_m).as_bytes())
            .map_err(|e| err(e.to_string()))?;
        tmp.persist(file).map_err(|e| err(e.to_string()))?;
        Ok(())
    }

    #[cfg(test)]
    mod tests {
        use super::*;

        #[test]
        fn a_path_survives_the_file_at_survey_coordinates() {
            let origin = [512_340.0, 5_123_450.0, 330.0];
            let keys = [
                Camera {
                    eye_m: Vec3::new(1.0, 2.0, 3.0),
                    look_at_m: Vec3::new(4.0, 2.0, 3.0),
                    up: Vec3::Z,
                    fov_y_deg: 70.0,
                },
                Camera {
                    eye_m: Vec3::new(2.5, 2.0, 3.0),
                    look_at_m: Vec3::new(2.5, 6.0, 2.0),
                    up: Vec3::Z,
                    fov_y_deg: 60.0,
                },
            ];
            let dir = tempfile::tempdir().unwrap();
            let f = dir.path().join("walk.toml");
            write(&f, &keys, origin).unwrap();
            let text = std::fs::read_to_string(&f).unwrap();
            assert!(text.contains("[[camera]]") && text.contains("512341"), "{text}");
            let back = read(&f, origin).unwrap();
            assert_eq!(back.len(), 2);
            for (a, b) in keys.iter().zip(&back) {
                assert!((a.eye_m - b.eye_m).length() < 1e-4 && (a.look_at_m - b.look_at_m).length() < 1e-4);
                assert_eq!(a.fov_y_deg, b.fov_y_deg);
            }
            assert!(is_file(&["walk.toml".into()]) && !is_file(&["entrance".into(), "chamber".into()]));
        }

        #[test]
        fn a_bad_path_file_names_itself_and_the_problem() {
            let dir = tempfile::tempdir().unwrap();
            let f = dir.path().join("bad.toml");
            std::fs::write(&f, "[[camera]]\neye = [0, 0, 0]\nlook_at = [0, 0, 0]\n").unwrap();
            let e = read(&f, [0.0; 3]).unwrap_err().to_string();
            assert!(e.contains("bad.toml") && e.contains("coincide"), "{e}");
            std::fs::write(&f, "").unwrap();
            assert!(read(&f, [0.0; 3]).unwrap_err().to_string().contains("camera"));
            let missing = read(&dir.path().join("none.toml"), [0.0; 3]).unwrap_err().to_string();
            assert!(missing.contains("none.toml"), "{missing}");
        }
    }
}
