//! Rock behind the scanned surfaces. Scans are shells: the SVO holds the cave's walls and nothing
//! behind them, so a cone that crosses a wall at a coarse level sees it as partly transparent and
//! goes on through empty "rock" (VCT's thin-wall leak). Here every cell of 2x2x2 leaves near a
//! surface that holds no oriented leaf is classified as rock or air from the oriented surface
//! nearest to it (the cell lies behind it, against its mean normal: rock), the signed-distance test of Hoppe et al. 1992 on the
//! leaves' Toksvig mean normals, kept to cells roughly straight behind the surface (see
//! `BEHIND_SLOPE`) and away from the surface's edges (an opening's rim: beyond it is sky, not
//! rock); anything else stays air. A cone whose axis enters a rock cell stops there (common.wgsl,
//! `trace_cone`): what is hidden behind the walls it met is taken to look like them, so closed caves
//! keep their energy, and a cone that leaves the scene through an opening keeps its transparency
//! for the environment — no opacity threshold has to tell a leak from an opening.
//!
//! The nearest surface is found by a breadth-first flood over cells from all surface cells at once
//! (26-neighbourhood, at most `ROCK_REACH_CELLS` layers): each empty cell takes, of the seeds its
//! neighbours in the previous layer carry, the one nearest to it (nearest-site propagation, as in
//! vector distance transforms). Cells further from every surface stay unclassified (air): a cone
//! leaking through a wall enters rock right behind it, within reach.
//!
//! Written by hand: a multi-source flood over a sparse cell set with per-cell seeds is a few
//! lines over a hash map; a kd-tree query per cell would touch every cell of every tile.

use std::collections::HashMap;

use glam::{IVec3, Vec3};

use crate::scene_data::SceneData;

/// Rock cells are 2^ROCK_LEVEL leaves on a side.
pub const ROCK_LEVEL: u32 = 1;
/// How far (in cells, Chebyshev) from a surface cell the classification reaches; also the margin
/// of cells kept around each tile (`ROCK_MARGIN` in common.wgsl).
pub const ROCK_REACH_CELLS: i32 = 4;
/// A cell is rock only if it lies behind its seed's surface within about 63 degrees of the inward
/// normal (depth >= this * lateral offset): beside an opening, the wall around it is the nearest
/// surface, and its plane extended across the opening must not turn the opening into rock.
pub const BEHIND_SLOPE: f32 = 0.5;
/// `TileGpu::rock_offset` of a tile without rock bits.
pub const NO_ROCK: u32 = u32::MAX;

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

/// Classifies rock and stores it as one bit per cell for each tile of `scene` (tile-local x fastest,
/// then y, then z), setting each tile's `rock_offset` into `scene.rock_words`.
pub fn classify(scene: &mut SceneData) {
    let leaf_m = scene.leaf_size_m;
    // Seeds: the mean position and Toksvig mean normal of the oriented leaves in each cell. Cells
    // whose leaves have no clear orientation (solid interiors, clutter) are flooded like empty
    // ones: solid matter behind a wall is rock as much as empty space is.
    let mut sums: HashMap<IVec3, (Vec3, Vec3, f32)> = HashMap::new();
    for l in &scene.leaves {
        let c_leaf = Vec3::from_slice(&l.center_m[..3]) / leaf_m;
        let cell = c_leaf.floor().as_ivec3() >> ROCK_LEVEL as i32;
        let mean = Vec3::from_slice(&l.normal_mean[..3]);
        if mean.length() > 0.2 {
            let e = sums.entry(cell).or_insert((Vec3::ZERO, Vec3::ZERO, 0.0));
            e.0 += c_leaf;
            e.1 += mean;
            e.2 += 1.0;
        }
    }
    let mut seed_of: HashMap<IVec3, Seed> = HashMap::new();
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
    let cell_leaves = (1 << ROCK_LEVEL) as f32;
    let centre = |c: IVec3| (c.as_vec3() + Vec3::splat(0.5)) * cell_leaves;
    let mut rock: Vec<IVec3> = Vec::new();
    for _ in 0..ROCK_REACH_CELLS {
        // One layer: every unvisited neighbour of the frontier takes, of the seeds its frontier
        // neighbours carry, the one nearest to its centre (nearest-site propagation).
        let mut offered: HashMap<IVec3, (f32, Seed)> = HashMap::new();
        for &cell in &frontier {
            let seed = seed_of[&cell];
            for dz in -1..=1 {
                for dy in -1..=1 {
                    for dx in -1..=1 {
                        let next = cell + IVec3::new(dx, dy, dz);
                        if seed_of.contains_key(&next) {
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
    scene.rock_words.clear();
    for t in &mut scene.tiles {
        if t.depth < ROCK_LEVEL {
            t.rock_offset = NO_ROCK;
            continue;
        }
        t.rock_offset = scene.rock_words.len() as u32;
        let g = u64::from(grid_side(t.depth));
        scene.rock_words.resize(scene.rock_words.len() + (g * g * g).div_ceil(32) as usize, 0);
    }
    for cell in rock {
        // A cell inside a tile is stored there; one outside every tile (rock beyond the scene's
        // bounds, where thin outer walls would otherwise leak) in every margin that holds it.
        let holders: Vec<usize> = match scene.tile_of(cell << ROCK_LEVEL as i32) {
            Some(t) => vec![t],
            None => (0..scene.tiles.len()).collect(),
        };
        for t in holders {
            let tile = scene.tiles[t];
            if let Some(bit) = bit_index(&tile, cell) {
                scene.rock_words[(tile.rock_offset + bit / 32) as usize] |= 1 << (bit % 32);
            }
        }
    }
}

/// Cells per side of a tile's rock grid: the tile's cells plus `ROCK_REACH_CELLS` on each side.
fn grid_side(depth: u32) -> u32 {
    (1u32 << (depth - ROCK_LEVEL)) + 2 * ROCK_REACH_CELLS as u32
}

/// Bit of rock cell `cell` (global cell units) in `tile`'s grid, if the grid holds it.
fn bit_index(tile: &crate::gpu_types::TileGpu, cell: IVec3) -> Option<u32> {
    if tile.rock_offset == NO_ROCK {
        return None;
    }
    let g = grid_side(tile.depth) as i32;
    let c =
        cell - (IVec3::from_array(tile.origin_leaf) >> ROCK_LEVEL as i32) + IVec3::splat(ROCK_REACH_CELLS);
    if c.cmplt(IVec3::ZERO).any() || c.cmpge(IVec3::splat(g)).any() {
        return None;
    }
    Some((c.x + g * (c.y + g * c.z)) as u32)
}

/// Whether leaf cell `v_leaf` (global leaf units) lies in a rock cell; as `in_rock` in common.wgsl:
/// the tile holding it decides, or outside every tile the first tile whose margin holds it.
pub fn in_rock(scene: &SceneData, v_leaf: IVec3) -> bool {
    let cell = v_leaf >> ROCK_LEVEL as i32;
    let test = |tile: &crate::gpu_types::TileGpu| {
        bit_index(tile, cell)
            .map(|bit| scene.rock_words[(tile.rock_offset + bit / 32) as usize] >> (bit % 32) & 1 == 1)
    };
    match scene.tile_of(v_leaf) {
        Some(t) => test(&scene.tiles[t]).unwrap_or(false),
        None => scene.tiles.iter().find_map(test).unwrap_or(false),
    }
}
