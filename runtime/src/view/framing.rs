//! A view and a light for scenes that bring none. A package built from a bare scan file has no
//! cameras and no lights; a fixed default view of its bounding box may see nothing (a scan from
//! inside a cave seen from outside its box, a bunny 15 cm across behind a survey origin), and an
//! unlit scene renders black. Here the data is framed by measurement: candidate views are scored
//! by splatting a sample of the surfels into a small depth buffer of their image (the share of
//! pixels a surface covers, the median visible distance, how squarely the surfaces face the eye):
//!
//! - from inside: empty cells of a coarse occupancy grid enclosed by surfaces that face them (the
//!   largest open spaces of a cave, found with a distance transform and an enclosure test),
//!   looking along the directions around them;
//! - from outside: the data fitted to the image from above, from the sides, and face-on along the
//!   principal axes of the points (a single disc, a wall or a terrain seen square).
//!
//! An inside view that sees a surface almost everywhere wins (ties: the one that sees furthest,
//! down a passage rather than into the nearest wall); else the outside view that shows the most
//! data while surfaces cover most of the image ([`MOST`]).
//! Without lights, [`headlamp`] gives the camera what a caver carries: a spot at the eye sized to
//! what the view sees.
//!
//! Written by hand: a 128^3 grid, a breadth-first distance transform, fixed-step ray marches and a
//! disc splatter into a 64x48 depth buffer are a few lines each; the choice of views is the
//! project's own.

use glam::{DVec3, IVec3, Vec3};

use crate::error::{Error, Result};
use crate::scene::data::{SceneData, SceneLight, Spot};
use crate::view::camera::Camera;

/// Cells per side of the occupancy grid at most.
const GRID_CELLS: i32 = 128;
/// Rows of the depth buffer a view is estimated in (columns follow the aspect).
const ESTIMATE_ROWS: usize = 48;
/// Vertical field of view of a framed camera, degrees.
pub(crate) const FRAMED_FOV_Y_DEG: f32 = 60.0;
/// Irradiance the headlamp gives a surface at the median distance the view sees, W/m^2 (an 8 W
/// lamp at about 0.8 m): auto exposure takes the absolute level out, but culling (`--light-cutoff`)
/// and EXR output see a lamp bright enough for the whole view.
pub(crate) const HEADLAMP_IRRADIANCE_W_M2: f32 = 1.0;
/// Colour of the headlamp (a neutral white LED).
pub(crate) const HEADLAMP_COLOR: [f32; 3] = [1.0, 0.95, 0.9];

/// A sample of the scene's surfels (at most `FIT_POINTS`, inside their robust bounds): what view
/// estimates and fits need.
#[derive(Clone, Debug)]
pub(crate) struct SurfelSample {
    /// Bounds of the surfels (1st to 99th percentile per axis when there are many) widened by
    /// `splat_radius_m`, frame metres.
    min_m: Vec3,
    max_m: Vec3,
    /// Frame-space surfel centres.
    points: Vec<Vec3>,
    /// Their unit normals (zero: none) and splat radii, widened by the square root of the
    /// sampling stride so the sample covers what all surfels cover.
    normals: Vec<Vec3>,
    radii: Vec<f32>,
    /// Splat radius of a typical surfel, metres.
    splat_radius_m: f32,
    /// Sum of the sample's normals.
    mean_normal: Vec3,
}

/// Surfels in a coarse grid over the sample's bounds: which cells hold a surface, and the sum of
/// the surfel normals there (for the search of inside views).
#[derive(Clone, Debug)]
struct Occupancy {
    min_m: Vec3,
    cell_m: f32,
    dims: IVec3,
    normals: Vec<Vec3>,
    occupied: Vec<bool>,
}

/// Of the 14 rays from a candidate eye, how many must meet a surface facing it.
const ENCLOSED_RAYS: u32 = 10;
/// Cell tests the surfel marking may make, about.
const MARK_BUDGET: f64 = 5e7;
/// Surfel centres kept for fitting outside views.
const FIT_POINTS: usize = 20_000;

/// What a view sees, estimated by splatting the surfel sample.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct ViewEstimate {
    /// Share of the image's pixels a surface covers, 0..=1.
    pub(crate) coverage: f32,
    /// Median distance of those hits, metres (0 when nothing is hit).
    pub(crate) median_distance_m: f32,
    /// Mean over the image of |cos| between the visible surface's normal and the view ray (0
    /// where nothing is seen): how much of the image a lamp at the eye lights. A strip seen
    /// end-on or a wall at grazing angles covers the image but shows it dark.
    pub(crate) lit: f32,
}

/// A chosen view and how it was found.
#[derive(Clone, Debug, PartialEq)]
pub struct Framing {
    pub(crate) camera: Camera,
    pub estimate: ViewEstimate,
    /// "inside" (from an open space among the surfaces) or "outside" (the data fitted to the image).
    pub(crate) kind: &'static str,
}

fn percentile(v: &mut [f32], q: f32) -> f32 {
    let k = ((v.len() - 1) as f32 * q).round() as usize;
    *v.select_nth_unstable_by(k, f32::total_cmp).1
}

impl SurfelSample {
    /// The sample of `scene`'s surfels (robust bounds: a few stray returns do not shrink the rest
    /// to a dot), or None without surfels.
    pub(crate) fn from_scene(scene: &SceneData, splat_scale: f32) -> Option<Self> {
        let centres: Vec<Vec3> = scene
            .surfels
            .iter()
            .map(|s| Vec3::from_slice(&s.position_radius[..3]))
            .filter(|p| p.is_finite())
            .collect();
        if centres.is_empty() {
            return None;
        }
        let trim = if centres.len() >= 1000 { 0.01 } else { 0.0 };
        let mut lo = Vec3::ZERO;
        let mut hi = Vec3::ZERO;
        for a in 0..3 {
            let mut v: Vec<f32> = centres.iter().map(|p| p[a]).collect();
            lo[a] = percentile(&mut v, trim);
            hi[a] = percentile(&mut v, 1.0 - trim);
        }
        let mut radii: Vec<f32> = scene
            .surfels
            .iter()
            .map(|s| s.position_radius[3])
            .filter(|r| r.is_finite() && *r > 0.0)
            .collect();
        let radius = if radii.is_empty() { 0.0 } else { percentile(&mut radii, 0.5) };
        let splat_radius_m = (radius * splat_scale).max((hi - lo).max_element() * 1e-3).max(1e-4);
        let mut sample = Self {
            min_m: lo - Vec3::splat(splat_radius_m),
            max_m: hi + Vec3::splat(splat_radius_m),
            points: Vec::new(),
            normals: Vec::new(),
            radii: Vec::new(),
            splat_radius_m,
            mean_normal: Vec3::ZERO,
        };
        let stride = scene.surfels.len().div_ceil(FIT_POINTS).max(1);
        for s in scene.surfels.iter().step_by(stride) {
            let p = Vec3::from_slice(&s.position_radius[..3]);
            if !sample.holds(p) {
                continue;
            }
            let n = Vec3::from_slice(&s.normal_spread[..3]).try_normalize().unwrap_or(Vec3::ZERO);
            let r = s.position_radius[3];
            let r = if r.is_finite() && r > 0.0 { r * splat_scale } else { splat_radius_m };
            sample.points.push(p);
            sample.normals.push(n);
            sample.radii.push(r * (stride as f32).sqrt());
            sample.mean_normal += n;
        }
        Some(sample)
    }

    fn holds(&self, p: Vec3) -> bool {
        p.cmpge(self.min_m).all() && p.cmplt(self.max_m).all()
    }

    /// Splats the sampled surfels into a small depth buffer of `camera`'s image, as the G-buffer
    /// pass does (discs of their projected radius, shrunk by the square root of how obliquely they
    /// are seen: the circle of an ellipse's area): the share of pixels covered and the median
    /// depth of what is visible. A coarse grid of rays overestimated thin data (a flight strip
    /// seen end-on fills 4 m cells, not the image).
    pub(crate) fn estimate(&self, camera: &Camera, aspect: f32) -> ViewEstimate {
        let (forward, right, up) = basis(camera);
        let tan_y = (camera.fov_y_deg.to_radians() * 0.5).tan();
        let h = ESTIMATE_ROWS;
        let w = ((h as f32 * aspect).round() as usize).clamp(8, 4 * h);
        let px_per_unit = h as f32 * 0.5 / tan_y;
        let mut depth = vec![(f32::INFINITY, 0.0f32); w * h];
        let near = 1e-3 * self.splat_radius_m;
        for ((p, n), r) in self.points.iter().zip(&self.normals).zip(&self.radii) {
            let v = *p - camera.eye_m;
            let z = v.dot(forward);
            if z <= near {
                continue;
            }
            let dist = v.length();
            let cx = (v.dot(right) / (z * tan_y * aspect) * 0.5 + 0.5) * w as f32;
            let cy = (0.5 - v.dot(up) / (z * tan_y) * 0.5) * h as f32;
            let facing = if *n == Vec3::ZERO { 1.0 } else { (n.dot(v) / dist).abs() };
            let radius_px = (r * px_per_unit / z * facing.max(0.02).sqrt()).max(0.5);
            let (x0, x1) = ((cx - radius_px).floor().max(0.0), (cx + radius_px).ceil().min(w as f32));
            let (y0, y1) = ((cy - radius_px).floor().max(0.0), (cy + radius_px).ceil().min(h as f32));
            if !(x0 < x1 && y0 < y1) {
                continue;
            }
            for y in y0 as usize..y1 as usize {
                for x in x0 as usize..x1 as usize {
                    let (dx, dy) = (x as f32 + 0.5 - cx, y as f32 + 0.5 - cy);
                    if dx * dx + dy * dy <= radius_px * radius_px {
                        let d = &mut depth[y * w + x];
                        if dist < d.0 {
                            *d = (dist, facing);
                        }
                    }
                }
            }
        }
        let lit = depth.iter().map(|d| d.1).sum::<f32>() / (w * h) as f32;
        let mut seen: Vec<f32> = depth.into_iter().map(|d| d.0).filter(|d| d.is_finite()).collect();
        let coverage = seen.len() as f32 / (w * h) as f32;
        let median_distance_m = if seen.is_empty() { 0.0 } else { percentile(&mut seen, 0.5) };
        ViewEstimate { coverage, median_distance_m, lit }
    }

    /// The camera looking along `dir` (unit) that fits the points to the image: centred on their
    /// extent across the view, as close as the nearest ones allow.
    fn fit(&self, dir: Vec3, aspect: f32) -> Camera {
        let up_hint = if dir.z.abs() > 0.95 { Vec3::Y } else { Vec3::Z };
        let right = dir.cross(up_hint).normalize();
        let up = right.cross(dir);
        let (mut lo, mut hi) = (Vec3::splat(f32::MAX), Vec3::splat(f32::MIN));
        for p in &self.points {
            let q = Vec3::new(p.dot(right), p.dot(up), p.dot(dir));
            lo = lo.min(q);
            hi = hi.max(q);
        }
        let r = self.splat_radius_m;
        let (lo, hi) = (lo - Vec3::new(r, r, 0.0), hi + Vec3::new(r, r, 0.0));
        let tan_y = (FRAMED_FOV_Y_DEG.to_radians() * 0.5).tan();
        let half = (hi - lo) * 0.5;
        let distance = (half.x / (tan_y * aspect)).max(half.y / tan_y).max(1e-4);
        let centre = (lo + hi) * 0.5;
        let target = right * centre.x + up * centre.y + dir * lo.z;
        Camera { eye_m: target - dir * distance, look_at_m: target, up: up_hint, fov_y_deg: FRAMED_FOV_Y_DEG }
    }

    /// Principal axes of the fitting points (eigenvectors of their covariance, any order).
    fn principal_axes(&self) -> Vec<Vec3> {
        let n = self.points.len() as f32;
        if n < 3.0 {
            return Vec::new();
        }
        let mean = self.points.iter().copied().sum::<Vec3>() / n;
        let mut cov = glam::Mat3::ZERO;
        for p in &self.points {
            let d = *p - mean;
            cov += glam::Mat3::from_cols(d * d.x, d * d.y, d * d.z);
        }
        // Power iteration with deflation: three symmetric eigenvectors are all this needs.
        let mut axes = Vec::new();
        let mut m = cov * (1.0 / n);
        for _ in 0..3 {
            let mut v = Vec3::new(0.6, 0.5, 0.62).normalize();
            for _ in 0..64 {
                let w = m * v;
                if w.length() < 1e-20 {
                    break;
                }
                v = w.normalize();
            }
            let lambda = v.dot(m * v);
            axes.push(v);
            m -= glam::Mat3::from_cols(v * v.x, v * v.y, v * v.z) * lambda;
        }
        axes
    }
}

impl Occupancy {
    /// The grid over `sample`'s bounds, every surfel of `scene` in it marked.
    fn new(scene: &SceneData, sample: &SurfelSample) -> Self {
        let (lo, hi) = (sample.min_m, sample.max_m);
        let splat_radius_m = sample.splat_radius_m;
        let cell_m = (hi - lo).max_element() / GRID_CELLS as f32;
        let dims = ((hi - lo) / cell_m).ceil().as_ivec3().clamp(IVec3::ONE, IVec3::splat(GRID_CELLS));
        let n = (dims.x * dims.y * dims.z) as usize;
        let mut grid =
            Self { min_m: lo, cell_m, dims, normals: vec![Vec3::ZERO; n], occupied: vec![false; n] };
        // A surfel covers the cells its splat disc passes through (within half a cell diagonal of
        // its plane and of its rim). How far out a disc may reach is bounded so the marking costs
        // at most about `MARK_BUDGET` cell tests: a few surfels may each span the grid (a
        // one-point scan framed to fill the image), millions stay within a few cells.
        let budget_reach = ((MARK_BUDGET / scene.surfels.len() as f64).cbrt() * 0.5).floor() as i32;
        let reach = ((splat_radius_m / cell_m).ceil() as i32).min(budget_reach.clamp(1, GRID_CELLS));
        let half_diagonal = 0.87 * cell_m;
        for s in &scene.surfels {
            let p = Vec3::from_slice(&s.position_radius[..3]);
            let Some(c) = grid.cell_of(p) else { continue };
            let n = Vec3::from_slice(&s.normal_spread[..3]).try_normalize().unwrap_or(Vec3::ZERO);
            for dz in -reach..=reach {
                for dy in -reach..=reach {
                    for dx in -reach..=reach {
                        let q = c + IVec3::new(dx, dy, dz);
                        let offset = grid.centre(q) - p;
                        let height = offset.dot(n);
                        if height.abs() > half_diagonal
                            || (offset - n * height).length() > splat_radius_m + half_diagonal
                        {
                            continue;
                        }
                        if let Some(k) = grid.index(q) {
                            grid.occupied[k] = true;
                            grid.normals[k] += n;
                        }
                    }
                }
            }
        }
        grid
    }

    fn index(&self, c: IVec3) -> Option<usize> {
        (c.cmpge(IVec3::ZERO).all() && c.cmplt(self.dims).all())
            .then(|| (c.x + self.dims.x * (c.y + self.dims.y * c.z)) as usize)
    }

    fn cell_of(&self, p: Vec3) -> Option<IVec3> {
        let c = ((p - self.min_m) / self.cell_m).floor();
        c.is_finite().then(|| c.as_ivec3()).filter(|c| self.index(*c).is_some())
    }

    fn centre(&self, c: IVec3) -> Vec3 {
        self.min_m + (c.as_vec3() + Vec3::splat(0.5)) * self.cell_m
    }

    /// The first surface along the ray (`dir` unit): distance in metres and whether the surfels
    /// there face the ray's origin.
    fn cast(&self, origin: Vec3, dir: Vec3) -> Option<(f32, bool)> {
        // Clip to the grid's box (slab test), then march half a cell at a time.
        let hi = self.min_m + self.dims.as_vec3() * self.cell_m;
        let inv = dir.recip();
        let t_a = (self.min_m - origin) * inv;
        let t_b = (hi - origin) * inv;
        let t0 = t_a.min(t_b).max_element().max(0.0);
        let t1 = t_a.max(t_b).min_element();
        if t0 > t1 || t0.is_nan() || t1.is_nan() {
            return None;
        }
        let step = 0.5 * self.cell_m;
        let mut t = t0 + 0.5 * step;
        while t <= t1 {
            if let Some(k) = self.cell_of(origin + dir * t).and_then(|c| self.index(c))
                && self.occupied[k]
            {
                return Some((t, self.normals[k].dot(dir) < 0.0));
            }
            t += step;
        }
        None
    }

    /// Eyes inside open spaces: sampled empty cells enclosed by surfaces facing them (at least
    /// `ENCLOSED_RAYS` of 14 rays along the axes and diagonals), ranked by that count, then by
    /// their distance to the nearest surface; at most `n`, at least a few cells apart.
    fn inside_eyes(&self, n: usize) -> Vec<Vec3> {
        let distance = self.distance_transform();
        let cells = (self.dims.x * self.dims.y * self.dims.z) as f32;
        let stride = (cells / 4096.0).cbrt().ceil().max(1.0) as i32;
        let dirs: Vec<Vec3> = [
            (1, 0, 0),
            (-1, 0, 0),
            (0, 1, 0),
            (0, -1, 0),
            (0, 0, 1),
            (0, 0, -1),
            (1, 1, 1),
            (1, 1, -1),
            (1, -1, 1),
            (1, -1, -1),
            (-1, 1, 1),
            (-1, 1, -1),
            (-1, -1, 1),
            (-1, -1, -1),
        ]
        .iter()
        .map(|&(x, y, z)| Vec3::new(x as f32, y as f32, z as f32).normalize())
        .collect();
        let mut ranked: Vec<(u32, u32, u16, IVec3)> = Vec::new();
        for z in (0..self.dims.z).step_by(stride as usize) {
            for y in (0..self.dims.y).step_by(stride as usize) {
                for x in (0..self.dims.x).step_by(stride as usize) {
                    let c = IVec3::new(x, y, z);
                    let Some(k) = self.index(c) else { continue };
                    if self.occupied[k] || distance[k] < 2 {
                        continue;
                    }
                    let (mut front, mut any) = (0, 0);
                    for d in &dirs {
                        if let Some((_, facing)) = self.cast(self.centre(c), *d) {
                            any += 1;
                            front += u32::from(facing);
                        }
                    }
                    // Enclosed by surfaces that face it: the inside of a cave, not the air above
                    // a terrain or around an object (those are framed from outside).
                    if front >= ENCLOSED_RAYS {
                        ranked.push((front, any, distance[k], c));
                    }
                }
            }
        }
        ranked.sort_by(|a, b| {
            (b.0, b.1, b.2).cmp(&(a.0, a.1, a.2)).then((a.3.z, a.3.y, a.3.x).cmp(&(b.3.z, b.3.y, b.3.x)))
        });
        let mut eyes: Vec<IVec3> = Vec::new();
        for (_, _, d, c) in ranked {
            let apart = i32::from(d).max(2 * stride);
            if eyes.iter().all(|e| (*e - c).abs().max_element() >= apart) {
                eyes.push(c);
                if eyes.len() == n {
                    break;
                }
            }
        }
        eyes.into_iter().map(|c| self.centre(c)).collect()
    }

    /// Chebyshev distance in cells from every cell to the nearest occupied one (breadth first,
    /// 26-neighbourhood), capped at u16::MAX.
    fn distance_transform(&self) -> Vec<u16> {
        let mut dist = vec![u16::MAX; self.occupied.len()];
        let mut frontier: Vec<IVec3> = Vec::new();
        for z in 0..self.dims.z {
            for y in 0..self.dims.y {
                for x in 0..self.dims.x {
                    let c = IVec3::new(x, y, z);
                    if let Some(k) = self.index(c).filter(|&k| self.occupied[k]) {
                        dist[k] = 0;
                        frontier.push(c);
                    }
                }
            }
        }
        let mut layer = 0u16;
        while !frontier.is_empty() && layer < u16::MAX - 1 {
            layer += 1;
            let mut next = Vec::new();
            for c in frontier {
                for dz in -1..=1 {
                    for dy in -1..=1 {
                        for dx in -1..=1 {
                            let q = c + IVec3::new(dx, dy, dz);
                            if let Some(k) = self.index(q).filter(|&k| dist[k] == u16::MAX) {
                                dist[k] = layer;
                                next.push(q);
                            }
                        }
                    }
                }
            }
            frontier = next;
        }
        dist
    }
}

/// Forward, right and up unit vectors of a camera.
fn basis(camera: &Camera) -> (Vec3, Vec3, Vec3) {
    let forward = (camera.look_at_m - camera.eye_m).normalize();
    let right = forward.cross(camera.up).normalize();
    (forward, right, right.cross(forward))
}

/// The best view of `scene` for an image of `aspect` (width / height), or None when it has no
/// surfels.
pub(crate) fn frame(scene: &SceneData, aspect: f32, splat_scale: f32) -> Option<Framing> {
    let sample = SurfelSample::from_scene(scene, splat_scale)?;
    let mut candidates: Vec<(Camera, &'static str)> = Vec::new();
    let centroid = sample.points.iter().copied().sum::<Vec3>() / sample.points.len().max(1) as f32;
    for eye in Occupancy::new(scene, &sample).inside_eyes(12) {
        let mut dirs: Vec<Vec3> = Vec::new();
        for k in 0..8 {
            let a = k as f32 * std::f32::consts::FRAC_PI_4;
            for elevation in [0.0f32, -25f32.to_radians()] {
                dirs.push(Vec3::new(a.cos() * elevation.cos(), a.sin() * elevation.cos(), elevation.sin()));
            }
        }
        if let Some(d) = (centroid - eye).try_normalize() {
            dirs.push(d);
        }
        for d in dirs {
            let up = if d.z.abs() > 0.95 { Vec3::Y } else { Vec3::Z };
            candidates
                .push((Camera { eye_m: eye, look_at_m: eye + d, up, fov_y_deg: FRAMED_FOV_Y_DEG }, "inside"));
        }
    }
    // Outside: looking down, from the sides at 30 and 60 degrees down, face-on along the principal
    // axes and against the mean normal (a few points: the disc or wall seen square). Never from
    // below: survey data has z up, and a terrain is not shown from underneath.
    let mut outside: Vec<Vec3> = vec![Vec3::NEG_Z];
    for k in 0..8 {
        let a = k as f32 * std::f32::consts::FRAC_PI_4;
        for elevation in [-30f32.to_radians(), -60f32.to_radians()] {
            outside.push(Vec3::new(a.cos() * elevation.cos(), a.sin() * elevation.cos(), elevation.sin()));
        }
    }
    for axis in sample.principal_axes() {
        outside.push(axis);
        outside.push(-axis);
    }
    if let Some(n) = sample.mean_normal.try_normalize() {
        outside.push(-n);
    }
    let first_outside = candidates.len();
    for d in outside {
        let Some(d) = d.try_normalize() else { continue };
        if d.z > 0.3 {
            continue;
        }
        let fit = sample.fit(d, aspect);
        for zoom in ZOOMS {
            let mut c = fit;
            c.eye_m = fit.look_at_m - (fit.look_at_m - fit.eye_m) * zoom;
            candidates.push((c, "outside"));
        }
    }
    let scored: Vec<(usize, Framing)> = candidates
        .into_iter()
        .enumerate()
        .filter(|(_, (c, _))| c.validate().is_ok())
        .map(|(i, (camera, kind))| (i, Framing { estimate: sample.estimate(&camera, aspect), camera, kind }))
        .collect();
    choose(scored, first_outside)
}

/// Outside views are tried at these fractions of the distance that fits all the data.
const ZOOMS: [f32; 6] = [1.0, 0.8, 0.65, 0.5, 0.35, 0.25];
/// "Most of the image": the share of pixels a chosen view should see a surface in.
pub(crate) const MOST: f32 = 0.6;

/// The choice among scored candidates (index, view; outside views from `first_outside` on, in
/// groups of `ZOOMS.len()` per direction): an inside view that sees a surface almost everywhere
/// and furthest (a cave); else the outside view that shows most of the data (least zoom) while
/// covering `MOST` of the image and facing the eye ([`ViewEstimate::lit`]), the better lit first;
/// else the best sum of coverage and lit.
fn choose(scored: Vec<(usize, Framing)>, first_outside: usize) -> Option<Framing> {
    let coverage = |f: &Framing| f.estimate.coverage;
    let best_inside =
        scored.iter().filter(|(i, _)| *i < first_outside).map(|(_, f)| coverage(f)).fold(0.0, f32::max);
    if best_inside >= MOST {
        return scored
            .into_iter()
            .filter(|(i, f)| *i < first_outside && coverage(f) >= best_inside - 0.02)
            .map(|(_, f)| f)
            .reduce(|a, b| if b.estimate.median_distance_m > a.estimate.median_distance_m { b } else { a });
    }
    let zoom_rank = |i: usize| (i - first_outside) % ZOOMS.len();
    let lit = |f: &Framing| f.estimate.lit;
    // Enough: covered, and not mostly at grazing angles (a headlamp would leave it dark).
    let enough: Vec<&(usize, Framing)> = scored
        .iter()
        .filter(|(i, f)| *i >= first_outside && coverage(f) >= MOST && lit(f) >= 0.5 * coverage(f))
        .collect();
    if let Some(least_zoom) = enough.iter().map(|(i, _)| zoom_rank(*i)).min() {
        return enough
            .into_iter()
            .filter(|(i, _)| zoom_rank(*i) == least_zoom)
            .map(|(_, f)| f.clone())
            .reduce(|a, b| if lit(&b) > lit(&a) { b } else { a });
    }
    // Nothing covers enough and faces the eye: the best sum of the two.
    let both = |f: &Framing| coverage(f) + lit(f);
    scored.into_iter().map(|(_, f)| f).reduce(|a, b| if both(&b) > both(&a) { b } else { a })
}

/// What a view of `scene` sees (for a camera the user chose), or None without surfels.
pub(crate) fn estimate(
    scene: &SceneData,
    camera: &Camera,
    aspect: f32,
    splat_scale: f32,
) -> Option<ViewEstimate> {
    SurfelSample::from_scene(scene, splat_scale).map(|s| s.estimate(camera, aspect))
}

/// A headlamp for `camera`: a spot at the eye along the view whose cone covers the image, bright
/// enough to give [`HEADLAMP_IRRADIANCE_W_M2`] at `distance_m` (the median distance the view sees).
pub(crate) fn headlamp(camera: &Camera, aspect: f32, distance_m: f32) -> SceneLight {
    let (forward, _, _) = basis(camera);
    let tan_y = (camera.fov_y_deg.to_radians() * 0.5).tan();
    let half_diagonal = (tan_y * (1.0 + aspect * aspect).sqrt()).atan();
    let outer = (half_diagonal * 1.15).min(1.4);
    let d = distance_m.max(1e-3);
    SceneLight {
        name: "headlamp".into(),
        position_m: camera.eye_m,
        intensity_w_sr: Vec3::from_array(HEADLAMP_COLOR) * (HEADLAMP_IRRADIANCE_W_M2 * d * d),
        spot: Some(Spot { direction: forward, inner_angle_rad: 0.8 * outer, outer_angle_rad: outer }),
        profile: None,
    }
}

/// Where the camera comes from.
#[derive(Clone, Debug, PartialEq)]
pub enum CameraChoice {
    /// A camera named in the package's scene.
    Named(String),
    /// World coordinates (f64, like the manifest).
    Explicit { eye_m: [f64; 3], look_at_m: [f64; 3], up: [f64; 3], fov_y_deg: f64 },
    /// The package's first camera, or, if it has none, the best view measured on the data
    /// (framing.rs).
    Default,
}

/// The camera a choice names in `scene`, for an image of `aspect` (width / height), and the
/// framing when it was framed on the data rather than given.
pub fn resolve_camera(
    scene: &SceneData,
    choice: &CameraChoice,
    aspect: f32,
    splat_scale: f32,
) -> Result<(Camera, Option<Framing>)> {
    match choice {
        CameraChoice::Named(name) => scene
            .cameras
            .iter()
            .find(|c| &c.name == name)
            .map(|c| (Camera::from_scene(c), None))
            // A point of interest's camera, as the viewers fly to it.
            .or_else(|| {
                let p = scene.pois.iter().find(|p| &p.name == name)?;
                Some((crate::view::story::stop_camera(&p.camera), None))
            })
            .ok_or_else(|| {
                let names: Vec<&str> = scene
                    .cameras
                    .iter()
                    .map(|c| c.name.as_str())
                    .chain(scene.pois.iter().map(|p| p.name.as_str()))
                    .collect();
                Error::Camera(format!(
                    "no camera or point of interest named {name:?} in {} (it has: {})",
                    scene.name,
                    if names.is_empty() { "none".into() } else { names.join(", ") }
                ))
            }),
        CameraChoice::Explicit { eye_m, look_at_m, up, fov_y_deg } => {
            let frame = DVec3::from_array(scene.frame_origin_m);
            Ok((
                Camera {
                    eye_m: (DVec3::from_array(*eye_m) - frame).as_vec3(),
                    look_at_m: (DVec3::from_array(*look_at_m) - frame).as_vec3(),
                    up: DVec3::from_array(*up).as_vec3(),
                    fov_y_deg: *fov_y_deg as f32,
                },
                None,
            ))
        }
        CameraChoice::Default => {
            if let Some(c) = scene.cameras.first() {
                return Ok((Camera::from_scene(c), None));
            }
            let f = frame(scene, aspect, splat_scale).ok_or_else(|| Error::Scene {
                package: scene.name.clone(),
                problem: "no surfels to frame a view on".into(),
            })?;
            Ok((f.camera, Some(f)))
        }
    }
}

/// A headlamp at `camera` sized for what it sees: 1 W/m^2 at the median distance of the surfaces
/// in view (`seen`: that estimate where the caller has it; else estimated here), or, with nothing
/// in view, at half the scene's diagonal. What `grotto render --headlamp` and the browser put in a
/// scene without light of its own.
pub fn scene_headlamp(
    scene: &SceneData,
    camera: &Camera,
    aspect: f32,
    splat_scale: f32,
    seen: Option<ViewEstimate>,
) -> SizedLamp {
    let seen = seen.or_else(|| estimate(scene, camera, aspect, splat_scale));
    let sized_for_m = seen.map(|e| e.median_distance_m).filter(|&d| d > 0.0).unwrap_or_else(|| {
        let (lo, hi) = scene.bounds_leaf();
        ((hi - lo) * scene.leaf_size_m).length() * 0.5
    });
    SizedLamp { light: headlamp(camera, aspect, sized_for_m), sized_for_m }
}

/// A headlamp and the distance it was sized for ([`scene_headlamp`]).
#[derive(Clone, Debug)]
pub struct SizedLamp {
    pub light: SceneLight,
    pub sized_for_m: f32,
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::gpu::types::SurfelGpu;

    fn scene_of(points: &[(Vec3, Vec3)], radius: f32) -> SceneData {
        SceneData {
            surfels: points
                .iter()
                .map(|(p, n)| SurfelGpu {
                    position_radius: p.extend(radius).to_array(),
                    normal_spread: n.extend(0.0).to_array(),
                    color: [200, 200, 200, 0],
                    scan: 0,
                })
                .collect(),
            ..Default::default()
        }
    }

    #[test]
    fn a_closed_room_is_seen_from_inside() {
        // A 10 x 6 x 4 m box sampled every 10 cm, normals facing in, far from the frame origin.
        let mut pts = Vec::new();
        let o = Vec3::new(300.0, -200.0, 50.0);
        let size = Vec3::new(10.0, 6.0, 4.0);
        for a in 0..3 {
            let (b, c) = ((a + 1) % 3, (a + 2) % 3);
            let nb = (size[b] / 0.1) as i32;
            let nc = (size[c] / 0.1) as i32;
            for i in 0..=nb {
                for j in 0..=nc {
                    for side in [0.0, 1.0] {
                        let mut p = Vec3::ZERO;
                        p[a] = side * size[a];
                        p[b] = i as f32 * 0.1;
                        p[c] = j as f32 * 0.1;
                        let mut n = Vec3::ZERO;
                        n[a] = if side == 0.0 { 1.0 } else { -1.0 };
                        pts.push((o + p, n));
                    }
                }
            }
        }
        let f = frame(&scene_of(&pts, 0.07), 4.0 / 3.0, 2.0).expect("surfels");
        assert_eq!(f.kind, "inside");
        assert!(f.estimate.coverage > 0.95, "{:?}", f.estimate);
        let inside = f.camera.eye_m.cmpgt(o).all() && f.camera.eye_m.cmplt(o + size).all();
        assert!(inside, "eye {} outside the room", f.camera.eye_m);
    }

    #[test]
    fn one_disc_fills_most_of_the_image() {
        let f = frame(
            &scene_of(&[(Vec3::new(5.0, 5.0, 5.0), Vec3::new(0.3, 0.2, 0.9).normalize())], 0.02),
            4.0 / 3.0,
            2.0,
        )
        .expect("a surfel");
        assert!(f.estimate.coverage > 0.5, "{f:?}");
    }

    #[test]
    fn a_flat_terrain_is_seen_from_above() {
        let mut pts = Vec::new();
        for i in 0..200 {
            for j in 0..100 {
                let p = Vec3::new(i as f32 * 5.0, j as f32 * 5.0, ((i * 7 + j * 3) % 11) as f32 * 0.1);
                pts.push((p, Vec3::NEG_Z)); // normals oriented away from the sky, as a bad guess can
            }
        }
        let f = frame(&scene_of(&pts, 3.0), 4.0 / 3.0, 2.0).expect("surfels");
        assert!(f.estimate.coverage >= MOST, "{f:?}");
        assert!(f.camera.eye_m.z > 1.0, "eye below the terrain: {f:?}");
    }

    #[test]
    fn headlamp_covers_the_image_and_scales_with_distance() {
        let cam = Camera { eye_m: Vec3::ZERO, look_at_m: Vec3::X, up: Vec3::Z, fov_y_deg: 60.0 };
        let near = headlamp(&cam, 4.0 / 3.0, 2.0);
        let far = headlamp(&cam, 4.0 / 3.0, 20.0);
        let spot = near.spot.expect("a spot");
        assert!(spot.direction.distance(Vec3::X) < 1e-6);
        // The image corner is 36.6 degrees off axis at 60 degrees vertical, 4:3.
        assert!(spot.inner_angle_rad > 36.6f32.to_radians() * 0.9 && spot.outer_angle_rad < 1.4);
        let ratio = far.intensity_w_sr.x / near.intensity_w_sr.x;
        assert!((ratio - 100.0).abs() < 1e-2, "{ratio}");
        // I / d^2 = the target irradiance on axis.
        assert!((near.intensity_w_sr.x / 4.0 - HEADLAMP_IRRADIANCE_W_M2 * HEADLAMP_COLOR[0]).abs() < 1e-6);
    }
}
