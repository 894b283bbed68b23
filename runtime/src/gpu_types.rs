//! Every struct the GPU sees, as `#[repr(C)]` Pod records with compile-time size checks.
//!
//! Keep in sync with `shaders/common.wgsl` (storage and uniform structs) and `passes/splat.wgsl`
//! (the splat uniform and the surfel vertex layout). WGSL aligns `vec3`/`vec4` to 16 bytes, so
//! everything here is built from 16-byte rows or from 4-byte scalars that fill whole rows.

use bytemuck::{Pod, Zeroable};

/// Most cones a leaf may gather with (the `cones` array in [`Params`]).
pub const MAX_CONES: usize = 16;

/// One resident tile. `origin_leaf` is the tile's minimum corner in global leaf units, counted from
/// the frame origin, so neighbouring tiles share one integer voxel grid at every level.
#[repr(C)]
#[derive(Clone, Copy, Debug, Default, Pod, Zeroable, PartialEq, Eq)]
pub struct TileGpu {
    pub origin_leaf: [i32; 3],
    pub depth: u32,
    pub node_offset: u32,
    pub leaf_offset: u32,
    pub node_count: u32,
    pub leaf_count: u32,
    pub pad: [u32; 4],
}

/// An SVO node with global indices: `first_child` is the global node index of the first child for
/// inner nodes and the global leaf index for leaves (the package stores tile-local indices).
#[repr(C)]
#[derive(Clone, Copy, Debug, Default, Pod, Zeroable, PartialEq, Eq)]
pub struct NodeGpu {
    pub first_child: u32,
    /// `child_mask | level << 8`.
    pub mask_level: u32,
}

impl NodeGpu {
    pub fn child_mask(&self) -> u32 {
        self.mask_level & 0xff
    }
    pub fn level(&self) -> u32 {
        self.mask_level >> 8
    }
}

/// Static attributes of one leaf.
#[repr(C)]
#[derive(Clone, Copy, Debug, Default, Pod, Zeroable, PartialEq)]
pub struct LeafGpu {
    /// Linear albedo and coverage opacity.
    pub albedo_opacity: [f32; 4],
    /// Toksvig mean normal (length = 1 - spread); w unused.
    pub normal_mean: [f32; 4],
    /// Leaf centre in frame metres; w unused.
    pub center_m: [f32; 4],
    /// Emitted radiance, W / (sr m^2); w unused.
    pub emission: [f32; 4],
}

/// Light state of one leaf, rewritten by inject (direct, out) and propagate (gather, out).
#[repr(C)]
#[derive(Clone, Copy, Debug, Default, Pod, Zeroable, PartialEq)]
pub struct LeafLightGpu {
    /// Outgoing radiance from point and spot lights (diffuse, NDF-weighted, shadowed).
    pub direct: [f32; 4],
    /// Cosine-weighted mean incoming radiance from the cones (irradiance / pi).
    pub gather: [f32; 4],
    /// Outgoing radiance `emission + direct + env + albedo * gather`, what the mip pass filters.
    pub out: [f32; 4],
    /// Environment light reflected by the leaf, `albedo * E_sh(n) / pi * V` (rgb), and its sky
    /// visibility V in 0..=1 (w): the radiance-weighted share of the cones that leave the scene.
    /// Written by the env pass; zero without an environment map.
    pub env: [f32; 4],
    /// Irradiance / pi from the lights beyond the shadow-map budget (their per-leaf share,
    /// shadowed by SVO cones or not at all), without albedo: shade adds `albedo * far`
    /// interpolated over leaves instead of evaluating those lights per pixel. Written by inject.
    pub far: [f32; 4],
}

/// A point or spot light in frame metres.
#[repr(C)]
#[derive(Clone, Copy, Debug, Default, Pod, Zeroable, PartialEq)]
pub struct LightGpu {
    /// xyz position, w = kind (0 point, 1 spot).
    pub position_kind: [f32; 4],
    /// Radiant intensity W / sr per channel, w = first shadow layer (-1: no shadow map).
    pub intensity_layer: [f32; 4],
    /// Spot axis, w = cos(outer angle).
    pub direction_cos_outer: [f32; 4],
    /// x = cos(inner angle); y = range in metres (beyond it the light's irradiance is under the
    /// cutoff and it is culled); z = how a light without a shadow map is shadowed
    /// (`light_shadow::*`); w = the irradiance cutoff, W/m^2 (inject skips a light whose
    /// unshadowed irradiance at a leaf is under it).
    pub params: [f32; 4],
}

/// `LightGpu::params.z`: how a light is shadowed. Keep in sync with common.wgsl.
pub mod light_shadow {
    /// A shadow map in the atlas, evaluated per pixel in shade.
    pub const MAP: f32 = 0.0;
    /// Beyond the budget: at leaf resolution, visibility from a cone traced through the SVO.
    pub const CONE: f32 = 1.0;
    /// Beyond the budget: at leaf resolution, unshadowed.
    pub const NONE: f32 = 2.0;
}

/// Per-dispatch settings shared by the compute passes.
#[repr(C)]
#[derive(Clone, Copy, Debug, Pod, Zeroable, PartialEq)]
pub struct Params {
    pub leaf_size_m: f32,
    pub tile_count: u32,
    pub leaf_count: u32,
    pub light_count: u32,

    pub cone_count: u32,
    pub cone_tan_half: f32,
    pub step_scale: f32,
    pub max_distance_m: f32,

    pub max_steps: u32,
    pub max_lod: u32,
    pub shadow_size: u32,
    pub flags: u32,

    pub width: u32,
    pub height: u32,
    pub exposure: f32,
    pub shadow_bias_m: f32,

    /// Shadow atlas: faces per row (each `shadow_size` texels square).
    pub shadow_cols: u32,
    /// Light grid cells per axis (`light_grid` binding: per-cell lists of the lights in range).
    pub light_grid_dims: [u32; 3],
    /// Light grid minimum corner in frame metres (xyz) and cell edge in metres (w).
    pub light_grid_min_m: [f32; 4],

    /// Scene bounds in leaf units (xyz), w unused.
    pub scene_min_leaf: [f32; 4],
    pub scene_max_leaf: [f32; 4],
    /// Background radiance (where a pixel sees nothing), w unused.
    pub background: [f32; 4],
    /// Camera for shade's position reconstruction: eye (w unused), forward (w = tan of half the
    /// vertical fov), right (w = aspect), up; frame metres.
    pub camera_eye_m: [f32; 4],
    pub camera_forward: [f32; 4],
    pub camera_right: [f32; 4],
    pub camera_up: [f32; 4],
    /// Unit cone directions in the tangent frame (z = normal), w = weight (weights sum to 1).
    pub cones: [[f32; 4]; MAX_CONES],
    /// Environment radiance as 9 real SH coefficients (rgb, w unused), order L00, L1-1, L10, L11,
    /// L2-2, L2-1, L20, L21, L22, already scaled by the scene's environment intensity.
    pub env_sh: [[f32; 4]; 9],
    /// Material slots (0 = diffuse, unused): x specular weight Ks, y GGX alpha, z index of
    /// refraction, w GGX roughness.
    pub materials: [[f32; 4]; 8],
    /// Prefiltered environment levels in the env atlas: x first row, y width, z height,
    /// w roughness.
    pub env_levels: [[f32; 4]; 8],
    /// x: levels in the env atlas (0: glossy reflection falls back to the SH), y: atlas width;
    /// zw unused.
    pub env_chain: [u32; 4],
}

/// `Params::flags` bits. Keep in sync with common.wgsl.
pub mod flags {
    /// Shade adds `albedo * gather` (trilinear over leaves).
    pub const INDIRECT: u32 = 1;
    /// Direct light from point and spot lights in shade.
    pub const DIRECT: u32 = 2;
    /// Shadow maps are valid and used.
    pub const SHADOWS: u32 = 4;
    /// Shade adds leaf emission.
    pub const EMISSION: u32 = 8;
    /// Indirect uses tricubic (B-spline) instead of trilinear filtering.
    pub const TRICUBIC: u32 = 16;
    /// An environment map lights the scene through its SH coefficients (`Params::env_sh`).
    pub const ENV: u32 = 32;
    /// Some lights are beyond the shadow-map budget: shade adds their per-leaf light (`far`).
    pub const FAR_LIGHTS: u32 = 64;
    /// Some surfels have a specular material: shade adds Fresnel-weighted reflection (a specular
    /// cone through the SVO, the environment where it escapes, GGX highlights of the lamps).
    pub const SPECULAR: u32 = 128;
}

/// Mip dispatch range: nodes `first .. first + count` of the height-ordered node list.
#[repr(C)]
#[derive(Clone, Copy, Debug, Default, Pod, Zeroable, PartialEq, Eq)]
pub struct MipRange {
    pub first: u32,
    pub count: u32,
    pub height: u32,
    pub pad: u32,
}

/// One inject dispatch: positions `first .. first + count` of each leaf's light-grid cell list;
/// `reset` = 1 for the first batch (which starts the leaf's direct light from zero). Keep in sync
/// with passes/inject.wgsl.
#[repr(C)]
#[derive(Clone, Copy, Debug, Default, Pod, Zeroable, PartialEq, Eq)]
pub struct InjectBatch {
    pub first: u32,
    pub count: u32,
    pub reset: u32,
    pub pad: u32,
}

/// Uniform of one splat render pass (one shadow layer or the camera). 256 bytes so that one buffer
/// holds all of them at dynamic offsets. Keep in sync with passes/splat.wgsl.
#[repr(C)]
#[derive(Clone, Copy, Debug, Pod, Zeroable, PartialEq)]
pub struct SplatUniform {
    pub view_proj: [[f32; 4]; 4],
    /// Eye or light position in frame metres, w unused.
    pub eye_m: [f32; 4],
    /// x, y: viewport size in pixels; z: smallest splat radius in pixels; w: projection scale
    /// (`proj[1][1]`) for the pixel-size estimate.
    pub viewport: [f32; 4],
    /// x: surfel radius scale (discs overlap so sparse sampling closes); yzw unused.
    pub splat: [f32; 4],
    pub pad: [[f32; 4]; 9],
}

/// One surfel as an instance vertex: frame position and radius, unit normal and spread, sRGB colour
/// with the material slot in alpha (0 diffuse, k: `SceneData::materials[k - 1]`).
#[repr(C)]
#[derive(Clone, Copy, Debug, Default, Pod, Zeroable, PartialEq)]
pub struct SurfelGpu {
    pub position_radius: [f32; 4],
    pub normal_spread: [f32; 4],
    pub color: [u8; 4],
}

const _: () = {
    assert!(size_of::<TileGpu>() == 48);
    assert!(size_of::<NodeGpu>() == 8);
    assert!(size_of::<LeafGpu>() == 64);
    assert!(size_of::<LeafLightGpu>() == 80);
    assert!(size_of::<LightGpu>() == 64);
    assert!(size_of::<Params>() == 80 + 16 + 48 + 64 + 16 * MAX_CONES + 16 * 9 + 16 * 8 * 2 + 16);
    assert!(size_of::<MipRange>() == 16);
    assert!(size_of::<InjectBatch>() == 16);
    assert!(size_of::<SplatUniform>() == 256);
    assert!(size_of::<SurfelGpu>() == 36);
};
