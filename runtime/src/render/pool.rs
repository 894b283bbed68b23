//! Fixed GPU pools for tile data. The renderer allocates its node, leaf and surfel buffers once,
//! at a capacity chosen from the GPU memory budget ([`PoolCaps`]), and keeps every resident tile
//! form (a tile at a level: [`TileKey`]) in one [`Slot`] of each pool for as long as it stays
//! resident. A change of residency then frees the slots of the forms that left, allocates slots
//! for the forms that arrived, and uploads only those; the tiles that stayed keep their place and
//! their light on the GPU, with no read-back.
//!
//! Slots are contiguous ranges (a tile's nodes index its own nodes and leaves by offset, and
//! propagation walks a tile's leaves as one range), allocated best-fit (`range-alloc`, the
//! allocator wgpu-hal uses). When the free space is enough but too fragmented for a new form, the
//! placement repacks: the forms that stayed are compacted toward each pool's start in the order
//! they lay, and the renderer moves their data and light there on the GPU, with no read-back
//! ([`Placement::moved`]); the new forms follow.
//!
//! Pure bookkeeping, no GPU, so the policy is unit-tested here.

use std::collections::HashMap;
use std::ops::Range;

use range_alloc::RangeAllocator;
use serde::Serialize;

use crate::error::{Error, Result};
use crate::gpu::types::{TileBufferBytes, TileGpu};
use crate::scene::data::SceneData;

/// Share of each pool residency leaves free when streaming, so a new tile form usually finds a
/// hole or the tail and the pools rarely need a repack: with none, residency fills every pool and
/// any fragmentation forces one (repacks per frame are in the fly-through tables of
/// docs/benchmarks.md).
pub(crate) const POOL_HEADROOM: f64 = 0.1;

pub(crate) use crate::scene::data::{TileKey, key};

/// Elements each pool holds.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq, Serialize)]
pub struct PoolCaps {
    /// Tile records (every tile of a package is held in some form, so this is the package's
    /// tile count when streaming).
    pub(crate) tiles: u64,
    pub(crate) nodes: u64,
    pub(crate) leaves: u64,
    pub(crate) surfels: u64,
}

impl PoolCaps {
    /// What `scene` uses.
    pub fn of(scene: &SceneData) -> Self {
        let counts = scene.counts();
        Self {
            tiles: scene.tiles.len() as u64,
            nodes: counts.nodes as u64,
            leaves: counts.leaves as u64,
            surfels: counts.surfels as u64,
        }
    }

    /// GPU bytes of pools this large (the formula residency counts with, [`TileBufferBytes`]; the
    /// tile records' pool holds at least one).
    pub fn bytes(&self, radiance_f16: bool) -> u64 {
        TileBufferBytes::of(self.tiles.max(1), self.nodes, self.leaves, self.surfels, radiance_f16).total()
    }

    /// These pools less `share` of each (nodes, leaves, surfels; tile records kept): what
    /// residency may fill when `share` is kept free ([`POOL_HEADROOM`]).
    pub(crate) fn less(&self, share: f64) -> Self {
        let keep = |n: u64| (n as f64 * (1.0 - share.clamp(0.0, 1.0))).floor() as u64;
        Self {
            tiles: self.tiles,
            nodes: keep(self.nodes),
            leaves: keep(self.leaves),
            surfels: keep(self.surfels),
        }
    }

    /// These pools, each grown to at least `need`'s.
    pub(crate) fn at_least(self, need: PoolCaps) -> Self {
        Self {
            tiles: self.tiles.max(need.tiles),
            nodes: self.nodes.max(need.nodes),
            leaves: self.leaves.max(need.leaves),
            surfels: self.surfels.max(need.surfels),
        }
    }

    /// Whether `used` fits in these pools.
    pub fn holds(&self, used: &PoolCaps) -> bool {
        used.tiles <= self.tiles
            && used.nodes <= self.nodes
            && used.leaves <= self.leaves
            && used.surfels <= self.surfels
    }

    /// Pools with `used`'s mix of nodes, leaves and surfels, grown in proportion until their bytes
    /// reach `budget_bytes`; never smaller than `used`. The mix of the first view's residency is
    /// the best guess of the mix of the next ones (a cave's tiles are alike), and residency keeps
    /// within each pool from then on (`residency::Budget::pools`).
    pub fn filling(used: PoolCaps, budget_bytes: u64, radiance_f16: bool) -> Self {
        let used_bytes = used.bytes(radiance_f16).max(1);
        let record = used.tiles * size_of::<TileGpu>() as u64;
        let scale =
            budget_bytes.saturating_sub(record) as f64 / used_bytes.saturating_sub(record).max(1) as f64;
        let grow = |n: u64| ((n as f64 * scale).floor() as u64).max(n);
        // Rounding each pool down keeps the sum within the budget; where `used` itself was over
        // (it never is: residency chose it within the budget), `used` wins.
        Self {
            tiles: used.tiles,
            nodes: grow(used.nodes),
            leaves: grow(used.leaves),
            surfels: grow(used.surfels),
        }
    }
}

impl PoolCaps {
    /// These pools shrunk in proportion until each buffer fits a binding of `binding_bytes` (the
    /// device's largest storage binding: WebGPU's default is 128 MiB), never below `used`: what
    /// does not fit then is the adapter's limit, which the renderer names.
    pub fn within_binding(self, used: PoolCaps, binding_bytes: u64, radiance_f16: bool) -> Self {
        let b = TileBufferBytes::of(self.tiles.max(1), self.nodes, self.leaves, self.surfels, radiance_f16);
        let largest = [b.nodes, b.leaves, b.leaf_light, b.faces, b.mip_order, b.surfels].into_iter().max();
        let largest = largest.unwrap_or(0);
        if largest <= binding_bytes {
            return self;
        }
        let scale = binding_bytes as f64 / largest as f64;
        let shrink = |n: u64, floor: u64| ((n as f64 * scale).floor() as u64).max(floor);
        Self {
            tiles: self.tiles,
            nodes: shrink(self.nodes, used.nodes),
            leaves: shrink(self.leaves, used.leaves),
            surfels: shrink(self.surfels, used.surfels),
        }
    }
}

/// Where one tile form lives in the pools.
#[derive(Clone, Debug, Default, PartialEq, Eq)]
pub(crate) struct Slot {
    pub(crate) nodes: Range<u32>,
    pub(crate) leaves: Range<u32>,
    pub(crate) surfels: Range<u32>,
}

impl Slot {
    /// Its range in pool 0 (nodes), 1 (leaves) or 2 (surfels).
    pub(crate) fn range(&self, pool: usize) -> &Range<u32> {
        match pool {
            0 => &self.nodes,
            1 => &self.leaves,
            _ => &self.surfels,
        }
    }

    fn range_mut(&mut self, pool: usize) -> &mut Range<u32> {
        match pool {
            0 => &mut self.nodes,
            1 => &mut self.leaves,
            _ => &mut self.surfels,
        }
    }
}

/// What [`Pools::place`] decided for a scene.
#[derive(Clone, Debug, Default)]
pub(crate) struct Placement {
    /// The scene's tiles in scene order, their offsets moved to their slots.
    pub(crate) tiles: Vec<TileGpu>,
    /// Each scene tile's slot.
    pub(crate) slots: Vec<Slot>,
    /// Each scene tile: it was resident before in this form and kept its slot (nothing to upload).
    pub(crate) kept: Vec<bool>,
    /// Each scene tile whose form stayed resident through a repack: its slot before (its data
    /// and light are moved on the GPU to its new slot).
    pub(crate) moved: Vec<Option<Slot>>,
    /// Every slot was reallocated (the free space was fragmented): the forms that stayed moved
    /// toward the pools' starts ([`Placement::moved`]), the new forms follow.
    pub(crate) repacked: bool,
    /// Slots freed (forms that left).
    pub(crate) freed: usize,
}

/// The three pools' allocators and the slot of every resident tile form.
#[derive(Debug)]
pub(crate) struct Pools {
    caps: PoolCaps,
    nodes: RangeAllocator<u32>,
    leaves: RangeAllocator<u32>,
    surfels: RangeAllocator<u32>,
    slots: HashMap<TileKey, Slot>,
    /// The next placement repacks whatever the free space ([`Pools::repack_next`]).
    repack_next: bool,
}

/// Ranges sorted and merged where they touch, empty ones dropped: one draw call a run.
pub(crate) fn merge_runs(mut r: Vec<Range<u32>>) -> Vec<Range<u32>> {
    r.retain(|r| !r.is_empty());
    r.sort_by_key(|r| r.start);
    let mut out: Vec<Range<u32>> = Vec::with_capacity(r.len());
    for x in r {
        match out.last_mut() {
            Some(last) if last.end == x.start => last.end = x.end,
            _ => out.push(x),
        }
    }
    out
}

impl Pools {
    /// Empty pools of `caps` elements (each at most `u32::MAX`: GPU indices are u32).
    pub(crate) fn new(caps: PoolCaps) -> Result<Self> {
        let cap = |what: &str, n: u64| {
            u32::try_from(n).map_err(|_| Error::Budget {
                what: format!("a pool of {n} {what} is over the 2^32 a GPU index can address"),
                hint: "lower --gpu-memory".into(),
            })
        };
        Ok(Self {
            caps,
            nodes: RangeAllocator::new(0..cap("nodes", caps.nodes)?),
            leaves: RangeAllocator::new(0..cap("leaves", caps.leaves)?),
            surfels: RangeAllocator::new(0..cap("surfels", caps.surfels)?),
            slots: HashMap::new(),
            repack_next: false,
        })
    }

    /// Makes the next [`Pools::place`] repack (compact every slot) even where the new forms fit
    /// the holes: to defragment on purpose, and for tests of the repack path.
    pub(crate) fn repack_next(&mut self) {
        self.repack_next = true;
    }

    pub(crate) fn caps(&self) -> PoolCaps {
        self.caps
    }

    /// The slot of every resident form.
    pub(crate) fn slots(&self) -> &HashMap<TileKey, Slot> {
        &self.slots
    }

    /// One past the highest leaf in use: the leaf passes dispatch over `0..leaf_end` (holes
    /// included; their results are never read).
    pub(crate) fn leaf_end(&self) -> u32 {
        self.slots.values().map(|s| s.leaves.end).max().unwrap_or(0)
    }

    /// The surfel ranges in use, merged where they touch, in order: what the splat passes draw.
    #[cfg(test)]
    fn surfel_runs(&self) -> Vec<Range<u32>> {
        merge_runs(self.slots.values().map(|s| s.surfels.clone()).collect())
    }

    fn alloc(a: &mut RangeAllocator<u32>, n: u32) -> Option<Range<u32>> {
        if n == 0 {
            return Some(0..0);
        }
        a.allocate_range(n).ok()
    }

    /// A slot of `n` nodes, `l` leaves and `s` surfels, or `None` (nothing taken) where one pool
    /// has no free range that long.
    fn alloc_slot(&mut self, (n, l, s): (u32, u32, u32)) -> Option<Slot> {
        let nodes = Self::alloc(&mut self.nodes, n)?;
        let Some(leaves) = Self::alloc(&mut self.leaves, l) else {
            self.free(&Slot { nodes, ..Default::default() });
            return None;
        };
        let Some(surfels) = Self::alloc(&mut self.surfels, s) else {
            self.free(&Slot { nodes, leaves, ..Default::default() });
            return None;
        };
        Some(Slot { nodes, leaves, surfels })
    }

    fn free(&mut self, s: &Slot) {
        for (a, r) in
            [(&mut self.nodes, &s.nodes), (&mut self.leaves, &s.leaves), (&mut self.surfels, &s.surfels)]
        {
            if !r.is_empty() {
                a.free_range(r.clone());
            }
        }
    }

    /// Gives every tile of `scene` a slot: the forms already resident keep theirs, the others
    /// get new ones, the forms that left are freed (`owners`: [`SceneData::surfel_owners`]). Pools that
    /// hold nothing yet are filled in scene order, so a scene placed once lies as it was loaded.
    /// An error when the scene needs more than the pools hold (residency keeps within them, so
    /// that is a bug, not a user's mistake).
    pub(crate) fn place(&mut self, scene: &SceneData, owners: &[Range<u32>]) -> Result<Placement> {
        let need = PoolCaps::of(scene);
        if !self.caps.holds(&need) {
            return Err(Error::Budget {
                what: format!("the scene needs {need:?} pool elements, over the pools' {:?}", self.caps),
                hint: "raise --memory or --gpu-memory (in a page: budget= or gpu_memory_mb=)".into(),
            });
        }
        let keys: Vec<TileKey> = scene.tiles.iter().map(key).collect();
        let wanted: HashMap<TileKey, usize> = keys.iter().enumerate().map(|(i, k)| (*k, i)).collect();
        // Free what left (or what a same-keyed tile no longer matches).
        let mut freed = 0;
        let gone: Vec<TileKey> = self
            .slots
            .iter()
            .filter(|(k, s)| {
                wanted.get(*k).is_none_or(|&t| {
                    let (n, l, su) = scene.tile_elements(owners, t);
                    (s.nodes.len() as u32, s.leaves.len() as u32, s.surfels.len() as u32) != (n, l, su)
                })
            })
            .map(|(k, _)| *k)
            .collect();
        for k in gone {
            if let Some(s) = self.slots.remove(&k) {
                self.free(&s);
                freed += 1;
            }
        }
        let mut kept: Vec<bool> = keys.iter().map(|k| self.slots.contains_key(k)).collect();
        // The new forms, largest first (best fit packs better that way).
        let mut new: Vec<usize> = (0..keys.len()).filter(|&t| !kept[t]).collect();
        if !self.slots.is_empty() {
            new.sort_by_key(|&t| {
                let (n, l, s) = scene.tile_elements(owners, t);
                std::cmp::Reverse((l, n, s))
            });
        }
        let mut repacked = std::mem::take(&mut self.repack_next) && !self.slots.is_empty();
        for &t in &new {
            if repacked {
                break;
            }
            match self.alloc_slot(scene.tile_elements(owners, t)) {
                Some(slot) => {
                    self.slots.insert(keys[t], slot);
                }
                None => {
                    repacked = true;
                    break;
                }
            }
        }
        let mut moved: Vec<Option<Slot>> = vec![None; keys.len()];
        if repacked {
            moved = self.repack(scene, owners, &keys, &kept)?;
            kept.fill(false);
        }
        let slots: Vec<Slot> = keys.iter().map(|k| self.slots[k].clone()).collect();
        let tiles = scene
            .tiles
            .iter()
            .zip(&slots)
            .map(|(t, s)| TileGpu { node_offset: s.nodes.start, leaf_offset: s.leaves.start, ..*t })
            .collect();
        Ok(Placement { tiles, slots, kept, moved, repacked, freed })
    }

    /// Starts over (the free space was fragmented; the scene fits: checked by the caller). In
    /// each pool the forms that stay (`stay`, per scene tile) come first, in the order they lay,
    /// so each moves toward the pool's start and the GPU can move them in place, front to back
    /// (`gpu::upload::move_within`); the new forms follow in scene order. Returns, per scene
    /// tile, the slot a form that stayed had before.
    fn repack(
        &mut self,
        scene: &SceneData,
        owners: &[Range<u32>],
        keys: &[TileKey],
        stay: &[bool],
    ) -> Result<Vec<Option<Slot>>> {
        let old = std::mem::take(&mut self.slots);
        *self = Self::new(self.caps)?;
        let before: Vec<Option<Slot>> =
            keys.iter().zip(stay).map(|(k, &s)| if s { old.get(k).cloned() } else { None }).collect();
        let mut slots: Vec<Slot> = vec![Slot::default(); keys.len()];
        let lost =
            || Error::Internal { what: "pools", message: "a checked scene did not fit empty pools".into() };
        for pool in 0..3 {
            let mut order: Vec<usize> = (0..keys.len()).filter(|&t| before[t].is_some()).collect();
            order.sort_by_key(|&t| before[t].as_ref().map_or(0, |s| s.range(pool).start));
            let rest = (0..keys.len()).filter(|&t| before[t].is_none());
            for t in order.into_iter().chain(rest) {
                let (n, l, su) = scene.tile_elements(owners, t);
                let (allocator, len) = match pool {
                    0 => (&mut self.nodes, n),
                    1 => (&mut self.leaves, l),
                    _ => (&mut self.surfels, su),
                };
                *slots[t].range_mut(pool) = Self::alloc(allocator, len).ok_or_else(lost)?;
            }
        }
        for (k, slot) in keys.iter().zip(slots) {
            self.slots.insert(*k, slot);
        }
        Ok(before)
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    /// A scene of tiles with these (x, nodes, leaves, surfels), at distinct places.
    fn scene(tiles: &[(i32, u32, u32, u32)]) -> SceneData {
        let mut s = SceneData::default();
        for &(x, n, l, su) in tiles {
            let (node_offset, leaf_offset) = (s.nodes.len() as u32, s.leaves.len() as u32);
            s.nodes.resize(s.nodes.len() + n as usize, Default::default());
            s.leaves.resize(s.leaves.len() + l as usize, Default::default());
            let first = s.surfels.len() as u32;
            s.surfels.resize(s.surfels.len() + su as usize, Default::default());
            s.tile_surfels.push(first..first + su);
            s.tiles.push(TileGpu {
                origin_leaf: [x, 0, 0],
                depth: 4,
                node_offset,
                leaf_offset,
                node_count: n,
                leaf_count: l,
                leaf_lod: 0,
                pad: [0; 3],
            });
        }
        s
    }

    fn place(p: &mut Pools, s: &SceneData) -> Result<Placement> {
        p.place(s, &s.surfel_owners().0)
    }

    fn caps(n: u64) -> PoolCaps {
        PoolCaps { tiles: 8, nodes: n, leaves: n, surfels: n }
    }

    /// No two resident slots share an element of any pool, and all lie within the caps.
    fn sound(p: &Pools) {
        let all: Vec<&Slot> = p.slots.values().collect();
        type Field = fn(&Slot) -> Range<u32>;
        let pools: [(Field, u64); 3] = [
            (|s| s.nodes.clone(), p.caps.nodes),
            (|s| s.leaves.clone(), p.caps.leaves),
            (|s| s.surfels.clone(), p.caps.surfels),
        ];
        for (get, cap) in pools {
            let mut r: Vec<Range<u32>> = all.iter().map(|s| get(s)).filter(|r| !r.is_empty()).collect();
            r.sort_by_key(|r| r.start);
            for w in r.windows(2) {
                assert!(w[0].end <= w[1].start, "{:?} overlaps {:?}", w[0], w[1]);
            }
            assert!(r.last().is_none_or(|r| u64::from(r.end) <= cap));
        }
    }

    #[test]
    fn a_first_scene_lies_as_loaded() {
        let s = scene(&[(0, 3, 2, 5), (1, 4, 3, 0), (2, 1, 1, 1)]);
        let mut p = Pools::new(PoolCaps::of(&s)).unwrap();
        let placed = place(&mut p, &s).unwrap();
        assert_eq!(placed.tiles, s.tiles, "fresh pools are filled in scene order");
        assert_eq!(placed.kept, vec![false; 3], "every tile is uploaded");
        assert_eq!(p.leaf_end(), 6);
        assert_eq!(p.surfel_runs(), vec![0..6]);
        sound(&p);
    }

    #[test]
    fn tiles_that_stay_keep_their_slots_and_only_new_ones_upload() {
        let a = scene(&[(0, 3, 2, 5), (1, 4, 3, 2), (2, 1, 1, 1)]);
        let mut p = Pools::new(caps(20)).unwrap();
        place(&mut p, &a).unwrap();
        let before = p.slots().clone();
        // Tile 1 leaves, tile 3 arrives, tiles 0 and 2 stay.
        let b = scene(&[(0, 3, 2, 5), (2, 1, 1, 1), (3, 6, 5, 4)]);
        let placed = place(&mut p, &b).unwrap();
        assert!(!placed.repacked);
        assert_eq!(placed.kept, vec![true, true, false]);
        assert_eq!(placed.freed, 1);
        for k in [key(&b.tiles[0]), key(&b.tiles[1])] {
            assert_eq!(p.slots()[&k], before[&k], "a tile that stays keeps its slot");
        }
        sound(&p);
        // The same place at another level is another form: placed anew.
        let mut c = b.clone();
        c.tiles[0].leaf_lod = 3;
        let placed = place(&mut p, &c).unwrap();
        assert_eq!(placed.kept, vec![false, true, true]);
        sound(&p);
        assert_eq!(p.surfel_runs().iter().map(|r| r.len()).sum::<usize>(), 10);
    }

    #[test]
    fn holes_are_reused_and_a_fragmented_pool_repacks() {
        let mut p = Pools::new(caps(6)).unwrap();
        // 2 + 2 + 2 in order; the first and last leave: two holes of 2.
        place(&mut p, &scene(&[(0, 2, 2, 2), (1, 2, 2, 2), (2, 2, 2, 2)])).unwrap();
        assert_eq!(p.slots()[&([1, 0, 0], 4, 0)].leaves, 2..4);
        // Two tiles of 2 fit the holes: no repack, the middle tile stays.
        let placed = place(&mut p, &scene(&[(1, 2, 2, 2), (3, 2, 2, 2), (4, 2, 2, 2)])).unwrap();
        assert!(!placed.repacked);
        assert_eq!(placed.kept, vec![true, false, false]);
        sound(&p);
        // Tiles 3 and 4 leave; one of 4 arrives: 4 free in two holes of 2 -> repack.
        let placed = place(&mut p, &scene(&[(1, 2, 2, 2), (5, 4, 4, 4)])).unwrap();
        assert!(placed.repacked, "4 leaves in two holes of 2 need a repack");
        assert_eq!(placed.kept, vec![false, false]);
        assert_eq!(p.leaf_end(), 6);
        sound(&p);
        // The tile that stayed moves to the start, where the GPU can move it in place; the new
        // one follows.
        let was = placed.moved[0].clone().expect("the tile that stayed is moved, not uploaded");
        assert_eq!(was.leaves, 2..4);
        assert_eq!(placed.slots[0].leaves, 0..2);
        assert_eq!(placed.moved[1], None);
        assert_eq!(placed.slots[1].leaves, 2..6);
    }

    #[test]
    fn a_repack_moves_every_form_that_stays_toward_the_start_in_the_order_they_lay() {
        let mut p = Pools::new(caps(40)).unwrap();
        // Five tiles of different sizes in each pool.
        let first = scene(&[(0, 3, 5, 1), (1, 4, 2, 6), (2, 2, 3, 2), (3, 5, 4, 3), (4, 1, 1, 1)]);
        place(&mut p, &first).unwrap();
        p.repack_next();
        // Tiles 1 and 3 leave; 5 arrives; 4, 0 and 2 stay, listed in another order.
        let next = scene(&[(4, 1, 1, 1), (5, 6, 6, 6), (0, 3, 5, 1), (2, 2, 3, 2)]);
        let placed = place(&mut p, &next).unwrap();
        assert!(placed.repacked);
        sound(&p);
        let stayed: Vec<usize> = (0..4).filter(|&t| placed.moved[t].is_some()).collect();
        assert_eq!(stayed, vec![0, 2, 3]);
        for pool in 0..3 {
            // (start before, range now), in the order the forms lay before.
            let mut moves: Vec<(u32, Range<u32>)> = stayed
                .iter()
                .map(|&t| {
                    (placed.moved[t].as_ref().unwrap().range(pool).start, placed.slots[t].range(pool).clone())
                })
                .collect();
            moves.sort_by_key(|m| m.0);
            let mut end = 0;
            for (from, to) in moves {
                assert!(to.start <= from, "pool {pool}: a form moves toward the start ({from} -> {to:?})");
                assert_eq!(to.start, end, "pool {pool}: packed in the order they lay");
                end = to.end;
            }
        }
    }

    #[test]
    fn a_scene_over_the_pools_is_refused_and_changes_nothing() {
        let mut p = Pools::new(caps(10)).unwrap();
        place(&mut p, &scene(&[(0, 4, 4, 4)])).unwrap();
        let before = p.slots().clone();
        let err = place(&mut p, &scene(&[(0, 4, 4, 4), (8, 7, 7, 7)])).unwrap_err();
        assert!(err.to_string().contains("pool"), "{err}");
        assert_eq!(p.slots(), &before);
        let err = Pools::new(PoolCaps { leaves: 1 << 33, ..caps(1) }).unwrap_err();
        assert!(err.to_string().contains("2^32"), "{err}");
    }

    #[test]
    fn surfels_of_a_hand_made_scene_belong_to_its_first_tile() {
        let mut s = scene(&[(0, 1, 1, 3), (1, 1, 1, 2)]);
        assert_eq!(s.surfel_owners(), (vec![0..3, 3..5], true));
        s.tile_surfels.clear();
        assert_eq!(s.surfel_owners(), (vec![0..5, 5..5], false));
    }

    #[test]
    fn pools_fill_the_budget_in_the_used_mix() {
        let used = PoolCaps { tiles: 10, nodes: 1000, leaves: 500, surfels: 2000 };
        let used_bytes = used.bytes(false);
        let caps = PoolCaps::filling(used, 3 * used_bytes, false);
        assert!(caps.bytes(false) <= 3 * used_bytes);
        assert!(caps.bytes(false) > 3 * used_bytes - 3 * used_bytes / 100);
        assert!(caps.holds(&used));
        assert_eq!(caps.tiles, 10);
        // Over the budget already: the used counts, not less.
        assert_eq!(PoolCaps::filling(used, used_bytes / 2, false), used);
    }

    #[test]
    fn pools_shrink_in_the_used_mix_to_fit_a_binding_and_never_below_what_is_used() {
        let used = PoolCaps { tiles: 10, nodes: 1000, leaves: 500, surfels: 2000 };
        let big = PoolCaps::filling(used, 1 << 30, false);
        let largest = |c: PoolCaps| {
            let b = TileBufferBytes::of(c.tiles, c.nodes, c.leaves, c.surfels, false);
            [b.nodes, b.leaves, b.leaf_light, b.faces, b.mip_order, b.surfels].into_iter().max().unwrap()
        };
        assert!(largest(big) > 128 << 20);
        let fit = big.within_binding(used, 128 << 20, false);
        assert!(largest(fit) <= 128 << 20 && largest(fit) > 127 << 20, "{fit:?}");
        assert!(fit.holds(&used) && big.holds(&fit));
        // The mix stays: surfels to nodes as before, within rounding.
        let ratio = |c: PoolCaps| c.surfels as f64 / c.nodes as f64;
        assert!((ratio(fit) - ratio(big)).abs() < 1e-3 * ratio(big));
        // Already within: unchanged; a binding smaller than what is used: the used counts.
        assert_eq!(fit.within_binding(used, 128 << 20, false), fit);
        assert_eq!(big.within_binding(used, 1024, false), PoolCaps { tiles: 10, ..used });
    }
}
