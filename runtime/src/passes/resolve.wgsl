// Anti-aliasing at rest (passes/resolve.rs): the frames of a still camera, each jittered within its
// pixels, averaged. Sample 0 (the pixel centres) starts the sums; every later sample adds to them
// and writes the mean back into the frame, so what a viewer presents or reads back is the
// anti-aliased image so far. Radiance and coverage average linearly; the tonemapped colour
// averages in linear light after the tonemap, as `grotto render --supersample`'s resolve does
// (render/frame.rs, Frame::downsampled), so a bright lamp's edge does not dominate its pixel.
#import color

struct Resolve {
    width: u32,
    height: u32,
    // 0 starts the sums; k adds the (k+1)-th sample.
    sample: u32,
    pad: u32,
}

@group(0) @binding(0) var<uniform> resolve: Resolve;
// The shade pass's frame: HDR and coverage as 4 f32 a pixel, then sRGB8 as one u32 a pixel.
@group(0) @binding(1) var<storage, read_write> frame: array<u32>;
// Per pixel: the HDR sum (rgb, coverage), then the linear tonemapped sum (rgb, unused).
@group(0) @binding(2) var<storage, read_write> sums: array<vec4<f32>>;

@compute @workgroup_size(8, 8)
fn resolve_samples(@builtin(global_invocation_id) gid: vec3<u32>) {
    if gid.x >= resolve.width || gid.y >= resolve.height {
        return;
    }
    let idx = gid.y * resolve.width + gid.x;
    let b = 4u * idx;
    let hdr = bitcast<vec4<f32>>(vec4<u32>(frame[b], frame[b + 1u], frame[b + 2u], frame[b + 3u]));
    let ldr_word = 4u * resolve.width * resolve.height + idx;
    let ldr = srgb_to_linear(unpack4x8unorm(frame[ldr_word]).rgb);
    if resolve.sample == 0u {
        sums[2u * idx] = hdr;
        sums[2u * idx + 1u] = vec4<f32>(ldr, 0.0);
        return;
    }
    let sum_hdr = sums[2u * idx] + hdr;
    let sum_ldr = sums[2u * idx + 1u].rgb + ldr;
    sums[2u * idx] = sum_hdr;
    sums[2u * idx + 1u] = vec4<f32>(sum_ldr, 0.0);
    let n = f32(resolve.sample + 1u);
    let mean = bitcast<vec4<u32>>(sum_hdr / n);
    frame[b] = mean.x;
    frame[b + 1u] = mean.y;
    frame[b + 2u] = mean.z;
    frame[b + 3u] = mean.w;
    frame[ldr_word] = pack4x8unorm(vec4<f32>(linear_to_srgb(clamp(sum_ldr / n, vec3<f32>(0.0), vec3<f32>(1.0))), 1.0));
}
