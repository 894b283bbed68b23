//! Propagation (propagate.wgsl): one bounce of cone-traced gathering at every leaf, one cone per
//! dispatch (`cone_batched`), then, once a bounce has run every leaf, the tail (tail.wgsl): the
//! estimate of the bounces not run, from each tile's ratio of two successive bounces.

use crate::error::Result;
use crate::gpu::Gpu;

/// The propagate pass over the settings' `cones` and the tail pass that ends each bounce.
#[derive(Debug)]
pub(crate) struct Propagate {
    batched: super::Batched,
    tail: super::ComputePipeline,
}

pub(crate) fn new(
    gpu: &Gpu,
    shared: &super::Shared,
    consts: super::PassConstants,
    cones: u32,
) -> Result<Propagate> {
    Ok(Propagate {
        batched: super::cone_batched(gpu, "propagate", crate::shaders::PROPAGATE, shared, consts, cones)?,
        tail: super::compute_pipeline(gpu, "tail", crate::shaders::TAIL, "tail", shared, consts)?,
    })
}

impl Propagate {
    /// Records the cones over `leaf_count` invocations of the active tiles; where `finish` is
    /// some, the bounce has now run every leaf and the tail pass ends it, one workgroup for each
    /// of the `finish` active tiles.
    pub(crate) fn record(&self, pass: &mut wgpu::ComputePass<'_>, leaf_count: u32, finish: Option<u32>) {
        self.batched.record(pass, leaf_count);
        if let Some(tiles) = finish {
            self.tail.bind(pass);
            super::dispatch_groups(pass, tiles);
        }
    }
}
