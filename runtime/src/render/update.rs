//! A new residency of the same package swapped into a renderer in place: the tile pools take
//! the new forms ([`super::tiles::TilePools::place`]), and the renderer redraws the shadow faces
//! that see a change and settles the light from what it kept.

use crate::error::Result;
use crate::render::counters::PassStats;
use crate::render::params::{material_slots, tail_ratio_max};
use crate::render::pool::PoolCaps;
use crate::render::renderer::{Compat, Renderer};
use crate::render::tiles::SceneUpdate;
use crate::scene::data::SceneData;
use grotto_format::Package;

impl Renderer {
    /// Replaces the scene with `scene`, another residency of the same package (the same lights,
    /// frame and bounds: every tile in some form), in place: the tile forms already resident keep
    /// their slots in the pools and their light; only the new forms are written (pool.rs). Shadow
    /// faces that see a changed tile are drawn again; the light is then settled from the kept
    /// light, starting with the new tiles and their neighbours (activity.rs). `None` when the
    /// scene cannot replace this one in place (other lights or bounds, over the pools, tiles put
    /// together by hand): make a new renderer then. Nothing is changed in that case. The scene may
    /// leave out the tile forms this renderer holds ([`SceneData::absent`]); a form it leaves out
    /// that the renderer does not hold is an error. `pkg`: the package whose surfels the scene
    /// left there for the renderer to decode as it writes them (a change of tiles read by
    /// `Streaming::load_changes`); it is needed only then.
    pub fn update_scene(&mut self, scene: &SceneData, pkg: Option<&Package>) -> Result<Option<SceneUpdate>> {
        if Compat::of(scene) != self.compat {
            return Ok(None);
        }
        let Some(placed) = self.pools.place(&self.gpu, (scene, pkg), self.leaf_size_m)? else {
            return Ok(None);
        };
        let mut update = placed.update;
        let (by_height, ranges) = scene.nodes_by_height_at(self.pools.tiles());
        self.light.mip.set_order(&self.gpu, &by_height, &ranges)?;
        update.upload_bytes += 4 * by_height.len() as u64;
        // Shadow faces that see a tile form that came or went.
        self.mark_shadow_faces(|_, face| {
            placed.changed.iter().any(|(lo, hi)| crate::view::camera::sees_box(&face.view_proj, *lo, *hi))
        });
        update.shadow_faces = self.shadows.dirty_count();
        self.follow_scene(scene, &placed.light_kept);
        Ok(Some(update))
    }

    /// The renderer's state after the pools took `scene`: counts, parameters and materials of the
    /// tiles now held, light activity seeded from the tiles whose light was kept, and everything
    /// the new tiles need redone.
    fn follow_scene(&mut self, scene: &SceneData, light_kept: &[bool]) {
        self.leaf_count = self.pools.leaf_end();
        self.base_params.tile_count = self.pools.tiles().len() as u32;
        self.base_params.leaf_count = self.leaf_count;
        // Tiles held in another form (coarse or fine) bound their matter by other cells.
        let (occupied_lo, occupied_hi) = scene.occupied_bounds_leaf();
        self.base_params.occupied_min_leaf = occupied_lo.extend(0.0).to_array();
        self.base_params.occupied_max_leaf = occupied_hi.extend(0.0).to_array();
        // New tiles may hold brighter rock: the tail's trusted ratio follows the leaves held.
        self.base_params.tail_ratio_max = tail_ratio_max(&self.settings, scene);
        let (_, specular_materials, specular_surfels) = material_slots(scene, &self.settings);
        (self.specular_materials, self.specular_surfels) = (specular_materials, specular_surfels);
        self.emissive = scene.has_emission();
        self.light.new_tiles(self.pools.tiles(), light_kept);
        // Direct and environment light for the new leaves (and the faces drawn again), a new
        // G-buffer, and bounces counted afresh as for a new renderer; a bounce over the old
        // tiles, still on its way back, is not this scene's.
        self.light.restart();
        // The new tiles need direct light wherever they are: inject runs over every leaf.
        self.light.light_edit = None;
        self.light.env_valid = false;
        self.targets.invalidate();
        self.stats_now = PassStats::default();
    }

    /// Bytes of the tile pools (what `--gpu-memory` bounds: nodes, radiance pyramid, mip order,
    /// leaves, leaf light, surfels, tile records).
    pub fn pool_bytes(&self) -> u64 {
        self.pools.caps().bytes(self.settings.radiance_f16)
    }

    /// The pools' capacities.
    pub(crate) fn pool_caps(&self) -> PoolCaps {
        self.pools.caps()
    }

    /// Makes the next [`Renderer::update_scene`] repack the pools (compact every slot, carrying
    /// the light of the forms that stay) even where the new forms fit the holes: to defragment
    /// at a quiet moment, and for tests of the repack path.
    pub fn repack_next_update(&mut self) {
        self.pools.repack_next();
    }
}
