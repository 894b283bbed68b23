//! Environment (env.wgsl): sky visibility and SH irradiance at every leaf, once per environment.

use crate::gpu::Gpu;

/// The env pipeline: one invocation per leaf, scene bindings only.
pub fn new(gpu: &Gpu, scene: &wgpu::BindGroupLayout, radiance_f16: bool) -> super::LeafPass {
    super::LeafPass::new(gpu, "env", crate::shaders::ENV, scene, radiance_f16)
}
