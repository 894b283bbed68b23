//! The tile pools on the GPU and the uploads into them: a scene's tiles written in place of
//! another's, only the forms new to the pools, the light of those that stay kept.

use std::collections::HashSet;
use std::ops::Range;
use std::sync::Arc;

use glam::Vec3;
use serde::Serialize;

use crate::error::{Error, Result};
use crate::gpu::Gpu;
use crate::gpu::types::{ActiveTile, LeafGpu, LeafLightGpu, NodeGpu, Params, SurfelGpu, TileGpu};
use crate::gpu::upload::{Move, Uploader, move_within};
use crate::light::setup::LightSetup;
use crate::passes::rebase::{Rebase, RebaseJob, rebased};
use crate::passes::splat::SplatRun;
use crate::passes::{self};
use crate::render::pool::{PoolCaps, Pools, TileKey, key, merge_runs};
use crate::scene::data::SceneData;

use crate::render::chunks::{CHUNK_SURFELS, Chunk, ChunkCache, Viewer, chunks_of};
use crate::render::params::Lookup;
use crate::render::params::tile_box;
use crate::render::pool::{Placement, Slot};
use grotto_format::Package;

/// The tile pools on the GPU (tile records, nodes, leaves, leaf light, surfels, and the tile
/// index in the lookup buffer) and where each resident tile form lives in them ([`Pools`]).
#[derive(Debug)]
pub(super) struct TilePools {
    slots: Pools,
    /// The resident tiles as the GPU holds them (offsets into the pools), and each one's surfels.
    tiles: Vec<TileGpu>,
    tile_surfels: Vec<Range<u32>>,
    /// Each resident tile's surfel chunks (chunks.rs), and those of every resident form.
    tile_chunks: Vec<Arc<Vec<Chunk>>>,
    chunk_cache: ChunkCache,
    /// Tiles may be culled by their boxes (their surfels lie in them: false for a scene put
    /// together by hand, whose surfels all count as its first tile's).
    cull_tiles: bool,
    tiles_buf: wgpu::Buffer,
    nodes_buf: wgpu::Buffer,
    leaves_buf: wgpu::Buffer,
    leaf_light: wgpu::Buffer,
    surfels: wgpu::Buffer,
    /// The lookup buffer (rock, tile index, light grid: lookup.wgsl), and the bytes the tile
    /// index may take in it.
    lookup: wgpu::Buffer,
    index_bytes: Range<u64>,
}

/// What [`TilePools::place`] wrote, for the renderer to follow.
pub(super) struct PlacedScene {
    pub(super) update: SceneUpdate,
    /// Per tile of the new scene: its light was kept (in place or carried through a repack).
    pub(super) light_kept: Vec<bool>,
    /// Boxes of the tile forms that came or went (shadow faces that see one are drawn again).
    pub(super) changed: Vec<(Vec3, Vec3)>,
}

impl TilePools {
    /// The pools of a new renderer: `placed` is where fresh pools put its scene, `up` holds the
    /// buffers with that scene written at their start.
    pub(super) fn new(
        slots: Pools,
        placed: Placement,
        (scene, cull_tiles): (&SceneData, bool),
        up: &Upload,
        index_bytes: Range<u64>,
    ) -> Self {
        let (owners, _) = scene.surfel_owners();
        let mut chunk_cache = ChunkCache::default();
        let tile_chunks = placed
            .tiles
            .iter()
            .zip(&owners)
            .map(|(t, r)| chunk_cache.get_or_build(key(t), &scene.surfels[r.start as usize..r.end as usize]))
            .collect();
        Self {
            slots,
            tile_surfels: placed.slots.iter().map(|s| s.surfels.clone()).collect(),
            tile_chunks,
            chunk_cache,
            tiles: placed.tiles,
            cull_tiles,
            tiles_buf: up.tiles.clone(),
            nodes_buf: up.nodes.clone(),
            leaves_buf: up.leaves.clone(),
            leaf_light: up.leaf_light.clone(),
            surfels: up.surfels.clone(),
            lookup: up.lookup.clone(),
            index_bytes,
        }
    }

    /// Writes `words` into the lookup buffer from word `at` (the light grid of edited lights).
    pub(super) fn write_lookup(&self, gpu: &Gpu, at: u32, words: &[u32]) {
        gpu.queue.write_buffer(&self.lookup, 4 * u64::from(at), bytemuck::cast_slice(words));
    }

    /// The resident tiles, as the GPU holds them.
    pub(super) fn tiles(&self) -> &[TileGpu] {
        &self.tiles
    }

    /// The pools' capacities.
    pub(super) fn caps(&self) -> PoolCaps {
        self.slots.caps()
    }

    /// Leaves in use (the end of the last leaf slot).
    pub(super) fn leaf_end(&self) -> u32 {
        self.slots.leaf_end()
    }

    /// Nodes in use (the end of the last node slot).
    pub(super) fn node_end(&self) -> u32 {
        self.slots.slots().values().map(|s| s.nodes.end).max().unwrap_or(0)
    }

    /// Makes the next [`TilePools::place`] repack every slot.
    pub(super) fn repack_next(&mut self) {
        self.slots.repack_next();
    }

    /// An error unless `scene` holds these tiles in the same forms, in order.
    pub(super) fn check_holds(&self, scene: &SceneData, what: &'static str) -> Result<()> {
        let same = scene.tiles.len() == self.tiles.len()
            && scene.tiles.iter().zip(&self.tiles).all(|(a, b)| key(a) == key(b));
        if same {
            Ok(())
        } else {
            Err(Error::Internal { what, message: "not the scene this renderer holds".into() })
        }
    }

    /// The light state of leaves `0..n`, read back.
    pub(super) fn read_light(&self, gpu: &Gpu, n: u32) -> Result<Vec<LeafLightGpu>> {
        let size = size_of::<LeafLightGpu>();
        let bytes = gpu.read_buffer(&self.leaf_light, u64::from(n) * size as u64)?;
        Ok(bytemuck::pod_collect_to_vec(&bytes[..n as usize * size]))
    }

    /// Writes the light state of leaves from `first_leaf` on.
    pub(super) fn write_light(&self, gpu: &Gpu, first_leaf: u32, light: &[LeafLightGpu]) {
        let at = u64::from(first_leaf) * size_of::<LeafLightGpu>() as u64;
        gpu.queue.write_buffer(&self.leaf_light, at, bytemuck::cast_slice(light));
    }

    /// The surfel ranges `viewer` may see, merged: by surfel chunks (chunks.rs), or with
    /// `by_chunks` off by tile boxes only (where tiles can be culled: the coarser draws, kept to
    /// measure against); every resident surfel without a viewer.
    pub(super) fn runs_seen(
        &self,
        viewer: Option<&Viewer<'_>>,
        (leaf_size_m, splat_scale): (f32, f32),
        by_chunks: bool,
    ) -> Vec<SplatRun> {
        if by_chunks && let Some(v) = viewer {
            let tiles = self.tile_surfels.iter().zip(self.tile_chunks.iter().map(|c| c.as_slice()));
            return super::chunks::runs_seen(tiles, v, splat_scale);
        }
        let seen = |t: &TileGpu| match viewer {
            Some(v) if self.cull_tiles => {
                let (lo, hi) = tile_box(t, leaf_size_m);
                crate::view::camera::sees_box(v.view_proj, lo, hi)
            }
            _ => true,
        };
        merge_runs(
            self.tiles
                .iter()
                .zip(&self.tile_surfels)
                .filter(|(t, _)| seen(t))
                .map(|(_, r)| r.clone())
                .collect(),
        )
        .into_iter()
        .map(SplatRun::all)
        .collect()
    }

    /// Places `scene`, another residency of the same package, in these pools: the tile forms
    /// already resident keep their slots and light; only the new forms are written (pool.rs), with
    /// the tile records and the tile index. `None`, with nothing changed, when the scene cannot
    /// replace this one in place (over the pools, tiles put together by hand, a tile index that
    /// outgrows its room). `pkg`: the package whose surfels `scene` left there (surfels.rs).
    pub(super) fn place(
        &mut self,
        gpu: &Gpu,
        (scene, pkg): (&SceneData, Option<&Package>),
        leaf_size_m: f32,
    ) -> Result<Option<PlacedScene>> {
        let (owners, exact) = scene.surfel_owners();
        if !exact || !self.cull_tiles || !self.slots.caps().holds(&PoolCaps::of(scene)) {
            return Ok(None);
        }
        self.check_absent_resident(scene)?;
        let index = crate::scene::tile_index::TileIndex::build(&scene.name, &scene.tiles)?;
        if 4 * index.words.len() as u64 > self.index_bytes.end - self.index_bytes.start {
            return Ok(None);
        }
        let old_slots = self.slots.slots().clone();
        let placed = self.slots.place(scene, &owners)?;
        let moved_bytes = self.move_stayed(gpu, scene, &placed)?;
        let (mut update, light_kept, built) =
            self.write_tiles(gpu, (scene, pkg), &owners, &placed, &index)?;
        update.moved_bytes = moved_bytes;
        // Tile forms that came or went.
        let new_keys: HashSet<TileKey> = placed.tiles.iter().map(key).collect();
        let changed: Vec<(Vec3, Vec3)> = self
            .tiles
            .iter()
            .filter(|t| !new_keys.contains(&key(t)))
            .chain(placed.tiles.iter().filter(|t| !old_slots.contains_key(&key(t))))
            .map(|t| tile_box(t, leaf_size_m))
            .collect();
        self.tile_surfels = placed.slots.iter().map(|s| s.surfels.clone()).collect();
        self.chunk_cache.retain(&new_keys);
        for (k, chunks) in built {
            self.chunk_cache.insert(k, chunks);
        }
        self.tile_chunks = placed
            .tiles
            .iter()
            .zip(&owners)
            .map(|(t, r)| {
                self.chunk_cache.get_or_build(key(t), &scene.surfels[r.start as usize..r.end as usize])
            })
            .collect();
        self.tiles = placed.tiles;
        Ok(Some(PlacedScene { update, light_kept, changed }))
    }

    /// An error unless every tile whose data `scene` does not hold is resident in that form: a
    /// change of tiles leaves out only what the renderer holds.
    fn check_absent_resident(&self, scene: &SceneData) -> Result<()> {
        for (t, tile) in scene.tiles.iter().enumerate() {
            let Some(s) = scene.absent_tile(t) else { continue };
            let resident = self.slots.slots().get(&key(tile)).is_some_and(|slot| {
                (slot.nodes.len(), slot.leaves.len(), slot.surfels.len())
                    == (tile.node_count as usize, s.leaves as usize, s.surfels as usize)
            });
            if !resident {
                return Err(Error::Internal {
                    what: "tile pools",
                    message: format!(
                        "tile {t} of the new scene is neither loaded nor resident in the renderer"
                    ),
                });
            }
        }
        Ok(())
    }

    /// After a repack: the forms that stayed move to their new slots on the GPU (nodes, leaves,
    /// their light, surfels: `gpu::upload::move_within`), and their nodes, which index their
    /// tile's nodes and leaves by pool position, are re-indexed on the GPU (passes/rebase.rs): no
    /// copy of them on the CPU, no read-back. Returns the bytes moved.
    fn move_stayed(&self, gpu: &Gpu, scene: &SceneData, placed: &Placement) -> Result<u64> {
        let stayed: Vec<(usize, &Slot)> =
            placed.moved.iter().enumerate().filter_map(|(t, m)| Some((t, m.as_ref()?))).collect();
        if stayed.is_empty() {
            return Ok(0);
        }
        let pools: [(usize, Vec<(&wgpu::Buffer, u64)>); 3] = [
            (0, vec![(&self.nodes_buf, size_of::<NodeGpu>() as u64)]),
            (
                1,
                vec![
                    (&self.leaves_buf, size_of::<LeafGpu>() as u64),
                    (&self.leaf_light, size_of::<LeafLightGpu>() as u64),
                ],
            ),
            (2, vec![(&self.surfels, size_of::<SurfelGpu>() as u64)]),
        ];
        let mut bytes = 0;
        for (pool, buffers) in pools {
            let mut ranges: Vec<(Range<u32>, u32)> = stayed
                .iter()
                .map(|(t, old)| (old.range(pool).clone(), placed.slots[*t].range(pool).start))
                .filter(|(r, _)| !r.is_empty())
                .collect();
            ranges.sort_by_key(|(r, _)| r.start);
            for (buffer, size) in buffers {
                let moves: Vec<Move> = ranges
                    .iter()
                    .map(|(r, to)| Move {
                        from: u64::from(r.start) * size,
                        to: u64::from(*to) * size,
                        len: r.len() as u64 * size,
                    })
                    .collect();
                bytes += move_within(gpu, buffer, &moves)?;
            }
        }
        // Re-indexed where they lie, from their old pool offsets to their new ones: a repack
        // is rare, so its pipeline is made when one happens.
        let jobs: Vec<RebaseJob> = stayed
            .iter()
            .map(|&(t, old)| {
                let (tile, at) = (&scene.tiles[t], &placed.tiles[t]);
                RebaseJob {
                    start: at.node_offset,
                    count: tile.node_count,
                    leaf_level: tile.depth - tile.leaf_lod,
                    from: (old.nodes.start, old.leaves.start),
                    to: (at.node_offset, at.leaf_offset),
                }
            })
            .collect();
        Rebase::new(gpu)?.run(gpu, &self.nodes_buf, &jobs)?;
        Ok(bytes)
    }

    /// Writes the forms new to the pools (their nodes re-indexed to their slots, leaves, light and
    /// surfels), then the tile records and the tile index; returns what was written, per tile
    /// whether its light was kept (in place, or moved with it), and the chunks of the surfels
    /// decoded from `pkg` as they were written.
    fn write_tiles(
        &self,
        gpu: &Gpu,
        (scene, pkg): (&SceneData, Option<&Package>),
        owners: &[Range<u32>],
        placed: &Placement,
        index: &crate::scene::tile_index::TileIndex,
    ) -> Result<(SceneUpdate, Vec<bool>, BuiltChunks)> {
        let mut up = Uploader::new(gpu);
        let mut update =
            SceneUpdate { repacked: placed.repacked, freed_tiles: placed.freed, ..Default::default() };
        let mut light_kept = placed.kept.clone();
        let mut built = Vec::new();
        for (i, (t, at)) in scene.tiles.iter().zip(&placed.tiles).enumerate() {
            if placed.kept[i] || placed.moved[i].is_some() {
                light_kept[i] = true;
                update.kept_tiles += 1;
                update.carried_leaves += t.leaf_count as usize;
                continue;
            }
            if scene.absent_tile(i).is_some() {
                return Err(Error::Internal {
                    what: "tile pools",
                    message: format!("tile {i} is new to the pools but its data was not loaded"),
                });
            }
            update.uploaded_tiles += 1;
            let (n0, l0) = (t.node_offset as usize, t.leaf_offset as usize);
            let nodes = rebased(
                &scene.nodes[n0..n0 + t.node_count as usize],
                t.depth - t.leaf_lod,
                (t.node_offset, t.leaf_offset),
                (at.node_offset, at.leaf_offset),
            );
            let leaves = &scene.leaves[l0..l0 + t.leaf_count as usize];
            let light = initial_light(leaves);
            let slot = &placed.slots[i];
            up.write(
                &self.nodes_buf,
                u64::from(at.node_offset) * size_of::<NodeGpu>() as u64,
                bytemuck::cast_slice(&nodes),
            )?;
            up.write(
                &self.leaves_buf,
                u64::from(at.leaf_offset) * size_of::<LeafGpu>() as u64,
                bytemuck::cast_slice(leaves),
            )?;
            up.write(
                &self.leaf_light,
                u64::from(at.leaf_offset) * size_of::<LeafLightGpu>() as u64,
                bytemuck::cast_slice(&light),
            )?;
            let surfels_at = u64::from(slot.surfels.start) * size_of::<SurfelGpu>() as u64;
            if scene.in_package(i).is_some() {
                let pkg = pkg.ok_or(Error::Internal {
                    what: "tile pools",
                    message: format!("tile {i}'s surfels are in a package none was given for"),
                })?;
                // Each piece is a whole number of chunks, so its chunks are the tile's from its start.
                let (mut chunks, mut at) = (Vec::new(), 0u32);
                scene.surfels_from_package(pkg, i, |piece| {
                    chunks.extend(chunks_of(piece).into_iter().map(|c| Chunk { first: c.first + at, ..c }));
                    let offset = surfels_at + u64::from(at) * size_of::<SurfelGpu>() as u64;
                    at += piece.len() as u32;
                    up.write(&self.surfels, offset, bytemuck::cast_slice(piece)).map(drop)
                })?;
                built.push((key(t), chunks));
            } else {
                let surfels = &scene.surfels[owners[i].start as usize..owners[i].end as usize];
                up.write(&self.surfels, surfels_at, bytemuck::cast_slice(surfels))?;
            }
        }
        up.write(&self.tiles_buf, 0, bytemuck::cast_slice(&placed.tiles))?;
        up.write(&self.lookup, self.index_bytes.start, bytemuck::cast_slice(&index.words))?;
        update.upload_bytes = up.written;
        Ok((update, light_kept, built))
    }
}

/// The chunks of tile forms built as their surfels were written.
type BuiltChunks = Vec<(TileKey, Vec<Chunk>)>;

// A piece decoded from a package is a whole number of chunks (write_tiles).
const _: () = assert!(crate::scene::surfels::PIECE_SURFELS.is_multiple_of(CHUNK_SURFELS as usize));

pub(super) const STORAGE: wgpu::BufferUsages =
    wgpu::BufferUsages::STORAGE.union(wgpu::BufferUsages::COPY_SRC).union(wgpu::BufferUsages::COPY_DST);

/// The buffers every pass shares, uploaded once: the static scene (bind group 0), the light state
/// (group 1), and the surfels the splat passes draw.
pub(super) struct Upload {
    pub(super) params: wgpu::Buffer,
    pub(super) tiles: wgpu::Buffer,
    pub(super) nodes: wgpu::Buffer,
    pub(super) leaves: wgpu::Buffer,
    pub(super) lookup: wgpu::Buffer,
    /// The lights' records (light/setup.rs `records`), with room for more.
    pub(super) lights: wgpu::Buffer,
    pub(super) leaf_light: wgpu::Buffer,
    pub(super) faces: wgpu::Buffer,
    pub(super) active: wgpu::Buffer,
    /// The bounce's largest change (16 bytes: the f32 bits, then padding), then each tile's.
    pub(super) changes: wgpu::Buffer,
    pub(super) surfels: wgpu::Buffer,
    pub(super) shared: passes::Shared,
    /// GPU bytes of all of them.
    pub(super) bytes: u64,
}

impl Upload {
    /// The buffers, the tile data in pools of `caps` elements with `scene` at their start (as
    /// fresh pools place it: pool.rs).
    #[allow(clippy::too_many_arguments)]
    pub(super) fn new(
        gpu: &Gpu,
        scene: &SceneData,
        caps: PoolCaps,
        lights: &LightSetup,
        lookup: &Lookup,
        shadow_atlas: &wgpu::TextureView,
        base_params: &Params,
        f16: bool,
        pull_surfels: bool,
    ) -> Result<Self> {
        let params = gpu.buffer_init(
            "params",
            bytemuck::bytes_of(base_params),
            wgpu::BufferUsages::UNIFORM | wgpu::BufferUsages::COPY_DST,
        )?;
        let mut up = Uploader::new(gpu);
        // A pool: `n` elements of `T`, the first ones written from `data`.
        fn pool<T: bytemuck::Pod>(
            up: &mut Uploader<'_>,
            gpu: &Gpu,
            label: &str,
            n: u64,
            data: &[T],
            usage: wgpu::BufferUsages,
        ) -> Result<wgpu::Buffer> {
            let b = gpu.buffer(label, n.max(data.len() as u64).max(1) * size_of::<T>() as u64, usage)?;
            up.write(&b, 0, bytemuck::cast_slice(data))?;
            Ok(b)
        }
        let leaf_light =
            pool(&mut up, gpu, "leaf light", caps.leaves, &initial_light(&scene.leaves), STORAGE)?;
        let face_bytes = if f16 { 8 } else { 16 };
        let faces = gpu.buffer("faces", caps.nodes.max(1) * 6 * face_bytes, STORAGE)?;
        // A 16-byte header, then at most every tile.
        let active =
            gpu.buffer("active tiles", 16 + size_of::<ActiveTile>() as u64 * caps.tiles.max(1), STORAGE)?;
        let changes = gpu.buffer("changes", 16 + 4 * caps.tiles.max(1), STORAGE)?;
        let lookup = gpu.buffer_init("lookup", bytemuck::cast_slice(&lookup.words), STORAGE)?;
        // A vertex buffer for instanced splats, a storage buffer for pulled ones, bound a window
        // at a time where it is larger than one binding (splat.rs).
        let surfel_usage = if pull_surfels {
            wgpu::BufferUsages::VERTEX | wgpu::BufferUsages::STORAGE | wgpu::BufferUsages::COPY_DST
        } else {
            wgpu::BufferUsages::VERTEX | wgpu::BufferUsages::COPY_DST
        } | wgpu::BufferUsages::COPY_SRC;
        let n_surfels = caps.surfels.max(scene.surfels.len() as u64).max(1);
        let surfels =
            gpu.windowed_buffer("surfels", n_surfels * size_of::<SurfelGpu>() as u64, surfel_usage)?;
        up.write(&surfels, 0, bytemuck::cast_slice(&scene.surfels))?;
        let tiles = pool(&mut up, gpu, "tiles", caps.tiles, &scene.tiles, STORAGE)?;
        let nodes = pool(&mut up, gpu, "nodes", caps.nodes, &scene.nodes, STORAGE)?;
        let leaves = pool(&mut up, gpu, "leaves", caps.leaves, &scene.leaves, STORAGE)?;
        // Room for the records of edited lights (`Renderer::edit_lights`): as many again, and
        // two asymmetric profiles' worth.
        let records = lights.records();
        let room = records.len() + records.len().max(256) + 2048;
        let lights_buf = pool(&mut up, gpu, "lights", room as u64, &records, STORAGE)?;
        let static_buffers = [
            (0, params.clone()),
            (1, tiles.clone()),
            (2, nodes.clone()),
            (3, leaves.clone()),
            (4, lights_buf.clone()),
            (7, lookup.clone()),
        ];
        let mut shared = passes::Shared::default();
        let mut bytes = surfels.size();
        for (binding, b) in static_buffers {
            bytes += b.size();
            shared.insert(0, binding, passes::Resource::Buffer(b));
        }
        shared.insert(0, 6, passes::Resource::Texture(shadow_atlas.clone()));
        for (binding, b) in [(0, &leaf_light), (1, &faces), (3, &active), (4, &changes)] {
            bytes += b.size();
            shared.insert(1, binding, passes::Resource::Buffer(b.clone()));
        }

        Ok(Upload {
            params,
            tiles,
            nodes,
            leaves,
            lookup,
            lights: lights_buf,
            leaf_light,
            faces,
            active,
            changes,
            surfels,
            shared,
            bytes,
        })
    }
}

/// The light state leaves start from: out = emission (no direct light, no gather yet).
pub(super) fn initial_light(leaves: &[LeafGpu]) -> Vec<LeafLightGpu> {
    leaves.iter().map(|l| LeafLightGpu { out: l.emission, ..Default::default() }).collect()
}

/// What [`Renderer::update_scene`] did.
#[derive(Clone, Debug, Default, Serialize)]
pub struct SceneUpdate {
    /// Tiles written to the pools (forms new to them), and tiles that kept their light (in their
    /// slot, or moved with it by a repack).
    pub uploaded_tiles: usize,
    pub kept_tiles: usize,
    /// Tile forms that left the pools.
    pub freed_tiles: usize,
    /// The free space was too fragmented for the new forms: the forms that stayed were moved,
    /// with their light, toward the pools' starts on the GPU, and the new ones written after.
    pub repacked: bool,
    /// Bytes a repack moved within the pools on the GPU.
    pub moved_bytes: u64,
    /// Bytes written to the GPU: the new forms' nodes, leaves, light and surfels, the tile table,
    /// tile index and mip order.
    pub upload_bytes: u64,
    /// Leaves that kept their light (in place, or carried through a repack).
    pub carried_leaves: usize,
    /// Shadow faces out of date after the change (those that see a changed tile, and any still
    /// catching up from an earlier one): drawn again by the next shadow passes.
    pub shadow_faces: usize,
}

impl SceneUpdate {
    /// This update followed by `later`, as one (a change of tiles written in steps): what they
    /// wrote, moved and freed together; the tiles and leaves kept are the first step's (what the
    /// change kept of the tiles before it), the shadow faces out of date the last step's.
    pub fn then(self, later: SceneUpdate) -> SceneUpdate {
        SceneUpdate {
            uploaded_tiles: self.uploaded_tiles + later.uploaded_tiles,
            kept_tiles: self.kept_tiles,
            freed_tiles: self.freed_tiles + later.freed_tiles,
            repacked: self.repacked || later.repacked,
            moved_bytes: self.moved_bytes + later.moved_bytes,
            upload_bytes: self.upload_bytes + later.upload_bytes,
            carried_leaves: self.carried_leaves,
            shadow_faces: later.shadow_faces,
        }
    }
}
