//! Propagation (propagate.wgsl): one bounce of cone-traced gathering at every leaf, in batches of
//! [`CONES_PER_BATCH`] cones per dispatch.
//!
//! Why batches: Mesa's software drivers (llvmpipe, lavapipe) share one budget of 65535 loop
//! iterations among all loops of a shader invocation and silently end every loop past it (as in
//! inject.rs). A cone's march loops over its steps, the rock probes of each step and the octree
//! descents of each sample, so an invocation tracing all its cones at fine steps ran out: on the
//! dogleg scene with every leaf sending 1, 16 cones at step 0.1 gathered 0.944 on lavapipe against
//! 0.999 from the CPU reference (which is step-invariant there); 9 cones, or step >= 0.35, matched.
//! With one cone per dispatch the budget is per cone. Results are the same to the bit: the running
//! sum is kept in the leaf state and added to in the same order (propagate.wgsl).

use crate::error::Result;
use crate::gpu::Gpu;
use crate::gpu_types::ConeBatch;

/// Cones traced by one propagate dispatch.
pub const CONES_PER_BATCH: u32 = 1;

#[derive(Debug)]
pub struct Propagate {
    pipeline: super::ComputePipeline,
    batches: Vec<wgpu::BindGroup>,
}

impl Propagate {
    pub fn new(gpu: &Gpu, shared: &super::Shared, radiance_f16: bool, cones: u32) -> Result<Self> {
        let pipeline = super::compute_pipeline(
            gpu,
            "propagate",
            crate::shaders::PROPAGATE,
            "propagate",
            shared,
            radiance_f16,
        )?;
        let layout = super::own_layout(&pipeline, "propagate")?;
        let batches = (0..cones.div_ceil(CONES_PER_BATCH).max(1))
            .map(|b| {
                let u = gpu.buffer_init(
                    "cone batch",
                    bytemuck::bytes_of(&ConeBatch {
                        first: b * CONES_PER_BATCH,
                        count: CONES_PER_BATCH,
                        pad0: 0,
                        pad1: 0,
                    }),
                    wgpu::BufferUsages::UNIFORM,
                )?;
                Ok(gpu.device.create_bind_group(&wgpu::BindGroupDescriptor {
                    label: Some("cone batch"),
                    layout,
                    entries: &[wgpu::BindGroupEntry { binding: 0, resource: u.as_entire_binding() }],
                }))
            })
            .collect::<Result<_>>()?;
        Ok(Self { pipeline, batches })
    }

    pub fn record(&self, pass: &mut wgpu::ComputePass<'_>, leaf_count: u32) {
        self.pipeline.bind(pass);
        for bg in &self.batches {
            pass.set_bind_group(super::OWN_GROUP, bg, &[]);
            super::dispatch_linear(pass, leaf_count);
        }
    }
}
