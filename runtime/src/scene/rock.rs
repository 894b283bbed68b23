//! Rock behind the scanned surfaces, as the GPU reads it. The classification (which cells behind
//! a wall are rock, and why) is `grotto_levels::rock`: the packer stores each tile's rock
//! (format 1.1) and scenes without it are classified here at load. A cone whose axis enters a
//! rock cell stops there (shaders/rock.wgsl, `trace_cone`): what is hidden behind the walls it met
//! is taken to look like them, so closed caves keep their energy, and a cone that leaves the scene
//! through an opening keeps its transparency for the environment — no opacity threshold has to
//! tell a leak from an opening.
//!
//! Storage: the rock cells of the whole scene go into one hash table of 4x4x4-cell bricks
//! ([`RockTable`]), looked up by global cell coordinates, so its size follows the rock (a shell
//! `ROCK_REACH_CELLS` thick behind the surfaces), never the volume of a tile, and a cell beyond
//! every tile's cube (rock behind the outer walls) is stored once. Lookup cost does not depend on
//! the number of tiles.

use glam::{IVec3, Vec3};
pub use grotto_levels::rock::{BEHIND_SLOPE, BRICK_SHIFT, ROCK_LEVEL, ROCK_REACH_CELLS, SurfaceLeaf};

use crate::gpu::types::{LeafGpu, TileGpu};

/// Classifies rock around `leaves` (frame metres, leaves of `leaf_m`) into a [`RockTable`]
/// (`grotto_levels::rock::classify`, for scenes whose package stores no rock).
pub(crate) fn classify(leaf_m: f32, leaves: &[LeafGpu]) -> RockTable {
    let surface: Vec<SurfaceLeaf> = leaves
        .iter()
        .map(|l| SurfaceLeaf {
            // The cell's centre, as the packer classifies (a leaf's centre is its surface's).
            center_leaf: l.cell(leaf_m).as_vec3() + 0.5,
            normal_mean: Vec3::from_slice(&l.normal_mean[..3]),
        })
        .collect();
    RockTable::build(&grotto_levels::rock::classify(&surface))
}

/// Words before the first entry: capacity - 1 (capacity a power of two), the longest probe
/// sequence any stored brick needs, the number of bricks, 0.
pub(crate) const HEADER_WORDS: usize = 4;
/// Words per entry: brick x, y, z (global brick units, i32 bits), then the 64 rock bits (cell
/// `x + 4 (y + 4 z)` within the brick, low word first).
pub(crate) const ENTRY_WORDS: usize = 5;
/// Brick x of an empty slot; no brick reaches it (leaf coordinates stay within +-2^28).
pub(crate) const EMPTY_KEY: i32 = i32::MIN;

/// The hash of a brick coordinate, identical in shaders/hash.wgsl (`cell_hash`): each axis times a large
/// odd constant (Teschner et al. 2003), xor-ed, then murmur3's finaliser so neighbouring bricks
/// spread over the table.
pub(crate) fn brick_hash(b: IVec3) -> u32 {
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
    pub(crate) fn build(cells: &[IVec3]) -> Self {
        Self::from_bricks(grotto_levels::rock::bricks(cells))
    }

    /// The table of `bricks` (global brick units, 64 cell bits each); a brick listed more than
    /// once (stored by two tiles) holds the union of its bits.
    pub(crate) fn from_bricks(bricks: impl IntoIterator<Item = (IVec3, u64)>) -> Self {
        let mut merged: std::collections::BTreeMap<(i32, i32, i32), u64> = Default::default();
        for (b, bits) in bricks {
            *merged.entry((b.z, b.y, b.x)).or_insert(0) |= bits;
        }
        // Ordered (z, y, x), so the table is reproducible.
        let list: Vec<(IVec3, u64)> =
            merged.into_iter().map(|((z, y, x), bits)| (IVec3::new(x, y, z), bits)).collect();
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
    pub(crate) fn contains(&self, cell: IVec3) -> bool {
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

    /// The box of every stored brick, in leaf units: (min, max); `None` without rock.
    pub(crate) fn bounds_leaf(&self) -> Option<(Vec3, Vec3)> {
        let shift = (BRICK_SHIFT + ROCK_LEVEL) as i32;
        let entries = self.words.get(HEADER_WORDS..)?.chunks_exact(ENTRY_WORDS);
        let bricks = entries
            .filter(|e| e[0] != EMPTY_KEY as u32)
            .map(|e| IVec3::new(e[0] as i32, e[1] as i32, e[2] as i32));
        bricks.fold(None, |acc, b| {
            let (b_lo, b_hi) = ((b << shift).as_vec3(), ((b + 1) << shift).as_vec3());
            Some(acc.map_or((b_lo, b_hi), |(lo, hi): (Vec3, Vec3)| (lo.min(b_lo), hi.max(b_hi))))
        })
    }

    /// Bricks stored (the third header word).
    pub fn bricks(&self) -> u32 {
        self.words.get(2).copied().unwrap_or(0)
    }
}

/// Bytes the rock took as the dense per-tile bit grids it replaced (one bit per cell over each
/// tile and a margin of `ROCK_REACH_CELLS` cells): kept to report the saving (`grotto inspect
/// --gpu-memory`), not used to render.
pub(crate) fn dense_grid_bytes(tiles: &[TileGpu]) -> u64 {
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
