//! Light injection (inject.wgsl): direct light from point and spot lights at every leaf.

use crate::gpu::Gpu;

/// The inject pipeline: one invocation per leaf, scene bindings only.
pub fn new(gpu: &Gpu, scene: &wgpu::BindGroupLayout, radiance_f16: bool) -> super::LeafPass {
    super::LeafPass::new(gpu, "inject", crate::shaders::INJECT, scene, radiance_f16)
}
