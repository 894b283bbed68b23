// Colour: the sRGB transfer function (IEC 61966-2-1, as grotto_format::color) and the tone map.

fn srgb_to_linear(c: vec3<f32>) -> vec3<f32> {
    let lo = c / 12.92;
    let hi = pow((c + vec3<f32>(0.055)) / 1.055, vec3<f32>(2.4));
    return select(hi, lo, c <= vec3<f32>(0.04045));
}

fn linear_to_srgb(c: vec3<f32>) -> vec3<f32> {
    let lo = c * 12.92;
    let hi = 1.055 * pow(c, vec3<f32>(1.0 / 2.4)) - 0.055;
    return select(hi, lo, c <= vec3<f32>(0.0031308));
}

// ACES filmic curve (Narkowicz 2015 fit), then the sRGB transfer function.
fn tonemap(hdr: vec3<f32>) -> vec3<f32> {
    let x = max(hdr, vec3<f32>(0.0));
    let mapped = clamp((x * (2.51 * x + 0.03)) / (x * (2.43 * x + 0.59) + 0.14), vec3<f32>(0.0), vec3<f32>(1.0));
    return linear_to_srgb(mapped);
}

// The scan view's colour of scan `index` (settings.rs `scan_color`, the same formula): hues a
// golden angle apart; grey for NO_SCAN, a splat that stands for several scans.
fn scan_color(index: u32) -> vec3<f32> {
    if index == NO_SCAN {
        return vec3<f32>(0.5);
    }
    let h = fract(f32(index) * 0.618034) * 6.0;
    let s = 0.7;
    let v = 0.95;
    let k = (vec3<f32>(5.0, 3.0, 1.0) + h) % 6.0;
    return v - v * s * clamp(min(k, 4.0 - k), vec3<f32>(0.0), vec3<f32>(1.0));
}
