//! Rigid poses: scan frame -> world, in f64. Given as translation + unit quaternion (w, x, y, z)
//! or as a 4x4 row-major matrix; anything that is not a rotation plus a translation (a scale, a
//! shear, a quaternion far from unit length, NaN) is refused with the reason, because a wrong pose
//! silently misplaces a whole scan.

use serde::Serialize;

/// `world = rotation * p + translation`.
#[derive(Clone, Copy, Debug, PartialEq, Serialize)]
pub struct Pose {
    /// Row-major 3x3 rotation.
    pub(crate) rotation: [[f64; 3]; 3],
    pub(crate) translation: [f64; 3],
}

impl Default for Pose {
    fn default() -> Self {
        Self::IDENTITY
    }
}

impl Pose {
    pub(crate) const IDENTITY: Pose =
        Pose { rotation: [[1.0, 0.0, 0.0], [0.0, 1.0, 0.0], [0.0, 0.0, 1.0]], translation: [0.0; 3] };

    /// From a unit quaternion `[w, x, y, z]` (Hamilton convention, rotating scan-frame vectors into
    /// the world) and a translation. Quaternions within 1e-3 of unit length are normalised.
    pub(crate) fn from_quaternion(wxyz: [f64; 4], translation: [f64; 3]) -> Result<Self, String> {
        if !wxyz.iter().chain(&translation).all(|v| v.is_finite()) {
            return Err(format!(
                "pose has a non-finite value: rotation {wxyz:?}, translation {translation:?}"
            ));
        }
        let norm = wxyz.iter().map(|v| v * v).sum::<f64>().sqrt();
        if (norm - 1.0).abs() > 1e-3 {
            return Err(format!("rotation quaternion {wxyz:?} has length {norm}, not 1"));
        }
        let [w, x, y, z] = wxyz.map(|v| v / norm);
        Ok(Self {
            rotation: [
                [1.0 - 2.0 * (y * y + z * z), 2.0 * (x * y - w * z), 2.0 * (x * z + w * y)],
                [2.0 * (x * y + w * z), 1.0 - 2.0 * (x * x + z * z), 2.0 * (y * z - w * x)],
                [2.0 * (x * z - w * y), 2.0 * (y * z + w * x), 1.0 - 2.0 * (x * x + y * y)],
            ],
            translation,
        })
    }

    /// From a row-major 4x4 matrix whose upper 3x3 is a rotation (orthonormal within 1e-4,
    /// determinant +1) and whose last row is `0 0 0 1`.
    pub(crate) fn from_matrix(m: [f64; 16]) -> Result<Self, String> {
        if !m.iter().all(|v| v.is_finite()) {
            return Err("pose matrix has a non-finite value".into());
        }
        if m[12..] != [0.0, 0.0, 0.0, 1.0] {
            return Err(format!("pose matrix's last row is {:?}, not [0, 0, 0, 1]", &m[12..]));
        }
        let r = [[m[0], m[1], m[2]], [m[4], m[5], m[6]], [m[8], m[9], m[10]]];
        for i in 0..3 {
            for j in 0..3 {
                let dot: f64 = (0..3).map(|k| r[i][k] * r[j][k]).sum();
                let want = if i == j { 1.0 } else { 0.0 };
                if (dot - want).abs() > 1e-4 {
                    return Err(format!(
                        "pose matrix's rotation part is not orthonormal (rows {i}.{j} = {dot:.6})"
                    ));
                }
            }
        }
        let det = r[0][0] * (r[1][1] * r[2][2] - r[1][2] * r[2][1])
            - r[0][1] * (r[1][0] * r[2][2] - r[1][2] * r[2][0])
            + r[0][2] * (r[1][0] * r[2][1] - r[1][1] * r[2][0]);
        if det < 0.0 {
            return Err("pose matrix is a reflection (determinant -1)".into());
        }
        Ok(Self { rotation: r, translation: [m[3], m[7], m[11]] })
    }

    pub(crate) fn rotate(&self, v: [f64; 3]) -> [f64; 3] {
        let r = &self.rotation;
        std::array::from_fn(|i| r[i][0] * v[0] + r[i][1] * v[1] + r[i][2] * v[2])
    }

    /// `p` in the scan's frame, moved into the world.
    pub fn apply(&self, p: [f64; 3]) -> [f64; 3] {
        let v = self.rotate(p);
        std::array::from_fn(|i| v[i] + self.translation[i])
    }

    /// `self` after `inner`: first `inner`, then `self`.
    #[cfg(test)]
    fn then_after(&self, inner: &Pose) -> Pose {
        let r = std::array::from_fn(|i| {
            std::array::from_fn(|j| (0..3).map(|k| self.rotation[i][k] * inner.rotation[k][j]).sum())
        });
        Pose { rotation: r, translation: self.apply(inner.translation) }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn quaternion_rotates_counter_clockwise_about_its_axis() {
        // 90 degrees about +z: x -> y.
        let h = std::f64::consts::FRAC_1_SQRT_2;
        let p = Pose::from_quaternion([h, 0.0, 0.0, h], [1.0, 2.0, 3.0]).unwrap();
        let v = p.apply([1.0, 0.0, 0.0]);
        assert!((v[0] - 1.0).abs() < 1e-12 && (v[1] - 3.0).abs() < 1e-12 && (v[2] - 3.0).abs() < 1e-12);
    }

    #[test]
    fn matrix_and_quaternion_agree_and_bad_poses_are_refused() {
        let raw = [0.9f64, 0.1, -0.3, 0.2];
        let norm = raw.iter().map(|v| v * v).sum::<f64>().sqrt();
        let q = Pose::from_quaternion(raw.map(|v| v / norm), [5e5, 5e6, 10.0]).unwrap();
        let r = q.rotation;
        let t = q.translation;
        let m = Pose::from_matrix([
            r[0][0], r[0][1], r[0][2], t[0], r[1][0], r[1][1], r[1][2], t[1], r[2][0], r[2][1], r[2][2],
            t[2], 0.0, 0.0, 0.0, 1.0,
        ])
        .unwrap();
        assert_eq!(q, m);
        assert!(Pose::from_quaternion([2.0, 0.0, 0.0, 0.0], [0.0; 3]).is_err());
        assert!(Pose::from_quaternion([f64::NAN, 0.0, 0.0, 1.0], [0.0; 3]).is_err());
        let mut scaled = [0.0; 16];
        for i in 0..3 {
            scaled[i * 5] = 2.0;
        }
        scaled[15] = 1.0;
        assert!(Pose::from_matrix(scaled).unwrap_err().contains("orthonormal"));
        let mut mirror = [0.0; 16];
        mirror[0] = -1.0;
        mirror[5] = 1.0;
        mirror[10] = 1.0;
        mirror[15] = 1.0;
        assert!(Pose::from_matrix(mirror).unwrap_err().contains("reflection"));
        let composed = q.then_after(&Pose::IDENTITY);
        assert_eq!(composed, q);
    }
}
