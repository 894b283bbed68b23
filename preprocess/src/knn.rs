//! Exact k nearest neighbours of a tile's points, cell by cell in Morton order.
//!
//! Written here rather than taken whole from kiddo: kiddo's per-query descent and result heap
//! were 40% of a build's samples (`perf record` of a 10^7-point build), while scan
//! points sorted by Morton code already sit grouped by cell at every level of an octree over
//! the tile, which a general kd-tree cannot use. kiddo stays as the fallback for the queries
//! this cannot prove (sparse points, a neighbourhood wider than its cells).
//!
//! Points are quantised to a 1024^3 grid over a cube around the tile and sorted by the 30-bit
//! Morton code, so a cell of level `L` (edge `cube / 2^L`) is one run of the sorted points: the
//! codes' top `3 L` bits. For a query in cell `c`, the candidates are the points of the 3x3x3
//! block of cells around `c`, gathered once for every point of `c`. Their `k` nearest are the
//! tile's `k` nearest whenever the `k`-th distance is shorter than the distance from the query to
//! the outside of the block (no point outside can be closer): the answer is then exact, not
//! approximate. Each query takes the level whose cells hold about [`TARGET_PER_CELL`] points
//! there (dense cells are split into their children), so candidate sets stay between about 50
//! and 150 points in dense and sparse parts of a scan alike; a query the block cannot prove tries
//! the blocks of coarser cells, then the kd-tree. On the synthetic 10^7 survey 98.8% of queries
//! are proven by their block and the rest by a coarser one; the build's normals stage there ran
//! in half the time it took with kiddo alone (docs/benchmarks.md, "Exact kNN by cells").

use std::num::NonZero;
use std::sync::OnceLock;

use grotto_format::svo::morton_encode;
use kiddo::SquaredEuclidean;
use kiddo::immutable::float::kdtree::ImmutableKdTree;
use rayon::prelude::*;

/// Points a cell should hold: with `k = 16` on a surface, a cell of edge near the 16th-neighbour
/// distance holds about five, which is what the block must reach past for the proof to hold.
const TARGET_PER_CELL: usize = 6;

/// Candidates past k that are dropped one by one rather than by a selection.
const SMALL_EXCESS: usize = 6;

/// A coarse block holding more candidates than this is left to the kd-tree.
const MAX_COARSE_CANDIDATES: usize = 4096;

/// Finest level (10 bits per axis).
const MAX_LEVEL: u32 = 10;

/// Exact k nearest neighbours of a point set, in Morton order: the grid where it can prove them,
/// else kiddo's kd-tree (built on the first such query).
#[derive(Debug)]
pub(crate) struct Knn {
    grid: MortonGrid,
    // u32 items (a tile's points are bounded by the memory budget) and 64-point leaves: measured
    // 10-15% faster than kiddo's default (u64, 32) for k = 16 on scan data.
    tree: OnceLock<ImmutableKdTree<f32, u32, 3, 64>>,
}

impl Knn {
    /// Sorts `positions` by Morton code; the returned `order[j]` is the input index of sorted
    /// point `j`.
    pub(crate) fn new(positions: &[[f32; 3]]) -> (Vec<u32>, Knn) {
        let (order, grid) = MortonGrid::new(positions);
        (order, Knn { grid, tree: OnceLock::new() })
    }

    /// The sorted points.
    pub(crate) fn points(&self) -> &[[f32; 3]] {
        &self.grid.points
    }

    /// The `min(k, n)` nearest points of sorted point `j` (itself included) into `out` as
    /// (squared distance, sorted index), in no particular order. `guess_d2` is the caller's
    /// guess of the k-th squared distance (the previous query's, widened): any value gives the
    /// same answer, a good one gives it faster. Queries in sorted order reuse `cache` best.
    pub(crate) fn nearest(
        &self,
        j: usize,
        k: usize,
        guess_d2: f32,
        cache: &mut CellCache,
        out: &mut Vec<(f32, u32)>,
    ) {
        if self.grid.nearest(j, k, guess_d2, cache, out) {
            return;
        }
        out.clear();
        let Some(kk) = NonZero::new(k) else { return };
        let tree = self.tree.get_or_init(|| ImmutableKdTree::new_from_slice(&self.grid.points));
        let q = &self.grid.points[j];
        let mut found = tree.nearest_n_within::<SquaredEuclidean>(q, guess_d2, kk, false);
        if found.len() < k.min(self.grid.points.len()) {
            found = tree.nearest_n_within::<SquaredEuclidean>(q, f32::INFINITY, kk, false);
        }
        out.extend(found.iter().map(|nb| (nb.distance, nb.item)));
    }
}

/// Sorted points of a tile and their cells at every level.
#[derive(Debug)]
struct MortonGrid {
    /// Corner of the cube the codes quantise.
    lo: [f32; 3],
    /// Edge of the cube, metres.
    cube_m: f32,
    /// Morton code of each sorted point.
    codes: Vec<u64>,
    /// The sorted points, and again by axis (the candidate scan reads three runs per cell).
    points: Vec<[f32; 3]>,
    xs: Vec<f32>,
    ys: Vec<f32>,
    zs: Vec<f32>,
    /// Level most cells are searched at (mean occupancy at least [`TARGET_PER_CELL`]).
    base_level: u32,
    levels: [OnceLock<Level>; MAX_LEVEL as usize + 1],
}

/// The non-empty cells of one level: their code prefixes, ascending, and where each one's points
/// start (`starts[i]..starts[i + 1]`).
#[derive(Debug)]
struct Level {
    prefixes: Vec<u64>,
    starts: Vec<u32>,
}

/// The candidates of one cell's block, kept while consecutive queries fall in the cell: runs of
/// the grid's sorted points, read in place.
#[derive(Debug, Default)]
pub(crate) struct CellCache {
    key: Option<(u32, u64)>,
    /// Candidates in all the block's cells.
    candidates: usize,
    /// The block's inner and outer faces, metres (infinite where the cube ends: no point lies
    /// beyond it).
    block_lo: [f32; 3],
    block_hi: [f32; 3],
    /// The block's three slabs along each axis (below, through and above the central cell):
    /// their bounds, metres, a hair wide so that a point quantised across a face by rounding is
    /// still inside.
    slabs_m: [[(f32, f32); 3]; 3],
    /// The block's non-empty cells: their runs of sorted points and their slab on each axis.
    cells: Vec<CachedCell>,
    /// The candidates a query kept, as squared distance (its bits: non-negative floats order
    /// like their bits) above sorted index, so that selection compares integers.
    found: Vec<u64>,
    /// Blocks of coarser cells, for the queries this block cannot prove.
    coarse: Option<Box<CellCache>>,
}

#[derive(Clone, Copy, Debug, Default)]
struct CachedCell {
    first: u32,
    end: u32,
    slab: [u8; 3],
}

impl CellCache {
    /// Puts the candidates within `limit_d2` of `q` first in `found` and returns how many.
    fn within(&mut self, grid: &MortonGrid, q: [f32; 3], limit_d2: f32) -> usize {
        self.found.resize(self.candidates, 0);
        let mut m = 0;
        // A cell's gap to the query is the sum of its slabs' gaps: nine per query rather than
        // three per cell (the per-cell box test was a third of this function's time).
        let gap2: [[f32; 3]; 3] = std::array::from_fn(|a| {
            self.slabs_m[a].map(|(lo, hi)| {
                let gap = (lo - q[a]).max(q[a] - hi).max(0.0);
                gap * gap
            })
        });
        for cell in &self.cells {
            let [sx, sy, sz] = cell.slab.map(usize::from);
            if gap2[0][sx] + gap2[1][sy] + gap2[2][sz] > limit_d2 {
                continue;
            }
            let (s, e) = (cell.first as usize, cell.end as usize);
            // One pass, branch-free: every candidate is written, the kept ones by advancing.
            // (Distances in a vectorised loop of their own, then the compaction, ran 1.5%
            // slower in `grotto-pack bench-normals`.)
            for (((&x, &y), &z), i) in
                grid.xs[s..e].iter().zip(&grid.ys[s..e]).zip(&grid.zs[s..e]).zip(s as u32..)
            {
                let (dx, dy, dz) = (x - q[0], y - q[1], z - q[2]);
                let d = dx * dx + dy * dy + dz * dz;
                self.found[m] = u64::from(d.to_bits()) << 32 | u64::from(i);
                m += usize::from(d <= limit_d2);
            }
        }
        m
    }
}

impl MortonGrid {
    /// Sorts `positions` by Morton code; `order()[j]` is the input index of sorted point `j`.
    fn new(positions: &[[f32; 3]]) -> (Vec<u32>, MortonGrid) {
        let mut lo = [f32::INFINITY; 3];
        let mut hi = [f32::NEG_INFINITY; 3];
        for p in positions {
            for a in 0..3 {
                lo[a] = lo[a].min(p[a]);
                hi[a] = hi[a].max(p[a]);
            }
        }
        if positions.is_empty() {
            lo = [0.0; 3];
            hi = [0.0; 3];
        }
        let extent = (0..3).map(|a| hi[a] - lo[a]).fold(0.0f32, f32::max);
        // A little over the extent, so the far corner quantises below 1024.
        let cube_m = if extent > 0.0 { extent * (1.0 + 1e-5) } else { 1.0 };
        let scale = 1024.0 / cube_m;
        // The 30-bit code above the 32-bit index in one u64: unique keys, so the parallel sort
        // gives the one order a single thread would, and sorting 8-byte integers rather than
        // (u64, u32) pairs ran faster.
        let mut keyed: Vec<u64> = positions
            .iter()
            .enumerate()
            .map(|(i, p)| {
                let c: [u32; 3] = std::array::from_fn(|a| (((p[a] - lo[a]) * scale) as u32).min(1023));
                morton_encode(c[0], c[1], c[2]) << 32 | i as u64
            })
            .collect();
        keyed.par_sort_unstable();
        let order: Vec<u32> = keyed.iter().map(|&k| k as u32).collect();
        let codes: Vec<u64> = keyed.iter().map(|&k| k >> 32).collect();
        let points: Vec<[f32; 3]> = order.iter().map(|&i| positions[i as usize]).collect();
        let [xs, ys, zs] = [0, 1, 2].map(|a| points.iter().map(|p| p[a]).collect());
        let mut grid =
            MortonGrid { lo, cube_m, codes, points, xs, ys, zs, base_level: 0, levels: Default::default() };
        // The finest level whose non-empty cells hold TARGET_PER_CELL points on average,
        // counted in one pass (two neighbours in sorted order fall in different cells at every
        // level from the one their codes' highest differing bit belongs to), so that only the
        // levels queries use are ever built.
        let mut cells_per_level = [usize::from(!grid.codes.is_empty()); MAX_LEVEL as usize + 1];
        for w in grid.codes.windows(2) {
            let diff = w[0] ^ w[1];
            if diff != 0 {
                let first = (MAX_LEVEL - (63 - diff.leading_zeros()) / 3) as usize;
                for count in &mut cells_per_level[first..] {
                    *count += 1;
                }
            }
        }
        grid.base_level = (0..=MAX_LEVEL)
            .rev()
            .find(|&l| cells_per_level[l as usize] * TARGET_PER_CELL <= grid.points.len())
            .unwrap_or(0);
        (order, grid)
    }

    fn level(&self, l: u32) -> &Level {
        self.levels[l as usize].get_or_init(|| {
            let shift = 3 * (MAX_LEVEL - l);
            let mut prefixes = Vec::new();
            let mut starts = Vec::new();
            let mut last = None;
            for (j, &c) in self.codes.iter().enumerate() {
                let p = c >> shift;
                if last != Some(p) {
                    prefixes.push(p);
                    starts.push(j as u32);
                    last = Some(p);
                }
            }
            starts.push(self.codes.len() as u32);
            Level { prefixes, starts }
        })
    }

    /// The `k` nearest points of sorted point `j` (itself included) as (squared distance,
    /// sorted index), or false where this grid cannot prove them.
    fn nearest(
        &self,
        j: usize,
        k: usize,
        guess_d2: f32,
        cache: &mut CellCache,
        out: &mut Vec<(f32, u32)>,
    ) -> bool {
        out.clear();
        if k == 0 {
            return true;
        }
        let code = self.codes[j];
        // Consecutive points mostly share a cell, and the cell chosen depends only on the code.
        let (l, prefix) = match cache.key {
            Some((l, p)) if code >> (3 * (MAX_LEVEL - l)) == p => (l, p),
            _ => {
                let (l, p) = self.cell_of(code);
                self.gather(l, p, cache);
                (l, p)
            }
        };
        debug_assert_eq!(cache.key, Some((l, prefix)));
        if self.prove(j, k, guess_d2, cache, out) {
            return true;
        }
        // Sparse here: the blocks of coarser cells, kept in a second cache since the points that
        // need them come in runs too.
        let coarse = cache.coarse.get_or_insert_with(Default::default);
        for l in (0..l).rev() {
            let prefix = code >> (3 * (MAX_LEVEL - l));
            if coarse.key != Some((l, prefix)) {
                self.gather(l, prefix, coarse);
            }
            if coarse.candidates > MAX_COARSE_CANDIDATES {
                break;
            }
            if self.prove(j, k, guess_d2, coarse, out) {
                return true;
            }
        }
        false
    }

    /// The k nearest of sorted point `j` among `cache`'s candidates, if they are provably the
    /// tile's.
    fn prove(
        &self,
        j: usize,
        k: usize,
        guess_d2: f32,
        cache: &mut CellCache,
        out: &mut Vec<(f32, u32)>,
    ) -> bool {
        out.clear();
        if cache.candidates < k {
            return false;
        }
        let q = self.points[j];
        // The k smallest: first among those within the caller's guess of the k-th distance
        // (a few more than k where the guess is good; cells wholly beyond it are skipped), else
        // among all.
        let mut m = cache.within(self, q, guess_d2);
        if m < k {
            m = cache.within(self, q, f32::INFINITY);
        }
        let found = &mut cache.found[..m];
        if m > k + SMALL_EXCESS {
            found.select_nth_unstable(k - 1);
        } else {
            // A good guess leaves a few more than k: dropping the largest a few times is
            // cheaper than a selection.
            for end in (k..m).rev() {
                let largest = (0..=end).max_by_key(|&i| found[i]).unwrap_or(end);
                found.swap(largest, end);
            }
        }
        let dk2 = f32::from_bits((found[..k].iter().max().copied().unwrap_or(0) >> 32) as u32);
        // Proof: nothing outside the block is nearer than its faces.
        let reach = (0..3)
            .map(|a| (q[a] - cache.block_lo[a]).min(cache.block_hi[a] - q[a]))
            .fold(f32::INFINITY, f32::min)
            - self.cube_m * 1e-5;
        if reach > 0.0 && dk2 < reach * reach {
            out.extend(found[..k].iter().map(|&key| (f32::from_bits((key >> 32) as u32), key as u32)));
            true
        } else {
            false
        }
    }

    /// The level and prefix of the cell a code is searched in: the base level's cell, split
    /// while it holds far more than the target.
    fn cell_of(&self, code: u64) -> (u32, u64) {
        let mut l = self.base_level;
        let mut cell = self.cell_index(l, code >> (3 * (MAX_LEVEL - l)));
        while l < MAX_LEVEL && cell.1 - cell.0 > 4 * TARGET_PER_CELL {
            l += 1;
            cell = self.cell_index(l, code >> (3 * (MAX_LEVEL - l)));
        }
        (l, code >> (3 * (MAX_LEVEL - l)))
    }

    /// The point range of the cell with this prefix at level `l` (empty if none).
    fn cell_index(&self, l: u32, prefix: u64) -> (usize, usize) {
        let level = self.level(l);
        match level.prefixes.binary_search(&prefix) {
            Ok(i) => (level.starts[i] as usize, level.starts[i + 1] as usize),
            Err(_) => (0, 0),
        }
    }

    fn gather(&self, l: u32, prefix: u64, cache: &mut CellCache) {
        cache.key = Some((l, prefix));
        cache.candidates = 0;
        cache.cells.clear();
        let c = morton_decode(prefix);
        let cells = 1i64 << l;
        let edge_m = self.cube_m / cells as f32;
        let eps_m = self.cube_m * 1e-5;
        let level = self.level(l);
        // Where the central cell sits among the prefixes: the neighbours are searched from
        // there, since most of them are near it in Morton order.
        let hint = level.prefixes.partition_point(|&p| p < prefix);
        cache.block_lo = std::array::from_fn(|a| {
            let c0 = i64::from(c[a]);
            if c0 == 0 { f32::NEG_INFINITY } else { self.lo[a] + (c0 - 1) as f32 * edge_m }
        });
        cache.block_hi = std::array::from_fn(|a| {
            let c0 = i64::from(c[a]);
            if c0 + 1 >= cells { f32::INFINITY } else { self.lo[a] + (c0 + 2) as f32 * edge_m }
        });
        cache.slabs_m = std::array::from_fn(|a| {
            std::array::from_fn(|s| {
                let lo = self.lo[a] + (i64::from(c[a]) + s as i64 - 1) as f32 * edge_m;
                (lo - eps_m, lo + edge_m + eps_m)
            })
        });
        for dz in -1i64..=1 {
            for dy in -1i64..=1 {
                for dx in -1i64..=1 {
                    let n = [i64::from(c[0]) + dx, i64::from(c[1]) + dy, i64::from(c[2]) + dz];
                    if n.iter().any(|&v| v < 0 || v >= cells) {
                        continue;
                    }
                    let p = morton_encode(n[0] as u32, n[1] as u32, n[2] as u32);
                    if let Some(i) = gallop(&level.prefixes, p, hint) {
                        let (s, e) = (level.starts[i] as usize, level.starts[i + 1] as usize);
                        cache.candidates += e - s;
                        cache.cells.push(CachedCell {
                            first: s as u32,
                            end: e as u32,
                            slab: [dx, dy, dz].map(|d| (d + 1) as u8),
                        });
                    }
                }
            }
        }
    }
}

/// Index of `want` in the ascending `v`, searched outward from `hint` (exponential search).
fn gallop(v: &[u64], want: u64, hint: usize) -> Option<usize> {
    let hint = hint.min(v.len().saturating_sub(1));
    if v.is_empty() {
        return None;
    }
    let (lo, hi) = if v[hint] < want {
        let mut step = 1;
        let mut lo = hint;
        loop {
            let at = hint + step;
            if at >= v.len() {
                break (lo, v.len());
            }
            if v[at] >= want {
                break (lo, at + 1);
            }
            lo = at;
            step *= 2;
        }
    } else {
        let mut step = 1;
        let mut hi = hint + 1;
        loop {
            if step > hint {
                break (0, hi);
            }
            let at = hint - step;
            if v[at] < want {
                break (at, hi);
            }
            hi = at + 1;
            step *= 2;
        }
    };
    v[lo..hi].binary_search(&want).ok().map(|i| lo + i)
}

/// Inverse of `morton_encode` for 10 bits per axis (x in the lowest bit of each triple).
fn morton_decode(code: u64) -> [u32; 3] {
    let compact = |mut v: u64| -> u32 {
        v &= 0x1249_2492_4924_9249;
        v = (v ^ (v >> 2)) & 0x10c3_0c30_c30c_30c3;
        v = (v ^ (v >> 4)) & 0x100f_00f0_0f00_f00f;
        v = (v ^ (v >> 8)) & 0x001f_0000_ff00_00ff;
        v = (v ^ (v >> 16)) & 0x001f_0000_0000_ffff;
        v = (v ^ (v >> 32)) & 0x1f_ffff;
        v as u32
    };
    [compact(code), compact(code >> 1), compact(code >> 2)]
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn morton_decode_inverts_encode() {
        for c in [[0, 0, 0], [1023, 0, 5], [17, 999, 1023], [512, 256, 128]] {
            assert_eq!(morton_decode(morton_encode(c[0], c[1], c[2])), c);
        }
    }

    fn brute_force_d2(points: &[[f32; 3]], q: [f32; 3], k: usize) -> Vec<f32> {
        let mut all: Vec<f32> =
            points.iter().map(|p| (0..3).map(|a| (p[a] - q[a]) * (p[a] - q[a])).sum::<f32>()).collect();
        all.sort_by(f32::total_cmp);
        all.truncate(k);
        all
    }

    /// A wall with a dense patch, a sparse strip far off, exact duplicates and a lone point.
    fn scan_like_points() -> Vec<[f32; 3]> {
        // splitmix64: the test needs repeatable spread, not a crate.
        let mut state = 7u64;
        let mut random = move || {
            state = state.wrapping_add(0x9e37_79b9_7f4a_7c15);
            let mut z = state;
            z = (z ^ (z >> 30)).wrapping_mul(0xbf58_476d_1ce4_e5b9);
            z = (z ^ (z >> 27)).wrapping_mul(0x94d0_49bb_1331_11eb);
            ((z ^ (z >> 31)) >> 40) as f32 / (1u64 << 24) as f32
        };
        let mut pts: Vec<[f32; 3]> = Vec::new();
        for _ in 0..6000 {
            pts.push([random() * 4.0, random() * 4.0, random() * 0.01]);
        }
        for _ in 0..3000 {
            pts.push([1.0 + random() * 0.3, 1.0 + random() * 0.3, random() * 0.01]);
        }
        for _ in 0..200 {
            pts.push([random() * 4.0, 5.0 + random() * 40.0, 3.0]);
        }
        pts.extend([[1.0, 1.0, 0.005]; 20]);
        pts.push([-30.0, 2.0, 9.0]);
        pts
    }

    /// Every answer of the grid, proven or from its coarser blocks, has the true k nearest
    /// distances; most come from the grid; and the kd-tree fallback answers the rest the same.
    #[test]
    fn the_grid_finds_the_true_nearest() {
        let pts = scan_like_points();
        let (order, grid) = MortonGrid::new(&pts);
        let sorted = grid.points.clone();
        assert!(order.iter().enumerate().all(|(j, &i)| pts[i as usize] == sorted[j]));
        let k = 16;
        let mut cache = CellCache::default();
        let mut out = Vec::new();
        let mut proven = 0;
        for (j, &q) in sorted.iter().enumerate() {
            if !grid.nearest(j, k, f32::INFINITY, &mut cache, &mut out) {
                continue;
            }
            proven += 1;
            let mut got: Vec<f32> = out.iter().map(|e| e.0).collect();
            got.sort_by(f32::total_cmp);
            assert_eq!(got, brute_force_d2(&sorted, q, k), "point {j}");
            assert!(
                out.iter()
                    .all(|e| (0..3).map(|a| (sorted[e.1 as usize][a] - q[a]).powi(2)).sum::<f32>() == e.0)
            );
        }
        assert!(proven * 10 > sorted.len() * 9, "{proven} of {} proven", sorted.len());

        // Through the fallback, and whatever the guess.
        let (_, knn) = Knn::new(&pts);
        for guess in [0.0, 1e-6, 1e-3, f32::INFINITY] {
            let mut cache = CellCache::default();
            for (j, &q) in sorted.iter().enumerate().step_by(7) {
                knn.nearest(j, k, guess, &mut cache, &mut out);
                let mut got: Vec<f32> = out.iter().map(|e| e.0).collect();
                got.sort_by(f32::total_cmp);
                assert_eq!(got, brute_force_d2(&sorted, q, k), "point {j}, guess {guess}");
            }
        }
    }

    #[test]
    fn the_cells_counted_in_one_pass_are_those_built() {
        let (_, grid) = MortonGrid::new(&scan_like_points());
        let built: Vec<usize> = (0..=MAX_LEVEL).map(|l| grid.level(l).prefixes.len()).collect();
        let fine_enough =
            (0..=MAX_LEVEL).rev().find(|&l| built[l as usize] * TARGET_PER_CELL <= grid.points.len());
        assert_eq!(Some(grid.base_level), fine_enough, "{built:?}");
        assert_eq!(built[0], 1);
    }

    #[test]
    fn one_point_and_empty_tiles() {
        let (order, knn) = Knn::new(&[]);
        assert!(order.is_empty() && knn.points().is_empty());
        let (order, knn) = Knn::new(&[[3.0, 4.0, 5.0]]);
        assert_eq!(order, vec![0]);
        let mut out = Vec::new();
        knn.nearest(0, 16, f32::INFINITY, &mut CellCache::default(), &mut out);
        assert_eq!(out, vec![(0.0, 0)]);
        knn.nearest(0, 0, f32::INFINITY, &mut CellCache::default(), &mut out);
        assert!(out.is_empty());
    }

    /// Survey coordinates kept in f32 far from the origin (a tile frame is local, but nothing
    /// here may assume it): the cells still prove exact answers.
    #[test]
    fn far_from_the_origin() {
        let pts: Vec<[f32; 3]> =
            scan_like_points().iter().map(|p| [p[0] + 5000.0, p[1] - 3000.0, p[2] + 300.0]).collect();
        let (_, knn) = Knn::new(&pts);
        let sorted = knn.points().to_vec();
        let mut cache = CellCache::default();
        let mut out = Vec::new();
        for (j, &q) in sorted.iter().enumerate().step_by(5) {
            knn.nearest(j, 8, f32::INFINITY, &mut cache, &mut out);
            let mut got: Vec<f32> = out.iter().map(|e| e.0).collect();
            got.sort_by(f32::total_cmp);
            assert_eq!(got, brute_force_d2(&sorted, q, 8), "point {j}");
        }
    }
}
