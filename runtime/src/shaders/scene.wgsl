// The static scene every compute pass reads: per-dispatch parameters and the leaves (bind group 0,
// read-only). The other parts of the static scene are declared by the subsystems that read them
// (svo, rock, lights), so a pass binds only what its imports declare (passes/mod.rs reflects each
// pass's layout from its module). Structs mirror runtime/src/gpu/types.rs (runtime/tests/layout.rs
// checks every member's offset); the constants come from Rust (shaders::constants).

struct Leaf {
    albedo_opacity: vec4<f32>,
    normal_mean: vec4<f32>,
    center_m: vec4<f32>,
    emission: vec4<f32>,
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
    // Where matter is (leaves and rock, one leaf of slack), leaf units: SceneData::occupied_bounds_leaf.
    occupied_min_leaf: vec4<f32>,
    occupied_max_leaf: vec4<f32>,
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
    // Word offsets in the lookup buffer (lookup.wgsl): x rock, y light grid, z tile index.
    lookup_base: vec4<u32>,
    // rgb: largest bounce ratio the tail estimate trusts (0: no tail); w unused.
    tail_ratio_max: vec4<f32>,
}

@group(0) @binding(0) var<uniform> params: Params;
@group(0) @binding(3) var<storage, read> leaves: array<Leaf>;
