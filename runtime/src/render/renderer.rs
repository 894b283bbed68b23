//! The renderer: uploads a [`SceneData`], builds the passes once, and per call runs exactly the
//! passes the effect plan marks `run` (counting each dispatch and timing it with GPU timestamps
//! where the adapter has them).
//!
//! Light transport state lives on the GPU between calls: injected direct light, the gathered
//! indirect light and the outgoing radiance of every leaf. Each light update adds one bounce:
//! `out_(k+1) = emission + direct + albedo * gather(out_k)`, so with albedo < 1 the radiance stays
//! bounded and converges to the fixed point.

use glam::Vec3;

use crate::error::{Error, Result};
use crate::gpu::Gpu;
use crate::gpu::types::Params;
use crate::light::plan::Pass;
use crate::light::setup::LightSetup;
use crate::passes::inject::Inject;
use crate::passes::{self, gbuffer, shade};
use crate::render::pool::{Placement, PoolCaps, Pools};
use crate::render::targets::{Stills, ViewTargets};
use crate::render::transport::LightTransport;
use crate::scene::data::{SceneData, SceneLight};

use crate::render::counters::{PassCounters, PassStats};
use crate::render::params::Lookup;
use crate::render::params::base_params;
use crate::render::params::material_slots;
use crate::render::scene_lights::SceneLights;
use crate::render::shadow_atlas::ShadowAtlas;
use crate::render::tiles::TilePools;
use crate::render::tiles::Upload;
use crate::settings::{ClipBox, Settings, ViewMode};

/// Uploaded scene, passes and light state.
#[derive(Debug)]
pub struct Renderer {
    pub(super) gpu: Gpu,
    pub(super) settings: Settings,
    pub(super) leaf_count: u32,
    pub(super) leaf_size_m: f32,
    pub(super) scene_diag_m: f32,
    pub(super) base_params: Params,
    /// The scene's lights: their records, counts and room for an edit in place.
    pub(super) lights: SceneLights,
    /// Specular materials with surfels, and those surfels (0 when `Settings::specular` is off).
    pub(super) specular_materials: usize,
    pub(super) specular_surfels: usize,
    pub(super) emissive: bool,
    /// An environment map lights the scene (it has SH coefficients and the setting allows it).
    pub(super) environment: bool,
    pub(super) params: wgpu::Buffer,
    /// Bytes of every buffer and texture created at upload (the G-buffer is added per view).
    pub(super) static_bytes: u64,
    /// Each node's six anisotropic values (read back by render/inspect.rs).
    pub(super) faces: wgpu::Buffer,
    /// The shadow pass, which of its faces are out of date, and what it drew.
    pub(super) shadows: ShadowAtlas,
    /// The G-buffer and shade passes, the view's targets, still frames, clip and detail.
    pub(super) targets: ViewTargets,
    /// What a scene must share with this one to be swapped in place ([`Renderer::update_scene`]).
    pub(super) compat: Compat,
    /// The tile pools and where each resident tile form lives in them (tiles.rs).
    pub(super) pools: TilePools,
    /// The light passes and the state of the light between frames.
    pub(super) light: LightTransport,
    /// How both splat passes fetch the surfel pool (passes/splat.rs).
    pub(super) splats: passes::splat::Fetch,
    pub(super) forced: Vec<Pass>,
    pub(super) stats_now: PassStats,
    /// The queries each pass writes its GPU time and work into.
    pub(super) counters: PassCounters,
}

/// What two scenes must share for one to replace the other in a renderer's pools: the same lights,
/// frame, bounds (so the light grid and shadow faces stay), coarsest level, materials and
/// environment. Residency keeps all of these (every tile is held in some form).
#[derive(Clone, Debug, PartialEq)]
pub(super) struct Compat {
    pub(super) lights: Vec<SceneLight>,
    pub(super) headlamp: bool,
    pub(super) leaf_size_m: f32,
    pub(super) bounds_leaf: (Vec3, Vec3),
    pub(super) max_lod: u32,
    pub(super) materials: Vec<(String, f32, f32, f32)>,
    pub(super) environment_sh: Option<[[f32; 3]; 9]>,
    pub(super) env_chain: bool,
    pub(super) rock_words: usize,
}

impl Compat {
    pub(super) fn of(scene: &SceneData) -> Self {
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

/// The pipeline constants `settings` ask for.
fn pass_constants(settings: &Settings) -> passes::PassConstants {
    passes::PassConstants {
        radiance_f16: settings.radiance_f16,
        cone_planes: settings.cone_planes,
        cone_rays: settings.cone_rays,
    }
}

impl Renderer {
    /// A renderer whose tile pools hold just `scene`.
    pub fn new(gpu: &Gpu, scene: &SceneData, settings: Settings) -> Result<Self> {
        Self::with_pools(gpu, scene, settings, PoolCaps::of(scene))
    }

    /// A renderer whose tile pools hold `caps` elements (at least what `scene` needs), so later
    /// scenes of other tile forms can replace this one in place ([`Renderer::update_scene`]).
    pub fn with_pools(gpu: &Gpu, scene: &SceneData, settings: Settings, caps: PoolCaps) -> Result<Self> {
        scene.check_held("a renderer made")?;
        settings.validate()?;
        let caps = caps.at_least(PoolCaps::of(scene));
        let (pools, placed, cull_tiles) = fresh_pools(scene, caps)?;
        let f16 = settings.radiance_f16;
        let consts = pass_constants(&settings);
        let (lo, hi) = scene.bounds_leaf();
        let leaf = scene.leaf_size_m.max(1e-6);
        let scene_diag_m = ((hi - lo) * leaf).length().max(leaf);
        let lights = light_setup(scene, &settings, scene_diag_m);
        let environment_on = scene.environment_sh.is_some() && settings.environment;
        let chain = scene.env_chain.as_ref().filter(|_| environment_on);
        let (materials, specular_materials, specular_surfels) = material_slots(scene, &settings);
        let splat_layout = passes::splat::layout(gpu);
        let mut splats = passes::splat::Fetch::new(gpu, caps.surfels);
        let shadows = ShadowAtlas::new(gpu, &splat_layout, &lights, &settings, &splats)?;
        let lookup = Lookup::new(scene, &lights)?;
        let base_params = base_params(
            scene,
            &settings,
            &lights,
            shadows.pass(),
            (lo, hi),
            scene_diag_m,
            chain,
            materials,
            &lookup,
        );
        let up = Upload::new(
            gpu,
            scene,
            caps,
            &lights,
            &lookup,
            shadows.pass().atlas(),
            &base_params,
            f16,
            splats.pulls(),
        )?;
        let tile_pools = TilePools::new(pools, placed, (scene, cull_tiles), &up, lookup.index_bytes());
        let shared = &up.shared;

        let (by_height, ranges) = scene.nodes_by_height();
        let lights_in_range = lights.grid.occupancy();
        let inject = gpu.scoped("inject", || Inject::new(gpu, shared, consts, lights_in_range.1))?;
        let env = gpu.scoped("env", || passes::env::new(gpu, shared, consts, settings.cones))?;
        let mip = gpu
            .scoped("mip", || passes::mip::Mip::new(gpu, shared, caps.nodes, &by_height, &ranges, consts))?;
        let propagate =
            gpu.scoped("propagate", || passes::propagate::new(gpu, shared, consts, settings.cones))?;
        let gbuffer = gpu
            .scoped("gbuffer", || gbuffer::Gbuffer::new(gpu, &splat_layout, &splats, settings.splat_blend))?;
        splats.set_surfels(gpu, &up.surfels);
        let shade = gpu.scoped("shade", || shade::Shade::new(gpu, shared, consts, chain))?;
        let static_bytes = up.bytes + shadows.bytes() + shade.env_atlas_bytes();
        let scene_lights = SceneLights::new(up.lights.clone(), lookup.grid_room, &lights, scene.headlamp);
        let light = LightTransport::new((inject, env, mip, propagate), up.active, up.changes, &scene.tiles);
        let targets = ViewTargets::new(gbuffer, shade, Stills::new(gpu)?);
        let mut r = Self {
            targets,
            light,
            shadows,
            splats,
            gpu: gpu.clone(),
            settings,
            leaf_count: scene.leaves.len() as u32,
            leaf_size_m: leaf,
            scene_diag_m,
            base_params,
            lights: scene_lights,
            specular_materials,
            specular_surfels,
            emissive: scene.has_emission(),
            environment: environment_on,
            params: up.params,
            static_bytes,
            faces: up.faces,
            compat: Compat::of(scene),
            pools: tile_pools,
            forced: Vec::new(),
            stats_now: PassStats::default(),
            counters: PassCounters::new(gpu),
        };
        r.mark_shadow_faces(|_, _| true);
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
        self.static_bytes + self.targets.bytes()
    }

    /// Lights with shadow maps; the others are lit per leaf (light/setup.rs).
    pub fn shadowed_lights(&self) -> usize {
        self.shadows.shadowed()
    }

    /// Lights in range per light-grid cell: mean and largest.
    pub fn lights_in_range(&self) -> (f32, u32) {
        self.lights.in_range
    }

    /// Whether the splat passes pull their surfels from the pool (one non-instanced draw of six
    /// vertices a surfel) rather than draw them as instances (passes/splat.rs).
    pub fn splats_pulled(&self) -> bool {
        self.splats.pulls()
    }

    /// The settings it renders with.
    pub fn settings(&self) -> &Settings {
        &self.settings
    }

    /// Pass counters and times so far.
    pub fn stats(&self) -> &PassStats {
        &self.stats_now
    }

    /// Thins far surfels for the camera's view as if the pixel floor were `detail` times larger
    /// (at least 1; 1: the level of detail the settings give). Shadow maps keep theirs.
    pub fn set_lod_detail(&mut self, detail: f32) {
        self.targets.set_lod_detail(detail);
    }

    /// Exposure of the next shade (the light state and G-buffer are kept).
    pub fn set_exposure(&mut self, exposure: f32) {
        self.settings.exposure = exposure;
    }

    /// Shows `view` from the next frame on (the light state stays: back to a lit view, the light
    /// passes run only where they had not).
    pub fn set_view(&mut self, view: ViewMode) {
        self.targets.change_mode(self.settings.view, view);
        self.settings.view = view;
    }

    /// Cuts the view to a box (frame metres), or not (`None`): see [`ClipBox`].
    pub fn set_clip(&mut self, clip: Option<ClipBox>) {
        self.targets.set_clip(clip);
    }

    /// The view's clip box, if it has one.
    pub fn clip(&self) -> Option<ClipBox> {
        self.targets.clip()
    }

    /// Faces of the shadow atlas (six per point light with a map, one per spot light).
    pub fn shadow_face_count(&self) -> usize {
        self.shadows.face_count()
    }

    /// Shadow faces drawn since the last call (a shadow pass draws the faces that see a change),
    /// drained like [`Renderer::take_bounce_work`].
    pub fn take_shadow_faces_drawn(&mut self) -> u64 {
        self.shadows.take_drawn()
    }
}

/// The scene's light setup, its light grid over the scene with one leaf of slack on every side.
pub(super) fn light_setup(scene: &SceneData, settings: &Settings, scene_diag_m: f32) -> LightSetup {
    let (lo, hi) = scene.bounds_leaf();
    let leaf = scene.leaf_size_m.max(1e-6);
    let near = (0.05 * leaf).max(1e-4);
    LightSetup::new(scene, settings, near, scene_diag_m * 2.0 + 1.0, (lo - 1.0) * leaf, (hi + 1.0) * leaf)
}

/// Pools of `caps` with `scene` placed at their start (as the tiles already are), and whether its
/// tiles may be culled by their boxes.
fn fresh_pools(scene: &SceneData, caps: PoolCaps) -> Result<(Pools, Placement, bool)> {
    let mut pools = Pools::new(caps)?;
    let (owners, cull_tiles) = scene.surfel_owners();
    let placed = pools.place(scene, &owners)?;
    if placed.tiles != scene.tiles {
        return Err(Error::Internal { what: "pools", message: "fresh pools moved a tile".into() });
    }
    Ok((pools, placed, cull_tiles))
}
