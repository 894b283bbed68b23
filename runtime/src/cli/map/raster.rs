//! An orthographic picture of scanned surfels: each surfel a disc of its own radius, the one
//! nearest the viewer kept per pixel, shaded by its colour and a relief light from the upper
//! left (north-west on a plan), as cartographers shade relief. A plan looks down on the floors
//! (surfels facing up); an extended elevation looks across each leg at the far wall.

use glam::{DVec3, Vec3};
use image::RgbImage;

/// Where a picture's pixels lie in the world.
#[derive(Clone, Copy, Debug, PartialEq)]
pub(crate) struct Frame2 {
    /// The world (plan: east, north; elevation: extended metres, height) of pixel (0, 0)'s top
    /// left corner.
    pub left_m: f64,
    pub top_m: f64,
    pub m_per_px: f64,
    pub width_px: u32,
    pub height_px: u32,
}

impl Frame2 {
    /// A frame covering `lo..hi` (metres, x right, y up) with `margin_px` around it.
    pub(crate) fn covering(lo: [f64; 2], hi: [f64; 2], m_per_px: f64, margin_px: u32) -> Self {
        let m = f64::from(margin_px) * m_per_px;
        let w = ((hi[0] - lo[0] + 2.0 * m) / m_per_px).ceil().max(1.0) as u32;
        let h = ((hi[1] - lo[1] + 2.0 * m) / m_per_px).ceil().max(1.0) as u32;
        Frame2 { left_m: lo[0] - m, top_m: hi[1] + m, m_per_px, width_px: w, height_px: h }
    }

    /// The pixel position (x right, y down) of a point at `(x_m, y_m)`.
    pub(crate) fn px(&self, x_m: f64, y_m: f64) -> [f32; 2] {
        [((x_m - self.left_m) / self.m_per_px) as f32, ((self.top_m - y_m) / self.m_per_px) as f32]
    }
}

/// A picture being splatted.
pub(crate) struct Raster {
    pub frame: Frame2,
    depth: Vec<f32>,
    rgb: Vec<[u8; 3]>,
    /// The relief light's direction (unit, world), toward the light.
    light: Vec3,
    /// Surfels drawn.
    pub drawn: u64,
}

impl Raster {
    pub(crate) fn new(frame: Frame2, light: Vec3) -> Self {
        let n = frame.width_px as usize * frame.height_px as usize;
        Raster {
            frame,
            depth: vec![f32::INFINITY; n],
            rgb: vec![[0; 3]; n],
            light: light.normalize(),
            drawn: 0,
        }
    }

    /// Splats a surfel seen at picture position `(x_m, y_m)` (metres) at `depth` (smaller is
    /// nearer the viewer) with radius `radius_m`, unit normal `n` and sRGB colour `srgb`.
    pub(crate) fn splat(
        &mut self,
        (x_m, y_m): (f64, f64),
        depth: f32,
        radius_m: f32,
        n: Vec3,
        srgb: [u8; 3],
    ) {
        let f = self.frame;
        let [cx, cy] = f.px(x_m, y_m);
        let r = (f64::from(radius_m) / f.m_per_px) as f32;
        let r = r.max(0.5);
        let (x0, x1) = ((cx - r).floor().max(0.0) as i64, (cx + r).ceil() as i64);
        let (y0, y1) = ((cy - r).floor().max(0.0) as i64, (cy + r).ceil() as i64);
        if x1 < 0 || y1 < 0 || x0 >= i64::from(f.width_px) || y0 >= i64::from(f.height_px) {
            return;
        }
        let shade = 0.35 + 0.65 * n.dot(self.light).max(0.0);
        let lit = srgb.map(|c| linear_to_srgb(srgb_to_linear(c) * shade));
        let mut any = false;
        for y in y0..y1.min(i64::from(f.height_px)) {
            for x in x0..x1.min(i64::from(f.width_px)) {
                let (px, py) = (x as f32 + 0.5 - cx, y as f32 + 0.5 - cy);
                // The pixel the centre falls in always; others inside the disc.
                let own = x == cx.floor() as i64 && y == cy.floor() as i64;
                if !own && px * px + py * py > r * r {
                    continue;
                }
                let i = y as usize * f.width_px as usize + x as usize;
                if depth < self.depth[i] {
                    self.depth[i] = depth;
                    self.rgb[i] = lit;
                    any = true;
                }
            }
        }
        self.drawn += u64::from(any);
    }

    /// The picture: surfels where drawn, paper elsewhere.
    pub(crate) fn image(&self) -> RgbImage {
        let f = self.frame;
        RgbImage::from_fn(f.width_px, f.height_px, |x, y| {
            let i = y as usize * f.width_px as usize + x as usize;
            image::Rgb(if self.depth[i].is_finite() { self.rgb[i] } else { super::draw::PAPER })
        })
    }
}

/// The relief light of a plan: from the north-west, 45 degrees up, as cartographers light relief.
pub(crate) fn plan_light() -> Vec3 {
    Vec3::new(-1.0, 1.0, std::f32::consts::SQRT_2)
}

/// Where a plan shows a world point: east and north, depth from above (the highest floor
/// nearest), or `None` for a surfel not facing up (walls seen edge-on, ceilings from behind).
pub(crate) fn plan_place(p: DVec3, n: Vec3) -> Option<((f64, f64), f32)> {
    (n.z > 0.05).then_some(((p.x, p.y), -p.z as f32))
}

fn srgb_to_linear(c: u8) -> f32 {
    let c = f32::from(c) / 255.0;
    if c <= 0.04045 { c / 12.92 } else { ((c + 0.055) / 1.055).powf(2.4) }
}

fn linear_to_srgb(v: f32) -> u8 {
    let v = v.clamp(0.0, 1.0);
    let s = if v <= 0.003_130_8 { v * 12.92 } else { 1.055 * v.powf(1.0 / 2.4) - 0.055 };
    (s * 255.0).round() as u8
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn a_splat_lands_where_the_frame_puts_it_and_the_nearest_wins() {
        let frame = Frame2::covering([0.0, 0.0], [10.0, 5.0], 0.1, 0);
        assert_eq!((frame.width_px, frame.height_px), (100, 50));
        let mut r = Raster::new(frame, Vec3::Z);
        r.splat((2.05, 4.95), 1.0, 0.01, Vec3::Z, [200, 0, 0]);
        r.splat((2.05, 4.95), 2.0, 0.01, Vec3::Z, [0, 200, 0]);
        let img = r.image();
        assert_eq!(img.get_pixel(20, 0).0, [200, 0, 0]);
        assert_eq!(img.get_pixel(21, 0).0, PAPER_FOR_TEST);
        // A disc of 0.3 m covers about pi 3^2 pixels.
        let mut r = Raster::new(frame, Vec3::Z);
        r.splat((5.0, 2.5), 1.0, 0.3, Vec3::Z, [100, 100, 100]);
        let covered = r.depth.iter().filter(|d| d.is_finite()).count();
        assert!((24..=36).contains(&covered), "{covered} pixels");
    }

    const PAPER_FOR_TEST: [u8; 3] = super::super::draw::PAPER;
}
