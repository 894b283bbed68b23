//! Propagation (propagate.wgsl): one bounce of cone-traced gathering at every leaf.

use crate::error::Result;
use crate::gpu::Gpu;

/// The propagate pipeline: one invocation per leaf, shared groups only.
pub fn new(gpu: &Gpu, shared: &super::Shared, radiance_f16: bool) -> Result<super::LeafPass> {
    super::LeafPass::new(gpu, "propagate", crate::shaders::PROPAGATE, shared, radiance_f16)
}
