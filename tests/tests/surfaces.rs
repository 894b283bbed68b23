//! Surfaces, not scales: surfels sampled like a scan (random positions, normals a few
//! degrees off, a few millimetres of range noise) on walls with a known shape, rendered with
//! direct light and compared with the exact shading of the true surface.
//!
//! - A flat wall and a round passage seen at a grazing angle: shown as the front-most disc alone,
//!   each pixel takes its disc's own normal and depth, and the wall breaks into scales; blended
//!   splats must keep the pixel-to-pixel variation of (rendered / exact) radiance under a bound.
//! - A round pillar in front of a far wall: pixels just outside its outline show the far wall,
//!   not the pillar (no bleeding across the depth gap).

use glam::{IVec3, Vec3};
use grotto_format::color::linear_to_srgb8;
use grotto_runtime::gpu::Gpu;
use grotto_runtime::gpu::types::SurfelGpu;
use grotto_runtime::render::Renderer;
use grotto_runtime::scene::data::{SceneData, SceneLight};
use grotto_runtime::settings::{IndirectFilter, Settings};
use grotto_runtime::view::camera::Camera;
use rand::{Rng, SeedableRng};

const LEAF_M: f32 = 0.1;
/// Scan sampling: about one point per SPACING_M squared, stored radius 0.7 spacings (as the
/// packer's 1.25 d_k / sqrt(k)), normals up to MAX_TILT_DEG off, range noise RANGE_NOISE_M.
const SPACING_M: f32 = 0.04;
const MAX_TILT_DEG: f32 = 10.0;
const RANGE_NOISE_M: f32 = 0.003;
const WALL_ALBEDO: Vec3 = Vec3::splat(0.6);
const PILLAR_ALBEDO: Vec3 = Vec3::new(0.8, 0.1, 0.1);
const W: u32 = 320;
const H: u32 = 240;

fn gpu() -> Gpu {
    Gpu::new(&grotto_tests::lavapipe()).unwrap()
}

/// The room: air over x, y in [0.1, 4.7] and z in [0.1, 2.3] metres, optionally with a round
/// rock pillar at (2.45, 3.05) of radius 0.4 m from floor to ceiling.
const ROOM_MIN: Vec3 = Vec3::new(0.1, 0.1, 0.1);
const ROOM_MAX: Vec3 = Vec3::new(4.7, 4.7, 2.3);
const PILLAR_XY: glam::Vec2 = glam::Vec2::new(2.45, 3.05);
const PILLAR_R_M: f32 = 0.4;
/// The passage: a round tube of radius 1 m along y at x = z = 1.2, y in [0.1, 4.7].
const TUBE_AXIS_XZ: glam::Vec2 = glam::Vec2::new(1.2, 1.2);
const TUBE_R_M: f32 = 1.0;

/// A surfel at `p` on a surface of normal `n`, as a scan would give it.
fn scanned(rng: &mut rand::rngs::SmallRng, p: Vec3, n: Vec3, albedo: Vec3) -> SurfelGpu {
    let tilt = rng.random::<f32>() * MAX_TILT_DEG.to_radians();
    let turn = rng.random::<f32>() * std::f32::consts::TAU;
    let a = n.any_orthonormal_vector();
    let b = n.cross(a);
    let normal = (n * tilt.cos() + (a * turn.cos() + b * turn.sin()) * tilt.sin()).normalize();
    let p = p + n * (rng.random::<f32>() * 2.0 - 1.0) * RANGE_NOISE_M;
    let rgb = albedo.to_array().map(linear_to_srgb8);
    SurfelGpu {
        position_radius: p.extend(0.7 * SPACING_M).to_array(),
        normal_spread: normal.extend(0.05).to_array(),
        color: [rgb[0], rgb[1], rgb[2], 0],
        scan: 0,
    }
}

/// Random samples over a `u` x `v` rectangle from `origin`, `n` its inward normal.
fn sample_rect(
    rng: &mut rand::rngs::SmallRng,
    out: &mut Vec<SurfelGpu>,
    (origin, u, v): (Vec3, Vec3, Vec3),
    n: Vec3,
    albedo: Vec3,
    keep: &dyn Fn(Vec3) -> bool,
) {
    // One sample in each SPACING_M square, anywhere in it: a scan's rows and columns, unevenly.
    let (nu, nv) = ((u.length() / SPACING_M) as usize, (v.length() / SPACING_M) as usize);
    for i in 0..nu {
        for j in 0..nv {
            let a = (i as f32 + rng.random::<f32>()) / nu as f32;
            let b = (j as f32 + rng.random::<f32>()) / nv as f32;
            // Drawn whether kept or not, so a scene with a pillar has the same walls as one without.
            let s = scanned(rng, origin + u * a + v * b, n, albedo);
            if keep(glam::Vec4::from(s.position_radius).truncate()) {
                out.push(s);
            }
        }
    }
}

/// Random samples over a vertical cylinder's side (`inward`: normals toward the axis).
fn sample_cylinder(
    rng: &mut rand::rngs::SmallRng,
    out: &mut Vec<SurfelGpu>,
    (centre, r, z0, z1): (glam::Vec2, f32, f32, f32),
    inward: bool,
    albedo: Vec3,
) {
    let (nu, nv) = ((std::f32::consts::TAU * r / SPACING_M) as usize, ((z1 - z0) / SPACING_M) as usize);
    for i in 0..nu {
        for j in 0..nv {
            let phi = (i as f32 + rng.random::<f32>()) / nu as f32 * std::f32::consts::TAU;
            let z = z0 + (z1 - z0) * (j as f32 + rng.random::<f32>()) / nv as f32;
            let radial = Vec3::new(phi.cos(), phi.sin(), 0.0);
            let p = (centre + r * radial.truncate()).extend(z);
            out.push(scanned(rng, p, if inward { -radial } else { radial }, albedo));
        }
    }
}

/// The rock (voxels: light transport and shadows) and its scanned surfels.
fn room(pillar: bool, light_m: Vec3) -> SceneData {
    let in_pillar = |p: Vec3| pillar && (p.truncate() - PILLAR_XY).length() < PILLAR_R_M;
    let air = |c: IVec3| {
        let p = (c.as_vec3() + 0.5) * LEAF_M;
        p.cmpgt(ROOM_MIN).all() && p.cmplt(ROOM_MAX).all() && !in_pillar(p)
    };
    let albedo = |c: IVec3| if in_pillar((c.as_vec3() + 0.5) * LEAF_M) { PILLAR_ALBEDO } else { WALL_ALBEDO };
    let mut s = grotto_fixtures::testscenes::carved(
        "room",
        LEAF_M,
        4,
        IVec3::new(48, 48, 24),
        &air,
        &albedo,
        Vec3::ZERO,
        None,
    );
    let mut rng = rand::rngs::SmallRng::seed_from_u64(44);
    let mut surfels = Vec::new();
    let (lo, hi) = (ROOM_MIN, ROOM_MAX);
    let d = hi - lo;
    let outside_pillar = |p: Vec3| !in_pillar(p);
    let walls = [
        ((lo, Vec3::Y * d.y, Vec3::Z * d.z), Vec3::X),
        ((Vec3::new(hi.x, lo.y, lo.z), Vec3::Y * d.y, Vec3::Z * d.z), Vec3::NEG_X),
        ((lo, Vec3::X * d.x, Vec3::Z * d.z), Vec3::Y),
        ((Vec3::new(lo.x, hi.y, lo.z), Vec3::X * d.x, Vec3::Z * d.z), Vec3::NEG_Y),
        ((lo, Vec3::X * d.x, Vec3::Y * d.y), Vec3::Z),
        ((Vec3::new(lo.x, lo.y, hi.z), Vec3::X * d.x, Vec3::Y * d.y), Vec3::NEG_Z),
    ];
    for (rect, n) in walls {
        sample_rect(&mut rng, &mut surfels, rect, n, WALL_ALBEDO, &outside_pillar);
    }
    if pillar {
        sample_cylinder(&mut rng, &mut surfels, (PILLAR_XY, PILLAR_R_M, lo.z, hi.z), false, PILLAR_ALBEDO);
    }
    s.surfels = surfels;
    s.lights.push(lamp(light_m));
    s
}

/// A round passage along y, closed at both ends.
fn tube(light_m: Vec3) -> SceneData {
    let inside = |p: Vec3| {
        glam::Vec2::new(p.x, p.z).distance(TUBE_AXIS_XZ) < TUBE_R_M && p.y > ROOM_MIN.y && p.y < ROOM_MAX.y
    };
    let air = |c: IVec3| inside((c.as_vec3() + 0.5) * LEAF_M);
    let mut s = grotto_fixtures::testscenes::carved(
        "tube",
        LEAF_M,
        4,
        IVec3::new(24, 48, 24),
        &air,
        &|_| WALL_ALBEDO,
        Vec3::ZERO,
        None,
    );
    let mut rng = rand::rngs::SmallRng::seed_from_u64(45);
    let mut surfels = Vec::new();
    // The tube's side as a cylinder about y: sample it as one about z, then turn z into y.
    let mut side = Vec::new();
    sample_cylinder(&mut rng, &mut side, (TUBE_AXIS_XZ, TUBE_R_M, ROOM_MIN.y, ROOM_MAX.y), true, WALL_ALBEDO);
    let swap = |v: [f32; 4]| [v[0], v[2], v[1], v[3]];
    surfels.extend(side.into_iter().map(|mut s| {
        s.position_radius = swap(s.position_radius);
        s.normal_spread = swap(s.normal_spread);
        s
    }));
    let r = TUBE_R_M;
    let corner = Vec3::new(TUBE_AXIS_XZ.x - r, 0.0, TUBE_AXIS_XZ.y - r);
    let on_cap = |p: Vec3| glam::Vec2::new(p.x, p.z).distance(TUBE_AXIS_XZ) < TUBE_R_M;
    for (y, n) in [(ROOM_MIN.y, Vec3::Y), (ROOM_MAX.y, Vec3::NEG_Y)] {
        let rect = (corner + Vec3::Y * y, Vec3::X * 2.0 * r, Vec3::Z * 2.0 * r);
        sample_rect(&mut rng, &mut surfels, rect, n, WALL_ALBEDO, &on_cap);
    }
    s.surfels = surfels;
    s.lights.push(lamp(light_m));
    s
}

fn lamp(position_m: Vec3) -> SceneLight {
    SceneLight {
        name: "lamp".into(),
        position_m,
        intensity_w_sr: Vec3::splat(100.0 / (4.0 * std::f32::consts::PI)),
        spot: None,
        profile: None,
    }
}

/// Direct light only (what the scales are made of), the front-most disc or blended.
fn direct(blend: bool, shadows: bool) -> Settings {
    Settings {
        bounces: 0,
        indirect: IndirectFilter::Off,
        shadows,
        shadow_map_size: 1024,
        splat_blend: blend,
        exposure: 1.0,
        ..Settings::default()
    }
}

/// Linear luminance per pixel of `scene` from `cam`.
fn render(gpu: &Gpu, scene: &SceneData, settings: Settings, cam: &Camera) -> Vec<f32> {
    let mut r = Renderer::new(gpu, scene, settings).unwrap();
    r.settle(|_, _| {}).unwrap();
    let (frame, _) = r.render(cam, W, H).unwrap();
    if let Some(dir) = std::env::var_os("GROTTO_SURFACES_OUT") {
        let name = format!(
            "{}-{}-{}-{}.png",
            scene.name,
            scene.surfels.len(),
            if settings_blend(&r) { "blend" } else { "front" },
            cam.eye_m.x
        );
        let img = image::RgbaImage::from_raw(W, H, frame.ldr.iter().flatten().copied().collect()).unwrap();
        img.save(std::path::Path::new(&dir).join(name)).unwrap();
    }
    luminance(&frame)
}

/// Linear luminance per pixel of `frame`.
fn luminance(frame: &grotto_runtime::render::Frame) -> Vec<f32> {
    frame.hdr.iter().map(|p| 0.2126 * p[0] + 0.7152 * p[1] + 0.0722 * p[2]).collect()
}

/// The camera on the pillar in front of the far wall (its outline near the middle of the view).
fn pillar_cam() -> Camera {
    Camera {
        eye_m: Vec3::new(2.45, 0.6, 1.2),
        look_at_m: Vec3::new(2.45, 3.05, 1.2),
        up: Vec3::Z,
        fov_y_deg: 50.0,
    }
}

fn settings_blend(r: &Renderer) -> bool {
    r.settings().splat_blend
}

/// The ray through pixel (x, y)'s centre, as shade.wgsl makes it.
fn ray(cam: &Camera, x: u32, y: u32) -> Vec3 {
    let forward = (cam.look_at_m - cam.eye_m).normalize();
    let right = forward.cross(cam.up).normalize();
    let up = right.cross(forward);
    let t = (cam.fov_y_deg.to_radians() * 0.5).tan();
    let ndc = ((x as f32 + 0.5) / W as f32 * 2.0 - 1.0, 1.0 - (y as f32 + 0.5) / H as f32 * 2.0);
    (forward + right * (ndc.0 * t * W as f32 / H as f32) + up * (ndc.1 * t)).normalize()
}

/// Exact radiance of a Lambertian point `p` with normal `n` and albedo `a` (luminance of a grey
/// albedo) under the scene's one lamp, unshadowed.
fn exact(scene: &SceneData, p: Vec3, n: Vec3, a: f32) -> f32 {
    let l = &scene.lights[0];
    let to = l.position_m - p;
    let d2 = to.length_squared();
    a / std::f32::consts::PI * l.intensity_w_sr.y * n.dot(to / d2.sqrt()).max(0.0) / d2
}

/// Half the side of the window [`variation`] compares each pixel with: scales are patches of a
/// few to tens of pixels, their edges steps between neighbours.
const WINDOW_HALF_PX: i32 = 4;

/// The pixel-to-pixel variation of `ratio` (rendered over exact radiance) over the pixels where
/// it is `Some`: the mean absolute difference from the mean of its 9x9 neighbourhood (those in
/// the set), over that mean. Exact shading of the true surface gives a constant ratio (its
/// falloff is divided out), so what is left is what the splats add: scales, rims, noise.
fn variation(ratio: &[Option<f32>]) -> (f64, usize) {
    let k = WINDOW_HALF_PX;
    let (mut sum, mut n) = (0.0f64, 0usize);
    for y in k..H as i32 - k {
        for x in k..W as i32 - k {
            let Some(r) = ratio[(y as u32 * W + x as u32) as usize] else { continue };
            let (mut acc, mut m) = (0.0f32, 0usize);
            for dy in -k..=k {
                for dx in -k..=k {
                    if let Some(q) = ratio[((y + dy) as u32 * W + (x + dx) as u32) as usize] {
                        acc += q;
                        m += 1;
                    }
                }
            }
            // Whole windows only: a wall's edge is not a scale.
            if m < ((2 * k + 1) * (2 * k + 1)) as usize {
                continue;
            }
            let mean = acc / m as f32;
            sum += f64::from((r - mean).abs() / mean.max(1e-9));
            n += 1;
        }
    }
    (sum / n.max(1) as f64, n)
}

/// Per pixel, rendered over exact radiance on the flat wall x = 0.1 (seen at about 11 degrees),
/// away from its edges.
fn flat_wall_ratio(scene: &SceneData, cam: &Camera, lum: &[f32]) -> Vec<Option<f32>> {
    (0..W * H)
        .map(|i| {
            let d = ray(cam, i % W, i / W);
            // The wall x = 0.1 is the nearest surface along rays toward -x that reach it inside
            // the room (the pillar is out of this view).
            if d.x >= -1e-3 {
                return None;
            }
            let p = cam.eye_m + d * ((ROOM_MIN.x - cam.eye_m.x) / d.x);
            let margin = 0.25;
            let inside = p.y > ROOM_MIN.y + margin
                && p.y < ROOM_MAX.y - margin
                && p.z > ROOM_MIN.z + margin
                && p.z < ROOM_MAX.z - margin;
            (inside && lum[i as usize] > 0.0)
                .then(|| lum[i as usize] / exact(scene, p, Vec3::X, WALL_ALBEDO.y))
        })
        .collect()
}

/// Per pixel, rendered over exact radiance on the tube's side, away from its ends.
fn tube_ratio(scene: &SceneData, cam: &Camera, lum: &[f32]) -> Vec<Option<f32>> {
    (0..W * H)
        .map(|i| {
            let d = ray(cam, i % W, i / W);
            // Inside the tube: solve |(o + t d - axis)_xz| = R for the positive root.
            let o = glam::Vec2::new(cam.eye_m.x, cam.eye_m.z) - TUBE_AXIS_XZ;
            let dv = glam::Vec2::new(d.x, d.z);
            let (a, b, c) = (dv.length_squared(), 2.0 * o.dot(dv), o.length_squared() - TUBE_R_M * TUBE_R_M);
            if a < 1e-6 {
                return None;
            }
            let t = (-b + (b * b - 4.0 * a * c).sqrt()) / (2.0 * a);
            let p = cam.eye_m + d * t;
            let n = -(glam::Vec2::new(p.x, p.z) - TUBE_AXIS_XZ).normalize().extend(0.0);
            let n = Vec3::new(n.x, 0.0, n.y);
            let inside = p.y > ROOM_MIN.y + 0.4 && p.y < ROOM_MAX.y - 0.4;
            (inside && lum[i as usize] > 0.0).then(|| lum[i as usize] / exact(scene, p, n, WALL_ALBEDO.y))
        })
        .collect()
}

/// Bounds on the variation of blended splats, per case (measured on lavapipe, `cargo test
/// --release -p grotto-tests --test surfaces -- --nocapture`: flat wall 0.0056 blended, 0.0162
/// front-most disc; round passage 0.0177 and 0.0404, most of it where the far walls are lit at a
/// grazing angle and each pixel averages a few noisy normals). The front-most disc fails both by
/// about 2x.
const FLAT_WALL_MAX: f64 = 0.008;
const ROUND_PASSAGE_MAX: f64 = 0.022;

#[test]
fn walls_seen_at_a_grazing_angle_are_smooth_surfaces_not_scales() {
    let gpu = gpu();
    let wall_cam = Camera {
        eye_m: Vec3::new(0.6, 0.4, 1.2),
        look_at_m: Vec3::new(0.1, 3.0, 1.0),
        up: Vec3::Z,
        fov_y_deg: 50.0,
    };
    let room = room(false, Vec3::new(2.4, 1.5, 1.8));
    let tube_cam = Camera {
        eye_m: Vec3::new(1.2, 0.4, 1.4),
        look_at_m: Vec3::new(1.2, 4.0, 1.1),
        up: Vec3::Z,
        fov_y_deg: 60.0,
    };
    let tube = tube(Vec3::new(1.4, 2.0, 1.7));
    type Ratio = fn(&SceneData, &Camera, &[f32]) -> Vec<Option<f32>>;
    let cases: [(&str, &SceneData, &Camera, Ratio, f64); 2] = [
        ("flat wall", &room, &wall_cam, flat_wall_ratio, FLAT_WALL_MAX),
        ("round passage", &tube, &tube_cam, tube_ratio, ROUND_PASSAGE_MAX),
    ];
    for (name, scene, cam, ratio, max) in cases {
        let blended = variation(&ratio(scene, cam, &render(&gpu, scene, direct(true, true), cam)));
        let front = variation(&ratio(scene, cam, &render(&gpu, scene, direct(false, true), cam)));
        eprintln!(
            "{name}: variation blended {:.4} ({} pixels), front-most disc {:.4} ({} pixels)",
            blended.0, blended.1, front.0, front.1
        );
        assert!(blended.1 > (W * H / 10) as usize, "{name}: too few wall pixels ({})", blended.1);
        assert!(blended.0 <= max, "{name}: blended splats vary by {:.4} > {max}", blended.0);
        // The test can fail: the front-most disc alone shows scales.
        assert!(front.0 > 1.5 * max, "{name}: the front-most disc varies by only {:.4}", front.0);
    }
}

#[test]
fn a_pillar_does_not_bleed_over_the_wall_behind_it() {
    let gpu = gpu();
    let cam = pillar_cam();
    let light = Vec3::new(2.0, 0.8, 1.9);
    // Unshadowed direct light: the wall behind is lit the same with and without the pillar.
    let with = render(&gpu, &room(true, light), direct(true, false), &cam);
    let without = render(&gpu, &room(false, light), direct(true, false), &cam);
    let bleeding = band_showing_the_pillar(&cam, &with, &without);
    eprintln!(
        "pillar outline: {} pixels 1.5 to 4 px outside, {} differ by > 5%: {:?}",
        bleeding.0,
        bleeding.1.len(),
        &bleeding.1[..bleeding.1.len().min(8)]
    );
    assert!(bleeding.0 > 200, "the band outside the pillar must be seen ({} pixels)", bleeding.0);
    assert!(
        bleeding.1.len() * 100 <= bleeding.0,
        "{} of {} pixels outside the pillar show it",
        bleeding.1.len(),
        bleeding.0
    );
    // The test can fail: discs grown to 3x their radius (splat scale 6) cover the band.
    let grown = Settings { splat_scale: 6.0, ..direct(true, false) };
    let fat = band_showing_the_pillar(&cam, &render(&gpu, &room(true, light), grown, &cam), &without);
    eprintln!("splat scale 6: {} of {} pixels outside the pillar show it", fat.1.len(), fat.0);
    assert!(fat.1.len() * 10 > fat.0, "discs grown 3x must cover the band ({} of {})", fat.1.len(), fat.0);
}

/// The pixels whose rays pass 1.5 to 4 pixels outside the pillar (away from floor and ceiling),
/// and those of them where `with` differs from `without` (no pillar) by more than 5%.
fn band_showing_the_pillar(
    cam: &Camera,
    with: &[f32],
    without: &[f32],
) -> (usize, Vec<(u32, u32, f32, f32)>) {
    // How far each pixel's ray passes outside the pillar, in pixels at the pillar's distance.
    let px_m = 2.0 * (cam.fov_y_deg.to_radians() * 0.5).tan() * (PILLAR_XY.y - cam.eye_m.y) / H as f32;
    let (mut band, mut bled) = (0usize, Vec::new());
    for i in 0..(W * H) as usize {
        let d = ray(cam, i as u32 % W, i as u32 / W);
        let o = cam.eye_m.truncate() - PILLAR_XY;
        let dv = d.truncate();
        // Closest approach of the ray to the pillar's axis, in the horizontal plane.
        let t = -o.dot(dv) / dv.length_squared();
        let miss_px = ((o + dv * t).length() - PILLAR_R_M) / px_m;
        let z = cam.eye_m.z + d.z * t;
        if !(1.5..4.0).contains(&miss_px) || !(ROOM_MIN.z + 0.3..=ROOM_MAX.z - 0.3).contains(&z) {
            continue;
        }
        band += 1;
        let rel = (with[i] - without[i]).abs() / without[i].max(1e-9);
        if rel > 0.05 {
            bled.push((i as u32 % W, i as u32 / W, miss_px, rel));
        }
    }
    (band, bled)
}

/// Anti-aliasing at rest (passes/resolve.rs): a still frame's jittered samples converge on each
/// pixel's area, measured against 4 x 4 supersampling (16 samples on a grid) around the pillar's
/// outline. One sample a pixel (the pixel centres) is the error to beat.
#[test]
fn a_still_frame_anti_aliases_the_pillar_outline_towards_supersampling() {
    use grotto_runtime::light::plan::Pass;
    let gpu = gpu();
    let cam = pillar_cam();
    let scene = room(true, Vec3::new(2.0, 0.8, 1.9));
    let mut r = Renderer::new(&gpu, &scene, Settings { still_samples: 16, ..direct(true, false) }).unwrap();
    r.settle(|_, _| {}).unwrap();
    let centres = luminance(&r.render(&cam, W, H).unwrap().0);
    let (still, plan) = r.render_still(&cam, W, H).unwrap();
    assert!(plan.runs(Pass::Resolve), "{}", plan.explain());
    assert_eq!(r.still_progress().map(|p| (p.samples, p.of)), Some((16, 16)));
    // Complete and nothing changed: the next still frame draws nothing, and its plan says so.
    let (rest, p) = r.draw_still(&cam, W, H).unwrap();
    assert!(p.complete() && !rest.runs(Pass::Gbuffer) && !rest.runs(Pass::Shade), "{}", rest.explain());
    let still = luminance(&still);
    let grid = luminance(&r.render(&cam, 4 * W, 4 * H).unwrap().0.downsampled(4));
    // Where the samples disagree with the grid: the outline; elsewhere all three agree.
    let err = |img: &[f32]| -> f64 {
        img.iter().zip(&grid).map(|(a, b)| f64::from((a - b).abs())).sum::<f64>() / grid.len() as f64
    };
    let (e1, e16) = (err(&centres), err(&still));
    eprintln!("mean |luminance - 4x4 supersampled|: pixel centres {e1:.5}, 16 still samples {e16:.5}");
    assert!(e1 > 0.0 && e16 < 0.6 * e1, "16 jittered samples {e16} against the centres' {e1}");
    // A change (here the exposure) starts the still frame again from the pixel centres.
    r.set_exposure(2.0);
    let (_, p) = r.draw_still(&cam, W, H).unwrap();
    assert_eq!((p.samples, p.of), (1, 16));
    let (_, p) = r.draw_still(&cam, W, H).unwrap();
    assert_eq!(p.samples, 2);
}

/// Per pixel near the crease where the floor z = 0.1 meets the wall x = 0.1 (within `band_m` of
/// it, away from the room's ends), rendered over exact radiance: which face the pixel shows, and
/// the ratio.
fn crease_ratio(scene: &SceneData, cam: &Camera, lum: &[f32], band_m: (f32, f32)) -> Vec<(bool, f32)> {
    let mut out = Vec::new();
    for i in 0..W * H {
        let d = ray(cam, i % W, i / W);
        let to_floor = (ROOM_MIN.z - cam.eye_m.z) / d.z;
        let to_wall = (ROOM_MIN.x - cam.eye_m.x) / d.x;
        let floor = to_floor > 0.0 && (to_wall <= 0.0 || to_floor < to_wall);
        let t = if floor { to_floor } else { to_wall };
        let p = cam.eye_m + d * t;
        let (n, from_crease) = if floor { (Vec3::Z, p.x - ROOM_MIN.x) } else { (Vec3::X, p.z - ROOM_MIN.z) };
        let away_from_ends = p.y > ROOM_MIN.y + 0.5 && p.y < ROOM_MAX.y - 0.5;
        if t > 0.0 && away_from_ends && (band_m.0..band_m.1).contains(&from_crease) && lum[i as usize] > 0.0 {
            out.push((floor, lum[i as usize] / exact(scene, p, n, WALL_ALBEDO.y)));
        }
    }
    out
}

/// Blending stays on one face of a crease: the floor's discs and the wall's meet at a right angle
/// within the depth tolerance, and averaging their normals would shade the strip along the
/// crease as a 45-degree bevel. Pixels within a disc's radius of the crease must shade as their
/// own face does farther out (measured on lavapipe: floor 1.011 of exact within 3 cm, 1.010 beyond
/// 15 cm; blending every disc within the tolerance, whatever its normal, gives the floor strip
/// 1.60, and the first version's depth pass, pushed back by a tolerance that grows at grazing
/// angles, chose the wall's discs as the floor's front and gave 1.33).
#[test]
fn a_crease_stays_sharp() {
    let gpu = gpu();
    let cam = Camera {
        eye_m: Vec3::new(1.4, 1.2, 1.1),
        look_at_m: Vec3::new(0.1, 2.4, 0.1),
        up: Vec3::Z,
        fov_y_deg: 40.0,
    };
    // Grazing on the floor, steep on the wall: the two faces differ by about 3x.
    let scene = room(false, Vec3::new(1.2, 2.4, 0.6));
    let lum = render(&gpu, &scene, direct(true, false), &cam);
    let error = |v: &[(bool, f32)], floor: bool| -> (f64, usize) {
        let side: Vec<f32> = v.iter().filter(|p| p.0 == floor).map(|p| p.1).collect();
        let mean = side.iter().map(|&r| f64::from(r)).sum::<f64>() / side.len().max(1) as f64;
        (mean, side.len())
    };
    let near = crease_ratio(&scene, &cam, &lum, (0.005, 0.03));
    let far = crease_ratio(&scene, &cam, &lum, (0.15, 0.4));
    for (floor, name) in [(true, "floor"), (false, "wall")] {
        let ((n_mean, n_px), (f_mean, f_px)) = (error(&near, floor), error(&far, floor));
        eprintln!(
            "{name}: rendered/exact {n_mean:.4} within 3 cm of the crease ({n_px} px), {f_mean:.4} beyond 15 cm ({f_px} px)"
        );
        assert!(n_px > 100 && f_px > 100, "{name}: {n_px} / {f_px} pixels");
        assert!((n_mean / f_mean - 1.0).abs() < 0.1, "{name}: {n_mean} near the crease against {f_mean}");
    }
}
