//! Distances at a few pixels of the last frame's G-buffer, read back without blocking (what a
//! browser can do; natively too, so a frame never waits on it): whether rock hides a point of
//! interest's label, and the surface point under a click (measuring, flying to a tapped wall).
//! The frame's camera and sub-pixel jitter travel with the read, so a point is rebuilt on the
//! very ray its distance was drawn along, however many frames later it arrives.

use glam::{Vec2, Vec3};

use crate::error::Result;
use crate::gpu::PendingRead;
use crate::render::renderer::Renderer;
use crate::view::camera::Camera;

/// Most pixels one probe reads (each is a 256-byte row of its buffer: 16 KiB).
pub const MAX_PROBE_PIXELS: usize = 64;

/// Bytes between two pixels' copies: wgpu's row alignment.
const ROW: u64 = 256;

/// A read of G-buffer distances under way.
#[derive(Debug)]
pub struct Probe {
    read: PendingRead,
    /// The pixels asked for, in the frame's own size; those outside it read as nothing.
    pub pixels: Vec<(u32, u32)>,
    /// The camera, size and sub-pixel jitter the frame read was drawn with.
    pub camera: Camera,
    pub width: u32,
    pub height: u32,
    pub jitter_px: [f32; 2],
}

impl Probe {
    /// Each pixel's distance in metres from the eye (None: background, or outside the frame),
    /// once the GPU is done (None: not yet).
    pub fn take(&self) -> Option<Result<Vec<Option<f32>>>> {
        let bytes = match self.read.take()? {
            Ok(b) => b,
            Err(e) => return Some(Err(e)),
        };
        let inside = |&(x, y): &(u32, u32)| x < self.width && y < self.height;
        let mut row = 0;
        Some(Ok(self
            .pixels
            .iter()
            .map(|p| {
                if !inside(p) {
                    return None;
                }
                let at = (row * ROW) as usize;
                row += 1;
                let d = f32::from_bits(u32::from_le_bytes(bytes.get(at..at + 4)?.try_into().ok()?));
                // The G-buffer packs the f32's bits into RGBA8 (packing.wgsl); cleared pixels are 0.
                (d.is_finite() && d > 0.0).then_some(d)
            })
            .collect()))
    }

    /// The frame point `distance_m` along pixel `i`'s ray, as the frame drew it (jitter included).
    pub fn point(&self, i: usize, distance_m: f32) -> Vec3 {
        let (x, y) = self.pixels[i];
        let raster = Vec2::new(x as f32 + 0.5 + self.jitter_px[0], y as f32 + 0.5 + self.jitter_px[1]);
        self.camera.eye_m + ray_through(&self.camera, self.width, self.height, raster) * distance_m
    }
}

/// The unit ray from `camera`'s eye through the continuous raster position `raster_px` (pixels,
/// rows top to bottom) of a `width x height` frame.
pub fn ray_through(camera: &Camera, width: u32, height: u32, raster_px: Vec2) -> Vec3 {
    let ndc = Vec2::new(raster_px.x / width as f32 * 2.0 - 1.0, 1.0 - raster_px.y / height as f32 * 2.0);
    let f = (camera.look_at_m - camera.eye_m).normalize_or(Vec3::X);
    let right = f.cross(camera.up).normalize_or(Vec3::X);
    let up = right.cross(f);
    let tan_y = (camera.fov_y_deg.to_radians() * 0.5).tan();
    let aspect = width as f32 / height.max(1) as f32;
    (f + right * (ndc.x * tan_y * aspect) + up * (ndc.y * tan_y)).normalize_or(f)
}

impl Renderer {
    /// Starts reading the last frame's distances at `pixels` (its own size; at most
    /// [`MAX_PROBE_PIXELS`], the rest are dropped). None before the first frame.
    pub fn start_probe(&self, pixels: &[(u32, u32)]) -> Result<Option<Probe>> {
        let Some(view) = self.targets.view.as_ref() else { return Ok(None) };
        let pixels = pixels[..pixels.len().min(MAX_PROBE_PIXELS)].to_vec();
        let (w, h) = (view.targets.width, view.targets.height);
        let inside: Vec<(u32, u32)> = pixels.iter().copied().filter(|&(x, y)| x < w && y < h).collect();
        let rows = inside.len().max(1) as u64;
        let buf = self.gpu.buffer(
            "probe",
            rows * ROW,
            wgpu::BufferUsages::COPY_SRC | wgpu::BufferUsages::COPY_DST,
        )?;
        let mut enc = self.gpu.device.create_command_encoder(&Default::default());
        for (row, &(x, y)) in inside.iter().enumerate() {
            copy_distance(&mut enc, &view.targets.distance, (x, y), &buf, row as u64 * ROW);
        }
        self.gpu.queue.submit([enc.finish()]);
        Ok(Some(Probe {
            read: self.gpu.start_read(&buf, rows * ROW),
            pixels,
            camera: view.camera,
            width: w,
            height: h,
            jitter_px: view.jitter_px,
        }))
    }
}

/// Records a copy of the distance texel at `(x, y)` into `buf` at `offset`.
pub(super) fn copy_distance(
    enc: &mut wgpu::CommandEncoder,
    distance: &wgpu::Texture,
    (x, y): (u32, u32),
    buf: &wgpu::Buffer,
    offset: u64,
) {
    enc.copy_texture_to_buffer(
        wgpu::TexelCopyTextureInfo {
            texture: distance,
            mip_level: 0,
            origin: wgpu::Origin3d { x, y, z: 0 },
            aspect: wgpu::TextureAspect::All,
        },
        wgpu::TexelCopyBufferInfo {
            buffer: buf,
            layout: wgpu::TexelCopyBufferLayout {
                offset,
                bytes_per_row: Some(ROW as u32),
                rows_per_image: Some(1),
            },
        },
        wgpu::Extent3d { width: 1, height: 1, depth_or_array_layers: 1 },
    );
}
