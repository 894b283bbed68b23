//! Light transport as one part of the renderer: the passes that move light (inject, env, mip,
//! propagate), the tiles whose light may still change and the bounce under way over them, the
//! read-backs that end a bounce or a light edit, and whether the direct and environment light
//! are current. The renderer's scheduler plans from this state and records the passes; what a
//! pass leaves behind is kept here ([`LightTransport::ran`]).

use crate::error::Result;
use crate::gpu::types::{ActiveTile, TileGpu};
use crate::gpu::{Gpu, PendingRead};
use crate::light::activity::{BounceWork, TileActivity, Why};
use crate::light::edit::PendingEdit;
use crate::light::plan::{EffectPlan, Pass};
use crate::passes;
use crate::passes::inject::Inject;
use crate::render::counters::PassStats;

/// The light passes and the state of the light between frames.
#[derive(Debug)]
pub(super) struct LightTransport {
    pub(super) inject: Inject,
    pub(super) env: passes::Batched,
    pub(super) mip: passes::mip::Mip,
    pub(super) propagate: passes::propagate::Propagate,
    /// The active tiles propagate reads, and what the bounce changed: its largest change (16
    /// bytes: the f32 bits, then padding), then each tile's (shaders/activity.wgsl `Changes`).
    active: wgpu::Buffer,
    pub(super) changes: wgpu::Buffer,
    pub(super) activity: TileActivity,
    /// Invocations (leaves) of the active tiles on the GPU, and the tiles (the tail pass's
    /// workgroups); `None` when the tiles changed since they were written.
    active_written: Option<(u32, u32)>,
    /// Bounces since the last [`LightTransport::take_bounce_work`], with what each updated.
    bounce_work: Vec<BounceWork>,
    /// A bounce under way in slices: its next invocation (active leaf, of `active_written`); the
    /// pyramid stays as its mip left it until it ends.
    pub(super) bounce_at: Option<u32>,
    /// The invocations the last propagate dispatch ran.
    pub(super) slice_run: (u32, u32),
    /// The last bounce's change, read back without blocking.
    pub(super) bounce_readback: Option<PendingRead>,
    /// The injected direct light is that of the current lights and shadow maps.
    pub(super) direct_valid: bool,
    /// The environment light was gathered for the current tiles.
    pub(super) env_valid: bool,
    /// A light edit whose direct light waits to be injected and tallied: inject then redoes
    /// only the tiles its lights reach (the active tiles), and the bounces wait for the tally
    /// of which tiles it changed (render/edit.rs).
    pub(super) light_edit: Option<PendingEdit>,
    /// Why a viewer holds the bounces, if it does.
    pub(super) held: Option<&'static str>,
}

impl LightTransport {
    /// The light passes over `tiles`, every tile still to be lit.
    pub(super) fn new(
        passes: (Inject, passes::Batched, passes::mip::Mip, passes::propagate::Propagate),
        active: wgpu::Buffer,
        changes: wgpu::Buffer,
        tiles: &[TileGpu],
    ) -> Self {
        let (inject, env, mip, propagate) = passes;
        Self {
            inject,
            env,
            mip,
            propagate,
            active,
            changes,
            activity: TileActivity::new(tiles),
            active_written: None,
            bounce_work: Vec::new(),
            bounce_at: None,
            slice_run: (0, 0),
            bounce_readback: None,
            direct_valid: false,
            env_valid: false,
            light_edit: None,
            held: None,
        }
    }

    /// The direct light is out of date and the bounces start again: a bounce split in slices is
    /// abandoned, and one still on its way back counts for nothing.
    pub(super) fn restart(&mut self) {
        self.direct_valid = false;
        self.bounce_at = None;
        self.bounce_readback = None;
    }

    /// Every tile's light may change, for `why`.
    pub(super) fn set_all_active(&mut self, why: Why) {
        self.activity.all(why);
        self.active_written = None;
    }

    /// The tiles are `tiles` now; those `kept` says kept their light start from it.
    pub(super) fn new_tiles(&mut self, tiles: &[TileGpu], kept: &[bool]) {
        self.activity = self.activity.after_change(tiles, kept);
        self.active_written = None;
    }

    /// Only the tiles `kept` says were seeded with carried light, and what touches them, are new.
    pub(super) fn seeded(&mut self, kept: &[bool]) {
        self.activity.seed(kept);
        self.active_written = None;
    }

    /// The active tiles on the GPU no longer match the activity.
    pub(super) fn activity_changed(&mut self) {
        self.active_written = None;
    }

    /// Invocations (leaves) of the active tiles on the GPU (0 when none are written).
    pub(super) fn active_items(&self) -> u32 {
        self.active_written.map_or(0, |(items, _)| items)
    }

    /// The tail pass's tiles where this dispatch ends the bounce.
    pub(super) fn finishing_tiles(&self) -> Option<u32> {
        let end = self.slice_run.1;
        self.active_written.and_then(|(items, tiles)| (end >= items).then_some(tiles))
    }

    /// Writes the active tiles where the plan propagates (or injects after a light edit) and
    /// the slice of them this call runs (`slice` invocations at most; None: the rest of the
    /// bounce). Returns the bytes written.
    pub(super) fn write_active(&mut self, gpu: &Gpu, plan: &EffectPlan, slice: Option<u32>) -> u64 {
        let inject_active = self.light_edit.is_some() && plan.runs(Pass::Inject);
        if !(plan.runs(Pass::Propagate) || inject_active) {
            return 0;
        }
        let mut bytes = 0;
        if self.bounce_at.is_none() && self.activity.pending_tiles() == 0 {
            // Forced past convergence: a bounce means every tile.
            self.set_all_active(Why::Verify);
        }
        if self.active_written.is_none() {
            let (tiles, items) = self.activity.active_tiles();
            let header = [tiles.len() as u32, items];
            gpu.queue.write_buffer(&self.active, 0, bytemuck::cast_slice(&header));
            if !tiles.is_empty() {
                gpu.queue.write_buffer(&self.active, 16, bytemuck::cast_slice(&tiles));
            }
            bytes += 8 + (tiles.len() * size_of::<ActiveTile>()) as u64;
            self.active_written = Some((items, tiles.len() as u32));
        }
        let items = self.active_items();
        let first = self.bounce_at.unwrap_or(0).min(items);
        let end = slice.map_or(items, |n| first.saturating_add(n).min(items));
        self.slice_run = (first, end);
        gpu.queue.write_buffer(&self.active, 8, bytemuck::cast_slice(&[first, end]));
        bytes + 8
    }

    /// Whether the frame's changes buffer starts afresh: a bounce starts (its changes are
    /// gathered over all its slices), or an edit's inject tallies what it changed.
    pub(super) fn clears_changes(&self, plan: &EffectPlan) -> bool {
        let tally = plan.runs(Pass::Inject) && self.light_edit.is_some();
        plan.runs(Pass::Propagate) && self.slice_run.0 == 0 || tally
    }

    /// What the passes in `ran` leave behind. `direct_done`: no shadow face waits for another
    /// round, so an inject (or no light to inject) makes the direct light current. Returns
    /// whether a read-back was started that the caller may wait for natively.
    pub(super) fn ran(&mut self, gpu: &Gpu, ran: &[Pass], lights: bool, direct_done: bool) -> bool {
        let mut reading = false;
        if ran.contains(&Pass::Inject) || !lights {
            // Faces deferred to the next round of a budgeted catch-up keep the shadow pass going
            // (and the next round ends in an inject of its own).
            self.direct_valid = direct_done;
            if ran.contains(&Pass::Inject) {
                reading |= self.start_edit_tally(gpu);
            }
        }
        if ran.contains(&Pass::Env) {
            self.env_valid = true;
        }
        if ran.contains(&Pass::Propagate) {
            let end = self.slice_run.1;
            if end < self.active_items() {
                // Part of a bounce: the rest runs in later calls, from the same pyramid.
                self.bounce_at = Some(end);
            } else {
                self.bounce_at = None;
                let tiles = self.activity.tiles() as u64;
                self.bounce_readback = Some(gpu.start_read(&self.changes, 16 + 4 * tiles));
                reading = true;
            }
        }
        reading
    }

    /// Inject ran for a pending edit: starts reading its tally back. Returns whether it did.
    fn start_edit_tally(&mut self, gpu: &Gpu) -> bool {
        let Some(edit) = self.light_edit.as_mut() else { return false };
        if !self.direct_valid {
            // Shadow faces deferred to another round (tiles changed under them): that round's
            // inject redoes every leaf, and every tile bounces, as for any change of lights.
            self.light_edit = None;
            self.set_all_active(Why::LightsChanged);
            return false;
        }
        let tiles = self.activity.tiles() as u64;
        edit.tally = Some(gpu.start_read(&self.changes, 16 + 4 * tiles));
        true
    }

    /// Finishes what a read-back brought: an edit's tally (the tiles it changed start the
    /// bounces: activity.rs `end_edit`) or the last bounce's change (which tiles the next bounce
    /// updates, and whether the light converged, counted in `stats`). Returns whether no
    /// read-back is pending any longer.
    pub(super) fn poll(&mut self, stats: &mut PassStats, tolerance: f32) -> Result<bool> {
        if let Some(edit) = &self.light_edit {
            let Some(read) = &edit.tally else { return Ok(true) };
            let Some(bytes) = read.take() else { return Ok(false) };
            let bytes = bytes?;
            let change: Vec<f32> = bytemuck::pod_collect_to_vec(&bytes[16..16 + 4 * self.activity.tiles()]);
            self.activity.end_edit(&change, tolerance);
            self.active_written = None;
            self.light_edit = None;
            return Ok(true);
        }
        let Some(read) = &self.bounce_readback else { return Ok(true) };
        let Some(bytes) = read.take() else { return Ok(false) };
        self.bounce_readback = None;
        let bytes = bytes?;
        let tiles = self.activity.tiles();
        let bits = u32::from_le_bytes([bytes[0], bytes[1], bytes[2], bytes[3]]);
        stats.last_change = Some(f32::from_bits(bits));
        stats.bounces_done += 1;
        let change: Vec<f32> = bytemuck::pod_collect_to_vec(&bytes[16..16 + 4 * tiles]);
        let work = self.activity.finish(&change, tolerance);
        stats.propagated_leaves += work.leaves;
        self.bounce_work.push(work);
        self.active_written = None;
        Ok(true)
    }

    /// What each propagation bounce since the last call updated, and why (drained).
    pub(super) fn take_bounce_work(&mut self) -> Vec<BounceWork> {
        std::mem::take(&mut self.bounce_work)
    }

    /// What a read-back under way is for, if one is: an edit's tally or a bounce's change.
    pub(super) fn reading(&self) -> Option<&'static str> {
        if self.light_edit.as_ref().is_some_and(|e| e.tally.is_some()) {
            Some("inject tally")
        } else {
            self.bounce_readback.is_some().then_some("propagate")
        }
    }

    /// Why the bounces wait, if they do: a viewer holds them, or the last bounce's change is
    /// still on its way back.
    pub(super) fn held_because(&self) -> Option<&'static str> {
        self.held.or_else(|| {
            self.bounce_readback.is_some().then_some("the last bounce's change is on its way back")
        })
    }
}
