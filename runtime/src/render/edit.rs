//! Light edits in place ([`Renderer::edit_lights`]): the new lights written over the old ones in
//! the buffers the renderer already has (lights, light grid, shadow atlas), the shadow faces of
//! the changed lights drawn again, direct light injected again only in the tiles their light
//! reaches, and propagation started from those tiles (light/edit.rs says why that is exact).
//! Everything else keeps its light: a lamp moved in a side passage does not relight the cave.

use serde::Serialize;

use crate::error::Result;
use crate::light::activity::Why;
use crate::light::edit::{self, EditScope, PendingEdit};
use crate::render::renderer::{Compat, Renderer, light_setup};
use crate::scene::data::SceneData;

/// What [`Renderer::edit_lights`] did.
#[derive(Clone, Debug, PartialEq, Serialize)]
pub struct LightEdit {
    /// The edit's scope: lights changed, faces drawn again, tiles injected again.
    pub scope: EditScope,
    /// Bytes written to the GPU (lights, light grid, shadow faces' uniforms).
    pub upload_bytes: u64,
}

impl Renderer {
    /// Takes `scene`'s lights (the scene this renderer holds, its lights edited: moved, added,
    /// deleted, dimmed, recoloured, a circuit switched) in place. The shadow faces of lights
    /// that changed are drawn again; the next inject redoes the tiles an old or new changed light
    /// reaches, and the bounces start from them, spreading as their light changes (activity.rs),
    /// with one bounce over every tile as the stopping test. The fixed point is the one a new
    /// renderer of `scene` converges to.
    ///
    /// `None`, with nothing changed, where the edit does not fit in place: another scene (tiles,
    /// frame, materials), more shadow faces, light records or light-grid words than the buffers
    /// have room for. Make a new renderer then (`stream::relit` does).
    pub fn edit_lights(&mut self, scene: &SceneData) -> Result<Option<LightEdit>> {
        let mut same_but_lights = Compat::of(scene);
        same_but_lights.lights.clone_from(&self.compat.lights);
        same_but_lights.headlamp = self.compat.headlamp;
        if same_but_lights != self.compat || self.pools.check_holds(scene, "edit_lights").is_err() {
            return Ok(None);
        }
        let mut setup = light_setup(scene, &self.settings, self.scene_diag_m);
        if setup.lights.is_empty() {
            // Inject does not run without lights: nothing would clear the old direct light, nor
            // end the edit (its tally is taken after an inject).
            return Ok(None);
        }
        if !self.shadows.fits(&mut setup) {
            return Ok(None);
        }
        // Counted after the faces took their slots: holes are records too.
        let records = setup.records();
        if !self.lights.fits(&setup, &records) {
            return Ok(None);
        }
        // Which lights changed, before the renderer forgets the old ones.
        let reach = edit::changed(
            &edit::lit_by(&self.compat.lights, &self.lights.mapped),
            &edit::lit_by(&scene.lights, &setup.mapped),
            self.settings.light_cutoff_w_m2,
        );
        let reached = edit::tiles_reached(self.pools.tiles(), self.leaf_size_m, &reach);

        self.pools.write_lookup(&self.gpu, self.base_params.lookup_base[1], &setup.grid.words);
        let redrawn = self.shadows.set_faces(&self.gpu, &setup);
        self.mark_shadow_faces(|i, _| redrawn.contains(&i));
        let upload_bytes = (records.len() * size_of::<crate::gpu::types::LightGpu>()
            + 4 * setup.grid.words.len()
            + redrawn.len() * size_of::<crate::gpu::types::SplatUniform>()) as u64;

        let p = &mut self.base_params;
        p.light_count = setup.lights.len() as u32;
        p.light_grid_dims = setup.grid.dims.to_array();
        p.light_grid_min_m = setup.grid.min_m.extend(setup.grid.cell_m).to_array();
        self.lights.take(&self.gpu, setup, &records, scene.headlamp);
        self.light.inject.set_max_lights_per_cell(&self.gpu, self.lights.in_range.1)?;
        self.compat = Compat::of(scene);

        // Direct light again, bounces counted afresh; the light elsewhere is the start.
        let tiles = self.light.activity.tiles();
        let scope = EditScope {
            lights: reach.len(),
            faces: redrawn.len(),
            tiles: reached.iter().filter(|&&r| r).count(),
            of_tiles: tiles,
            leaves: (self.pools.tiles().iter().zip(&reached))
                .filter(|(_, r)| **r)
                .map(|(t, _)| u64::from(t.leaf_count))
                .sum(),
        };
        if self.light.direct_valid || self.light.light_edit.is_some() {
            // Inject redoes the tiles in reach (with an earlier edit's still waiting), then
            // the bounces start from those whose direct light it changed (`end_edit`).
            self.light.activity.begin_edit(&reached);
            let (tiles, leaves) = self.light.activity.pending_tiles_leaves();
            let before = self.light.light_edit.as_ref().map_or(0, |e| e.scope.lights);
            let scope = EditScope {
                lights: before + scope.lights,
                faces: self.shadows.dirty_count(),
                tiles,
                of_tiles: scope.of_tiles,
                leaves,
            };
            self.light.light_edit = Some(PendingEdit { scope, tally: None });
        } else {
            // Every leaf still waits for direct light (a new renderer, a change of tiles): it
            // all runs, as it would have.
            self.light.set_all_active(Why::LightsChanged);
        }
        self.light.activity_changed();
        self.light.restart();
        self.stats_now.last_change = None;
        self.stats_now.bounces_done = 0;
        Ok(Some(LightEdit { scope, upload_bytes }))
    }
}
