//! The shadow atlas as one part of the renderer: the shadow pass and its faces (passes/shadow.rs),
//! which faces are out of date and the batch the next pass draws (shadow_queue.rs), and the
//! counts the plan and a viewer read. The renderer marks faces (it knows which surfel chunks a
//! face sees) and schedules the pass; everything the pass leaves behind is kept here.

use crate::error::Result;
use crate::gpu::Gpu;
use crate::light::setup::LightSetup;
use crate::passes::shadow::{Batch, Face, Shadow};
use crate::passes::splat::{Fetch, SplatRun};
use crate::render::counters::PassWork;
use crate::render::shadow_queue::ShadowQueue;
use crate::settings::Settings;

/// The shadow pass, its faces' state and what it drew.
#[derive(Debug)]
pub(super) struct ShadowAtlas {
    pass: Shadow,
    queue: ShadowQueue,
    /// The faces the pass under way draws (chosen just before it is recorded).
    batch: Batch,
    /// Faces drawn since the last [`ShadowAtlas::take_drawn`].
    drawn: u64,
    /// Lights with shadow maps; the others are lit per leaf (light/setup.rs).
    shadowed: usize,
    /// Faces in use (six per point light with a map, one per spot light; holes left out).
    faces: usize,
}

impl ShadowAtlas {
    /// The atlas for `lights`' faces, with room for the faces of lights a designer adds within
    /// the shadow budget (render/edit.rs); every face starts out of date.
    pub(super) fn new(
        gpu: &Gpu,
        splat_layout: &wgpu::BindGroupLayout,
        lights: &LightSetup,
        settings: &Settings,
        splats: &Fetch,
    ) -> Result<Self> {
        let pass = gpu.scoped("shadow", || {
            let budget_faces = 6 * settings.shadowed_lights as usize;
            let room = if settings.shadows { settings.light_room_faces as usize } else { 0 };
            let want = (lights.faces.len() + room).min(budget_faces.max(lights.faces.len()));
            Shadow::new(
                gpu,
                splat_layout,
                &lights.faces,
                want,
                settings.shadow_map_size,
                settings.min_splat_px,
                settings.splat_scale,
                splats,
            )
        })?;
        Ok(Self {
            pass,
            queue: ShadowQueue::new(lights.faces.len()),
            batch: Batch::default(),
            drawn: 0,
            shadowed: lights.shadowed,
            faces: lights.faces.len(),
        })
    }

    /// The shadow pass (its atlas is bound by the passes that read shadows).
    pub(super) fn pass(&self) -> &Shadow {
        &self.pass
    }

    /// Lights with shadow maps.
    pub(super) fn shadowed(&self) -> usize {
        self.shadowed
    }

    /// Faces in use.
    pub(super) fn face_count(&self) -> usize {
        self.faces
    }

    /// Every face slot with its index (holes included).
    pub(super) fn face_slots(&self) -> impl Iterator<Item = (usize, &Face)> {
        self.pass.faces().iter().enumerate()
    }

    /// Whether face `i` waits to be drawn.
    pub(super) fn is_dirty(&self, i: usize) -> bool {
        self.queue.is_dirty(i)
    }

    /// Marks face `i` out of date, drawing `runs` when its turn comes.
    pub(super) fn mark(&mut self, i: usize, runs: Vec<SplatRun>) {
        self.queue.mark(i, runs);
    }

    /// Faces out of date where shadow maps are in use (with shadows off, or no light given a
    /// map, faces stay marked but nothing waits for them).
    pub(super) fn faces_left(&self, shadows_on: bool) -> usize {
        if shadows_on && self.shadowed > 0 { self.queue.dirty_count() } else { 0 }
    }

    /// Faces out of date, whether or not anything waits for them.
    pub(super) fn dirty_count(&self) -> usize {
        self.queue.dirty_count()
    }

    /// Faces the next pass draws of those out of date, and the budget, where a budget of
    /// `frame_ms` leaves some for later frames.
    pub(super) fn catch_up(&self, frame_ms: f32) -> Option<(usize, usize, f32)> {
        let b = self.queue.batch(frame_ms);
        (!b.finishes).then(|| (b.faces.len(), self.queue.dirty_count(), frame_ms))
    }

    /// Chooses the faces the pass about to run draws within `frame_ms`; returns the bytes of the
    /// staging atlas where it had to be made for them.
    pub(super) fn choose_batch(&mut self, gpu: &Gpu, frame_ms: f32) -> Result<u64> {
        self.batch = self.queue.batch(frame_ms);
        if self.batch.staged { self.pass.ensure_staging(gpu) } else { Ok(0) }
    }

    /// Records the pass over the chosen batch; returns its draws and surfels.
    pub(super) fn record(
        &self,
        enc: &mut wgpu::CommandEncoder,
        splats: &Fetch,
        queries: (Option<wgpu::RenderPassTimestampWrites<'_>>, Option<(&wgpu::QuerySet, u32)>),
    ) -> PassWork {
        let b = &self.batch;
        let work = PassWork {
            draws: b.faces.iter().map(|&i| self.queue.runs(i).len() as u64).sum(),
            surfels: b.surfels,
            ..PassWork::default()
        };
        self.pass.record(enc, splats, b, |i| self.queue.runs(i), queries);
        work
    }

    /// The pass ran (in `ms`, where it was timed): its batch is drawn, and the next budgets use
    /// its rate.
    pub(super) fn ran(&mut self, ms: Option<f64>) {
        let batch = std::mem::take(&mut self.batch);
        self.drawn += batch.faces.len() as u64;
        self.queue.drawn(&batch);
        if let Some(ms) = ms {
            self.queue.timed(ms);
        }
    }

    /// A viewer's clock for the last pass where passes are not timed.
    pub(super) fn timed(&mut self, ms: f64) {
        self.queue.timed(ms);
    }

    /// Whether `setup`'s faces fit the atlas with the faces now in use keeping their slots
    /// (`setup` takes those slots).
    pub(super) fn fits(&self, setup: &mut LightSetup) -> bool {
        setup.keep_slots(self.pass.faces(), self.pass.capacity())
    }

    /// Takes `setup`'s faces and light counts; returns the faces whose maps must be drawn again.
    pub(super) fn set_faces(&mut self, gpu: &Gpu, setup: &LightSetup) -> Vec<usize> {
        let redrawn = self.pass.set_faces(gpu, &setup.faces);
        self.queue.resize(setup.faces.len());
        self.shadowed = setup.shadowed;
        self.faces = setup.faces.iter().filter(|f| !f.is_hole()).count();
        redrawn
    }

    /// Faces drawn since the last call.
    pub(super) fn take_drawn(&mut self) -> u64 {
        std::mem::take(&mut self.drawn)
    }

    /// GPU bytes of the atlas (and its staging copy, once made).
    pub(super) fn bytes(&self) -> u64 {
        self.pass.bytes()
    }
}
