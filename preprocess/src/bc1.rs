//! Surfel colours as BC1 (DXT1) blocks: each block holds 16 consecutive surfels. Surfels are in
//! Morton order, so a block's colours are spatial neighbours, which is what makes a 4x4 texture
//! codec work on points. Encoding by `texpresso` (a port of libsquish, cluster fit); a short last
//! block is masked so padding does not bend its endpoints. Blocks are encoded in parallel (rayon's
//! current pool): cluster fit costs about a microsecond per surfel, as much as a fifth of the
//! normals, and a large tile is built alone.

use grotto_format::spec::Bc1Block;
use rayon::prelude::*;
use texpresso::{Algorithm, Format, Params};

pub fn encode(colors: &[[u8; 3]]) -> Vec<Bc1Block> {
    let params = Params { algorithm: Algorithm::ClusterFit, ..Params::default() };
    colors
        .par_chunks(16)
        .map(|chunk| {
            let mut rgba = [[0u8; 4]; 16];
            for (px, c) in rgba.iter_mut().zip(chunk) {
                *px = [c[0], c[1], c[2], 255];
            }
            let mask = if chunk.len() == 16 { u32::MAX } else { (1u32 << chunk.len()) - 1 };
            let mut out = [0u8; 8];
            Format::Bc1.compress_block_masked(rgba, mask, params, &mut out);
            Bc1Block(out)
        })
        .collect()
}

pub use grotto_format::color::decode_bc1 as decode;

/// Peak signal-to-noise ratio (dB, 8-bit RGB) and the largest channel error of `b` against `a`.
pub fn psnr(a: &[[u8; 3]], b: &[[u8; 3]]) -> (f64, u8) {
    let (mut se, mut worst) = (0f64, 0u8);
    for (x, y) in a.iter().zip(b) {
        for k in 0..3 {
            let d = x[k].abs_diff(y[k]);
            worst = worst.max(d);
            se += f64::from(d) * f64::from(d);
        }
    }
    let mse = se / (3 * a.len().max(1)) as f64;
    let psnr = if mse == 0.0 { f64::INFINITY } else { 10.0 * (255.0f64 * 255.0 / mse).log10() };
    (psnr, worst)
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn smooth_colours_survive_and_short_blocks_are_masked() {
        let colors: Vec<[u8; 3]> = (0..37).map(|i| [100 + i as u8, 80 + 2 * i as u8, 60]).collect();
        let blocks = encode(&colors);
        assert_eq!(blocks.len(), 3);
        let back = decode(&blocks, colors.len());
        assert_eq!(back.len(), 37);
        let (p, worst) = psnr(&colors, &back);
        assert!(p > 35.0 && worst <= 8, "psnr {p}, worst {worst}");
        // A single colour is exact up to RGB565 quantisation.
        let flat = decode(&encode(&[[200, 100, 50]; 5]), 5);
        for c in flat {
            assert!(c.iter().zip([200u8, 100, 50]).all(|(a, b)| a.abs_diff(b) <= 4), "{c:?}");
        }
    }
}
