// A gather cone followed as rays (Settings::cone_rays): the composited march (cone.wgsl)
// counts a surface a cone runs along at every step, and a cone whose axis enters rock takes the
// colour it last sampled for all it had not seen, which gave closed rooms near a lamp 5-15% too
// much of each bounce (docs/reference.md, "Where a wall's cones read too much"). Here the cone's
// footprint is split into RAY_COUNT equal shares (gpu/types.rs `cone_rays::PATTERN`); each ray
// walks the leaf cells it crosses (Amanatides & Woo) and ends where it enters rock or goes behind
// a leaf's surface, bringing the radiance pyramid's colour there read over its share of the
// footprint. The cone is covered by the share of its rays that ended: a surface is counted once,
// where the rays met it. Mirrored by cpu_ref::trace_cone_rays.
#import svo
#import rock

// Settings::cone_rays, as a pipeline constant (passes/mod.rs `PassConstants`): where it is off
// the ray code is compiled out of propagate.
override cone_rays: bool = false;

// Whether `p_m` (metres) lies behind leaf `leaf_index`'s surface: the plane through its surfels'
// centroid across their mean normal, moved RAY_PLANE_OFFSET_LEAVES of its edge out. A leaf whose
// normals disagree (mean shorter than 0.3: a thin sheet seen from both sides) is solid.
fn ray_behind_leaf(leaf_index: u32, p_m: vec3<f32>) -> bool {
    let leaf = leaves[leaf_index];
    let m = leaf.normal_mean.xyz;
    let r = length(m);
    let edge = max(params.leaf_size_m, leaf.center_m.w);
    return r < 0.3 || dot(p_m - leaf.center_m.xyz, m / r) <= RAY_PLANE_OFFSET_LEAVES * edge;
}

// The pyramid's colour at `at_leaf` seen along `d`: a trilinear sample of the level whose voxels
// are as wide as the footprint `diameter_m` (the nearer level: half a voxel), one level coarser
// at a time where it is empty; w = 0 where every level is. One level, not two blended
// (sample_lod): the colour reads took about half the pass, and blending the next level moved no
// scene's error by more than 0.0006 (docs/reference.md, "Where the light goes wrong").
fn ray_colour(at_leaf: vec3<f32>, d: vec3<f32>, diameter_m: f32) -> vec4<f32> {
    let lod = clamp(log2(0.5 * diameter_m / params.leaf_size_m), 0.0, f32(params.max_lod));
    for (var l = u32(floor(lod + 0.5)); l <= params.max_lod; l++) {
        let s = sample_level(at_leaf, l, d, false);
        if s.a > 1e-6 {
            return vec4<f32>(s.rgb / s.a, 1.0);
        }
    }
    return vec4<f32>(0.0);
}

// One ray from `origin_m` along unit `d`: the distance (metres) at which it met a surface and
// what it met (x: distance, y: 1 at a leaf, 2 at rock, 0 where it left the scene). A cell's rock
// comes from its brick's 64 bits, looked up where the ray enters a new brick (8 leaves wide)
// instead of once a cell: the same answers as in_rock, which cpu_ref::ray_hit asks cell by cell.
// Leaves are not looked up once a block (svo.wgsl `leaf_in_block`): the lanes of a SIMD group enter
// new blocks at different cells, so the group pays the lookup on most steps anyway, and the pass
// was slower that way (docs/reference.md). Empty
// space is crossed a box at a time: the node the leaf lookup found missing, cut to the rock-free
// brick or cell (cpu_ref::ray_hit walks every cell; the GPU-vs-CPU test holds the two equal).
fn ray_hit(origin_m: vec3<f32>, d: vec3<f32>) -> vec2<f32> {
    let leaf = params.leaf_size_m;
    let t_start = leaf;
    let start = (origin_m + d * t_start) / leaf;
    var cell = vec3<i32>(floor(start));
    let moving = abs(d) > vec3<f32>(1e-12);
    let up = d > vec3<f32>(0.0);
    let cell_step = select(vec3<i32>(-1), vec3<i32>(1), up);
    let edge = (vec3<f32>(cell) + select(vec3<f32>(0.0), vec3<f32>(1.0), up) - start) / d;
    let inf = vec3<f32>(1e30);
    var t_next = select(inf, edge, moving);
    let t_cell = select(inf, abs(1.0 / d), moving);
    var t = t_start;
    let none = vec3<i32>(0x7fffffff);
    var brick_key = none;
    var brick = vec2<u32>(0u);
    // A segment of n leaf edges crosses at most sqrt(3) n + 3 cells.
    let most = u32(ceil(1.7320508 * params.max_distance_m / leaf)) + 4u;
    for (var i = 0u; i < most; i++) {
        let p_leaf = (origin_m + d * t) / leaf;
        if t > params.max_distance_m || outside_scene(p_leaf) || cone_left_matter(p_leaf, 0.0) {
            break;
        }
        let found = find_leaf_or_gap(cell);
        if found.leaf != EMPTY {
            let t_exit = t_start + min(t_next.x, min(t_next.y, t_next.z)) * leaf;
            if ray_behind_leaf(found.leaf, origin_m + d * t_exit) {
                return vec2<f32>(t, 1.0);
            }
        }
        let rock_cell = cell >> vec3<u32>(ROCK_LEVEL);
        let key = rock_cell >> vec3<u32>(ROCK_BRICK_SHIFT);
        if any(key != brick_key) {
            brick_key = key;
            brick = rock_brick_bits(key);
        }
        if rock_bit(brick, rock_cell, key) {
            return vec2<f32>(t, 2.0);
        }
        if found.leaf == EMPTY {
            // Empty space: the box proved free of leaves (the gap) and of rock (the brick where
            // its 64 bits are clear, else this rock cell) is crossed in one step, to the first
            // cell past it. The walk meets the cells it would have met cell by cell.
            let rock_shift = select(ROCK_LEVEL, ROCK_LEVEL + ROCK_BRICK_SHIFT, all(brick == vec2<u32>(0u)));
            let rock_lo = (cell >> vec3<u32>(rock_shift)) << vec3<u32>(rock_shift);
            let box_lo = max(found.lo, rock_lo);
            let box_hi = min(found.lo + vec3<i32>(1 << found.level), rock_lo + vec3<i32>(1 << rock_shift));
            if any(box_hi - box_lo > vec3<i32>(1)) {
                let face = select(vec3<f32>(box_lo), vec3<f32>(box_hi), up);
                let t_out = select(inf, (face - start) / d, moving);
                var out_axis = 2u;
                if t_out.x <= t_out.y && t_out.x <= t_out.z {
                    out_axis = 0u;
                } else if t_out.y <= t_out.z {
                    out_axis = 1u;
                }
                let t_box = t_out[out_axis];
                // Inside the box on the other axes (where rounding put the exit point outside,
                // the next step crosses that face at once), past it on the axis it leaves by.
                cell = clamp(vec3<i32>(floor(start + d * t_box)), box_lo, box_hi - vec3<i32>(1));
                cell[out_axis] = select(box_lo[out_axis] - 1, box_hi[out_axis], up[out_axis]);
                let far = vec3<f32>(cell) + select(vec3<f32>(0.0), vec3<f32>(1.0), up);
                t_next = select(inf, (far - start) / d, moving);
                t = t_start + t_box * leaf;
                continue;
            }
        }
        var axis = 2u;
        if t_next.x <= t_next.y && t_next.x <= t_next.z {
            axis = 0u;
        } else if t_next.y <= t_next.z {
            axis = 1u;
        }
        t = t_start + t_next[axis] * leaf;
        cell[axis] += cell_step[axis];
        t_next[axis] += t_cell[axis];
    }
    return vec2<f32>(t, 0.0);
}

// The cone from `origin_m` along unit `dir` of half-angle tangent `tan_half`, over the surface of
// unit normal `n`, as rays: premultiplied radiance and the share of its rays that met a surface.
// `origin_m` is the composited march's origin, `lift_m` above the surface; the rays start
// RAY_LIFT_LEAVES of a leaf above it instead (they stop at the first surface, so they need not
// clear their own leaf's cube).
fn trace_cone_rays(origin_m: vec3<f32>, dir: vec3<f32>, n: vec3<f32>, tan_half: f32, lift_m: f32) -> vec4<f32> {
    let leaf = params.leaf_size_m;
    let o = origin_m - n * (lift_m - RAY_LIFT_LEAVES * leaf);
    let rock_cell_m = leaf * f32(1u << ROCK_LEVEL);
    var up = vec3<f32>(0.0, 0.0, 1.0);
    if abs(dir.z) >= 0.9 {
        up = vec3<f32>(1.0, 0.0, 0.0);
    }
    let e1 = normalize(cross(dir, up));
    let e2 = cross(dir, e1);
    let share = 1.0 / f32(RAY_COUNT);
    var acc = vec4<f32>(0.0);
    // A local copy: indexing a constant array by a loop variable needs it in memory.
    var pattern = RAY_PATTERN;
    for (var k = 0u; k < RAY_COUNT; k++) {
        let u = pattern[k];
        var d = normalize(dir + tan_half * (u.x * e1 + u.y * e2));
        let rise = dot(d, n);
        if rise < RAY_MIN_RISE {
            d = normalize(d + n * (RAY_MIN_RISE - rise));
        }
        let hit = ray_hit(o, d);
        if hit.y == 0.0 {
            continue;
        }
        // At rock the surface lies in front of it, at most half a rock cell back.
        let back = select(0.0, 0.5 * rock_cell_m, hit.y == 2.0);
        let at = (o + d * max(hit.x - back, leaf)) / leaf;
        let c = ray_colour(at, d, max(2.0 * hit.x * tan_half * sqrt(share), leaf));
        acc += share * vec4<f32>(c.rgb, 1.0);
    }
    return acc;
}
