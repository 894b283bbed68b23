//! Surfel colours as BC1 (DXT1) blocks: each block holds 16 consecutive surfels. Surfels are in
//! Morton order, so a block's colours are spatial neighbours, which is what makes a 4x4 texture
//! codec work on points. Two encoders and their mix ([`Bc1Fit`]): Intel's ISPC kernel
//! (`intel_tex_2`, SIMD, `--colors bc1-fast`), `texpresso`'s cluster fit (a port of libsquish,
//! `--colors bc1-cluster`), about 40 times slower for 0.7-2.4 dB more PSNR, and the default: ISPC,
//! then cluster fit for the blocks ISPC leaves visibly off (`grotto-pack bench-bc1`,
//! docs/benchmarks.md). Blocks are encoded in parallel (rayon's current pool): a large tile is
//! built alone.

use grotto_format::spec::Bc1Block;
use rayon::prelude::*;

/// Blocks per call of the ISPC kernel (a surface of 4 x 4 * this pixels); runs of them are
/// encoded in parallel.
const BLOCKS_PER_CALL: usize = 256;

/// Squared error (summed over a block's 16 surfels and 3 channels, 8-bit units) above which
/// [`Bc1Fit::Refined`] tries the cluster fit: an RMS error of 1.6 levels a channel. Below it the
/// cluster fit's gain is mostly under the RGB565 quantisation floor (about 190 for a block); the
/// blocks above it hold most of the visible error (edges, mixed materials).
pub(crate) const REFINE_ABOVE_SQUARED_ERROR: u32 = 384;

/// Which BC1 encoder.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub(crate) enum Bc1Fit {
    /// Intel's ISPC BC1 kernel: about 4 ns a surfel.
    Fast,
    /// texpresso's cluster fit: the best endpoints it can find, about 150 ns a surfel.
    Cluster,
    /// ISPC, then the cluster fit for blocks whose error is above
    /// [`REFINE_ABOVE_SQUARED_ERROR`], keeping whichever of the two is closer.
    Refined,
}

pub(crate) fn encode(colors: &[[u8; 3]], fit: Bc1Fit) -> Vec<Bc1Block> {
    match fit {
        Bc1Fit::Fast => encode_fast(colors),
        Bc1Fit::Cluster => encode_cluster(colors),
        Bc1Fit::Refined => encode_refined(colors, REFINE_ABOVE_SQUARED_ERROR),
    }
}

fn encode_cluster(colors: &[[u8; 3]]) -> Vec<Bc1Block> {
    colors.par_chunks(16).map(cluster_block).collect()
}

fn cluster_block(chunk: &[[u8; 3]]) -> Bc1Block {
    use texpresso::{Algorithm, Format, Params};
    let params = Params { algorithm: Algorithm::ClusterFit, ..Params::default() };
    let mut rgba = [[0u8; 4]; 16];
    for (px, c) in rgba.iter_mut().zip(chunk) {
        *px = [c[0], c[1], c[2], 255];
    }
    // A short last block is masked so padding does not bend its endpoints.
    let mask = if chunk.len() == 16 { u32::MAX } else { (1u32 << chunk.len()) - 1 };
    let mut out = [0u8; 8];
    Format::Bc1.compress_block_masked(rgba, mask, params, &mut out);
    Bc1Block(out)
}

/// Squared error of one decoded block against its colours (all channels).
fn block_error(block: &Bc1Block, chunk: &[[u8; 3]]) -> u32 {
    texpresso::Format::Bc1
        .decompress_block(&block.0)
        .iter()
        .zip(chunk)
        .map(|(px, c)| (0..3).map(|k| u32::from(px[k].abs_diff(c[k])).pow(2)).sum::<u32>())
        .sum()
}

fn encode_refined(colors: &[[u8; 3]], threshold: u32) -> Vec<Bc1Block> {
    let mut blocks = encode_fast(colors);
    blocks.par_iter_mut().zip(colors.par_chunks(16)).for_each(|(block, chunk)| {
        let fast = block_error(block, chunk);
        if fast > threshold {
            let cluster = cluster_block(chunk);
            if block_error(&cluster, chunk) < fast {
                *block = cluster;
            }
        }
    });
    blocks
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

pub(crate) use grotto_format::color::decode_bc1 as decode;

/// Peak signal-to-noise ratio (dB, 8-bit RGB) and the largest channel error of `b` against `a`.
pub(crate) fn psnr(a: &[[u8; 3]], b: &[[u8; 3]]) -> (f64, u8) {
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
        for fit in [Bc1Fit::Fast, Bc1Fit::Cluster, Bc1Fit::Refined] {
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

    /// The mix is never worse than ISPC alone on any block, and it does try the cluster fit: on
    /// blocks of two far-apart colour clusters plus noise ISPC is off by more than the
    /// threshold, and there the result is at least as close as the cluster fit's.
    #[test]
    fn the_refined_fit_keeps_the_closer_block() {
        let mut state = 11u32;
        let mut noise = move || {
            state = state.wrapping_mul(1_664_525).wrapping_add(1_013_904_223);
            (state >> 27) as u8
        };
        let colors: Vec<[u8; 3]> = (0..16 * 64)
            .map(|i| {
                let base: [u8; 3] = match (i / 16) % 4 {
                    0 => [120, 110, 100],
                    1 => {
                        if i % 3 == 0 {
                            [230, 40, 30]
                        } else {
                            [20, 200, 60]
                        }
                    }
                    2 => [(i % 16 * 16) as u8, 90, 255 - (i % 16 * 16) as u8],
                    _ => {
                        if i % 2 == 0 {
                            [250, 250, 250]
                        } else {
                            [5, 5, 80]
                        }
                    }
                };
                base.map(|c| c.saturating_add(noise()))
            })
            .collect();
        let [fast, cluster, refined] =
            [Bc1Fit::Fast, Bc1Fit::Cluster, Bc1Fit::Refined].map(|fit| encode(&colors, fit));
        let mut refined_blocks = 0;
        for (b, chunk) in colors.chunks(16).enumerate() {
            let (f, c, r) = (
                block_error(&fast[b], chunk),
                block_error(&cluster[b], chunk),
                block_error(&refined[b], chunk),
            );
            assert!(r <= f, "block {b}: refined {r} against ISPC {f}");
            if f > REFINE_ABOVE_SQUARED_ERROR {
                assert!(r <= c, "block {b}: refined {r} against cluster fit {c}");
                refined_blocks += usize::from(refined[b].0 != fast[b].0);
            } else {
                assert_eq!(refined[b].0, fast[b].0, "block {b} is under the threshold");
            }
        }
        assert!(refined_blocks > 0, "no block took the cluster fit");
    }
}
