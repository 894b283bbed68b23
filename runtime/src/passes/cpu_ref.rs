//! CPU reference of the mip and cone-gather passes: the same SVO walk, anisotropic compositing,
//! quadrilinear sampling and cone marching as shaders/svo.wgsl, cone.wgsl / mip.wgsl / propagate.wgsl, written
//! plainly in f64 so the GPU results can be checked against it on small hand-built SVOs; and the
//! gather cones as rays (shaders/cone_rays.wgsl).

use glam::{DVec3, IVec3, Vec3};

use crate::gpu::types::{LeafLightGpu, Params, cone_rays as rays};
use crate::scene::data::SceneData;

/// Closure of a cone that left the scene nearly opaque (`close_cone` in shaders/cone.wgsl): its
/// missing share filled with `last`, the colour of the matter it was crossing.
pub(crate) fn close_cone(acc: [f64; 4], last: [f64; 3]) -> [f64; 4] {
    const CLOSE_LO: f64 = 0.8;
    const CLOSE_HI: f64 = 0.95;
    if acc[3] <= 1e-6 {
        return acc;
    }
    let x = ((acc[3] - CLOSE_LO) / (CLOSE_HI - CLOSE_LO)).clamp(0.0, 1.0);
    let s = x * x * (3.0 - 2.0 * x);
    let fill = s * (1.0 - acc[3]);
    [acc[0] + fill * last[0], acc[1] + fill * last[1], acc[2] + fill * last[2], acc[3] + fill]
}

/// A cone whose axis entered rock (`enter_rock` in shaders/cone.wgsl): it ends opaque; what is hidden
/// looks like `last`, the colour of the wall it was crossing (or, having met nothing, like the
/// rock cell's own filtered radiance `s`).
pub(crate) fn enter_rock(acc: [f64; 4], s: [f64; 4], last: [f64; 3]) -> [f64; 4] {
    let behind = if acc[3] <= 1e-6 && s[3] > 1e-6 { [s[0] / s[3], s[1] / s[3], s[2] / s[3]] } else { last };
    let rest = 1.0 - acc[3];
    [acc[0] + rest * behind[0], acc[1] + rest * behind[1], acc[2] + rest * behind[2], 1.0]
}

/// One step of [`CpuScene::trace_cone_observed`]'s march.
#[derive(Clone, Copy, Debug)]
pub enum MarchStep {
    /// A sample at `t_m` along the axis, of a footprint `diameter_m` wide read at voxel edge
    /// `edge_m`: its premultiplied radiance and opacity for the step, and the cone's after it.
    Sample { t_m: f64, diameter_m: f64, edge_m: f64, step: [f64; 4], acc: [f64; 4] },
    /// The axis entered rock at `t_m`: the cone ended with `acc`, what it had not seen filled with
    /// `last`.
    Rock { t_m: f64, last: [f64; 3], acc: [f64; 4] },
}

/// `PLANE_CLEAR` and `SAMPLE_EDGE` in shaders/cone.wgsl.
const PLANE_CLEAR: f64 = 2.0 / 3.0;
const SAMPLE_EDGE: f64 = 0.5;

/// The scene plus a radiance pyramid.
#[derive(Debug)]
pub struct CpuScene<'a> {
    pub scene: &'a SceneData,
    /// Six values per node, as in the GPU `faces` buffer.
    pub faces: Vec<[f64; 4]>,
}

/// The xyz of a `Params` vec4, in f64.
fn xyz(v: [f32; 4]) -> DVec3 {
    DVec3::new(v[0].into(), v[1].into(), v[2].into())
}

/// `cone_left_matter` in shaders/svo.wgsl: whether the ball of `radius_leaf` about `q_leaf` lies
/// wholly outside the box of the matter.
fn left_matter(p: &Params, q_leaf: DVec3, radius_leaf: f64) -> bool {
    let (lo, hi) = (xyz(p.occupied_min_leaf), xyz(p.occupied_max_leaf));
    let gap = (lo - q_leaf).max(q_leaf - hi).max(DVec3::ZERO);
    gap.length_squared() > radius_leaf * radius_leaf
}

fn add(a: [f64; 4], b: [f64; 4], wb: f64) -> [f64; 4] {
    [a[0] + wb * b[0], a[1] + wb * b[1], a[2] + wb * b[2], a[3] + wb * b[3]]
}

impl<'a> CpuScene<'a> {
    /// Builds the pyramid from each leaf's outgoing radiance.
    pub fn mip(scene: &'a SceneData, light: &[LeafLightGpu]) -> Self {
        let mut faces = vec![[0.0f64; 4]; scene.nodes.len() * 6];
        let (order, ranges) = scene.nodes_by_height();
        for r in &ranges {
            for &n in &order[r.first as usize..(r.first + r.count) as usize] {
                let node = scene.nodes[n as usize];
                if r.height == 0 {
                    let leaf = node.first_child as usize;
                    let a = f64::from(scene.leaves[leaf].albedo_opacity[3]);
                    let o = light[leaf].out;
                    let v = [f64::from(o[0]) * a, f64::from(o[1]) * a, f64::from(o[2]) * a, a];
                    for f in 0..6 {
                        faces[n as usize * 6 + f] = v;
                    }
                    continue;
                }
                let mask = node.child_mask();
                let child = |o: u32, f: usize| -> [f64; 4] {
                    if (mask >> o) & 1 == 0 {
                        return [0.0; 4];
                    }
                    let c = node.first_child + (mask & ((1 << o) - 1)).count_ones();
                    faces[c as usize * 6 + f]
                };
                let mut values = [[0.0f64; 4]; 6];
                for (f, value) in values.iter_mut().enumerate() {
                    let bit = 1u32 << (f / 2);
                    let positive = f % 2 == 0;
                    let mut sum = [0.0; 4];
                    for o in (0..8u32).filter(|o| o & bit == 0) {
                        let (lo, hi) = (child(o, f), child(o | bit, f));
                        let (front, back) = if positive { (lo, hi) } else { (hi, lo) };
                        sum = add(sum, add(front, back, 1.0 - front[3]), 1.0);
                    }
                    *value = sum.map(|v| v * 0.25);
                }
                faces[n as usize * 6..n as usize * 6 + 6].copy_from_slice(&values);
            }
        }
        Self { scene, faces }
    }

    fn find_tile(&self, v_leaf: IVec3) -> Option<usize> {
        self.scene.tile_of(v_leaf)
    }

    /// Global node index of voxel `v` at `lod`, as `find_node` in shaders/svo.wgsl.
    pub fn find_node(&self, v: IVec3, lod: u32) -> Option<u32> {
        let v_leaf = v << lod as i32;
        let tile = self.scene.tiles[self.find_tile(v_leaf)?];
        if lod > tile.depth {
            return None;
        }
        let l = lod.max(tile.leaf_lod);
        let levels = tile.depth - l;
        let local = (v_leaf - IVec3::from_array(tile.origin_leaf)) >> l as i32;
        let mut n = tile.node_offset;
        for level in 0..levels {
            let b = levels - 1 - level;
            let o = ((local.x >> b) & 1) | ((local.y >> b) & 1) << 1 | ((local.z >> b) & 1) << 2;
            let node = self.scene.nodes[n as usize];
            let mask = node.child_mask();
            if (mask >> o) & 1 == 0 {
                return None;
            }
            n = node.first_child + (mask & ((1 << o) - 1)).count_ones();
        }
        Some(n)
    }

    fn directional(&self, n: u32, dir: DVec3) -> [f64; 4] {
        let base = n as usize * 6;
        let w = dir * dir;
        let fx = self.faces[base + if dir.x >= 0.0 { 0 } else { 1 }];
        let fy = self.faces[base + if dir.y >= 0.0 { 2 } else { 3 }];
        let fz = self.faces[base + if dir.z >= 0.0 { 4 } else { 5 }];
        add(add(fx.map(|v| v * w.x), fy, w.y), fz, w.z)
    }

    /// How much of leaf `leaf_index` a sample at `p_leaf` sees under the cone-planes knob:
    /// shaders/svo.wgsl `leaf_plane_share`.
    fn leaf_plane_share(&self, leaf_index: u32, p_leaf: DVec3) -> f64 {
        let leaf = &self.scene.leaves[leaf_index as usize];
        let m = Vec3::from_slice(&leaf.normal_mean[..3]).as_dvec3();
        let r = m.length();
        if r < 0.3 {
            return 1.0;
        }
        let leaf_m = f64::from(self.scene.leaf_size_m);
        let edge = leaf_m.max(f64::from(leaf.center_m[3]));
        let center = Vec3::from_slice(&leaf.center_m[..3]).as_dvec3();
        let ahead = (p_leaf * leaf_m - center).dot(m / r) / edge;
        (1.0 - 2.0 * ahead).clamp(0.0, 1.0)
    }

    /// shaders/svo.wgsl `node_plane_share`: a leaf node's share, or the mean of a parent's leaves'.
    fn node_plane_share(&self, n: u32, p_leaf: DVec3) -> f64 {
        let node = self.scene.nodes[n as usize];
        let mask = node.child_mask();
        if mask == 0 {
            return self.leaf_plane_share(node.first_child, p_leaf);
        }
        let sum: f64 = (0..8u32)
            .filter(|o| (mask >> o) & 1 != 0)
            .map(|o| {
                let c = self.scene.nodes[(node.first_child + (mask & ((1 << o) - 1)).count_ones()) as usize];
                if c.child_mask() == 0 { self.leaf_plane_share(c.first_child, p_leaf) } else { 1.0 }
            })
            .sum();
        sum / f64::from(mask.count_ones())
    }

    /// Trilinear sample of level `lod` at `p_leaf` along `dir`; with `planes`, the levels up to
    /// `PLANE_LODS` as half-spaces (shaders/svo.wgsl `corner_weight`).
    pub(crate) fn sample_level(&self, p_leaf: DVec3, lod: u32, dir: DVec3, planes: bool) -> [f64; 4] {
        let u = p_leaf / f64::from(1u32 << lod) - DVec3::splat(0.5);
        let base = u.floor();
        let f = u - base;
        let i0 = base.as_ivec3();
        let mut acc = [0.0; 4];
        for c in 0..8 {
            let o = IVec3::new(c & 1, (c >> 1) & 1, (c >> 2) & 1);
            let of = o.as_dvec3();
            let w3 = (DVec3::ONE - f) * (DVec3::ONE - of) + f * of;
            let w = w3.x * w3.y * w3.z;
            if w <= 0.0 {
                continue;
            }
            if let Some(n) = self.find_node(i0 + o, lod) {
                let w = if planes && lod <= crate::gpu::types::PLANE_LODS {
                    w * self.node_plane_share(n, p_leaf)
                } else {
                    w
                };
                acc = add(acc, self.directional(n, dir), w);
            }
        }
        acc
    }

    /// Quadrilinear sample at fractional `lod`.
    pub fn sample_lod(&self, p_leaf: DVec3, lod: f64, max_lod: u32, dir: DVec3, planes: bool) -> [f64; 4] {
        let l = lod.clamp(0.0, f64::from(max_lod));
        let l0 = l.floor() as u32;
        let t = l - f64::from(l0);
        let a = self.sample_level(p_leaf, l0, dir, planes);
        if t <= 0.0 || l0 >= max_lod {
            return a;
        }
        let b = self.sample_level(p_leaf, l0 + 1, dir, planes);
        [0, 1, 2, 3].map(|k| a[k] + (b[k] - a[k]) * t)
    }

    /// One cone, as `trace_cone` in shaders/cone.wgsl: from `origin_m` along unit `dir`, the
    /// origin `rise[0]` metres above its own surface and rising `rise[1]` metres per metre.
    pub fn trace_cone(&self, p: &Params, origin_m: DVec3, dir: DVec3, rise: [f64; 2]) -> [f64; 4] {
        self.trace_cone_observed(p, origin_m, dir, rise, |_| {})
    }

    /// [`Self::trace_cone`], telling `observe` each step of the march (to see where a cone
    /// gathers its light: reference/examples/edge_cones.rs).
    pub fn trace_cone_observed(
        &self,
        p: &Params,
        origin_m: DVec3,
        dir: DVec3,
        rise: [f64; 2],
        mut observe: impl FnMut(MarchStep),
    ) -> [f64; 4] {
        let leaf = f64::from(p.leaf_size_m);
        let (lo, hi) = (xyz(p.scene_min_leaf), xyz(p.scene_max_leaf));
        let mut acc = [0.0f64; 4];
        let mut last = [0.0f64; 3];
        let mut t = leaf;
        let mut t_prev = 0.0;
        let tan_half = f64::from(p.cone_tan_half);
        let planes = p.flags & crate::gpu::types::flags::CONE_PLANES != 0;
        for _ in 0..p.max_steps {
            if t > f64::from(p.max_distance_m) {
                break;
            }
            let cell_m = leaf * f64::from(1u32 << crate::scene::rock::ROCK_LEVEL);
            let n = (((t - t_prev) / cell_m).ceil() as u32).min(64);
            for k in 1..=n {
                let tk = t_prev + (t - t_prev) * f64::from(k) / f64::from(n);
                let qk = (origin_m + dir * tk) / leaf;
                if crate::scene::rock::in_rock(&self.scene.rock, qk.floor().as_ivec3()) {
                    let d = leaf.max(2.0 * tk * tan_half);
                    let lod = ((d / leaf).log2() + 1.0).max(f64::from(crate::scene::rock::ROCK_LEVEL + 1));
                    let end = enter_rock(acc, self.sample_lod(qk, lod, p.max_lod, dir, false), last);
                    observe(MarchStep::Rock { t_m: tk, last, acc: end });
                    return end;
                }
            }
            let q = (origin_m + dir * t) / leaf;
            if q.cmplt(lo).any()
                || q.cmpgt(hi).any()
                || left_matter(p, q, leaf.max(2.0 * t * tan_half) / (2.0 * leaf))
            {
                break;
            }
            let clear = PLANE_CLEAR * (rise[0] + t * rise[1] - 0.5 * leaf);
            let diameter = leaf.max((2.0 * t * tan_half).min(clear));
            let edge = leaf.max(SAMPLE_EDGE * diameter);
            let mut s = self.sample_lod(q, (edge / leaf).log2(), p.max_lod, dir, planes);
            if s[3] > 1e-6 {
                last = [s[0] / s[3], s[1] / s[3], s[2] / s[3]];
                let ratio = diameter * f64::from(p.step_scale) / edge;
                let a = 1.0 - (1.0 - s[3].min(1.0)).max(0.0).powf(ratio);
                let k = a / s[3];
                s = [s[0] * k, s[1] * k, s[2] * k, a];
            }
            acc = add(acc, s, 1.0 - acc[3]);
            observe(MarchStep::Sample { t_m: t, diameter_m: diameter, edge_m: edge, step: s, acc });
            if acc[3] >= 0.995 {
                return [acc[0] / acc[3], acc[1] / acc[3], acc[2] / acc[3], 1.0];
            }
            t_prev = t;
            t += diameter * f64::from(p.step_scale);
        }
        close_cone(acc, last)
    }

    /// The gathered radiance of leaf `i` (irradiance / pi), as propagate.wgsl: with cones, or
    /// each cone as rays where `p.flags` has `CONE_RAYS`.
    pub(crate) fn gather(&self, p: &Params, i: usize) -> DVec3 {
        if p.flags & crate::gpu::types::flags::CONE_RAYS != 0 {
            self.gather_with(p, i, |origin, d, n, rise| self.trace_cone_rays(p, origin, d, n, rise[0]))
        } else {
            self.gather_with(p, i, |origin, d, _, rise| self.trace_cone(p, origin, d, rise))
        }
    }

    /// [`Self::gather`] with another march: `march(origin_m, dir, normal, rise)` (`normal`: the
    /// leaf's unit mean normal the cones are set around) returns a cone's premultiplied radiance
    /// and opacity as [`Self::trace_cone`] does (reference/examples try other marches over the
    /// same cone set, interleave and weights).
    pub fn gather_with(
        &self,
        p: &Params,
        i: usize,
        mut march: impl FnMut(DVec3, DVec3, DVec3, [f64; 2]) -> [f64; 4],
    ) -> DVec3 {
        let leaf = &self.scene.leaves[i];
        let mean = Vec3::from_slice(&leaf.normal_mean[..3]).as_dvec3();
        let r = mean.length();
        let n = if r < 1e-4 { DVec3::Z } else { mean / r };
        let s = if n.z >= 0.0 { 1.0 } else { -1.0 };
        let a = -1.0 / (s + n.z);
        let b = n.x * n.y * a;
        let t1 = DVec3::new(1.0 + s * n.x * n.x * a, s * b, -s * n.x);
        let t2 = DVec3::new(b, s + n.y * n.y * a, -n.y);
        let lift = f64::from(p.leaf_size_m.max(leaf.center_m[3]));
        let origin = Vec3::from_slice(&leaf.center_m[..3]).as_dvec3() + n * lift;
        let bg = DVec3::new(p.background[0].into(), p.background[1].into(), p.background[2].into());
        // The interleave angle of ndf.wgsl's `cone_interleave_rad`.
        let cell = (Vec3::from_slice(&leaf.center_m[..3]) / p.leaf_size_m).floor().as_ivec3();
        let k = if p.flags & crate::gpu::types::flags::CONE_INTERLEAVE != 0 {
            (cell.x & 1) + 2 * (cell.y & 1) + 4 * (cell.z & 1)
        } else {
            0
        };
        let phi = f64::from(k) * std::f64::consts::FRAC_PI_4;
        let (sin_phi, cos_phi) = phi.sin_cos();
        let mut g = DVec3::ZERO;
        for c in &p.cones[..p.cone_count as usize] {
            let (x, y) = (f64::from(c[0]), f64::from(c[1]));
            let (x, y) = (cos_phi * x - sin_phi * y, sin_phi * x + cos_phi * y);
            let d = (t1 * x + t2 * y + n * f64::from(c[2])).normalize();
            let s = march(origin, d, n, [lift, d.dot(n)]);
            g += f64::from(c[3]) * (DVec3::new(s[0], s[1], s[2]) + (1.0 - s[3]) * bg);
        }
        g
    }

    /// Largest error of the GPU's gathered radiance `got` against [`CpuScene::gather`] over every
    /// `step`-th surface leaf (rock interiors, with no mean normal, gather trivially), relative
    /// to the CPU value or 0.05 where that is smaller; and how many leaves were checked.
    pub fn worst_gather_error(&self, p: &Params, got: &[LeafLightGpu], step: usize) -> (f64, usize) {
        let mut worst = 0.0f64;
        let mut checked = 0;
        for i in (0..self.scene.leaves.len()).step_by(step.max(1)) {
            if self.scene.leaves[i].normal_mean[..3].iter().all(|&v| v == 0.0) {
                continue;
            }
            let want = self.gather(p, i);
            for k in 0..3 {
                worst = worst.max((f64::from(got[i].gather[k]) - want[k]).abs() / want[k].abs().max(0.05));
            }
            checked += 1;
        }
        (worst, checked)
    }
}

/// Where a ray of [`CpuScene::ray_hit`] ended.
#[derive(Clone, Copy, Debug, PartialEq)]
pub enum RayEnd {
    /// Behind a leaf's surface, in the cell entered `t_m` along the ray.
    Leaf { t_m: f64 },
    /// In rock, in the cell entered `t_m` along the ray.
    Rock { t_m: f64 },
    /// Out of the scene or past the march's distance.
    Escaped,
}

impl CpuScene<'_> {
    /// `ray_behind_leaf` in shaders/cone_rays.wgsl.
    fn ray_behind_leaf(&self, leaf_index: u32, p: &Params, p_m: DVec3) -> bool {
        let leaf = &self.scene.leaves[leaf_index as usize];
        let m = Vec3::from_slice(&leaf.normal_mean[..3]).as_dvec3();
        let r = m.length();
        let edge = f64::from(p.leaf_size_m.max(leaf.center_m[3]));
        let centre = Vec3::from_slice(&leaf.center_m[..3]).as_dvec3();
        r < 0.3 || (p_m - centre).dot(m / r) <= f64::from(rays::PLANE_OFFSET_LEAVES) * edge
    }

    /// `ray_hit` in shaders/cone_rays.wgsl: one ray from `origin_m` along unit `d` walks the leaf
    /// cells it crosses (Amanatides & Woo) until it goes behind a leaf's surface or enters rock.
    /// Every cell, one at a time: the GPU crosses empty boxes whole, and is checked against this.
    pub fn ray_hit(&self, p: &Params, origin_m: DVec3, d: DVec3) -> RayEnd {
        let leaf = f64::from(p.leaf_size_m);
        let (lo, hi) = (xyz(p.scene_min_leaf), xyz(p.scene_max_leaf));
        let t_start = leaf;
        let start = (origin_m + d * t_start) / leaf;
        let mut cell = start.floor().as_ivec3();
        let moving = d.abs().cmpgt(DVec3::splat(1e-12));
        let up = d.cmpgt(DVec3::ZERO);
        let cell_step = IVec3::select(up, IVec3::ONE, IVec3::NEG_ONE);
        let edge = (cell.as_dvec3() + DVec3::select(up, DVec3::ONE, DVec3::ZERO) - start) / d;
        let mut t_next = DVec3::select(moving, edge, DVec3::INFINITY);
        let t_cell = DVec3::select(moving, d.recip().abs(), DVec3::INFINITY);
        let mut t = t_start;
        let most = (1.732_050_8 * f64::from(p.max_distance_m) / leaf).ceil() as u32 + 4;
        for _ in 0..most {
            let q = (origin_m + d * t) / leaf;
            if t > f64::from(p.max_distance_m)
                || q.cmplt(lo).any()
                || q.cmpgt(hi).any()
                || left_matter(p, q, 0.0)
            {
                break;
            }
            let t_exit = t_start + t_next.min_element() * leaf;
            let leaf_index = self.find_node(cell, 0).map(|n| self.scene.nodes[n as usize].first_child);
            if leaf_index.is_some_and(|i| self.ray_behind_leaf(i, p, origin_m + d * t_exit)) {
                return RayEnd::Leaf { t_m: t };
            }
            if crate::scene::rock::in_rock(&self.scene.rock, cell) {
                return RayEnd::Rock { t_m: t };
            }
            let axis = if t_next.x <= t_next.y && t_next.x <= t_next.z {
                0
            } else if t_next.y <= t_next.z {
                1
            } else {
                2
            };
            t = t_start + t_next[axis] * leaf;
            cell[axis] += cell_step[axis];
            t_next[axis] += t_cell[axis];
        }
        RayEnd::Escaped
    }

    /// `ray_colour` in shaders/cone_rays.wgsl: the pyramid's colour at `at_leaf` along `d`, a
    /// trilinear sample of the level nearest the footprint `diameter_m`, coarser where it is empty.
    fn ray_colour(&self, p: &Params, at_leaf: DVec3, d: DVec3, diameter_m: f64) -> Option<[f64; 3]> {
        let lod = (0.5 * diameter_m / f64::from(p.leaf_size_m)).log2().clamp(0.0, f64::from(p.max_lod));
        for l in (lod + 0.5).floor() as u32..=p.max_lod {
            let s = self.sample_level(at_leaf, l, d, false);
            if s[3] > 1e-6 {
                return Some([s[0] / s[3], s[1] / s[3], s[2] / s[3]]);
            }
        }
        None
    }

    /// One gather cone as rays, as `trace_cone_rays` in shaders/cone_rays.wgsl: from the cone's
    /// `origin_m` (`lift_m` above its surface of unit normal `n`) along unit `dir`, premultiplied
    /// radiance and the share of its rays that met a surface.
    pub fn trace_cone_rays(
        &self,
        p: &Params,
        origin_m: DVec3,
        dir: DVec3,
        n: DVec3,
        lift_m: f64,
    ) -> [f64; 4] {
        let leaf = f64::from(p.leaf_size_m);
        let o = origin_m - n * (lift_m - f64::from(rays::LIFT_LEAVES) * leaf);
        let rock_cell_m = leaf * f64::from(1u32 << crate::scene::rock::ROCK_LEVEL);
        let tan_half = f64::from(p.cone_tan_half);
        let up = if dir.z.abs() >= 0.9 { DVec3::X } else { DVec3::Z };
        let e1 = dir.cross(up).normalize();
        let e2 = dir.cross(e1);
        let share = 1.0 / rays::PATTERN.len() as f64;
        let min_rise = f64::from(rays::MIN_RISE);
        let mut acc = [0.0f64; 4];
        for [x, y] in rays::PATTERN {
            let mut d = (dir + tan_half * (f64::from(x) * e1 + f64::from(y) * e2)).normalize();
            let rise = d.dot(n);
            if rise < min_rise {
                d = (d + n * (min_rise - rise)).normalize();
            }
            let (t, back) = match self.ray_hit(p, o, d) {
                RayEnd::Leaf { t_m } => (t_m, 0.0),
                // The surface lies in front of the rock, at most half a rock cell back.
                RayEnd::Rock { t_m } => (t_m, 0.5 * rock_cell_m),
                RayEnd::Escaped => continue,
            };
            let at = (o + d * (t - back).max(leaf)) / leaf;
            let c =
                self.ray_colour(p, at, d, (2.0 * t * tan_half * share.sqrt()).max(leaf)).unwrap_or([0.0; 3]);
            acc = add(acc, [c[0], c[1], c[2], 1.0], share);
        }
        acc
    }
}
