//! Cave surveys as surveyors keep them: a centreline of stations joined by legs, with the
//! passage dimensions measured at stations. Read from Survex's `.3d` files ([`svx3d`], the format
//! `cavern` writes) and Compass plot files ([`plt`]). Written by hand: no maintained Rust crate
//! reads either format, and both are small, documented binary/text formats.
//!
//! Positions are in the survey's own coordinates, metres (east, north, up), as the file gives
//! them: [`Survey::crs`] names their system where the file does.

use std::collections::HashMap;

use serde::{Deserialize, Serialize};

pub mod plt;
pub mod svx3d;

/// A survey station.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub struct Station {
    /// The full name, as the survey gives it (Survex: `cave.entrance.1`).
    pub name: String,
    /// East, north, up, metres, in the survey's coordinates.
    pub position_m: [f64; 3],
    pub flags: StationFlags,
}

/// What a survey says about a station.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq, Serialize, Deserialize)]
pub struct StationFlags {
    /// On a leg above ground.
    pub surface: bool,
    /// On an underground leg (both at an entrance).
    pub underground: bool,
    /// Marked as an entrance.
    pub entrance: bool,
    /// Exported: a connection point to other surveys.
    pub exported: bool,
    /// A fixed point (a control point whose coordinates were given).
    pub fixed: bool,
    /// Anonymous (a splay's far end, unnamed).
    pub anonymous: bool,
    /// On the passage wall.
    pub wall: bool,
}

/// What a survey says about a leg.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq, Serialize, Deserialize)]
pub struct LegFlags {
    /// Above ground.
    pub surface: bool,
    /// Duplicates data in another leg (a resurvey).
    pub duplicate: bool,
    /// A splay shot (radial, from a station to the wall).
    pub splay: bool,
}

/// A leg of the centreline: a straight line between two positions.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub struct Leg {
    pub from_m: [f64; 3],
    pub to_m: [f64; 3],
    /// Indices into [`Survey::stations`] of the stations at its ends, where one stands there.
    pub from: Option<usize>,
    pub to: Option<usize>,
    /// The survey the leg belongs to (Survex: the prefix, `cave.entrance`).
    pub survey: String,
    pub flags: LegFlags,
}

/// Passage dimensions measured at a station: left, right, up, down, metres (`None`: not
/// measured).
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub struct CrossSection {
    pub station: String,
    pub lrud_m: [Option<f64>; 4],
    /// The last station of its passage.
    pub last: bool,
}

/// A survey: its stations, legs and measured passage dimensions.
#[derive(Clone, Debug, Default, PartialEq, Serialize, Deserialize)]
pub struct Survey {
    pub title: String,
    /// The coordinate system as the file names it (a PROJ string, `EPSG:n`), where it does.
    pub crs: Option<String>,
    /// The file holds an extended elevation rather than real coordinates.
    pub extended_elevation: bool,
    pub stations: Vec<Station>,
    pub legs: Vec<Leg>,
    pub cross_sections: Vec<CrossSection>,
}

/// A survey file that cannot be read: the file and what is wrong.
#[derive(Debug, thiserror::Error)]
#[error("{path}: {problem}")]
pub struct SurveyError {
    pub path: String,
    pub problem: String,
}

/// Which survey format a file's first bytes name, if any.
pub fn survey_format(first_bytes: &[u8]) -> Option<&'static str> {
    if first_bytes.starts_with(svx3d::MAGIC) {
        Some("Survex .3d")
    } else if plt::looks_like_plt(first_bytes) {
        Some("Compass .plt")
    } else {
        None
    }
}

/// Reads a survey file, Survex `.3d` or Compass `.plt` by its contents.
#[cfg(not(target_arch = "wasm32"))]
pub fn read(path: &std::path::Path) -> Result<Survey, SurveyError> {
    let bytes = std::fs::read(path).map_err(|e| SurveyError {
        path: path.display().to_string(),
        problem: format!("cannot read it: {e}"),
    })?;
    parse(&bytes, &path.display().to_string())
}

/// Parses a survey file's bytes; `name` names it in errors.
pub fn parse(bytes: &[u8], name: &str) -> Result<Survey, SurveyError> {
    let err = |problem: String| SurveyError { path: name.to_string(), problem };
    match survey_format(bytes) {
        Some("Survex .3d") => svx3d::parse(bytes).map_err(err),
        Some(_) => plt::parse(bytes).map_err(err),
        None => Err(err(format!(
            "not a survey grotto reads (first bytes {:02x?}): give a Survex .3d file (cavern FILE.svx \
             writes one) or a Compass .plt plot file",
            &bytes[..bytes.len().min(8)]
        ))),
    }
}

impl Survey {
    /// Joins each leg's ends to the stations standing there (the first of those at the same
    /// position: equated stations share one).
    pub(crate) fn link_legs(&mut self) {
        let key = |p: [f64; 3]| p.map(|v| (v * 100.0).round() as i64);
        let mut at: HashMap<[i64; 3], usize> = HashMap::new();
        for (i, s) in self.stations.iter().enumerate() {
            at.entry(key(s.position_m)).or_insert(i);
        }
        for leg in &mut self.legs {
            leg.from = at.get(&key(leg.from_m)).copied();
            leg.to = at.get(&key(leg.to_m)).copied();
        }
    }

    /// A reason the survey cannot be stored or used: a position not finite, a leg naming a
    /// station that is not there.
    pub fn check(&self) -> Result<(), String> {
        let finite = |p: &[f64; 3]| p.iter().all(|v| v.is_finite());
        if let Some(s) = self.stations.iter().find(|s| !finite(&s.position_m)) {
            return Err(format!("station {} has position {:?}", s.name, s.position_m));
        }
        for (i, leg) in self.legs.iter().enumerate() {
            if !finite(&leg.from_m) || !finite(&leg.to_m) {
                return Err(format!("leg {i} runs {:?} -> {:?}", leg.from_m, leg.to_m));
            }
            if [leg.from, leg.to].into_iter().flatten().any(|k| k >= self.stations.len()) {
                return Err(format!("leg {i} names a station past the {} there are", self.stations.len()));
            }
        }
        if let Some(c) =
            self.cross_sections.iter().find(|c| c.lrud_m.iter().flatten().any(|v| !v.is_finite()))
        {
            return Err(format!("the passage dimensions at {} are {:?}", c.station, c.lrud_m));
        }
        Ok(())
    }

    /// Moves every position by `offset_m` (east, north, up).
    pub fn translate(&mut self, offset_m: [f64; 3]) {
        let add = |p: &mut [f64; 3]| (0..3).for_each(|a| p[a] += offset_m[a]);
        self.stations.iter_mut().for_each(|s| add(&mut s.position_m));
        for leg in &mut self.legs {
            add(&mut leg.from_m);
            add(&mut leg.to_m);
        }
    }

    /// The station named `name`.
    pub fn station(&self, name: &str) -> Option<&Station> {
        self.stations.iter().find(|s| s.name == name)
    }

    /// The surveyed length, metres: every underground leg that is neither a splay nor a
    /// duplicate nor above ground, as surveyors count a cave's length.
    pub fn surveyed_length_m(&self) -> f64 {
        self.legs
            .iter()
            .filter(|l| !(l.flags.splay || l.flags.duplicate || l.flags.surface))
            .map(|l| (0..3).map(|a| (l.to_m[a] - l.from_m[a]).powi(2)).sum::<f64>().sqrt())
            .sum()
    }
}
