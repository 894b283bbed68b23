//! Candidate compact surfel encodings for survey-scale packages (issue 15), and what they cost in
//! accuracy: `grotto-pack bench-encoding PACKAGE` quantises a package's surfels each way and
//! measures bytes per point and the errors against the full-precision surfels
//! (docs/benchmarks.md). The package format does not store these yet; this decides which it will.
//!
//! The quantisation shared by the candidates:
//! - position: offset inside its leaf voxel, `bits` per axis, so the step is `leaf / 2^bits`
//!   ([`position_bits`] picks the fewest bits whose worst case, half a step on every axis, stays
//!   within a given distance);
//! - normal: octahedral map (Meyer et al. 2010), `2 x NORMAL_BITS` bits, with the nearest of the
//!   four surrounding codes chosen by angle (Cigolle et al. 2014's "precise" variant);
//! - radius: log-coded in a byte, 16 codes per octave from 2^-12 m (0.24 mm) up;
//! - spread: linear in a byte.
//!
//! Written by hand: the octahedral map is a few lines, and the rest is this project's own layout.

/// Bits per octahedral coordinate.
pub const NORMAL_BITS: u32 = 12;
/// Radius codes per octave, and the radius of code 0 as a power of two of metres.
const RADIUS_CODES_PER_OCTAVE: f32 = 16.0;
const RADIUS_MIN_LOG2: f32 = -12.0;

/// The fewest bits per axis (1..=16) whose worst position error inside a leaf of `leaf_m`, half a
/// step on each axis (`sqrt(3) / 2` steps), is at most `max_error_m`.
pub fn position_bits(leaf_m: f64, max_error_m: f64) -> u32 {
    (1..=16).find(|&b| leaf_m / f64::from(1u32 << b) * 3f64.sqrt() / 2.0 <= max_error_m).unwrap_or(16)
}

/// The position's leaf cell (clamped into the tile's `cells`) and its offset quantised to `bits`.
pub fn quantise_position(p_tile_m: [f32; 3], leaf_m: f64, cells: u32, bits: u32) -> ([u32; 3], [u32; 3]) {
    let steps = f64::from(1u32 << bits);
    let mut cell = [0u32; 3];
    let mut q = [0u32; 3];
    for a in 0..3 {
        let x = f64::from(p_tile_m[a]) / leaf_m;
        let c = x.floor().clamp(0.0, f64::from(cells - 1));
        cell[a] = c as u32;
        q[a] = ((x - c) * steps).floor().clamp(0.0, steps - 1.0) as u32;
    }
    (cell, q)
}

/// The centre of the quantised position's step.
pub fn dequantise_position(cell: [u32; 3], q: [u32; 3], leaf_m: f64, bits: u32) -> [f32; 3] {
    let steps = f64::from(1u32 << bits);
    std::array::from_fn(|a| ((f64::from(cell[a]) + (f64::from(q[a]) + 0.5) / steps) * leaf_m) as f32)
}

fn oct_wrap(x: f32, y: f32) -> (f32, f32) {
    ((1.0 - y.abs()) * x.signum(), (1.0 - x.abs()) * y.signum())
}

/// Unit normal to its octahedral point in [-1, 1]^2.
fn oct_map(n: [f32; 3]) -> (f32, f32) {
    let l1 = n[0].abs() + n[1].abs() + n[2].abs();
    if l1.is_nan() || l1 <= 0.0 {
        return (0.0, 0.0);
    }
    let (x, y) = (n[0] / l1, n[1] / l1);
    if n[2] < 0.0 { oct_wrap(x, y) } else { (x, y) }
}

/// The octahedral point of the codes back to a unit normal.
pub fn oct_decode(u: u32, v: u32) -> [f32; 3] {
    let max = ((1u32 << NORMAL_BITS) - 1) as f32;
    let (x, y) = (u as f32 / max * 2.0 - 1.0, v as f32 / max * 2.0 - 1.0);
    let z = 1.0 - x.abs() - y.abs();
    let (x, y) = if z < 0.0 { oct_wrap(x, y) } else { (x, y) };
    let l = (x * x + y * y + z * z).sqrt();
    [x / l, y / l, z / l]
}

/// The codes (each `NORMAL_BITS` bits) of the four around `n`'s octahedral point whose normal is
/// nearest to `n`.
pub fn oct_encode(n: [f32; 3]) -> (u32, u32) {
    let max = ((1u32 << NORMAL_BITS) - 1) as f32;
    let (x, y) = oct_map(n);
    let (fx, fy) = (((x + 1.0) / 2.0 * max).floor(), ((y + 1.0) / 2.0 * max).floor());
    let mut best = (0u32, 0u32, f32::NEG_INFINITY);
    for (dx, dy) in [(0.0, 0.0), (1.0, 0.0), (0.0, 1.0), (1.0, 1.0)] {
        let (u, v) = ((fx + dx).clamp(0.0, max) as u32, (fy + dy).clamp(0.0, max) as u32);
        let d = oct_decode(u, v);
        let cos = d[0] * n[0] + d[1] * n[1] + d[2] * n[2];
        if cos > best.2 {
            best = (u, v, cos);
        }
    }
    (best.0, best.1)
}

pub fn radius_code(radius_m: f32) -> u8 {
    let c = (radius_m.max(f32::MIN_POSITIVE).log2() - RADIUS_MIN_LOG2) * RADIUS_CODES_PER_OCTAVE;
    c.round().clamp(0.0, 255.0) as u8
}

pub fn radius_m(code: u8) -> f32 {
    (f32::from(code) / RADIUS_CODES_PER_OCTAVE + RADIUS_MIN_LOG2).exp2()
}

pub fn spread_code(spread: f32) -> u8 {
    (spread.clamp(0.0, 1.0) * 255.0).round() as u8
}

pub fn spread(code: u8) -> f32 {
    f32::from(code) / 255.0
}

/// A little-endian bit stream: each value's low bits, least significant first.
#[derive(Debug, Default)]
pub struct BitWriter {
    bytes: Vec<u8>,
    acc: u64,
    filled: u32,
}

impl BitWriter {
    pub fn put(&mut self, value: u32, bits: u32) {
        self.acc |= u64::from(value & ((1u64 << bits) - 1) as u32) << self.filled;
        self.filled += bits;
        while self.filled >= 8 {
            self.bytes.push(self.acc as u8);
            self.acc >>= 8;
            self.filled -= 8;
        }
    }

    pub fn finish(mut self) -> Vec<u8> {
        if self.filled > 0 {
            self.bytes.push(self.acc as u8);
        }
        self.bytes
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn angle_deg(a: [f32; 3], b: [f32; 3]) -> f64 {
        let c = f64::from(a[0] * b[0] + a[1] * b[1] + a[2] * b[2]).clamp(-1.0, 1.0);
        c.acos().to_degrees()
    }

    #[test]
    fn normals_survive_the_octahedral_codes_within_a_twentieth_of_a_degree() {
        let mut worst = 0f64;
        let mut state = 0x2545_f491_4f6c_dd1du64;
        let mut next = || {
            state ^= state << 13;
            state ^= state >> 7;
            state ^= state << 17;
            (state >> 11) as f32 / (1u64 << 53) as f32 * 2.0 - 1.0
        };
        for i in 0..20_000 {
            // Random directions, and the axes and diagonals where the map folds.
            let n = match i {
                0 => [0.0, 0.0, -1.0],
                1 => [1.0, 0.0, 0.0],
                2 => [0.0, -1.0, 0.0],
                3 => [0.577, -0.577, -0.577],
                _ => [next(), next(), next()],
            };
            let l = (n[0] * n[0] + n[1] * n[1] + n[2] * n[2]).sqrt();
            if l < 1e-3 {
                continue;
            }
            let n = n.map(|c| c / l);
            let (u, v) = oct_encode(n);
            worst = worst.max(angle_deg(n, oct_decode(u, v)));
        }
        assert!(worst < 0.05, "worst {worst} degrees");
    }

    #[test]
    fn positions_move_at_most_the_bound_their_bits_were_chosen_for() {
        for leaf_m in [0.0625, 0.125, 1.0] {
            let bits = position_bits(leaf_m, 0.001);
            let cells = 64;
            let mut worst = 0f64;
            for i in 0..5000 {
                let p = [(i as f32 * 0.7919) % 4.0, (i as f32 * 0.3571) % 4.0, (i as f32 * 0.1117) % 4.0]
                    .map(|c| c * (leaf_m as f32 * cells as f32 / 4.0) * 0.999);
                let (cell, q) = quantise_position(p, leaf_m, cells, bits);
                let d = dequantise_position(cell, q, leaf_m, bits);
                let e = (0..3).map(|a| f64::from(d[a] - p[a]).powi(2)).sum::<f64>().sqrt();
                worst = worst.max(e);
            }
            // f32 positions of a 64-leaf tile carry their own rounding (a few micrometres).
            assert!(worst <= 0.001 + 1e-5, "leaf {leaf_m}: {bits} bits, worst {worst} m");
        }
        assert_eq!(position_bits(0.0625, 0.001), 6);
    }

    #[test]
    fn radius_and_spread_codes_round_trip_within_their_steps() {
        for r in [0.0003f32, 0.004, 0.05, 0.9, 12.0] {
            let back = radius_m(radius_code(r));
            assert!((back / r - 1.0).abs() < 0.022, "{r} -> {back}");
        }
        for s in [0.0f32, 0.013, 0.5, 1.0] {
            assert!((spread(spread_code(s)) - s).abs() <= 0.5 / 255.0 + 1e-6);
        }
        let mut w = BitWriter::default();
        w.put(0b101, 3);
        w.put(0xfff, 12);
        w.put(1, 1);
        assert_eq!(w.finish(), vec![0b1111_1101, 0b1111_1111]);
    }
}
