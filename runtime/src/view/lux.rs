//! The lux view's false colours (`--view lux`): illuminance on the surfaces, what a lighting
//! designer reads for glare and darkness, on a logarithmic scale from 1 to 10,000 lux. One table
//! for the shader (generated into its constants, shaders/mod.rs), the legends of images and the
//! window, and the page.
//!
//! Illuminance is the light arriving at a surface, whatever its colour: direct, indirect and
//! environment light, read photometrically (grotto_format::photometry: 683 lm/W at luminance 1).
//! Emission (a glowing area light's own surface) and specular reflection are light leaving a
//! surface, not arriving, so the view leaves them out.

/// The scale's stops: log10(lux) and the sRGB colour there; between stops the colours blend in
/// sRGB, below the first it fades to black at 0.1 lux, above the last it is the glare colour.
pub const LUX_STOPS: [(f32, [f32; 3]); 5] = [
    (0.0, [0.10, 0.10, 0.55]), // 1 lx: a dark path
    (1.0, [0.00, 0.62, 0.85]), // 10 lx: visitor paths in show caves
    (2.0, [0.15, 0.80, 0.20]), // 100 lx: a lit formation
    (3.0, [1.00, 0.85, 0.00]), // 1,000 lx: bright
    (4.0, [0.90, 0.10, 0.05]), // 10,000 lx: glare
];

/// Above the last stop.
pub const GLARE: [f32; 3] = [1.0, 0.0, 1.0];

/// The false colour of `lux` (sRGB 0..1), as shade.wgsl's `lux_color`.
pub fn lux_color(lux: f32) -> [f32; 3] {
    let l = lux.max(1e-6).log10();
    let (first, last) = (LUX_STOPS[0], LUX_STOPS[LUX_STOPS.len() - 1]);
    if l < first.0 {
        let t = (l + 1.0).clamp(0.0, 1.0);
        return first.1.map(|c| c * t);
    }
    if l > last.0 + 0.15 {
        return GLARE;
    }
    if l >= last.0 {
        return last.1;
    }
    let i = LUX_STOPS.iter().rposition(|s| s.0 <= l).unwrap_or(0);
    let (a, b) = (LUX_STOPS[i], LUX_STOPS[i + 1]);
    let t = (l - a.0) / (b.0 - a.0);
    [0, 1, 2].map(|c| a.1[c] + (b.1[c] - a.1[c]) * t)
}

/// WGSL for the table and `lux_color` (the same as [`lux_color`]).
pub(crate) fn wgsl() -> String {
    let stops: Vec<String> = LUX_STOPS
        .iter()
        .map(|(l, c)| format!("vec4<f32>({l:?}, {:?}, {:?}, {:?})", c[0], c[1], c[2]))
        .collect();
    format!(
        "const LUX_STOPS = array<vec4<f32>, {n}>({stops});\n\
         const LUX_GLARE = vec3<f32>({:?}, {:?}, {:?});\n\
         fn lux_color(lux: f32) -> vec3<f32> {{\n\
         \x20   let l = log10_lux(max(lux, 1e-6));\n\
         \x20   if l < LUX_STOPS[0].x {{ return LUX_STOPS[0].yzw * clamp(l + 1.0, 0.0, 1.0); }}\n\
         \x20   if l > LUX_STOPS[{last}].x + 0.15 {{ return LUX_GLARE; }}\n\
         \x20   if l >= LUX_STOPS[{last}].x {{ return LUX_STOPS[{last}].yzw; }}\n\
         \x20   var i = 0u;\n\
         \x20   for (var k = 0u; k < {last}u; k++) {{ if LUX_STOPS[k].x <= l {{ i = k; }} }}\n\
         \x20   let a = LUX_STOPS[i];\n\
         \x20   let b = LUX_STOPS[i + 1u];\n\
         \x20   return mix(a.yzw, b.yzw, (l - a.x) / (b.x - a.x));\n\
         }}\n\
         fn log10_lux(x: f32) -> f32 {{ return log2(x) * 0.30103; }}\n",
        GLARE[0],
        GLARE[1],
        GLARE[2],
        n = LUX_STOPS.len(),
        stops = stops.join(", "),
        last = LUX_STOPS.len() - 1,
    )
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn the_scale_runs_dark_to_glare_and_meets_its_stops() {
        assert_eq!(lux_color(1.0), LUX_STOPS[0].1);
        assert_eq!(lux_color(100.0), LUX_STOPS[2].1);
        assert_eq!(lux_color(0.0), [0.0; 3], "no light is black");
        assert_eq!(lux_color(1e6), GLARE);
        let mid = lux_color(10f32.powf(1.5));
        assert!((mid[1] - 0.5 * (LUX_STOPS[1].1[1] + LUX_STOPS[2].1[1])).abs() < 1e-5);
        assert!(wgsl().contains("const LUX_STOPS = array<vec4<f32>, 5>"));
    }
}
