//! Hand-built scenes with known answers, carved out of solid rock: every cell that is not air is
//! an opaque leaf, so light cannot leak through walls and what a cone meets is well defined.
//! Used by the GPU tests (furnace, multiple bounces, plan) and the accuracy reference.
//!
//! Surface leaves (next to air) get the mean direction to their air neighbours as normal and one
//! surfel per open face; rock further in has no surfels.

use glam::{IVec3, Vec3};
use grotto_format::color::linear_to_srgb8;

use crate::gpu_types::SurfelGpu;
use crate::scene_data::{SceneCamera, SceneData, SceneLight, VoxelLeaf};

const NEIGHBOURS: [IVec3; 6] = [IVec3::X, IVec3::NEG_X, IVec3::Y, IVec3::NEG_Y, IVec3::Z, IVec3::NEG_Z];

/// Solid rock over `dims` leaves with the cells where `air` is true carved out.
/// `normal_override` may give a leaf's normal (the furnace uses it for rock).
#[allow(clippy::too_many_arguments)]
pub fn carved(
    name: &str,
    leaf_size_m: f32,
    tile_depth: u32,
    dims: IVec3,
    air: &dyn Fn(IVec3) -> bool,
    albedo: &dyn Fn(IVec3) -> Vec3,
    emission: Vec3,
    normal_override: Option<&dyn Fn(IVec3) -> Vec3>,
) -> SceneData {
    let mut cells = Vec::new();
    let mut surfels = Vec::new();
    let inside = |c: IVec3| c.cmpge(IVec3::ZERO).all() && c.cmplt(dims).all();
    for z in 0..dims.z {
        for y in 0..dims.y {
            for x in 0..dims.x {
                let c = IVec3::new(x, y, z);
                if air(c) {
                    continue;
                }
                let albedo = albedo(c);
                let mut open = Vec3::ZERO;
                for d in NEIGHBOURS {
                    let n = c + d;
                    if inside(n) && air(n) {
                        open += d.as_vec3();
                        let center = (c.as_vec3() + Vec3::splat(0.5) + d.as_vec3() * 0.5) * leaf_size_m;
                        let rgb = albedo.to_array().map(linear_to_srgb8);
                        surfels.push(SurfelGpu {
                            position_radius: center.extend(0.75 * leaf_size_m).to_array(),
                            normal_spread: d.as_vec3().extend(0.0).to_array(),
                            color: [rgb[0], rgb[1], rgb[2], 0],
                        });
                    }
                }
                let normal = match normal_override {
                    Some(f) => f(c),
                    None => open.normalize_or_zero(),
                };
                cells.push(VoxelLeaf { cell: c, albedo, opacity: 1.0, normal_mean: normal, emission });
            }
        }
    }
    let mut scene = SceneData::from_voxels(name, leaf_size_m, tile_depth, &cells);
    scene.surfels = surfels;
    scene
}

/// The furnace: a closed spherical shell (inner radius `radius_leaves`, two leaves thick, normals
/// toward the centre) in a cube of `2^depth` leaves, every leaf with emission `e` and albedo
/// `albedo`. Every cone from the shell ends on the shell, so the exact answer everywhere is
/// `e / (1 - albedo)`. Like a scanned cave, the shell is thin: coarse levels see through it in
/// part, which the rock behind it (rock.rs) has to stop.
pub fn furnace_sphere(depth: u32, radius_leaves: f32, albedo: f32, e: f32) -> SceneData {
    open_sphere(depth, radius_leaves, albedo, e, f32::INFINITY)
}

/// The furnace shell with a round opening: leaves whose direction from the centre has a z
/// component above `cap_cos` are left out (`cap_cos` >= 1: closed).
pub fn open_sphere(depth: u32, radius_leaves: f32, albedo: f32, e: f32, cap_cos: f32) -> SceneData {
    let n = 1i32 << depth;
    let center = Vec3::splat(n as f32 * 0.5);
    let leaf_size_m = 0.1;
    let mut cells = Vec::new();
    let mut surfels = Vec::new();
    for z in 0..n {
        for y in 0..n {
            for x in 0..n {
                let c = IVec3::new(x, y, z);
                let p = c.as_vec3() + Vec3::splat(0.5);
                let d = (p - center).length();
                if d < radius_leaves || d >= radius_leaves + 2.0 || (p.z - center.z) / d > cap_cos {
                    continue;
                }
                let inward = (center - p).normalize_or(Vec3::Z);
                cells.push(VoxelLeaf {
                    cell: c,
                    albedo: Vec3::splat(albedo),
                    opacity: 1.0,
                    normal_mean: inward,
                    emission: Vec3::splat(e),
                });
                if d < radius_leaves + 1.0 {
                    // At the leaf centre: the surfel lies in its own leaf (the reference takes
                    // emission from the leaf a surfel is in).
                    let at = p;
                    let rgb = linear_to_srgb8(albedo);
                    surfels.push(SurfelGpu {
                        position_radius: (at * leaf_size_m).extend(0.75 * leaf_size_m).to_array(),
                        normal_spread: inward.extend(0.0).to_array(),
                        color: [rgb, rgb, rgb, 0],
                    });
                }
            }
        }
    }
    let mut scene = SceneData::from_voxels("furnace sphere", leaf_size_m, depth, &cells);
    scene.surfels = surfels;
    scene
}

/// Cells of the multi-bounce scene: room A (with the light), a corridor east, a long one north,
/// one west, and chamber C north of A behind 19 leaves of rock. No straight line joins a surface
/// the light sees to a surface of C (the corridor north is too narrow for the slope the corridor
/// west needs), so C is dark after one bounce and lit after several. The corridor north is long
/// so that even wide cones from C do not reach the lit walls through coarse voxels.
pub fn dogleg_air(c: IVec3) -> bool {
    let in_box = |lo: [i32; 3], hi: [i32; 3]| {
        c.cmpge(IVec3::from_array(lo)).all() && c.cmplt(IVec3::from_array(hi)).all()
    };
    in_box([2, 1, 2], [10, 9, 10])          // room A
        || in_box([10, 4, 4], [22, 8, 8])   // corridor east
        || in_box([18, 8, 4], [22, 32, 8])  // corridor north
        || in_box([10, 32, 4], [22, 36, 8]) // corridor west
        || in_box([2, 28, 2], [10, 40, 10]) // chamber C
}

/// Whether a cell belongs to chamber C or its walls (for measuring it).
pub fn dogleg_chamber(c: IVec3) -> bool {
    c.x >= 1 && c.x <= 10 && c.y >= 27 && c.y <= 40 && c.z >= 1 && c.z <= 10
}

/// The multi-bounce scene: 24 x 42 x 12 leaves of 0.25 m in 16-leaf tiles (several tiles, so cones
/// cross tile borders), albedo 0.8, one 200 W point light in room A.
pub fn dogleg() -> SceneData {
    let leaf = 0.25;
    let mut s = carved(
        "dogleg",
        leaf,
        4,
        IVec3::new(24, 42, 12),
        &dogleg_air,
        &|_| Vec3::splat(0.8),
        Vec3::ZERO,
        None,
    );
    s.lights.push(SceneLight {
        name: "lamp".into(),
        position_m: Vec3::new(6.0, 5.0, 6.0) * leaf,
        intensity_w_sr: Vec3::splat(200.0 / (4.0 * std::f32::consts::PI)),
        spot: None,
    });
    s.cameras.push(SceneCamera {
        name: "overview".into(),
        eye_m: Vec3::new(3.0, 2.0, 8.0) * leaf,
        look_at_m: Vec3::new(20.0, 6.0, 5.0) * leaf,
        up: Vec3::Z,
        fov_y_deg: 75.0,
    });
    s
}

/// A closed box (Cornell-like) for colour bleeding: 24 leaves of 0.1 m inside, red wall at -x,
/// green at +x, the rest grey 0.7, one 30 W point light under the ceiling, a camera at the open
/// side looking in. Rock is one leaf thick around it.
pub fn colour_box() -> SceneData {
    let n = 26;
    let air = |c: IVec3| c.cmpge(IVec3::ONE).all() && c.cmplt(IVec3::splat(n - 1)).all();
    let albedo = |c: IVec3| {
        if c.x == 0 {
            Vec3::new(0.75, 0.12, 0.1)
        } else if c.x == n - 1 {
            Vec3::new(0.12, 0.65, 0.15)
        } else {
            Vec3::splat(0.7)
        }
    };
    let leaf = 0.1;
    let mut s = carved("colour box", leaf, 5, IVec3::splat(n), &air, &albedo, Vec3::ZERO, None);
    s.lights.push(SceneLight {
        name: "lamp".into(),
        position_m: Vec3::new(13.0, 13.0, 22.0) * leaf,
        intensity_w_sr: Vec3::new(1.0, 0.9, 0.8) * (30.0 / (4.0 * std::f32::consts::PI)),
        spot: None,
    });
    s.cameras.push(SceneCamera {
        name: "front".into(),
        eye_m: Vec3::new(13.0, 2.0, 13.0) * leaf,
        look_at_m: Vec3::new(13.0, 24.0, 11.0) * leaf,
        up: Vec3::Z,
        fov_y_deg: 70.0,
    });
    s
}
