//! A cone march whose coverage counts rays, not steps (issue 47), tried on the CPU against the
//! runtime's march and the path tracer: what the first bounce carries to each face of the colour
//! box or each region of the dogleg (leaves on their surfels, as packages have them), as a share of
//! what the reference's first bounce carries (1 where the bounce is carried exactly).
//!
//! The runtime's cone (`cpu_ref::trace_cone`, the GPU's march) composites every sample's opacity
//! front to back, so a surface a cone runs along is counted again at every step, and a cone whose
//! axis enters rock takes the colour it last sampled for all it had not yet seen
//! (docs/reference.md, "Where a wall's cones read too much"). The march tried here follows `RAYS`
//! rays spread evenly over each cone's solid angle through the rock behind the shells (the
//! runtime's rock table); a ray ends where it enters rock, and brings the colour of the radiance
//! pyramid where it met the surface, read at the share of the footprint it stands for. The cone
//! is covered by the share of its rays that ended: a surface is counted once, by the rays that
//! met it, where they met it.
//!
//! `cargo run --release -p grotto-reference --example ray_cones -- [colour-box|emit-ceiling|dogleg|passage]`
//! (`emit-ceiling`: the colour box with no lamp and its ceiling glowing). Knobs, by environment:
//! `RAYS=1|7|19` (default 7); `LIFT=k`, the rays start k leaves off the surface instead of the
//! cones' lift; `LOD_MIN=k` and `LOD_MAX=k`, the pyramid levels a ray's colour is read between;
//! `GROW=g`, each step at least g times the ray's share of the footprint instead of half a leaf;
//! `NOLEAF=1`, a ray ends at rock only, not where it meets a leaf. It prints, per region, the
//! GPU's first bounce, the CPU cones' (the same march, as a check) and the rays', each over the
//! reference's, then how many samples the cones took and how many steps the rays did.
use glam::{DVec3, Vec3};
use grotto_fixtures::testscenes;
use grotto_reference::accuracy::breakdown::{BreakdownScene, balanced_cut, luminance as lum, settled};
use grotto_reference::{PathSettings, SurfelScene};
use grotto_runtime::gpu::types::Params;
use grotto_runtime::gpu::{Gpu, GpuOptions};
use grotto_runtime::passes::cpu_ref::CpuScene;
use grotto_runtime::scene::data::SceneData;
use grotto_runtime::scene::rock::{ROCK_LEVEL, in_rock};
use grotto_runtime::settings::{Quality, Settings};

/// Offsets over the unit disc (the cone's footprint in units of its radius), each standing for an
/// equal share of it: the centre and rings at the radii that halve their annuli's area.
fn ray_pattern(rays: usize) -> anyhow::Result<Vec<[f64; 2]>> {
    let rings: &[(usize, f64)] = match rays {
        1 => &[],
        7 => &[(6, 0.756)],
        19 => &[(6, 0.5), (12, 0.866)],
        other => anyhow::bail!("RAYS={other}: 1, 7 or 19"),
    };
    let mut out = vec![[0.0, 0.0]];
    for (k, &(count, radius)) in rings.iter().enumerate() {
        let turn = if k % 2 == 1 { std::f64::consts::PI / count as f64 } else { 0.0 };
        for j in 0..count {
            let a = turn + std::f64::consts::TAU * j as f64 / count as f64;
            out.push([radius * a.cos(), radius * a.sin()]);
        }
    }
    Ok(out)
}

/// A knob from the environment, if set and readable.
fn env<T: std::str::FromStr>(name: &str) -> Option<T> {
    std::env::var(name).ok().and_then(|v| v.parse().ok())
}

struct RayMarch<'a> {
    cpu: &'a CpuScene<'a>,
    p: Params,
    pattern: Vec<[f64; 2]>,
    lod_min: f64,
    lod_max: f64,
    hit_leaves: bool,
    grow: f64,
    steps: std::cell::Cell<u64>,
    hits: std::cell::Cell<u64>,
    escaped: std::cell::Cell<u64>,
    blank: std::cell::Cell<u64>,
}

impl RayMarch<'_> {
    /// One cone from `origin_m` along unit `dir`, its surface's normal `n`: premultiplied radiance
    /// and the share of its rays that ended on a surface (the cone's opacity).
    fn cone(&self, origin_m: DVec3, dir: DVec3, n: DVec3) -> [f64; 4] {
        let leaf = f64::from(self.p.leaf_size_m);
        let cell_m = leaf * f64::from(1u32 << ROCK_LEVEL);
        let tan_half = f64::from(self.p.cone_tan_half);
        let up = if dir.z.abs() < 0.9 { DVec3::Z } else { DVec3::X };
        let e1 = dir.cross(up).normalize();
        let e2 = dir.cross(e1);
        let corner = |v: [f32; 4]| DVec3::new(v[0].into(), v[1].into(), v[2].into());
        let (lo, hi) = (corner(self.p.scene_min_leaf), corner(self.p.scene_max_leaf));
        let share = 1.0 / self.pattern.len() as f64;
        let mut acc = [0.0f64; 4];
        for u in &self.pattern {
            let mut d = (dir + tan_half * (u[0] * e1 + u[1] * e2)).normalize();
            // Rays of a grazing cone that would dip under the cone's own surface run just above
            // it instead (a path from the surface cannot go below it).
            let rise = d.dot(n);
            if rise < 0.02 {
                d = (d + n * (0.02 - rise)).normalize();
            }
            let step = 0.5 * leaf;
            let mut t = leaf;
            loop {
                let q = (origin_m + d * t) / leaf;
                if t > f64::from(self.p.max_distance_m) || q.cmplt(lo).any() || q.cmpgt(hi).any() {
                    self.escaped.set(self.escaped.get() + 1);
                    break;
                }
                let rock = in_rock(&self.cpu.scene.rock, q.floor().as_ivec3());
                let surface =
                    self.hit_leaves && self.cpu.sample_lod(q, 0.0, self.p.max_lod, d, false)[3] >= 0.5;
                if rock || surface {
                    // Where the ray met the surface: at a leaf, here; at rock, at most a rock cell
                    // back (the shell lies in front of the rock). Its colour is read over this
                    // ray's share of the footprint, coarser where the finest level is empty.
                    let back = if surface { 0.0 } else { 0.5 * cell_m };
                    let at = (origin_m + d * (t - back).max(leaf)) / leaf;
                    let diameter = (2.0 * t * tan_half * share.sqrt()).max(leaf);
                    let mut lod = (0.5 * diameter / leaf).log2().clamp(self.lod_min, self.lod_max);
                    let mut s = self.cpu.sample_lod(at, lod, self.p.max_lod, d, false);
                    while s[3] <= 1e-6 && lod < f64::from(self.p.max_lod) {
                        lod += 1.0;
                        s = self.cpu.sample_lod(at, lod, self.p.max_lod, d, false);
                    }
                    if s[3] <= 1e-6 {
                        self.blank.set(self.blank.get() + 1);
                    }
                    self.hits.set(self.hits.get() + 1);
                    if s[3] > 1e-6 {
                        for k in 0..3 {
                            acc[k] += share * s[k] / s[3];
                        }
                    }
                    acc[3] += share;
                    break;
                }
                self.steps.set(self.steps.get() + 1);
                t += step.max(self.grow * 2.0 * t * tan_half * share.sqrt());
            }
        }
        acc
    }
}

fn surface_normal(data: &SceneData, i: usize) -> Option<DVec3> {
    let m = Vec3::from_slice(&data.leaves[i].normal_mean[..3]).as_dvec3();
    (m.length() > 1e-4).then(|| m.normalize())
}

fn main() -> anyhow::Result<()> {
    let gpu = Gpu::new(&GpuOptions { prefer_software: true, ..Default::default() })?;
    let which = std::env::args().nth(1).unwrap_or_else(|| "colour-box".into());
    let rays: usize = env("RAYS").unwrap_or(7);
    let glowing = which == "emit-ceiling";
    let kind = match which.as_str() {
        "colour-box" | "emit-ceiling" => BreakdownScene::ColourBox,
        "dogleg" => BreakdownScene::Dogleg,
        "passage" => BreakdownScene::Passage,
        other => anyhow::bail!("scene {other}: colour-box, emit-ceiling, dogleg or passage"),
    };
    let mut data = kind.data().map_err(anyhow::Error::msg)?;
    if glowing {
        data.lights.clear();
        let leaf = data.leaf_size_m;
        for l in &mut data.leaves {
            if l.cell(leaf).z == testscenes::COLOUR_BOX_CELLS - 1 {
                l.emission = [1.0, 1.0, 1.0, 0.0];
            }
        }
    }
    if kind != BreakdownScene::Passage {
        testscenes::leaves_on_surfels(&mut data);
    }
    let regions = kind.regions(&data);
    let mut region_of = vec![None; data.leaves.len()];
    for (r, (_, leaves)) in regions.iter().enumerate() {
        for &i in leaves {
            region_of[i] = Some(r);
        }
    }
    let names: Vec<&str> = regions.iter().map(|(n, _)| n.as_str()).collect();
    let lift: Option<f64> = env("LIFT");
    let r0 = settled(&gpu, &data, balanced_cut(0))?;
    let light0 = r0.read_leaf_light()?;
    let light1 = settled(&gpu, &data, balanced_cut(1))?.read_leaf_light()?;
    let p = r0.params();
    let cpu = CpuScene::mip(&data, &light0);
    let march = RayMarch {
        cpu: &cpu,
        p,
        pattern: ray_pattern(rays)?,
        lod_min: env("LOD_MIN").unwrap_or(0.0),
        lod_max: env("LOD_MAX").unwrap_or(f64::from(p.max_lod)),
        hit_leaves: std::env::var("NOLEAF").is_err(),
        grow: env("GROW").unwrap_or(0.0),
        steps: 0.into(),
        hits: 0.into(),
        escaped: 0.into(),
        blank: 0.into(),
    };
    let scene = SurfelScene::from_scene(&data, Settings::preset(Quality::Balanced).splat_scale);
    let full = PathSettings::for_scene(&data);
    let f0 = scene.leaf_radiance(&data, 256, &PathSettings { max_bounces: 0, ..full }, 2);
    let f1 = scene.leaf_radiance(&data, 256, &PathSettings { max_bounces: 1, ..full }, 3);
    let k = names.len();
    let (mut gpu_sum, mut cone_sum, mut ray_sum, mut ref_sum) =
        (vec![0.0; k], vec![0.0; k], vec![0.0; k], vec![0.0; k]);
    let mut cone_steps = 0u64;
    for (i, leaf) in data.leaves.iter().enumerate() {
        let (Some(a), Some(b)) = (&f0[i], &f1[i]) else { continue };
        let Some(n) = surface_normal(&data, i) else { continue };
        let Some(f) = region_of[i] else { continue };
        let albedo = DVec3::new(
            leaf.albedo_opacity[0].into(),
            leaf.albedo_opacity[1].into(),
            leaf.albedo_opacity[2].into(),
        );
        let bounce = |g: DVec3| lum((albedo * g).as_vec3().to_array());
        let cone =
            cpu.gather_with(&p, i, |o, d, rise| cpu.trace_cone_observed(&p, o, d, rise, |_| cone_steps += 1));
        let ray = cpu.gather_with(&p, i, |o, d, rise| {
            // LIFT=k: the rays start k leaves off the surface instead of the cones' lift.
            let o = lift.map_or(o, |k| o - n * (rise[0] - k * f64::from(data.leaf_size_m)));
            march.cone(o, d, n)
        });
        gpu_sum[f] += lum(light1[i].shown(leaf)) - lum(light0[i].shown(leaf));
        cone_sum[f] += bounce(cone);
        ray_sum[f] += bounce(ray);
        ref_sum[f] += lum(b.mean.to_array()) - lum(a.mean.to_array());
    }
    println!("| {which}, {rays} rays | {} |", names.join(" | "));
    for (name, sums) in [("GPU cones", &gpu_sum), ("CPU cones", &cone_sum), ("rays", &ray_sum)] {
        let cells: Vec<String> = (0..k).map(|f| format!("{:.3}", sums[f] / ref_sum[f])).collect();
        println!("| {name} | {} |", cells.join(" | "));
    }
    eprintln!(
        "the cones' march: {cone_steps} samples; rays: {} ended on a surface ({} read no colour), {} left the scene, {} steps",
        march.hits.get(),
        march.blank.get(),
        march.escaped.get(),
        march.steps.get()
    );
    Ok(())
}
