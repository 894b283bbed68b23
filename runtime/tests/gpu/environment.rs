//! Environment light: SH irradiance on the GPU against the CPU, a constant sky against an equal
//! ambient term, a closed cave under a sky and an opening; the BRDF terms in WGSL.

use super::*;

/// A pseudo-random environment (9 RGB SH coefficients) whose irradiance stays positive: a strong
/// constant term under random higher bands.
fn random_sky(seed: u32) -> [[f32; 3]; 9] {
    let light = random_light(9, seed);
    let mut sh = [[0.0f32; 3]; 9];
    for (i, c) in sh.iter_mut().enumerate() {
        for k in 0..3 {
            let v = light[i].out[k] / [3.0, 1.0, 0.5][k] - 0.5;
            c[k] = if i == 0 { 4.0 + v } else { 0.8 * v };
        }
    }
    sh
}

#[test]
fn sh_irradiance_on_the_gpu_matches_the_cpu_for_ten_thousand_normals() {
    use grotto_runtime::scene::data::VoxelLeaf;
    // Isolated leaves on a sparse grid with random unit normals; cones end at once (max distance
    // below a leaf), so every leaf sees the whole sky (V = 1) and gets exactly albedo * E(n) / pi.
    let normals = random_light(10_000, 5);
    let cells: Vec<VoxelLeaf> = normals
        .iter()
        .enumerate()
        .map(|(i, l)| {
            let i = i as i32;
            let v = Vec3::new(l.out[0] / 3.0 - 0.5, l.out[1] - 0.5, l.out[2] * 2.0 - 0.5);
            VoxelLeaf {
                cell: glam::IVec3::new(i % 32, (i / 32) % 32, i / 1024) * 3,
                albedo: Vec3::new(0.8, 0.5, 0.3),
                opacity: 1.0,
                normal_mean: v.normalize_or(Vec3::Z),
                emission: Vec3::ZERO,
            }
        })
        .collect();
    let mut scene = SceneData::from_voxels("sh probes", 0.1, 7, &cells);
    let sky = random_sky(3);
    scene.environment_sh = Some(sky);
    let settings = Settings { max_distance_m: Some(0.05), bounces: 1, ..Default::default() };
    let mut r = Renderer::new(gpu(), &scene, settings).unwrap();
    let plan = r.update_light().unwrap();
    assert!(plan.runs(Pass::Env), "{}", plan.explain());
    let light = r.read_leaf_light().unwrap();
    let sh = grotto_format::spec::ShRgb9 { coeffs: sky };
    let mut worst = 0.0f64;
    for (leaf, state) in scene.leaves.iter().zip(&light) {
        let n = Vec3::from_slice(&leaf.normal_mean[..3]).normalize().as_dvec3().to_array();
        let e = grotto_preprocess::env::irradiance(&sh, n);
        assert!(e.iter().all(|&v| v > 0.0), "the test sky must stay positive");
        for (k, e_k) in e.iter().enumerate() {
            let want = f64::from(leaf.albedo_opacity[k]) * e_k / std::f64::consts::PI;
            worst = worst.max((f64::from(state.env[k]) - want).abs() / want);
        }
        assert_eq!(state.env[3], 1.0, "an unoccluded leaf sees all of the sky");
    }
    eprintln!("SH irradiance, {} normals: worst relative error {worst:.2e}", light.len());
    assert!(worst < 1e-4, "GPU SH irradiance differs from the CPU by {worst}");
}

#[test]
fn constant_environment_equals_an_equal_ambient_term() {
    use grotto_runtime::scene::data::SceneCamera;
    use grotto_runtime::view::camera::Camera;
    let ambient = [0.3f32, 0.45, 0.6];
    // The shell with an opening, seen from inside with the opening in view: walls lit through it
    // and sky behind it.
    let plain = testscenes::open_sphere(5, 11.0, 0.6, 0.0, 0.8);
    let mut with_env = plain.clone();
    // A constant map: only L00, with L00 * Y00 = the radiance.
    let mut sh = [[0.0f32; 3]; 9];
    sh[0] = ambient.map(|a| a / 0.282_094_8);
    with_env.environment_sh = Some(sh);
    let c = Vec3::splat(1.6);
    let camera = Camera::from_scene(&SceneCamera {
        name: "up".into(),
        eye_m: c,
        look_at_m: c + Vec3::new(0.5, 0.2, 1.0),
        up: Vec3::Y,
        fov_y_deg: 80.0,
    });
    let (w, h) = (64, 48);
    let base = Settings { bounces: 3, convergence_tolerance: 0.0, exposure: 1.0, ..Default::default() };
    let render = |scene, settings: Settings| {
        let mut r = Renderer::new(gpu(), scene, settings).unwrap();
        r.settle(|_, _| {}).unwrap();
        r.render(&camera, w, h).unwrap().0.hdr
    };
    let a = render(&with_env, base.clone());
    let b = render(&plain, Settings { background: ambient, ..base });
    let (mut worst, mut peak) = (0.0f32, 0.0f32);
    for (p, q) in a.iter().zip(&b) {
        for k in 0..3 {
            worst = worst.max((p[k] - q[k]).abs());
            peak = peak.max(q[k]);
        }
    }
    eprintln!("constant env vs ambient: worst difference {worst:.2e} of peak {peak:.3}");
    let sky_pixels = a.iter().filter(|p| p[3] < 0.5).count();
    assert!(peak > 0.1 && sky_pixels > 100 && sky_pixels < a.len() / 2, "{sky_pixels} sky pixels");
    assert!(worst < 1e-4 * peak, "constant environment and ambient differ by {worst}");
}

#[test]
fn a_closed_cave_stays_dark_under_a_sky_and_an_opening_lets_it_in() {
    use grotto_runtime::settings::Quality;
    let sky = {
        let mut sh = [[0.0f32; 3]; 9];
        sh[0] = [1.0 / 0.282_094_8; 3];
        sh
    };
    // Sky visibility of the shell's inner surface: from any point inside a sphere, the
    // cosine-weighted share of the hemisphere that a patch of the sphere fills is that patch's
    // share of the sphere's area, so an opening of cap cosine c is seen by (1 - c) / 2 of every
    // inner leaf's hemisphere.
    let inside = |depth: u32, radius: f32, cap_cos: f32, q: Quality| {
        let mut scene = testscenes::open_sphere(depth, radius, 0.6, 0.0, cap_cos);
        scene.environment_sh = Some(sky);
        let centre = Vec3::splat((1u32 << depth) as f32 * 0.5 * scene.leaf_size_m);
        let inner: Vec<bool> = scene
            .leaves
            .iter()
            .map(|l| Vec3::from_slice(&l.center_m[..3]).distance(centre) < (radius + 1.0) * scene.leaf_size_m)
            .collect();
        let mut r = Renderer::new(gpu(), &scene, Settings { bounces: 2, ..Settings::preset(q) }).unwrap();
        r.settle(|_, _| {}).unwrap();
        let light = r.read_leaf_light().unwrap();
        let v: Vec<f32> = light.iter().zip(&inner).filter(|(_, i)| **i).map(|(l, _)| l.env[3]).collect();
        let out_max = light.iter().map(|l| l.out[1]).fold(0.0f32, f32::max);
        (v.iter().sum::<f32>() / v.len() as f32, out_max)
    };
    let (closed_v, closed_out) = inside(6, 24.0, f32::INFINITY, Quality::Balanced);
    let (v8, _) = inside(6, 24.0, 0.8, Quality::Balanced);
    let (v5, _) = inside(6, 24.0, 0.5, Quality::Balanced);
    eprintln!(
        "sky on a shell (balanced): closed: mean sky visibility {closed_v:.1e}, brightest leaf \
         {closed_out:.1e}; opening of cap cosine 0.8: {v8:.4} (exact 0.1); 0.5: {v5:.4} (exact 0.25)"
    );
    assert!(closed_v == 0.0 && closed_out == 0.0, "light leaked through the closed shell");
    // Cones wider than the opening see its rim as partly opaque, so VCT underestimates it; the
    // bounds say it lets the sky in, in proportion to its size, and never more than it should.
    assert!(v5 > 0.35 * 0.25 && v5 < 1.05 * 0.25, "cap 0.5: {v5}");
    assert!(v8 > 0.2 * 0.1 && v8 < v5, "cap 0.8: {v8}");
}

/// Runs `kernel` (WGSL using shaders/brdf.wgsl, reading and writing `io` at group 0 binding 0)
/// once per element of `io` and returns `io` afterwards.
fn run_brdf_kernel(kernel: &str, io: &[[f32; 4]]) -> Vec<[f32; 4]> {
    let g = gpu();
    let src = grotto_runtime::shaders::compose(&format!(
        "#import brdf\n@group(0) @binding(0) var<storage, read_write> io: array<vec4<f32>>;\n{kernel}"
    ))
    .unwrap();
    let module = g.device.create_shader_module(wgpu::ShaderModuleDescriptor {
        label: Some("brdf probe"),
        source: wgpu::ShaderSource::Wgsl(src.into()),
    });
    let pipeline = g.device.create_compute_pipeline(&wgpu::ComputePipelineDescriptor {
        label: Some("brdf probe"),
        layout: None,
        module: &module,
        entry_point: Some("probe"),
        compilation_options: Default::default(),
        cache: None,
    });
    let buf = g
        .buffer_init(
            "brdf io",
            bytemuck::cast_slice(io),
            wgpu::BufferUsages::STORAGE | wgpu::BufferUsages::COPY_SRC,
        )
        .expect("a few bytes fit any adapter");
    let group = g.device.create_bind_group(&wgpu::BindGroupDescriptor {
        label: Some("brdf io"),
        layout: &pipeline.get_bind_group_layout(0),
        entries: &[wgpu::BindGroupEntry { binding: 0, resource: buf.as_entire_binding() }],
    });
    let mut enc = g.device.create_command_encoder(&Default::default());
    {
        let mut pass = enc.begin_compute_pass(&Default::default());
        pass.set_pipeline(&pipeline);
        pass.set_bind_group(0, &group, &[]);
        pass.dispatch_workgroups((io.len() as u32).div_ceil(64), 1, 1);
    }
    g.queue.submit([enc.finish()]);
    let bytes = g.read_buffer(&buf, (io.len() * 16) as u64).unwrap();
    bytemuck::pod_collect_to_vec(&bytes[..io.len() * 16])
}

#[test]
fn fresnel_and_distribution_terms_match_their_closed_forms() {
    // x: cos of incidence, y: index of refraction, z: n.h, w: GGX alpha. Out: x = F, y = D,
    // z = the hemisphere integral of D (n.h) for that alpha (must be 1).
    let kernel = "
@compute @workgroup_size(64)

fn probe(@builtin(global_invocation_id) gid: vec3<u32>) {
    let i = gid.x;
    if i >= arrayLength(&io) {
        return;
    }
    let q = io[i];
    // Integral over mu = n.h of D(mu) mu 2 pi dmu, midpoint rule.
    let steps = 20000u;
    var sum = 0.0;
    for (var k = 0u; k < steps; k++) {
        let mu = (f32(k) + 0.5) / f32(steps);
        sum += ggx_d(mu, q.w) * mu;
    }
    io[i] = vec4<f32>(fresnel_dielectric(q.x, q.y), ggx_d(q.z, q.w), sum * 2.0 * PI / f32(steps), 0.0);
}";
    // Full Fresnel for unpolarised light, in f64 (Cook & Torrance's form).
    let fresnel = |c: f64, n: f64| {
        let g = (n * n + c * c - 1.0).sqrt();
        let a = (g - c) / (g + c);
        let b = (c * (g + c) - 1.0) / (c * (g - c) + 1.0);
        0.5 * a * a * (1.0 + b * b)
    };
    let mut io = Vec::new();
    for &n in &[1.33f32, 1.5, 2.4] {
        for &c in &[1.0f32, 0.0, 0.5, 0.1, 0.9] {
            for &alpha in &[0.1f32, 0.3, 0.7, 1.0] {
                for &nh in &[1.0f32, 0.0, 0.8] {
                    io.push([c, n, nh, alpha]);
                }
            }
        }
    }
    let out = run_brdf_kernel(kernel, &io);
    let (mut worst_f, mut worst_d, mut worst_int) = (0.0f64, 0.0f64, 0.0f64);
    for (q, o) in io.iter().zip(&out) {
        let (c, n, nh, alpha) = (f64::from(q[0]), f64::from(q[1]), f64::from(q[2]), f64::from(q[3]));
        // Closed forms at normal and grazing incidence; the full formula elsewhere.
        let f_want = if c == 1.0 {
            ((n - 1.0) / (n + 1.0)).powi(2)
        } else if c == 0.0 {
            1.0
        } else {
            fresnel(c, n)
        };
        let a2 = alpha * alpha;
        let d_want = if nh == 1.0 {
            1.0 / (std::f64::consts::PI * a2)
        } else if nh == 0.0 {
            a2 / std::f64::consts::PI
        } else {
            let d = nh * nh * (a2 - 1.0) + 1.0;
            a2 / (std::f64::consts::PI * d * d)
        };
        worst_f = worst_f.max((f64::from(o[0]) - f_want).abs() / f_want);
        worst_d = worst_d.max((f64::from(o[1]) - d_want).abs() / d_want);
        worst_int = worst_int.max((f64::from(o[2]) - 1.0).abs());
    }
    eprintln!("Fresnel {worst_f:.2e}, GGX D {worst_d:.2e} relative; |integral of D cos - 1| {worst_int:.2e}");
    assert!(worst_f < 1e-5, "Fresnel differs from its closed form by {worst_f}");
    assert!(worst_d < 1e-5, "D differs from its closed form by {worst_d}");
    assert!(worst_int < 2e-3, "D is not normalised: {worst_int}");
}
