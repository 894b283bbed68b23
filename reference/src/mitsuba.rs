//! The same scene for Mitsuba 3, so the reference can be checked by a renderer that shares none
//! of its code: every surfel as a Mitsuba shape (its disc, or for the hand-built
//! scenes the voxel face it stands for), its albedo as a two-sided diffuse BSDF, its emission as
//! an area emitter, the point lights as `point` emitters with the same intensity, the camera with
//! the same eye, target, up and vertical field of view, and a box pixel filter (the reference
//! integrates each pixel's area).
//! `scripts/mitsuba-check.py` renders what this writes and compares (docs/reference-mitsuba.md).
//!
//! Written by hand because it is the project's own mapping: Mitsuba's XML is its scene format,
//! and no crate writes it.

use std::fmt::Write as _;

use glam::Vec3;
use grotto_runtime::view::camera::Camera;

use crate::error::Error;
use crate::tracer::SurfelScene;

/// What each surfel becomes in Mitsuba.
#[derive(Clone, Copy, Debug, PartialEq)]
pub enum Shapes {
    /// The reference's own discs (`disk`, same radius): the same model of the surface. The
    /// reference's disc emits on both sides and a Mitsuba area emitter on its front only, so an
    /// emitting disc gets a twin a hair behind it facing the other way (overlapping discs meet
    /// at grazing angles, so a path can reach a disc's back even in a closed shell).
    Discs,
    /// The square voxel face of side `side_m` the surfel stands for (`rectangle`): the exact
    /// surface of the hand-built scenes (fixtures' `carved`: one surfel per open face, on the
    /// face, facing the air), closed, with emitters facing the air.
    Faces { side_m: f32 },
}

/// A Mitsuba 3 scene (XML, version 3.0.0) of `scene` seen by `camera` at `width` x `height` with
/// `spp` samples per pixel and unbounded path depth (Russian roulette from the fifth bounce, as
/// Mitsuba's path tracer does by default), each surfel as `shapes` says.
pub fn scene_xml(
    scene: &SurfelScene,
    shapes: Shapes,
    camera: &Camera,
    width: u32,
    height: u32,
    spp: u32,
) -> Result<String, Error> {
    let mut s = String::new();
    let _ = writeln!(s, "<scene version=\"3.0.0\">");
    let _ =
        writeln!(s, "  <integrator type=\"path\"><integer name=\"max_depth\" value=\"-1\"/></integrator>");
    sensor_and_lights(&mut s, camera, (width, height, spp), scene.lights())?;
    let v = |v: Vec3| format!("{:.9}, {:.9}, {:.9}", v.x, v.y, v.z);
    // One BSDF per distinct albedo, referenced by the discs (`albedo_of`: each disc's).
    let mut albedos: Vec<Vec3> = Vec::new();
    let albedo_of: Vec<usize> = scene
        .discs()
        .iter()
        .map(|d| {
            albedos.iter().position(|x| *x == d.albedo).unwrap_or_else(|| {
                albedos.push(d.albedo);
                albedos.len() - 1
            })
        })
        .collect();
    for (i, a) in albedos.iter().enumerate() {
        let _ = writeln!(
            s,
            "  <bsdf type=\"twosided\" id=\"albedo{i}\"><bsdf type=\"diffuse\"><rgb name=\"reflectance\" value=\"{}\"/></bsdf></bsdf>",
            v(*a)
        );
    }
    for (d, &albedo) in scene.discs().iter().zip(&albedo_of) {
        let emits = d.emission != Vec3::ZERO;
        // A right-handed frame (t1 x t2 = n): Mitsuba's disk is the unit disc and its rectangle
        // the square [-1, 1]^2, both in z = 0 facing +z; for an axis-aligned normal the frame is
        // axis-aligned (glam's branchless basis), so a face's square lies on its voxel face.
        let (kind, half, n) = match shapes {
            Shapes::Discs => ("disk", d.radius_m, d.normal),
            Shapes::Faces { side_m } => {
                ("rectangle", 0.5 * side_m, face_normal(d.center_m, d.normal, side_m))
            }
        };
        let twin = emits && shapes == Shapes::Discs;
        // The twin sits 1e-3 of the disc's radius behind it: beyond Mitsuba's ray offsets at
        // these scales (~1e-4 relative), far below anything the image resolves.
        let sides: &[(Vec3, Vec3)] = if twin {
            &[(n, d.center_m), (-n, d.center_m - n * (1e-3 * d.radius_m))]
        } else {
            &[(n, d.center_m)]
        };
        for &(n, c) in sides {
            let (t1, t2) = n.any_orthonormal_pair();
            let (t1, t2) = if t1.cross(t2).dot(n) > 0.0 { (t1, t2) } else { (t2, t1) };
            let (a, b) = (t1 * half, t2 * half);
            let _ = write!(
                s,
                "  <shape type=\"{kind}\"><transform name=\"to_world\"><matrix value=\"{} {} {} {} {} {} {} {} {} {} {} {} 0 0 0 1\"/></transform><ref id=\"albedo{albedo}\"/>",
                a.x, b.x, n.x, c.x, a.y, b.y, n.y, c.y, a.z, b.z, n.z, c.z
            );
            if emits {
                let _ = write!(
                    s,
                    "<emitter type=\"area\"><rgb name=\"radiance\" value=\"{}\"/></emitter>",
                    v(d.emission)
                );
            }
            let _ = writeln!(s, "</shape>");
        }
    }
    let _ = writeln!(s, "</scene>");
    Ok(s)
}

/// Appends the perspective sensor of `camera` (vertical field of view, `spp` samples a pixel,
/// box filter, linear RGB film of `width` x `height`) and `lights` as point emitters with the
/// same intensity; spot lights are refused by name. Shared by the reference's scenes and the
/// true-surface benchmark's (truth.rs).
pub(crate) fn sensor_and_lights(
    s: &mut String,
    camera: &Camera,
    (width, height, spp): (u32, u32, u32),
    lights: &[grotto_runtime::scene::data::SceneLight],
) -> Result<(), Error> {
    let v = |v: Vec3| format!("{:.9}, {:.9}, {:.9}", v.x, v.y, v.z);
    let _ = writeln!(
        s,
        "  <sensor type=\"perspective\">\n    <string name=\"fov_axis\" value=\"y\"/>\n    <float name=\"fov\" value=\"{:.9}\"/>\n    <transform name=\"to_world\"><lookat origin=\"{}\" target=\"{}\" up=\"{}\"/></transform>\n    <sampler type=\"independent\"><integer name=\"sample_count\" value=\"{spp}\"/></sampler>\n    <film type=\"hdrfilm\">\n      <integer name=\"width\" value=\"{width}\"/>\n      <integer name=\"height\" value=\"{height}\"/>\n      <string name=\"pixel_format\" value=\"rgb\"/>\n      <rfilter type=\"box\"/>\n    </film>\n  </sensor>",
        camera.fov_y_deg,
        v(camera.eye_m),
        v(camera.look_at_m),
        v(camera.up)
    );
    for l in lights {
        if l.spot.is_some() {
            return Err(Error::SpotForMitsuba(l.name.clone()));
        }
        if l.profile.is_some() {
            return Err(Error::ProfileForMitsuba(l.name.clone()));
        }
        let _ = writeln!(
            s,
            "  <emitter type=\"point\"><point name=\"position\" value=\"{}\"/><rgb name=\"intensity\" value=\"{}\"/></emitter>",
            v(l.position_m),
            v(l.intensity_w_sr)
        );
    }
    Ok(())
}

/// The normal of the voxel face centred at `center_m` on a grid of `side_m` cells: along the one
/// axis on which the centre lies on a grid plane, on the side `normal` leans to (the furnace's
/// surfels lean toward its centre, the other scenes' are the face normals already).
fn face_normal(center_m: Vec3, normal: Vec3, side_m: f32) -> Vec3 {
    let off_plane = (center_m / side_m).to_array().map(|v| (v - v.round()).abs());
    let axis = (0..3).min_by(|&a, &b| off_plane[a].total_cmp(&off_plane[b])).unwrap_or(2);
    let mut n = Vec3::ZERO;
    n[axis] = if normal[axis] < 0.0 { -1.0 } else { 1.0 };
    n
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::tracer::Disc;
    use grotto_runtime::scene::data::{SceneLight, Spot};

    fn camera() -> Camera {
        Camera { eye_m: Vec3::ZERO, look_at_m: Vec3::X, up: Vec3::Z, fov_y_deg: 60.0 }
    }

    #[test]
    fn discs_keep_centre_normal_and_radius_and_emitters_get_a_twin_facing_back() {
        let discs = vec![
            Disc::new(Vec3::new(2.0, 0.0, 0.0), Vec3::X, 0.1, Vec3::splat(0.5), Vec3::ZERO),
            Disc::new(Vec3::new(0.0, 3.0, 0.0), Vec3::Y, 0.2, Vec3::splat(0.8), Vec3::ONE),
        ];
        let scene = SurfelScene::new(discs, Vec::new(), 0.05);
        let xml = scene_xml(&scene, Shapes::Discs, &camera(), 8, 6, 4).unwrap();
        let matrices: Vec<Vec<f32>> = xml
            .lines()
            .filter_map(|l| l.split("matrix value=\"").nth(1))
            .map(|m| m.split('"').next().unwrap().split(' ').map(|x| x.parse().unwrap()).collect())
            .collect();
        // The plain disc, then the emitter and its twin.
        let d = scene.discs();
        let want = [(d[0], 1.0f32), (d[1], 1.0), (d[1], -1.0)];
        assert_eq!(matrices.len(), want.len());
        for (m, (d, side)) in matrices.iter().zip(want) {
            let col = |j: usize| Vec3::new(m[j], m[4 + j], m[8 + j]);
            assert!((col(3) - d.center_m).length() < 1e-3 * d.radius_m + 1e-6, "centre");
            assert!(
                (col(0).length() - d.radius_m).abs() < 1e-6 && (col(1).length() - d.radius_m).abs() < 1e-6
            );
            // The disk's +z (its normal) is the third column, and the frame is right-handed.
            assert!(col(0).cross(col(1)).normalize().dot(col(2)) > 0.999);
            assert!((col(2) - side * d.normal).length() < 1e-6, "normal {:?}", col(2));
            // A twin lies behind its disc.
            assert!((col(3) - d.center_m).dot(d.normal) <= 0.0);
        }
        assert_eq!(xml.matches("type=\"area\"").count(), 2);
        assert_eq!(xml.matches("<bsdf type=\"twosided\"").count(), 2);
        assert!(xml.contains("<float name=\"fov\" value=\"60.000000000\"/>"));
    }

    #[test]
    fn a_spot_light_is_refused_by_name() {
        let spot = SceneLight {
            name: "torch".into(),
            position_m: Vec3::ZERO,
            intensity_w_sr: Vec3::ONE,
            spot: Some(Spot { direction: Vec3::X, inner_angle_rad: 0.2, outer_angle_rad: 0.4 }),
            profile: None,
        };
        let scene =
            SurfelScene::new(vec![Disc::new(Vec3::X, Vec3::X, 0.1, Vec3::ONE, Vec3::ZERO)], vec![spot], 0.05);
        let e = scene_xml(&scene, Shapes::Discs, &camera(), 8, 6, 4).unwrap_err();
        assert!(e.to_string().contains("torch"), "{e}");
    }
}
