//! The accuracy-vs-time sweep: each scene is rendered once by the reference (with its standard
//! error) and then by the runtime under each quality knob alone and the presets; every run records
//! its error against the reference, its GPU time per pass and its GPU memory. `report` turns the
//! rows into docs/accuracy.md (table, Pareto front, preset check).

use std::collections::BTreeMap;
use std::fmt::Write as _;

use glam::Vec3;
use grotto_fixtures::testscenes;
use grotto_preprocess::build::{ColorCodec, SurfelCodec};
use grotto_runtime::gpu::Gpu;
use grotto_runtime::light::plan::Pass;
use grotto_runtime::render::renderer::{Frame, IndirectFilter, Quality, Renderer, Settings};
use grotto_runtime::scene::data::SceneData;
use grotto_runtime::view::camera::Camera;
use serde::Serialize;

use crate::{Estimate, PathSettings, SurfelScene};

/// A scene of the sweep and its reference image.
#[derive(Debug)]
pub struct SweepScene {
    pub name: String,
    pub description: String,
    pub data: SceneData,
    pub camera: Camera,
    pub reference: Vec<Estimate>,
    pub reference_s: f64,
    pub spp: u32,
    /// References cut after k indirect bounces, for k in `TRUNCATED_BOUNCES`: the runtime with k
    /// bounces is compared with these to judge propagation alone, without the missing bounces.
    pub truncated: Vec<(u32, Vec<Estimate>)>,
    /// The same surfels built into other packages (SVO depth, colour codec, surfel encoding, SH
    /// window), each rendered with the balanced preset and judged against this scene's reference.
    pub variants: Vec<Variant>,
}

/// A package variant of a sweep scene.
#[derive(Debug)]
pub struct Variant {
    /// Config name in the report.
    pub name: String,
    pub knob: String,
    pub data: SceneData,
}

/// Bounce counts with a truncated reference.
pub const TRUNCATED_BOUNCES: [u32; 4] = [0, 1, 2, 4];

/// One runtime configuration.
#[derive(Clone, Debug, Serialize)]
pub struct Config {
    pub name: String,
    /// Which knob it varies ("preset" for the presets, "baseline").
    pub knob: String,
    pub settings: Settings,
}

/// One measured run.
#[derive(Clone, Debug, Serialize)]
pub struct Row {
    pub scene: String,
    pub config: String,
    pub knob: String,
    /// sqrt(sum |runtime - reference|^2 / sum |reference|^2) over the pixels both see.
    pub rel_rmse: f64,
    /// The reference's own noise on the same scale: sqrt(sum se^2 / sum |reference|^2).
    pub reference_noise: f64,
    /// Signed error of the mean: sum(runtime) / sum(reference) - 1 over the same pixels and channels
    /// (positive: the runtime is too bright).
    pub bias: f64,
    /// Mean FLIP (NVIDIA's perceptual difference, 0 = identical, 1 = maximal; `nv-flip`, default
    /// 67 pixels per degree) between the tonemapped runtime and reference images, both at the
    /// exposure that auto-exposure picks for the reference.
    pub flip: f64,
    /// For "bounces k" runs with a truncated reference: (relative RMSE, bias) against the reference
    /// cut after the same k bounces.
    pub truncated: Option<(f64, f64)>,
    /// GPU milliseconds to converge the light (shadow + inject + every bounce) and to draw a
    /// frame (gbuffer + shade).
    pub light_ms: f64,
    pub frame_ms: f64,
    pub bounces: u32,
    pub gpu_bytes: u64,
    pub pass_ms: BTreeMap<String, f64>,
    /// For the balanced preset: (k, relative RMSE with the runtime at k x k samples per pixel) for
    /// k in [`SUPERSAMPLE_CHECK`]; empty for the other rows.
    pub supersample_errors: Vec<(u32, f64)>,
}

/// The hand-built scenes (name, description, scene): the furnace shell, the colour box and the
/// hidden-chamber dogleg (also rendered by Mitsuba 3 to check the reference: mitsuba.rs).
pub fn closed_scenes() -> Vec<(&'static str, &'static str, SceneData)> {
    let mut furnace = testscenes::furnace_sphere(5, 11.0, 0.8, 1.0);
    let c = Vec3::splat(1.6);
    furnace.cameras.push(grotto_runtime::scene::data::SceneCamera {
        name: "inside".into(),
        eye_m: c,
        look_at_m: c + Vec3::new(1.0, 0.3, -0.2),
        up: Vec3::Z,
        fov_y_deg: 70.0,
    });
    vec![
        ("furnace", "closed shell, emission 1, albedo 0.8 (exact radiance 5 everywhere)", furnace),
        (
            "colour box",
            "closed box, red and green walls, one 30 W lamp: colour bleeding",
            testscenes::colour_box(),
        ),
        (
            "dogleg",
            "rock, a lit room and a chamber behind three right-angle corridors, one 200 W lamp",
            testscenes::dogleg(),
        ),
    ]
}

/// The built-in scenes: the furnace shell, the colour box, the hidden-chamber dogleg and the
/// synthetic demo cave; `only` keeps the one with that name.
pub fn scenes(width: u32, height: u32, spp: u32, only: Option<&str>) -> Vec<SweepScene> {
    scenes_cached(width, height, spp, only, None)
}

/// [`scenes`], with the reference renders kept in `cache` (a folder) and read back while the scene,
/// the image size and the paths per pixel are the same: for iterating on the runtime with
/// `--config`, where the references would otherwise dominate. The key hashes the scene's surfels,
/// lights, camera and environment, and the path tracer's version below (bump it with any change
/// to the path tracer).
pub fn scenes_cached(
    width: u32,
    height: u32,
    spp: u32,
    only: Option<&str>,
    cache: Option<&std::path::Path>,
) -> Vec<SweepScene> {
    let mut out = Vec::new();
    let defs: Vec<_> = closed_scenes().into_iter().filter(|d| only.is_none_or(|o| o == d.0)).collect();
    let mut defs: Vec<_> = defs.into_iter().map(|(a, b, c)| (a, b, c, Vec::new())).collect();
    if only.is_none_or(|o| o == "bunny") {
        match bunny() {
            Ok(data) => defs.push((
                "bunny",
                "a real scan: the Stanford bunny's ten range scans (362k points) merged with the poses of bun.conf, 2 mm leaves, one lamp above and in front; indirect light is its own interreflection",
                data,
                Vec::new(),
            )),
            Err(e) => eprintln!("bunny scene skipped: {e}"),
        }
    }
    if only.is_none_or(|o| o == "cave with sky") {
        let sky = shared_data().join("envmaps/probulator_ennis.hdr");
        match demo_cave(ColorCodec::Raw, SurfelCodec::Full, 0.25, Some(&sky), false).and_then(|raw| {
            let windowed = demo_cave(ColorCodec::Raw, SurfelCodec::Full, 0.25, Some(&sky), true)?;
            Ok((raw, windowed))
        }) {
            Ok((raw, windowed)) => defs.push((
                "cave with sky",
                "the demo cave lit also by an environment map (probulator ennis.hdr, whose bright window makes SH irradiance ring negative: windowed at s = 0.124) through its entrance, SH unwindowed; the reference sees the same 9 unwindowed coefficients as its sky",
                raw,
                vec![Variant { name: "SH windowed".into(), knob: "sh window".into(), data: windowed }],
            )),
            Err(e) => eprintln!("cave with sky scene skipped: {e}"),
        }
    }
    if only.is_none_or(|o| o == "demo cave") {
        match demo_cave_variants() {
            Ok((data, variants)) => defs.push((
                "demo cave",
                "the synthetic demo cave (80k points, 0.25 m leaves, raw colours, 14 lamps), camera at the entrance: a passage lit mostly indirectly",
                data,
                variants,
            )),
            Err(e) => eprintln!("demo cave scene skipped: {e}"),
        }
    }
    for (name, description, data, variants) in defs {
        let camera = Camera::from_scene(&data.cameras[0]);
        let scene = SurfelScene::from_scene(&data, Settings::default().splat_scale);
        let key = reference_key(&data, width, height, spp);
        let (reference, reference_s) = cached_render(cache, name, key, "full", width * height, || {
            scene.render(&camera, width, height, spp, &PathSettings::for_scene(&data), 1)
        });
        let truncated = TRUNCATED_BOUNCES
            .iter()
            .map(|&k| {
                let cut = PathSettings { max_bounces: k + 1, ..PathSettings::for_scene(&data) };
                let (est, _) = cached_render(cache, name, key, &format!("cut{k}"), width * height, || {
                    scene.render(&camera, width, height, spp, &cut, 2)
                });
                (k, est)
            })
            .collect();
        out.push(SweepScene {
            name: name.into(),
            description: description.into(),
            data,
            camera,
            reference,
            reference_s,
            spp,
            truncated,
            variants,
        });
    }
    out
}

/// The path tracer's version in [`scenes_cached`]'s key.
const REFERENCE_CACHE_VERSION: u64 = 1;

/// FNV-1a over what a reference render depends on.
fn reference_key(data: &SceneData, width: u32, height: u32, spp: u32) -> u64 {
    let mut h = 0xcbf2_9ce4_8422_2325u64;
    let mut eat = |bytes: &[u8]| {
        for &b in bytes {
            h = (h ^ u64::from(b)).wrapping_mul(0x100_0000_01b3);
        }
    };
    eat(&REFERENCE_CACHE_VERSION.to_le_bytes());
    eat(&[width, height, spp].map(u32::to_le_bytes).concat());
    eat(bytemuck::cast_slice(&data.surfels));
    eat(format!("{:?}{:?}{:?}{:?}", data.lights, data.cameras, data.environment_sh, data.materials)
        .as_bytes());
    h
}

/// `render()` and the seconds it took, or both from `cache` where a file with this key holds
/// them (the seconds then are the render's when it was made); a fresh render is written there
/// (a failed write only costs the next run a render). The file: the seconds as f64, then the
/// image's `Estimate`s, little-endian.
fn cached_render(
    cache: Option<&std::path::Path>,
    scene: &str,
    key: u64,
    what: &str,
    pixels: u32,
    render: impl FnOnce() -> Vec<Estimate>,
) -> (Vec<Estimate>, f64) {
    let path = cache.map(|dir| dir.join(format!("{}-{what}-{key:016x}.f32", slug(scene))));
    if let Some(bytes) = path.as_ref().and_then(|p| std::fs::read(p).ok())
        && bytes.len() == 8 + pixels as usize * size_of::<Estimate>()
    {
        let seconds = f64::from_le_bytes(bytes[..8].try_into().expect("8 bytes"));
        return (bytemuck::pod_collect_to_vec(&bytes[8..]), seconds);
    }
    let t0 = std::time::Instant::now();
    let est = render();
    let seconds = t0.elapsed().as_secs_f64();
    if let Some(path) = path
        && path.parent().is_some_and(|dir| std::fs::create_dir_all(dir).is_ok())
    {
        let bytes = [&seconds.to_le_bytes()[..], bytemuck::cast_slice(&est)].concat();
        let _ = grotto_runtime::cli::export::write_atomically(&path, &bytes);
    }
    (est, seconds)
}

/// A small synthetic cave built through the whole pipeline (synth -> package -> scene).
pub fn demo_cave(
    colors: ColorCodec,
    surfels: SurfelCodec,
    leaf_m: f64,
    sky: Option<&std::path::Path>,
    sh_window: bool,
) -> Result<SceneData, String> {
    let dir = tempfile::tempdir().map_err(|e| e.to_string())?;
    let cave = grotto_fixtures::SmallCave {
        colors,
        surfels,
        leaf_m,
        sky: sky.map(std::path::Path::to_path_buf),
        sh_window,
        ..Default::default()
    };
    let out = grotto_fixtures::small_cave_package(dir.path(), &cave).map_err(|e| e.to_string())?;
    let pkg = grotto_format::Package::open(&out).map_err(|e| e.to_string())?;
    let mut scene = SceneData::from_package(&pkg).map_err(|e| e.to_string())?;
    // The entrance camera first: it looks down a passage the lamps light mostly indirectly.
    scene.cameras.sort_by_key(|c| c.name != "entrance");
    Ok(scene)
}

/// `../shared/data` beside the repository (the real third-party scans).
pub fn shared_data() -> std::path::PathBuf {
    std::path::Path::new(env!("CARGO_MANIFEST_DIR")).join("../../shared/data")
}

/// The Stanford bunny's range scans, registered by bun.conf and built into a package with 2 mm
/// leaves; a lamp and a camera are placed from its bounds (the scans carry neither).
pub fn bunny() -> Result<SceneData, String> {
    use grotto_preprocess::build::{self, BuildParams};
    let conf = shared_data().join("ply/stanford-bunny/data/bun.conf");
    let manifest = grotto_preprocess::manifest::Manifest::load(&conf).map_err(|e| e.to_string())?;
    let dir = tempfile::tempdir().map_err(|e| e.to_string())?;
    let out = dir.path().join("bunny.grotto");
    let bp = BuildParams {
        work_dir: dir.path().join("work"),
        memory_budget_bytes: 256 << 20,
        threads: 2,
        // The tile cap docs/accuracy.md was measured with (3/4 budget / threads / 256 B then).
        max_tile_points: 393_216,
        leaf_m: 1.0 / 512.0,
        colors: ColorCodec::Raw,
        surfels: SurfelCodec::Full,
        min_tile_extent_m: 1.0 / 16.0,
        max_tile_extent_m: 0.25,
        halo_m: 0.004,
        ..BuildParams::default()
    };
    build::build(&manifest, &conf, &out, &bp, &|_| {}).map_err(|e| e.to_string())?;
    let pkg = grotto_format::Package::open(&out).map_err(|e| e.to_string())?;
    let mut scene = SceneData::from_package(&pkg).map_err(|e| e.to_string())?;
    let (lo, hi) = scene.surfels.iter().fold((Vec3::MAX, Vec3::MIN), |(lo, hi), s| {
        let p = Vec3::from_slice(&s.position_radius[..3]);
        (lo.min(p), hi.max(p))
    });
    let (c, size) = ((lo + hi) * 0.5, (hi - lo).max_element());
    let light_m = c + Vec3::new(0.6, 1.2, 1.0) * size;
    scene.lights.push(grotto_runtime::scene::data::SceneLight {
        name: "lamp".into(),
        position_m: light_m,
        // About 3 W/m^2 on the bunny.
        intensity_w_sr: Vec3::splat(3.0 * (light_m - c).length_squared()),
        spot: None,
    });
    scene.cameras.push(grotto_runtime::scene::data::SceneCamera {
        name: "front".into(),
        eye_m: c + Vec3::new(0.3, 0.25, 1.8) * size,
        look_at_m: c,
        up: Vec3::Y,
        fov_y_deg: 45.0,
    });
    Ok(scene)
}

/// The demo cave with raw colours, full-precision surfels and 0.25 m leaves (the reference's
/// scene), and the package knobs around it: one SVO level coarser and finer, BC1 colours (the
/// default ISPC kernel refined by cluster fit, ISPC alone as `--colors bc1-fast` and cluster fit
/// alone as `--colors bc1-cluster`), compact surfels (format 2.0, what `grotto-pack build` writes
/// by default).
fn demo_cave_variants() -> Result<(SceneData, Vec<Variant>), String> {
    let base = demo_cave(ColorCodec::Raw, SurfelCodec::Full, 0.25, None, true)?;
    let mut variants = Vec::new();
    for (name, knob, colors, surfels, leaf_m) in [
        ("leaf 0.5 m (depth -1)", "svo depth", ColorCodec::Raw, SurfelCodec::Full, 0.5),
        ("leaf 0.125 m (depth +1)", "svo depth", ColorCodec::Raw, SurfelCodec::Full, 0.125),
        ("BC1 colours", "colours", ColorCodec::Bc1, SurfelCodec::Full, 0.25),
        ("BC1 colours, ISPC", "colours", ColorCodec::Bc1Fast, SurfelCodec::Full, 0.25),
        ("BC1 colours, cluster fit", "colours", ColorCodec::Bc1Cluster, SurfelCodec::Full, 0.25),
        ("compact surfels", "surfels", ColorCodec::Raw, SurfelCodec::Compact, 0.25),
    ] {
        let v = demo_cave(colors, surfels, leaf_m, None, true)?;
        if v.surfels.len() != base.surfels.len() {
            return Err(format!(
                "{name}: {} surfels against {} in the reference scene",
                v.surfels.len(),
                base.surfels.len()
            ));
        }
        variants.push(Variant { name: name.into(), knob: knob.into(), data: v });
    }
    Ok((base, variants))
}

/// Knob of the one-bounce step runs (judged against the reference cut after one bounce).
pub const ONE_BOUNCE_STEP: &str = "step, 1 bounce";
/// Knob of the one-bounce aperture runs.
pub const ONE_BOUNCE_APERTURE: &str = "aperture, 1 bounce";
/// `--step` values swept, coarse to fine (the balanced preset's among them).
pub const MARCH_STEPS: [f32; 4] = [1.0, 0.5, 0.25, 0.1];
/// `--aperture` values swept, wide to narrow (the balanced preset's among them).
pub const MARCH_APERTURES: [f32; 4] = [1.0, 0.7, 0.5, 0.35];

/// Whether a knob is one of the one-bounce march sweeps.
fn one_bounce_knob(knob: &str) -> bool {
    knob == ONE_BOUNCE_STEP || knob == ONE_BOUNCE_APERTURE
}

/// Knob of the runs that count only the bounces run (no tail estimate), judged against the
/// reference cut after the same bounces: propagation alone.
pub const CUT_BOUNCES: &str = "bounces, no tail";

/// Whether a knob's rows are judged against a cut reference rather than full transport.
fn judged_cut(knob: &str) -> bool {
    knob == CUT_BOUNCES || one_bounce_knob(knob)
}

/// Config name of a full-transport step / aperture run ("balanced" at the preset's own value).
fn swept_name(knob: &str, value: f32, preset_value: f32) -> String {
    if value == preset_value { "balanced".into() } else { format!("{knob} {value}") }
}

/// Each knob alone around the balanced preset, and the three presets.
pub fn configs() -> Vec<Config> {
    let base = Settings::preset(Quality::Balanced);
    let mut v = Vec::new();
    let mut add = |knob: &str, name: String, settings: Settings| {
        v.push(Config { name, knob: knob.into(), settings });
    };
    for q in Quality::ALL {
        add("preset", q.name().into(), Settings::preset(q));
    }
    for cones in [4u32, 6, 8, 10, 12, 16].into_iter().filter(|&c| c != base.cones) {
        add("cones", format!("cones {cones}"), Settings { cones, ..base.clone() });
    }
    for a in MARCH_APERTURES.into_iter().filter(|&a| a != base.cone_aperture_scale) {
        add("aperture", format!("aperture {a}"), Settings { cone_aperture_scale: a, ..base.clone() });
    }
    for s in MARCH_STEPS.into_iter().filter(|&s| s != base.step_scale) {
        add("step", format!("step {s}"), Settings { step_scale: s, ..base.clone() });
    }
    // The march alone: one bounce against the reference cut after one bounce, so the bounces not
    // run do not hide what the step and the cone width do (issue 21). No tail: one bounce has none
    // anyway (it needs two bounces' changes), and this says so.
    let one = Settings { bounces: 1, bounce_tail: false, ..base.clone() };
    for a in MARCH_APERTURES {
        add(
            ONE_BOUNCE_APERTURE,
            format!("aperture {a}, 1 bounce"),
            Settings { cone_aperture_scale: a, ..one.clone() },
        );
    }
    for s in MARCH_STEPS {
        add(ONE_BOUNCE_STEP, format!("step {s}, 1 bounce"), Settings { step_scale: s, ..one.clone() });
    }
    for b in [0u32, 1, 2, 4, 8, 16] {
        add("bounces", format!("bounces {b}"), Settings { bounces: b, ..base.clone() });
    }
    // What the tail estimate buys: the balanced preset without it, and propagation alone (the
    // bounces run and nothing more) against the reference cut after the same bounces.
    add("tail", "no tail".into(), Settings { bounce_tail: false, ..base.clone() });
    // What interleaved cone sets buy: every leaf with the same set, as before they came.
    add("interleave", "no interleave".into(), Settings { cone_interleave: false, ..base.clone() });
    for b in TRUNCATED_BOUNCES {
        add(
            CUT_BOUNCES,
            format!("bounces {b}, no tail"),
            Settings { bounces: b, bounce_tail: false, ..base.clone() },
        );
    }
    add("filter", "tricubic".into(), Settings { indirect: IndirectFilter::Tricubic, ..base.clone() });
    for m in [128u32, 1024] {
        add("shadow map", format!("shadow map {m}"), Settings { shadow_map_size: m, ..base.clone() });
    }
    add("radiance", "radiance f16".into(), Settings { radiance_f16: true, ..base.clone() });
    v
}

/// Runtime samples per pixel side when it is compared with the reference. A regular grid aliases
/// on thin bright features: at 4x4 the demo cave's lamp-lit pillar edge, one pixel wide, made the
/// direct light alone 0.034 off its cut reference (0.012 at 8x8, 0.010 at 16x16, the reference's
/// noise 0.0065); the report lists the balanced preset at [`SUPERSAMPLE_CHECK`] so the comparison's
/// own error can be seen.
pub const SUPERSAMPLE: u32 = 8;

/// Supersampling the balanced preset is also judged at, to show the comparison has converged.
pub const SUPERSAMPLE_CHECK: [u32; 3] = [4, 8, 16];

/// Box filter of a `width*k` x `height*k` image down to `width` x `height`; alpha = covered share,
/// colour = mean over the covered samples.
fn box_downsample(big: &[[f32; 4]], width: u32, height: u32, k: u32) -> Vec<[f32; 4]> {
    let big_w = (width * k) as usize;
    let mut out = Vec::with_capacity((width * height) as usize);
    for y in 0..height as usize {
        for x in 0..width as usize {
            let mut acc = [0.0f32; 4];
            for j in 0..k as usize {
                for i in 0..k as usize {
                    let p = big[(y * k as usize + j) * big_w + x * k as usize + i];
                    if p[3] >= 0.5 {
                        for c in 0..3 {
                            acc[c] += p[c];
                        }
                        acc[3] += 1.0;
                    }
                }
            }
            let n = acc[3].max(1.0);
            out.push([acc[0] / n, acc[1] / n, acc[2] / n, acc[3] / (k * k) as f32]);
        }
    }
    out
}

/// Mean FLIP of the runtime's `got` against `reference`, both tonemapped (ACES, sRGB) at the
/// reference's auto-exposure; pixels the runtime leaves uncovered take the reference's value.
fn flip_mean(got: &[[f32; 4]], reference: &[Estimate], width: u32, height: u32) -> f64 {
    let ref_hdr: Vec<[f32; 4]> = reference.iter().map(|e| [e.mean.x, e.mean.y, e.mean.z, 1.0]).collect();
    let exposure = grotto_runtime::cli::render_job::auto_exposure(&ref_hdr);
    let ldr = |p: &[f32; 4]| [0, 1, 2].map(|c| crate::aces_srgb(p[c] * exposure));
    let r8: Vec<u8> = ref_hdr.iter().flat_map(ldr).collect();
    let t8: Vec<u8> =
        got.iter().zip(&ref_hdr).flat_map(|(g, r)| if g[3] >= 0.5 { ldr(g) } else { ldr(r) }).collect();
    let map = nv_flip::flip(
        nv_flip::FlipImageRgb8::with_data(width, height, &r8),
        nv_flip::FlipImageRgb8::with_data(width, height, &t8),
        nv_flip::DEFAULT_PIXELS_PER_DEGREE,
    );
    f64::from(nv_flip::FlipPool::from_image(&map).mean())
}

/// The reference, the runtime and their difference side by side, for finding where an error sits:
/// both images tonemapped at the reference's auto-exposure, the difference per pixel as red where
/// the runtime is brighter and blue where it is darker (luminance, full colour at half the
/// reference's mean luminance), grey where the runtime leaves the pixel uncovered.
pub fn error_map(got: &[[f32; 4]], reference: &[Estimate], width: u32, height: u32) -> Frame {
    let lum = |c: [f32; 3]| 0.2126 * c[0] + 0.7152 * c[1] + 0.0722 * c[2];
    let ref_hdr: Vec<[f32; 4]> = reference.iter().map(|e| [e.mean.x, e.mean.y, e.mean.z, 1.0]).collect();
    let exposure = grotto_runtime::cli::render_job::auto_exposure(&ref_hdr);
    let mean_lum = (ref_hdr.iter().map(|p| f64::from(lum([p[0], p[1], p[2]]))).sum::<f64>()
        / ref_hdr.len().max(1) as f64) as f32;
    let full = (0.5 * mean_lum).max(1e-12);
    let ldr = |p: &[f32; 4]| {
        let [r, g, b] = [0, 1, 2].map(|c| crate::aces_srgb(p[c] * exposure));
        [r, g, b, 255]
    };
    let (w, h) = (width as usize, height as usize);
    let mut frame =
        Frame { width: width * 3, height, hdr: vec![[0.0; 4]; 3 * w * h], ldr: vec![[0; 4]; 3 * w * h] };
    for y in 0..h {
        for x in 0..w {
            let (g, r) = (got[y * w + x], ref_hdr[y * w + x]);
            let row = y * 3 * w;
            frame.hdr[row + x] = r;
            frame.ldr[row + x] = ldr(&r);
            frame.hdr[row + w + x] = g;
            frame.ldr[row + w + x] = ldr(&g);
            let d = lum([g[0], g[1], g[2]]) - lum([r[0], r[1], r[2]]);
            let t = (d.abs() / full).min(1.0);
            let shade = (255.0 * (1.0 - t)) as u8;
            frame.hdr[row + 2 * w + x] = [d, d, d, 1.0];
            frame.ldr[row + 2 * w + x] = if g[3] < 0.5 {
                [128, 128, 128, 255]
            } else if d > 0.0 {
                [255, shade, shade, 255]
            } else {
                [shade, shade, 255, 255]
            };
        }
    }
    frame
}

/// (relative RMSE, reference noise on that scale, bias of the mean).
fn rel_rmse(got: &[[f32; 4]], reference: &[Estimate]) -> (f64, f64, f64) {
    let (mut num, mut den, mut noise) = (0.0f64, 0.0f64, 0.0f64);
    let (mut sum_got, mut sum_ref) = (0.0f64, 0.0f64);
    for (g, r) in got.iter().zip(reference) {
        if g[3] < 0.5 {
            continue;
        }
        for (k, &v) in g[..3].iter().enumerate() {
            let d = f64::from(v - r.mean[k]);
            num += d * d;
            den += f64::from(r.mean[k]).powi(2);
            noise += f64::from(r.std_err[k]).powi(2);
            sum_got += f64::from(v);
            sum_ref += f64::from(r.mean[k]);
        }
    }
    let den = den.max(1e-30);
    ((num / den).sqrt(), (noise / den).sqrt(), sum_got / sum_ref.max(1e-30) - 1.0)
}

/// Runs every config on every scene, then the balanced preset on each scene's package variants.
pub fn sweep(
    gpu: &Gpu,
    scenes: &[SweepScene],
    configs: &[Config],
    width: u32,
    height: u32,
    error_maps: Option<&std::path::Path>,
    mut progress: impl FnMut(&str, &str),
) -> grotto_runtime::Result<Vec<Row>> {
    let mut rows = Vec::new();
    let balanced = Config {
        name: "balanced".into(),
        knob: "preset".into(),
        settings: Settings::preset(Quality::Balanced),
    };
    for s in scenes {
        // Warm-up: the first run on a device compiles pipelines inside the driver; not measured.
        if let Some(c) = configs.first() {
            let mut r = Renderer::new(gpu, &s.data, c.settings.clone())?;
            r.settle(|_, _| {})?;
            r.render(&s.camera, width, height)?;
        }
        for c in configs {
            progress(&s.name, &c.name);
            rows.push(run_one(gpu, s, &s.data, c, width, height, error_maps)?);
        }
        for v in &s.variants {
            progress(&s.name, &v.name);
            let c = Config { name: v.name.clone(), knob: v.knob.clone(), ..balanced.clone() };
            rows.push(run_one(gpu, s, &v.data, &c, width, height, error_maps)?);
        }
    }
    Ok(rows)
}

/// One runtime run of `config` on `data` (the scene `s` or a package variant of it), judged
/// against `s`'s reference; with `error_maps`, its [`error_map`]s are written there.
fn run_one(
    gpu: &Gpu,
    s: &SweepScene,
    data: &SceneData,
    c: &Config,
    width: u32,
    height: u32,
    error_maps: Option<&std::path::Path>,
) -> grotto_runtime::Result<Row> {
    let mut settings = c.settings.clone();
    settings.exposure = 1.0;
    let mut r = Renderer::new(gpu, data, settings)?;
    let mut light_ms = 0.0;
    let mut pass_ms: BTreeMap<String, f64> = BTreeMap::new();
    // Light until converged or the budget is spent, summing each pass's GPU time.
    loop {
        let plan = r.update_light()?;
        for step in plan.steps.iter().filter(|st| st.run) {
            let ms = r.stats().last_ms.get(&step.pass).copied().unwrap_or(0.0);
            light_ms += ms;
            *pass_ms.entry(step.pass.name().into()).or_default() += ms;
        }
        if !plan.runs(Pass::Propagate) {
            break;
        }
    }
    r.render(&s.camera, width, height)?;
    let frame_ms: f64 = [Pass::Gbuffer, Pass::Shade]
        .iter()
        .map(|p| {
            let ms = r.stats().last_ms.get(p).copied().unwrap_or(0.0);
            *pass_ms.entry(p.name().into()).or_default() += ms;
            ms
        })
        .sum();
    // Before the larger renders below grow the render targets.
    let gpu_bytes = r.gpu_bytes();
    // The reference integrates each pixel's area; the runtime samples pixel centres. Compare like
    // with like: the error image is the runtime at SUPERSAMPLE^2 samples per pixel, box-filtered
    // (the frame above is the one timed).
    let mut supersampled = |k: u32| -> grotto_runtime::Result<Vec<[f32; 4]>> {
        let (big, _) = r.render(&s.camera, width * k, height * k)?;
        Ok(box_downsample(&big.hdr, width, height, k))
    };
    let hdr = supersampled(SUPERSAMPLE)?;
    let supersample_errors = if c.name == "balanced" {
        SUPERSAMPLE_CHECK
            .iter()
            .map(|&k| {
                let img = if k == SUPERSAMPLE { hdr.clone() } else { supersampled(k)? };
                Ok((k, rel_rmse(&img, &s.reference).0))
            })
            .collect::<grotto_runtime::Result<Vec<_>>>()?
    } else {
        Vec::new()
    };
    let (err, noise, bias) = rel_rmse(&hdr, &s.reference);
    let flip = flip_mean(&hdr, &s.reference, width, height);
    let cut =
        judged_cut(&c.knob).then(|| s.truncated.iter().find(|(k, _)| *k == c.settings.bounces)).flatten();
    let truncated = cut.map(|(_, img)| {
        let (e, _, b) = rel_rmse(&hdr, img);
        (e, b)
    });
    if let Some(dir) = error_maps {
        let stem = format!("{}-{}", slug(&s.name), slug(&c.name));
        let write = |name: String, reference: &[Estimate]| {
            let path = dir.join(name);
            std::fs::create_dir_all(dir).map_err(|e| grotto_runtime::cli::export::output_error(&path, e))?;
            let map = error_map(&hdr, reference, width, height);
            grotto_runtime::cli::image_out::write_frame(&map, &path.with_extension("png"))?;
            grotto_runtime::cli::image_out::write_frame(&map, &path.with_extension("exr"))
        };
        write(stem.clone(), &s.reference)?;
        if let Some((k, img)) = cut {
            write(format!("{stem}-cut{k}"), img)?;
        }
    }
    Ok(Row {
        scene: s.name.clone(),
        config: c.name.clone(),
        knob: c.knob.clone(),
        rel_rmse: err,
        reference_noise: noise,
        bias,
        flip,
        truncated,
        light_ms,
        frame_ms,
        bounces: r.stats().bounces_done,
        gpu_bytes,
        pass_ms,
        supersample_errors,
    })
}

/// Rows on the Pareto front of (total time, error) within one scene.
pub fn pareto(rows: &[Row]) -> Vec<bool> {
    rows.iter()
        .map(|a| {
            let ta = a.light_ms + a.frame_ms;
            !rows.iter().any(|b| {
                let tb = b.light_ms + b.frame_ms;
                (tb <= ta && b.rel_rmse < a.rel_rmse) || (tb < ta && b.rel_rmse <= a.rel_rmse)
            })
        })
        .collect()
}

/// Whether fast < balanced < high in time and fast > balanced > high in error on `rows` (one scene).
/// A finer preset may tie a coarser one (within [`MONOTONE_SLACK`]) only where it is at the
/// reference's own noise ([`NOISE_FLOOR`] times it): no preset can measure better than that
/// (the furnace, where the bounce tail makes every preset exact).
pub fn presets_monotone(rows: &[Row]) -> Option<bool> {
    let get = |q: Quality| rows.iter().find(|r| r.knob == "preset" && r.config == q.name());
    let (f, b, h) = (get(Quality::Fast)?, get(Quality::Balanced)?, get(Quality::High)?);
    let t = |r: &Row| r.light_ms + r.frame_ms;
    let better = |coarse: &Row, fine: &Row| {
        fine.rel_rmse < coarse.rel_rmse
            || (fine.rel_rmse <= coarse.rel_rmse + MONOTONE_SLACK
                && fine.rel_rmse <= NOISE_FLOOR * fine.reference_noise)
    };
    Some(t(f) < t(b) && t(b) < t(h) && better(f, b) && better(b, h))
}

/// An error within this factor of the reference's own noise is as low as the reference can judge.
pub const NOISE_FLOOR: f64 = 1.1;

/// How much worse (in relative RMSE or |bias|) a finer row may be than the coarser one before a
/// knob's rows count as not monotone. Every row is judged against the same reference image, so its noise moves
/// all rows alike; what is left is the runtime's own rounding, far below this.
pub const MONOTONE_SLACK: f64 = 0.002;

/// A knob's rows from coarse to fine (config names), the full-transport ones around the balanced
/// preset and the one-bounce ones.
pub fn knob_series(knob: &str) -> Vec<String> {
    let base = Settings::preset(Quality::Balanced);
    match knob {
        "step" => MARCH_STEPS.iter().map(|&s| swept_name(knob, s, base.step_scale)).collect(),
        "aperture" => {
            MARCH_APERTURES.iter().map(|&a| swept_name(knob, a, base.cone_aperture_scale)).collect()
        }
        ONE_BOUNCE_STEP => MARCH_STEPS.iter().map(|s| format!("step {s}, 1 bounce")).collect(),
        ONE_BOUNCE_APERTURE => MARCH_APERTURES.iter().map(|a| format!("aperture {a}, 1 bounce")).collect(),
        _ => Vec::new(),
    }
}

/// The error of `knob`'s rows on one scene from coarse to fine (against the cut reference for the
/// one-bounce knobs), or None where a row is missing. For the step it is the relative RMSE. For the
/// aperture it is |bias|: with the cone count fixed, a narrower cone covers less of the hemisphere
/// (9 cones at `--aperture` 0.35 cover 12% of it), so its RMSE grows with the gaps between cones;
/// what the aperture must not change is the energy (issue 21: "wide cones should blur, not darken").
pub fn knob_errors(rows: &[Row], knob: &str) -> Option<Vec<f64>> {
    let aperture = knob == "aperture" || knob == ONE_BOUNCE_APERTURE;
    knob_series(knob)
        .iter()
        .map(|name| {
            let r = rows.iter().find(|r| &r.config == name)?;
            let (e, b) = if judged_cut(knob) { r.truncated? } else { (r.rel_rmse, r.bias) };
            Some(if aperture { b.abs() } else { e })
        })
        .collect()
}

/// Whether each finer row of `knob` is at least as accurate as the coarser one (`knob_errors`),
/// within `MONOTONE_SLACK`.
pub fn knob_monotone(rows: &[Row], knob: &str) -> Option<bool> {
    let e = knob_errors(rows, knob)?;
    Some(e.windows(2).all(|w| w[1] <= w[0] + MONOTONE_SLACK))
}

/// The knobs whose rows must get more accurate as they get finer.
pub const MONOTONE_KNOBS: [&str; 4] = ["step", "aperture", ONE_BOUNCE_STEP, ONE_BOUNCE_APERTURE];

/// A monotone check in the report: yes, **no**, or `missing` where rows were not measured.
fn verdict(v: Option<bool>, missing: &'static str) -> &'static str {
    match v {
        Some(true) => "yes",
        Some(false) => "**no**",
        None => missing,
    }
}

/// File-name form of a scene name.
pub fn slug(name: &str) -> String {
    name.chars().map(|c| if c.is_ascii_alphanumeric() { c.to_ascii_lowercase() } else { '-' }).collect()
}

/// docs/accuracy.md.
pub fn report(
    scenes: &[SweepScene],
    rows: &[Row],
    device: &str,
    width: u32,
    height: u32,
    command: &str,
) -> String {
    let mut s = String::new();
    let _ = writeln!(s, "# Accuracy against time\n");
    let _ = writeln!(
        s,
        "Generated by `{command}` (do not edit by hand). Device for the runtime's GPU times: {device}. \
         Images {width}x{height}. Reference: `grotto-reference`, Monte Carlo path tracing on the same surfels, \
         lights and albedo, each pixel integrated over its area; the runtime is rendered at {SUPERSAMPLE}x{SUPERSAMPLE} \
         samples per pixel and box-filtered so both estimate the same pixel values (the frame time is for one \
         frame at {width}x{height}). Error over the pixels the runtime covers: relative RMSE of linear radiance \
         (the reference's own noise on the same scale is listed so it can be seen to be far below the errors \
         it judges), bias = sum(runtime) / sum(reference) - 1, and mean FLIP (NVIDIA's perceptual metric, \
         `nv-flip`, 67 pixels per degree) of both images tonemapped at the reference's auto-exposure. Time: \
         milliseconds of the passes (timestamp queries on a hardware adapter, CPU wall time per pass on a \
         software one: docs/runtime.md, \"Per-pass GPU times\") to converge the light (shadow maps, injection, every bounce until \
         converged or the budget is spent) and to draw one frame. Memory: GPU buffers and textures the \
         renderer holds. Knobs vary one at a time around the balanced preset; package knobs (SVO depth, \
         colour codec, compact surfels) rebuild the scene's package and run the balanced preset on it, against the same \
         reference. Pareto-optimal rows (no other row is both faster and more accurate) are marked *.\n"
    );
    let _ = writeln!(s, "## Presets (`grotto render --quality fast|balanced|high`)\n");
    let _ = writeln!(s, "Relative RMSE / GPU ms to converge and draw one frame, per scene.\n");
    let _ = writeln!(
        s,
        "| preset | {} |",
        scenes.iter().map(|sc| sc.name.as_str()).collect::<Vec<_>>().join(" | ")
    );
    let _ = writeln!(s, "|---|{}", "---:|".repeat(scenes.len()));
    for q in Quality::ALL {
        let cells: Vec<String> = scenes
            .iter()
            .map(|sc| {
                rows.iter()
                    .find(|r| r.scene == sc.name && r.knob == "preset" && r.config == q.name())
                    .map_or("-".into(), |r| format!("{:.4} / {:.0}", r.rel_rmse, r.light_ms + r.frame_ms))
            })
            .collect();
        let _ = writeln!(s, "| {} | {} |", q.name(), cells.join(" | "));
    }
    let monotone: Vec<&str> = scenes
        .iter()
        .filter(|sc| {
            let mine: Vec<Row> = rows.iter().filter(|r| r.scene == sc.name).cloned().collect();
            presets_monotone(&mine) != Some(true)
        })
        .map(|sc| sc.name.as_str())
        .collect();
    let _ = writeln!(
        s,
        "\nEach preset slower and more accurate than the one below it on every scene (or as accurate \
         where both are within {NOISE_FLOOR} times the reference's own noise): {}\n",
        if monotone.is_empty() { "yes".to_string() } else { format!("**no** ({})", monotone.join(", ")) }
    );
    let checked: Vec<&Row> = scenes
        .iter()
        .filter_map(|sc| rows.iter().find(|r| r.scene == sc.name && !r.supersample_errors.is_empty()))
        .collect();
    if !checked.is_empty() {
        let _ = writeln!(
            s,
            "The comparison's own error: the balanced preset's relative RMSE with the runtime sampled at k x k \
             points per pixel before the box filter (the report uses {SUPERSAMPLE}x{SUPERSAMPLE}), beside the \
             reference's noise. A regular grid aliases on thin bright features that the reference integrates \
             exactly; where two columns agree, the comparison no longer adds error of its own.\n"
        );
        let heads: Vec<String> = SUPERSAMPLE_CHECK.iter().map(|k| format!("{k}x{k}")).collect();
        let _ = writeln!(s, "| scene | {} | reference noise |", heads.join(" | "));
        let _ = writeln!(s, "|---|{}---:|", "---:|".repeat(heads.len()));
        for r in checked {
            let cells: Vec<String> = r.supersample_errors.iter().map(|(_, e)| format!("{e:.4}")).collect();
            let _ = writeln!(s, "| {} | {} | {:.4} |", r.scene, cells.join(" | "), r.reference_noise);
        }
        let _ = writeln!(s);
    }
    let _ = writeln!(
        s,
        "Finer march knobs more accurate: `step` 1 > 0.5 > 0.25 > 0.1 in relative RMSE, `aperture` \
         1 > 0.7 > 0.5 > 0.35 in |bias| (with the cone count fixed a narrower cone leaves gaps between cones, \
         which raises the RMSE; the aperture must change blur, not energy), each finer row at most \
         {MONOTONE_SLACK} above the coarser one; with the balanced preset's {} bounces against full \
         transport, and with 1 bounce against the reference cut after one bounce:\n",
        Settings::preset(Quality::Balanced).bounces
    );
    let _ = writeln!(
        s,
        "| knob | {} |",
        scenes.iter().map(|sc| sc.name.as_str()).collect::<Vec<_>>().join(" | ")
    );
    let _ = writeln!(s, "|---|{}", ":-:|".repeat(scenes.len()));
    for knob in MONOTONE_KNOBS {
        let cells: Vec<&str> = scenes
            .iter()
            .map(|sc| {
                let mine: Vec<Row> = rows.iter().filter(|r| r.scene == sc.name).cloned().collect();
                verdict(knob_monotone(&mine, knob), "-")
            })
            .collect();
        let _ = writeln!(s, "| {knob} | {} |", cells.join(" | "));
    }
    let _ = writeln!(s);
    for sc in scenes {
        let all: Vec<Row> = rows.iter().filter(|r| r.scene == sc.name).cloned().collect();
        // The one-bounce march rows are judged against the cut reference, in their own table.
        let (march, mine): (Vec<Row>, Vec<Row>) = all.iter().cloned().partition(|r| one_bounce_knob(&r.knob));
        let front = pareto(&mine);
        let noise = mine.first().map_or(0.0, |r| r.reference_noise);
        let _ = writeln!(s, "## {}\n", sc.name);
        let _ = writeln!(s, "![{} error against time](accuracy/{}.svg)\n", sc.name, slug(&sc.name));
        let _ = writeln!(
            s,
            "{}. Reference: {} paths per pixel in {:.1} s, own noise {:.4} (relative RMSE scale). {} leaves, {} surfels.\n",
            sc.description,
            sc.spp,
            sc.reference_s,
            noise,
            sc.data.leaves.len(),
            sc.data.surfels.len()
        );
        let _ = writeln!(
            s,
            "| config | knob | rel. RMSE | bias | FLIP | light ms | frame ms | bounces | GPU MiB | Pareto |"
        );
        let _ = writeln!(s, "|---|---|---:|---:|---:|---:|---:|---:|---:|:-:|");
        let mut order: Vec<usize> = (0..mine.len()).collect();
        order.sort_by(|&a, &b| {
            (mine[a].light_ms + mine[a].frame_ms).total_cmp(&(mine[b].light_ms + mine[b].frame_ms))
        });
        for i in order {
            let r = &mine[i];
            let _ = writeln!(
                s,
                "| {} | {} | {:.4} | {:+.3} | {:.4} | {:.1} | {:.1} | {} | {:.1} | {} |",
                r.config,
                r.knob,
                r.rel_rmse,
                r.bias,
                r.flip,
                r.light_ms,
                r.frame_ms,
                r.bounces,
                r.gpu_bytes as f64 / (1 << 20) as f64,
                if front[i] { "*" } else { "" }
            );
        }
        let _ = writeln!(
            s,
            "\nPresets monotone (each slower and more accurate than the one below): {}\n",
            verdict(presets_monotone(&mine), "not measured")
        );
        if !march.is_empty() {
            let _ = writeln!(
                s,
                "The march alone: the balanced preset at one bounce, `--step` and `--aperture` varied, against \
                 the reference cut after one bounce (so the bounces not run do not hide what the march does).\n"
            );
            let _ = writeln!(s, "| config | rel. RMSE (cut reference) | bias (cut reference) | light ms |");
            let _ = writeln!(s, "|---|---:|---:|---:|");
            for knob in [ONE_BOUNCE_STEP, ONE_BOUNCE_APERTURE] {
                for name in knob_series(knob) {
                    if let Some(r) = march.iter().find(|r| r.config == name) {
                        let (e, b) = r.truncated.unwrap_or((f64::NAN, f64::NAN));
                        let _ = writeln!(s, "| {} | {e:.4} | {b:+.3} | {:.1} |", r.config, r.light_ms);
                    }
                }
            }
            let _ = writeln!(s);
        }
        let mono_line = |knob: &str| verdict(knob_monotone(&all, knob), "not measured");
        let _ = writeln!(
            s,
            "Finer is more accurate: step {}, aperture {}; at one bounce against the cut reference: step {}, aperture {}.\n",
            mono_line("step"),
            mono_line("aperture"),
            mono_line(ONE_BOUNCE_STEP),
            mono_line(ONE_BOUNCE_APERTURE)
        );
        let cut: Vec<&Row> = mine.iter().filter(|r| r.knob == CUT_BOUNCES && r.truncated.is_some()).collect();
        if !cut.is_empty() {
            let _ = writeln!(
                s,
                "Propagation alone: the runtime after k bounces without the tail estimate, against the \
                 reference cut after the same k bounces (the rows above compare with full transport, so they \
                 also count the bounces not run).\n"
            );
            let _ = writeln!(s, "| bounces | rel. RMSE (cut reference) | bias (cut reference) |");
            let _ = writeln!(s, "|---:|---:|---:|");
            for r in cut {
                let (e, b) = r.truncated.unwrap_or_default();
                let _ = writeln!(s, "| {} | {e:.4} | {b:+.3} |", r.bounces);
            }
            let _ = writeln!(s);
        }
    }
    s
}

/// An SVG of error against total GPU time (log-log) for one scene's rows: every run as a point, the
/// Pareto front as a line, the presets labelled.
pub fn plot_svg(scene: &str, rows: &[Row]) -> String {
    use plotters::prelude::*;
    // Full-transport rows only: the one-bounce march rows answer another question.
    let mine: Vec<&Row> = rows.iter().filter(|r| r.scene == scene && !one_bounce_knob(&r.knob)).collect();
    let t = |r: &Row| (r.light_ms + r.frame_ms).max(0.1);
    let (t_lo, t_hi) = mine.iter().fold((f64::MAX, f64::MIN), |(a, b), r| (a.min(t(r)), b.max(t(r))));
    let (e_lo, e_hi) =
        mine.iter().fold((f64::MAX, f64::MIN), |(a, b), r| (a.min(r.rel_rmse), b.max(r.rel_rmse)));
    let mut svg = String::new();
    {
        let root = SVGBackend::with_string(&mut svg, (640, 420)).into_drawing_area();
        let _ = root.fill(&WHITE);
        let chart = ChartBuilder::on(&root)
            .caption(format!("{scene}: error against GPU time"), ("sans-serif", 18))
            .margin(12)
            .x_label_area_size(40)
            .y_label_area_size(56)
            .build_cartesian_2d(
                (t_lo * 0.8..t_hi * 1.25).log_scale(),
                (e_lo.max(1e-4) * 0.8..e_hi * 1.25).log_scale(),
            );
        let Ok(mut chart) = chart else { return svg_fallback(scene) };
        let _ = chart
            .configure_mesh()
            .x_desc("GPU time to converge + one frame (ms)")
            .y_desc("relative RMSE")
            .draw();
        let _ = chart.draw_series(mine.iter().map(|r| Circle::new((t(r), r.rel_rmse), 3, BLUE.filled())));
        let owned: Vec<Row> = mine.iter().map(|r| (*r).clone()).collect();
        let front = pareto(&owned);
        let mut pts: Vec<(f64, f64)> =
            owned.iter().zip(&front).filter(|(_, f)| **f).map(|(r, _)| (t(r), r.rel_rmse)).collect();
        pts.sort_by(|a, b| a.0.total_cmp(&b.0));
        let _ = chart.draw_series(LineSeries::new(pts, &RED));
        for r in mine.iter().filter(|r| r.knob == "preset") {
            let _ = chart.draw_series(std::iter::once(Text::new(
                r.config.clone(),
                (t(r), r.rel_rmse),
                ("sans-serif", 14).into_font().color(&BLACK),
            )));
        }
        let _ = root.present();
    }
    svg
}

fn svg_fallback(scene: &str) -> String {
    format!("<svg xmlns=\"http://www.w3.org/2000/svg\"><text x=\"10\" y=\"20\">{scene}: no data</text></svg>")
}

/// The many-lights measurement: the demo cave (raw colours) relit by a lamp string of `lamps`
/// 8 W lamps, its path-traced reference (every lamp with shadow rays), and the runtime's
/// balanced preset with the shadow-map budget, its fallback and the light cutoff varied. Returns
/// the scene and one row per configuration (knob "budget" or "cutoff").
pub fn lights_sweep(
    gpu: &Gpu,
    lamps: usize,
    width: u32,
    height: u32,
    spp: u32,
    mut progress: impl FnMut(&str),
) -> Result<(SweepScene, Vec<Row>), String> {
    use grotto_runtime::cli::render_job::{STRING_LAMP_LIFT_M, STRING_LAMP_W};
    use grotto_runtime::render::renderer::ShadowFallback;
    let mut data = demo_cave(ColorCodec::Raw, SurfelCodec::Full, 0.25, None, true)?;
    data.lights = data.lamp_string(lamps, STRING_LAMP_W, STRING_LAMP_LIFT_M);
    let camera = Camera::from_scene(&data.cameras[0]);
    let scene = SurfelScene::from_scene(&data, Settings::default().splat_scale);
    progress("reference");
    let t0 = std::time::Instant::now();
    let reference = scene.render(&camera, width, height, spp, &PathSettings::for_scene(&data), 1);
    let s = SweepScene {
        name: format!("demo cave, {} lamps", data.lights.len()),
        description: format!(
            "the synthetic demo cave (80k points, 0.25 m leaves, raw colours) relit by a lamp string of {} 8 W lamps spread over its floors, camera at the entrance",
            data.lights.len()
        ),
        camera,
        reference,
        reference_s: t0.elapsed().as_secs_f64(),
        spp,
        truncated: Vec::new(),
        variants: Vec::new(),
        data,
    };
    let base = Settings::preset(Quality::Balanced);
    let mut configs = Vec::new();
    for budget in [0u32, 4, 16, 64] {
        for fallback in [ShadowFallback::Cone, ShadowFallback::None] {
            if budget as usize >= s.data.lights.len() && fallback == ShadowFallback::None {
                continue;
            }
            configs.push(Config {
                name: format!("budget {budget}, rest {}", fallback.name()),
                knob: "budget".into(),
                settings: Settings { shadowed_lights: budget, shadow_fallback: fallback, ..base.clone() },
            });
        }
    }
    for cutoff in [0.0f32, 2e-3, 2e-2] {
        configs.push(Config {
            name: format!("cutoff {cutoff:e} W/m^2"),
            knob: "cutoff".into(),
            settings: Settings { light_cutoff_w_m2: cutoff, ..base.clone() },
        });
    }
    // Warm-up: pipelines compile on the first run.
    let mut r = Renderer::new(gpu, &s.data, base.clone()).map_err(|e| e.to_string())?;
    r.settle(|_, _| {}).map_err(|e| e.to_string())?;
    let mut rows = Vec::new();
    for c in &configs {
        progress(&c.name);
        rows.push(run_one(gpu, &s, &s.data, c, width, height, None).map_err(|e| e.to_string())?);
    }
    Ok((s, rows))
}

/// Markdown for [`lights_sweep`]'s rows.
pub fn lights_report(
    s: &SweepScene,
    rows: &[Row],
    device: &str,
    width: u32,
    height: u32,
    command: &str,
) -> String {
    let mut md = String::new();
    let _ = writeln!(md, "# Many lights: the shadow-map budget and the light cutoff against the reference\n");
    let _ = writeln!(md, "Generated by `{command}` on {device}; do not edit by hand.\n");
    let _ = writeln!(
        md,
        "Scene: {}. Reference: {} paths per pixel at {width}x{height}, every lamp sampled with a shadow ray at every path vertex ({:.0} s). \
         The runtime runs the balanced preset until converged, rendered at {SUPERSAMPLE}x{SUPERSAMPLE} samples per pixel and box-filtered; \
         error = relative RMSE against the reference, bias = relative error of the mean. Light ms = shadow maps + injection + mip + env + \
         propagation to convergence; frame ms = G-buffer + shade of one frame.\n",
        s.description, s.spp, s.reference_s
    );
    let _ = writeln!(
        md,
        "| configuration | error | bias | FLIP | light (ms) | frame (ms) | shadow (ms) | inject (ms) |"
    );
    let _ = writeln!(md, "|---|---:|---:|---:|---:|---:|---:|---:|");
    for r in rows {
        let _ = writeln!(
            md,
            "| {} | {:.4} | {:+.4} | {:.4} | {:.0} | {:.0} | {:.0} | {:.0} |",
            r.config,
            r.rel_rmse,
            r.bias,
            r.flip,
            r.light_ms,
            r.frame_ms,
            r.pass_ms.get("shadow").copied().unwrap_or(0.0),
            r.pass_ms.get("inject").copied().unwrap_or(0.0)
        );
    }
    let _ = writeln!(
        md,
        "\nBudget rows use the default cutoff ({:e} W/m^2); cutoff rows the default budget ({} lamps with shadow maps, the rest with SVO cone shadows).",
        Settings::default().light_cutoff_w_m2,
        Settings::default().shadowed_lights
    );
    md
}

#[cfg(test)]
mod tests {
    use super::*;

    fn row(config: &str, knob: &str, rel_rmse: f64, bias: f64, cut: Option<(f64, f64)>) -> Row {
        Row {
            scene: "s".into(),
            config: config.into(),
            knob: knob.into(),
            rel_rmse,
            reference_noise: 0.01,
            bias,
            flip: 0.0,
            truncated: cut,
            light_ms: 1.0,
            frame_ms: 1.0,
            bounces: 4,
            gpu_bytes: 0,
            pass_ms: BTreeMap::new(),
            supersample_errors: Vec::new(),
        }
    }

    #[test]
    fn march_knobs_are_judged_coarse_to_fine_on_their_own_measure() {
        let steps = |errors: [f64; 3]| {
            vec![
                row("balanced", "preset", 0.20, -0.1, None),
                row("step 1", "step", errors[0], -0.1, None),
                row("step 0.25", "step", errors[1], -0.1, None),
                row("step 0.1", "step", errors[2], -0.1, None),
            ]
        };
        // step 1 > balanced (0.5) > 0.25 > 0.1, within the slack.
        assert_eq!(knob_monotone(&steps([0.25, 0.19, 0.1915]), "step"), Some(true));
        assert_eq!(knob_monotone(&steps([0.25, 0.19, 0.195]), "step"), Some(false));
        assert_eq!(knob_monotone(&steps([0.18, 0.17, 0.16]), "step"), Some(false));
        assert_eq!(knob_monotone(&steps([0.25, 0.19, 0.18])[1..], "step"), None, "balanced missing");
        // The aperture is judged by |bias|: a narrow cone's larger RMSE (gaps) does not count.
        let ap: Vec<Row> = MARCH_APERTURES
            .iter()
            .zip([(0.15, -0.04), (0.14, -0.03), (0.15, -0.02), (0.30, 0.01)])
            .map(|(a, cut)| {
                row(&format!("aperture {a}, 1 bounce"), ONE_BOUNCE_APERTURE, 0.5, -0.3, Some(cut))
            })
            .collect();
        assert_eq!(knob_errors(&ap, ONE_BOUNCE_APERTURE), Some(vec![0.04, 0.03, 0.02, 0.01]));
        assert_eq!(knob_monotone(&ap, ONE_BOUNCE_APERTURE), Some(true));
        // One-bounce runs are judged against the cut reference, not full transport.
        let st: Vec<Row> = MARCH_STEPS
            .iter()
            .zip([0.2, 0.15, 0.14, 0.13])
            .map(|(s, e)| row(&format!("step {s}, 1 bounce"), ONE_BOUNCE_STEP, 0.9 - e, -0.3, Some((e, 0.0))))
            .collect();
        assert_eq!(knob_monotone(&st, ONE_BOUNCE_STEP), Some(true));
        assert!(judged_cut(ONE_BOUNCE_STEP) && judged_cut(CUT_BOUNCES) && !judged_cut("step"));
        // The bounce sweep runs with the tail, so it is judged against full transport.
        assert!(!judged_cut("bounces"));
    }

    #[test]
    fn presets_may_tie_only_at_the_reference_noise() {
        let presets = |e: [f64; 3], ms: [f64; 3]| -> Vec<Row> {
            ["fast", "balanced", "high"]
                .iter()
                .zip(e.iter().zip(ms))
                .map(|(name, (&e, ms))| Row { light_ms: ms, ..row(name, "preset", e, 0.0, None) })
                .collect()
        };
        // Reference noise 0.01 (row()): strictly better, or tied at 0.011 and below.
        assert_eq!(presets_monotone(&presets([0.3, 0.2, 0.1], [1.0, 2.0, 3.0])), Some(true));
        assert_eq!(presets_monotone(&presets([0.0105, 0.0105, 0.0105], [1.0, 2.0, 3.0])), Some(true));
        assert_eq!(presets_monotone(&presets([0.2, 0.2, 0.1], [1.0, 2.0, 3.0])), Some(false));
        assert_eq!(presets_monotone(&presets([0.3, 0.2, 0.1], [1.0, 3.0, 2.0])), Some(false));
        assert_eq!(presets_monotone(&presets([0.3, 0.2, 0.1], [1.0, 2.0, 3.0])[..2]), None);
    }
}
