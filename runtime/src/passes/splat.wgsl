// Surfel splatting, shared by the shadow and gbuffer passes: each surfel is an oriented disc (a
// quad in its tangent plane, fragments outside the unit circle discarded), so depth is the disc's
// true depth. A disc smaller than `viewport.z` pixels is grown to it so sparse samples leave no
// holes. `Splat` mirrors SplatUniform in runtime/src/gpu/types.rs (runtime/tests/layout.rs).
//
// Blended splatting (passes/gbuffer.rs) draws the discs twice: `fs_gbuffer` as they are, which
// leaves the front-most disc in the targets and its depth in the depth buffer; then `fs_blend`,
// each disc pulled toward the eye by `-splat.z` disc radii (more at grazing angles), adds every
// fragment within that tolerance behind the front, of a surface facing as the front disc does,
// with a smooth radial weight into float targets, normalised by shade. The point shaded stays the
// front disc's (a blended distance pulls it behind the surface where the tolerance reaches far:
// sparse clouds, silhouettes), so only normal and albedo are blended.
#import geometry
#import packing
#import color

struct Splat {
    view_proj: mat4x4<f32>,
    eye_m: vec4<f32>,
    // x, y: viewport size in pixels; z: smallest radius in pixels; w: proj[1][1].
    viewport: vec4<f32>,
    // x: surfel radius scale; y: 1 to colour by scan; z: depth offset in disc radii, negative
    // toward the eye (blended splatting's accumulation pass; 0 elsewhere).
    splat: vec4<f32>,
    // The clip box, frame metres; w: 1 where it clips.
    clip_min_m: vec4<f32>,
    clip_max_m: vec4<f32>,
    pad: array<vec4<f32>, 7>,
}

@group(0) @binding(0) var<uniform> splat: Splat;

struct VsOut {
    @builtin(position) clip: vec4<f32>,
    @location(0) disc: vec2<f32>,
    @location(1) world: vec3<f32>,
    @location(2) normal_spread: vec4<f32>,
    @location(3) color: vec4<f32>,
}


// The surfel pool as words, for the pulled path (SurfelGpu: 10 words; a WGSL struct of vec4s
// would be 48 bytes apart, not 40).
@group(1) @binding(0) var<storage, read> surfel_words: array<u32>;

// Instanced: one instance a surfel, its six vertices the quad's corners.
@vertex
fn vs(
    @builtin(vertex_index) vi: u32,
    @location(0) position_radius: vec4<f32>,
    @location(1) normal_spread: vec4<f32>,
    @location(2) color: vec4<f32>,
    @location(3) scan: u32,
) -> VsOut {
    return splat_corner(vi, position_radius, normal_spread, color, scan, 1.0);
}

// Pulled: six vertices a surfel in one draw, the surfel read from the pool. The instance index
// is the draw's stride (passes/splat.rs `SplatRun`): every stride-th surfel, grown by its root.
@vertex
fn vs_pulled(@builtin(vertex_index) vi: u32, @builtin(instance_index) stride: u32) -> VsOut {
    let k = max(stride, 1u);
    let b = (vi / 6u) * k * 10u;
    let w = &surfel_words;
    let position_radius = bitcast<vec4<f32>>(vec4<u32>((*w)[b], (*w)[b + 1u], (*w)[b + 2u], (*w)[b + 3u]));
    let normal_spread = bitcast<vec4<f32>>(vec4<u32>((*w)[b + 4u], (*w)[b + 5u], (*w)[b + 6u], (*w)[b + 7u]));
    return splat_corner(vi % 6u, position_radius, normal_spread, unpack4x8unorm((*w)[b + 8u]), (*w)[b + 9u], sqrt(f32(k)));
}

// Corner `vi` (0..6) of a surfel's disc, its radius times `grow`.
fn splat_corner(vi: u32, position_radius: vec4<f32>, normal_spread: vec4<f32>, color: vec4<f32>, scan: u32, grow: f32) -> VsOut {
    var out: VsOut;
    let p = position_radius.xyz;
    if splat.clip_min_m.w > 0.0 && (any(p < splat.clip_min_m.xyz) || any(p > splat.clip_max_m.xyz)) {
        // Cut away: every corner at one point outside the clip volume draws nothing.
        out.clip = vec4<f32>(2.0, 2.0, 2.0, 1.0);
        return out;
    }
    var corners = array<vec2<f32>, 6>(
        vec2<f32>(-1.0, -1.0), vec2<f32>(1.0, -1.0), vec2<f32>(1.0, 1.0),
        vec2<f32>(-1.0, -1.0), vec2<f32>(1.0, 1.0), vec2<f32>(-1.0, 1.0),
    );
    let c = corners[vi];
    let n = normalize(normal_spread.xyz);
    let frame = basis(n);
    let t1 = frame[0];
    let t2 = frame[1];
    let center_clip = splat.view_proj * vec4<f32>(position_radius.xyz, 1.0);
    var r = position_radius.w * splat.splat.x * grow;
    if center_clip.w > 0.0 {
        let px = r * splat.viewport.w * splat.viewport.y * 0.5 / center_clip.w;
        if px < splat.viewport.z {
            r *= splat.viewport.z / max(px, 1e-6);
        }
    }
    let world = position_radius.xyz + (t1 * c.x + t2 * c.y) * r;
    var moved = world;
    if splat.splat.z != 0.0 {
        // Blended splatting's accumulation pass: the disc pulled toward the eye by its depth
        // tolerance, so it passes the depth pass's test (the true front-most disc) wherever it
        // lies within that tolerance behind the front. The whole disc is scaled about the eye
        // (one factor for its corners), so it covers exactly the same pixels with the same
        // interpolation (moving each corner by the same length would not). A disc seen at a
        // grazing angle spans more depth across a pixel's neighbours: the tolerance grows with
        // 1 / |cos| (up to 4x) so its neighbours on the same surface still fall inside. At most
        // three quarters of the way to the eye (the near plane).
        let to = p - splat.eye_m.xyz;
        let dist = max(length(to), 1e-6);
        let facing = max(abs(dot(to / dist, n)), 0.25);
        let scale = max(1.0 + splat.splat.z * r / facing / dist, 0.25);
        moved = splat.eye_m.xyz + (world - splat.eye_m.xyz) * scale;
    }
    out.clip = splat.view_proj * vec4<f32>(moved, 1.0);
    out.disc = c;
    out.world = world;
    out.normal_spread = vec4<f32>(n, normal_spread.w);
    // Alpha carries the material slot (0 diffuse, k / 255 for SceneData::materials[k - 1]).
    out.color = vec4<f32>(srgb_to_linear(color.rgb), color.a);
    if splat.splat.y > 0.5 {
        out.color = vec4<f32>(scan_color(scan), color.a);
    }
    return out;
}


@fragment
fn fs_shadow(in: VsOut) -> @location(0) vec4<f32> {
    if dot(in.disc, in.disc) > 1.0 {
        discard;
    }
    return pack_f32(distance(in.world, splat.eye_m.xyz));
}

struct GbufferOut {
    // Distance from the eye (0 = nothing), packed f32.
    @location(0) distance: vec4<f32>,
    // Octahedral unit normal, packed.
    @location(1) normal: vec4<f32>,
    @location(2) albedo: vec4<f32>,
}

@fragment
fn fs_gbuffer(in: VsOut) -> GbufferOut {
    if dot(in.disc, in.disc) > 1.0 {
        discard;
    }
    var n = in.normal_spread.xyz;
    // Shade both sides: a disc seen from behind shows its back face.
    if dot(n, splat.eye_m.xyz - in.world) < 0.0 {
        n = -n;
    }
    var out: GbufferOut;
    out.distance = pack_f32(distance(in.world, splat.eye_m.xyz));
    out.normal = pack_normal(n);
    out.albedo = in.color;
    return out;
}

// The depth pass's front disc normal (eye-facing, packed), read by `fs_blend`.
@group(2) @binding(0) var front_normal: texture_2d<f32>;

struct BlendOut {
    // Sum of w * normal (facing the eye), and of w.
    @location(0) normal_weight: vec4<f32>,
    // Sum of w * linear albedo (alpha unused).
    @location(1) albedo: vec4<f32>,
}

@fragment
fn fs_blend(in: VsOut) -> BlendOut {
    let r2 = dot(in.disc, in.disc);
    if r2 > 1.0 {
        discard;
    }
    // Smooth to zero at the rim, so a disc's edge never shows as a step; never exactly zero, so
    // a pixel only rims cover still has a surface.
    let k = 1.0 - r2;
    var w = max(k * k, 1e-3);
    var n = in.normal_spread.xyz;
    if dot(n, splat.eye_m.xyz - in.world) < 0.0 {
        n = -n;
    }
    // Only discs of the front disc's surface: within the depth tolerance lie also the discs of a
    // crease's other face (floor meeting wall) and, near a convex outline, of the far side (a
    // pillar's edge, whose normals turned to the eye cancel the front's: the glancing-wall truth
    // camera had 175 black rim pixels). Full weight within about 25 degrees of the front disc's
    // normal (scan noise), none beyond 60.
    let front = unpack_normal(textureLoad(front_normal, vec2<i32>(in.clip.xy), 0));
    let agree = clamp((dot(n, front) - 0.5) / 0.4, 0.0, 1.0);
    w *= agree * agree;
    var out: BlendOut;
    out.normal_weight = vec4<f32>(n * w, w);
    out.albedo = vec4<f32>(in.color.rgb * w, 0.0);
    return out;
}
