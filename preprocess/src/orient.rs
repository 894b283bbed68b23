//! Normal orientation for scans without a scanner position (a merged, registered cloud): which
//! side of a wall is the open passage.
//!
//! A cave is seen from inside, so its scanned walls enclose the passage: a point in open passage
//! lies inside the surface the walls make, a point in the rock behind a wall outside it. That is
//! the inside/outside test of volumetric model repair (Nooruddin & Turk 2003): count the wall
//! crossings along a ray from the point to the edge of the data; odd is inside. Scan gaps and the
//! cave's own openings let single rays through, so six rays vote (both ways along each axis), from
//! a point a little in front of the wall and a point a little behind it, and each point's sign is
//! then taken from its neighbourhood's votes.
//!
//! The walls are a coarse occupancy grid of every point in the build (`CaveGrid`), stored as
//! sorted runs of occupied cells along each axis, so a ray's crossing count is one binary search
//! in one column. It is built once in the plan step (out of core, from the tile bins) and shared
//! read-only by every tile job, so a point at a tile border gets the same votes in the tiles on
//! either side of it.
//!
//! Written by hand: the parity vote is the project's own, and no crate offers column-run parity
//! over a sparse voxel set.

use std::collections::HashMap;
use std::io::Write;
use std::path::{Path, PathBuf};

use rayon::prelude::*;

use crate::bins::{self, FLAG_HALO, TilePlan};
use crate::{Error, Result};

/// Occupancy cell edge in leaves: coarse enough that a wall sampled at the leaf spacing has no
/// holes a ray slips through.
pub(crate) const CELL_LEAVES: f64 = 2.0;
/// How far in front of / behind the wall the votes are taken, in cells: clear of the wall's own
/// cells on a rough wall, inside all but the narrowest squeezes.
pub(crate) const VOTE_OFFSET_CELLS: f64 = 1.5;
/// The largest score one point's votes can give (6 rays from each side).
pub(crate) const MAX_SCORE: i32 = 12;

type Columns = HashMap<(i32, i32), Vec<[i32; 2]>, foldhash::fast::FixedState>;

/// The walls of the whole build as occupied cells, indexed for ray parity along the three axes.
#[derive(Debug)]
pub(crate) struct CaveGrid {
    pub(crate) cell_m: f64,
    /// World position of cell (0, 0, 0)'s lower corner.
    pub(crate) origin_m: [f64; 3],
    /// Occupied cells.
    pub(crate) cells: usize,
    /// For axis a: the column keyed by the two other coordinates (in axis order), holding the
    /// runs of occupied cells along a as [first, last], ascending and disjoint.
    columns: [Columns; 3],
}

impl CaveGrid {
    /// From occupied cells (any order, duplicates allowed).
    pub(crate) fn from_cells(cell_m: f64, origin_m: [f64; 3], mut cells: Vec<[i32; 3]>) -> Self {
        cells.par_sort_unstable();
        cells.dedup();
        let count = cells.len();
        let columns = std::array::from_fn(|axis| {
            let (b, c) = ((axis + 1) % 3, (axis + 2) % 3);
            let (lo, hi) = (b.min(c), b.max(c));
            let mut keyed: Vec<(i32, i32, i32)> = cells.iter().map(|k| (k[lo], k[hi], k[axis])).collect();
            keyed.par_sort_unstable();
            let mut cols = Columns::default();
            for (u, v, a) in keyed {
                let runs = cols.entry((u, v)).or_default();
                match runs.last_mut() {
                    Some(last) if last[1] + 1 == a => last[1] = a,
                    _ => runs.push([a, a]),
                }
            }
            cols
        });
        CaveGrid { cell_m, origin_m, cells: count, columns }
    }

    fn key(&self, p_world_m: [f64; 3]) -> Option<[i32; 3]> {
        let mut k = [0i32; 3];
        for a in 0..3 {
            let c = ((p_world_m[a] - self.origin_m[a]) / self.cell_m).floor();
            if !(c.is_finite() && c.abs() < f64::from(i32::MAX)) {
                return None;
            }
            k[a] = c as i32;
        }
        Some(k)
    }

    fn column(&self, axis: usize, k: [i32; 3]) -> &[[i32; 2]] {
        let (b, c) = ((axis + 1) % 3, (axis + 2) % 3);
        let (lo, hi) = (b.min(c), b.max(c));
        self.columns[axis].get(&(k[lo], k[hi])).map_or(&[], Vec::as_slice)
    }

    /// Along `axis` through cell `k`: the runs wholly below the cell, or None where the cell is
    /// itself in a run (a wall cell).
    fn runs_below(&self, axis: usize, k: [i32; 3]) -> Option<usize> {
        let runs = self.column(axis, k);
        let below = runs.partition_point(|r| r[1] < k[axis]);
        runs.get(below).is_none_or(|r| r[0] > k[axis]).then_some(below)
    }

    /// Whether the cell holding `p_world_m` holds a wall point.
    #[cfg(test)]
    fn occupied(&self, p_world_m: [f64; 3]) -> bool {
        self.key(p_world_m).is_some_and(|k| self.runs_below(2, k).is_none())
    }

    /// The inside votes at an empty cell: +1 for each of the six axis rays that crosses the walls
    /// an odd number of times, -1 for each even one. None where the cell is a wall cell.
    fn inside_votes(&self, p_world_m: [f64; 3]) -> Option<i32> {
        let k = self.key(p_world_m)?;
        let mut votes = 0;
        for axis in 0..3 {
            let below = self.runs_below(axis, k)?;
            let above = self.column(axis, k).len() - below;
            votes += if below % 2 == 1 { 1 } else { -1 };
            votes += if above % 2 == 1 { 1 } else { -1 };
        }
        Some(votes)
    }

    /// How strongly `normal` (unit) at the wall point `p_world_m` faces the open passage, in
    /// -`MAX_SCORE`..=`MAX_SCORE`: the inside votes in front of the wall minus those behind it.
    /// Positive: the normal faces the passage; negative: the rock; zero: no evidence (open
    /// terrain, or both sides wall cells).
    pub(crate) fn score(&self, p_world_m: [f64; 3], normal: [f64; 3]) -> i32 {
        let off = VOTE_OFFSET_CELLS * self.cell_m;
        let side = |s: f64| {
            self.inside_votes(std::array::from_fn(|a| p_world_m[a] + s * off * normal[a])).unwrap_or(0)
        };
        side(1.0) - side(-1.0)
    }

    /// Builds the grid from every point the plan tiled (own points of each tile bin).
    pub(crate) fn from_plan(plan: &TilePlan, work_dir: &Path, cell_m: f64) -> Result<Self> {
        let origin_m = plan.grid_origin_m();
        let per_tile: Vec<Vec<[i32; 3]>> = (0..plan.tiles.len())
            .into_par_iter()
            .map(|t| {
                let tile_origin = plan.origin_m(&plan.tiles[t]);
                let mut keys: Vec<[i32; 3]> = bins::read_bin(work_dir, plan, t)?
                    .iter()
                    .filter(|p| p.flags & FLAG_HALO == 0)
                    .map(|p| {
                        let q = p.pos_tile_m(plan.quantum_m);
                        std::array::from_fn(|a| {
                            ((tile_origin[a] - origin_m[a] + f64::from(q[a])) / cell_m).floor() as i32
                        })
                    })
                    .collect();
                keys.sort_unstable();
                keys.dedup();
                Ok(keys)
            })
            .collect::<Result<_>>()?;
        Ok(Self::from_cells(cell_m, origin_m, per_tile.concat()))
    }

    /// The occupied cells, sorted (what [`CaveGrid::save`] writes).
    fn sorted_cells(&self) -> Vec<[i32; 3]> {
        let mut out: Vec<[i32; 3]> = self.columns[2]
            .iter()
            .flat_map(|(&(x, y), runs)| runs.iter().flat_map(move |r| (r[0]..=r[1]).map(move |z| [x, y, z])))
            .collect();
        out.sort_unstable();
        out
    }

    /// Writes the grid to `path` atomically.
    pub(crate) fn save(&self, path: &Path) -> Result<()> {
        let io = |source| Error::Io { path: path.to_path_buf(), source };
        let dir = path.parent().unwrap_or(Path::new("."));
        let mut tmp = tempfile::NamedTempFile::new_in(dir).map_err(io)?;
        let cells = self.sorted_cells();
        let mut head = Vec::with_capacity(48);
        head.extend_from_slice(GRID_MAGIC);
        head.extend_from_slice(&self.cell_m.to_le_bytes());
        for o in self.origin_m {
            head.extend_from_slice(&o.to_le_bytes());
        }
        head.extend_from_slice(&(cells.len() as u64).to_le_bytes());
        let mut w = std::io::BufWriter::new(tmp.as_file_mut());
        w.write_all(&head).map_err(io)?;
        w.write_all(bytemuck::cast_slice(&cells)).map_err(io)?;
        w.flush().map_err(io)?;
        drop(w);
        tmp.as_file().sync_all().map_err(io)?;
        tmp.persist(path).map_err(|e| io(e.error))?;
        Ok(())
    }

    /// Reads a grid [`CaveGrid::save`] wrote; a damaged or foreign file is an error naming it.
    pub(crate) fn load(path: &Path) -> Result<Self> {
        let bytes = std::fs::read(path).map_err(|source| Error::Io { path: path.to_path_buf(), source })?;
        let bad = |reason: &str| Error::Read {
            path: path.to_path_buf(),
            format: "orientation grid",
            reason: reason.into(),
        };
        if bytes.len() < 48 || &bytes[..8] != GRID_MAGIC {
            return Err(bad("not an orientation grid (magic or header)"));
        }
        let f = |i: usize| f64::from_le_bytes(bytes[i..i + 8].try_into().unwrap_or_default());
        let cell_m = f(8);
        let origin_m = [f(16), f(24), f(32)];
        let count = u64::from_le_bytes(bytes[40..48].try_into().unwrap_or_default());
        let body = &bytes[48..];
        if count.checked_mul(12) != Some(body.len() as u64) || !(cell_m > 0.0 && cell_m.is_finite()) {
            return Err(bad("cell count or size disagrees with the file"));
        }
        let cells: Vec<[i32; 3]> = body
            .chunks_exact(12)
            .map(|c| {
                std::array::from_fn(|a| {
                    i32::from_le_bytes(c[a * 4..a * 4 + 4].try_into().unwrap_or_default())
                })
            })
            .collect();
        Ok(Self::from_cells(cell_m, origin_m, cells))
    }
}

const GRID_MAGIC: &[u8; 8] = b"GRTORNT1";

/// Where the plan step keeps the orientation grid for a plan (named by its fingerprint, so a
/// re-plan never reads a stale one).
pub(crate) fn grid_path(work_dir: &Path, plan: &TilePlan) -> PathBuf {
    work_dir.join(format!("orient-{}.grid", plan.fingerprint))
}

/// The orientation grid of `plan`: read from the work directory, or built from the tile bins and
/// saved there when it is missing or unreadable.
pub(crate) fn load_or_build(plan: &TilePlan, work_dir: &Path, leaf_m: f64) -> Result<CaveGrid> {
    let path = grid_path(work_dir, plan);
    let cell_m = CELL_LEAVES * leaf_m;
    if let Ok(g) = CaveGrid::load(&path)
        && g.cell_m == cell_m
    {
        return Ok(g);
    }
    let g = CaveGrid::from_plan(plan, work_dir, cell_m)?;
    g.save(&path)?;
    Ok(g)
}

/// What orientation without a scanner did over a tile or a build.
#[derive(Clone, Copy, Debug, Default, PartialEq, serde::Serialize, serde::Deserialize)]
pub struct OrientStats {
    /// Points oriented by the votes (their scan has no scanner position).
    pub points: u64,
    /// Of those, the normals that face away from where the old rule (toward the scan frame's
    /// origin) would have turned them.
    pub(crate) flipped: u64,
    /// Points whose own votes disagreed with their neighbourhood's (the neighbourhood won).
    pub(crate) corrected: u64,
    /// Points with no evidence either way (their neighbourhood's votes sum to zero): turned up (+z).
    pub(crate) undecided: u64,
    /// Points whose neighbourhood's votes sum to less than one point's full vote: the sign is a
    /// weak choice.
    pub(crate) weak: u64,
    /// Sum over points of |neighbourhood score| / (k * MAX_SCORE), for the mean confidence.
    pub(crate) confidence_sum: f64,
}

impl OrientStats {
    pub(crate) fn add(&mut self, o: &OrientStats) {
        self.points += o.points;
        self.flipped += o.flipped;
        self.corrected += o.corrected;
        self.undecided += o.undecided;
        self.weak += o.weak;
        self.confidence_sum += o.confidence_sum;
    }

    /// Mean confidence in 0..=1 (1: every neighbour's every ray agreed).
    pub fn mean_confidence(&self) -> f64 {
        if self.points == 0 { 0.0 } else { self.confidence_sum / self.points as f64 }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    /// A closed box of wall cells, 20 x 10 x 8 cells, hollow inside.
    fn hollow_box(hole: bool) -> CaveGrid {
        let mut cells = Vec::new();
        for x in 0..20 {
            for y in 0..10 {
                for z in 0..8 {
                    let wall = x == 0 || x == 19 || y == 0 || y == 9 || z == 0 || z == 7;
                    // An opening in the x = 19 end wall.
                    let opening = hole && x == 19 && (3..7).contains(&y) && (2..6).contains(&z);
                    if wall && !opening {
                        cells.push([x, y, z]);
                    }
                }
            }
        }
        CaveGrid::from_cells(1.0, [0.0; 3], cells)
    }

    #[test]
    fn walls_of_a_closed_passage_vote_for_the_inside_and_survive_an_opening() {
        for hole in [false, true] {
            let g = hollow_box(hole);
            // Floor point at (5.5, 4.5, 0.5): up faces the passage (every ray agrees when the
            // box is closed; the +x ray escapes through the opening when it is not).
            let up = g.score([5.5, 4.5, 0.5], [0.0, 0.0, 1.0]);
            assert_eq!(up, if hole { MAX_SCORE - 2 } else { MAX_SCORE });
            assert_eq!(g.score([5.5, 4.5, 0.5], [0.0, 0.0, -1.0]), -up);
            // Side wall y = 9: -y faces the passage.
            assert!(g.score([10.5, 9.5, 3.5], [0.0, -1.0, 0.0]) > 0);
            // In front of the opening: the x ray escapes, the others still vote inside.
            assert!(g.score([17.5, 4.5, 0.5], [0.0, 0.0, 1.0]) > 0, "hole {hole}");
        }
        let g = hollow_box(false);
        assert!(g.occupied([0.5, 0.5, 0.5]) && !g.occupied([5.5, 5.5, 5.5]));
        // Far outside the data: no walls, no evidence.
        assert_eq!(g.score([500.0, 500.0, 500.0], [0.0, 0.0, 1.0]), 0);
        // Non-finite or absurd positions give no evidence instead of a panic.
        assert_eq!(g.score([f64::NAN, 0.0, 0.0], [0.0, 0.0, 1.0]), 0);
        assert_eq!(g.score([1e300, 0.0, 0.0], [0.0, 0.0, 1.0]), 0);
    }

    #[test]
    fn open_ground_gives_no_evidence() {
        // One flat layer of cells: above and below look alike to parity.
        let cells: Vec<[i32; 3]> = (0..30).flat_map(|x| (0..30).map(move |y| [x, y, 0])).collect();
        let g = CaveGrid::from_cells(1.0, [0.0; 3], cells);
        assert_eq!(g.score([15.5, 15.5, 0.5], [0.0, 0.0, 1.0]), 0);
    }

    #[test]
    fn the_grid_file_round_trips_and_a_damaged_one_is_refused() {
        let d = tempfile::tempdir().unwrap();
        let p = d.path().join("g.grid");
        let g = hollow_box(true);
        g.save(&p).unwrap();
        let back = CaveGrid::load(&p).unwrap();
        assert_eq!(back.cells, g.cells);
        assert_eq!(back.sorted_cells(), g.sorted_cells());
        assert_eq!(back.score([5.5, 4.5, 0.5], [0.0, 0.0, 1.0]), g.score([5.5, 4.5, 0.5], [0.0, 0.0, 1.0]));
        let bytes = std::fs::read(&p).unwrap();
        std::fs::write(&p, &bytes[..bytes.len() - 5]).unwrap();
        let e = CaveGrid::load(&p).unwrap_err().to_string();
        assert!(e.contains("g.grid"), "{e}");
    }
}
