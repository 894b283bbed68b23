//! Anti-aliasing at rest (resolve.wgsl): while the camera, the light and the settings stay still,
//! each frame is drawn again with its pixels' sample point moved within the pixel (a Halton
//! (2, 3) sequence; sample 0 is the pixel centres) and averaged with the ones before. One sample
//! a frame, so a weak adapter stays as responsive as without it and the image sharpens over the
//! next frames; moving frames draw one sample, as before. The splat pass shifts its projection
//! and the shade pass its rays by the same sub-pixel offset ([`jittered_view_proj`],
//! [`jittered_forward`]: a test checks they agree).
//!
//! Written here rather than taken from a crate: it is two buffers and one small compute shader
//! over grotto's own frame layout.

use glam::{Mat4, Vec3};

use crate::error::Result;
use crate::gpu::Gpu;

/// Samples a pixel a still frame gathers by default (`Settings::still_samples`).
pub const DEFAULT_STILL_SAMPLES: u32 = 8;
/// Most samples a pixel (the f32 sums hold far more; past this the image no longer changes
/// visibly on a 8-bit display).
pub const MAX_STILL_SAMPLES: u32 = 64;

/// Where sample `k` sits in its pixel, in pixels from the centre (x right, y down): the centre
/// for 0, then the Halton (2, 3) points, which fill the pixel evenly for any count.
pub fn jitter_px(k: u32) -> [f32; 2] {
    if k == 0 {
        return [0.0, 0.0];
    }
    [radical_inverse(k, 2) - 0.5, radical_inverse(k, 3) - 0.5]
}

fn radical_inverse(mut k: u32, base: u32) -> f32 {
    let (mut inv, mut f) = (0.0f32, 1.0 / base as f32);
    while k > 0 {
        inv += (k % base) as f32 * f;
        k /= base;
        f /= base as f32;
    }
    inv
}

/// `view_proj` with every pixel sampling `jitter` pixels from its centre: the image moves the
/// other way in normalised device coordinates (y up there, down in pixels).
pub(crate) fn jittered_view_proj(view_proj: Mat4, jitter: [f32; 2], width: u32, height: u32) -> Mat4 {
    let shift = Vec3::new(-2.0 * jitter[0] / width as f32, 2.0 * jitter[1] / height as f32, 0.0);
    Mat4::from_translation(shift) * view_proj
}

/// Shade's ray basis with every pixel's ray through the point `jitter` pixels from its centre:
/// the ray is `forward + right * ndc.x * tan * aspect + up * ndc.y * tan` before normalising,
/// linear in the pixel, so the offset folds into `forward` (shade.wgsl needs no change).
pub(crate) fn jittered_forward(
    forward: Vec3,
    (right, up): (Vec3, Vec3),
    tan_half_fov_y: f32,
    jitter: [f32; 2],
    (width, height): (u32, u32),
) -> Vec3 {
    let aspect = width as f32 / height as f32;
    forward + right * (2.0 * jitter[0] / width as f32 * tan_half_fov_y * aspect)
        - up * (2.0 * jitter[1] / height as f32 * tan_half_fov_y)
}

/// The resolve pipeline.
#[derive(Debug)]
pub(crate) struct Resolve {
    pipeline: wgpu::ComputePipeline,
    layout: wgpu::BindGroupLayout,
}

/// One view's sums and bind group (made on the first still frame of a size).
#[derive(Debug)]
pub(crate) struct Sums {
    uniform: wgpu::Buffer,
    bind_group: wgpu::BindGroup,
    width: u32,
    height: u32,
}

impl Resolve {
    pub(crate) fn new(gpu: &Gpu) -> Result<Self> {
        let (pipeline, layout) =
            super::frame_pipeline(gpu, "resolve", crate::shaders::RESOLVE, "resolve_samples")?;
        Ok(Self { pipeline, layout })
    }

    /// The sums of a `width` x `height` frame in `frame` (shade's outputs).
    pub(crate) fn sums(&self, gpu: &Gpu, frame: &wgpu::Buffer, width: u32, height: u32) -> Result<Sums> {
        let pixels = u64::from(width) * u64::from(height);
        let sums = gpu.buffer("resolve sums", pixels * 32, wgpu::BufferUsages::STORAGE)?;
        let uniform =
            gpu.buffer("resolve", 16, wgpu::BufferUsages::UNIFORM | wgpu::BufferUsages::COPY_DST)?;
        let bind_group = gpu.device.create_bind_group(&wgpu::BindGroupDescriptor {
            label: Some("resolve"),
            layout: &self.layout,
            entries: &[
                wgpu::BindGroupEntry { binding: 0, resource: uniform.as_entire_binding() },
                wgpu::BindGroupEntry { binding: 1, resource: frame.as_entire_binding() },
                wgpu::BindGroupEntry { binding: 2, resource: sums.as_entire_binding() },
            ],
        });
        Ok(Sums { uniform, bind_group, width, height })
    }

    /// Adds sample `sample` (0 starts the sums) and writes the mean into the frame.
    pub(crate) fn record(&self, gpu: &Gpu, pass: &mut wgpu::ComputePass<'_>, sums: &Sums, sample: u32) {
        gpu.queue.write_buffer(&sums.uniform, 0, bytemuck::cast_slice(&[sums.width, sums.height, sample, 0]));
        pass.set_pipeline(&self.pipeline);
        pass.set_bind_group(0, &sums.bind_group, &[]);
        pass.dispatch_workgroups(sums.width.div_ceil(8), sums.height.div_ceil(8), 1);
    }
}

impl Sums {
    /// GPU bytes of the sums.
    pub(crate) fn bytes(&self) -> u64 {
        u64::from(self.width) * u64::from(self.height) * 32
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::view::camera::Camera;

    #[test]
    fn the_samples_fill_the_pixel_and_start_at_its_centre() {
        assert_eq!(jitter_px(0), [0.0, 0.0]);
        let pts: Vec<[f32; 2]> = (0..16).map(jitter_px).collect();
        assert!(pts.iter().flatten().all(|v| (-0.5..0.5).contains(v)), "{pts:?}");
        // Every quarter of the pixel gets samples.
        for (sx, sy) in [(-1.0, -1.0), (-1.0, 1.0), (1.0, -1.0), (1.0, 1.0)] {
            let n = pts.iter().filter(|p| p[0] * sx >= 0.0 && p[1] * sy >= 0.0).count();
            assert!(n >= 3, "quarter ({sx}, {sy}): {n} of 16");
        }
    }

    /// The rasteriser and shade must see the same point: a world point the jittered matrix puts
    /// at raster position q (pixels, continuous) is on the jittered ray shade builds for a pixel
    /// centred at q (shade's ray is linear in the pixel position, shade.wgsl).
    #[test]
    fn the_jittered_projection_and_the_jittered_rays_agree() {
        let cam = Camera {
            eye_m: Vec3::new(1.0, -2.0, 0.5),
            look_at_m: Vec3::new(4.0, 1.0, 0.0),
            up: Vec3::Z,
            fov_y_deg: 70.0,
        };
        let (w, h) = (64u32, 48u32);
        let vp = cam.view_proj(w, h, 0.01, 100.0);
        let forward = (cam.look_at_m - cam.eye_m).normalize();
        let right = forward.cross(cam.up).normalize();
        let up = right.cross(forward);
        let tan = (cam.fov_y_deg.to_radians() * 0.5).tan();
        let aspect = w as f32 / h as f32;
        for k in [0, 1, 2, 5] {
            let j = jitter_px(k);
            let m = jittered_view_proj(vp, j, w, h);
            let f = jittered_forward(forward, (right, up), tan, j, (w, h));
            for p in [Vec3::new(5.0, 2.0, 1.0), Vec3::new(3.0, -1.0, -0.4), Vec3::new(6.0, 3.5, 0.9)] {
                let clip = m * p.extend(1.0);
                let q = ((clip.x / clip.w + 1.0) * 0.5 * w as f32, (1.0 - clip.y / clip.w) * 0.5 * h as f32);
                // shade.wgsl: ndc from the pixel position, then the ray from the basis.
                let ndc = (q.0 / w as f32 * 2.0 - 1.0, 1.0 - q.1 / h as f32 * 2.0);
                let ray = (f + right * (ndc.0 * tan * aspect) + up * (ndc.1 * tan)).normalize();
                let to_p = (p - cam.eye_m).normalize();
                assert!(ray.dot(to_p) > 1.0 - 1e-6, "sample {k}, {p}: ray {ray}, point {to_p}");
            }
            // And the jitter moves the image: a zero jitter would not pass for k > 0.
            if k > 0 {
                let unjittered = vp * Vec3::new(5.0, 2.0, 1.0).extend(1.0);
                let jittered = m * Vec3::new(5.0, 2.0, 1.0).extend(1.0);
                let dx = (jittered.x / jittered.w - unjittered.x / unjittered.w) * 0.5 * w as f32;
                assert!((dx + j[0]).abs() < 1e-3, "sample {k}: moved {dx} px for a jitter of {}", j[0]);
            }
        }
    }
}
