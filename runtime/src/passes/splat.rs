//! Surfel splatting (splat.wgsl), shared by the shadow and G-buffer passes: the render pipeline
//! that draws every surfel as an oriented disc, its uniform layout, and the uniforms themselves.

use crate::error::Result;
use crate::gpu::Gpu;
use crate::gpu::types::{SplatUniform, SurfelGpu};

pub(crate) const DEPTH_FORMAT: wgpu::TextureFormat = wgpu::TextureFormat::Depth32Float;

/// The depth attachment both splat passes use: cleared to the far plane, not kept after the pass.
pub(crate) fn depth_cleared(view: &wgpu::TextureView) -> wgpu::RenderPassDepthStencilAttachment<'_> {
    wgpu::RenderPassDepthStencilAttachment {
        view,
        depth_ops: Some(wgpu::Operations { load: wgpu::LoadOp::Clear(1.0), store: wgpu::StoreOp::Discard }),
        stencil_ops: None,
    }
}

/// The splat uniform's layout (group 0 of splat.wgsl).
pub(crate) fn layout(gpu: &Gpu) -> wgpu::BindGroupLayout {
    gpu.device.create_bind_group_layout(&wgpu::BindGroupLayoutDescriptor {
        label: Some("splat"),
        entries: &[wgpu::BindGroupLayoutEntry {
            binding: 0,
            visibility: wgpu::ShaderStages::VERTEX | wgpu::ShaderStages::FRAGMENT,
            ty: wgpu::BindingType::Buffer {
                ty: wgpu::BufferBindingType::Uniform,
                has_dynamic_offset: false,
                min_binding_size: None,
            },
            count: None,
        }],
    })
}

/// `count` splat uniforms in one buffer, with one bind group per slot (bound at its offset).
#[derive(Debug)]
pub(crate) struct Uniforms {
    buffer: wgpu::Buffer,
    pub(crate) groups: Vec<wgpu::BindGroup>,
}

impl Uniforms {
    pub(crate) fn new(gpu: &Gpu, label: &str, layout: &wgpu::BindGroupLayout, count: usize) -> Result<Self> {
        let size = size_of::<SplatUniform>() as u64;
        // Each draw binds one slot, so 64 KiB uniform bindings (WebGPU's default, lavapipe)
        // still hold hundreds of shadow faces.
        let buffer = gpu.slotted_buffer(
            label,
            size,
            count as u64,
            wgpu::BufferUsages::UNIFORM | wgpu::BufferUsages::COPY_DST,
        )?;
        let groups = (0..count as u64)
            .map(|slot| {
                gpu.device.create_bind_group(&wgpu::BindGroupDescriptor {
                    label: Some(label),
                    layout,
                    entries: &[wgpu::BindGroupEntry {
                        binding: 0,
                        resource: wgpu::BindingResource::Buffer(wgpu::BufferBinding {
                            buffer: &buffer,
                            offset: slot * size,
                            size: wgpu::BufferSize::new(size),
                        }),
                    }],
                })
            })
            .collect();
        Ok(Self { buffer, groups })
    }

    pub(crate) fn write(&self, gpu: &Gpu, slot: usize, u: &SplatUniform) {
        gpu.queue.write_buffer(
            &self.buffer,
            (slot * size_of::<SplatUniform>()) as u64,
            bytemuck::bytes_of(u),
        );
    }
}

const SURFEL_ATTRIBUTES: [wgpu::VertexAttribute; 4] = wgpu::vertex_attr_array![
    0 => Float32x4,
    1 => Float32x4,
    2 => Unorm8x4,
    3 => Uint32,
];

/// A render pipeline drawing every surfel as an oriented disc into `targets`.
pub(crate) fn pipeline(
    gpu: &Gpu,
    label: &str,
    layout: &wgpu::BindGroupLayout,
    fragment_entry: &str,
    targets: &[Option<wgpu::ColorTargetState>],
) -> Result<wgpu::RenderPipeline> {
    let module = gpu.device.create_shader_module(wgpu::ShaderModuleDescriptor {
        label: Some("splat"),
        source: wgpu::ShaderSource::Wgsl(crate::shaders::compose(crate::shaders::SPLAT)?.into()),
    });
    let pl = gpu.device.create_pipeline_layout(&wgpu::PipelineLayoutDescriptor {
        label: Some(label),
        bind_group_layouts: &[Some(layout)],
        immediate_size: 0,
    });
    Ok(gpu.device.create_render_pipeline(&wgpu::RenderPipelineDescriptor {
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
    }))
}
