//! Environment (env.wgsl): sky visibility and SH irradiance at every leaf, once per environment,
//! one cone per dispatch (`cone_batched`).

use crate::error::Result;
use crate::gpu::Gpu;

/// The env pass over the settings' `cones`.
pub(crate) fn new(
    gpu: &Gpu,
    shared: &super::Shared,
    consts: super::PassConstants,
    cones: u32,
) -> Result<super::Batched> {
    super::cone_batched(gpu, "env", crate::shaders::ENV, shared, consts, cones)
}
