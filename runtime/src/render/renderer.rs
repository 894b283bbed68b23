//! The renderer: uploads a [`SceneData`], builds the passes once, and per call runs exactly the
//! passes the effect plan marks `run` (counting each dispatch and timing it with GPU timestamps
//! where the adapter has them).
//!
//! Light transport state lives on the GPU between calls: injected direct light, the gathered
//! indirect light and the outgoing radiance of every leaf. Each light update adds one bounce:
//! `out_(k+1) = emission + direct + albedo * gather(out_k)`, so with albedo < 1 the radiance stays
//! bounded and converges to the fixed point.

use std::collections::{BTreeMap, HashMap, HashSet};
use std::ops::Range;
use web_time::Instant;

use glam::{Mat4, Vec3};
use serde::Serialize;

use crate::error::{Error, Result};
use crate::gpu::Gpu;
use crate::gpu::types::{
    ActiveTile, LeafGpu, LeafLightGpu, LightGpu, MAX_CONES, NodeGpu, Params, SplatUniform, SurfelGpu,
    TileGpu, flags,
};
use crate::light::activity::{BounceWork, TileActivity, Why};
use crate::light::plan::{self, EffectPlan, Pass, PlanInputs};
use crate::light::setup::LightSetup;
use crate::passes::{self, gbuffer, shade, shadow};
use crate::render::pool::{PoolCaps, Pools, TileKey, key, merge_runs, surfel_owners};
use crate::scene::data::{EnvChain, MAX_ENV_LEVELS, MAX_MATERIALS, SceneData, SceneLight};
use crate::view::camera::Camera;

pub use crate::settings::{
    ClipBox, IndirectFilter, MAX_SHADOWED_LIGHTS, Quality, Settings, ShadowFallback, ViewMode, scan_color,
};

/// Cosine-distributed directions on the +z hemisphere (a Fibonacci spiral on the unit disc lifted
/// to the hemisphere), equal weights summing to 1, and the half-angle tangent that makes the cones
/// cover the hemisphere's solid angle (2 pi / n each).
pub fn cone_set(n: u32, aperture_scale: f32) -> (Vec<[f32; 4]>, f32) {
    let golden = std::f32::consts::PI * (3.0 - 5f32.sqrt());
    let dirs = (0..n)
        .map(|i| {
            let u = (i as f32 + 0.5) / n as f32;
            let r = u.sqrt();
            let phi = i as f32 * golden;
            let d = Vec3::new(r * phi.cos(), r * phi.sin(), (1.0 - u).max(0.0).sqrt()).normalize();
            [d.x, d.y, d.z, 1.0 / n as f32]
        })
        .collect();
    let cos_half = 1.0 - 1.0 / n as f32;
    let half = (cos_half.clamp(-1.0, 1.0).acos() * aperture_scale).min(1.45);
    (dirs, half.tan())
}

/// Middle grey over the geometric mean luminance of the pixels that see something.
pub fn auto_exposure(hdr: &[[f32; 4]]) -> f32 {
    let mut sum = 0.0f64;
    let mut n = 0usize;
    for p in hdr {
        let l = 0.2126 * p[0] + 0.7152 * p[1] + 0.0722 * p[2];
        if l.is_finite() && l > 0.0 {
            sum += f64::from(l.max(1e-6)).ln();
            n += 1;
        }
    }
    if n == 0 {
        return 1.0;
    }
    let mean = (sum / n as f64).exp();
    (0.18 / mean).clamp(1e-6, 1e9) as f32
}

/// One rendered image.
#[derive(Clone, Debug)]
pub struct Frame {
    pub width: u32,
    pub height: u32,
    /// Linear radiance, rows top to bottom; alpha is 1 where a surfel covers the pixel, 0 where the
    /// background shows.
    pub hdr: Vec<[f32; 4]>,
    /// Tonemapped sRGB8 RGBA.
    pub ldr: Vec<[u8; 4]>,
}

/// Per-pass counters and the last measured GPU time.
#[derive(Clone, Debug, Default, Serialize)]
pub struct PassStats {
    /// How many times each pass was recorded (a skipped pass stays at zero).
    pub dispatches: BTreeMap<Pass, u64>,
    /// GPU milliseconds of each pass's last run (timestamp queries), or, where the adapter has
    /// none, CPU wall time from recording the pass to the end of its own blocking submit.
    pub last_ms: BTreeMap<Pass, f64>,
    pub bounces_done: u32,
    pub last_change: Option<f32>,
    /// Leaves updated by all propagation bounces so far (a bounce updates only the tiles whose
    /// light may still change: activity.rs).
    pub propagated_leaves: u64,
}

#[derive(Debug)]
struct View {
    camera: Camera,
    targets: gbuffer::Targets,
    outputs: shade::Outputs,
}

/// Uploaded scene, passes and light state.
#[derive(Debug)]
pub struct Renderer {
    gpu: Gpu,
    settings: Settings,
    leaf_count: u32,
    #[cfg(feature = "test-hooks")]
    node_count: u32,
    leaf_size_m: f32,
    scene_diag_m: f32,
    base_params: Params,
    point_lights: usize,
    spot_lights: usize,
    /// The scene's last light is a headlamp added for a lightless scene (the plan says so).
    headlamp: bool,
    /// Lights with shadow maps; the others are lit per leaf (lights.rs).
    shadowed: usize,
    /// Shadow-atlas faces (six per point light with a map, one per spot light).
    shadow_faces: usize,
    /// Lights per light-grid cell: mean and largest.
    lights_in_range: (f32, u32),
    /// Specular materials with surfels, and those surfels (0 when `Settings::specular` is off).
    specular_materials: usize,
    specular_surfels: usize,
    emissive: bool,
    /// An environment map lights the scene (it has SH coefficients and the setting allows it).
    environment: bool,
    env_valid: bool,
    params: wgpu::Buffer,
    /// Bytes of every buffer and texture created at upload (the G-buffer is added per view).
    static_bytes: u64,
    /// The light state: carried across reloads (`light_by_tile`, `seed_light`) and read by the
    /// test hooks.
    leaf_light: wgpu::Buffer,
    #[cfg(feature = "test-hooks")]
    faces: wgpu::Buffer,
    /// The active tiles propagate reads, and what the bounce changed: its largest change (16
    /// bytes: the f32 bits, then padding), then each tile's (shaders/activity.wgsl `Changes`).
    active: wgpu::Buffer,
    changes: wgpu::Buffer,
    activity: TileActivity,
    /// Invocations (leaves) of the active tiles on the GPU; `None` when the tiles changed since
    /// they were written.
    active_written: Option<u32>,
    /// Bounces since the last [`Renderer::take_bounce_work`], with what each updated.
    bounce_work: Vec<BounceWork>,
    surfels: wgpu::Buffer,
    /// The tile pools (pool.rs): where each resident tile form lives in the buffers.
    pools: Pools,
    /// The resident tiles as the GPU holds them (offsets into the pools), and each one's surfels.
    tiles: Vec<TileGpu>,
    tile_surfels: Vec<Range<u32>>,
    /// Tiles may be culled by their boxes (their surfels lie in them: false for a scene put
    /// together by hand, whose surfels all count as its first tile's).
    cull_tiles: bool,
    tiles_buf: wgpu::Buffer,
    nodes_buf: wgpu::Buffer,
    leaves_buf: wgpu::Buffer,
    /// The lookup buffer (rock, light grid, tile index: lookup.wgsl); the tile index starts at
    /// word `base_params.lookup_base[2]` and runs to the end of the buffer.
    lookup_buf: wgpu::Buffer,
    /// Shadow faces the next shadow pass draws (every face after a change of lights; after a
    /// change of tiles, the faces that see one), and how many were drawn since the last
    /// [`Renderer::take_shadow_faces_drawn`].
    shadow_dirty: Vec<bool>,
    shadow_drawn: u64,
    /// The camera's view-projection of the G-buffer (tiles outside it are not drawn), and whether
    /// the tiles changed since it was drawn.
    camera_view_proj: Option<Mat4>,
    gbuffer_stale: bool,
    /// What a scene must share with this one to be swapped in place ([`Renderer::update_scene`]).
    compat: Compat,
    inject: passes::Batched,
    env: passes::Batched,
    mip: passes::mip::Mip,
    propagate: passes::Batched,
    shadow: shadow::Shadow,
    gbuffer: gbuffer::Gbuffer,
    shade: shade::Shade,
    view: Option<View>,
    direct_valid: bool,
    forced: Vec<Pass>,
    /// Why a viewer holds the bounces, if it does ([`Renderer::hold_light`]).
    light_held: Option<&'static str>,
    /// The last bounce's change, read back without blocking (`poll_light`).
    bounce_readback: Option<crate::gpu::PendingRead>,
    /// The view's clip box ([`Renderer::set_clip`]).
    clip: Option<ClipBox>,
    /// A bounce under way in slices ([`Renderer::update_light_slice`]): its next invocation
    /// (active leaf, of `active_written`); the pyramid stays as its mip left it until it ends.
    bounce_at: Option<u32>,
    /// The invocations the last propagate dispatch ran.
    slice_run: (u32, u32),
    stats_now: PassStats,
    queries: Option<(wgpu::QuerySet, wgpu::Buffer)>,
}

const STORAGE: wgpu::BufferUsages =
    wgpu::BufferUsages::STORAGE.union(wgpu::BufferUsages::COPY_SRC).union(wgpu::BufferUsages::COPY_DST);

/// Specular material slots (slot 0 = diffuse: x Ks, y GGX alpha, z ior, w roughness), and the
/// specular materials and surfels the settings keep.
fn material_slots(scene: &SceneData, settings: &Settings) -> ([[f32; 4]; MAX_MATERIALS + 1], usize, usize) {
    let mut slots = [[0.0f32; 4]; MAX_MATERIALS + 1];
    let (mut materials, mut surfels) = (0, 0);
    for (k, m) in scene.materials.iter().enumerate().take(MAX_MATERIALS) {
        slots[k + 1] = [m.specular, m.roughness * m.roughness, m.ior, m.roughness];
        if settings.specular && m.surfels > 0 {
            materials += 1;
            surfels += m.surfels;
        }
    }
    (slots, materials, surfels)
}

/// The env atlas's level table for shade (`Params::env_levels`, `Params::env_chain`).
fn env_levels(chain: Option<&EnvChain>) -> ([[f32; 4]; MAX_ENV_LEVELS], [u32; 4]) {
    let mut levels = [[0.0f32; 4]; MAX_ENV_LEVELS];
    let Some(c) = chain else { return (levels, [0, 1, 0, 0]) };
    for (k, l) in c.levels.iter().take(MAX_ENV_LEVELS).enumerate() {
        levels[k] = [l.0 as f32, l.1 as f32, l.2 as f32, l.3];
    }
    (levels, [c.levels.len().min(MAX_ENV_LEVELS) as u32, c.width, 0, 0])
}

/// The compute parameters that do not change per frame.
#[allow(clippy::too_many_arguments)]
fn base_params(
    scene: &SceneData,
    settings: &Settings,
    lights: &LightSetup,
    shadow: &shadow::Shadow,
    (lo, hi): (Vec3, Vec3),
    scene_diag_m: f32,
    chain: Option<&EnvChain>,
    materials: [[f32; 4]; MAX_MATERIALS + 1],
    lookup: &Lookup,
) -> Params {
    let leaf = scene.leaf_size_m.max(1e-6);
    let (cones, tan_half) = cone_set(settings.cones, settings.cone_aperture_scale);
    let mut cone_arr = [[0.0f32; 4]; MAX_CONES];
    cone_arr[..cones.len()].copy_from_slice(&cones);
    let (env_levels, env_chain) = env_levels(chain);
    Params {
        leaf_size_m: leaf,
        tile_count: scene.tiles.len() as u32,
        leaf_count: scene.leaves.len() as u32,
        light_count: lights.lights.len() as u32,
        cone_count: settings.cones,
        cone_tan_half: tan_half,
        step_scale: settings.step_scale,
        max_distance_m: settings.max_distance_m.unwrap_or(scene_diag_m),
        max_steps: settings.march_steps(),
        max_lod: scene.max_lod(),
        shadow_size: shadow.face_size(),
        flags: 0,
        width: 0,
        height: 0,
        exposure: settings.exposure,
        shadow_bias_m: 1.5 * leaf,
        shadow_cols: shadow.cols(),
        light_grid_dims: lights.grid.dims.to_array(),
        light_grid_min_m: lights.grid.min_m.extend(lights.grid.cell_m).to_array(),
        scene_min_leaf: lo.extend(0.0).to_array(),
        scene_max_leaf: hi.extend(0.0).to_array(),
        background: Vec3::from_array(settings.background).extend(0.0).to_array(),
        camera_eye_m: [0.0; 4],
        camera_forward: [0.0, 0.0, -1.0, 1.0],
        camera_right: [1.0, 0.0, 0.0, 1.0],
        camera_up: [0.0, 1.0, 0.0, 0.0],
        cones: cone_arr,
        env_sh: match (&scene.environment_sh, settings.environment) {
            (Some(sh), true) => sh.map(|c| [c[0], c[1], c[2], 0.0]),
            _ => [[0.0; 4]; 9],
        },
        materials,
        env_levels,
        env_chain,
        lookup_base: lookup.base,
        tail_ratio_max: tail_ratio_max(settings, &scene.leaves),
    }
}

/// The largest bounce ratio the tail estimate trusts, per channel: the spectral radius of one
/// bounce is at most the largest albedo (the cone weights sum to 1 and opacity only loses
/// light), so a leaf whose change grew by more is still filling with light, not converging.
fn tail_ratio_max(settings: &Settings, leaves: &[LeafGpu]) -> [f32; 4] {
    if !settings.bounce_tail {
        return [0.0; 4];
    }
    let mut m = [0.0f32; 4];
    for l in leaves {
        for (k, v) in m.iter_mut().take(3).enumerate() {
            let a = l.albedo_opacity[k];
            if a.is_finite() {
                *v = v.max(a);
            }
        }
    }
    m.map(|v| v.min(crate::gpu::types::TAIL_RATIO_MAX))
}

/// The one lookup buffer's contents (lookup.wgsl): the rock table, the light grid and the tile
/// index, at word offsets `base`, with room after the index for the index of a scene with other
/// tile forms (its size follows how the tiles align; one that outgrows it makes a new renderer,
/// `update_scene`).
struct Lookup {
    base: [u32; 4],
    words: Vec<u32>,
}

impl Lookup {
    fn new(scene: &SceneData, lights: &LightSetup) -> Result<Self> {
        let index = crate::scene::tile_index::TileIndex::build(&scene.name, &scene.tiles)?;
        let (rock, grid) = (&scene.rock.words, &lights.grid.words);
        let room = 2 * index.words.len() + 64;
        let mut words = Vec::with_capacity(rock.len() + grid.len() + room);
        words.extend_from_slice(rock);
        words.extend_from_slice(grid);
        let index_base = words.len();
        words.extend_from_slice(&index.words);
        words.resize(index_base + room, 0);
        let base = [0, rock.len() as u32, index_base as u32, 0];
        Ok(Self { base, words })
    }
}

/// The buffers every pass shares, uploaded once: the static scene (bind group 0), the light state
/// (group 1), and the surfels the splat passes draw.
struct Upload {
    params: wgpu::Buffer,
    tiles: wgpu::Buffer,
    nodes: wgpu::Buffer,
    leaves: wgpu::Buffer,
    lookup: wgpu::Buffer,
    #[cfg_attr(not(feature = "test-hooks"), allow(dead_code))]
    leaf_light: wgpu::Buffer,
    #[cfg_attr(not(feature = "test-hooks"), allow(dead_code))]
    faces: wgpu::Buffer,
    active: wgpu::Buffer,
    /// The bounce's largest change (16 bytes: the f32 bits, then padding), then each tile's.
    changes: wgpu::Buffer,
    surfels: wgpu::Buffer,
    shared: passes::Shared,
    /// GPU bytes of all of them.
    bytes: u64,
}

impl Upload {
    /// The buffers, the tile data in pools of `caps` elements with `scene` at their start (as
    /// fresh pools place it: pool.rs).
    #[allow(clippy::too_many_arguments)]
    fn new(
        gpu: &Gpu,
        scene: &SceneData,
        caps: PoolCaps,
        lights: &LightSetup,
        lookup: &Lookup,
        shadow_atlas: &wgpu::TextureView,
        base_params: &Params,
        f16: bool,
    ) -> Result<Self> {
        let params = gpu.buffer_init(
            "params",
            bytemuck::bytes_of(base_params),
            wgpu::BufferUsages::UNIFORM | wgpu::BufferUsages::COPY_DST,
        )?;
        // A pool: `n` elements of `T`, the first ones written from `data`.
        fn pool<T: bytemuck::Pod>(
            gpu: &Gpu,
            label: &str,
            n: u64,
            data: &[T],
            usage: wgpu::BufferUsages,
        ) -> Result<wgpu::Buffer> {
            let b = gpu.buffer(label, n.max(data.len() as u64).max(1) * size_of::<T>() as u64, usage)?;
            if !data.is_empty() {
                gpu.queue.write_buffer(&b, 0, bytemuck::cast_slice(data));
            }
            Ok(b)
        }
        let leaf_light = pool(gpu, "leaf light", caps.leaves, &initial_light(&scene.leaves), STORAGE)?;
        let face_bytes = if f16 { 8 } else { 16 };
        let faces = gpu.buffer("faces", caps.nodes.max(1) * 6 * face_bytes, STORAGE)?;
        // A 16-byte header, then at most every tile.
        let active =
            gpu.buffer("active tiles", 16 + size_of::<ActiveTile>() as u64 * caps.tiles.max(1), STORAGE)?;
        let changes = gpu.buffer("changes", 16 + 4 * caps.tiles.max(1), STORAGE)?;
        let lookup = gpu.buffer_init("lookup", bytemuck::cast_slice(&lookup.words), STORAGE)?;
        let surfels = pool(
            gpu,
            "surfels",
            caps.surfels,
            &scene.surfels,
            wgpu::BufferUsages::VERTEX | wgpu::BufferUsages::COPY_DST,
        )?;
        let tiles = pool(gpu, "tiles", caps.tiles, &scene.tiles, STORAGE)?;
        let nodes = pool(gpu, "nodes", caps.nodes, &scene.nodes, STORAGE)?;
        let leaves = pool(gpu, "leaves", caps.leaves, &scene.leaves, STORAGE)?;
        // The shadow faces' matrices follow the lights, one 64-byte record each (lights.wgsl).
        let mut light_records: Vec<LightGpu> = lights.lights.clone();
        light_records.extend(lights.faces.iter().map(|f| {
            let [c0, c1, c2, c3] = f.view_proj.to_cols_array_2d();
            LightGpu { position_kind: c0, intensity_layer: c1, direction_cos_outer: c2, params: c3 }
        }));
        let static_buffers = [
            (0, params.clone()),
            (1, tiles.clone()),
            (2, nodes.clone()),
            (3, leaves.clone()),
            (4, gpu.buffer_init("lights", bytemuck::cast_slice(&light_records), STORAGE)?),
            (7, lookup.clone()),
        ];
        let mut shared = passes::Shared::default();
        let mut bytes = surfels.size();
        for (binding, b) in static_buffers {
            bytes += b.size();
            shared.insert(0, binding, passes::Resource::Buffer(b));
        }
        shared.insert(0, 6, passes::Resource::Texture(shadow_atlas.clone()));
        for (binding, b) in [(0, &leaf_light), (1, &faces), (3, &active), (4, &changes)] {
            bytes += b.size();
            shared.insert(1, binding, passes::Resource::Buffer(b.clone()));
        }

        Ok(Upload {
            params,
            tiles,
            nodes,
            leaves,
            lookup,
            leaf_light,
            faces,
            active,
            changes,
            surfels,
            shared,
            bytes,
        })
    }
}

/// The light state leaves start from: out = emission (no direct light, no gather yet).
fn initial_light(leaves: &[LeafGpu]) -> Vec<LeafLightGpu> {
    leaves.iter().map(|l| LeafLightGpu { out: l.emission, ..Default::default() }).collect()
}

/// What two scenes must share for one to replace the other in a renderer's pools: the same lights,
/// frame, bounds (so the light grid and shadow faces stay), coarsest level, materials and
/// environment. Residency keeps all of these (every tile is held in some form).
#[derive(Clone, Debug, PartialEq)]
struct Compat {
    lights: Vec<SceneLight>,
    headlamp: bool,
    leaf_size_m: f32,
    bounds_leaf: (Vec3, Vec3),
    max_lod: u32,
    materials: Vec<(String, f32, f32, f32)>,
    environment_sh: Option<[[f32; 3]; 9]>,
    env_chain: bool,
    rock_words: usize,
}

impl Compat {
    fn of(scene: &SceneData) -> Self {
        Self {
            lights: scene.lights.clone(),
            headlamp: scene.headlamp,
            leaf_size_m: scene.leaf_size_m,
            bounds_leaf: scene.bounds_leaf(),
            max_lod: scene.max_lod(),
            materials: scene
                .materials
                .iter()
                .map(|m| (m.name.clone(), m.specular, m.roughness, m.ior))
                .collect(),
            environment_sh: scene.environment_sh,
            env_chain: scene.env_chain.is_some(),
            rock_words: scene.rock.words.len(),
        }
    }
}

/// A tile's box in frame metres, grown by what its surfels' discs may reach past it.
fn tile_box(t: &TileGpu, leaf_m: f32) -> (Vec3, Vec3) {
    let lo = glam::IVec3::from_array(t.origin_leaf).as_vec3() * leaf_m;
    let edge = (1u64 << t.depth.min(40)) as f32 * leaf_m;
    let margin = ((1u64 << t.leaf_lod.min(40)) as f32 + 2.0) * leaf_m;
    (lo - Vec3::splat(margin), lo + Vec3::splat(edge + margin))
}

/// A frame on the GPU, for a viewer to present ([`Renderer::ldr_output`]).
#[derive(Clone, Copy, Debug)]
pub struct LdrOutput<'a> {
    pub buffer: &'a wgpu::Buffer,
    pub first_word: u32,
    pub width: u32,
    pub height: u32,
}

/// Where the light stands ([`Renderer::light_progress`]).
#[derive(Clone, Copy, Debug, PartialEq, Serialize)]
pub struct LightProgress {
    pub bounces_done: u32,
    pub bounce_budget: u32,
    pub last_change: Option<f32>,
    pub converged: bool,
}

impl LightProgress {
    /// 0..=1 for an indicator: 1 when converged, else bounces done of the budget.
    pub fn fraction(&self) -> f32 {
        if self.converged {
            1.0
        } else {
            (self.bounces_done as f32 / self.bounce_budget.max(1) as f32).min(0.99)
        }
    }
}

/// What [`Renderer::update_scene`] did.
#[derive(Clone, Debug, Default, Serialize)]
pub struct SceneUpdate {
    /// Tiles written to the pools (forms new to them), and tiles that kept their slot and light.
    pub uploaded_tiles: usize,
    pub kept_tiles: usize,
    /// Tile forms that left the pools.
    pub freed_tiles: usize,
    /// The free space was too fragmented for the new forms: every tile was written again, the
    /// light of those that stayed read back and carried to their new slots.
    pub repacked: bool,
    /// Bytes written to the GPU: the new forms' nodes, leaves, light and surfels, the tile table,
    /// tile index and mip order.
    pub upload_bytes: u64,
    /// Leaves that kept their light (in place, or carried through a repack).
    pub carried_leaves: usize,
    /// Shadow faces that see a changed tile (drawn again by the next shadow pass).
    pub shadow_faces: usize,
}

/// Timestamp queries for every pass, where the adapter has them.
fn pass_queries(gpu: &Gpu) -> Option<(wgpu::QuerySet, wgpu::Buffer)> {
    gpu.timestamps.then(|| {
        let set = gpu.device.create_query_set(&wgpu::QuerySetDescriptor {
            label: Some("pass times"),
            ty: wgpu::QueryType::Timestamp,
            count: 2 * Pass::ALL.len() as u32,
        });
        let buf = gpu.device.create_buffer(&wgpu::BufferDescriptor {
            label: Some("pass times"),
            size: 16 * Pass::ALL.len() as u64,
            usage: wgpu::BufferUsages::QUERY_RESOLVE | wgpu::BufferUsages::COPY_SRC,
            mapped_at_creation: false,
        });
        (set, buf)
    })
}

/// Light state per tile, keyed by where the tile is and at which level it is held
/// ([`Renderer::light_by_tile`], [`Renderer::seed_light`]).
#[derive(Clone, Debug, Default)]
pub struct CarriedLight {
    tiles: HashMap<TileKey, Vec<LeafLightGpu>>,
}

impl CarriedLight {
    /// Leaves held.
    pub fn leaves(&self) -> usize {
        self.tiles.values().map(Vec::len).sum()
    }
}

impl Renderer {
    pub fn new(gpu: &Gpu, scene: &SceneData, settings: Settings) -> Result<Self> {
        Self::with_pools(gpu, scene, settings, PoolCaps::of(scene))
    }

    /// A renderer whose tile pools hold `caps` elements (at least what `scene` needs), so later
    /// scenes of other tile forms can replace this one in place ([`Renderer::update_scene`]).
    pub fn with_pools(gpu: &Gpu, scene: &SceneData, settings: Settings, caps: PoolCaps) -> Result<Self> {
        settings.validate()?;
        let caps = caps.at_least(PoolCaps::of(scene));
        let mut pools = Pools::new(caps)?;
        let (owners, cull_tiles) = surfel_owners(scene);
        let placed = pools.place(scene, &owners)?;
        if placed.tiles != scene.tiles {
            return Err(Error::Internal { what: "pools", message: "fresh pools moved a tile".into() });
        }
        let f16 = settings.radiance_f16;
        let (lo, hi) = scene.bounds_leaf();
        let leaf = scene.leaf_size_m.max(1e-6);
        let scene_diag_m = ((hi - lo) * leaf).length().max(leaf);
        // The light grid over the scene with one leaf of slack on every side.
        let near = (0.05 * leaf).max(1e-4);
        let lights = LightSetup::new(
            scene,
            &settings,
            near,
            scene_diag_m * 2.0 + 1.0,
            (lo - 1.0) * leaf,
            (hi + 1.0) * leaf,
        );
        let environment_on = scene.environment_sh.is_some() && settings.environment;
        let chain = scene.env_chain.as_ref().filter(|_| environment_on);
        let (materials, specular_materials, specular_surfels) = material_slots(scene, &settings);

        let splat_layout = passes::splat::layout(gpu);
        let shadow = gpu.scoped("shadow", || {
            shadow::Shadow::new(
                gpu,
                &splat_layout,
                &lights.faces,
                settings.shadow_map_size,
                settings.min_splat_px,
                settings.splat_scale,
            )
        })?;
        let lookup = Lookup::new(scene, &lights)?;
        let base_params = base_params(
            scene,
            &settings,
            &lights,
            &shadow,
            (lo, hi),
            scene_diag_m,
            chain,
            materials,
            &lookup,
        );

        let up = Upload::new(gpu, scene, caps, &lights, &lookup, shadow.atlas(), &base_params, f16)?;
        let shared = &up.shared;

        let (by_height, ranges) = scene.nodes_by_height();
        let lights_in_range = lights.grid.occupancy();
        let inject = gpu.scoped("inject", || passes::inject::new(gpu, shared, f16, lights_in_range.1))?;
        let env = gpu.scoped("env", || passes::env::new(gpu, shared, f16, settings.cones))?;
        let mip =
            gpu.scoped("mip", || passes::mip::Mip::new(gpu, shared, caps.nodes, &by_height, &ranges, f16))?;
        let propagate =
            gpu.scoped("propagate", || passes::propagate::new(gpu, shared, f16, settings.cones))?;
        let gbuffer = gpu.scoped("gbuffer", || gbuffer::Gbuffer::new(gpu, &splat_layout))?;
        let shade = gpu.scoped("shade", || shade::Shade::new(gpu, shared, f16, chain))?;
        let static_bytes = up.bytes + shadow.bytes() + shade.env_atlas_bytes();
        let shadow_faces = lights.faces.len();
        let r = Self {
            inject,
            env,
            mip,
            propagate,
            shadow,
            gbuffer,
            shade,
            gpu: gpu.clone(),
            settings,
            leaf_count: scene.leaves.len() as u32,
            #[cfg(feature = "test-hooks")]
            node_count: scene.nodes.len() as u32,
            leaf_size_m: leaf,
            scene_diag_m,
            base_params,
            point_lights: lights.point_lights,
            spot_lights: lights.spot_lights,
            headlamp: scene.headlamp,
            shadowed: lights.shadowed,
            shadow_faces,
            lights_in_range,
            specular_materials,
            specular_surfels,
            emissive: scene.has_emission(),
            environment: environment_on,
            env_valid: false,
            params: up.params,
            static_bytes,
            leaf_light: up.leaf_light,
            #[cfg(feature = "test-hooks")]
            faces: up.faces,
            active: up.active,
            changes: up.changes,
            activity: TileActivity::new(&scene.tiles),
            active_written: None,
            bounce_work: Vec::new(),
            surfels: up.surfels,
            tile_surfels: placed.slots.iter().map(|s| s.surfels.clone()).collect(),
            tiles: placed.tiles,
            pools,
            cull_tiles,
            tiles_buf: up.tiles,
            nodes_buf: up.nodes,
            leaves_buf: up.leaves,
            lookup_buf: up.lookup,
            shadow_dirty: vec![true; shadow_faces],
            shadow_drawn: 0,
            camera_view_proj: None,
            gbuffer_stale: false,
            compat: Compat::of(scene),
            view: None,
            direct_valid: false,
            forced: Vec::new(),
            light_held: None,
            bounce_readback: None,
            clip: None,
            bounce_at: None,
            slice_run: (0, 0),
            stats_now: PassStats::default(),
            queries: pass_queries(gpu),
        };
        gpu.check("upload")?;
        Ok(r)
    }

    /// The compute parameters of a light update (what the CPU reference needs).
    pub fn params(&self) -> Params {
        self.frame_params(None)
    }

    /// GPU memory the renderer holds: scene buffers, radiance pyramid, shadow atlas (distance +
    /// depth), and the current view's G-buffer and outputs.
    pub fn gpu_bytes(&self) -> u64 {
        let view = self.view.as_ref().map_or(0, |v| {
            let px = u64::from(v.targets.width) * u64::from(v.targets.height);
            px * 4 * 4 + v.outputs.frame.size()
        });
        self.static_bytes + view
    }

    /// Lights with shadow maps; the others are lit per leaf (lights.rs).
    pub fn shadowed_lights(&self) -> usize {
        self.shadowed
    }

    /// Lights in range per light-grid cell: mean and largest.
    pub fn lights_in_range(&self) -> (f32, u32) {
        self.lights_in_range
    }

    pub fn settings(&self) -> &Settings {
        &self.settings
    }

    pub fn stats(&self) -> &PassStats {
        &self.stats_now
    }

    /// Exposure of the next shade (the light state and G-buffer are kept).
    pub fn set_exposure(&mut self, exposure: f32) {
        self.settings.exposure = exposure;
    }

    /// Shows `view` from the next frame on (the light state stays: back to a lit view, the light
    /// passes run only where they had not).
    pub fn set_view(&mut self, view: ViewMode) {
        // The scan view colours the G-buffer's albedo; the others only shade it differently.
        if (view == ViewMode::Scan) != (self.settings.view == ViewMode::Scan) {
            self.gbuffer_stale = true;
        }
        self.settings.view = view;
    }

    /// Cuts the view to a box (frame metres), or not (`None`): see [`ClipBox`].
    pub fn set_clip(&mut self, clip: Option<ClipBox>) {
        if clip != self.clip {
            self.gbuffer_stale = true;
        }
        self.clip = clip;
    }

    pub fn clip(&self) -> Option<ClipBox> {
        self.clip
    }

    /// While held, frames run no bounces, and the plan gives `why`: a viewer holds the light while
    /// its camera moves, so light work is what yields to the frame rate.
    pub fn hold_light(&mut self, why: Option<&'static str>) {
        self.light_held = why;
    }

    /// A light update (as [`Renderer::update_light`]) whose propagation runs at most `max_leaves`
    /// leaves of the current bounce: a bounce split over several calls ends as the whole one does
    /// (each leaf gathers from the same pyramid), and counts once it has run every leaf. Returns
    /// the leaves propagated.
    pub fn update_light_slice(&mut self, max_leaves: u32) -> Result<u32> {
        self.poll_light()?;
        let p = self.plan(None);
        self.execute(&p, None, Some(max_leaves.max(64)))?;
        if !p.runs(Pass::Propagate) {
            return Ok(0);
        }
        Ok(self.slice_run.1 - self.slice_run.0)
    }

    /// Where the light stands: bounces done of the budget, the last change, and whether it has
    /// converged (no more light work until something changes), held or not.
    pub fn light_progress(&self) -> LightProgress {
        // The light's own state: neither a hold nor a view without light is convergence.
        let mut i = self.inputs(None);
        i.light_held = None;
        i.plain_view = None;
        let p = plan::plan(&i);
        LightProgress {
            bounces_done: self.stats_now.bounces_done,
            bounce_budget: self.settings.bounces,
            last_change: self.stats_now.last_change,
            converged: !(p.runs(Pass::Shadow)
                || p.runs(Pass::Inject)
                || p.runs(Pass::Env)
                || p.runs(Pass::Propagate)),
        }
    }

    /// The bounce budget from now on (raising it past the bounces done lets the light go on
    /// converging; the light already propagated stays).
    pub fn set_bounces(&mut self, bounces: u32) {
        self.settings.bounces = bounces;
    }

    /// Turns shadow maps on or off; the direct light is injected again either way.
    pub fn set_shadows(&mut self, on: bool) {
        if self.settings.shadows != on {
            self.settings.shadows = on;
            self.invalidate_lights();
        }
    }

    /// Marks the lights changed: the next update re-renders shadow maps and re-injects, and the
    /// bounces are counted afresh (the light converges again from the new direct light).
    pub fn invalidate_lights(&mut self) {
        self.direct_valid = false;
        self.shadow_dirty.fill(true);
        self.stats_now.last_change = None;
        self.stats_now.bounces_done = 0;
        self.bounce_at = None;
        // A bounce under the old lights still on its way back counts for nothing now.
        self.bounce_readback = None;
        self.set_all_active(Why::LightsChanged);
    }

    fn set_all_active(&mut self, why: Why) {
        self.activity.all(why);
        self.active_written = None;
    }

    /// What each propagation bounce since the last call updated, and why (drained).
    pub fn take_bounce_work(&mut self) -> Vec<BounceWork> {
        std::mem::take(&mut self.bounce_work)
    }

    fn inputs(&self, frame: Option<(&Camera, u32, u32)>) -> PlanInputs {
        let gbuffer_valid = match (frame, &self.view) {
            (Some((c, w, h)), Some(v)) => {
                !self.gbuffer_stale && v.camera == *c && v.targets.width == w && v.targets.height == h
            }
            _ => false,
        };
        PlanInputs {
            headlamp: self.headlamp,
            point_lights: self.point_lights,
            spot_lights: self.spot_lights,
            shadows_enabled: self.settings.shadows,
            shadowed: self.shadowed,
            shadow_budget: self.settings.shadowed_lights,
            fallback: self.settings.shadow_fallback.describe(),
            lights_in_range: self.lights_in_range,
            specular_materials: self.specular_materials,
            specular_surfels: self.specular_surfels,
            emissive_leaves: self.emissive,
            environment: self.environment,
            ambient: self.settings.background.iter().any(|&b| b > 0.0),
            env_valid: self.env_valid,
            direct_valid: self.direct_valid,
            bounces_done: self.stats_now.bounces_done,
            bounce_budget: self.settings.bounces,
            last_change: self.stats_now.last_change,
            convergence_tolerance: self.settings.convergence_tolerance,
            tiles_pending: self.activity.pending_tiles(),
            tiles_total: self.activity.tiles(),
            tiles_why: self.activity.pending_why(),
            frame: frame.is_some(),
            gbuffer_valid,
            plain_view: (!self.settings.view.shows_light()).then(|| self.settings.view.name()),
            light_held: self.light_held.or_else(|| {
                self.bounce_readback.is_some().then_some("the last bounce's change is on its way back")
            }),
            bounce_part: self.bounce_at.map(|next| (next, self.active_written.unwrap_or(0))),
        }
    }

    /// The plan the next [`Renderer::update_light`] (no camera) or [`Renderer::render`] would run.
    pub fn plan(&self, frame: Option<(&Camera, u32, u32)>) -> EffectPlan {
        let mut p = plan::plan(&self.inputs(frame));
        for step in &mut p.steps {
            if !step.run && self.forced.contains(&step.pass) {
                // Shade needs a G-buffer and the light passes need nothing: any pass may be forced
                // except gbuffer/shade without a frame.
                if frame.is_some() || !matches!(step.pass, Pass::Gbuffer | Pass::Shade) {
                    step.run = true;
                    step.reason = format!("forced (plan said: {})", step.reason);
                }
            }
        }
        p
    }

    /// Runs these passes even where the plan would skip them (tests prove skipping changes
    /// nothing; `--force` on the command line does the same for a user who doubts the plan).
    pub fn set_forced(&mut self, passes: &[Pass]) {
        self.forced = passes.to_vec();
    }

    /// Runs the light part of the plan (shadow, inject, one bounce); returns the plan it ran.
    pub fn update_light(&mut self) -> Result<EffectPlan> {
        self.poll_light()?;
        let p = self.plan(None);
        self.execute(&p, None, None)?;
        Ok(p)
    }

    /// Runs light updates until the plan stops propagating (converged or budget spent); returns
    /// the number of bounces run.
    pub fn settle(&mut self, progress: impl FnMut(u32, Option<f32>)) -> Result<u32> {
        self.settle_at_most(u32::MAX, progress)
    }

    /// As [`Renderer::settle`], stopping after at most `max_bounces` bounces; what is left runs
    /// one bounce per rendered frame ([`Renderer::render`]), so the light converges over frames.
    pub fn settle_at_most(
        &mut self,
        max_bounces: u32,
        mut progress: impl FnMut(u32, Option<f32>),
    ) -> Result<u32> {
        let start = self.stats_now.bounces_done;
        loop {
            if self.stats_now.bounces_done - start >= max_bounces && self.direct_valid {
                return Ok(self.stats_now.bounces_done - start);
            }
            let p = self.update_light()?;
            progress(self.stats_now.bounces_done, self.stats_now.last_change);
            if !p.runs(Pass::Propagate) {
                return Ok(self.stats_now.bounces_done - start);
            }
        }
    }

    /// Each tile's light state as this renderer holds it for `scene` (the scene it was made
    /// for, or last updated to), to carry into the renderer of another scene that holds some of
    /// the same tiles.
    pub fn light_by_tile(&self, scene: &SceneData) -> Result<CarriedLight> {
        self.check_holds(scene, "light_by_tile")?;
        let state = self.read_light(self.leaf_count)?;
        let mut tiles = HashMap::new();
        for t in &self.tiles {
            let range = t.leaf_offset as usize..(t.leaf_offset + t.leaf_count) as usize;
            if let Some(leaves) = state.get(range) {
                tiles.insert(key(t), leaves.to_vec());
            }
        }
        Ok(CarriedLight { tiles })
    }

    /// An error unless `scene` holds this renderer's tiles in the same forms, in order.
    fn check_holds(&self, scene: &SceneData, what: &'static str) -> Result<()> {
        let same = scene.tiles.len() == self.tiles.len()
            && scene.tiles.iter().zip(&self.tiles).all(|(a, b)| key(a) == key(b));
        if same {
            Ok(())
        } else {
            Err(Error::Internal { what, message: "not the scene this renderer holds".into() })
        }
    }

    /// The light state of leaves `0..n`, read back.
    fn read_light(&self, n: u32) -> Result<Vec<LeafLightGpu>> {
        let size = size_of::<LeafLightGpu>();
        let bytes = self.gpu.read_buffer(&self.leaf_light, u64::from(n) * size as u64)?;
        Ok(bytemuck::pod_collect_to_vec(&bytes[..n as usize * size]))
    }

    /// Starts every tile of `scene` (this renderer's scene) that `carried` holds in the same form
    /// (same place, depth and level) from the light it had there, instead of from none: tiles
    /// that stay resident keep their converged light across a reload, and only what changed
    /// needs bounces. Direct light, environment light and `out` are recomputed by the passes as
    /// usual. Returns the leaves seeded. ([`Renderer::update_scene`] keeps the light in place
    /// instead, with no read-back; this is for a renderer made anew.)
    pub fn seed_light(&mut self, scene: &SceneData, carried: &CarriedLight) -> Result<usize> {
        self.check_holds(scene, "seed_light")?;
        let mut seeded = 0;
        let mut kept = vec![false; self.tiles.len()];
        for (t, k) in self.tiles.iter().zip(&mut kept) {
            if let Some(from) = carried.tiles.get(&key(t))
                && from.len() == t.leaf_count as usize
            {
                let at = u64::from(t.leaf_offset) * size_of::<LeafLightGpu>() as u64;
                self.gpu.queue.write_buffer(&self.leaf_light, at, bytemuck::cast_slice(from));
                seeded += from.len();
                *k = true;
            }
        }
        if seeded > 0 {
            // Only the new tiles and what touches them need bounces (activity.rs).
            self.activity.seed(&kept);
            self.active_written = None;
        }
        Ok(seeded)
    }

    /// Replaces the scene with `scene`, another residency of the same package (the same lights,
    /// frame and bounds: every tile in some form), in place: the tile forms already resident keep
    /// their slots in the pools and their light; only the new forms are written (pool.rs). Shadow
    /// faces that see a changed tile are drawn again; the light is then settled from the kept
    /// light, starting with the new tiles and their neighbours (activity.rs). `None` when the
    /// scene cannot replace this one in place (other lights or bounds, over the pools, tiles put
    /// together by hand): make a new renderer then. Nothing is changed in that case.
    pub fn update_scene(&mut self, scene: &SceneData) -> Result<Option<SceneUpdate>> {
        let (owners, exact) = surfel_owners(scene);
        let need = PoolCaps::of(scene);
        if !exact || !self.cull_tiles || !self.pools.caps().holds(&need) || Compat::of(scene) != self.compat {
            return Ok(None);
        }
        let index = crate::scene::tile_index::TileIndex::build(&scene.name, &scene.tiles)?;
        let index_offset = 4 * u64::from(self.base_params.lookup_base[2]);
        if 4 * index.words.len() as u64 > self.lookup_buf.size() - index_offset {
            return Ok(None);
        }
        let old_slots = self.pools.slots().clone();
        let old_leaf_end = self.pools.leaf_end();
        let placed = self.pools.place(scene, &owners)?;
        let write = |buf: &wgpu::Buffer, at: u64, bytes: &[u8]| {
            if !bytes.is_empty() {
                self.gpu.queue.write_buffer(buf, at, bytes);
            }
            bytes.len() as u64
        };
        // The light of the forms that stayed, where a repack moved them: read back before
        // anything is written.
        let moved: HashMap<TileKey, Vec<LeafLightGpu>> = if placed.repacked {
            let state = self.read_light(old_leaf_end)?;
            placed
                .tiles
                .iter()
                .filter_map(|t| {
                    let s = old_slots.get(&key(t))?;
                    Some((key(t), state.get(s.leaves.start as usize..s.leaves.end as usize)?.to_vec()))
                })
                .collect()
        } else {
            HashMap::new()
        };
        let mut update =
            SceneUpdate { repacked: placed.repacked, freed_tiles: placed.freed, ..Default::default() };
        let mut light_kept = placed.kept.clone();
        for (i, (t, at)) in scene.tiles.iter().zip(&placed.tiles).enumerate() {
            if placed.kept[i] {
                update.kept_tiles += 1;
                update.carried_leaves += t.leaf_count as usize;
                continue;
            }
            update.uploaded_tiles += 1;
            let (n0, l0) = (t.node_offset as usize, t.leaf_offset as usize);
            let leaf_level = t.depth - t.leaf_lod;
            // Indices inside the tile move with it: to its nodes for inner nodes, to its leaves
            // for the nodes at its leaf level.
            let nodes: Vec<NodeGpu> = scene.nodes[n0..n0 + t.node_count as usize]
                .iter()
                .map(|n| {
                    let first_child = if n.level() == leaf_level {
                        n.first_child.wrapping_sub(t.leaf_offset).wrapping_add(at.leaf_offset)
                    } else {
                        n.first_child.wrapping_sub(t.node_offset).wrapping_add(at.node_offset)
                    };
                    NodeGpu { first_child, ..*n }
                })
                .collect();
            let leaves = &scene.leaves[l0..l0 + t.leaf_count as usize];
            let light = match moved.get(&key(t)) {
                Some(l) if l.len() == leaves.len() => {
                    light_kept[i] = true;
                    update.carried_leaves += l.len();
                    l.clone()
                }
                _ => initial_light(leaves),
            };
            let surfels = &scene.surfels[owners[i].start as usize..owners[i].end as usize];
            let slot = &placed.slots[i];
            update.upload_bytes += write(
                &self.nodes_buf,
                u64::from(at.node_offset) * size_of::<NodeGpu>() as u64,
                bytemuck::cast_slice(&nodes),
            ) + write(
                &self.leaves_buf,
                u64::from(at.leaf_offset) * size_of::<LeafGpu>() as u64,
                bytemuck::cast_slice(leaves),
            ) + write(
                &self.leaf_light,
                u64::from(at.leaf_offset) * size_of::<LeafLightGpu>() as u64,
                bytemuck::cast_slice(&light),
            ) + write(
                &self.surfels,
                u64::from(slot.surfels.start) * size_of::<SurfelGpu>() as u64,
                bytemuck::cast_slice(surfels),
            );
        }
        update.upload_bytes += write(&self.tiles_buf, 0, bytemuck::cast_slice(&placed.tiles))
            + write(&self.lookup_buf, index_offset, bytemuck::cast_slice(&index.words));
        let (by_height, ranges) = scene.nodes_by_height_at(&placed.tiles);
        self.mip.set_order(&self.gpu, &by_height, &ranges)?;
        update.upload_bytes += 4 * by_height.len() as u64;

        // Shadow faces that see a tile form that came or went.
        let new_keys: HashSet<TileKey> = placed.tiles.iter().map(key).collect();
        let changed: Vec<(Vec3, Vec3)> = self
            .tiles
            .iter()
            .filter(|t| !new_keys.contains(&key(t)))
            .chain(placed.tiles.iter().filter(|t| !old_slots.contains_key(&key(t))))
            .map(|t| tile_box(t, self.leaf_size_m))
            .collect();
        for (face, dirty) in self.shadow.faces().iter().zip(&mut self.shadow_dirty) {
            if changed.iter().any(|(lo, hi)| crate::view::camera::sees_box(&face.view_proj, *lo, *hi)) {
                *dirty = true;
            }
        }
        update.shadow_faces = self.shadow_dirty.iter().filter(|d| **d).count();

        self.tile_surfels = placed.slots.iter().map(|s| s.surfels.clone()).collect();
        self.tiles = placed.tiles;
        self.leaf_count = self.pools.leaf_end();
        #[cfg(feature = "test-hooks")]
        {
            self.node_count = self.pools.slots().values().map(|s| s.nodes.end).max().unwrap_or(0);
        }
        self.base_params.tile_count = self.tiles.len() as u32;
        self.base_params.leaf_count = self.leaf_count;
        // New tiles may hold brighter rock: the tail's trusted ratio follows the leaves held.
        self.base_params.tail_ratio_max = tail_ratio_max(&self.settings, &scene.leaves);
        let (_, specular_materials, specular_surfels) = material_slots(scene, &self.settings);
        (self.specular_materials, self.specular_surfels) = (specular_materials, specular_surfels);
        self.emissive = scene.has_emission();
        self.activity = TileActivity::new(&self.tiles);
        self.activity.seed(&light_kept);
        self.active_written = None;
        // Direct and environment light for the new leaves (and the faces drawn again), a new
        // G-buffer, and bounces counted afresh as for a new renderer.
        self.direct_valid = false;
        self.env_valid = false;
        self.gbuffer_stale = true;
        self.stats_now = PassStats::default();
        self.bounce_at = None;
        // The change of a bounce over the old tiles, still on its way back, is not this scene's.
        self.bounce_readback = None;
        Ok(Some(update))
    }

    /// Bytes of the tile pools (what `--gpu-memory` bounds: nodes, radiance pyramid, mip order,
    /// leaves, leaf light, surfels, tile records).
    pub fn pool_bytes(&self) -> u64 {
        self.pools.caps().bytes(self.settings.radiance_f16)
    }

    /// The pools' capacities.
    pub fn pool_caps(&self) -> PoolCaps {
        self.pools.caps()
    }

    /// Faces of the shadow atlas (six per point light with a map, one per spot light).
    pub fn shadow_face_count(&self) -> usize {
        self.shadow_faces
    }

    /// Shadow faces drawn since the last call (a shadow pass draws the faces that see a change),
    /// drained like [`Renderer::take_bounce_work`].
    pub fn take_shadow_faces_drawn(&mut self) -> u64 {
        std::mem::take(&mut self.shadow_drawn)
    }

    /// The surfel ranges of the tiles a view of `view_proj` may see, merged (every resident surfel
    /// where tiles cannot be culled, or without a view).
    fn runs_seen(&self, view_proj: Option<&Mat4>) -> Vec<Range<u32>> {
        let seen = |t: &TileGpu| match view_proj {
            Some(m) if self.cull_tiles => {
                let (lo, hi) = tile_box(t, self.leaf_size_m);
                crate::view::camera::sees_box(m, lo, hi)
            }
            _ => true,
        };
        merge_runs(
            self.tiles
                .iter()
                .zip(&self.tile_surfels)
                .filter(|(t, _)| seen(t))
                .map(|(_, r)| r.clone())
                .collect(),
        )
    }

    /// Renders one frame (running whatever light work the plan asks for first: progressive, at
    /// most one bounce per frame).
    pub fn render(&mut self, camera: &Camera, width: u32, height: u32) -> Result<(Frame, EffectPlan)> {
        let p = self.draw(camera, width, height)?;
        Ok((self.read_frame()?, p))
    }

    /// The buffer the last frame's HDR radiance is in (4 f32 a pixel, rows top to bottom, from
    /// its start) and its bytes there: what a browser reads back without blocking for its
    /// exposure.
    pub fn hdr_output(&self) -> Option<(&wgpu::Buffer, u64)> {
        self.view.as_ref().map(|v| (&v.outputs.frame, v.outputs.hdr_bytes()))
    }

    /// The last frame [`Renderer::draw`] (or render) made, read back.
    pub fn read_frame(&self) -> Result<Frame> {
        let view = self.view("shade")?;
        let (width, height) = (view.targets.width, view.targets.height);
        let pixels = u64::from(width) * u64::from(height);
        let bytes = self.gpu.read_buffer(&view.outputs.frame, view.outputs.frame.size())?;
        let (hdr_bytes, ldr_bytes) = bytes.split_at(view.outputs.hdr_bytes() as usize);
        let hdr: Vec<[f32; 4]> = bytemuck::pod_collect_to_vec(hdr_bytes);
        let ldr: Vec<[u8; 4]> = bytemuck::pod_collect_to_vec(&ldr_bytes[..(pixels * 4) as usize]);
        Ok(Frame { width, height, hdr, ldr })
    }

    /// Renders one frame as [`Renderer::render`] does, leaving it on the GPU ([`Renderer::ldr_output`])
    /// instead of reading it back: what a window presents.
    pub fn draw(&mut self, camera: &Camera, width: u32, height: u32) -> Result<EffectPlan> {
        camera.validate()?;
        if width == 0 || height == 0 || width > 16384 || height > 16384 {
            return Err(Error::Setting {
                name: "size",
                problem: format!("{width}x{height} is outside 1..=16384"),
            });
        }
        self.poll_light()?;
        let p = self.plan(Some((camera, width, height)));
        self.execute(&p, Some((camera, width, height)), None)?;
        Ok(p)
    }

    /// The distance in metres from the eye to the surface at pixel `(x, y)` of the last frame
    /// (its own size, rows top to bottom); None where the background shows or outside the frame.
    pub fn distance_at(&self, x: u32, y: u32) -> Result<Option<f32>> {
        let view = self.view("pick")?;
        if x >= view.targets.width || y >= view.targets.height {
            return Ok(None);
        }
        let buf =
            self.gpu.buffer("pick", 256, wgpu::BufferUsages::COPY_SRC | wgpu::BufferUsages::COPY_DST)?;
        let mut enc = self.gpu.device.create_command_encoder(&Default::default());
        enc.copy_texture_to_buffer(
            wgpu::TexelCopyTextureInfo {
                texture: &view.targets.distance,
                mip_level: 0,
                origin: wgpu::Origin3d { x, y, z: 0 },
                aspect: wgpu::TextureAspect::All,
            },
            wgpu::TexelCopyBufferInfo {
                buffer: &buf,
                layout: wgpu::TexelCopyBufferLayout {
                    offset: 0,
                    bytes_per_row: Some(256),
                    rows_per_image: Some(1),
                },
            },
            wgpu::Extent3d { width: 1, height: 1, depth_or_array_layers: 1 },
        );
        self.gpu.queue.submit([enc.finish()]);
        let b = self.gpu.read_buffer(&buf, 4)?;
        // The G-buffer packs the f32's bits into RGBA8 (packing.wgsl); cleared pixels are 0.
        let d = f32::from_bits(u32::from_le_bytes([b[0], b[1], b[2], b[3]]));
        Ok((d.is_finite() && d > 0.0).then_some(d))
    }

    /// The last frame's tonemapped pixels (one packed RGBA8 u32 a pixel, rows top to bottom, from
    /// word `first_word` of `buffer`) and its size; `None` before the first frame.
    pub fn ldr_output(&self) -> Option<LdrOutput<'_>> {
        self.view.as_ref().map(|v| LdrOutput {
            buffer: &v.outputs.frame,
            first_word: v.outputs.ldr_first_word(),
            width: v.targets.width,
            height: v.targets.height,
        })
    }

    fn frame_params(&self, frame: Option<(&Camera, u32, u32)>) -> Params {
        let mut p = self.base_params;
        let s = &self.settings;
        // Auto exposure sets it after the light has settled (`set_exposure`).
        p.exposure = s.exposure;
        let mut f = flags::EMISSION;
        if !self.direct_valid || (self.environment && !self.env_valid) {
            f |= flags::NEW_SERIES;
        }
        if s.direct && p.light_count > 0 {
            f |= flags::DIRECT;
        }
        if s.direct && s.shadows && self.shadowed < p.light_count as usize {
            f |= flags::FAR_LIGHTS;
        }
        if s.shadows && self.shadow_faces > 0 {
            f |= flags::SHADOWS;
        }
        match s.indirect {
            IndirectFilter::Trilinear => f |= flags::INDIRECT,
            IndirectFilter::Tricubic => f |= flags::INDIRECT | flags::TRICUBIC,
            IndirectFilter::Off => {}
        }
        if self.environment {
            f |= flags::ENV;
        }
        if self.specular_surfels > 0 {
            f |= flags::SPECULAR;
        }
        if s.cone_interleave {
            f |= flags::CONE_INTERLEAVE;
        }
        f |= match s.view {
            ViewMode::Lit => 0,
            ViewMode::Albedo => flags::VIEW_ALBEDO,
            ViewMode::Normals => flags::VIEW_NORMALS,
            ViewMode::Light => flags::VIEW_LIGHT,
            ViewMode::Level => flags::VIEW_LEVEL,
            ViewMode::Scan => flags::VIEW_SCAN,
        };
        p.flags = f;
        if let Some((c, w, h)) = frame {
            p.width = w;
            p.height = h;
            let forward = (c.look_at_m - c.eye_m).normalize();
            let right = forward.cross(c.up).normalize();
            let up = right.cross(forward);
            p.camera_eye_m = c.eye_m.extend(0.0).to_array();
            p.camera_forward = forward.extend((c.fov_y_deg.to_radians() * 0.5).tan()).to_array();
            p.camera_right = right.extend(w as f32 / h as f32).to_array();
            p.camera_up = up.extend(0.0).to_array();
        }
        p
    }

    fn timestamp_pair(&self, pass: Pass) -> Option<(&wgpu::QuerySet, u32)> {
        let i = Pass::ALL.iter().position(|p| *p == pass).unwrap_or(0) as u32;
        self.queries.as_ref().map(|(set, _)| (set, 2 * i))
    }

    /// Writes the camera's splat uniform and (re)makes the view's targets when the size changed.
    fn prepare_view(&mut self, camera: &Camera, w: u32, h: u32) -> Result<()> {
        let near = (0.02 * self.leaf_size_m).max(1e-4);
        let far = (camera.eye_m.length() + self.scene_diag_m) * 2.0 + 1.0;
        let m = camera.view_proj(w, h, near, far);
        let u = SplatUniform {
            view_proj: m.to_cols_array_2d(),
            eye_m: camera.eye_m.extend(1.0).to_array(),
            viewport: [
                w as f32,
                h as f32,
                self.settings.min_splat_px,
                1.0 / (camera.fov_y_deg.to_radians() * 0.5).tan(),
            ],
            splat: [
                self.settings.splat_scale,
                f32::from(u8::from(self.settings.view == ViewMode::Scan)),
                0.0,
                0.0,
            ],
            clip_min_m: self.clip.map_or([0.0; 4], |c| c.min_m.extend(1.0).to_array()),
            clip_max_m: self.clip.map_or([0.0; 4], |c| c.max_m.extend(1.0).to_array()),
            pad: [[0.0; 4]; 7],
        };
        self.gbuffer.set_camera(&self.gpu, &u);
        self.camera_view_proj = Some(m);
        let reuse = self.view.as_ref().is_some_and(|v| v.targets.width == w && v.targets.height == h);
        if !reuse {
            // The largest per-view buffer first, before any target is allocated.
            let pixels = u64::from(w) * u64::from(h);
            self.gpu.check_buffer("shade hdr", pixels * 16, wgpu::BufferUsages::STORAGE)?;
            let targets = gbuffer::Targets::new(&self.gpu, w, h)?;
            let outputs = self.shade.outputs(&self.gpu, &targets)?;
            self.view = Some(View { camera: *camera, targets, outputs });
        } else if let Some(v) = self.view.as_mut() {
            v.camera = *camera;
        }
        Ok(())
    }

    fn view(&self, pass: &'static str) -> Result<&View> {
        self.view.as_ref().ok_or(Error::Internal { what: pass, message: "no view was prepared".into() })
    }

    fn encoder(&self) -> wgpu::CommandEncoder {
        self.gpu.device.create_command_encoder(&wgpu::CommandEncoderDescriptor { label: Some("frame") })
    }

    /// Records one pass into `enc`.
    fn record(&self, enc: &mut wgpu::CommandEncoder, pass: Pass) -> Result<()> {
        let ts = self.timestamp_pair(pass);
        let render_ts = ts.map(|(set, i)| wgpu::RenderPassTimestampWrites {
            query_set: set,
            beginning_of_pass_write_index: Some(i),
            end_of_pass_write_index: Some(i + 1),
        });
        match pass {
            Pass::Shadow => {
                let draws: Vec<Option<Vec<Range<u32>>>> = self
                    .shadow
                    .faces()
                    .iter()
                    .zip(&self.shadow_dirty)
                    .map(|(f, &dirty)| dirty.then(|| self.runs_seen(Some(&f.view_proj))))
                    .collect();
                self.shadow.record(enc, &self.surfels, &draws, render_ts);
            }
            Pass::Gbuffer => {
                let v = self.view("gbuffer")?;
                let runs = self.runs_seen(self.camera_view_proj.as_ref());
                self.gbuffer.record(enc, &v.targets, &self.surfels, &runs, render_ts);
            }
            compute => {
                let tw = ts.map(|(set, i)| wgpu::ComputePassTimestampWrites {
                    query_set: set,
                    beginning_of_pass_write_index: Some(i),
                    end_of_pass_write_index: Some(i + 1),
                });
                let mut cp = enc.begin_compute_pass(&wgpu::ComputePassDescriptor {
                    label: Some(compute.name()),
                    timestamp_writes: tw,
                });
                match compute {
                    Pass::Inject => self.inject.record(&mut cp, self.leaf_count),
                    Pass::Env => self.env.record(&mut cp, self.leaf_count),
                    Pass::Mip => self.mip.record(&mut cp),
                    Pass::Propagate => self.propagate.record(&mut cp, self.slice_run.1 - self.slice_run.0),
                    Pass::Shade => {
                        let v = self.view("shade")?;
                        self.shade.record(&mut cp, &v.outputs, v.targets.width, v.targets.height);
                    }
                    Pass::Shadow | Pass::Gbuffer => {}
                }
            }
        }
        Ok(())
    }

    /// Records and submits the plan's passes (one encoder, or one per pass where the adapter has
    /// no timestamp queries and each is timed on the CPU); `ran` collects the passes recorded.
    fn record_frame(&mut self, plan: &EffectPlan, ran: &mut Vec<Pass>) -> Result<()> {
        let mut enc = self.encoder();
        if plan.runs(Pass::Propagate) && self.slice_run.0 == 0 {
            // A bounce starts: its changes are gathered over all its slices.
            enc.clear_buffer(&self.changes, 0, None);
        }
        for step in plan.steps.iter().filter(|s| s.run) {
            let recorded = Instant::now();
            self.record(&mut enc, step.pass)?;
            *self.stats_now.dispatches.entry(step.pass).or_default() += 1;
            ran.push(step.pass);
            if self.queries.is_none() && !cfg!(target_arch = "wasm32") {
                // No timestamp queries: time each pass on the CPU, recording to completion of its
                // own blocking submit (not in a browser, which cannot block).
                let done = std::mem::replace(&mut enc, self.encoder());
                self.gpu.queue.submit([done.finish()]);
                self.gpu.wait()?;
                let ms = recorded.elapsed().as_secs_f64() * 1e3;
                self.stats_now.last_ms.insert(step.pass, ms);
            }
        }
        if let Some((set, buf)) = &self.queries
            && !ran.is_empty()
        {
            enc.resolve_query_set(set, 0..2 * Pass::ALL.len() as u32, buf, 0);
        }
        self.gpu.queue.submit([enc.finish()]);
        self.gpu.wait()
    }

    /// Runs `plan`; its propagation runs at most `slice` invocations of the bounce (None: the
    /// rest of it).
    fn execute(
        &mut self,
        plan: &EffectPlan,
        frame: Option<(&Camera, u32, u32)>,
        slice: Option<u32>,
    ) -> Result<()> {
        let params = self.frame_params(frame);
        self.gpu.queue.write_buffer(&self.params, 0, bytemuck::bytes_of(&params));
        if plan.runs(Pass::Propagate) {
            if self.bounce_at.is_none() && self.activity.pending_tiles() == 0 {
                // Forced past convergence: a bounce means every tile.
                self.set_all_active(Why::Verify);
            }
            if self.active_written.is_none() {
                let (tiles, items) = self.activity.active_tiles();
                let header = [tiles.len() as u32, items];
                self.gpu.queue.write_buffer(&self.active, 0, bytemuck::cast_slice(&header));
                if !tiles.is_empty() {
                    self.gpu.queue.write_buffer(&self.active, 16, bytemuck::cast_slice(&tiles));
                }
                self.active_written = Some(items);
            }
            let items = self.active_written.unwrap_or(0);
            let first = self.bounce_at.unwrap_or(0).min(items);
            let end = slice.map_or(items, |n| first.saturating_add(n).min(items));
            self.slice_run = (first, end);
            self.gpu.queue.write_buffer(&self.active, 8, bytemuck::cast_slice(&[first, end]));
        }
        if let Some((camera, w, h)) = frame
            && plan.runs(Pass::Gbuffer)
        {
            self.prepare_view(camera, w, h)?;
        }
        // The frame runs inside one validation error scope; when it catches an error, each pass
        // is recorded again alone in a scope of its own (and not submitted) to name the culprit.
        // A command buffer per pass would name it directly, but costs lavapipe time on every frame
        // (tried: frames of the bunny at 64x48 went from 0.1 s to 1.5 s), so the fast path stays
        // one encoder and only a failing frame pays for the search.
        let mut ran: Vec<Pass> = Vec::new();
        let gpu = self.gpu.clone();
        let (outcome, error) = gpu.capture(|| self.record_frame(plan, &mut ran));
        if let Some(e) = error {
            let culprit = ran.iter().copied().find(|&pass| {
                self.gpu
                    .scoped(pass.name(), || {
                        let mut enc = self.encoder();
                        self.record(&mut enc, pass)?;
                        enc.finish();
                        Ok(())
                    })
                    .is_err()
            });
            return Err(Error::Gpu { pass: culprit.map_or("frame", Pass::name), message: e.to_string() });
        }
        outcome?;
        self.gpu.check("frame")?;
        if let Some((_, buf)) = &self.queries
            && !ran.is_empty()
        {
            let bytes = self.gpu.read_buffer(buf, 16 * Pass::ALL.len() as u64)?;
            let ticks: Vec<u64> = bytemuck::pod_collect_to_vec(&bytes);
            let period = f64::from(self.gpu.queue.get_timestamp_period());
            for pass in &ran {
                let i = Pass::ALL.iter().position(|p| p == pass).unwrap_or(0);
                let dt = ticks[2 * i + 1].saturating_sub(ticks[2 * i]) as f64 * period / 1e6;
                self.stats_now.last_ms.insert(*pass, dt);
            }
        }
        if ran.contains(&Pass::Shadow) {
            self.shadow_drawn += self.shadow_dirty.iter().filter(|d| **d).count() as u64;
            self.shadow_dirty.fill(false);
        }
        if ran.contains(&Pass::Gbuffer) {
            self.gbuffer_stale = false;
        }
        if ran.contains(&Pass::Inject) || (self.point_lights + self.spot_lights == 0) {
            self.direct_valid = true;
        }
        if ran.contains(&Pass::Env) {
            self.env_valid = true;
        }
        let end = self.slice_run.1;
        let items = self.active_written.unwrap_or(0);
        if ran.contains(&Pass::Propagate) && end < items {
            // Part of a bounce: the rest runs in later calls, from the same pyramid.
            self.bounce_at = Some(end);
        } else if ran.contains(&Pass::Propagate) {
            self.bounce_at = None;
            let tiles = self.activity.tiles();
            self.bounce_readback = Some(self.gpu.start_read(&self.changes, 16 + 4 * tiles as u64));
            // Natively the bounce ends here; a browser collects its change on a later frame
            // (`poll_light`), and plans no light work until then.
            if !cfg!(target_arch = "wasm32") {
                let gpu = self.gpu.clone();
                gpu.wait_for("propagate", || Ok(self.poll_light()?.then_some(())))?;
            }
        }
        Ok(())
    }

    /// Finishes the last bounce where its read-back has arrived: its change decides which tiles
    /// the next bounce updates, and whether the light converged. Returns whether no read-back is
    /// pending any longer. Every call that plans (`draw`, `update_light`, `update_light_slice`)
    /// calls it first, so in a browser a bounce that ended on an earlier frame is counted before
    /// the next plan.
    fn poll_light(&mut self) -> Result<bool> {
        let Some(read) = &self.bounce_readback else { return Ok(true) };
        let Some(bytes) = read.take() else { return Ok(false) };
        self.bounce_readback = None;
        let bytes = bytes?;
        let tiles = self.activity.tiles();
        let bits = u32::from_le_bytes([bytes[0], bytes[1], bytes[2], bytes[3]]);
        self.stats_now.last_change = Some(f32::from_bits(bits));
        self.stats_now.bounces_done += 1;
        let change: Vec<f32> = bytemuck::pod_collect_to_vec(&bytes[16..16 + 4 * tiles]);
        let work = self.activity.finish(&change, self.settings.convergence_tolerance);
        self.stats_now.propagated_leaves += work.leaves;
        self.bounce_work.push(work);
        self.active_written = None;
        Ok(true)
    }

    /// Each leaf's light state (direct, gather, out), for tests and the reference comparison.
    #[cfg(feature = "test-hooks")]
    pub fn read_leaf_light(&self) -> Result<Vec<LeafLightGpu>> {
        self.read_light(self.leaf_count)
    }

    /// Overwrites each leaf's light state (tests: a known radiance field before a mip or gather).
    #[cfg(feature = "test-hooks")]
    pub fn write_leaf_light(&mut self, state: &[LeafLightGpu]) -> Result<()> {
        if state.len() != self.leaf_count as usize {
            return Err(Error::Setting {
                name: "leaf light",
                problem: "length differs from the leaf count".into(),
            });
        }
        self.gpu.queue.write_buffer(&self.leaf_light, 0, bytemuck::cast_slice(state));
        self.stats_now.last_change = None;
        self.set_all_active(Why::Start);
        Ok(())
    }

    /// The six anisotropic values of every node (after a mip pass).
    #[cfg(feature = "test-hooks")]
    pub fn read_faces(&self) -> Result<Vec<[f32; 4]>> {
        let n = self.node_count as usize * 6;
        if self.settings.radiance_f16 {
            let bytes = self.gpu.read_buffer(&self.faces, n as u64 * 8)?;
            let halves: Vec<half::f16> = bytemuck::pod_collect_to_vec(&bytes[..n * 8]);
            return Ok(halves.chunks_exact(4).map(|c| [0, 1, 2, 3].map(|k| c[k].to_f32())).collect());
        }
        let bytes = self.gpu.read_buffer(&self.faces, n as u64 * 16)?;
        Ok(bytemuck::pod_collect_to_vec(&bytes[..n * 16]))
    }

    /// Makes the next [`Renderer::update_scene`] repack the pools (compact every slot, carrying
    /// the light of the forms that stay) even where the new forms fit the holes: to defragment
    /// at a quiet moment, and for tests of the repack path.
    pub fn repack_next_update(&mut self) {
        self.pools.repack_next();
    }

    /// Runs only the mip pass (tests).
    #[cfg(feature = "test-hooks")]
    pub fn run_mip(&mut self) -> Result<()> {
        let p =
            EffectPlan { steps: vec![plan::Step { pass: Pass::Mip, run: true, reason: "requested".into() }] };
        self.execute(&p, None, None)
    }

    /// Runs only mip + propagate, i.e. one bounce over every tile regardless of the plan (tests).
    #[cfg(feature = "test-hooks")]
    pub fn run_bounce(&mut self) -> Result<()> {
        self.set_all_active(Why::Verify);
        let p = EffectPlan {
            steps: vec![
                plan::Step { pass: Pass::Mip, run: true, reason: "requested".into() },
                plan::Step { pass: Pass::Propagate, run: true, reason: "requested".into() },
            ],
        };
        self.execute(&p, None, None)
    }
}
