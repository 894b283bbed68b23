//! Propagation (propagate.wgsl): one bounce of cone-traced gathering at every leaf.

use crate::gpu::Gpu;

#[derive(Debug)]
pub struct Propagate {
    pipeline: wgpu::ComputePipeline,
}

impl Propagate {
    pub fn new(gpu: &Gpu, scene: &wgpu::BindGroupLayout) -> Self {
        Self {
            pipeline: super::compute_pipeline(
                gpu,
                "propagate",
                crate::shaders::PROPAGATE,
                "propagate",
                &[scene],
            ),
        }
    }

    pub fn record(&self, pass: &mut wgpu::ComputePass<'_>, scene: &wgpu::BindGroup, leaf_count: u32) {
        pass.set_pipeline(&self.pipeline);
        pass.set_bind_group(0, scene, &[]);
        super::dispatch_linear(pass, leaf_count);
    }
}
