//! The effect plan: which passes a frame runs, decided from the scene and the renderer's state, each
//! with the reason. The renderer executes exactly the passes marked `run` and counts dispatches, so
//! a test can prove a skipped pass is really skipped.
//!
//! Rules: no point or spot lights, no shadow maps and no injection (area lights are emissive
//! leaves); static lights, shadow maps and injection once; no environment map, no env (SH) pass,
//! and with one, the env pass once (the sky visibility does not change with the light); no light at
//! all or a zero bounce budget, no propagation (the mip runs only for a pass that reads it); once the largest relative change of a bounce falls under the
//! tolerance (or the budget is spent) propagation stops until something changes; the G-buffer is
//! re-splatted only when the camera or image size changed; lights beyond the shadow-map budget
//! render no shadow maps (lit per leaf); shade traces specular cones only where a specular material
//! covers surfels.

use serde::Serialize;

use crate::light::edit::EditScope;

/// A pass of the frame, in execution order.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Hash, PartialOrd, Ord, Serialize)]
#[serde(rename_all = "snake_case")]
pub enum Pass {
    Shadow,
    Inject,
    Mip,
    Env,
    Propagate,
    Gbuffer,
    Shade,
    Resolve,
}

impl Pass {
    pub(crate) const ALL: [Pass; 8] = [
        Pass::Shadow,
        Pass::Inject,
        Pass::Mip,
        Pass::Env,
        Pass::Propagate,
        Pass::Gbuffer,
        Pass::Shade,
        Pass::Resolve,
    ];

    /// The pass's name as the plan and the panel print it.
    pub fn name(self) -> &'static str {
        match self {
            Pass::Shadow => "shadow",
            Pass::Inject => "inject",
            Pass::Mip => "mip",
            Pass::Env => "env",
            Pass::Propagate => "propagate",
            Pass::Gbuffer => "gbuffer",
            Pass::Shade => "shade",
            Pass::Resolve => "resolve",
        }
    }
}

/// One pass's decision.
#[derive(Clone, Debug, PartialEq, Serialize)]
pub struct Step {
    pub pass: Pass,
    pub run: bool,
    pub reason: String,
}

/// The decisions for one frame.
#[derive(Clone, Debug, PartialEq, Serialize)]
pub struct EffectPlan {
    pub steps: Vec<Step>,
}

impl EffectPlan {
    /// Whether the plan runs `pass`.
    pub fn runs(&self, pass: Pass) -> bool {
        self.steps.iter().any(|s| s.pass == pass && s.run)
    }

    /// One line per pass: `run  inject   3 point lights changed` or `skip ...`.
    pub fn explain(&self) -> String {
        let mut s = String::new();
        for step in &self.steps {
            s += &format!(
                "{:4}  {:9}  {}\n",
                if step.run { "run" } else { "skip" },
                step.pass.name(),
                step.reason
            );
        }
        s
    }
}

/// What the plan is decided from.
#[derive(Clone, Debug, PartialEq)]
pub struct PlanInputs {
    /// One of the spot lights is a headlamp at the camera, added because the scene has no light.
    pub headlamp: bool,
    pub point_lights: usize,
    pub spot_lights: usize,
    pub shadows_enabled: bool,
    /// Lights with shadow maps (the brightest within the budget), and the budget.
    pub shadowed: usize,
    pub shadow_budget: u32,
    /// How the lights beyond the budget are shadowed, in words.
    pub fallback: &'static str,
    /// Lights in range per light-grid cell: mean and largest.
    pub lights_in_range: (f32, u32),
    /// Specular materials with surfels, and their surfels (0: shade reflects nothing).
    pub specular_materials: usize,
    pub specular_surfels: usize,
    pub emissive_leaves: bool,
    /// The scene has an environment map (SH coefficients) and it is enabled.
    pub environment: bool,
    /// A non-zero constant background radiance lights what the cones see escape.
    pub ambient: bool,
    /// The env pass has run for the current environment.
    pub env_valid: bool,
    /// Shadow maps and injected direct light match the current lights.
    pub direct_valid: bool,
    /// A light edit in place waits for its direct light: the lights it changed, the faces drawn
    /// again and the tiles injected again (light/edit.rs).
    pub light_edit: Option<EditScope>,
    /// Shadow maps catching up under a per-frame budget: faces the next pass draws, of those
    /// out of date, and the budget in milliseconds (render/shadow_queue.rs). None: the next pass
    /// draws every face out of date, or none is.
    pub shadow_catch_up: Option<(usize, usize, f32)>,
    pub bounces_done: u32,
    pub bounce_budget: u32,
    /// Largest relative change of the last bounce, if one ran since the last change.
    pub last_change: Option<f32>,
    pub convergence_tolerance: f32,
    /// Tiles the next bounce would update (those whose light may still change: activity.rs), of
    /// all tiles, and why in words. Converged means the last bounce changed nothing by more than
    /// the tolerance and no tile is left to update.
    pub tiles_pending: usize,
    pub tiles_total: usize,
    pub tiles_why: String,
    /// A frame (G-buffer + shade) is requested, not only a light update.
    pub frame: bool,
    /// The G-buffer matches the requested camera and size.
    pub gbuffer_valid: bool,
    /// How the G-buffer draws the discs, in words (blended, or front-most and why).
    pub splats: &'static str,
    /// The image shows no light (a view mode: albedo, normals, level), by name: the light passes
    /// wait until a view shows light.
    pub plain_view: Option<&'static str>,
    /// Why a viewer holds the bounces (its camera moves: frames stay responsive, the direct light
    /// and the image still update; or it ran this frame's light already, within its budget).
    pub light_held: Option<&'static str>,
    /// A bounce under way in slices: the next leaf and the bounce's leaves (the pyramid is kept
    /// until it ends).
    pub bounce_part: Option<(u32, u32)>,
    /// Anti-aliasing at rest (passes/resolve.rs): this frame's sample and the samples a pixel a
    /// still frame gathers; None where the frame is not drawn as a still (a moving camera, or
    /// `grotto render` without `--samples`).
    pub still: Option<(u32, u32)>,
}

/// Decides the passes for one frame or light update.
pub fn plan(i: &PlanInputs) -> EffectPlan {
    let analytic = i.point_lights + i.spot_lights;
    let lights_text = if i.headlamp {
        format!(
            "{} point, {} spot lights (a headlamp at the camera: the scene has no light of its own)",
            i.point_lights, i.spot_lights
        )
    } else {
        format!("{} point, {} spot lights", i.point_lights, i.spot_lights)
    };
    let env = env_step(i);
    let propagate = propagate_step(i, analytic);
    let mut steps = vec![shadow_step(i, analytic, &lights_text), inject_step(i, analytic, &lights_text)];
    steps.push(mip_step(i, &propagate, &env));
    steps.push(env);
    steps.push(Step { pass: Pass::Propagate, run: propagate.0, reason: propagate.1 });
    steps.push(gbuffer_step(i));
    steps.push(shade_step(i));
    steps.push(resolve_step(i));
    if let Some(view) = i.plain_view {
        let image = |p: Pass| matches!(p, Pass::Gbuffer | Pass::Shade | Pass::Resolve);
        for s in steps.iter_mut().filter(|s| s.run && !image(s.pass)) {
            s.run = false;
            s.reason = format!("the {view} view shows no light (else: {})", s.reason);
        }
    }
    EffectPlan { steps }
}

/// Shadow maps: drawn when lights with maps changed.
fn shadow_step(i: &PlanInputs, analytic: usize, lights_text: &str) -> Step {
    if analytic == 0 {
        Step { pass: Pass::Shadow, run: false, reason: "no point or spot lights".into() }
    } else if !i.shadows_enabled {
        Step { pass: Pass::Shadow, run: false, reason: "shadows disabled".into() }
    } else if i.shadowed == 0 {
        Step {
            pass: Pass::Shadow,
            run: false,
            reason: format!(
                "shadow-map budget {}: all {analytic} lights lit per leaf with {}",
                i.shadow_budget, i.fallback
            ),
        }
    } else if i.direct_valid {
        Step { pass: Pass::Shadow, run: false, reason: "lights unchanged: shadow maps still valid".into() }
    } else {
        let rest = analytic - i.shadowed;
        let beyond =
            if rest > 0 { format!("; {rest} more lit per leaf with {}", i.fallback) } else { String::new() };
        let faces = match i.shadow_catch_up {
            Some((now, of, ms)) => format!(
                "; {now} of {of} faces out of date drawn this frame ({ms} ms budget), the rest over the next frames"
            ),
            None => String::new(),
        };
        let why = match &i.light_edit {
            Some(e) => format!(
                "a light edit changed {} light(s): their {} face(s) drawn again, the others kept",
                e.lights, e.faces
            ),
            None => "lights or tiles changed".into(),
        };
        Step {
            pass: Pass::Shadow,
            run: true,
            reason: format!(
                "{} of {lights_text} get shadow maps (brightest first, budget {}){beyond}; {why}{faces}",
                i.shadowed, i.shadow_budget
            ),
        }
    }
}

/// Injection: direct light into the leaves, when lights changed.
fn inject_step(i: &PlanInputs, analytic: usize, lights_text: &str) -> Step {
    if analytic == 0 {
        Step {
            pass: Pass::Inject,
            run: false,
            reason: "no point or spot lights (area lights are emissive leaves)".into(),
        }
    } else if i.direct_valid {
        Step {
            pass: Pass::Inject,
            run: false,
            reason: "lights unchanged: injected direct light still valid".into(),
        }
    } else if let Some((now, of, _)) = i.shadow_catch_up.filter(|_| i.shadows_enabled && i.shadowed > 0) {
        Step {
            pass: Pass::Inject,
            run: false,
            reason: format!(
                "shadow maps catching up ({now} of {of} faces this frame): direct light waits for the whole atlas"
            ),
        }
    } else {
        let why = match &i.light_edit {
            Some(e) => format!(
                "a light edit changed {} light(s): only the {} of {} tiles ({} leaves) their light reaches",
                e.lights, e.tiles, e.of_tiles, e.leaves
            ),
            None => "lights changed".into(),
        };
        Step {
            pass: Pass::Inject,
            run: true,
            reason: format!(
                "{lights_text}, {:.1} in range per grid cell on average (at most {}); {why}",
                i.lights_in_range.0, i.lights_in_range.1
            ),
        }
    }
}

/// The environment pass: sky light through the openings, when there is an environment map.
fn env_step(i: &PlanInputs) -> Step {
    if !i.environment {
        Step { pass: Pass::Env, run: false, reason: "no environment map".into() }
    } else if i.env_valid {
        Step {
            pass: Pass::Env,
            run: false,
            reason: "environment unchanged: sky visibility still valid".into(),
        }
    } else {
        Step {
            pass: Pass::Env,
            run: true,
            reason: "environment map: SH irradiance through the openings the cones find".into(),
        }
    }
}

/// Whether a bounce runs, and why: the budget, light in the scene, convergence, tiles pending,
/// a viewer holding the light, a bounce under way in slices.
fn propagate_step(i: &PlanInputs, analytic: usize) -> (bool, String) {
    let any_light = analytic > 0 || i.emissive_leaves || i.environment || i.ambient;
    let propagate = if i.bounce_budget == 0 {
        (false, "bounce budget is 0 (direct light only)".to_string())
    } else if !any_light {
        (false, "no light in the scene: nothing to propagate".to_string())
    } else if let Some(e) = &i.light_edit {
        (
            false,
            format!(
                "a light edit's direct light first: the bounces start from the tiles it changes, of the {} in its lights' reach",
                e.tiles
            ),
        )
    } else if i.bounces_done >= i.bounce_budget {
        (false, format!("converged by budget: {} of {} bounces done", i.bounces_done, i.bounce_budget))
    } else if let Some(c) = i.last_change.filter(|&c| c < i.convergence_tolerance && i.tiles_pending == 0) {
        (
            false,
            format!(
                "converged: a bounce over every tile changed radiance by {c:.2e} < {:.0e}",
                i.convergence_tolerance
            ),
        )
    } else if i.tiles_pending < i.tiles_total {
        (
            true,
            format!(
                "bounce {} of {} over {} of {} tiles ({})",
                i.bounces_done + 1,
                i.bounce_budget,
                i.tiles_pending,
                i.tiles_total,
                i.tiles_why
            ),
        )
    } else {
        (true, format!("bounce {} of {}", i.bounces_done + 1, i.bounce_budget))
    };
    let catching_up = i.shadow_catch_up.is_some() && !i.direct_valid && i.shadows_enabled && i.shadowed > 0;
    let held = i.light_held.or(catching_up.then_some("the shadow maps are catching up"));
    match (propagate.0, held, i.bounce_part) {
        (true, Some(why), _) => (false, format!("{why}: bounce {} waits", i.bounces_done + 1)),
        (true, None, Some((next, of))) => (
            true,
            format!(
                "bounce {} of {}, continued: leaves {next}.. of {of}",
                i.bounces_done + 1,
                i.bounce_budget
            ),
        ),
        _ => propagate,
    }
}

/// The mip pass: the radiance pyramid, for a bounce that starts or for the env pass.
fn mip_step(i: &PlanInputs, propagate: &(bool, String), env: &Step) -> Step {
    // A sliced bounce gathers from the pyramid its mip made.
    let mid_bounce = i.bounce_part.is_some();
    Step {
        pass: Pass::Mip,
        run: (propagate.0 && !mid_bounce) || env.run,
        reason: if propagate.0 && mid_bounce {
            "the bounce under way keeps the pyramid its mip made".into()
        } else if propagate.0 {
            "propagation needs the radiance pyramid".into()
        } else if env.run {
            "the env pass needs the pyramid's opacity".into()
        } else {
            propagate.1.clone()
        },
    }
}

/// The G-buffer: drawn when the camera, the size or what is drawn changed.
fn gbuffer_step(i: &PlanInputs) -> Step {
    if !i.frame {
        Step { pass: Pass::Gbuffer, run: false, reason: "light update only, no image requested".into() }
    } else if i.gbuffer_valid {
        Step { pass: Pass::Gbuffer, run: false, reason: "camera and size unchanged".into() }
    } else {
        Step {
            pass: Pass::Gbuffer,
            run: true,
            reason: format!("camera, size or what is drawn changed; {}", i.splats),
        }
    }
}

/// Shading: every frame that asks for an image.
fn shade_step(i: &PlanInputs) -> Step {
    if i.frame {
        let reason = if i.specular_materials > 0 {
            format!(
                "image requested; specular cones for {} specular materials ({} surfels)",
                i.specular_materials, i.specular_surfels
            )
        } else {
            "image requested; no specular materials: diffuse only, no specular cones".into()
        };
        Step { pass: Pass::Shade, run: true, reason }
    } else {
        Step { pass: Pass::Shade, run: false, reason: "light update only, no image requested".into() }
    }
}

/// Anti-aliasing at rest: a still frame's samples after the first add to the mean.
fn resolve_step(i: &PlanInputs) -> Step {
    let (run, reason) = match i.still {
        _ if !i.frame => (false, "light update only, no image requested".into()),
        None => (false, "not a still frame: one sample a pixel (the camera moves, or no --samples)".into()),
        Some((_, 1)) => (false, "one sample a pixel (still samples 1: no anti-aliasing)".into()),
        Some((0, of)) => (true, format!("still frame: sample 1 of {of} (the pixel centres) starts the mean")),
        Some((k, of)) => (
            true,
            format!("still frame: sample {} of {of}, jittered within the pixel, added to the mean", k + 1),
        ),
    };
    Step { pass: Pass::Resolve, run, reason }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn base() -> PlanInputs {
        PlanInputs {
            headlamp: false,
            point_lights: 1,
            spot_lights: 0,
            shadows_enabled: true,
            shadowed: 1,
            shadow_budget: 16,
            fallback: "SVO cone shadows",
            lights_in_range: (1.0, 1),
            specular_materials: 0,
            specular_surfels: 0,
            emissive_leaves: false,
            environment: false,
            ambient: false,
            env_valid: false,
            direct_valid: false,
            light_edit: None,
            shadow_catch_up: None,
            bounces_done: 0,
            bounce_budget: 4,
            last_change: None,
            convergence_tolerance: 1e-3,
            tiles_pending: 1,
            tiles_total: 1,
            tiles_why: "1 no light yet".into(),
            frame: true,
            gbuffer_valid: false,
            splats: "blended splats",
            plain_view: None,
            light_held: None,
            bounce_part: None,
            still: None,
        }
    }

    #[test]
    fn a_light_edit_says_what_it_redoes() {
        let edit = EditScope { lights: 2, faces: 6, tiles: 3, of_tiles: 40, leaves: 900 };
        let p = plan(&PlanInputs { light_edit: Some(edit), ..base() });
        let text = p.explain();
        assert!(p.runs(Pass::Shadow) && p.runs(Pass::Inject), "{text}");
        assert!(text.contains("changed 2 light(s): their 6 face(s) drawn again"), "{text}");
        assert!(text.contains("only the 3 of 40 tiles (900 leaves)"), "{text}");
        assert!(
            !p.runs(Pass::Propagate) && text.contains("bounces start from the tiles it changes"),
            "{text}"
        );
        assert!(!plan(&base()).explain().contains("light edit"));
    }

    #[test]
    fn only_a_still_frame_resolves_samples() {
        let moving = plan(&base());
        assert!(!moving.runs(Pass::Resolve), "{}", moving.explain());
        let first = plan(&PlanInputs { still: Some((0, 8)), ..base() });
        assert!(
            first.runs(Pass::Resolve) && first.explain().contains("sample 1 of 8"),
            "{}",
            first.explain()
        );
        let fourth = plan(&PlanInputs { still: Some((3, 8)), gbuffer_valid: false, ..base() });
        assert!(fourth.runs(Pass::Resolve) && fourth.explain().contains("sample 4 of 8"));
        let one = plan(&PlanInputs { still: Some((0, 1)), ..base() });
        assert!(!one.runs(Pass::Resolve), "one sample a pixel needs no resolve");
        let light_only = plan(&PlanInputs { still: Some((2, 8)), frame: false, ..base() });
        assert!(!light_only.runs(Pass::Resolve));
        // A view without light still anti-aliases.
        let plain = plan(&PlanInputs { still: Some((2, 8)), plain_view: Some("normals"), ..base() });
        assert!(plain.runs(Pass::Resolve) && !plain.runs(Pass::Inject), "{}", plain.explain());
    }

    #[test]
    fn no_point_lights_no_shadow_or_inject() {
        let p = plan(&PlanInputs { point_lights: 0, emissive_leaves: true, ..base() });
        assert!(!p.runs(Pass::Shadow) && !p.runs(Pass::Inject));
        assert!(p.runs(Pass::Propagate), "emission still propagates");
    }

    #[test]
    fn a_moving_camera_holds_the_bounces_but_not_the_direct_light_or_the_image() {
        let moving = plan(&PlanInputs { light_held: Some("the camera is moving"), ..base() });
        assert!(!moving.runs(Pass::Propagate) && !moving.runs(Pass::Mip));
        assert!(moving.runs(Pass::Shadow) && moving.runs(Pass::Inject) && moving.runs(Pass::Shade));
        assert!(moving.explain().contains("the camera is moving: bounce 1 waits"), "{}", moving.explain());
        // Held or not, a converged light does not propagate, and says so.
        let settled = PlanInputs { direct_valid: true, bounces_done: 4, ..base() };
        let p = plan(&PlanInputs { light_held: Some("the camera is moving"), ..settled.clone() });
        assert!(!p.runs(Pass::Propagate) && p.explain().contains("converged by budget"));
        assert!(plan(&PlanInputs { light_held: None, ..base() }).runs(Pass::Propagate));
        // A bounce in slices: the rest of it runs on the pyramid it started with.
        let part = plan(&PlanInputs { bounce_part: Some((4096, 10_000)), direct_valid: true, ..base() });
        assert!(part.runs(Pass::Propagate) && !part.runs(Pass::Mip), "{}", part.explain());
        assert!(part.explain().contains("leaves 4096.. of 10000"));
    }

    #[test]
    fn converged_stops_propagation() {
        let settled = PlanInputs { direct_valid: true, bounces_done: 2, tiles_pending: 0, ..base() };
        let p = plan(&PlanInputs { last_change: Some(1e-5), ..settled.clone() });
        assert!(!p.runs(Pass::Mip) && !p.runs(Pass::Propagate) && !p.runs(Pass::Shadow));
        assert!(p.explain().contains("converged"));
        let p = plan(&PlanInputs { last_change: Some(0.1), ..settled.clone() });
        assert!(p.runs(Pass::Propagate));
        // A small change where the last bounce looked is not convergence while tiles are left
        // (the check over every tile has not run yet).
        let partial = PlanInputs {
            last_change: Some(1e-5),
            tiles_pending: 3,
            tiles_total: 10,
            tiles_why: "3 convergence check".into(),
            ..settled
        };
        let p = plan(&partial);
        assert!(p.runs(Pass::Propagate) && p.explain().contains("over 3 of 10 tiles"), "{}", p.explain());
    }

    #[test]
    fn environment_runs_its_pass_once_and_lights_a_lampless_scene() {
        let p = plan(&base());
        assert!(!p.runs(Pass::Env), "no environment map, no env pass");
        let sky = PlanInputs { point_lights: 0, environment: true, ..base() };
        let p = plan(&sky);
        assert!(p.runs(Pass::Env) && p.runs(Pass::Mip) && p.runs(Pass::Propagate));
        let p = plan(&PlanInputs { env_valid: true, bounces_done: 1, last_change: Some(0.5), ..sky.clone() });
        assert!(!p.runs(Pass::Env) && p.runs(Pass::Propagate));
        // Direct-only with a sky: the env pass still needs the pyramid, propagation does not run.
        let p = plan(&PlanInputs { bounce_budget: 0, ..sky });
        assert!(p.runs(Pass::Env) && p.runs(Pass::Mip) && !p.runs(Pass::Propagate));
    }

    #[test]
    fn lights_beyond_the_budget_skip_the_shadow_pass() {
        let many = PlanInputs { point_lights: 256, shadowed: 16, lights_in_range: (23.5, 40), ..base() };
        let p = plan(&many);
        assert!(p.runs(Pass::Shadow) && p.runs(Pass::Inject));
        assert!(p.explain().contains("240 more lit per leaf"), "{}", p.explain());
        assert!(p.explain().contains("23.5 in range"), "{}", p.explain());
        let p = plan(&PlanInputs { shadowed: 0, shadow_budget: 0, ..many });
        assert!(!p.runs(Pass::Shadow) && p.runs(Pass::Inject), "{}", p.explain());
    }

    #[test]
    fn specular_cones_only_with_specular_materials() {
        assert!(plan(&base()).explain().contains("no specular cones"));
        let p = plan(&PlanInputs { specular_materials: 2, specular_surfels: 900, ..base() });
        assert!(
            p.explain().contains("specular cones for 2 specular materials (900 surfels)"),
            "{}",
            p.explain()
        );
    }

    #[test]
    fn headlamp_is_named_in_the_plan() {
        let p = plan(&PlanInputs { headlamp: true, point_lights: 0, spot_lights: 1, ..base() });
        assert!(p.runs(Pass::Inject) && p.explain().contains("headlamp at the camera"), "{}", p.explain());
        assert!(!plan(&base()).explain().contains("headlamp"));
    }

    #[test]
    fn dark_scene_propagates_nothing() {
        let p = plan(&PlanInputs { point_lights: 0, ..base() });
        assert!(!p.runs(Pass::Propagate) && !p.runs(Pass::Mip));
        assert!(p.runs(Pass::Shade));
    }

    #[test]
    fn a_view_without_light_skips_the_light_passes_and_says_why() {
        let p = plan(&PlanInputs { plain_view: Some("albedo"), frame: true, ..base() });
        for pass in [Pass::Shadow, Pass::Inject, Pass::Mip, Pass::Propagate] {
            let step = p.steps.iter().find(|s| s.pass == pass).unwrap();
            assert!(!step.run && step.reason.contains("albedo view shows no light"), "{step:?}");
        }
        assert!(p.runs(Pass::Gbuffer) && p.runs(Pass::Shade));
    }

    #[test]
    fn shadow_maps_catching_up_hold_inject_and_the_bounces_until_the_last_face() {
        let p = plan(&PlanInputs { shadow_catch_up: Some((3, 40, 8.0)), ..base() });
        assert!(p.runs(Pass::Shadow), "{}", p.explain());
        assert!(
            p.explain().contains("3 of 40 faces out of date drawn this frame (8 ms budget)"),
            "{}",
            p.explain()
        );
        assert!(!p.runs(Pass::Inject) && !p.runs(Pass::Propagate) && !p.runs(Pass::Mip), "{}", p.explain());
        assert!(p.explain().contains("direct light waits for the whole atlas"), "{}", p.explain());
        // The pass that draws the last faces injects and bounces in the same frame.
        let last = plan(&base());
        assert!(last.runs(Pass::Shadow) && last.runs(Pass::Inject) && last.runs(Pass::Propagate));
        // Shadows off: nothing waits for them.
        let off = plan(&PlanInputs { shadows_enabled: false, shadow_catch_up: Some((3, 40, 8.0)), ..base() });
        assert!(off.runs(Pass::Inject) && off.runs(Pass::Propagate), "{}", off.explain());
    }
}
