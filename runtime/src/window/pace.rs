//! The viewer's frame budget: how much light work a frame gets. While the camera moves the
//! bounces wait (the renderer holds them, and the plan says so), so frames stay as fast as the
//! G-buffer and shading allow; at rest, the light converges in slices of a bounce
//! ([`crate::render::Renderer::update_light_slice`]) sized to what the budget leaves beside the
//! frame. Pure bookkeeping, tested without a window.

use serde::Serialize;
use web_time::Instant;

use crate::light::plan::EffectPlan;
use crate::viewer::{LightPacing, REST_FRAME_MS};

/// Leaves in the first slice, before a slice has been timed.
pub(crate) const FIRST_SLICE_LEAVES: u32 = 4096;

/// Moving averages of what a frame's draw and a leaf's propagation cost.
#[derive(Clone, Debug)]
pub struct Pacer {
    budget_ms: f64,
    draw_ms: Option<f64>,
    leaf_ms: Option<f64>,
}

fn average(old: Option<f64>, new: f64) -> f64 {
    old.map_or(new, |o| 0.7 * o + 0.3 * new)
}

impl Pacer {
    pub(crate) fn new(budget_ms: f64) -> Self {
        Self { budget_ms, draw_ms: None, leaf_ms: None }
    }

    /// Milliseconds of light work for a frame: none while the camera moves; at rest, what the
    /// rest budget (the frame budget, at least [`REST_FRAME_MS`]) leaves beside the draw, and at
    /// least as long as the draw itself where the draw alone overruns it (a software adapter), so
    /// a frame at rest stays within twice a moving one.
    pub(crate) fn light_ms(&self, moving: bool) -> f64 {
        if moving {
            return 0.0;
        }
        let draw = self.draw_ms.unwrap_or(0.0);
        (self.budget_ms.max(REST_FRAME_MS) - draw).max(draw).max(1.0)
    }

    /// Leaves a slice may propagate in `ms`.
    pub(crate) fn slice_leaves(&self, ms: f64) -> u32 {
        match self.leaf_ms {
            Some(per_leaf) if per_leaf > 0.0 => (ms / per_leaf).clamp(64.0, u32::MAX as f64) as u32,
            _ => FIRST_SLICE_LEAVES,
        }
    }

    /// A frame's draw (G-buffer and shading, no bounce) took `ms`.
    pub(crate) fn record_draw(&mut self, ms: f64) {
        self.draw_ms = Some(average(self.draw_ms, ms));
    }

    /// A light update that propagated `leaves` leaves took `ms`.
    pub(crate) fn record_slice(&mut self, ms: f64, leaves: u32) {
        if leaves > 0 {
            self.leaf_ms = Some(average(self.leaf_ms, ms / f64::from(leaves)));
        }
    }
}

/// The window's light for one frame: slices timed on the CPU for as long as the pacer gives the
/// light ([`Pacer::light_ms`]), each sized to the time left at the last measured rate.
pub(crate) struct TimedSlices<'a> {
    pacer: &'a mut Pacer,
    light_ms: f64,
    started: Instant,
    slice: Instant,
}

impl<'a> TimedSlices<'a> {
    pub(crate) fn new(pacer: &'a mut Pacer, moving: bool) -> Self {
        let light_ms = pacer.light_ms(moving);
        let now = Instant::now();
        Self { pacer, light_ms, started: now, slice: now }
    }
}

impl LightPacing for TimedSlices<'_> {
    fn next_slice(&mut self) -> Option<u32> {
        let left_ms = self.light_ms - self.started.elapsed().as_secs_f64() * 1e3;
        self.slice = Instant::now();
        (left_ms > 0.0).then(|| self.pacer.slice_leaves(left_ms))
    }

    fn slice_ran(&mut self, leaves: u32) {
        self.pacer.record_slice(self.slice.elapsed().as_secs_f64() * 1e3, leaves);
    }
}

/// What the frames of a viewing session cost (`grotto view --json`, docs/benchmarks.md).
#[derive(Clone, Debug, Default, Serialize)]
pub struct FrameLog {
    /// Milliseconds of each frame (input to present) while the camera moved, and at rest.
    pub moving_ms: Vec<f64>,
    pub rest_ms: Vec<f64>,
    /// Each time the camera came to rest with the light not converged: frames and seconds until
    /// it converged (a rest cut short by moving again is not counted).
    pub converge_frames: Vec<u32>,
    pub converge_s: Vec<f64>,
    /// Render scale and detail factor of each moving frame (what the frame-time target traded).
    pub moving_traded: Vec<(f32, f32)>,
    /// Bounces run at rest, over all frames.
    pub(crate) rest_bounces: u64,
    /// Frames and time since the camera came to rest, and whether this rest's convergence was
    /// counted.
    #[serde(skip)]
    resting: Option<(u32, Instant, bool)>,
}

impl FrameLog {
    /// Records a frame that took `ms`; `converged`: the light after it.
    pub(crate) fn frame(&mut self, ms: f64, moving: bool, converged: bool, bounces: u32) {
        if moving {
            self.moving_ms.push(ms);
            self.resting = None;
            return;
        }
        self.rest_ms.push(ms);
        self.rest_bounces += u64::from(bounces);
        let (frames, since, counted) = self.resting.get_or_insert((0, Instant::now(), false));
        *frames += 1;
        // Once per rest, and only where there was light work to wait for.
        if converged && !*counted {
            *counted = true;
            if *frames > 1 || bounces > 0 {
                self.converge_frames.push(*frames);
                self.converge_s.push(since.elapsed().as_secs_f64());
            }
        }
    }

    /// Median and 95th percentile of `v`.
    pub fn percentiles(v: &[f64]) -> Option<(f64, f64)> {
        if v.is_empty() {
            return None;
        }
        let mut s = v.to_vec();
        s.sort_by(f64::total_cmp);
        let at = |q: f64| s[((s.len() - 1) as f64 * q).round() as usize];
        Some((at(0.5), at(0.95)))
    }
}

/// `GROTTO_VIEW_TRACE`: a line for each frame whose state differs from the last frame's (and
/// every hundredth), and the light's plan where the passes it runs changed, so that a stuck
/// light says why without a line for each of thousands of frames that all say the same.
#[derive(Default)]
pub(crate) struct Trace {
    state: String,
    runs: Vec<bool>,
}

impl Trace {
    pub(crate) fn frame(&mut self, n: u32, ms: f64, state: &str, light_plan: &EffectPlan) {
        if state != self.state || n.is_multiple_of(100) {
            eprintln!("frame {n} {ms:.1} ms {state}");
            state.clone_into(&mut self.state);
        }
        let runs: Vec<bool> = light_plan.steps.iter().map(|s| s.run).collect();
        if runs != self.runs {
            eprintln!("light plan at frame {n}:\n{}", light_plan.explain());
            self.runs = runs;
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn moving_frames_get_no_light_and_resting_frames_get_the_rest_of_the_budget() {
        let mut p = Pacer::new(133.0);
        assert_eq!(p.slice_leaves(10.0), FIRST_SLICE_LEAVES, "nothing timed yet");
        p.record_draw(13.0);
        p.record_slice(20.0, 10_000);
        assert_eq!(p.light_ms(true), 0.0);
        assert_eq!(p.light_ms(false), 120.0, "133 - 13");
        assert_eq!(p.slice_leaves(p.light_ms(false)), 60_000);
        // A 33 ms budget still gives a frame at rest the rest frame's time.
        let mut q = Pacer::new(33.0);
        q.record_draw(13.0);
        assert_eq!(q.light_ms(false), REST_FRAME_MS - 13.0);
        // A software adapter: the draw alone overruns the budget, so the light gets as long again.
        let mut slow = Pacer::new(33.0);
        slow.record_draw(250.0);
        slow.record_slice(100.0, 4096);
        assert_eq!(slow.light_ms(false), 250.0, "as long as the draw");
        assert_eq!(slow.slice_leaves(250.0), 10_240);
        // Updates without propagation teach nothing about leaves; tiny budgets still progress.
        slow.record_slice(5000.0, 0);
        assert_eq!(slow.slice_leaves(250.0), 10_240);
        assert_eq!(slow.slice_leaves(0.0), 64);
    }

    #[test]
    fn the_log_counts_frames_to_converge_once_per_rest() {
        let mut log = FrameLog::default();
        log.frame(50.0, true, false, 0);
        for _ in 0..3 {
            log.frame(40.0, false, false, 1);
        }
        log.frame(40.0, false, true, 1);
        log.frame(20.0, false, true, 0);
        assert_eq!(log.converge_frames, vec![4]);
        assert_eq!((log.moving_ms.len(), log.rest_ms.len(), log.rest_bounces), (1, 5, 4));
        // Moving again and resting again counts a second rest.
        log.frame(50.0, true, false, 0);
        log.frame(40.0, false, true, 1);
        assert_eq!(log.converge_frames, vec![4, 1]);
        assert_eq!(FrameLog::percentiles(&[3.0, 1.0, 2.0]), Some((2.0, 3.0)));
    }
}
