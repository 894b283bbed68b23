//! Pinhole cameras in frame coordinates and camera paths between named viewpoints.

use glam::{Mat4, Vec3};

use crate::error::{Error, Result};
use crate::scene_data::SceneCamera;

/// A perspective camera (right-handed, depth 0..1 as wgpu expects).
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Camera {
    pub eye_m: Vec3,
    pub look_at_m: Vec3,
    pub up: Vec3,
    pub fov_y_deg: f32,
}

impl Camera {
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
