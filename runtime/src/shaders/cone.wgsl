// Cone tracing through the radiance pyramid (Crassin et al. 2011): gather cones and shadow cones.
#import svo
#import rock
#import ndf

// Settings::cone_planes, as a pipeline constant (passes/mod.rs `PassConstants`): the march sees
// the finest levels' leaves as half-spaces behind their surfaces (svo.wgsl `leaf_plane_share`).
// Where it is off the plane code is compiled out of the march.
override cone_planes: bool = false;

// A sample's premultiplied radiance and opacity for one march step: the mip values are for
// crossing one voxel, the step is `ratio` voxel edges long, so opacity (and premultiplied
// radiance with it) is corrected to that length.
fn per_step(s: vec4<f32>, ratio: f32) -> vec4<f32> {
    if s.a <= 1e-6 {
        return s;
    }
    let a = 1.0 - pow(max(1.0 - min(s.a, 1.0), 0.0), ratio);
    return vec4<f32>(s.rgb * (a / s.a), a);
}

// A trilinear sample of a voxel of edge e spreads e / 2 (standard deviation per axis), as a disc
// of radius e does: a cone of diameter d is sampled at e = SAMPLE_EDGE * d (docs/runtime.md,
// "What a sample covers").
const SAMPLE_EDGE: f32 = 0.5;
// Near the surface a cone starts from, its footprint is at most PLANE_CLEAR times its height
// above that surface (less half a leaf), so that the trilinear support (1.5 e below the sample)
// never reaches the surface itself: grazing cones would see their own wall.
const PLANE_CLEAR: f32 = 0.6666667;

// Front-to-back composited cone from `origin_m` along unit `dir`, its origin `rise.x` metres above
// its own surface and rising `rise.y` metres per metre along `dir`: premultiplied radiance and
// opacity. A cone that becomes opaque (>= 0.995) is renormalised by its opacity, i.e. what is
// hidden behind the last surfaces is assumed to look like them; one whose axis enters rock, or
// that leaves the scene nearly opaque, is filled with the colour of the last matter it sampled
// (enter_rock, close_cone); one that leaves the scene open keeps its transparency (the
// environment's share, added by the caller).
fn trace_cone(origin_m: vec3<f32>, dir: vec3<f32>, tan_half: f32, rise: vec2<f32>) -> vec4<f32> {
    let leaf = params.leaf_size_m;
    var acc = vec4<f32>(0.0);
    // The colour of the last matter sampled: what the cone was crossing when it stopped.
    var last = vec3<f32>(0.0);
    var t = leaf;
    var t_prev = 0.0;
    for (var i = 0u; i < params.max_steps; i++) {
        if t > params.max_distance_m {
            break;
        }
        // Rock anywhere since the last sample: coarse steps are many rock cells long and would
        // jump over the rock right behind a thin wall.
        let t_rock = rock_on_segment(origin_m, dir, t_prev, t);
        if t_rock >= 0.0 {
            // The sample that stands for what lies behind: one level coarser than the footprint
            // and at least 4 leaves wide, so that it still sees the wall in front of this rock
            // when the step jumped it.
            let q = (origin_m + dir * t_rock) / leaf;
            let d = max(leaf, 2.0 * t_rock * tan_half);
            return enter_rock(acc, sample_lod(q, max(log2(d / leaf) + 1.0, f32(ROCK_LEVEL + 1u)), dir), last);
        }
        let p_leaf = (origin_m + dir * t) / leaf;
        if outside_scene(p_leaf) || cone_left_matter(p_leaf, max(0.5 * leaf, t * tan_half) / leaf) {
            break;
        }
        let clear = PLANE_CLEAR * (rise.x + t * rise.y - 0.5 * leaf);
        let diameter = max(leaf, min(2.0 * t * tan_half, clear));
        let edge = max(leaf, SAMPLE_EDGE * diameter);
        let lod = log2(edge / leaf);
        let raw = sample_lod_planes(p_leaf, lod, dir, cone_planes);
        if raw.a > 1e-6 {
            last = raw.rgb / raw.a;
        }
        acc += (1.0 - acc.a) * per_step(raw, diameter * params.step_scale / edge);
        if acc.a >= 0.995 {
            return vec4<f32>(acc.rgb / acc.a, 1.0);
        }
        t_prev = t;
        t += diameter * params.step_scale;
    }
    return close_cone(acc, last);
}

// A cone that leaves the scene nearly opaque has crossed solid matter whose coarse, blurred
// opacity never quite saturates (trilinear weights toward the empty space outside): from opacity
// CLOSE_LO to CLOSE_HI its missing share is filled with `last`, the matter it was crossing. Far below the thresholds of
// a closure that had to stand in for rock (0.2 to 0.6 before rock.rs): openings keep their sky.
const CLOSE_LO: f32 = 0.8;
const CLOSE_HI: f32 = 0.95;

fn close_cone(acc: vec4<f32>, last: vec3<f32>) -> vec4<f32> {
    if acc.a <= 1e-6 {
        return acc;
    }
    let s = smoothstep(CLOSE_LO, CLOSE_HI, acc.a);
    return vec4<f32>(acc.rgb + s * (1.0 - acc.a) * last, mix(acc.a, 1.0, s));
}

// A cone whose axis entered rock: scans are shells, so at a coarse level a wall is partly
// transparent and the cone would go on through the empty rock behind it (a leak). It ends opaque;
// what is hidden looks like `last`, the wall it was crossing (or, having met nothing, like the
// rock cell's own filtered radiance `s`). Mirrored by cpu_ref::enter_rock.
fn enter_rock(acc: vec4<f32>, s: vec4<f32>, last: vec3<f32>) -> vec4<f32> {
    var behind = last;
    if acc.a <= 1e-6 && s.a > 1e-6 {
        behind = s.rgb / s.a;
    }
    return vec4<f32>(acc.rgb + (1.0 - acc.a) * behind, 1.0);
}

// Shadow cone toward a light (Crassin et al. 2011): the share of a narrow cone from `origin_m`
// along unit `l` that reaches distance `dist_m` through the voxels' filtered opacity; 0 where the
// axis enters rock. Its footprint widens with SHADOW_CONE_TAN_HALF away from both ends (a spindle,
// at least one leaf wide): a point light is seen along a ray, so the cone must narrow again at the
// lamp, or lamps hung just above a floor would sit inside a coarse voxel holding that floor and
// shadow themselves.
const SHADOW_CONE_TAN_HALF: f32 = 0.1;

fn cone_visibility(origin_m: vec3<f32>, l: vec3<f32>, dist_m: f32) -> f32 {
    let leaf = params.leaf_size_m;
    var a = 0.0;
    var t = leaf;
    var t_prev = 0.0;
    let t_end = dist_m - leaf;
    for (var i = 0u; i < params.max_steps; i++) {
        if t >= t_end {
            break;
        }
        if rock_on_segment(origin_m, l, t_prev, t) >= 0.0 {
            return 0.0;
        }
        let diameter = max(leaf, 2.0 * min(t, dist_m - t) * SHADOW_CONE_TAN_HALF);
        let s = sample_lod((origin_m + l * t) / leaf, log2(diameter / leaf), l);
        a += (1.0 - a) * per_step(s, params.step_scale).a;
        if a >= 0.995 {
            return 0.0;
        }
        t_prev = t;
        t += diameter * params.step_scale;
    }
    return 1.0 - a;
}
