//! Shadow maps rendered from surfels (splat.wgsl, `fs_shadow`): one layer of distance-to-light per
//! cube face of a point light or per spot light, with a depth buffer for the nearest disc. Inject
//! and shade read the layers with a 3x3 percentage-closer filter (common.wgsl).

use crate::gpu::Gpu;
use crate::gpu_types::SurfelGpu;

/// Distance to the light as a packed f32 (splat.wgsl `pack_f32`): float targets do not render on GL.
pub const DISTANCE_FORMAT: wgpu::TextureFormat = wgpu::TextureFormat::Rgba8Unorm;

/// Clear colour whose packed bytes read back as `f32` `v`.
pub fn packed_clear(v: f32) -> wgpu::Color {
    let b = v.to_bits().to_le_bytes();
    let c = |i: usize| f64::from(b[i]) / 255.0;
    wgpu::Color { r: c(0), g: c(1), b: c(2), a: c(3) }
}
pub const DEPTH_FORMAT: wgpu::TextureFormat = wgpu::TextureFormat::Depth32Float;

/// The depth attachment both splat passes use: cleared to the far plane, not kept after the pass.
pub fn depth_cleared(view: &wgpu::TextureView) -> wgpu::RenderPassDepthStencilAttachment<'_> {
    wgpu::RenderPassDepthStencilAttachment {
        view,
        depth_ops: Some(wgpu::Operations { load: wgpu::LoadOp::Clear(1.0), store: wgpu::StoreOp::Discard }),
        stencil_ops: None,
    }
}

/// The uniform layout and instance layout both splat passes use.
pub fn splat_layout(gpu: &Gpu) -> wgpu::BindGroupLayout {
    gpu.device.create_bind_group_layout(&wgpu::BindGroupLayoutDescriptor {
        label: Some("splat"),
        entries: &[super::uniform_entry(0, wgpu::ShaderStages::VERTEX | wgpu::ShaderStages::FRAGMENT, false)],
    })
}

const SURFEL_ATTRIBUTES: [wgpu::VertexAttribute; 3] = wgpu::vertex_attr_array![
    0 => Float32x4,
    1 => Float32x4,
    2 => Unorm8x4,
];

/// A render pipeline drawing every surfel as an oriented disc into `targets`.
pub fn splat_pipeline(
    gpu: &Gpu,
    label: &str,
    layout: &wgpu::BindGroupLayout,
    fragment_entry: &str,
    targets: &[Option<wgpu::ColorTargetState>],
) -> wgpu::RenderPipeline {
    let module = gpu.device.create_shader_module(wgpu::ShaderModuleDescriptor {
        label: Some("splat"),
        source: wgpu::ShaderSource::Wgsl(crate::shaders::SPLAT.into()),
    });
    let pl = gpu.device.create_pipeline_layout(&wgpu::PipelineLayoutDescriptor {
        label: Some(label),
        bind_group_layouts: &[Some(layout)],
        immediate_size: 0,
    });
    gpu.device.create_render_pipeline(&wgpu::RenderPipelineDescriptor {
        label: Some(label),
        layout: Some(&pl),
        vertex: wgpu::VertexState {
            module: &module,
            entry_point: Some("vs"),
            compilation_options: Default::default(),
            buffers: &[Some(wgpu::VertexBufferLayout {
                array_stride: size_of::<SurfelGpu>() as u64,
                step_mode: wgpu::VertexStepMode::Instance,
                attributes: &SURFEL_ATTRIBUTES,
            })],
        },
        primitive: wgpu::PrimitiveState { cull_mode: None, ..Default::default() },
        depth_stencil: Some(wgpu::DepthStencilState {
            format: DEPTH_FORMAT,
            depth_write_enabled: Some(true),
            depth_compare: Some(wgpu::CompareFunction::Less),
            stencil: Default::default(),
            bias: Default::default(),
        }),
        multisample: Default::default(),
        fragment: Some(wgpu::FragmentState {
            module: &module,
            entry_point: Some(fragment_entry),
            compilation_options: Default::default(),
            targets,
        }),
        multiview_mask: None,
        cache: None,
    })
}

#[derive(Debug)]
pub struct Shadow {
    pipeline: wgpu::RenderPipeline,
}

impl Shadow {
    pub fn new(gpu: &Gpu, layout: &wgpu::BindGroupLayout) -> Self {
        let targets = [Some(wgpu::ColorTargetState {
            format: DISTANCE_FORMAT,
            blend: None,
            write_mask: wgpu::ColorWrites::ALL,
        })];
        Self { pipeline: splat_pipeline(gpu, "shadow", layout, "fs_shadow", &targets) }
    }

    /// Renders every face into its square of the atlas in one pass (one viewport per face);
    /// `uniforms[i]` binds face i's splat uniform.
    #[allow(clippy::too_many_arguments)]
    pub fn record(
        &self,
        enc: &mut wgpu::CommandEncoder,
        atlas: &wgpu::Texture,
        depth: &wgpu::TextureView,
        face_size: u32,
        cols: u32,
        uniforms: &[wgpu::BindGroup],
        surfels: &wgpu::Buffer,
        surfel_count: u32,
        timestamps: Option<wgpu::RenderPassTimestampWrites<'_>>,
    ) {
        let view = atlas.create_view(&Default::default());
        let mut pass = enc.begin_render_pass(&wgpu::RenderPassDescriptor {
            label: Some("shadow"),
            color_attachments: &[Some(wgpu::RenderPassColorAttachment {
                view: &view,
                depth_slice: None,
                resolve_target: None,
                ops: wgpu::Operations {
                    load: wgpu::LoadOp::Clear(packed_clear(1e30)),
                    store: wgpu::StoreOp::Store,
                },
            })],
            depth_stencil_attachment: Some(depth_cleared(depth)),
            timestamp_writes: timestamps,
            occlusion_query_set: None,
            multiview_mask: None,
        });
        pass.set_pipeline(&self.pipeline);
        pass.set_vertex_buffer(0, surfels.slice(..));
        let s = face_size as f32;
        for (i, group) in uniforms.iter().enumerate() {
            let (x, y) = ((i as u32 % cols) as f32 * s, (i as u32 / cols) as f32 * s);
            pass.set_viewport(x, y, s, s, 0.0, 1.0);
            pass.set_bind_group(0, group, &[]);
            pass.draw(0..6, 0..surfel_count);
        }
    }
}
