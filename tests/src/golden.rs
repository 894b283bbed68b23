//! Golden images: the one tolerance every image comparison uses (the end-to-end tests here,
//! and the viewer's test in runtime/tests/cli.rs, which includes this file).

use std::path::PathBuf;

/// Differences between two RGBA8 images, per channel value in 0..=255 (alpha ignored).
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct ImageDiff {
    pub mean_abs: f64,
    pub p99_abs: u8,
    pub max_abs: u8,
}

/// The shared tolerance: mean |difference| at most 1.5 / 255 and 99% of channel values
/// within 16 / 255. Loose enough for rasterisation and float-order differences between
/// backends (Vulkan, GL) and drivers (measured Vulkan against GL on lavapipe/llvmpipe: mean
/// 0.52, p99 10), tight enough that a wrong pass fails (measured on the demo chamber: no
/// bounces, mean 20.1; no shadows, mean 5.2 and p99 80; tests/tests/render.rs checks both).
pub const MEAN_ABS_MAX: f64 = 1.5;
pub const P99_ABS_MAX: u8 = 16;

pub fn diff(a: &[[u8; 4]], b: &[[u8; 4]]) -> ImageDiff {
    assert_eq!(a.len(), b.len(), "image sizes differ");
    let mut hist = [0u64; 256];
    let mut sum = 0u64;
    for (p, q) in a.iter().zip(b) {
        for k in 0..3 {
            let d = p[k].abs_diff(q[k]);
            hist[d as usize] += 1;
            sum += u64::from(d);
        }
    }
    let n = (a.len() * 3).max(1) as u64;
    let mut acc = 0u64;
    let mut p99 = 0u8;
    for (d, &c) in hist.iter().enumerate() {
        acc += c;
        if acc * 100 >= n * 99 {
            p99 = d as u8;
            break;
        }
    }
    let max = hist.iter().rposition(|&c| c > 0).unwrap_or(0) as u8;
    ImageDiff { mean_abs: sum as f64 / n as f64, p99_abs: p99, max_abs: max }
}

/// The image at 1/`f` of its size, each pixel the rounded mean of an `f` x `f` block (edges
/// that do not fill a block are dropped). For comparing frames from two different rasterisers
/// (the browser's SwiftShader against lavapipe): where overlapping surfel discs meet at nearly
/// the same depth, each resolves the tie its own way, pixel by pixel, and the surfels' own
/// colours differ; averaged over 2 x 2 blocks that noise falls under the tolerance (the browser
/// test's chamber at 320x240, `cargo test -p grotto-tests --test browser -- --nocapture`: mean
/// 1.55 and p99 16 per pixel, 1.27 and 10 per block), while a wrong pass still changes whole
/// regions (the browser without bounces: mean 9.37 per block). With blended splats
/// the ties no longer decide a pixel: mean 0.18 and p99 3 per pixel, 0.17 and 2 per block.
pub fn block_mean(pixels: &[[u8; 4]], width: u32, height: u32, f: u32) -> Vec<[u8; 4]> {
    let (f, w) = (f.max(1) as usize, width as usize);
    let (bw, bh) = (w / f, height as usize / f);
    let mut out = Vec::with_capacity(bw * bh);
    for by in 0..bh {
        for bx in 0..bw {
            let mut sum = [0u32; 4];
            for y in by * f..(by + 1) * f {
                for x in bx * f..(bx + 1) * f {
                    for (s, v) in sum.iter_mut().zip(pixels[y * w + x]) {
                        *s += u32::from(v);
                    }
                }
            }
            let n = (f * f) as u32;
            out.push(sum.map(|s| ((s + n / 2) / n) as u8));
        }
    }
    out
}

pub fn within_tolerance(d: &ImageDiff) -> bool {
    d.mean_abs <= MEAN_ABS_MAX && d.p99_abs <= P99_ABS_MAX
}

pub fn path(name: &str) -> PathBuf {
    PathBuf::from(env!("CARGO_MANIFEST_DIR")).join("golden").join(format!("{name}.png"))
}

/// Compares an RGBA8 image with `tests/golden/NAME.png`; with `GROTTO_BLESS=1` writes it
/// instead. On a mismatch the image is saved beside the golden as `NAME.actual.png`.
pub fn check(name: &str, width: u32, height: u32, pixels: &[[u8; 4]]) -> ImageDiff {
    let golden = path(name);
    let bytes: Vec<u8> = pixels.iter().flatten().copied().collect();
    if std::env::var_os("GROTTO_BLESS").is_some() {
        std::fs::create_dir_all(golden.parent().expect("golden dir")).expect("create tests/golden");
        image::save_buffer(&golden, &bytes, width, height, image::ExtendedColorType::Rgba8)
            .expect("write golden");
        return ImageDiff { mean_abs: 0.0, p99_abs: 0, max_abs: 0 };
    }
    let img = image::open(&golden)
        .unwrap_or_else(|e| panic!("{}: {e} (run with GROTTO_BLESS=1 to create it)", golden.display()))
        .to_rgba8();
    assert_eq!(img.dimensions(), (width, height), "{}: size differs", golden.display());
    let want: Vec<[u8; 4]> = img.as_raw().chunks_exact(4).map(|c| [c[0], c[1], c[2], c[3]]).collect();
    let d = diff(pixels, &want);
    if !within_tolerance(&d) {
        let actual = golden.with_extension("actual.png");
        let _ = image::save_buffer(&actual, &bytes, width, height, image::ExtendedColorType::Rgba8);
    }
    d
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn tolerance_accepts_noise_and_rejects_a_shift() {
        let a: Vec<[u8; 4]> = (0..10_000u32).map(|i| [(i % 251) as u8, (i % 13) as u8, 90, 255]).collect();
        let mut noisy = a.clone();
        for (i, p) in noisy.iter_mut().enumerate().filter(|(i, _)| i % 97 == 0) {
            p[0] = p[0].wrapping_add(40 + (i % 3) as u8);
        }
        assert!(within_tolerance(&diff(&a, &noisy)), "{:?}", diff(&a, &noisy));
        let darker: Vec<[u8; 4]> = a.iter().map(|p| [p[0].saturating_sub(6), p[1], p[2], p[3]]).collect();
        assert!(!within_tolerance(&diff(&a, &darker)));
    }
}
