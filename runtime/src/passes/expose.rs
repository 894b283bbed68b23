//! Exposure after the fact (expose.wgsl): a frame's radiance tonemapped again at a new exposure,
//! in place. Automatic exposure measures the first frame's light and then wants that same frame
//! at the exposure it chose; drawing it again would repeat the G-buffer's and every pixel's light
//! lookups (on a software adapter, seconds at 800x600) for a change of one multiplier.
//!
//! Written here rather than taken from a crate: one small compute shader over grotto's own frame
//! layout, calling the shade pass's own tone map.

use crate::error::Result;
use crate::gpu::Gpu;

/// The expose pipeline.
#[derive(Debug)]
pub(crate) struct Expose {
    pipeline: wgpu::ComputePipeline,
    layout: wgpu::BindGroupLayout,
}

impl Expose {
    pub(crate) fn new(gpu: &Gpu) -> Result<Self> {
        let (pipeline, layout) =
            super::frame_pipeline(gpu, "expose", crate::shaders::EXPOSE, "expose_frame")?;
        Ok(Self { pipeline, layout })
    }

    /// Tonemaps the `width` x `height` frame in `frame` (shade's outputs) again at `exposure`.
    pub(crate) fn run(
        &self,
        gpu: &Gpu,
        frame: &wgpu::Buffer,
        width: u32,
        height: u32,
        exposure: f32,
    ) -> Result<()> {
        let words = [width, height, exposure.to_bits(), 0];
        let uniform = gpu.buffer_init("expose", bytemuck::cast_slice(&words), wgpu::BufferUsages::UNIFORM)?;
        let bind_group = gpu.device.create_bind_group(&wgpu::BindGroupDescriptor {
            label: Some("expose"),
            layout: &self.layout,
            entries: &[
                wgpu::BindGroupEntry { binding: 0, resource: uniform.as_entire_binding() },
                wgpu::BindGroupEntry { binding: 1, resource: frame.as_entire_binding() },
            ],
        });
        let mut enc =
            gpu.device.create_command_encoder(&wgpu::CommandEncoderDescriptor { label: Some("expose") });
        {
            let mut pass = enc.begin_compute_pass(&wgpu::ComputePassDescriptor {
                label: Some("expose"),
                timestamp_writes: None,
            });
            pass.set_pipeline(&self.pipeline);
            pass.set_bind_group(0, &bind_group, &[]);
            pass.dispatch_workgroups(width.div_ceil(8), height.div_ceil(8), 1);
        }
        gpu.queue.submit([enc.finish()]);
        Ok(())
    }
}
