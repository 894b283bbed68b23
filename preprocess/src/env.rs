//! Environment maps: lat-long HDR (Radiance, via `image`) and EXR (scanline or tiled, mip-mapped,
//! half or float, via `exr`) -> 9 RGB spherical-harmonic coefficients of radiance, and a glossy
//! mip chain prefiltered for GGX and stored as BC6H.
//!
//! Convention (z up, as survey data): row 0 of the map looks up (+z); column 0 looks along +x,
//! azimuth grows toward +y. A pixel is constant radiance over its cell
//! `phi in [2 pi i / W, 2 pi (i+1) / W], theta in [pi j / H, pi (j+1) / H]`.
//!
//! Projection integrates each real SH basis function over each pixel cell exactly (the basis is
//! separable in z = cos(theta) and phi, and every factor has a closed-form antiderivative), so a
//! constant map gives exactly L00, and per-pixel solid angles sum to 4 pi to rounding. Irradiance
//! follows Ramamoorthi & Hanrahan 2001: `E(n) = sum_l A_l sum_m L_lm Y_lm(n)`, A = (pi, 2pi/3,
//! pi/4). A very bright, small source (a sun) makes that band-limited E ring negative opposite to
//! it; `window` damps bands 1 and 2 (`w_l = 1 / (1 + s l^2 (l+1)^2)`) with the smallest `s` that
//! keeps E >= 0 on a dense sphere of directions.

use std::path::Path;

use grotto_format::spec::{Bc6hBlock, EnvMipLevel, ShRgb9};

use crate::{Error, Result};

/// A lat-long map in linear RGB.
#[derive(Clone, Debug)]
pub struct LatLong {
    pub width: usize,
    pub height: usize,
    pub rgb: Vec<[f32; 3]>,
}

const Y0: f64 = 0.282_094_791_773_878_1; // 1 / (2 sqrt(pi))
const Y1: f64 = 0.488_602_511_902_919_9; // sqrt(3 / (4 pi))
const Y2: f64 = 1.092_548_430_592_079_2; // sqrt(15 / (4 pi))
const Y20: f64 = 0.315_391_565_252_52; // sqrt(5 / (16 pi))
const Y22: f64 = 0.546_274_215_296_039_6; // sqrt(15 / (16 pi))

/// The 9 real SH basis functions at unit direction `d`, order L00, L1-1, L10, L11, L2-2, L2-1,
/// L20, L21, L22.
pub fn sh_basis(d: [f64; 3]) -> [f64; 9] {
    let [x, y, z] = d;
    [
        Y0,
        Y1 * y,
        Y1 * z,
        Y1 * x,
        Y2 * x * y,
        Y2 * y * z,
        Y20 * (3.0 * z * z - 1.0),
        Y2 * x * z,
        Y22 * (x * x - y * y),
    ]
}

/// Convolution weights of the clamped cosine per band (Ramamoorthi & Hanrahan).
pub(crate) const A_HAT: [f64; 3] =
    [std::f64::consts::PI, 2.0 * std::f64::consts::PI / 3.0, std::f64::consts::PI / 4.0];

fn band(i: usize) -> usize {
    match i {
        0 => 0,
        1..=3 => 1,
        _ => 2,
    }
}

/// Irradiance at normal `n` from radiance coefficients.
pub fn irradiance(sh: &ShRgb9, n: [f64; 3]) -> [f64; 3] {
    let y = sh_basis(n);
    let mut e = [0.0; 3];
    for (i, c) in sh.coeffs.iter().enumerate() {
        for k in 0..3 {
            e[k] += A_HAT[band(i)] * f64::from(c[k]) * y[i];
        }
    }
    e
}

impl LatLong {
    /// Reads a `.hdr` or `.exr` file.
    pub fn read(path: &Path) -> Result<Self> {
        let err =
            |reason: String| Error::Read { path: path.to_path_buf(), format: "environment map", reason };
        let ext = path.extension().and_then(|e| e.to_str()).map(str::to_ascii_lowercase);
        let map = match ext.as_deref() {
            Some("hdr") => {
                let img = image::open(path).map_err(|e| err(e.to_string()))?.into_rgb32f();
                let (w, h) = (img.width() as usize, img.height() as usize);
                LatLong { width: w, height: h, rgb: img.pixels().map(|p| p.0).collect() }
            }
            Some("exr") => {
                use exr::prelude::*;
                let image = read_first_rgba_layer_from_file(
                    path,
                    |size, _| (size.0, size.1, vec![[0f32; 3]; size.0 * size.1]),
                    |(w, _, px): &mut (usize, usize, Vec<[f32; 3]>),
                     pos,
                     (r, g, b, _a): (f32, f32, f32, f32)| {
                        px[pos.1 * *w + pos.0] = [r, g, b];
                    },
                )
                .map_err(|e| err(e.to_string()))?;
                let (w, h, rgb) = image.layer_data.channel_data.pixels;
                LatLong { width: w, height: h, rgb }
            }
            _ => return Err(err("not a .hdr or .exr file".into())),
        };
        if map.width < 2 || map.height < 1 || map.rgb.len() != map.width * map.height {
            return Err(err(format!("{}x{} is not a usable lat-long map", map.width, map.height)));
        }
        // Negative or non-finite radiance is invalid; clamp rather than poison every coefficient.
        let mut map = map;
        let mut bad = 0usize;
        for p in &mut map.rgb {
            for c in p.iter_mut() {
                if !c.is_finite() || *c < 0.0 {
                    *c = 0.0;
                    bad += 1;
                }
            }
        }
        if bad * 10 > map.rgb.len() * 3 {
            return Err(err(format!("{bad} channel values are negative or not finite")));
        }
        Ok(map)
    }

    /// Exact solid angle of a pixel row's cells.
    pub fn row_solid_angle(&self, j: usize) -> f64 {
        let (z0, z1) = self.row_z(j);
        (z0 - z1) * std::f64::consts::TAU / self.width as f64
    }

    fn row_z(&self, j: usize) -> (f64, f64) {
        let t0 = std::f64::consts::PI * j as f64 / self.height as f64;
        let t1 = std::f64::consts::PI * (j + 1) as f64 / self.height as f64;
        (t0.cos(), t1.cos())
    }

    /// Direction at the centre of pixel (i, j).
    pub(crate) fn direction(&self, i: usize, j: usize) -> [f64; 3] {
        let phi = std::f64::consts::TAU * (i as f64 + 0.5) / self.width as f64;
        let theta = std::f64::consts::PI * (j as f64 + 0.5) / self.height as f64;
        [theta.sin() * phi.cos(), theta.sin() * phi.sin(), theta.cos()]
    }

    /// Projects onto 9 RGB SH coefficients with exact per-pixel integrals of the basis.
    pub fn project_sh9(&self) -> ShRgb9 {
        // Antiderivatives in z of 1, z, 3z^2 - 1, sqrt(1 - z^2), z sqrt(1 - z^2), 1 - z^2.
        let fz = |z: f64| {
            let s = (1.0 - z * z).max(0.0).sqrt();
            [
                z,
                z * z / 2.0,
                z * z * z - z,
                (z * s + z.clamp(-1.0, 1.0).asin()) / 2.0,
                -(s * s * s) / 3.0,
                z - z * z * z / 3.0,
            ]
        };
        // ... and in phi of 1, cos, sin, cos 2phi, sin 2phi / 2.
        let fp = |p: f64| [p, p.sin(), -p.cos(), (2.0 * p).sin() / 2.0, -(2.0 * p).cos() / 4.0];
        let mut acc = [[0f64; 3]; 9];
        let col: Vec<[f64; 5]> = (0..self.width)
            .map(|i| {
                let (a, b) = (
                    fp(std::f64::consts::TAU * i as f64 / self.width as f64),
                    fp(std::f64::consts::TAU * (i + 1) as f64 / self.width as f64),
                );
                std::array::from_fn(|k| b[k] - a[k])
            })
            .collect();
        for j in 0..self.height {
            let (z0, z1) = self.row_z(j);
            let (a, b) = (fz(z1), fz(z0));
            let r: [f64; 6] = std::array::from_fn(|k| b[k] - a[k]);
            for (i, c) in col.iter().enumerate() {
                // Integral of each basis function over the cell (dOmega = dz dphi).
                let w = [
                    Y0 * r[0] * c[0],
                    Y1 * r[3] * c[2],
                    Y1 * r[1] * c[0],
                    Y1 * r[3] * c[1],
                    Y2 * r[5] * c[4],
                    Y2 * r[4] * c[2],
                    Y20 * r[2] * c[0],
                    Y2 * r[4] * c[1],
                    Y22 * r[5] * c[3],
                ];
                let px = self.rgb[j * self.width + i];
                for (a, wk) in acc.iter_mut().zip(w) {
                    for k in 0..3 {
                        a[k] += wk * f64::from(px[k]);
                    }
                }
            }
        }
        ShRgb9 { coeffs: acc.map(|c| c.map(|v| v as f32)) }
    }

    /// Radiance at a direction, bilinear.
    pub(crate) fn sample(&self, d: [f64; 3]) -> [f32; 3] {
        let theta = d[2].clamp(-1.0, 1.0).acos();
        let phi = d[1].atan2(d[0]).rem_euclid(std::f64::consts::TAU);
        let x = phi / std::f64::consts::TAU * self.width as f64 - 0.5;
        let y =
            (theta / std::f64::consts::PI * self.height as f64 - 0.5).clamp(0.0, (self.height - 1) as f64);
        let (x0, y0) = (x.floor(), y.floor());
        let (fx, fy) = ((x - x0) as f32, (y - y0) as f32);
        let xi = |v: f64| (v as i64).rem_euclid(self.width as i64) as usize;
        let yi = |v: f64| (v as usize).min(self.height - 1);
        let p = |xx: f64, yy: f64| self.rgb[yi(yy) * self.width + xi(xx)];
        let (a, b, c, e) = (p(x0, y0), p(x0 + 1.0, y0), p(x0, y0 + 1.0), p(x0 + 1.0, y0 + 1.0));
        std::array::from_fn(|k| {
            (a[k] * (1.0 - fx) + b[k] * fx) * (1.0 - fy) + (c[k] * (1.0 - fx) + e[k] * fx) * fy
        })
    }

    /// Half resolution (2x2 box, solid-angle weighted rows).
    pub(crate) fn downsample(&self) -> LatLong {
        let (w, h) = ((self.width / 2).max(1), (self.height / 2).max(1));
        let mut rgb = vec![[0f32; 3]; w * h];
        for j in 0..h {
            for i in 0..w {
                let mut sum = [0f64; 3];
                let mut wsum = 0f64;
                for (dj, di) in [(0, 0), (0, 1), (1, 0), (1, 1)] {
                    let (sj, si) = ((2 * j + dj).min(self.height - 1), (2 * i + di).min(self.width - 1));
                    let wgt = self.row_solid_angle(sj);
                    let px = self.rgb[sj * self.width + si];
                    for k in 0..3 {
                        sum[k] += wgt * f64::from(px[k]);
                    }
                    wsum += wgt;
                }
                rgb[j * w + i] = sum.map(|v| (v / wsum.max(1e-300)) as f32);
            }
        }
        LatLong { width: w, height: h, rgb }
    }
}

/// Damps bands 1 and 2 just enough that irradiance is non-negative on a dense sphere of
/// directions. Returns the window strength `s` used (0 when none was needed).
pub(crate) fn window(sh: &mut ShRgb9) -> f64 {
    let dirs = fibonacci_sphere(4096);
    let min_e = |sh: &ShRgb9| {
        dirs.iter().map(|d| irradiance(sh, *d)).fold(f64::INFINITY, |m, e| m.min(e[0]).min(e[1]).min(e[2]))
    };
    let apply = |s: f64| {
        let mut out = *sh;
        for (i, c) in out.coeffs.iter_mut().enumerate() {
            let l = band(i) as f64;
            let w = 1.0 / (1.0 + s * l * l * (l + 1.0) * (l + 1.0));
            *c = c.map(|v| (f64::from(v) * w) as f32);
        }
        out
    };
    let ok = |s: f64| min_e(&apply(s)) >= 0.0;
    if ok(0.0) {
        return 0.0;
    }
    let (mut lo, mut hi) = (0.0, 1.0);
    while !ok(hi) {
        hi *= 2.0;
        if hi > 1e9 {
            break;
        }
    }
    for _ in 0..60 {
        let mid = 0.5 * (lo + hi);
        if ok(mid) { hi = mid } else { lo = mid }
    }
    *sh = apply(hi);
    hi
}

/// `n` well-spread unit directions.
pub(crate) fn fibonacci_sphere(n: usize) -> Vec<[f64; 3]> {
    let golden = std::f64::consts::PI * (3.0 - 5f64.sqrt());
    (0..n)
        .map(|i| {
            let z = 1.0 - 2.0 * (i as f64 + 0.5) / n as f64;
            let r = (1.0 - z * z).sqrt();
            let p = golden * i as f64;
            [r * p.cos(), r * p.sin(), z]
        })
        .collect()
}

/// A prefiltered level before compression.
#[derive(Clone, Debug)]
pub struct GlossLevel {
    pub(crate) roughness: f32,
    pub map: LatLong,
}

/// GGX-prefiltered levels (split-sum, N = V = R): level k has roughness k / (levels - 1) and
/// half the width of the one before (at least 8x4). Filtered importance sampling: each of the
/// `samples` GGX directions reads a source level whose pixels match the sample's solid angle.
pub fn prefilter(map: &LatLong, base_width: usize, levels: usize, samples: usize) -> Vec<GlossLevel> {
    let mut pyramid = vec![map.clone()];
    while pyramid.last().is_some_and(|m| m.width > 8) {
        let next = pyramid.last().expect("non-empty").downsample();
        pyramid.push(next);
    }
    let base = resample(map, base_width.max(8).next_power_of_two());
    let mut out = Vec::with_capacity(levels);
    for level in 0..levels.max(1) {
        let roughness = if levels > 1 { level as f32 / (levels - 1) as f32 } else { 0.0 };
        let w = (base.width >> level).max(8);
        let h = (w / 2).max(4);
        if level == 0 || roughness == 0.0 {
            out.push(GlossLevel { roughness, map: resample(&base, w) });
            continue;
        }
        let a = f64::from(roughness * roughness);
        let mut rgb = vec![[0f32; 3]; w * h];
        let proto = LatLong { width: w, height: h, rgb: Vec::new() };
        let src_pixel_sa = |m: &LatLong| 4.0 * std::f64::consts::PI / (m.width * m.height) as f64;
        for j in 0..h {
            for i in 0..w {
                let n = proto.direction(i, j);
                let (t, b) = tangent_frame(n);
                let mut sum = [0f64; 3];
                let mut wsum = 0f64;
                for s in 0..samples {
                    // Hammersley point -> GGX half vector.
                    let u = (s as f64 + 0.5) / samples as f64;
                    let v = f64::from((s as u32).reverse_bits()) / 4_294_967_296.0;
                    let phi = std::f64::consts::TAU * v;
                    let cos_t = ((1.0 - u) / (1.0 + (a * a - 1.0) * u)).sqrt();
                    let sin_t = (1.0 - cos_t * cos_t).max(0.0).sqrt();
                    let hl = [sin_t * phi.cos(), sin_t * phi.sin(), cos_t];
                    let hw: [f64; 3] = std::array::from_fn(|k| t[k] * hl[0] + b[k] * hl[1] + n[k] * hl[2]);
                    let vh = hl[2];
                    let l: [f64; 3] = std::array::from_fn(|k| 2.0 * vh * hw[k] - n[k]);
                    let nl = l[0] * n[0] + l[1] * n[1] + l[2] * n[2];
                    if nl <= 0.0 {
                        continue;
                    }
                    // pdf of l = D(h) (n.h) / (4 v.h); with n = v it is D / 4.
                    let d = a * a / (std::f64::consts::PI * ((cos_t * cos_t) * (a * a - 1.0) + 1.0).powi(2));
                    let pdf = d / 4.0;
                    let sample_sa = 1.0 / (samples as f64 * pdf);
                    let lod = (0.5 * (sample_sa / src_pixel_sa(map)).log2()).max(0.0);
                    let src = &pyramid[(lod.round() as usize).min(pyramid.len() - 1)];
                    let c = src.sample(l);
                    for k in 0..3 {
                        sum[k] += nl * f64::from(c[k]);
                    }
                    wsum += nl;
                }
                rgb[j * w + i] = sum.map(|v| (v / wsum.max(1e-300)) as f32);
            }
        }
        out.push(GlossLevel { roughness, map: LatLong { width: w, height: h, rgb } });
    }
    out
}

fn tangent_frame(n: [f64; 3]) -> ([f64; 3], [f64; 3]) {
    let up = if n[2].abs() < 0.999 { [0.0, 0.0, 1.0] } else { [1.0, 0.0, 0.0] };
    let t = [up[1] * n[2] - up[2] * n[1], up[2] * n[0] - up[0] * n[2], up[0] * n[1] - up[1] * n[0]];
    let l = (t[0] * t[0] + t[1] * t[1] + t[2] * t[2]).sqrt();
    let t = t.map(|c| c / l);
    let b = [n[1] * t[2] - n[2] * t[1], n[2] * t[0] - n[0] * t[2], n[0] * t[1] - n[1] * t[0]];
    (t, b)
}

/// Area-averaged resampling to `width` x `width / 2` (box filter through the pyramid, then
/// bilinear).
fn resample(map: &LatLong, width: usize) -> LatLong {
    let mut m = map.clone();
    while m.width >= 2 * width {
        m = m.downsample();
    }
    if m.width == width && m.height == width / 2 {
        return m;
    }
    let h = (width / 2).max(1);
    let proto = LatLong { width, height: h, rgb: Vec::new() };
    let rgb = (0..h)
        .flat_map(|j| (0..width).map(move |i| (i, j)))
        .map(|(i, j)| m.sample(proto.direction(i, j)))
        .collect();
    LatLong { width, height: h, rgb }
}

/// BC6H (unsigned half) blocks of a level, by `intel_tex_2` (ISPC texture compressor).
pub(crate) fn encode_bc6h(map: &LatLong) -> Vec<Bc6hBlock> {
    let rgba: Vec<half::f16> = map
        .rgb
        .iter()
        .flat_map(|c| [c[0], c[1], c[2], 1.0].map(|v| half::f16::from_f32(v.clamp(0.0, 65_000.0))))
        .collect();
    let bytes: &[u8] = bytemuck::cast_slice(&rgba);
    let surface = intel_tex_2::RgbaSurface {
        data: bytes,
        width: map.width as u32,
        height: map.height as u32,
        stride: map.width as u32 * 8,
    };
    let out = intel_tex_2::bc6h::compress_blocks(&intel_tex_2::bc6h::slow_settings(), &surface);
    out.chunks_exact(16).map(|c| Bc6hBlock(c.try_into().expect("16-byte blocks"))).collect()
}

/// The level table and block array for a chain.
pub fn encode_chain(levels: &[GlossLevel]) -> (Vec<EnvMipLevel>, Vec<Bc6hBlock>) {
    let table = grotto_format::level_table(
        levels.iter().map(|l| (l.map.width as u32, l.map.height as u32, l.roughness)),
    );
    let blocks: Vec<Bc6hBlock> = levels.iter().flat_map(|l| encode_bc6h(&l.map)).collect();
    debug_assert_eq!(blocks.len() as u32, table.iter().map(|l| l.block_count).sum::<u32>());
    (table, blocks)
}

#[cfg(test)]
mod tests {
    use super::*;

    fn constant(w: usize, h: usize, c: [f32; 3]) -> LatLong {
        LatLong { width: w, height: h, rgb: vec![c; w * h] }
    }

    #[test]
    fn solid_angles_sum_to_four_pi() {
        for (w, h) in [(8, 4), (64, 32), (1024, 512), (37, 19)] {
            let m = constant(w, h, [1.0; 3]);
            let sum: f64 = (0..h).map(|j| m.row_solid_angle(j) * w as f64).sum();
            assert!((sum - 4.0 * std::f64::consts::PI).abs() < 1e-6, "{w}x{h}: {sum}");
        }
    }

    #[test]
    fn constant_map_gives_only_l00_and_irradiance_pi_l() {
        let m = constant(64, 32, [2.0, 1.0, 0.5]);
        let sh = m.project_sh9();
        for k in 0..3 {
            let l = [2.0, 1.0, 0.5][k];
            assert!((f64::from(sh.coeffs[0][k]) - l * 4.0 * std::f64::consts::PI * Y0).abs() < 1e-4 * l);
            for c in &sh.coeffs[1..] {
                assert!(c[k].abs() < 1e-5, "{:?}", sh.coeffs);
            }
        }
        for d in fibonacci_sphere(100) {
            let e = irradiance(&sh, d);
            for k in 0..3 {
                let want = std::f64::consts::PI * [2.0, 1.0, 0.5][k];
                assert!((e[k] - want).abs() < 1e-4 * want, "{e:?}");
            }
        }
    }

    /// A disc of radiance 1 and angular radius `alpha` around `dir`, rendered with 8x8
    /// supersampling per pixel.
    fn disc(w: usize, h: usize, dir: [f64; 3], alpha: f64) -> LatLong {
        let cos_a = alpha.cos();
        let mut rgb = vec![[0f32; 3]; w * h];
        for j in 0..h {
            for i in 0..w {
                let mut hit = 0;
                for s in 0..64 {
                    let phi = std::f64::consts::TAU * (i as f64 + ((s % 8) as f64 + 0.5) / 8.0) / w as f64;
                    let theta = std::f64::consts::PI * (j as f64 + ((s / 8) as f64 + 0.5) / 8.0) / h as f64;
                    let d = [theta.sin() * phi.cos(), theta.sin() * phi.sin(), theta.cos()];
                    if d[0] * dir[0] + d[1] * dir[1] + d[2] * dir[2] >= cos_a {
                        hit += 1;
                    }
                }
                rgb[j * w + i] = [hit as f32 / 64.0; 3];
            }
        }
        LatLong { width: w, height: h, rgb }
    }

    #[test]
    fn a_small_bright_disc_matches_its_closed_form_projection() {
        let alpha = 0.2f64;
        let dir = {
            let v = [0.3f64, -0.5, 0.6];
            let l = (v[0] * v[0] + v[1] * v[1] + v[2] * v[2]).sqrt();
            v.map(|c| c / l)
        };
        let sh = disc(512, 256, dir, alpha).project_sh9();
        // Zonal harmonics of a cap: z_l = 2 pi * integral_{cos a}^{1} Y_l0(z) dz, rotated to dir:
        // L_lm = sqrt(4 pi / (2l + 1)) z_l Y_lm(dir).
        let c = alpha.cos();
        let z0 = std::f64::consts::TAU * Y0 * (1.0 - c);
        let z1 = std::f64::consts::TAU * Y1 * (1.0 - c * c) / 2.0;
        let z2 = std::f64::consts::TAU * Y20 * ((1.0 - c * c * c) - (1.0 - c));
        let y = sh_basis(dir);
        for i in 0..9 {
            let (l, zl) = [(0.0, z0), (1.0, z1), (2.0, z2)][band(i)];
            let want = (4.0 * std::f64::consts::PI / (2.0 * l + 1.0)).sqrt() * zl * y[i];
            let got = f64::from(sh.coeffs[i][0]);
            assert!((got - want).abs() < 2e-3 * z0.abs(), "coefficient {i}: {got} vs {want}");
        }
    }

    #[test]
    fn windowing_keeps_irradiance_non_negative_everywhere() {
        // A sun: tiny, 10^4 times brighter than the sky.
        let mut m = disc(256, 128, [0.0, 0.6, 0.8], 0.03);
        for p in &mut m.rgb {
            *p = p.map(|v| 0.05 + 1e4 * v);
        }
        let mut sh = m.project_sh9();
        let raw_min =
            fibonacci_sphere(4096).iter().map(|d| irradiance(&sh, *d)[0]).fold(f64::INFINITY, f64::min);
        assert!(raw_min < 0.0, "the test needs ringing: {raw_min}");
        let s = window(&mut sh);
        assert!(s > 0.0);
        // Checked on directions other than those the window was fitted on.
        let mut x = 0x1234_5678_u64;
        let mut next = move || {
            x ^= x << 13;
            x ^= x >> 7;
            x ^= x << 17;
            (x >> 11) as f64 / (1u64 << 53) as f64
        };
        for _ in 0..10_000 {
            let z = 2.0 * next() - 1.0;
            let p = std::f64::consts::TAU * next();
            let r = (1.0 - z * z).sqrt();
            let e = irradiance(&sh, [r * p.cos(), r * p.sin(), z]);
            assert!(e.iter().all(|&v| v >= -1e-6 * f64::from(sh.coeffs[0][0])), "{e:?}");
        }
        // A map that does not ring is left alone.
        let mut flat = constant(32, 16, [1.0; 3]).project_sh9();
        let before = flat;
        assert_eq!(window(&mut flat), 0.0);
        assert_eq!(flat, before);
    }

    #[test]
    fn prefiltered_chain_has_the_promised_shape_and_conserves_a_constant() {
        let m = constant(128, 64, [0.5, 1.0, 2.0]);
        let levels = prefilter(&m, 64, 4, 64);
        assert_eq!(levels.len(), 4);
        assert_eq!((levels[0].map.width, levels[0].map.height, levels[3].map.width), (64, 32, 8));
        for l in &levels {
            for p in &l.map.rgb {
                assert!((p[2] - 2.0).abs() < 1e-3, "roughness {}: {p:?}", l.roughness);
            }
        }
        let (table, blocks) = encode_chain(&levels);
        assert_eq!(table.iter().map(|t| t.block_count).sum::<u32>() as usize, blocks.len());
        assert_eq!(table[1].first_block, table[0].block_count);
    }
}
