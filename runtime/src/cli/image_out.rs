//! Writing rendered frames: PNG (the tonemapped sRGB8 image), JPEG (the same, lossy: a published
//! site's still picture) or OpenEXR (linear f32 radiance), by extension, atomically (temp file beside the target, then rename), like every grotto output.

use std::io::BufWriter;
use std::path::Path;

use crate::cli::export::{atomically, output_error};
use crate::error::{Error, Result};
use crate::render::Frame;
/// Output kind chosen from the file extension.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum ImageKind {
    Png,
    Jpeg,
    Exr,
}

/// The image kind `path`'s extension asks for; an error naming the extensions known.
pub fn kind_of(path: &Path) -> Result<ImageKind> {
    match path.extension().and_then(|e| e.to_str()).map(str::to_ascii_lowercase).as_deref() {
        Some("png") => Ok(ImageKind::Png),
        Some("jpg" | "jpeg") => Ok(ImageKind::Jpeg),
        Some("exr") => Ok(ImageKind::Exr),
        _ => Err(Error::Output {
            path: path.display().to_string(),
            reason: "unknown image format (use .png, .jpg or .exr)".into(),
        }),
    }
}

/// Writes `frame` to `path` (.png, .jpg or .exr).
pub fn write_frame(frame: &Frame, path: &Path) -> Result<()> {
    match kind_of(path)? {
        ImageKind::Png => write_png(frame, path),
        ImageKind::Jpeg => write_jpeg(frame, path),
        ImageKind::Exr => write_exr(frame, path),
    }
}

/// Quality 88: a cave's soft gradients without visible blocks at a tenth of the PNG's bytes.
fn write_jpeg(frame: &Frame, path: &Path) -> Result<()> {
    use image::ImageEncoder;
    let rgb: Vec<u8> = frame.ldr.iter().flat_map(|p| [p[0], p[1], p[2]]).collect();
    atomically(path, |file| {
        let enc = image::codecs::jpeg::JpegEncoder::new_with_quality(BufWriter::new(file), 88);
        enc.write_image(&rgb, frame.width, frame.height, image::ExtendedColorType::Rgb8)
            .map_err(|e| output_error(path, e))
    })
}

fn write_png(frame: &Frame, path: &Path) -> Result<()> {
    use image::ImageEncoder;
    atomically(path, |file| {
        let enc = image::codecs::png::PngEncoder::new(BufWriter::new(file));
        enc.write_image(
            bytemuck::cast_slice(&frame.ldr),
            frame.width,
            frame.height,
            image::ExtendedColorType::Rgba8,
        )
        .map_err(|e| output_error(path, e))
    })
}

fn write_exr(frame: &Frame, path: &Path) -> Result<()> {
    use exr::prelude::*;
    let w = frame.width as usize;
    let pixels = &frame.hdr;
    let channels = SpecificChannels::rgba(|Vec2(x, y): Vec2<usize>| {
        let p = pixels[y * w + x];
        (p[0], p[1], p[2], p[3])
    });
    let layer = Layer::new(
        (w, frame.height as usize),
        LayerAttributes::named("grotto"),
        Encoding::SMALL_LOSSLESS,
        channels,
    );
    let image = Image::from_layer(layer);
    atomically(path, |file| {
        image.write().to_buffered(BufWriter::new(file)).map_err(|e| output_error(path, e))
    })
}

/// Reads a PNG as RGBA8 (golden images).
pub fn read_png(path: &Path) -> Result<(u32, u32, Vec<[u8; 4]>)> {
    let img = image::open(path).map_err(|e| output_error(path, e))?.to_rgba8();
    let (w, h) = img.dimensions();
    Ok((w, h, bytemuck::pod_collect_to_vec(img.as_raw())))
}
