//! Presents the renderer's tonemapped frame on a surface (present.wgsl): scaled to the target by
//! nearest sampling, with the light's convergence as a bar along the bottom. Shared by the
//! window (`grotto view`) and the browser viewer, which differ only in where the surface comes
//! from.

use crate::error::Result;
use crate::gpu::Gpu;
use crate::render::frame::LdrOutput;
use crate::render::light::LightProgress;

/// The convergence bar's state (its colour in present.wgsl).
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum Bar {
    /// Grey: the light waits for the camera to rest.
    Held = 0,
    /// Amber: converging.
    Converging = 1,
    /// Green: converged.
    Converged = 2,
}

impl Bar {
    /// The bar's colour for the light's `progress`: held while the camera `moving`.
    pub fn of(progress: &LightProgress, moving: bool) -> Self {
        if progress.converged {
            Self::Converged
        } else if moving {
            Self::Held
        } else {
            Self::Converging
        }
    }
}

/// Where a frame is presented: a surface texture's view, its size, and whether its format
/// encodes sRGB on write.
#[derive(Debug)]
pub struct Target<'a> {
    pub view: &'a wgpu::TextureView,
    pub width: u32,
    pub height: u32,
    pub srgb: bool,
}

/// The surface's next texture to draw into; None where there is none this frame (the surface was
/// outdated or lost, and is configured again for the next, or timed out).
pub fn acquire(
    gpu: &Gpu,
    surface: &wgpu::Surface<'_>,
    config: &wgpu::SurfaceConfiguration,
) -> Option<wgpu::SurfaceTexture> {
    match surface.get_current_texture() {
        wgpu::CurrentSurfaceTexture::Success(t) | wgpu::CurrentSurfaceTexture::Suboptimal(t) => Some(t),
        wgpu::CurrentSurfaceTexture::Outdated | wgpu::CurrentSurfaceTexture::Lost => {
            surface.configure(&gpu.device, config);
            None
        }
        _ => None,
    }
}

/// The presenting pipeline and its uniform.
#[derive(Debug)]
pub struct Blit {
    pipeline: wgpu::RenderPipeline,
    layout: wgpu::BindGroupLayout,
    uniform: wgpu::Buffer,
}

impl Blit {
    /// A pipeline drawing into targets of `format`.
    pub fn new(gpu: &Gpu, format: wgpu::TextureFormat) -> Result<Self> {
        let src = crate::shaders::compose(crate::shaders::PRESENT)?;
        let module = gpu.device.create_shader_module(wgpu::ShaderModuleDescriptor {
            label: Some("present"),
            source: wgpu::ShaderSource::Wgsl(src.into()),
        });
        let entry = |binding, ty| wgpu::BindGroupLayoutEntry {
            binding,
            visibility: wgpu::ShaderStages::FRAGMENT,
            ty: wgpu::BindingType::Buffer { ty, has_dynamic_offset: false, min_binding_size: None },
            count: None,
        };
        let layout = gpu.device.create_bind_group_layout(&wgpu::BindGroupLayoutDescriptor {
            label: Some("present"),
            entries: &[
                entry(0, wgpu::BufferBindingType::Storage { read_only: true }),
                entry(1, wgpu::BufferBindingType::Uniform),
            ],
        });
        let pl = gpu.device.create_pipeline_layout(&wgpu::PipelineLayoutDescriptor {
            label: Some("present"),
            bind_group_layouts: &[Some(&layout)],
            immediate_size: 0,
        });
        let pipeline = gpu.device.create_render_pipeline(&wgpu::RenderPipelineDescriptor {
            label: Some("present"),
            layout: Some(&pl),
            vertex: wgpu::VertexState {
                module: &module,
                entry_point: Some("vs"),
                compilation_options: Default::default(),
                buffers: &[],
            },
            primitive: Default::default(),
            depth_stencil: None,
            multisample: Default::default(),
            fragment: Some(wgpu::FragmentState {
                module: &module,
                entry_point: Some("fs"),
                compilation_options: Default::default(),
                targets: &[Some(format.into())],
            }),
            multiview_mask: None,
            cache: None,
        });
        let uniform =
            gpu.buffer("present blit", 32, wgpu::BufferUsages::UNIFORM | wgpu::BufferUsages::COPY_DST)?;
        gpu.check("present")?;
        Ok(Self { pipeline, layout, uniform })
    }

    /// Records the blit of `frame` into `target` (cleared first), with the bar at `progress`
    /// (0..=1) of the width.
    pub fn record(
        &self,
        gpu: &Gpu,
        enc: &mut wgpu::CommandEncoder,
        frame: &LdrOutput<'_>,
        target: &Target<'_>,
        progress: f32,
        bar: Bar,
    ) {
        let u: [u32; 8] = [
            frame.width,
            frame.height,
            target.width,
            target.height,
            u32::from(target.srgb),
            progress.to_bits(),
            bar as u32,
            frame.first_word,
        ];
        gpu.queue.write_buffer(&self.uniform, 0, bytemuck::cast_slice(&u));
        let group = gpu.device.create_bind_group(&wgpu::BindGroupDescriptor {
            label: Some("present"),
            layout: &self.layout,
            entries: &[
                wgpu::BindGroupEntry { binding: 0, resource: frame.buffer.as_entire_binding() },
                wgpu::BindGroupEntry { binding: 1, resource: self.uniform.as_entire_binding() },
            ],
        });
        let mut pass = enc.begin_render_pass(&wgpu::RenderPassDescriptor {
            label: Some("present"),
            color_attachments: &[Some(wgpu::RenderPassColorAttachment {
                view: target.view,
                depth_slice: None,
                resolve_target: None,
                ops: wgpu::Operations {
                    load: wgpu::LoadOp::Clear(wgpu::Color::BLACK),
                    store: wgpu::StoreOp::Store,
                },
            })],
            depth_stencil_attachment: None,
            timestamp_writes: None,
            occlusion_query_set: None,
            multiview_mask: None,
        });
        pass.set_pipeline(&self.pipeline);
        pass.set_bind_group(0, &group, &[]);
        pass.draw(0..3, 0..1);
    }
}
