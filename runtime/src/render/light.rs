//! The light state the renderer keeps on the GPU between frames: bounces run whole or in
//! slices, convergence, holding the light while a viewer moves, and light carried across reloads.

use std::collections::HashMap;

use serde::Serialize;

use crate::error::Result;
use crate::gpu::types::LeafLightGpu;
use crate::light::activity::{BounceWork, Why};
use crate::light::plan::{self, EffectPlan, Pass};
use crate::passes::shadow::Face;
use crate::passes::splat::SplatRun;
use crate::render::chunks::Viewer;
use crate::render::pool::{TileKey, key};
use crate::scene::data::SceneData;

use crate::render::renderer::Renderer;

impl Renderer {
    /// While held, frames run no bounces, and the plan gives `why`: a viewer holds the light while
    /// its camera moves, so light work is what yields to the frame rate.
    pub fn hold_light(&mut self, why: Option<&'static str>) {
        self.light.held = why;
    }

    /// A light update (as [`Renderer::update_light`]) whose propagation runs at most `max_leaves`
    /// leaves of the current bounce: a bounce split over several calls ends as the whole one does
    /// (each leaf gathers from the same pyramid), and counts once it has run every leaf. Returns
    /// the leaves propagated.
    pub fn update_light_slice(&mut self, max_leaves: u32) -> Result<u32> {
        self.poll_light()?;
        let p = self.plan(None);
        self.execute(&p, None, Some(max_leaves.max(64)))?;
        if !p.runs(Pass::Propagate) {
            return Ok(0);
        }
        Ok(self.light.slice_run.1 - self.light.slice_run.0)
    }

    /// Where the light stands: bounces done of the budget, the last change, and whether it has
    /// converged (no more light work until something changes), held or not.
    pub fn light_progress(&self) -> LightProgress {
        // The light's own state: neither a hold nor a view without light is convergence.
        let mut i = self.inputs(None);
        i.light_held = None;
        i.plain_view = None;
        let p = plan::plan(&i);
        LightProgress {
            shadow_faces_left: self.shadow_faces_left(),
            bounces_done: self.stats_now.bounces_done,
            bounce_budget: self.settings.bounces,
            last_change: self.stats_now.last_change,
            converged: self.light.light_edit.is_none()
                && !(p.runs(Pass::Shadow)
                    || p.runs(Pass::Inject)
                    || p.runs(Pass::Env)
                    || p.runs(Pass::Propagate)),
        }
    }

    /// The bounce budget from now on (raising it past the bounces done lets the light go on
    /// converging; the light already propagated stays).
    pub fn set_bounces(&mut self, bounces: u32) {
        self.settings.bounces = bounces;
    }

    /// Turns shadow maps on or off; the direct light is injected again either way.
    pub fn set_shadows(&mut self, on: bool) {
        if self.settings.shadows != on {
            self.settings.shadows = on;
            self.invalidate_lights();
        }
    }

    /// Marks the lights changed: the next update re-renders shadow maps and re-injects, and the
    /// bounces are counted afresh (the light converges again from the new direct light).
    pub fn invalidate_lights(&mut self) {
        self.light.light_edit = None;
        self.light.restart();
        self.mark_shadow_faces(|_, _| true);
        self.stats_now.last_change = None;
        self.stats_now.bounces_done = 0;
        self.light.set_all_active(Why::LightsChanged);
    }

    /// Marks the shadow faces `which` picks out of date, each with the surfel chunks it draws
    /// now; faces already out of date are marked again (the pools may have moved under them).
    pub(super) fn mark_shadow_faces(&mut self, which: impl Fn(usize, &Face) -> bool) {
        let size = self.shadows.pass().face_size();
        let grow_ndc = Viewer::grow_for(size, size, self.settings.min_splat_px);
        let marks: Vec<(usize, Vec<SplatRun>)> = (self.shadows.face_slots())
            .filter(|(i, f)| !f.is_hole() && (which(*i, f) || self.shadows.is_dirty(*i)))
            .map(|(i, f)| {
                let viewer = Viewer {
                    view_proj: &f.view_proj,
                    grow_ndc,
                    light: Some((f.eye_m, f.range_m)),
                    lod: self.lod(f.eye_m, f.proj_scale * size as f32 * 0.5, 1.0),
                };
                (i, self.runs_seen(Some(&viewer)))
            })
            .collect();
        for (i, runs) in marks {
            self.shadows.mark(i, runs);
        }
    }

    /// Shadow faces out of date where shadow maps are in use (with shadows off, or no light
    /// given a map, faces stay marked but nothing waits for them).
    pub(super) fn shadow_faces_left(&self) -> usize {
        self.shadows.faces_left(self.settings.shadows)
    }

    /// Shadow faces the next pass draws of those out of date, and the budget, where the budget
    /// leaves some for later frames (the plan's `shadow_catch_up`).
    pub(super) fn shadow_catch_up(&self) -> Option<(usize, usize, f32)> {
        if self.light.direct_valid || !self.settings.shadows || self.settings.shadow_frame_ms <= 0.0 {
            return None;
        }
        self.shadows.catch_up(self.settings.shadow_frame_ms)
    }

    /// The last shadow pass took `ms` by a viewer's clock (a browser, where passes are not
    /// timed: the frame's time, which only overstates it): the next budgets use its rate.
    pub fn note_shadow_frame_ms(&mut self, ms: f64) {
        self.shadows.timed(ms);
    }

    /// What each propagation bounce since the last call updated, and why (drained).
    pub fn take_bounce_work(&mut self) -> Vec<BounceWork> {
        self.light.take_bounce_work()
    }

    /// Runs the light part of the plan (shadow, inject, one bounce); returns the plan it ran.
    pub fn update_light(&mut self) -> Result<EffectPlan> {
        self.poll_light()?;
        let p = self.plan(None);
        self.execute(&p, None, None)?;
        Ok(p)
    }

    /// Runs light updates until the plan stops propagating (converged or budget spent); returns
    /// the number of bounces run.
    pub fn settle(&mut self, progress: impl FnMut(u32, Option<f32>)) -> Result<u32> {
        self.settle_at_most(u32::MAX, progress)
    }

    /// As [`Renderer::settle`], stopping after at most `max_bounces` bounces; what is left runs
    /// one bounce per rendered frame ([`Renderer::render`]), so the light converges over frames,
    /// as do shadow faces under a frame budget (`Settings::shadow_frame_ms`).
    pub fn settle_at_most(
        &mut self,
        max_bounces: u32,
        mut progress: impl FnMut(u32, Option<f32>),
    ) -> Result<u32> {
        let start = self.stats_now.bounces_done;
        loop {
            // Shadow faces under a frame budget catch up over the frames, as the bounces left do.
            let direct_done = self.light.direct_valid || self.settings.shadow_frame_ms > 0.0;
            if self.stats_now.bounces_done - start >= max_bounces && direct_done {
                return Ok(self.stats_now.bounces_done - start);
            }
            let p = self.update_light()?;
            progress(self.stats_now.bounces_done, self.stats_now.last_change);
            // A shadow pass catching up holds the bounces; the loop goes on until they run.
            // An edit's inject holds the bounces until its tally says where they start.
            if !(p.runs(Pass::Propagate)
                || p.runs(Pass::Inject)
                || p.runs(Pass::Shadow) && !self.light.direct_valid)
            {
                return Ok(self.stats_now.bounces_done - start);
            }
        }
    }

    /// Each tile's light state as this renderer holds it for `scene` (the scene it was made
    /// for, or last updated to), to carry into the renderer of another scene that holds some of
    /// the same tiles.
    pub fn light_by_tile(&self, scene: &SceneData) -> Result<CarriedLight> {
        self.pools.check_holds(scene, "light_by_tile")?;
        let state = self.pools.read_light(&self.gpu, self.leaf_count)?;
        let mut tiles = HashMap::new();
        for t in self.pools.tiles() {
            let range = t.leaf_offset as usize..(t.leaf_offset + t.leaf_count) as usize;
            if let Some(leaves) = state.get(range) {
                tiles.insert(key(t), leaves.to_vec());
            }
        }
        Ok(CarriedLight { tiles })
    }

    /// Starts every tile of `scene` (this renderer's scene) that `carried` holds in the same form
    /// (same place, depth and level) from the light it had there, instead of from none: tiles
    /// that stay resident keep their converged light across a reload, and only what changed
    /// needs bounces. Direct light, environment light and `out` are recomputed by the passes as
    /// usual. Returns the leaves seeded. ([`Renderer::update_scene`] keeps the light in place
    /// instead, with no read-back; this is for a renderer made anew.)
    pub fn seed_light(&mut self, scene: &SceneData, carried: &CarriedLight) -> Result<usize> {
        self.pools.check_holds(scene, "seed_light")?;
        let mut seeded = 0;
        let mut kept = vec![false; self.pools.tiles().len()];
        for (t, k) in self.pools.tiles().iter().zip(&mut kept) {
            if let Some(from) = carried.tiles.get(&key(t))
                && from.len() == t.leaf_count as usize
            {
                self.pools.write_light(&self.gpu, t.leaf_offset, from);
                seeded += from.len();
                *k = true;
            }
        }
        if seeded > 0 {
            // Only the new tiles and what touches them need bounces (activity.rs).
            self.light.seeded(&kept);
        }
        Ok(seeded)
    }

    /// Finishes the last bounce where its read-back has arrived: its change decides which tiles
    /// the next bounce updates, and whether the light converged. Returns whether no read-back is
    /// pending any longer. Every call that plans (`draw`, `update_light`, `update_light_slice`)
    /// calls it first, so in a browser a bounce that ended on an earlier frame is counted before
    /// the next plan.
    pub(super) fn poll_light(&mut self) -> Result<bool> {
        self.light.poll(&mut self.stats_now, self.settings.convergence_tolerance)
    }

    /// Natively, waits for what the last frame started reading back (an edit's tally, a
    /// bounce's change) and finishes it; a browser, which cannot block, collects it on a later
    /// frame (`poll_light`) and plans no light work until then.
    pub(super) fn wait_for_light(&mut self) -> Result<()> {
        if cfg!(target_arch = "wasm32") {
            return Ok(());
        }
        let gpu = self.gpu.clone();
        while let Some(what) = self.light.reading() {
            gpu.wait_for(what, || Ok(self.poll_light()?.then_some(())))?;
        }
        Ok(())
    }
}

/// Where the light stands ([`Renderer::light_progress`]).
#[derive(Clone, Copy, Debug, PartialEq, Serialize)]
pub struct LightProgress {
    /// Shadow faces out of date, still to be drawn (a viewer's frame budget spreads them over
    /// frames: render/shadow_queue.rs).
    pub shadow_faces_left: usize,
    pub bounces_done: u32,
    pub bounce_budget: u32,
    pub(crate) last_change: Option<f32>,
    pub converged: bool,
}

impl LightProgress {
    /// 0..=1 for an indicator: 1 when converged, else bounces done of the budget.
    pub fn fraction(&self) -> f32 {
        if self.converged {
            1.0
        } else {
            (self.bounces_done as f32 / self.bounce_budget.max(1) as f32).min(0.99)
        }
    }
}

/// Light state per tile, keyed by where the tile is and at which level it is held
/// ([`Renderer::light_by_tile`], [`Renderer::seed_light`]).
#[derive(Clone, Debug, Default)]
pub struct CarriedLight {
    pub(super) tiles: HashMap<TileKey, Vec<LeafLightGpu>>,
}
