//! Colours as the package stores them: leaf albedo and surfel colours are sRGB-encoded (IEC
//! 61966-2-1) 8-bit values, surfel colours optionally as BC1 blocks of 16 consecutive surfels.
//! Every crate converts through these, so the writer and the readers agree to the bit.

use crate::spec::Bc1Block;

/// sRGB-encoded value in 0..=1 to linear.
pub fn srgb_to_linear(c: f32) -> f32 {
    if c <= 0.040_45 { c / 12.92 } else { ((c + 0.055) / 1.055).powf(2.4) }
}

/// Linear value to sRGB-encoded, clamped to 0..=1.
pub fn linear_to_srgb(c: f32) -> f32 {
    let c = c.clamp(0.0, 1.0);
    if c <= 0.003_130_8 { c * 12.92 } else { 1.055 * c.powf(1.0 / 2.4) - 0.055 }
}

/// sRGB byte to linear, as the GPU decodes an `Unorm8Srgb` texel. From a table of the 256 values
/// of [`srgb_to_linear`] (the same bits): a build converts every point's colour, and `powf` per
/// channel was 1.3% of a build's samples.
pub fn srgb8_to_linear(c: u8) -> f32 {
    static TABLE: std::sync::LazyLock<[f32; 256]> =
        std::sync::LazyLock::new(|| std::array::from_fn(|i| srgb_to_linear(i as f32 / 255.0)));
    TABLE[usize::from(c)]
}

/// Linear value to the nearest sRGB byte (clamped).
pub fn linear_to_srgb8(c: f32) -> u8 {
    (linear_to_srgb(c) * 255.0).round() as u8
}

/// The first `n` colours of BC1 `blocks` (the standard decoder: texpresso, a port of libsquish).
pub fn decode_bc1(blocks: &[Bc1Block], n: usize) -> Vec<[u8; 3]> {
    blocks
        .iter()
        .flat_map(|b| texpresso::Format::Bc1.decompress_block(&b.0))
        .take(n)
        .map(|px| [px[0], px[1], px[2]])
        .collect()
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn every_byte_survives_a_round_trip_through_linear() {
        for v in 0..=255u8 {
            assert_eq!(linear_to_srgb8(srgb8_to_linear(v)), v);
        }
        assert_eq!(linear_to_srgb8(-1.0), 0);
        assert_eq!(linear_to_srgb8(2.0), 255);
    }
}
