//! Rock behind the scanned surfaces. Scans are shells: the SVO holds the cave's walls and nothing
//! behind them, so a cone that crosses a wall at a coarse level sees it as partly transparent and
//! goes on through empty "rock" (VCT's thin-wall leak). Here every cell of 2x2x2 leaves near a
//! surface that holds no oriented leaf is classified as rock or air from the oriented surface
//! nearest to it (the cell lies behind it, against its mean normal: rock), the signed-distance test of Hoppe et al. 1992 on the
//! leaves' Toksvig mean normals, kept to cells roughly straight behind the surface (see
//! `BEHIND_SLOPE`) and away from the surface's edges (an opening's rim: beyond it is sky, not
//! rock); anything else stays air. A cone whose axis enters a rock cell stops there (shaders/rock.wgsl,
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
//!
//! Storage: the rock cells of the whole scene go into one hash table of 4x4x4-cell bricks
//! ([`RockTable`]), looked up by global cell coordinates, so its size follows the rock (a shell
//! `ROCK_REACH_CELLS` thick behind the surfaces), never the volume of a tile, and a cell beyond
//! every tile's cube (rock behind the outer walls) is stored once. Lookup cost does not depend on
//! the number of tiles.

// foldhash: the flood makes millions of lookups of small integer keys, where std's SipHash
// (DoS-resistant, slow) cost more than the flood itself.
use foldhash::{HashMap, HashSet};

use glam::{IVec3, Vec3};

use crate::gpu_types::{LeafGpu, TileGpu};

/// Rock cells are 2^ROCK_LEVEL leaves on a side.
pub const ROCK_LEVEL: u32 = 1;
/// How far (in cells, Chebyshev) from a surface cell the classification reaches; also the margin
/// of cells kept around each tile (`ROCK_MARGIN` in shaders/rock.wgsl).
pub const ROCK_REACH_CELLS: i32 = 4;
/// A cell is rock only if it lies behind its seed's surface within about 63 degrees of the inward
/// normal (depth >= this * lateral offset): beside an opening, the wall around it is the nearest
/// surface, and its plane extended across the opening must not turn the opening into rock.
pub const BEHIND_SLOPE: f32 = 0.5;

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

/// Classifies rock around `leaves` (frame metres, leaves of `leaf_m`) into a [`RockTable`].
pub fn classify(leaf_m: f32, leaves: &[LeafGpu]) -> RockTable {
    // Seeds: the mean position and Toksvig mean normal of the oriented leaves in each cell. Cells
    // whose leaves have no clear orientation (solid interiors, clutter) are flooded like empty
    // ones: solid matter behind a wall is rock as much as empty space is.
    let mut sums: HashMap<IVec3, (Vec3, Vec3, f32)> = HashMap::default();
    for l in leaves {
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
    RockTable::build(&rock)
}

/// Rock cells per brick side, as a shift: a brick is 4x4x4 cells, its 64 bits two words.
pub const BRICK_SHIFT: u32 = 2;
/// Words before the first entry: capacity - 1 (capacity a power of two), the longest probe
/// sequence any stored brick needs, the number of bricks, 0.
pub const HEADER_WORDS: usize = 4;
/// Words per entry: brick x, y, z (global brick units, i32 bits), then the 64 rock bits (cell
/// `x + 4 (y + 4 z)` within the brick, low word first).
pub const ENTRY_WORDS: usize = 5;
/// Brick x of an empty slot; no brick reaches it (leaf coordinates stay within +-2^28).
pub const EMPTY_KEY: i32 = i32::MIN;

/// The hash of a brick coordinate, identical in shaders/hash.wgsl (`cell_hash`): each axis times a large
/// odd constant (Teschner et al. 2003), xor-ed, then murmur3's finaliser so neighbouring bricks
/// spread over the table.
pub fn brick_hash(b: IVec3) -> u32 {
    let mut h = (b.x as u32).wrapping_mul(0x8da6_b343)
        ^ (b.y as u32).wrapping_mul(0xd816_3841)
        ^ (b.z as u32).wrapping_mul(0xcb1a_b31f);
    h ^= h >> 16;
    h = h.wrapping_mul(0x85eb_ca6b);
    h ^= h >> 13;
    h = h.wrapping_mul(0xc2b2_ae35);
    h ^ (h >> 16)
}

/// Linear probing in a table of `entry_words`-word entries after `header_words` header words,
/// whose empty slots start with [`EMPTY_KEY`] (the rock table and the tile index,
/// tile_index.rs): from slot `hash & mask`, the first empty slot and the probes it took, or
/// `Err(slot)` of an entry that starts with `key` already.
pub(crate) fn free_slot(
    words: &[u32],
    header_words: usize,
    entry_words: usize,
    mask: usize,
    hash: usize,
    key: &[u32],
) -> Result<(usize, u32), usize> {
    let mut slot = hash & mask;
    let mut probe = 0u32;
    loop {
        let e = header_words + slot * entry_words;
        if words[e] == EMPTY_KEY as u32 {
            return Ok((slot, probe));
        }
        if words[e..e + key.len()] == *key {
            return Err(slot);
        }
        slot = (slot + 1) & mask;
        probe += 1;
    }
}

/// Rock as the GPU reads it: an open-addressing hash table (linear probing, load at most 1/2) of
/// the bricks that hold rock. Its size follows the rock cells, which lie within
/// `ROCK_REACH_CELLS` of the scanned surfaces: it grows with the surface, not with the volume of
/// the tiles (a dense grid per tile did, and outgrew what adapters bind on sparse scans).
#[derive(Clone, Debug, Default, PartialEq, Eq)]
pub struct RockTable {
    pub words: Vec<u32>,
}

impl RockTable {
    /// The table of `cells` (global rock-cell units; repeats are fine).
    pub fn build(cells: &[IVec3]) -> Self {
        let mut bricks: HashMap<IVec3, u64> = HashMap::default();
        for &c in cells {
            let b = c >> BRICK_SHIFT as i32;
            let l = c - (b << BRICK_SHIFT as i32);
            *bricks.entry(b).or_insert(0) |= 1u64 << (l.x + 4 * (l.y + 4 * l.z));
        }
        let mut list: Vec<(IVec3, u64)> = bricks.into_iter().collect();
        // Deterministic order (hash map iteration order is not), so the table is reproducible.
        list.sort_by_key(|(b, _)| (b.z, b.y, b.x));
        let capacity = (2 * list.len()).next_power_of_two().max(1);
        let mask = capacity - 1;
        let mut words = vec![0u32; HEADER_WORDS + capacity * ENTRY_WORDS];
        for e in 0..capacity {
            words[HEADER_WORDS + e * ENTRY_WORDS] = EMPTY_KEY as u32;
        }
        let mut longest = 0u32;
        for &(b, bits) in &list {
            let key = [b.x as u32, b.y as u32, b.z as u32];
            // Bricks are unique (a map's keys): no slot holds this key yet.
            let (slot, probe) =
                free_slot(&words, HEADER_WORDS, ENTRY_WORDS, mask, brick_hash(b) as usize, &key)
                    .unwrap_or_default();
            longest = longest.max(probe);
            let e = HEADER_WORDS + slot * ENTRY_WORDS;
            words[e..e + ENTRY_WORDS].copy_from_slice(&[
                b.x as u32,
                b.y as u32,
                b.z as u32,
                bits as u32,
                (bits >> 32) as u32,
            ]);
        }
        words[..HEADER_WORDS].copy_from_slice(&[mask as u32, longest, list.len() as u32, 0]);
        Self { words }
    }

    /// Whether rock cell `cell` (global cell units) is rock: `in_rock` in shaders/rock.wgsl.
    pub fn contains(&self, cell: IVec3) -> bool {
        let words = &self.words;
        let (Some(&mask), Some(&longest)) = (words.first(), words.get(1)) else { return false };
        let b = cell >> BRICK_SHIFT as i32;
        let mut slot = brick_hash(b) & mask;
        for _ in 0..=longest {
            let e = HEADER_WORDS + slot as usize * ENTRY_WORDS;
            let Some(entry) = words.get(e..e + ENTRY_WORDS) else { return false };
            if entry[0] == EMPTY_KEY as u32 {
                return false;
            }
            if IVec3::new(entry[0] as i32, entry[1] as i32, entry[2] as i32) == b {
                let l = cell - (b << BRICK_SHIFT as i32);
                let bit = (l.x + 4 * (l.y + 4 * l.z)) as usize;
                return entry[3 + bit / 32] >> (bit % 32) & 1 == 1;
            }
            slot = (slot + 1) & mask;
        }
        false
    }

    /// Bricks stored (the third header word).
    pub fn bricks(&self) -> u32 {
        self.words.get(2).copied().unwrap_or(0)
    }
}

/// Bytes the rock took as the dense per-tile bit grids it replaced (one bit per cell over each
/// tile and a margin of `ROCK_REACH_CELLS` cells): kept to report the saving (`grotto inspect
/// --gpu-memory`), not used to render.
pub fn dense_grid_bytes(tiles: &[TileGpu]) -> u64 {
    tiles
        .iter()
        .filter(|t| t.depth >= ROCK_LEVEL)
        .map(|t| {
            let g = u64::from((1u32 << (t.depth - ROCK_LEVEL)) + 2 * ROCK_REACH_CELLS as u32);
            (g * g * g).div_ceil(32) * 4
        })
        .sum()
}

/// Whether leaf cell `v_leaf` (global leaf units) lies in a rock cell of `rock`; as `in_rock` in
/// shaders/rock.wgsl.
pub fn in_rock(rock: &RockTable, v_leaf: IVec3) -> bool {
    rock.contains(v_leaf >> ROCK_LEVEL as i32)
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn table_answers_exactly_the_cells_it_was_built_from() {
        // A shell of cells around a sphere crossing brick borders and negative coordinates, and
        // a few isolated far cells: every stored cell is found, every other cell near them not.
        let mut cells = Vec::new();
        for z in -12..12 {
            for y in -12..12 {
                for x in -12..12 {
                    let r2 = x * x + y * y + z * z;
                    if (64..=100).contains(&r2) {
                        cells.push(IVec3::new(x, y, z));
                    }
                }
            }
        }
        cells.push(IVec3::new(1 << 26, -(1 << 26), 7));
        cells.push(IVec3::new(-(1 << 26), 3, 1 << 26));
        let table = RockTable::build(&cells);
        let set: std::collections::HashSet<IVec3> = cells.iter().copied().collect();
        for z in -14..14 {
            for y in -14..14 {
                for x in -14..14 {
                    let c = IVec3::new(x, y, z);
                    assert_eq!(table.contains(c), set.contains(&c), "cell {c}");
                }
            }
        }
        for &c in &cells[cells.len() - 2..] {
            assert!(table.contains(c));
            assert!(!table.contains(c + IVec3::X));
        }
        // Load at most 1/2, so the table is at most twice the bricks, whatever the volume spanned.
        let bricks = table.bricks() as usize;
        let capacity = (table.words.len() - HEADER_WORDS) / ENTRY_WORDS;
        assert!(capacity <= 4 * bricks.max(1) && capacity >= 2 * bricks, "{capacity} for {bricks}");
    }

    #[test]
    fn empty_table_holds_nothing() {
        let table = RockTable::build(&[]);
        assert_eq!(table.words.len(), HEADER_WORDS + ENTRY_WORDS);
        assert!(!table.contains(IVec3::ZERO));
        assert!(!table.contains(IVec3::splat(i32::MIN)));
    }
}
