//! Rock behind the scanned surfaces. Scans are shells: the SVO holds the cave's walls and nothing
//! behind them, so a cone that crosses a wall at a coarse level sees it as partly transparent and
//! goes on through empty "rock" (VCT's thin-wall leak). Here every cell of 2x2x2 leaves near a
//! surface that holds no oriented leaf is classified as rock or air from the oriented surface
//! nearest to it (the cell lies behind it, against its mean normal: rock), the signed-distance
//! test of Hoppe et al. 1992 on the leaves' Toksvig mean normals, kept to cells roughly straight
//! behind the surface (see `BEHIND_SLOPE`) and away from the surface's edges (an opening's rim:
//! beyond it is sky, not rock); anything else stays air. The runtime stops a cone whose axis
//! enters a rock cell (grotto-runtime's rock.rs and shaders/rock.wgsl).
//!
//! The nearest surface is found by a breadth-first flood over cells from all surface cells at once
//! (26-neighbourhood, at most `ROCK_REACH_CELLS` layers): each empty cell takes, of the seeds its
//! neighbours in the previous layer carry, the one nearest to it (nearest-site propagation, as in
//! vector distance transforms). Cells further from every surface stay unclassified (air).
//!
//! Written by hand: a multi-source flood over a sparse cell set with per-cell seeds is a few
//! lines over a hash map; a kd-tree query per cell would touch every cell of every tile.
//!
//! Per tile ([`tile_rock`]): the classification of a cell depends only on the surface within
//! [`CONTEXT_CELLS`] of it, so a tile's rock, the cells within `ROCK_REACH_CELLS` of its cube,
//! is computed exactly from its own leaves and its neighbours' leaves near it. The union of every
//! tile's rock is the rock of the whole package: the packer stores it per tile (format 1.1) and
//! the runtime loads only what its tiles need.

// foldhash: the flood makes millions of lookups of small integer keys, where std's SipHash
// (DoS-resistant, slow) cost more than the flood itself.
use std::collections::BTreeMap;

use foldhash::{HashMap, HashSet};
use glam::{IVec3, Vec3};
use grotto_format::spec::{ROCK_BRICK_SHIFT, ROCK_CELL_SHIFT, RockBrick};

/// Rock cells are 2^ROCK_LEVEL leaves on a side.
pub const ROCK_LEVEL: u32 = ROCK_CELL_SHIFT;
/// Rock cells per brick side, as a shift: a brick is 4x4x4 cells, its 64 bits two words.
pub const BRICK_SHIFT: u32 = ROCK_BRICK_SHIFT;
/// How far (in cells, Chebyshev) from a surface cell the classification reaches; also the margin
/// of cells kept around each tile (`ROCK_MARGIN` in shaders/rock.wgsl).
pub const ROCK_REACH_CELLS: i32 = 4;
/// A cell is rock only if it lies behind its seed's surface within about 63 degrees of the inward
/// normal (depth >= this * lateral offset): beside an opening, the wall around it is the nearest
/// surface, and its plane extended across the opening must not turn the opening into rock.
pub const BEHIND_SLOPE: f32 = 0.5;
/// Cells around a tile's rock whose surface decides it: a cell is claimed by a seed within the
/// reach, through frontier cells within the reach of their own seeds, and a seed is an edge or
/// not by its neighbours (one more cell); four to spare.
pub(crate) const CONTEXT_CELLS: i32 = 3 * ROCK_REACH_CELLS + 4;

/// What the classification reads of a leaf: its centre in leaf units of one frame (any origin on
/// the leaf grid) and its Toksvig mean normal.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct SurfaceLeaf {
    pub center_leaf: Vec3,
    pub normal_mean: Vec3,
}

#[derive(Clone, Copy)]
struct Seed {
    center_leaf: Vec3,
    normal: Vec3,
    /// On the edge of a surface (an opening's rim, a scan's border): the space behind it is not
    /// known to be rock, so the cells it is nearest to stay air.
    edge: bool,
}

/// Whether seed cell `cell` lacks a neighbouring seed cell in some direction of its tangent
/// plane (8 directions 45 degrees apart, each matched within about 53 degrees, or bending 45
/// degrees toward the normal: a concave corner continues the surface, an opening's rim does not).
fn is_edge(cell: IVec3, normal: Vec3, seeds: &HashMap<IVec3, Seed>) -> bool {
    let t1 = normal.any_orthonormal_vector();
    let t2 = normal.cross(t1);
    (0..8).any(|k| {
        let a = k as f32 * std::f32::consts::FRAC_PI_4;
        let dir = t1 * a.cos() + t2 * a.sin();
        let bent = (dir + normal).normalize();
        !(-1..=1).any(|dz| {
            (-1..=1).any(|dy| {
                (-1..=1).any(|dx| {
                    let o = IVec3::new(dx, dy, dz);
                    if o == IVec3::ZERO || !seeds.contains_key(&(cell + o)) {
                        return false;
                    }
                    let u = o.as_vec3().normalize();
                    u.dot(dir) > 0.6 || u.dot(bent) > 0.6
                })
            })
        })
    })
}

/// The rock cells (global rock-cell units, sorted z, y, x) around `leaves`.
pub fn classify(leaves: &[SurfaceLeaf]) -> Vec<IVec3> {
    // Seeds: the mean position and Toksvig mean normal of the oriented leaves in each cell. Cells
    // whose leaves have no clear orientation (solid interiors, clutter) are flooded like empty
    // ones: solid matter behind a wall is rock as much as empty space is.
    let mut sums: HashMap<IVec3, (Vec3, Vec3, f32)> = HashMap::default();
    for l in leaves {
        let c_leaf = l.center_leaf;
        let cell = c_leaf.floor().as_ivec3() >> ROCK_LEVEL as i32;
        let mean = l.normal_mean;
        if mean.length() > 0.2 {
            let e = sums.entry(cell).or_insert((Vec3::ZERO, Vec3::ZERO, 0.0));
            e.0 += c_leaf;
            e.1 += mean;
            e.2 += 1.0;
        }
    }
    let mut seed_of: HashMap<IVec3, Seed> = HashMap::default();
    let mut frontier = Vec::new();
    let mut cells: Vec<_> = sums.into_iter().collect();
    // Deterministic order (hash map iteration order is not).
    cells.sort_by_key(|(c, _)| (c.z, c.y, c.x));
    for (cell, (sum_c, sum_n, k)) in cells {
        let Some(normal) = sum_n.try_normalize() else { continue };
        seed_of.insert(cell, Seed { center_leaf: sum_c / k, normal, edge: false });
        frontier.push(cell);
    }
    let edges: Vec<IVec3> =
        frontier.iter().copied().filter(|&c| is_edge(c, seed_of[&c].normal, &seed_of)).collect();
    for c in edges {
        if let Some(seed) = seed_of.get_mut(&c) {
            seed.edge = true;
        }
    }
    // Only a seed that is no edge makes rock, within `ROCK_REACH_CELLS` of itself, and which seed
    // claims a cell there depends only on cells within `ROCK_REACH_CELLS` of that cell: the flood
    // is kept to blocks of 8 cells around those seeds' blocks (8 >= twice the reach, so this is
    // exact). Sparse clouds (airborne scans at fine leaves) are almost all edges; flooding their
    // isolated seeds made (2 r + 1)^3 cells each for nothing.
    const BLOCK_SHIFT: i32 = 3;
    const _: () = assert!(1 << BLOCK_SHIFT >= 2 * ROCK_REACH_CELLS);
    let core: HashSet<IVec3> =
        seed_of.iter().filter(|(_, s)| !s.edge).map(|(c, _)| *c >> BLOCK_SHIFT).collect();
    let mut region: HashSet<IVec3> = HashSet::default();
    for b in &core {
        for dz in -1..=1 {
            for dy in -1..=1 {
                for dx in -1..=1 {
                    region.insert(*b + IVec3::new(dx, dy, dz));
                }
            }
        }
    }
    let in_region = |c: IVec3| region.contains(&(c >> BLOCK_SHIFT));
    frontier.retain(|&c| in_region(c));
    let cell_leaves = (1 << ROCK_LEVEL) as f32;
    let centre = |c: IVec3| (c.as_vec3() + Vec3::splat(0.5)) * cell_leaves;
    let mut rock: Vec<IVec3> = Vec::new();
    for _ in 0..ROCK_REACH_CELLS {
        // One layer: every unvisited neighbour of the frontier takes, of the seeds its frontier
        // neighbours carry, the one nearest to its centre (nearest-site propagation).
        let mut offered: HashMap<IVec3, (f32, Seed)> = HashMap::default();
        for &cell in &frontier {
            let seed = seed_of[&cell];
            for dz in -1..=1 {
                for dy in -1..=1 {
                    for dx in -1..=1 {
                        let next = cell + IVec3::new(dx, dy, dz);
                        if seed_of.contains_key(&next) || !in_region(next) {
                            continue;
                        }
                        let d = centre(next).distance_squared(seed.center_leaf);
                        let e = offered.entry(next).or_insert((f32::INFINITY, seed));
                        if d < e.0 {
                            *e = (d, seed);
                        }
                    }
                }
            }
        }
        let mut next_frontier: Vec<IVec3> = offered.keys().copied().collect();
        next_frontier.sort_by_key(|c| (c.z, c.y, c.x));
        for &cell in &next_frontier {
            let seed = offered[&cell].1;
            seed_of.insert(cell, seed);
            let offset = centre(cell) - seed.center_leaf;
            let depth = -offset.dot(seed.normal);
            let lateral = (offset + depth * seed.normal).length();
            if !seed.edge && depth > 0.0 && depth >= BEHIND_SLOPE * lateral {
                rock.push(cell);
            }
        }
        frontier = next_frontier;
    }
    rock
}

/// Rock cells grouped into bricks (global brick units, sorted z, y, x) with their 64 bits.
pub fn bricks(cells: &[IVec3]) -> Vec<(IVec3, u64)> {
    let mut map: BTreeMap<(i32, i32, i32), u64> = BTreeMap::new();
    for &c in cells {
        let b = c >> BRICK_SHIFT as i32;
        let l = c - (b << BRICK_SHIFT as i32);
        *map.entry((b.z, b.y, b.x)).or_insert(0) |= 1u64 << (l.x + 4 * (l.y + 4 * l.z));
    }
    map.into_iter().map(|((z, y, x), bits)| (IVec3::new(x, y, z), bits)).collect()
}

/// The rock a tile stores: of the rock classified from `context` (its leaves and its
/// neighbours' within [`CONTEXT_CELLS`] of it, leaf units of one frame), the cells within
/// `ROCK_REACH_CELLS` of the tile's cube (`origin_leaf`, `side_leaves` leaves on a side, both
/// multiples of a brick's 8 leaves), as bricks relative to the tile's origin.
pub(crate) fn tile_rock(origin_leaf: IVec3, side_leaves: i32, context: &[SurfaceLeaf]) -> Vec<RockBrick> {
    let brick_leaves = 1 << (ROCK_LEVEL + BRICK_SHIFT);
    debug_assert!(origin_leaf % brick_leaves == IVec3::ZERO && side_leaves % brick_leaves == 0);
    let lo = (origin_leaf >> ROCK_LEVEL as i32) - IVec3::splat(ROCK_REACH_CELLS);
    let hi =
        ((origin_leaf + IVec3::splat(side_leaves)) >> ROCK_LEVEL as i32) + IVec3::splat(ROCK_REACH_CELLS);
    let mine: Vec<IVec3> =
        classify(context).into_iter().filter(|c| c.cmpge(lo).all() && c.cmplt(hi).all()).collect();
    let origin_brick = origin_leaf / brick_leaves;
    bricks(&mine)
        .into_iter()
        .map(|(b, bits)| RockBrick {
            brick: (b - origin_brick).to_array(),
            reserved: 0,
            bits: [bits as u32, (bits >> 32) as u32],
        })
        .collect()
}

/// Whether point `p_leaf` (leaf units) lies within [`CONTEXT_CELLS`] of the tile at
/// `origin_leaf` with `side_leaves` leaves: the neighbours' leaves [`tile_rock`] needs.
pub(crate) fn in_context(origin_leaf: IVec3, side_leaves: i32, p_leaf: Vec3) -> bool {
    let margin = (CONTEXT_CELLS << ROCK_LEVEL) as f32;
    let lo = origin_leaf.as_vec3() - Vec3::splat(margin);
    let hi = (origin_leaf + IVec3::splat(side_leaves)).as_vec3() + Vec3::splat(margin);
    p_leaf.cmpge(lo).all() && p_leaf.cmplt(hi).all()
}
