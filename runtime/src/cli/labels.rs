//! Labels of points of interest drawn into rendered images (`grotto render --labels`, and the
//! still picture `grotto publish` writes for browsers without WebGPU), looking as the page draws
//! them: a yellow dot on the anchor, the title in a dark box above it. A label rock hides is left
//! out by the viewers' rule ([`crate::view::story::hidden`]) from the G-buffer distances at the
//! anchors, read back as the viewers read them (render/probe.rs).
//!
//! Drawn on the CPU with ab_glyph rather than by a GPU pass: a few dozen glyphs once an image,
//! where a text pass would cost every renderer a font atlas and a pipeline it never uses
//! otherwise. The font is egui's (the window's), so no second font ships.

use ab_glyph::{Font, FontRef, PxScale, ScaleFont, point};
use serde::Serialize;

use crate::error::Result;
use crate::gpu::Gpu;
use crate::render::Frame;
use crate::render::probe::MAX_PROBE_PIXELS;
use crate::render::renderer::Renderer;
use crate::scene::story::ScenePoi;
use crate::view::camera::Camera;
use crate::view::story;

/// A point of interest's label in one written image, for `--json`.
#[derive(Clone, Debug, PartialEq, Serialize)]
pub struct LabelReport {
    pub poi: String,
    pub title: String,
    /// The anchor in the written image: raster pixels, rows top to bottom.
    pub x_px: f32,
    pub y_px: f32,
    pub distance_m: f32,
    /// False where rock nearer than the anchor hides it; such a label is not drawn.
    pub visible: bool,
}

/// Titles longer than this are cut with an ellipsis (a label is a name, the text is elsewhere).
const MAX_TITLE_CHARS: usize = 60;

/// The labels of `pois` in the frame `r` drew last, with `camera` at `w_px x h_px`, placed in the
/// written image `1 / supersample` of that size. Blocks on the G-buffer read (a job may).
pub(crate) fn find(
    gpu: &Gpu,
    r: &Renderer,
    pois: &[ScenePoi],
    camera: &Camera,
    (w_px, h_px): (u32, u32),
    supersample: u32,
) -> Result<Vec<LabelReport>> {
    let seen: Vec<(&ScenePoi, story::Projected)> =
        pois.iter().filter_map(|p| Some((p, story::project(camera, w_px, h_px, p.position_m)?))).collect();
    let mut labels = Vec::with_capacity(seen.len());
    // Nothing in view (or none asked for): no read-back at all.
    for chunk in seen.chunks(MAX_PROBE_PIXELS) {
        let pixels: Vec<(u32, u32)> = chunk.iter().map(|(_, a)| (a.x_px as u32, a.y_px as u32)).collect();
        let Some(probe) = r.start_probe(&pixels)? else { return Ok(Vec::new()) };
        let surfaces = gpu.wait_for("probe", || probe.take().transpose())?;
        let k = 1.0 / supersample as f32;
        labels.extend(chunk.iter().zip(surfaces).map(|((poi, at), surface_m)| LabelReport {
            poi: poi.name.clone(),
            title: poi.title.clone(),
            x_px: at.x_px * k,
            y_px: at.y_px * k,
            distance_m: at.distance_m,
            visible: !story::hidden(at.distance_m, surface_m),
        }));
    }
    Ok(labels)
}

/// Draws the visible `labels` into `frame`'s tonemapped image (the radiance stays as rendered),
/// and with `lux_legend` the lux view's legend. The far labels first, so a nearer one covers a
/// farther one, as on the page.
pub(crate) fn draw(frame: &mut Frame, labels: &[LabelReport], lux_legend: bool) {
    if lux_legend {
        draw_lux_legend(frame);
    }
    // The page's 13 px at 600 rows and up, in proportion; never smaller than readable.
    let text_px = (frame.height as f32 / 46.0).clamp(13.0, 64.0);
    let font = FontRef::try_from_slice(epaint_default_fonts::UBUNTU_LIGHT)
        .expect("egui's bundled font is a valid TrueType font");
    let mut order: Vec<&LabelReport> = labels.iter().filter(|l| l.visible).collect();
    order.sort_by(|a, b| b.distance_m.total_cmp(&a.distance_m));
    let mut canvas = Canvas { frame };
    for l in order {
        canvas.label(&font, text_px, l);
    }
}

/// The page's label colours (web/static/index.html, `.poi`).
const DOT: [f32; 3] = [255.0, 207.0, 64.0];
const INK: [f32; 3] = [255.0, 255.0, 255.0];
const BLACK: [f32; 3] = [0.0; 3];

struct Canvas<'a> {
    frame: &'a mut Frame,
}

impl Canvas<'_> {
    /// Blends `rgb` over the pixel at `(x, y)` with coverage `alpha` (sRGB bytes, as a browser
    /// composes its page); outside the image, nothing.
    fn blend(&mut self, x: i64, y: i64, rgb: [f32; 3], alpha: f32) {
        let (w, h) = (self.frame.width as i64, self.frame.height as i64);
        if x < 0 || y < 0 || x >= w || y >= h || alpha <= 0.0 {
            return;
        }
        let p = &mut self.frame.ldr[(y * w + x) as usize];
        let a = alpha.min(1.0);
        for c in 0..3 {
            p[c] = (rgb[c] * a + p[c] as f32 * (1.0 - a)).round().clamp(0.0, 255.0) as u8;
        }
    }

    /// A disc of radius `r` about `(cx, cy)`, its edge anti-aliased by coverage.
    fn disc(&mut self, cx: f32, cy: f32, r: f32, rgb: [f32; 3], alpha: f32) {
        for y in (cy - r - 1.0).floor() as i64..=(cy + r + 1.0).ceil() as i64 {
            for x in (cx - r - 1.0).floor() as i64..=(cx + r + 1.0).ceil() as i64 {
                let d = ((x as f32 + 0.5 - cx).powi(2) + (y as f32 + 0.5 - cy).powi(2)).sqrt();
                self.blend(x, y, rgb, alpha * (r + 0.5 - d).clamp(0.0, 1.0));
            }
        }
    }

    /// A box `[x0, x1) x [y0, y1)` with corners rounded by `r`.
    fn rounded_box(&mut self, (x0, y0): (f32, f32), (x1, y1): (f32, f32), r: f32, rgb: [f32; 3], alpha: f32) {
        for y in y0.floor() as i64..y1.ceil() as i64 {
            for x in x0.floor() as i64..x1.ceil() as i64 {
                let (px, py) = (x as f32 + 0.5, y as f32 + 0.5);
                // Distance outside the box shrunk by r, compared with r: the rounded corner.
                let dx = (x0 + r - px).max(px - (x1 - r)).max(0.0);
                let dy = (y0 + r - py).max(py - (y1 - r)).max(0.0);
                let cover = (r + 0.5 - (dx * dx + dy * dy).sqrt()).clamp(0.0, 1.0);
                let inside = (px - x0).min(x1 - px).min(py - y0).min(y1 - py) + 0.5;
                self.blend(x, y, rgb, alpha * cover * inside.clamp(0.0, 1.0));
            }
        }
    }

    /// `text` laid out at `text_px`: its glyphs (origin at the top left) and its width.
    fn layout(font: &FontRef<'_>, text_px: f32, text: &str) -> (Vec<ab_glyph::Glyph>, f32) {
        let scale = PxScale::from(text_px);
        let scaled = font.as_scaled(scale);
        let mut glyphs = Vec::new();
        let mut pen = 0.0;
        let mut previous = None;
        for ch in text.chars() {
            let id = scaled.glyph_id(ch);
            if let Some(p) = previous {
                pen += scaled.kern(p, id);
            }
            glyphs.push(id.with_scale_and_position(scale, point(pen, scaled.ascent())));
            pen += scaled.h_advance(id);
            previous = Some(id);
        }
        (glyphs, pen)
    }

    /// Draws laid-out glyphs with their top left at `(x0, y0)`.
    fn ink(&mut self, font: &FontRef<'_>, glyphs: Vec<ab_glyph::Glyph>, (x0, y0): (f32, f32)) {
        for g in glyphs {
            if let Some(outline) = font.outline_glyph(g) {
                let b = outline.px_bounds();
                let (ox, oy) = (x0 + b.min.x, y0 + b.min.y);
                outline.draw(|gx, gy, cover| {
                    self.blend((ox + gx as f32).round() as i64, (oy + gy as f32).round() as i64, INK, cover)
                });
            }
        }
    }

    fn label(&mut self, font: &FontRef<'_>, text_px: f32, l: &LabelReport) {
        let k = text_px / 13.0;
        let scaled = font.as_scaled(PxScale::from(text_px));
        let (glyphs, pen) = Self::layout(font, text_px, &title_of(&l.title));
        let (pad_x, pad_y) = (6.0 * k, 1.0 * k);
        let (box_w, box_h) = (pen + 2.0 * pad_x, scaled.height() + 2.0 * pad_y);
        // Centred over the anchor, 8 px above it; kept inside the image sideways (the page lets a
        // label run off its edge, where a visitor can turn; an image cannot).
        let w = self.frame.width as f32;
        let x0 = (l.x_px - box_w * 0.5).min(w - box_w).max(0.0);
        let y1 = l.y_px - 8.0 * k;
        let y0 = y1 - box_h;
        self.rounded_box((x0, y0), (x0 + box_w, y1), 3.0 * k, BLACK, 0.7);
        self.ink(font, glyphs, (x0 + pad_x, y0 + pad_y));
        // The dot: 8 px across with a 1 px black ring.
        self.disc(l.x_px, l.y_px, 5.0 * k, BLACK, 1.0);
        self.disc(l.x_px, l.y_px, 4.0 * k, DOT, 1.0);
    }
}

/// The lux view's legend (view/lux.rs) in the image's bottom left corner: the colour scale from
/// 0.1 to 20,000 lux on its logarithmic axis, the decades named.
pub(crate) fn draw_lux_legend(frame: &mut Frame) {
    use crate::view::lux::lux_color;
    let text_px = (frame.height as f32 / 46.0).clamp(11.0, 48.0);
    let k = text_px / 13.0;
    let font = FontRef::try_from_slice(epaint_default_fonts::UBUNTU_LIGHT)
        .expect("egui's bundled font is a valid TrueType font");
    let (lo, hi) = (-1.0f32, 4.3f32);
    let bar_w = (frame.width as f32 * 0.45).clamp(120.0, 600.0);
    let bar_h = 10.0 * k;
    let (x0, y1) = (10.0 * k, frame.height as f32 - 8.0 * k);
    let y_bar = y1 - bar_h - text_px * 1.4;
    let mut canvas = Canvas { frame };
    canvas.rounded_box(
        (x0 - 6.0 * k, y_bar - text_px * 1.5),
        (x0 + bar_w + 24.0 * k, y1 + 4.0 * k),
        3.0 * k,
        BLACK,
        0.7,
    );
    for i in 0..bar_w.ceil() as i64 {
        let l = lo + (hi - lo) * (i as f32 + 0.5) / bar_w;
        let c = lux_color(10f32.powf(l)).map(|v| v * 255.0);
        for y in y_bar as i64..(y_bar + bar_h) as i64 {
            canvas.blend(x0 as i64 + i, y, c, 1.0);
        }
    }
    let (title, w) = Canvas::layout(&font, text_px, "illuminance, lux");
    let _ = w;
    canvas.ink(&font, title, (x0, y_bar - text_px * 1.35));
    for (decade, name) in [(0.0, "1"), (1.0, "10"), (2.0, "100"), (3.0, "1k"), (4.0, "10k")] {
        let x = x0 + (decade - lo) / (hi - lo) * bar_w;
        for y in (y_bar + bar_h) as i64..(y_bar + bar_h + 3.0 * k) as i64 {
            canvas.blend(x as i64, y, INK, 1.0);
        }
        let (glyphs, w) = Canvas::layout(&font, text_px, name);
        canvas.ink(&font, glyphs, (x - w * 0.5, y_bar + bar_h + 3.0 * k));
    }
}

fn title_of(title: &str) -> String {
    if title.chars().count() <= MAX_TITLE_CHARS {
        return title.to_string();
    }
    let cut: String = title.chars().take(MAX_TITLE_CHARS - 1).collect();
    format!("{}…", cut.trim_end())
}

#[cfg(test)]
mod tests {
    use super::*;

    fn frame(w: u32, h: u32, grey: u8) -> Frame {
        let n = (w * h) as usize;
        Frame { width: w, height: h, hdr: vec![[0.0; 4]; n], ldr: vec![[grey, grey, grey, 255]; n] }
    }

    fn label(x_px: f32, y_px: f32, visible: bool) -> LabelReport {
        LabelReport { poi: "p".into(), title: "The chamber".into(), x_px, y_px, distance_m: 3.0, visible }
    }

    #[test]
    fn a_label_draws_its_dot_on_the_anchor_and_its_title_above_it() {
        let mut f = frame(320, 240, 40);
        draw(&mut f, &[label(160.0, 150.0, true)], false);
        let at = |x: u32, y: u32| f.ldr[(y * 320 + x) as usize];
        assert_eq!(at(160, 150), [255, 207, 64, 255], "the dot's centre has the page's yellow");
        // The box above the anchor is darker than the grey it covers; white ink lies within it.
        let (box_rows, dot_rows) = (120..140u32, 145..156u32);
        let box_px: Vec<[u8; 4]> =
            box_rows.flat_map(|y| (100..220).map(move |x| (x, y))).map(|(x, y)| at(x, y)).collect();
        assert!(box_px.iter().any(|p| p[0] < 20), "a dark box above the anchor");
        assert!(box_px.iter().any(|p| p[0] > 200), "white text in it");
        assert!(dot_rows.clone().all(|y| at(100, y) == [40, 40, 40, 255]), "nothing beside the dot");
        // Nothing below the dot.
        assert!((160..240).all(|y| at(160, y) == [40, 40, 40, 255]));
        assert!(f.hdr.iter().all(|p| *p == [0.0; 4]), "the radiance is as rendered");
    }

    #[test]
    fn a_hidden_label_draws_nothing_and_one_at_the_edge_stays_whole() {
        let mut f = frame(200, 100, 40);
        draw(&mut f, &[label(100.0, 50.0, false)], false);
        assert!(f.ldr.iter().all(|p| *p == [40, 40, 40, 255]));
        // At the right edge: the box moves in, so its text is not cut; the dot stays at the anchor.
        draw(&mut f, &[label(199.0, 60.0, true)], false);
        let col = |x: u32| (0..100).any(|y| f.ldr[(y * 200 + x) as usize][0] > 200);
        assert!(col(199) || col(198), "the dot at the edge");
        let inked: Vec<u32> =
            (0..200).filter(|&x| (0..45).any(|y| f.ldr[(y * 200 + x) as usize][0] > 200)).collect();
        assert!(inked.first().is_some_and(|&x| x < 150), "the title runs left of the anchor: {inked:?}");
    }

    #[test]
    fn the_lux_legend_shows_the_scale_in_the_bottom_left_corner() {
        let mut f = frame(400, 300, 40);
        draw_lux_legend(&mut f);
        let rows = |y0: u32, y1: u32| (y0..y1).flat_map(|y| (0..400).map(move |x| (x, y)));
        let changed = rows(0, 300).filter(|&(x, y)| f.ldr[(y * 400 + x) as usize] != [40, 40, 40, 255]);
        let (xs, ys): (Vec<u32>, Vec<u32>) = changed.unzip();
        assert!(xs.iter().max().unwrap() < &300 && ys.iter().min().unwrap() > &200, "in the corner");
        // The scale's colours are in it: the 100 lx green somewhere.
        let green = crate::view::lux::lux_color(100.0).map(|c| (c * 255.0).round() as u8);
        let near = |p: &[u8; 4]| (0..3).all(|c| p[c].abs_diff(green[c]) <= 3);
        assert!(f.ldr.iter().any(near), "the 100 lx colour");
    }

    #[test]
    fn long_titles_are_cut() {
        let t = title_of(&"x".repeat(200));
        assert_eq!(t.chars().count(), MAX_TITLE_CHARS);
        assert!(t.ends_with('…'));
        assert_eq!(title_of("Short"), "Short");
    }
}
