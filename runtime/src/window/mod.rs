//! `grotto view`: a window (winit) on the same renderer `grotto render` uses. A thin shell: it
//! opens the package as a render job does ([`crate::engine::open`]), keeps the resident tiles
//! following the camera on a loader thread ([`Follow`]: flying never waits for the disk), renders
//! each frame with [`Renderer::draw`] (at rest, once the light is in, [`Renderer::draw_still`]:
//! a sample a pixel more each frame, anti-aliasing the still image) and presents the tonemapped output through a small blit
//! (present.rs) with the panel (egui, [`panel`]) over it.
//!
//! Light yields to the frame rate ([`pace`], through the frame both viewers draw:
//! [`crate::viewer::light_then_draw`]): while the camera moves the renderer holds its bounces (the
//! plan says so); at rest the light converges in as many slices of a bounce a frame as fit in the
//! frame budget. A bar along the bottom shows the convergence (grey: waiting for the
//! camera to rest, amber: converging, green: converged).
//!
//! Controls: mouse drag looks around (in orbit, turns around the pivot), WASD flies (Q/E
//! down/up), the wheel sets the speed (in orbit, the distance), a right click orbits the point
//! under the cursor and O the point at the centre (O again: fly), Tab jumps to the next named
//! camera, R back to the first, 1-7 switch the view (lit, albedo, normals, light, level, scan, lux),
//! C cuts the view to a clip box (a section at eye height; the panel edits it), H hides the
//! panel, K starts and stops recording a camera path (`grotto render --path FILE.toml` flies
//! it; T marks a tour stop meanwhile), P writes a screenshot once the light has converged, F11
//! toggles full screen, Esc quits. The package's points of interest are labelled and listed,
//! its tours play (G, N, B), M measures between two clicked points and a double click flies to
//! the wall there ([`story`]).

mod lamps;
mod pace;
mod panel;
mod story;

use std::path::PathBuf;
use std::sync::Arc;
use std::time::Instant;

use glam::Vec3;
use serde::Serialize;
use winit::application::ApplicationHandler;
use winit::event::{ElementState, MouseButton, MouseScrollDelta, WindowEvent};
use winit::event_loop::{ActiveEventLoop, EventLoop};
use winit::keyboard::{KeyCode, PhysicalKey};
use winit::window::{Fullscreen, Window, WindowId};

pub use pace::{FrameLog, Pacer};

use crate::cli::image_out;
use crate::engine::RenderOptions;
use crate::error::{Error, Result};
use crate::gpu::Gpu;
use crate::render::present::{Bar, Blit, Target};
use crate::render::{LightProgress, Renderer};
use crate::scene::data::SceneData;
use crate::settings::{ClipBox, Quality, ViewMode, scan_color};
use crate::stream::follow::{self, Follow};
use crate::view::camera::{self, Camera, Nav};
use crate::view::frame_target::FrameTarget;

/// What `grotto view` is asked.
#[derive(Clone, Debug)]
pub struct ViewOptions {
    /// The package, camera, settings, GPU and budgets, as `grotto render` takes them; `width` and
    /// `height` are the window's first inner size.
    pub render: RenderOptions,
    /// The preset the settings came from, as the panel shows it (None: knobs set one by one).
    pub quality: Option<Quality>,
    /// The renderer draws at the window's size times this (software adapters are slow per pixel).
    pub render_scale: f32,
    /// Where P writes its screenshot (default `grotto-view-N.png`); with `after_frames`, the
    /// viewer writes it by itself after that many frames, once the camera rests and the light has
    /// converged (so it matches `grotto render` of the same camera), and exits.
    pub screenshot: Option<PathBuf>,
    pub after_frames: Option<u32>,
    /// Record a camera path from the start and write it here on exit (K does the same by hand).
    pub record_path: Option<PathBuf>,
    /// Milliseconds a frame at rest may spend, bounces included.
    pub frame_budget_ms: f64,
    /// Milliseconds a moving frame aims at (render scale, then detail, traded for it:
    /// view/frame_target.rs); `None`: moving frames draw at `render_scale` whatever they cost.
    pub frame_target_ms: Option<f64>,
    /// Show the panel (H toggles it).
    pub panel: bool,
    /// Called after each change of tiles lands: the binary hands the allocator's free pages
    /// back to the system there (what the change decoded and freed).
    pub after_swap: Option<fn()>,
}

/// What a viewing session did.
#[derive(Clone, Debug, Default, Serialize)]
pub struct ViewSummary {
    pub device: String,
    pub frames: u32,
    pub seconds: f64,
    pub screenshots: Vec<String>,
    /// Camera path files written, with their keyframes, and tours recorded with their stops.
    pub paths: Vec<(String, usize)>,
    pub tours: Vec<(String, usize)>,
    /// Changes of resident tiles swapped in while flying.
    pub(crate) tile_swaps: u32,
    /// Tiles found damaged while streaming, each shown at the form it had (also printed to
    /// stderr as found).
    pub warnings: Vec<String>,
    /// Frame times while moving and at rest, and how long the light took to converge at rest.
    pub log: FrameLog,
    /// The story's state when the window closed: labels, measurement, tour.
    pub story: Option<story::StorySummary>,
    /// Lighting files saved in lighting mode (V).
    pub lights_saved: Vec<String>,
}

/// Opens the window and runs until it is closed (or the scripted screenshot is written).
pub fn run(opts: ViewOptions) -> Result<ViewSummary> {
    let event_loop = EventLoop::new().map_err(|e| Error::NoDisplay(e.to_string()))?;
    let mut app =
        App { opts, state: None, error: None, summary: ViewSummary::default(), started: Instant::now() };
    event_loop.run_app(&mut app).map_err(|e| Error::NoDisplay(e.to_string()))?;
    if let Some(e) = app.error {
        return Err(e);
    }
    if let Some(s) = app.state.as_mut() {
        // A recording still running when the window closed is kept.
        if let Some(keys) = s.recording.take() {
            app.summary.paths.push(save_path(&app.opts, &keys, &s.scene)?);
            app.summary.tours.extend(story::save_tour(&app.opts, &mut s.story, &s.scene)?);
        }
        app.summary.log = std::mem::take(&mut s.log);
        story::answer_clicks(s)?;
        app.summary.story = Some(s.story.summary(&s.nav.camera(), story::drawn_px(s)));
        app.summary.lights_saved = std::mem::take(&mut s.lamps.saved);
    }
    app.summary.seconds = app.started.elapsed().as_secs_f64();
    Ok(app.summary)
}

/// Writes a recorded camera path to `--record-path` (or the next `grotto-path-N.toml`); returns
/// the file and its keyframes.
fn save_path(opts: &ViewOptions, keys: &[Camera], scene: &SceneData) -> Result<(String, usize)> {
    let file = opts.record_path.clone().unwrap_or_else(|| next_name("grotto-path", "toml"));
    camera::path_file::write(&file, keys, scene.frame_origin_m)?;
    Ok((file.display().to_string(), keys.len()))
}

/// Where a screenshot goes: `--screenshot`, or the next `grotto-view-N.png`.
fn shot_path(opts: &ViewOptions) -> PathBuf {
    opts.screenshot.clone().unwrap_or_else(|| next_name("grotto-view", "png"))
}

/// `stem-N.ext` for the first N whose file does not exist yet.
pub(super) fn next_name(stem: &str, ext: &str) -> PathBuf {
    (0..)
        .map(|i| PathBuf::from(format!("{stem}-{i}.{ext}")))
        .find(|p| !p.exists())
        .unwrap_or_else(|| PathBuf::from(format!("{stem}.{ext}")))
}

struct App {
    opts: ViewOptions,
    state: Option<State>,
    error: Option<Error>,
    summary: ViewSummary,
    started: Instant,
}

/// The window, its surface, the renderer and what the person is doing.
struct State {
    window: Arc<Window>,
    gpu: Gpu,
    surface: wgpu::Surface<'static>,
    config: wgpu::SurfaceConfiguration,
    blit: Blit,
    ui: Ui,
    renderer: Renderer,
    /// The scene the renderer holds (its tiles change as the camera moves, over budget).
    scene: SceneData,
    follow: Option<Follow>,
    /// The camera and clip box the loader last chose tiles for.
    chosen_for: Option<(Camera, Option<ClipBox>)>,
    /// The scene's box, frame metres (the clip box's range).
    bounds_m: (Vec3, Vec3),
    cameras: Vec<Camera>,
    camera_index: usize,
    nav: Nav,
    /// Keys held (W, A, S, D, Q, E), the mouse button, the last cursor position.
    held: [bool; 6],
    dragging: bool,
    cursor: Option<(f64, f64)>,
    last_frame: Instant,
    last_camera: Option<Camera>,
    pacer: Pacer,
    target: Option<FrameTarget>,
    log: FrameLog,
    /// Keyframes of the camera path being recorded.
    recording: Option<Vec<Camera>>,
    /// Exposure from the frame (not the command line or the panel): set again once when the light
    /// first converges, since the first frame has only direct light.
    auto_exposure: AutoExposure,
    /// A screenshot waiting for the light to converge, and whether Esc asked to quit after it.
    shot: Option<PathBuf>,
    quit_after_shot: bool,
    frame_ms: f64,
    /// GROTTO_VIEW_TRACE: each frame's state on stderr where it changed.
    trace: Option<pace::Trace>,
    story: story::StoryUi,
    lamps: lamps::LampEditor,
}

#[derive(Clone, Copy, Debug, PartialEq)]
enum AutoExposure {
    Off,
    FirstFrame,
    AtConvergence,
    Done,
}

/// A new keyframe once the camera has moved 0.25 m or turned 10 degrees since the last one.
fn keyframe_due(last: Option<&Camera>, now: &Camera) -> bool {
    let Some(last) = last else { return true };
    let turn = (last.look_at_m - last.eye_m)
        .normalize_or_zero()
        .dot((now.look_at_m - now.eye_m).normalize_or_zero());
    (now.eye_m - last.eye_m).length() > 0.25 || turn < 10f32.to_radians().cos()
}

/// The panel's egui context, its winit input and its wgpu painter.
struct Ui {
    ctx: egui::Context,
    input: egui_winit::State,
    painter: egui_wgpu::Renderer,
    visible: bool,
    knobs: panel::PanelKnobs,
}

impl App {
    fn start(&mut self, event_loop: &ActiveEventLoop) -> Result<()> {
        let o = &self.opts.render;
        let attrs = Window::default_attributes()
            .with_title(format!("grotto view {}", o.package.display()))
            .with_inner_size(winit::dpi::PhysicalSize::new(o.width, o.height));
        let window = Arc::new(event_loop.create_window(attrs).map_err(|e| Error::NoDisplay(e.to_string()))?);
        let (gpu, surface) = Gpu::for_window(&o.gpu, window.clone())?;
        let caps = surface.get_capabilities(&gpu.adapter);
        // A plain (non-sRGB) format shows the renderer's sRGB bytes as they are.
        let format = caps
            .formats
            .iter()
            .copied()
            .find(|f| !f.is_srgb())
            .or_else(|| caps.formats.first().copied())
            .ok_or_else(|| Error::Device("the window's surface offers no format".into()))?;
        let size = window.inner_size();
        let config = wgpu::SurfaceConfiguration {
            usage: wgpu::TextureUsages::RENDER_ATTACHMENT,
            format,
            color_space: wgpu::SurfaceColorSpace::Auto,
            width: size.width.max(1),
            height: size.height.max(1),
            present_mode: wgpu::PresentMode::Fifo,
            desired_maximum_frame_latency: 2,
            alpha_mode: caps.alpha_modes.first().copied().unwrap_or(wgpu::CompositeAlphaMode::Auto),
            view_formats: Vec::new(),
        };
        surface.configure(&gpu.device, &config);
        let blit = Blit::new(&gpu, format)?;
        let mut prepared = crate::engine::open(o, &gpu)?;
        let mut settings = o.settings.clone();
        settings.exposure = o.exposure.unwrap_or(1.0);
        let (mut renderer, follow) = follow::start(
            &gpu,
            &mut prepared.scene,
            settings.clone(),
            prepared.streaming,
            prepared.residency,
            o.loader_steps(),
        )?;
        renderer.set_clip(prepared.clip);
        let (lo, hi) = prepared.scene.bounds_leaf();
        let bounds_m = (lo * prepared.scene.leaf_size_m, hi * prepared.scene.leaf_size_m);
        let nav = Nav::for_scene(&prepared.cameras[0], &prepared.scene);
        // Tab goes through the package's named cameras, after the one the view opened on.
        let first = prepared.cameras[0];
        let cameras: Vec<Camera> = std::iter::once(first)
            .chain(prepared.scene.cameras.iter().map(Camera::from_scene).filter(|c| *c != first))
            .collect();
        let ctx = egui::Context::default();
        let input = egui_winit::State::new(
            ctx.clone(),
            egui::ViewportId::ROOT,
            &window,
            Some(window.scale_factor() as f32),
            None,
            Some(gpu.device.limits().max_texture_dimension_2d as usize),
        );
        let painter = egui_wgpu::Renderer::new(&gpu.device, format, egui_wgpu::RendererOptions::default());
        let knobs = panel::PanelKnobs {
            quality: self.opts.quality,
            bounces: settings.bounces,
            exposure: settings.exposure,
            shadows: settings.shadows,
            view: settings.view,
            clip: prepared.clip,
        };
        let ui = Ui { ctx, input, painter, visible: self.opts.panel, knobs };
        window.request_redraw();
        self.summary.device = gpu.describe();
        let story = story::StoryUi::new(&prepared.scene);
        let lamps = lamps::LampEditor::new(
            o.lights.clone(),
            grotto_format::Package::open(&o.package)?.scene()?.lights,
        );
        self.state = Some(State {
            window,
            gpu,
            surface,
            config,
            blit,
            ui,
            renderer,
            scene: prepared.scene,
            follow,
            chosen_for: Some((prepared.cameras[0], prepared.clip)),
            bounds_m,
            cameras,
            camera_index: 0,
            nav,
            held: [false; 6],
            dragging: false,
            cursor: None,
            last_frame: Instant::now(),
            last_camera: None,
            pacer: Pacer::new(self.opts.frame_budget_ms),
            target: self.opts.frame_target_ms.map(FrameTarget::new),
            log: FrameLog::default(),
            recording: self.opts.record_path.as_ref().map(|_| Vec::new()),
            auto_exposure: if o.exposure.is_none() && settings.view.exposed() {
                AutoExposure::FirstFrame
            } else {
                AutoExposure::Off
            },
            shot: None,
            quit_after_shot: false,
            frame_ms: 0.0,
            trace: std::env::var_os("GROTTO_VIEW_TRACE").map(|_| pace::Trace::default()),
            story,
            lamps,
        });
        if let Some(s) = &mut self.state {
            let_go_of_tiles(s);
        }
        Ok(())
    }

    fn frame(&mut self, event_loop: &ActiveEventLoop) -> Result<()> {
        let Some(s) = self.state.as_mut() else { return Ok(()) };
        let now = Instant::now();
        let dt = now.duration_since(s.last_frame).as_secs_f32().min(0.25);
        s.last_frame = now;
        let flying = s.story.step(&s.gpu, &mut s.nav, s.held, dt)?;
        let cam = s.nav.camera();
        let moving = flying || s.last_camera.is_some_and(|c| c != cam);
        s.last_camera = Some(cam);

        let swapped = follow_camera(s, cam)?;
        self.summary.tile_swaps += u32::from(swapped);
        for n in s.follow.as_mut().map(|f| f.take_notices()).unwrap_or_default() {
            eprintln!("warning: {n}");
            self.summary.warnings.push(n);
        }
        if let (true, Some(after)) = (swapped, self.opts.after_swap) {
            after();
        }

        // Moving, the frame-time target trades scale and detail; at rest they come back.
        let (t_scale, detail) = s.target.as_ref().map_or((1.0, 1.0), |t| t.for_frame(moving));
        let scale = (self.opts.render_scale * t_scale).clamp(0.05, 1.0);
        s.renderer.set_lod_detail(detail);
        let (w, h) = (
            ((s.config.width as f32 * scale) as u32).max(1),
            ((s.config.height as f32 * scale) as u32).max(1),
        );
        let bounces_before = s.renderer.stats().bounces_done;
        // At rest with the light in, each frame adds a sample a pixel jittered within it
        // (anti-aliasing at rest, passes/resolve.rs) until the still frame is complete.
        let loading = s.follow.as_ref().is_some_and(|f| f.busy());
        let still = |r: &Renderer| {
            let settled = r.light_progress().converged || !r.settings().view.shows_light();
            !moving && settled && !loading
        };
        let mut pacing = pace::TimedSlices::new(&mut s.pacer, moving);
        let drawn =
            crate::viewer::light_then_draw(&mut s.renderer, &cam, (w, h), moving, &mut pacing, still)?;
        let (plan, t) = (drawn.plan, drawn.draw_started);
        s.story.drawn(&s.renderer, &cam, (s.config.width, s.config.height), (w, h))?;
        if !(plan.runs(crate::light::plan::Pass::Shadow) || plan.runs(crate::light::plan::Pass::Inject)) {
            // Direct light (after a change of lights or tiles) is not what a frame costs.
            let draw_ms = t.elapsed().as_secs_f64() * 1e3;
            s.pacer.record_draw(draw_ms);
            if moving && let Some(target) = &mut s.target {
                target.record_moving(draw_ms);
            }
        }
        let bounces = s.renderer.stats().bounces_done.saturating_sub(bounces_before);
        let progress = s.renderer.light_progress();
        let expose = match s.auto_exposure {
            AutoExposure::FirstFrame => Some(AutoExposure::AtConvergence),
            AutoExposure::AtConvergence if progress.converged => Some(AutoExposure::Done),
            _ => None,
        };
        if let Some(next) = expose {
            let e = crate::render::auto_exposure(&s.renderer.read_frame()?.hdr);
            s.renderer.set_exposure(e);
            s.ui.knobs.exposure = e;
            s.auto_exposure = next;
            s.renderer.draw(&cam, w, h)?;
        }

        self.present(moving, progress, &plan)?;
        let Some(s) = self.state.as_mut() else { return Ok(()) };
        let frame_ms = now.elapsed().as_secs_f64() * 1e3;
        s.frame_ms = if s.frame_ms == 0.0 { frame_ms } else { 0.9 * s.frame_ms + 0.1 * frame_ms };
        s.log.frame(frame_ms, moving, progress.converged, bounces);
        if moving {
            s.log.moving_traded.push((scale, detail));
        }
        if let Some(trace) = &mut s.trace {
            let state = format!(
                "moving {moving} bounces {bounces} {progress:?} view {} shot pending {} loading {loading}",
                s.renderer.settings().view.name(),
                s.shot.is_some(),
            );
            trace.frame(self.summary.frames, frame_ms, &state, &drawn.light_plan);
        }
        self.summary.frames += 1;
        if let Some(keys) = &mut s.recording
            && keyframe_due(keys.last(), &cam)
        {
            keys.push(cam);
        }

        let at_rest = !moving
            && (progress.converged || !s.renderer.settings().view.shows_light())
            && s.follow.as_ref().is_none_or(|f| !f.busy())
            && s.renderer.still_progress().is_some_and(|p| p.complete());
        s.story.at_rest = at_rest;
        if self.summary.frames >= self.opts.after_frames.unwrap_or(u32::MAX) && at_rest && s.shot.is_none() {
            s.shot = Some(shot_path(&self.opts));
            s.quit_after_shot = true;
        }
        if at_rest && let Some(path) = s.shot.take() {
            // The frame just presented, read back (not drawn again).
            image_out::write_frame(&s.renderer.read_frame()?, &path)?;
            self.summary.screenshots.push(path.display().to_string());
            if s.quit_after_shot {
                event_loop.exit();
                return Ok(());
            }
        }
        // At rest with the light converged, nothing changes until an event: the loop waits
        // (but for the frames a scripted screenshot waits for: a view without light rests at once).
        let scripted = self.summary.frames < self.opts.after_frames.unwrap_or(0);
        if !at_rest || scripted || s.shot.is_some() || s.recording.is_some() || s.story.busy(&cam) {
            s.window.request_redraw();
        }
        Ok(())
    }

    /// Blits the frame with the convergence bar, and draws the panel over it.
    fn present(
        &mut self,
        moving: bool,
        progress: LightProgress,
        plan: &crate::light::plan::EffectPlan,
    ) -> Result<()> {
        let Some(s) = self.state.as_mut() else { return Ok(()) };
        let Some(out) = s.renderer.ldr_output() else { return Ok(()) };
        let Some(frame) = crate::render::present::acquire(&s.gpu, &s.surface, &s.config) else {
            return Ok(());
        };
        let held = moving && !progress.converged;
        let view = frame.texture.create_view(&Default::default());
        let mut enc = s.gpu.device.create_command_encoder(&Default::default());
        let target = Target {
            view: &view,
            width: s.config.width,
            height: s.config.height,
            srgb: s.config.format.is_srgb(),
        };
        s.blit.record(&s.gpu, &mut enc, &out, &target, progress.fraction(), Bar::of(&progress, moving));
        let mut edit = None;
        if s.ui.visible {
            let shown = model(s, progress, held, plan);
            let raw = s.ui.input.take_egui_input(&s.window);
            let mut knobs = s.ui.knobs;
            let (cam, window_px, recording) =
                (s.nav.camera(), (s.config.width, s.config.height), s.recording.is_some());
            let (story, lamps, scene) = (&mut s.story, &mut s.lamps, &s.scene);
            let mut lamp_edit = None;
            let mut out = s.ui.ctx.run_ui(raw, |ui| {
                panel::show(ui.ctx(), &shown, &mut knobs);
                story.show(ui.ctx(), &cam, (window_px, recording), scene.circuits());
                lamp_edit = lamp_edit.take().or(lamps.show(ui.ctx(), scene));
            });
            s.ui.input.handle_platform_output(&s.window, out.platform_output);
            let screen = egui_wgpu::ScreenDescriptor {
                size_in_pixels: [s.config.width, s.config.height],
                pixels_per_point: out.pixels_per_point,
            };
            let jobs = s.ui.ctx.tessellate(out.shapes, out.pixels_per_point);
            for (id, deltas) in &out.textures_delta.set {
                for delta in deltas {
                    s.ui.painter.update_texture(&s.gpu.device, &s.gpu.queue, *id, delta);
                }
            }
            let extra = s.ui.painter.update_buffers(&s.gpu.device, &s.gpu.queue, &mut enc, &jobs, &screen);
            {
                let pass = enc.begin_render_pass(&wgpu::RenderPassDescriptor {
                    label: Some("panel"),
                    color_attachments: &[Some(wgpu::RenderPassColorAttachment {
                        view: &view,
                        depth_slice: None,
                        resolve_target: None,
                        ops: wgpu::Operations { load: wgpu::LoadOp::Load, store: wgpu::StoreOp::Store },
                    })],
                    depth_stencil_attachment: None,
                    timestamp_writes: None,
                    occlusion_query_set: None,
                    multiview_mask: None,
                });
                s.ui.painter.render(&mut pass.forget_lifetime(), &jobs, &screen);
            }
            s.gpu.queue.submit(extra.into_iter().chain([enc.finish()]));
            for id in &out.textures_delta.free {
                s.ui.painter.free_texture(id);
            }
            // Applied above (epaint checks that none is dropped unapplied).
            out.textures_delta.clear();
            if knobs != s.ui.knobs {
                apply_knobs(s, knobs)?;
            }
            edit = lamp_edit;
        } else {
            s.gpu.queue.submit([enc.finish()]);
        }
        s.window.pre_present_notify();
        s.gpu.queue.present(frame);
        s.gpu.check("window")?;
        // Lighting mode works with the panel hidden too (clicks and keys).
        lamps::update(s, edit)
    }

    fn key(&mut self, event_loop: &ActiveEventLoop, code: KeyCode, pressed: bool) -> Result<()> {
        let Some(s) = self.state.as_mut() else { return Ok(()) };
        if pressed && (s.story.key(code, s.nav.camera(), s.recording.is_some()) || lamps::key(s, code)?) {
            return Ok(());
        }
        let held = [KeyCode::KeyW, KeyCode::KeyA, KeyCode::KeyS, KeyCode::KeyD, KeyCode::KeyQ, KeyCode::KeyE];
        if let Some(k) = held.iter().position(|c| *c == code) {
            s.held[k] = pressed;
            return Ok(());
        }
        if !pressed {
            return Ok(());
        }
        let views = [
            KeyCode::Digit1,
            KeyCode::Digit2,
            KeyCode::Digit3,
            KeyCode::Digit4,
            KeyCode::Digit5,
            KeyCode::Digit6,
            KeyCode::Digit7,
        ];
        if let Some(k) = views.iter().position(|c| *c == code) {
            s.renderer.set_view(ViewMode::ALL[k]);
            s.ui.knobs.view = ViewMode::ALL[k];
            return Ok(());
        }
        let speed = s.nav.speed_m_s;
        match code {
            KeyCode::Escape if s.shot.is_some() => s.quit_after_shot = true,
            KeyCode::Escape => event_loop.exit(),
            KeyCode::Tab | KeyCode::KeyR => {
                s.camera_index =
                    if code == KeyCode::KeyR { 0 } else { (s.camera_index + 1) % s.cameras.len() };
                s.nav = Nav::from_camera(&s.cameras[s.camera_index], speed);
            }
            KeyCode::KeyO if s.nav.orbit.is_some() => s.nav.fly(),
            KeyCode::KeyO => {
                let (w, h) = s.renderer.ldr_output().map_or((0, 0), |o| (o.width, o.height));
                pick_orbit(s, w / 2, h / 2)?;
            }
            KeyCode::KeyH => s.ui.visible = !s.ui.visible,
            KeyCode::KeyC => {
                let clip = match s.renderer.clip() {
                    Some(_) => None,
                    None => Some(panel::section_at_eye(s.bounds_m, s.nav.camera().eye_m)),
                };
                s.renderer.set_clip(clip);
                s.ui.knobs.clip = clip;
            }
            KeyCode::KeyK => match s.recording.take() {
                None => s.recording = Some(Vec::new()),
                Some(keys) => {
                    self.summary.paths.push(save_path(&self.opts, &keys, &s.scene)?);
                    // The stops marked (T) belong to this recording: written beside it now.
                    self.summary.tours.extend(story::save_tour(&self.opts, &mut s.story, &s.scene)?);
                }
            },
            KeyCode::F11 => {
                let full = s.window.fullscreen().is_none().then_some(Fullscreen::Borderless(None));
                s.window.set_fullscreen(full);
            }
            KeyCode::KeyP => s.shot = Some(shot_path(&self.opts)),
            _ => {}
        }
        s.window.request_redraw();
        Ok(())
    }

    fn fail(&mut self, event_loop: &ActiveEventLoop, e: Error) {
        self.error = Some(e);
        event_loop.exit();
    }
}

/// Orbits the surface point at pixel `(x, y)` of the last frame (nothing there: no change).
fn pick_orbit(s: &mut State, x: u32, y: u32) -> Result<()> {
    let Some(o) = s.renderer.ldr_output() else { return Ok(()) };
    let (w, h) = (o.width, o.height);
    let Some(distance_m) = s.renderer.distance_at(x, y)? else { return Ok(()) };
    let cam = s.nav.camera();
    // The pixel's ray (the same projection the G-buffer drew with).
    let centre = glam::Vec2::new(x as f32 + 0.5, y as f32 + 0.5);
    let dir = crate::render::probe::ray_through(&cam, w, h, centre);
    s.nav.orbit_around(cam.eye_m + dir * distance_m);
    Ok(())
}

/// What the panel shows now.
fn model(
    s: &State,
    progress: LightProgress,
    held: bool,
    plan: &crate::light::plan::EffectPlan,
) -> panel::PanelModel {
    let r = &s.renderer;
    let resident = s.follow.as_ref().map(|f| f.current().totals);
    panel::PanelModel {
        adapter: s.gpu.describe(),
        fps: if s.frame_ms > 0.0 { 1e3 / s.frame_ms } else { 0.0 },
        frame_ms: s.frame_ms,
        traded: s.target.as_ref().map(FrameTarget::traded),
        light: Some(progress),
        held,
        plan: plan.explain(),
        pass_ms: r.stats().last_ms.iter().map(|(p, ms)| (p.name(), *ms)).collect(),
        tiles: resident.map(|t| (t.full_tiles, t.coarse_tiles, t.far_tiles)),
        tile_count: s.scene.tiles.len(),
        tile_bytes: s.scene.tile_bytes(r.settings().radiance_f16),
        pool_bytes: r.pool_bytes(),
        gpu_bytes: r.gpu_bytes(),
        surfels: s.scene.counts().surfels,
        recording: s.recording.as_ref().map(Vec::len),
        orbit: s.nav.orbit.is_some(),
        speed_m_s: s.nav.speed_m_s,
        bounds_m: s.bounds_m,
        eye_m: s.nav.camera().eye_m,
        scans: match r.settings().view {
            ViewMode::Scan => s
                .scene
                .scan_names
                .iter()
                .enumerate()
                .map(|(i, n)| (n.clone(), scan_color(i as u32)))
                .collect(),
            _ => Vec::new(),
        },
    }
}

/// Where tiles stream, the scene lets go of its tile data once the renderer holds it: the loader
/// reads a scene for each change of tiles, and a renderer made anew has it read again
/// ([`follow::Follow::reload_into`]). A package that fits keeps its scene: a new renderer is made
/// from it as it is.
fn let_go_of_tiles(s: &mut State) {
    if s.follow.is_some() {
        s.scene.release_tile_data();
    }
}

/// Tiles follow the camera: takes what the loader has ready (true where the tiles changed), and
/// asks for the view now.
fn follow_camera(s: &mut State, cam: Camera) -> Result<bool> {
    let Some(f) = &mut s.follow else { return Ok(false) };
    let mut swapped = false;
    if let Some(arrived) = f.poll()? {
        if let Some(new_scene) = arrived.scene {
            let whole = || f.load_whole(&arrived.residency);
            crate::stream::swap_tiles(
                &s.gpu,
                &mut s.renderer,
                &mut s.scene,
                (new_scene, f.package()),
                whole,
            )?;
            s.scene.release_tile_data();
            swapped = true;
        }
        if arrived.rest > 0 {
            // The change came in part: the rest is asked for next.
            s.chosen_for = None;
        }
        f.accept(arrived.residency);
    }
    let want = (cam, s.renderer.clip());
    if s.chosen_for != Some(want) && !f.busy() {
        f.request(&cam, want.1, (s.scene.lights.clone(), s.scene.headlamp), s.scene.held_tiles());
        s.chosen_for = Some(want);
    }
    Ok(swapped)
}

/// Applies what the panel changed.
fn apply_knobs(s: &mut State, k: panel::PanelKnobs) -> Result<()> {
    let old = s.ui.knobs;
    if k.quality != old.quality
        && let Some(q) = k.quality
    {
        // The march's constants are baked into the passes: a new renderer, its light from dark.
        let settings = s.renderer.settings().with_preset(q);
        let caps = s.renderer.pool_caps();
        s.renderer = match &s.follow {
            Some(f) => {
                f.reload_into(&mut s.scene)?;
                Renderer::with_pools(&s.gpu, &s.scene, settings, caps)?
            }
            None => Renderer::new(&s.gpu, &s.scene, settings)?,
        };
        let_go_of_tiles(s);
        s.renderer.set_clip(k.clip);
        s.ui.knobs = panel::PanelKnobs { quality: k.quality, bounces: s.renderer.settings().bounces, ..k };
        return Ok(());
    }
    if k.bounces != old.bounces {
        s.renderer.set_bounces(k.bounces);
    }
    if k.exposure != old.exposure {
        s.renderer.set_exposure(k.exposure);
        s.auto_exposure = AutoExposure::Off;
    }
    if k.shadows != old.shadows {
        s.renderer.set_shadows(k.shadows);
    }
    if k.view != old.view {
        s.renderer.set_view(k.view);
    }
    if k.clip != old.clip {
        s.renderer.set_clip(k.clip);
    }
    s.ui.knobs = k;
    Ok(())
}

impl ApplicationHandler for App {
    fn resumed(&mut self, event_loop: &ActiveEventLoop) {
        if self.state.is_none()
            && let Err(e) = self.start(event_loop)
        {
            self.fail(event_loop, e);
        }
    }

    fn window_event(&mut self, event_loop: &ActiveEventLoop, _id: WindowId, event: WindowEvent) {
        // The panel sees input first; what it takes (a click on a slider) does not fly the camera.
        let taken = match self.state.as_mut() {
            Some(s) if s.ui.visible => {
                let r = s.ui.input.on_window_event(&s.window, &event);
                if r.repaint && !matches!(event, WindowEvent::RedrawRequested) {
                    s.window.request_redraw();
                }
                r.consumed
            }
            _ => false,
        };
        // Input wakes a loop that waits at rest (other events, such as the redraw itself, do not).
        if let Some(s) = self.state.as_mut()
            && matches!(
                event,
                WindowEvent::KeyboardInput { .. }
                    | WindowEvent::MouseInput { .. }
                    | WindowEvent::CursorMoved { .. }
                    | WindowEvent::MouseWheel { .. }
                    | WindowEvent::Resized(_)
                    | WindowEvent::Focused(_)
            )
        {
            s.window.request_redraw();
        }
        let outcome = match event {
            WindowEvent::CloseRequested => {
                event_loop.exit();
                Ok(())
            }
            WindowEvent::Resized(size) => {
                if let Some(s) = self.state.as_mut() {
                    s.config.width = size.width.max(1);
                    s.config.height = size.height.max(1);
                    s.surface.configure(&s.gpu.device, &s.config);
                }
                Ok(())
            }
            WindowEvent::RedrawRequested => self.frame(event_loop),
            _ if taken => Ok(()),
            WindowEvent::KeyboardInput { event, .. } => match event.physical_key {
                PhysicalKey::Code(code) => self.key(event_loop, code, event.state == ElementState::Pressed),
                PhysicalKey::Unidentified(_) => Ok(()),
            },
            WindowEvent::MouseInput { state, button: MouseButton::Left, .. } => {
                if let Some(s) = self.state.as_mut() {
                    s.dragging = state == ElementState::Pressed;
                    s.story.mouse(s.dragging, s.cursor, s.lamps.on);
                }
                Ok(())
            }
            WindowEvent::MouseInput { state: ElementState::Pressed, button: MouseButton::Right, .. } => {
                match self.state.as_mut() {
                    Some(s) => match (s.cursor, s.renderer.ldr_output().map(|o| o.width)) {
                        (Some((x, y)), Some(w)) => {
                            // Window pixels to the frame's (it is drawn at --render-scale).
                            let k = w as f64 / f64::from(s.config.width.max(1));
                            pick_orbit(s, (x * k) as u32, (y * k) as u32)
                        }
                        _ => Ok(()),
                    },
                    None => Ok(()),
                }
            }
            WindowEvent::CursorMoved { position, .. } => {
                if let Some(s) = self.state.as_mut() {
                    if let (true, Some((x, y))) = (s.dragging, s.cursor) {
                        s.story.guide.take_over();
                        s.nav.look((position.x - x) as f32, (position.y - y) as f32);
                    }
                    s.cursor = Some((position.x, position.y));
                }
                Ok(())
            }
            WindowEvent::MouseWheel { delta, .. } => {
                if let Some(s) = self.state.as_mut() {
                    let lines = match delta {
                        MouseScrollDelta::LineDelta(_, y) => y,
                        MouseScrollDelta::PixelDelta(p) => p.y as f32 / 40.0,
                    };
                    s.nav.wheel(lines);
                }
                Ok(())
            }
            _ => Ok(()),
        };
        if let Err(e) = outcome {
            self.fail(event_loop, e);
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn orbit_keeps_the_pivot_in_view_and_fly_resumes_where_the_orbit_left_the_eye() {
        let c = Camera { eye_m: Vec3::ZERO, look_at_m: Vec3::X, up: Vec3::Z, fov_y_deg: 60.0 };
        let mut nav = Nav::from_camera(&c, 1.0);
        let pivot = Vec3::new(4.0, 3.0, 0.0);
        nav.orbit_around(pivot);
        let at = nav.camera();
        assert!(at.eye_m.length() < 1e-5 && (at.look_at_m - pivot).length() < 1e-5, "{at:?}");
        nav.yaw_rad += 1.0;
        let turned = nav.camera();
        assert!((turned.look_at_m - pivot).length() < 1e-5);
        assert!(((turned.eye_m - pivot).length() - 5.0).abs() < 1e-4, "same distance");
        nav.fly();
        assert!((nav.camera().eye_m - turned.eye_m).length() < 1e-5);
    }

    #[test]
    fn keyframes_come_with_movement_not_with_time() {
        let c = Camera { eye_m: Vec3::ZERO, look_at_m: Vec3::X, up: Vec3::Z, fov_y_deg: 60.0 };
        assert!(keyframe_due(None, &c));
        assert!(!keyframe_due(Some(&c), &c));
        let moved = Camera { eye_m: Vec3::new(0.3, 0.0, 0.0), look_at_m: Vec3::new(1.3, 0.0, 0.0), ..c };
        assert!(keyframe_due(Some(&c), &moved));
        let turned = Camera { look_at_m: Vec3::new(1.0, 0.2, 0.0), ..c };
        assert!(keyframe_due(Some(&c), &turned), "11 degrees");
    }
}
