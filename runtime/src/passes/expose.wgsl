// Exposure after the fact (passes/expose.rs): the frame's sRGB8 pixels tonemapped again from its
// HDR radiance at a new exposure, exactly as the shade pass writes them (`tonemap(hdr *
// exposure)`), without shading the frame again.
#import color

struct Expose {
    width: u32,
    height: u32,
    exposure: f32,
    pad: u32,
}

@group(0) @binding(0) var<uniform> expose: Expose;
// The shade pass's frame: HDR and coverage as 4 f32 a pixel, then sRGB8 as one u32 a pixel.
@group(0) @binding(1) var<storage, read_write> frame: array<u32>;

@compute @workgroup_size(8, 8)
fn expose_frame(@builtin(global_invocation_id) gid: vec3<u32>) {
    if gid.x >= expose.width || gid.y >= expose.height {
        return;
    }
    let idx = gid.y * expose.width + gid.x;
    let b = 4u * idx;
    let hdr = bitcast<vec3<f32>>(vec3<u32>(frame[b], frame[b + 1u], frame[b + 2u]));
    frame[4u * expose.width * expose.height + idx] = pack4x8unorm(vec4<f32>(tonemap(hdr * expose.exposure), 1.0));
}
