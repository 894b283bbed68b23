//! Surfel splatting (splat.wgsl), shared by the shadow and G-buffer passes: the render pipeline
//! that draws every surfel as an oriented disc, its uniform layout, and the uniforms themselves.
//!
//! Surfels are pulled: one non-instanced draw of six vertices a surfel, the vertex shader reading
//! its surfel from the pool as a storage buffer by `vertex_index / 6`. GPUs run such draws far
//! faster than one instance of a six-vertex quad a surfel. A pool larger than one storage binding
//! is bound a window at a time. Where an adapter has no storage buffers in vertex shaders, the
//! surfels are drawn as instances instead, the portable path; both draw the same discs in the
//! same order (instanced draws take no level of detail: render/chunks.rs).

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

/// How the splat passes fetch their surfels: pulled from the pool as a storage buffer, or drawn
/// as instances. One for both passes: the pool and its binding are the renderer's.
#[derive(Debug)]
pub(crate) struct Fetch {
    /// The layout of the surfel binding (group 1) where surfels are pulled; `None`: instanced.
    surfels_layout: Option<wgpu::BindGroupLayout>,
    /// Surfels a window of the pool holds: a pool larger than one storage binding is bound a
    /// window at a time (each starting at a multiple of this, which is a multiple of 32 so a
    /// window starts on a 256-byte offset and at a multiple of every stride).
    window: u32,
    /// The pool ([`Fetch::set_surfels`]; allocated once), and its windows' bindings where pulled.
    surfels: Option<(wgpu::Buffer, Vec<wgpu::BindGroup>)>,
}

impl Fetch {
    /// Pulled where the adapter has storage buffers in vertex shaders, else instanced.
    pub(crate) fn new(gpu: &Gpu, surfel_capacity: u64) -> Self {
        let size = size_of::<SurfelGpu>() as u64;
        let limits = gpu.device.limits();
        let align = u64::from(limits.min_storage_buffer_offset_alignment.max(1));
        // Windows start at multiples of 32 surfels (1,280 bytes: a multiple of every alignment
        // up to 256) or of the alignment's own multiple where it is larger.
        let unit = 32 * align.div_ceil(256).next_power_of_two();
        let fit = limits.max_storage_buffer_binding_size / size / unit * unit;
        let pull =
            gpu.adapter.get_downlevel_capabilities().flags.contains(wgpu::DownlevelFlags::VERTEX_STORAGE)
                && fit > 0;
        let window = fit.min(surfel_capacity.max(1).div_ceil(unit) * unit).min(u64::from(u32::MAX)) as u32;
        let surfels_layout = pull.then(|| {
            gpu.device.create_bind_group_layout(&wgpu::BindGroupLayoutDescriptor {
                label: Some("splat surfels"),
                entries: &[wgpu::BindGroupLayoutEntry {
                    binding: 0,
                    visibility: wgpu::ShaderStages::VERTEX,
                    ty: wgpu::BindingType::Buffer {
                        ty: wgpu::BufferBindingType::Storage { read_only: true },
                        has_dynamic_offset: false,
                        min_binding_size: None,
                    },
                    count: None,
                }],
            })
        });
        Self { surfels_layout, window: window.max(1), surfels: None }
    }

    /// Whether the draws pull their surfels (else they are instanced).
    pub(crate) fn pulls(&self) -> bool {
        self.surfels_layout.is_some()
    }

    /// The surfel pool the draws read.
    pub(crate) fn set_surfels(&mut self, gpu: &Gpu, surfels: &wgpu::Buffer) {
        let size = size_of::<SurfelGpu>() as u64;
        let pool = surfels.size() / size;
        let groups = self.surfels_layout.as_ref().map_or_else(Vec::new, |layout| {
            (0..pool.div_ceil(u64::from(self.window)))
                .map(|w| {
                    let first = w * u64::from(self.window);
                    let n = u64::from(self.window).min(pool - first);
                    gpu.device.create_bind_group(&wgpu::BindGroupDescriptor {
                        label: Some("splat surfels"),
                        layout,
                        entries: &[wgpu::BindGroupEntry {
                            binding: 0,
                            resource: wgpu::BindingResource::Buffer(wgpu::BufferBinding {
                                buffer: surfels,
                                offset: first * size,
                                size: std::num::NonZeroU64::new(n * size),
                            }),
                        }],
                    })
                })
                .collect()
        });
        self.surfels = Some((surfels.clone(), groups));
    }

    /// Draws `runs` into `pass` (its pipeline and group 0 set), binding what they read.
    pub(crate) fn draw(&self, pass: &mut wgpu::RenderPass<'_>, runs: &[SplatRun]) {
        let Some((buffer, groups)) = &self.surfels else { return };
        if !self.pulls() {
            pass.set_vertex_buffer(0, buffer.slice(..));
            for run in runs {
                pass.draw(0..6, run.surfels.clone());
            }
            return;
        }
        let mut bound: Option<u32> = None;
        for run in runs {
            // The stride rides in the instance index (one instance), which the vertex shader
            // reads back; the vertex index counts the surfels drawn in the bound window, so
            // surfel = window start + (vertex / 6) x stride.
            let k = run.stride.max(1);
            let mut start = run.surfels.start;
            while start < run.surfels.end {
                let w = start / self.window;
                let base = w * self.window;
                let end = run.surfels.end.min(base.saturating_add(self.window));
                if bound != Some(w)
                    && let Some(g) = groups.get(w as usize)
                {
                    pass.set_bind_group(1, g, &[]);
                    bound = Some(w);
                }
                let (first, last) = ((start - base).div_ceil(k), (end - base).div_ceil(k));
                if first < last {
                    pass.draw(first * 6..last * 6, k..k + 1);
                }
                start = end;
            }
        }
    }
}

/// Surfels of the pool a splat draw covers: every `stride`-th of `surfels` (those whose pool
/// index is a multiple of it), each grown by sqrt(stride) so that a sparser set still closes the
/// surface (a level of detail: render/chunks.rs chooses it from the discs' size in pixels).
#[derive(Clone, Debug, PartialEq, Eq)]
pub(crate) struct SplatRun {
    pub(crate) surfels: std::ops::Range<u32>,
    pub(crate) stride: u32,
}

impl SplatRun {
    /// Every surfel of `surfels`.
    pub(crate) fn all(surfels: std::ops::Range<u32>) -> Self {
        Self { surfels, stride: 1 }
    }

    /// Surfels the draw covers.
    pub(crate) fn drawn(&self) -> u64 {
        let k = self.stride.max(1);
        u64::from(self.surfels.end.div_ceil(k).saturating_sub(self.surfels.start.div_ceil(k)))
    }
}

const SURFEL_ATTRIBUTES: [wgpu::VertexAttribute; 4] = wgpu::vertex_attr_array![
    0 => Float32x4,
    1 => Float32x4,
    2 => Unorm8x4,
    3 => Uint32,
];

/// A render pipeline drawing every surfel as an oriented disc into `targets`, fetching surfels
/// as `fetch` says. `accumulate`: blended splatting's accumulation pass (depth tested against the
/// depth pass, not written), with the layout of the front normal it reads (group 2).
pub(crate) fn pipeline(
    gpu: &Gpu,
    label: &str,
    layout: &wgpu::BindGroupLayout,
    fetch: &Fetch,
    (fragment_entry, targets): (&str, &[Option<wgpu::ColorTargetState>]),
    accumulate: Option<&wgpu::BindGroupLayout>,
) -> Result<wgpu::RenderPipeline> {
    let module = gpu.device.create_shader_module(wgpu::ShaderModuleDescriptor {
        label: Some("splat"),
        source: wgpu::ShaderSource::Wgsl(crate::shaders::compose(crate::shaders::SPLAT)?.into()),
    });
    let instanced = [Some(wgpu::VertexBufferLayout {
        array_stride: size_of::<SurfelGpu>() as u64,
        step_mode: wgpu::VertexStepMode::Instance,
        attributes: &SURFEL_ATTRIBUTES,
    })];
    // Group 1 the surfel pool where pulled; group 2 the depth pass's front normal, read by the
    // accumulation pass (blended splatting, gbuffer.rs).
    let mut groups: Vec<Option<&wgpu::BindGroupLayout>> = vec![Some(layout), fetch.surfels_layout.as_ref()];
    match accumulate {
        Some(front) => groups.push(Some(front)),
        None if groups[1].is_none() => {
            groups.pop();
        }
        None => {}
    }
    let pl = gpu.device.create_pipeline_layout(&wgpu::PipelineLayoutDescriptor {
        label: Some(label),
        bind_group_layouts: &groups,
        immediate_size: 0,
    });
    Ok(gpu.device.create_render_pipeline(&wgpu::RenderPipelineDescriptor {
        label: Some(label),
        layout: Some(&pl),
        vertex: wgpu::VertexState {
            module: &module,
            entry_point: Some(if fetch.surfels_layout.is_some() { "vs_pulled" } else { "vs" }),
            compilation_options: Default::default(),
            buffers: if fetch.surfels_layout.is_some() { &[] } else { &instanced },
        },
        primitive: wgpu::PrimitiveState { cull_mode: None, ..Default::default() },
        depth_stencil: Some(wgpu::DepthStencilState {
            format: DEPTH_FORMAT,
            depth_write_enabled: Some(accumulate.is_none()),
            depth_compare: Some(if accumulate.is_some() {
                wgpu::CompareFunction::LessEqual
            } else {
                wgpu::CompareFunction::Less
            }),
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
