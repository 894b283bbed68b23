//! One module per pass, its WGSL beside it. Each builds its pipeline once and records itself into
//! an encoder; the renderer decides (through the effect plan) which ones run.
//!
//! Compute passes share bind group 0 (the scene, declared in shaders/common.wgsl); a pass's own
//! resources are group 1.

pub mod env;
pub mod gbuffer;
pub mod inject;
pub mod mip;
pub mod propagate;
pub mod shade;
pub mod shadow;

use crate::gpu::Gpu;

/// Bind group 0 layout: keep in sync with the bindings in shaders/common.wgsl.
pub fn scene_layout(gpu: &Gpu) -> wgpu::BindGroupLayout {
    let mut entries = vec![wgpu::BindGroupLayoutEntry {
        binding: 0,
        visibility: wgpu::ShaderStages::COMPUTE,
        ty: wgpu::BindingType::Buffer {
            ty: wgpu::BufferBindingType::Uniform,
            has_dynamic_offset: false,
            min_binding_size: None,
        },
        count: None,
    }];
    for b in 1..=8 {
        entries.push(storage_entry(b, false));
    }
    entries.push(texture_entry(9, wgpu::TextureViewDimension::D2));
    entries.push(storage_entry(10, false));
    entries.push(storage_entry(11, false));
    gpu.device.create_bind_group_layout(&wgpu::BindGroupLayoutDescriptor {
        label: Some("scene"),
        entries: &entries,
    })
}

pub fn storage_entry(binding: u32, read_only: bool) -> wgpu::BindGroupLayoutEntry {
    wgpu::BindGroupLayoutEntry {
        binding,
        visibility: wgpu::ShaderStages::COMPUTE,
        ty: wgpu::BindingType::Buffer {
            ty: wgpu::BufferBindingType::Storage { read_only },
            has_dynamic_offset: false,
            min_binding_size: None,
        },
        count: None,
    }
}

pub fn uniform_entry(
    binding: u32,
    visibility: wgpu::ShaderStages,
    dynamic: bool,
) -> wgpu::BindGroupLayoutEntry {
    wgpu::BindGroupLayoutEntry {
        binding,
        visibility,
        ty: wgpu::BindingType::Buffer {
            ty: wgpu::BufferBindingType::Uniform,
            has_dynamic_offset: dynamic,
            min_binding_size: None,
        },
        count: None,
    }
}

pub fn texture_entry(binding: u32, dim: wgpu::TextureViewDimension) -> wgpu::BindGroupLayoutEntry {
    wgpu::BindGroupLayoutEntry {
        binding,
        visibility: wgpu::ShaderStages::COMPUTE,
        ty: wgpu::BindingType::Texture {
            sample_type: wgpu::TextureSampleType::Float { filterable: false },
            view_dimension: dim,
            multisampled: false,
        },
        count: None,
    }
}

/// A compute pipeline from common.wgsl + `pass_src`, entry point `entry`; `radiance_f16` sets the
/// pipeline constant of the same name (the radiance pyramid's storage precision).
pub fn compute_pipeline(
    gpu: &Gpu,
    label: &str,
    pass_src: &str,
    entry: &str,
    layouts: &[&wgpu::BindGroupLayout],
    radiance_f16: bool,
) -> wgpu::ComputePipeline {
    let module = gpu.device.create_shader_module(wgpu::ShaderModuleDescriptor {
        label: Some(label),
        source: wgpu::ShaderSource::Wgsl(crate::shaders::compose(pass_src).into()),
    });
    let layouts: Vec<Option<&wgpu::BindGroupLayout>> = layouts.iter().map(|l| Some(*l)).collect();
    let layout = gpu.device.create_pipeline_layout(&wgpu::PipelineLayoutDescriptor {
        label: Some(label),
        bind_group_layouts: &layouts,
        immediate_size: 0,
    });
    gpu.device.create_compute_pipeline(&wgpu::ComputePipelineDescriptor {
        label: Some(label),
        layout: Some(&layout),
        module: &module,
        entry_point: Some(entry),
        compilation_options: wgpu::PipelineCompilationOptions {
            constants: &[("radiance_f16", if radiance_f16 { 1.0 } else { 0.0 })],
            ..Default::default()
        },
        cache: None,
    })
}

/// A compute pass with one invocation per leaf that binds only the scene (inject, env,
/// propagate); its WGSL entry point has the pass's name.
#[derive(Debug)]
pub struct LeafPass {
    pipeline: wgpu::ComputePipeline,
}

impl LeafPass {
    pub fn new(
        gpu: &Gpu,
        name: &str,
        pass_src: &str,
        scene: &wgpu::BindGroupLayout,
        radiance_f16: bool,
    ) -> Self {
        Self { pipeline: compute_pipeline(gpu, name, pass_src, name, &[scene], radiance_f16) }
    }

    pub fn record(&self, pass: &mut wgpu::ComputePass<'_>, scene: &wgpu::BindGroup, leaf_count: u32) {
        pass.set_pipeline(&self.pipeline);
        pass.set_bind_group(0, scene, &[]);
        dispatch_linear(pass, leaf_count);
    }
}

/// Dispatches 64-wide groups covering `n` items as a 2D grid (at most 65535 groups per
/// dimension); shaders recover the item with `linear_index` (common.wgsl).
pub fn dispatch_linear(pass: &mut wgpu::ComputePass<'_>, n: u32) {
    let groups = n.div_ceil(64).max(1);
    let x = groups.min(65535);
    pass.dispatch_workgroups(x, groups.div_ceil(x), 1);
}
