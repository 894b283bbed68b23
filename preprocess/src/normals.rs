//! Per-point normals, normal spread and surfel radius for one tile.
//!
//! For each point: its k nearest neighbours (exact, over the tile and its halo so tile borders
//! see across: `knn.rs`, cells in Morton order with kiddo's kd-tree behind them), their covariance on coordinates centred at their mean (in f64),
//! and the eigenvector of the smallest eigenvalue as the normal. It is oriented toward the scanner
//! the point came from: caves are enclosed, so "up" or "away from the centroid" is wrong, while
//! the scanner always sees the wall from the open side. A plausible input normal (unit length,
//! within 60 degrees of the PCA plane's normal) is kept instead.
//!
//! Degenerate neighbourhoods have defined results, never NaN: fewer than 3 distinct points or
//! all duplicates -> the unit vector toward the scanner, and `TilePoints::isolated_radius_m` as
//! radius; collinear points -> the direction perpendicular to the line closest to the scanner
//! direction.
//!
//! Spread is `1 - |mean of the neighbours' unit normals|` (Toksvig); the radius covers the area
//! per point: `1.25 * d_k / sqrt(k)` where `d_k` is the distance to the k-th neighbour (1.25 closes
//! the gaps a square lattice leaves between inscribed discs).

use rayon::prelude::*;

use crate::knn::{CellCache, Knn};
use crate::manifest::SeenFrom;
use crate::orient::{CaveGrid, MAX_SCORE, OrientStats};

/// The guess of a point's squared k-th distance is the previous point's times this (1.14 times the
/// distance): the kNN first looks among the candidates within it. The result is exact whatever the
/// factor (too tight a guess searches all candidates again); it only sets the speed: with the
/// kNN by cells 1.3 ran 1.5% faster than 1.5 and 0.5% faster than 1.2 (`grotto-pack
/// bench-normals --points 1000000 --threads 1`, docs/benchmarks.md).
pub(crate) const KNN_BOUND_FACTOR: f32 = 1.3;

/// Surfel radii are widened by this over the disc that covers the area per point, so neighbouring
/// discs overlap without holes.
pub(crate) const RADIUS_COVER_FACTOR: f64 = 1.25;

/// The result for one point.
#[derive(Clone, Copy, Debug, PartialEq)]
pub(crate) struct PointNormal {
    pub(crate) normal: [f32; 3],
    pub(crate) spread: f32,
    pub(crate) radius_m: f32,
}

/// Eigen-decomposition of a symmetric 3x3 matrix by cyclic Jacobi rotations. Returns eigenvalues
/// ascending and their unit eigenvectors (columns as arrays).
///
/// Hand-written rather than taken from a linear-algebra crate: this runs once per point (10^8
/// times for a large cave), on a fixed 3x3 size where Jacobi is branch-light and exact to a few
/// ulps, and it stays accurate when eigenvalues nearly coincide (rotations only ever shrink the
/// off-diagonal part; no characteristic polynomial is solved).
pub(crate) fn sym_eigen3(m: [[f64; 3]; 3]) -> ([f64; 3], [[f64; 3]; 3]) {
    let mut a = m;
    let mut v = [[1.0, 0.0, 0.0], [0.0, 1.0, 0.0], [0.0, 0.0, 1.0]];
    let scale = a.iter().flatten().map(|x| x.abs()).fold(0.0, f64::max);
    if scale == 0.0 || !scale.is_finite() {
        return ([0.0; 3], [[1.0, 0.0, 0.0], [0.0, 1.0, 0.0], [0.0, 0.0, 1.0]]);
    }
    for _sweep in 0..32 {
        let off = a[0][1].abs() + a[0][2].abs() + a[1][2].abs();
        // 1e-15 relative: below it, rotations only shuffle rounding (a tighter bound can spin
        // through all sweeps without progress).
        if off <= scale * 1e-15 {
            break;
        }
        for (p, q) in [(0usize, 1usize), (0, 2), (1, 2)] {
            if a[p][q].abs() <= scale * 1e-300 {
                continue;
            }
            let theta = (a[q][q] - a[p][p]) / (2.0 * a[p][q]);
            let t = theta.signum() / (theta.abs() + (theta * theta + 1.0).sqrt());
            let t = if theta == 0.0 { 1.0 } else { t };
            let c = 1.0 / (t * t + 1.0).sqrt();
            let s = t * c;
            for row in &mut a {
                let (akp, akq) = (row[p], row[q]);
                row[p] = c * akp - s * akq;
                row[q] = s * akp + c * akq;
            }
            let (rp, rq) = (a[p], a[q]);
            a[p] = std::array::from_fn(|k| c * rp[k] - s * rq[k]);
            a[q] = std::array::from_fn(|k| s * rp[k] + c * rq[k]);
            for row in &mut v {
                let (vp, vq) = (row[p], row[q]);
                row[p] = c * vp - s * vq;
                row[q] = s * vp + c * vq;
            }
        }
    }
    let mut idx = [0usize, 1, 2];
    idx.sort_by(|&i, &j| a[i][i].total_cmp(&a[j][j]));
    let vals = idx.map(|i| a[i][i]);
    let vecs = idx.map(|i| [v[0][i], v[1][i], v[2][i]]);
    (vals, vecs)
}

/// The eigenvalues (ascending) of symmetric `m` and the unit eigenvector of the smallest, in
/// closed form: the smallest eigenvalue as the smallest root of the characteristic cubic of the
/// shifted and scaled matrix, by Newton's method; the other two from the cubic's coefficients;
/// the vector as the longest cross product of two rows of `m - smallest * I`. `None` where the
/// two smallest eigenvalues lie closer than a tenth of the spectrum's spread, where the vector
/// would lose digits (lines, blobs, duplicates): [`sym_eigen3`] is exact there.
pub(crate) fn smallest_eigenvector(m: [[f64; 3]; 3]) -> Option<([f64; 3], [f64; 3])> {
    let p1 = m[0][1] * m[0][1] + m[0][2] * m[0][2] + m[1][2] * m[1][2];
    let q = (m[0][0] + m[1][1] + m[2][2]) / 3.0;
    let (d0, d1, d2) = (m[0][0] - q, m[1][1] - q, m[2][2] - q);
    let p = ((d0 * d0 + d1 * d1 + d2 * d2 + 2.0 * p1) / 6.0).sqrt();
    if !(p > 0.0 && p.is_finite()) {
        return None;
    }
    // b = (m - q I) / p has trace 0 and tr(b^2) = 6, so its characteristic polynomial is
    // g(x) = x^3 - 3x - det(b), whose roots lie in [-2, 2] (Smith 1961); det(b) = det(m - q I)
    // / p^3 (one division rather than nine).
    let det_a = d0 * (d1 * d2 - m[1][2] * m[1][2]) - m[0][1] * (m[0][1] * d2 - m[1][2] * m[0][2])
        + m[0][2] * (m[0][1] * m[1][2] - d1 * m[0][2]);
    let r = (det_a / (p * p * p)).clamp(-2.0, 2.0);
    // Newton's method from below the smallest root: on [-2, -1] g rises and is concave, so every
    // step lands between the last point and the root, never past it. The start is a cubic in
    // sqrt(2 - r) fitted to the root (within 7.4e-4 over all r), lowered by 1e-3 to stay below
    // it. The error after a step is at most about x / (x^2 - 1) times the square of the one
    // before, under 11 where the gap test below passes: three steps take 1.7e-3 to rounding.
    // A fixed count leaves no loop exit to mispredict. This replaced Smith's acos and two cos,
    // and it is accurate to rounding where acos near +-1 is good to 2e-8.
    let u = (2.0 - r).sqrt();
    let mut x =
        (((-0.004_723_875_8 * u + 0.045_890_885_5) * u - 0.572_575_913_3) * u - 1.000_730_8 - 1e-3).max(-2.0);
    for _ in 0..3 {
        // Past -1 the two smallest roots meet (the gap test declines); the floor keeps the
        // division finite there.
        let slope = (3.0 * (x * x - 1.0)).max(1e-300);
        x = (x - (x * (x * x - 3.0) - r) / slope).min(-1.0);
    }
    let x = x.min(-1.0);
    // The other roots: they sum to -x and their product is x^2 - 3 (g has no x^2 term and its
    // pairwise products sum to -3).
    let half_gap = (12.0 - 3.0 * x * x).max(0.0).sqrt() / 2.0;
    let smallest = q + p * x;
    let middle = q + p * (-x / 2.0 - half_gap);
    let largest = q + p * (-x / 2.0 + half_gap);
    // The vector's error is the eigenvalue's over the gap to the middle one; a gap under p / 10
    // (lines, blobs) goes to Jacobi, which is exact there.
    if !middle.is_finite() || middle - smallest <= 0.1 * p {
        return None;
    }
    let rows: [[f64; 3]; 3] =
        std::array::from_fn(|i| std::array::from_fn(|j| m[i][j] - if i == j { smallest } else { 0.0 }));
    let cross = |a: [f64; 3], b: [f64; 3]| {
        [a[1] * b[2] - a[2] * b[1], a[2] * b[0] - a[0] * b[2], a[0] * b[1] - a[1] * b[0]]
    };
    let best = [cross(rows[0], rows[1]), cross(rows[0], rows[2]), cross(rows[1], rows[2])]
        .into_iter()
        .max_by(|a, b| dot(*a, *a).total_cmp(&dot(*b, *b)))
        .expect("three candidates");
    Some(([smallest, middle, largest], normalize(best)?))
}

fn normalize(v: [f64; 3]) -> Option<[f64; 3]> {
    let l = (v[0] * v[0] + v[1] * v[1] + v[2] * v[2]).sqrt();
    let inv = 1.0 / l;
    (l > 1e-12 && l.is_finite()).then(|| v.map(|c| c * inv))
}

fn dot(a: [f64; 3], b: [f64; 3]) -> f64 {
    a[0] * b[0] + a[1] * b[1] + a[2] * b[2]
}

/// Normal of one neighbourhood, oriented toward `view` (unit vector from the point to its
/// scanner).
#[cfg(test)]
fn normal_from_neighbourhood(neighbours: &[[f64; 3]], view: [f64; 3]) -> [f64; 3] {
    normal_from_points(neighbours.len(), || neighbours.iter().copied(), view)
}

/// The normal of a neighbourhood, oriented toward `view`, over points read twice from `points` (the mean, then the
/// covariance about it), so the estimator reads the tile's f32 points in place.
fn normal_from_points<I: Iterator<Item = [f64; 3]>>(
    count: usize,
    points: impl Fn() -> I,
    view: [f64; 3],
) -> [f64; 3] {
    if count < 3 {
        return view;
    }
    let n = count as f64;
    let mut mean = [0.0; 3];
    for p in points() {
        for a in 0..3 {
            mean[a] += p[a];
        }
    }
    let mean = mean.map(|c| c / n);
    let mut cov = [[0.0; 3]; 3];
    for p in points() {
        let d = [p[0] - mean[0], p[1] - mean[1], p[2] - mean[2]];
        for i in 0..3 {
            for j in i..3 {
                cov[i][j] += d[i] * d[j];
            }
        }
    }
    cov[1][0] = cov[0][1];
    cov[2][0] = cov[0][2];
    cov[2][1] = cov[1][2];
    // Most neighbourhoods are planes, well separated: closed form. Near-degenerate ones (lines,
    // duplicates, blobs) take Jacobi.
    if let Some((vals, smallest)) = smallest_eigenvector(cov)
        && vals[2] > 1e-24
        && vals[1] > vals[2] * 1e-8
    {
        return if dot(smallest, view) < 0.0 { smallest.map(|c| -c) } else { smallest };
    }
    let (vals, vecs) = sym_eigen3(cov);
    let largest = vals[2];
    // Duplicates: no extent at all. Collinear: one direction only.
    if largest <= 1e-24 {
        return view;
    }
    let normal = if vals[1] <= largest * 1e-8 {
        let line = vecs[2];
        match normalize(std::array::from_fn(|a| view[a] - dot(view, line) * line[a])) {
            Some(n) => n,
            None => vecs[0],
        }
    } else {
        vecs[0]
    };
    if dot(normal, view) < 0.0 { normal.map(|c| -c) } else { normal }
}

/// Inputs of one tile: all points (own and halo), which are own, scanner positions in the tile's
/// frame per point, optional input normals (zero vector = none), and the radius of a point with
/// no distinct neighbour.
#[derive(Debug)]
pub(crate) struct TilePoints<'a> {
    pub(crate) positions: &'a [[f32; 3]],
    pub(crate) own: &'a [bool],
    pub(crate) scanner_tile_m: &'a [[f64; 3]],
    pub(crate) input_normals: &'a [[f32; 3]],
    /// A point alone in its tile and halo, or among exact duplicates, has no spacing to take a
    /// radius from: it gets this one (the builder gives half a leaf: it stands for the leaf it
    /// falls in, drawn and voxelised rather than a zero-area disc nothing sees).
    pub(crate) isolated_radius_m: f32,
    /// Keep a plausible input normal (`--normals keep`) rather than estimating every normal.
    pub(crate) keep_input_normals: bool,
    /// Orientation for points whose scan has no scanner position (none: every point faces its
    /// scanner).
    pub(crate) orient: Option<Orient<'a>>,
}

/// What estimation did with a tile's own points: normals their files carried, those kept, and
/// orientation without a scanner.
#[derive(Clone, Copy, Debug, Default, PartialEq, serde::Serialize, serde::Deserialize)]
pub(crate) struct NormalStats {
    /// Own points whose file carried a normal (counted under `--normals estimate` too).
    pub(crate) input_normals: u64,
    /// Of those, kept rather than re-estimated.
    pub(crate) input_kept: u64,
    pub(crate) orientation: OrientStats,
}

impl NormalStats {
    pub(crate) fn add(&mut self, o: &NormalStats) {
        self.input_normals += o.input_normals;
        self.input_kept += o.input_kept;
        self.orientation.add(&o.orientation);
    }
}

/// How points without a scanner are oriented: by the enclosure votes of `grid` (see orient.rs).
#[derive(Clone, Copy, Debug)]
pub(crate) struct Orient<'a> {
    pub(crate) grid: &'a CaveGrid,
    /// World position of the tile's frame.
    pub(crate) tile_origin_m: [f64; 3],
    /// Per point: `None` where its scan has a scanner position (its normal faces the scanner),
    /// else the side its scan saw the walls from (inside: the normal faces what the walls
    /// enclose; outside: away from it).
    pub(crate) seen_from: &'a [Option<SeenFrom>],
}

/// Normals for the own points of a tile, in order. `k` neighbours (the point itself included).
pub(crate) fn estimate(tile: &TilePoints<'_>, k: usize) -> Vec<PointNormal> {
    estimate_with_stats(tile, k).0
}

/// [`estimate`], with what it did with file normals and orientation without a scanner.
pub(crate) fn estimate_with_stats(tile: &TilePoints<'_>, k: usize) -> (Vec<PointNormal>, NormalStats) {
    let n = tile.positions.len();
    if n == 0 {
        return (Vec::new(), NormalStats::default());
    }
    let k = k.clamp(3, 64).min(n);
    // Queries run in Morton order: the grid gathers each cell's candidates once for all of its
    // points, and the kd-tree (for what the grid cannot prove) walks the same leaves from one
    // query to the next. `order[j]` is the input index of sorted point j.
    let (order, knn) = Knn::new(tile.positions);
    let own_sorted: Vec<bool> = order.iter().map(|&i| tile.own[i as usize]).collect();
    // Everything below is in sorted order (`j`), neighbour lists included. Per point: normal,
    // radius, the enclosure score of that normal (MAX_SCORE where the point faces its scanner:
    // that orientation is known), and whether its input normal was kept.
    let mut lists: Vec<u32> = vec![0; n * k];
    let mut per_point: Vec<Estimate> = vec![Estimate::default(); n];
    // Own points first. A halo point's normal only matters where an own point has it as a
    // neighbour (spread and orientation votes average over the neighbourhood), which is a thin
    // shell of the halo: only those are estimated next (a quarter of the points at 10^8 were
    // halo copies, most never a neighbour).
    estimate_sorted(tile, &knn, &order, k, &|j| own_sorted[j], &mut lists, &mut per_point);
    let mut needed = vec![false; n];
    for (j, list) in lists.chunks(k).enumerate() {
        if own_sorted[j] {
            for &nb in list {
                needed[nb as usize] |= !own_sorted[nb as usize];
            }
        }
    }
    estimate_sorted(tile, &knn, &order, k, &|j| needed[j], &mut lists, &mut per_point);
    drop(needed);
    // Spread and final orientation in sorted order, in parallel over fixed runs: a point's
    // neighbours lie near it in Morton order, so their estimates are mostly in cache (in input
    // order every neighbour was a miss). The orientation statistics are summed run by run in
    // order, so they do not depend on the thread count.
    let sorted_results: Vec<(Vec<PointNormal>, OrientStats)> = order
        .par_chunks(4096)
        .enumerate()
        .map(|(run, inputs)| {
            let mut orientation = OrientStats::default();
            let normals = inputs
                .iter()
                .enumerate()
                .map(|(off, &i)| (run * 4096 + off, i as usize))
                .filter(|&(j, _)| own_sorted[j])
                .map(|(j, i)| {
                    let list = &lists[j * k..(j + 1) * k];
                    let ni = match tile.orient.filter(|o| o.seen_from[i].is_some()) {
                        Some(_) => orient_by_neighbourhood(tile, i, j, list, &per_point, &mut orientation),
                        None => per_point[j].normal,
                    };
                    let mut sum = [0.0f64; 3];
                    for &nb in list {
                        let nj = per_point[nb as usize].normal;
                        // Flip neighbours onto this point's side: orientation is not the spread.
                        let sign = if dot(nj, ni) < 0.0 { -1.0 } else { 1.0 };
                        for a in 0..3 {
                            sum[a] += sign * nj[a];
                        }
                    }
                    let mean_len = (dot(sum, sum)).sqrt() / list.len() as f64;
                    let radius = per_point[j].radius_m;
                    PointNormal {
                        normal: ni.map(|c| c as f32),
                        spread: (1.0 - mean_len).clamp(0.0, 1.0) as f32,
                        radius_m: if radius > 0.0 { radius as f32 } else { tile.isolated_radius_m },
                    }
                })
                .collect();
            (normals, orientation)
        })
        .collect();
    let mut stats = NormalStats::default();
    // Own points' results in sorted order, then put back in input order.
    let mut by_sorted = Vec::with_capacity(n);
    for (normals, orientation) in sorted_results {
        by_sorted.extend(normals);
        stats.orientation.add(&orientation);
    }
    // rank[j]: where sorted point j's result sits in `by_sorted` (own points only).
    let mut rank = vec![0u32; n];
    let mut next = 0u32;
    for (j, r) in rank.iter_mut().enumerate() {
        if own_sorted[j] {
            *r = next;
            next += 1;
        }
    }
    let mut sorted_of = vec![0u32; n];
    for (j, &i) in order.iter().enumerate() {
        sorted_of[i as usize] = j as u32;
    }
    let mut out = Vec::with_capacity(by_sorted.len());
    for i in (0..n).filter(|&i| tile.own[i]) {
        let j = sorted_of[i] as usize;
        out.push(by_sorted[rank[j] as usize]);
        stats.input_normals += u64::from(tile.input_normals[i] != [0.0; 3]);
        stats.input_kept += u64::from(per_point[j].kept);
    }
    (out, stats)
}

/// What the first pass finds for one point (sorted order).
#[derive(Clone, Copy, Debug, Default)]
struct Estimate {
    normal: [f64; 3],
    radius_m: f64,
    /// Enclosure score of `normal` (MAX_SCORE where the point faces its scanner).
    score: i32,
    /// Its input normal was kept.
    kept: bool,
}

/// Neighbour lists and oriented normals and radii of the sorted points `wanted` picks, in
/// parallel over runs of sorted points (queries in Morton order reuse the kNN's cells).
fn estimate_sorted(
    tile: &TilePoints<'_>,
    knn: &Knn,
    order: &[u32],
    k: usize,
    wanted: &(dyn Fn(usize) -> bool + Sync),
    lists: &mut [u32],
    per_point: &mut [Estimate],
) {
    const RUN: usize = 1024;
    let pts = knn.points();
    lists.par_chunks_mut(k * RUN).zip(per_point.par_chunks_mut(RUN)).enumerate().for_each(
        |(run, (lists, per_point))| {
            let mut cache = CellCache::default();
            let mut found: Vec<(f32, u32)> = Vec::with_capacity(k);
            // Morton neighbours have similar spacing: the previous k-th distance widened
            // (KNN_BOUND_FACTOR) is the guess of the next.
            let mut bound = f32::INFINITY;
            for (off, (list, estimate)) in lists.chunks_mut(k).zip(per_point.iter_mut()).enumerate() {
                let j = run * RUN + off;
                if !wanted(j) {
                    continue;
                }
                knn.nearest(j, k, bound, &mut cache, &mut found);
                for (slot, nb) in
                    list.iter_mut().zip(found.iter().map(|nb| nb.1).chain(std::iter::repeat(j as u32)))
                {
                    *slot = nb;
                }
                let i = order[j] as usize;
                let p = pts[j].map(f64::from);
                let bare = tile.orient.and_then(|o| o.seen_from[i].map(|side| (o, side)));
                // Without a scanner, the PCA sign is provisional (up); the votes decide below.
                let view = match bare {
                    Some(_) => [0.0, 0.0, 1.0],
                    None => {
                        let s = tile.scanner_tile_m[i];
                        normalize([s[0] - p[0], s[1] - p[1], s[2] - p[2]]).unwrap_or([0.0, 0.0, 1.0])
                    }
                };
                let mut normal = normal_from_points(
                    found.len(),
                    || found.iter().map(|nb| pts[nb.1 as usize].map(f64::from)),
                    view,
                );
                let input = tile.input_normals[i].map(f64::from);
                let mut kept = false;
                if tile.keep_input_normals
                    && let Some(given) = normalize(input)
                    && (dot(input, input) - 1.0).abs() < 0.05
                    && dot(given, normal).abs() > 0.5
                {
                    normal = if dot(given, view) < 0.0 { given.map(|c| -c) } else { given };
                    kept = true;
                }
                let score = match bare {
                    Some((o, side)) => {
                        let score = o.grid.score(std::array::from_fn(|a| o.tile_origin_m[a] + p[a]), normal);
                        match side {
                            SeenFrom::Inside => score,
                            SeenFrom::Outside => -score,
                        }
                    }
                    None => MAX_SCORE,
                };
                let d2 = found.iter().map(|nb| nb.0).fold(0.0f32, f32::max);
                bound = if d2 > 0.0 { d2 * KNN_BOUND_FACTOR } else { f32::INFINITY };
                *estimate = Estimate {
                    normal,
                    radius_m: RADIUS_COVER_FACTOR * f64::from(d2).sqrt() / (k as f64).sqrt(),
                    score,
                    kept,
                };
            }
        },
    );
}

/// The sign of point `i`'s normal (no scanner) from its neighbourhood's enclosure votes: each
/// neighbour's score, turned onto `i`'s normal by the cosine between them (a neighbour across a
/// crease says little about this side). Zero evidence turns the normal up (+z: open ground).
/// `i` is the point's input index, `j` its sorted one; `list` and `per_point` are sorted.
fn orient_by_neighbourhood(
    tile: &TilePoints<'_>,
    i: usize,
    j: usize,
    list: &[u32],
    per_point: &[Estimate],
    stats: &mut OrientStats,
) -> [f64; 3] {
    let ni = per_point[j].normal;
    let total: f64 = list
        .iter()
        .map(|&nb| f64::from(per_point[nb as usize].score) * dot(per_point[nb as usize].normal, ni))
        .sum();
    let facing = if total > 0.0 {
        true
    } else if total < 0.0 {
        false
    } else {
        stats.undecided += 1;
        ni[2] >= 0.0
    };
    let normal = if facing { ni } else { ni.map(|c| -c) };
    stats.points += 1;
    let score = per_point[j].score;
    if score != 0 && (score > 0) != facing {
        stats.corrected += 1;
    }
    if total.abs() < f64::from(MAX_SCORE) {
        stats.weak += 1;
    }
    stats.confidence_sum += total.abs() / (list.len() as f64 * f64::from(MAX_SCORE));
    // The old rule turned every normal toward the scan frame's origin.
    let p = tile.positions[i].map(f64::from);
    let s = tile.scanner_tile_m[i];
    if dot(normal, [s[0] - p[0], s[1] - p[1], s[2] - p[2]]) < 0.0 {
        stats.flipped += 1;
    }
    normal
}

#[cfg(test)]
mod tests {
    use super::*;

    fn rot(axis: [f64; 3], angle: f64) -> [[f64; 3]; 3] {
        let a = normalize(axis).unwrap();
        let (s, c) = angle.sin_cos();
        let t = 1.0 - c;
        [
            [t * a[0] * a[0] + c, t * a[0] * a[1] - s * a[2], t * a[0] * a[2] + s * a[1]],
            [t * a[0] * a[1] + s * a[2], t * a[1] * a[1] + c, t * a[1] * a[2] - s * a[0]],
            [t * a[0] * a[2] - s * a[1], t * a[1] * a[2] + s * a[0], t * a[2] * a[2] + c],
        ]
    }

    fn compose(r: [[f64; 3]; 3], vals: [f64; 3]) -> [[f64; 3]; 3] {
        std::array::from_fn(|i| std::array::from_fn(|j| (0..3).map(|k| r[i][k] * vals[k] * r[j][k]).sum()))
    }

    #[test]
    fn jacobi_recovers_eigenpairs_even_when_eigenvalues_nearly_coincide() {
        for (vals, angle) in [
            ([1e-6, 1.0, 2.0], 0.7),
            ([1.0, 1.0 + 1e-9, 3.0], 1.3),
            ([0.5, 2.0, 2.0 + 1e-12], 2.1),
            ([1e-20, 1e-3, 1e3], 0.4),
        ] {
            let r = rot([0.3, -0.5, 0.8], angle);
            let m = compose(r, vals);
            let (got, vecs) = sym_eigen3(m);
            for i in 0..3 {
                assert!((got[i] - vals[i]).abs() <= 1e-12 * vals[2], "{vals:?}: {got:?}");
            }
            // The smallest eigenvector is exact whenever it is separated from the others.
            let truth = [r[0][0], r[1][0], r[2][0]];
            assert!(dot(vecs[0], truth).abs() > 1.0 - 1e-9 || vals[1] - vals[0] < 1e-6, "{vals:?}");
            // And the reconstruction is exact in every case.
            let back = compose(
                [
                    [vecs[0][0], vecs[1][0], vecs[2][0]],
                    [vecs[0][1], vecs[1][1], vecs[2][1]],
                    [vecs[0][2], vecs[1][2], vecs[2][2]],
                ],
                got,
            );
            for i in 0..3 {
                for j in 0..3 {
                    assert!((back[i][j] - m[i][j]).abs() < 1e-12 * vals[2].max(1.0));
                }
            }
        }
    }

    #[test]
    fn the_closed_form_agrees_with_jacobi_where_it_answers() {
        let mut answered = 0;
        for (i, vals) in [
            [1e-6, 1.0, 2.0],
            [1e-4, 0.3, 0.31],
            [0.0, 1e-3, 1e3],
            [2.0, 2.5, 9.0],
            [1e-12, 1e-5, 1.0],
            // Degenerate: the two smallest (nearly) coincide, so the closed form declines.
            [1.0, 1.0 + 1e-9, 3.0],
            [0.0, 0.0, 1.0],
            [1.0, 1.0, 1.0],
        ]
        .into_iter()
        .enumerate()
        {
            let r = rot([0.3, -0.5 + 0.1 * i as f64, 0.8], 0.3 + 0.4 * i as f64);
            let m = compose(r, vals);
            let (jvals, jvecs) = sym_eigen3(m);
            match smallest_eigenvector(m) {
                Some((got, v)) => {
                    answered += 1;
                    for k in 0..3 {
                        assert!((got[k] - jvals[k]).abs() <= 1e-12 * vals[2], "{vals:?}: {got:?} {jvals:?}");
                    }
                    assert!(dot(v, jvecs[0]).abs() > 1.0 - 1e-12, "{vals:?}: {v:?} {:?}", jvecs[0]);
                }
                None => assert!(vals[1] - vals[0] < 0.1 * vals[2], "{vals:?} declined"),
            }
        }
        assert_eq!(answered, 3);
    }

    #[test]
    fn the_closed_form_is_exact_over_the_spectra_it_answers() {
        // Spectra from flat planes to near-lines, down to the gap where it declines: Newton's
        // fixed three steps must reach rounding everywhere it answers.
        let mut answered = 0;
        for i in 0..4000 {
            let t = f64::from(i) / 4000.0;
            let vals = [1e-6 * (i % 7) as f64, 0.02 + 0.98 * t * t, 1.0];
            let r = rot([0.3, -0.5 + 0.0003 * f64::from(i), 0.8], 0.001 * f64::from(i));
            let m = compose(r, vals);
            let (jvals, jvecs) = sym_eigen3(m);
            if let Some((got, v)) = smallest_eigenvector(m) {
                answered += 1;
                for k in 0..3 {
                    assert!((got[k] - jvals[k]).abs() <= 1e-12, "{vals:?}: {got:?} {jvals:?}");
                }
                assert!(dot(v, jvecs[0]).abs() > 1.0 - 1e-12, "{vals:?}");
            }
        }
        // Those with the middle eigenvalue under about 0.033 (a tenth of p) go to Jacobi.
        assert!(answered > 3400, "{answered}");
    }

    #[test]
    fn points_without_a_distinct_neighbour_get_the_isolated_radius() {
        // One point alone, then a tile of exact duplicates: no spacing to measure.
        for positions in [vec![[1.0f32, 2.0, 3.0]], vec![[1.0f32, 2.0, 3.0]; 8]] {
            let n = positions.len();
            let out = estimate(
                &TilePoints {
                    positions: &positions,
                    own: &vec![true; n],
                    scanner_tile_m: &vec![[0.0, 0.0, 10.0]; n],
                    input_normals: &vec![[0.0; 3]; n],
                    isolated_radius_m: 0.03125,
                    keep_input_normals: true,
                    orient: None,
                },
                16,
            );
            assert!(out.iter().all(|p| p.radius_m == 0.03125), "{out:?}");
        }
    }

    #[test]
    fn degenerate_neighbourhoods_have_defined_normals() {
        let view = [0.0, 0.6, 0.8];
        // Fewer than 3 points, and exact duplicates: toward the scanner.
        assert_eq!(normal_from_neighbourhood(&[[1.0, 2.0, 3.0]], view), view);
        assert_eq!(normal_from_neighbourhood(&[[1.0, 2.0, 3.0]; 8], view), view);
        // Collinear along x: perpendicular to the line, toward the scanner.
        let line: Vec<[f64; 3]> = (0..8).map(|i| [f64::from(i) * 0.1, 0.0, 0.0]).collect();
        let n = normal_from_neighbourhood(&line, view);
        assert!(n[0].abs() < 1e-9 && (dot(n, view) - 1.0).abs() < 1e-9, "{n:?}");
        // A perfect plane z = 5 seen from below.
        let plane: Vec<[f64; 3]> = (0..16).map(|i| [f64::from(i % 4), f64::from(i / 4), 5.0]).collect();
        let n = normal_from_neighbourhood(&plane, [0.0, 0.0, -1.0]);
        assert_eq!(n, [0.0, 0.0, -1.0]);
        for v in [n, normal_from_neighbourhood(&line, view)] {
            assert!(v.iter().all(|c| c.is_finite()));
        }
    }

    #[test]
    fn a_plane_gets_zero_spread_and_radius_from_spacing() {
        let s = 0.01;
        let positions: Vec<[f32; 3]> =
            (0..400).map(|i| [(i % 20) as f32 * s, (i / 20) as f32 * s, 1.0]).collect();
        let own = vec![true; positions.len()];
        let scanners = vec![[0.1, 0.1, 3.0]; positions.len()];
        let inputs = vec![[0.0; 3]; positions.len()];
        let out = estimate(
            &TilePoints {
                positions: &positions,
                own: &own,
                scanner_tile_m: &scanners,
                input_normals: &inputs,
                isolated_radius_m: 0.5,
                keep_input_normals: true,
                orient: None,
            },
            16,
        );
        for p in &out {
            assert!((p.normal[2] - 1.0).abs() < 1e-6 && p.spread < 1e-6);
        }
        // Interior point: d_16 on a square lattice is sqrt(5) * s -> r ~ 0.70 s, enough to close gaps.
        let r = out[210].radius_m / s;
        assert!((0.65..0.75).contains(&r), "{r}");
    }
}
