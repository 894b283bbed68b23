//! The survey's centreline as a map lays it out: the legs that draw the cave (underground, not
//! splays or duplicates), each station's passage direction, the extended elevation's unrolled
//! distance along the legs, and a grid that finds the leg a scanned point belongs to.
//!
//! The grid is written here rather than taken from a crate: the kd-trees in use (kiddo) index
//! points, and the question here is the nearest of a few thousand segments, which a uniform grid
//! of their bounding boxes answers in a handful of distance tests.

use std::collections::HashMap;

use glam::DVec3;
use grotto_format::survey::Survey;

/// One leg as the map draws it.
#[derive(Clone, Debug)]
pub(crate) struct MapLeg {
    pub from_m: DVec3,
    pub to_m: DVec3,
    /// Stations at its ends (indices into the survey's stations), where named ones stand there.
    pub from: Option<usize>,
    pub to: Option<usize>,
    /// The extended elevation's horizontal position of `from_m`, metres from the start, and
    /// the direction the leg is laid out in (+1: to the right, -1: to the left).
    pub extended_from_m: f64,
    pub extended_sign: f64,
}

impl MapLeg {
    /// The horizontal length, metres: what the leg takes of the extended elevation.
    pub(crate) fn horizontal_m(&self) -> f64 {
        (self.to_m - self.from_m).truncate().length()
    }

    /// The point of the leg nearest `p`: its fraction along the leg (0..=1) and distance.
    pub(crate) fn nearest(&self, p: DVec3) -> (f64, f64) {
        let d = self.to_m - self.from_m;
        let len2 = d.length_squared();
        let t = if len2 > 0.0 { ((p - self.from_m).dot(d) / len2).clamp(0.0, 1.0) } else { 0.0 };
        (t, (self.from_m + d * t - p).length())
    }
}

/// The centreline of a survey, laid out for a map.
#[derive(Debug)]
pub(crate) struct Centreline {
    pub legs: Vec<MapLeg>,
    /// Per station of the survey: its unit horizontal passage direction (the mean of its legs'
    /// directions, each taken leaving the station's side consistently), where it has a leg.
    pub direction: Vec<Option<DVec3>>,
    /// The extended elevation's total length, metres.
    pub extended_m: f64,
    grid: LegGrid,
}

impl Centreline {
    /// The centreline of `survey`, its extended elevation started at its first entrance (else
    /// its first fixed point, else its first station), each leg laid out to the right of the one
    /// before it, a branch after the end of the last, as Survex's `extend` does by default.
    /// `reach_m`: how far from its leg a point may lie and still belong to it.
    pub(crate) fn new(survey: &Survey, reach_m: f64) -> Self {
        let drawn: Vec<&grotto_format::survey::Leg> =
            survey.legs.iter().filter(|l| !(l.flags.splay || l.flags.duplicate || l.flags.surface)).collect();
        let mut by_station: HashMap<usize, Vec<usize>> = HashMap::new();
        for (i, l) in drawn.iter().enumerate() {
            for s in [l.from, l.to].into_iter().flatten() {
                by_station.entry(s).or_default().push(i);
            }
        }
        let start = survey
            .stations
            .iter()
            .enumerate()
            .position(|(i, s)| s.flags.entrance && by_station.contains_key(&i))
            .or_else(|| {
                survey
                    .stations
                    .iter()
                    .enumerate()
                    .position(|(i, s)| s.flags.fixed && by_station.contains_key(&i))
            })
            .or_else(|| drawn.first().and_then(|l| l.from));
        let mut legs: Vec<MapLeg> = drawn
            .iter()
            .map(|l| MapLeg {
                from_m: DVec3::from_array(l.from_m),
                to_m: DVec3::from_array(l.to_m),
                from: l.from,
                to: l.to,
                extended_from_m: f64::NAN,
                extended_sign: 1.0,
            })
            .collect();
        // Depth-first from the start; legs no walk reaches (another series) start after the end.
        let mut station_x: HashMap<usize, f64> = HashMap::new();
        let mut end_m = 0.0f64;
        let mut order: Vec<usize> = start.into_iter().collect();
        order.extend(drawn.iter().filter_map(|l| l.from));
        for root in order {
            if station_x.contains_key(&root) {
                continue;
            }
            station_x.insert(root, end_m);
            let mut stack = vec![root];
            while let Some(s) = stack.pop() {
                let x = station_x[&s];
                for &i in by_station.get(&s).map(Vec::as_slice).unwrap_or_default() {
                    if legs[i].extended_from_m.is_finite() {
                        continue;
                    }
                    let forward = legs[i].from == Some(s);
                    let h = legs[i].horizontal_m();
                    // Laid out to the right from the end we stand at.
                    legs[i].extended_from_m = if forward { x } else { x + h };
                    legs[i].extended_sign = if forward { 1.0 } else { -1.0 };
                    end_m = end_m.max(x + h);
                    let other = if forward { legs[i].to } else { legs[i].from };
                    if let Some(o) = other.filter(|o| !station_x.contains_key(o)) {
                        station_x.insert(o, x + h);
                        stack.push(o);
                    }
                }
            }
        }
        for l in legs.iter_mut().filter(|l| !l.extended_from_m.is_finite()) {
            // Legs without stations at either end: laid out after everything else.
            l.extended_from_m = end_m;
            end_m += l.horizontal_m();
        }
        let mut direction = vec![None; survey.stations.len()];
        for (s, ls) in &by_station {
            let mut sum = DVec3::ZERO;
            for &i in ls {
                let l = &legs[i];
                let d = (l.to_m - l.from_m).truncate().extend(0.0).normalize_or_zero();
                // The first leg sets the sense; the others join it.
                let d = if sum.dot(d) < 0.0 { -d } else { d };
                sum += d;
            }
            direction[*s] = Some(sum.normalize_or_zero()).filter(|d| d.length_squared() > 0.5);
        }
        let grid = LegGrid::new(&legs, reach_m);
        Centreline { legs, direction, extended_m: end_m, grid }
    }

    /// The leg `p` belongs to (the nearest within reach) with its fraction along it and distance.
    pub(crate) fn leg_of(&self, p: DVec3) -> Option<(usize, f64, f64)> {
        self.grid.nearest(&self.legs, p)
    }
}

/// Legs bucketed by the cells their bounding boxes, grown by the reach, cover.
#[derive(Debug)]
struct LegGrid {
    cell_m: f64,
    reach_m: f64,
    cells: HashMap<[i64; 3], Vec<u32>>,
}

impl LegGrid {
    /// Cells per leg are bounded: a leg longer than this many cells along an axis is split
    /// into the cells its own segment crosses, grown by the reach.
    fn new(legs: &[MapLeg], reach_m: f64) -> Self {
        let cell_m = reach_m.max(0.5);
        let mut cells: HashMap<[i64; 3], Vec<u32>> = HashMap::new();
        let key = |p: DVec3| (p / cell_m).floor().as_i64vec3().to_array();
        for (i, l) in legs.iter().enumerate() {
            // Walk the leg in steps of a cell and add the cells around each step.
            let len = (l.to_m - l.from_m).length();
            let steps = (len / cell_m).ceil().max(1.0) as usize;
            let mut seen = std::collections::HashSet::new();
            for k in 0..=steps {
                let c = key(l.from_m.lerp(l.to_m, k as f64 / steps as f64));
                for dz in -1..=1 {
                    for dy in -1..=1 {
                        for dx in -1..=1 {
                            let n = [c[0] + dx, c[1] + dy, c[2] + dz];
                            if seen.insert(n) {
                                cells.entry(n).or_default().push(i as u32);
                            }
                        }
                    }
                }
            }
        }
        LegGrid { cell_m, reach_m, cells }
    }

    fn nearest(&self, legs: &[MapLeg], p: DVec3) -> Option<(usize, f64, f64)> {
        let c = (p / self.cell_m).floor().as_i64vec3().to_array();
        let mut best: Option<(usize, f64, f64)> = None;
        for &i in self.cells.get(&c)? {
            let (t, d) = legs[i as usize].nearest(p);
            if d <= self.reach_m && best.is_none_or(|b| d < b.2) {
                best = Some((i as usize, t, d));
            }
        }
        best
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use grotto_format::survey::{Leg, LegFlags, Station, StationFlags};

    fn station(name: &str, p: [f64; 3], entrance: bool) -> Station {
        Station {
            name: name.into(),
            position_m: p,
            flags: StationFlags { entrance, underground: true, ..Default::default() },
        }
    }

    fn leg(a: [f64; 3], b: [f64; 3], from: usize, to: usize) -> Leg {
        Leg {
            from_m: a,
            to_m: b,
            from: Some(from),
            to: Some(to),
            survey: "t".into(),
            flags: LegFlags::default(),
        }
    }

    #[test]
    fn the_extended_elevation_unrolls_legs_from_the_entrance_and_points_find_their_leg() {
        // An L: 10 m east, then 6 m north and 3 m down; the entrance at the far end of the L.
        let p = [[0.0, 0.0, 0.0], [10.0, 0.0, 0.0], [10.0, 6.0, -3.0]];
        let survey = Survey {
            stations: vec![station("a", p[0], false), station("b", p[1], false), station("c", p[2], true)],
            legs: vec![leg(p[0], p[1], 0, 1), leg(p[1], p[2], 1, 2)],
            ..Default::default()
        };
        let c = Centreline::new(&survey, 3.0);
        assert!((c.extended_m - 16.0).abs() < 1e-9, "{}", c.extended_m);
        // From c: the second leg is walked backwards first, laid out over 0..6, the first over 6..16.
        assert_eq!((c.legs[1].extended_from_m, c.legs[1].extended_sign), (6.0, -1.0));
        assert_eq!((c.legs[0].extended_from_m, c.legs[0].extended_sign), (16.0, -1.0));
        let (i, t, d) = c.leg_of(DVec3::new(4.0, 1.5, 0.0)).expect("beside the first leg");
        assert_eq!(i, 0);
        assert!((t - 0.4).abs() < 1e-9 && (d - 1.5).abs() < 1e-9);
        assert!(c.leg_of(DVec3::new(4.0, 5.0, 0.0)).is_none(), "beyond reach");
        // b's direction is the mean of east and north (either sense).
        let d = c.direction[1].expect("b has legs");
        assert!((d.x.abs() - d.y.abs()).abs() < 1e-9 && d.z == 0.0);
    }
}
