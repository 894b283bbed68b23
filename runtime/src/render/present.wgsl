// Presents the renderer's tonemapped frame (packed RGBA8, rows top to bottom) in a window or canvas,
// scaled to the window by nearest sampling, with the light's convergence as a bar along the
// bottom (grey: waiting for the camera to rest, amber: converging, green: converged). Where the
// surface is sRGB, the already encoded values are decoded first so the surface's encoding gives
// them back.
#import color

struct Blit {
    src: vec2<u32>,
    dst: vec2<u32>,
    srgb_target: u32,
    progress: f32,
    bar_state: u32,
    // Word of the first pixel in `ldr` (the renderer's frame buffer: HDR first, passes/shade.rs).
    first_word: u32,
}

@group(0) @binding(0) var<storage, read> ldr: array<u32>;
@group(0) @binding(1) var<uniform> blit: Blit;

const BAR_PX: f32 = 3.0;

@vertex
fn vs(@builtin(vertex_index) i: u32) -> @builtin(position) vec4<f32> {
    let uv = vec2<f32>(f32((i << 1u) & 2u), f32(i & 2u));
    return vec4<f32>(uv * 2.0 - 1.0, 0.0, 1.0);
}

@fragment
fn fs(@builtin(position) p: vec4<f32>) -> @location(0) vec4<f32> {
    let x = min(u32(p.x * f32(blit.src.x) / f32(blit.dst.x)), blit.src.x - 1u);
    let y = min(u32(p.y * f32(blit.src.y) / f32(blit.dst.y)), blit.src.y - 1u);
    var c = unpack4x8unorm(ldr[blit.first_word + y * blit.src.x + x]).rgb;
    if p.y > f32(blit.dst.y) - BAR_PX && p.x < blit.progress * f32(blit.dst.x) {
        let colours = array<vec3<f32>, 3>(vec3<f32>(0.5), vec3<f32>(0.9, 0.6, 0.1), vec3<f32>(0.2, 0.8, 0.3));
        c = colours[min(blit.bar_state, 2u)];
    }
    if blit.srgb_target != 0u {
        c = srgb_to_linear(c);
    }
    return vec4<f32>(c, 1.0);
}
