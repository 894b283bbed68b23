//! Propagation (propagate.wgsl): one bounce of cone-traced gathering at every leaf, one cone per
//! dispatch (`cone_batched`).

use crate::error::Result;
use crate::gpu::Gpu;

/// The propagate pass over the settings' `cones`.
pub(crate) fn new(
    gpu: &Gpu,
    shared: &super::Shared,
    consts: super::PassConstants,
    cones: u32,
) -> Result<super::Batched> {
    super::cone_batched(gpu, "propagate", crate::shaders::PROPAGATE, shared, consts, cones)
}
