//! A published cave's story: points of interest (labelled places a visitor can fly to) and guided
//! tours (stops with a camera, a text and a dwell time), stored in the scene section and read by
//! the viewers (docs/manifest.md, docs/web.md).
//!
//! Two shapes: [`Poi`] and [`Tour`] are what the scene holds (JSON, world metres, forward
//! compatible like the rest of the scene); [`StorySpec`] is what a person writes (TOML `[[poi]]`
//! and `[[tour]]` tables, in a build manifest or in a file given to `grotto publish`), strict
//! about unknown keys and turned into the former by [`StorySpec::into_story`]. Both callers parse
//! the same spec, so a manifest's and a publish file's tables cannot drift apart.

use serde::{Deserialize, Serialize};

/// A labelled place: where its label sits and the camera a visitor is flown to.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub struct Poi {
    /// Unique within the package; tours and links refer to it by this.
    pub name: String,
    pub title: String,
    #[serde(default, skip_serializing_if = "String::is_empty")]
    pub text: String,
    /// The label's anchor: a point on (or near) the surface it names.
    pub position_m: [f64; 3],
    pub eye_m: [f64; 3],
    pub look_at_m: [f64; 3],
    pub fov_y_deg: f64,
}

/// A guided tour: stops visited in order.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub struct Tour {
    pub name: String,
    #[serde(default)]
    pub title: String,
    pub stops: Vec<TourStop>,
}

/// One stop of a tour: where the camera goes (a point of interest's camera, a named camera, or
/// one given here), what the visitor reads there and for how long.
#[derive(Clone, Debug, Default, PartialEq, Serialize, Deserialize)]
#[serde(default)]
pub struct TourStop {
    #[serde(skip_serializing_if = "Option::is_none")]
    pub poi: Option<String>,
    /// A camera of the scene, by name.
    #[serde(skip_serializing_if = "Option::is_none")]
    pub camera: Option<String>,
    #[serde(skip_serializing_if = "Option::is_none")]
    pub eye_m: Option<[f64; 3]>,
    #[serde(skip_serializing_if = "Option::is_none")]
    pub look_at_m: Option<[f64; 3]>,
    #[serde(skip_serializing_if = "Option::is_none")]
    pub fov_y_deg: Option<f64>,
    /// Shown at the stop (default: the point of interest's text).
    #[serde(skip_serializing_if = "String::is_empty")]
    pub text: String,
    /// Seconds the stop is shown once its light has converged.
    pub dwell_s: f64,
    /// Seconds of the flight to the stop (None: from the distance, see the viewers).
    #[serde(skip_serializing_if = "Option::is_none")]
    pub flight_s: Option<f64>,
}

/// Longest dwell or flight a stop may ask for: an hour (a typo's 1e9 s would freeze a tour).
pub const MAX_STOP_S: f64 = 3600.0;

/// Checks a story against the names of the scene's cameras: unique names, references that
/// resolve, one camera a stop, finite numbers, times within `0..=MAX_STOP_S`. The message names
/// the place.
pub fn check(pois: &[Poi], tours: &[Tour], cameras: &[&str]) -> Result<(), String> {
    let finite = |what: &str, v: &[f64]| {
        if v.iter().all(|x| x.is_finite()) { Ok(()) } else { Err(format!("{what} is not finite: {v:?}")) }
    };
    let mut names = std::collections::BTreeSet::new();
    for p in pois {
        let what = format!("point of interest '{}'", p.name);
        if p.name.is_empty() {
            return Err("a point of interest has no name".into());
        }
        if !names.insert(p.name.as_str()) {
            return Err(format!("{what} is named twice"));
        }
        finite(&what, &p.position_m)?;
        finite(&what, &p.eye_m)?;
        finite(&what, &p.look_at_m)?;
        check_view(&what, p.eye_m, p.look_at_m, p.fov_y_deg)?;
    }
    let mut tour_names = std::collections::BTreeSet::new();
    for t in tours {
        let what = format!("tour '{}'", t.name);
        if t.name.is_empty() {
            return Err("a tour has no name".into());
        }
        if !tour_names.insert(t.name.as_str()) {
            return Err(format!("{what} is named twice"));
        }
        if t.stops.is_empty() {
            return Err(format!("{what} has no stops"));
        }
        for (i, s) in t.stops.iter().enumerate() {
            let what = format!("{what}, stop {}", i + 1);
            let given = [s.poi.is_some(), s.camera.is_some(), s.eye_m.is_some()];
            if given.iter().filter(|g| **g).count() != 1 {
                return Err(format!("{what}: give exactly one of poi, camera or eye"));
            }
            if let Some(p) = &s.poi
                && !pois.iter().any(|q| &q.name == p)
            {
                return Err(format!("{what}: no point of interest named '{p}'"));
            }
            if let Some(c) = &s.camera
                && !cameras.contains(&c.as_str())
            {
                return Err(format!("{what}: no camera named '{c}'"));
            }
            if let Some(eye) = s.eye_m {
                let look_at = s.look_at_m.ok_or_else(|| format!("{what}: an eye needs a look_at"))?;
                finite(&what, &eye)?;
                finite(&what, &look_at)?;
                check_view(&what, eye, look_at, s.fov_y_deg.unwrap_or(60.0))?;
            }
            for (name, t) in [("dwell_s", Some(s.dwell_s)), ("flight_s", s.flight_s)] {
                if let Some(t) = t
                    && !(0.0..=MAX_STOP_S).contains(&t)
                {
                    return Err(format!("{what}: {name} {t} is outside 0..={MAX_STOP_S}"));
                }
            }
        }
    }
    Ok(())
}

fn check_view(what: &str, eye: [f64; 3], look_at: [f64; 3], fov_y_deg: f64) -> Result<(), String> {
    let d: f64 = (0..3).map(|a| (look_at[a] - eye[a]).powi(2)).sum::<f64>().sqrt();
    if d <= 1e-6 {
        return Err(format!("{what}: eye and look_at coincide"));
    }
    if !(fov_y_deg > 0.1 && fov_y_deg < 179.0) {
        return Err(format!("{what}: field of view {fov_y_deg} deg is outside 0.1..179"));
    }
    Ok(())
}

/// Points of interest and tours as a person writes them (TOML; docs/manifest.md "Points of
/// interest and tours"): `[[poi]]` and `[[tour]]` with `[[tour.stop]]`. World metres, as the
/// manifest's lights and cameras.
#[derive(Clone, Debug, Default, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct StorySpec {
    #[serde(default)]
    pub poi: Vec<PoiSpec>,
    #[serde(default)]
    pub tour: Vec<TourSpec>,
}

/// `[[poi]]`: `name`, `title` (default the name), `text`, `position` (the label), `eye` and
/// `look_at` (default the position), `fov_deg` (default 60).
#[derive(Clone, Debug, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct PoiSpec {
    pub name: String,
    pub title: Option<String>,
    #[serde(default)]
    pub text: String,
    pub position: [f64; 3],
    pub eye: [f64; 3],
    pub look_at: Option<[f64; 3]>,
    pub fov_deg: Option<f64>,
}

/// `[[tour]]`: `name`, `title`, and its `[[tour.stop]]`s.
#[derive(Clone, Debug, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct TourSpec {
    pub name: String,
    #[serde(default)]
    pub title: String,
    #[serde(default)]
    pub stop: Vec<StopSpec>,
}

/// `[[tour.stop]]`: one of `poi`, `camera` or `eye` + `look_at` (+ `fov_deg`); `text`,
/// `dwell_s` (default 6), `flight_s` (default: from the distance).
#[derive(Clone, Debug, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct StopSpec {
    pub poi: Option<String>,
    pub camera: Option<String>,
    pub eye: Option<[f64; 3]>,
    pub look_at: Option<[f64; 3]>,
    pub fov_deg: Option<f64>,
    #[serde(default)]
    pub text: String,
    #[serde(default = "default_dwell_s")]
    pub dwell_s: f64,
    pub flight_s: Option<f64>,
}

fn default_dwell_s() -> f64 {
    6.0
}

impl StorySpec {
    /// The scene's shape of it, checked against the names of the scene's `cameras` ([`check`]).
    pub fn into_story(self, cameras: &[&str]) -> Result<(Vec<Poi>, Vec<Tour>), String> {
        let (pois, tours) = self.convert();
        check(&pois, &tours, cameras)?;
        Ok((pois, tours))
    }

    /// The scene's shape of it, unchecked: for a story that is checked once merged with another
    /// ([`merged`]).
    pub fn convert(self) -> (Vec<Poi>, Vec<Tour>) {
        let pois: Vec<Poi> = self
            .poi
            .into_iter()
            .map(|p| Poi {
                title: p.title.unwrap_or_else(|| p.name.clone()),
                name: p.name,
                text: p.text,
                position_m: p.position,
                eye_m: p.eye,
                look_at_m: p.look_at.unwrap_or(p.position),
                fov_y_deg: p.fov_deg.unwrap_or(60.0),
            })
            .collect();
        let tours: Vec<Tour> = self
            .tour
            .into_iter()
            .map(|t| Tour {
                name: t.name,
                title: t.title,
                stops: t
                    .stop
                    .into_iter()
                    .map(|s| TourStop {
                        poi: s.poi,
                        camera: s.camera,
                        eye_m: s.eye,
                        look_at_m: s.look_at,
                        fov_y_deg: s.fov_deg,
                        text: s.text,
                        dwell_s: s.dwell_s,
                        flight_s: s.flight_s,
                    })
                    .collect(),
            })
            .collect();
        (pois, tours)
    }
}

/// `base`'s points of interest and tours with `extra`'s added; an extra one named as one of
/// `base` replaces it in place (a publish file amending a package's story).
pub fn merged<T: Clone>(base: &[T], extra: &[T], name: impl Fn(&T) -> &str) -> Vec<T> {
    let mut out = base.to_vec();
    for e in extra {
        match out.iter_mut().find(|b| name(b) == name(e)) {
            Some(b) => *b = e.clone(),
            None => out.push(e.clone()),
        }
    }
    out
}

#[cfg(test)]
mod tests {
    use super::*;

    fn spec(text: &str) -> StorySpec {
        serde_json::from_str(text).unwrap()
    }

    #[test]
    fn a_story_resolves_its_defaults_and_refuses_what_would_break_a_tour() {
        let ok = spec(
            r#"{"poi": [{"name": "altar", "text": "A flowstone altar.", "position": [1, 2, 3], "eye": [0, 0, 3]}],
                "tour": [{"name": "main", "stop": [{"poi": "altar"}, {"camera": "entrance", "dwell_s": 2},
                          {"eye": [0, 0, 0], "look_at": [0, 1, 0], "fov_deg": 50, "text": "Up the passage"}]}]}"#,
        );
        let (pois, tours) = ok.into_story(&["entrance"]).unwrap();
        assert_eq!(pois[0].title, "altar");
        assert_eq!(pois[0].look_at_m, [1.0, 2.0, 3.0]);
        assert_eq!(pois[0].fov_y_deg, 60.0);
        assert_eq!(tours[0].stops.len(), 3);
        assert_eq!(tours[0].stops[0].dwell_s, 6.0);
        assert_eq!(tours[0].stops[1].dwell_s, 2.0);

        let refused = [
            (
                r#"{"tour": [{"name": "t", "stop": [{"poi": "nowhere"}]}]}"#,
                "no point of interest named 'nowhere'",
            ),
            (r#"{"tour": [{"name": "t", "stop": [{"camera": "attic"}]}]}"#, "no camera named 'attic'"),
            (
                r#"{"tour": [{"name": "t", "stop": [{"camera": "entrance", "eye": [0, 0, 0]}]}]}"#,
                "exactly one",
            ),
            (r#"{"tour": [{"name": "t", "stop": [{"eye": [0, 0, 0]}]}]}"#, "needs a look_at"),
            (r#"{"tour": [{"name": "t", "stop": []}]}"#, "has no stops"),
            (r#"{"tour": [{"name": "t", "stop": [{"camera": "entrance", "dwell_s": 1e9}]}]}"#, "dwell_s"),
            (r#"{"tour": [{"name": "t", "stop": [{"camera": "entrance", "dwell_s": -1}]}]}"#, "dwell_s"),
            (
                r#"{"poi": [{"name": "a", "position": [0, 0, 0], "eye": [0, 0, 0]}]}"#,
                "point of interest 'a': eye and look_at coincide",
            ),
            (
                r#"{"poi": [{"name": "a", "position": [1, 0, 0], "eye": [0, 0, 0]},
                            {"name": "a", "position": [1, 0, 0], "eye": [0, 0, 0]}]}"#,
                "named twice",
            ),
            (
                r#"{"poi": [{"name": "a", "position": [1, 0, 0], "eye": [0, 0, 0], "fov_deg": 0}]}"#,
                "field of view",
            ),
        ];
        for (text, expected) in refused {
            let e = spec(text).into_story(&["entrance"]).unwrap_err();
            assert!(e.contains(expected), "{text}: {e}");
        }
        // Unknown keys are errors (a misspelt `dwel_s` must not silently become 6 s).
        assert!(
            serde_json::from_str::<StorySpec>(r#"{"tour": [{"name": "t", "stop": [{"dwel_s": 1}]}]}"#)
                .is_err()
        );
    }

    #[test]
    fn an_extra_story_replaces_by_name_and_adds_the_rest() {
        let base = vec![("a", 1), ("b", 2)];
        let extra = vec![("b", 20), ("c", 30)];
        assert_eq!(merged(&base, &extra, |x| x.0), vec![("a", 1), ("b", 20), ("c", 30)]);
    }
}
