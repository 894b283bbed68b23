//! Light injection (inject.wgsl): direct light from point and spot lights at every leaf, in
//! batches of at most [`LIGHTS_PER_BATCH`] lights of each leaf's light-grid cell per dispatch,
//! accumulated in the leaf state (the first batch resets it).
//!
//! Why batches: Mesa's software drivers (llvmpipe, lavapipe) share one budget of 65535 loop
//! iterations among all loops of a shader invocation (`LP_MAX_TGSI_LOOP_ITERATIONS`) and silently
//! end every loop past it; an SVO shadow cone toward a lamp can take thousands of iterations, so
//! one invocation looping over a long lamp list lost its last lamps (runtime/tests/gpu.rs
//! `many_cone_shadowed_lamps_add_up_...` fails with a single batch). Short
//! dispatches also keep real GPUs clear of driver watchdogs, as the Lexolights report's multipass
//! lighting does.

use crate::error::Result;
use crate::gpu::Gpu;
use crate::gpu::types::InjectBatch;

/// Lights of a cell handled by one inject dispatch.
pub(crate) const LIGHTS_PER_BATCH: u32 = 4;

/// Inject's pipelines: the batched pass, and the tally of an edit's change
/// (inject_tally.wgsl).
#[derive(Debug)]
pub(crate) struct Inject {
    lights: super::Batched,
    tally: super::ComputePipeline,
}

impl Inject {
    /// The inject pass for a light grid whose longest cell list holds `max_lights_per_cell`
    /// lights.
    pub(crate) fn new(
        gpu: &Gpu,
        shared: &super::Shared,
        consts: super::PassConstants,
        max_lights_per_cell: u32,
    ) -> Result<Self> {
        let lights = super::Batched::new(
            gpu,
            "inject",
            crate::shaders::INJECT,
            shared,
            consts,
            batches(max_lights_per_cell),
        )?;
        let tally = super::compute_pipeline(
            gpu,
            "inject tally",
            crate::shaders::INJECT_TALLY,
            "tally",
            shared,
            consts,
        )?;
        Ok(Self { lights, tally })
    }

    /// The batches for a light grid whose longest list now holds `max_lights_per_cell` lights
    /// (after an edit in place).
    pub(crate) fn set_max_lights_per_cell(&mut self, gpu: &Gpu, max_lights_per_cell: u32) -> Result<()> {
        self.lights.set_values(gpu, batches(max_lights_per_cell))
    }

    /// Injects `n` leaves (every leaf, or after an edit in place the active tiles' leaves, then
    /// tallies their change per tile: `edit`).
    pub(crate) fn record(&self, pass: &mut wgpu::ComputePass<'_>, n: u32, edit: bool) {
        self.lights.record(pass, n);
        if edit {
            self.tally.bind(pass);
            super::dispatch_linear(pass, n);
        }
    }
}

/// The batches of lights for a light grid whose longest cell list holds `max_lights_per_cell`
/// lights (at least one batch runs, so that a scene whose lights reach no leaf still resets the
/// direct light).
fn batches(max_lights_per_cell: u32) -> impl Iterator<Item = InjectBatch> {
    let count = max_lights_per_cell.div_ceil(LIGHTS_PER_BATCH).max(1);
    (0..count).map(move |b| InjectBatch {
        first: b * LIGHTS_PER_BATCH,
        count: LIGHTS_PER_BATCH,
        reset: u32::from(b == 0),
        last: u32::from(b + 1 == count),
    })
}
