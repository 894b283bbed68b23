//! The CPU-side scene the passes upload: tiles, SVO nodes with global indices, leaf attributes,
//! surfels and lights, all in one *frame* whose origin is the first tile's f64 origin, so every
//! f32 the GPU sees is small (survey coordinates stay f64 until here).
//!
//! Built from a package ([`SceneData::from_package`]) or from voxels ([`SceneData::from_voxels`],
//! used by the test scenes and the reference). Several tiles are the normal case: tiles share one
//! leaf grid, and each tile's origin is an integer leaf offset from the frame origin.

use std::collections::BTreeMap;

use glam::{DVec3, IVec3, Vec3};
use grotto_format::color::srgb8_to_linear;
use grotto_format::spec::Rgba8;
use grotto_format::spec::{Surfel, SvoNode};
use grotto_format::svo::{morton_decode, morton_encode, nodes_from_leaves};
use grotto_format::{Package, SectionKind, SvoData};

use crate::error::Result;
use crate::gpu::types::{LeafGpu, MipRange, NodeGpu, SurfelGpu, TileBufferBytes, TileGpu};
use crate::scene::coarse::{COARSE_LEVELS, FAR_LEVELS};
use grotto_format::{Circuit, Light};

/// A point or spot light in frame coordinates.
#[derive(Clone, Debug, PartialEq)]
pub struct SceneLight {
    pub name: String,
    pub position_m: Vec3,
    /// Radiant intensity per channel, W / sr (`color * power / 4 pi`; spots keep the point-light
    /// intensity, so narrowing a spot does not brighten it).
    pub intensity_w_sr: Vec3,
    pub spot: Option<Spot>,
    /// How its intensity varies with direction (an IES profile, or an area light's cosine); with
    /// one, `intensity_w_sr` is the peak's.
    pub profile: Option<std::sync::Arc<grotto_format::LightProfile>>,
}

impl SceneLight {
    /// The fraction of `intensity_w_sr` sent toward unit direction `d` (from the light): the
    /// spot's smoothstep falloff (as lights.wgsl's `spot_factor`) and the profile. The GPU
    /// samples the profile on a 1 degree x 5 degree grid (light/profile.rs): the same within
    /// that grid's interpolation.
    pub fn factor_toward(&self, d: Vec3) -> f32 {
        let spot = self.spot.map_or(1.0, |s| {
            let outer = s.outer_angle_rad.clamp(1e-3, 1.48);
            let inner = s.inner_angle_rad.clamp(0.0, outer);
            let (co, ci) = (outer.cos(), inner.cos().max(outer.cos() + 1e-4));
            let t = ((d.dot(s.direction) - co) / (ci - co)).clamp(0.0, 1.0);
            t * t * (3.0 - 2.0 * t)
        });
        spot * self.profile.as_ref().map_or(1.0, |p| p.toward(d.to_array()))
    }
}

#[derive(Clone, Copy, Debug, PartialEq)]
/// A spot light's cone: its axis and the angles where it starts and ends falling off.
pub struct Spot {
    pub direction: Vec3,
    pub inner_angle_rad: f32,
    pub outer_angle_rad: f32,
}

/// Named viewpoints live with the points of interest and tours (story.rs).
pub use crate::scene::story::SceneCamera;

/// Attributes of one leaf for [`SceneData::from_voxels`].
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct VoxelLeaf {
    pub cell: IVec3,
    pub albedo: Vec3,
    pub opacity: f32,
    /// Toksvig mean normal (zero: no preferred direction).
    pub normal_mean: Vec3,
    pub emission: Vec3,
}

/// Everything the renderer uploads.
#[derive(Clone, Debug, Default)]
pub struct SceneData {
    pub name: String,
    /// World position (f64) of the frame origin.
    pub frame_origin_m: [f64; 3],
    pub leaf_size_m: f32,
    pub tiles: Vec<TileGpu>,
    pub nodes: Vec<NodeGpu>,
    pub leaves: Vec<LeafGpu>,
    pub surfels: Vec<SurfelGpu>,
    /// Each tile's surfels (a range of `surfels`, tiles in order), so the renderer's pools can
    /// keep a tile's surfels in its slot (pool.rs). Empty where the scene was put together by
    /// hand; the renderer then counts every surfel as the first tile's.
    pub tile_surfels: Vec<std::ops::Range<u32>>,
    pub lights: Vec<SceneLight>,
    pub cameras: Vec<SceneCamera>,
    /// Points of interest and guided tours (story.rs).
    pub pois: Vec<crate::scene::story::ScenePoi>,
    pub tours: Vec<crate::scene::story::SceneTour>,
    /// Environment radiance as 9 real SH coefficients (RGB, world axes, which the frame shares),
    /// scaled by the scene's environment intensity; None without an environment map.
    pub environment_sh: Option<[[f32; 3]; 9]>,
    /// Rock behind the surfaces (rock.rs).
    pub rock: crate::scene::rock::RockTable,
    /// Specular materials with a region, in slot order: surfel colour alpha `k` (1..=7) means
    /// `materials[k - 1]`, 0 diffuse. The surfels in a material's region are assigned at load.
    pub materials: Vec<SceneMaterial>,
    /// The environment's GGX-prefiltered mip chain, decoded from BC6H; None without one.
    pub env_chain: Option<EnvChain>,
    /// The last light is a headlamp the render job added because the scene had no light
    /// (framing.rs); the plan says so.
    pub headlamp: bool,
    /// The package's scans by index (`SurfelGpu::scan`), for the scan view's legend.
    pub scan_names: Vec<String>,
    /// The lights before their circuits were switched, where there are circuits to switch (the
    /// package's, or a lighting file's: scene/lighting.rs): `lights` is made from it.
    pub lighting: Option<Relight>,
    /// Per tile (empty: the scene holds every tile), where the scene does not hold the tile's
    /// nodes, leaves and surfels because a renderer does: what it knows of the tile instead.
    /// Such a tile takes no room in `nodes`, `leaves` and `surfels` (its offsets there and its
    /// `tile_surfels` range are empty). A change of tiles reads only the tiles that change
    /// ([`SceneData::from_package_with_held`]); a scene lets go of all once a renderer holds them
    /// ([`SceneData::release_tile_data`]).
    pub absent: Vec<Option<TileSummary>>,
    /// Per tile (empty: none), a full tile whose surfels a change of tiles left in the package
    /// for the renderer to decode as it writes them (surfels.rs); its `tile_surfels` range is
    /// empty.
    pub in_package: Vec<Option<SurfelsInPackage>>,
    /// The specular materials' regions in the frame, in slot order (surfels.rs).
    pub material_regions: Vec<MaterialRegion>,
}

/// How many nodes, leaves and surfels a scene's tiles hold.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq, serde::Serialize)]
pub struct SceneCounts {
    pub nodes: usize,
    pub leaves: usize,
    pub surfels: usize,
}

/// A package's lights with a lighting file's merged in (scene/lighting.rs `merged`), as a scene takes them
/// (`SceneData::relight`) and a published page is given them (viewer.json `lighting`).
#[derive(Clone, Debug, PartialEq, serde::Serialize, serde::Deserialize)]
pub struct Relight {
    pub lights: Vec<Light>,
    pub circuits: Vec<Circuit>,
    /// The package's area lights that glow from its leaves.
    pub baked: Vec<String>,
}

/// GPU bytes of the scene-sized buffers ([`SceneData::buffer_bytes`]).
#[derive(Clone, Copy, Debug, PartialEq, Eq, serde::Serialize)]
pub struct SceneBytes {
    /// The buffers that hold tiles.
    #[serde(flatten)]
    pub tile_buffers: TileBufferBytes,
    /// The rock hash table (rock.rs).
    pub rock: u64,
    /// What the rock took as dense per-tile bit grids before (not allocated; for comparison).
    pub rock_dense_grid: u64,
}

impl SceneBytes {
    /// Everything allocated (the dense grid is not).
    pub fn total(&self) -> u64 {
        self.tile_buffers.total() + self.rock
    }
}

/// How [`SceneData::from_package_with`] loads a tile.
#[derive(Clone, Copy, Debug, PartialEq, Eq, serde::Serialize)]
#[serde(rename_all = "snake_case")]
pub enum TileMode {
    /// Every leaf and surfel, as built.
    Full,
    /// Its coarse level (coarse.rs): leaves `COARSE_LEVELS` levels up, one splat each.
    Coarse,
    /// Its far level: leaves `FAR_LEVELS` levels up (at most the tile's depth), one splat each.
    Far,
    /// Not at all.
    Skip,
}

impl TileMode {
    /// Levels above its leaves a tile of SVO depth `depth` is held at in this mode.
    pub(crate) fn leaf_lod(self, depth: u32) -> u32 {
        match self {
            Self::Full | Self::Skip => 0,
            Self::Coarse => COARSE_LEVELS.min(depth),
            Self::Far => FAR_LEVELS.min(depth),
        }
    }
}

pub use crate::scene::summary::{HeldTiles, TileKey, TileSummary};
pub(crate) use crate::scene::summary::{MAX_MATERIALS, key};
use crate::scene::summary::{albedo_max, cells_box};
use crate::scene::surfels::{MaterialRegion, SurfelsInPackage};

/// A specular material as shade uses it.
#[derive(Clone, Debug, PartialEq)]
pub struct SceneMaterial {
    pub(crate) name: String,
    /// Weight of the specular layer, 0..=1 (Liu et al.'s Ks); the diffuse layer keeps 1 - Ks F.
    pub(crate) specular: f32,
    /// GGX roughness (alpha = roughness^2).
    pub(crate) roughness: f32,
    pub(crate) ior: f32,
    /// Surfels assigned to it.
    pub surfels: usize,
}

/// Prefiltered lat-long levels stacked top to bottom in one RGBA f32 image (`width` = the first
/// level's width); `levels[k]` = (first row, width, height, roughness).
#[derive(Clone, Debug, PartialEq)]
pub struct EnvChain {
    pub(crate) width: u32,
    pub(crate) height: u32,
    pub(crate) rgba: Vec<[f32; 4]>,
    pub(crate) levels: Vec<(u32, u32, u32, f32)>,
}

/// Most levels of an environment chain shade reads.
pub(crate) const MAX_ENV_LEVELS: usize = grotto_format::spec::MAX_ENV_MIP_LEVELS;

/// Decodes environment `index`'s prefiltered BC6H chain (checked by `Package::env_chain`, whose
/// rules bound the atlas by the blocks it holds) on the CPU (bcdec_rs: not every adapter samples
/// BC6H, and the chain is small), scaled by `intensity`. None when the package has no chain.
pub(crate) fn read_env_chain(pkg: &Package, index: u32, intensity: f32) -> Result<Option<EnvChain>> {
    let Some(chain) = pkg.env_chain(index)? else { return Ok(None) };
    let (width, height) = (chain.atlas_width(), chain.atlas_height());
    let table: Vec<(u32, u32, u32, f32)> = chain
        .levels
        .iter()
        .zip(chain.level_rows())
        .map(|(l, row)| (row, l.width, l.height, l.roughness))
        .collect();
    let mut rgba = vec![[0.0f32; 4]; width as usize * height as usize];
    for (l, &(row0, w, h, _)) in chain.levels.iter().zip(&table) {
        let bw = w.div_ceil(4);
        for b in 0..l.block_count {
            let mut px = [0f32; 48];
            bcdec_rs::bc6h_float(&chain.blocks[(l.first_block + b) as usize].0, &mut px, 12, false);
            let (bx, by) = ((b % bw) * 4, (b / bw) * 4);
            for y in 0..4 {
                for x in 0..4 {
                    let (u, v) = (bx + x, by + y);
                    if u < w && v < h {
                        let k = ((y * 4 + x) * 3) as usize;
                        let c = [px[k], px[k + 1], px[k + 2]]
                            .map(|c| if c.is_finite() { c.max(0.0) * intensity } else { 0.0 });
                        rgba[((row0 + v) * width + u) as usize] = [c[0], c[1], c[2], 1.0];
                    }
                }
            }
        }
    }
    Ok(Some(EnvChain { width, height, rgba, levels: table }))
}

/// A tile's leaves in the frame (`origin_leaf`: the tile's corner in frame leaves of `leaf_m`).
/// `SvoData` has one attribute per leaf node (checked on read), so indexing cannot fail.
pub(crate) fn full_leaves(svo: &SvoData<'_>, depth: u32, origin_leaf: IVec3, leaf_m: f32) -> Vec<LeafGpu> {
    let emission = svo.emission.as_deref();
    let leaf_nodes = svo.nodes.iter().filter(|n| u32::from(n.level) == depth);
    leaf_nodes
        .enumerate()
        .map(|(li, n)| {
            let cell = morton_decode(n.morton);
            let center = (origin_leaf + IVec3::new(cell[0] as i32, cell[1] as i32, cell[2] as i32)).as_vec3()
                + Vec3::splat(0.5);
            let Rgba8(c) = svo.albedo[li];
            let ndf = svo.ndf[li];
            let e = emission.map_or([0.0; 3], |e| e[li].radiance);
            LeafGpu {
                albedo_opacity: [
                    srgb8_to_linear(c[0]),
                    srgb8_to_linear(c[1]),
                    srgb8_to_linear(c[2]),
                    svo.opacity[li],
                ],
                normal_mean: [ndf.mean[0], ndf.mean[1], ndf.mean[2], 0.0],
                center_m: (center * leaf_m).extend(0.0).to_array(),
                emission: [e[0], e[1], e[2], 0.0],
            }
        })
        .collect()
}

/// Moves each of a tile's full leaves (in SVO leaf order, `svo`'s leaf nodes) from its cell's
/// centre to the area-weighted centroid of the surfels in it, kept inside the cell. Light is then
/// evaluated, and cones start, at the surface the leaf holds, wherever the leaf grid falls: with
/// the cell's centre a wall on a cell face had its leaf light taken half a leaf off the wall and
/// its cones started half a leaf nearer to or farther from it than on a wall through the cell's
/// middle (moving a room by a fraction of a leaf changed its first bounce by 4%).
/// Leaves with no surfel (none in their cell) keep the cell's centre. Fed one surfel at a time,
/// so a tile's surfels need never be held whole.
pub(crate) struct LeafCentroids {
    /// The tile's leaves by Morton code: (code, leaf index).
    by_morton: Vec<(u64, usize)>,
    side: u64,
    sums: Vec<(DVec3, f64)>,
    /// The last surfel's leaf (its place in `by_morton`).
    at: Option<usize>,
    leaf_m: f32,
}

impl LeafCentroids {
    pub(crate) fn new(svo: &SvoData<'_>, depth: u32, leaves: usize, leaf_m: f32) -> Self {
        let mut by_morton: Vec<(u64, usize)> = svo
            .nodes
            .iter()
            .filter(|n| u32::from(n.level) == depth)
            .enumerate()
            .map(|(i, n)| (n.morton, i))
            .collect();
        // Leaves are stored in Morton order; sorting is only for a package that is not.
        if !by_morton.is_sorted() {
            by_morton.sort_unstable();
        }
        Self {
            by_morton,
            side: 1u64 << depth.min(21),
            sums: vec![(DVec3::ZERO, 0.0); leaves],
            at: None,
            leaf_m,
        }
    }

    pub(crate) fn add(&mut self, s: &Surfel) {
        let p = DVec3::from_array(s.position_tile_m.map(f64::from));
        let c = (p / f64::from(self.leaf_m)).floor();
        if !c.is_finite() || c.min_element() < 0.0 || c.max_element() >= self.side as f64 {
            return;
        }
        let m = morton_encode(c.x as u32, c.y as u32, c.z as u32);
        // Surfels are stored in Morton order too, so a surfel is mostly in the previous one's
        // leaf or the next: the search runs only when neither is.
        let by_morton = &self.by_morton;
        let found = match self.at {
            Some(k) if by_morton[k].0 == m => Some(k),
            Some(k) if by_morton.get(k + 1).is_some_and(|&(n, _)| n == m) => Some(k + 1),
            _ => by_morton.binary_search_by_key(&m, |&(k, _)| k).ok(),
        };
        let Some(k) = found else { return };
        self.at = Some(k);
        if let Some(sum) = self.sums.get_mut(by_morton[k].1) {
            let w = f64::from(s.radius_m).powi(2).max(1e-12);
            sum.0 += w * p;
            sum.1 += w;
        }
    }

    /// Each leaf with surfels to their centroid, kept inside its cell.
    pub(crate) fn move_leaves(self, leaves: &mut [LeafGpu], tile_shift_m: DVec3) {
        let leaf_m = f64::from(self.leaf_m);
        for (l, (sum, w)) in leaves.iter_mut().zip(self.sums) {
            if w <= 0.0 {
                continue;
            }
            let centre = Vec3::from_slice(&l.center_m[..3]).as_dvec3();
            let low = centre - tile_shift_m - DVec3::splat(0.5 * leaf_m);
            // Inside the cell, a hair from its faces, so the cell is still `floor(centre / leaf)`.
            let inset = 1e-3 * leaf_m;
            let local = (sum / w).clamp(low + inset, low + DVec3::splat(leaf_m - inset));
            let moved = (local + tile_shift_m).as_vec3();
            l.center_m[..3].copy_from_slice(&moved.to_array());
        }
    }
}

/// The frame every loaded scene of `pkg` shares: the corner of its first tile with an SVO (f64
/// world metres) and that tile's leaf edge; None when no tile has one.
/// From the section table alone: no tile data is read.
pub(crate) fn frame_of(pkg: &Package) -> Result<Option<([f64; 3], f64)>> {
    Ok(pkg
        .tiles()
        .find(|t| t.find(SectionKind::SvoNodes, 0).is_some_and(|s| s.raw_len > 0))
        .map(|t| (t.origin_m(), t.leaf_size_m())))
}

impl SceneData {
    /// Appends a tile's nodes down to `leaf_level` with global indices: `first_child` becomes a
    /// global node index for inner nodes and a global leaf index for the nodes at `leaf_level`
    /// (the k-th node of that level is the tile's k-th leaf). `nodes` is in the spec's
    /// breadth-first order, so the nodes down to a level are a prefix of it.
    pub(crate) fn push_nodes(
        &mut self,
        nodes: &[SvoNode],
        leaf_level: u32,
        node_offset: u32,
        leaf_offset: u32,
    ) {
        let mut leaf = leaf_offset;
        let within = |n: &&SvoNode| u32::from(n.level) <= leaf_level;
        grow_for(&mut self.nodes, nodes.iter().take_while(within).count());
        for n in nodes.iter().take_while(within) {
            let (first_child, mask) = if u32::from(n.level) == leaf_level {
                leaf += 1;
                (leaf - 1, 0)
            } else {
                (node_offset + n.first_child, n.child_mask)
            };
            self.nodes.push(NodeGpu { first_child, mask_level: u32::from(mask) | u32::from(n.level) << 8 });
        }
    }

    /// The tile whose cube holds leaf cell `v_leaf` (global leaf units), by a scan: the CPU
    /// reference's lookup, which the GPU's tile index (tile_index.rs) is tested against.
    pub(crate) fn tile_of(&self, v_leaf: IVec3) -> Option<usize> {
        self.tiles.iter().position(|t| {
            let rel = v_leaf - IVec3::from_array(t.origin_leaf);
            let size = 1i32 << t.depth;
            rel.cmpge(IVec3::ZERO).all() && rel.cmplt(IVec3::splat(size)).all()
        })
    }

    /// Frame-space bounds of all tiles in leaf units: (min, max).
    pub fn bounds_leaf(&self) -> (Vec3, Vec3) {
        let mut lo = Vec3::splat(f32::MAX);
        let mut hi = Vec3::splat(f32::MIN);
        for t in &self.tiles {
            let o = IVec3::from_array(t.origin_leaf).as_vec3();
            lo = lo.min(o);
            hi = hi.max(o + Vec3::splat((1u64 << t.depth) as f32));
        }
        if self.tiles.is_empty() { (Vec3::ZERO, Vec3::ZERO) } else { (lo, hi) }
    }

    /// Where matter is, in leaf units: the box around every leaf's cell (a coarse leaf's whole
    /// cell) and every rock brick, grown by one leaf (cones start a leaf off their surface) and
    /// cut to the tiles' cubes. A cone starts inside it, and a cone's cross-section that has left
    /// it never meets it again (both are convex), so the march stops there
    /// (`cone_left_matter` in shaders/svo.wgsl) instead of crossing the rest of the tiles' cubes,
    /// where it would only read coarse levels' blur of matter behind it. `(0, 0)` when empty.
    pub fn occupied_bounds_leaf(&self) -> (Vec3, Vec3) {
        let (mut lo, mut hi) = cells_box(self.leaf_size_m, &self.leaves)
            .unwrap_or((Vec3::splat(f32::MAX), Vec3::splat(f32::MIN)));
        for (a, b) in self.absent.iter().flatten().filter_map(|s| s.occupied_leaf) {
            (lo, hi) = (lo.min(a), hi.max(b));
        }
        if let Some((rock_lo, rock_hi)) = self.rock.bounds_leaf() {
            (lo, hi) = (lo.min(rock_lo), hi.max(rock_hi));
        }
        if lo.cmpgt(hi).any() {
            return (Vec3::ZERO, Vec3::ZERO);
        }
        let (tiles_lo, tiles_hi) = self.bounds_leaf();
        ((lo - 1.0).max(tiles_lo), (hi + 1.0).min(tiles_hi))
    }

    /// Deepest level every tile has: cones sample no coarser than this.
    pub(crate) fn max_lod(&self) -> u32 {
        self.tiles.iter().map(|t| t.depth).min().unwrap_or(0)
    }

    /// A lamp string of `n` point lights of `power_w` watts each (warm white), as show caves hang
    /// them: spread evenly over the cave's floors by farthest-point sampling of the upward-facing
    /// leaves (starting from the one nearest the scene's first light, or the first such leaf), each
    /// lamp `lift_m` above its floor leaf where that spot and the way up to it are open (no leaf
    /// within one cell, no rock). Deterministic. Fewer than `n` where the floors have fewer open
    /// spots. Used to measure how cost and error grow with the number of lights.
    pub fn lamp_string(&self, n: usize, power_w: f32, lift_m: f32) -> Vec<SceneLight> {
        let leaf = self.leaf_size_m;
        let occupied: std::collections::HashSet<IVec3> = self.leaves.iter().map(|l| l.cell(leaf)).collect();
        let open = |p: Vec3| {
            let c = (p / leaf).floor().as_ivec3();
            let near_leaf = (-1..=1)
                .any(|z| (-1..=1).any(|y| (-1..=1).any(|x| occupied.contains(&(c + IVec3::new(x, y, z))))));
            !near_leaf && !crate::scene::rock::in_rock(&self.rock, c)
        };
        let steps = (lift_m / leaf).ceil().max(1.0) as i32;
        let candidates: Vec<Vec3> = self
            .leaves
            .iter()
            .filter_map(|l| {
                let m = Vec3::from_slice(&l.normal_mean[..3]);
                let r = m.length();
                if r < 0.5 || m.z / r < 0.8 {
                    return None;
                }
                // From the cell's centre (a leaf's centre is on its surface), as before leaves
                // moved there, so the lamps measured with stay where they were.
                let base = (l.cell(leaf).as_vec3() + 0.5) * leaf;
                let lamp = base + Vec3::Z * lift_m;
                // The way up from two leaves above the floor to the lamp must be open too.
                let clear = (2..=steps).all(|k| {
                    let p = base + Vec3::Z * (lift_m * k as f32 / steps as f32);
                    !occupied.contains(&(p / leaf).floor().as_ivec3())
                });
                (clear && open(lamp)).then_some(lamp)
            })
            .collect();
        if candidates.is_empty() || n == 0 {
            return Vec::new();
        }
        let start = self
            .lights
            .first()
            .map(|l| {
                (0..candidates.len())
                    .min_by(|&a, &b| {
                        candidates[a]
                            .distance_squared(l.position_m)
                            .total_cmp(&candidates[b].distance_squared(l.position_m))
                    })
                    .unwrap_or(0)
            })
            .unwrap_or(0);
        let mut dist2 = vec![f32::INFINITY; candidates.len()];
        let mut chosen = Vec::with_capacity(n.min(candidates.len()));
        let mut next = start;
        while chosen.len() < n.min(candidates.len()) {
            chosen.push(next);
            let p = candidates[next];
            let mut best = (0usize, -1.0f32);
            for (i, (c, d)) in candidates.iter().zip(dist2.iter_mut()).enumerate() {
                *d = d.min(c.distance_squared(p));
                if *d > best.1 {
                    best = (i, *d);
                }
            }
            if best.1 <= 0.0 {
                break;
            }
            next = best.0;
        }
        let intensity = Vec3::new(1.0, 0.78, 0.55) * (power_w / (4.0 * std::f32::consts::PI));
        chosen
            .into_iter()
            .enumerate()
            .map(|(i, k)| SceneLight {
                name: format!("string-{i}"),
                position_m: candidates[k],
                intensity_w_sr: intensity,
                spot: None,
                profile: None,
            })
            .collect()
    }

    /// Whether anything lights the scene by itself: point or spot lights, emissive leaves, or an
    /// environment map.
    pub fn has_own_light(&self) -> bool {
        !self.lights.is_empty() || self.environment_sh.is_some() || self.has_emission()
    }

    /// Bytes of every GPU buffer whose size follows the scene's content (tiles, nodes, leaves,
    /// surfels, rock), as the renderer creates them (`radiance_f16`: the pyramid's precision).
    /// Lights, shadow atlas and image buffers follow the settings and are not counted.
    pub fn buffer_bytes(&self, radiance_f16: bool) -> SceneBytes {
        let len = |n: usize| n as u64;
        let counts = self.counts();
        SceneBytes {
            tile_buffers: TileBufferBytes::of(
                len(self.tiles.len()),
                len(counts.nodes),
                len(counts.leaves),
                len(counts.surfels),
                radiance_f16,
            ),
            rock: len(self.rock.words.len()) * 4,
            rock_dense_grid: crate::scene::rock::dense_grid_bytes(&self.tiles),
        }
    }

    /// GPU bytes of the tile data ([`TileBufferBytes`] summed over the tiles): what
    /// `--gpu-memory` bounds.
    pub fn tile_bytes(&self, radiance_f16: bool) -> u64 {
        self.buffer_bytes(radiance_f16).tile_buffers.total()
    }

    /// True when any leaf emits.
    pub(crate) fn has_emission(&self) -> bool {
        self.leaves.iter().any(|l| l.emission[..3].iter().any(|&e| e > 0.0))
            || self.absent.iter().flatten().any(|s| s.emission)
    }

    /// The largest finite albedo of any leaf, per channel (the bounce tail's trusted ratio).
    pub(crate) fn albedo_max(&self) -> [f32; 3] {
        let mut m = albedo_max(&self.leaves);
        for s in self.absent.iter().flatten() {
            m = std::array::from_fn(|k| m[k].max(s.albedo_max[k]));
        }
        m
    }

    /// The nodes, leaves and surfels of the tiles, held here or not.
    pub fn counts(&self) -> SceneCounts {
        let absent = self.absent.iter().flatten();
        SceneCounts {
            nodes: self.nodes.len() + absent.clone().map(|s| s.nodes() as usize).sum::<usize>(),
            leaves: self.leaves.len() + absent.clone().map(|s| s.leaves as usize).sum::<usize>(),
            surfels: self.surfels.len()
                + absent.map(|s| s.surfels as usize).sum::<usize>()
                + self.in_package.iter().flatten().map(|s| s.surfels as usize).sum::<usize>(),
        }
    }

    /// What the scene knows of tile `t` where it does not hold its data.
    pub(crate) fn absent_tile(&self, t: usize) -> Option<&TileSummary> {
        self.absent.get(t).and_then(Option::as_ref)
    }

    /// Whether the scene holds every tile's data (a renderer can be made from it).
    pub fn holds_all_tiles(&self) -> bool {
        self.absent.iter().all(Option::is_none) && self.in_package.iter().all(Option::is_none)
    }

    /// An error where some tile's data is not held here: `what` (a renderer made) needs it.
    pub(crate) fn check_held(&self, what: &'static str) -> Result<()> {
        if self.holds_all_tiles() {
            return Ok(());
        }
        Err(crate::error::Error::Internal {
            what,
            message: "the scene's tile data was let go once a renderer held it: load the scene again".into(),
        })
    }

    /// Each tile's surfels: `tile_surfels` where it covers the surfels exactly, tile after tile;
    /// else (a scene put together by hand) every surfel counted as the first tile's. Either way
    /// each surfel has one owner, so a slot holds whole tiles. The flag: the ranges were the
    /// scene's own (each tile's surfels lie in its box). A tile not held here owns an empty range.
    pub(crate) fn surfel_owners(&self) -> (Vec<std::ops::Range<u32>>, bool) {
        let n = self.surfels.len() as u32;
        let mut next = 0;
        let exact = self.tile_surfels.len() == self.tiles.len()
            && self.tile_surfels.iter().all(|r| {
                let ok = r.start == next && r.end >= r.start;
                next = r.end;
                ok
            })
            && next == n;
        if exact {
            return (self.tile_surfels.clone(), true);
        }
        ((0..self.tiles.len()).map(|t| if t == 0 { 0..n } else { n..n }).collect(), false)
    }

    /// Nodes, leaves and surfels tile `t` holds, whether the scene holds them or not (`owners`:
    /// [`SceneData::surfel_owners`]).
    pub(crate) fn tile_elements(&self, owners: &[std::ops::Range<u32>], t: usize) -> (u32, u32, u32) {
        let tile = &self.tiles[t];
        let surfels = match (self.absent_tile(t), self.in_package(t)) {
            (Some(s), _) => s.surfels,
            (None, Some(left)) => left.surfels,
            (None, None) => owners.get(t).map_or(0, |r| r.len() as u32),
        };
        (tile.node_count, tile.leaf_count, surfels)
    }

    /// What the scene knows of tile `t`, from its data where it holds it.
    pub(crate) fn summary(&self, owners: &[std::ops::Range<u32>], t: usize) -> TileSummary {
        if let Some(s) = self.absent_tile(t) {
            return s.clone();
        }
        let tile = &self.tiles[t];
        let nodes = &self.nodes[tile.node_offset as usize..(tile.node_offset + tile.node_count) as usize];
        let leaves = &self.leaves[tile.leaf_offset as usize..(tile.leaf_offset + tile.leaf_count) as usize];
        let surfels = owners.get(t).map_or(&[][..], |r| &self.surfels[r.start as usize..r.end as usize]);
        let mut summary =
            TileSummary::of(tile.depth - tile.leaf_lod, nodes, leaves, surfels, self.leaf_size_m);
        if let Some(left) = self.in_package(t) {
            (summary.surfels, summary.material_surfels) = (left.surfels, left.material_surfels);
        }
        summary
    }

    /// The summary of every tile form, by key: what a load for another residency may leave out
    /// ([`SceneData::from_package_with_held`]).
    pub fn held_tiles(&self) -> HeldTiles {
        let (owners, _) = self.surfel_owners();
        self.tiles.iter().enumerate().map(|(t, tile)| (key(tile), self.summary(&owners, t))).collect()
    }

    /// Gives a scene whose tile data was let go its data again, from `from`: the same package's
    /// tiles loaded again in the same forms (an error, nothing changed, otherwise).
    pub fn restore_tile_data(&mut self, from: SceneData) -> Result<()> {
        let same =
            from.holds_all_tiles()
                && from.tiles.len() == self.tiles.len()
                && from.tiles.iter().zip(&self.tiles).all(|(a, b)| {
                    (key(a), a.node_count, a.leaf_count) == (key(b), b.node_count, b.leaf_count)
                });
        if !same {
            return Err(crate::error::Error::Internal {
                what: "restore_tile_data",
                message: "the scene loaded again holds other tiles".into(),
            });
        }
        (self.tiles, self.nodes, self.leaves, self.surfels, self.tile_surfels) =
            (from.tiles, from.nodes, from.leaves, from.surfels, from.tile_surfels);
        (self.absent, self.in_package) = (Vec::new(), Vec::new());
        Ok(())
    }

    /// Takes `old`'s lights (with their circuits' state), headlamp and story: another residency
    /// of the same package read anew has the package's, and the view keeps its own.
    pub(crate) fn take_lights_and_story(&mut self, old: &mut SceneData) {
        self.lighting = old.lighting.take();
        self.lights.clone_from(&old.lights);
        self.headlamp = old.headlamp;
        (self.pois, self.tours) = (std::mem::take(&mut old.pois), std::mem::take(&mut old.tours));
    }

    /// Lets go of the tiles' nodes, leaves and surfels once a renderer holds them: a viewer keeps
    /// on the CPU nothing its GPU holds. Each tile's summary stays ([`TileSummary`]); a new
    /// renderer needs the scene loaded again (it refuses this one), a change of tiles only the
    /// tiles that change.
    pub fn release_tile_data(&mut self) {
        let (owners, exact) = self.surfel_owners();
        // A scene put together by hand has no surfels by tile to account for.
        if !exact {
            return;
        }
        self.absent = (0..self.tiles.len()).map(|t| Some(self.summary(&owners, t))).collect();
        for (t, r) in self.tiles.iter_mut().zip(&mut self.tile_surfels) {
            (t.node_offset, t.leaf_offset, *r) = (0, 0, 0..0);
        }
        (self.nodes, self.leaves, self.surfels) = (Vec::new(), Vec::new(), Vec::new());
        self.in_package = Vec::new();
    }

    /// Node indices ordered by height (0 = leaves) and the range of each height, for the mip pass.
    pub fn nodes_by_height(&self) -> (Vec<u32>, Vec<MipRange>) {
        self.nodes_by_height_at(&self.tiles)
    }

    /// As [`SceneData::nodes_by_height`], with the scene's tiles (in order) held at `placed`'s
    /// node offsets (the renderer's pools, pool.rs).
    pub(crate) fn nodes_by_height_at(&self, placed: &[TileGpu]) -> (Vec<u32>, Vec<MipRange>) {
        let mut buckets: Vec<Vec<u32>> = Vec::new();
        for (k, (t, at)) in self.tiles.iter().zip(placed).enumerate() {
            if let Some(s) = self.absent_tile(k) {
                // Breadth-first: level `l`'s nodes follow the levels above.
                let mut first = at.node_offset;
                for (l, &n) in s.nodes_by_level.iter().enumerate() {
                    let h = (t.depth - t.leaf_lod).saturating_sub(l as u32) as usize;
                    if buckets.len() <= h {
                        buckets.resize(h + 1, Vec::new());
                    }
                    buckets[h].extend(first..first + n);
                    first += n;
                }
                continue;
            }
            for i in 0..t.node_count {
                let n = t.node_offset + i;
                // Height above the tile's own leaves (a coarse tile's are 2^leaf_lod wide).
                let h = (t.depth - t.leaf_lod - self.nodes[n as usize].level()) as usize;
                if buckets.len() <= h {
                    buckets.resize(h + 1, Vec::new());
                }
                buckets[h].push(at.node_offset + i);
            }
        }
        let mut order = Vec::with_capacity(self.counts().nodes);
        let mut ranges = Vec::with_capacity(buckets.len());
        for (h, b) in buckets.into_iter().enumerate() {
            ranges.push(MipRange {
                first: order.len() as u32,
                count: b.len() as u32,
                height: h as u32,
                pad: 0,
            });
            order.extend(b);
        }
        (order, ranges)
    }

    /// Reads every tile of `pkg` (checked SVO view, surfels, colours) and its scene.
    pub fn from_package(pkg: &Package) -> Result<Self> {
        Self::from_package_with(pkg, |_| TileMode::Full)
    }

    /// Reads `pkg` with each tile as `mode_of(tile index)` says: as built, at its coarse or far
    /// level (stored in the package, or derived by [`coarse_level`]), or not at all. The rock is
    /// the loaded tiles' stored rock, or else classified from every loaded tile's full leaves, so
    /// a coarse tile keeps the rock behind its walls.
    pub fn from_package_with(pkg: &Package, mode_of: impl Fn(usize) -> TileMode) -> Result<Self> {
        Self::load(pkg, mode_of, None, None)
    }

    /// As [`SceneData::from_package_with`], with the rock already classified for these tiles: it
    /// depends on which tiles are loaded, not on their modes, so residency classifies it once
    /// (from a first load) and passes it to every later load.
    pub fn from_package_with_rock(
        pkg: &Package,
        mode_of: impl Fn(usize) -> TileMode,
        rock: crate::scene::rock::RockTable,
    ) -> Result<Self> {
        Self::load(pkg, mode_of, Some(rock), None)
    }

    /// As [`SceneData::from_package_with_rock`], leaving out the tile forms in `held` (a
    /// renderer holds them: [`SceneData::held_tiles`] of its scene): only the tiles that change
    /// are read and decoded, and those left out take no memory here ([`SceneData::absent`]).
    pub fn from_package_with_held(
        pkg: &Package,
        mode_of: impl Fn(usize) -> TileMode,
        rock: crate::scene::rock::RockTable,
        held: &HeldTiles,
    ) -> Result<Self> {
        Self::load(pkg, mode_of, Some(rock), Some(held))
    }

    /// Builds tiles of `2^tile_depth` leaves from explicit leaf cells (global leaf coordinates,
    /// frame origin at cell 0). Cells repeated keep the first.
    pub fn from_voxels(name: &str, leaf_size_m: f32, tile_depth: u32, cells: &[VoxelLeaf]) -> Self {
        let mut by_tile: BTreeMap<[i32; 3], Vec<(u64, VoxelLeaf)>> = BTreeMap::new();
        for c in cells {
            let t = c.cell >> tile_depth as i32;
            let local = c.cell - (t << tile_depth as i32);
            let m = morton_encode(local.x as u32, local.y as u32, local.z as u32);
            by_tile.entry([t.z, t.y, t.x]).or_default().push((m, *c));
        }
        let mut out = SceneData { name: name.into(), leaf_size_m, ..Default::default() };
        for (key, mut list) in by_tile {
            list.sort_by_key(|(m, _)| *m);
            list.dedup_by_key(|(m, _)| *m);
            let codes: Vec<u64> = list.iter().map(|(m, _)| *m).collect();
            let nodes = nodes_from_leaves(&codes, tile_depth).expect("sorted unique codes within the tile");
            let origin = IVec3::new(key[2], key[1], key[0]) << tile_depth as i32;
            let node_offset = out.nodes.len() as u32;
            let leaf_offset = out.leaves.len() as u32;
            out.push_nodes(&nodes, tile_depth, node_offset, leaf_offset);
            for (_, v) in &list {
                out.leaves.push(LeafGpu {
                    albedo_opacity: v.albedo.extend(v.opacity).to_array(),
                    normal_mean: v.normal_mean.extend(0.0).to_array(),
                    center_m: ((v.cell.as_vec3() + Vec3::splat(0.5)) * leaf_size_m).extend(0.0).to_array(),
                    emission: v.emission.extend(0.0).to_array(),
                });
            }
            out.tiles.push(TileGpu {
                origin_leaf: origin.to_array(),
                depth: tile_depth,
                node_offset,
                leaf_offset,
                node_count: nodes.len() as u32,
                leaf_count: list.len() as u32,
                leaf_lod: 0,
                pad: [0; 3],
            });
            out.tile_surfels.push(0..0);
        }
        out.rock = crate::scene::rock::classify(out.leaf_size_m, &out.leaves);
        out
    }
}

/// sRGB colour of each of a tile's `n` surfels (BC1 or raw; grey where the package has none).
pub(crate) fn tile_colors(tile: &grotto_format::Tile<'_>, n: usize) -> Result<Vec<[u8; 3]>> {
    Ok(crate::scene::surfels::SurfelColors::of(tile)?.run(0, n))
}

/// Makes room in `v` for `additional` more, by at least an eighth of its length: a scene's
/// vectors grow tile by tile, and doubling left up to half of a large vector unused at a change
/// of tiles' peak (a vector of leaves, 14.6 MB in heaptrack of `grotto view`), while growing by
/// exactly each tile would copy the whole vector once a tile where `realloc` cannot grow in
/// place (wasm).
pub(crate) fn grow_for<T>(v: &mut Vec<T>, additional: usize) {
    if v.capacity() - v.len() < additional {
        v.reserve_exact(additional.max(v.len() / 8));
    }
}
