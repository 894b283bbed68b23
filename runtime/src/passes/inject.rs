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

/// The inject pass for a light grid whose longest cell list holds `max_lights_per_cell` lights
/// (at least one batch runs, so that a scene whose lights reach no leaf still resets the direct
/// light).
pub(crate) fn new(
    gpu: &Gpu,
    shared: &super::Shared,
    radiance_f16: bool,
    max_lights_per_cell: u32,
) -> Result<super::Batched> {
    let count = max_lights_per_cell.div_ceil(LIGHTS_PER_BATCH).max(1);
    let batches = (0..count).map(|b| InjectBatch {
        first: b * LIGHTS_PER_BATCH,
        count: LIGHTS_PER_BATCH,
        reset: u32::from(b == 0),
        pad: 0,
    });
    super::Batched::new(gpu, "inject", crate::shaders::INJECT, shared, radiance_f16, batches)
}
