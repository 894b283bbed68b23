//! The places a viewer goes, in the scene's f32 frame: named cameras, points of interest and
//! tours (grotto_format holds them in world metres). What the viewers label, fly to and play. A
//! tour's stops are resolved here once, each to a camera, a title and a text, so a viewer never
//! looks a name up mid-tour.

use glam::{DVec3, Vec3};
use grotto_format::{Camera as WorldCamera, Poi, Tour};

/// A named viewpoint in frame coordinates.
#[derive(Clone, Debug, PartialEq)]
pub struct SceneCamera {
    pub name: String,
    pub eye_m: Vec3,
    pub look_at_m: Vec3,
    pub up: Vec3,
    pub fov_y_deg: f32,
}

/// A labelled place, in frame coordinates.
#[derive(Clone, Debug, PartialEq)]
pub struct ScenePoi {
    pub name: String,
    pub title: String,
    pub text: String,
    /// The label's anchor.
    pub position_m: Vec3,
    /// Where a visitor is flown to see it.
    pub camera: SceneCamera,
}

/// A guided tour, its stops resolved.
#[derive(Clone, Debug, PartialEq)]
pub struct SceneTour {
    pub name: String,
    pub title: String,
    pub stops: Vec<SceneStop>,
}

/// One stop: its camera, what is shown there, for how long once the light has converged, and
/// how long the flight there takes (None: from the distance, [`crate::view::story::flight_s`]).
#[derive(Clone, Debug, PartialEq)]
pub struct SceneStop {
    pub camera: SceneCamera,
    /// The point of interest it shows, as an index into the scene's.
    pub poi: Option<usize>,
    pub title: String,
    pub text: String,
    pub dwell_s: f32,
    pub flight_s: Option<f32>,
}

/// `pois` and `tours` (checked: grotto_format::story::check) in the frame at `frame_origin_m`;
/// stops naming a camera take it from `cameras`. A stop whose reference does not resolve (a
/// story not checked against these cameras) is left out rather than guessed.
pub fn in_frame(
    frame_origin_m: [f64; 3],
    pois: &[Poi],
    tours: &[Tour],
    cameras: &[WorldCamera],
) -> (Vec<ScenePoi>, Vec<SceneTour>) {
    let origin = DVec3::from_array(frame_origin_m);
    let at = |p: [f64; 3]| (DVec3::from_array(p) - origin).as_vec3();
    let camera = |name: &str, eye: [f64; 3], look_at: [f64; 3], up: [f64; 3], fov: f64| SceneCamera {
        name: name.to_owned(),
        eye_m: at(eye),
        look_at_m: at(look_at),
        up: DVec3::from_array(up).as_vec3().normalize_or(Vec3::Z),
        fov_y_deg: fov as f32,
    };
    let z_up = [0.0, 0.0, 1.0];
    let scene_pois: Vec<ScenePoi> = pois
        .iter()
        .map(|p| ScenePoi {
            name: p.name.clone(),
            title: p.title.clone(),
            text: p.text.clone(),
            position_m: at(p.position_m),
            camera: camera(&p.name, p.eye_m, p.look_at_m, z_up, p.fov_y_deg),
        })
        .collect();
    let scene_tours = tours
        .iter()
        .map(|t| SceneTour {
            name: t.name.clone(),
            title: t.title.clone(),
            stops: t
                .stops
                .iter()
                .filter_map(|s| {
                    let (cam, poi, title) = if let Some(name) = &s.poi {
                        let i = scene_pois.iter().position(|p| &p.name == name)?;
                        (scene_pois[i].camera.clone(), Some(i), scene_pois[i].title.clone())
                    } else if let Some(name) = &s.camera {
                        let c = cameras.iter().find(|c| &c.name == name)?;
                        (camera(name, c.eye_m, c.look_at_m, c.up, c.fov_y_deg), None, String::new())
                    } else {
                        let (eye, look_at) = (s.eye_m?, s.look_at_m?);
                        (camera("", eye, look_at, z_up, s.fov_y_deg.unwrap_or(60.0)), None, String::new())
                    };
                    let text = if s.text.is_empty() {
                        poi.map(|i| scene_pois[i].text.clone()).unwrap_or_default()
                    } else {
                        s.text.clone()
                    };
                    Some(SceneStop {
                        camera: cam,
                        poi,
                        title,
                        text,
                        dwell_s: s.dwell_s as f32,
                        flight_s: s.flight_s.map(|f| f as f32),
                    })
                })
                .collect(),
        })
        .collect();
    (scene_pois, scene_tours)
}
