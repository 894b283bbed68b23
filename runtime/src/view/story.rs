//! What the viewers do with a scene's story (scene/story.rs) and its surfaces, the same in the
//! window and the browser: labels of points of interest projected into the frame and hidden where
//! rock is nearer than they are; smooth flights between cameras; the tour player; measurements
//! between picked surface points; and the view link a page's address carries.

use glam::{DVec3, Vec3};

use crate::scene::data::SceneCamera;
use crate::scene::story::SceneTour;
use crate::view::camera::{Camera, Nav};

/// A label's place in a `width x height` frame: raster pixels (rows top to bottom) and its
/// distance from the eye.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Projected {
    pub x_px: f32,
    pub y_px: f32,
    pub distance_m: f32,
}

/// Where frame point `p_m` shows in a `width x height` frame of `camera`; None behind the eye or
/// outside the frame.
pub fn project(camera: &Camera, width: u32, height: u32, p_m: Vec3) -> Option<Projected> {
    let clip = camera.view_proj(width, height, 0.01, 1e5) * p_m.extend(1.0);
    if clip.w <= 1e-4 {
        return None;
    }
    let (nx, ny) = (clip.x / clip.w, clip.y / clip.w);
    if !(nx.abs() <= 1.0 && ny.abs() <= 1.0) {
        return None;
    }
    Some(Projected {
        x_px: (nx * 0.5 + 0.5) * width as f32,
        y_px: (0.5 - ny * 0.5) * height as f32,
        distance_m: (p_m - camera.eye_m).length(),
    })
}

/// Whether rock hides a label `label_m` from the eye, given the G-buffer's distance at its pixel
/// (None: nothing drawn there). A label sits on the surface it names, so that surface's own
/// distance must not hide it: only a surface nearer by more than 10 cm and 3% does (the
/// surfel discs' depth is within a few mm of the rock's; 3% covers a label placed a little
/// inside a curved wall).
pub fn hidden(label_m: f32, surface_m: Option<f32>) -> bool {
    surface_m.is_some_and(|s| s < label_m - (0.1 + 0.03 * label_m))
}

/// Seconds a flight between two cameras takes when none is given: a second, plus the eye's
/// travel at 3 m/s and the turn at 90 degrees a second, at most 8.
pub fn flight_s(from: &Camera, to: &Camera) -> f32 {
    let travel = (to.eye_m - from.eye_m).length() / 3.0;
    let a = (from.look_at_m - from.eye_m).normalize_or(Vec3::X);
    let b = (to.look_at_m - to.eye_m).normalize_or(Vec3::X);
    let turn = a.dot(b).clamp(-1.0, 1.0).acos().to_degrees() / 90.0;
    (1.0 + travel.max(turn)).min(8.0)
}

/// A flight from one camera to another: the eye eases in and out along the straight line, the
/// view direction turns along the great circle, the field of view follows.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Flight {
    pub from: Camera,
    pub to: Camera,
    pub duration_s: f32,
    pub elapsed_s: f32,
}

impl Flight {
    pub fn new(from: Camera, to: Camera, duration_s: Option<f32>) -> Self {
        let duration_s = duration_s.unwrap_or_else(|| flight_s(&from, &to)).max(0.0);
        Self { from, to, duration_s, elapsed_s: 0.0 }
    }

    /// The camera after `dt_s` more seconds.
    pub fn advance(&mut self, dt_s: f32) -> Camera {
        self.elapsed_s = (self.elapsed_s + dt_s.max(0.0)).min(self.duration_s);
        self.at(if self.duration_s > 0.0 { self.elapsed_s / self.duration_s } else { 1.0 })
    }

    pub fn done(&self) -> bool {
        self.elapsed_s >= self.duration_s
    }

    /// The camera at `t` of the way (0..=1), eased (smoothstep).
    pub fn at(&self, t: f32) -> Camera {
        let t = t.clamp(0.0, 1.0);
        if t >= 1.0 {
            return self.to;
        }
        let s = t * t * (3.0 - 2.0 * t);
        let a = (self.from.look_at_m - self.from.eye_m).normalize_or(Vec3::X);
        let b = (self.to.look_at_m - self.to.eye_m).normalize_or(Vec3::X);
        let q = glam::Quat::from_rotation_arc(a, b);
        let dir = glam::Quat::IDENTITY.slerp(q, s) * a;
        let eye_m = self.from.eye_m.lerp(self.to.eye_m, s);
        Camera {
            eye_m,
            look_at_m: eye_m + dir,
            up: Vec3::Z,
            fov_y_deg: self.from.fov_y_deg + (self.to.fov_y_deg - self.from.fov_y_deg) * s,
        }
    }
}

/// Where a tour is.
#[derive(Clone, Copy, Debug, PartialEq)]
pub enum TourPhase {
    /// Flying to the stop.
    Flying,
    /// At the stop, waiting for the light to converge (the dwell starts then).
    Arriving,
    /// At the stop, the light converged; seconds left before the next flight.
    Dwelling { left_s: f32 },
    /// After the last stop's dwell.
    Finished,
}

impl TourPhase {
    pub fn name(&self) -> &'static str {
        match self {
            Self::Flying => "flying",
            Self::Arriving => "arriving",
            Self::Dwelling { .. } => "dwelling",
            Self::Finished => "finished",
        }
    }
}

/// Plays a tour: flies to each stop, waits there for the light to converge, dwells, flies on.
/// Paused, it holds where it is (a flight stops mid-air).
#[derive(Clone, Debug)]
pub struct TourPlayer {
    pub tour: usize,
    pub stop: usize,
    pub phase: TourPhase,
    pub paused: bool,
    flight: Option<Flight>,
}

impl TourPlayer {
    /// Starts tour `index` (`tour`) from `from`: flies to its first stop.
    pub fn start(index: usize, tour: &SceneTour, from: Camera) -> Self {
        let mut p = Self { tour: index, stop: 0, phase: TourPhase::Flying, paused: false, flight: None };
        p.go(tour, 0, from);
        p
    }

    fn go(&mut self, tour: &SceneTour, stop: usize, from: Camera) {
        self.stop = stop.min(tour.stops.len().saturating_sub(1));
        let Some(s) = tour.stops.get(self.stop) else {
            self.phase = TourPhase::Finished;
            self.flight = None;
            return;
        };
        self.flight = Some(Flight::new(from, stop_camera(&s.camera), s.flight_s));
        self.phase = TourPhase::Flying;
    }

    /// Moves to the stop `delta` away (clamped to the tour), flying from `from`.
    pub fn step(&mut self, tour: &SceneTour, delta: i32, from: Camera) {
        let stop = (self.stop as i64 + i64::from(delta)).clamp(0, tour.stops.len() as i64 - 1) as usize;
        self.go(tour, stop, from);
    }

    /// The camera flying, for this frame after `dt_s` seconds (None: not flying, the camera is
    /// the viewer's own). `settled`: the frame at the stop is final (light converged, tiles in),
    /// which starts the dwell; the dwell counts down only while settled.
    pub fn tick(&mut self, tour: &SceneTour, dt_s: f32, settled: bool) -> Option<Camera> {
        if self.paused {
            return None;
        }
        match self.phase {
            TourPhase::Flying => {
                let f = self.flight.as_mut()?;
                let c = f.advance(dt_s);
                if f.done() {
                    self.phase = TourPhase::Arriving;
                    self.flight = None;
                }
                Some(c)
            }
            TourPhase::Arriving => {
                if settled {
                    let dwell = tour.stops.get(self.stop).map_or(0.0, |s| s.dwell_s);
                    self.phase = TourPhase::Dwelling { left_s: dwell };
                }
                None
            }
            TourPhase::Dwelling { left_s } => {
                let left = if settled { left_s - dt_s } else { left_s };
                if left > 0.0 {
                    self.phase = TourPhase::Dwelling { left_s: left };
                } else if self.stop + 1 < tour.stops.len() {
                    let from = stop_camera(&tour.stops[self.stop].camera);
                    self.go(tour, self.stop + 1, from);
                } else {
                    self.phase = TourPhase::Finished;
                }
                None
            }
            TourPhase::Finished => None,
        }
    }

    /// Whether the camera moves under the tour (the light waits while it does).
    pub fn flying(&self) -> bool {
        !self.paused && self.phase == TourPhase::Flying
    }
}

/// The cameras `grotto render --tour` draws: one a stop (the view a visitor sees there once the
/// light has converged), or with `fps`, the tour as a film: each flight at `fps` frames a second
/// (eased as the viewers fly it) and each stop held for its dwell.
pub fn tour_cameras(tour: &SceneTour, fps: Option<f32>) -> Vec<Camera> {
    let stops: Vec<Camera> = tour.stops.iter().map(|s| stop_camera(&s.camera)).collect();
    let Some(fps) = fps.filter(|f| f.is_finite() && *f > 0.0) else { return stops };
    let mut out = Vec::new();
    for (i, s) in tour.stops.iter().enumerate() {
        if i > 0 {
            let f = Flight::new(stops[i - 1], stops[i], s.flight_s);
            let n = (f.duration_s * fps).ceil().max(1.0) as u32;
            out.extend((1..n).map(|k| f.at(k as f32 / n as f32)));
        }
        let hold = (s.dwell_s * fps).round().max(1.0) as u32;
        out.extend(std::iter::repeat_n(stops[i], hold as usize));
    }
    out
}

/// A stop's or a point of interest's camera as the viewers show it: its eye and view direction
/// with z up, as fly controls hold it ([`Nav::from_camera`]), so arriving and then looking
/// around does not jump.
pub fn stop_camera(c: &SceneCamera) -> Camera {
    Nav::from_camera(&Camera::from_scene(c), 1.0).camera()
}

/// A measurement between two surface points (world metres, f64: survey coordinates).
#[derive(Clone, Copy, Debug, PartialEq, serde::Serialize)]
pub struct Measurement {
    pub a_m: [f64; 3],
    pub b_m: [f64; 3],
    pub distance_m: f64,
    /// b above a (negative: below).
    pub height_m: f64,
    pub horizontal_m: f64,
}

impl Measurement {
    pub fn between(a_m: DVec3, b_m: DVec3) -> Self {
        let d = b_m - a_m;
        Self {
            a_m: a_m.to_array(),
            b_m: b_m.to_array(),
            distance_m: d.length(),
            height_m: d.z,
            horizontal_m: d.truncate().length(),
        }
    }
}

/// A camera as a page address carries it (`at=x,y,z,yaw,pitch,fov`): the eye in world metres to
/// the millimetre, heading and pitch in degrees to the thousandth (0.17 mm across at 10 m),
/// the vertical field of view in degrees. Survey coordinates stay f64 in the text.
pub fn view_link(camera: &Camera, frame_origin_m: [f64; 3]) -> String {
    let nav = Nav::from_camera(camera, 1.0);
    let eye = DVec3::from_array(frame_origin_m) + camera.eye_m.as_dvec3();
    format!(
        "{:.3},{:.3},{:.3},{:.3},{:.3},{:.2}",
        eye.x,
        eye.y,
        eye.z,
        nav.yaw_rad.to_degrees(),
        nav.pitch_rad.to_degrees(),
        camera.fov_y_deg
    )
}

/// The camera of a [`view_link`] in the frame at `frame_origin_m`; an error names what is wrong.
pub fn parse_view_link(text: &str, frame_origin_m: [f64; 3]) -> Result<Camera, String> {
    let v: Vec<f64> = text
        .split(',')
        .map(|s| s.trim().parse::<f64>().map_err(|_| format!("view link {text:?}: {s:?} is not a number")))
        .collect::<Result<_, _>>()?;
    if v.len() != 6 || !v.iter().all(|x| x.is_finite()) {
        return Err(format!("view link {text:?}: expected 6 finite numbers x,y,z,heading,pitch,fov"));
    }
    let eye_m = (DVec3::new(v[0], v[1], v[2]) - DVec3::from_array(frame_origin_m)).as_vec3();
    if eye_m.abs().max_element() >= 1e7 {
        return Err(format!("view link {text:?}: the eye is far outside the scene"));
    }
    let nav = Nav {
        eye_m,
        yaw_rad: (v[3] as f32).to_radians(),
        pitch_rad: (v[4] as f32).to_radians().clamp(-1.5, 1.5),
        speed_m_s: 1.0,
        fov_y_deg: (v[5] as f32).clamp(1.0, 170.0),
        orbit: None,
    };
    Ok(nav.camera())
}

/// Stops recorded in a viewer as a story file (`[[tour]]` with `[[tour.stop]]`s in world metres,
/// grotto_format::story::StorySpec's syntax), which `grotto publish --story` and `grotto render
/// --story` read: each stop's eye, the point a metre ahead, its field of view, `dwell_s`.
pub fn tour_toml(name: &str, stops: &[Camera], frame_origin_m: [f64; 3], dwell_s: f32) -> String {
    let origin = DVec3::from_array(frame_origin_m);
    let world = |p: Vec3| {
        let w = origin + p.as_dvec3();
        format!("[{:.4}, {:.4}, {:.4}]", w.x, w.y, w.z)
    };
    let mut out = format!("# Recorded by grotto view.\n[[tour]]\nname = {name:?}\n");
    for c in stops {
        let ahead = c.eye_m + (c.look_at_m - c.eye_m).normalize_or(Vec3::X);
        out += &format!(
            "\n[[tour.stop]]\neye = {}\nlook_at = {}\nfov_deg = {:.2}\ndwell_s = {dwell_s}\n",
            world(c.eye_m),
            world(ahead),
            c.fov_y_deg
        );
    }
    out
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::scene::story::SceneStop;

    fn cam(eye: Vec3, look_at: Vec3) -> Camera {
        Camera { eye_m: eye, look_at_m: look_at, up: Vec3::Z, fov_y_deg: 60.0 }
    }

    #[test]
    fn a_point_projects_where_the_ray_through_its_pixel_goes() {
        let c = cam(Vec3::new(1.0, 2.0, 1.5), Vec3::new(5.0, 3.0, 1.0));
        let (w, h) = (320, 240);
        for p in [Vec3::new(6.0, 3.5, 1.2), Vec3::new(4.0, 1.0, 2.0), Vec3::new(7.0, 4.0, 0.2)] {
            let q = project(&c, w, h, p).unwrap();
            let ray = crate::render::probe::ray_through(&c, w, h, glam::Vec2::new(q.x_px, q.y_px));
            let back = c.eye_m + ray * q.distance_m;
            assert!((back - p).length() < 1e-4 * q.distance_m, "{p} came back as {back}");
        }
        // Behind the eye or outside the frame: no label.
        assert!(project(&c, w, h, Vec3::new(-3.0, 1.0, 1.5)).is_none());
        assert!(project(&c, w, h, Vec3::new(2.0, 12.0, 1.5)).is_none());
    }

    #[test]
    fn a_label_on_its_own_wall_shows_and_one_behind_rock_does_not() {
        assert!(!hidden(5.0, Some(5.0)));
        assert!(!hidden(5.0, Some(4.8)));
        assert!(!hidden(5.0, None));
        assert!(hidden(5.0, Some(3.0)));
        assert!(hidden(20.0, Some(19.0)));
    }

    #[test]
    fn a_flight_starts_and_ends_on_its_cameras_and_turns_smoothly() {
        let a = cam(Vec3::ZERO, Vec3::X);
        let b = cam(Vec3::new(6.0, 0.0, 0.0), Vec3::new(6.0, 1.0, 0.0));
        let mut f = Flight::new(a, b, None);
        assert!((f.duration_s - 3.0).abs() < 1e-5, "{}", f.duration_s);
        assert_eq!(f.at(0.0).eye_m, a.eye_m);
        let mut last = f.at(0.0);
        let mut n = 0;
        while !f.done() {
            let c = f.advance(0.05);
            let (d0, d1) = (last.look_at_m - last.eye_m, c.look_at_m - c.eye_m);
            assert!(d0.angle_between(d1).to_degrees() < 5.0, "a jump of the view at step {n}");
            assert!((c.eye_m - last.eye_m).length() < 0.2, "a jump of the eye at step {n}");
            last = c;
            n += 1;
        }
        assert_eq!(last, b);
    }

    fn tour() -> SceneTour {
        let stop = |x: f32, dwell_s: f32| SceneStop {
            camera: SceneCamera {
                name: String::new(),
                eye_m: Vec3::new(x, 0.0, 0.0),
                look_at_m: Vec3::new(x + 1.0, 0.0, 0.0),
                up: Vec3::Z,
                fov_y_deg: 60.0,
            },
            poi: None,
            title: String::new(),
            text: String::new(),
            dwell_s,
            flight_s: Some(1.0),
        };
        SceneTour { name: "t".into(), title: String::new(), stops: vec![stop(0.0, 2.0), stop(3.0, 1.0)] }
    }

    #[test]
    fn a_tour_dwells_only_once_the_light_has_converged_and_ends_after_its_last_stop() {
        let t = tour();
        let mut p = TourPlayer::start(0, &t, cam(Vec3::new(-5.0, 0.0, 0.0), Vec3::ZERO));
        let mut arrived = None;
        for _ in 0..30 {
            if let Some(c) = p.tick(&t, 0.1, false) {
                arrived = Some(c);
            }
        }
        assert_eq!(p.phase, TourPhase::Arriving, "the light has not converged: no dwell");
        assert_eq!(arrived.unwrap(), stop_camera(&t.stops[0].camera));
        p.paused = true;
        assert!(p.tick(&t, 10.0, true).is_none());
        assert_eq!(p.phase, TourPhase::Arriving, "paused: holds");
        p.paused = false;
        p.tick(&t, 0.1, true);
        assert_eq!(p.phase, TourPhase::Dwelling { left_s: 2.0 });
        for _ in 0..25 {
            p.tick(&t, 0.1, true);
        }
        assert_eq!((p.stop, p.phase), (1, TourPhase::Flying));
        for _ in 0..40 {
            p.tick(&t, 0.1, true);
        }
        assert_eq!(p.phase, TourPhase::Finished);
        // Stepping back flies to the first stop again.
        p.step(&t, -1, stop_camera(&t.stops[1].camera));
        assert_eq!((p.stop, p.phase), (0, TourPhase::Flying));
    }

    #[test]
    fn a_tour_renders_a_frame_a_stop_or_a_film_of_its_flights_and_dwells() {
        let t = tour();
        let stops = tour_cameras(&t, None);
        assert_eq!(stops, [stop_camera(&t.stops[0].camera), stop_camera(&t.stops[1].camera)]);
        // 10 fps: stop 0 held 2 s (20 frames), a 1 s flight (9 frames between), stop 1 held 1 s.
        let film = tour_cameras(&t, Some(10.0));
        assert_eq!(film.len(), 20 + 9 + 10);
        assert!(film[..20].iter().all(|c| *c == stops[0]) && film[29..].iter().all(|c| *c == stops[1]));
        assert!(film[20..29].windows(2).all(|w| w[1].eye_m.x > w[0].eye_m.x), "the flight moves on");
    }

    #[test]
    fn recorded_stops_read_back_as_a_tour_of_the_same_views() {
        let origin = [512_345.25, 5_123_456.75, 345.5];
        let stops = [
            cam(Vec3::new(1.0, 2.0, 1.5), Vec3::new(4.0, 2.0, 1.0)),
            cam(Vec3::new(3.0, -1.0, 2.0), Vec3::new(3.0, 5.0, 2.0)),
        ];
        let text = tour_toml("recorded", &stops, origin, 4.0);
        let spec: grotto_format::story::StorySpec = toml::from_str(&text).unwrap();
        let (pois, tours) = spec.into_story(&[]).unwrap();
        let (_, tours) = crate::scene::story::in_frame(origin, &pois, &tours, &[]);
        let back = tour_cameras(&tours[0], None);
        for (a, b) in stops.iter().zip(&back) {
            assert!((a.eye_m - b.eye_m).length() < 1e-3, "{} vs {}", a.eye_m, b.eye_m);
            let (da, db) = (a.look_at_m - a.eye_m, b.look_at_m - b.eye_m);
            assert!(da.angle_between(db) < 1e-3);
        }
        assert_eq!(tours[0].stops[1].dwell_s, 4.0);
    }

    #[test]
    fn a_view_link_restores_the_camera_to_well_under_a_centimetre_at_survey_coordinates() {
        let origin = [512_345.25, 5_123_456.75, 345.5];
        let c = cam(Vec3::new(12.3456, -7.891, 2.25), Vec3::new(20.0, -3.0, 1.0));
        let link = view_link(&c, origin);
        assert!(link.starts_with("512357.596,5123448.859,347.750,"), "{link}");
        let back = parse_view_link(&link, origin).unwrap();
        assert!((back.eye_m - c.eye_m).length() < 1e-3, "{} vs {}", back.eye_m, c.eye_m);
        let (d0, d1) = (c.look_at_m - c.eye_m, back.look_at_m - back.eye_m);
        // 0.001 degrees: 0.17 mm at 10 m.
        assert!(d0.angle_between(d1).to_degrees() < 2e-3);
        for bad in ["1,2,3", "1,2,3,4,5,x", "1,2,3,4,5,NaN", "1e300,0,0,0,0,60"] {
            assert!(parse_view_link(bad, origin).is_err(), "{bad}");
        }
    }

    #[test]
    fn a_measurement_says_distance_height_and_horizontal_run() {
        let m = Measurement::between(
            DVec3::new(512_000.0, 5_000_000.0, 300.0),
            DVec3::new(512_003.0, 5_000_004.0, 298.0),
        );
        assert!((m.horizontal_m - 5.0).abs() < 1e-9);
        assert!((m.height_m + 2.0).abs() < 1e-9);
        assert!((m.distance_m - 29f64.sqrt()).abs() < 1e-9);
    }
}
