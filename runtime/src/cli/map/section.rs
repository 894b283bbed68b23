//! A passage's cross-section at a station from the scanned points in a thin slab across it:
//! the outline traced by angle around the section's middle (the median distance of the points
//! in each angular bin; bins no point fell in follow their neighbours), its width, height and
//! area, and where the station stands in it.

use serde::Serialize;

/// Angular bins of an outline: 2 degrees each. A polygon of 180 vertices on a circle misses
/// 0.02% of its area.
const BINS: usize = 180;

/// Share of the bins that must hold points for an outline to be drawn at all: less, and the
/// scans did not see enough of the passage around the station.
const MIN_FILLED: f64 = 0.4;

/// The widest run of empty bins an outline may bridge: a quarter turn (a floor under water, a
/// ledge's shadow). Wider, and the outline would be guessed, not traced.
const MAX_GAP_BINS: usize = BINS / 4;

/// A cross-section outline in the section's plane: u to the right looking along the passage,
/// v up, metres from the station.
#[derive(Clone, Debug, Serialize)]
pub(crate) struct Outline {
    pub polygon: Vec<[f64; 2]>,
    pub width_m: f64,
    pub height_m: f64,
    pub area_m2: f64,
    /// Whether the station stands inside the outline (in the air of the passage).
    pub inside: bool,
    /// From the station to the outline's centroid, metres.
    pub from_middle_m: f64,
    /// Points the outline was traced from.
    pub points: usize,
    /// Share of the angular bins that held points (the rest were filled from their neighbours).
    pub seen: f64,
}

/// The outline of `points` (u, v), or why the scans saw too little of it to trace one.
pub(crate) fn outline(points: &[[f32; 2]]) -> Result<Outline, String> {
    if points.len() < BINS / 4 {
        return Err(format!("{} scanned points in its slab, fewer than {}", points.len(), BINS / 4));
    }
    let (mut lo, mut hi) = ([f64::INFINITY; 2], [f64::NEG_INFINITY; 2]);
    for p in points {
        for a in 0..2 {
            lo[a] = lo[a].min(f64::from(p[a]));
            hi[a] = hi[a].max(f64::from(p[a]));
        }
    }
    // The middle of the points' box: a denser floor would pull a mean towards it.
    let mid = [0.5 * (lo[0] + hi[0]), 0.5 * (lo[1] + hi[1])];
    let mut bins: Vec<Vec<f64>> = vec![Vec::new(); BINS];
    for p in points {
        let (du, dv) = (f64::from(p[0]) - mid[0], f64::from(p[1]) - mid[1]);
        let angle = dv.atan2(du).rem_euclid(std::f64::consts::TAU);
        let k = ((angle / std::f64::consts::TAU * BINS as f64) as usize).min(BINS - 1);
        bins[k].push((du * du + dv * dv).sqrt());
    }
    let radius: Vec<Option<f64>> = bins
        .iter_mut()
        .map(|b| {
            (!b.is_empty()).then(|| {
                b.sort_by(f64::total_cmp);
                b[b.len() / 2]
            })
        })
        .collect();
    let filled = radius.iter().flatten().count();
    let seen = filled as f64 / BINS as f64;
    let gap = widest_gap(&radius);
    if seen < MIN_FILLED || gap > MAX_GAP_BINS {
        return Err(format!(
            "the scans saw {:.0}% of the way round it, with a gap of {} degrees (at least {:.0}%, gaps up to {} degrees)",
            100.0 * seen,
            gap * 360 / BINS,
            100.0 * MIN_FILLED,
            MAX_GAP_BINS * 360 / BINS
        ));
    }
    let polygon: Vec<[f64; 2]> = (0..BINS)
        .map(|k| {
            let r = radius[k].unwrap_or_else(|| fill_between(&radius, k));
            let angle = (k as f64 + 0.5) / BINS as f64 * std::f64::consts::TAU;
            [mid[0] + r * angle.cos(), mid[1] + r * angle.sin()]
        })
        .collect();
    let extent = |a: usize| {
        let (l, h) =
            polygon.iter().fold((f64::INFINITY, f64::NEG_INFINITY), |(l, h), p| (l.min(p[a]), h.max(p[a])));
        h - l
    };
    let (area_m2, centroid) = area_and_centroid(&polygon);
    Ok(Outline {
        width_m: extent(0),
        height_m: extent(1),
        area_m2,
        inside: contains(&polygon, [0.0, 0.0]),
        from_middle_m: (centroid[0].powi(2) + centroid[1].powi(2)).sqrt(),
        points: points.len(),
        seen,
        polygon,
    })
}

/// The longest run of empty bins, going round.
fn widest_gap(radius: &[Option<f64>]) -> usize {
    let n = radius.len();
    let Some(start) = radius.iter().position(Option::is_some) else { return n };
    let (mut widest, mut run) = (0, 0);
    for d in 1..=n {
        if radius[(start + d) % n].is_none() {
            run += 1;
            widest = widest.max(run);
        } else {
            run = 0;
        }
    }
    widest
}

/// The radius at empty bin `k`: linear between the nearest filled bins on either side.
fn fill_between(radius: &[Option<f64>], k: usize) -> f64 {
    let n = radius.len();
    let before = (1..n).find_map(|d| radius[(k + n - d) % n].map(|r| (d, r)));
    let after = (1..n).find_map(|d| radius[(k + d) % n].map(|r| (d, r)));
    match (before, after) {
        (Some((db, rb)), Some((da, ra))) => rb + (ra - rb) * db as f64 / (db + da) as f64,
        (Some((_, r)), None) | (None, Some((_, r))) => r,
        (None, None) => 0.0,
    }
}

/// The shoelace area and the centroid of a simple polygon.
fn area_and_centroid(p: &[[f64; 2]]) -> (f64, [f64; 2]) {
    let (mut a2, mut cx, mut cy) = (0.0, 0.0, 0.0);
    for i in 0..p.len() {
        let (q, r) = (p[i], p[(i + 1) % p.len()]);
        let cross = q[0] * r[1] - r[0] * q[1];
        a2 += cross;
        cx += (q[0] + r[0]) * cross;
        cy += (q[1] + r[1]) * cross;
    }
    if a2.abs() < 1e-12 {
        return (0.0, p.first().copied().unwrap_or_default());
    }
    (0.5 * a2.abs(), [cx / (3.0 * a2), cy / (3.0 * a2)])
}

/// Whether `q` lies inside the polygon (even-odd rule).
fn contains(p: &[[f64; 2]], q: [f64; 2]) -> bool {
    let mut inside = false;
    for i in 0..p.len() {
        let (a, b) = (p[i], p[(i + 1) % p.len()]);
        if (a[1] > q[1]) != (b[1] > q[1]) && q[0] < a[0] + (q[1] - a[1]) / (b[1] - a[1]) * (b[0] - a[0]) {
            inside = !inside;
        }
    }
    inside
}

/// The section as an SVG drawing at `px_per_m`: the outline, the station, its width and height
/// written beside it and a 1 m scale bar.
pub(crate) fn svg(name: &str, o: &Outline, px_per_m: f64) -> String {
    use std::fmt::Write;
    let (mut lo, mut hi) = ([0.0f64; 2], [0.0f64; 2]);
    for p in &o.polygon {
        for a in 0..2 {
            lo[a] = lo[a].min(p[a]);
            hi[a] = hi[a].max(p[a]);
        }
    }
    let margin = 0.5;
    let (w, h) =
        ((hi[0] - lo[0] + 2.0 * margin) * px_per_m, (hi[1] - lo[1] + 2.0 * margin) * px_per_m + 60.0);
    let x = |u: f64| (u - lo[0] + margin) * px_per_m;
    let y = |v: f64| (hi[1] + margin - v) * px_per_m;
    let mut s = String::new();
    let _ = writeln!(
        s,
        "<svg xmlns=\"http://www.w3.org/2000/svg\" width=\"{w:.0}\" height=\"{h:.0}\" viewBox=\"0 0 {w:.1} {h:.1}\">"
    );
    let _ = writeln!(s, "<rect width=\"100%\" height=\"100%\" fill=\"white\"/>");
    let points: Vec<String> = o.polygon.iter().map(|p| format!("{:.1},{:.1}", x(p[0]), y(p[1]))).collect();
    let _ = writeln!(
        s,
        "<polygon points=\"{}\" fill=\"#e8e2d6\" stroke=\"#222\" stroke-width=\"2\"/>",
        points.join(" ")
    );
    let _ = writeln!(s, "<circle cx=\"{:.1}\" cy=\"{:.1}\" r=\"4\" fill=\"#c81e1e\"/>", x(0.0), y(0.0));
    let base = (hi[1] - lo[1] + 2.0 * margin) * px_per_m;
    let _ = writeln!(
        s,
        "<line x1=\"10\" y1=\"{:.1}\" x2=\"{:.1}\" y2=\"{:.1}\" stroke=\"#222\" stroke-width=\"3\"/><text x=\"10\" y=\"{:.1}\" font-family=\"sans-serif\" font-size=\"12\">1 m</text>",
        base + 15.0,
        10.0 + px_per_m,
        base + 15.0,
        base + 32.0
    );
    let _ = writeln!(
        s,
        "<text x=\"{:.1}\" y=\"{:.1}\" font-family=\"sans-serif\" font-size=\"13\">{}: width {:.2} m, height {:.2} m, area {:.2} m²</text>",
        20.0 + px_per_m,
        base + 20.0,
        super::draw::xml_escape(name),
        o.width_m,
        o.height_m,
        o.area_m2
    );
    s.push_str("</svg>\n");
    s
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn an_ellipse_scanned_unevenly_gives_its_width_height_and_area() {
        // A 4 m wide, 2.5 m high ellipse, the station 0.5 m above its floor, points every 2 cm of
        // angle on its upper half and every 10 cm on the lower (a floor seen at a glance).
        let (a, b) = (2.0f64, 1.25f64);
        let centre = [0.3, 1.25 - 0.5];
        let mut pts = Vec::new();
        let mut t = 0.0f64;
        while t < std::f64::consts::TAU {
            pts.push([(centre[0] + a * t.cos()) as f32, (centre[1] + b * t.sin()) as f32]);
            t += if t < std::f64::consts::PI { 0.005 } else { 0.03 };
        }
        let o = outline(&pts).expect("seen all round");
        let area = std::f64::consts::PI * a * b;
        assert!((o.width_m - 4.0).abs() < 0.02 && (o.height_m - 2.5).abs() < 0.02, "{o:?}");
        assert!((o.area_m2 - area).abs() / area < 0.005, "{} against {area}", o.area_m2);
        assert!(o.inside && (o.from_middle_m - (0.09f64 + 0.5625).sqrt()).abs() < 0.02);
        // Half of it unseen: no outline.
        let half: Vec<[f32; 2]> = pts.iter().copied().filter(|p| p[1] > centre[1] as f32 + 0.4).collect();
        let why = outline(&half).unwrap_err();
        assert!(why.contains("gap"), "{why}");
    }
}
