//! Deferred shading (shade.wgsl): one thread per pixel over the G-buffer, writing linear HDR and
//! tonemapped sRGB8 into one storage buffer the renderer reads back or a viewer presents. Owns the
//! environment atlas it reads for glossy reflections (the prefiltered levels stacked top to bottom).

use super::gbuffer::Targets;
use crate::error::Result;
use crate::gpu::Gpu;
use crate::scene::data::EnvChain;

#[derive(Debug)]
pub(crate) struct Shade {
    pipeline: super::ComputePipeline,
    env_atlas: wgpu::TextureView,
    env_atlas_bytes: u64,
}

/// Shade's outputs and bind group for one G-buffer: one buffer (WebGPU allows 8 storage buffers
/// per stage by default), HDR and coverage as 4 f32 a pixel, then sRGB8 as one u32 a pixel.
#[derive(Debug)]
pub(crate) struct Outputs {
    pub(crate) frame: wgpu::Buffer,
    pub(crate) pixels: u64,
    pub(crate) bind_group: wgpu::BindGroup,
}

impl Outputs {
    /// Bytes of the HDR part, which starts the buffer.
    pub(crate) fn hdr_bytes(&self) -> u64 {
        self.pixels * 16
    }

    /// Word offset of the sRGB8 part.
    pub(crate) fn ldr_first_word(&self) -> u32 {
        (self.pixels * 4) as u32
    }
}

impl Shade {
    /// `env_chain`: the prefiltered environment levels, when the scene is lit by one (a 1x1
    /// placeholder atlas without).
    pub(crate) fn new(
        gpu: &Gpu,
        shared: &super::Shared,
        consts: super::PassConstants,
        env_chain: Option<&EnvChain>,
    ) -> Result<Self> {
        let pipeline = super::compute_pipeline(gpu, "shade", crate::shaders::SHADE, "shade", shared, consts)?;
        let (width, height) = env_chain.map_or((1, 1), |c| (c.width, c.height));
        let tex = gpu.texture_2d(
            "env atlas",
            width,
            height,
            wgpu::TextureFormat::Rgba32Float,
            wgpu::TextureUsages::TEXTURE_BINDING | wgpu::TextureUsages::COPY_DST,
        )?;
        let placeholder = [[0.0f32; 4]];
        let texels: &[[f32; 4]] = env_chain.map_or(&placeholder[..], |c| &c.rgba);
        gpu.queue.write_texture(
            tex.as_image_copy(),
            bytemuck::cast_slice(texels),
            wgpu::TexelCopyBufferLayout {
                offset: 0,
                bytes_per_row: Some(width * 16),
                rows_per_image: Some(height),
            },
            wgpu::Extent3d { width, height, depth_or_array_layers: 1 },
        );
        Ok(Self {
            pipeline,
            env_atlas: tex.create_view(&Default::default()),
            env_atlas_bytes: u64::from(width) * u64::from(height) * 16,
        })
    }

    /// GPU bytes of the environment atlas.
    pub(crate) fn env_atlas_bytes(&self) -> u64 {
        self.env_atlas_bytes
    }

    pub(crate) fn outputs(&self, gpu: &Gpu, targets: &Targets) -> Result<Outputs> {
        let layout = super::own_layout(&self.pipeline, "shade")?;
        let pixels = u64::from(targets.width) * u64::from(targets.height);
        let usage = wgpu::BufferUsages::STORAGE | wgpu::BufferUsages::COPY_SRC;
        let frame = gpu.buffer("shade frame", pixels * 20, usage)?;
        let views = [
            &targets.distance,
            &targets.normal,
            &targets.albedo,
            &targets.normal_weight,
            &targets.albedo_sum,
        ]
        .map(|t| t.create_view(&Default::default()));
        let view = |v| wgpu::BindingResource::TextureView(v);
        let bind_group = gpu.device.create_bind_group(&wgpu::BindGroupDescriptor {
            label: Some("shade"),
            layout,
            entries: &[
                wgpu::BindGroupEntry { binding: 0, resource: view(&views[0]) },
                wgpu::BindGroupEntry { binding: 1, resource: view(&views[1]) },
                wgpu::BindGroupEntry { binding: 2, resource: view(&views[2]) },
                wgpu::BindGroupEntry { binding: 3, resource: frame.as_entire_binding() },
                wgpu::BindGroupEntry { binding: 5, resource: view(&self.env_atlas) },
                wgpu::BindGroupEntry { binding: 6, resource: view(&views[3]) },
                wgpu::BindGroupEntry { binding: 7, resource: view(&views[4]) },
            ],
        });
        Ok(Outputs { frame, pixels, bind_group })
    }

    pub(crate) fn record(&self, pass: &mut wgpu::ComputePass<'_>, out: &Outputs, w: u32, h: u32) {
        self.pipeline.bind(pass);
        pass.set_bind_group(super::OWN_GROUP, &out.bind_group, &[]);
        pass.dispatch_workgroups(w.div_ceil(8), h.div_ceil(8), 1);
    }
}
