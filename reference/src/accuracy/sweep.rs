//! Running the sweep: every scene under every configuration, each frame's error against the
//! reference (relative RMSE, bias, FLIP), its time and memory; and the many-lights sweep.

use std::collections::BTreeMap;

use grotto_preprocess::build::{ColorCodec, SurfelCodec};
use grotto_runtime::gpu::Gpu;
use grotto_runtime::light::plan::Pass;
use grotto_runtime::render::{Frame, Renderer};
use grotto_runtime::scene::data::SceneData;
use grotto_runtime::settings::{Quality, Settings};
use grotto_runtime::view::camera::Camera;

use crate::accuracy::configs::Config;
use crate::accuracy::configs::Row;
use crate::accuracy::configs::judged_cut;
use crate::accuracy::configs::slug;
use crate::accuracy::scenes::SweepScene;
use crate::accuracy::scenes::demo_cave;
use crate::tracer::{Estimate, PathSettings, SurfelScene};

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
pub(crate) fn box_downsample(big: &[[f32; 4]], width: u32, height: u32, k: u32) -> Vec<[f32; 4]> {
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
pub(crate) fn flip_mean(got: &[[f32; 4]], reference: &[Estimate], width: u32, height: u32) -> f64 {
    let ref_hdr: Vec<[f32; 4]> = reference.iter().map(|e| [e.mean.x, e.mean.y, e.mean.z, 1.0]).collect();
    let exposure = grotto_runtime::render::auto_exposure(&ref_hdr);
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
    let exposure = grotto_runtime::render::auto_exposure(&ref_hdr);
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
pub(crate) fn rel_rmse(got: &[[f32; 4]], reference: &[Estimate]) -> (f64, f64, f64) {
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
pub(crate) fn run_one(
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
    use grotto_runtime::engine::{STRING_LAMP_LIFT_M, STRING_LAMP_W};
    use grotto_runtime::settings::ShadowFallback;
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
