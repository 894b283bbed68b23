//! The renderer: uploads a [`SceneData`], builds the passes once, and per call runs exactly the
//! passes the effect plan marks `run` (counting each dispatch and timing it with GPU timestamps
//! where the adapter has them).
//!
//! Light transport state lives on the GPU between calls: injected direct light, the gathered
//! indirect light and the outgoing radiance of every leaf. Each light update adds one bounce:
//! `out_(k+1) = emission + direct + albedo * gather(out_k)`, so with albedo < 1 the radiance stays
//! bounded and converges to the fixed point.

use std::collections::BTreeMap;
use std::time::Instant;

use glam::{Mat4, Vec3};
use serde::Serialize;

use crate::camera::Camera;
use crate::error::{Error, Result};
use crate::gpu::Gpu;
use crate::gpu_types::{LeafLightGpu, LightGpu, MAX_CONES, Params, SplatUniform, flags, light_shadow};
use crate::passes::{self, gbuffer, shade, shadow};
use crate::plan::{self, EffectPlan, Pass, PlanInputs};
use crate::scene_data::{MAX_ENV_LEVELS, MAX_MATERIALS, SceneData};

/// How indirect light is filtered at a pixel.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Serialize)]
#[serde(rename_all = "snake_case")]
pub enum IndirectFilter {
    Trilinear,
    Tricubic,
    Off,
}

/// The quality knobs of the runtime.
#[derive(Clone, Debug, PartialEq, Serialize)]
pub struct Settings {
    /// Cones per leaf gather, 1..=16.
    pub cones: u32,
    /// Multiplies each cone's half-angle (1 = cones just tile the hemisphere's solid angle).
    pub cone_aperture_scale: f32,
    /// Step along a cone as a fraction of its current diameter.
    pub step_scale: f32,
    /// Longest cone, metres (`None`: the scene diagonal).
    pub max_distance_m: Option<f32>,
    pub max_steps: u32,
    /// Bounce budget: propagation passes before the plan stops them.
    pub bounces: u32,
    /// Propagation stops once a bounce changes no leaf's radiance by more than this (relative).
    pub convergence_tolerance: f32,
    pub shadows: bool,
    pub shadow_map_size: u32,
    pub indirect: IndirectFilter,
    /// Direct light at pixels (off: only indirect and emission, for tests).
    pub direct: bool,
    pub exposure: f32,
    /// Radiance where a pixel or a cone sees nothing (the environment before SH lands), linear RGB.
    pub background: [f32; 3],
    /// Smallest splat radius in pixels (hole filling).
    pub min_splat_px: f32,
    /// Surfel radius multiplier for splatting. The stored radius (1.25 d_k / sqrt(k)) is about
    /// 0.7 point spacings, which tiles a regular grid but leaves holes in scanner sampling
    /// (`grotto render out/demo.grotto --camera chamber --size 640x480 --bounces 0 --no-shadows
    /// --splat-scale S` prints the uncovered pixels: 105 at S = 1.5, 0 at 2.0).
    pub splat_scale: f32,
    /// Store the radiance pyramid (six directional values per node) as f16 instead of f32: half
    /// the memory and bandwidth of the largest buffer; values above 65504 are clamped.
    pub radiance_f16: bool,
    /// Light the scene with its environment map's SH coefficients (when it has one).
    pub environment: bool,
    /// Reflection on specular materials (wet walls, water) where the scene assigns them.
    pub specular: bool,
    /// Shadow-map budget: this many of the brightest point and spot lights get shadow maps and
    /// are shaded per pixel; the others follow `shadow_fallback` (lights.rs).
    pub shadowed_lights: u32,
    /// How lights beyond the shadow-map budget are shadowed.
    pub shadow_fallback: ShadowFallback,
    /// Irradiance, W/m^2, under which a light's contribution is dropped: it bounds each light's
    /// range for culling (0: every light reaches everywhere).
    pub light_cutoff_w_m2: f32,
}

/// What lights beyond the shadow-map budget do (lights.rs).
#[derive(Clone, Copy, Debug, PartialEq, Eq, Serialize)]
#[serde(rename_all = "snake_case")]
pub enum ShadowFallback {
    /// Lit at leaf resolution, visibility from a cone traced through the SVO toward the light.
    Cone,
    /// Lit at leaf resolution, unshadowed (light passes through walls).
    None,
}

impl ShadowFallback {
    pub fn name(self) -> &'static str {
        match self {
            ShadowFallback::Cone => "cone",
            ShadowFallback::None => "none",
        }
    }

    pub fn parse(s: &str) -> Option<Self> {
        [ShadowFallback::Cone, ShadowFallback::None].into_iter().find(|f| f.name() == s)
    }

    /// In words, for the effect plan.
    pub fn describe(self) -> &'static str {
        match self {
            ShadowFallback::Cone => "SVO cone shadows",
            ShadowFallback::None => "no shadows",
        }
    }
}

impl Default for Settings {
    fn default() -> Self {
        Self {
            cones: 6,
            cone_aperture_scale: 1.0,
            step_scale: 0.5,
            max_distance_m: None,
            max_steps: 256,
            bounces: 8,
            convergence_tolerance: 1e-3,
            shadows: true,
            shadow_map_size: 512,
            indirect: IndirectFilter::Trilinear,
            direct: true,
            exposure: 1.0,
            background: [0.0; 3],
            min_splat_px: 0.75,
            splat_scale: 2.0,
            radiance_f16: false,
            environment: true,
            specular: true,
            shadowed_lights: 16,
            shadow_fallback: ShadowFallback::Cone,
            light_cutoff_w_m2: 2e-4,
        }
    }
}

/// Named trade-offs between error and time (`--quality`); their measured error and time on every
/// accuracy scene are in docs/accuracy.md, where the sweep checks each costs more time and has
/// less error than the one below it.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Serialize)]
#[serde(rename_all = "snake_case")]
pub enum Quality {
    Fast,
    Balanced,
    High,
}

impl Quality {
    pub const ALL: [Quality; 3] = [Quality::Fast, Quality::Balanced, Quality::High];

    pub fn name(self) -> &'static str {
        match self {
            Quality::Fast => "fast",
            Quality::Balanced => "balanced",
            Quality::High => "high",
        }
    }

    pub fn parse(s: &str) -> Option<Self> {
        Self::ALL.into_iter().find(|q| q.name() == s)
    }
}

impl Settings {
    /// The knobs of a quality preset (everything else at its default).
    pub fn preset(q: Quality) -> Self {
        let d = Settings::default();
        match q {
            Quality::Fast => Settings { cones: 4, step_scale: 1.0, bounces: 2, shadow_map_size: 256, ..d },
            Quality::Balanced => Settings {
                cones: 9,
                cone_aperture_scale: 0.7,
                step_scale: 0.5,
                bounces: 4,
                shadow_map_size: 512,
                ..d
            },
            Quality::High => Settings {
                cones: 16,
                cone_aperture_scale: 0.7,
                step_scale: 0.35,
                bounces: 8,
                shadow_map_size: 1024,
                indirect: IndirectFilter::Tricubic,
                ..d
            },
        }
    }

    pub fn validate(&self) -> Result<()> {
        if !(1..=MAX_CONES as u32).contains(&self.cones) {
            return Err(Error::Setting {
                name: "cones",
                problem: format!("{} is outside 1..=16", self.cones),
            });
        }
        if !(self.step_scale > 0.05 && self.step_scale <= 4.0) {
            return Err(Error::Setting {
                name: "step_scale",
                problem: format!("{} is outside 0.05..=4", self.step_scale),
            });
        }
        if !(self.cone_aperture_scale > 0.05 && self.cone_aperture_scale <= 4.0) {
            return Err(Error::Setting {
                name: "cone_aperture_scale",
                problem: "must be in 0.05..=4".into(),
            });
        }
        if !(16..=8192).contains(&self.shadow_map_size) {
            return Err(Error::Setting { name: "shadow_map_size", problem: "must be in 16..=8192".into() });
        }
        if !(self.light_cutoff_w_m2.is_finite() && self.light_cutoff_w_m2 >= 0.0) {
            return Err(Error::Setting {
                name: "light_cutoff_w_m2",
                problem: "must be finite and not negative".into(),
            });
        }
        if self.shadowed_lights > MAX_SHADOWED_LIGHTS {
            return Err(Error::Setting {
                name: "shadowed_lights",
                problem: format!(
                    "{} is over {MAX_SHADOWED_LIGHTS} (the atlas would pass 8192^2)",
                    self.shadowed_lights
                ),
            });
        }
        if !(self.exposure.is_finite() && self.exposure > 0.0) {
            return Err(Error::Setting { name: "exposure", problem: "must be finite and positive".into() });
        }
        Ok(())
    }
}

/// Most lights with shadow maps: 6 faces each for point lights in one 2D atlas.
pub const MAX_SHADOWED_LIGHTS: u32 = 256;

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
    node_count: u32,
    surfel_count: u32,
    leaf_size_m: f32,
    scene_diag_m: f32,
    base_params: Params,
    point_lights: usize,
    spot_lights: usize,
    /// The scene's last light is a headlamp added for a lightless scene (the plan says so).
    headlamp: bool,
    /// Lights with shadow maps; the others are lit per leaf (lights.rs).
    shadowed: usize,
    /// Lights per light-grid cell: mean and largest.
    lights_in_range: (f32, u32),
    /// Specular materials with surfels, and those surfels (0 when `Settings::specular` is off).
    specular_materials: usize,
    specular_surfels: usize,
    /// The prefiltered environment levels (shade.wgsl `env_atlas`).
    env_atlas: wgpu::TextureView,
    emissive: bool,
    /// An environment map lights the scene (it has SH coefficients and the setting allows it).
    environment: bool,
    env_valid: bool,
    shadow_layers: Vec<Mat4>,
    lights_gpu: Vec<LightGpu>,
    params: wgpu::Buffer,
    /// Bytes of every buffer and texture created at upload (the G-buffer is added per view).
    static_bytes: u64,
    leaf_light: wgpu::Buffer,
    faces: wgpu::Buffer,
    stats: wgpu::Buffer,
    surfels: wgpu::Buffer,
    splat_uniforms: wgpu::Buffer,
    /// Shadow layers' splat uniforms, then the camera's.
    splat_groups: Vec<wgpu::BindGroup>,
    shadow_distance: wgpu::Texture,
    shadow_face_size: u32,
    shadow_cols: u32,
    shadow_depth: wgpu::TextureView,
    scene_group: wgpu::BindGroup,
    inject: passes::inject::Inject,
    env: passes::LeafPass,
    mip: passes::mip::Mip,
    propagate: passes::LeafPass,
    shadow: shadow::Shadow,
    gbuffer: gbuffer::Gbuffer,
    shade: shade::Shade,
    view: Option<View>,
    direct_valid: bool,
    forced: Vec<Pass>,
    stats_now: PassStats,
    queries: Option<(wgpu::QuerySet, wgpu::Buffer)>,
}

const STORAGE: wgpu::BufferUsages =
    wgpu::BufferUsages::STORAGE.union(wgpu::BufferUsages::COPY_SRC).union(wgpu::BufferUsages::COPY_DST);

impl Renderer {
    pub fn new(gpu: &Gpu, scene: &SceneData, settings: Settings) -> Result<Self> {
        settings.validate()?;
        let faces_bytes = scene.buffer_bytes(settings.radiance_f16).faces;
        let (lo, hi) = scene.bounds_leaf();
        let leaf = scene.leaf_size_m.max(1e-6);
        let scene_diag_m = ((hi - lo) * leaf).length().max(leaf);

        // Lights and their shadow layers.
        let mut lights_gpu = Vec::new();
        let mut shadow_layers = Vec::new();
        // Light position and projection scale (1 / tan(fov / 2)) of each shadow layer.
        let mut shadow_eyes: Vec<(Vec3, f32)> = Vec::new();
        let near = (0.05 * leaf).max(1e-4);
        let far = scene_diag_m * 2.0 + 1.0;
        // Shadow maps for the brightest lights within the budget (lights.rs); the rest are lit at
        // leaf resolution by inject with the fallback's shadows.
        let mut mapped = vec![false; scene.lights.len()];
        if settings.shadows {
            for &k in
                crate::lights::brightest_first(&scene.lights).iter().take(settings.shadowed_lights as usize)
            {
                mapped[k] = true;
            }
        }
        let fallback = match settings.shadow_fallback {
            ShadowFallback::Cone => light_shadow::CONE,
            ShadowFallback::None => light_shadow::NONE,
        };
        // Lights with shadow maps first: every light-grid cell then lists them before the rest,
        // and shade, which evaluates only those per pixel, stops at the first one without.
        let order: Vec<usize> = (0..scene.lights.len())
            .filter(|&k| mapped[k])
            .chain((0..scene.lights.len()).filter(|&k| !mapped[k]))
            .collect();
        for (l, &has_map) in order.iter().map(|&k| (&scene.lights[k], &mapped[k])) {
            let first = if has_map { shadow_layers.len() as f32 } else { -1.0 };
            // Without shadows at all every light is shaded per pixel, unshadowed.
            let how = if has_map || !settings.shadows { light_shadow::MAP } else { fallback };
            let range = crate::lights::range_m(l.intensity_w_sr, settings.light_cutoff_w_m2);
            let p = l.position_m;
            match l.spot {
                None => {
                    if has_map {
                        for (fwd, up) in [
                            (Vec3::X, Vec3::Y),
                            (Vec3::NEG_X, Vec3::Y),
                            (Vec3::Y, Vec3::Z),
                            (Vec3::NEG_Y, Vec3::Z),
                            (Vec3::Z, Vec3::Y),
                            (Vec3::NEG_Z, Vec3::Y),
                        ] {
                            let proj = Mat4::perspective_rh(std::f32::consts::FRAC_PI_2, 1.0, near, far);
                            shadow_layers.push(proj * Mat4::look_at_rh(p, p + fwd, up));
                            shadow_eyes.push((p, 1.0));
                        }
                    }
                    lights_gpu.push(LightGpu {
                        position_kind: p.extend(0.0).to_array(),
                        intensity_layer: l.intensity_w_sr.extend(first).to_array(),
                        direction_cos_outer: [0.0, 0.0, -1.0, -1.0],
                        params: [-1.0, range.min(f32::MAX), how, settings.light_cutoff_w_m2],
                    });
                }
                Some(s) => {
                    let outer = s.outer_angle_rad.clamp(1e-3, 1.48);
                    let inner = s.inner_angle_rad.clamp(0.0, outer);
                    if has_map {
                        let up = if s.direction.cross(Vec3::Z).length() < 1e-3 { Vec3::Y } else { Vec3::Z };
                        let proj = Mat4::perspective_rh(2.0 * outer, 1.0, near, far);
                        shadow_layers.push(proj * Mat4::look_at_rh(p, p + s.direction, up));
                        shadow_eyes.push((p, 1.0 / outer.tan()));
                    }
                    lights_gpu.push(LightGpu {
                        position_kind: p.extend(1.0).to_array(),
                        intensity_layer: l.intensity_w_sr.extend(first).to_array(),
                        direction_cos_outer: s.direction.extend(outer.cos()).to_array(),
                        params: [inner.cos(), range.min(f32::MAX), how, settings.light_cutoff_w_m2],
                    });
                }
            }
        }
        let shadowed = mapped.iter().filter(|&&m| m).count();
        // The light grid over the scene, one leaf of slack on every side.
        let light_grid = crate::lights::LightGrid::build(
            (lo - 1.0) * leaf,
            (hi + 1.0) * leaf,
            &lights_gpu
                .iter()
                .map(|l| (Vec3::from_slice(&l.position_kind[..3]), l.params[1]))
                .collect::<Vec<_>>(),
        );
        let lights_in_range = light_grid.occupancy();
        let point_lights = scene.lights.iter().filter(|l| l.spot.is_none()).count();
        let spot_lights = scene.lights.len() - point_lights;

        // Shadow atlas: faces in a near-square grid; faces shrink if the grid would exceed the
        // adapter's largest 2D texture.
        let layers = shadow_layers.len().max(1) as u32;
        let shadow_cols = (f64::from(layers).sqrt().ceil() as u32).max(1);
        let shadow_rows = layers.div_ceil(shadow_cols);
        let max_dim = gpu.device.limits().max_texture_dimension_2d;
        let face_size = if shadow_layers.is_empty() {
            1
        } else {
            settings.shadow_map_size.min(max_dim / shadow_cols).min(max_dim / shadow_rows).max(1)
        };
        let (cones, tan_half) = cone_set(settings.cones, settings.cone_aperture_scale);
        let mut cone_arr = [[0.0f32; 4]; MAX_CONES];
        cone_arr[..cones.len()].copy_from_slice(&cones);
        let environment_on = scene.environment_sh.is_some() && settings.environment;
        // Specular material slots (slot 0 = diffuse) and the environment's prefiltered levels.
        let mut material_slots = [[0.0f32; 4]; MAX_MATERIALS + 1];
        let (mut specular_materials, mut specular_surfels) = (0, 0);
        for (k, m) in scene.materials.iter().enumerate().take(MAX_MATERIALS) {
            let alpha = m.roughness * m.roughness;
            material_slots[k + 1] = [m.specular, alpha, m.ior, m.roughness];
            if settings.specular && m.surfels > 0 {
                specular_materials += 1;
                specular_surfels += m.surfels;
            }
        }
        let mut env_levels = [[0.0f32; 4]; MAX_ENV_LEVELS];
        let chain = scene.env_chain.as_ref().filter(|_| environment_on);
        let env_level_count = chain.map_or(0, |c| c.levels.len().min(MAX_ENV_LEVELS) as u32);
        let env_atlas_size = chain.map_or((1, 1), |c| (c.width, c.height));
        if let Some(c) = chain {
            for (k, l) in c.levels.iter().take(MAX_ENV_LEVELS).enumerate() {
                env_levels[k] = [l.0 as f32, l.1 as f32, l.2 as f32, l.3];
            }
        }
        let base_params = Params {
            leaf_size_m: leaf,
            tile_count: scene.tiles.len() as u32,
            leaf_count: scene.leaves.len() as u32,
            light_count: lights_gpu.len() as u32,
            cone_count: settings.cones,
            cone_tan_half: tan_half,
            step_scale: settings.step_scale,
            max_distance_m: settings.max_distance_m.unwrap_or(scene_diag_m),
            max_steps: settings.max_steps,
            max_lod: scene.max_lod(),
            shadow_size: face_size,
            flags: 0,
            width: 0,
            height: 0,
            exposure: settings.exposure,
            shadow_bias_m: 1.5 * leaf,
            shadow_cols,
            light_grid_dims: light_grid.dims.to_array(),
            light_grid_min_m: light_grid.min_m.extend(light_grid.cell_m).to_array(),
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
            materials: material_slots,
            env_levels,
            env_chain: [env_level_count, env_atlas_size.0, 0, 0],
        };

        let params = gpu.buffer_init(
            "params",
            bytemuck::bytes_of(&base_params),
            wgpu::BufferUsages::UNIFORM | wgpu::BufferUsages::COPY_DST,
        )?;
        let tiles = gpu.buffer_init("tiles", bytemuck::cast_slice(&scene.tiles), STORAGE)?;
        let nodes = gpu.buffer_init("nodes", bytemuck::cast_slice(&scene.nodes), STORAGE)?;
        let leaves = gpu.buffer_init("leaves", bytemuck::cast_slice(&scene.leaves), STORAGE)?;
        // Initial light state: out = emission (no direct, no gather yet).
        let initial: Vec<LeafLightGpu> =
            scene.leaves.iter().map(|l| LeafLightGpu { out: l.emission, ..Default::default() }).collect();
        let leaf_light = gpu.buffer_init("leaf light", bytemuck::cast_slice(&initial), STORAGE)?;
        let faces = gpu.buffer("faces", faces_bytes, STORAGE)?;
        let lights_buf = gpu.buffer_init("lights", bytemuck::cast_slice(&lights_gpu), STORAGE)?;
        let mats: Vec<[[f32; 4]; 4]> = shadow_layers.iter().map(|m| m.to_cols_array_2d()).collect();
        let shadow_mats = gpu.buffer_init("shadow matrices", bytemuck::cast_slice(&mats), STORAGE)?;
        let stats = gpu.buffer_init("stats", &[0u8; 16], STORAGE)?;
        let surfels =
            gpu.buffer_init("surfels", bytemuck::cast_slice(&scene.surfels), wgpu::BufferUsages::VERTEX)?;

        let atlas_size = wgpu::Extent3d {
            width: face_size * shadow_cols,
            height: face_size * shadow_rows,
            depth_or_array_layers: 1,
        };
        let shadow_distance = gpu.texture_2d(
            "shadow atlas",
            atlas_size.width,
            atlas_size.height,
            shadow::DISTANCE_FORMAT,
            wgpu::TextureUsages::RENDER_ATTACHMENT | wgpu::TextureUsages::TEXTURE_BINDING,
        )?;
        let shadow_depth = gpu
            .texture_2d(
                "shadow depth",
                atlas_size.width,
                atlas_size.height,
                shadow::DEPTH_FORMAT,
                wgpu::TextureUsages::RENDER_ATTACHMENT,
            )?
            .create_view(&Default::default());
        let shadow_view = shadow_distance.create_view(&Default::default());
        let env_atlas_tex = gpu.texture_2d(
            "env atlas",
            env_atlas_size.0,
            env_atlas_size.1,
            wgpu::TextureFormat::Rgba32Float,
            wgpu::TextureUsages::TEXTURE_BINDING | wgpu::TextureUsages::COPY_DST,
        )?;
        let placeholder = [[0.0f32; 4]];
        let atlas_texels: &[[f32; 4]] = chain.map_or(&placeholder[..], |c| &c.rgba);
        gpu.queue.write_texture(
            env_atlas_tex.as_image_copy(),
            bytemuck::cast_slice(atlas_texels),
            wgpu::TexelCopyBufferLayout {
                offset: 0,
                bytes_per_row: Some(env_atlas_size.0 * 16),
                rows_per_image: Some(env_atlas_size.1),
            },
            wgpu::Extent3d { width: env_atlas_size.0, height: env_atlas_size.1, depth_or_array_layers: 1 },
        );
        let env_atlas = env_atlas_tex.create_view(&Default::default());

        let scene_layout = passes::scene_layout(gpu);
        let f16 = settings.radiance_f16;
        let buffers =
            [&params, &tiles, &nodes, &leaves, &leaf_light, &faces, &lights_buf, &shadow_mats, &stats];
        let mut entries: Vec<wgpu::BindGroupEntry<'_>> = buffers
            .iter()
            .enumerate()
            .map(|(i, b)| wgpu::BindGroupEntry { binding: i as u32, resource: b.as_entire_binding() })
            .collect();
        entries.push(wgpu::BindGroupEntry {
            binding: 9,
            resource: wgpu::BindingResource::TextureView(&shadow_view),
        });
        let rock = gpu.buffer_init("rock", bytemuck::cast_slice(&scene.rock.words), STORAGE)?;
        entries.push(wgpu::BindGroupEntry { binding: 10, resource: rock.as_entire_binding() });
        let light_grid_buf =
            gpu.buffer_init("light grid", bytemuck::cast_slice(&light_grid.words), STORAGE)?;
        entries.push(wgpu::BindGroupEntry { binding: 11, resource: light_grid_buf.as_entire_binding() });
        let scene_group = gpu.device.create_bind_group(&wgpu::BindGroupDescriptor {
            label: Some("scene"),
            layout: &scene_layout,
            entries: &entries,
        });

        let atlas_bytes = u64::from(atlas_size.width) * u64::from(atlas_size.height) * 8;
        let static_bytes = [
            &params,
            &tiles,
            &nodes,
            &leaves,
            &leaf_light,
            &faces,
            &lights_buf,
            &shadow_mats,
            &stats,
            &surfels,
            &rock,
            &light_grid_buf,
        ]
        .iter()
        .map(|b| b.size())
        .sum::<u64>()
            + atlas_bytes
            + u64::from(env_atlas_size.0) * u64::from(env_atlas_size.1) * 16;
        let splat_layout = shadow::splat_layout(gpu);
        let splat_uniforms = gpu.buffer(
            "splat uniforms",
            (shadow_layers.len() as u64 + 1) * size_of::<SplatUniform>() as u64,
            wgpu::BufferUsages::UNIFORM | wgpu::BufferUsages::COPY_DST,
        )?;
        // One bind group per uniform slot, each bound at its slot's static offset.
        let splat_groups: Vec<wgpu::BindGroup> = (0..=shadow_layers.len() as u64)
            .map(|slot| {
                gpu.device.create_bind_group(&wgpu::BindGroupDescriptor {
                    label: Some("splat"),
                    layout: &splat_layout,
                    entries: &[wgpu::BindGroupEntry {
                        binding: 0,
                        resource: wgpu::BindingResource::Buffer(wgpu::BufferBinding {
                            buffer: &splat_uniforms,
                            offset: slot * size_of::<SplatUniform>() as u64,
                            size: wgpu::BufferSize::new(size_of::<SplatUniform>() as u64),
                        }),
                    }],
                })
            })
            .collect();
        // Shadow layer uniforms never change for static lights: write them once.
        let settings_splat = settings.splat_scale;
        for (i, (m, (eye, scale))) in shadow_layers.iter().zip(&shadow_eyes).enumerate() {
            let u = SplatUniform {
                view_proj: m.to_cols_array_2d(),
                eye_m: eye.extend(1.0).to_array(),
                viewport: [face_size as f32, face_size as f32, settings.min_splat_px, *scale],
                splat: [settings_splat, 0.0, 0.0, 0.0],
                pad: [[0.0; 4]; 9],
            };
            gpu.queue.write_buffer(
                &splat_uniforms,
                (i * size_of::<SplatUniform>()) as u64,
                bytemuck::bytes_of(&u),
            );
        }

        let (by_height, ranges) = scene.nodes_by_height();
        let queries = gpu.timestamps.then(|| {
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
        });
        let r = Self {
            inject: passes::inject::Inject::new(gpu, &scene_layout, f16, lights_in_range.1)?,
            env: passes::env::new(gpu, &scene_layout, f16),
            mip: passes::mip::Mip::new(gpu, &scene_layout, &by_height, &ranges, f16)?,
            propagate: passes::propagate::new(gpu, &scene_layout, f16),
            shadow: shadow::Shadow::new(gpu, &splat_layout),
            gbuffer: gbuffer::Gbuffer::new(gpu, &splat_layout),
            shade: shade::Shade::new(gpu, &scene_layout, f16),
            gpu: gpu.clone(),
            settings,
            leaf_count: scene.leaves.len() as u32,
            node_count: scene.nodes.len() as u32,
            surfel_count: scene.surfels.len() as u32,
            leaf_size_m: leaf,
            scene_diag_m,
            base_params,
            point_lights,
            spot_lights,
            headlamp: scene.headlamp,
            shadowed,
            lights_in_range,
            specular_materials,
            specular_surfels,
            env_atlas,
            emissive: scene.has_emission(),
            environment: environment_on,
            env_valid: false,
            shadow_layers,
            lights_gpu,
            params,
            static_bytes,
            leaf_light,
            faces,
            stats,
            surfels,
            splat_uniforms,
            splat_groups,
            shadow_distance,
            shadow_face_size: face_size,
            shadow_cols,
            shadow_depth,
            scene_group,
            view: None,
            direct_valid: false,
            forced: Vec::new(),
            stats_now: PassStats::default(),
            queries,
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
            px * 4 * 4 + v.outputs.hdr.size() + v.outputs.ldr.size()
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

    /// Marks the lights changed: the next update re-renders shadow maps and re-injects.
    pub fn invalidate_lights(&mut self) {
        self.direct_valid = false;
        self.stats_now.last_change = None;
    }

    fn inputs(&self, frame: Option<(&Camera, u32, u32)>) -> PlanInputs {
        let gbuffer_valid = match (frame, &self.view) {
            (Some((c, w, h)), Some(v)) => v.camera == *c && v.targets.width == w && v.targets.height == h,
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
            frame: frame.is_some(),
            gbuffer_valid,
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
        let p = self.plan(None);
        self.execute(&p, None)?;
        Ok(p)
    }

    /// Runs light updates until the plan stops propagating (converged or budget spent); returns
    /// the number of bounces run.
    pub fn settle(&mut self, mut progress: impl FnMut(u32, Option<f32>)) -> Result<u32> {
        let start = self.stats_now.bounces_done;
        loop {
            let p = self.update_light()?;
            progress(self.stats_now.bounces_done, self.stats_now.last_change);
            if !p.runs(Pass::Propagate) {
                return Ok(self.stats_now.bounces_done - start);
            }
        }
    }

    /// Renders one frame (running whatever light work the plan asks for first: progressive, at
    /// most one bounce per frame).
    pub fn render(&mut self, camera: &Camera, width: u32, height: u32) -> Result<(Frame, EffectPlan)> {
        camera.validate()?;
        if width == 0 || height == 0 || width > 16384 || height > 16384 {
            return Err(Error::Setting {
                name: "size",
                problem: format!("{width}x{height} is outside 1..=16384"),
            });
        }
        let p = self.plan(Some((camera, width, height)));
        self.execute(&p, Some((camera, width, height)))?;
        let view = self.view.as_ref().ok_or(Error::Gpu { pass: "shade", message: "no view".into() })?;
        let pixels = u64::from(width) * u64::from(height);
        let hdr_bytes = self.gpu.read_buffer(&view.outputs.hdr, pixels * 16)?;
        let ldr_bytes = self.gpu.read_buffer(&view.outputs.ldr, pixels * 4)?;
        let hdr: Vec<[f32; 4]> = bytemuck::pod_collect_to_vec(&hdr_bytes[..(pixels * 16) as usize]);
        let ldr: Vec<[u8; 4]> = bytemuck::pod_collect_to_vec(&ldr_bytes[..(pixels * 4) as usize]);
        Ok((Frame { width, height, hdr, ldr }, p))
    }

    fn frame_params(&self, frame: Option<(&Camera, u32, u32)>) -> Params {
        let mut p = self.base_params;
        let s = &self.settings;
        let mut f = flags::EMISSION;
        if s.direct && !self.lights_gpu.is_empty() {
            f |= flags::DIRECT;
        }
        if s.direct && s.shadows && self.shadowed < self.lights_gpu.len() {
            f |= flags::FAR_LIGHTS;
        }
        if s.shadows && !self.shadow_layers.is_empty() {
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

    fn execute(&mut self, plan: &EffectPlan, frame: Option<(&Camera, u32, u32)>) -> Result<()> {
        let params = self.frame_params(frame);
        self.gpu.queue.write_buffer(&self.params, 0, bytemuck::bytes_of(&params));
        if let Some((camera, w, h)) = frame
            && plan.runs(Pass::Gbuffer)
        {
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
                splat: [self.settings.splat_scale, 0.0, 0.0, 0.0],
                pad: [[0.0; 4]; 9],
            };
            let slot = self.shadow_layers.len() as u64 * size_of::<SplatUniform>() as u64;
            self.gpu.queue.write_buffer(&self.splat_uniforms, slot, bytemuck::bytes_of(&u));
            let reuse = self.view.as_ref().is_some_and(|v| v.targets.width == w && v.targets.height == h);
            if !reuse {
                // The largest per-view buffer first, before any target is allocated.
                let pixels = u64::from(w) * u64::from(h);
                self.gpu.check_buffer("shade hdr", pixels * 16, wgpu::BufferUsages::STORAGE)?;
                let targets = gbuffer::Targets::new(&self.gpu, w, h)?;
                let outputs = self.shade.outputs(&self.gpu, &targets, &self.env_atlas)?;
                self.view = Some(View { camera: *camera, targets, outputs });
            } else if let Some(v) = self.view.as_mut() {
                v.camera = *camera;
            }
        }
        let mut enc =
            self.gpu.device.create_command_encoder(&wgpu::CommandEncoderDescriptor { label: Some("frame") });
        let mut ran: Vec<Pass> = Vec::new();
        if plan.runs(Pass::Propagate) {
            enc.clear_buffer(&self.stats, 0, None);
        }
        for step in plan.steps.iter().filter(|s| s.run) {
            let recorded = Instant::now();
            let ts = self.timestamp_pair(step.pass);
            match step.pass {
                Pass::Shadow => {
                    let tw = ts.map(|(set, i)| wgpu::RenderPassTimestampWrites {
                        query_set: set,
                        beginning_of_pass_write_index: Some(i),
                        end_of_pass_write_index: Some(i + 1),
                    });
                    let layers = self.shadow_layers.len();
                    self.shadow.record(
                        &mut enc,
                        &self.shadow_distance,
                        &self.shadow_depth,
                        self.shadow_face_size,
                        self.shadow_cols,
                        &self.splat_groups[..layers],
                        &self.surfels,
                        self.surfel_count,
                        tw,
                    );
                }
                Pass::Gbuffer => {
                    let v = self
                        .view
                        .as_ref()
                        .ok_or(Error::Gpu { pass: "gbuffer", message: "no view".into() })?;
                    let tw = ts.map(|(set, i)| wgpu::RenderPassTimestampWrites {
                        query_set: set,
                        beginning_of_pass_write_index: Some(i),
                        end_of_pass_write_index: Some(i + 1),
                    });
                    self.gbuffer.record(
                        &mut enc,
                        &v.targets,
                        &self.splat_groups[self.shadow_layers.len()],
                        &self.surfels,
                        self.surfel_count,
                        tw,
                    );
                }
                compute => {
                    let tw = ts.map(|(set, i)| wgpu::ComputePassTimestampWrites {
                        query_set: set,
                        beginning_of_pass_write_index: Some(i),
                        end_of_pass_write_index: Some(i + 1),
                    });
                    let mut pass = enc.begin_compute_pass(&wgpu::ComputePassDescriptor {
                        label: Some(compute.name()),
                        timestamp_writes: tw,
                    });
                    match compute {
                        Pass::Inject => self.inject.record(&mut pass, &self.scene_group, self.leaf_count),
                        Pass::Env => self.env.record(&mut pass, &self.scene_group, self.leaf_count),
                        Pass::Mip => self.mip.record(&mut pass, &self.scene_group),
                        Pass::Propagate => {
                            self.propagate.record(&mut pass, &self.scene_group, self.leaf_count)
                        }
                        Pass::Shade => {
                            let v = self
                                .view
                                .as_ref()
                                .ok_or(Error::Gpu { pass: "shade", message: "no view".into() })?;
                            self.shade.record(
                                &mut pass,
                                &self.scene_group,
                                &v.outputs,
                                v.targets.width,
                                v.targets.height,
                            );
                        }
                        Pass::Shadow | Pass::Gbuffer => {}
                    }
                }
            }
            *self.stats_now.dispatches.entry(step.pass).or_default() += 1;
            ran.push(step.pass);
            if self.queries.is_none() {
                // No timestamp queries: time each pass on the CPU, recording to completion of its
                // own blocking submit.
                let done = std::mem::replace(
                    &mut enc,
                    self.gpu
                        .device
                        .create_command_encoder(&wgpu::CommandEncoderDescriptor { label: Some("frame") }),
                );
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
        self.gpu.wait()?;
        self.gpu.check("frame")?;
        if let Some((_, buf)) = &self.queries {
            if !ran.is_empty() {
                let bytes = self.gpu.read_buffer(buf, 16 * Pass::ALL.len() as u64)?;
                let ticks: Vec<u64> = bytemuck::pod_collect_to_vec(&bytes);
                let period = f64::from(self.gpu.queue.get_timestamp_period());
                for pass in &ran {
                    let i = Pass::ALL.iter().position(|p| p == pass).unwrap_or(0);
                    let dt = ticks[2 * i + 1].saturating_sub(ticks[2 * i]) as f64 * period / 1e6;
                    self.stats_now.last_ms.insert(*pass, dt);
                }
            }
        }
        if ran.contains(&Pass::Inject) || (self.point_lights + self.spot_lights == 0) {
            self.direct_valid = true;
        }
        if ran.contains(&Pass::Env) {
            self.env_valid = true;
        }
        if ran.contains(&Pass::Propagate) {
            let bytes = self.gpu.read_buffer(&self.stats, 16)?;
            let bits = u32::from_le_bytes([bytes[0], bytes[1], bytes[2], bytes[3]]);
            self.stats_now.last_change = Some(f32::from_bits(bits));
            self.stats_now.bounces_done += 1;
        }
        Ok(())
    }

    /// Each leaf's light state (direct, gather, out), for tests and the reference comparison.
    pub fn read_leaf_light(&self) -> Result<Vec<LeafLightGpu>> {
        let size = size_of::<LeafLightGpu>();
        let bytes = self.gpu.read_buffer(&self.leaf_light, u64::from(self.leaf_count) * size as u64)?;
        Ok(bytemuck::pod_collect_to_vec(&bytes[..self.leaf_count as usize * size]))
    }

    /// Overwrites each leaf's light state (tests: a known radiance field before a mip or gather).
    pub fn write_leaf_light(&mut self, state: &[LeafLightGpu]) -> Result<()> {
        if state.len() != self.leaf_count as usize {
            return Err(Error::Setting {
                name: "leaf light",
                problem: "length differs from the leaf count".into(),
            });
        }
        self.gpu.queue.write_buffer(&self.leaf_light, 0, bytemuck::cast_slice(state));
        self.stats_now.last_change = None;
        Ok(())
    }

    /// The six anisotropic values of every node (after a mip pass).
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

    /// Runs only the mip pass (tests).
    pub fn run_mip(&mut self) -> Result<()> {
        let p =
            EffectPlan { steps: vec![plan::Step { pass: Pass::Mip, run: true, reason: "requested".into() }] };
        self.execute(&p, None)
    }

    /// Runs only mip + propagate, i.e. one bounce regardless of the plan (tests).
    pub fn run_bounce(&mut self) -> Result<()> {
        let p = EffectPlan {
            steps: vec![
                plan::Step { pass: Pass::Mip, run: true, reason: "requested".into() },
                plan::Step { pass: Pass::Propagate, run: true, reason: "requested".into() },
            ],
        };
        self.execute(&p, None)
    }
}
