//! The browser viewer: grotto's renderer on WebGPU, in a page `grotto publish` writes. A thin
//! shell, like the window's: the package arrives by HTTP range requests ([`fetch`]) — its head
//! and directory first, then the sections of every tile at its far level (the first frame), then
//! finer tiles in the streaming priority residency gives them (`grotto_runtime::stream`), a step
//! of at most `step_mb` at a time, swapped into the renderer's pools in place. Nothing blocks on
//! the GPU: a bounce's change arrives on a later frame (the renderer counts it before its next plan), and a frame
//! is recorded only once the last one's work is done, so light work never piles up in the
//! queue. The page's script (web/static/index.html) owns the DOM: it forwards input to a
//! [`Viewer`], shows the status [`Viewer::frame`] returns, and sets the ready marker.
//!
//! On other targets the crate is empty.
#![cfg(target_arch = "wasm32")]

mod error;
mod fetch;
use fetch::{FETCH_GAP, Source, fetch_all, insert};
mod health;
mod page;
mod story;

pub use error::Error;
use error::to_js;
pub use grotto_runtime::guide::{LabelStatus, MeasureStatus, TourStatus};
pub use page::{Options, Status};
use page::{parse_options, settings_of};

use std::cell::RefCell;
use std::rc::Rc;
use std::sync::{Arc, Mutex};

use grotto_runtime::engine::memory::MemoryPlan;
use grotto_runtime::engine::{self, Load, SceneRequest};
use grotto_runtime::gpu::{Gpu, GpuOptions, PendingRead};
use grotto_runtime::guide::{Guide, PickFor};
use grotto_runtime::light::plan::Pass;
use grotto_runtime::render::Renderer;
use grotto_runtime::render::present::{Bar, Blit, Target};
use grotto_runtime::scene::data::{SceneData, TileMode};
use grotto_runtime::settings::ViewMode;
use grotto_runtime::stream::residency::{self, Budget, Residency};
use grotto_runtime::stream::{self, Streaming};
use grotto_runtime::view::camera::{Camera, Nav};
use grotto_runtime::view::frame_target::FrameTarget;
use grotto_runtime::view::framing::{CameraChoice, resolve_camera};
use grotto_runtime::viewer::{LightPacing, REST_FRAME_MS, light_then_draw};
use wasm_bindgen::prelude::*;
use web_time::Instant;

/// Where a fetch under way leaves its result for the next frame.
type Slot = Rc<RefCell<Option<Result<Vec<fetch::Fetched>, Error>>>>;

/// A step of tiles on its way: the residency, and the fetch's result once it arrived.
struct Step {
    residency: Residency,
    arrived: Slot,
}

struct State {
    gpu: Gpu,
    surface: wgpu::Surface<'static>,
    config: wgpu::SurfaceConfiguration,
    blit: Blit,
    renderer: Renderer,
    scene: SceneData,
    streaming: Streaming,
    source: Source,
    current: Residency,
    step: Option<Step>,
    step_bytes: u64,
    /// The memory budget's split (engine/memory.rs).
    memory: MemoryPlan,
    /// The camera residency last chose for; None: choose again.
    chosen_for: Option<Camera>,
    /// The view wants no other tiles than those resident.
    settled: bool,
    nav: Nav,
    cameras: Vec<(String, Camera)>,
    camera_index: usize,
    width: u32,
    height: u32,
    held: [bool; 6],
    last_input: Instant,
    last_frame: Instant,
    opened: Instant,
    first_frame_ms: f64,
    ready_ms: Option<f64>,
    /// What the frame shown was drawn for, when it was drawn ready and at rest: a frame for the
    /// same (camera, size, view, exposure) would draw the same image, so none is drawn.
    shown_at_rest: Option<(Camera, u32, u32, ViewMode, u32)>,
    frames: u32,
    first_frame_bytes: u64,
    /// When the GPU finished the last frame's work (None: not yet).
    frame_done: Arc<Mutex<Option<Instant>>>,
    /// The last frame recorded, to time once it is done.
    last: Option<LastFrame>,
    /// GPU milliseconds of recent frames, and the leaves of the next light slice.
    recent_ms: Vec<f64>,
    slice_leaves: u32,
    /// Longest frame at rest (ms).
    rest_ms: f64,
    /// The frame-time target while moving.
    target: Option<FrameTarget>,
    /// What the plan said of propagation at the last frame (the panel shows it).
    light_plan: String,
    auto_exposure: bool,
    exposure: f32,
    bar: bool,
    /// The frame read back for automatic exposure, and whether the light had converged then.
    exposure_read: Option<(PendingRead, bool)>,
    exposure_final: bool,
    story: Guide,
    health: health::Health,
}

/// What the page's readiness asks of its own state; the renderer's part is asked apart, so a
/// frame can ask it once its light has run ([`light_then_draw`]).
#[derive(Clone, Copy)]
struct Ready {
    /// No step of tiles on its way, the view settled, no exposure read-back pending, a frame
    /// shown.
    idle: bool,
    exposure_final: bool,
}

impl Ready {
    fn of(s: &State) -> Self {
        Self {
            idle: s.step.is_none() && s.settled && s.exposure_read.is_none() && s.frames > 0,
            exposure_final: s.exposure_final,
        }
    }

    /// At rest with the light in and the exposure final.
    fn holds(self, renderer: &Renderer, moving: bool) -> bool {
        // A view without light (normals, albedo...) waits for neither the light nor the exposure.
        let view = renderer.settings().view;
        (renderer.light_progress().converged || !view.shows_light())
            && !moving
            && self.idle
            && (self.exposure_final || !view.exposed())
    }
}

/// The page's light for one frame: one slice, sized from the last frame's time ([`State::pace`]).
struct OneSlice(Option<u32>);

impl LightPacing for OneSlice {
    fn next_slice(&mut self) -> Option<u32> {
        self.0.take()
    }

    fn slice_ran(&mut self, _leaves: u32) {}
}

/// A frame recorded: when, the leaves its light slice propagated, and whether it was a plain
/// draw (no shadow maps or injection, which a frame does not usually pay for).
#[derive(Clone, Copy, Debug)]
struct LastFrame {
    submitted: Instant,
    leaves: u32,
    plain: bool,
    moving: bool,
    /// The frame ran the shadow pass (its time, which only overstates the pass's, sizes the
    /// next shadow budget: the browser does not time passes).
    shadow: bool,
}

/// The viewer the page drives.
#[wasm_bindgen]
pub struct Viewer {
    state: State,
}

impl std::fmt::Debug for Viewer {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.debug_struct("Viewer").field("adapter", &self.state.gpu.describe()).finish_non_exhaustive()
    }
}

#[wasm_bindgen]
impl Viewer {
    /// Opens the package at `url` on `canvas`; `options` is [`Options`] as JSON. Fetches the
    /// head, directory and the far level of every tile, then draws nothing yet: the first
    /// [`Viewer::frame`] draws.
    pub async fn open(
        canvas: web_sys::HtmlCanvasElement,
        url: String,
        options: String,
    ) -> Result<Viewer, JsError> {
        Self::open_inner(canvas, url, options).await.map_err(to_js)
    }

    async fn open_inner(
        canvas: web_sys::HtmlCanvasElement,
        url: String,
        options: String,
    ) -> Result<Viewer, Error> {
        let opened = Instant::now();
        let o = parse_options(&options)?;
        let mut settings = settings_of(&o)?;
        let rest_ms = page::rest_ms_of(&o, REST_FRAME_MS)?;
        let exposure = settings.exposure;
        let width = o.width.unwrap_or(canvas.width()).clamp(1, 4096);
        let height = o.height.unwrap_or(canvas.height()).clamp(1, 4096);
        canvas.set_width(width);
        canvas.set_height(height);
        let memory = page::memory_plan(&o, u64::from(width) * u64::from(height), &mut settings)?;

        let (surface, gpu) = webgpu(canvas, &memory).await?;

        let (mut source, mut pkg) = Source::open(&url).await?;
        // The first frame: every tile at its far level.
        let far_sections = stream::sections_for(&pkg, &vec![TileMode::Far; pkg.tile_count() as usize], false);
        let ranges = pkg.missing(far_sections, FETCH_GAP);
        let fetched = fetch_all(url.clone(), ranges, source.expect.clone()).await?;
        insert(&mut pkg, &mut source, &fetched)?;
        let world_scene = pkg.scene()?;
        let request = SceneRequest {
            settings: &settings,
            aspect: width as f32 / height as f32,
            budget: Budget { gpu_bytes: memory.pool_bytes, points: memory.points, pools: None },
            relight: page::relight_of(&o)?,
            lamp_string: None,
            story: story::given(&world_scene, o.story.as_ref())?,
            load: Load::FarFirst,
        };
        let aspect = request.aspect;
        let (mut far, streaming) = engine::open_scene(pkg, &request).map_err(|e| match e {
            grotto_runtime::Error::Scene { problem, .. } => Error::Setting(format!("{url}: {problem}")),
            e => e.into(),
        })?;
        let mut streaming = streaming
            .ok_or_else(|| Error::Setting(format!("{url}: the package opened whole, not far-first")))?;

        // The first camera as `grotto render` resolves it (named, the package's first, or
        // framed on the data); Tab goes through the package's named cameras after it.
        let choice = o.camera.clone().map_or(CameraChoice::Default, CameraChoice::Named);
        let (mut camera, framed) = resolve_camera(&far, &choice, aspect, settings.splat_scale)?;
        if let Some(at) = &o.at {
            camera = grotto_runtime::view::story::parse_view_link(at, far.frame_origin_m)
                .map_err(Error::Setting)?;
        }
        let story = Guide::new(far.pois.clone(), far.tours.clone(), far.frame_origin_m);
        let cameras = camera_list(&far, o.camera.clone(), camera);
        if !far.has_own_light() {
            let seen = framed.map(|f| f.estimate);
            engine::add_headlamp(&mut far, &camera, aspect, settings.splat_scale, seen);
        }
        // The pools are sized for the tiles this view wants, which arrive after the first frame.
        let want = streaming.choose(&camera, None)?;
        let renderer = stream::renderer_for(&gpu, &far, settings, Some((&mut streaming, &want)))?;
        far.release_tile_data();
        let current = streaming.far_residency();

        let (config, format) = configure_surface(&surface, &gpu, width, height)?;
        let blit = Blit::new(&gpu, format)?;
        let nav = Nav::for_scene(&camera, &far);
        let now = Instant::now();
        Ok(Viewer {
            state: State {
                first_frame_bytes: source.fetched_bytes,
                gpu,
                surface,
                config,
                blit,
                renderer,
                scene: far,
                streaming,
                source,
                current,
                step: None,
                step_bytes: o.step_mb.map_or(memory.step_bytes, |mb| mb << 20),
                memory,
                chosen_for: None,
                settled: false,
                nav,
                cameras,
                camera_index: 0,
                width,
                height,
                held: [false; 6],
                last_input: now,
                last_frame: now,
                opened,
                first_frame_ms: 0.0,
                ready_ms: None,
                frames: 0,
                // Nothing submitted yet: the first frame may go.
                frame_done: Arc::new(Mutex::new(Some(now))),
                last: None,
                recent_ms: Vec::new(),
                slice_leaves: 4096,
                rest_ms,
                target: page::frame_target_of(&o),
                light_plan: String::new(),
                auto_exposure: o.exposure.is_none(),
                bar: o.bar.unwrap_or(true),
                exposure,
                shown_at_rest: None,
                exposure_read: None,
                exposure_final: o.exposure.is_some(),
                story,
                health: health::Health::default(),
            },
        })
    }

    /// One animation frame: takes arrived tiles, moves the camera, plans and records the passes
    /// the scene calls for, presents. Returns the [`Status`] as JSON.
    pub fn frame(&mut self) -> Result<String, JsError> {
        self.state.frame().map_err(to_js)
    }

    /// A key went down or up (`KeyboardEvent.code`): WASD fly, Q/E down/up, Tab next camera, R
    /// the first, 1-7 the view. Returns whether the viewer used it.
    pub fn key(&mut self, code: &str, down: bool) -> bool {
        self.state.key(code, down)
    }

    /// The mouse dragged by (dx, dy) CSS pixels: look around.
    pub fn drag(&mut self, dx: f32, dy: f32) {
        self.state.take_over();
        self.state.nav.look(dx, dy);
        self.state.last_input = Instant::now();
    }

    /// Two fingers on a touch screen: spread by `scale` since the last call (moves forward),
    /// their midpoint moved by `(dx, dy)` canvas pixels (pans with them).
    pub fn pinch(&mut self, scale: f32, dx: f32, dy: f32) {
        let s = &mut self.state;
        s.take_over();
        s.nav.pinch(scale, dx, dy, s.height as f32);
        s.last_input = Instant::now();
    }

    /// The wheel turned (lines, up positive): flying speed.
    pub fn wheel(&mut self, lines: f32) {
        self.state.nav.wheel(lines);
    }

    /// The package's camera names, in order (JSON).
    pub fn cameras(&self) -> String {
        serde_json::to_string(&self.state.cameras.iter().map(|(n, _)| n).collect::<Vec<_>>())
            .unwrap_or_default()
    }

    /// Jumps to camera `i` of [`Viewer::cameras`].
    pub fn set_camera(&mut self, i: usize) {
        let s = &mut self.state;
        if let Some((_, c)) = s.cameras.get(i) {
            s.camera_index = i;
            s.nav = Nav::from_camera(c, s.nav.speed_m_s);
            s.last_input = Instant::now();
        }
    }

    /// Shows `view` (lit, albedo, normals, light, level, scan).
    pub fn set_view(&mut self, view: &str) -> Result<(), JsError> {
        let v = ViewMode::parse(view).ok_or_else(|| JsError::new(&format!("unknown view {view:?}")))?;
        self.state.renderer.set_view(v);
        Ok(())
    }

    /// The points of interest and tours (JSON: `{"pois": [{name, title, text}], "tours": [{name,
    /// title, stops: [{title, text}]}]}`).
    pub fn story(&self) -> String {
        let st = &self.state.story;
        serde_json::json!({
            "pois": st.pois.iter().map(|p| serde_json::json!({"name": p.name, "title": p.title, "text": p.text})).collect::<Vec<_>>(),
            "tours": st.tours.iter().map(|t| serde_json::json!({
                "name": t.name,
                "title": t.title,
                "stops": t.stops.iter().map(|s| serde_json::json!({"title": s.title, "text": s.text})).collect::<Vec<_>>(),
            })).collect::<Vec<_>>(),
        })
        .to_string()
    }

    /// Flies to point of interest `i` of [`Viewer::story`] (a tour playing stops).
    /// The lighting circuits a visitor can switch (JSON: `[{name, title, on}]`; empty without).
    pub fn circuits(&self) -> String {
        serde_json::to_string(self.state.scene.circuits()).unwrap_or_else(|_| "[]".into())
    }

    /// Switches circuit `name` on or off (show lighting, work lighting...): the page's renderer
    /// takes the new lights and the light converges again, as it does at rest.
    pub fn switch_circuit(&mut self, name: &str, on: bool) -> Result<(), JsError> {
        let s = &mut self.state;
        if s.scene.switch_circuit(name, on).map_err(|e| JsError::new(&e))? {
            // A renderer made anew needs the tiles the page let go: their sections were
            // fetched, and stay.
            let (streaming, current) = (&s.streaming, &s.current);
            let reload = |scene: &mut SceneData| {
                if scene.holds_all_tiles() {
                    return Ok(());
                }
                scene.restore_tile_data(streaming.load(current, Vec::new(), false)?)
            };
            stream::relit(&s.gpu, &mut s.renderer, &mut s.scene, reload)
                .map_err(|e| JsError::new(&e.to_string()))?;
            s.shown_at_rest = None;
        }
        Ok(())
    }

    pub fn fly_to_poi(&mut self, i: usize) {
        let from = self.state.nav.camera();
        self.state.story.fly_to_poi(i, from);
    }

    /// A click or tap at canvas pixel `(x, y)` of the rendered frame: `measure` picks a
    /// measurement's next end, `fly` flies toward the surface there. Answered a few frames later
    /// (the G-buffer's distance is read back without blocking); the status shows it.
    pub fn pick(&mut self, x: f32, y: f32, what: &str) -> Result<(), JsError> {
        let what = match what {
            "measure" => PickFor::Measure,
            "fly" => PickFor::Fly,
            _ => return Err(JsError::new(&format!("pick for {what:?}: expected measure or fly"))),
        };
        self.state.story.pick(x, y, what);
        Ok(())
    }

    /// Forgets the measurement.
    pub fn clear_measure(&mut self) {
        self.state.story.clear_measure();
    }

    /// Plays tour `i` from its first stop.
    pub fn tour_play(&mut self, i: usize) {
        let from = self.state.nav.camera();
        self.state.story.play(i, from);
    }

    /// Pauses (true) or resumes (false) the tour.
    pub fn tour_pause(&mut self, paused: bool) {
        self.state.story.pause(paused);
    }

    /// Goes `delta` stops on (negative: back) and plays from there.
    pub fn tour_step(&mut self, delta: i32) {
        let from = self.state.nav.camera();
        self.state.story.step(delta, from);
    }

    /// Ends the tour where the camera is.
    pub fn tour_stop(&mut self) {
        self.state.story.tour = None;
    }

    /// The camera as a view link (`x,y,z,heading,pitch,fov`), for the page's address.
    pub fn view_link(&self) -> String {
        grotto_runtime::view::story::view_link(&self.state.nav.camera(), self.state.scene.frame_origin_m)
    }

    /// Jumps to the camera of a view link.
    pub fn set_view_link(&mut self, link: &str) -> Result<(), JsError> {
        let s = &mut self.state;
        let c = grotto_runtime::view::story::parse_view_link(link, s.scene.frame_origin_m)
            .map_err(|e| JsError::new(&e))?;
        s.story.flight = None;
        s.story.tour = None;
        s.nav = Nav::from_camera(&c, s.nav.speed_m_s);
        s.last_input = Instant::now();
        Ok(())
    }
}

/// The input stops counting as movement this long after the last event.
const REST_AFTER_MS: u128 = 200;

impl State {
    fn moving(&self) -> bool {
        self.held.iter().any(|h| *h) || self.last_input.elapsed().as_millis() < REST_AFTER_MS
    }

    /// The visitor moves the camera: a flight ends where it is, a tour pauses.
    fn take_over(&mut self) {
        self.story.take_over();
    }

    fn key(&mut self, code: &str, down: bool) -> bool {
        let held = ["KeyW", "KeyA", "KeyS", "KeyD", "KeyQ", "KeyE"];
        if let Some(k) = held.iter().position(|c| *c == code) {
            if down {
                self.take_over();
            }
            self.held[k] = down;
            self.last_input = Instant::now();
            return true;
        }
        if !down {
            return false;
        }
        if let Some(d) = code.strip_prefix("Digit").and_then(|d| d.parse::<usize>().ok()) {
            if let Some(v) = d.checked_sub(1).and_then(|i| ViewMode::ALL.get(i)) {
                self.renderer.set_view(*v);
                return true;
            }
            return false;
        }
        match code {
            "Tab" | "KeyR" => {
                self.take_over();
                let i = if code == "KeyR" { 0 } else { (self.camera_index + 1) % self.cameras.len() };
                self.camera_index = i;
                self.nav = Nav::from_camera(&self.cameras[i].1, self.nav.speed_m_s);
                self.last_input = Instant::now();
                true
            }
            _ => false,
        }
    }

    fn frame(&mut self) -> Result<String, Error> {
        let now = Instant::now();
        let dt = now.duration_since(self.last_frame).as_secs_f32().min(0.25);
        self.last_frame = now;
        self.story.poll(self.nav.camera())?;
        let settled = self.image_final(false);
        match self.story.camera(dt, settled) {
            Some(c) => self.nav = Nav::from_camera(&c, self.nav.speed_m_s),
            None => self.nav.step(self.held, dt),
        }
        let moving = self.moving() || self.story.flying();
        let camera = self.nav.camera();

        // The GPU still works on the last frame: record nothing more (the queue would only grow).
        let Some(done) = self.frame_done.lock().ok().and_then(|t| *t) else {
            return self.status(moving);
        };
        if let Some(last) = self.last.take() {
            self.pace(last, done);
        }
        self.tiles(&camera, moving)?;
        self.exposure_step()?;
        // Ready and at rest, the image shown is the one this frame would draw: draw nothing, so a
        // weak adapter leaves the page (and a laptop its GPU) alone until something changes.
        let rest_key =
            (camera, self.width, self.height, self.renderer.settings().view, self.exposure.to_bits());
        if self.ready(moving) && self.shown_at_rest == Some(rest_key) {
            // Clicks on the frame at rest still need its distances.
            self.story.drawn(
                &self.renderer,
                &camera,
                (self.width, self.height),
                (self.width, self.height),
            )?;
            return self.status(moving);
        }
        self.shown_at_rest = None;
        // Light first, one slice of a bounce at rest sized by `pace` (as the window viewer does,
        // window/mod.rs); then the frame with the light held, so the draw does not run the rest of
        // the bounce.
        let submitted = Instant::now();
        *self.frame_done.lock().map_err(|_| Error::Setting("frame timing poisoned".into()))? = None;
        // Moving, the frame-time target trades scale and detail; at rest they come back.
        let (scale, detail) = self.target.as_ref().map_or((1.0, 1.0), |t| t.for_frame(moving));
        // The budget's image scale holds at rest too: targets larger would pass their share.
        let scale = scale * self.memory.pixel_scale;
        self.renderer.set_lod_detail(detail);
        let (w, h) =
            (((self.width as f32 * scale) as u32).max(1), ((self.height as f32 * scale) as u32).max(1));
        // Ready, each frame adds a sample a pixel jittered within it (anti-aliasing at rest,
        // passes/resolve.rs); the page rests once the still frame is complete.
        let ready = Ready::of(self);
        let mut pacing = OneSlice(Some(self.slice_leaves));
        let drawn = light_then_draw(&mut self.renderer, &camera, (w, h), moving, &mut pacing, |r| {
            ready.holds(r, moving)
        })?;
        self.light_plan = (drawn.light_plan.steps.iter())
            .find(|s| s.pass == Pass::Propagate)
            .map(|s| s.reason.clone())
            .unwrap_or_default();
        self.present(moving)?;
        self.story.drawn(&self.renderer, &camera, (self.width, self.height), (w, h))?;
        self.frames += 1;
        if self.image_final(moving) {
            self.shown_at_rest = Some(rest_key);
        }
        if self.frames == 1 {
            self.first_frame_ms = self.opened.elapsed().as_secs_f64() * 1e3;
        }
        // Direct light (after a change of lights or tiles) is not what a frame costs.
        let (plain, shadow) = (!drawn.direct_light(), drawn.shadow());
        let leaves = drawn.leaves as u32;
        self.last = Some(LastFrame { submitted, leaves, plain, moving, shadow });
        let frame_done = self.frame_done.clone();
        self.gpu.queue.on_submitted_work_done(move || {
            if let Ok(mut t) = frame_done.lock() {
                *t = Some(Instant::now());
            }
        });
        self.status(moving)
    }

    /// Sizes the next light slice from what the last frame took on the GPU (submitted onto an
    /// idle queue, reported done: the only timing a browser gives without timestamp queries,
    /// and too coarse to split a frame into its light and its draw). As the window's pacer
    /// (window/pace.rs): a frame at rest aims at `rest_ms` (`REST_FRAME_MS` unless the page says),
    /// or at twice the draw where the draw alone takes more, so the light always gets at least
    /// the draw's time; the draw is the quickest recent frame.
    fn pace(&mut self, last: LastFrame, done: Instant) {
        let ms = done.saturating_duration_since(last.submitted).as_secs_f64() * 1e3;
        if last.shadow {
            self.renderer.note_shadow_frame_ms(ms);
        }
        if !last.plain {
            return;
        }
        if last.moving
            && let Some(t) = &mut self.target
        {
            t.record_moving(ms);
        }
        self.recent_ms.push(ms);
        if self.recent_ms.len() > 32 {
            self.recent_ms.remove(0);
        }
        if last.leaves == 0 {
            return;
        }
        let draw_ms = self.recent_ms.iter().copied().fold(f64::INFINITY, f64::min);
        let target = self.rest_ms.max(2.0 * draw_ms);
        let k = (target / ms.max(1.0)).clamp(0.5, 1.5);
        self.slice_leaves = ((f64::from(self.slice_leaves) * k) as u32).clamp(64, 1 << 24);
    }

    /// Streaming: takes a step of tiles that arrived, or starts the next one where the camera
    /// rests and the view wants other tiles.
    fn tiles(&mut self, camera: &Camera, moving: bool) -> Result<(), Error> {
        if let Some(step) = &self.step {
            let Some(arrived) = step.arrived.borrow_mut().take() else { return Ok(()) };
            let step = self.step.take().expect("checked above");
            // A failed step is tried again later or stops streaming (health.rs); the view stays.
            let arrived = match arrived {
                Ok(a) => a,
                Err(e) => {
                    self.chosen_for = None;
                    return self.health.failed(e, Instant::now());
                }
            };
            self.health.succeeded();
            insert(self.streaming.package_mut(), &mut self.source, &arrived)?;
            return self.swap(step.residency);
        }
        if self.health.stopped() {
            // What arrived is all there will be: the view is as settled as it gets.
            self.settled = true;
            return Ok(());
        }
        if moving || self.chosen_for.as_ref() == Some(camera) || !self.health.may_fetch(Instant::now()) {
            return Ok(());
        }
        let want = self.streaming.choose(camera, self.renderer.clip())?;
        let want = residency::cap_modes(self.streaming.tiles(), want, &self.health.damaged);
        let (next, deferred) =
            residency::limit_uploads(self.streaming.tiles(), &self.current, want, self.step_bytes);
        self.settled = deferred == 0 && next.modes() == self.current.modes();
        if next.modes() == self.current.modes() {
            self.chosen_for = Some(*camera);
            return Ok(());
        }
        let ranges = self.streaming.package().missing(self.streaming.sections_for(&next), FETCH_GAP);
        if ranges.is_empty() {
            return self.swap(next);
        }
        let arrived: Slot = Rc::new(RefCell::new(None));
        let slot = arrived.clone();
        let url = self.source.url.clone();
        let expect = self.source.expect.clone();
        wasm_bindgen_futures::spawn_local(async move {
            let r = fetch_all(url, ranges, expect).await;
            *slot.borrow_mut() = Some(r);
        });
        self.step = Some(Step { residency: next, arrived });
        Ok(())
    }

    fn swap(&mut self, next: Residency) -> Result<(), Error> {
        // Only the tile forms the renderer lacks are decoded; the page keeps none once its GPU
        // holds them (wasm memory never shrinks back from a peak).
        let held = self.scene.held_tiles();
        let scene =
            match self.streaming.load_changes(&next, self.scene.lights.clone(), self.scene.headlamp, &held) {
                Ok(scene) => scene,
                // Damaged sections: their tiles stay as they are (health.rs), the rest stream on.
                Err(grotto_runtime::Error::Package(e)) => {
                    let e = Error::Package(e);
                    self.health.damaged_step(self.streaming.package(), &self.current, &next, &e);
                    self.chosen_for = None;
                    return Ok(());
                }
                Err(e) => return Err(e.into()),
            };
        let whole = || self.streaming.load(&next, Vec::new(), false);
        let pkg = self.streaming.package();
        stream::swap_tiles(&self.gpu, &mut self.renderer, &mut self.scene, (scene, pkg), whole)?;
        self.scene.release_tile_data();
        self.current = next;
        // Fetched bytes beyond the budget's cache: only what the tiles now held read is kept,
        // so a long visit holds what its view needs, not all it has seen.
        if self.streaming.package().held_bytes() > self.memory.fetch_cache_bytes {
            let keep = self.streaming.sections_for(&self.current);
            self.streaming.package_mut().release_fetched(keep);
        }
        // Choose again: the step may have been one of several.
        self.chosen_for = None;
        self.settled = false;
        // New tiles change the light, and so the exposure.
        if self.auto_exposure {
            self.exposure_final = false;
        }
        Ok(())
    }

    /// Automatic exposure as `grotto render` sets it (middle grey over the mean log luminance,
    /// `renderer::auto_exposure`), from a frame read back without blocking: once early, and
    /// again once the light has converged on the tiles the view wants.
    fn exposure_step(&mut self) -> Result<(), Error> {
        if !self.auto_exposure {
            return Ok(());
        }
        if let Some((read, converged)) = &self.exposure_read {
            let Some(bytes) = read.take() else { return Ok(()) };
            let converged = *converged;
            self.exposure_read = None;
            let bytes = bytes?;
            let hdr: Vec<[f32; 4]> = bytemuck::pod_collect_to_vec(&bytes);
            self.exposure = grotto_runtime::render::auto_exposure(&hdr);
            self.renderer.set_exposure(self.exposure);
            self.exposure_final = converged;
            return Ok(());
        }
        // A view without light (normals, albedo...) or on a fixed scale (lux) says nothing of the
        // exposure the lit view wants.
        if !self.renderer.settings().view.exposed() {
            return Ok(());
        }
        let converged = self.renderer.light_progress().converged && self.settled && self.step.is_none();
        let due = (self.frames == 1) || (converged && !self.exposure_final);
        if due && let Some((out, hdr_bytes)) = self.renderer.hdr_output() {
            let read = self.gpu.start_read(out, hdr_bytes);
            self.exposure_read = Some((read, converged));
        }
        Ok(())
    }

    fn present(&mut self, moving: bool) -> Result<(), Error> {
        let Some(out) = self.renderer.ldr_output() else { return Ok(()) };
        let Some(frame) = grotto_runtime::render::present::acquire(&self.gpu, &self.surface, &self.config)
        else {
            return Ok(());
        };
        let view = frame.texture.create_view(&Default::default());
        let mut enc = self.gpu.device.create_command_encoder(&Default::default());
        let progress = self.renderer.light_progress();
        let target = Target {
            view: &view,
            width: self.config.width,
            height: self.config.height,
            srgb: self.config.format.is_srgb(),
        };
        let shown = if self.bar { progress.fraction() } else { 0.0 };
        self.blit.record(&self.gpu, &mut enc, &out, &target, shown, Bar::of(&progress, moving));
        self.gpu.queue.submit([enc.finish()]);
        self.gpu.queue.present(frame);
        self.gpu.check("present")?;
        Ok(())
    }

    /// The light has converged, the tiles the view wants are resident, the exposure is final
    /// and the camera rests.
    fn ready(&self, moving: bool) -> bool {
        Ready::of(self).holds(&self.renderer, moving)
    }

    /// Ready, and the still frame's anti-aliasing samples all in: the image will not change.
    fn image_final(&self, moving: bool) -> bool {
        self.ready(moving) && self.renderer.still_progress().is_some_and(|p| p.complete())
    }

    fn status(&mut self, moving: bool) -> Result<String, Error> {
        let progress = self.renderer.light_progress();
        let tiles = page::tile_counts(&self.current.modes());
        // Ready: the image is final, its anti-aliasing samples all in.
        let ready = self.image_final(moving);
        let camera = self.nav.camera();
        if ready && self.ready_ms.is_none() {
            self.ready_ms = Some(self.opened.elapsed().as_secs_f64() * 1e3);
        }
        let s = Status {
            state: if ready { "ready" } else { "converging" },
            adapter: self.gpu.describe(),
            package_bytes: self.source.package_bytes,
            fetched_bytes: self.source.fetched_bytes,
            first_frame_bytes: self.first_frame_bytes,
            requests: self.source.requests,
            fetching: self.step.is_some(),
            tiles,
            bounces_done: progress.bounces_done,
            bounce_budget: progress.bounce_budget,
            light_fraction: progress.fraction(),
            converged: progress.converged,
            frames: self.frames,
            camera: self.cameras.get(self.camera_index).map(|(n, _)| n.clone()).unwrap_or_default(),
            view: self.renderer.settings().view.name(),
            exposure: self.exposure,
            width: self.width,
            height: self.height,
            no_ranges: self.source.no_ranges,
            first_frame_ms: self.first_frame_ms,
            ready_ms: self.ready_ms,
            light_plan: self.light_plan.clone(),
            frame_ms: self.recent_ms.last().copied(),
            traded: self.target.as_ref().map(FrameTarget::traded),
            labels: self.story.labels(&camera, self.width, self.height),
            labels_current: self.story.labels_current(&camera),
            measure: self.story.measure_status(&camera, self.width, self.height),
            tour: self.story.tour_status(),
            link: grotto_runtime::view::story::view_link(&camera, self.scene.frame_origin_m),
            gpu_bytes: self.renderer.gpu_bytes(),
            binding_bytes: self.gpu.device.limits().max_storage_buffer_binding_size,
            streaming: self.health.state(),
            notice: self.health.notice(),
            damaged_tiles: self.health.damaged.len(),
            stream_failures: self.health.failures(),
            wasm_bytes: (core::arch::wasm32::memory_size(0) as u64) << 16,
            budget: self.memory.budget.describe(),
            budget_bytes: self.memory.budget.total_bytes,
            budget_gpu_bytes: self.memory.gpu_bytes,
            held_package_bytes: self.streaming.package().held_bytes(),
        };
        serde_json::to_string(&s).map_err(|e| Error::Setting(e.to_string()))
    }
}

/// A WebGPU surface on `canvas` and a device on the adapter that can show it.
/// The device asks for WebGPU's default limits, and a larger storage binding only where the
/// adapter has one and the budget's pools could use it (engine/memory.rs).
async fn webgpu(
    canvas: web_sys::HtmlCanvasElement,
    memory: &MemoryPlan,
) -> Result<(wgpu::Surface<'static>, Gpu), Error> {
    let mut desc = wgpu::InstanceDescriptor::new_without_display_handle();
    desc.backends = wgpu::Backends::BROWSER_WEBGPU;
    let instance = wgpu::Instance::new(desc);
    let surface = instance
        .create_surface(wgpu::SurfaceTarget::Canvas(canvas))
        .map_err(|e| Error::Setting(format!("no WebGPU canvas: {e}")))?;
    let adapter = instance
        .request_adapter(&wgpu::RequestAdapterOptions {
            power_preference: wgpu::PowerPreference::HighPerformance,
            compatible_surface: Some(&surface),
            ..Default::default()
        })
        .await
        .map_err(|e| Error::Setting(format!("this browser gives no WebGPU adapter: {e}")))?;
    let binding = memory.storage_binding_bytes(adapter.limits().max_storage_buffer_binding_size);
    let opts =
        GpuOptions { webgpu_limits: true, max_storage_binding_bytes: Some(binding), ..Default::default() };
    let gpu = Gpu::on_adapter(adapter, &opts).await?;
    Ok((surface, gpu))
}

/// The viewer's cameras: the first as `grotto render` resolves it (named, the package's first, or
/// framed on the data), then the package's other named cameras, which Tab goes through.
fn camera_list(far: &SceneData, named: Option<String>, camera: Camera) -> Vec<(String, Camera)> {
    let first_name = named.or_else(|| far.cameras.first().map(|c| c.name.clone()));
    std::iter::once((first_name.unwrap_or_else(|| "framed".into()), camera))
        .chain(
            far.cameras.iter().map(|c| (c.name.clone(), Camera::from_scene(c))).filter(|(_, c)| *c != camera),
        )
        .collect()
}

/// The canvas configured for frames of `width` x `height` in a linear (not sRGB) format, shown
/// at the display's pace; returns the configuration and the format the blit writes.
fn configure_surface(
    surface: &wgpu::Surface<'static>,
    gpu: &Gpu,
    width: u32,
    height: u32,
) -> Result<(wgpu::SurfaceConfiguration, wgpu::TextureFormat), Error> {
    let caps = surface.get_capabilities(&gpu.adapter);
    let format = caps.formats.iter().copied().find(|f| !f.is_srgb()).unwrap_or(caps.formats[0]);
    let mut config = surface
        .get_default_config(&gpu.adapter, width, height)
        .ok_or_else(|| Error::Setting(format!("the canvas cannot show {} frames", gpu.describe())))?;
    config.format = format;
    config.present_mode = wgpu::PresentMode::Fifo;
    surface.configure(&gpu.device, &config);
    Ok((config, format))
}
