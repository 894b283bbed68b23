//! Every struct the GPU sees, as `#[repr(C)]` Pod records with compile-time size checks.
//!
//! Mirrored by the WGSL structs of `shaders/` and `passes/` (runtime/tests/layout.rs compares
//! every member's offset through naga) and by the surfel vertex layout of `passes/splat.rs`. WGSL aligns `vec3`/`vec4` to 16 bytes, so
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
    /// Level (counted up from the package's leaves) of the tile's leaves here: 0 for the tile as
    /// built, k for its coarse level (scene/data.rs `coarse_tile`), whose leaves are the nodes
    /// 2^k package leaves wide and whose SVO ends there.
    pub leaf_lod: u32,
    pub pad: [u32; 3],
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
    /// Which of the eight children exist (bit k: child k).
    pub fn child_mask(&self) -> u32 {
        self.mask_level & 0xff
    }
    /// The node's level in its tile's SVO (0: the root).
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
    /// Where the leaf's surface is, frame metres: its surfels' area-weighted centroid, inside its
    /// cell (the cell's centre where it has no surfel; a coarse leaf's centroid); w: the leaf's
    /// edge in metres where it is a coarse leaf (wider than the package's leaves), else 0.
    pub center_m: [f32; 4],
    /// Emitted radiance, W / (sr m^2); w unused.
    pub emission: [f32; 4],
}

impl LeafGpu {
    /// The leaf's cell on the frame's leaf grid (leaves of `leaf_m`); `center_m` is inside it.
    pub fn cell(&self, leaf_m: f32) -> glam::IVec3 {
        (glam::Vec3::from_slice(&self.center_m[..3]) / leaf_m).floor().as_ivec3()
    }
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
    /// The running sum of a bounce's cones until its last batch (rgb), so that `gather` keeps
    /// the bounce before for the residual meanwhile; after it, the bounce before's residual,
    /// for the tail pass's ratio.
    pub pending: [f32; 4],
    /// What the last bounce changed the gather by (rgb): the ratio of two successive ones,
    /// summed over the leaf's tile, estimates the bounces not run (`Settings::bounce_tail`,
    /// passes/tail.wgsl). Zeroed when the light sources change ([`flags::NEW_SERIES`]).
    pub residual: [f32; 4],
    /// The estimated gather of the bounces not run (rgb, irradiance / pi): shade adds
    /// `albedo * (gather + tail)`; `out` and the pyramid hold only the bounces run.
    pub tail: [f32; 4],
}

impl LeafLightGpu {
    /// The radiance the leaf shows (rgb): `out` (the bounces run) plus `albedo * tail` (the
    /// estimate of those not run), as shade adds them up (light_state.wgsl `leaf_shown`).
    pub fn shown(&self, leaf: &LeafGpu) -> [f32; 3] {
        std::array::from_fn(|k| self.out[k] + leaf.albedo_opacity[k] * self.tail[k])
    }

    /// Whether a leaf whose bounce changed its gather by `residual` after the bounce before
    /// changed it by `last` is settling in that channel (its own ratio in 0..=1), so that it
    /// counts in its tile's ratio: passes/tail.wgsl `leaf_settling`.
    pub fn settling(residual: f32, last: f32) -> bool {
        last.abs() > 1e-20 && (0.0..=1.0).contains(&(residual / last))
    }

    /// The ratio the tail pass extrapolates a tile's bounces with, per channel: the summed
    /// residual of the tile's settling leaves ([`LeafLightGpu::settling`]) over their bounce
    /// before's (`last`), trusted where it lies in 0..=1 and at most `ratio_max`
    /// (`Params::tail_ratio_max`), else 0: passes/tail.wgsl `tile_ratio`.
    pub fn tile_ratio(residual: [f32; 3], last: [f32; 3], ratio_max: [f32; 3]) -> [f32; 3] {
        std::array::from_fn(|k| {
            if Self::settling(residual[k], last[k]) { (residual[k] / last[k]).min(ratio_max[k]) } else { 0.0 }
        })
    }

    /// The tail of a leaf whose bounce changed its gather by `residual`, in a tile whose ratio
    /// is `r` ([`LeafLightGpu::tile_ratio`]): the rest of the geometric series, as tail.wgsl.
    pub fn tail_of(residual: [f32; 3], r: [f32; 3]) -> [f32; 3] {
        std::array::from_fn(|k| residual[k] * (r[k] / (1.0 - r[k])))
    }
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
    /// ([`LightShadow::encode`]); w = the irradiance cutoff, W/m^2 (inject skips a light whose
    /// unshadowed irradiance at a leaf is under it).
    pub params: [f32; 4],
}

/// `LightGpu::params.z`: how a light is shadowed, one type for both sides (the WGSL constants are
/// generated from it).
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
#[repr(u32)]
pub enum LightShadow {
    /// A shadow map in the atlas, evaluated per pixel in shade.
    Map = 0,
    /// Beyond the budget: at leaf resolution, visibility from a cone traced through the SVO.
    Cone = 1,
    /// Beyond the budget: at leaf resolution, unshadowed.
    None = 2,
}

impl LightShadow {
    /// Every way a light can be shadowed.
    pub const ALL: [LightShadow; 3] = [LightShadow::Map, LightShadow::Cone, LightShadow::None];

    /// The WGSL constant (generated by `shaders::constants`).
    pub fn wgsl_name(self) -> &'static str {
        match self {
            LightShadow::Map => "LIGHT_MAP",
            LightShadow::Cone => "LIGHT_CONE",
            LightShadow::None => "LIGHT_NONE",
        }
    }

    /// As stored in `LightGpu::params[2]` (WGSL rounds it back: `light_shadow_kind`).
    pub fn encode(self) -> f32 {
        self as u32 as f32
    }
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
    /// Where matter is ([`crate::scene::data::SceneData::occupied_bounds_leaf`]), leaf units
    /// (xyz), w unused: a march stops once its cone's cross-section has left this box.
    pub occupied_min_leaf: [f32; 4],
    pub occupied_max_leaf: [f32; 4],
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
    /// Word offsets of the tables in the lookup buffer (lookup.wgsl): x rock, y light grid,
    /// z tile index; w unused.
    pub lookup_base: [u32; 4],
    /// Largest ratio of successive bounces the tail estimate trusts, per channel (rgb; the
    /// scene's largest albedo, at most [`TAIL_RATIO_MAX`]); zero without the tail; w unused.
    pub tail_ratio_max: [f32; 4],
}

/// Cap on the bounce ratio of the tail estimate: the tail is `r / (1 - r)` residuals, 19 here.
pub const TAIL_RATIO_MAX: f32 = 0.95;

/// The levels whose nodes `Settings::cone_planes` turns into half-spaces (WGSL `PLANE_LODS`):
/// the leaves and their parents. Coarser nodes hold more than one surface (a corridor's two
/// walls), which one plane does not describe.
pub const PLANE_LODS: u32 = 1;

/// `Params::flags` bits (generated into WGSL as `FLAG_*` by `shaders::constants`).
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
    /// View modes (settings.rs `ViewMode`): shade writes albedo, normals or the tile level
    /// instead of light, or lights every surface as if its albedo were 1.
    pub const VIEW_ALBEDO: u32 = 256;
    /// View mode: the normals, no light.
    pub const VIEW_NORMALS: u32 = 512;
    /// View mode: the light alone (every albedo 1).
    pub const VIEW_LIGHT: u32 = 1024;
    /// View mode: the level each tile is held at (full, coarse, far).
    pub const VIEW_LEVEL: u32 = 2048;
    /// The G-buffer's albedo holds each surfel's scan colour; shade shows it as the level view
    /// shows levels.
    pub const VIEW_SCAN: u32 = 4096;
    /// The light sources changed since the last inject or env pass (new lights, a new
    /// environment): those passes start a new series for propagate's tail estimate (zero the
    /// residual). A forced re-run over unchanged light does not, so it changes nothing.
    pub const NEW_SERIES: u32 = 8192;
    /// Each leaf turns its cone set by its interleave angle (`Settings::cone_interleave`).
    pub const CONE_INTERLEAVE: u32 = 16384;
    /// The G-buffer holds blended splats' sums (passes/gbuffer.rs): shade takes the normal,
    /// albedo and distance from them.
    pub const BLEND: u32 = 32768;
    /// View mode: illuminance in lux as false colours (with VIEW_LIGHT: albedo 1; view/lux.rs).
    pub const VIEW_LUX: u32 = 65536;
    /// Inject runs over the active tiles' leaves only (a light edit in place: light/edit.rs).
    pub const INJECT_ACTIVE: u32 = 131072;
    /// Cones traced through the radiance see the finest levels' leaves as the half-space behind
    /// their surface (`Settings::cone_planes`, shaders/svo.wgsl `leaf_plane_share`). The CPU
    /// reference reads it here; the GPU passes have it as the pipeline constant `cone_planes`.
    pub const CONE_PLANES: u32 = 262144;
    /// Propagate follows each gather cone as rays that end at the first surface
    /// (`Settings::cone_rays`, shaders/cone_rays.wgsl). The CPU reference reads it here; the GPU
    /// pass has it as the pipeline constant `cone_rays`.
    pub const CONE_RAYS: u32 = 524288;
    /// The views shade writes without light (settings.rs `ViewMode::shows_light`).
    pub const VIEWS_WITHOUT_LIGHT: u32 = VIEW_ALBEDO | VIEW_NORMALS | VIEW_LEVEL | VIEW_SCAN;

    /// Every flag the WGSL reads, with its name there (not CONE_PLANES nor CONE_RAYS: pipeline
    /// constants).
    pub const ALL: [(&str, u32); 18] = [
        ("FLAG_INJECT_ACTIVE", INJECT_ACTIVE),
        ("FLAG_VIEW_LUX", VIEW_LUX),
        ("FLAG_VIEW_ALBEDO", VIEW_ALBEDO),
        ("FLAG_VIEW_SCAN", VIEW_SCAN),
        ("FLAG_VIEW_NORMALS", VIEW_NORMALS),
        ("FLAG_VIEW_LIGHT", VIEW_LIGHT),
        ("FLAG_VIEW_LEVEL", VIEW_LEVEL),
        ("FLAG_INDIRECT", INDIRECT),
        ("FLAG_DIRECT", DIRECT),
        ("FLAG_SHADOWS", SHADOWS),
        ("FLAG_EMISSION", EMISSION),
        ("FLAG_TRICUBIC", TRICUBIC),
        ("FLAG_ENV", ENV),
        ("FLAG_FAR_LIGHTS", FAR_LIGHTS),
        ("FLAG_SPECULAR", SPECULAR),
        ("FLAG_NEW_SERIES", NEW_SERIES),
        ("FLAG_CONE_INTERLEAVE", CONE_INTERLEAVE),
        ("FLAG_BLEND", BLEND),
    ];
}

/// The ray march of `Settings::cone_rays` (shaders/cone_rays.wgsl, `CpuScene::trace_cone_rays`),
/// the shell rule that measured best on the CPU (reference/examples/ray_cones.rs with
/// `CELLS=1 PLANEHIT=1 PLANE_OFFSET=0.25 LIFT=0.3`, docs/reference.md "Where the light goes
/// wrong"). Generated into WGSL as `RAY_*` (`shaders::constants`).
pub mod cone_rays {
    /// The rays start this many leaf edges above the leaf's centroid along its mean normal.
    pub const LIFT_LEAVES: f32 = 0.3;
    /// A ray meets a leaf where it goes behind the plane through the leaf's centroid across its
    /// mean normal moved this many of its edges out, toward the air: a quarter leaf closes the
    /// shell between edge-touching leaves without standing up to a leaf in front of the surface.
    pub const PLANE_OFFSET_LEAVES: f32 = 0.25;
    /// A ray that would dip under its own surface (a grazing cone's rim) rises at least this much
    /// per metre instead: a path leaving a surface cannot go below it.
    pub const MIN_RISE: f32 = 0.02;
    /// Offsets over the unit disc of the cone's footprint, each for an equal share of it: the
    /// centre and six rays at the radius that halves the annulus around the centre's seventh
    /// (sqrt((1 + 1/7) / 2) = 0.756). 19 rays changed the colour box's first bounce by at most
    /// 0.007 of the reference's.
    pub const PATTERN: [[f32; 2]; 7] = [
        [0.0, 0.0],
        [0.756, 0.0],
        [0.378, 0.654_715_2],
        [-0.378, 0.654_715_2],
        [-0.756, 0.0],
        [-0.378, -0.654_715_2],
        [0.378, -0.654_715_2],
    ];
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
/// `reset` = 1 for the first batch (which starts the leaf's direct light from zero). Mirrored in WGSL (runtime/tests/layout.rs)
/// with passes/inject.wgsl.
#[repr(C)]
#[derive(Clone, Copy, Debug, Default, Pod, Zeroable, PartialEq, Eq)]
pub struct InjectBatch {
    pub first: u32,
    pub count: u32,
    /// The first batch: it starts the direct light from zero.
    pub reset: u32,
    /// The last batch: after an edit in place it records how much the direct light changed.
    pub last: u32,
}

/// One propagate dispatch: cones `first .. first + count` of the cone set (passes/propagate.rs).
/// Mirrored in passes/propagate.wgsl.
#[repr(C)]
#[derive(Clone, Copy, Debug, Default, Pod, Zeroable, PartialEq, Eq)]
pub struct ConeBatch {
    pub first: u32,
    pub count: u32,
    pub pad0: u32,
    pub pad1: u32,
}

/// One tile of a propagation bounce's active list (activity.rs, shaders/activity.wgsl): its
/// leaves `first_leaf .. first_leaf + leaf_count` are the bounce's invocations `first_item ..`.
#[repr(C)]
#[derive(Clone, Copy, Debug, Default, Pod, Zeroable, PartialEq, Eq)]
pub struct ActiveTile {
    pub tile: u32,
    pub first_leaf: u32,
    pub leaf_count: u32,
    pub first_item: u32,
}

/// Uniform of one splat render pass (one shadow layer or the camera). 256 bytes so that one buffer
/// holds all of them at static offsets. Mirrored by `Splat` in passes/splat.wgsl.
#[repr(C)]
#[derive(Clone, Copy, Debug, Pod, Zeroable, PartialEq)]
pub struct SplatUniform {
    pub view_proj: [[f32; 4]; 4],
    /// Eye or light position in frame metres, w unused.
    pub eye_m: [f32; 4],
    /// x, y: viewport size in pixels; z: smallest splat radius in pixels; w: projection scale
    /// (`proj[1][1]`) for the pixel-size estimate.
    pub viewport: [f32; 4],
    /// x: surfel radius scale (discs overlap so sparse sampling closes); y: 1 to colour each
    /// surfel by its scan (the scan view); zw unused.
    pub splat: [f32; 4],
    /// The clip box (settings.rs `ClipBox`), frame metres; w: 1 where it clips, 0 where not.
    pub clip_min_m: [f32; 4],
    pub clip_max_m: [f32; 4],
    pub pad: [[f32; 4]; 7],
}

/// One surfel as an instance vertex: frame position and radius, unit normal and spread, sRGB colour
/// with the material slot in alpha (0 diffuse, k: `SceneData::materials[k - 1]`), and the index
/// of the scan it came from in the package's scan list ([`NO_SCAN`]: none, as for the splats of
/// coarse levels, which stand for several).
#[repr(C)]
#[derive(Clone, Copy, Debug, Default, Pod, Zeroable, PartialEq)]
pub struct SurfelGpu {
    pub position_radius: [f32; 4],
    pub normal_spread: [f32; 4],
    pub color: [u8; 4],
    pub scan: u32,
}

/// [`SurfelGpu::scan`] of a surfel that stands for no one scan.
pub const NO_SCAN: u32 = u32::MAX;

const _: () = {
    assert!(size_of::<TileGpu>() == 48);
    assert!(size_of::<NodeGpu>() == 8);
    assert!(size_of::<LeafGpu>() == 64);
    assert!(size_of::<LeafLightGpu>() == 128);
    assert!(size_of::<LightGpu>() == 64);
    assert!(size_of::<Params>() == 80 + 16 + 80 + 64 + 16 * MAX_CONES + 16 * 9 + 16 * 8 * 2 + 16 + 16 + 16);
    assert!(size_of::<MipRange>() == 16);
    assert!(size_of::<InjectBatch>() == 16);
    assert!(size_of::<ConeBatch>() == 16);
    assert!(size_of::<ActiveTile>() == 16);
    assert!(size_of::<SplatUniform>() == 256);
    assert!(size_of::<SurfelGpu>() == 40);
};

/// GPU bytes of the per-element buffers that hold tiles, as the renderer allocates them: tile
/// records, nodes, the radiance pyramid (six faces a node), the mip order, leaves, leaf light and
/// surfels. The one formula behind residency's tile costs, the pools' sizes and a scene's bytes.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq, serde::Serialize)]
pub struct TileBufferBytes {
    pub tiles: u64,
    pub nodes: u64,
    pub leaves: u64,
    pub leaf_light: u64,
    /// The anisotropic radiance pyramid (six values per node).
    pub faces: u64,
    pub mip_order: u64,
    pub surfels: u64,
}

impl TileBufferBytes {
    /// The bytes of `tiles` tile records, `nodes` nodes, `leaves` leaves and `surfels` surfels.
    pub fn of(tiles: u64, nodes: u64, leaves: u64, surfels: u64, radiance_f16: bool) -> Self {
        let face = if radiance_f16 { 8 } else { 16 };
        Self {
            tiles: tiles * size_of::<TileGpu>() as u64,
            nodes: nodes * size_of::<NodeGpu>() as u64,
            leaves: leaves * size_of::<LeafGpu>() as u64,
            leaf_light: leaves * size_of::<LeafLightGpu>() as u64,
            faces: nodes * 6 * face,
            mip_order: nodes * 4,
            surfels: surfels * size_of::<SurfelGpu>() as u64,
        }
    }

    /// All of them.
    pub fn total(&self) -> u64 {
        self.tiles + self.nodes + self.leaves + self.leaf_light + self.faces + self.mip_order + self.surfels
    }
}
