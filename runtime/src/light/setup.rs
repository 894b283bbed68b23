//! Many lights (show caves hang hundreds of lamps): which lights get shadow maps, how far each one
//! reaches, and the light grid that lets inject and shade visit only the lights in range.
//!
//! - Budget: the `shadowed_lights` brightest lights (largest radiant intensity) get shadow maps
//!   and are evaluated per pixel; the rest are evaluated once per leaf by inject, shadowed by a
//!   cone traced through the SVO toward the light (Crassin et al. 2011's soft shadow cone) or not
//!   at all, and shade interpolates their light over leaves like the gathered light. Their cost
//!   per frame is then independent of how many there are.
//! - Range: a point light's irradiance falls as I / d^2, so past `sqrt(I / cutoff)` it adds less
//!   than `cutoff` W/m^2 anywhere; it is dropped there (a hard cut, so inside the range the light
//!   is exact).
//! - Grid: a uniform grid over the scene (at most 32 cells per axis, coarser if the lists would
//!   pass 4M entries) holds, per cell, the lights whose range sphere touches it. Built on the CPU
//!   when the lights change; cost then grows with the lights in range, not all lights.

use glam::{Mat4, UVec3, Vec3};

use crate::gpu::types::{LightGpu, LightShadow};
use crate::light::profile;
use crate::passes::shadow::Face;
use crate::scene::data::{SceneData, SceneLight};
use crate::settings::{Settings, ShadowFallback};

/// The scene's lights as the GPU takes them: lights with shadow maps first (every light-grid cell
/// then lists them before the rest, and shade, which evaluates only those per pixel, stops at the
/// first one without), their shadow-atlas faces, and the light grid.
#[derive(Clone, Debug)]
pub(crate) struct LightSetup {
    pub(crate) lights: Vec<LightGpu>,
    pub(crate) faces: Vec<Face>,
    /// Profiles' records (light/profile.rs), after the faces' matrices in the lights buffer;
    /// a profiled light's `params.x` is its block's record index there.
    pub(crate) profiles: Vec<LightGpu>,
    /// Lights with shadow maps; the others are lit per leaf by inject.
    pub(crate) shadowed: usize,
    /// Whether each scene light (in the scene's order) has a shadow map.
    pub(crate) mapped: Vec<bool>,
    /// Each light with a map: its index in `lights`, its first face and how many it has.
    face_blocks: Vec<(usize, usize, usize)>,
    /// Each light with a profile: its index in `lights` and where its block starts in `profiles`.
    profiled: Vec<(usize, usize)>,
    pub(crate) point_lights: usize,
    pub(crate) spot_lights: usize,
    pub(crate) grid: LightGrid,
}

impl LightSetup {
    /// `near_m` / `far_m`: the shadow projections' depth range; the grid covers `grid_lo_m ..
    /// grid_hi_m`.
    pub(crate) fn new(
        scene: &SceneData,
        settings: &Settings,
        near_m: f32,
        far_m: f32,
        grid_lo_m: Vec3,
        grid_hi_m: Vec3,
    ) -> Self {
        // Shadow maps for the brightest lights within the budget; the rest are lit at leaf
        // resolution by inject with the fallback's shadows.
        let mut mapped = vec![false; scene.lights.len()];
        if settings.shadows {
            for &k in brightest_first(&scene.lights).iter().take(settings.shadowed_lights as usize) {
                mapped[k] = true;
            }
        }
        let fallback = match settings.shadow_fallback {
            ShadowFallback::Cone => LightShadow::Cone,
            ShadowFallback::None => LightShadow::None,
        };
        let order = (0..scene.lights.len())
            .filter(|&k| mapped[k])
            .chain((0..scene.lights.len()).filter(|&k| !mapped[k]));
        let (mut lights, mut faces, mut profiles) = (Vec::new(), Vec::new(), Vec::new());
        let mut profiled: Vec<(usize, usize)> = Vec::new();
        let mut face_blocks = Vec::new();
        for k in order {
            let (l, has_map) = (&scene.lights[k], mapped[k]);
            let first = if has_map { faces.len() as f32 } else { -1.0 };
            if has_map {
                face_blocks.push((lights.len(), faces.len(), if l.spot.is_some() { 1 } else { 6 }));
            }
            // Without shadows at all every light is shaded per pixel, unshadowed.
            let how = if has_map || !settings.shadows { LightShadow::Map } else { fallback }.encode();
            let range = range_m(l.intensity_w_sr, settings.light_cutoff_w_m2);
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
                            let proj = Mat4::perspective_rh(std::f32::consts::FRAC_PI_2, 1.0, near_m, far_m);
                            let view_proj = proj * Mat4::look_at_rh(p, p + fwd, up);
                            faces.push(Face { view_proj, eye_m: p, proj_scale: 1.0, range_m: range });
                        }
                    }
                    let (kind, aim) = match &l.profile {
                        Some(prof) => {
                            profiled.push((lights.len(), profiles.len()));
                            profiles.extend(profile::records(prof));
                            (profile::KIND_PROFILED, Vec3::from_array(prof.frame().0))
                        }
                        None => (0.0, Vec3::NEG_Z),
                    };
                    lights.push(LightGpu {
                        position_kind: p.extend(kind).to_array(),
                        intensity_layer: l.intensity_w_sr.extend(first).to_array(),
                        direction_cos_outer: aim.extend(-1.0).to_array(),
                        params: [-1.0, range.min(f32::MAX), how, settings.light_cutoff_w_m2],
                    });
                }
                Some(s) => {
                    let outer = s.outer_angle_rad.clamp(1e-3, 1.48);
                    let inner = s.inner_angle_rad.clamp(0.0, outer);
                    if has_map {
                        let up = if s.direction.cross(Vec3::Z).length() < 1e-3 { Vec3::Y } else { Vec3::Z };
                        let proj = Mat4::perspective_rh(2.0 * outer, 1.0, near_m, far_m);
                        let view_proj = proj * Mat4::look_at_rh(p, p + s.direction, up);
                        faces.push(Face {
                            view_proj,
                            eye_m: p,
                            proj_scale: 1.0 / outer.tan(),
                            range_m: range,
                        });
                    }
                    lights.push(LightGpu {
                        position_kind: p.extend(1.0).to_array(),
                        intensity_layer: l.intensity_w_sr.extend(first).to_array(),
                        direction_cos_outer: s.direction.extend(outer.cos()).to_array(),
                        params: [inner.cos(), range.min(f32::MAX), how, settings.light_cutoff_w_m2],
                    });
                }
            }
        }
        let grid = LightGrid::build(
            grid_lo_m,
            grid_hi_m,
            &lights
                .iter()
                .map(|l| (Vec3::from_slice(&l.position_kind[..3]), l.params[1]))
                .collect::<Vec<_>>(),
        );
        let point_lights = scene.lights.iter().filter(|l| l.spot.is_none()).count();
        let mut setup = LightSetup {
            lights,
            faces,
            profiles,
            shadowed: mapped.iter().filter(|&&m| m).count(),
            mapped,
            face_blocks,
            profiled,
            point_lights,
            spot_lights: scene.lights.len() - point_lights,
            grid,
        };
        setup.index_profiles();
        setup
    }

    /// A profile block's index counts the lights and the faces' matrices before it.
    fn index_profiles(&mut self) {
        for &(light, at) in &self.profiled {
            self.lights[light].params[0] = (self.lights.len() + self.faces.len() + at) as f32;
        }
    }

    /// The lights buffer's records (lights.wgsl): the lights, each shadow face's matrix (one
    /// 64-byte record), then the profiles.
    pub(crate) fn records(&self) -> Vec<LightGpu> {
        let mut out = self.lights.clone();
        out.extend(self.faces.iter().map(|f| {
            let [c0, c1, c2, c3] = f.view_proj.to_cols_array_2d();
            LightGpu { position_kind: c0, intensity_layer: c1, direction_cos_outer: c2, params: c3 }
        }));
        out.extend_from_slice(&self.profiles);
        out
    }

    /// Lays the faces out in an atlas of `capacity` faces so that a light whose faces are the
    /// same as `old`'s keep the slots they had there (an edit then draws only the faces of the
    /// lights it changed, not those of every light after them); the other lights take the first
    /// free run of slots. Slots no light uses are holes ([`Face::hole`]). Returns false, with
    /// `self` unchanged, where the faces do not fit.
    pub(crate) fn keep_slots(&mut self, old: &[Face], capacity: usize) -> bool {
        let mut slot_of: Vec<Option<usize>> = vec![None; self.face_blocks.len()];
        let mut used = vec![false; capacity];
        for (b, &(_, first, n)) in self.face_blocks.iter().enumerate() {
            let want = &self.faces[first..first + n];
            let start = (0..old.len().saturating_sub(n - 1).min(capacity.saturating_sub(n - 1)))
                .find(|&s| old[s..s + n] == *want && used[s..s + n].iter().all(|u| !u));
            if let Some(s) = start {
                used[s..s + n].fill(true);
                slot_of[b] = Some(s);
            }
        }
        for (b, &(_, _, n)) in self.face_blocks.iter().enumerate() {
            if slot_of[b].is_some() {
                continue;
            }
            let Some(s) = (0..capacity.saturating_sub(n - 1)).find(|&s| used[s..s + n].iter().all(|u| !u))
            else {
                return false;
            };
            used[s..s + n].fill(true);
            slot_of[b] = Some(s);
        }
        let len = used.iter().rposition(|&u| u).map_or(0, |i| i + 1);
        let mut faces = vec![Face::hole(); len];
        let blocks = self.face_blocks.clone();
        for (b, &(light, first, n)) in blocks.iter().enumerate() {
            let s = slot_of[b].unwrap_or(first);
            faces[s..s + n].copy_from_slice(&self.faces[first..first + n]);
            self.lights[light].intensity_layer[3] = s as f32;
            self.face_blocks[b].1 = s;
        }
        self.faces = faces;
        self.index_profiles();
        true
    }
}

/// Most cells per grid axis.
pub(crate) const GRID_MAX_DIM: u32 = 32;
/// Most light indices over all cells before the grid is made coarser.
pub(crate) const GRID_MAX_ENTRIES: usize = 1 << 22;

/// Distance past which a light of radiant intensity `intensity_w_sr` gives less than
/// `cutoff_w_m2` of irradiance; infinite for a zero cutoff.
pub(crate) fn range_m(intensity_w_sr: Vec3, cutoff_w_m2: f32) -> f32 {
    if cutoff_w_m2 > 0.0 {
        (intensity_w_sr.max_element().max(0.0) / cutoff_w_m2).sqrt()
    } else {
        f32::INFINITY
    }
}

/// Light indices, brightest first (largest channel of the radiant intensity; ties keep the
/// package order, so the choice is deterministic).
pub(crate) fn brightest_first(lights: &[SceneLight]) -> Vec<usize> {
    let mut order: Vec<usize> = (0..lights.len()).collect();
    order.sort_by(|&a, &b| {
        let (ia, ib) = (lights[a].intensity_w_sr.max_element(), lights[b].intensity_w_sr.max_element());
        ib.total_cmp(&ia).then(a.cmp(&b))
    });
    order
}

/// Per-cell light lists over a uniform grid. `words` is what the GPU binds: `cells + 1` offsets
/// (absolute word indices, cell c's lights are `words[words[c]..words[c + 1]]`), then the lists.
#[derive(Clone, Debug, PartialEq)]
pub(crate) struct LightGrid {
    pub(crate) min_m: Vec3,
    pub(crate) cell_m: f32,
    pub(crate) dims: UVec3,
    pub(crate) words: Vec<u32>,
}

impl LightGrid {
    /// The grid over the box `lo_m..hi_m` for lights at `position_m` reaching `range_m`.
    pub(crate) fn build(lo_m: Vec3, hi_m: Vec3, lights: &[(Vec3, f32)]) -> Self {
        let extent = (hi_m - lo_m).max(Vec3::splat(1e-3));
        let mut max_dim = GRID_MAX_DIM;
        loop {
            let cell_m = extent.max_element() / max_dim as f32;
            let dims = (extent / cell_m).ceil().as_uvec3().clamp(UVec3::ONE, UVec3::splat(max_dim));
            let cells = (dims.x * dims.y * dims.z) as usize;
            let mut lists: Vec<Vec<u32>> = vec![Vec::new(); cells];
            let mut entries = 0usize;
            let mut over = false;
            'lights: for (k, &(p, r)) in lights.iter().enumerate() {
                // Cell range of the sphere's bounding box, then the exact sphere-box test.
                let (a, b) = if r.is_finite() {
                    let a = ((p - r - lo_m) / cell_m).floor();
                    let b = ((p + r - lo_m) / cell_m).floor();
                    (a, b)
                } else {
                    (Vec3::ZERO, (dims - 1).as_vec3())
                };
                let top = (dims - 1).as_vec3();
                if (b.cmplt(Vec3::ZERO)).any() || (a.cmpgt(top)).any() {
                    continue;
                }
                let (a, b) = (a.clamp(Vec3::ZERO, top).as_uvec3(), b.clamp(Vec3::ZERO, top).as_uvec3());
                for z in a.z..=b.z {
                    for y in a.y..=b.y {
                        for x in a.x..=b.x {
                            let c_lo = lo_m + UVec3::new(x, y, z).as_vec3() * cell_m;
                            let nearest = p.clamp(c_lo, c_lo + cell_m);
                            if r.is_finite() && nearest.distance_squared(p) > r * r {
                                continue;
                            }
                            lists[(x + dims.x * (y + dims.y * z)) as usize].push(k as u32);
                            entries += 1;
                            if entries > GRID_MAX_ENTRIES && max_dim > 1 {
                                over = true;
                                break 'lights;
                            }
                        }
                    }
                }
            }
            if over {
                max_dim /= 2;
                continue;
            }
            let mut words = Vec::with_capacity(cells + 1 + entries);
            let mut at = (cells + 1) as u32;
            for l in &lists {
                words.push(at);
                at += l.len() as u32;
            }
            words.push(at);
            for l in &lists {
                words.extend_from_slice(l);
            }
            return Self { min_m: lo_m, cell_m, dims, words };
        }
    }

    pub(crate) fn cells(&self) -> usize {
        (self.dims.x * self.dims.y * self.dims.z) as usize
    }

    /// The lights listed for the cell holding `p_m` (clamped into the grid), as the GPU reads it.
    #[cfg(test)]
    fn lights_at(&self, p_m: Vec3) -> &[u32] {
        let c = ((p_m - self.min_m) / self.cell_m)
            .floor()
            .clamp(Vec3::ZERO, (self.dims - 1).as_vec3())
            .as_uvec3();
        let i = (c.x + self.dims.x * (c.y + self.dims.y * c.z)) as usize;
        &self.words[self.words[i] as usize..self.words[i + 1] as usize]
    }

    /// Mean and largest number of lights per cell.
    pub(crate) fn occupancy(&self) -> (f32, u32) {
        let cells = self.cells();
        let counts = (0..cells).map(|i| self.words[i + 1] - self.words[i]);
        let max = counts.clone().max().unwrap_or(0);
        let total: u64 = counts.map(u64::from).sum();
        (total as f32 / cells.max(1) as f32, max)
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn lcg(seed: &mut u64) -> f32 {
        *seed = seed.wrapping_mul(6364136223846793005).wrapping_add(1442695040888963407);
        (*seed >> 40) as f32 / (1u64 << 24) as f32
    }

    #[test]
    fn every_light_in_range_of_a_point_is_in_its_cell() {
        let mut s = 9u64;
        let lo = Vec3::new(-3.0, 1.0, -0.5);
        let hi = Vec3::new(40.0, 12.0, 7.0);
        let lights: Vec<(Vec3, f32)> = (0..300)
            .map(|_| {
                let p = lo + (hi - lo) * Vec3::new(lcg(&mut s), lcg(&mut s), lcg(&mut s)) * 1.2 - 2.0;
                (p, 0.5 + 6.0 * lcg(&mut s))
            })
            .collect();
        let grid = LightGrid::build(lo, hi, &lights);
        assert!(grid.dims.max_element() <= GRID_MAX_DIM && grid.dims.min_element() >= 1);
        let (mean, max) = grid.occupancy();
        assert!(mean < 300.0 * 0.5, "culling must drop most lights per cell: mean {mean}, max {max}");
        for _ in 0..5000 {
            let p = lo + (hi - lo) * Vec3::new(lcg(&mut s), lcg(&mut s), lcg(&mut s));
            let listed = grid.lights_at(p);
            for (k, &(q, r)) in lights.iter().enumerate() {
                if p.distance(q) <= r {
                    assert!(listed.contains(&(k as u32)), "light {k} reaches {p} but is not listed");
                }
            }
        }
    }

    #[test]
    fn infinite_ranges_list_every_light_everywhere_and_the_grid_stays_bounded() {
        let lights: Vec<(Vec3, f32)> =
            (0..5000).map(|i| (Vec3::splat(i as f32 * 0.01), f32::INFINITY)).collect();
        let grid = LightGrid::build(Vec3::ZERO, Vec3::splat(50.0), &lights);
        assert!(grid.words.len() <= GRID_MAX_ENTRIES + grid.cells() + 1 + lights.len());
        assert_eq!(grid.lights_at(Vec3::splat(49.0)).len(), 5000);
        assert_eq!(grid.lights_at(Vec3::splat(-10.0)).len(), 5000, "points outside clamp into the grid");
    }

    fn lamps(xs: &[f32], spot_at: Option<usize>) -> SceneData {
        let lights = (xs.iter().enumerate())
            .map(|(k, &x)| SceneLight {
                name: format!("l{k}"),
                position_m: Vec3::new(x, 1.0, 1.0),
                intensity_w_sr: Vec3::splat(x),
                spot: (spot_at == Some(k)).then_some(crate::scene::data::Spot {
                    direction: Vec3::NEG_Z,
                    inner_angle_rad: 0.3,
                    outer_angle_rad: 0.5,
                }),
                profile: None,
            })
            .collect();
        SceneData { lights, ..Default::default() }
    }

    fn setup(scene: &SceneData) -> LightSetup {
        LightSetup::new(scene, &Settings::default(), 0.01, 100.0, Vec3::ZERO, Vec3::splat(10.0))
    }

    #[test]
    fn an_edit_keeps_the_atlas_slots_of_the_lights_it_did_not_change() {
        let before = setup(&lamps(&[1.0, 2.0, 3.0], Some(1)));
        assert_eq!(before.faces.len(), 13);
        // The first lamp deleted: the spot and the last lamp keep their slots (6 and 7..13), and
        // slots 0..6 are holes that nothing draws.
        let mut after = setup(&lamps(&[2.0, 3.0], Some(0)));
        let mut faces = after.faces.clone();
        assert!(after.keep_slots(&before.faces, 19));
        assert_eq!(after.faces.len(), 13);
        assert!(after.faces[..6].iter().all(Face::is_hole));
        assert_eq!(after.faces[6..], before.faces[6..]);
        assert_eq!(after.lights.iter().map(|l| l.intensity_layer[3]).collect::<Vec<_>>(), [6.0, 7.0]);
        // A point lamp added takes the first free run of six: the holes.
        let mut more = setup(&lamps(&[2.0, 3.0, 5.0], Some(0)));
        assert!(more.keep_slots(&after.faces, 13));
        assert!(more.faces[..6].iter().all(|f| !f.is_hole()) && more.faces[6..] == before.faces[6..]);
        // Too little room: false, the setup unchanged.
        faces.truncate(7);
        let mut big = setup(&lamps(&[7.0, 8.0, 9.0], None));
        let unchanged = big.faces.clone();
        assert!(!big.keep_slots(&faces, 13));
        assert_eq!(big.faces, unchanged);
        let records = more.records();
        assert_eq!(records.len(), more.lights.len() + more.faces.len() + more.profiles.len());
    }

    #[test]
    fn range_follows_the_inverse_square_law() {
        let r = range_m(Vec3::new(4.0, 1.0, 0.0), 1e-2);
        assert!((4.0 / (r * r) - 1e-2).abs() < 1e-6);
        assert!(range_m(Vec3::ONE, 0.0).is_infinite());
    }
}
