//! Surfel colours as BC1 (DXT1) blocks: each block holds 16 consecutive surfels. Surfels are in
//! Morton order, so a block's colours are spatial neighbours, which is what makes a 4x4 texture
//! codec work on points. Two encoders ([`Bc1Fit`]): `texpresso`'s cluster fit (a port of
//! libsquish, the default) and Intel's ISPC kernel (`intel_tex_2`, SIMD, `--colors bc1-fast`),
//! about 40 times faster for 0.7-2.4 dB less PSNR (`grotto-pack bench-bc1`, docs/benchmarks.md). Blocks are encoded in
//! parallel (rayon's current pool): a large tile is built alone.

use grotto_format::spec::Bc1Block;
use rayon::prelude::*;

/// Blocks per call of the ISPC kernel (a surface of 4 x 4 * this pixels); runs of them are
/// encoded in parallel.
const BLOCKS_PER_CALL: usize = 256;

/// Which BC1 encoder.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum Bc1Fit {
    /// Intel's ISPC BC1 kernel: about 4 ns a surfel.
    Fast,
    /// texpresso's cluster fit: the best endpoints it can find, about 150 ns a surfel.
    Cluster,
}

pub fn encode(colors: &[[u8; 3]], fit: Bc1Fit) -> Vec<Bc1Block> {
    match fit {
        Bc1Fit::Fast => encode_fast(colors),
        Bc1Fit::Cluster => encode_cluster(colors),
    }
}

fn encode_cluster(colors: &[[u8; 3]]) -> Vec<Bc1Block> {
    use texpresso::{Algorithm, Format, Params};
    let params = Params { algorithm: Algorithm::ClusterFit, ..Params::default() };
    colors
        .par_chunks(16)
        .map(|chunk| {
            let mut rgba = [[0u8; 4]; 16];
            for (px, c) in rgba.iter_mut().zip(chunk) {
                *px = [c[0], c[1], c[2], 255];
            }
            // A short last block is masked so padding does not bend its endpoints.
            let mask = if chunk.len() == 16 { u32::MAX } else { (1u32 << chunk.len()) - 1 };
            let mut out = [0u8; 8];
            Format::Bc1.compress_block_masked(rgba, mask, params, &mut out);
            Bc1Block(out)
        })
        .collect()
}

fn encode_fast(colors: &[[u8; 3]]) -> Vec<Bc1Block> {
    colors
        .par_chunks(16 * BLOCKS_PER_CALL)
        .flat_map_iter(|run| {
            // Block b is the 4x4 pixels at x = 4b of a 4-pixel-high surface, surfel i of it the
            // pixel (i % 4, i / 4): texel order, as the decoder reads them back.
            let blocks = run.len().div_ceil(16);
            let width = 4 * blocks;
            let mut rgba = vec![0u8; width * 4 * 4];
            for (b, chunk) in run.chunks(16).enumerate() {
                for i in 0..16 {
                    // A short last block repeats its last colour: no new colour to bend the
                    // endpoints, where black padding would.
                    let c = chunk[i.min(chunk.len() - 1)];
                    let o = ((i / 4) * width + 4 * b + i % 4) * 4;
                    rgba[o..o + 4].copy_from_slice(&[c[0], c[1], c[2], 255]);
                }
            }
            let surface = intel_tex_2::RgbaSurface {
                data: &rgba,
                width: width as u32,
                height: 4,
                stride: (width * 4) as u32,
            };
            let out = intel_tex_2::bc1::compress_blocks(&surface);
            out.chunks_exact(8).map(|b| Bc1Block(b.try_into().expect("8-byte blocks"))).collect::<Vec<_>>()
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
    fn smooth_colours_survive_and_short_blocks_are_padded_or_masked() {
        let colors: Vec<[u8; 3]> = (0..37).map(|i| [100 + i as u8, 80 + 2 * i as u8, 60]).collect();
        for fit in [Bc1Fit::Fast, Bc1Fit::Cluster] {
            let blocks = encode(&colors, fit);
            assert_eq!(blocks.len(), 3);
            let back = decode(&blocks, colors.len());
            assert_eq!(back.len(), 37);
            let (p, worst) = psnr(&colors, &back);
            assert!(p > 35.0 && worst <= 8, "{fit:?}: psnr {p}, worst {worst}");
            // A single colour is exact up to RGB565 quantisation.
            let flat = decode(&encode(&[[200, 100, 50]; 5], fit), 5);
            for c in flat {
                assert!(c.iter().zip([200u8, 100, 50]).all(|(a, b)| a.abs_diff(b) <= 4), "{fit:?}: {c:?}");
            }
        }
    }

    #[test]
    fn the_fast_encoder_keeps_blocks_apart() {
        // Blocks of one colour each, over more than one kernel call: a block's pixels mixed with
        // its neighbour's (a wrong surface layout) would show as a colour from the other block.
        let colors: Vec<[u8; 3]> =
            (0..16 * 600).map(|i| if (i / 16) % 2 == 0 { [250, 10, 10] } else { [10, 10, 250] }).collect();
        let back = decode(&encode(&colors, Bc1Fit::Fast), colors.len());
        for (i, (a, b)) in colors.iter().zip(&back).enumerate() {
            assert!(a.iter().zip(b).all(|(x, y)| x.abs_diff(*y) <= 8), "surfel {i}: {a:?} -> {b:?}");
        }
    }
}
