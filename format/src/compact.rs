//! The compact surfel encoding of format 2.0 (section kind 18, `surfels-compact`): surfels grouped
//! in runs by leaf, positions quantised inside their leaf, octahedral normals, a log-coded radius
//! and a spread byte, laid out as planes so zstd finds each plane's redundancy (docs/format.md,
//! "Compact surfels"). [`encode`] refuses a tile it cannot store within the stated bounds, so the
//! writer keeps that tile's surfels at full precision; [`decode`] and [`check`] trust nothing.
//!
//! Written by hand: the octahedral map (Meyer et al. 2010, with the nearest of the four surrounding
//! codes chosen as in Cigolle et al. 2014) is a few lines, and the rest is this format's own layout.

use crate::spec::Surfel;
use crate::svo::{morton_decode, morton_encode};

/// Bits per octahedral coordinate written; a reader takes 1..=16 from the header.
pub const NORMAL_BITS: u32 = 12;
/// Most bits per position axis.
pub const MAX_POSITION_BITS: u32 = 16;
/// Bytes before the planes.
pub const HEADER_LEN: usize = 16;
/// Most surfels in one run (a leaf with more takes several runs).
pub const MAX_RUN: usize = u16::MAX as usize;
/// The bound the packer uses: no position moves further than this.
pub const MAX_POSITION_ERROR_M: f64 = 0.001;
/// Radius codes per octave; code 1 is [`RADIUS_MIN_M`], code 0 is a radius of zero.
const RADIUS_CODES_PER_OCTAVE: f32 = 16.0;
const RADIUS_MIN_LOG2: f32 = -12.0;
/// Smallest non-zero radius code, metres (2^-12 m, 0.24 mm).
pub const RADIUS_MIN_M: f32 = 1.0 / 4096.0;

/// The fewest bits per axis (1..=16) whose worst position error inside a leaf of `leaf_m`, half a
/// step on each axis (`sqrt(3) / 2` steps), is at most `max_error_m`; `None` when 16 do not do.
pub fn position_bits(leaf_m: f64, max_error_m: f64) -> Option<u32> {
    (1..=MAX_POSITION_BITS).find(|&b| leaf_m / f64::from(1u32 << b) * 3f64.sqrt() / 2.0 <= max_error_m)
}

/// The position's leaf cell (clamped into the tile's `cells` per axis) and its offset quantised
/// to `bits`.
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

/// The centre of the quantised position's step, metres from the tile origin.
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

/// The octahedral codes (`bits` each) back to a unit normal. Every pair of codes gives a unit
/// vector: the octahedron's points are never at the origin.
pub fn oct_decode(u: u32, v: u32, bits: u32) -> [f32; 3] {
    let max = ((1u32 << bits) - 1) as f32;
    let (x, y) = (u as f32 / max * 2.0 - 1.0, v as f32 / max * 2.0 - 1.0);
    let z = 1.0 - x.abs() - y.abs();
    let (x, y) = if z < 0.0 { oct_wrap(x, y) } else { (x, y) };
    let l = (x * x + y * y + z * z).sqrt();
    [x / l, y / l, z / l]
}

/// The codes (`bits` each) of the four around `n`'s octahedral point whose normal is nearest `n`:
/// at most 0.0484 degrees off with 12 bits.
pub fn oct_encode(n: [f32; 3], bits: u32) -> (u32, u32) {
    let max = ((1u32 << bits) - 1) as f32;
    let (x, y) = oct_map(n);
    let (fx, fy) = (((x + 1.0) / 2.0 * max).floor(), ((y + 1.0) / 2.0 * max).floor());
    // Nearest by squared distance, not by cosine: near 1 an f32 cosine cannot tell apart codes
    // 0.03 and 0.05 degrees off (its spacing there is 6e-8), the difference vector can.
    let mut best = (0u32, 0u32, f32::INFINITY);
    for (dx, dy) in [(0.0, 0.0), (1.0, 0.0), (0.0, 1.0), (1.0, 1.0)] {
        let (u, v) = ((fx + dx).clamp(0.0, max) as u32, (fy + dy).clamp(0.0, max) as u32);
        let d = oct_decode(u, v, bits);
        let dist2 = (d[0] - n[0]).powi(2) + (d[1] - n[1]).powi(2) + (d[2] - n[2]).powi(2);
        if dist2 < best.2 {
            best = (u, v, dist2);
        }
    }
    (best.0, best.1)
}

/// The nearest code (in log space) of a radius; 0 only for a radius of zero or below half the
/// smallest code.
pub fn radius_code(radius_m: f32) -> u8 {
    if radius_m.is_nan() || radius_m < RADIUS_MIN_M / 2.0 {
        return 0;
    }
    let c = (radius_m.log2() - RADIUS_MIN_LOG2) * RADIUS_CODES_PER_OCTAVE + 1.0;
    c.round().clamp(1.0, 255.0) as u8
}

/// The surfel radius in metres a log-radius byte stands for.
pub fn radius_m(code: u8) -> f32 {
    if code == 0 { 0.0 } else { ((f32::from(code) - 1.0) / RADIUS_CODES_PER_OCTAVE + RADIUS_MIN_LOG2).exp2() }
}

/// The byte that codes an NDF spread (0..=1).
pub fn spread_code(spread: f32) -> u8 {
    (spread.clamp(0.0, 1.0) * 255.0).round() as u8
}

/// The NDF spread a spread byte stands for.
pub fn spread(code: u8) -> f32 {
    f32::from(code) / 255.0
}

/// Whether a decoded radius is as close as the code allows: within 2.2% (half a code step is
/// 2^(1/32) - 1 = 2.19%), or within 0.125 mm for radii below the smallest code.
pub fn radius_within_bound(stored_m: f32, decoded_m: f32) -> bool {
    let e = (decoded_m - stored_m).abs();
    e <= 0.022 * stored_m || e <= RADIUS_MIN_M / 2.0
}

/// A little-endian bit stream: each value's low bits, least significant first.
#[derive(Debug, Default)]
struct BitWriter {
    bytes: Vec<u8>,
    acc: u64,
    filled: u32,
}

impl BitWriter {
    fn put(&mut self, value: u32, bits: u32) {
        self.acc |= (u64::from(value) & ((1u64 << bits) - 1)) << self.filled;
        self.filled += bits;
        while self.filled >= 8 {
            self.bytes.push(self.acc as u8);
            self.acc >>= 8;
            self.filled -= 8;
        }
    }

    fn finish(mut self) -> Vec<u8> {
        if self.filled > 0 {
            self.bytes.push(self.acc as u8);
        }
        self.bytes
    }
}

/// Reads what [`BitWriter`] wrote; past the end it reads zeros (lengths are checked before).
struct BitReader<'a> {
    bytes: &'a [u8],
    next: usize,
    acc: u64,
    filled: u32,
}

impl<'a> BitReader<'a> {
    fn new(bytes: &'a [u8]) -> Self {
        Self { bytes, next: 0, acc: 0, filled: 0 }
    }

    fn get(&mut self, bits: u32) -> u32 {
        while self.filled < bits {
            let b = self.bytes.get(self.next).copied().unwrap_or(0);
            self.next += 1;
            self.acc |= u64::from(b) << self.filled;
            self.filled += 8;
        }
        let v = (self.acc & ((1u64 << bits) - 1)) as u32;
        self.acc >>= bits;
        self.filled -= bits;
        v
    }
}

/// The header of a compact section (16 bytes, little-endian).
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub struct Header {
    pub surfel_count: u32,
    pub run_count: u32,
    pub position_bits: u32,
    pub normal_bits: u32,
}

/// Where each plane lies in the decoded bytes.
struct Planes {
    runs: std::ops::Range<usize>,
    counts: std::ops::Range<usize>,
    positions: std::ops::Range<usize>,
    normals: std::ops::Range<usize>,
    radii: std::ops::Range<usize>,
    spreads: std::ops::Range<usize>,
}

impl Header {
    fn to_bytes(self) -> [u8; HEADER_LEN] {
        let mut b = [0u8; HEADER_LEN];
        b[0..4].copy_from_slice(&self.surfel_count.to_le_bytes());
        b[4..8].copy_from_slice(&self.run_count.to_le_bytes());
        b[8] = self.position_bits as u8;
        b[9] = self.normal_bits as u8;
        b
    }

    /// The header of `bytes`, checked against their length and the tile's depth.
    pub fn read(bytes: &[u8]) -> Result<Self, String> {
        let Some(h) = bytes.get(..HEADER_LEN) else {
            return Err(format!("{} bytes is shorter than the {HEADER_LEN}-byte header", bytes.len()));
        };
        let u32_at = |i: usize| u32::from_le_bytes([h[i], h[i + 1], h[i + 2], h[i + 3]]);
        let header = Self {
            surfel_count: u32_at(0),
            run_count: u32_at(4),
            position_bits: u32::from(h[8]),
            normal_bits: u32::from(h[9]),
        };
        if !(1..=MAX_POSITION_BITS).contains(&header.position_bits) || !(1..=16).contains(&header.normal_bits)
        {
            return Err(format!(
                "{} position bits and {} normal bits (each must be 1..=16)",
                header.position_bits, header.normal_bits
            ));
        }
        if h[10..].iter().any(|&b| b != 0) {
            return Err("reserved header bytes are not zero".into());
        }
        if header.run_count > header.surfel_count {
            return Err(format!("{} runs for {} surfels", header.run_count, header.surfel_count));
        }
        let expected = header.planes().map(|p| p.spreads.end);
        if expected != Some(bytes.len()) {
            return Err(format!(
                "{} bytes where {} surfels in {} runs take {}",
                bytes.len(),
                header.surfel_count,
                header.run_count,
                expected.map_or("more than this machine can address".into(), |e| e.to_string())
            ));
        }
        Ok(header)
    }

    /// The byte ranges of the planes, in checked arithmetic.
    fn planes(self) -> Option<Planes> {
        let (n, r) = (self.surfel_count as usize, self.run_count as usize);
        let bits = |per: u32| n.checked_mul(per as usize)?.checked_add(7).map(|b| b / 8);
        let mut at = HEADER_LEN;
        let mut next = |len: usize| -> Option<std::ops::Range<usize>> {
            let start = at;
            at = at.checked_add(len)?;
            Some(start..at)
        };
        Some(Planes {
            runs: next(r.checked_mul(8)?)?,
            counts: next(r.checked_mul(2)?)?,
            positions: next(bits(3 * self.position_bits)?)?,
            normals: next(bits(2 * self.normal_bits)?)?,
            radii: next(n)?,
            spreads: next(n)?,
        })
    }
}

/// One surfel's codes: its leaf's Morton code, its position within the leaf, octahedral normal,
/// radius and spread codes ([`code_surfels`]), which [`encode_codes`] packs into a section. The
/// split lets a caller code runs of surfels in parallel (this crate stays single-threaded).
#[derive(Clone, Copy, Debug, Default, PartialEq)]
pub struct SurfelCodes {
    morton: u64,
    q: [u32; 3],
    normal: [u32; 2],
    radius: u8,
    spread: u8,
}

/// Codes `surfels` into `out` (same length), or `None` when one of them cannot be stored within
/// the bounds (see [`encode`]).
pub fn code_surfels(
    surfels: &[Surfel],
    leaf_m: f64,
    depth: u32,
    max_position_error_m: f64,
    out: &mut [SurfelCodes],
) -> Option<()> {
    let position_bits = position_bits(leaf_m, max_position_error_m)?;
    let cells = 1u32.checked_shl(depth)?;
    if out.len() != surfels.len() {
        return None;
    }
    for (s, code) in surfels.iter().zip(out) {
        let (cell, q) = quantise_position(s.position_tile_m, leaf_m, cells, position_bits);
        let back = dequantise_position(cell, q, leaf_m, position_bits);
        let moved =
            (0..3).map(|a| (f64::from(back[a]) - f64::from(s.position_tile_m[a])).powi(2)).sum::<f64>();
        // The f32 rounding of the decoded position (micrometres in a tile of tens of metres).
        let f32_slack = f64::from(s.position_tile_m.iter().fold(0f32, |m, c| m.max(c.abs()))) * 1e-7;
        if moved.is_nan() || moved.sqrt() > max_position_error_m + f32_slack {
            return None;
        }
        let radius = radius_code(s.radius_m);
        if !radius_within_bound(s.radius_m, radius_m(radius)) {
            return None;
        }
        let (u, v) = oct_encode(s.normal, NORMAL_BITS);
        *code = SurfelCodes {
            morton: morton_encode(cell[0], cell[1], cell[2]),
            q,
            normal: [u, v],
            radius,
            spread: spread_code(s.spread),
        };
    }
    Some(())
}

/// Encodes a tile's surfels, in their order, or `None` when one of them cannot be stored within
/// the bounds (a position more than `max_position_error_m` away, as for a surfel outside the
/// tile's cube or leaves too large for 16 bits; a radius beyond the codes) or the tile has more
/// than `u32::MAX` surfels.
pub fn encode(surfels: &[Surfel], leaf_m: f64, depth: u32, max_position_error_m: f64) -> Option<Vec<u8>> {
    let mut codes = vec![SurfelCodes::default(); surfels.len()];
    code_surfels(surfels, leaf_m, depth, max_position_error_m, &mut codes)?;
    encode_codes(&codes, leaf_m, max_position_error_m)
}

/// Packs surfels coded by [`code_surfels`] (with the same leaf and bound) into a section.
pub fn encode_codes(codes: &[SurfelCodes], leaf_m: f64, max_position_error_m: f64) -> Option<Vec<u8>> {
    let position_bits = position_bits(leaf_m, max_position_error_m)?;
    let surfel_count = u32::try_from(codes.len()).ok()?;
    let (mut positions, mut normals) = (BitWriter::default(), BitWriter::default());
    let mut radii = Vec::with_capacity(codes.len());
    let mut spreads = Vec::with_capacity(codes.len());
    let (mut runs, mut counts): (Vec<u64>, Vec<u16>) = (Vec::new(), Vec::new());
    let mut last_morton = 0u64;
    for c in codes {
        match counts.last_mut() {
            Some(n) if c.morton == last_morton && usize::from(*n) < MAX_RUN => *n += 1,
            _ => {
                runs.push(c.morton.wrapping_sub(last_morton));
                counts.push(1);
                last_morton = c.morton;
            }
        }
        for a in c.q {
            positions.put(a, position_bits);
        }
        normals.put(c.normal[0], NORMAL_BITS);
        normals.put(c.normal[1], NORMAL_BITS);
        radii.push(c.radius);
        spreads.push(c.spread);
    }
    let header =
        Header { surfel_count, run_count: runs.len() as u32, position_bits, normal_bits: NORMAL_BITS };
    let planes = header.planes()?;
    let mut out = Vec::with_capacity(planes.spreads.end);
    out.extend_from_slice(&header.to_bytes());
    out.extend(runs.iter().flat_map(|d| d.to_le_bytes()));
    out.extend(counts.iter().flat_map(|c| c.to_le_bytes()));
    out.extend(positions.finish());
    out.extend(normals.finish());
    out.extend(radii);
    out.extend(spreads);
    debug_assert_eq!(out.len(), planes.spreads.end);
    Some(out)
}

/// Checks a compact section's structure for a tile of `depth`: the header, the planes' lengths,
/// the runs (each non-empty, adding up to the surfels, each leaf inside the tile).
pub fn check(bytes: &[u8], depth: u32) -> Result<Header, String> {
    let header = Header::read(bytes)?;
    let planes = header.planes().expect("checked by Header::read");
    let cells_end = 1u64.checked_shl(3 * depth).ok_or("tile too deep")?;
    let mut morton = 0u64;
    let mut total = 0u64;
    let counts = bytes[planes.counts].chunks_exact(2).map(|c| u16::from_le_bytes([c[0], c[1]]));
    for (i, (d, count)) in bytes[planes.runs].chunks_exact(8).zip(counts).enumerate() {
        morton = morton.wrapping_add(u64::from_le_bytes(d.try_into().expect("chunks of 8")));
        if morton >= cells_end {
            return Err(format!(
                "run {i}'s leaf (Morton code {morton}) lies outside the tile of depth {depth}"
            ));
        }
        if count == 0 {
            return Err(format!("run {i} is empty"));
        }
        total += u64::from(count);
    }
    if total != u64::from(header.surfel_count) {
        return Err(format!("the runs hold {total} surfels, the header says {}", header.surfel_count));
    }
    Ok(header)
}

/// Decodes a compact section of a tile with leaves of `leaf_m` and `depth` levels.
pub fn decode(bytes: &[u8], leaf_m: f64, depth: u32) -> Result<Vec<Surfel>, String> {
    let mut out = Vec::with_capacity(count(bytes, depth)?);
    decode_each(bytes, leaf_m, depth, |s| out.push(s))?;
    Ok(out)
}

/// How many surfels a section holds (its checked header's count).
pub fn count(bytes: &[u8], depth: u32) -> Result<usize, String> {
    Ok(check(bytes, depth)?.surfel_count as usize)
}

/// [`decode`] one surfel at a time, none of them held: `each` gets them in stored order.
pub fn decode_each(
    bytes: &[u8],
    leaf_m: f64,
    depth: u32,
    mut each: impl FnMut(Surfel),
) -> Result<(), String> {
    let header = check(bytes, depth)?;
    let planes = header.planes().expect("checked by Header::read");
    let (pb, nb) = (header.position_bits, header.normal_bits);
    let mut positions = BitReader::new(&bytes[planes.positions]);
    let mut normals = BitReader::new(&bytes[planes.normals]);
    let mut radii = bytes[planes.radii].iter();
    let mut spreads = bytes[planes.spreads].iter();
    let counts = bytes[planes.counts].chunks_exact(2).map(|c| u16::from_le_bytes([c[0], c[1]]));
    let mut morton = 0u64;
    for (d, count) in bytes[planes.runs].chunks_exact(8).zip(counts) {
        morton = morton.wrapping_add(u64::from_le_bytes(d.try_into().expect("chunks of 8")));
        let cell = morton_decode(morton);
        for _ in 0..count {
            let q = [positions.get(pb), positions.get(pb), positions.get(pb)];
            let (u, v) = (normals.get(nb), normals.get(nb));
            each(Surfel {
                position_tile_m: dequantise_position(cell, q, leaf_m, pb),
                radius_m: radius_m(*radii.next().expect("planes sized by the header")),
                normal: oct_decode(u, v, nb),
                spread: spread(*spreads.next().expect("planes sized by the header")),
            });
        }
    }
    Ok(())
}

#[cfg(test)]
mod tests {
    use super::*;

    /// atan2(|a x b|, a . b) in f64: an acos of an f32 dot product is off by thousandths of a
    /// degree this close to 1.
    fn angle_deg(a: [f32; 3], b: [f32; 3]) -> f64 {
        let (a, b) = (a.map(f64::from), b.map(f64::from));
        let c = [a[1] * b[2] - a[2] * b[1], a[2] * b[0] - a[0] * b[2], a[0] * b[1] - a[1] * b[0]];
        (c[0] * c[0] + c[1] * c[1] + c[2] * c[2])
            .sqrt()
            .atan2(a[0] * b[0] + a[1] * b[1] + a[2] * b[2])
            .to_degrees()
    }

    struct Rng(u64);
    impl Rng {
        fn next(&mut self) -> f32 {
            self.0 ^= self.0 << 13;
            self.0 ^= self.0 >> 7;
            self.0 ^= self.0 << 17;
            (self.0 >> 11) as f32 / (1u64 << 53) as f32
        }
    }

    #[test]
    fn normals_survive_the_octahedral_codes_within_a_twentieth_of_a_degree() {
        let mut worst = 0f64;
        let mut rng = Rng(0x2545_f491_4f6c_dd1d);
        for i in 0..500_000 {
            // Random directions, and the axes and diagonals where the map folds.
            let n = match i {
                0 => [0.0, 0.0, -1.0],
                1 => [1.0, 0.0, 0.0],
                2 => [0.0, -1.0, 0.0],
                3 => [0.577, -0.577, -0.577],
                _ => [rng.next() * 2.0 - 1.0, rng.next() * 2.0 - 1.0, rng.next() * 2.0 - 1.0],
            };
            let l = (n[0] * n[0] + n[1] * n[1] + n[2] * n[2]).sqrt();
            if l < 1e-3 {
                continue;
            }
            let n = n.map(|c| c / l);
            let (u, v) = oct_encode(n, NORMAL_BITS);
            worst = worst.max(angle_deg(n, oct_decode(u, v, NORMAL_BITS)));
        }
        // The 12-bit "precise" octahedral code's worst case is 0.0484 degrees.
        assert!(worst < 0.0485, "worst {worst} degrees");
    }

    #[test]
    fn positions_move_at_most_the_bound_their_bits_were_chosen_for() {
        for leaf_m in [0.0625, 0.125, 1.0] {
            let bits = position_bits(leaf_m, 0.001).unwrap();
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
        assert_eq!(position_bits(0.0625, 0.001), Some(6));
        assert_eq!(position_bits(200.0, 0.001), None);
    }

    #[test]
    fn radius_and_spread_codes_round_trip_within_their_steps() {
        for r in [0.0f32, 0.00005, 0.0003, 0.004, 0.05, 0.9, 12.0] {
            let back = radius_m(radius_code(r));
            assert!(radius_within_bound(r, back), "{r} -> {back}");
        }
        assert_eq!(radius_code(0.0), 0);
        assert!(!radius_within_bound(20.0, radius_m(radius_code(20.0))));
        for s in [0.0f32, 0.013, 0.5, 1.0] {
            assert!((spread(spread_code(s)) - s).abs() <= 0.5 / 255.0 + 1e-6);
        }
        let mut w = BitWriter::default();
        w.put(0b101, 3);
        w.put(0xfff, 12);
        w.put(1, 1);
        let bytes = w.finish();
        assert_eq!(bytes, vec![0b1111_1101, 0b1111_1111]);
        let mut r = BitReader::new(&bytes);
        assert_eq!((r.get(3), r.get(12), r.get(1)), (0b101, 0xfff, 1));
    }

    fn surfels(n: usize, extent_m: f32, rng: &mut Rng) -> Vec<Surfel> {
        let mut out: Vec<Surfel> = (0..n)
            .map(|_| {
                let n = [rng.next() - 0.5, rng.next() - 0.5, rng.next() - 0.5 + 1e-3];
                let l = (n[0] * n[0] + n[1] * n[1] + n[2] * n[2]).sqrt();
                Surfel {
                    position_tile_m: [rng.next() * extent_m, rng.next() * extent_m, rng.next() * extent_m],
                    radius_m: rng.next() * 0.05,
                    normal: n.map(|c| c / l),
                    spread: rng.next(),
                }
            })
            .collect();
        // Leaf order, as the packer writes them, but any order must round-trip.
        out[..n / 2].sort_by_key(|s| {
            let c = s.position_tile_m.map(|c| (c / extent_m * 64.0) as u32);
            morton_encode(c[0], c[1], c[2])
        });
        out
    }

    #[test]
    fn a_tile_round_trips_within_the_bounds_in_its_order() {
        let mut rng = Rng(7);
        let (depth, extent) = (6, 4.0f32);
        let leaf_m = f64::from(extent) / 64.0;
        let input = surfels(3000, extent, &mut rng);
        let bytes = encode(&input, leaf_m, depth, MAX_POSITION_ERROR_M).unwrap();
        let back = decode(&bytes, leaf_m, depth).unwrap();
        assert_eq!(back.len(), input.len());
        for (a, b) in input.iter().zip(&back) {
            let moved =
                (0..3).map(|i| (a.position_tile_m[i] - b.position_tile_m[i]).powi(2)).sum::<f32>().sqrt();
            assert!(moved <= 0.001 + 1e-6, "{a:?} -> {b:?}");
            assert!(angle_deg(a.normal, b.normal) < 0.0485);
            assert!(radius_within_bound(a.radius_m, b.radius_m));
            assert!((a.spread - b.spread).abs() <= 0.5 / 255.0 + 1e-6);
        }
        assert_eq!(check(&bytes, depth).unwrap().surfel_count, 3000);
        // One at a time, the same surfels in the same order.
        let mut each = Vec::new();
        decode_each(&bytes, leaf_m, depth, |s| each.push(s)).unwrap();
        assert_eq!(bytemuck::cast_slice::<Surfel, u8>(&each), bytemuck::cast_slice::<Surfel, u8>(&back));
        assert_eq!(count(&bytes, depth), Ok(3000));
        assert!(decode_each(&bytes[..bytes.len() / 2], leaf_m, depth, |_| {}).is_err());
        // An empty tile, and one leaf holding more than a run.
        assert!(decode(&encode(&[], leaf_m, depth, 0.001).unwrap(), leaf_m, depth).unwrap().is_empty());
        let one = Surfel { position_tile_m: [0.01; 3], radius_m: 0.01, normal: [0.0, 0.0, 1.0], spread: 0.0 };
        let many = vec![one; MAX_RUN + 10];
        let bytes = encode(&many, leaf_m, depth, 0.001).unwrap();
        assert_eq!(Header::read(&bytes).unwrap().run_count, 2);
        assert_eq!(decode(&bytes, leaf_m, depth).unwrap().len(), MAX_RUN + 10);
    }

    #[test]
    fn surfels_the_bounds_cannot_hold_are_refused_not_moved() {
        let leaf_m = 4.0 / 64.0;
        let inside =
            Surfel { position_tile_m: [1.0; 3], radius_m: 0.01, normal: [0.0, 0.0, 1.0], spread: 0.0 };
        let outside = Surfel { position_tile_m: [4.5, 1.0, 1.0], ..inside };
        assert!(encode(&[inside, outside], leaf_m, 6, 0.001).is_none());
        assert!(encode(&[Surfel { radius_m: 40.0, ..inside }], leaf_m, 6, 0.001).is_none());
        // Leaves of 200 m need more than 16 bits for 1 mm.
        assert!(encode(&[inside], 200.0, 0, 0.001).is_none());
    }

    #[test]
    fn damaged_sections_are_refused_with_a_reason() {
        let mut rng = Rng(11);
        let leaf_m = 4.0 / 64.0;
        let good = encode(&surfels(100, 4.0, &mut rng), leaf_m, 6, 0.001).unwrap();
        let refuse = |bytes: &[u8], what: &str| {
            let e = decode(bytes, leaf_m, 6).unwrap_err();
            assert!(e.contains(what), "{e}");
        };
        refuse(&good[..10], "shorter than");
        refuse(&good[..good.len() - 1], "bytes where");
        let mut lying = good.clone();
        lying[0..4].copy_from_slice(&u32::MAX.to_le_bytes());
        refuse(&lying, "bytes where");
        let mut bits = good.clone();
        bits[8] = 0;
        refuse(&bits, "position bits");
        let mut empty_run = good.clone();
        let counts = HEADER_LEN + 8 * Header::read(&good).unwrap().run_count as usize;
        empty_run[counts..counts + 2].copy_from_slice(&0u16.to_le_bytes());
        refuse(&empty_run, "is empty");
        let mut far = good.clone();
        far[HEADER_LEN..HEADER_LEN + 8].copy_from_slice(&(1u64 << 40).to_le_bytes());
        refuse(&far, "outside the tile");
        // A tile one level shallower cannot hold the same leaves.
        assert!(decode(&good, leaf_m * 2.0, 5).is_err());
    }
}
