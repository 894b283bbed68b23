//! Photometry for lights written by people: luminous flux in lumens and colour temperatures in
//! kelvin, turned into grotto's radiometric units (a light's `power_w` and linear sRGB `color`).
//!
//! grotto renders three linear sRGB channels. A channel value of radiant flux, irradiance or
//! radiance is read photometrically the way every RGB renderer does: its luminance
//! `Y = 0.2126 R + 0.7152 G + 0.0722 B` (ITU-R BT.709 / sRGB) times 683 lm/W, the luminous
//! efficacy at 555 nm that defines the candela. So a light of `power_w` watts and colour `c` emits
//! `683 * Y(c) * power_w` lumens, and an irradiance of `E` W/m^2 per channel is `683 * Y(E)` lux.
//!
//! Colour temperatures sum Planck's law against the CIE 1931 2-degree observer (the 5 nm table),
//! then convert XYZ to linear sRGB (IEC 61966-2-1, D65). Hand-written because it is a few lines
//! of physics and one standard table; the crates that do it fit curves to 8-bit colours (1-2%
//! off in the warm range show caves use) or wrap a colour-science library far larger than this.
//! (An analytic fit of the observer, Wyman et al. 2013, was tried: 0.004 off in x at 1500 K.)

/// Lumens per watt at 555 nm (the definition of the candela).
pub const LUMENS_PER_WATT: f64 = 683.0;

/// Luminance of a linear sRGB triple (the Y row of the sRGB to XYZ matrix).
pub fn luminance(rgb: [f64; 3]) -> f64 {
    0.2126 * rgb[0] + 0.7152 * rgb[1] + 0.0722 * rgb[2]
}

/// Watts (grotto's radiant power) of a light of `lumens` with colour `rgb`; None where the
/// colour has no luminance.
pub fn watts_of_lumens(lumens: f64, rgb: [f64; 3]) -> Option<f64> {
    let y = luminance(rgb);
    (y > 1e-9).then(|| lumens / (LUMENS_PER_WATT * y))
}

/// Lux of an irradiance given per linear sRGB channel in W/m^2.
pub fn lux_of_irradiance(rgb_w_m2: [f64; 3]) -> f64 {
    LUMENS_PER_WATT * luminance(rgb_w_m2)
}

/// Colour temperatures this module answers for, kelvin (candle flame to blue sky).
pub const KELVIN_RANGE: std::ops::RangeInclusive<f64> = 1000.0..=40000.0;

/// The CIE 1931 2-degree standard observer's colour matching functions x, y, z at 380, 385 ...
/// 780 nm (CIE 15:2004, as distributed by the Colour and Vision Research Laboratory, UCL,
/// cvrl.org: standard data, not anyone's code).
#[rustfmt::skip]
const CIE_1931_5NM: [[f64; 3]; 81] = [
    [0.001368, 0.000039, 0.006450],
    [0.002236, 0.000064, 0.010550],
    [0.004243, 0.000120, 0.020050],
    [0.007650, 0.000217, 0.036210],
    [0.014310, 0.000396, 0.067850],
    [0.023190, 0.000640, 0.110200],
    [0.043510, 0.001210, 0.207400],
    [0.077630, 0.002180, 0.371300],
    [0.134380, 0.004000, 0.645600],
    [0.214770, 0.007300, 1.039050],
    [0.283900, 0.011600, 1.385600],
    [0.328500, 0.016840, 1.622960],
    [0.348280, 0.023000, 1.747060],
    [0.348060, 0.029800, 1.782600],
    [0.336200, 0.038000, 1.772110],
    [0.318700, 0.048000, 1.744100],
    [0.290800, 0.060000, 1.669200],
    [0.251100, 0.073900, 1.528100],
    [0.195360, 0.090980, 1.287640],
    [0.142100, 0.112600, 1.041900],
    [0.095640, 0.139020, 0.812950],
    [0.058010, 0.169300, 0.616200],
    [0.032010, 0.208020, 0.465180],
    [0.014700, 0.258600, 0.353300],
    [0.004900, 0.323000, 0.272000],
    [0.002400, 0.407300, 0.212300],
    [0.009300, 0.503000, 0.158200],
    [0.029100, 0.608200, 0.111700],
    [0.063270, 0.710000, 0.078250],
    [0.109600, 0.793200, 0.057250],
    [0.165500, 0.862000, 0.042160],
    [0.225750, 0.914850, 0.029840],
    [0.290400, 0.954000, 0.020300],
    [0.359700, 0.980300, 0.013400],
    [0.433450, 0.994950, 0.008750],
    [0.512050, 1.000000, 0.005750],
    [0.594500, 0.995000, 0.003900],
    [0.678400, 0.978600, 0.002750],
    [0.762100, 0.952000, 0.002100],
    [0.842500, 0.915400, 0.001800],
    [0.916300, 0.870000, 0.001650],
    [0.978600, 0.816300, 0.001400],
    [1.026300, 0.757000, 0.001100],
    [1.056700, 0.694900, 0.001000],
    [1.062200, 0.631000, 0.000800],
    [1.045600, 0.566800, 0.000600],
    [1.002600, 0.503000, 0.000340],
    [0.938400, 0.441200, 0.000240],
    [0.854450, 0.381000, 0.000190],
    [0.751400, 0.321000, 0.000100],
    [0.642400, 0.265000, 0.000050],
    [0.541900, 0.217000, 0.000030],
    [0.447900, 0.175000, 0.000020],
    [0.360800, 0.138200, 0.000010],
    [0.283500, 0.107000, 0.000000],
    [0.218700, 0.081600, 0.000000],
    [0.164900, 0.061000, 0.000000],
    [0.121200, 0.044580, 0.000000],
    [0.087400, 0.032000, 0.000000],
    [0.063600, 0.023200, 0.000000],
    [0.046770, 0.017000, 0.000000],
    [0.032900, 0.011920, 0.000000],
    [0.022700, 0.008210, 0.000000],
    [0.015840, 0.005723, 0.000000],
    [0.011359, 0.004102, 0.000000],
    [0.008111, 0.002929, 0.000000],
    [0.005790, 0.002091, 0.000000],
    [0.004109, 0.001484, 0.000000],
    [0.002899, 0.001047, 0.000000],
    [0.002049, 0.000740, 0.000000],
    [0.001440, 0.000520, 0.000000],
    [0.001000, 0.000361, 0.000000],
    [0.000690, 0.000249, 0.000000],
    [0.000476, 0.000172, 0.000000],
    [0.000332, 0.000120, 0.000000],
    [0.000235, 0.000085, 0.000000],
    [0.000166, 0.000060, 0.000000],
    [0.000117, 0.000042, 0.000000],
    [0.000083, 0.000030, 0.000000],
    [0.000059, 0.000021, 0.000000],
    [0.000042, 0.000015, 0.000000],
];

/// CIE XYZ of a black body at `kelvin`, scaled to Y = 1 (Planck's law summed against the 5 nm
/// observer table, as CIE 15 computes tristimulus values).
pub fn planck_xyz(kelvin: f64) -> [f64; 3] {
    // Planck's law up to a constant: lambda^-5 / (exp(c2 / (lambda T)) - 1), c2 = hc/k.
    const C2_M_K: f64 = 1.438_776_877e-2;
    let mut xyz = [0.0; 3];
    for (i, cmf) in CIE_1931_5NM.iter().enumerate() {
        let lambda_m = (380.0 + 5.0 * i as f64) * 1e-9;
        let b = lambda_m.powi(-5) / (C2_M_K / (lambda_m * kelvin)).exp_m1();
        for c in 0..3 {
            xyz[c] += b * cmf[c];
        }
    }
    let y = xyz[1];
    xyz.map(|v| v / y)
}

/// Linear sRGB of CIE XYZ (D65 white).
pub fn xyz_to_linear_srgb(xyz: [f64; 3]) -> [f64; 3] {
    let [x, y, z] = xyz;
    [
        3.240_454_2 * x - 1.537_138_5 * y - 0.498_531_4 * z,
        -0.969_266_0 * x + 1.876_010_8 * y + 0.041_556_0 * z,
        0.055_643_4 * x - 0.204_025_9 * y + 1.057_225_2 * z,
    ]
}

/// Linear sRGB of chromaticity `(x, y)` at luminance 1.
pub fn xy_to_linear_srgb(x: f64, y: f64) -> [f64; 3] {
    xyz_to_linear_srgb([x / y, 1.0, (1.0 - x - y) / y])
}

/// The linear sRGB colour of a black body at `kelvin`, luminance 1. Below about 1900 K the
/// locus leaves the sRGB gamut (blue < 0): the nearest colour inside it, luminance kept. None
/// outside [`KELVIN_RANGE`].
pub fn kelvin_rgb(kelvin: f64) -> Option<[f64; 3]> {
    if !KELVIN_RANGE.contains(&kelvin) {
        return None;
    }
    let rgb = xyz_to_linear_srgb(planck_xyz(kelvin)).map(|c| c.max(0.0));
    let y = luminance(rgb);
    Some(rgb.map(|c| c / y))
}

#[cfg(test)]
mod tests {
    use super::*;

    /// The Planckian locus (CIE 1931 2-degree observer) as published: Wyszecki and Stiles,
    /// Color Science (1982), and M. Charity's blackbody colour table (vendian.org, 2001), which
    /// agree to the 4th decimal; 2856 K is CIE standard illuminant A (CIE 15:2004: x 0.44757,
    /// y 0.40745).
    const LOCUS: [(f64, f64, f64); 10] = [
        (1000.0, 0.6528, 0.3444),
        (1500.0, 0.5857, 0.3931),
        (2000.0, 0.5267, 0.4133),
        (2856.0, 0.44757, 0.40745),
        (3000.0, 0.4369, 0.4041),
        (4000.0, 0.3805, 0.3768),
        (5000.0, 0.3451, 0.3516),
        (6500.0, 0.3135, 0.3236),
        (8000.0, 0.2952, 0.3048),
        (10000.0, 0.2807, 0.2884),
    ];

    #[test]
    fn colour_temperatures_match_the_published_locus_within_a_percent() {
        for (t, x, y) in LOCUS {
            let xyz = planck_xyz(t);
            let s = xyz[0] + xyz[1] + xyz[2];
            let (gx, gy) = (xyz[0] / s, xyz[1] / s);
            assert!(
                (gx - x).abs() < 2e-4 && (gy - y).abs() < 2e-4,
                "{t} K: xy {gx:.4} {gy:.4}, table {x} {y}"
            );
            if t < 2000.0 {
                continue; // outside sRGB: clamped, compared by chromaticity only
            }
            // Linear sRGB, luminance 1, against the table's chromaticity through the same matrix.
            let got = kelvin_rgb(t).unwrap();
            let want = xy_to_linear_srgb(x, y);
            let peak = want.iter().cloned().fold(0.0, f64::max);
            for c in 0..3 {
                let err = (got[c] - want[c]).abs() / peak;
                assert!(
                    err < 0.01,
                    "{t} K channel {c}: {:.4} against {:.4} ({err:.4} of the peak)",
                    got[c],
                    want[c]
                );
            }
        }
        // Warm is red-heavy, cold blue-heavy, 6500 K close to white (D65 lies just off the locus).
        let warm = kelvin_rgb(2700.0).unwrap();
        assert!(warm[0] > warm[1] && warm[1] > warm[2]);
        let cold = kelvin_rgb(12000.0).unwrap();
        assert!(cold[2] > cold[0]);
        let d65ish = kelvin_rgb(6500.0).unwrap();
        assert!(d65ish.iter().all(|c| (c - 1.0).abs() < 0.06), "{d65ish:?}");
        assert_eq!(kelvin_rgb(500.0), None);
        assert_eq!(kelvin_rgb(f64::NAN), None);
    }

    #[test]
    fn lumens_and_watts_are_the_same_light() {
        let white = [1.0, 1.0, 1.0];
        assert!((luminance(white) - 1.0).abs() < 1e-12);
        assert!((watts_of_lumens(683.0, white).unwrap() - 1.0).abs() < 1e-12);
        // A colour of half the luminance needs twice the watts for the same lumens.
        let dim = [0.5, 0.5, 0.5];
        assert!((watts_of_lumens(683.0, dim).unwrap() - 2.0).abs() < 1e-12);
        assert_eq!(watts_of_lumens(100.0, [0.0; 3]), None);
        assert!((lux_of_irradiance([1.0; 3]) - 683.0).abs() < 1e-9);
    }
}
