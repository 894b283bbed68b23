//! A viewer's guide to a scene's story, the same in the window and the browser: points of
//! interest labelled over the frame (hidden where rock is nearer, from G-buffer distances read
//! back without blocking: render/probe.rs), flights to them and to a double-clicked wall, guided
//! tours, and measuring between clicked surface points. The decisions are [`crate::view::story`]'s;
//! this holds a viewer's state and what arrives from the GPU a few frames later.

use glam::{DVec3, Vec3};
use serde::Serialize;

use crate::error::Result;
use crate::render::Renderer;
use crate::render::probe::{MAX_PROBE_PIXELS, Probe};
use crate::scene::story::{SceneCamera, ScenePoi, SceneTour};
use crate::view::camera::Camera;
use crate::view::story::{self, Flight, Measurement, TourPlayer};

/// Labels probed at once (the rest of a probe's pixels are for clicks).
const LABELS_PROBED: usize = MAX_PROBE_PIXELS - 16;

/// What a click asked for.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum PickFor {
    /// A measurement's next end.
    Measure,
    /// Fly toward the point (a double tap).
    Fly,
    /// A lamp placed or aimed there (`grotto view`'s lighting mode): [`Guide::placed`].
    Place,
}

/// A probe under way: which of its pixels are labels (by point-of-interest index) and which are
/// clicks.
#[derive(Debug)]
struct Pending {
    probe: Probe,
    labels: Vec<usize>,
    picks: Vec<PickFor>,
}

/// A label as a viewer draws it: canvas pixels, and whether rock hides it (None: not yet known
/// for this view).
#[derive(Clone, Debug, Serialize)]
pub struct LabelStatus {
    pub poi: usize,
    pub x: f32,
    pub y: f32,
    pub distance_m: f32,
    pub visible: Option<bool>,
}

/// The measurement as a viewer shows it: its ends (world metres) and where they show now.
#[derive(Clone, Debug, Serialize)]
pub struct MeasureStatus {
    /// 0, 1 or 2 ends picked.
    pub points: Vec<[f64; 3]>,
    /// Canvas pixels of each end in the current view (None: behind the eye or outside).
    pub pixels: Vec<Option<[f32; 2]>>,
    pub result: Option<Measurement>,
    /// Clicks that found no surface (the background) so far.
    pub missed: u32,
}

/// A tour as a viewer shows it.
#[derive(Clone, Debug, Serialize)]
pub struct TourStatus {
    pub tour: usize,
    pub name: String,
    pub stop: usize,
    pub stops: usize,
    pub phase: &'static str,
    pub paused: bool,
    pub title: String,
    pub text: String,
    pub dwell_left_s: Option<f32>,
}

/// A viewer's story and tools.
#[derive(Debug)]
pub struct Guide {
    pub pois: Vec<ScenePoi>,
    pub tours: Vec<SceneTour>,
    /// Whether rock hides each point of interest, as last probed, and the camera of that probe.
    visible: Vec<Option<bool>>,
    probed_for: Option<Camera>,
    pending: Option<Pending>,
    /// Clicks waiting for a probe: canvas (window) pixels, as [`Guide::pick`] takes them, and
    /// what for.
    picks: Vec<((f32, f32), PickFor)>,
    measure: Vec<DVec3>,
    missed: u32,
    /// A flight to a point of interest or a tapped wall (not a tour's).
    pub flight: Option<Flight>,
    pub tour: Option<TourPlayer>,
    frame_origin_m: [f64; 3],
    /// Surface points picked for [`PickFor::Place`] (frame metres) with the eye they were seen
    /// from, for the caller to take.
    pub placed: Vec<(Vec3, Vec3)>,
}

impl Guide {
    pub fn new(pois: Vec<ScenePoi>, tours: Vec<SceneTour>, frame_origin_m: [f64; 3]) -> Self {
        Self {
            visible: vec![None; pois.len()],
            pois,
            tours,
            probed_for: None,
            pending: None,
            picks: Vec::new(),
            measure: Vec::new(),
            missed: 0,
            flight: None,
            tour: None,
            frame_origin_m,
            placed: Vec::new(),
        }
    }

    /// A click at pixel `(x, y)` of the canvas (the window; not of the frame, which may be drawn
    /// smaller: [`Guide::drawn`] scales it), answered once a probe of the frame shown arrives.
    pub fn pick(&mut self, x: f32, y: f32, what: PickFor) {
        if self.picks.len() < 8 {
            self.picks.push(((x, y), what));
        }
    }

    pub fn clear_measure(&mut self) {
        self.measure.clear();
    }

    /// The camera the story moves this frame (a flight, or a tour's), after `dt_s`; `settled`:
    /// the image at rest is final (a tour's dwell waits for it).
    pub fn camera(&mut self, dt_s: f32, settled: bool) -> Option<Camera> {
        if let Some(f) = &mut self.flight {
            let c = f.advance(dt_s);
            if f.done() {
                self.flight = None;
            }
            return Some(c);
        }
        let player = self.tour.as_mut()?;
        player.tick(self.tours.get(player.tour)?, dt_s, settled)
    }

    /// Flies from `from` to point of interest `i` (a tour playing stops).
    pub fn fly_to_poi(&mut self, i: usize, from: Camera) {
        if let Some(p) = self.pois.get(i) {
            self.tour = None;
            self.flight = Some(Flight::new(from, story::stop_camera(&p.camera), None));
        }
    }

    /// Plays tour `i` from its first stop, flying there from `from`.
    pub fn play(&mut self, i: usize, from: Camera) {
        if let Some(t) = self.tours.get(i) {
            self.flight = None;
            self.tour = Some(TourPlayer::start(i, t, from));
        }
    }

    /// Pauses (true) or resumes (false) the tour playing.
    pub fn pause(&mut self, paused: bool) {
        if let Some(p) = &mut self.tour {
            p.paused = paused;
        }
    }

    /// Goes `delta` stops on (negative: back) and plays from there.
    pub fn step(&mut self, delta: i32, from: Camera) {
        if let Some(p) = &mut self.tour
            && let Some(t) = self.tours.get(p.tour)
        {
            p.step(t, delta, from);
            p.paused = false;
        }
    }

    /// The visitor moves the camera: a flight ends where it is, a tour pauses.
    pub fn take_over(&mut self) {
        self.flight = None;
        self.pause(true);
    }

    /// The story moves the camera (the light waits, as while the visitor moves it).
    pub fn flying(&self) -> bool {
        self.flight.is_some() || self.tour.as_ref().is_some_and(TourPlayer::flying)
    }

    /// Takes an arrived probe: labels' visibility, clicked points; a double tap's point starts
    /// a flight from `from` toward it.
    pub fn poll(&mut self, from: Camera) -> Result<()> {
        if let Some(to) = self.take_probe()? {
            self.tour = None;
            self.flight = Some(Flight::new(from, to, None));
        }
        Ok(())
    }

    fn take_probe(&mut self) -> Result<Option<Camera>> {
        let Some(p) = &self.pending else { return Ok(None) };
        let Some(read) = p.probe.take() else { return Ok(None) };
        let p = self.pending.take().expect("checked above");
        let distances = read?;
        let (w, h) = (p.probe.width, p.probe.height);
        for (k, &i) in p.labels.iter().enumerate() {
            let Some(at) = story::project(&p.probe.camera, w, h, self.pois[i].position_m) else { continue };
            self.visible[i] = Some(!story::hidden(at.distance_m, distances[k]));
        }
        self.probed_for = Some(p.probe.camera);
        let mut fly = None;
        for (k, what) in p.picks.iter().enumerate() {
            let at = p.labels.len() + k;
            let Some(d) = distances[at] else {
                self.missed += 1;
                continue;
            };
            let point = p.probe.point(at, d);
            match what {
                PickFor::Measure => {
                    if self.measure.len() == 2 {
                        self.measure.clear();
                    }
                    self.measure.push(DVec3::from_array(self.frame_origin_m) + point.as_dvec3());
                }
                PickFor::Fly => fly = Some(toward(&p.probe.camera, point)),
                PickFor::Place => self.placed.push((point, p.probe.camera.eye_m)),
            }
        }
        Ok(fly)
    }

    /// After a frame was drawn at `drawn` (rendered size; the canvas is `full`): probes the
    /// labels in view and the clicks waiting, unless a probe is under way.
    pub fn drawn(
        &mut self,
        renderer: &Renderer,
        camera: &Camera,
        full: (u32, u32),
        drawn: (u32, u32),
    ) -> Result<()> {
        if self.pending.is_some() || (self.probed_for == Some(*camera) && self.picks.is_empty()) {
            return Ok(());
        }
        let (sx, sy) = (drawn.0 as f32 / full.0 as f32, drawn.1 as f32 / full.1 as f32);
        let mut seen: Vec<(usize, f32, (u32, u32))> = self
            .pois
            .iter()
            .enumerate()
            .filter_map(|(i, p)| {
                let at = story::project(camera, drawn.0, drawn.1, p.position_m)?;
                Some((i, at.distance_m, (at.x_px as u32, at.y_px as u32)))
            })
            .collect();
        seen.sort_by(|a, b| a.1.total_cmp(&b.1));
        seen.truncate(LABELS_PROBED);
        let picks = std::mem::take(&mut self.picks);
        let mut pixels: Vec<(u32, u32)> = seen.iter().map(|s| s.2).collect();
        pixels.extend(picks.iter().map(|((x, y), _)| ((x * sx) as u32, (y * sy) as u32)));
        let Some(probe) = renderer.start_probe(&pixels)? else {
            self.picks = picks;
            return Ok(());
        };
        self.pending = Some(Pending {
            probe,
            labels: seen.iter().map(|s| s.0).collect(),
            picks: picks.iter().map(|p| p.1).collect(),
        });
        Ok(())
    }

    pub fn labels(&self, camera: &Camera, w: u32, h: u32) -> Vec<LabelStatus> {
        let current = self.probed_for == Some(*camera);
        self.pois
            .iter()
            .enumerate()
            .filter_map(|(i, p)| {
                let at = story::project(camera, w, h, p.position_m)?;
                Some(LabelStatus {
                    poi: i,
                    x: at.x_px,
                    y: at.y_px,
                    distance_m: at.distance_m,
                    // While the view changes, the last known answer (a label does not blink).
                    visible: if current { self.visible[i] } else { self.visible[i].or(Some(true)) },
                })
            })
            .collect()
    }

    /// The scene's frame origin, world metres (what view links are given in).
    pub fn frame_origin_m(&self) -> [f64; 3] {
        self.frame_origin_m
    }

    /// Clicks not answered yet (waiting for a frame's probe, or its read-back under way).
    pub fn answering(&self) -> bool {
        self.pending.is_some() || !self.picks.is_empty()
    }

    /// A probe's read-back under way.
    pub fn probing(&self) -> bool {
        self.pending.is_some()
    }

    /// Whether the labels' visibility is that of `camera`'s view (what a test waits for).
    pub fn labels_current(&self, camera: &Camera) -> bool {
        self.pois.is_empty() || (self.probed_for == Some(*camera) && self.pending.is_none())
    }

    pub fn measure_status(&self, camera: &Camera, w: u32, h: u32) -> MeasureStatus {
        let origin = DVec3::from_array(self.frame_origin_m);
        MeasureStatus {
            points: self.measure.iter().map(|p| p.to_array()).collect(),
            pixels: self
                .measure
                .iter()
                .map(|p| story::project(camera, w, h, (*p - origin).as_vec3()).map(|q| [q.x_px, q.y_px]))
                .collect(),
            result: (self.measure.len() == 2).then(|| Measurement::between(self.measure[0], self.measure[1])),
            missed: self.missed,
        }
    }

    pub fn tour_status(&self) -> Option<TourStatus> {
        let p = self.tour.as_ref()?;
        let t = self.tours.get(p.tour)?;
        let s = t.stops.get(p.stop)?;
        Some(TourStatus {
            tour: p.tour,
            name: t.name.clone(),
            stop: p.stop,
            stops: t.stops.len(),
            phase: p.phase.name(),
            paused: p.paused,
            title: s.title.clone(),
            text: s.text.clone(),
            dwell_left_s: match p.phase {
                story::TourPhase::Dwelling { left_s } => Some(left_s),
                _ => None,
            },
        })
    }
}

/// A camera flown toward `point_m` (a tapped wall), stopping short of it by a third of the way
/// or at least a metre, looking at it.
fn toward(from: &Camera, point_m: Vec3) -> Camera {
    let d = point_m - from.eye_m;
    let len = d.length();
    let stop = (len / 3.0).max(1.0).min(len * 0.9);
    let eye_m = point_m - d / len.max(1e-6) * stop;
    story::stop_camera(&SceneCamera {
        name: String::new(),
        eye_m,
        look_at_m: point_m,
        up: Vec3::Z,
        fov_y_deg: from.fov_y_deg,
    })
}
