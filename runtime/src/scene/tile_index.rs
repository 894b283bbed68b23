//! Constant-time tile lookup: which tile's cube holds a leaf cell. A cone sample or a shadow probe
//! asks this for every corner it reads, so its cost must not grow with the number of tiles (the
//! linear scan it replaces did: a package of 180 tiles made every sample 180 tests).
//!
//! Tiles are power-of-two cubes of leaves. The packer cuts them from one pyramid anchored at a
//! fine cell, so a tile of depth `d` lies on the grid of cells `2^d` leaves wide counted from that
//! anchor; any tile of the largest depth shares the anchor's alignment at every smaller size. The
//! index is one open-addressing hash table (linear probing, load at most 1/2) keyed by (cell at a
//! depth, depth), one entry per tile; a lookup probes once per distinct tile depth (a bit mask in
//! the header: a handful in practice, at most 32), each probe bounded by the longest probe sequence
//! stored in the header. A tile that is not aligned to the anchor (hand-built scenes) is entered at
//! the largest depth at which it is, once per cell of that depth it covers.
//!
//! Written by hand for the same reason as the rock table (rock.rs): the GPU reads the words as
//! they are, so the layout is the project's own; shaders/svo.wgsl `find_tile` mirrors
//! [`TileIndex::find`].

use glam::IVec3;

use crate::error::{Error, Result};
use crate::gpu::types::TileGpu;
use crate::scene::rock::{brick_hash, free_slot};

/// Words before the first entry: capacity - 1 (capacity a power of two), the longest probe
/// sequence any entry needs, the mask of depths entries are keyed at, the entry count, the anchor
/// (x, y, z as i32 bits, global leaf units), 0.
pub(crate) const HEADER_WORDS: usize = 8;
/// Words per entry: cell x, y, z (at the entry's depth, counted from the anchor, i32 bits), the
/// depth, the tile's index.
pub(crate) const ENTRY_WORDS: usize = 5;
/// Cell x of an empty slot (no cell reaches it: leaf coordinates stay within +-2^28).
pub(crate) const EMPTY_KEY: i32 = i32::MIN;
/// Most entries an index may hold (tiles not aligned to the anchor take several): 2^22 entries is
/// 160 MiB of table at load 1/2, far beyond any package the packer writes (one entry per tile).
pub(crate) const MAX_ENTRIES: usize = 1 << 22;

/// Hash of a cell at `depth`, identical in shaders/svo.wgsl (`tile_hash`).
pub(crate) fn tile_hash(cell: IVec3, depth: u32) -> u32 {
    brick_hash(cell) ^ depth.wrapping_mul(0x9e37_79b9)
}

/// The lookup table the GPU reads (`words`), built from the tile list.
#[derive(Clone, Debug, Default, PartialEq, Eq)]
pub struct TileIndex {
    pub(crate) words: Vec<u32>,
}

impl TileIndex {
    /// The index of `tiles`, whose cubes must not overlap (two tiles at the same place and depth
    /// are refused; other overlaps find one of them). `scene` names the package in errors.
    pub fn build(scene: &str, tiles: &[TileGpu]) -> Result<Self> {
        let anchor =
            tiles.iter().max_by_key(|t| t.depth).map_or(IVec3::ZERO, |t| IVec3::from_array(t.origin_leaf));
        let mut entries: Vec<(IVec3, u32, u32)> = Vec::with_capacity(tiles.len());
        for (i, t) in tiles.iter().enumerate() {
            if t.depth > 28 {
                return Err(Error::Scene {
                    package: scene.into(),
                    problem: format!("tile {i} is 2^{} leaves wide (at most 2^28)", t.depth),
                });
            }
            let rel = IVec3::from_array(t.origin_leaf) - anchor;
            // The largest depth at which the tile's corner lies on the anchor's grid.
            let aligned = (rel.x | rel.y | rel.z | (1 << t.depth)).trailing_zeros().min(t.depth);
            let per_axis = 1i64 << (t.depth - aligned);
            // 3 * (depth - aligned) bits of entries: compared as exponents first (no overflow).
            if 3 * (t.depth - aligned) > MAX_ENTRIES.trailing_zeros()
                || entries.len() as i64 + per_axis.pow(3) > MAX_ENTRIES as i64
            {
                return Err(Error::Scene {
                    package: scene.into(),
                    problem: format!(
                        "tile {i} (depth {}) is not aligned to the other tiles' grid; indexing it \
                         would take more than {MAX_ENTRIES} entries",
                        t.depth
                    ),
                });
            }
            let base = rel >> aligned as i32;
            let n = per_axis as i32;
            for z in 0..n {
                for y in 0..n {
                    for x in 0..n {
                        entries.push((base + IVec3::new(x, y, z), aligned, i as u32));
                    }
                }
            }
        }
        let capacity = (2 * entries.len()).next_power_of_two().max(1);
        let mask = capacity - 1;
        let mut words = vec![0u32; HEADER_WORDS + capacity * ENTRY_WORDS];
        for e in 0..capacity {
            words[HEADER_WORDS + e * ENTRY_WORDS] = EMPTY_KEY as u32;
        }
        let (mut longest, mut depths) = (0u32, 0u32);
        for &(cell, depth, tile) in &entries {
            depths |= 1 << depth;
            let key = [cell.x as u32, cell.y as u32, cell.z as u32, depth];
            let (slot, probe) =
                free_slot(&words, HEADER_WORDS, ENTRY_WORDS, mask, tile_hash(cell, depth) as usize, &key)
                    .map_err(|taken| Error::Scene {
                        package: scene.into(),
                        problem: format!(
                            "tiles {} and {tile} overlap",
                            words[HEADER_WORDS + taken * ENTRY_WORDS + 4]
                        ),
                    })?;
            longest = longest.max(probe);
            let e = HEADER_WORDS + slot * ENTRY_WORDS;
            words[e..e + 4].copy_from_slice(&key);
            words[e + 4] = tile;
        }
        words[..HEADER_WORDS].copy_from_slice(&[
            mask as u32,
            longest,
            depths,
            entries.len() as u32,
            anchor.x as u32,
            anchor.y as u32,
            anchor.z as u32,
            0,
        ]);
        Ok(Self { words })
    }

    /// The tile whose cube holds leaf cell `v_leaf` (global leaf units): `find_tile` in
    /// shaders/svo.wgsl, as the tests check it.
    #[cfg(test)]
    fn find(&self, v_leaf: IVec3) -> Option<u32> {
        let w = &self.words;
        let header = w.get(..HEADER_WORDS)?;
        let (mask, longest, mut depths) = (header[0], header[1], header[2]);
        let anchor = IVec3::new(header[4] as i32, header[5] as i32, header[6] as i32);
        let rel = v_leaf.wrapping_sub(anchor);
        while depths != 0 {
            let d = depths.trailing_zeros();
            depths &= depths - 1;
            let cell = rel >> d as i32;
            let mut slot = tile_hash(cell, d) & mask;
            for _ in 0..=longest {
                let e = HEADER_WORDS + slot as usize * ENTRY_WORDS;
                let entry = w.get(e..e + ENTRY_WORDS)?;
                if entry[0] == EMPTY_KEY as u32 {
                    break;
                }
                if entry[..4] == [cell.x as u32, cell.y as u32, cell.z as u32, d] {
                    return Some(entry[4]);
                }
                slot = (slot + 1) & mask;
            }
        }
        None
    }

    /// Distinct depths a lookup probes.
    #[cfg(test)]
    fn depths_probed(&self) -> u32 {
        self.words.get(2).map_or(0, |d| d.count_ones())
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn tile(origin: [i32; 3], depth: u32) -> TileGpu {
        TileGpu { origin_leaf: origin, depth, ..Default::default() }
    }

    /// The scan the index replaces ([`crate::scene::data::SceneData::tile_of`]).
    fn linear(tiles: &[TileGpu], v: IVec3) -> Option<u32> {
        let scene = crate::scene::data::SceneData { tiles: tiles.to_vec(), ..Default::default() };
        scene.tile_of(v).map(|i| i as u32)
    }

    /// An adaptive tiling as the packer makes it: a pyramid anchored at `anchor`, tiles of depths
    /// 3..=5 cut where a pseudo-random occupancy says so, some cells left empty.
    fn pyramid(anchor: IVec3) -> Vec<TileGpu> {
        let mut tiles = Vec::new();
        let mut seed = 0x2545_f491_u32;
        let mut next = || {
            seed ^= seed << 13;
            seed ^= seed >> 17;
            seed ^= seed << 5;
            seed
        };
        for z in -2..2 {
            for y in -1..2 {
                for x in -3..3 {
                    let top = anchor + IVec3::new(x, y, z) * 32;
                    match next() % 4 {
                        0 => {}
                        1 => tiles.push(tile(top.to_array(), 5)),
                        _ => {
                            for c in 0..8 {
                                let o = top + IVec3::new(c & 1, (c >> 1) & 1, (c >> 2) & 1) * 16;
                                match next() % 3 {
                                    0 => {}
                                    1 => tiles.push(tile(o.to_array(), 4)),
                                    _ => {
                                        for g in 0..8 {
                                            if next() % 2 == 0 {
                                                let p = o + IVec3::new(g & 1, (g >> 1) & 1, (g >> 2) & 1) * 8;
                                                tiles.push(tile(p.to_array(), 3));
                                            }
                                        }
                                    }
                                }
                            }
                        }
                    }
                }
            }
        }
        tiles
    }

    #[test]
    fn finds_the_same_tile_as_a_linear_scan_everywhere() {
        // Anchored off the frame origin (the frame origin is the first tile's corner, not the
        // pyramid's), cells probed inside, on borders, and outside every tile.
        let tiles = pyramid(IVec3::new(-13, 7, 101));
        assert!(tiles.len() > 40, "{} tiles", tiles.len());
        let index = TileIndex::build("test", &tiles).unwrap();
        assert_eq!(index.depths_probed(), 3);
        let entries = index.words[3] as usize;
        assert_eq!(entries, tiles.len(), "aligned tiles take one entry each");
        for z in (-80..80).step_by(3) {
            for y in (-45..80).step_by(2) {
                for x in (-120..110).step_by(3) {
                    let v = IVec3::new(-13 + x, 7 + y, 101 + z);
                    assert_eq!(index.find(v), linear(&tiles, v), "cell {v}");
                }
            }
        }
    }

    #[test]
    fn unaligned_tiles_are_entered_cell_by_cell() {
        // A depth-3 tile shifted by 2 leaves against the depth-4 tile that sets the anchor.
        let tiles = [tile([0, 0, 0], 4), tile([18, 0, 0], 3), tile([-8, 3, 0], 2)];
        let index = TileIndex::build("test", &tiles).unwrap();
        assert_eq!(index.words[3], 1 + 4 * 4 * 4 + 4 * 4 * 4);
        for z in -4..20 {
            for y in -4..20 {
                for x in -12..30 {
                    let v = IVec3::new(x, y, z);
                    assert_eq!(index.find(v), linear(&tiles, v), "cell {v}");
                }
            }
        }
    }

    #[test]
    fn overlapping_tiles_and_empty_lists_are_handled() {
        let err = TileIndex::build("pkg.grotto", &[tile([0, 0, 0], 3), tile([0, 0, 0], 3)]).unwrap_err();
        assert!(err.to_string().contains("overlap"), "{err}");
        let empty = TileIndex::build("test", &[]).unwrap();
        assert_eq!(empty.find(IVec3::ZERO), None);
        // A tile too unaligned to index is refused, not a huge allocation.
        let err = TileIndex::build("pkg.grotto", &[tile([0, 0, 0], 20), tile([(1 << 20) + 1, 0, 0], 12)])
            .unwrap_err();
        assert!(err.to_string().contains("not aligned"), "{err}");
    }
}
