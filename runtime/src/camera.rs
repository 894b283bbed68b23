//! Pinhole cameras in frame coordinates and camera paths between named viewpoints.

use glam::{Mat4, Vec3, Vec4};

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

/// Whether the box `lo..hi` (frame metres) may show in a view of `view_proj` (wgpu clip space: z
/// in 0..=w): false only where all eight corners lie outside one clip plane, so it never culls
/// what shows. Shadow faces and the G-buffer cull tiles with it; residency's `in_frustum` is the
/// same test from view parameters, with no far plane.
pub fn sees_box(view_proj: &Mat4, lo: Vec3, hi: Vec3) -> bool {
    let corners: [Vec4; 8] = std::array::from_fn(|i| {
        let c = Vec3::new(
            if i & 1 == 0 { lo.x } else { hi.x },
            if i & 2 == 0 { lo.y } else { hi.y },
            if i & 4 == 0 { lo.z } else { hi.z },
        );
        *view_proj * c.extend(1.0)
    });
    let outside = |plane: fn(Vec4) -> f32| corners.iter().all(|&c| plane(c) < 0.0);
    let planes: [fn(Vec4) -> f32; 6] =
        [|c| c.w + c.x, |c| c.w - c.x, |c| c.w + c.y, |c| c.w - c.y, |c| c.z, |c| c.w - c.z];
    !planes.into_iter().any(outside)
}

#[cfg(test)]
mod tests {
    use super::*;

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
