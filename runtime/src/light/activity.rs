//! Light work only where something changed: which tiles the next propagation bounce updates, and
//! why.
//!
//! A bounce updates the leaves of the *active* tiles only (propagate.wgsl reads the active-leaf
//! list) and records each tile's largest relative change. A tile stays active while its own light
//! or a touching tile's light changed by more than the convergence tolerance in the last bounce;
//! a tile whose light carried over from the previous set of tiles starts inactive unless it
//! touches a tile that is new. Light reaches further than a touching tile in one bounce (a cone
//! runs down a corridor), so "nothing active" is not yet convergence: it triggers one bounce over
//! every tile, and only a bounce over every tile that changes no leaf by more than the tolerance
//! ends the work. The stopping test is therefore the batch render's, and the fixed point the same.

use std::collections::BTreeMap;

use serde::Serialize;

use crate::gpu::types::{ActiveTile, TileGpu};

/// Why a bounce updates a tile.
#[derive(Clone, Copy, Debug, PartialEq, Eq, PartialOrd, Ord, Hash, Serialize)]
#[serde(rename_all = "snake_case")]
pub enum Why {
    /// The renderer has no light yet (every tile).
    Start,
    /// The lights changed (every tile).
    LightsChanged,
    /// A light edit changed the tile's direct light (light/edit.rs).
    LightEdited,
    /// The tile was not resident in this form before: its light starts from darkness.
    New,
    /// The tile touches a new tile.
    BesideNew,
    /// The tile's own light changed by more than the tolerance in the last bounce.
    Changed,
    /// The tile touches a tile whose light changed by more than the tolerance.
    BesideChanged,
    /// No tile changed where the last bounce looked: one bounce over every tile checks the rest.
    Verify,
}

impl Why {
    pub(crate) fn describe(self) -> &'static str {
        match self {
            Why::Start => "no light yet",
            Why::LightsChanged => "lights changed",
            Why::LightEdited => "direct light changed by an edit",
            Why::New => "new",
            Why::BesideNew => "beside a new tile",
            Why::Changed => "still changing",
            Why::BesideChanged => "beside a changing tile",
            Why::Verify => "convergence check over every tile",
        }
    }
}

/// What one propagation bounce updated.
#[derive(Clone, Debug, PartialEq, Serialize)]
pub struct BounceWork {
    /// Tiles updated, and of them how many for each reason.
    pub tiles: usize,
    /// Tiles in the scene.
    pub of_tiles: usize,
    pub why: BTreeMap<Why, usize>,
    pub leaves: u64,
    /// The bounce covered every tile (its change is the batch render's stopping test).
    pub every_tile: bool,
    /// Tiles updated whose largest relative change exceeded the tolerance.
    pub changed: usize,
    /// Largest relative change of any updated leaf.
    pub max_change: f32,
    /// Scene tile indices updated, when they are few enough to list (`--explain`).
    pub tile_list: Option<Vec<u32>>,
}

/// Tiles listed by index in a [`BounceWork`] (more are only counted).
pub(crate) const LISTED_TILES: usize = 24;

/// Per-tile propagation state of one scene (the renderer's tiles, in their order).
#[derive(Clone, Debug)]
pub(crate) struct TileActivity {
    /// `leaf_offset`, `leaf_count` of each tile.
    leaves: Vec<(u32, u32)>,
    /// Each tile form's place and level (origin leaf, depth, leaf level): which tile is which
    /// across a change of tiles.
    forms: Vec<([i32; 3], u32, u32)>,
    /// Tiles whose boxes touch (share a face, edge or corner) or overlap, by tile.
    neighbours: Vec<Vec<u32>>,
    /// Why the next bounce updates each tile (`None`: it does not).
    next: Vec<Option<Why>>,
    /// During a light edit in place: `next` as it was before (activity.rs `begin_edit`).
    before_edit: Option<Vec<Option<Why>>>,
}

impl TileActivity {
    /// Every tile active (`Why::Start`).
    pub(crate) fn new(tiles: &[TileGpu]) -> Self {
        let leaves = tiles.iter().map(|t| (t.leaf_offset, t.leaf_count)).collect();
        let forms = tiles.iter().map(|t| (t.origin_leaf, t.depth, t.leaf_lod)).collect();
        let next = vec![Some(Why::Start); tiles.len()];
        Self { leaves, forms, neighbours: touching(tiles), next, before_edit: None }
    }

    /// The activity of `tiles` after a change from this one, where `kept[t]` says tile `t` kept
    /// its light ([`TileActivity::seed`]). A tile still new here, whose light no bounce has
    /// spread since it arrived, counts as new there too: a change of tiles written in steps runs
    /// no bounce between them, and must leave the light work a change written whole leaves.
    pub(crate) fn after_change(&self, tiles: &[TileGpu], kept: &[bool]) -> Self {
        let still_new: std::collections::HashSet<&([i32; 3], u32, u32)> = (self.forms.iter())
            .zip(&self.next)
            .filter(|(_, why)| **why == Some(Why::New))
            .map(|(f, _)| f)
            .collect();
        let kept: Vec<bool> = (tiles.iter())
            .zip(kept)
            .map(|(t, &k)| k && !still_new.contains(&(t.origin_leaf, t.depth, t.leaf_lod)))
            .collect();
        let mut next = Self::new(tiles);
        next.seed(&kept);
        next
    }

    /// Every tile active for `why` (an edit under way is forgotten: everything runs).
    pub(crate) fn all(&mut self, why: Why) {
        self.next.fill(Some(why));
        self.before_edit = None;
    }

    /// After a reload: `carried[t]` says tile `t` kept its light. The others are new, and the
    /// tiles touching them follow; a tile that kept its light and touches nothing new waits.
    pub(crate) fn seed(&mut self, carried: &[bool]) {
        self.next.fill(None);
        for (t, &kept) in carried.iter().enumerate().take(self.next.len()) {
            if !kept {
                self.next[t] = Some(Why::New);
                for &n in &self.neighbours[t] {
                    let n = n as usize;
                    if carried.get(n).copied().unwrap_or(false) {
                        self.next[n] = Some(Why::BesideNew);
                    }
                }
            }
        }
        if self.pending_tiles() == 0 {
            // Nothing is new, yet the scene differs: one bounce over every tile decides.
            self.all(Why::Verify);
        }
    }

    /// A light edit in place: the tiles `reached[t]` names (an edited light's old or new light
    /// reaches them) become the active tiles inject redoes; the tiles pending before (still
    /// changing) wait for [`TileActivity::end_edit`]. A second edit before that adds its tiles.
    pub(crate) fn begin_edit(&mut self, reached: &[bool]) {
        if self.before_edit.is_none() {
            let idle = vec![None; self.next.len()];
            self.before_edit = Some(std::mem::replace(&mut self.next, idle));
        }
        for (next, _) in self.next.iter_mut().zip(reached).filter(|(_, r)| **r) {
            *next = Some(Why::LightEdited);
        }
    }

    /// The edit's direct light is injected, and `change[t]` is how much it changed tile `t`'s
    /// (relative, inject_tally.wgsl; meaningful for the tiles it redid): the tiles it changed by
    /// the tolerance or more start the bounces, with those pending before the edit. Where none
    /// is, one bounce over every tile checks (the stopping test stays the batch render's).
    pub(crate) fn end_edit(&mut self, change: &[f32], tolerance: f32) {
        let redone = std::mem::take(&mut self.next);
        self.next = self.before_edit.take().unwrap_or_else(|| vec![None; redone.len()]);
        for (t, r) in redone.iter().enumerate() {
            let c = change.get(t).copied().unwrap_or(f32::NAN);
            if r.is_some() && (c.is_nan() || c >= tolerance) {
                self.next[t] = Some(Why::LightEdited);
            }
        }
        if self.pending_tiles() == 0 {
            self.all(Why::Verify);
        }
    }

    /// Tiles the next bounce updates.
    pub(crate) fn pending_tiles(&self) -> usize {
        self.next.iter().filter(|w| w.is_some()).count()
    }

    /// Tiles the next bounce updates, and their leaves.
    pub(crate) fn pending_tiles_leaves(&self) -> (usize, u64) {
        let pending = (self.next.iter().zip(&self.leaves)).filter(|(w, _)| w.is_some());
        pending.fold((0, 0), |(t, l), (_, &(_, n))| (t + 1, l + u64::from(n)))
    }

    pub(crate) fn tiles(&self) -> usize {
        self.next.len()
    }

    /// Counts by reason of the tiles the next bounce updates, in words ("5 new, 9 beside a new
    /// tile").
    pub(crate) fn pending_why(&self) -> String {
        describe_counts(&count_why(self.next.iter().flatten()))
    }

    /// The next bounce's tiles as propagate reads them (shaders/activity.wgsl), tiles without
    /// leaves left out, and the number of its invocations (their leaves).
    pub(crate) fn active_tiles(&self) -> (Vec<ActiveTile>, u32) {
        let mut items = 0;
        let mut out = Vec::new();
        for (t, w) in self.next.iter().enumerate() {
            let (first_leaf, leaf_count) = self.leaves[t];
            if w.is_some() && leaf_count > 0 {
                out.push(ActiveTile { tile: t as u32, first_leaf, leaf_count, first_item: items });
                items += leaf_count;
            }
        }
        (out, items)
    }

    /// Ends a bounce that updated the pending tiles, given each tile's largest relative change
    /// (`change[t]`, meaningful for the tiles it updated): chooses the next bounce's tiles and
    /// returns what this one did. A change that is not a number counts as a change.
    pub(crate) fn finish(&mut self, change: &[f32], tolerance: f32) -> BounceWork {
        let ran: Vec<usize> = (0..self.next.len()).filter(|&t| self.next[t].is_some()).collect();
        let why = count_why(self.next.iter().flatten());
        let every_tile = ran.len() == self.next.len();
        let c = |t: usize| change.get(t).copied().unwrap_or(f32::NAN);
        let changing: Vec<usize> =
            ran.iter().copied().filter(|&t| c(t).is_nan() || c(t) >= tolerance).collect();
        let max_change = ran.iter().map(|&t| c(t)).fold(0.0f32, |m, x| if x.is_nan() { m } else { m.max(x) });
        let work = BounceWork {
            tiles: ran.len(),
            of_tiles: self.next.len(),
            why,
            leaves: ran.iter().map(|&t| u64::from(self.leaves[t].1)).sum(),
            every_tile,
            changed: changing.len(),
            max_change,
            tile_list: (ran.len() <= LISTED_TILES).then(|| ran.iter().map(|&t| t as u32).collect()),
        };
        self.next.fill(None);
        for &t in &changing {
            for &n in &self.neighbours[t] {
                self.next[n as usize].get_or_insert(Why::BesideChanged);
            }
        }
        for &t in &changing {
            self.next[t] = Some(Why::Changed);
        }
        if changing.is_empty() && !every_tile {
            self.all(Why::Verify);
        }
        work
    }
}

fn count_why<'a>(reasons: impl Iterator<Item = &'a Why>) -> BTreeMap<Why, usize> {
    let mut by = BTreeMap::new();
    for w in reasons {
        *by.entry(*w).or_default() += 1;
    }
    by
}

/// Tiles by reason in words: "12 new, 22 beside a new tile".
pub fn describe_counts(by: &BTreeMap<Why, usize>) -> String {
    by.iter().map(|(w, n)| format!("{n} {}", w.describe())).collect::<Vec<_>>().join(", ")
}

/// For each tile, the other tiles whose boxes (origin .. origin + 2^depth leaves of the package)
/// touch or overlap it: a sweep over the tiles sorted by their lowest x, so the cost follows the
/// pairs close in x rather than every pair.
fn touching(tiles: &[TileGpu]) -> Vec<Vec<u32>> {
    let boxes: Vec<([i64; 3], [i64; 3])> = tiles
        .iter()
        .map(|t| {
            let lo = t.origin_leaf.map(i64::from);
            let edge = 1i64 << t.depth.min(40);
            (lo, lo.map(|v| v + edge))
        })
        .collect();
    let mut order: Vec<usize> = (0..tiles.len()).collect();
    order.sort_by_key(|&t| boxes[t].0[0]);
    let mut out = vec![Vec::new(); tiles.len()];
    for (k, &a) in order.iter().enumerate() {
        for &b in &order[k + 1..] {
            if boxes[b].0[0] > boxes[a].1[0] {
                break;
            }
            let meet = (0..3).all(|ax| boxes[a].0[ax] <= boxes[b].1[ax] && boxes[b].0[ax] <= boxes[a].1[ax]);
            if meet {
                out[a].push(b as u32);
                out[b].push(a as u32);
            }
        }
    }
    for list in &mut out {
        list.sort_unstable();
    }
    out
}

#[cfg(test)]
mod tests {
    use super::*;

    /// A row of `n` tiles of depth 2 (4 leaves) along x, 10 leaves each.
    fn row(n: usize) -> Vec<TileGpu> {
        (0..n)
            .map(|i| TileGpu {
                origin_leaf: [4 * i as i32, 0, 0],
                depth: 2,
                leaf_offset: 10 * i as u32,
                leaf_count: 10,
                ..Default::default()
            })
            .collect()
    }

    #[test]
    fn touching_tiles_are_neighbours_and_distant_ones_are_not() {
        let mut tiles = row(4);
        // A tile diagonal to tile 0 (shares an edge), and one a leaf away from everything.
        tiles.push(TileGpu { origin_leaf: [-4, 4, 0], depth: 2, ..Default::default() });
        tiles.push(TileGpu { origin_leaf: [0, 0, 5], depth: 2, ..Default::default() });
        let n = touching(&tiles);
        assert_eq!(n[0], vec![1, 4]);
        assert_eq!(n[1], vec![0, 2]);
        assert_eq!(n[3], vec![2]);
        assert!(n[5].is_empty());
    }

    #[test]
    fn a_change_in_two_steps_leaves_the_work_of_one_change() {
        let tiles = row(6);
        // Whole: tiles 1 and 4 arrive at once.
        let mut start = TileActivity::new(&tiles);
        start.seed(&[true; 6]);
        let whole = start.after_change(&tiles, &[true, false, true, true, false, true]);
        // In steps: tile 1, then tile 4, no bounce between; the second step keeps tile 1's light.
        let first = start.after_change(&tiles, &[true, false, true, true, true, true]);
        let second = first.after_change(&tiles, &[true, true, true, true, false, true]);
        assert_eq!(second.next, whole.next);
        assert_eq!(second.next[1], Some(Why::New));
        // Once a bounce has spread a new tile's light, it is kept as any other.
        let mut bounced = first.clone();
        bounced.next.fill(None);
        let later = bounced.after_change(&tiles, &[true, true, true, true, false, true]);
        assert_eq!(later.next[1], None);
    }

    #[test]
    fn a_reload_activates_new_tiles_and_their_neighbours_only() {
        let mut a = TileActivity::new(&row(6));
        assert_eq!(a.pending_tiles(), 6);
        a.seed(&[true, true, true, false, true, true]);
        assert_eq!(
            a.next,
            vec![None, None, Some(Why::BesideNew), Some(Why::New), Some(Why::BesideNew), None]
        );
        let (tiles, items) = a.active_tiles();
        assert_eq!(items, 30);
        let at = |tile, first_leaf, first_item| ActiveTile { tile, first_leaf, leaf_count: 10, first_item };
        assert_eq!(tiles, vec![at(2, 20, 0), at(3, 30, 10), at(4, 40, 20)]);
        assert_eq!(a.pending_why(), "1 new, 2 beside a new tile");
    }

    #[test]
    fn change_spreads_to_neighbours_then_a_check_over_every_tile_ends_it() {
        let mut a = TileActivity::new(&row(6));
        a.seed(&[true, true, true, false, true, true]);
        // Tile 3 still changes, 2 and 4 do not: 3 and its neighbours again.
        let mut change = [0.0f32; 6];
        change[3] = 0.1;
        let w = a.finish(&change, 1e-3);
        assert_eq!((w.tiles, w.changed, w.leaves, w.every_tile), (3, 1, 30, false));
        assert_eq!(w.tile_list, Some(vec![2, 3, 4]));
        assert_eq!(a.next[3], Some(Why::Changed));
        assert_eq!(a.next[2], Some(Why::BesideChanged));
        assert_eq!(a.pending_tiles(), 3);
        // Nothing changes where it looked: every tile is checked once.
        let w = a.finish(&[0.0; 6], 1e-3);
        assert_eq!(w.changed, 0);
        assert_eq!(a.pending_tiles(), 6);
        assert!(a.next.iter().all(|w| *w == Some(Why::Verify)));
        // The check finds a far tile changing (light down a corridor): it and its neighbour run.
        change = [0.0; 6];
        change[0] = 0.01;
        let w = a.finish(&change, 1e-3);
        assert!(w.every_tile);
        assert_eq!(a.next[..2], [Some(Why::Changed), Some(Why::BesideChanged)]);
        assert_eq!(a.pending_tiles(), 2);
        a.finish(&[0.0; 6], 1e-3);
        // A clean check over every tile: nothing is left to do.
        let w = a.finish(&[0.0; 6], 1e-3);
        assert!(w.every_tile && w.changed == 0);
        assert_eq!(a.pending_tiles(), 0);
    }

    #[test]
    fn a_change_that_is_not_a_number_counts_as_a_change() {
        let mut a = TileActivity::new(&row(3));
        a.finish(&[0.0, f32::NAN, 0.0], 1e-3);
        assert_eq!(a.next, vec![Some(Why::BesideChanged), Some(Why::Changed), Some(Why::BesideChanged)]);
    }

    #[test]
    fn an_edit_redoes_the_tiles_it_reaches_and_bounces_from_those_it_changed() {
        let mut a = TileActivity::new(&row(5));
        a.finish(&[0.0, 0.0, 0.0, 0.1, 0.0], 1e-3);
        assert_eq!(a.pending_tiles(), 3);
        // Its reach: tiles 0 and 1; inject redoes those only.
        a.begin_edit(&[true, true, false, false, false]);
        assert_eq!(a.next, vec![Some(Why::LightEdited), Some(Why::LightEdited), None, None, None]);
        // A second edit before the tally adds its tiles.
        a.begin_edit(&[false, false, false, false, true]);
        assert_eq!(a.pending_tiles(), 3);
        // Tile 1's direct light did not change (rock between it and the lamp): it does not
        // bounce; the tiles pending before the edit do.
        a.end_edit(&[0.2, 0.0, 9.0, 0.0, f32::NAN], 1e-3);
        assert_eq!(
            a.next,
            vec![
                Some(Why::LightEdited),
                None,
                Some(Why::BesideChanged),
                Some(Why::Changed),
                Some(Why::LightEdited)
            ]
        );
        // An edit that changes nothing, with nothing pending: one check over every tile.
        let mut b = TileActivity::new(&row(2));
        b.finish(&[0.0; 2], 1e-3);
        assert_eq!(b.pending_tiles(), 0);
        b.begin_edit(&[true, false]);
        b.end_edit(&[0.0, 0.0], 1e-3);
        assert_eq!(b.next, vec![Some(Why::Verify); 2]);
    }

    #[test]
    fn nothing_new_after_a_reload_still_checks_every_tile() {
        let mut a = TileActivity::new(&row(3));
        a.seed(&[true, true, true]);
        assert_eq!(a.pending_tiles(), 3);
        assert_eq!(a.next[0], Some(Why::Verify));
    }
}
