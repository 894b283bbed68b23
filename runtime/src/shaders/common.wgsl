// Shared by every grotto compute pass: the scene bindings (group 0), SVO lookup, anisotropic
// quadrilinear sampling and cone tracing. Prepended to each pass's WGSL by `shaders::compose`.
// Keep the structs in sync with runtime/src/gpu_types.rs.

const EMPTY: u32 = 0xffffffffu;

const FLAG_INDIRECT: u32 = 1u;
const FLAG_DIRECT: u32 = 2u;
const FLAG_SHADOWS: u32 = 4u;
const FLAG_EMISSION: u32 = 8u;
const FLAG_TRICUBIC: u32 = 16u;
const FLAG_ENV: u32 = 32u;
const FLAG_FAR_LIGHTS: u32 = 64u;
const FLAG_SPECULAR: u32 = 128u;

// Light::params.z, how a light is shadowed (gpu_types.rs light_shadow).
const LIGHT_MAP: u32 = 0u;
const LIGHT_CONE: u32 = 1u;
const LIGHT_NONE: u32 = 2u;

struct Tile {
    origin_leaf: vec3<i32>,
    depth: u32,
    node_offset: u32,
    leaf_offset: u32,
    node_count: u32,
    leaf_count: u32,
    pad3: u32,
    pad0: u32,
    pad1: u32,
    pad2: u32,
}

struct Node {
    first_child: u32,
    mask_level: u32,
}

struct Leaf {
    albedo_opacity: vec4<f32>,
    normal_mean: vec4<f32>,
    center_m: vec4<f32>,
    emission: vec4<f32>,
}

struct LeafLight {
    direct: vec4<f32>,
    gather: vec4<f32>,
    out: vec4<f32>,
    // rgb: albedo * E_sh(n) / pi * V; w: sky visibility V (env pass).
    env: vec4<f32>,
    // Irradiance / pi from the lights beyond the shadow-map budget, without albedo (inject).
    far: vec4<f32>,
}

struct Light {
    position_kind: vec4<f32>,
    intensity_layer: vec4<f32>,
    direction_cos_outer: vec4<f32>,
    // x: cos(inner angle); y: range in metres; z: LIGHT_MAP, LIGHT_CONE or LIGHT_NONE; w: the
    // irradiance cutoff, W/m^2.
    params: vec4<f32>,
}

struct Params {
    leaf_size_m: f32,
    tile_count: u32,
    leaf_count: u32,
    light_count: u32,
    cone_count: u32,
    cone_tan_half: f32,
    step_scale: f32,
    max_distance_m: f32,
    max_steps: u32,
    max_lod: u32,
    shadow_size: u32,
    flags: u32,
    width: u32,
    height: u32,
    exposure: f32,
    shadow_bias_m: f32,
    shadow_cols: u32,
    light_grid_x: u32,
    light_grid_y: u32,
    light_grid_z: u32,
    // xyz: light grid minimum corner, frame metres; w: cell edge, metres.
    light_grid_min_m: vec4<f32>,
    scene_min_leaf: vec4<f32>,
    scene_max_leaf: vec4<f32>,
    background: vec4<f32>,
    camera_eye_m: vec4<f32>,
    camera_forward: vec4<f32>,
    camera_right: vec4<f32>,
    camera_up: vec4<f32>,
    cones: array<vec4<f32>, 16>,
    // Environment radiance, 9 real SH coefficients (rgb), L00, L1-1, L10, L11, L2-2 .. L22.
    env_sh: array<vec4<f32>, 9>,
    // Material slots: x Ks, y GGX alpha, z ior, w roughness (slot 0 = diffuse).
    materials: array<vec4<f32>, 8>,
    // Env atlas levels: x first row, y width, z height, w roughness.
    env_levels: array<vec4<f32>, 8>,
    // x: env atlas levels (0: none), y: atlas width.
    env_chain: vec4<u32>,
}

struct Stats {
    // Largest relative change of any leaf's outgoing radiance in the last bounce, as f32 bits
    // (non-negative floats order like their bit patterns, so atomicMax works).
    max_change_bits: atomic<u32>,
    pad0: u32,
    pad1: u32,
    pad2: u32,
}

@group(0) @binding(0) var<uniform> params: Params;
@group(0) @binding(1) var<storage, read_write> tiles: array<Tile>;
@group(0) @binding(2) var<storage, read_write> nodes: array<Node>;
@group(0) @binding(3) var<storage, read_write> leaves: array<Leaf>;
@group(0) @binding(4) var<storage, read_write> leaf_light: array<LeafLight>;
// Six anisotropic values per node (premultiplied radiance, opacity), by travel direction:
// 0 +x, 1 -x, 2 +y, 3 -y, 4 +z, 5 -z. Stored as raw words, 4 per value as f32 or 2 as packed f16
// (`radiance_f16`, set by the renderer's `radiance_f16` setting): halves the pyramid's memory and
// bandwidth; see load_face/store_face.
@group(0) @binding(5) var<storage, read_write> faces: array<u32>;
override radiance_f16: bool = false;
// Largest finite f16: brighter values are clamped rather than turned into infinity.
const F16_MAX: f32 = 65504.0;
@group(0) @binding(6) var<storage, read_write> lights: array<Light>;
@group(0) @binding(7) var<storage, read_write> shadow_view_proj: array<mat4x4<f32>>;
@group(0) @binding(8) var<storage, read_write> stats: Stats;
// Shadow atlas: distance from the light to the nearest surfel (packed f32), one square face per
// cube face of a point light or per spot light, `shadow_cols` faces per row. A 2D atlas rather
// than an array texture: wgpu's GL backend neither renders nor copies into array layers.
@group(0) @binding(9) var shadow_dist: texture_2d<f32>;
// Rock behind the scanned surfaces (runtime/src/rock.rs, `RockTable`): a hash table of bricks of
// 4x4x4 rock cells (cells of 2x2x2 leaves). Header: capacity - 1, longest probe, bricks, 0; then
// ROCK_ENTRY_WORDS words an entry: brick x, y, z, 64 rock bits. Constants come from rock.rs
// (shaders::constants).
@group(0) @binding(10) var<storage, read_write> rock: array<u32>;
// Per-cell lists of the lights in range (runtime/src/lights.rs): cells + 1 offsets (absolute word
// indices), then the light indices.
@group(0) @binding(11) var<storage, read_write> light_grid: array<u32>;

// rock.rs `brick_hash`.
fn rock_hash(b: vec3<i32>) -> u32 {
    var h = (u32(b.x) * 0x8da6b343u) ^ (u32(b.y) * 0xd8163841u) ^ (u32(b.z) * 0xcb1ab31fu);
    h ^= h >> 16u;
    h *= 0x85ebca6bu;
    h ^= h >> 13u;
    h *= 0xc2b2ae35u;
    return h ^ (h >> 16u);
}

// Whether the leaf cell holding `p_leaf` lies in rock (rock.rs, `in_rock`). The probe loop is
// bounded by the longest probe sequence the table was built with.
fn in_rock(p_leaf: vec3<f32>) -> bool {
    let cell = vec3<i32>(floor(p_leaf)) >> vec3<u32>(ROCK_LEVEL);
    let b = cell >> vec3<u32>(ROCK_BRICK_SHIFT);
    let mask = rock[0];
    let longest = rock[1];
    var slot = rock_hash(b) & mask;
    for (var i = 0u; i <= longest; i++) {
        let e = ROCK_HEADER_WORDS + slot * ROCK_ENTRY_WORDS;
        let k = vec3<i32>(bitcast<i32>(rock[e]), bitcast<i32>(rock[e + 1u]), bitcast<i32>(rock[e + 2u]));
        if k.x == ROCK_EMPTY_KEY {
            return false;
        }
        if all(k == b) {
            let l = cell - (b << vec3<u32>(ROCK_BRICK_SHIFT));
            let bit = u32(l.x + 4 * (l.y + 4 * l.z));
            return ((rock[e + 3u + bit / 32u] >> (bit % 32u)) & 1u) == 1u;
        }
        slot = (slot + 1u) & mask;
    }
    return false;
}

// The tile whose cube holds the leaf cell `v_leaf` (global leaf units), or EMPTY. A linear scan:
// resident tile counts are small today; streaming will replace it with a tile grid.
fn find_tile(v_leaf: vec3<i32>) -> u32 {
    for (var t = 0u; t < params.tile_count; t++) {
        let tile = tiles[t];
        let rel = v_leaf - tile.origin_leaf;
        let size = 1 << tile.depth;
        if all(rel >= vec3<i32>(0)) && all(rel < vec3<i32>(size)) {
            return t;
        }
    }
    return EMPTY;
}

// The node covering voxel `v` of the global grid at `lod` (0 = leaves, voxel edge leaf * 2^lod),
// or EMPTY where that space is empty or outside every tile.
fn find_node(v: vec3<i32>, lod: u32) -> u32 {
    let v_leaf = v << vec3<u32>(lod);
    let t = find_tile(v_leaf);
    if t == EMPTY {
        return EMPTY;
    }
    let tile = tiles[t];
    if lod > tile.depth {
        return EMPTY;
    }
    let local = vec3<u32>(v_leaf - tile.origin_leaf) >> vec3<u32>(lod);
    return descend(tile.node_offset, local, tile.depth - lod);
}

// Global leaf index of the leaf cell `v` (global leaf units), or EMPTY.
fn find_leaf(v: vec3<i32>) -> u32 {
    let n = find_node(v, 0u);
    if n == EMPTY {
        return EMPTY;
    }
    return nodes[n].first_child;
}

fn load_face(i: u32) -> vec4<f32> {
    if radiance_f16 {
        return vec4<f32>(unpack2x16float(faces[2u * i]), unpack2x16float(faces[2u * i + 1u]));
    }
    let b = 4u * i;
    return bitcast<vec4<f32>>(vec4<u32>(faces[b], faces[b + 1u], faces[b + 2u], faces[b + 3u]));
}

fn store_face(i: u32, v: vec4<f32>) {
    if radiance_f16 {
        let c = min(v, vec4<f32>(F16_MAX));
        faces[2u * i] = pack2x16float(c.xy);
        faces[2u * i + 1u] = pack2x16float(c.zw);
        return;
    }
    let u = bitcast<vec4<u32>>(v);
    let b = 4u * i;
    faces[b] = u.x;
    faces[b + 1u] = u.y;
    faces[b + 2u] = u.z;
    faces[b + 3u] = u.w;
}

// The node's value seen by a ray travelling along unit `dir`: its three facing directional
// values weighted by the squared direction components (the weights sum to 1).
fn directional(n: u32, dir: vec3<f32>) -> vec4<f32> {
    let w = dir * dir;
    let base = n * 6u;
    let fx = load_face(base + select(1u, 0u, dir.x >= 0.0));
    let fy = load_face(base + select(3u, 2u, dir.y >= 0.0));
    let fz = load_face(base + select(5u, 4u, dir.z >= 0.0));
    return fx * w.x + fy * w.y + fz * w.z;
}

// Descends `levels` levels from node `n` along the low bits of `local` (bit levels-1 first).
fn descend(start: u32, local: vec3<u32>, levels: u32) -> u32 {
    var n = start;
    for (var level = 0u; level < levels; level++) {
        let b = levels - 1u - level;
        let o = ((local.x >> b) & 1u) | (((local.y >> b) & 1u) << 1u) | (((local.z >> b) & 1u) << 2u);
        let node = nodes[n];
        let mask = node.mask_level & 0xffu;
        if ((mask >> o) & 1u) == 0u {
            return EMPTY;
        }
        n = node.first_child + countOneBits(mask & ((1u << o) - 1u));
    }
    return n;
}

// Trilinear sample of level `lod` at `p_leaf` (leaf units from the frame origin): voxel centres
// sit at (i + 0.5) * 2^lod. Empty space contributes zero radiance and zero opacity.
// The eight corners share their ancestors down to where their coordinates' bits differ, so when
// they lie in one tile the walk from the root is done once for all of them (same nodes as eight
// find_node calls, which cpu_ref.rs does).
fn sample_level(p_leaf: vec3<f32>, lod: u32, dir: vec3<f32>) -> vec4<f32> {
    let scale = f32(1u << lod);
    let u = p_leaf / scale - vec3<f32>(0.5);
    let base = floor(u);
    let f = u - base;
    let i0 = vec3<i32>(base);
    let t = find_tile(i0 << vec3<u32>(lod));
    let t1 = find_tile((i0 + vec3<i32>(1)) << vec3<u32>(lod));
    var acc = vec4<f32>(0.0);
    if t != EMPTY && t == t1 && lod <= tiles[t].depth {
        let tile = tiles[t];
        let levels = tile.depth - lod;
        let lo = vec3<u32>((i0 << vec3<u32>(lod)) - tile.origin_leaf) >> vec3<u32>(lod);
        let hi = lo + vec3<u32>(1u);
        let diff = (lo ^ hi).x | (lo ^ hi).y | (lo ^ hi).z;
        let low_bits = min(32u - countLeadingZeros(diff), levels);
        let ancestor = descend(tile.node_offset, lo >> vec3<u32>(low_bits), levels - low_bits);
        if ancestor == EMPTY {
            return acc;
        }
        let mask = (1u << low_bits) - 1u;
        for (var c = 0u; c < 8u; c++) {
            let o = vec3<u32>(c & 1u, (c >> 1u) & 1u, (c >> 2u) & 1u);
            let w3 = mix(vec3<f32>(1.0) - f, f, vec3<f32>(o));
            let w = w3.x * w3.y * w3.z;
            if w <= 0.0 {
                continue;
            }
            let n = descend(ancestor, (lo + o) & vec3<u32>(mask), low_bits);
            if n != EMPTY {
                acc += w * directional(n, dir);
            }
        }
        return acc;
    }
    for (var c = 0u; c < 8u; c++) {
        let o = vec3<u32>(c & 1u, (c >> 1u) & 1u, (c >> 2u) & 1u);
        let corner = vec3<f32>(o);
        let w3 = mix(vec3<f32>(1.0) - f, f, corner);
        let w = w3.x * w3.y * w3.z;
        if w <= 0.0 {
            continue;
        }
        let n = find_node(i0 + vec3<i32>(o), lod);
        if n != EMPTY {
            acc += w * directional(n, dir);
        }
    }
    return acc;
}

// Quadrilinear sample: trilinear in the two levels around the fractional `lod`, blended.
fn sample_lod(p_leaf: vec3<f32>, lod: f32, dir: vec3<f32>) -> vec4<f32> {
    let l = clamp(lod, 0.0, f32(params.max_lod));
    let l0 = u32(floor(l));
    let t = l - f32(l0);
    let a = sample_level(p_leaf, l0, dir);
    if t <= 0.0 || l0 >= params.max_lod {
        return a;
    }
    let b = sample_level(p_leaf, l0 + 1u, dir);
    return mix(a, b, t);
}

fn outside_scene(p_leaf: vec3<f32>) -> bool {
    return any(p_leaf < params.scene_min_leaf.xyz) || any(p_leaf > params.scene_max_leaf.xyz);
}

// A sample's premultiplied radiance and opacity for one march step: the mip values are for
// crossing one voxel of edge `diameter`, the step is a fraction `step_scale` of it, so opacity
// (and premultiplied radiance with it) is corrected to that fraction.
fn per_step(s: vec4<f32>) -> vec4<f32> {
    if s.a <= 1e-6 {
        return s;
    }
    let a = 1.0 - pow(max(1.0 - min(s.a, 1.0), 0.0), params.step_scale);
    return vec4<f32>(s.rgb * (a / s.a), a);
}

// Front-to-back composited cone from `origin_m` along unit `dir`: premultiplied radiance and
// opacity. A cone that becomes opaque (>= 0.995) is renormalised by its opacity, i.e. what is
// hidden behind the last surfaces is assumed to look like them; one whose axis enters rock ends
// there the same way (enter_rock); a cone that leaves the scene keeps its transparency (the
// environment's share, added by the caller).
fn trace_cone(origin_m: vec3<f32>, dir: vec3<f32>, tan_half: f32) -> vec4<f32> {
    let leaf = params.leaf_size_m;
    var acc = vec4<f32>(0.0);
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
            return enter_rock(acc, sample_lod(q, max(log2(d / leaf) + 1.0, f32(ROCK_LEVEL + 1u)), dir));
        }
        let p_leaf = (origin_m + dir * t) / leaf;
        if outside_scene(p_leaf) {
            break;
        }
        let diameter = max(leaf, 2.0 * t * tan_half);
        let lod = log2(diameter / leaf);
        let s = per_step(sample_lod(p_leaf, lod, dir));
        acc += (1.0 - acc.a) * s;
        if acc.a >= 0.995 {
            return vec4<f32>(acc.rgb / acc.a, 1.0);
        }
        t_prev = t;
        t += diameter * params.step_scale;
    }
    return close_cone(acc);
}

// A cone that leaves the scene nearly opaque has crossed solid matter whose coarse, blurred
// opacity never quite saturates (trilinear weights toward the empty space outside): from opacity
// CLOSE_LO to CLOSE_HI its missing share is filled with what it saw. Far below the thresholds of
// a closure that had to stand in for rock (0.2 to 0.6 before rock.rs): openings keep their sky.
const CLOSE_LO: f32 = 0.8;
const CLOSE_HI: f32 = 0.95;

fn close_cone(acc: vec4<f32>) -> vec4<f32> {
    if acc.a <= 1e-6 {
        return acc;
    }
    let s = smoothstep(CLOSE_LO, CLOSE_HI, acc.a);
    let a = mix(acc.a, 1.0, s);
    return vec4<f32>(acc.rgb * (a / acc.a), a);
}

// The first distance in (t0, t1] (metres along the cone axis) at which the axis lies in rock,
// probed once per rock cell length (at most 64 probes), or -1.
fn rock_on_segment(origin_m: vec3<f32>, dir: vec3<f32>, t0: f32, t1: f32) -> f32 {
    let cell_m = params.leaf_size_m * f32(1u << ROCK_LEVEL);
    let n = min(u32(ceil((t1 - t0) / cell_m)), 64u);
    for (var k = 1u; k <= n; k++) {
        let t = t0 + (t1 - t0) * f32(k) / f32(n);
        if in_rock((origin_m + dir * t) / params.leaf_size_m) {
            return t;
        }
    }
    return -1.0;
}

// A cone whose axis entered rock: scans are shells, so at a coarse level a wall is partly
// transparent and the cone would go on through the empty rock behind it (a leak). It ends opaque;
// what is hidden behind the surfaces it met looks like them (or, having met none, like the rock
// cell's own filtered radiance `s`). Mirrored by cpu_ref::enter_rock.
fn enter_rock(acc: vec4<f32>, s: vec4<f32>) -> vec4<f32> {
    var behind = vec3<f32>(0.0);
    if acc.a > 1e-6 {
        behind = acc.rgb / acc.a;
    } else if s.a > 1e-6 {
        behind = s.rgb / s.a;
    }
    return vec4<f32>(acc.rgb + (1.0 - acc.a) * behind, 1.0);
}

// Orthonormal basis around unit `n` (Duff et al. 2017, branchless).
fn basis(n: vec3<f32>) -> mat3x3<f32> {
    let s = select(-1.0, 1.0, n.z >= 0.0);
    let a = -1.0 / (s + n.z);
    let b = n.x * n.y * a;
    let t1 = vec3<f32>(1.0 + s * n.x * n.x * a, s * b, -s * n.x);
    let t2 = vec3<f32>(b, s + n.y * n.y * a, -n.y);
    return mat3x3<f32>(t1, t2, n);
}

// Unit mean normal of a leaf, or +z where its normals cancel (no preferred side).
fn leaf_normal(mean: vec3<f32>) -> vec3<f32> {
    let r = length(mean);
    if r < 1e-4 {
        return vec3<f32>(0.0, 0.0, 1.0);
    }
    return mean / r;
}

// A leaf's cones start one leaf off its surface, so that a cone does not see its own leaf first.
fn leaf_cone_origin(leaf: Leaf) -> vec3<f32> {
    return leaf.center_m.xyz + leaf_normal(leaf.normal_mean.xyz) * params.leaf_size_m;
}

// World direction of a cone given in the leaf's tangent frame (z = mean normal).
fn leaf_cone_dir(leaf: Leaf, local: vec3<f32>) -> vec3<f32> {
    return normalize(basis(leaf_normal(leaf.normal_mean.xyz)) * local);
}

// Cosine term averaged over a leaf's normal distribution: a share |mean| of the normals at the
// mean direction and the rest spread over its hemisphere, whose mean clamped cosine is (1 + c) / 4.
fn ndf_cos(mean: vec3<f32>, l: vec3<f32>) -> f32 {
    let r = min(length(mean), 1.0);
    let c = dot(leaf_normal(mean), l);
    return r * max(c, 0.0) + (1.0 - r) * max(1.0 + c, 0.0) * 0.25;
}

// Fraction of a light's shadow map that sees past `p` (3x3 percentage-closer filter).
fn shadow_visibility(light: Light, p: vec3<f32>, dist: f32, bias_m: f32) -> f32 {
    let first = light.intensity_layer.w;
    if first < 0.0 || (params.flags & FLAG_SHADOWS) == 0u {
        return 1.0;
    }
    let d = p - light.position_kind.xyz;
    var face = 0u;
    if light.position_kind.w < 0.5 {
        let a = abs(d);
        if a.x >= a.y && a.x >= a.z {
            face = select(1u, 0u, d.x >= 0.0);
        } else if a.y >= a.z {
            face = select(3u, 2u, d.y >= 0.0);
        } else {
            face = select(5u, 4u, d.z >= 0.0);
        }
    }
    let layer = u32(first) + face;
    let clip = shadow_view_proj[layer] * vec4<f32>(p, 1.0);
    if clip.w <= 0.0 {
        return 1.0;
    }
    let ndc = clip.xy / clip.w;
    let uv = vec2<f32>(ndc.x * 0.5 + 0.5, 0.5 - ndc.y * 0.5);
    if any(uv < vec2<f32>(0.0)) || any(uv > vec2<f32>(1.0)) {
        return 1.0;
    }
    let size = i32(params.shadow_size);
    let tile = vec2<i32>(i32(layer % params.shadow_cols), i32(layer / params.shadow_cols)) * size;
    let texel = clamp(vec2<i32>(uv * f32(size)), vec2<i32>(0), vec2<i32>(size - 1));
    var lit = 0.0;
    for (var dy = -1; dy <= 1; dy++) {
        for (var dx = -1; dx <= 1; dx++) {
            let q = clamp(texel + vec2<i32>(dx, dy), vec2<i32>(0), vec2<i32>(size - 1));
            let stored = unpack_f32(textureLoad(shadow_dist, tile + q, 0));
            lit += select(0.0, 1.0, dist - bias_m <= stored);
        }
    }
    return lit / 9.0;
}

// Index of the light-grid cell holding `p_m` (clamped into the grid); its lights are
// light_grid[light_grid[c] .. light_grid[c + 1]].
fn light_cell(p_m: vec3<f32>) -> u32 {
    let dims = vec3<i32>(i32(params.light_grid_x), i32(params.light_grid_y), i32(params.light_grid_z));
    let f = floor((p_m - params.light_grid_min_m.xyz) / params.light_grid_min_m.w);
    let c = clamp(vec3<i32>(f), vec3<i32>(0), dims - vec3<i32>(1));
    return u32(c.x + dims.x * (c.y + dims.y * c.z));
}

fn light_shadow_kind(light: Light) -> u32 {
    return u32(light.params.z + 0.5);
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
        a += (1.0 - a) * per_step(s).a;
        if a >= 0.995 {
            return 0.0;
        }
        t_prev = t;
        t += diameter * params.step_scale;
    }
    return 1.0 - a;
}

// A light as seen from `p`: unit direction `l` to it, distance (at least 0.1 mm) and spot falloff
// in 0..=1, which is 0 beyond the light's range (it bounds culling) or outside its spot.
struct LightSeen {
    l: vec3<f32>,
    dist: f32,
    falloff: f32,
}

fn light_seen(light: Light, p: vec3<f32>) -> LightSeen {
    let to_light = light.position_kind.xyz - p;
    let dist = max(length(to_light), 1e-4);
    let l = to_light / dist;
    if dist > light.params.y {
        return LightSeen(l, dist, 0.0);
    }
    return LightSeen(l, dist, spot_factor(light, l));
}

// What a leaf sends on: out = emission + direct + env + albedo * gather (every pass that changes
// one of the terms recomputes it).
fn leaf_out(leaf: Leaf, s: LeafLight) -> vec4<f32> {
    return vec4<f32>(leaf.emission.rgb + s.direct.rgb + s.env.rgb + leaf.albedo_opacity.rgb * s.gather.rgb, 0.0);
}

// Spot falloff of a light toward unit direction `l` from the lit point (1 for point lights).
fn spot_factor(light: Light, l: vec3<f32>) -> f32 {
    if light.position_kind.w < 0.5 {
        return 1.0;
    }
    let c = dot(-l, light.direction_cos_outer.xyz);
    let outer = light.direction_cos_outer.w;
    let inner = light.params.x;
    return smoothstep(outer, max(inner, outer + 1e-4), c);
}

// ACES filmic curve (Narkowicz 2015 fit), then the sRGB transfer function.
fn tonemap(hdr: vec3<f32>) -> vec3<f32> {
    let x = max(hdr, vec3<f32>(0.0));
    let mapped = clamp((x * (2.51 * x + 0.03)) / (x * (2.43 * x + 0.59) + 0.14), vec3<f32>(0.0), vec3<f32>(1.0));
    let lo = mapped * 12.92;
    let hi = 1.055 * pow(mapped, vec3<f32>(1.0 / 2.4)) - 0.055;
    return select(hi, lo, mapped <= vec3<f32>(0.0031308));
}

// Item index of a 1D workload dispatched as a 2D grid of 64-wide groups (dispatches are limited
// to 65535 groups per dimension). Keep in sync with passes::dispatch_linear.
fn linear_index(gid: vec3<u32>, nwg: vec3<u32>) -> u32 {
    return gid.x + gid.y * nwg.x * 64u;
}

// Inverses of pack_f32 / pack_normal in passes/splat.wgsl (values stored in Rgba8Unorm targets).
fn unpack_f32(c: vec4<f32>) -> f32 {
    return bitcast<f32>(pack4x8unorm(c));
}

fn unpack_normal(c: vec4<f32>) -> vec3<f32> {
    let p = unpack2x16unorm(pack4x8unorm(c)) * 2.0 - vec2<f32>(1.0);
    var n = vec3<f32>(p, 1.0 - abs(p.x) - abs(p.y));
    let t = max(-n.z, 0.0);
    n.x += select(t, -t, n.x >= 0.0);
    n.y += select(t, -t, n.y >= 0.0);
    return normalize(n);
}

// Real SH basis constants (same order and signs as preprocess/src/env.rs, which projects the map).
const SH_Y0: f32 = 0.282094791773878;
const SH_Y1: f32 = 0.488602511902920;
const SH_Y2: f32 = 1.092548430592079;
const SH_Y20: f32 = 0.315391565252520;
const SH_Y22: f32 = 0.546274215296040;

// Environment SH convolved per band: sum_l band[l] sum_m L_lm Y_lm(d). band = (1, 1, 1) is the
// radiance itself; (1, 2/3, 1/4) is irradiance / pi (Ramamoorthi & Hanrahan 2001); a cone of
// half-angle t averages band l by the mean of P_l over its cap: (1, (1+c)/2, c(1+c)/2), c = cos t.
fn sh_eval(d: vec3<f32>, band: vec3<f32>) -> vec3<f32> {
    let s = params.env_sh;
    var e = s[0].rgb * (SH_Y0 * band.x);
    e += (s[1].rgb * d.y + s[2].rgb * d.z + s[3].rgb * d.x) * (SH_Y1 * band.y);
    e += (s[4].rgb * (SH_Y2 * d.x * d.y) + s[5].rgb * (SH_Y2 * d.y * d.z)
        + s[6].rgb * (SH_Y20 * (3.0 * d.z * d.z - 1.0)) + s[7].rgb * (SH_Y2 * d.x * d.z)
        + s[8].rgb * (SH_Y22 * (d.x * d.x - d.y * d.y))) * band.z;
    return e;
}

// Mean environment radiance over a cone around unit `d` whose half-angle has cosine `c`.
fn sh_cone_radiance(d: vec3<f32>, c: f32) -> vec3<f32> {
    return max(sh_eval(d, vec3<f32>(1.0, 0.5 * (1.0 + c), 0.5 * c * (1.0 + c))), vec3<f32>(0.0));
}

// Irradiance / pi from the environment alone for a leaf or surfel whose normals have mean vector
// `mean` (|mean| = r in 0..=1, Toksvig): the NDF mixture of ndf_cos, a share r of clamped cosine
// at the mean normal (bands pi, 2pi/3, pi/4) and 1 - r of (1 + cos) / 4 (bands pi, pi/3, 0).
// r = 1 is Ramamoorthi & Hanrahan's formula.
fn sh_irradiance_ndf_over_pi(mean: vec3<f32>) -> vec3<f32> {
    let r = clamp(length(mean), 0.0, 1.0);
    let n = leaf_normal(mean);
    let band = vec3<f32>(1.0, r * (2.0 / 3.0) + (1.0 - r) / 3.0, 0.25 * r);
    return max(sh_eval(n, band), vec3<f32>(0.0));
}
