//! G-buffer (splat.wgsl, `fs_gbuffer`): surfels as oriented discs with true depth into distance,
//! normal and albedo targets. Discs are grown to a minimum pixel radius so the demo's sampling
//! leaves no holes.

use super::splat;
use crate::error::Result;
use crate::gpu::Gpu;
use crate::gpu::types::SplatUniform;

/// Packed f32 distance and octahedral normal (splat.wgsl): 8-bit unorm targets render everywhere.
pub(crate) const DISTANCE_FORMAT: wgpu::TextureFormat = wgpu::TextureFormat::Rgba8Unorm;
pub(crate) const NORMAL_FORMAT: wgpu::TextureFormat = wgpu::TextureFormat::Rgba8Unorm;
pub(crate) const ALBEDO_FORMAT: wgpu::TextureFormat = wgpu::TextureFormat::Rgba8UnormSrgb;

/// The targets of one image size.
#[derive(Debug)]
pub(crate) struct Targets {
    pub(crate) width: u32,
    pub(crate) height: u32,
    pub(crate) distance: wgpu::Texture,
    pub(crate) normal: wgpu::Texture,
    pub(crate) albedo: wgpu::Texture,
    pub(crate) depth: wgpu::Texture,
}

impl Targets {
    pub(crate) fn new(gpu: &Gpu, width: u32, height: u32) -> Result<Self> {
        let make = |label, format| {
            gpu.texture_2d(
                label,
                width,
                height,
                format,
                // Copy source: a viewer reads a pixel's distance back to pick a point.
                wgpu::TextureUsages::RENDER_ATTACHMENT
                    | wgpu::TextureUsages::TEXTURE_BINDING
                    | wgpu::TextureUsages::COPY_SRC,
            )
        };
        Ok(Self {
            width,
            height,
            distance: make("gbuffer distance", DISTANCE_FORMAT)?,
            normal: make("gbuffer normal", NORMAL_FORMAT)?,
            albedo: make("gbuffer albedo", ALBEDO_FORMAT)?,
            depth: make("gbuffer depth", splat::DEPTH_FORMAT)?,
        })
    }
}

/// The G-buffer pass and the camera's splat uniform.
#[derive(Debug)]
pub(crate) struct Gbuffer {
    pipeline: wgpu::RenderPipeline,
    camera: splat::Uniforms,
}

impl Gbuffer {
    /// The pass, fetching surfels as `fetch` does.
    pub(crate) fn new(gpu: &Gpu, layout: &wgpu::BindGroupLayout, fetch: &splat::Fetch) -> Result<Self> {
        let t =
            |format| Some(wgpu::ColorTargetState { format, blend: None, write_mask: wgpu::ColorWrites::ALL });
        let targets = [t(DISTANCE_FORMAT), t(NORMAL_FORMAT), t(ALBEDO_FORMAT)];
        Ok(Self {
            pipeline: splat::pipeline(gpu, "gbuffer", layout, fetch, "fs_gbuffer", &targets)?,
            camera: splat::Uniforms::new(gpu, "camera splat", layout, 1)?,
        })
    }

    /// The camera the next recording draws from.
    pub(crate) fn set_camera(&self, gpu: &Gpu, u: &SplatUniform) {
        self.camera.write(gpu, 0, u);
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
        let mut pass = enc.begin_render_pass(&wgpu::RenderPassDescriptor {
            label: Some("gbuffer"),
            color_attachments: &[attach(&views[0]), attach(&views[1]), attach(&views[2])],
            depth_stencil_attachment: Some(splat::depth_cleared(&depth)),
            timestamp_writes: timestamps,
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
}
