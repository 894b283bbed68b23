//! A cone march whose coverage counts rays, not steps, tried on the CPU against the
//! runtime's march and the path tracer: what the first bounces carry to each region of the colour
//! box, the dogleg (both with their leaves on their surfels, as packages have them) or the scanned
//! passage, as a share of what the reference's carry (1 where the bounces are carried exactly).
//!
//! The runtime's cone (`cpu_ref::trace_cone`, the GPU's march) composites every sample's opacity
//! front to back, so a surface a cone runs along is counted again at every step, and a cone whose
//! axis enters rock takes the colour it last sampled for all it had not yet seen
//! (docs/reference.md, "Where a wall's cones read too much"). The march tried here follows `RAYS`
//! rays spread evenly over each cone's solid angle (the same cone set, interleave and weights,
//! through `cpu_ref::gather_with`); a ray ends where it enters the rock behind the shells (the
//! runtime's rock table) or meets a leaf, and brings the colour of the radiance pyramid there,
//! read over the share of the footprint it stands for. The cone is covered by the share of its
//! rays that ended: a surface is counted once, by the rays that met it, where they met it.
//!
//! `cargo run --release -p grotto-reference --example ray_cones -- [colour-box|emit-ceiling|dogleg|passage]`
//! (`emit-ceiling`: the colour box with no lamp and its ceiling glowing). Knobs, by environment:
//! `BOUNCES=k` (default 1), the bounces run (the GPU's, and the CPU's each over the pyramid of the
//! one before), against the reference cut after as many; `RAYS=1|7|19` (default 7); `LIFT=k`, the
//! rays start k leaves off the surface instead of the cones' lift; `LOD_MIN=k` and `LOD_MAX=k`,
//! the pyramid levels a ray's colour is read between; `GROW=g`, each step at least g times the
//! ray's share of the footprint instead of half a leaf; `NOLEAF=1`, a ray ends at rock only;
//! `CELLS=1`, a ray walks the leaf cells it crosses and meets a leaf by its cell, and with it
//! `PLANEHIT=1` only where it goes behind the leaf's plane in that cell (`PLANE_OFFSET=k`: the
//! plane moved k leaves out, toward the air); `COSW=1`, rays weighted by their cosine within
//! their cone. It prints, per region, what the bounces add to the leaves' light on the GPU, with
//! the CPU cones (the same march, as a check), with the rays and with the runtime's ray march on
//! the GPU (`Settings::cone_rays`: these rays with `CELLS=1 PLANEHIT=1 PLANE_OFFSET=0.25
//! LIFT=0.3`), each over what the reference's add, then how many samples the cones took and how
//! many steps the rays did (with `CELLS`, also what a walk crossing empty nodes whole would
//! visit, and the bricks of 4x4x4 leaves the rays enter). `SLABS=r` adds region r leaf slab by leaf slab (`slabs`);
//! `BY_FACES=1` each region's leaves by how many facets their surfels lie on (`by_faces`);
//! `FACETS=1|2` the CPU bounces again with the leaves of several facets lit (and with 2, also
//! gathering) facet by facet (`FacetLight`); `SPLAT=s` makes the reference's discs s times their
//! surfels' radius instead of the runtime's splat scale (2).
use glam::{DVec3, IVec3, Vec3};
use grotto_fixtures::testscenes;
use grotto_reference::accuracy::breakdown::{BreakdownScene, balanced_cut, luminance as lum, settled};
use grotto_reference::{PathSettings, SurfelScene};
use grotto_runtime::gpu::types::{LeafLightGpu, Params};
use grotto_runtime::gpu::{Gpu, GpuOptions};
use grotto_runtime::passes::cpu_ref::CpuScene;
use grotto_runtime::scene::data::SceneData;
use grotto_runtime::scene::rock::{ROCK_LEVEL, in_rock};
use grotto_runtime::settings::{Quality, Settings};

/// Offsets over the unit disc (the cone's footprint in units of its radius), each standing for an
/// equal share of it: the centre and rings at the radii that halve their annuli's area (7 rays:
/// the annulus from sqrt(1/7) to 1; 19: from sqrt(1/19) to sqrt(7/19) and from there to 1).
fn ray_pattern(rays: usize) -> anyhow::Result<Vec<[f64; 2]>> {
    let rings: &[(usize, f64)] = match rays {
        1 => &[],
        7 => &[(6, 0.756)],
        19 => &[(6, 0.459), (12, 0.827)],
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

/// The ray march's knobs (from the environment, `main`) and what it counted.
struct RayMarch {
    p: Params,
    pattern: Vec<[f64; 2]>,
    lod_min: f64,
    lod_max: f64,
    hit_leaves: bool,
    cells: bool,
    plane_hit: bool,
    plane_offset_m: f64,
    cos_weighted: bool,
    grow: f64,
    steps: std::cell::Cell<u64>,
    visits: [std::cell::Cell<u64>; 2],
    bricks: std::cell::Cell<u64>,
    hits: std::cell::Cell<u64>,
    escaped: std::cell::Cell<u64>,
    blank: std::cell::Cell<u64>,
}

impl RayMarch {
    /// One cone from `origin_m` along unit `dir`, its surface's normal `n`: premultiplied radiance
    /// and the share of its rays that ended on a surface (the cone's opacity).
    fn cone(&self, cpu: &CpuScene<'_>, origin_m: DVec3, dir: DVec3, n: DVec3) -> [f64; 4] {
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
        // COSW=1: each ray weighted by its cosine to the surface's normal (the cone's weight is its
        // cosine-weighted solid angle, and the rays sample the solid angle evenly); else evenly.
        let ray_dir = |u: &[f64; 2]| (dir + tan_half * (u[0] * e1 + u[1] * e2)).normalize();
        let cos_sum: f64 = self.pattern.iter().map(|u| ray_dir(u).dot(n).max(0.0)).sum();
        for u in &self.pattern {
            let mut d = ray_dir(u);
            let weight = if self.cos_weighted && cos_sum > 0.0 { d.dot(n).max(0.0) / cos_sum } else { share };
            // Rays of a grazing cone that would dip under the cone's own surface run just above
            // it instead (a path from the surface cannot go below it).
            let rise = d.dot(n);
            if rise < 0.02 {
                d = (d + n * (0.02 - rise)).normalize();
            }
            let step = 0.5 * leaf;
            let mut t = leaf;
            // CELLS=1: the ray walks the leaf cells it crosses (Amanatides & Woo), `t` where it
            // enters each, and meets a leaf by its cell.
            let start = (origin_m + d * t) / leaf;
            let mut cell = start.floor().as_ivec3();
            let dir_step = d.signum().as_ivec3();
            let next_edge = (cell.as_dvec3() + d.signum().max(DVec3::ZERO) - start) / d;
            let mut t_next = DVec3::select(d.abs().cmpgt(DVec3::splat(1e-12)), next_edge, DVec3::INFINITY);
            let t_cell = DVec3::select(d.abs().cmpgt(DVec3::splat(1e-12)), (1.0 / d).abs(), DVec3::INFINITY);
            let t_start = t;
            let mut last_key: [Option<(u32, IVec3)>; 2] = [None; 2];
            let mut last_brick: Option<IVec3> = None;
            loop {
                let q = (origin_m + d * t) / leaf;
                if t > f64::from(self.p.max_distance_m) || q.cmplt(lo).any() || q.cmpgt(hi).any() {
                    self.escaped.set(self.escaped.get() + 1);
                    break;
                }
                let (rock, surface) = if self.cells {
                    let leaf_here = if self.hit_leaves { cpu.find_node(cell, 0) } else { None };
                    // PLANEHIT=1: a ray meets a leaf only where, in its cell, it goes behind the
                    // plane through the leaf's surfels across their mean normal.
                    let exit_m = origin_m + d * (t_start + t_next.min_element() * leaf);
                    let surface = leaf_here
                        .is_some_and(|n| !self.plane_hit || behind_leaf(cpu, n, exit_m, self.plane_offset_m));
                    (in_rock(&cpu.scene.rock, cell), surface)
                } else {
                    let surface =
                        self.hit_leaves && cpu.sample_lod(q, 0.0, self.p.max_lod, d, false)[3] >= 0.5;
                    (in_rock(&cpu.scene.rock, q.floor().as_ivec3()), surface)
                };
                if rock || surface {
                    // Where the ray met the surface: at a leaf, here; at rock, at most a rock cell
                    // back (the shell lies in front of the rock).
                    let back = if surface { 0.0 } else { 0.5 * cell_m };
                    let at = (origin_m + d * (t - back).max(leaf)) / leaf;
                    let diameter = (2.0 * t * tan_half * share.sqrt()).max(leaf);
                    if let Some(c) = self.colour_at(cpu, at, d, diameter) {
                        for k in 0..3 {
                            acc[k] += weight * c[k];
                        }
                    }
                    acc[3] += weight;
                    break;
                }
                self.steps.set(self.steps.get() + 1);
                if self.cells {
                    self.count_visits(cpu, cell, &mut last_brick, &mut last_key);
                    let axis = if t_next.x <= t_next.y && t_next.x <= t_next.z {
                        0
                    } else if t_next.y <= t_next.z {
                        1
                    } else {
                        2
                    };
                    t = t_start + t_next[axis] * leaf;
                    cell[axis] += dir_step[axis];
                    t_next[axis] += t_cell[axis];
                } else {
                    t += step.max(self.grow * 2.0 * t * tan_half * share.sqrt());
                }
            }
        }
        acc
    }

    /// The pyramid's colour at `at` (leaf units) seen along `d`, read over a footprint
    /// `diameter_m` wide (a ray's share of its cone's), coarser where the finer level is empty.
    fn colour_at(&self, cpu: &CpuScene<'_>, at: DVec3, d: DVec3, diameter_m: f64) -> Option<[f64; 3]> {
        let leaf = f64::from(self.p.leaf_size_m);
        let mut lod = (0.5 * diameter_m / leaf).log2().clamp(self.lod_min, self.lod_max);
        let mut s = cpu.sample_lod(at, lod, self.p.max_lod, d, false);
        while s[3] <= 1e-6 && lod < f64::from(self.p.max_lod) {
            lod += 1.0;
            s = cpu.sample_lod(at, lod, self.p.max_lod, d, false);
        }
        self.hits.set(self.hits.get() + 1);
        if s[3] <= 1e-6 {
            self.blank.set(self.blank.get() + 1);
            return None;
        }
        Some([s[0] / s[3], s[1] / s[3], s[2] / s[3]])
    }

    /// Counts, for a ray entering leaf cell `cell`, what a walk crossing empty nodes of 4 and 8
    /// leaves whole would visit (a visit where the node it stands in changes) and the bricks of
    /// 4x4x4 leaves it enters (a walk over a table of one 64-bit mask a brick, leaves and rock,
    /// would fetch one a brick).
    fn count_visits(
        &self,
        cpu: &CpuScene<'_>,
        cell: IVec3,
        last_brick: &mut Option<IVec3>,
        last_key: &mut [Option<(u32, IVec3)>; 2],
    ) {
        if *last_brick != Some(cell >> 2) {
            self.bricks.set(self.bricks.get() + 1);
            *last_brick = Some(cell >> 2);
        }
        for (k, level) in [2u32, 3].into_iter().enumerate() {
            let node = cell >> level as i32;
            let empty = cpu.find_node(node, level).is_none() && {
                let rock_cells = 1i32 << (level - ROCK_LEVEL);
                let base = node * rock_cells;
                !(0..rock_cells.pow(3)).any(|j| {
                    let o = IVec3::new(j % rock_cells, (j / rock_cells) % rock_cells, j / rock_cells.pow(2));
                    in_rock(&cpu.scene.rock, (base + o) << ROCK_LEVEL as i32)
                })
            };
            let key = if empty { (level, node) } else { (0, cell) };
            if last_key[k] != Some(key) {
                self.visits[k].set(self.visits[k].get() + 1);
                last_key[k] = Some(key);
            }
        }
    }
}

/// Whether `p_m` lies behind the surface of leaf node `n`: the plane through its surfels' centroid
/// across their mean normal (a leaf whose normals scatter too much to have one counts as solid).
fn behind_leaf(cpu: &CpuScene<'_>, n: u32, p_m: DVec3, offset_m: f64) -> bool {
    let node = cpu.scene.nodes[n as usize];
    if node.child_mask() != 0 {
        return true;
    }
    let leaf = &cpu.scene.leaves[node.first_child as usize];
    let m = Vec3::from_slice(&leaf.normal_mean[..3]).as_dvec3();
    let r = m.length();
    r < 0.3 || (p_m - Vec3::from_slice(&leaf.center_m[..3]).as_dvec3()).dot(m / r) <= offset_m
}

/// Whether leaf `i` has a surface to gather over (a mean normal; `gather_with` gives it unit
/// length): rock interiors have none.
fn on_surface(data: &SceneData, i: usize) -> bool {
    Vec3::from_slice(&data.leaves[i].normal_mean[..3]).length() > 1e-4
}

/// The scene `which` names (the hand-built ones with their leaves on their surfels), its regions'
/// names and each leaf's region.
fn scene_named(which: &str) -> anyhow::Result<(SceneData, Vec<String>, Vec<Option<usize>>)> {
    let kind = match which {
        "colour-box" | "emit-ceiling" => BreakdownScene::ColourBox,
        "dogleg" => BreakdownScene::Dogleg,
        "passage" => BreakdownScene::Passage,
        other => anyhow::bail!("scene {other}: colour-box, emit-ceiling, dogleg or passage"),
    };
    let mut data = kind.data().map_err(anyhow::Error::msg)?;
    if which == "emit-ceiling" {
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
    Ok((data, regions.into_iter().map(|(n, _)| n).collect(), region_of))
}

/// SLABS=r: region r's leaves in slabs one leaf thick across its longest axis (`SLAB_AXIS`
/// overrides: 0, 1, 2): per slab, the reference's share of what the bounces add to the region,
/// and the GPU's, the CPU cones' and the rays' over the reference's.
fn slabs(
    data: &SceneData,
    region_of: &[Option<usize>],
    region: usize,
    light0: &[LeafLightGpu],
    lights: [&Vec<LeafLightGpu>; 3],
    (f0, fk): (&[Option<grotto_reference::Estimate>], &[Option<grotto_reference::Estimate>]),
) {
    let cells: Vec<(usize, IVec3)> = (0..data.leaves.len())
        .filter(|&i| region_of[i] == Some(region) && f0[i].is_some() && fk[i].is_some())
        .map(|i| (i, data.leaves[i].cell(data.leaf_size_m)))
        .collect();
    let (lo, hi) = cells.iter().fold((IVec3::MAX, IVec3::MIN), |(lo, hi), (_, c)| (lo.min(*c), hi.max(*c)));
    let axis = env("SLAB_AXIS").unwrap_or_else(|| (hi - lo).max_position());
    let mut sums = std::collections::BTreeMap::<i32, [f64; 4]>::new();
    for &(i, c) in &cells {
        let leaf = &data.leaves[i];
        let e = sums.entry(c[axis]).or_default();
        for (k, l) in lights.iter().enumerate() {
            e[k] += lum(l[i].shown(leaf)) - lum(light0[i].shown(leaf));
        }
        let (a, b) = (f0[i].as_ref().map(|e| e.mean), fk[i].as_ref().map(|e| e.mean));
        if let (Some(a), Some(b)) = (a, b) {
            e[3] += lum(b.to_array()) - lum(a.to_array());
        }
    }
    let total: f64 = sums.values().map(|v| v[3]).sum();
    println!("| slab (axis {axis}) | share | GPU cones | CPU cones | rays |");
    for (x, v) in &sums {
        println!(
            "| {x} | {:.3} | {:.3} | {:.3} | {:.3} |",
            v[3] / total,
            v[0] / v[3],
            v[1] / v[3],
            v[2] / v[3]
        );
    }
}

/// BY_FACES=1: each region's leaves by how many faces of their rock cell their surfels lie on
/// (1: a wall, 2: an edge, 3: a corner; the mean normal's length tells them apart on a carved
/// scene), per class the reference's share of what the bounces add to the region and the GPU
/// cones' and rays' over the reference's.
fn by_faces(
    data: &SceneData,
    names: &[String],
    region_of: &[Option<usize>],
    surface: &[bool],
    light0: &[LeafLightGpu],
    lights: [&Vec<LeafLightGpu>; 2],
    (f0, fk): (&[Option<grotto_reference::Estimate>], &[Option<grotto_reference::Estimate>]),
) {
    let mut sums = std::collections::BTreeMap::<(usize, usize), [f64; 4]>::new();
    for (i, leaf) in data.leaves.iter().enumerate() {
        let (Some(a), Some(b)) = (&f0[i], &fk[i]) else { continue };
        let Some(r) = region_of[i].filter(|_| surface[i]) else { continue };
        let len = Vec3::from_slice(&leaf.normal_mean[..3]).length();
        let faces = if len > 0.85 {
            1
        } else if len > 0.64 {
            2
        } else {
            3
        };
        let e = sums.entry((r, faces)).or_default();
        for (k, l) in lights.iter().enumerate() {
            e[k] += lum(l[i].shown(leaf)) - lum(light0[i].shown(leaf));
        }
        e[2] += lum(b.mean.to_array()) - lum(a.mean.to_array());
        e[3] += 1.0;
    }
    println!("| region | faces | leaves | share | GPU cones | GPU rays |");
    for (&(r, faces), v) in &sums {
        let total: f64 = sums.iter().filter(|((q, _), _)| *q == r).map(|(_, v)| v[2]).sum();
        println!(
            "| {} | {faces} | {} | {:.3} | {:.3} | {:.3} |",
            names[r],
            v[3],
            v[2] / total,
            v[0] / v[2],
            v[1] / v[2]
        );
    }
}

/// FACETS=1: the bounces gather over a pyramid whose leaves of several facets (a carved scene's
/// convex edges: an opening's rim) show each travel direction the light of the facets facing it,
/// each facet's direct light its own (the runtime's, with the leaf's normal set to the facet's)
/// instead of one light for all of them; FACETS=2: each facet also gathers on its own (from its
/// surfels' centroid across its normal), and the leaf's light is its facets' mean.
struct FacetLight {
    /// Per facet rank k, the scene with each leaf of several facets given its k-th facet's
    /// normal and centroid (its last where it has fewer).
    scenes: Vec<SceneData>,
    /// Leaf, its level-0 node, and its facets.
    leaves: Vec<(usize, u32, Vec<Facet>)>,
    own_gather: bool,
}

/// One facet of a leaf: its normal, direct light and surfel count.
struct Facet {
    normal: DVec3,
    direct: [f32; 4],
    surfels: f64,
}

impl FacetLight {
    fn new(gpu: &Gpu, data: &SceneData, own_gather: bool) -> anyhow::Result<Self> {
        let leaf_m = data.leaf_size_m;
        let cell_leaf: std::collections::HashMap<IVec3, usize> =
            data.leaves.iter().enumerate().map(|(i, l)| (l.cell(leaf_m), i)).collect();
        let mut facets = std::collections::BTreeMap::<usize, Vec<(IVec3, Vec3, f32)>>::new();
        for s in &data.surfels {
            let p = Vec3::from_slice(&s.position_radius[..3]);
            let n = Vec3::from_slice(&s.normal_spread[..3]);
            let cell = ((p - n * 0.5 * leaf_m) / leaf_m).floor().as_ivec3();
            if let Some(&i) = cell_leaf.get(&cell) {
                let f = facets.entry(i).or_default();
                let axis = n.round().as_ivec3();
                match f.iter_mut().find(|(a, _, _)| *a == axis) {
                    Some(e) => {
                        e.1 += p;
                        e.2 += 1.0;
                    }
                    None => f.push((axis, p, 1.0)),
                }
            }
        }
        facets.retain(|_, f| f.len() > 1);
        let most = facets.values().map(Vec::len).max().unwrap_or(0);
        let mut scenes = Vec::new();
        let mut lit: Vec<Vec<LeafLightGpu>> = Vec::new();
        for k in 0..most {
            let mut one = data.clone();
            for (&i, f) in &facets {
                let (axis, sum, count) = f[k.min(f.len() - 1)];
                let n = axis.as_vec3();
                let lo = data.leaves[i].cell(leaf_m).as_vec3() * leaf_m;
                let inset = Vec3::splat(0.01 * leaf_m);
                let c = (sum / count).clamp(lo + inset, lo + Vec3::splat(leaf_m) - inset);
                let l = &mut one.leaves[i];
                l.normal_mean = [n.x, n.y, n.z, 0.0];
                l.center_m = [c.x, c.y, c.z, l.center_m[3]];
            }
            lit.push(settled(gpu, &one, balanced_cut(0))?.read_leaf_light()?);
            scenes.push(one);
        }
        let (order, ranges) = data.nodes_by_height();
        let leaf_node: std::collections::HashMap<usize, u32> = ranges
            .iter()
            .filter(|r| r.height == 0)
            .flat_map(|r| order[r.first as usize..(r.first + r.count) as usize].iter())
            .map(|&n| (data.nodes[n as usize].first_child as usize, n))
            .collect();
        let leaves = facets
            .iter()
            .filter_map(|(&i, f)| {
                let node = *leaf_node.get(&i)?;
                let per = f.iter().enumerate().map(|(k, (n, _, c))| Facet {
                    normal: n.as_dvec3(),
                    direct: lit[k][i].out,
                    surfels: f64::from(*c),
                });
                Some((i, node, per.collect()))
            })
            .collect();
        Ok(Self { scenes, leaves, own_gather })
    }

    /// Each facet leaf's level-0 faces: per travel direction, the mean of `out` (per leaf, per
    /// facet) over the facets that face it, each by its cosine; left as it is where none does.
    fn apply(&self, data: &SceneData, cpu: &mut CpuScene<'_>, out: &[Vec<[f32; 4]>]) {
        for ((i, node, facets), outs) in self.leaves.iter().zip(out) {
            let a = f64::from(data.leaves[*i].albedo_opacity[3]);
            for f in 0..6 {
                let mut travel = DVec3::ZERO;
                travel[f / 2] = if f % 2 == 0 { 1.0 } else { -1.0 };
                let (mut sum, mut w) = ([0.0f64; 3], 0.0);
                for (facet, o) in facets.iter().zip(outs) {
                    let seen = (-facet.normal.dot(travel)).max(0.0);
                    for k in 0..3 {
                        sum[k] += seen * f64::from(o[k]);
                    }
                    w += seen;
                }
                if w > 0.0 {
                    cpu.faces[*node as usize * 6 + f] = [sum[0] / w * a, sum[1] / w * a, sum[2] / w * a, a];
                }
            }
        }
    }
}

fn main() -> anyhow::Result<()> {
    let gpu = Gpu::new(&GpuOptions { prefer_software: true, ..Default::default() })?;
    let which = std::env::args().nth(1).unwrap_or_else(|| "colour-box".into());
    let rays: usize = env("RAYS").unwrap_or(7);
    let (data, names, region_of) = scene_named(&which)?;
    let lift: Option<f64> = env("LIFT");
    let r0 = settled(&gpu, &data, balanced_cut(0))?;
    let light0 = r0.read_leaf_light()?;
    let p = r0.params();
    let march = RayMarch {
        p,
        pattern: ray_pattern(rays)?,
        lod_min: env("LOD_MIN").unwrap_or(0.0),
        lod_max: env("LOD_MAX").unwrap_or(f64::from(p.max_lod)),
        hit_leaves: std::env::var("NOLEAF").is_err(),
        cells: std::env::var("CELLS").is_ok(),
        plane_hit: std::env::var("PLANEHIT").is_ok(),
        plane_offset_m: env::<f64>("PLANE_OFFSET").unwrap_or(0.0) * f64::from(p.leaf_size_m),
        cos_weighted: std::env::var("COSW").is_ok(),
        grow: env("GROW").unwrap_or(0.0),
        steps: 0.into(),
        visits: [0.into(), 0.into()],
        bricks: 0.into(),
        hits: 0.into(),
        escaped: 0.into(),
        blank: 0.into(),
    };
    let bounces: u32 = env("BOUNCES").unwrap_or(1);
    let light_k = settled(&gpu, &data, balanced_cut(bounces))?.read_leaf_light()?;
    // The runtime's own ray march (`Settings::cone_rays`), the shell rule `CELLS=1 PLANEHIT=1
    // PLANE_OFFSET=0.25 LIFT=0.3` runs here.
    let light_gpu_rays =
        settled(&gpu, &data, Settings { cone_rays: true, ..balanced_cut(bounces) })?.read_leaf_light()?;
    // SPLAT=s: the reference's discs s times their surfels' radius (the runtime's splat scale).
    let splat = env("SPLAT").unwrap_or(Settings::preset(Quality::Balanced).splat_scale);
    let mut scene = SurfelScene::from_scene(&data, splat);
    // CLIP=1: the reference's discs cut to their leaf cells (no disc reaches into an opening).
    if std::env::var("CLIP").is_ok() {
        scene.clip_discs_to_cells(data.leaf_size_m);
    }
    let full = PathSettings::for_scene(&data);
    let f0 = scene.leaf_radiance(&data, 256, &PathSettings { max_bounces: 0, ..full }, 2);
    let fk = scene.leaf_radiance(&data, 256, &PathSettings { max_bounces: bounces, ..full }, 3);
    let surface: Vec<bool> = (0..data.leaves.len()).map(|i| on_surface(&data, i)).collect();
    // Bounces on the CPU: each gathers over the pyramid of the one before, out = the direct light
    // (and emission) + albedo * gather, as propagate.wgsl.
    let mut cone_steps = 0u64;
    let mut run = |rays: bool, facets: Option<&FacetLight>| {
        let mut light = light0.clone();
        // Per leaf of several facets, per facet: its outgoing light (FACETS).
        let mut facet_out: Vec<Vec<[f32; 4]>> = facets
            .map(|f| f.leaves.iter().map(|(_, _, per)| per.iter().map(|x| x.direct).collect()).collect())
            .unwrap_or_default();
        for _ in 0..bounces {
            let mut cpu = CpuScene::mip(&data, &light);
            if let Some(f) = facets {
                f.apply(&data, &mut cpu, &facet_out);
            }
            let mut gather = |cpu: &CpuScene<'_>, i: usize| {
                if rays {
                    cpu.gather_with(&p, i, |o, d, n, rise| {
                        // LIFT=k: the rays start k leaves off the surface instead of the cones' lift.
                        let o = lift.map_or(o, |k| o - n * (rise[0] - k * f64::from(data.leaf_size_m)));
                        march.cone(cpu, o, d, n)
                    })
                } else {
                    cpu.gather_with(&p, i, |o, d, _, rise| {
                        cpu.trace_cone_observed(&p, o, d, rise, |_| cone_steps += 1)
                    })
                }
            };
            let mut next = light0.clone();
            for (i, leaf) in data.leaves.iter().enumerate() {
                if !surface[i] {
                    continue;
                }
                let g = gather(&cpu, i);
                for k in 0..3 {
                    next[i].gather[k] = g[k] as f32;
                    next[i].out[k] = light0[i].out[k] + leaf.albedo_opacity[k] * g[k] as f32;
                }
            }
            if let Some(f) = facets {
                for ((i, _, per), outs) in f.leaves.iter().zip(facet_out.iter_mut()) {
                    let albedo = data.leaves[*i].albedo_opacity;
                    let (mut mean, mut weight) = (DVec3::ZERO, 0.0);
                    for (k, (facet, o)) in per.iter().zip(outs.iter_mut()).enumerate() {
                        let g = if f.own_gather {
                            let view = CpuScene { scene: &f.scenes[k], faces: cpu.faces.clone() };
                            gather(&view, *i)
                        } else {
                            DVec3::from_array(std::array::from_fn(|c| f64::from(next[*i].gather[c])))
                        };
                        for c in 0..3 {
                            o[c] = facet.direct[c] + albedo[c] * g[c] as f32;
                        }
                        mean += g * facet.surfels;
                        weight += facet.surfels;
                    }
                    let g = mean / weight;
                    for c in 0..3 {
                        next[*i].gather[c] = g[c] as f32;
                        next[*i].out[c] = light0[*i].out[c] + albedo[c] * g[c] as f32;
                    }
                }
            }
            light = next;
        }
        light
    };
    let cone_light = run(false, None);
    let ray_light = run(true, None);
    if let Some(mode) = env::<u32>("FACETS") {
        let facets = FacetLight::new(&gpu, &data, mode >= 2)?;
        let cones = run(false, Some(&facets));
        let rays = run(true, Some(&facets));
        let (mut c, mut r, mut g) = (vec![0.0; names.len()], vec![0.0; names.len()], vec![0.0; names.len()]);
        for (i, leaf) in data.leaves.iter().enumerate() {
            let (Some(a), Some(b)) = (&f0[i], &fk[i]) else { continue };
            let Some(f) = region_of[i].filter(|_| surface[i]) else { continue };
            c[f] += lum(cones[i].shown(leaf)) - lum(light0[i].shown(leaf));
            r[f] += lum(rays[i].shown(leaf)) - lum(light0[i].shown(leaf));
            g[f] += lum(b.mean.to_array()) - lum(a.mean.to_array());
        }
        let what = if mode >= 2 { "direct light and gather" } else { "direct light" };
        println!(
            "| {} leaves of several facets, {what} per facet | {} |",
            facets.leaves.len(),
            names.join(" | ")
        );
        for (name, v) in [("CPU cones", &c), ("rays", &r)] {
            let cells: Vec<String> = (0..names.len()).map(|f| format!("{:.3}", v[f] / g[f])).collect();
            println!("| {name} | {} |", cells.join(" | "));
        }
    }
    if let Some(region) = env::<usize>("SLABS") {
        let lights = [&light_k, &cone_light, &ray_light];
        slabs(&data, &region_of, region, &light0, lights, (&f0, &fk));
    }
    let k = names.len();
    let (mut gpu_sum, mut cone_sum, mut ray_sum, mut ref_sum) =
        (vec![0.0; k], vec![0.0; k], vec![0.0; k], vec![0.0; k]);
    let mut gpu_ray_sum = vec![0.0; k];
    for (i, leaf) in data.leaves.iter().enumerate() {
        let (Some(a), Some(b)) = (&f0[i], &fk[i]) else { continue };
        let Some(f) = region_of[i].filter(|_| surface[i]) else { continue };
        let added = |l: &[LeafLightGpu]| lum(l[i].shown(leaf)) - lum(light0[i].shown(leaf));
        gpu_sum[f] += added(&light_k);
        gpu_ray_sum[f] += added(&light_gpu_rays);
        cone_sum[f] += added(&cone_light);
        ray_sum[f] += added(&ray_light);
        ref_sum[f] += lum(b.mean.to_array()) - lum(a.mean.to_array());
    }
    if std::env::var("BY_FACES").is_ok() {
        by_faces(&data, &names, &region_of, &surface, &light0, [&light_k, &light_gpu_rays], (&f0, &fk));
    }
    println!("| {which}, {rays} rays, {bounces} bounces | {} |", names.join(" | "));
    let rows =
        [("GPU cones", &gpu_sum), ("CPU cones", &cone_sum), ("rays", &ray_sum), ("GPU rays", &gpu_ray_sum)];
    for (name, sums) in rows {
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
    if std::env::var("CELLS").is_ok() {
        eprintln!(
            "a walk crossing empty nodes whole: {} visits with nodes of 4 leaves, {} with nodes of 8; {} bricks of 4x4x4 leaves entered",
            march.visits[0].get(),
            march.visits[1].get(),
            march.bricks.get()
        );
    }
    Ok(())
}
