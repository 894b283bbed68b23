//! A package's tiles, lights, environment, materials, cameras and rock loaded into a
//! [`SceneData`], each tile full, coarse or skipped as residency says.

use glam::{DVec3, IVec3, Vec3};
use grotto_format::spec::ShRgb9;
use grotto_format::{Package, Scene, Scope, SectionKind, Tile};

use crate::error::{Error, Result};
use crate::gpu::types::{LeafGpu, SurfelGpu, TileGpu};
use crate::scene::coarse::{CoarseLevel, coarse_level, gpu_tile};
use crate::scene::data::{
    HeldTiles, LeafCentroids, MAX_MATERIALS, SceneCamera, SceneData, SceneMaterial, TileKey, TileMode,
    TileSummary, frame_of, full_leaves, read_env_chain, tile_colors, tile_scans,
};
use crate::scene::rock::RockTable;

/// A tile that residency loads, in the mode it chose, at its leaf offset from the frame origin.
type LoadedTile<'a> = (Tile<'a>, TileMode, IVec3);

/// Rock bricks at their global brick coordinates, with their 64 bits of rock.
type RockBricks = Vec<(IVec3, u64)>;

impl SceneData {
    /// `held`: tile forms a renderer holds already, left out (with the rock given: it is
    /// classified from every tile's leaves otherwise).
    pub(crate) fn load(
        pkg: &Package,
        mode_of: impl Fn(usize) -> TileMode,
        rock: Option<RockTable>,
        held: Option<&HeldTiles>,
    ) -> Result<Self> {
        let name = pkg.path().display().to_string();
        let scene = pkg.scene()?;
        let mut out = SceneData {
            name: name.clone(),
            scan_names: scene.scans.iter().map(|s| s.name.clone()).collect(),
            ..Default::default()
        };
        // The frame does not depend on which tiles are loaded: cameras and lights keep their
        // place whatever residency chose.
        let leaf_size = frame_of(pkg)?.map(|(origin, leaf)| {
            out.frame_origin_m = origin;
            out.leaf_size_m = leaf as f32;
            leaf
        });
        let (loaded, stored_rock) = out.tiles_to_load(pkg, &mode_of, leaf_size, rock.is_none())?;
        let classify_rock = rock.is_none() && stored_rock.is_none();
        let mut hidden_leaves: Vec<LeafGpu> = Vec::new();
        let mut absent = Vec::new();
        let key_of = |tile: &Tile<'_>, mode: TileMode, origin_leaf: IVec3| {
            (origin_leaf.to_array(), tile.depth(), mode.leaf_lod(tile.depth()))
        };
        // The surfels land in one vector: sized once from the section table, it holds no
        // doubling's slack and is never copied while it grows (a tile of millions of points
        // would otherwise cost up to three times its surfels at the moment it grows).
        let surfels: u64 = (loaded.iter())
            .filter(|(t, m, o)| held.is_none_or(|h| !h.contains_key(&key_of(t, *m, *o))))
            .map(|(t, m, _)| match m.leaf_lod(t.depth()) {
                0 => t.surfel_count_from_table().unwrap_or(0),
                k => t
                    .find(SectionKind::CoarseLeaves, k)
                    .map_or(0, |s| s.raw_len / size_of::<grotto_format::spec::CoarseLeaf>() as u64),
            })
            .sum();
        out.surfels.reserve_exact(usize::try_from(surfels).unwrap_or(0));
        for (tile, mode, origin_leaf) in loaded {
            let key = key_of(&tile, mode, origin_leaf);
            if let Some(summary) = held.and_then(|h| h.get(&key)) {
                out.push_absent(key, summary);
                absent.push(Some(summary.clone()));
                continue;
            }
            let before = out.tiles.len();
            out.push_tile(&tile, mode, origin_leaf, classify_rock, &mut hidden_leaves, &scene)?;
            absent.extend((before..out.tiles.len()).map(|_| None));
        }
        if absent.iter().any(Option::is_some) {
            out.absent = absent;
        }
        out.push_lights(&scene);
        out.push_environment(pkg, &scene)?;
        out.apply_materials(&scene)?;
        out.push_cameras(&scene);
        (out.pois, out.tours) =
            crate::scene::story::in_frame(out.frame_origin_m, &scene.pois, &scene.tours, &scene.cameras);
        out.rock = match (rock, stored_rock) {
            (Some(rock), _) => rock,
            (None, Some(bricks)) => RockTable::from_bricks(bricks),
            (None, None) => out.classified_rock(hidden_leaves),
        };
        Ok(out)
    }

    fn bad(&self, problem: String) -> Error {
        Error::Scene { package: self.name.clone(), problem }
    }

    /// The tiles residency loads, each checked against the shared leaf grid; and, where asked
    /// (`want_rock`), the package's rock bricks when every loaded tile has them and lies on the
    /// bricks' grid (format 1.1), else `None`: the rock is then classified from the full leaves
    /// of every loaded tile, coarse ones too.
    fn tiles_to_load<'a>(
        &self,
        pkg: &'a Package,
        mode_of: &impl Fn(usize) -> TileMode,
        leaf_size: Option<f64>,
        want_rock: bool,
    ) -> Result<(Vec<LoadedTile<'a>>, Option<RockBricks>)> {
        let brick_leaves = grotto_format::spec::ROCK_BRICK_LEAVES as i32;
        let mut stored_rock: Option<RockBricks> = if want_rock { Some(Vec::new()) } else { None };
        let mut loaded = Vec::new();
        for tile in pkg.tiles() {
            let mode = mode_of(tile.index() as usize);
            if mode == TileMode::Skip {
                continue;
            }
            let ls = tile.leaf_size_m();
            let ls0 = leaf_size.unwrap_or(ls);
            if (ls0 - ls).abs() > ls0 * 1e-9 {
                return Err(self
                    .bad(format!("tile {} has leaf size {ls} m, the first tile has {ls0} m", tile.index())));
            }
            let origin_leaf = grotto_levels::origin_leaf(tile.origin_m(), self.frame_origin_m, ls0)
                .ok_or_else(|| {
                    self.bad(format!("tile {} origin is not on the shared leaf grid", tile.index()))
                })?;
            if let Some(bricks) = &mut stored_rock {
                match tile.rock()? {
                    Some(list) if origin_leaf % brick_leaves == IVec3::ZERO => {
                        let origin_brick = origin_leaf / brick_leaves;
                        bricks.extend(list.iter().map(|b| {
                            (
                                origin_brick + IVec3::from_array(b.brick),
                                u64::from(b.bits[0]) | u64::from(b.bits[1]) << 32,
                            )
                        }));
                    }
                    // A tile without an SVO has no rock to store.
                    None if tile.find(SectionKind::SvoNodes, 0).is_none() => {}
                    _ => stored_rock = None,
                }
            }
            loaded.push((tile, mode, origin_leaf));
        }
        Ok((loaded, stored_rock))
    }

    /// One tile in `mode`: its nodes, leaves and surfels (full), or its coarse level's leaves and
    /// one splat each (coarse, far). Where the rock is classified here, a coarse tile's full
    /// leaves go to `hidden_leaves`.
    fn push_tile(
        &mut self,
        tile: &Tile<'_>,
        mode: TileMode,
        origin_leaf: IVec3,
        classify_rock: bool,
        hidden_leaves: &mut Vec<LeafGpu>,
        scene: &Scene,
    ) -> Result<()> {
        let depth = tile.depth();
        let leaf_lod = mode.leaf_lod(depth);
        let stored_coarse = if leaf_lod > 0 { tile.coarse(leaf_lod)? } else { None };
        // The full SVO: for a full tile, for a coarse tile whose level is not stored, and for
        // the rock where it is classified here.
        let svo = if leaf_lod == 0 || stored_coarse.is_none() || classify_rock { tile.svo()? } else { None };
        // Its full leaves: for a full tile, and for the rock where it is classified here.
        let leaves = match &svo {
            Some(svo) if leaf_lod == 0 || classify_rock => {
                full_leaves(svo, depth, origin_leaf, self.leaf_size_m)
            }
            _ => Vec::new(),
        };
        let node_offset = self.nodes.len() as u32;
        let leaf_offset = self.leaves.len() as u32;
        let surfel_offset = self.surfels.len() as u32;
        if leaf_lod > 0 {
            let level = match (stored_coarse, &svo) {
                (Some(c), _) => CoarseLevel { nodes: c.nodes.into_owned(), leaves: c.leaves.into_owned() },
                (None, Some(svo)) => coarse_level(svo, depth, leaf_lod, tile.leaf_size_m()),
                (None, None) => return Ok(()),
            };
            if level.nodes.is_empty() {
                return Ok(());
            }
            self.push_nodes(&level.nodes, depth - leaf_lod, node_offset, leaf_offset);
            let tile_origin_m = origin_leaf.as_vec3() * self.leaf_size_m;
            let coarse = gpu_tile(&level.leaves, leaf_lod, self.leaf_size_m, tile_origin_m);
            self.leaves.extend(coarse.leaves);
            self.surfels.extend(coarse.splats);
            if classify_rock {
                hidden_leaves.extend(leaves);
            }
        } else {
            let Some(svo) = &svo else { return Ok(()) };
            if svo.nodes.is_empty() {
                return Ok(());
            }
            self.push_nodes(svo.nodes.as_ref(), depth, node_offset, leaf_offset);
            self.push_full_leaves_and_surfels(tile, svo, leaves, origin_leaf, scene)?;
        }
        self.tiles.push(TileGpu {
            origin_leaf: origin_leaf.to_array(),
            depth,
            node_offset,
            leaf_offset,
            node_count: self.nodes.len() as u32 - node_offset,
            leaf_count: self.leaves.len() as u32 - leaf_offset,
            leaf_lod,
            pad: [0; 3],
        });
        self.tile_surfels.push(surfel_offset..self.surfels.len() as u32);
        Ok(())
    }

    /// A tile form the renderer holds: its record, with no nodes, leaves or surfels here.
    fn push_absent(&mut self, (origin_leaf, depth, leaf_lod): TileKey, summary: &TileSummary) {
        let surfels = self.surfels.len() as u32;
        self.tiles.push(TileGpu {
            origin_leaf,
            depth,
            node_offset: self.nodes.len() as u32,
            leaf_offset: self.leaves.len() as u32,
            node_count: summary.nodes(),
            leaf_count: summary.leaves,
            leaf_lod,
            pad: [0; 3],
        });
        self.tile_surfels.push(surfels..surfels);
    }

    /// A full tile's leaves (moved to where its surfels lie) and its surfels: tile-local f32 to
    /// frame f32 through the f64 tile offset, with their colours and scans. The surfels are
    /// decoded one at a time straight into the scene's, so a tile of millions of points is never
    /// held twice (decoded, then converted).
    fn push_full_leaves_and_surfels(
        &mut self,
        tile: &Tile<'_>,
        svo: &grotto_format::SvoData<'_>,
        mut leaves: Vec<LeafGpu>,
        origin_leaf: IVec3,
        scene: &Scene,
    ) -> Result<()> {
        let shift = DVec3::from_array(tile.origin_m()) - DVec3::from_array(self.frame_origin_m);
        let mut centroids = LeafCentroids::new(svo, tile.depth(), leaves.len(), self.leaf_size_m);
        let first = self.surfels.len();
        let surfels = &mut self.surfels;
        // The load reserved room for every tile's surfels at once (from the section table).
        let has_surfels = tile.for_each_surfel(|s| {
            centroids.add(s);
            let p = (DVec3::from_array(s.position_tile_m.map(f64::from)) + shift).as_vec3();
            surfels.push(SurfelGpu {
                position_radius: p.extend(s.radius_m).to_array(),
                normal_spread: [s.normal[0], s.normal[1], s.normal[2], s.spread],
                color: [0; 4],
                scan: 0,
            });
        })?;
        if has_surfels {
            // The tile's frame offset as the leaves have it (whole leaves).
            let leaf_shift = origin_leaf.as_dvec3() * f64::from(self.leaf_size_m);
            centroids.move_leaves(&mut leaves, leaf_shift);
        }
        self.leaves.extend(leaves);
        if !has_surfels {
            return Ok(());
        }
        let count = self.surfels.len() - first;
        let colors = tile_colors(tile, count)?;
        let scans = tile_scans(tile, count, scene.scans.len()).map_err(|p| self.bad(p))?;
        for ((g, c), scan) in self.surfels[first..].iter_mut().zip(colors).zip(scans) {
            g.color = [c[0], c[1], c[2], 0];
            g.scan = scan;
        }
        Ok(())
    }

    /// A package position in the frame.
    fn to_frame(&self, p: [f64; 3]) -> Vec3 {
        (DVec3::from_array(p) - DVec3::from_array(self.frame_origin_m)).as_vec3()
    }

    /// The scene's point and spot lights whose circuits are on (area lights are emissive leaves
    /// already).
    fn push_lights(&mut self, scene: &Scene) {
        let lights =
            crate::scene::lighting::scene_lights(&scene.lights, &scene.circuits, self.frame_origin_m, |_| {
                true
            });
        self.lights.extend(lights);
        if !scene.circuits.is_empty() {
            self.lighting = Some(crate::scene::lighting::Relight::of_package(&scene.lights, &scene.circuits));
        }
    }

    /// The environment's SH irradiance and prefiltered chain, scaled by its intensity.
    fn push_environment(&mut self, pkg: &Package, scene: &Scene) -> Result<()> {
        let Some(env) = &scene.environment else { return Ok(()) };
        let section = pkg.find(SectionKind::EnvSh9, Scope::Global, env.index).ok_or_else(|| {
            self.bad(format!("the scene's environment {} has no env-sh9 section", env.index))
        })?;
        let sh = pkg.read::<ShRgb9>(&section)?;
        let first = sh.first().ok_or_else(|| self.bad("the env-sh9 section is empty".into()))?;
        if !(env.intensity.is_finite() && env.intensity >= 0.0) {
            return Err(
                self.bad(format!("environment intensity {} is not a finite number >= 0", env.intensity))
            );
        }
        self.environment_sh = Some(first.coeffs.map(|c| c.map(|v| v * env.intensity)));
        self.env_chain = read_env_chain(pkg, env.index, env.intensity)?;
        Ok(())
    }

    /// Specular materials with regions: each gets a slot, and the surfels in its region (facing
    /// up enough) take it; where regions overlap, the last one listed wins.
    fn apply_materials(&mut self, scene: &Scene) -> Result<()> {
        let frame = DVec3::from_array(self.frame_origin_m);
        let mut slot = 0u8;
        for m in &scene.materials {
            let Some(region) = &m.region else { continue };
            if m.specular.is_nan() || m.specular <= 0.0 {
                continue;
            }
            if usize::from(slot) >= MAX_MATERIALS {
                return Err(self.bad(format!(
                    "material '{}': at most {MAX_MATERIALS} specular materials with regions are supported",
                    m.name
                )));
            }
            slot += 1;
            let lo = DVec3::from_array(region.min_m) - frame;
            let hi = DVec3::from_array(region.max_m) - frame;
            for s in &mut self.surfels {
                let p = Vec3::from_slice(&s.position_radius[..3]).as_dvec3();
                if p.cmpge(lo).all() && p.cmple(hi).all() && s.normal_spread[2] >= region.min_normal_z {
                    s.color[3] = slot;
                }
            }
            self.materials.push(SceneMaterial {
                name: m.name.clone(),
                specular: m.specular.clamp(0.0, 1.0),
                roughness: m.roughness.clamp(0.02, 1.0),
                ior: m.ior.clamp(1.0, 3.0),
                surfels: 0,
            });
        }
        // Counted once every region is applied, with those of the tiles the renderer holds.
        for s in &self.surfels {
            if let Some(m) = usize::from(s.color[3]).checked_sub(1).and_then(|k| self.materials.get_mut(k)) {
                m.surfels += 1;
            }
        }
        for held in self.absent.iter().flatten() {
            for (m, n) in self.materials.iter_mut().zip(held.material_surfels) {
                m.surfels += n as usize;
            }
        }
        Ok(())
    }

    /// The scene's named cameras in the frame.
    fn push_cameras(&mut self, scene: &Scene) {
        for c in &scene.cameras {
            self.cameras.push(SceneCamera {
                name: c.name.clone(),
                eye_m: self.to_frame(c.eye_m),
                look_at_m: self.to_frame(c.look_at_m),
                up: DVec3::from_array(c.up).as_vec3(),
                fov_y_deg: c.fov_y_deg as f32,
            });
        }
    }

    /// The rock classified from the full leaves of every loaded tile: those of the full tiles, and
    /// `hidden_leaves` of the coarse ones.
    fn classified_rock(&self, mut hidden_leaves: Vec<LeafGpu>) -> RockTable {
        if hidden_leaves.is_empty() {
            return crate::scene::rock::classify(self.leaf_size_m, &self.leaves);
        }
        for t in self.tiles.iter().filter(|t| t.leaf_lod == 0) {
            let range = t.leaf_offset as usize..(t.leaf_offset + t.leaf_count) as usize;
            hidden_leaves.extend_from_slice(&self.leaves[range]);
        }
        crate::scene::rock::classify(self.leaf_size_m, &hidden_leaves)
    }
}
