//! The accuracy-vs-time sweep: each scene is rendered once by the reference (with its standard
//! error) and then by the runtime under each quality knob alone and the presets; every run records
//! its error against the reference, its GPU time per pass and its GPU memory. `report` turns the
//! rows into docs/accuracy.md (table, Pareto front, preset check).

pub mod breakdown;
mod configs;
mod report;
mod scenes;
mod sweep;

pub use configs::{
    CUT_BOUNCES, Config, MARCH_APERTURES, MARCH_STEPS, ONE_BOUNCE_APERTURE, ONE_BOUNCE_STEP, Row,
    TRUNCATED_BOUNCES, Variant, configs, slug,
};
pub use report::{
    MONOTONE_KNOBS, MONOTONE_SLACK, NOISE_FLOOR, knob_errors, knob_monotone, knob_series, lights_report,
    pareto, plot_svg, presets_monotone, report, with_truth,
};
pub use scenes::{
    CARVED_SCENES, SCANNED_CARVED_SCENES, SweepScene, bunny, closed_scenes, demo_cave, scanned_carved,
    scanned_passage, scene_named, scenes, scenes_cached, shared_data,
};
pub use sweep::{SUPERSAMPLE, SUPERSAMPLE_CHECK, error_map, lights_sweep, sweep};
