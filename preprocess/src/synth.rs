//! A deterministic procedural cave with a known surface, scanned like a terrestrial laser scanner.
//!
//! The cave is an implicit function `f(x)`: negative in open space, positive in rock, zero on the
//! wall. It is the smooth union (polynomial smooth-min, 0.6 m) of winding passages (capsules with
//! varying radius along a seeded random walk, one side branch) and chambers (ellipsoids), each cut
//! by a flat sediment floor; rock columns stand in the chambers; two octaves of value noise roughen
//! the walls (5 cm at 1.3 m, 1.5 cm at 0.35 m). Because `f` is closed-form, [`SynthCave::normal`]
//! gives the exact wall normal anywhere, which later stages use as ground truth.
//!
//! Scanning: stations along the passages; each casts rays on an even azimuth/elevation grid (-60
//! to +90 degrees elevation, like a tripod scanner) and sphere-traces `f` to the first wall hit,
//! so occlusion and the density falloff with range are those of a real scan. Range noise is
//! Gaussian, 2 mm + 50 ppm of the range. Colours are limestone bands, darker wet floors and
//! mineral streaks. A spatial grid of primitive lists keeps an evaluation of `f` at a few
//! primitives, so 10^8 points take minutes, not hours.

use std::collections::HashMap;

use crate::pose::Pose;

/// What to generate.
#[derive(Clone, Debug, serde::Serialize, serde::Deserialize)]
pub struct SynthParams {
    pub seed: u64,
    /// Approximate number of points over all scans.
    pub points: u64,
    /// Main passage segments (4 m each); chambers every few segments.
    pub segments: usize,
    /// World position of the cave's local origin (survey coordinates).
    pub offset_m: [f64; 3],
    /// Maximum scanner range, metres.
    pub max_range_m: f64,
    /// Multiplies the range noise (2 mm + 50 ppm of the range at 1; 0 = exact surface points).
    #[serde(default = "one")]
    pub noise_scale: f64,
}

fn one() -> f64 {
    1.0
}

impl Default for SynthParams {
    fn default() -> Self {
        Self {
            seed: 7,
            points: 1_000_000,
            segments: 24,
            offset_m: [512_000.0, 5_123_000.0, 300.0],
            max_range_m: 60.0,
            noise_scale: 1.0,
        }
    }
}

#[derive(Clone, Copy, Debug)]
enum Shape {
    /// Segment a-b with radius ra at a, rb at b; rock below `floor_z`.
    Capsule { a: [f64; 3], b: [f64; 3], ra: f64, rb: f64, floor_z: f64 },
    /// Ellipsoid chamber; rock below `floor_z`.
    Chamber { c: [f64; 3], r: [f64; 3], floor_z: f64 },
}

/// A rock column: vertical cylinder, solid inside.
#[derive(Clone, Copy, Debug)]
struct Column {
    xy: [f64; 2],
    radius: f64,
}

/// The cave in its local frame (metres, z up).
#[derive(Debug)]
pub struct SynthCave {
    shapes: Vec<Shape>,
    columns: Vec<Column>,
    /// Grid cell -> shapes and columns that can matter there.
    grid: HashMap<[i32; 3], (Vec<u16>, Vec<u16>)>,
    seed: u64,
    /// Scanner stations (local frame, in open space).
    pub stations: Vec<[f64; 3]>,
    /// Chamber centres (for lights and cameras).
    pub chambers: Vec<[f64; 3]>,
    /// Points along the main passage (for lamp strings and cameras).
    pub path: Vec<[f64; 3]>,
    /// Points along the side passage, from the chamber it leaves.
    pub branch: Vec<[f64; 3]>,
}

const CELL_M: f64 = 4.0;
/// Side of the cubes [`SynthCave::occupied_cells`] lists, metres.
pub const GRID_CELL_M: f64 = CELL_M;
const BLEND_M: f64 = 0.6;
const NOISE: [(f64, f64); 2] = [(0.05, 1.0 / 1.3), (0.015, 1.0 / 0.35)];

fn splitmix(mut x: u64) -> u64 {
    x = x.wrapping_add(0x9e37_79b9_7f4a_7c15);
    x = (x ^ (x >> 30)).wrapping_mul(0xbf58_476d_1ce4_e5b9);
    x = (x ^ (x >> 27)).wrapping_mul(0x94d0_49bb_1331_11eb);
    x ^ (x >> 31)
}

/// Uniform in [0, 1) from a hash.
fn unit(h: u64) -> f64 {
    (h >> 11) as f64 / (1u64 << 53) as f64
}

/// Deterministic stream of uniforms.
struct Rng(u64);

impl Rng {
    fn next(&mut self) -> f64 {
        self.0 = splitmix(self.0);
        unit(self.0)
    }

    fn range(&mut self, lo: f64, hi: f64) -> f64 {
        lo + (hi - lo) * self.next()
    }

    /// Standard normal (Box-Muller).
    fn gauss(&mut self) -> f64 {
        let u = self.next().max(1e-300);
        let v = self.next();
        (-2.0 * u.ln()).sqrt() * (std::f64::consts::TAU * v).cos()
    }
}

fn sub(a: [f64; 3], b: [f64; 3]) -> [f64; 3] {
    [a[0] - b[0], a[1] - b[1], a[2] - b[2]]
}

fn dot(a: [f64; 3], b: [f64; 3]) -> f64 {
    a[0] * b[0] + a[1] * b[1] + a[2] * b[2]
}

fn len(a: [f64; 3]) -> f64 {
    dot(a, a).sqrt()
}

/// C1 value noise in about [-1, 1].
fn value_noise(seed: u64, p: [f64; 3]) -> f64 {
    let i = p.map(|v| v.floor());
    let f: [f64; 3] = std::array::from_fn(|a| p[a] - i[a]);
    let s = f.map(|t| t * t * (3.0 - 2.0 * t));
    let corner = |dx: i64, dy: i64, dz: i64| {
        let h = splitmix(
            seed ^ ((i[0] as i64 + dx) as u64).wrapping_mul(0x9e37_79b1)
                ^ ((i[1] as i64 + dy) as u64).wrapping_mul(0x85eb_ca77_c2b2_ae63)
                ^ ((i[2] as i64 + dz) as u64).wrapping_mul(0xc2b2_ae3d_27d4_eb4f),
        );
        unit(h) * 2.0 - 1.0
    };
    let lerp = |a: f64, b: f64, t: f64| a + (b - a) * t;
    let x00 = lerp(corner(0, 0, 0), corner(1, 0, 0), s[0]);
    let x10 = lerp(corner(0, 1, 0), corner(1, 1, 0), s[0]);
    let x01 = lerp(corner(0, 0, 1), corner(1, 0, 1), s[0]);
    let x11 = lerp(corner(0, 1, 1), corner(1, 1, 1), s[0]);
    lerp(lerp(x00, x10, s[1]), lerp(x01, x11, s[1]), s[2])
}

fn smin(a: f64, b: f64, k: f64) -> f64 {
    let h = (k - (a - b).abs()).max(0.0);
    a.min(b) - h * h / (4.0 * k)
}

impl Shape {
    fn eval(&self, p: [f64; 3]) -> f64 {
        match *self {
            Shape::Capsule { a, b, ra, rb, floor_z } => {
                let ab = sub(b, a);
                let t = (dot(sub(p, a), ab) / dot(ab, ab)).clamp(0.0, 1.0);
                let c = [a[0] + ab[0] * t, a[1] + ab[1] * t, a[2] + ab[2] * t];
                (len(sub(p, c)) - (ra + (rb - ra) * t)).max(floor_z - p[2])
            }
            Shape::Chamber { c, r, floor_z } => {
                let q = sub(p, c);
                let k0 = len([q[0] / r[0], q[1] / r[1], q[2] / r[2]]);
                let k1 = len([q[0] / (r[0] * r[0]), q[1] / (r[1] * r[1]), q[2] / (r[2] * r[2])]);
                let d = if k1 > 0.0 { k0 * (k0 - 1.0) / k1 } else { -r[0].min(r[1]).min(r[2]) };
                d.max(floor_z - p[2])
            }
        }
    }

    fn bounds(&self) -> ([f64; 3], [f64; 3]) {
        match *self {
            Shape::Capsule { a, b, ra, rb, .. } => {
                let r = ra.max(rb);
                (std::array::from_fn(|i| a[i].min(b[i]) - r), std::array::from_fn(|i| a[i].max(b[i]) + r))
            }
            Shape::Chamber { c, r, .. } => {
                (std::array::from_fn(|i| c[i] - r[i]), std::array::from_fn(|i| c[i] + r[i]))
            }
        }
    }
}

impl SynthCave {
    /// Lays out the cave from the seed.
    pub fn new(params: &SynthParams) -> Self {
        let mut rng = Rng(params.seed);
        let mut shapes = Vec::new();
        let mut columns = Vec::new();
        let mut chambers = Vec::new();
        let mut path = Vec::new();
        let mut branch_path = Vec::new();
        let mut stations = Vec::new();
        let mut walk = |start: [f64; 3], heading: f64, segments: usize, rng: &mut Rng, main: bool| {
            let (mut p, mut h, mut r) = (start, heading, 2.0);
            let mut branch_from = None;
            for s in 0..segments {
                h += rng.range(-0.45, 0.45);
                let climb = rng.range(-0.6, 0.6);
                let q = [p[0] + 4.0 * h.cos(), p[1] + 4.0 * h.sin(), p[2] + climb];
                let r_next = (r + rng.range(-0.35, 0.35)).clamp(1.3, 3.0);
                let floor_z = p[2].min(q[2]) - 0.55 * r.min(r_next);
                shapes.push(Shape::Capsule { a: p, b: q, ra: r, rb: r_next, floor_z });
                if main {
                    path.push(p)
                } else {
                    branch_path.push(p)
                }
                if s % 2 == 0 {
                    stations.push([p[0], p[1], floor_z + 1.5_f64.min(0.9 * r)]);
                }
                if s % 6 == 3 {
                    let c = [q[0] + 2.0 * h.cos(), q[1] + 2.0 * h.sin(), q[2] + 0.5];
                    let rad = [rng.range(5.0, 8.0), rng.range(4.0, 6.0), rng.range(3.0, 4.0)];
                    let floor_z = c[2] - 0.6 * rad[2];
                    shapes.push(Shape::Chamber { c, r: rad, floor_z });
                    chambers.push(c);
                    stations.push([c[0], c[1], floor_z + 1.6]);
                    for _ in 0..1 + (rng.next() * 2.0) as usize {
                        let ang = rng.range(0.0, std::f64::consts::TAU);
                        let dist = rng.range(0.45, 0.7);
                        columns.push(Column {
                            xy: [c[0] + dist * rad[0] * ang.cos(), c[1] + dist * rad[1] * ang.sin()],
                            radius: rng.range(0.35, 0.8),
                        });
                    }
                    if branch_from.is_none() {
                        branch_from = Some((c, h + std::f64::consts::FRAC_PI_2));
                    }
                }
                p = q;
                r = r_next;
            }
            if main {
                path.push(p)
            } else {
                branch_path.push(p)
            }
            branch_from
        };
        let branch = walk([0.0; 3], 0.0, params.segments.max(1), &mut rng, true);
        if let Some((c, h)) = branch {
            walk(c, h, (params.segments / 3).max(2), &mut rng, false);
        }
        let mut cave = SynthCave {
            shapes,
            columns,
            grid: HashMap::new(),
            seed: params.seed,
            stations,
            chambers,
            path,
            branch: branch_path,
        };
        cave.build_grid();
        // Keep stations that are well inside open space and clear of columns.
        let keep: Vec<[f64; 3]> = cave.stations.iter().copied().filter(|s| cave.eval(*s) < -0.4).collect();
        cave.stations = keep;
        cave
    }

    fn build_grid(&mut self) {
        let margin = BLEND_M + 1.0;
        let cell = |v: f64| (v / CELL_M).floor() as i32;
        for (i, s) in self.shapes.iter().enumerate() {
            let (lo, hi) = s.bounds();
            for x in cell(lo[0] - margin)..=cell(hi[0] + margin) {
                for y in cell(lo[1] - margin)..=cell(hi[1] + margin) {
                    for z in cell(lo[2] - margin)..=cell(hi[2] + margin) {
                        self.grid.entry([x, y, z]).or_default().0.push(i as u16);
                    }
                }
            }
        }
        let keys: Vec<[i32; 3]> = self.grid.keys().copied().collect();
        for (i, c) in self.columns.iter().enumerate() {
            for k in &keys {
                let (x0, y0) = (f64::from(k[0]) * CELL_M, f64::from(k[1]) * CELL_M);
                let dx = (c.xy[0] - (x0 + CELL_M / 2.0)).abs() - CELL_M / 2.0;
                let dy = (c.xy[1] - (y0 + CELL_M / 2.0)).abs() - CELL_M / 2.0;
                if dx.max(0.0).hypot(dy.max(0.0)) < c.radius + margin {
                    self.grid.get_mut(k).expect("key from grid").1.push(i as u16);
                }
            }
        }
    }

    /// The implicit function: < 0 in open space, > 0 in rock (roughly metres near the wall).
    pub fn eval(&self, p: [f64; 3]) -> f64 {
        let key = p.map(|v| (v / CELL_M).floor() as i32);
        let Some((shapes, columns)) = self.grid.get(&key) else { return CELL_M };
        let mut f = f64::INFINITY;
        for &i in shapes {
            let d = self.shapes[i as usize].eval(p);
            f = if f.is_infinite() { d } else { smin(f, d, BLEND_M) };
        }
        for &i in columns {
            let c = &self.columns[i as usize];
            let d = (p[0] - c.xy[0]).hypot(p[1] - c.xy[1]) - c.radius;
            f = f.max(-d);
        }
        if f.is_infinite() {
            return CELL_M;
        }
        let mut n = 0.0;
        for (k, (amp, freq)) in NOISE.iter().enumerate() {
            n += amp * value_noise(self.seed.wrapping_add(k as u64), p.map(|v| v * freq));
        }
        f + n
    }

    /// The first wall point along the ray from `from` (in open space) toward `toward`, within
    /// `max_m` (sphere tracing `f`, as the scanner does): where a label can sit on the rock.
    pub fn first_wall(&self, from: [f64; 3], toward: [f64; 3], max_m: f64) -> Option<[f64; 3]> {
        let d: [f64; 3] = std::array::from_fn(|a| toward[a] - from[a]);
        let len = (d[0] * d[0] + d[1] * d[1] + d[2] * d[2]).sqrt();
        if len < 1e-9 {
            return None;
        }
        let mut t = 0.0;
        for _ in 0..512 {
            let p: [f64; 3] = std::array::from_fn(|a| from[a] + d[a] / len * t);
            let f = self.eval(p);
            if f > -1e-3 {
                // A start in or at the rock is no view of it (a label on the eye is refused).
                return (t > 0.1).then_some(p);
            }
            t += (-f).max(2e-3) * 0.8;
            if t > max_m {
                return None;
            }
        }
        None
    }

    /// Unit wall normal at (or near) `p`, pointing into the open cave (-grad f).
    pub fn normal(&self, p: [f64; 3]) -> [f64; 3] {
        let e = 1e-4;
        let g: [f64; 3] = std::array::from_fn(|a| {
            let mut hi = p;
            let mut lo = p;
            hi[a] += e;
            lo[a] -= e;
            self.eval(hi) - self.eval(lo)
        });
        let l = len(g).max(1e-30);
        g.map(|v| -v / l)
    }

    /// First wall hit from `o` along unit `d` within `max_t`, refined to ~1e-6 m.
    pub(crate) fn trace(&self, o: [f64; 3], d: [f64; 3], max_t: f64) -> Option<f64> {
        // Noise gradients make f a little steeper than a distance; 0.7 keeps steps safe.
        let mut t = 0.0;
        let mut prev_t = 0.0;
        for _ in 0..512 {
            let p = [o[0] + d[0] * t, o[1] + d[1] * t, o[2] + d[2] * t];
            let f = self.eval(p);
            if f >= 0.0 {
                // Bisect between the last open-space sample and this one.
                let (mut a, mut b) = (prev_t, t);
                for _ in 0..30 {
                    let m = 0.5 * (a + b);
                    if self.eval([o[0] + d[0] * m, o[1] + d[1] * m, o[2] + d[2] * m]) >= 0.0 {
                        b = m;
                    } else {
                        a = m;
                    }
                }
                return Some(0.5 * (a + b));
            }
            prev_t = t;
            t += (-f * 0.7).max(2e-3);
            if t > max_t {
                return None;
            }
        }
        None
    }

    /// Lower corners (local frame) of the cubes of side [`GRID_CELL_M`] where a wall may lie:
    /// outside their union `eval` is rock. For meshing the true surface (grotto-reference truth).
    pub fn occupied_cells(&self) -> Vec<[f64; 3]> {
        let mut keys: Vec<[i32; 3]> = self.grid.keys().copied().collect();
        keys.sort_unstable();
        keys.into_iter().map(|k| k.map(|v| f64::from(v) * CELL_M)).collect()
    }

    /// sRGB colour of the wall at `p` with normal `n`.
    pub fn color(&self, p: [f64; 3], n: [f64; 3]) -> [u8; 3] {
        let band = 0.5 + 0.5 * (p[2] * 2.3 + 0.8 * value_noise(self.seed ^ 0xba5e, p.map(|v| v * 0.4))).sin();
        let streak = value_noise(self.seed ^ 0x5eed, [p[0] * 0.3, p[1] * 0.3, p[2] * 3.0]).max(0.0);
        let floor = n[2].max(0.0).powi(2);
        let base = [0.78, 0.72, 0.62].map(|c| c * (0.75 + 0.25 * band));
        let rgb: [f64; 3] = std::array::from_fn(|i| {
            let wet = base[i] * (1.0 - 0.45 * floor);
            let ochre = [0.55, 0.35, 0.18][i];
            wet * (1.0 - 0.6 * streak) + ochre * 0.6 * streak
        });
        rgb.map(|c| (c.clamp(0.0, 1.0) * 255.0).round() as u8)
    }
}

/// One simulated scan: points in the scan's own frame, and its pose.
#[derive(Debug)]
pub struct SynthScan {
    /// Scan frame -> world (survey coordinates).
    pub world_from_scan: Pose,
    /// Station in world coordinates.
    pub station_world_m: [f64; 3],
    pub xyz: Vec<[f64; 3]>,
    pub rgb: Vec<[u8; 3]>,
    /// Return intensity, 0..=65535 (falls with range and incidence).
    pub(crate) intensity: Vec<u16>,
}

/// Scans the cave from station `s`, casting about `rays` rays. Rays are processed in parallel;
/// the result is deterministic.
pub fn scan(cave: &SynthCave, params: &SynthParams, s: usize, rays: u64) -> SynthScan {
    use rayon::prelude::*;
    let station = cave.stations[s];
    let el_lo = -60f64.to_radians();
    let el_hi = 90f64.to_radians();
    // Rings thin out by cos(elevation), so the even angular step comes from the solid angle.
    let solid_angle = std::f64::consts::TAU * (el_hi.sin() - el_lo.sin());
    let step = (solid_angle / rays.max(1) as f64).sqrt();
    let n_az = (std::f64::consts::TAU / step).ceil().max(1.0) as usize;
    let n_el = ((el_hi - el_lo) / step).ceil().max(1.0) as usize;
    // A scanner levels itself but has an arbitrary heading: the scan frame is yawed.
    let mut rng = Rng(splitmix(params.seed ^ (s as u64).wrapping_mul(0x51ed)));
    let yaw = rng.range(0.0, std::f64::consts::TAU);
    let half = yaw / 2.0;
    let world_from_scan = Pose::from_quaternion(
        [half.cos(), 0.0, 0.0, half.sin()],
        std::array::from_fn(|a| params.offset_m[a] + station[a]),
    )
    .expect("unit quaternion");
    let scan_from_local =
        |v: [f64; 3]| [v[0] * yaw.cos() + v[1] * yaw.sin(), -v[0] * yaw.sin() + v[1] * yaw.cos(), v[2]];
    let hits: Vec<([f64; 3], [u8; 3], u16)> = (0..n_el)
        .into_par_iter()
        .flat_map_iter(|ei| {
            let el = el_lo + (ei as f64 + 0.5) * step;
            // Fewer azimuth steps near the zenith keep the angular spacing even.
            let n = ((n_az as f64) * el.cos()).ceil().max(1.0) as usize;
            let mut rng = Rng(splitmix(params.seed ^ ((s as u64) << 32 | ei as u64)));
            (0..n)
                .filter_map(|ai| {
                    let az = (ai as f64 + 0.5) * std::f64::consts::TAU / n as f64;
                    let d = [el.cos() * az.cos(), el.cos() * az.sin(), el.sin()];
                    let t = cave.trace(station, d, params.max_range_m)?;
                    let noisy = t + rng.gauss() * (0.002 + 50e-6 * t) * params.noise_scale;
                    let hit = [station[0] + d[0] * t, station[1] + d[1] * t, station[2] + d[2] * t];
                    let n = cave.normal(hit);
                    let cos_i = (-dot(n, d)).clamp(0.05, 1.0);
                    let intensity = (65535.0 * cos_i * (1.0 / (1.0 + t / 30.0))).round() as u16;
                    let local = [d[0] * noisy, d[1] * noisy, d[2] * noisy];
                    Some((scan_from_local(local), cave.color(hit, n), intensity))
                })
                .collect::<Vec<_>>()
        })
        .collect();
    SynthScan {
        world_from_scan,
        station_world_m: world_from_scan.translation,
        xyz: hits.iter().map(|h| h.0).collect(),
        rgb: hits.iter().map(|h| h.1).collect(),
        intensity: hits.iter().map(|h| h.2).collect(),
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn stations_are_in_open_space_and_rays_hit_walls_on_the_surface() {
        let params = SynthParams { segments: 8, ..SynthParams::default() };
        let cave = SynthCave::new(&params);
        assert!(cave.stations.len() >= 3);
        let scan = scan(&cave, &params, 0, 20_000);
        assert!(scan.xyz.len() > 15_000, "a closed cave returns most rays: {}", scan.xyz.len());
        // Noise-free hits lie on f = 0; with range noise, within a few sigma of it.
        let pose = scan.world_from_scan;
        let mut worst = 0f64;
        for p in scan.xyz.iter().take(2000) {
            let w = pose.apply(*p);
            let local: [f64; 3] = std::array::from_fn(|a| w[a] - params.offset_m[a]);
            worst = worst.max(cave.eval(local).abs());
        }
        assert!(worst < 0.03, "worst |f| at hits {worst}");
        // Normals face the station (into the open cave) for most points.
        let facing = scan
            .xyz
            .iter()
            .take(2000)
            .filter(|p| {
                let w = pose.apply(**p);
                let local: [f64; 3] = std::array::from_fn(|a| w[a] - params.offset_m[a]);
                dot(cave.normal(local), sub(cave.stations[0], local)) > 0.0
            })
            .count();
        assert!(facing > 1950, "{facing}");
    }

    #[test]
    fn a_label_lands_on_the_wall_ahead_and_never_on_the_eye() {
        let cave = SynthCave::new(&SynthParams { segments: 8, ..SynthParams::default() });
        let eye = cave.stations[0];
        let ahead = cave.path[3];
        let at = cave.first_wall(eye, ahead, 60.0).unwrap();
        assert!(cave.eval(at).abs() < 0.01, "{} m off the wall", cave.eval(at));
        let d = (0..3).map(|a| (at[a] - eye[a]).powi(2)).sum::<f64>().sqrt();
        assert!(d > 0.1, "the wall point is the eye");
        // From inside the rock (found a little past the wall along the same ray): nothing, a
        // label there would sit on the eye.
        let inside = (1..200)
            .map(|k| std::array::from_fn(|a| at[a] + (at[a] - eye[a]) / d * 0.01 * k as f64))
            .find(|p: &[f64; 3]| cave.eval(*p) > 0.02)
            .expect("rock behind the wall within 2 m");
        assert!(cave.first_wall(inside, ahead, 60.0).is_none());
    }

    #[test]
    fn same_seed_same_cave() {
        let p = SynthParams { segments: 6, ..SynthParams::default() };
        let (a, b) = (SynthCave::new(&p), SynthCave::new(&p));
        assert_eq!(a.stations, b.stations);
        let (sa, sb) = (scan(&a, &p, 1, 5000), scan(&b, &p, 1, 5000));
        assert_eq!(sa.xyz, sb.xyz);
    }
}

/// The cave's centreline as a surveyor would enter it in Survex (`.svx`): stations on the
/// passages' axes (the main passage from its entrance, the side passage from the main station
/// nearest its start), each leg's tape, compass and clino read with the noise of a careful
/// survey (tape 1 cm, compass and clino 0.5 degrees, one standard deviation, seeded), the
/// entrance fixed at its world position. `cavern` compiles it into the `.3d` file `grotto map`
/// reads; the noise makes the computed stations wander from the scanned passage as a real
/// traverse does.
pub fn survey_svx(cave: &SynthCave, params: &SynthParams) -> String {
    use std::fmt::Write as _;
    let mut rng = Rng(params.seed ^ 0x5eed_5eed);
    let mut reading = |from: &str, to: &str, a: [f64; 3], b: [f64; 3], out: &mut String| {
        let d = sub(b, a);
        let horizontal = (d[0] * d[0] + d[1] * d[1]).sqrt();
        let tape = len(d) + 0.01 * rng.gauss();
        let compass = (d[0].atan2(d[1]).to_degrees() + 0.5 * rng.gauss()).rem_euclid(360.0);
        let clino = d[2].atan2(horizontal).to_degrees() + 0.5 * rng.gauss();
        let _ = writeln!(out, "{from} {to} {tape:.2} {compass:.1} {clino:.1}");
    };
    let o = params.offset_m;
    let mut s = String::from(
        "; The synthetic cave's centreline, written by `grotto-pack synth` with the reading noise of a\n\
         ; careful survey (tape 1 cm, compass and clino 0.5 degrees). Compile with cavern.\n",
    );
    let _ = writeln!(s, "*begin synth\n*title \"Synthetic cave\"");
    if let Some(e) = cave.path.first() {
        let _ = writeln!(s, "*fix m0 {:.3} {:.3} {:.3}", e[0] + o[0], e[1] + o[1], e[2] + o[2]);
        let _ = writeln!(s, "*entrance m0");
    }
    let _ = writeln!(s, "*data normal from to tape compass clino");
    for (k, w) in cave.path.windows(2).enumerate() {
        reading(&format!("m{k}"), &format!("m{}", k + 1), w[0], w[1], &mut s);
    }
    if let Some(b0) = cave.branch.first() {
        let nearest = (0..cave.path.len())
            .min_by(|&i, &j| len(sub(cave.path[i], *b0)).total_cmp(&len(sub(cave.path[j], *b0))));
        if let Some(m) = nearest {
            reading(&format!("m{m}"), "b0", cave.path[m], *b0, &mut s);
        }
        for (k, w) in cave.branch.windows(2).enumerate() {
            reading(&format!("b{k}"), &format!("b{}", k + 1), w[0], w[1], &mut s);
        }
    }
    let _ = writeln!(s, "*end synth");
    s
}

/// What `write_dataset` wrote.
#[derive(Clone, Debug, serde::Serialize)]
pub struct SynthSummary {
    pub(crate) dir: String,
    pub manifest: String,
    pub scans: usize,
    pub points: u64,
    pub(crate) files: Vec<String>,
}

/// Points of interest on the rock seen from the cameras, and a tour through them (docs/web.md's
/// example): the passage ahead of the entrance, the first chamber's far wall and its first
/// column.
fn story(cave: &SynthCave, manifest: &mut String, world: &dyn Fn([f64; 3]) -> String) {
    use std::fmt::Write as _;
    let mut stops = Vec::new();
    let mut poi = |name: &str, title: &str, text: &str, eye: [f64; 3], toward: [f64; 3]| {
        let Some(at) = cave.first_wall(eye, toward, 60.0) else { return };
        let _ = writeln!(
            manifest,
            "[[poi]]\nname = \"{name}\"\ntitle = \"{title}\"\ntext = \"{text}\"\nposition = {}\neye = {}\n",
            world(at),
            world(eye)
        );
        stops.push(name.to_owned());
    };
    if cave.path.len() > 3 {
        let (e, ahead) = (cave.path[0], cave.path[3]);
        poi("passage", "The main passage", "The passage winds on past the lamps.", e, ahead);
    }
    if let Some(c) = cave.chambers.first() {
        let eye = [c[0] - 3.0, c[1] - 2.0, c[2] + 0.5];
        let beyond = [c[0] + 3.0, c[1] + 2.0, c[2] - 0.5];
        poi("chamber", "The first chamber", "Its far wall, lit by the chamber's lamp.", eye, beyond);
        if let Some(col) = cave.columns.first() {
            let toward = [col.xy[0], col.xy[1], c[2]];
            poi(
                "column",
                "A rock column",
                "Floor to ceiling, left standing as the passage grew.",
                eye,
                toward,
            );
        }
    }
    if stops.len() >= 2 {
        let _ = writeln!(manifest, "[[tour]]\nname = \"visit\"\ntitle = \"A short visit\"\n");
        for s in &stops {
            let _ = writeln!(manifest, "[[tour.stop]]\npoi = \"{s}\"\ndwell_s = 5.0\n");
        }
    }
}

/// Writes the scans (formats assigned round-robin from `formats`), `manifest.toml` and
/// `synth.json` (the parameters, to rebuild the analytic cave as ground truth) into `dir`.
/// E57 scans carry their pose in the file and the manifest leaves it out, so both pose paths are
/// exercised. `progress(done, total)` is called after each scan.
pub fn write_dataset(
    dir: &std::path::Path,
    params: &SynthParams,
    formats: &[crate::ingest::ScanFormat],
    progress: &dyn Fn(usize, usize),
) -> crate::Result<SynthSummary> {
    use std::fmt::Write as _;

    use crate::ingest::ScanFormat;
    use crate::scanwrite::{ScanData, rotation_to_quaternion, write_scan};

    let io = |source| crate::Error::Io { path: dir.to_path_buf(), source };
    if formats.is_empty() || params.points == 0 || params.points > 10_000_000_000 {
        return Err(crate::Error::Parameter {
            name: "synth",
            reason: "needs formats and 1..=1e10 points".into(),
        });
    }
    std::fs::create_dir_all(dir).map_err(io)?;
    let cave = SynthCave::new(params);
    let stations = cave.stations.len();
    let rays = params.points.div_ceil(stations as u64);
    let mut manifest = String::from(
        "# Synthetic cave written by `grotto-pack synth`; see docs/manifest.md.\n\
         # Scans in the scanner's frame; E57 scans carry their pose in the file.\n\n",
    );
    let (mut files, mut total) = (Vec::new(), 0u64);
    for s in 0..stations {
        let format = formats[s % formats.len()];
        let ext = match format {
            ScanFormat::Las => "las",
            ScanFormat::Laz => "laz",
            ScanFormat::Ply => "ply",
            ScanFormat::E57 => "e57",
        };
        let name = format!("scan-{s:03}.{ext}");
        let sc = scan(&cave, params, s, rays);
        let pose = sc.world_from_scan;
        write_scan(
            &dir.join(&name),
            format,
            &ScanData {
                xyz: &sc.xyz,
                rgb: &sc.rgb,
                intensity: &sc.intensity,
                normals: &[],
                pose: Some(pose),
            },
        )?;
        let _ = writeln!(manifest, "[[scan]]\npath = \"{name}\"");
        if format != ScanFormat::E57 {
            let q = rotation_to_quaternion(&pose.rotation);
            let t = pose.translation;
            let _ = writeln!(manifest, "translation = [{:.4}, {:.4}, {:.4}]", t[0], t[1], t[2]);
            let _ = writeln!(manifest, "rotation = [{}, {}, {}, {}]", q[0], q[1], q[2], q[3]);
        }
        let _ = writeln!(manifest, "origin = [0.0, 0.0, 0.0]\n");
        total += sc.xyz.len() as u64;
        files.push(name);
        progress(s + 1, stations);
    }
    let o = params.offset_m;
    let world = |p: [f64; 3]| format!("[{:.3}, {:.3}, {:.3}]", p[0] + o[0], p[1] + o[1], p[2] + o[2]);
    for (i, c) in cave.chambers.iter().enumerate() {
        let _ = writeln!(
            manifest,
            "[[light]]\nname = \"chamber-{i}\"\nkind = \"point\"\nposition = {}\ncolor = [1.0, 0.85, 0.7]\npower_w = 60.0\n",
            world([c[0], c[1], c[2] + 1.0])
        );
    }
    // A lamp string along the main passage, as in show caves.
    for (i, p) in cave.path.iter().enumerate().step_by(3) {
        let _ = writeln!(
            manifest,
            "[[light]]\nname = \"lamp-{i}\"\nkind = \"point\"\nposition = {}\ncolor = [1.0, 0.78, 0.55]\npower_w = 8.0\n",
            world([p[0], p[1], p[2] + 0.6])
        );
    }
    if cave.path.len() > 2 {
        let _ = writeln!(
            manifest,
            "[[camera]]\nname = \"entrance\"\neye = {}\nlook_at = {}\nfov_deg = 70.0\n",
            world(cave.path[0]),
            world(cave.path[2])
        );
    }
    if let Some(c) = cave.chambers.first() {
        let _ = writeln!(
            manifest,
            "[[camera]]\nname = \"chamber\"\neye = {}\nlook_at = {}\nfov_deg = 80.0\n",
            world([c[0] - 3.0, c[1] - 2.0, c[2] + 0.5]),
            world(*c)
        );
    }
    story(&cave, &mut manifest, &world);
    let manifest_path = dir.join("manifest.toml");
    std::fs::write(&manifest_path, manifest).map_err(io)?;
    std::fs::write(dir.join("cave.svx"), survey_svx(&cave, params)).map_err(io)?;
    files.push("cave.svx".into());
    std::fs::write(dir.join("synth.json"), serde_json::to_string_pretty(params).unwrap_or_default())
        .map_err(io)?;
    Ok(SynthSummary {
        dir: dir.display().to_string(),
        manifest: manifest_path.display().to_string(),
        scans: stations,
        points: total,
        files,
    })
}
