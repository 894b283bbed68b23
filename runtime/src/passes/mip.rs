//! Anisotropic mipmapping (mip.wgsl): one dispatch per node height, leaves first, so every level
//! reads finished children (wgpu orders dispatches that write and read the same buffer).

use crate::error::Result;
use crate::gpu::Gpu;
use crate::gpu_types::MipRange;

#[derive(Debug)]
pub struct Mip {
    pipeline: super::ComputePipeline,
    levels: Vec<(wgpu::BindGroup, u32)>,
}

impl Mip {
    pub fn new(
        gpu: &Gpu,
        shared: &super::Shared,
        by_height: &[u32],
        ranges: &[MipRange],
        radiance_f16: bool,
    ) -> Result<Self> {
        let pipeline = super::compute_pipeline(gpu, "mip", crate::shaders::MIP, "mip", shared, radiance_f16)?;
        let layout = super::own_layout(&pipeline, "mip")?;
        let order =
            gpu.buffer_init("mip order", bytemuck::cast_slice(by_height), wgpu::BufferUsages::STORAGE)?;
        let levels = ranges
            .iter()
            .map(|r| {
                let u = gpu.buffer_init("mip range", bytemuck::bytes_of(r), wgpu::BufferUsages::UNIFORM)?;
                let bg = gpu.device.create_bind_group(&wgpu::BindGroupDescriptor {
                    label: Some("mip level"),
                    layout,
                    entries: &[
                        wgpu::BindGroupEntry { binding: 0, resource: u.as_entire_binding() },
                        wgpu::BindGroupEntry { binding: 1, resource: order.as_entire_binding() },
                    ],
                });
                Ok((bg, r.count))
            })
            .collect::<Result<_>>()?;
        Ok(Self { pipeline, levels })
    }

    pub fn record(&self, pass: &mut wgpu::ComputePass<'_>) {
        self.pipeline.bind(pass);
        for (bg, count) in &self.levels {
            pass.set_bind_group(super::OWN_GROUP, bg, &[]);
            super::dispatch_linear(pass, *count);
        }
    }
}
