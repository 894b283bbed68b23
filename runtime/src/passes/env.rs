//! Environment (env.wgsl): sky visibility and SH irradiance at every leaf, once per environment.

use crate::error::Result;
use crate::gpu::Gpu;

/// The env pipeline: one invocation per leaf, shared groups only.
pub fn new(gpu: &Gpu, shared: &super::Shared, radiance_f16: bool) -> Result<super::LeafPass> {
    super::LeafPass::new(gpu, "env", crate::shaders::ENV, shared, radiance_f16)
}
