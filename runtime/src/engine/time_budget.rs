//! The first picture's light bought with time (`grotto render --time-budget SECONDS`): the job
//! runs its light's first update at the cheapest preset and times it on this device, predicts
//! from it what each preset's light would take, and keeps the most accurate preset that fits.
//!
//! The prediction scales the probe's own passes by how much more each costs under another
//! preset, as the accuracy report measured it over its scenes ([`LADDER`]; a test checks the
//! table against docs/accuracy.json). Each preset is predicted at its whole bounce budget, an
//! upper bound: light that converges sooner stops sooner.

use std::collections::BTreeMap;
use web_time::Instant;

use serde::Serialize;

use crate::error::{Error, Result};
use crate::gpu::Gpu;
use crate::light::plan::Pass;
use crate::render::Renderer;
use crate::settings::{Quality, Settings};

/// A preset as the report measured it against the cheapest: its error, and what its passes cost.
#[derive(Clone, Copy, Debug)]
pub(crate) struct Rung {
    pub(crate) quality: Quality,
    /// Mean relative RMSE of the preset over docs/accuracy.md's scenes.
    pub(crate) mean_error: f64,
    /// A propagation bounce's time (and the environment pass's, which marches the same cones)
    /// over the fast preset's: the median over the report's scenes.
    pub(crate) march_cost: f64,
    /// The shadow pass's time over the fast preset's (its maps are larger): the median over the
    /// report's scenes with lights.
    pub(crate) shadow_cost: f64,
}

/// The presets, cheapest and least accurate first, with their figures from docs/accuracy.json
/// (`time_budget::tests::the_ladder_is_the_reports` recomputes them from it).
pub(crate) const LADDER: [Rung; 3] = [
    Rung { quality: Quality::Fast, mean_error: 0.0698, march_cost: 1.0, shadow_cost: 1.0 },
    Rung { quality: Quality::Balanced, mean_error: 0.0481, march_cost: 2.74, shadow_cost: 1.35 },
    Rung { quality: Quality::High, mean_error: 0.0465, march_cost: 2.99, shadow_cost: 2.25 },
];

/// The light time a scan given where a package is expected gets when no preset or knob was
/// asked for: a first look that a 2-core machine gives within about half a minute.
pub const SCAN_DEFAULT_BUDGET_S: f64 = 30.0;

/// A budget as a user gives it: finite and above zero.
pub fn check_budget(seconds: f64) -> Result<f64> {
    if seconds.is_finite() && seconds > 0.0 {
        Ok(seconds)
    } else {
        Err(Error::Setting {
            name: "time_budget",
            problem: format!("{seconds} is not a time: give the seconds the light may take, above 0"),
        })
    }
}

/// The settings of preset `q` on top of the job's other settings, with shadow maps no larger
/// than `shadow_cap` (a memory budget's).
pub(crate) fn rung_settings(job: &Settings, q: Quality, shadow_cap: Option<u32>) -> Settings {
    let mut s = job.with_preset(q);
    if let Some(cap) = shadow_cap {
        s.shadow_map_size = s.shadow_map_size.min(cap);
    }
    s
}

/// The light's first update at the cheapest preset, timed.
#[derive(Clone, Debug, Default, PartialEq)]
pub(crate) struct Probe {
    /// Wall seconds, from the first pass to the GPU's end.
    pub(crate) wall_s: f64,
    /// Milliseconds of each pass that ran, summed over the updates the probe took.
    pub(crate) pass_ms: BTreeMap<Pass, f64>,
    /// Bounces run (1, or 0 where the scene has no light to propagate).
    pub(crate) bounces: u32,
}

impl Probe {
    /// Runs light updates until the first bounce has run (or the plan has no light work left),
    /// then waits for the GPU. `progress` gets the bounces done and the last change.
    pub(crate) fn run(
        gpu: &Gpu,
        r: &mut Renderer,
        mut progress: impl FnMut(u32, Option<f32>),
    ) -> Result<Self> {
        let t = Instant::now();
        let mut pass_ms = BTreeMap::new();
        loop {
            let plan = r.update_light()?;
            for pass in Pass::ALL {
                if let (true, Some(ms)) = (plan.runs(pass), r.stats().last_ms.get(&pass)) {
                    *pass_ms.entry(pass).or_insert(0.0) += ms;
                }
            }
            progress(r.stats().bounces_done, r.stats().last_change);
            let light_work = [Pass::Shadow, Pass::Inject, Pass::Propagate].iter().any(|&p| plan.runs(p));
            if r.stats().bounces_done >= 1 || !light_work {
                break;
            }
        }
        gpu.wait()?;
        Ok(Probe { wall_s: t.elapsed().as_secs_f64(), pass_ms, bounces: r.stats().bounces_done })
    }

    /// Predicted wall seconds of `rung`'s whole light at `bounces` bounces, from nothing.
    fn predict_s(&self, rung: &Rung, bounces: u32) -> f64 {
        let ran: f64 = self.pass_ms.values().sum();
        if ran <= 0.0 {
            return self.wall_s;
        }
        let per_bounce = f64::from(bounces) / f64::from(self.bounces.max(1));
        let model: f64 = self
            .pass_ms
            .iter()
            .map(|(pass, ms)| {
                ms * match pass {
                    Pass::Shadow => rung.shadow_cost,
                    Pass::Env => rung.march_cost,
                    Pass::Propagate => rung.march_cost * per_bounce,
                    Pass::Mip => per_bounce,
                    _ => 1.0,
                }
            })
            .sum();
        self.wall_s * model / ran
    }
}

/// What `--time-budget` chose, and what it gave up (the summary's `time_budget`).
#[derive(Clone, Debug, PartialEq, Serialize)]
pub struct BudgetChoice {
    pub budget_s: f64,
    /// Seconds of the first update at the fast preset, the probe the prediction scales.
    pub probe_s: f64,
    pub chosen: Quality,
    /// The chosen preset's bounce budget (fewer than the preset's where even it did not fit).
    pub bounces: u32,
    /// Predicted seconds of the light in all, the probe's included.
    pub predicted_s: f64,
    /// The chosen preset's mean error on the report's scenes.
    pub mean_error: f64,
    /// More accurate presets that did not fit: their names and predicted seconds.
    pub gave_up: Vec<(Quality, f64)>,
    /// The budget was too small for any preset: the cheapest light was run (the probe's bounce,
    /// and as many more as fitted).
    pub too_small: bool,
    /// The chosen preset is not the probe's: its renderer was made anew, its light from dark.
    pub made_anew: bool,
}

impl BudgetChoice {
    /// One line for the user: what was chosen, why, and what was given up.
    pub fn describe(&self) -> String {
        let gave_up = if self.gave_up.is_empty() {
            String::new()
        } else {
            let each: Vec<String> =
                self.gave_up.iter().map(|(q, s)| format!("{} (~{s:.1} s)", q.name())).collect();
            format!("; gave up {}", each.join(" and "))
        };
        if self.too_small {
            format!(
                "time budget {:.1} s: too small for any preset; rendered the cheapest light, {} with {} bounce{}, \
                 ~{:.1} s (its first bounce took {:.1} s on this device){gave_up}",
                self.budget_s,
                self.chosen.name(),
                self.bounces,
                if self.bounces == 1 { "" } else { "s" },
                self.predicted_s,
                self.probe_s
            )
        } else {
            format!(
                "time budget {:.1} s: {} (mean error {:.3} on the accuracy report's scenes), light ~{:.1} s \
                 predicted from a first bounce at fast of {:.1} s{gave_up}",
                self.budget_s,
                self.chosen.name(),
                self.mean_error,
                self.predicted_s,
                self.probe_s
            )
        }
    }
}

/// The most accurate preset whose light fits `budget_s` after `probe` (fast, already run).
pub(crate) fn choose(budget_s: f64, probe: &Probe) -> BudgetChoice {
    let fast = &LADDER[0];
    let fast_bounces = Settings::preset(Quality::Fast).bounces;
    // Fast goes on from the probe; any other preset starts anew, the probe's time spent.
    let predicted = |rung: &Rung| {
        let bounces = Settings::preset(rung.quality).bounces;
        if rung.quality == Quality::Fast {
            probe.predict_s(rung, bounces.max(probe.bounces))
        } else {
            probe.wall_s + probe.predict_s(rung, bounces)
        }
    };
    if probe.bounces == 0 {
        // No light to propagate (a view without light): no preset buys a better picture.
        return BudgetChoice {
            budget_s,
            probe_s: probe.wall_s,
            chosen: Quality::Fast,
            bounces: fast_bounces,
            predicted_s: probe.wall_s,
            mean_error: fast.mean_error,
            gave_up: Vec::new(),
            too_small: false,
            made_anew: false,
        };
    }
    let times: Vec<f64> = LADDER.iter().map(predicted).collect();
    let fits = |k: usize| times[k] <= budget_s;
    let gave_up = |k: usize| -> Vec<(Quality, f64)> {
        LADDER.iter().zip(&times).skip(k + 1).map(|(r, t)| (r.quality, *t)).collect()
    };
    if let Some(k) = (0..LADDER.len()).rev().find(|&k| fits(k)) {
        return BudgetChoice {
            budget_s,
            probe_s: probe.wall_s,
            chosen: LADDER[k].quality,
            bounces: Settings::preset(LADDER[k].quality).bounces,
            predicted_s: times[k],
            mean_error: LADDER[k].mean_error,
            gave_up: gave_up(k),
            too_small: false,
            made_anew: k != 0,
        };
    }
    // Not even fast's bounces fit: as many as do after the probe's, at least the probe's.
    let mut bounces = probe.bounces.max(1);
    while bounces < fast_bounces && probe.predict_s(fast, bounces + 1) <= budget_s {
        bounces += 1;
    }
    BudgetChoice {
        budget_s,
        probe_s: probe.wall_s,
        chosen: Quality::Fast,
        bounces,
        predicted_s: probe.predict_s(fast, bounces),
        mean_error: fast.mean_error,
        gave_up: gave_up(0),
        too_small: true,
        made_anew: false,
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn probe(wall_s: f64) -> Probe {
        // A demo-cave-like first update: shadows, inject, mip and one bounce.
        let pass_ms = BTreeMap::from([
            (Pass::Shadow, 240.0),
            (Pass::Inject, 15.0),
            (Pass::Mip, 8.0),
            (Pass::Propagate, 250.0),
        ]);
        Probe { wall_s, pass_ms, bounces: 1 }
    }

    #[test]
    fn the_budget_buys_the_most_accurate_preset_that_fits_and_says_what_it_gave_up() {
        let p = probe(0.513);
        // Fast: the probe and one more bounce (mip + propagate): 0.513 + 0.258.
        let fast_s = 0.513 * (513.0 + 258.0) / 513.0;
        let big = choose(1e6, &p);
        assert_eq!(big.chosen, Quality::High);
        assert!(big.made_anew && big.gave_up.is_empty() && !big.too_small);
        let mid = choose(3.5, &p);
        assert_eq!(mid.chosen, Quality::Balanced, "{}", mid.describe());
        assert_eq!(mid.gave_up.len(), 1);
        assert!(mid.predicted_s <= 3.5 && mid.gave_up[0].1 > 3.5, "{mid:?}");
        let low = choose(fast_s + 0.01, &p);
        assert_eq!((low.chosen, low.bounces, low.too_small), (Quality::Fast, 2, false));
        assert!((low.predicted_s - fast_s).abs() < 1e-9);
        let text = mid.describe();
        assert!(text.contains("balanced") && text.contains("gave up high"), "{text}");
    }

    #[test]
    fn a_budget_too_small_for_any_preset_renders_the_cheapest_light_and_says_so() {
        let p = probe(0.513);
        let c = choose(0.1, &p);
        assert!(c.too_small && !c.made_anew);
        assert_eq!((c.chosen, c.bounces), (Quality::Fast, 1));
        assert_eq!(c.gave_up.len(), 2);
        assert!(c.describe().contains("too small for any preset"), "{}", c.describe());
        for bad in [f64::NAN, -1.0, 0.0, f64::INFINITY] {
            let e = check_budget(bad).unwrap_err();
            assert!(matches!(e, Error::Setting { name: "time_budget", .. }), "{e}");
        }
        assert_eq!(check_budget(2.5).unwrap(), 2.5);
        // Nothing to propagate: the probe's renderer is kept, whatever the budget.
        let dark = choose(1e6, &Probe { bounces: 0, ..probe(0.2) });
        assert_eq!((dark.chosen, dark.made_anew, dark.too_small), (Quality::Fast, false, false));
    }

    #[test]
    fn more_bounces_and_wider_marches_are_predicted_to_cost_more() {
        let p = probe(1.0);
        let t: Vec<f64> =
            LADDER.iter().map(|r| p.predict_s(r, Settings::preset(r.quality).bounces)).collect();
        assert!(t[0] < t[1] && t[1] < t[2], "{t:?}");
        // Only the bounce-bound passes scale with bounces.
        let one = p.predict_s(&LADDER[0], 1);
        assert!((one - 1.0).abs() < 1e-12, "{one}");
        assert!(p.predict_s(&LADDER[0], 2) < 2.0 * one);
    }

    /// The ladder's figures against the report they come from: each preset's mean error over
    /// the report's scenes, and the medians of its propagate-per-bounce and shadow times over
    /// fast's. A regenerated report that moves them fails here until the table follows.
    #[test]
    fn the_ladder_is_the_reports() {
        let path = concat!(env!("CARGO_MANIFEST_DIR"), "/../docs/accuracy.json");
        let rows: Vec<serde_json::Value> =
            serde_json::from_str(&std::fs::read_to_string(path).expect("docs/accuracy.json")).unwrap();
        let preset = |scene: &str, q: Quality| {
            rows.iter().find(|r| r["scene"] == scene && r["knob"] == "preset" && r["config"] == q.name())
        };
        let scenes: Vec<String> = rows
            .iter()
            .filter(|r| r["knob"] == "preset" && r["config"] == "fast")
            .filter_map(|r| r["scene"].as_str().map(String::from))
            .collect();
        assert!(scenes.len() >= 5, "{scenes:?}");
        let median = |mut v: Vec<f64>| {
            v.sort_by(f64::total_cmp);
            v[v.len() / 2]
        };
        let ms = |r: &serde_json::Value, pass: &str| r["pass_ms"][pass].as_f64().unwrap_or(0.0);
        for rung in &LADDER {
            let (mut errors, mut march, mut shadow) = (Vec::new(), Vec::new(), Vec::new());
            for s in &scenes {
                let (Some(fast), Some(this)) = (preset(s, Quality::Fast), preset(s, rung.quality)) else {
                    panic!("{s}: no {} row", rung.quality.name())
                };
                errors.push(this["rel_rmse"].as_f64().unwrap());
                let per_bounce =
                    |r: &serde_json::Value| ms(r, "propagate") / r["bounces"].as_f64().unwrap().max(1.0);
                march.push(per_bounce(this) / per_bounce(fast));
                if ms(fast, "shadow") > 0.0 {
                    shadow.push(ms(this, "shadow") / ms(fast, "shadow"));
                }
            }
            let mean = errors.iter().sum::<f64>() / errors.len() as f64;
            let name = rung.quality.name();
            assert!((mean - rung.mean_error).abs() < 0.002, "{name}: mean error {mean:.4} in the report");
            let (m, s) = (median(march), median(shadow));
            assert!((m / rung.march_cost - 1.0).abs() < 0.1, "{name}: march cost {m:.2} in the report");
            assert!((s / rung.shadow_cost - 1.0).abs() < 0.1, "{name}: shadow cost {s:.2} in the report");
        }
        // The ladder's order is the report's: each preset more accurate than the one below it.
        assert!(LADDER.windows(2).all(|w| w[1].mean_error < w[0].mean_error));
    }
}
