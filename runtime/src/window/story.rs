//! `grotto view`'s story: the package's points of interest labelled over the frame (hidden where
//! rock is nearer) and listed in a small window that flies to them, its tours played, paused and
//! stepped, measuring between two clicked surface points, a double click flying to the wall
//! there, and tour stops marked while a camera path is recorded. The state and the decisions are
//! the runtime's guide (guide.rs), the browser's too; this is the window's input and egui.
//!
//! Keys: M measures (click two points), G plays or pauses the tour, N and B step to the next and
//! the previous stop, T marks a tour stop while recording (K).

use std::time::Instant;

use crate::error::Result;
use serde::Serialize;

use crate::guide::{Guide, MeasureStatus, PickFor, TourStatus};
use crate::render::Renderer;
use crate::scene::data::SceneData;
use crate::view::camera::{Camera, Nav};
use winit::keyboard::KeyCode;

/// Two clicks this close in time and place are a double click.
const DOUBLE_CLICK_S: f32 = 0.35;
const DOUBLE_CLICK_PX: f64 = 6.0;

/// Writes the tour stops marked while recording (T) beside the path, as a story file (`grotto
/// publish --story`, `grotto render --story`); returns it and its stops, None without stops.
pub(super) fn save_tour(
    opts: &super::ViewOptions,
    story: &mut StoryUi,
    scene: &SceneData,
) -> Result<Option<(String, usize)>> {
    let stops = std::mem::take(&mut story.stops);
    if stops.is_empty() {
        return Ok(None);
    }
    let file = opts.record_path.as_ref().map_or_else(
        || super::next_name("grotto-tour", "toml"),
        |p| p.with_file_name(format!("{}-tour.toml", p.file_stem().unwrap_or_default().to_string_lossy())),
    );
    let text = crate::view::story::tour_toml("recorded", &stops, scene.frame_origin_m, 6.0);
    crate::cli::export::atomically(&file, |mut f| {
        std::io::Write::write_all(&mut f, text.as_bytes())
            .map_err(|e| crate::cli::export::output_error(&file, e))
    })?;
    Ok(Some((file.display().to_string(), stops.len())))
}

pub(super) struct StoryUi {
    pub(super) guide: Guide,
    measuring: bool,
    /// The tour the window's menu picks.
    tour: usize,
    /// Tour stops marked while recording (T).
    pub(super) stops: Vec<Camera>,
    press: Option<(f64, f64)>,
    last_click: Option<(Instant, (f64, f64))>,
    /// The image at rest was final at the last frame (a tour's dwell waits for it).
    pub(super) at_rest: bool,
    /// A circuit switched in the window (name, on), for the window to relight.
    pub(super) switch: Option<(String, bool)>,
}

/// The story's state as `grotto view --json` reports it on exit.
#[derive(Clone, Debug, Serialize)]
pub struct StorySummary {
    /// Points of interest in view and whether rock hides them (None: not probed yet).
    pub labels: Vec<(String, Option<bool>)>,
    pub measure: MeasureStatus,
    pub tour: Option<TourStatus>,
    /// The camera as a view link (`x,y,z,heading,pitch,fov`, world metres).
    pub camera: String,
}

/// The size the last frame was drawn at (the window's before the first).
pub(super) fn drawn_px(s: &super::State) -> (u32, u32) {
    s.renderer.ldr_output().map_or((s.config.width, s.config.height), |o| (o.width, o.height))
}

/// Answers the clicks made so far, before the session's summary and before lighting mode saves
/// its lamps (a frame still drawing then must not lose them): waits for the probe's read-back
/// under way, and probes the last frame drawn for clicks still waiting.
pub(super) fn answer_clicks(s: &mut super::State) -> Result<()> {
    let (full, drawn, cam) = ((s.config.width, s.config.height), drawn_px(s), s.nav.camera());
    let guide = &mut s.story.guide;
    // Two rounds: the probe under way, then one for the clicks that came after it started.
    for _ in 0..2 {
        if !guide.answering() {
            break;
        }
        guide.drawn(&s.renderer, &cam, full, drawn)?;
        s.gpu.wait_for("probe", || {
            guide.poll(cam)?;
            Ok((!guide.probing()).then_some(()))
        })?;
    }
    Ok(())
}

impl StoryUi {
    /// The summary for `camera`'s frame of `size` pixels.
    pub(super) fn summary(&self, camera: &Camera, size: (u32, u32)) -> StorySummary {
        StorySummary {
            labels: (self.guide.labels(camera, size.0, size.1).into_iter())
                .map(|l| (self.guide.pois[l.poi].name.clone(), l.visible))
                .collect(),
            measure: self.guide.measure_status(camera, size.0, size.1),
            tour: self.guide.tour_status(),
            camera: crate::view::story::view_link(camera, self.guide.frame_origin_m()),
        }
    }

    pub(super) fn new(scene: &SceneData) -> Self {
        Self {
            guide: Guide::new(scene.pois.clone(), scene.tours.clone(), scene.frame_origin_m),
            measuring: false,
            tour: 0,
            stops: Vec::new(),
            press: None,
            last_click: None,
            at_rest: false,
            switch: None,
        }
    }

    /// Before a frame: takes arrived probes, then moves the camera along a flight or tour, or
    /// by the keys held. Returns whether the story moved it (the light waits, as for the keys).
    pub(super) fn step(
        &mut self,
        gpu: &crate::gpu::Gpu,
        nav: &mut Nav,
        held: [bool; 6],
        dt_s: f32,
    ) -> Result<bool> {
        // Read-backs complete as the device is polled (a browser does this by itself).
        let _ = gpu.device.poll(wgpu::PollType::Poll);
        self.guide.poll(nav.camera())?;
        if held.iter().any(|h| *h) {
            self.guide.take_over();
        }
        match self.guide.camera(dt_s, self.at_rest) {
            Some(c) => *nav = Nav::from_camera(&c, nav.speed_m_s),
            None => nav.step(held, dt_s),
        }
        Ok(self.guide.flying())
    }

    /// After a frame drawn at `drawn` pixels in a window of `full`: probes labels and clicks.
    pub(super) fn drawn(
        &mut self,
        r: &Renderer,
        cam: &Camera,
        full: (u32, u32),
        drawn: (u32, u32),
    ) -> Result<()> {
        self.guide.drawn(r, cam, full, drawn)
    }

    /// Something is under way that needs frames even at rest (a probe, a flight, a tour).
    pub(super) fn busy(&self, cam: &Camera) -> bool {
        !self.guide.labels_current(cam)
            || self.guide.flying()
            || self
                .guide
                .tour
                .as_ref()
                .is_some_and(|t| !t.paused && t.phase != crate::view::story::TourPhase::Finished)
    }

    /// The story's keys; returns whether one was used.
    pub(super) fn key(&mut self, code: KeyCode, cam: Camera, recording: bool) -> bool {
        match code {
            KeyCode::KeyM => {
                self.measuring = !self.measuring;
                if !self.measuring {
                    self.guide.clear_measure();
                }
            }
            KeyCode::KeyT if recording => self.stops.push(cam),
            KeyCode::KeyG => self.play_or_pause(cam),
            KeyCode::KeyN => self.guide.step(1, cam),
            KeyCode::KeyB => self.guide.step(-1, cam),
            _ => return false,
        }
        true
    }

    fn play_or_pause(&mut self, cam: Camera) {
        match &mut self.guide.tour {
            Some(p) if p.tour == self.tour && p.phase != crate::view::story::TourPhase::Finished => {
                p.paused = !p.paused
            }
            _ => self.guide.play(self.tour, cam),
        }
    }

    /// The left button at `cursor` (window pixels, which the guide takes as they are: it scales
    /// them to the frame drawn): a click without a drag places a lamp (`placing`: lighting mode,
    /// window/lamps.rs) or measures (M), a double click flies to the wall there.
    pub(super) fn mouse(&mut self, pressed: bool, cursor: Option<(f64, f64)>, placing: bool) {
        let Some((x, y)) = cursor else { return };
        if pressed {
            self.press = Some((x, y));
            return;
        }
        let Some((px, py)) = self.press.take() else { return };
        if (x - px).hypot(y - py) > DOUBLE_CLICK_PX {
            return;
        }
        let at = (x as f32, y as f32);
        let double = self.last_click.is_some_and(|(t, (lx, ly))| {
            t.elapsed().as_secs_f32() < DOUBLE_CLICK_S && (x - lx).hypot(y - ly) < DOUBLE_CLICK_PX
        });
        if double {
            self.last_click = None;
            self.guide.pick(at.0, at.1, PickFor::Fly);
        } else {
            self.last_click = Some((Instant::now(), (x, y)));
            if placing {
                self.guide.pick(at.0, at.1, PickFor::Place);
            } else if self.measuring {
                self.guide.pick(at.0, at.1, PickFor::Measure);
            }
        }
    }

    /// The labels and the measurement over the frame, and the story's window (points of
    /// interest, tours, measuring). `window_px`: the window's size in pixels.
    pub(super) fn show(
        &mut self,
        ctx: &egui::Context,
        cam: &Camera,
        (window_px, recording): ((u32, u32), bool),
        circuits: &[grotto_format::Circuit],
    ) {
        let k = 1.0 / ctx.pixels_per_point();
        let painter = ctx.layer_painter(egui::LayerId::background());
        let yellow = egui::Color32::from_rgb(255, 207, 64);
        for l in self.guide.labels(cam, window_px.0, window_px.1) {
            if l.visible == Some(false) {
                continue;
            }
            let at = egui::pos2(l.x * k, l.y * k);
            painter.circle(at, 4.0, yellow, egui::Stroke::new(1.0, egui::Color32::BLACK));
            let title = &self.guide.pois[l.poi].title;
            let font = egui::FontId::proportional(14.0);
            let text = painter.layout_no_wrap(title.clone(), font, egui::Color32::WHITE);
            let rect =
                egui::Rect::from_center_size(at - egui::vec2(0.0, 16.0), text.size() + egui::vec2(10.0, 4.0));
            painter.rect_filled(rect, 3.0, egui::Color32::from_black_alpha(180));
            painter.galley(rect.min + egui::vec2(5.0, 2.0), text, egui::Color32::WHITE);
        }
        let m = self.guide.measure_status(cam, window_px.0, window_px.1);
        let ends: Vec<egui::Pos2> =
            m.pixels.iter().flatten().map(|p| egui::pos2(p[0] * k, p[1] * k)).collect();
        for p in &ends {
            painter.circle_filled(*p, 4.0, yellow);
        }
        if let [a, b] = ends[..] {
            painter.line_segment([a, b], egui::Stroke::new(2.0, yellow));
        }
        egui::Window::new("story").default_pos([8.0, 420.0]).default_width(220.0).show(ctx, |ui| {
            for (i, p) in self.guide.pois.clone().iter().enumerate() {
                if ui.button(&p.title).on_hover_text(&p.text).clicked() {
                    self.guide.fly_to_poi(i, *cam);
                }
            }
            if !self.guide.tours.is_empty() {
                ui.separator();
                let names: Vec<String> = self
                    .guide
                    .tours
                    .iter()
                    .map(|t| if t.title.is_empty() { t.name.clone() } else { t.title.clone() })
                    .collect();
                egui::ComboBox::from_label("tour")
                    .selected_text(names[self.tour.min(names.len() - 1)].clone())
                    .show_ui(ui, |ui| {
                        for (i, n) in names.iter().enumerate() {
                            ui.selectable_value(&mut self.tour, i, n);
                        }
                    });
                ui.horizontal(|ui| {
                    if ui.button("play / pause (G)").clicked() {
                        self.play_or_pause(*cam);
                    }
                    if ui.button("next (N)").clicked() {
                        self.guide.step(1, *cam);
                    }
                });
                if let Some(t) = self.guide.tour_status() {
                    ui.label(format!(
                        "stop {} of {} ({}{}): {}",
                        t.stop + 1,
                        t.stops,
                        t.phase,
                        if t.paused { ", paused" } else { "" },
                        if t.text.is_empty() { &t.title } else { &t.text }
                    ));
                }
            }
            if !circuits.is_empty() {
                ui.separator();
                ui.label("lighting");
                for c in circuits {
                    let mut on = c.on;
                    let title = if c.title.is_empty() { &c.name } else { &c.title };
                    if ui.checkbox(&mut on, title).changed() {
                        self.switch = Some((c.name.clone(), on));
                    }
                }
            }
            ui.separator();
            if ui.checkbox(&mut self.measuring, "measure (M): click two points").changed() && !self.measuring
            {
                self.guide.clear_measure();
            }
            if let Some(r) = m.result {
                ui.label(format!(
                    "{:.3} m apart, height {:+.3} m, level {:.3} m",
                    r.distance_m, r.height_m, r.horizontal_m
                ));
            }
            if recording {
                ui.label(format!("tour stops marked (T): {}", self.stops.len()));
            }
        });
    }
}
