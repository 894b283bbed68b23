//! G-buffer (splat.wgsl): surfels as oriented discs with true depth into distance, normal and
//! albedo targets. Discs are grown to a minimum pixel radius so the demo's sampling leaves no
//! holes.
//!
//! Blended splatting (`Settings::splat_blend`, where the adapter can blend `Rgba16Float`): the
//! front-most disc alone gives every pixel its own disc's normal, depth and light, so a wall seen
//! at a grazing angle breaks into scales. Instead the discs are drawn twice. The depth pass
//! (`fs_gbuffer`) is the plain one: the front-most disc's distance (the point shaded, picking,
//! holes), normal and material in the targets, its depth in the depth buffer. The accumulation
//! pass (`fs_blend`) draws every disc pulled toward the eye by its depth tolerance and tests it
//! against that depth (not written): a disc within its tolerance behind the front passes. It adds
//! the fragment's normal and albedo with a smooth radial weight, times how well its normal agrees
//! with the front disc's (the other face of a crease, the far side of a pillar's outline lie
//! within the tolerance too). Shade divides by the weights, so each pixel is shaded once with the
//! surface's blended normal and albedo at the front disc's point. (Pushing the depth pass back
//! instead, by a tolerance that grows at grazing angles, was the first version: its depth test
//! then chose the disc with the nearest pushed depth, at a crease the steep wall's disc over the
//! grazing floor's, and shaded the floor as wall. Blending the distance too was tried: where the
//! tolerance reaches far, on sparse clouds and at silhouettes, it pulls the point behind the
//! surface, which then reads as shadowed: a 1,000-point LAS file went 79% black.) Discs of a
//! surface behind a depth gap fail the test: silhouettes stay crisp. Where float targets cannot
//! blend, the front-most disc is kept, as before.

use super::splat;
use crate::error::Result;
use crate::gpu::Gpu;
use crate::gpu::types::SplatUniform;

/// Packed f32 distance and octahedral normal (splat.wgsl): 8-bit unorm targets render everywhere.
pub(crate) const DISTANCE_FORMAT: wgpu::TextureFormat = wgpu::TextureFormat::Rgba8Unorm;
pub(crate) const NORMAL_FORMAT: wgpu::TextureFormat = wgpu::TextureFormat::Rgba8Unorm;
pub(crate) const ALBEDO_FORMAT: wgpu::TextureFormat = wgpu::TextureFormat::Rgba8UnormSrgb;
/// Blended splatting's sums (weights up to thousands: f16 holds them).
pub(crate) const BLEND_FORMAT: wgpu::TextureFormat = wgpu::TextureFormat::Rgba16Float;

/// The accumulation pass pulls each disc toward the eye by this many of its radii (up to 4x more
/// at grazing angles, splat.wgsl): the depth tolerance within which discs count as one surface. A disc's
/// neighbours on a surface scanned with normals a few degrees apart lie well within one radius;
/// the far side of a pillar or a fold lies beyond it.
pub(crate) const BLEND_DEPTH_RADII: f32 = 1.0;

/// Whether `gpu` can render and blend the accumulation targets.
pub(crate) fn can_blend(gpu: &Gpu) -> bool {
    let f = gpu.adapter.get_texture_format_features(BLEND_FORMAT);
    f.allowed_usages.contains(wgpu::TextureUsages::RENDER_ATTACHMENT)
        && f.flags.contains(wgpu::TextureFormatFeatureFlags::BLENDABLE)
}

/// The targets of one image size.
#[derive(Debug)]
pub(crate) struct Targets {
    pub(crate) width: u32,
    pub(crate) height: u32,
    pub(crate) distance: wgpu::Texture,
    pub(crate) normal: wgpu::Texture,
    pub(crate) albedo: wgpu::Texture,
    pub(crate) depth: wgpu::Texture,
    /// Blended splatting's sums (w n, w) and (w albedo, unused); 1x1 and unused without it.
    pub(crate) normal_weight: wgpu::Texture,
    pub(crate) albedo_sum: wgpu::Texture,
    /// The accumulation pass's view of the depth pass's normal target (blending only).
    front_normal: Option<wgpu::BindGroup>,
}

/// The G-buffer pass and the camera's splat uniforms (slot 0 the depth pass, 1 the accumulation).
#[derive(Debug)]
pub(crate) struct Gbuffer {
    pipeline: wgpu::RenderPipeline,
    camera: splat::Uniforms,
    /// The accumulation pass and the layout of the front normal it reads, where blending.
    blend: Option<(wgpu::RenderPipeline, wgpu::BindGroupLayout)>,
}

impl Gbuffer {
    /// The pass, fetching surfels as `fetch` does; blended where `blend` and the adapter can.
    pub(crate) fn new(
        gpu: &Gpu,
        layout: &wgpu::BindGroupLayout,
        fetch: &splat::Fetch,
        blend: bool,
    ) -> Result<Self> {
        let t = |format, blend| {
            Some(wgpu::ColorTargetState { format, blend, write_mask: wgpu::ColorWrites::ALL })
        };
        let targets = [t(DISTANCE_FORMAT, None), t(NORMAL_FORMAT, None), t(ALBEDO_FORMAT, None)];
        let pipeline = splat::pipeline(gpu, "gbuffer", layout, fetch, ("fs_gbuffer", &targets), None)?;
        let blend = if blend && can_blend(gpu) {
            let add = wgpu::BlendComponent {
                src_factor: wgpu::BlendFactor::One,
                dst_factor: wgpu::BlendFactor::One,
                operation: wgpu::BlendOperation::Add,
            };
            let sum = Some(wgpu::BlendState { color: add, alpha: add });
            let targets = [t(BLEND_FORMAT, sum), t(BLEND_FORMAT, sum)];
            let front = gpu.device.create_bind_group_layout(&wgpu::BindGroupLayoutDescriptor {
                label: Some("gbuffer front normal"),
                entries: &[wgpu::BindGroupLayoutEntry {
                    binding: 0,
                    visibility: wgpu::ShaderStages::FRAGMENT,
                    ty: wgpu::BindingType::Texture {
                        sample_type: wgpu::TextureSampleType::Float { filterable: false },
                        view_dimension: wgpu::TextureViewDimension::D2,
                        multisampled: false,
                    },
                    count: None,
                }],
            });
            let stage = ("fs_blend", &targets[..]);
            Some((splat::pipeline(gpu, "gbuffer blend", layout, fetch, stage, Some(&front))?, front))
        } else {
            None
        };
        Ok(Self { pipeline, camera: splat::Uniforms::new(gpu, "camera splat", layout, 2)?, blend })
    }

    /// Whether the pass blends splats (else the front-most disc is shown).
    pub(crate) fn blends(&self) -> bool {
        self.blend.is_some()
    }

    /// The targets of a `width` x `height` image.
    pub(crate) fn targets(&self, gpu: &Gpu, width: u32, height: u32) -> Result<Targets> {
        let sampled = wgpu::TextureUsages::TEXTURE_BINDING;
        let make = |label, format, usage| gpu.texture_2d(label, width, height, format, usage);
        // Copy source: a viewer reads a pixel's distance back to pick a point.
        let usage = wgpu::TextureUsages::RENDER_ATTACHMENT | sampled | wgpu::TextureUsages::COPY_SRC;
        let distance = make("gbuffer distance", DISTANCE_FORMAT, usage)?;
        let (sums, side) = match self.blend {
            Some(_) => (wgpu::TextureUsages::RENDER_ATTACHMENT | sampled, (width, height)),
            None => (sampled, (1, 1)),
        };
        let sum = |label| gpu.texture_2d(label, side.0, side.1, BLEND_FORMAT, sums);
        let normal = make("gbuffer normal", NORMAL_FORMAT, usage)?;
        let front_normal = self.blend.as_ref().map(|(_, layout)| {
            gpu.device.create_bind_group(&wgpu::BindGroupDescriptor {
                label: Some("gbuffer front normal"),
                layout,
                entries: &[wgpu::BindGroupEntry {
                    binding: 0,
                    resource: wgpu::BindingResource::TextureView(&normal.create_view(&Default::default())),
                }],
            })
        });
        Ok(Targets {
            width,
            height,
            normal,
            front_normal,
            albedo: make("gbuffer albedo", ALBEDO_FORMAT, usage)?,
            depth: make("gbuffer depth", splat::DEPTH_FORMAT, wgpu::TextureUsages::RENDER_ATTACHMENT)?,
            distance,
            normal_weight: sum("gbuffer blend normal")?,
            albedo_sum: sum("gbuffer blend albedo")?,
        })
    }

    /// The camera the next recording draws from.
    pub(crate) fn set_camera(&self, gpu: &Gpu, u: &SplatUniform) {
        let mut depth_pass = *u;
        depth_pass.splat[2] = 0.0;
        self.camera.write(gpu, 0, &depth_pass);
        let mut pulled = *u;
        pulled.splat[2] = -BLEND_DEPTH_RADII;
        self.camera.write(gpu, 1, &pulled);
    }

    pub(crate) fn record(
        &self,
        enc: &mut wgpu::CommandEncoder,
        targets: &Targets,
        fetch: &splat::Fetch,
        runs: &[splat::SplatRun],
        (timestamps, stats): (Option<wgpu::RenderPassTimestampWrites<'_>>, Option<(&wgpu::QuerySet, u32)>),
    ) {
        let views =
            [&targets.distance, &targets.normal, &targets.albedo].map(|t| t.create_view(&Default::default()));
        let depth = targets.depth.create_view(&Default::default());
        let attach = |view| {
            Some(wgpu::RenderPassColorAttachment {
                view,
                depth_slice: None,
                resolve_target: None,
                ops: wgpu::Operations {
                    load: wgpu::LoadOp::Clear(wgpu::Color::TRANSPARENT),
                    store: wgpu::StoreOp::Store,
                },
            })
        };
        let blend = self.blend.as_ref();
        // With an accumulation pass the timestamps span both: the depth pass starts them, the
        // accumulation ends them.
        let (first_ts, second_ts) = match (timestamps, blend.is_some()) {
            (Some(t), true) => (
                Some(wgpu::RenderPassTimestampWrites { end_of_pass_write_index: None, ..t.clone() }),
                Some(wgpu::RenderPassTimestampWrites { beginning_of_pass_write_index: None, ..t }),
            ),
            (t, _) => (t, None),
        };
        let mut depth_ops = splat::depth_cleared(&depth);
        if blend.is_some() {
            // The accumulation pass tests against it.
            depth_ops.depth_ops =
                Some(wgpu::Operations { load: wgpu::LoadOp::Clear(1.0), store: wgpu::StoreOp::Store });
        }
        {
            let mut pass = enc.begin_render_pass(&wgpu::RenderPassDescriptor {
                label: Some("gbuffer"),
                color_attachments: &[attach(&views[0]), attach(&views[1]), attach(&views[2])],
                depth_stencil_attachment: Some(depth_ops),
                timestamp_writes: first_ts,
                occlusion_query_set: None,
                multiview_mask: None,
            });
            if let Some((set, i)) = stats {
                pass.begin_pipeline_statistics_query(set, i);
            }
            pass.set_pipeline(&self.pipeline);
            pass.set_bind_group(0, &self.camera.groups[0], &[]);
            // The surfel runs in view (the renderer culls by chunk box).
            fetch.draw(&mut pass, runs);
            if stats.is_some() {
                pass.end_pipeline_statistics_query();
            }
        }
        let (Some((pipeline, _)), Some(front)) = (blend, &targets.front_normal) else { return };
        let sums = [&targets.normal_weight, &targets.albedo_sum].map(|t| t.create_view(&Default::default()));
        let mut pass = enc.begin_render_pass(&wgpu::RenderPassDescriptor {
            label: Some("gbuffer blend"),
            color_attachments: &[attach(&sums[0]), attach(&sums[1])],
            depth_stencil_attachment: Some(wgpu::RenderPassDepthStencilAttachment {
                view: &depth,
                depth_ops: Some(wgpu::Operations { load: wgpu::LoadOp::Load, store: wgpu::StoreOp::Discard }),
                stencil_ops: None,
            }),
            timestamp_writes: second_ts,
            occlusion_query_set: None,
            multiview_mask: None,
        });
        pass.set_pipeline(pipeline);
        pass.set_bind_group(0, &self.camera.groups[1], &[]);
        pass.set_bind_group(2, front, &[]);
        fetch.draw(&mut pass, runs);
    }
}
