//! A light edit in place (a lamp moved, dimmed, added, deleted, a circuit switched): which
//! lights changed, how far their old and new light reaches, and the tiles inside that reach —
//! the only tiles whose direct light the edit changes, so inject redoes those and propagation
//! starts from them (activity.rs), instead of relighting the whole cave.
//!
//! A light's direct light at a leaf depends on the light alone (position, intensity, spot,
//! profile, and how it is shadowed: a shadow map or the fallback) and on the leaf's place; past
//! its range (light/setup.rs `range_m`) inject adds nothing. So the leaves an edit changes lie in
//! the range spheres of the lights it removed or added (a moved or dimmed lamp is one of each),
//! and every other leaf's direct light is the same to the bit.

use glam::{IVec3, Vec3};
use serde::Serialize;

use crate::gpu::types::TileGpu;
use crate::light::setup::range_m;
use crate::scene::data::SceneLight;

/// A light as inject sees it: the scene light (its name aside) and whether it has a shadow map.
#[derive(Clone, Debug)]
pub(crate) struct LitBy<'a> {
    pub(crate) light: &'a SceneLight,
    pub(crate) mapped: bool,
}

impl LitBy<'_> {
    fn same(&self, other: &LitBy<'_>) -> bool {
        let (a, b) = (self.light, other.light);
        self.mapped == other.mapped
            && a.position_m == b.position_m
            && a.intensity_w_sr == b.intensity_w_sr
            && a.spot == b.spot
            && a.profile == b.profile
    }
}

/// Where an edited light's light reaches: its position and range (infinite without a cutoff).
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Reach {
    pub centre_m: Vec3,
    pub range_m: f32,
}

/// `lights` with whether each has a shadow map (`mapped`, in the same order).
pub(crate) fn lit_by<'a>(lights: &'a [SceneLight], mapped: &[bool]) -> Vec<LitBy<'a>> {
    lights.iter().zip(mapped).map(|(light, &mapped)| LitBy { light, mapped }).collect()
}

/// The reach of every light `old` has and `new` has not, and the other way round, compared as
/// multisets (the order of lights does not matter, and two equal lamps count twice).
pub(crate) fn changed(old: &[LitBy<'_>], new: &[LitBy<'_>], cutoff_w_m2: f32) -> Vec<Reach> {
    let mut out = Vec::new();
    let mut unmatched = |from: &[LitBy<'_>], against: &[LitBy<'_>]| {
        let mut taken = vec![false; against.len()];
        for l in from {
            let hit = (0..against.len()).find(|&k| !taken[k] && against[k].same(l));
            match hit {
                Some(k) => taken[k] = true,
                None => out.push(Reach {
                    centre_m: l.light.position_m,
                    range_m: range_m(l.light.intensity_w_sr, cutoff_w_m2),
                }),
            }
        }
    };
    unmatched(old, new);
    unmatched(new, old);
    out
}

/// For each tile, whether its box (origin .. origin + 2^depth leaves, grown by one leaf: a
/// leaf's centre may sit on the box's face) meets any of `reach`'s spheres.
pub(crate) fn tiles_reached(tiles: &[TileGpu], leaf_m: f32, reach: &[Reach]) -> Vec<bool> {
    tiles
        .iter()
        .map(|t| {
            let lo = IVec3::from_array(t.origin_leaf).as_vec3() * leaf_m - leaf_m;
            let hi = lo + ((1u64 << t.depth.min(40)) as f32 + 2.0) * leaf_m;
            reach.iter().any(|r| {
                !r.range_m.is_finite()
                    || r.centre_m.clamp(lo, hi).distance_squared(r.centre_m) <= r.range_m * r.range_m
            })
        })
        .collect()
}

/// What an edit in place left to do, for the plan and a viewer's panel.
#[derive(Clone, Debug, Default, PartialEq, Serialize)]
pub struct EditScope {
    /// Lights added or removed (a moved, dimmed or recoloured lamp counts as one of each).
    pub lights: usize,
    /// Shadow-atlas faces drawn again (those of changed lights, and of lights whose face moved).
    pub faces: usize,
    /// Tiles whose direct light is injected again (inside a changed light's reach), of all.
    pub tiles: usize,
    pub of_tiles: usize,
    /// Leaves in those tiles.
    pub leaves: u64,
}

/// A light edit in place whose direct light is not injected and tallied yet (the renderer's).
#[derive(Debug)]
pub(crate) struct PendingEdit {
    pub(crate) scope: EditScope,
    /// The tally of how much inject changed each tile's direct light, on its way back.
    pub(crate) tally: Option<crate::gpu::PendingRead>,
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::scene::data::Spot;

    fn lamp(x: f32, watts: f32) -> SceneLight {
        SceneLight {
            name: format!("lamp at {x}"),
            position_m: Vec3::new(x, 0.0, 0.0),
            intensity_w_sr: Vec3::splat(watts / (4.0 * std::f32::consts::PI)),
            spot: None,
            profile: None,
        }
    }

    fn lit(l: &[SceneLight]) -> Vec<LitBy<'_>> {
        l.iter().map(|light| LitBy { light, mapped: true }).collect()
    }

    #[test]
    fn a_moved_lamp_changes_its_old_and_new_place_and_nothing_else() {
        let old = [lamp(0.0, 10.0), lamp(5.0, 10.0), lamp(9.0, 10.0)];
        let mut new = old.clone();
        new[1].position_m.x = 6.0;
        // Renamed and reordered lamps are the same lamps.
        new.swap(0, 2);
        new[0].name = "renamed".into();
        let r = changed(&lit(&old), &lit(&new), 1e-2);
        assert_eq!(r.len(), 2);
        assert_eq!((r[0].centre_m.x, r[1].centre_m.x), (5.0, 6.0));
        assert!((r[0].range_m - range_m(old[1].intensity_w_sr, 1e-2)).abs() < 1e-6);
        // A lamp that loses its shadow map lights differently.
        let mut unmapped = lit(&old);
        unmapped[2].mapped = false;
        assert_eq!(changed(&lit(&old), &unmapped, 1e-2).len(), 2);
        // Two equal lamps, one deleted: one change.
        let twins = [lamp(1.0, 3.0), lamp(1.0, 3.0)];
        assert_eq!(changed(&lit(&twins), &lit(&twins[..1]), 1e-2).len(), 1);
        let mut spot = old.clone();
        spot[0].spot = Some(Spot { direction: Vec3::Z, inner_angle_rad: 0.2, outer_angle_rad: 0.4 });
        assert_eq!(changed(&lit(&old), &lit(&spot), 1e-2).len(), 2);
    }

    #[test]
    fn the_tiles_reached_are_those_a_range_sphere_meets() {
        // A row of tiles 4 leaves wide along x, leaves of 0.5 m: tile i spans 2i .. 2i + 2 m.
        let tiles: Vec<TileGpu> =
            (0..8).map(|i| TileGpu { origin_leaf: [4 * i, 0, 0], depth: 2, ..Default::default() }).collect();
        let r = Reach { centre_m: Vec3::new(7.0, 1.0, 1.0), range_m: 1.2 };
        let hit = tiles_reached(&tiles, 0.5, &[r]);
        // 7 +- 1.2 m, boxes grown by one leaf: tiles 2 (4..6 m, to 6.5), 3 and 4 (8 m, from 7.5).
        assert_eq!(hit, [false, false, true, true, true, false, false, false]);
        let all = tiles_reached(&tiles, 0.5, &[Reach { range_m: f32::INFINITY, ..r }]);
        assert!(all.iter().all(|&h| h));
        assert!(tiles_reached(&tiles, 0.5, &[]).iter().all(|&h| !h));
    }
}
