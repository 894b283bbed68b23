//! The runtime's quality knobs ([`Settings`]), their named presets ([`Quality`]) and their
//! validation.

use serde::Serialize;

use crate::error::{Error, Result};
use crate::gpu::types::MAX_CONES;

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
    /// Most samples along one cone at step 0.5 or coarser; a finer step allows proportionally
    /// more (`Settings::march_steps`), so that a finer march reaches as far instead of stopping
    /// short.
    pub max_steps: u32,
    /// Bounce budget: propagation passes before the plan stops them.
    pub bounces: u32,
    /// Propagation stops once a bounce changes no leaf's radiance by more than this (relative).
    pub convergence_tolerance: f32,
    /// Estimate the bounces not run: from the second bounce on, each leaf keeps beside its gather
    /// the rest of a geometric series whose ratio is that of its last two bounces' changes (per
    /// channel, trusted up to the scene's largest albedo), and shade adds it, so bright closed
    /// rock converges in a few bounces instead of dozens (passes/propagate.wgsl).
    pub bounce_tail: bool,
    /// Turn each leaf's cone set about its normal by one of eight angles by the parity of its
    /// cell (interleaved sampling, shaders/ndf.wgsl `cone_interleave_rad`), so neighbouring
    /// leaves miss different directions and filtering averages the misses instead of one fixed
    /// set missing the same corridor on a whole wall. Off: every leaf uses the same set.
    pub cone_interleave: bool,
    /// Gather cones see each leaf of the two finest levels as the half-space behind its surface
    /// (the plane through its surfels' centroid across its mean normal) instead of a whole cube,
    /// so they stop where the surface is rather than up to a voxel before it, as they did in
    /// concave corners (docs/reference.md "Where the light goes wrong"). Off by
    /// default: it helps scans whose leaves sit on their surfels and hurts the hand-built
    /// scenes (docs/accuracy.md, knob "cone planes").
    pub cone_planes: bool,
    /// Gather cones are followed as seven rays spread evenly over each cone, each ending where it
    /// enters rock or goes behind a leaf's surface and bringing the radiance there; the cone is
    /// covered by the share of its rays that ended. The composited march counts a surface a
    /// cone runs along at every step (the closed rooms' excess); the balanced and high presets
    /// use rays at aperture 1, where the seven rays spread over the cone's whole share of the
    /// hemisphere (docs/accuracy.md, knob "composited march").
    pub cone_rays: bool,
    pub shadows: bool,
    pub shadow_map_size: u32,
    /// Milliseconds a frame may spend on shadow maps out of date (after a change of tiles or
    /// lights), at the pass's measured surfels per millisecond; the other faces follow over the
    /// next frames, shown together when the last is drawn (render/shadow_queue.rs). 0: every
    /// face at once (images and batch work); the viewers set it (`--shadow-ms`).
    pub shadow_frame_ms: f32,
    /// Shadow-atlas faces kept free, beyond the spare cells of its grid, for lights a designer
    /// adds in place (`Renderer::edit_lights`; 6: one point light). 0 for images and batch work,
    /// which never edit; the viewers set 6. An added light that does not fit makes a new
    /// renderer (with every light's faces drawn again).
    pub light_room_faces: u32,
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
    /// are shaded per pixel; the others follow `shadow_fallback` (light/setup.rs).
    pub shadowed_lights: u32,
    /// How lights beyond the shadow-map budget are shadowed.
    pub shadow_fallback: ShadowFallback,
    /// Irradiance, W/m^2, under which a light's contribution is dropped: it bounds each light's
    /// range for culling (0: every light reaches everywhere).
    pub light_cutoff_w_m2: f32,
    /// Draw only the surfel chunks a shadow face or the camera may see (render/chunks.rs); off,
    /// whole tiles by their boxes (the same image, more work: for measuring
    /// the difference, `--cull tiles`).
    pub cull_chunks: bool,
    /// Thin far surfel chunks to every k-th surfel, grown to close the surface, where their discs
    /// are under the pixel floor (`min_splat_px`) anyway (render/chunks.rs `Lod`): distant walls
    /// cost in proportion to their pixels, not their points. Off: every surfel drawn
    /// (`--no-splat-lod`). Only where surfels are pulled (passes/splat.rs).
    pub splat_lod: bool,
    /// Blend every disc of the front surface at a pixel (normal and albedo, weighted smoothly to
    /// each disc's rim; shaded at the front disc's point), not the front-most disc alone, whose own normal and light
    /// break a wall seen at a grazing angle into scales (passes/gbuffer.rs). Where the adapter
    /// cannot blend f16 targets (GL), the front-most disc is shown either way.
    pub splat_blend: bool,
    /// Samples a pixel a still frame gathers (anti-aliasing at rest, passes/resolve.rs): while
    /// camera, light and settings stay unchanged, each `Renderer::draw_still` adds one sample
    /// jittered within the pixel and shows the mean. 1: no anti-aliasing. `grotto render
    /// --samples`, `grotto view --still-samples`.
    pub still_samples: u32,
    /// What the image shows (`--view`): the lit scene, or one of the views survey users judge
    /// their data with. Views that show no light skip the light passes (plan.rs).
    pub view: ViewMode,
}

/// What a rendered image shows.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq, Serialize)]
#[serde(rename_all = "snake_case")]
pub enum ViewMode {
    /// The scene lit (direct, indirect, environment, specular), tonemapped.
    #[default]
    Lit,
    /// Each surfel's albedo, sRGB, no light.
    Albedo,
    /// Each surfel's normal as colour (`0.5 + 0.5 n`, world axes), no light.
    Normals,
    /// The light alone: the lit scene with every albedo 1 (grey walls), tonemapped.
    Light,
    /// Illuminance on the surfaces in lux as false colours (view/lux.rs, a legend with it): a
    /// lighting designer's glare and darkness at a glance. The HDR image holds the lux.
    Lux,
    /// The level each tile is held at (full green, coarse yellow, far red; magenta where no tile
    /// holds the point), shaded by the angle to the eye: to see what residency chose.
    Level,
    /// Each surfel's source scan as a colour ([`scan_color`]; grey where a splat stands for
    /// several, as coarse levels do), shaded by the angle to the eye: where two scans' walls do
    /// not coincide, the nearer one shows through in stripes and patches (misregistration).
    Scan,
}

/// The colour of scan `index` in the scan view, linear RGB: hues a golden angle apart, so
/// neighbouring indices differ most and any count of scans gets distinct colours. The same
/// formula runs in `color.wgsl` (`scan_color`); the scan view's test checks they agree.
pub fn scan_color(index: u32) -> [f32; 3] {
    if index == crate::gpu::types::NO_SCAN {
        return [0.5; 3];
    }
    let h = (index as f32 * 0.618_034).fract() * 6.0;
    let (s, v) = (0.7_f32, 0.95_f32);
    let hsv = |k: f32| {
        let k = (k + h) % 6.0;
        v - v * s * (k.min(4.0 - k)).clamp(0.0, 1.0)
    };
    [hsv(5.0), hsv(3.0), hsv(1.0)]
}

/// A box that cuts the view (`--clip`, the viewer's section tool), frame metres: surfels outside
/// it are not drawn, so a passage shows from above with its ceiling cut away, and residency gives
/// the point budget to the tiles inside it. It cuts what is seen, not the light: the rock outside
/// still casts shadows and bounces light, so the passage is lit as it is in the whole cave.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct ClipBox {
    pub min_m: glam::Vec3,
    pub max_m: glam::Vec3,
}

impl ClipBox {
    /// Whether the box `lo..hi` has a point inside the clip box.
    pub(crate) fn meets(&self, lo: glam::Vec3, hi: glam::Vec3) -> bool {
        lo.cmple(self.max_m).all() && hi.cmpge(self.min_m).all()
    }
}

impl ViewMode {
    /// Every view mode, in the panel's order.
    pub const ALL: [ViewMode; 7] = [
        ViewMode::Lit,
        ViewMode::Albedo,
        ViewMode::Normals,
        ViewMode::Light,
        ViewMode::Level,
        ViewMode::Scan,
        ViewMode::Lux,
    ];

    /// The mode's name, as `--view` takes it.
    pub fn name(self) -> &'static str {
        match self {
            ViewMode::Lit => "lit",
            ViewMode::Albedo => "albedo",
            ViewMode::Normals => "normals",
            ViewMode::Light => "light",
            ViewMode::Lux => "lux",
            ViewMode::Level => "level",
            ViewMode::Scan => "scan",
        }
    }

    /// The mode `--view` names, if it names one.
    pub fn parse(s: &str) -> Option<Self> {
        Self::ALL.into_iter().find(|v| v.name() == s)
    }

    /// The image shows no light: the light passes have nothing to do for it.
    pub fn shows_light(self) -> bool {
        matches!(self, ViewMode::Lit | ViewMode::Light | ViewMode::Lux)
    }

    /// The image is exposed and tonemapped (the lux view shows lux on a fixed scale instead).
    pub fn exposed(self) -> bool {
        matches!(self, ViewMode::Lit | ViewMode::Light)
    }
}

/// What lights beyond the shadow-map budget do (light/setup.rs).
#[derive(Clone, Copy, Debug, PartialEq, Eq, Serialize)]
#[serde(rename_all = "snake_case")]
pub enum ShadowFallback {
    /// Lit at leaf resolution, visibility from a cone traced through the SVO toward the light.
    Cone,
    /// Lit at leaf resolution, unshadowed (light passes through walls).
    None,
}

impl ShadowFallback {
    /// The filter's name, as `--indirect-filter` takes it.
    pub fn name(self) -> &'static str {
        match self {
            ShadowFallback::Cone => "cone",
            ShadowFallback::None => "none",
        }
    }

    /// The filter `--indirect-filter` names, if it names one.
    pub fn parse(s: &str) -> Option<Self> {
        [ShadowFallback::Cone, ShadowFallback::None].into_iter().find(|f| f.name() == s)
    }

    /// In words, for the effect plan.
    pub(crate) fn describe(self) -> &'static str {
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
            bounce_tail: true,
            cone_interleave: true,
            cone_planes: false,
            cone_rays: false,
            shadows: true,
            shadow_map_size: 512,
            shadow_frame_ms: 0.0,
            light_room_faces: 0,
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
            cull_chunks: true,
            splat_lod: true,
            splat_blend: true,
            still_samples: crate::passes::resolve::DEFAULT_STILL_SAMPLES,
            view: ViewMode::Lit,
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
    /// The presets, fastest first.
    pub const ALL: [Quality; 3] = [Quality::Fast, Quality::Balanced, Quality::High];

    /// The preset's name, as `--quality` takes it.
    pub fn name(self) -> &'static str {
        match self {
            Quality::Fast => "fast",
            Quality::Balanced => "balanced",
            Quality::High => "high",
        }
    }

    /// The preset `--quality` names, if it names one.
    pub fn parse(s: &str) -> Option<Self> {
        Self::ALL.into_iter().find(|q| q.name() == s)
    }
}

impl Settings {
    /// The bound on samples per cone the march runs with: `max_steps`, scaled by 0.5 / step for
    /// steps finer than 0.5.
    pub(crate) fn march_steps(&self) -> u32 {
        let scaled = f64::from(self.max_steps) * (0.5 / f64::from(self.step_scale.max(1e-3))).max(1.0);
        scaled.ceil().clamp(1.0, 1e6) as u32
    }

    /// The knobs of a quality preset (everything else at its default).
    pub fn preset(q: Quality) -> Self {
        let d = Settings::default();
        match q {
            Quality::Fast => Settings { cones: 4, step_scale: 1.0, bounces: 2, shadow_map_size: 256, ..d },
            // 8 interleaved cones: 10 were 0.0025 better on the demo cave, 20-30% slower, and put
            // the colour box at the edge of its time budget (docs/runtime.md).
            // Rays at aperture 1: on the scanned rooms the composited march counted a wall a cone
            // runs along at every step (colour box 0.091 -> 0.032, dogleg 0.068 -> 0.048,
            // passage 0.065 -> 0.022; docs/reference.md "Judged on scans"), for light time
            // within 15% of the march's. Fast keeps the march: with two bounces its excess is
            // smaller, and it stays the cheapest.
            Quality::Balanced => Settings {
                cones: 8,
                cone_aperture_scale: 1.0,
                cone_rays: true,
                step_scale: 0.5,
                bounces: 3,
                shadow_map_size: 512,
                ..d
            },
            // Balanced's rays with more bounces and a finer shadow map. 8 cones, not 16: with
            // rays, 12 and 16 cones erred more on the scanned dogleg (0.0462 and 0.0435 against
            // 0.0404) and the passage (0.0348, 0.0326 against 0.0313) than 8 did, at up to twice
            // the time (docs/reference.md "Judged on scans").
            Quality::High => Settings {
                cones: 8,
                cone_aperture_scale: 1.0,
                cone_rays: true,
                step_scale: 0.5,
                bounces: 8,
                shadow_map_size: 1024,
                ..d
            },
        }
    }

    /// These settings with preset `q`'s knobs where presets differ (the march, bounces, shadow
    /// map size, indirect filter); the rest as they are (a viewer switching presets).
    pub fn with_preset(&self, q: Quality) -> Self {
        let p = Settings::preset(q);
        Settings {
            cones: p.cones,
            cone_aperture_scale: p.cone_aperture_scale,
            step_scale: p.step_scale,
            max_steps: p.max_steps,
            cone_rays: p.cone_rays,
            cone_planes: p.cone_planes,
            bounces: p.bounces,
            shadow_map_size: p.shadow_map_size,
            indirect: p.indirect,
            ..self.clone()
        }
    }

    /// An error naming the first setting out of its range.
    pub fn validate(&self) -> Result<()> {
        let most = crate::passes::resolve::MAX_STILL_SAMPLES;
        if !(1..=most).contains(&self.still_samples) {
            return Err(Error::Setting {
                name: "still_samples",
                problem: format!("{} is outside 1..={most} (1: no anti-aliasing)", self.still_samples),
            });
        }
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
        if !(self.shadow_frame_ms.is_finite() && (0.0..=10_000.0).contains(&self.shadow_frame_ms)) {
            return Err(Error::Setting {
                name: "shadow_frame_ms",
                problem: format!("{} is outside 0..=10000 (0: every face at once)", self.shadow_frame_ms),
            });
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
pub(crate) const MAX_SHADOWED_LIGHTS: u32 = 256;
