//! One module per pass, its WGSL beside it. Each builds its pipeline once, owns its resources and
//! bind groups, and records itself into an encoder; the renderer decides (through the effect plan)
//! which ones run.
//!
//! Compute passes share two bind groups, declared by the WGSL subsystems they import: group 0 the
//! static scene (read-only: parameters, tiles, nodes, leaves, lights, shadow matrices and atlas,
//! rock, light grid) and group 1 the light state (read-write: leaf light, radiance pyramid,
//! statistics). A pass's own resources are group 2. Layouts are reflected from each composed
//! module (naga), so a pass binds only what its imports declare.

pub mod cpu_ref;
pub mod env;
pub mod expose;
pub mod gbuffer;
pub mod inject;
pub mod mip;
pub mod propagate;
pub mod rebase;
pub mod resolve;
pub mod shade;
pub mod shadow;
pub mod splat;

use std::collections::BTreeMap;

use crate::error::{Error, Result};
use crate::gpu::Gpu;

/// A resource of a shared bind group.
#[derive(Clone, Debug)]
pub(crate) enum Resource {
    Buffer(wgpu::Buffer),
    Texture(wgpu::TextureView),
}

impl Resource {
    fn binding(&self) -> wgpu::BindingResource<'_> {
        match self {
            Resource::Buffer(b) => b.as_entire_binding(),
            Resource::Texture(v) => wgpu::BindingResource::TextureView(v),
        }
    }
}

/// The resources of the shared bind groups, by group then binding (the numbers in the WGSL).
#[derive(Clone, Debug, Default)]
pub(crate) struct Shared {
    pub(crate) groups: BTreeMap<u32, BTreeMap<u32, Resource>>,
}

impl Shared {
    pub(crate) fn insert(&mut self, group: u32, binding: u32, resource: Resource) {
        self.groups.entry(group).or_default().insert(binding, resource);
    }
}

/// Group of a pass's own resources.
pub(crate) const OWN_GROUP: u32 = 2;

/// The bind group layout entries a composed WGSL module declares, by group (naga reflection of
/// its resource variables): uniforms, storage buffers (read-only unless written) and
/// non-filterable float 2D textures, visible to `stages`.
pub fn reflect_layouts(
    src: &str,
    stages: wgpu::ShaderStages,
) -> Result<BTreeMap<u32, Vec<wgpu::BindGroupLayoutEntry>>> {
    let internal = |message: String| Error::Internal { what: "WGSL reflection", message };
    let module = naga::front::wgsl::parse_str(src).map_err(|e| internal(e.emit_to_string(src)))?;
    let mut groups: BTreeMap<u32, Vec<wgpu::BindGroupLayoutEntry>> = BTreeMap::new();
    for (_, var) in module.global_variables.iter() {
        let Some(rb) = &var.binding else { continue };
        let ty = match var.space {
            naga::AddressSpace::Uniform => wgpu::BindingType::Buffer {
                ty: wgpu::BufferBindingType::Uniform,
                has_dynamic_offset: false,
                min_binding_size: None,
            },
            naga::AddressSpace::Storage { access } => wgpu::BindingType::Buffer {
                ty: wgpu::BufferBindingType::Storage {
                    read_only: !access.contains(naga::StorageAccess::STORE),
                },
                has_dynamic_offset: false,
                min_binding_size: None,
            },
            naga::AddressSpace::Handle => match module.types[var.ty].inner {
                naga::TypeInner::Image {
                    dim: naga::ImageDimension::D2,
                    arrayed: false,
                    class: naga::ImageClass::Sampled { kind: naga::ScalarKind::Float, multi: false },
                } => wgpu::BindingType::Texture {
                    sample_type: wgpu::TextureSampleType::Float { filterable: false },
                    view_dimension: wgpu::TextureViewDimension::D2,
                    multisampled: false,
                },
                ref other => return Err(internal(format!("binding {rb:?} has unsupported type {other:?}"))),
            },
            other => return Err(internal(format!("binding {rb:?} in address space {other:?}"))),
        };
        groups.entry(rb.group).or_default().push(wgpu::BindGroupLayoutEntry {
            binding: rb.binding,
            visibility: stages,
            ty,
            count: None,
        });
    }
    for entries in groups.values_mut() {
        entries.sort_by_key(|e| e.binding);
    }
    Ok(groups)
}

/// A compute pipeline with its reflected layouts and its shared bind groups made.
#[derive(Debug)]
pub(crate) struct ComputePipeline {
    pub(crate) pipeline: wgpu::ComputePipeline,
    /// Layout of the pass's own group ([`OWN_GROUP`]), when its WGSL declares one.
    pub(crate) own_layout: Option<wgpu::BindGroupLayout>,
    shared: Vec<(u32, wgpu::BindGroup)>,
}

impl ComputePipeline {
    /// Sets the pipeline and the shared bind groups.
    pub(crate) fn bind(&self, pass: &mut wgpu::ComputePass<'_>) {
        pass.set_pipeline(&self.pipeline);
        for (group, bg) in &self.shared {
            pass.set_bind_group(*group, bg, &[]);
        }
    }
}

/// The settings baked into the passes as WGSL pipeline constants (`override`s), so a pass
/// compiles without the code an unset one would skip (a uniform flag kept the plane code in the
/// march's inner loop and slowed propagate by a third even where it was off: docs/runtime.md
/// "Cone planes").
#[derive(Clone, Copy, Debug, Default)]
pub(crate) struct PassConstants {
    /// `radiance_f16` (shaders/light_state.wgsl): the radiance pyramid's precision.
    pub radiance_f16: bool,
    /// `cone_planes` (shaders/cone.wgsl): `Settings::cone_planes`.
    pub cone_planes: bool,
    /// `cone_rays` (shaders/cone_rays.wgsl): `Settings::cone_rays`.
    pub cone_rays: bool,
}

impl PassConstants {
    /// The pipeline constants a composed source declares, with their values: WebGPU rejects a
    /// constant the module does not declare (and naga does since wgpu #9133), and not every
    /// pass imports both.
    fn for_source(self, src: &str) -> Vec<(&'static str, f64)> {
        let all = [
            ("radiance_f16", self.radiance_f16),
            ("cone_planes", self.cone_planes),
            ("cone_rays", self.cone_rays),
        ];
        all.into_iter()
            .filter(|(name, _)| src.contains(&format!("override {name}:")))
            .map(|(name, on)| (name, if on { 1.0 } else { 0.0 }))
            .collect()
    }
}

/// Pipeline `label` from `pass_src` (composed with its imports), entry point `entry`;
/// `consts` sets the pipeline constants the source declares ([`PassConstants`]).
/// Groups other than [`OWN_GROUP`] are bound from `shared`.
pub(crate) fn compute_pipeline(
    gpu: &Gpu,
    label: &'static str,
    pass_src: &str,
    entry: &str,
    shared: &Shared,
    consts: PassConstants,
) -> Result<ComputePipeline> {
    let src = crate::shaders::compose(pass_src)?;
    let constants = consts.for_source(&src);
    let reflected = reflect_layouts(&src, wgpu::ShaderStages::COMPUTE)?;
    let top = reflected.keys().max().copied().unwrap_or(0);
    let layouts: Vec<wgpu::BindGroupLayout> = (0..=top)
        .map(|g| {
            gpu.device.create_bind_group_layout(&wgpu::BindGroupLayoutDescriptor {
                label: Some(label),
                entries: reflected.get(&g).map_or(&[][..], Vec::as_slice),
            })
        })
        .collect();
    let mut bound = Vec::new();
    for (&g, entries) in reflected.iter().filter(|(g, _)| **g != OWN_GROUP) {
        let resources = shared.groups.get(&g);
        let bind: Vec<wgpu::BindGroupEntry<'_>> = entries
            .iter()
            .map(|e| {
                let r = resources.and_then(|r| r.get(&e.binding)).ok_or_else(|| Error::Internal {
                    what: label,
                    message: format!("no resource for group {g} binding {}", e.binding),
                })?;
                Ok(wgpu::BindGroupEntry { binding: e.binding, resource: r.binding() })
            })
            .collect::<Result<_>>()?;
        let group = gpu.device.create_bind_group(&wgpu::BindGroupDescriptor {
            label: Some(label),
            layout: &layouts[g as usize],
            entries: &bind,
        });
        bound.push((g, group));
    }
    let module = gpu.device.create_shader_module(wgpu::ShaderModuleDescriptor {
        label: Some(label),
        source: wgpu::ShaderSource::Wgsl(src.into()),
    });
    let refs: Vec<Option<&wgpu::BindGroupLayout>> = layouts.iter().map(Some).collect();
    let layout = gpu.device.create_pipeline_layout(&wgpu::PipelineLayoutDescriptor {
        label: Some(label),
        bind_group_layouts: &refs,
        immediate_size: 0,
    });
    let pipeline = gpu.device.create_compute_pipeline(&wgpu::ComputePipelineDescriptor {
        label: Some(label),
        layout: Some(&layout),
        module: &module,
        entry_point: Some(entry),
        compilation_options: wgpu::PipelineCompilationOptions { constants: &constants, ..Default::default() },
        cache: None,
    });
    let own_layout = reflected.contains_key(&OWN_GROUP).then(|| layouts[OWN_GROUP as usize].clone());
    Ok(ComputePipeline { pipeline, own_layout, shared: bound })
}

/// A pipeline of its own over a frame's buffers (resolve, expose): `src` composed, its one bind
/// group (group 0) reflected, entry point `entry`. Returns the pipeline and that group's layout.
pub(crate) fn frame_pipeline(
    gpu: &Gpu,
    label: &'static str,
    src: &str,
    entry: &str,
) -> Result<(wgpu::ComputePipeline, wgpu::BindGroupLayout)> {
    let src = crate::shaders::compose(src)?;
    let reflected = reflect_layouts(&src, wgpu::ShaderStages::COMPUTE)?;
    let entries = reflected
        .get(&0)
        .ok_or_else(|| Error::Internal { what: label, message: "the WGSL declares no group 0".into() })?;
    let layout =
        gpu.device.create_bind_group_layout(&wgpu::BindGroupLayoutDescriptor { label: Some(label), entries });
    let module = gpu.device.create_shader_module(wgpu::ShaderModuleDescriptor {
        label: Some(label),
        source: wgpu::ShaderSource::Wgsl(src.into()),
    });
    let pl = gpu.device.create_pipeline_layout(&wgpu::PipelineLayoutDescriptor {
        label: Some(label),
        bind_group_layouts: &[Some(&layout)],
        immediate_size: 0,
    });
    let pipeline = gpu.device.create_compute_pipeline(&wgpu::ComputePipelineDescriptor {
        label: Some(label),
        layout: Some(&pl),
        module: &module,
        entry_point: Some(entry),
        compilation_options: Default::default(),
        cache: None,
    });
    Ok((pipeline, layout))
}

/// A compute pass with one invocation per leaf, dispatched once per batch, each batch's uniform
/// (binding 0 of the pass's own group) in a bind group made once: inject's lights and the cone
/// passes' cones (`cone_batched`). Results accumulate in the leaf state between dispatches.
#[derive(Debug)]
pub(crate) struct Batched {
    name: &'static str,
    pipeline: ComputePipeline,
    batches: Vec<wgpu::BindGroup>,
}

impl Batched {
    /// The pass `name` (its WGSL entry point has the pass's name) with one batch per value.
    pub(crate) fn new<T: bytemuck::Pod>(
        gpu: &Gpu,
        name: &'static str,
        pass_src: &str,
        shared: &Shared,
        consts: PassConstants,
        values: impl IntoIterator<Item = T>,
    ) -> Result<Self> {
        let pipeline = compute_pipeline(gpu, name, pass_src, name, shared, consts)?;
        let mut pass = Self { name, pipeline, batches: Vec::new() };
        pass.set_values(gpu, values)?;
        Ok(pass)
    }

    /// One batch per value from now on (inject's batches after a light edit: the pipeline
    /// stays, only the small uniforms are made again).
    pub(crate) fn set_values<T: bytemuck::Pod>(
        &mut self,
        gpu: &Gpu,
        values: impl IntoIterator<Item = T>,
    ) -> Result<()> {
        let name = self.name;
        let layout = own_layout(&self.pipeline, name)?;
        self.batches = values
            .into_iter()
            .map(|v| {
                let u = gpu.buffer_init(name, bytemuck::bytes_of(&v), wgpu::BufferUsages::UNIFORM)?;
                Ok(gpu.device.create_bind_group(&wgpu::BindGroupDescriptor {
                    label: Some(name),
                    layout,
                    entries: &[wgpu::BindGroupEntry { binding: 0, resource: u.as_entire_binding() }],
                }))
            })
            .collect::<Result<_>>()?;
        Ok(())
    }

    pub(crate) fn record(&self, pass: &mut wgpu::ComputePass<'_>, leaf_count: u32) {
        self.pipeline.bind(pass);
        for bg in &self.batches {
            pass.set_bind_group(OWN_GROUP, bg, &[]);
            dispatch_linear(pass, leaf_count);
        }
    }
}

/// Cones traced by one dispatch of a cone pass ([`cone_batched`]).
pub(crate) const CONES_PER_BATCH: u32 = 1;

/// A pass that traces the cone set (env, propagate) in batches of [`CONES_PER_BATCH`] cones per
/// dispatch.
///
/// Why batches: Mesa's software drivers (llvmpipe, lavapipe) share one budget of 65535 loop
/// iterations among all loops of a shader invocation and silently end every loop past it (as in
/// inject.rs). A cone's march loops over its steps, the rock probes of each step and the octree
/// descents of each sample, so an invocation tracing all its cones at fine steps ran out: on the
/// dogleg scene with every leaf sending 1, 16 cones at step 0.1 gathered 0.944 on lavapipe against
/// 0.999 from the CPU reference (which is step-invariant there); 9 cones, or step >= 0.35,
/// matched. With one cone per dispatch the budget is per cone. Results are the same to the bit:
/// the running sums are kept in the leaf state and added to in the same order (the WGSL).
pub(crate) fn cone_batched(
    gpu: &Gpu,
    name: &'static str,
    pass_src: &str,
    shared: &Shared,
    consts: PassConstants,
    cones: u32,
) -> Result<Batched> {
    let batches = (0..cones.div_ceil(CONES_PER_BATCH).max(1)).map(|b| crate::gpu::types::ConeBatch {
        first: b * CONES_PER_BATCH,
        count: CONES_PER_BATCH,
        pad0: 0,
        pad1: 0,
    });
    Batched::new(gpu, name, pass_src, shared, consts, batches)
}

/// The own group's layout of `p`, which its WGSL must declare.
pub(crate) fn own_layout<'a>(
    p: &'a ComputePipeline,
    label: &'static str,
) -> Result<&'a wgpu::BindGroupLayout> {
    p.own_layout
        .as_ref()
        .ok_or(Error::Internal { what: label, message: format!("the WGSL declares no group {OWN_GROUP}") })
}

/// Dispatches 64-wide groups covering `n` items as a 2D grid (at most 65535 groups per
/// dimension); shaders recover the item with `linear_index` (shaders/dispatch.wgsl).
pub(crate) fn dispatch_linear(pass: &mut wgpu::ComputePass<'_>, n: u32) {
    dispatch_groups(pass, n.div_ceil(64));
}

/// Dispatches `groups` workgroups (at least one) as a 2D grid of at most 65535 per dimension;
/// shaders recover the group's index as `id.x + id.y * num_workgroups.x`.
pub(crate) fn dispatch_groups(pass: &mut wgpu::ComputePass<'_>, groups: u32) {
    let groups = groups.max(1);
    let x = groups.min(65535);
    pass.dispatch_workgroups(x, groups.div_ceil(x), 1);
}
