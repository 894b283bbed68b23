//! Light injection (inject.wgsl): direct light from point and spot lights at every leaf.

use crate::gpu::Gpu;

#[derive(Debug)]
pub struct Inject {
    pipeline: wgpu::ComputePipeline,
}

impl Inject {
    pub fn new(gpu: &Gpu, scene: &wgpu::BindGroupLayout) -> Self {
        Self { pipeline: super::compute_pipeline(gpu, "inject", crate::shaders::INJECT, "inject", &[scene]) }
    }

    pub fn record(&self, pass: &mut wgpu::ComputePass<'_>, scene: &wgpu::BindGroup, leaf_count: u32) {
        pass.set_pipeline(&self.pipeline);
        pass.set_bind_group(0, scene, &[]);
        super::dispatch_linear(pass, leaf_count);
    }
}
