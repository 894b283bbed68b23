//! The frame both viewers draw, the window's and the page's: light first, in slices of a bounce
//! for as long as the viewer's pacing allows (none while the camera moves, none once the light has
//! converged or the view shows none), then the frame with the light held, so the draw adds no
//! light work of its own; at rest, a still frame's next jittered sample instead of a plain frame.
//! How long the light may run is the shell's: the window times slices on the CPU, the page sizes
//! one slice a frame from when the GPU reported the last frame done.

use web_time::Instant;

use crate::error::Result;
use crate::light::plan::{EffectPlan, Pass};
use crate::render::Renderer;
use crate::view::camera::Camera;

/// Longest frame at rest in both viewers (the page's `rest_ms` may say otherwise): nothing on
/// screen moves but the light, and a person who starts moving again waits at most this long for
/// the first moving frame. What a rest frame adds to its draw is the light's share of the time:
/// at 100 ms the light gets about two thirds of a frame on a software adapter, at 33 ms about
/// half, and converges that much later (docs/benchmarks.md).
pub const REST_FRAME_MS: f64 = 100.0;

/// Slices of a bounce that one frame may run at most, whatever the pacing says.
pub const MAX_SLICES_A_FRAME: u32 = 64;

/// What a viewer's frame ran.
#[derive(Clone, Debug)]
pub struct ViewerFrame {
    /// The plan of the frame drawn.
    pub plan: EffectPlan,
    /// The light's plan before its slices ran (why the light ran or waits).
    pub light_plan: EffectPlan,
    /// Whether light slices ran before the frame, and the leaves they propagated.
    pub light_ran: bool,
    pub leaves: u64,
    /// When the draw began, after the light (a viewer times its draws from here).
    pub draw_started: Instant,
}

impl ViewerFrame {
    /// Whether the frame or its light drew shadow faces or injected direct light: a change of
    /// lights or tiles, not what a frame costs.
    pub fn direct_light(&self) -> bool {
        let direct = |p: &EffectPlan| p.runs(Pass::Shadow) || p.runs(Pass::Inject);
        direct(&self.plan) || self.light_ran && direct(&self.light_plan)
    }

    /// Whether shadow faces were drawn, by the frame or its light.
    pub fn shadow(&self) -> bool {
        self.plan.runs(Pass::Shadow) || self.light_ran && self.light_plan.runs(Pass::Shadow)
    }
}

/// Why the frame drawn after the light holds the bounces.
pub fn held_because(moving: bool) -> &'static str {
    if moving { "the camera is moving" } else { "this frame's light ran before it, within the frame budget" }
}

/// How much light a viewer's frame may run before it is drawn: the shell's pacing.
pub trait LightPacing {
    /// Leaves the next slice of a bounce may propagate, or None: no more light this frame.
    fn next_slice(&mut self) -> Option<u32>;
    /// The slice just asked for propagated `leaves` leaves.
    fn slice_ran(&mut self, leaves: u32);
}

/// Draws a viewer's frame of `camera` at `width` x `height`: light slices while `pacing` gives
/// them (never while `moving`, once the light has converged, or where the view shows no light),
/// then the frame with the light held. `still`, asked once the light has run: whether the viewer
/// is at rest with its image settled, so the frame is a still frame's next sample
/// ([`Renderer::draw_still`]) rather than a plain one.
pub fn light_then_draw(
    renderer: &mut Renderer,
    camera: &Camera,
    (width, height): (u32, u32),
    moving: bool,
    pacing: &mut impl LightPacing,
    still: impl FnOnce(&Renderer) -> bool,
) -> Result<ViewerFrame> {
    renderer.hold_light(None);
    let light_plan = renderer.plan(None);
    let shows_light = renderer.settings().view.shows_light();
    let (mut light_ran, mut leaves) = (false, 0u64);
    for _ in 0..MAX_SLICES_A_FRAME {
        if moving || !shows_light || renderer.light_progress().converged {
            break;
        }
        let Some(n) = pacing.next_slice() else { break };
        let done = renderer.update_light_slice(n)?;
        pacing.slice_ran(done);
        light_ran = true;
        leaves += u64::from(done);
    }
    renderer.hold_light(Some(held_because(moving)));
    let draw_started = Instant::now();
    let plan = if still(renderer) {
        renderer.draw_still(camera, width, height)?.0
    } else {
        renderer.draw(camera, width, height)?
    };
    Ok(ViewerFrame { plan, light_plan, light_ran, leaves, draw_started })
}
