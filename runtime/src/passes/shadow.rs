//! Shadow maps rendered from surfels (splat.wgsl, `fs_shadow`): one square face of distance to the
//! light per cube face of a point light or per spot light, in one 2D atlas (wgpu's GL backend
//! neither renders nor copies into array layers), with a depth buffer for the nearest disc. Owns
//! the atlas and the faces' splat uniforms; inject and shade read the atlas with a 3x3
//! percentage-closer filter (shaders/lights.wgsl).
//!
//! A face draws only the surfel chunks its frustum and its light's range meet (render/chunks.rs),
//! and after a change of resident tiles only the faces that see a changed tile are drawn again
//! (the others keep their texels: the pass loads the atlas and clears a redrawn face by copying a
//! blank one over it). Under a per-frame budget the faces are drawn over several frames into a
//! staging atlas, made when first needed, and copied over the shown one together when the last
//! is drawn (render/shadow_queue.rs).

use glam::{Mat4, Vec3};

use super::splat;
use crate::error::Result;
use crate::gpu::Gpu;
use crate::gpu::types::SplatUniform;

/// Distance to the light as a packed f32 (packing.wgsl `pack_f32`): float targets do not render on GL.
pub(crate) const DISTANCE_FORMAT: wgpu::TextureFormat = wgpu::TextureFormat::Rgba8Unorm;

/// The near-square grid (columns, rows) the atlas lays `layers` faces out in.
pub(crate) fn atlas_grid(layers: u32) -> (u32, u32) {
    let cols = (f64::from(layers).sqrt().ceil() as u32).max(1);
    (cols, layers.div_ceil(cols))
}

/// Clear colour whose packed bytes read back as `f32` `v`.
pub(crate) fn packed_clear(v: f32) -> wgpu::Color {
    let b = v.to_bits().to_le_bytes();
    let c = |i: usize| f64::from(b[i]) / 255.0;
    wgpu::Color { r: c(0), g: c(1), b: c(2), a: c(3) }
}

/// One face of the atlas: light-space view-projection, the light's position, the projection
/// scale (1 / tan(fov / 2)), and the light's range (nothing beyond it is lit: infinite without a
/// cutoff).
#[derive(Clone, Copy, Debug, PartialEq)]
pub(crate) struct Face {
    pub(crate) view_proj: Mat4,
    pub(crate) eye_m: Vec3,
    pub(crate) proj_scale: f32,
    pub(crate) range_m: f32,
}

impl Face {
    /// An atlas slot no light uses (after an edit in place: light/setup.rs `keep_slots`):
    /// never marked out of date, never drawn.
    pub(crate) fn hole() -> Self {
        Face { view_proj: Mat4::ZERO, eye_m: Vec3::ZERO, proj_scale: 0.0, range_m: 0.0 }
    }

    pub(crate) fn is_hole(&self) -> bool {
        self.proj_scale == 0.0
    }
}

#[derive(Debug)]
pub(crate) struct Shadow {
    pipeline: wgpu::RenderPipeline,
    face_size: u32,
    cols: u32,
    atlas: wgpu::TextureView,
    atlas_texture: wgpu::Texture,
    /// One face cleared to "nothing within 1e30 m", copied over a face before it is redrawn.
    blank: wgpu::Texture,
    depth: wgpu::TextureView,
    /// Faces drawn over several frames wait here until the last is drawn (made when first used).
    staging: Option<(wgpu::Texture, wgpu::TextureView)>,
    uniforms: splat::Uniforms,
    faces: Vec<Face>,
    atlas_bytes: u64,
    /// The splat uniforms' smallest disc in pixels and disc scale.
    splat: (f32, f32),
}

impl Shadow {
    /// The atlas for `faces`, with room for `capacity` faces in all (lights an edit adds: see
    /// [`Shadow::set_faces`]; the near-square grid's spare cells add to it), at `face_size`
    /// texels each; faces shrink if the grid would pass the adapter's largest 2D texture.
    #[allow(clippy::too_many_arguments)]
    pub(crate) fn new(
        gpu: &Gpu,
        layout: &wgpu::BindGroupLayout,
        faces: &[Face],
        capacity: usize,
        face_size: u32,
        min_splat_px: f32,
        splat_scale: f32,
        fetch: &splat::Fetch,
    ) -> Result<Self> {
        let targets = [Some(wgpu::ColorTargetState {
            format: DISTANCE_FORMAT,
            blend: None,
            write_mask: wgpu::ColorWrites::ALL,
        })];
        let pipeline = splat::pipeline(gpu, "shadow", layout, fetch, ("fs_shadow", &targets), None)?;
        let layers = capacity.max(faces.len()).max(1) as u32;
        let (cols, rows) = atlas_grid(layers);
        // The grid's spare cells cost nothing more: they are room for faces an edit adds.
        let layers = if faces.is_empty() { layers } else { cols * rows };
        let max_dim = gpu.device.limits().max_texture_dimension_2d;
        let face_size =
            if faces.is_empty() { 1 } else { face_size.min(max_dim / cols).min(max_dim / rows).max(1) };
        let (width, height) = (face_size * cols, face_size * rows);
        let atlas_texture = gpu.texture_2d(
            "shadow atlas",
            width,
            height,
            DISTANCE_FORMAT,
            wgpu::TextureUsages::RENDER_ATTACHMENT
                | wgpu::TextureUsages::TEXTURE_BINDING
                | wgpu::TextureUsages::COPY_DST,
        )?;
        let atlas = atlas_texture.create_view(&Default::default());
        let blank = gpu.texture_2d(
            "shadow blank face",
            face_size,
            face_size,
            DISTANCE_FORMAT,
            wgpu::TextureUsages::RENDER_ATTACHMENT | wgpu::TextureUsages::COPY_SRC,
        )?;
        {
            let mut enc = gpu.device.create_command_encoder(&Default::default());
            let view = blank.create_view(&Default::default());
            enc.begin_render_pass(&wgpu::RenderPassDescriptor {
                label: Some("shadow blank face"),
                color_attachments: &[Some(wgpu::RenderPassColorAttachment {
                    view: &view,
                    depth_slice: None,
                    resolve_target: None,
                    ops: wgpu::Operations {
                        load: wgpu::LoadOp::Clear(packed_clear(1e30)),
                        store: wgpu::StoreOp::Store,
                    },
                })],
                depth_stencil_attachment: None,
                timestamp_writes: None,
                occlusion_query_set: None,
                multiview_mask: None,
            });
            gpu.queue.submit([enc.finish()]);
        }
        let depth = gpu
            .texture_2d(
                "shadow depth",
                width,
                height,
                splat::DEPTH_FORMAT,
                wgpu::TextureUsages::RENDER_ATTACHMENT,
            )?
            .create_view(&Default::default());
        let uniforms = splat::Uniforms::new(gpu, "shadow splat", layout, layers as usize)?;
        let atlas_bytes = (u64::from(width) * u64::from(height) + u64::from(face_size * face_size)) * 8;
        Ok(Self {
            pipeline,
            face_size,
            cols,
            atlas,
            atlas_texture,
            blank,
            depth,
            staging: None,
            uniforms,
            faces: Vec::new(),
            atlas_bytes,
            splat: (min_splat_px, splat_scale),
        }
        .with_faces(gpu, faces))
    }

    fn with_faces(mut self, gpu: &Gpu, faces: &[Face]) -> Self {
        self.set_faces(gpu, faces);
        self
    }

    /// Slots the atlas has room for.
    pub(crate) fn capacity(&self) -> usize {
        self.uniforms.groups.len()
    }

    /// Takes `faces` (at most [`Shadow::capacity`]; more are dropped) in place of the faces it
    /// had; returns the slots whose face changed (holes left out: nothing draws them). Their
    /// texels are stale until drawn again.
    pub(crate) fn set_faces(&mut self, gpu: &Gpu, faces: &[Face]) -> Vec<usize> {
        let faces = &faces[..faces.len().min(self.capacity())];
        let mut changed = Vec::new();
        for (i, f) in faces.iter().enumerate() {
            if self.faces.get(i) == Some(f) || f.is_hole() {
                continue;
            }
            changed.push(i);
            let u = SplatUniform {
                view_proj: f.view_proj.to_cols_array_2d(),
                eye_m: f.eye_m.extend(1.0).to_array(),
                viewport: [self.face_size as f32, self.face_size as f32, self.splat.0, f.proj_scale],
                splat: [self.splat.1, 0.0, 0.0, 0.0],
                // Shadows come from the whole cave: the clip box cuts the view only.
                clip_min_m: [0.0; 4],
                clip_max_m: [0.0; 4],
                pad: [[0.0; 4]; 7],
            };
            self.uniforms.write(gpu, i, &u);
        }
        self.faces = faces.to_vec();
        changed
    }

    /// The distance atlas, as inject and shade bind it.
    pub(crate) fn atlas(&self) -> &wgpu::TextureView {
        &self.atlas
    }

    pub(crate) fn face_size(&self) -> u32 {
        self.face_size
    }

    pub(crate) fn cols(&self) -> u32 {
        self.cols
    }

    /// The faces, as [`Shadow::new`] or [`Shadow::set_faces`] was given them.
    pub(crate) fn faces(&self) -> &[Face] {
        &self.faces
    }

    /// GPU bytes of the atlas, its depth buffer (4 bytes a texel each) and the blank face (the
    /// staging atlas, when made, adds half the first two).
    pub(crate) fn bytes(&self) -> u64 {
        self.atlas_bytes
    }

    /// Makes the staging atlas if it is not made yet; returns the bytes it added (0 if it was).
    pub(crate) fn ensure_staging(&mut self, gpu: &Gpu) -> Result<u64> {
        if self.staging.is_some() {
            return Ok(0);
        }
        let size = self.atlas_texture.size();
        let texture = gpu.texture_2d(
            "shadow staging atlas",
            size.width,
            size.height,
            DISTANCE_FORMAT,
            wgpu::TextureUsages::RENDER_ATTACHMENT
                | wgpu::TextureUsages::COPY_SRC
                | wgpu::TextureUsages::COPY_DST,
        )?;
        let view = texture.create_view(&Default::default());
        self.staging = Some((texture, view));
        Ok(u64::from(size.width) * u64::from(size.height) * 4)
    }

    /// The texel where face `i`'s square starts in the atlas.
    fn corner(&self, i: usize) -> (u32, u32) {
        ((i as u32 % self.cols) * self.face_size, (i as u32 / self.cols) * self.face_size)
    }

    /// Face `i`'s square of an atlas, as a copy source or target.
    fn face_copy<'t>(&self, texture: &'t wgpu::Texture, i: usize) -> wgpu::TexelCopyTextureInfo<'t> {
        let (x, y) = self.corner(i);
        wgpu::TexelCopyTextureInfo {
            texture,
            mip_level: 0,
            origin: wgpu::Origin3d { x, y, z: 0 },
            aspect: wgpu::TextureAspect::All,
        }
    }

    /// Renders `batch`'s faces (each drawing the surfel chunks `runs` gives it) into their squares
    /// of the atlas in one pass (one viewport per face): the shown atlas, cleared whole where
    /// every face is drawn, else the named faces cleared first (the blank face copied over each);
    /// or the staging atlas, whose faces `batch.commit` names are copied to the shown one after.
    pub(crate) fn record<'r>(
        &self,
        enc: &mut wgpu::CommandEncoder,
        fetch: &splat::Fetch,
        batch: &Batch,
        runs: impl Fn(usize) -> &'r [splat::SplatRun],
        (timestamps, stats): (Option<wgpu::RenderPassTimestampWrites<'_>>, Option<(&wgpu::QuerySet, u32)>),
    ) {
        let (target, view) = match (&self.staging, batch.staged) {
            (Some((t, v)), true) => (t, v),
            // The renderer makes the staging atlas before a staged batch; without it, draw shown.
            _ => (&self.atlas_texture, &self.atlas),
        };
        let extent =
            wgpu::Extent3d { width: self.face_size, height: self.face_size, depth_or_array_layers: 1 };
        if !batch.whole {
            for &i in &batch.faces {
                enc.copy_texture_to_texture(self.blank.as_image_copy(), self.face_copy(target, i), extent);
            }
        }
        let load = if batch.whole { wgpu::LoadOp::Clear(packed_clear(1e30)) } else { wgpu::LoadOp::Load };
        {
            let mut pass = enc.begin_render_pass(&wgpu::RenderPassDescriptor {
                label: Some("shadow"),
                color_attachments: &[Some(wgpu::RenderPassColorAttachment {
                    view,
                    depth_slice: None,
                    resolve_target: None,
                    ops: wgpu::Operations { load, store: wgpu::StoreOp::Store },
                })],
                depth_stencil_attachment: Some(splat::depth_cleared(&self.depth)),
                timestamp_writes: timestamps,
                occlusion_query_set: None,
                multiview_mask: None,
            });
            if let Some((set, i)) = stats {
                pass.begin_pipeline_statistics_query(set, i);
            }
            pass.set_pipeline(&self.pipeline);
            let s = self.face_size as f32;
            for &i in &batch.faces {
                let Some(group) = self.uniforms.groups.get(i) else { continue };
                let (x, y) = self.corner(i);
                pass.set_viewport(x as f32, y as f32, s, s, 0.0, 1.0);
                pass.set_bind_group(0, group, &[]);
                fetch.draw(&mut pass, runs(i));
            }
            if stats.is_some() {
                pass.end_pipeline_statistics_query();
            }
        }
        if !std::ptr::eq(target, &self.atlas_texture) {
            for &i in &batch.commit {
                enc.copy_texture_to_texture(
                    self.face_copy(target, i),
                    self.face_copy(&self.atlas_texture, i),
                    extent,
                );
            }
        }
    }
}

/// The faces one shadow pass draws (chosen by render/shadow_queue.rs).
#[derive(Clone, Debug, Default, PartialEq)]
pub(crate) struct Batch {
    /// Faces drawn, in atlas order.
    pub(crate) faces: Vec<usize>,
    /// Surfels the faces draw.
    pub(crate) surfels: u64,
    /// No face is left out of date after this pass.
    pub(crate) finishes: bool,
    /// The faces go to the staging atlas (the pass does not finish, or earlier faces already
    /// wait there); `commit` then lists the staged faces copied to the shown atlas at its end.
    pub(crate) staged: bool,
    pub(crate) commit: Vec<usize>,
    /// Every face of the atlas is drawn, into the shown atlas: the pass clears it whole.
    pub(crate) whole: bool,
}
