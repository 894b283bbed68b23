//! What a map draws over its picture, once for the PNG (into the pixels, anti-aliased by
//! coverage) and once for the SVG (as vector elements over the same picture): lines, dots and
//! text. Text is rasterised with ab_glyph and egui's font, as the rendered labels are
//! (cli/labels.rs).

use ab_glyph::{Font, FontRef, PxScale, ScaleFont, point};
use image::RgbImage;

/// Colours of the overlay.
pub(crate) const CENTRELINE: [u8; 3] = [200, 30, 30];
pub(crate) const INK: [u8; 3] = [20, 20, 20];
pub(crate) const GRID: [u8; 3] = [120, 140, 170];
pub(crate) const PAPER: [u8; 3] = [255, 255, 255];

/// One overlay element in image pixels (rows top to bottom).
#[derive(Clone, Debug)]
pub(crate) enum Mark {
    Line {
        a: [f32; 2],
        b: [f32; 2],
        width_px: f32,
        rgb: [u8; 3],
    },
    Dot {
        at: [f32; 2],
        r_px: f32,
        rgb: [u8; 3],
    },
    /// Text with its top left at `at`, on a halo of paper so it reads over rock.
    Text {
        at: [f32; 2],
        size_px: f32,
        text: String,
        rgb: [u8; 3],
    },
}

/// Draws `marks` into `img`.
pub(crate) fn draw(img: &mut RgbImage, marks: &[Mark]) {
    let font = FontRef::try_from_slice(epaint_default_fonts::UBUNTU_LIGHT)
        .expect("egui's bundled font is a valid TrueType font");
    for m in marks {
        match m {
            Mark::Line { a, b, width_px, rgb } => line(img, *a, *b, *width_px, *rgb),
            Mark::Dot { at, r_px, rgb } => disc(img, *at, *r_px, *rgb),
            Mark::Text { at, size_px, text, rgb } => {
                // The halo: the text drawn a pixel off in each direction in paper colour.
                for (dx, dy) in [(-1.0, 0.0), (1.0, 0.0), (0.0, -1.0), (0.0, 1.0)] {
                    text_at(img, &font, [at[0] + dx, at[1] + dy], *size_px, text, PAPER);
                }
                text_at(img, &font, *at, *size_px, text, *rgb);
            }
        }
    }
}

/// `marks` as SVG elements.
pub(crate) fn svg(marks: &[Mark]) -> String {
    let mut s = String::new();
    let hex = |c: [u8; 3]| format!("#{:02x}{:02x}{:02x}", c[0], c[1], c[2]);
    for m in marks {
        match m {
            Mark::Line { a, b, width_px, rgb } => s.push_str(&format!(
                "<line x1=\"{:.2}\" y1=\"{:.2}\" x2=\"{:.2}\" y2=\"{:.2}\" stroke=\"{}\" stroke-width=\"{width_px:.2}\" stroke-linecap=\"round\"/>\n",
                a[0], a[1], b[0], b[1], hex(*rgb)
            )),
            Mark::Dot { at, r_px, rgb } => s.push_str(&format!(
                "<circle cx=\"{:.2}\" cy=\"{:.2}\" r=\"{r_px:.2}\" fill=\"{}\"/>\n",
                at[0], at[1], hex(*rgb)
            )),
            Mark::Text { at, size_px, text, rgb } => s.push_str(&format!(
                "<text x=\"{:.2}\" y=\"{:.2}\" font-family=\"sans-serif\" font-size=\"{size_px:.1}\" fill=\"{}\" stroke=\"white\" stroke-width=\"2\" paint-order=\"stroke\" dominant-baseline=\"hanging\">{}</text>\n",
                at[0], at[1], hex(*rgb), xml_escape(text)
            )),
        }
    }
    s
}

/// `text` with XML's five special characters escaped.
pub(crate) fn xml_escape(text: &str) -> String {
    text.replace('&', "&amp;")
        .replace('<', "&lt;")
        .replace('>', "&gt;")
        .replace('"', "&quot;")
        .replace('\'', "&apos;")
}

fn blend(img: &mut RgbImage, x: i64, y: i64, rgb: [u8; 3], alpha: f32) {
    if x < 0 || y < 0 || x >= i64::from(img.width()) || y >= i64::from(img.height()) || alpha <= 0.0 {
        return;
    }
    let p = img.get_pixel_mut(x as u32, y as u32);
    let a = alpha.min(1.0);
    for (out, ink) in p.0.iter_mut().zip(rgb) {
        *out = (f32::from(ink) * a + f32::from(*out) * (1.0 - a)).round() as u8;
    }
}

/// A segment `width` wide, its edges anti-aliased by coverage.
fn line(img: &mut RgbImage, a: [f32; 2], b: [f32; 2], width: f32, rgb: [u8; 3]) {
    let half = 0.5 * width;
    let (x0, x1) = (a[0].min(b[0]) - half - 1.0, a[0].max(b[0]) + half + 1.0);
    let (y0, y1) = (a[1].min(b[1]) - half - 1.0, a[1].max(b[1]) + half + 1.0);
    let (dx, dy) = (b[0] - a[0], b[1] - a[1]);
    let len2 = (dx * dx + dy * dy).max(1e-12);
    for y in y0.floor() as i64..=y1.ceil() as i64 {
        for x in x0.floor() as i64..=x1.ceil() as i64 {
            let (px, py) = (x as f32 + 0.5, y as f32 + 0.5);
            let t = (((px - a[0]) * dx + (py - a[1]) * dy) / len2).clamp(0.0, 1.0);
            let d = ((a[0] + t * dx - px).powi(2) + (a[1] + t * dy - py).powi(2)).sqrt();
            blend(img, x, y, rgb, (half + 0.5 - d).clamp(0.0, 1.0));
        }
    }
}

fn disc(img: &mut RgbImage, c: [f32; 2], r: f32, rgb: [u8; 3]) {
    line(img, c, c, 2.0 * r, rgb);
}

fn text_at(img: &mut RgbImage, font: &FontRef<'_>, at: [f32; 2], size_px: f32, text: &str, rgb: [u8; 3]) {
    let scale = PxScale::from(size_px);
    let scaled = font.as_scaled(scale);
    let mut pen = at[0];
    let mut previous = None;
    for ch in text.chars() {
        let id = scaled.glyph_id(ch);
        if let Some(p) = previous {
            pen += scaled.kern(p, id);
        }
        let glyph = id.with_scale_and_position(scale, point(pen, at[1] + scaled.ascent()));
        pen += scaled.h_advance(id);
        previous = Some(id);
        if let Some(outline) = font.outline_glyph(glyph) {
            let bounds = outline.px_bounds();
            outline.draw(|gx, gy, cover| {
                blend(
                    img,
                    bounds.min.x as i64 + i64::from(gx),
                    bounds.min.y as i64 + i64::from(gy),
                    rgb,
                    cover,
                );
            });
        }
    }
}

/// The width of `text` at `size_px`, pixels.
pub(crate) fn text_width(size_px: f32, text: &str) -> f32 {
    let font = FontRef::try_from_slice(epaint_default_fonts::UBUNTU_LIGHT)
        .expect("egui's bundled font is a valid TrueType font");
    let scaled = font.as_scaled(PxScale::from(size_px));
    text.chars().map(|c| scaled.h_advance(scaled.glyph_id(c))).sum()
}
