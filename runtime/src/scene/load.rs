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
    TileSummary, frame_of, full_leaves, grow_for, read_env_chain, tile_colors,
};
use crate::scene::rock::RockTable;
use crate::scene::surfels::{
    MaterialRegion, PIECE_SURFELS, SurfelColors, SurfelsInPackage, frame_surfel, material_slot, scan_indices,
    scan_of,
};

/// A tile that residency loads, in the mode it chose, at its leaf offset from the frame origin.
type LoadedTile<'a> = (Tile<'a>, TileMode, IVec3);

/// Rock bricks at their global brick coordinates, with their 64 bits of rock.
type RockBricks = Vec<(IVec3, u64)>;

/// How a load takes each tile: whether it classifies the rock from the tiles' leaves, and
/// whether it leaves full tiles' surfels in the package.
#[derive(Clone, Copy)]
struct TileLoad {
    classify_rock: bool,
    defer_surfels: bool,
}

impl SceneData {
    /// `held`: tile forms a renderer holds already, left out (with the rock given: it is
    /// classified from every tile's leaves otherwise). A change of tiles (`held` given) leaves
    /// its full tiles' surfels in the package for the renderer to decode as it writes them
    /// ([`SceneData::in_package`]).
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
        (out.materials, out.material_regions) = out.material_regions_of(&scene)?;
        let defer_surfels = held.is_some();
        let classify_rock = rock.is_none() && stored_rock.is_none();
        let mut hidden_leaves: Vec<LeafGpu> = Vec::new();
        let (mut absent, mut in_package) = (Vec::new(), Vec::new());
        let key_of = |tile: &Tile<'_>, mode: TileMode, origin_leaf: IVec3| {
            (origin_leaf.to_array(), tile.depth(), mode.leaf_lod(tile.depth()))
        };
        // The surfels land in one vector: sized once from the section table, it holds no
        // doubling's slack and is never copied while it grows (a tile of millions of points
        // would otherwise cost up to three times its surfels at the moment it grows).
        let surfels: u64 = (loaded.iter())
            .filter(|(t, m, o)| held.is_none_or(|h| !h.contains_key(&key_of(t, *m, *o))))
            .map(|(t, m, _)| match m.leaf_lod(t.depth()) {
                0 if defer_surfels => 0,
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
                in_package.push(None);
                continue;
            }
            let before = out.tiles.len();
            let load = TileLoad { classify_rock, defer_surfels };
            let left = out.push_tile(&tile, mode, origin_leaf, load, &mut hidden_leaves, &scene)?;
            if out.tiles.len() > before {
                absent.push(None);
                in_package.push(left);
            }
        }
        if absent.iter().any(Option::is_some) {
            out.absent = absent;
        }
        if in_package.iter().any(Option::is_some) {
            out.in_package = in_package;
        }
        out.push_lights(&scene);
        out.push_environment(pkg, &scene)?;
        out.count_material_surfels();
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
    /// leaves go to `hidden_leaves`. Returns what it knows of a full tile's surfels it left in the
    /// package (`load.defer_surfels`).
    fn push_tile(
        &mut self,
        tile: &Tile<'_>,
        mode: TileMode,
        origin_leaf: IVec3,
        TileLoad { classify_rock, defer_surfels }: TileLoad,
        hidden_leaves: &mut Vec<LeafGpu>,
        scene: &Scene,
    ) -> Result<Option<SurfelsInPackage>> {
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
        let mut left = None;
        if leaf_lod > 0 {
            let level = match (stored_coarse, &svo) {
                (Some(c), _) => CoarseLevel { nodes: c.nodes.into_owned(), leaves: c.leaves.into_owned() },
                (None, Some(svo)) => coarse_level(svo, depth, leaf_lod, tile.leaf_size_m()),
                (None, None) => return Ok(None),
            };
            if level.nodes.is_empty() {
                return Ok(None);
            }
            self.push_nodes(&level.nodes, depth - leaf_lod, node_offset, leaf_offset);
            let tile_origin_m = origin_leaf.as_vec3() * self.leaf_size_m;
            let coarse = gpu_tile(&level.leaves, leaf_lod, self.leaf_size_m, tile_origin_m);
            grow_for(&mut self.leaves, coarse.leaves.len());
            self.leaves.extend(coarse.leaves);
            let regions = &self.material_regions;
            // A level the package does not store was not in the load's count of surfels.
            grow_for(&mut self.surfels, coarse.splats.len());
            self.surfels.extend(coarse.splats.into_iter().map(|mut s| {
                s.color[3] = material_slot(regions, &s);
                s
            }));
            if classify_rock {
                hidden_leaves.extend(leaves);
            }
        } else {
            let Some(svo) = &svo else { return Ok(None) };
            if svo.nodes.is_empty() {
                return Ok(None);
            }
            self.push_nodes(svo.nodes.as_ref(), depth, node_offset, leaf_offset);
            left =
                self.push_full_leaves_and_surfels(tile, svo, leaves, (origin_leaf, defer_surfels), scene)?;
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
        Ok(left)
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
    /// frame f32 through the f64 tile offset, with their colours, scans and material slots. The
    /// surfels are decoded one at a time straight into the scene's, so a tile of millions of
    /// points is never held twice (decoded, then converted). Where `defer` (a change of tiles),
    /// they are read only to place the leaves and count them, and stay in the package: returned
    /// is what the renderer needs to decode them as it writes them (surfels.rs).
    fn push_full_leaves_and_surfels(
        &mut self,
        tile: &Tile<'_>,
        svo: &grotto_format::SvoData<'_>,
        mut leaves: Vec<LeafGpu>,
        (origin_leaf, defer): (IVec3, bool),
        scene: &Scene,
    ) -> Result<Option<SurfelsInPackage>> {
        let shift = DVec3::from_array(tile.origin_m()) - DVec3::from_array(self.frame_origin_m);
        let mut centroids = LeafCentroids::new(svo, tile.depth(), leaves.len(), self.leaf_size_m);
        let first = self.surfels.len();
        let (surfels, regions) = (&mut self.surfels, &self.material_regions);
        let mut left = SurfelsInPackage { tile: tile.index(), ..Default::default() };
        // The load reserved room for every tile's surfels at once (from the section table).
        let has_surfels = tile.for_each_surfel(|s| {
            centroids.add(s);
            if defer {
                let slot = material_slot(regions, &frame_surfel(s, shift));
                if let Some(n) =
                    usize::from(slot).checked_sub(1).and_then(|k| left.material_surfels.get_mut(k))
                {
                    *n += 1;
                }
                left.surfels += 1;
            } else {
                surfels.push(frame_surfel(s, shift));
            }
        })?;
        if has_surfels {
            // The tile's frame offset as the leaves have it (whole leaves).
            let leaf_shift = origin_leaf.as_dvec3() * f64::from(self.leaf_size_m);
            centroids.move_leaves(&mut leaves, leaf_shift);
        }
        grow_for(&mut self.leaves, leaves.len());
        self.leaves.extend(leaves);
        if !has_surfels {
            return Ok(None);
        }
        if defer {
            // Their colours and scans are read (and so checked) now, so a damaged section fails
            // this load, not the write; nothing of them is decoded.
            let n = left.surfels as usize;
            SurfelColors::of(tile)?;
            scan_indices(tile, n, scene.scans.len()).map_err(|p| self.bad(p))?;
            return Ok(Some(left));
        }
        let count = self.surfels.len() - first;
        let colors = tile_colors(tile, count)?;
        let scans = scan_indices(tile, count, scene.scans.len()).map_err(|p| self.bad(p))?;
        for (k, g) in self.surfels[first..].iter_mut().enumerate() {
            let c = colors.get(k).copied().unwrap_or([0; 3]);
            g.color = [c[0], c[1], c[2], material_slot(&self.material_regions, g)];
            g.scan = scan_of(scans.as_deref(), k);
        }
        Ok(None)
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

    /// The scene's specular materials with regions, in slot order, and their regions in the
    /// frame: a surfel in a material's region, facing up enough, takes its slot; where regions
    /// overlap, the last one listed wins.
    fn material_regions_of(&self, scene: &Scene) -> Result<(Vec<SceneMaterial>, Vec<MaterialRegion>)> {
        let (mut materials, mut regions) = (Vec::new(), Vec::new());
        for m in &scene.materials {
            let Some(region) = &m.region else { continue };
            if m.specular.is_nan() || m.specular <= 0.0 {
                continue;
            }
            if materials.len() >= MAX_MATERIALS {
                return Err(self.bad(format!(
                    "material '{}': at most {MAX_MATERIALS} specular materials with regions are supported",
                    m.name
                )));
            }
            regions.push(MaterialRegion::in_frame(region, self.frame_origin_m));
            materials.push(SceneMaterial {
                name: m.name.clone(),
                specular: m.specular.clamp(0.0, 1.0),
                roughness: m.roughness.clamp(0.02, 1.0),
                ior: m.ior.clamp(1.0, 3.0),
                surfels: 0,
            });
        }
        Ok((materials, regions))
    }

    /// Each specular material's surfels: those held here, those of the tiles the renderer holds
    /// and those left in the package.
    fn count_material_surfels(&mut self) {
        for s in &self.surfels {
            if let Some(m) = usize::from(s.color[3]).checked_sub(1).and_then(|k| self.materials.get_mut(k)) {
                m.surfels += 1;
            }
        }
        let held = self.absent.iter().flatten().map(|h| h.material_surfels);
        let left = self.in_package.iter().flatten().map(|l| l.material_surfels);
        for counts in held.chain(left) {
            for (m, n) in self.materials.iter_mut().zip(counts) {
                m.surfels += n as usize;
            }
        }
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

/// A change of tiles' surfels left in the package (surfels.rs), decoded when they are written.
impl SceneData {
    /// What the scene knows of tile `t`'s surfels where it left them in the package.
    pub(crate) fn in_package(&self, t: usize) -> Option<&SurfelsInPackage> {
        self.in_package.get(t).and_then(Option::as_ref)
    }

    /// Tile `t`'s surfels that this scene left in `pkg` ([`SceneData::in_package`]),
    /// decoded as a load would decode them and handed to `each` in order, at most
    /// [`PIECE_SURFELS`] at a time (every piece but the last holds exactly that many). A package
    /// that now reads otherwise than it did at load (another count) is an error.
    pub(crate) fn surfels_from_package(
        &self,
        pkg: &Package,
        t: usize,
        each: impl FnMut(&[SurfelGpu]) -> Result<()>,
    ) -> Result<()> {
        self.surfels_from_package_by(pkg, t, PIECE_SURFELS, each)
    }

    /// As [`SceneData::surfels_from_package`], in pieces of `piece_len`.
    fn surfels_from_package_by(
        &self,
        pkg: &Package,
        t: usize,
        piece_len: usize,
        mut each: impl FnMut(&[SurfelGpu]) -> Result<()>,
    ) -> Result<()> {
        let bad = |problem: String| Error::Scene { package: self.name.clone(), problem };
        let Some(held) = self.in_package(t) else {
            return Err(bad(format!("tile record {t} has no surfels left in the package")));
        };
        let tile =
            pkg.tile(held.tile).ok_or_else(|| bad(format!("the package has no tile {}", held.tile)))?;
        let n = held.surfels as usize;
        let colors = SurfelColors::of(&tile)?;
        let scans = scan_indices(&tile, n, self.scan_names.len()).map_err(bad)?;
        let shift = DVec3::from_array(tile.origin_m()) - DVec3::from_array(self.frame_origin_m);
        let mut piece = Vec::with_capacity(n.min(piece_len));
        let (mut k, mut failed) = (0usize, None);
        // A piece's colours are decoded with it, its first surfel being number `k - piece.len()`.
        let mut write = |piece: &mut Vec<SurfelGpu>, k: usize| {
            let first = k - piece.len();
            let run = colors.run(first, piece.len());
            for (i, g) in piece.iter_mut().enumerate() {
                let c = run.get(i).copied().unwrap_or([0; 3]);
                g.color = [c[0], c[1], c[2], g.color[3]];
                g.scan = scan_of(scans.as_deref(), first + i);
            }
            let written = each(piece);
            piece.clear();
            written
        };
        tile.for_each_surfel(|s| {
            if failed.is_some() || k >= n {
                k += 1;
                return;
            }
            let mut g = frame_surfel(s, shift);
            g.color[3] = material_slot(&self.material_regions, &g);
            piece.push(g);
            k += 1;
            if piece.len() == piece_len {
                failed = write(&mut piece, k).err();
            }
        })?;
        if let Some(e) = failed {
            return Err(e);
        }
        if k != n {
            return Err(bad(format!("tile {} read {k} surfels, {n} when it was loaded", held.tile)));
        }
        if !piece.is_empty() {
            write(&mut piece, k)?;
        }
        Ok(())
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::gpu::types::NO_SCAN;

    /// A change of tiles leaves its full tiles' surfels in the package and holds the rest as a
    /// whole load does; decoded in pieces, they are that load's surfels, colour, scan and material
    /// slot, to the bit.
    #[test]
    fn surfels_left_in_the_package_decode_to_those_a_whole_load_holds() {
        use grotto_preprocess::build::{ColorCodec, SurfelCodec};
        // BC1 colours in blocks of 16 (a piece of 1000 starts mid-block), raw colours and full
        // surfels.
        for (colors, surfels) in
            [(ColorCodec::Bc1, SurfelCodec::Compact), (ColorCodec::Raw, SurfelCodec::Full)]
        {
            let dir = tempfile::tempdir().unwrap();
            let cave = grotto_fixtures::SmallCave {
                max_tile_extent_m: 4.0,
                wet: true,
                colors,
                surfels,
                ..Default::default()
            };
            let pkg = Package::open(grotto_fixtures::small_cave_package(dir.path(), &cave).unwrap()).unwrap();
            surfels_left_in_the_package_decode_as_a_whole_load(&pkg);
        }
    }

    fn surfels_left_in_the_package_decode_as_a_whole_load(pkg: &Package) {
        let whole = SceneData::from_package(pkg).unwrap();
        let modes = |_| TileMode::Full;
        let left =
            SceneData::from_package_with_held(pkg, modes, whole.rock.clone(), &HeldTiles::new()).unwrap();
        assert!(whole.tiles.len() > 2 && left.surfels.is_empty() && !left.holds_all_tiles());
        assert!(whole.surfels.iter().any(|s| s.color[3] > 0), "the wet cave assigns materials");
        assert!(whole.surfels.iter().any(|s| s.scan != NO_SCAN && s.scan > 0), "and has scans");
        assert_eq!(left.counts(), whole.counts());
        assert_eq!(left.materials, whole.materials, "material surfels counted as they were read");
        assert_eq!(left.held_tiles(), whole.held_tiles());
        assert_eq!(
            (&left.leaves, &left.nodes),
            (&whole.leaves, &whole.nodes),
            "leaves placed as a whole load places them"
        );
        for t in 0..whole.tiles.len() {
            let (mut got, mut pieces) = (Vec::new(), Vec::new());
            left.surfels_from_package_by(pkg, t, 1000, |p| {
                got.extend_from_slice(p);
                pieces.push(p.len());
                Ok(())
            })
            .unwrap();
            let r = whole.tile_surfels[t].clone();
            assert_eq!(got, whole.surfels[r.start as usize..r.end as usize], "tile {t}");
            assert!(pieces.iter().rev().skip(1).all(|&n| n == 1000), "{pieces:?}");
        }
        assert!(whole.surfels.len() > 3000, "several pieces a tile");
        let stop = left
            .surfels_from_package(pkg, 0, |_| Err(Error::Internal { what: "test", message: "full".into() }));
        assert!(matches!(stop, Err(Error::Internal { what: "test", .. })), "a piece's error ends the decode");
        assert!(
            whole.surfels_from_package(pkg, 0, |_| Ok(())).is_err(),
            "a tile whose surfels are held here"
        );
    }
}
