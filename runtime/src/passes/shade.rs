//! Deferred shading (shade.wgsl): one thread per pixel over the G-buffer, writing linear HDR and
//! tonemapped sRGB8 into storage buffers the renderer reads back.

use super::gbuffer::Targets;
use crate::error::Result;
use crate::gpu::Gpu;

#[derive(Debug)]
pub struct Shade {
    pipeline: wgpu::ComputePipeline,
    layout: wgpu::BindGroupLayout,
}

/// Shade's outputs and bind group for one G-buffer.
#[derive(Debug)]
pub struct Outputs {
    pub hdr: wgpu::Buffer,
    pub ldr: wgpu::Buffer,
    pub bind_group: wgpu::BindGroup,
}

impl Shade {
    pub fn new(gpu: &Gpu, scene: &wgpu::BindGroupLayout, radiance_f16: bool) -> Self {
        let d2 = wgpu::TextureViewDimension::D2;
        let layout = gpu.device.create_bind_group_layout(&wgpu::BindGroupLayoutDescriptor {
            label: Some("shade"),
            entries: &[
                super::texture_entry(0, d2),
                super::texture_entry(1, d2),
                super::texture_entry(2, d2),
                super::storage_entry(3, false),
                super::storage_entry(4, false),
                super::texture_entry(5, d2),
            ],
        });
        let pipeline = super::compute_pipeline(
            gpu,
            "shade",
            crate::shaders::SHADE,
            "shade",
            &[scene, &layout],
            radiance_f16,
        );
        Self { pipeline, layout }
    }

    /// `env_atlas`: the prefiltered environment levels (a 1x1 placeholder without).
    pub fn outputs(&self, gpu: &Gpu, targets: &Targets, env_atlas: &wgpu::TextureView) -> Result<Outputs> {
        let pixels = u64::from(targets.width) * u64::from(targets.height);
        let usage = wgpu::BufferUsages::STORAGE | wgpu::BufferUsages::COPY_SRC;
        let hdr = gpu.buffer("shade hdr", pixels * 16, usage)?;
        let ldr = gpu.buffer("shade ldr", pixels * 4, usage)?;
        let views =
            [&targets.distance, &targets.normal, &targets.albedo].map(|t| t.create_view(&Default::default()));
        let bind_group = gpu.device.create_bind_group(&wgpu::BindGroupDescriptor {
            label: Some("shade"),
            layout: &self.layout,
            entries: &[
                wgpu::BindGroupEntry { binding: 0, resource: wgpu::BindingResource::TextureView(&views[0]) },
                wgpu::BindGroupEntry { binding: 1, resource: wgpu::BindingResource::TextureView(&views[1]) },
                wgpu::BindGroupEntry { binding: 2, resource: wgpu::BindingResource::TextureView(&views[2]) },
                wgpu::BindGroupEntry { binding: 3, resource: hdr.as_entire_binding() },
                wgpu::BindGroupEntry { binding: 4, resource: ldr.as_entire_binding() },
                wgpu::BindGroupEntry { binding: 5, resource: wgpu::BindingResource::TextureView(env_atlas) },
            ],
        });
        Ok(Outputs { hdr, ldr, bind_group })
    }

    pub fn record(
        &self,
        pass: &mut wgpu::ComputePass<'_>,
        scene: &wgpu::BindGroup,
        out: &Outputs,
        w: u32,
        h: u32,
    ) {
        pass.set_pipeline(&self.pipeline);
        pass.set_bind_group(0, scene, &[]);
        pass.set_bind_group(1, &out.bind_group, &[]);
        pass.dispatch_workgroups(w.div_ceil(8), h.div_ceil(8), 1);
    }
}
