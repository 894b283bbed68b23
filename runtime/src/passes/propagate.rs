//! Propagation (propagate.wgsl): one bounce of cone-traced gathering at every leaf.

use crate::gpu::Gpu;

/// The propagate pipeline: one invocation per leaf, scene bindings only.
pub fn new(gpu: &Gpu, scene: &wgpu::BindGroupLayout, radiance_f16: bool) -> super::LeafPass {
    super::LeafPass::new(gpu, "propagate", crate::shaders::PROPAGATE, scene, radiance_f16)
}
