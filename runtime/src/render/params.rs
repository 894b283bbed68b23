//! What the passes read from the renderer's parameters: the cone set, the scene's base
//! parameters, material and environment slots, and the one lookup buffer; and auto-exposure.

use glam::Vec3;

use crate::error::Result;
use crate::gpu::types::{MAX_CONES, Params, TileGpu};
use crate::light::setup::LightSetup;
use crate::passes::shadow;
use crate::scene::data::{EnvChain, MAX_ENV_LEVELS, MAX_MATERIALS, SceneData};

use crate::settings::Settings;

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

/// Specular material slots (slot 0 = diffuse: x Ks, y GGX alpha, z ior, w roughness), and the
/// specular materials and surfels the settings keep.
pub(super) fn material_slots(
    scene: &SceneData,
    settings: &Settings,
) -> ([[f32; 4]; MAX_MATERIALS + 1], usize, usize) {
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
pub(super) fn env_levels(chain: Option<&EnvChain>) -> ([[f32; 4]; MAX_ENV_LEVELS], [u32; 4]) {
    let mut levels = [[0.0f32; 4]; MAX_ENV_LEVELS];
    let Some(c) = chain else { return (levels, [0, 1, 0, 0]) };
    for (k, l) in c.levels.iter().take(MAX_ENV_LEVELS).enumerate() {
        levels[k] = [l.0 as f32, l.1 as f32, l.2 as f32, l.3];
    }
    (levels, [c.levels.len().min(MAX_ENV_LEVELS) as u32, c.width, 0, 0])
}

/// The compute parameters that do not change per frame.
#[allow(clippy::too_many_arguments)]
pub(super) fn base_params(
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
    let (occupied_lo, occupied_hi) = scene.occupied_bounds_leaf();
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
        occupied_min_leaf: occupied_lo.extend(0.0).to_array(),
        occupied_max_leaf: occupied_hi.extend(0.0).to_array(),
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
        tail_ratio_max: tail_ratio_max(settings, scene),
    }
}

/// The largest bounce ratio the tail estimate trusts, per channel: the spectral radius of one
/// bounce is at most the largest albedo (the cone weights sum to 1 and opacity only loses
/// light), so a leaf whose change grew by more is still filling with light, not converging.
pub(super) fn tail_ratio_max(settings: &Settings, scene: &SceneData) -> [f32; 4] {
    if !settings.bounce_tail {
        return [0.0; 4];
    }
    let [r, g, b] = scene.albedo_max();
    [r, g, b, 0.0].map(|v| v.min(crate::gpu::types::TAIL_RATIO_MAX))
}

/// The one lookup buffer's contents (lookup.wgsl): the rock table, the tile index and the light
/// grid, at word offsets `base`. After the index comes room for the index of a scene with other
/// tile forms (its size follows how the tiles align; one that outgrows it makes a new renderer,
/// `update_scene`), after the grid room for the grid of edited lights (one that outgrows it
/// makes a new renderer, `edit_lights`).
pub(super) struct Lookup {
    pub(super) base: [u32; 4],
    pub(super) words: Vec<u32>,
    /// Words the tile index and the light grid may take, from their bases.
    pub(super) index_room: u32,
    pub(super) grid_room: u32,
}

impl Lookup {
    pub(super) fn new(scene: &SceneData, lights: &LightSetup) -> Result<Self> {
        let index = crate::scene::tile_index::TileIndex::build(&scene.name, &scene.tiles)?;
        let (rock, grid) = (&scene.rock.words, &lights.grid.words);
        let index_room = 2 * index.words.len() + 64;
        let grid_room = 2 * grid.len() + 1024;
        let mut words = Vec::with_capacity(rock.len() + index_room + grid_room);
        words.extend_from_slice(rock);
        let index_base = words.len();
        words.extend_from_slice(&index.words);
        words.resize(index_base + index_room, 0);
        let grid_base = words.len();
        words.extend_from_slice(grid);
        words.resize(grid_base + grid_room, 0);
        let base = [0, grid_base as u32, index_base as u32, 0];
        Ok(Self { base, words, index_room: index_room as u32, grid_room: grid_room as u32 })
    }

    /// The bytes the tile index may take.
    pub(super) fn index_bytes(&self) -> std::ops::Range<u64> {
        let at = 4 * u64::from(self.base[2]);
        at..at + 4 * u64::from(self.index_room)
    }
}

/// A tile's box in frame metres, grown by what its surfels' discs may reach past it.
pub(super) fn tile_box(t: &TileGpu, leaf_m: f32) -> (Vec3, Vec3) {
    let lo = glam::IVec3::from_array(t.origin_leaf).as_vec3() * leaf_m;
    let edge = (1u64 << t.depth.min(40)) as f32 * leaf_m;
    let margin = ((1u64 << t.leaf_lod.min(40)) as f32 + 2.0) * leaf_m;
    (lo - Vec3::splat(margin), lo + Vec3::splat(edge + margin))
}
