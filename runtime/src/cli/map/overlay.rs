//! A map picture's place for each point and what is drawn over it: the centreline, the
//! stations and their names, a grid in survey coordinates with its values, a scale bar and (on
//! a plan) a north arrow. Written as PNG (the overlay in the pixels) and SVG (the PNG as its
//! image, the overlay as vectors).

use std::path::Path;

use glam::{DVec3, Vec3};
use grotto_format::survey::Survey;

use super::centreline::{Centreline, MapLeg};
use super::draw::{self, CENTRELINE, GRID, INK, Mark};
use super::raster::{Frame2, Raster};
use super::{Picture, file_name};
use crate::error::Result;

/// Where the extended elevation shows point `p` (normal `n`) near `leg` at fraction `t`:
/// (extended metres, height), depth and the normal in the picture's frame (x right, y up, z
/// toward the viewer), or `None` for a surface facing away. The viewer stands to the right of
/// each leg as it is laid out and looks across it, so the far wall shows.
pub(crate) fn elevation_place(leg: &MapLeg, t: f64, p: DVec3, n: Vec3) -> Option<((f64, f64), f32, Vec3)> {
    let along = (leg.to_m - leg.from_m).truncate();
    let h = along.length();
    let x = leg.extended_from_m + leg.extended_sign * t * h;
    let (dir, left) = if h > 1e-6 {
        let d = along / h * leg.extended_sign;
        (d.extend(0.0), DVec3::new(-d.y, d.x, 0.0))
    } else {
        // A vertical leg: looked at from the south.
        (DVec3::X, DVec3::Y)
    };
    let n64 = n.as_dvec3();
    let toward_viewer = -n64.dot(left);
    if toward_viewer < -0.05 {
        return None;
    }
    let on_leg = leg.from_m.lerp(leg.to_m, t);
    let depth = (p - on_leg).dot(left) as f32;
    let n_picture = Vec3::new(n64.dot(dir) as f32, n.z, toward_viewer as f32);
    Some(((x, p.z), depth, n_picture))
}

/// A "nice" spacing (1, 2 or 5 times a power of ten) near `target`.
fn nice(target: f64) -> f64 {
    let p = 10f64.powf(target.log10().floor());
    [1.0, 2.0, 5.0, 10.0].into_iter().map(|k| k * p).find(|&s| s >= target).unwrap_or(10.0 * p)
}

/// Grid lines every nice spacing across `frame`, with their values written at the left and top
/// edges (`names`: how the x and y values read, e.g. "E" and "N").
fn grid(frame: &Frame2, names: [&str; 2], text_px: f32) -> Vec<Mark> {
    let (w, h) = (f64::from(frame.width_px), f64::from(frame.height_px));
    let spacing = nice(w.max(h) * frame.m_per_px / 8.0);
    let mut marks = Vec::new();
    let x_lo = (frame.left_m / spacing).ceil() as i64;
    let x_hi = ((frame.left_m + w * frame.m_per_px) / spacing).floor() as i64;
    for k in x_lo..=x_hi {
        let x_m = k as f64 * spacing;
        let x = frame.px(x_m, frame.top_m)[0];
        marks.push(Mark::Line { a: [x, 0.0], b: [x, h as f32], width_px: 1.0, rgb: GRID });
        marks.push(Mark::Text {
            at: [x + 3.0, 3.0],
            size_px: text_px,
            text: format!("{} {x_m:.0}", names[0]),
            rgb: GRID,
        });
    }
    let y_lo = ((frame.top_m - h * frame.m_per_px) / spacing).ceil() as i64;
    let y_hi = (frame.top_m / spacing).floor() as i64;
    for k in y_lo..=y_hi {
        let y_m = k as f64 * spacing;
        let y = frame.px(frame.left_m, y_m)[1];
        marks.push(Mark::Line { a: [0.0, y], b: [w as f32, y], width_px: 1.0, rgb: GRID });
        marks.push(Mark::Text {
            at: [3.0, y + 3.0],
            size_px: text_px,
            text: format!("{} {y_m:.0}", names[1]),
            rgb: GRID,
        });
    }
    marks
}

/// A scale bar about a fifth of the picture wide at its bottom left, with its length and the
/// map scale written over it.
fn scale_bar(frame: &Frame2, scale: u32, text_px: f32) -> Vec<Mark> {
    let length_m = nice(f64::from(frame.width_px) * frame.m_per_px / 5.0);
    let length_px = (length_m / frame.m_per_px) as f32;
    let y = frame.height_px as f32 - 16.0;
    let x0 = 16.0;
    let mut marks = vec![Mark::Line { a: [x0, y], b: [x0 + length_px, y], width_px: 4.0, rgb: INK }];
    for x in [x0, x0 + length_px] {
        marks.push(Mark::Line { a: [x, y - 6.0], b: [x, y + 4.0], width_px: 2.0, rgb: INK });
    }
    marks.push(Mark::Text {
        at: [x0, y - 8.0 - text_px],
        size_px: text_px,
        text: format!("{length_m} m   1:{scale}"),
        rgb: INK,
    });
    marks
}

/// A north arrow at the top right (grid north: up is +y, north in the survey's coordinates).
fn north_arrow(frame: &Frame2, text_px: f32) -> Vec<Mark> {
    let x = frame.width_px as f32 - 30.0;
    let (top, bottom) = (20.0 + text_px, 70.0 + text_px);
    vec![
        Mark::Line { a: [x, bottom], b: [x, top], width_px: 3.0, rgb: INK },
        Mark::Line { a: [x, top], b: [x - 8.0, top + 14.0], width_px: 3.0, rgb: INK },
        Mark::Line { a: [x, top], b: [x + 8.0, top + 14.0], width_px: 3.0, rgb: INK },
        Mark::Text { at: [x - 0.35 * text_px, 8.0], size_px: text_px, text: "N".into(), rgb: INK },
    ]
}

/// The centreline's legs and its named stations, their names where they do not cover another.
fn centreline_marks(
    legs: impl Iterator<Item = ([f32; 2], [f32; 2])>,
    stations: impl Iterator<Item = (String, [f32; 2])>,
    text_px: f32,
) -> Vec<Mark> {
    let mut marks: Vec<Mark> =
        legs.map(|(a, b)| Mark::Line { a, b, width_px: 2.0, rgb: CENTRELINE }).collect();
    let mut taken: Vec<[f32; 4]> = Vec::new();
    for (name, at) in stations {
        marks.push(Mark::Dot { at, r_px: 3.0, rgb: CENTRELINE });
        let w = draw::text_width(text_px, &name);
        let b = [at[0] + 5.0, at[1] + 2.0, at[0] + 5.0 + w, at[1] + 2.0 + text_px];
        if taken.iter().all(|t| b[2] < t[0] || b[0] > t[2] || b[3] < t[1] || b[1] > t[3]) {
            taken.push(b);
            marks.push(Mark::Text { at: [b[0], b[1]], size_px: text_px, text: name, rgb: INK });
        }
    }
    marks
}

/// The short name of a station on a map: its last part (Survex's `cave.passage.12` reads 12),
/// as surveyors label their drawings; the full name is in `passages.csv`.
fn label(name: &str) -> String {
    name.rsplit('.').next().unwrap_or(name).to_owned()
}

/// The text size of a picture's overlay.
fn text_px(frame: &Frame2) -> f32 {
    (frame.width_px.max(frame.height_px) as f32 / 90.0).clamp(11.0, 28.0)
}

/// Writes the plan: `DIR/plan.png` and `DIR/plan.svg`.
pub(crate) fn write_plan(
    dir: &Path,
    raster: &Raster,
    survey: &Survey,
    line: &Centreline,
    scale: u32,
) -> Result<Picture> {
    let f = raster.frame;
    let t = text_px(&f);
    let mut marks = grid(&f, ["E", "N"], t * 0.8);
    marks.extend(centreline_marks(
        line.legs.iter().map(|l| (f.px(l.from_m.x, l.from_m.y), f.px(l.to_m.x, l.to_m.y))),
        drawn_stations(survey, line).map(|(name, p)| (label(name), f.px(p.x, p.y))),
        t,
    ));
    marks.extend(scale_bar(&f, scale, t));
    marks.extend(north_arrow(&f, t));
    write_picture(dir, "plan", raster, &marks)
}

/// Writes the extended elevation: `DIR/elevation.png` and `DIR/elevation.svg`.
pub(crate) fn write_elevation(
    dir: &Path,
    raster: &Raster,
    survey: &Survey,
    line: &Centreline,
    scale: u32,
) -> Result<Picture> {
    let f = raster.frame;
    let t = text_px(&f);
    let mut marks = grid(&f, ["", "z"], t * 0.8);
    let ends = |l: &MapLeg| {
        let x1 = l.extended_from_m + l.extended_sign * l.horizontal_m();
        (f.px(l.extended_from_m, l.from_m.z), f.px(x1, l.to_m.z))
    };
    // Each station where its first leg laid out puts it.
    let mut placed = Vec::new();
    let mut seen = std::collections::HashSet::new();
    for l in &line.legs {
        let (a, b) = ends(l);
        for (s, at) in [(l.from, a), (l.to, b)] {
            if let Some(s) = s.filter(|s| !survey.stations[*s].flags.anonymous && seen.insert(*s)) {
                placed.push((label(&survey.stations[s].name), at));
            }
        }
    }
    marks.extend(centreline_marks(line.legs.iter().map(ends), placed.into_iter(), t));
    marks.extend(scale_bar(&f, scale, t));
    write_picture(dir, "elevation", raster, &marks)
}

/// The named stations the map's legs reach, with their positions.
fn drawn_stations<'a>(
    survey: &'a Survey,
    line: &'a Centreline,
) -> impl Iterator<Item = (&'a str, DVec3)> + 'a {
    survey
        .stations
        .iter()
        .enumerate()
        .filter(move |(i, s)| !s.flags.anonymous && line.direction[*i].is_some())
        .map(|(_, s)| (s.name.as_str(), DVec3::from_array(s.position_m)))
}

fn write_picture(dir: &Path, name: &str, raster: &Raster, marks: &[Mark]) -> Result<Picture> {
    let f = raster.frame;
    let mut img = raster.image();
    // The bare picture first, then the overlay drawn into the same pixels: no copy of either.
    let bare_png = dir.join(format!("{name}-image.png"));
    write_png(&bare_png, &img)?;
    draw::draw(&mut img, marks);
    let png = dir.join(format!("{name}.png"));
    write_png(&png, &img)?;
    let svg = dir.join(format!("{name}.svg"));
    let text = format!(
        "<svg xmlns=\"http://www.w3.org/2000/svg\" xmlns:xlink=\"http://www.w3.org/1999/xlink\" width=\"{w}\" height=\"{h}\" viewBox=\"0 0 {w} {h}\">\n<image href=\"{}\" x=\"0\" y=\"0\" width=\"{w}\" height=\"{h}\"/>\n{}</svg>\n",
        file_name(&format!("{name}-image.png")),
        draw::svg(marks),
        w = f.width_px,
        h = f.height_px
    );
    crate::cli::export::write_atomically(&svg, text.as_bytes())?;
    Ok(Picture {
        png: png.display().to_string(),
        svg: svg.display().to_string(),
        width_px: f.width_px,
        height_px: f.height_px,
        surfels_drawn: raster.drawn,
    })
}

/// Streams `img` into `path` as PNG, atomically.
fn write_png(path: &Path, img: &image::RgbImage) -> Result<()> {
    use image::ImageEncoder;
    crate::cli::export::atomically(path, |file| {
        image::codecs::png::PngEncoder::new(std::io::BufWriter::new(file))
            .write_image(img.as_raw(), img.width(), img.height(), image::ExtendedColorType::Rgb8)
            .map_err(|e| crate::cli::export::output_error(path, e))
    })
}
