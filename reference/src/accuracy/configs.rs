//! What the sweep runs: each quality knob alone around the balanced preset, and the presets; the
//! rows a run records.

use std::collections::BTreeMap;

use grotto_runtime::scene::data::SceneData;
use grotto_runtime::settings::{IndirectFilter, Quality, Settings};
use serde::Serialize;

/// A package variant of a sweep scene.
#[derive(Debug)]
pub struct Variant {
    /// Config name in the report.
    pub name: String,
    pub(crate) knob: String,
    pub(crate) data: SceneData,
}

/// Bounce counts with a truncated reference.
pub const TRUNCATED_BOUNCES: [u32; 4] = [0, 1, 2, 4];

/// One runtime configuration.
#[derive(Clone, Debug, Serialize)]
pub struct Config {
    pub name: String,
    /// Which knob it varies ("preset" for the presets, "baseline").
    pub knob: String,
    pub(crate) settings: Settings,
}

/// One measured run.
#[derive(Clone, Debug, Serialize)]
pub struct Row {
    pub(crate) scene: String,
    pub(crate) config: String,
    pub(crate) knob: String,
    /// sqrt(sum |runtime - reference|^2 / sum |reference|^2) over the pixels both see.
    pub rel_rmse: f64,
    /// The reference's own noise on the same scale: sqrt(sum se^2 / sum |reference|^2).
    pub reference_noise: f64,
    /// Signed error of the mean: sum(runtime) / sum(reference) - 1 over the same pixels and channels
    /// (positive: the runtime is too bright).
    pub(crate) bias: f64,
    /// Mean FLIP (NVIDIA's perceptual difference, 0 = identical, 1 = maximal; `nv-flip`, default
    /// 67 pixels per degree) between the tonemapped runtime and reference images, both at the
    /// exposure that auto-exposure picks for the reference.
    pub(crate) flip: f64,
    /// For "bounces k" runs with a truncated reference: (relative RMSE, bias) against the reference
    /// cut after the same k bounces.
    pub(crate) truncated: Option<(f64, f64)>,
    /// GPU milliseconds to converge the light (shadow + inject + every bounce) and to draw a
    /// frame (gbuffer + shade).
    pub(crate) light_ms: f64,
    pub(crate) frame_ms: f64,
    pub(crate) bounces: u32,
    pub(crate) gpu_bytes: u64,
    pub(crate) pass_ms: BTreeMap<String, f64>,
    /// For the balanced preset: (k, relative RMSE with the runtime at k x k samples per pixel) for
    /// k in [`SUPERSAMPLE_CHECK`]; empty for the other rows.
    pub(crate) supersample_errors: Vec<(u32, f64)>,
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
pub(crate) fn one_bounce_knob(knob: &str) -> bool {
    knob == ONE_BOUNCE_STEP || knob == ONE_BOUNCE_APERTURE
}

/// Knob of the runs that count only the bounces run (no tail estimate), judged against the
/// reference cut after the same bounces: propagation alone.
pub const CUT_BOUNCES: &str = "bounces, no tail";

/// Whether a knob's rows are judged against a cut reference rather than full transport.
pub(crate) fn judged_cut(knob: &str) -> bool {
    knob == CUT_BOUNCES || one_bounce_knob(knob)
}

/// Config name of a full-transport step / aperture run ("balanced" at the preset's own value).
pub(crate) fn swept_name(knob: &str, value: f32, preset_value: f32) -> String {
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
    // run do not hide what the step and the cone width do. No tail: one bounce has none
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
    // The gather the balanced and high presets replaced: the composited cone march at the
    // aperture it had (0.5), to show what rays buy on each scene.
    let march = Settings { cone_rays: false, cone_aperture_scale: 0.5, ..base.clone() };
    let high_march =
        Settings { cone_rays: false, cone_aperture_scale: 0.5, ..Settings::preset(Quality::High) };
    add("composited march", "composited march".into(), march.clone());
    add("composited march", "high, composited march".into(), high_march.clone());
    // Fast keeps the march; with rays it would be cheaper than balanced still.
    add(
        "composited march",
        "fast, cone rays".into(),
        Settings { cone_rays: true, ..Settings::preset(Quality::Fast) },
    );
    // The march with leaves as the half-spaces behind their surfaces at the finest levels.
    add("cone planes", "cone planes".into(), Settings { cone_planes: true, ..march });
    for (q, marched) in [(Quality::Fast, Settings::preset(Quality::Fast)), (Quality::High, high_march)] {
        add("cone planes", format!("{}, cone planes", q.name()), Settings { cone_planes: true, ..marched });
    }
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

/// File-name form of a scene name.
pub fn slug(name: &str) -> String {
    name.chars().map(|c| if c.is_ascii_alphanumeric() { c.to_ascii_lowercase() } else { '-' }).collect()
}
