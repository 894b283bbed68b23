//! The path tracer: the package's surfels as discs in a BVH, next-event estimation toward the
//! runtime's point and spot lights, cosine-sampled bounces with Russian roulette.

use std::f32::consts::PI;

use bvh::aabb::{Aabb, Bounded, IntersectsAabb};
use bvh::bounding_hierarchy::BHShape;
use bvh::bvh::Bvh;
use glam::{IVec3, Vec3};
use grotto_format::color::srgb8_to_linear;
use grotto_runtime::passes::cpu_ref::CpuScene;
use grotto_runtime::scene::data::{SceneData, SceneLight};
use grotto_runtime::view::camera::Camera;
use nalgebra::Point3;
use rand::rngs::SmallRng;
use rand::{Rng, SeedableRng};
use rayon::prelude::*;

/// One surfel as the reference sees it.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Disc {
    pub(crate) center_m: Vec3,
    pub normal: Vec3,
    pub(crate) radius_m: f32,
    /// Linear albedo.
    pub(crate) albedo: Vec3,
    /// Emitted radiance, W / (sr m^2).
    pub(crate) emission: Vec3,
    /// The box a hit must lie in (`SurfelScene::clip_discs_to_cells`); unbounded by default.
    clip_m: [Vec3; 2],
    node_index: usize,
}

impl Disc {
    /// A disc at `center_m` facing `normal`, of `radius_m`, with its albedo and emitted radiance.
    pub fn new(center_m: Vec3, normal: Vec3, radius_m: f32, albedo: Vec3, emission: Vec3) -> Self {
        let clip_m = [Vec3::NEG_INFINITY, Vec3::INFINITY];
        Self {
            center_m,
            normal: normal.normalize_or(Vec3::Z),
            radius_m,
            albedo,
            emission,
            clip_m,
            node_index: 0,
        }
    }

    /// The disc's centre, metres.
    pub fn center_m(&self) -> Vec3 {
        self.center_m
    }

    /// The disc's radius as traced (the surfel's times the splat scale), metres.
    pub fn radius_m(&self) -> f32 {
        self.radius_m
    }

    /// Ray parameter of the hit, if the ray meets the disc within (t_min, t_max).
    pub fn hit(&self, o: Vec3, d: Vec3, t_min: f32, t_max: f32) -> Option<f32> {
        let denom = self.normal.dot(d);
        if denom.abs() < 1e-8 {
            return None;
        }
        let t = self.normal.dot(self.center_m - o) / denom;
        if !(t > t_min && t < t_max) {
            return None;
        }
        let p = o + d * t;
        let inside = p.cmpge(self.clip_m[0]).all() && p.cmple(self.clip_m[1]).all();
        ((p - self.center_m).length_squared() <= self.radius_m * self.radius_m && inside).then_some(t)
    }
}

impl Bounded<f32, 3> for Disc {
    fn aabb(&self) -> Aabb<f32, 3> {
        // Exact box of a disc: extent along each axis is r * sqrt(1 - n_axis^2).
        let e = (Vec3::ONE - self.normal * self.normal).max(Vec3::ZERO).powf(0.5) * self.radius_m;
        let lo = self.center_m - e;
        let hi = self.center_m + e;
        Aabb::with_bounds(Point3::new(lo.x, lo.y, lo.z), Point3::new(hi.x, hi.y, hi.z))
    }
}

impl BHShape<f32, 3> for Disc {
    fn set_bh_node_index(&mut self, i: usize) {
        self.node_index = i;
    }
    fn bh_node_index(&self) -> usize {
        self.node_index
    }
}

/// A ray segment as a BVH query: slab test against [t_min, t_max].
struct Segment {
    o: Vec3,
    inv_d: Vec3,
    t_min: f32,
    t_max: f32,
}

impl IntersectsAabb<f32, 3> for Segment {
    fn intersects_aabb(&self, aabb: &Aabb<f32, 3>) -> bool {
        let lo = Vec3::new(aabb.min.x, aabb.min.y, aabb.min.z);
        let hi = Vec3::new(aabb.max.x, aabb.max.y, aabb.max.z);
        let a = (lo - self.o) * self.inv_d;
        let b = (hi - self.o) * self.inv_d;
        let t0 = a.min(b).max_element().max(self.t_min);
        let t1 = a.max(b).min_element().min(self.t_max);
        t0 <= t1
    }
}

/// How paths are traced.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct PathSettings {
    /// Bounces before Russian roulette starts.
    pub min_bounces: u32,
    /// Hard cap (a path this long has throughput below any displayable level at albedo <= 0.99).
    pub max_bounces: u32,
    /// Radiance of rays that leave the scene (the runtime's background).
    pub background: Vec3,
    /// Environment radiance as 9 SH coefficients (the package's env-sh9 times its intensity):
    /// rays that leave the scene add its radiance in their direction, clamped at 0.
    pub env_sh: Option<[[f32; 3]; 9]>,
}

impl PathSettings {
    /// The defaults with the scene's environment.
    pub fn for_scene(scene: &SceneData) -> Self {
        Self { env_sh: scene.environment_sh, ..Self::default() }
    }

    /// Radiance arriving from outside the scene along unit `d`.
    pub(crate) fn sky(&self, d: Vec3) -> Vec3 {
        let Some(sh) = &self.env_sh else { return self.background };
        let y = grotto_preprocess::env::sh_basis(d.as_dvec3().to_array());
        let mut l = [0.0f64; 3];
        for (c, yi) in sh.iter().zip(y) {
            for k in 0..3 {
                l[k] += f64::from(c[k]) * yi;
            }
        }
        self.background + Vec3::new(l[0].max(0.0) as f32, l[1].max(0.0) as f32, l[2].max(0.0) as f32)
    }
}

impl Default for PathSettings {
    fn default() -> Self {
        Self { min_bounces: 3, max_bounces: 4096, background: Vec3::ZERO, env_sh: None }
    }
}

/// The scene for path tracing.
#[derive(Debug)]
pub struct SurfelScene {
    discs: Vec<Disc>,
    bvh: Bvh<f32, 3>,
    lights: Vec<SceneLight>,
    /// Shortest first segment for closest-hit queries, metres.
    step_m: f32,
    /// Diagonal of the discs' bounds: no segment grows past it.
    extent_m: f32,
    /// Offset of secondary rays from the surface, metres.
    epsilon_m: f32,
    /// Offset of shadow rays along the normal: a quarter of the feature size (the leaf), as the
    /// runtime's shade pass offsets its shadow lookups. The discs are enlarged to close gaps
    /// between samples, so on a curved surface a ray leaving one disc at a grazing angle would
    /// otherwise hit its overlapping neighbour (with `shadow_offset_m = epsilon_m`, `accuracy
    /// --scene bunny` shows the runtime's direct light 10% brighter than the reference's).
    shadow_offset_m: f32,
    /// Offset of bounce rays along the normal: a hair (`epsilon_m`). Checked against Mitsuba 3
    /// on the same discs (docs/reference-mitsuba.md, `grotto-reference mitsuba`, which renders
    /// both): a quarter leaf here too makes the dogleg's reference brighter than Mitsuba's by
    /// several percent.
    bounce_offset_m: f32,
    /// The runtime's rock (runtime/src/rock.rs): tiles and rock bits only. A ray that would leave
    /// the scene through a gap between scanned discs but crosses rock on the way is absorbed, as
    /// rock there would absorb it; the runtime's cones stop there too. None for bare disc sets.
    rock: Option<SceneData>,
}

/// A mean with its standard error (Pod: the accuracy sweep's reference cache stores images as
/// their bytes).
#[derive(Clone, Copy, Debug, PartialEq, bytemuck::Pod, bytemuck::Zeroable)]
#[repr(C)]
pub struct Estimate {
    pub mean: Vec3,
    pub std_err: Vec3,
}

/// The leaf cell a surfel belongs to: a quarter leaf behind its surface, so a surfel lying exactly
/// on a cell face (hand-built scenes) finds the solid side's leaf.
fn surface_cell(center_m: Vec3, normal: Vec3, leaf_m: f32) -> IVec3 {
    ((center_m - normal.normalize_or_zero() * (0.25 * leaf_m)) / leaf_m).floor().as_ivec3()
}

impl Estimate {
    /// Sample mean and its standard error (sample variance / n, square-rooted).
    fn of(samples: impl Iterator<Item = Vec3>) -> Self {
        let (mut sum, mut sum2, mut n) = (Vec3::ZERO, Vec3::ZERO, 0u32);
        for v in samples {
            sum += v;
            sum2 += v * v;
            n += 1;
        }
        let k = n.max(1) as f32;
        let mean = sum / k;
        let var = (sum2 / k - mean * mean).max(Vec3::ZERO) / (k - 1.0).max(1.0);
        Estimate { mean, std_err: var.powf(0.5) }
    }
}

/// Cosine-distributed direction around unit `n`.
pub fn cosine_sample(n: Vec3, u1: f32, u2: f32) -> Vec3 {
    let r = u1.sqrt();
    let phi = 2.0 * PI * u2;
    let (t1, t2) = n.any_orthonormal_pair();
    (t1 * (r * phi.cos()) + t2 * (r * phi.sin()) + n * (1.0 - u1).max(0.0).sqrt()).normalize()
}

impl SurfelScene {
    /// The runtime's scene: surfels (radius times `splat_scale`, as the G-buffer draws them),
    /// colours, leaf emission, point and spot lights.
    pub fn from_scene(scene: &SceneData, splat_scale: f32) -> Self {
        let cpu = CpuScene { scene, faces: Vec::new() };
        let leaf = scene.leaf_size_m;
        let discs = scene
            .surfels
            .iter()
            .map(|s| {
                let c = Vec3::from_slice(&s.position_radius[..3]);
                let cell = surface_cell(c, Vec3::from_slice(&s.normal_spread[..3]), leaf);
                let emission = cpu
                    .find_node(cell, 0)
                    .map(|n| {
                        Vec3::from_slice(
                            &scene.leaves[scene.nodes[n as usize].first_child as usize].emission[..3],
                        )
                    })
                    .unwrap_or(Vec3::ZERO);
                let albedo = Vec3::new(
                    srgb8_to_linear(s.color[0]),
                    srgb8_to_linear(s.color[1]),
                    srgb8_to_linear(s.color[2]),
                );
                Disc::new(
                    c,
                    Vec3::from_slice(&s.normal_spread[..3]),
                    s.position_radius[3] * splat_scale,
                    albedo,
                    emission,
                )
            })
            .collect();
        let mut out = Self::new(discs, scene.lights.clone(), leaf);
        out.rock = Some(SceneData {
            leaf_size_m: scene.leaf_size_m,
            tiles: scene.tiles.clone(),
            rock: scene.rock.clone(),
            ..SceneData::default()
        });
        out
    }

    /// Any discs and lights; `feature_m` sets the first query segment and the surface offset.
    pub fn new(mut discs: Vec<Disc>, lights: Vec<SceneLight>, feature_m: f32) -> Self {
        let bvh = Bvh::build_with_executor(&mut discs, bvh::bvh::rayon_executor);
        let (mut lo, mut hi) = (Vec3::splat(f32::MAX), Vec3::splat(f32::MIN));
        for d in &discs {
            lo = lo.min(d.center_m - Vec3::splat(d.radius_m));
            hi = hi.max(d.center_m + Vec3::splat(d.radius_m));
        }
        let extent_m = if discs.is_empty() { 1.0 } else { (hi - lo).length().max(1e-3) };
        let feature = feature_m.max(extent_m * 1e-5);
        Self {
            discs,
            bvh,
            lights,
            step_m: 4.0 * feature,
            extent_m,
            epsilon_m: 1e-3 * feature,
            shadow_offset_m: 0.25 * feature,
            bounce_offset_m: 1e-3 * feature,
            rock: None,
        }
    }

    /// The scene's discs, as the BVH holds them.
    pub fn discs(&self) -> &[Disc] {
        &self.discs
    }

    /// The same scene with shadow rays offset `shadow_m` and bounce rays `bounce_m` from the
    /// surface (each at least a hair): the Mitsuba check measures what the offsets change.
    pub fn with_ray_offsets(mut self, shadow_m: f32, bounce_m: f32) -> Self {
        self.shadow_offset_m = shadow_m.max(self.epsilon_m);
        self.bounce_offset_m = bounce_m.max(self.epsilon_m);
        self
    }

    pub(crate) fn lights(&self) -> &[SceneLight] {
        &self.lights
    }

    /// Closest disc hit by the ray (unit `d`), within `t_max`: its ray parameter and its index in
    /// [`SurfelScene::discs`].
    pub fn intersect(&self, o: Vec3, d: Vec3, t_max: f32) -> Option<(f32, usize)> {
        let mut t_lo = 0.0f32;
        let mut seg = self.step_m;
        let inv_d = Vec3::ONE / d;
        loop {
            let t_hi = (t_lo + seg).min(t_max);
            let q = Segment { o, inv_d, t_min: t_lo, t_max: t_hi };
            let mut best: Option<(f32, usize)> = None;
            for disc in self.bvh.traverse_iterator(&q, &self.discs) {
                if let Some(t) =
                    disc.hit(o, d, self.epsilon_m.max(t_lo - self.epsilon_m), best.map_or(t_hi, |b| b.0))
                {
                    best = Some((t, self.index(disc)));
                }
            }
            if best.is_some() {
                return best;
            }
            if t_hi >= t_max || t_hi >= 2.0 * self.extent_m + t_lo {
                return None;
            }
            t_lo = t_hi;
            seg *= 4.0;
        }
    }

    /// Position in `discs` of a disc the BVH returned (it yields references into the slice).
    fn index(&self, disc: &Disc) -> usize {
        (disc as *const Disc as usize - self.discs.as_ptr() as usize) / size_of::<Disc>()
    }

    /// Whether anything lies between `a` and `b`.
    pub(crate) fn occluded(&self, a: Vec3, b: Vec3) -> bool {
        let v = b - a;
        let len = v.length();
        if len <= 2.0 * self.epsilon_m {
            return false;
        }
        let d = v / len;
        let q = Segment { o: a, inv_d: Vec3::ONE / d, t_min: self.epsilon_m, t_max: len - self.epsilon_m };
        self.bvh
            .traverse_iterator(&q, &self.discs)
            .any(|disc| disc.hit(a, d, self.epsilon_m, len - self.epsilon_m).is_some())
    }

    /// Direct radiance reflected at `p` (normal `n` facing the viewer, albedo `albedo`) from
    /// point and spot lights (profiles included), shadow rays included.
    fn direct(&self, p: Vec3, n: Vec3, albedo: Vec3) -> Vec3 {
        let mut e = Vec3::ZERO;
        for l in &self.lights {
            let to = l.position_m - p;
            let dist = to.length().max(1e-4);
            let dir = to / dist;
            let c = n.dot(dir);
            if c <= 0.0 {
                continue;
            }
            // The spot's falloff and the profile, as the runtime's lights give them.
            let spot = l.factor_toward(-dir);
            if spot <= 0.0 || self.occluded(p + n * self.shadow_offset_m, l.position_m) {
                continue;
            }
            e += l.intensity_w_sr * (c * spot / (dist * dist));
        }
        albedo / PI * e
    }

    /// Whether the ray from `o` along unit `d` crosses a rock cell before it leaves the rock grid
    /// (the tiles plus their margins), probed once per rock cell length.
    fn through_rock(&self, o: Vec3, d: Vec3) -> bool {
        let Some(rock) = &self.rock else { return false };
        let leaf = rock.leaf_size_m;
        let margin =
            (grotto_runtime::scene::rock::ROCK_REACH_CELLS << grotto_runtime::scene::rock::ROCK_LEVEL) as f32;
        let (lo, hi) = rock.bounds_leaf();
        let (lo, hi) = (lo - Vec3::splat(margin), hi + Vec3::splat(margin));
        let step = (1u32 << grotto_runtime::scene::rock::ROCK_LEVEL) as f32;
        let mut p = o / leaf;
        let max_steps = ((hi - lo).length() / step) as usize + 2;
        for _ in 0..max_steps {
            p += d * step;
            if p.cmplt(lo).any() || p.cmpgt(hi).any() {
                return false;
            }
            if grotto_runtime::scene::rock::in_rock(&rock.rock, p.floor().as_ivec3()) {
                return true;
            }
        }
        false
    }

    /// Radiance arriving at `o` from direction `-d` (one path sample).
    pub fn trace(&self, o: Vec3, d: Vec3, settings: &PathSettings, rng: &mut SmallRng) -> Vec3 {
        let mut radiance = Vec3::ZERO;
        let mut throughput = Vec3::ONE;
        let (mut o, mut d) = (o, d);
        for bounce in 0..settings.max_bounces {
            let Some((t, i)) = self.intersect(o, d, f32::INFINITY) else {
                // Only a lit sky makes the rock test matter (closed scenes without one skip it).
                let sky = settings.sky(d);
                if sky != Vec3::ZERO && !self.through_rock(o, d) {
                    radiance += throughput * sky;
                }
                break;
            };
            let disc = &self.discs[i];
            let p = o + d * t;
            let n = if disc.normal.dot(d) < 0.0 { disc.normal } else { -disc.normal };
            radiance += throughput * (disc.emission + self.direct(p, n, disc.albedo));
            // Diffuse bounce: cosine sampling cancels the cosine / pdf, leaving the albedo.
            throughput *= disc.albedo;
            if bounce + 1 >= settings.min_bounces {
                let q = throughput.max_element().min(0.99);
                if q <= 0.0 || rng.random::<f32>() >= q {
                    break;
                }
                throughput /= q;
            }
            o = p + n * self.bounce_offset_m;
            d = cosine_sample(n, rng.random(), rng.random());
        }
        radiance
    }

    /// Outgoing radiance of the surface at disc `i`'s centre: emission + reflected light
    /// (direct and `paths` indirect samples).
    pub fn surface_radiance(&self, i: usize, paths: u32, settings: &PathSettings, seed: u64) -> Estimate {
        let disc = &self.discs[i];
        let n = disc.normal;
        let p = disc.center_m;
        let mut rng = SmallRng::seed_from_u64(seed ^ (i as u64).wrapping_mul(0x9E37_79B9_7F4A_7C15));
        let base = disc.emission + self.direct(p, n, disc.albedo);
        let e = Estimate::of((0..paths).map(|_| {
            let d = cosine_sample(n, rng.random(), rng.random());
            disc.albedo * self.trace(p + n * self.bounce_offset_m, d, settings, &mut rng)
        }));
        Estimate { mean: base + e.mean, std_err: e.std_err }
    }

    /// Cuts each disc to the leaf cell its surfel belongs to (a hair wider), so the discs tile
    /// the surface the leaves do instead of standing past it: at an opening's rim a disc, enlarged
    /// to close the gaps between samples, reaches into the opening and narrows it.
    pub fn clip_discs_to_cells(&mut self, leaf_m: f32) {
        let hair = Vec3::splat(1e-3 * leaf_m);
        for d in &mut self.discs {
            let lo = surface_cell(d.center_m, d.normal, leaf_m).as_vec3() * leaf_m;
            d.clip_m = [lo - hair, lo + Vec3::splat(leaf_m) + hair];
        }
    }

    /// Outgoing radiance per leaf of `scene` (the scene this was built from): the mean over the
    /// surfels inside the leaf, `paths` paths each; `None` for leaves no surfel lies in (rock
    /// interiors, empty cells). Index = global leaf index, as the runtime's leaf light buffer.
    pub fn leaf_radiance(
        &self,
        scene: &SceneData,
        paths: u32,
        settings: &PathSettings,
        seed: u64,
    ) -> Vec<Option<Estimate>> {
        let cpu = CpuScene { scene, faces: Vec::new() };
        let leaf_m = scene.leaf_size_m;
        let mut members: Vec<Vec<usize>> = vec![Vec::new(); scene.leaves.len()];
        for (i, d) in self.discs.iter().enumerate() {
            let cell = surface_cell(d.center_m, d.normal, leaf_m);
            if let Some(n) = cpu.find_node(cell, 0) {
                members[scene.nodes[n as usize].first_child as usize].push(i);
            }
        }
        members
            .par_iter()
            .map(|m| {
                if m.is_empty() {
                    return None;
                }
                let k = m.len() as f32;
                let (mut mean, mut var) = (Vec3::ZERO, Vec3::ZERO);
                for &i in m {
                    let e = self.surface_radiance(i, paths, settings, seed);
                    mean += e.mean / k;
                    var += e.std_err * e.std_err / (k * k);
                }
                Some(Estimate { mean, std_err: var.powf(0.5) })
            })
            .collect()
    }

    /// A `width x height` image of `camera` (same pixel rays as the runtime's shade pass) with
    /// `spp` jittered paths per pixel: per-pixel mean and standard error.
    pub fn render(
        &self,
        camera: &Camera,
        width: u32,
        height: u32,
        spp: u32,
        settings: &PathSettings,
        seed: u64,
    ) -> Vec<Estimate> {
        self.render_with_progress(camera, width, height, spp, settings, seed, |_| {})
    }

    /// [`SurfelScene::render`] in bands of rows, calling `progress(rows_done)` after each band.
    #[allow(clippy::too_many_arguments)]
    pub fn render_with_progress(
        &self,
        camera: &Camera,
        width: u32,
        height: u32,
        spp: u32,
        settings: &PathSettings,
        seed: u64,
        mut progress: impl FnMut(u32),
    ) -> Vec<Estimate> {
        let mut out = Vec::with_capacity((width * height) as usize);
        let band = 8u32;
        for y0 in (0..height).step_by(band as usize) {
            let y1 = (y0 + band).min(height);
            out.extend(self.render_rows(camera, width, height, y0..y1, spp, settings, seed));
            progress(y1);
        }
        out
    }

    #[allow(clippy::too_many_arguments)]
    fn render_rows(
        &self,
        camera: &Camera,
        width: u32,
        height: u32,
        rows: std::ops::Range<u32>,
        spp: u32,
        settings: &PathSettings,
        seed: u64,
    ) -> Vec<Estimate> {
        let forward = (camera.look_at_m - camera.eye_m).normalize();
        let right = forward.cross(camera.up).normalize();
        let up = right.cross(forward);
        let t = (camera.fov_y_deg.to_radians() * 0.5).tan();
        let aspect = width as f32 / height as f32;
        (rows.start * width..rows.end * width)
            .into_par_iter()
            .map(|idx| {
                let (x, y) = (idx % width, idx / width);
                let mut rng =
                    SmallRng::seed_from_u64(seed.wrapping_mul(0x2545_F491_4F6C_DD1D) ^ u64::from(idx));
                Estimate::of((0..spp).map(|_| {
                    let sx = (x as f32 + rng.random::<f32>()) / width as f32 * 2.0 - 1.0;
                    let sy = 1.0 - (y as f32 + rng.random::<f32>()) / height as f32 * 2.0;
                    let d = (forward + right * (sx * t * aspect) + up * (sy * t)).normalize();
                    self.trace(camera.eye_m, d, settings, &mut rng)
                }))
            })
            .collect()
    }
}

/// ACES filmic tonemap and sRGB encoding of linear `x` (the runtime's shade pass, on the CPU).
pub fn aces_srgb(x: f32) -> u8 {
    let x = x.max(0.0);
    let m = ((x * (2.51 * x + 0.03)) / (x * (2.43 * x + 0.59) + 0.14)).clamp(0.0, 1.0);
    grotto_format::color::linear_to_srgb8(m)
}
