//! Still frames: anti-aliasing at rest (passes/resolve.rs). While the camera, the size, the clip,
//! the detail, the frame's parameters (exposure, view, flags) and the light stay as they were,
//! each [`Renderer::draw_still`] draws the next sample a pixel, jittered within it, and shows the
//! mean; anything else starts again from the pixel centres. Viewers call it at rest and `draw`
//! while moving; `grotto render --samples` calls it until the frame is complete.

use crate::error::Result;
use crate::light::plan::{EffectPlan, Pass};
use crate::passes::resolve::jitter_px;
use crate::render::renderer::Renderer;
use crate::render::targets::StillKey;
use crate::view::camera::Camera;

/// Where a still frame stands: samples a pixel gathered, of how many.
#[derive(Clone, Copy, Debug, PartialEq, Eq, serde::Serialize)]
pub struct StillProgress {
    pub samples: u32,
    pub of: u32,
}

impl StillProgress {
    /// Every sample is in: drawing again would change nothing.
    pub fn complete(&self) -> bool {
        self.samples >= self.of
    }
}

impl Renderer {
    /// Draws the next sample of a still frame of `camera` at `width` x `height` (the first, at
    /// the pixel centres, when anything changed since the last call), leaving the mean on the GPU
    /// as [`Renderer::draw`] does. Returns the plan it ran; where the frame was already complete
    /// nothing is drawn (what the last frame shows is still right) and the plan says so.
    pub fn draw_still(
        &mut self,
        camera: &Camera,
        width: u32,
        height: u32,
    ) -> Result<(EffectPlan, StillProgress)> {
        camera.validate()?;
        Self::check_size(width, height)?;
        self.poll_light()?;
        let of = self.settings.still_samples.max(1);
        self.targets.stills.jitter_px = [0.0; 2];
        let key = StillKey {
            camera: *camera,
            size: (width, height),
            clip: self.targets.clip(),
            detail_bits: self.targets.lod_detail().to_bits(),
            of,
            params: bytemuck::bytes_of(&self.frame_params(Some((camera, width, height)))).to_vec(),
        };
        let mut sample = match &self.targets.stills.still {
            // Tiles swapped in since: the samples so far show the old ones.
            Some((k, samples)) if *k == key && !self.targets.is_stale() => *samples,
            _ => 0,
        };
        if sample >= of {
            let mut plan = self.plan(None);
            for step in plan
                .steps
                .iter_mut()
                .filter(|s| matches!(s.pass, Pass::Gbuffer | Pass::Shade | Pass::Resolve))
            {
                step.run = false;
                step.reason =
                    format!("the still frame is complete ({of} samples a pixel) and nothing changed");
            }
            return Ok((plan, StillProgress { samples: of, of }));
        }
        let frame = Some((camera, width, height));
        let mut plan = self.still_plan(sample, of, frame);
        let light = [Pass::Shadow, Pass::Inject, Pass::Mip, Pass::Env, Pass::Propagate];
        if sample > 0 && light.iter().any(|&p| plan.runs(p)) {
            // The light changes with this frame: start again.
            sample = 0;
            plan = self.still_plan(0, of, frame);
        }
        self.execute(&plan, frame, None)?;
        self.targets.stills.still = Some((key, sample + 1));
        self.targets.stills.next = None;
        self.targets.stills.jitter_px = [0.0; 2];
        Ok((plan, StillProgress { samples: sample + 1, of }))
    }

    /// Where the still frame the last [`Renderer::draw_still`] drew stands; None after a
    /// [`Renderer::draw`] or a change of light.
    pub fn still_progress(&self) -> Option<StillProgress> {
        self.targets.stills.still.as_ref().map(|(k, samples)| StillProgress { samples: *samples, of: k.of })
    }

    /// Draws a still frame with every sample (`Settings::still_samples`) and reads it back: what
    /// `grotto render --samples` writes. Light work the plan asks for runs first, with the
    /// first sample.
    pub fn render_still(
        &mut self,
        camera: &Camera,
        width: u32,
        height: u32,
    ) -> Result<(super::frame::Frame, EffectPlan)> {
        self.targets.stills.still = None;
        let (mut plan, mut progress) = self.draw_still(camera, width, height)?;
        // The rest of the samples see the light the first one ran (a frame runs at most one
        // bounce; more would start the samples again).
        let held = self.light.held.replace("the first sample of this still frame ran the light");
        while !progress.complete() {
            match self.draw_still(camera, width, height) {
                Ok(next) => (plan, progress) = next,
                Err(e) => {
                    self.light.held = held;
                    return Err(e);
                }
            }
        }
        self.light.held = held;
        Ok((self.read_frame()?, plan))
    }

    fn still_plan(&mut self, sample: u32, of: u32, frame: Option<(&Camera, u32, u32)>) -> EffectPlan {
        self.targets.stills.jitter_px = jitter_px(sample);
        self.targets.stills.next = Some((sample, of));
        self.plan(frame)
    }
}
