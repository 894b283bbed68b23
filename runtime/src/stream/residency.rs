//! Which tiles the renderer holds in full under a GPU memory budget and a point budget, for a
//! view. Every tile keeps at least its far level (coarse.rs, `FAR_LEVELS` above its leaves)
//! resident, reserved first: cones that leave the full tiles still meet walls and light. The rest
//! of the budget goes by priority: tiles in the view frustum, then tiles that light them (within
//! `light_reach_m` of a visible tile, or holding a light), then the others; nearer first within
//! each class, so detail falls off with distance as the budget runs out. Each tile in turn is held
//! full if that fits, else at its coarse level (`COARSE_LEVELS`) if that fits, else stays far; a
//! tile that does not fit is passed over for smaller ones behind it (greedy), never split.
//!
//! Pure policy over byte counts, no GPU: the renderer's buffers follow the same per-tile formula
//! ([`TileBufferBytes`], the formula the pools and `SceneData::buffer_bytes` use), so the bytes chosen here
//! are the bytes the renderer holds for tiles.

use glam::{DVec3, Vec3};
use grotto_format::spec::{CoarseLeaf, SvoNode};
use grotto_format::{Package, SectionKind};
use serde::Serialize;

use crate::error::{Error, Result};
use crate::gpu::types::TileBufferBytes;
use crate::scene::data::TileMode;

/// What one representation of a tile costs on the GPU.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq, Serialize)]
pub struct TileCost {
    pub(crate) nodes: u64,
    pub(crate) leaves: u64,
    pub(crate) surfels: u64,
    pub bytes: u64,
}

impl TileCost {
    pub(crate) fn new(nodes: u64, leaves: u64, surfels: u64, radiance_f16: bool) -> Self {
        Self {
            nodes,
            leaves,
            surfels,
            bytes: TileBufferBytes::of(1, nodes, leaves, surfels, radiance_f16).total(),
        }
    }
}

/// A tile as the policy sees it: its box in frame metres and what each representation costs.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct TileFootprint {
    /// The package's tile index.
    pub index: usize,
    pub min_m: Vec3,
    pub max_m: Vec3,
    pub full: TileCost,
    pub coarse: TileCost,
    pub far: TileCost,
}

impl TileFootprint {
    /// What the tile costs held in `mode`.
    pub(crate) fn cost(&self, mode: TileMode) -> TileCost {
        match mode {
            TileMode::Full => self.full,
            TileMode::Coarse => self.coarse,
            TileMode::Far => self.far,
            TileMode::Skip => TileCost::default(),
        }
    }
}

/// The budgets residency keeps.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Serialize)]
pub struct Budget {
    /// Bytes of tile data on the GPU (`--gpu-memory`).
    pub gpu_bytes: u64,
    /// Surfels drawn (`--point-budget`).
    pub points: u64,
    /// Elements of each of the renderer's tile pools (pool.rs), once they are allocated: a
    /// residency must fit each pool, not only the bytes.
    pub pools: Option<crate::render::pool::PoolCaps>,
}

/// The view residency serves.
#[derive(Clone, Debug, PartialEq)]
pub struct View {
    pub eye_m: Vec3,
    pub forward: Vec3,
    pub up: Vec3,
    pub fov_y_rad: f32,
    pub aspect: f32,
    /// Light positions (frame metres).
    pub lights_m: Vec<Vec3>,
    /// How far light travels between tiles that matters (cone reach).
    pub light_reach_m: f32,
    /// The view's clip box: a tile wholly outside it is not drawn, so it is not visible.
    pub clip: Option<crate::settings::ClipBox>,
}

/// Why a tile ranks where it does.
#[derive(Clone, Copy, Debug, PartialEq, Eq, PartialOrd, Ord, Serialize)]
#[serde(rename_all = "snake_case")]
pub enum Relevance {
    Other,
    /// Lights a visible tile (near one, or holds a light).
    Lights,
    Visible,
}

/// One tile's decision.
#[derive(Clone, Copy, Debug, PartialEq, Serialize)]
pub struct Decision {
    pub tile: usize,
    pub relevance: Relevance,
    pub(crate) distance_m: f32,
    pub mode: TileMode,
}

/// What [`choose`] decided.
#[derive(Clone, Debug, PartialEq, Serialize)]
pub struct Residency {
    /// In priority order.
    pub decisions: Vec<Decision>,
    #[serde(flatten)]
    pub totals: ResidencyTotals,
}

/// The totals of a [`Residency`] (what summaries report).
#[derive(Clone, Copy, Debug, PartialEq, Serialize)]
pub struct ResidencyTotals {
    pub(crate) budget: Budget,
    /// Tile bytes held: every far level plus the finer tiles' extra.
    pub resident_bytes: u64,
    /// Of them, the reserve: every tile at its far level.
    pub(crate) coarse_bytes: u64,
    /// Surfels drawn.
    pub(crate) surfels: u64,
    pub full_tiles: usize,
    pub coarse_tiles: usize,
    pub far_tiles: usize,
    /// Visible tiles left coarse or far for lack of budget.
    pub(crate) visible_coarse: usize,
}

impl Residency {
    /// Each package tile's mode, as `SceneData::from_package_with` takes it (tiles the policy
    /// never saw are skipped): a table made once, read in constant time per tile.
    pub fn mode_of(&self) -> impl Fn(usize) -> TileMode + use<> {
        let modes = self.modes();
        move |i| modes.get(i).copied().unwrap_or(TileMode::Skip)
    }

    /// Each package tile's mode, indexed by tile (tiles the policy never saw: `Skip`): two
    /// residencies hold the same tiles in the same form exactly when these are equal.
    pub fn modes(&self) -> Vec<TileMode> {
        let mut modes = vec![TileMode::Skip; self.decisions.iter().map(|d| d.tile + 1).max().unwrap_or(0)];
        for d in &self.decisions {
            modes[d.tile] = d.mode;
        }
        modes
    }

    /// The decisions as text (`--explain`): the first `rows` tiles by priority, then counts.
    pub fn explain(&self, rows: usize) -> String {
        use std::fmt::Write;
        let t = &self.totals;
        let mut out = format!(
            "residency: {} tiles full, {} coarse, {} far ({} in view not full), {} of {} budget, {} surfels\n  \
             tile  relevance  distance m  mode\n",
            t.full_tiles,
            t.coarse_tiles,
            t.far_tiles,
            t.visible_coarse,
            crate::gpu::human_bytes(t.resident_bytes),
            crate::gpu::human_bytes(t.budget.gpu_bytes),
            t.surfels
        );
        for d in self.decisions.iter().take(rows) {
            let _ = writeln!(out, "  {:4}  {:9?}  {:10.1}  {:?}", d.tile, d.relevance, d.distance_m, d.mode);
        }
        if self.decisions.len() > rows {
            let _ = writeln!(out, "  ... {} more (all in --json)", self.decisions.len() - rows);
        }
        out
    }

    /// Every tile full (nothing was cut).
    #[cfg(test)]
    fn all_full(&self) -> bool {
        self.totals.coarse_tiles == 0 && self.totals.far_tiles == 0
    }
}

/// Every tile of `pkg` with an SVO, with its box in the scene's frame
/// ([`crate::scene::data::frame_of`]) and its costs full, coarse and far. The node and leaf counts
/// of each come from the section table where the package stores them (format 1.1: no tile data
/// is read); otherwise from one read of the tile's node array. A coarse tile's splats are counted
/// as its leaves (an upper bound: empty blocks draw none), so the bytes chosen are never under
/// what is held.
pub fn footprints(pkg: &Package, radiance_f16: bool) -> Result<Vec<TileFootprint>> {
    let mut out = Vec::new();
    let Some((frame_origin_m, _)) = crate::scene::data::frame_of(pkg)? else { return Ok(out) };
    for tile in pkg.tiles() {
        let depth = tile.depth();
        let len = |kind: SectionKind, item: u32, each: usize| {
            tile.find(kind, item).map(|s| s.raw_len / each as u64)
        };
        // Nodes and leaves of the tile `k` levels above its leaves (0: as built), as stored.
        let stored = |k: u32| -> Option<(u64, u64)> {
            Some(if k == 0 {
                (len(SectionKind::SvoNodes, 0, size_of::<SvoNode>())?, len(SectionKind::LeafOpacity, 0, 4)?)
            } else {
                (
                    len(SectionKind::CoarseNodes, k, size_of::<SvoNode>())?,
                    len(SectionKind::CoarseLeaves, k, size_of::<CoarseLeaf>())?,
                )
            })
        };
        let levels = [0, TileMode::Coarse.leaf_lod(depth), TileMode::Far.leaf_lod(depth)];
        let nodes = if levels.iter().all(|&k| stored(k).is_some()) {
            None
        } else {
            let Some(nodes) = tile.read::<SvoNode>(SectionKind::SvoNodes)? else { continue };
            Some(nodes)
        };
        let [(node_count, leaves), coarse, far] = levels.map(|k| {
            stored(k)
                .or_else(|| {
                    let cut = depth - k;
                    let levels = nodes.as_deref()?.iter().map(|n| u32::from(n.level));
                    Some((
                        levels.clone().filter(|&l| l <= cut).count() as u64,
                        levels.filter(|&l| l == cut).count() as u64,
                    ))
                })
                .unwrap_or_default()
        });
        if node_count == 0 {
            continue;
        }
        let surfels = tile.surfel_count_from_table().unwrap_or(0);
        let full = TileCost::new(node_count, leaves, surfels, radiance_f16);
        let level =
            |k: u32, (n, l): (u64, u64)| if k == 0 { full } else { TileCost::new(n, l, l, radiance_f16) };
        let (coarse, far) = (level(levels[1], coarse), level(levels[2], far));
        let lo = DVec3::from_array(tile.origin_m()) - DVec3::from_array(frame_origin_m);
        out.push(TileFootprint {
            index: tile.index() as usize,
            min_m: lo.as_vec3(),
            max_m: (lo + DVec3::splat(tile.extent_m())).as_vec3(),
            full,
            coarse,
            far,
        });
    }
    Ok(out)
}

fn distance_to_box(p: Vec3, lo: Vec3, hi: Vec3) -> f32 {
    (lo - p).max(p - hi).max(Vec3::ZERO).length()
}

fn boxes_within(a: (Vec3, Vec3), b: (Vec3, Vec3), gap: f32) -> bool {
    ((a.0 - b.1).max(b.0 - a.1)).max(Vec3::ZERO).length() <= gap
}

/// Whether the box `lo..hi` meets the view's frustum (no far plane): a box is outside when all
/// its corners are outside one of the four side planes or behind the eye.
fn in_frustum(view: &View, lo: Vec3, hi: Vec3) -> bool {
    if distance_to_box(view.eye_m, lo, hi) == 0.0 {
        return true;
    }
    let f = view.forward.normalize_or(Vec3::NEG_Z);
    let r = f.cross(view.up).normalize_or(Vec3::X);
    let u = r.cross(f);
    let th = (0.5 * view.fov_y_rad).tan();
    let tw = th * view.aspect;
    // Inward normals of the side planes through the eye, and the near plane at the eye.
    let planes =
        [f - r / tw, f + r / tw, f - u / th, f + u / th].map(|n| n.normalize()).into_iter().chain([f]);
    for n in planes {
        let corner_max = (0..8)
            .map(|c| {
                let p = Vec3::new(
                    if c & 1 == 0 { lo.x } else { hi.x },
                    if c & 2 == 0 { lo.y } else { hi.y },
                    if c & 4 == 0 { lo.z } else { hi.z },
                );
                (p - view.eye_m).dot(n)
            })
            .fold(f32::MIN, f32::max);
        if corner_max < 0.0 {
            return false;
        }
    }
    true
}

/// Chooses the full tiles for `view` within `budget`. Errors: the coarse levels alone are over
/// the budget, or a tile's full form is (it could never be loaded); both say what to change.
pub fn choose(tiles: &[TileFootprint], view: &View, budget: Budget) -> Result<Residency> {
    // The reserve: every tile at its far level.
    let reserve_bytes: u64 = tiles.iter().map(|t| t.far.bytes).sum();
    let reserve_surfels: u64 = tiles.iter().map(|t| t.far.surfels).sum();
    if reserve_bytes > budget.gpu_bytes {
        return Err(Error::Budget {
            what: format!(
                "the far levels of all {} tiles need {} of GPU memory, over the budget of {}",
                tiles.len(),
                crate::gpu::human_bytes(reserve_bytes),
                crate::gpu::human_bytes(budget.gpu_bytes)
            ),
            hint: "raise --memory or --gpu-memory (in a page: budget= or gpu_memory_mb=)".into(),
        });
    }
    if let Some(t) = tiles.iter().find(|t| t.full.bytes > budget.gpu_bytes) {
        return Err(Error::Budget {
            what: format!(
                "tile {} needs {} of GPU memory when loaded, over the budget of {}",
                t.index,
                crate::gpu::human_bytes(t.full.bytes),
                crate::gpu::human_bytes(budget.gpu_bytes)
            ),
            hint: "raise --memory or --gpu-memory (in a page: budget=), or build the package with \
                   smaller tiles (grotto-pack build --max-tile-m) or a larger leaf (--leaf-m)"
                .into(),
        });
    }
    // A tile the clip box cuts away still lights the ones inside (it keeps its light class), but
    // its points are not drawn: the point budget goes to the tiles inside the box.
    let visible: Vec<bool> = tiles
        .iter()
        .map(|t| in_frustum(view, t.min_m, t.max_m) && view.clip.is_none_or(|c| c.meets(t.min_m, t.max_m)))
        .collect();
    let visible_boxes: Vec<(Vec3, Vec3)> =
        tiles.iter().zip(&visible).filter(|(_, v)| **v).map(|(t, _)| (t.min_m, t.max_m)).collect();
    let mut decisions: Vec<Decision> = tiles
        .iter()
        .zip(&visible)
        .map(|(t, &vis)| {
            let relevance = if vis {
                Relevance::Visible
            } else if view.lights_m.iter().any(|&l| distance_to_box(l, t.min_m, t.max_m) == 0.0)
                || visible_boxes.iter().any(|&o| boxes_within((t.min_m, t.max_m), o, view.light_reach_m))
            {
                Relevance::Lights
            } else {
                Relevance::Other
            };
            Decision {
                tile: t.index,
                relevance,
                distance_m: distance_to_box(view.eye_m, t.min_m, t.max_m),
                mode: TileMode::Far,
            }
        })
        .collect();
    // Positions in `tiles` (and `decisions`) by priority.
    let mut order: Vec<usize> = (0..tiles.len()).collect();
    order.sort_by(|&i, &j| {
        let (a, b) = (&decisions[i], &decisions[j]);
        b.relevance.cmp(&a.relevance).then(a.distance_m.total_cmp(&b.distance_m)).then(a.tile.cmp(&b.tile))
    });
    let (mut bytes, mut surfels) = (reserve_bytes, reserve_surfels);
    // Elements of each pool in use: (nodes, leaves), surfels counted above.
    let mut used =
        (tiles.iter().map(|t| t.far.nodes).sum::<u64>(), tiles.iter().map(|t| t.far.leaves).sum::<u64>());
    let fits_pools = |nodes: u64, leaves: u64, surfels: u64| {
        budget.pools.is_none_or(|p| nodes <= p.nodes && leaves <= p.leaves && surfels <= p.surfels)
    };
    if !fits_pools(used.0, used.1, surfels) {
        return Err(Error::Budget {
            what: format!("the far levels of all {} tiles do not fit the renderer's tile pools", tiles.len()),
            hint: "raise --memory or --gpu-memory (in a page: budget= or gpu_memory_mb=)".into(),
        });
    }
    for &k in &order {
        let t = &tiles[k];
        for mode in [TileMode::Full, TileMode::Coarse] {
            let c = t.cost(mode);
            let extra_bytes = c.bytes.saturating_sub(t.far.bytes);
            let extra_surfels = c.surfels.saturating_sub(t.far.surfels);
            let (nodes, leaves) = (
                used.0 + c.nodes.saturating_sub(t.far.nodes),
                used.1 + c.leaves.saturating_sub(t.far.leaves),
            );
            if bytes + extra_bytes <= budget.gpu_bytes
                && surfels + extra_surfels <= budget.points
                && fits_pools(nodes, leaves, surfels + extra_surfels)
            {
                bytes += extra_bytes;
                surfels += extra_surfels;
                used = (nodes, leaves);
                decisions[k].mode = mode;
                break;
            }
        }
    }
    let decisions: Vec<Decision> = order.into_iter().map(|k| decisions[k]).collect();
    let totals = ResidencyTotals::of(&decisions, budget, bytes, reserve_bytes, surfels);
    Ok(Residency { decisions, totals })
}

impl ResidencyTotals {
    /// The totals of `decisions` holding `resident_bytes` (of them `coarse_bytes` the reserve)
    /// and drawing `surfels`.
    fn of(
        decisions: &[Decision],
        budget: Budget,
        resident_bytes: u64,
        coarse_bytes: u64,
        surfels: u64,
    ) -> Self {
        let count = |m: TileMode| decisions.iter().filter(|d| d.mode == m).count();
        Self {
            budget,
            resident_bytes,
            coarse_bytes,
            surfels,
            full_tiles: count(TileMode::Full),
            coarse_tiles: count(TileMode::Coarse),
            far_tiles: count(TileMode::Far),
            visible_coarse: decisions
                .iter()
                .filter(|d| d.mode != TileMode::Full && d.relevance == Relevance::Visible)
                .count(),
        }
    }
}

/// How fine a mode is (far 0, coarse 1, full 2).
fn fineness(m: TileMode) -> u8 {
    match m {
        TileMode::Skip => 0,
        TileMode::Far => 1,
        TileMode::Coarse => 2,
        TileMode::Full => 3,
    }
}

/// `next` with its changes from `current` bounded by an upload of `max_bytes` (`--upload-per-frame`):
/// every change to a coarser form is made (it frees room, and the deferred ones hold less), then
/// changes to finer forms in `next`'s priority order while their bytes fit, at least one; the
/// rest keep `current`'s form and wait for a later frame. Each tile's form costs at most what
/// `next` gives it, so the result keeps every budget `next` keeps. Returns it and the changes
/// deferred.
pub fn limit_uploads(
    tiles: &[TileFootprint],
    current: &Residency,
    next: Residency,
    max_bytes: u64,
) -> (Residency, usize) {
    let now = current.modes();
    let by_index: std::collections::HashMap<usize, &TileFootprint> =
        tiles.iter().map(|t| (t.index, t)).collect();
    let mode_now = |i: usize| now.get(i).copied().unwrap_or(TileMode::Far);
    let mut upload = 0u64;
    let mut decisions = next.decisions;
    for d in &decisions {
        let was = mode_now(d.tile);
        if fineness(d.mode) < fineness(was) {
            upload += by_index.get(&d.tile).map_or(0, |t| t.cost(d.mode).bytes);
        }
    }
    let (mut deferred, mut upgraded) = (0, 0);
    for d in &mut decisions {
        let was = mode_now(d.tile);
        if fineness(d.mode) <= fineness(was) {
            continue;
        }
        let cost = by_index.get(&d.tile).map_or(0, |t| t.cost(d.mode).bytes);
        if upgraded == 0 || upload + cost <= max_bytes {
            upload += cost;
            upgraded += 1;
        } else {
            d.mode = was;
            deferred += 1;
        }
    }
    let budget = next.totals.budget;
    let (mut bytes, mut surfels) = (0u64, 0u64);
    for d in &decisions {
        if let Some(t) = by_index.get(&d.tile) {
            bytes += t.cost(d.mode).bytes;
            surfels += t.cost(d.mode).surfels;
        }
    }
    let totals = ResidencyTotals::of(&decisions, budget, bytes, next.totals.coarse_bytes, surfels);
    (Residency { decisions, totals }, deferred)
}

/// `next` with some tiles held no finer than a mode (`caps`: tile and the finest mode it may take;
/// a browser holds a tile whose finer sections arrived damaged at the form it had). A coarser
/// form costs less, so the result keeps every budget `next` keeps; its totals are recounted.
pub fn cap_modes(
    tiles: &[TileFootprint],
    next: Residency,
    caps: &std::collections::BTreeMap<usize, TileMode>,
) -> Residency {
    if caps.is_empty() {
        return next;
    }
    let by_index: std::collections::HashMap<usize, &TileFootprint> =
        tiles.iter().map(|t| (t.index, t)).collect();
    let mut decisions = next.decisions;
    for d in &mut decisions {
        if let Some(&cap) = caps.get(&d.tile)
            && fineness(d.mode) > fineness(cap)
        {
            d.mode = cap;
        }
    }
    let (mut bytes, mut surfels) = (0u64, 0u64);
    for d in &decisions {
        if let Some(t) = by_index.get(&d.tile) {
            bytes += t.cost(d.mode).bytes;
            surfels += t.cost(d.mode).surfels;
        }
    }
    let totals =
        ResidencyTotals::of(&decisions, next.totals.budget, bytes, next.totals.coarse_bytes, surfels);
    Residency { decisions, totals }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn a_capped_tile_stays_at_its_cap_and_the_totals_follow() {
        let tiles = row(3);
        let decisions = (0..3)
            .map(|i| Decision {
                tile: i,
                relevance: Relevance::Visible,
                distance_m: 1.0,
                mode: TileMode::Full,
            })
            .collect::<Vec<_>>();
        let budget = Budget { gpu_bytes: 1 << 20, points: u64::MAX, pools: None };
        let next = Residency { totals: ResidencyTotals::of(&decisions, budget, 3000, 300, 150), decisions };
        let caps = [(1, TileMode::Far)].into_iter().collect();
        let capped = cap_modes(&tiles, next, &caps);
        assert_eq!(capped.modes(), [TileMode::Full, TileMode::Far, TileMode::Full]);
        assert_eq!((capped.totals.resident_bytes, capped.totals.surfels), (2100, 105));
        assert_eq!(capped.totals.full_tiles, 2);
    }

    /// A row of `n` 4 m tiles along +x, each 1000 B full / 100 B coarse and far, 50 / 5 surfels
    /// (shallow tiles, whose far level is their coarse level).
    fn row(n: usize) -> Vec<TileFootprint> {
        (0..n)
            .map(|i| TileFootprint {
                index: i,
                min_m: Vec3::new(4.0 * i as f32, 0.0, 0.0),
                max_m: Vec3::new(4.0 * i as f32 + 4.0, 4.0, 4.0),
                full: TileCost { nodes: 0, leaves: 0, surfels: 50, bytes: 1000 },
                coarse: TileCost { nodes: 0, leaves: 0, surfels: 5, bytes: 100 },
                far: TileCost { nodes: 0, leaves: 0, surfels: 5, bytes: 100 },
            })
            .collect()
    }

    fn looking(eye: Vec3, forward: Vec3) -> View {
        View {
            eye_m: eye,
            forward,
            up: Vec3::Z,
            fov_y_rad: 60f32.to_radians(),
            aspect: 1.0,
            lights_m: Vec::new(),
            light_reach_m: 2.0,
            clip: None,
        }
    }

    #[test]
    fn a_clip_box_gives_the_point_budget_to_the_tiles_inside_it() {
        // From tile 0 looking along +x every tile is visible; the budget holds 3 tiles in full.
        // Without a clip box they are the nearest three; with the view cut to tiles 6..=8 they
        // are those, and the cut-away tiles stop being visible (tile 5 and 9, next to the box,
        // still light it).
        let tiles = row(10);
        let mut view = looking(Vec3::new(2.0, 2.0, 2.0), Vec3::X);
        let budget = Budget { gpu_bytes: 10 * 100 + 3 * 900, points: u64::MAX, pools: None };
        let full = |r: &Residency| -> Vec<usize> {
            let mut f: Vec<usize> =
                r.decisions.iter().filter(|d| d.mode == TileMode::Full).map(|d| d.tile).collect();
            f.sort_unstable();
            f
        };
        assert_eq!(full(&choose(&tiles, &view, budget).unwrap()), [0, 1, 2]);
        view.clip = Some(crate::settings::ClipBox {
            min_m: Vec3::new(24.5, -1.0, -1.0),
            max_m: Vec3::new(35.5, 5.0, 5.0),
        });
        let r = choose(&tiles, &view, budget).unwrap();
        assert_eq!(full(&r), [6, 7, 8]);
        let relevance = |t: usize| r.decisions.iter().find(|d| d.tile == t).unwrap().relevance;
        assert_eq!((relevance(6), relevance(8)), (Relevance::Visible, Relevance::Visible));
        assert_eq!((relevance(5), relevance(9)), (Relevance::Lights, Relevance::Lights));
        assert_eq!(relevance(0), Relevance::Other, "the eye's own tile is cut away");
        // The same with a point budget of three full tiles: it goes to the same tiles.
        let points = Budget { gpu_bytes: u64::MAX, points: 10 * 5 + 3 * 45, pools: None };
        assert_eq!(full(&choose(&tiles, &view, points).unwrap()), [6, 7, 8]);
    }

    #[test]
    fn visible_and_near_tiles_come_first_and_the_budget_holds() {
        let tiles = row(10);
        // In tile 5 looking along +x: tiles 5..9 visible; 4 lights them (adjacent); the rest not.
        let view = looking(Vec3::new(22.0, 2.0, 2.0), Vec3::X);
        let budget = Budget { gpu_bytes: 10 * 100 + 3 * 900, points: u64::MAX, pools: None };
        let r = choose(&tiles, &view, budget).unwrap();
        let order: Vec<usize> = r.decisions.iter().map(|d| d.tile).collect();
        assert_eq!(order, [5, 6, 7, 8, 9, 4, 3, 2, 1, 0]);
        assert_eq!(r.decisions[5].relevance, Relevance::Lights);
        assert_eq!(r.decisions[6].relevance, Relevance::Other);
        let full: Vec<usize> =
            r.decisions.iter().filter(|d| d.mode == TileMode::Full).map(|d| d.tile).collect();
        assert_eq!(full, [5, 6, 7], "the nearest visible tiles");
        assert_eq!(r.totals.resident_bytes, budget.gpu_bytes);
        assert_eq!(r.totals.visible_coarse, 2);
        let text = r.explain(3);
        assert!(
            text.contains("3 tiles full, 7 coarse, 0 far (2 in view not full)")
                && text.contains("... 7 more"),
            "{text}"
        );
        // Never over the budget, whatever it is.
        for gpu_bytes in (1000..=10_000).step_by(77) {
            let r = choose(&tiles, &view, Budget { gpu_bytes, points: u64::MAX, pools: None }).unwrap();
            assert!(r.totals.resident_bytes <= gpu_bytes);
            let held: u64 = r.decisions.iter().map(|d| tiles[d.tile].cost(d.mode).bytes).sum();
            assert_eq!(held, r.totals.resident_bytes);
        }
    }

    #[test]
    fn detail_falls_off_with_distance_as_the_budget_runs_out() {
        // Deep tiles: 1000 B full, 100 B coarse, 10 B far. From tile 0 looking along +x, every
        // tile is visible and priority is distance: the budget makes the nearest full, the next
        // coarse and leaves the farthest far, and is never exceeded, whatever it is.
        let mut tiles = row(10);
        for t in &mut tiles {
            t.far = TileCost { nodes: 0, leaves: 0, surfels: 1, bytes: 10 };
        }
        let view = looking(Vec3::new(-1.0, 2.0, 2.0), Vec3::X);
        let budget = Budget { gpu_bytes: 10 * 10 + 2 * 990 + 4 * 90, points: u64::MAX, pools: None };
        let r = choose(&tiles, &view, budget).unwrap();
        let modes: Vec<TileMode> = r.decisions.iter().map(|d| d.mode).collect();
        use TileMode::{Coarse, Far, Full};
        assert_eq!(modes, [Full, Full, Coarse, Coarse, Coarse, Coarse, Far, Far, Far, Far]);
        assert_eq!((r.totals.full_tiles, r.totals.coarse_tiles, r.totals.far_tiles), (2, 4, 4));
        assert_eq!(r.totals.resident_bytes, budget.gpu_bytes);
        assert!(r.explain(0).contains("2 tiles full, 4 coarse, 4 far (8 in view not full)"));
        for gpu_bytes in (1000..=10_000).step_by(37) {
            let r = choose(&tiles, &view, Budget { gpu_bytes, points: u64::MAX, pools: None }).unwrap();
            let held: u64 = r.decisions.iter().map(|d| tiles[d.tile].cost(d.mode).bytes).sum();
            assert!(held == r.totals.resident_bytes && held <= gpu_bytes, "{held} of {gpu_bytes}");
        }
        let mut one = tiles[..1].to_vec();
        one[0].full.bytes = 5;
        let err = choose(&one, &view, Budget { gpu_bytes: 9, points: u64::MAX, pools: None }).unwrap_err();
        assert!(err.to_string().contains("far levels of all 1 tiles"), "{err}");
    }

    #[test]
    fn a_tile_behind_the_camera_that_holds_a_light_outranks_unlit_ones() {
        let tiles = row(10);
        let mut view = looking(Vec3::new(22.0, 2.0, 2.0), Vec3::X);
        view.lights_m.push(Vec3::new(2.0, 2.0, 2.0));
        let r = choose(&tiles, &view, Budget { gpu_bytes: 100_000, points: u64::MAX, pools: None }).unwrap();
        let lights: Vec<usize> =
            r.decisions.iter().filter(|d| d.relevance == Relevance::Lights).map(|d| d.tile).collect();
        assert_eq!(lights, [4, 0]);
        assert!(r.all_full());
    }

    #[test]
    fn the_point_budget_bounds_the_surfels_drawn() {
        let tiles = row(10);
        let view = looking(Vec3::new(22.0, 2.0, 2.0), Vec3::X);
        let r = choose(&tiles, &view, Budget { gpu_bytes: u64::MAX, points: 10 * 5 + 2 * 45, pools: None })
            .unwrap();
        assert_eq!(r.totals.full_tiles, 2);
        assert_eq!(r.totals.surfels, 140);
    }

    #[test]
    fn budgets_too_small_for_the_coarse_levels_or_one_tile_are_clear_errors() {
        let mut tiles = row(4);
        let view = looking(Vec3::ZERO, Vec3::X);
        let err =
            choose(&tiles, &view, Budget { gpu_bytes: 399, points: u64::MAX, pools: None }).unwrap_err();
        assert!(err.to_string().contains("far levels of all 4 tiles"), "{err}");
        tiles[2].full.bytes = 5000;
        let err =
            choose(&tiles, &view, Budget { gpu_bytes: 4000, points: u64::MAX, pools: None }).unwrap_err();
        let msg = err.to_string();
        assert!(msg.contains("tile 2") && msg.contains("--max-tile-m"), "{msg}");
    }

    #[test]
    fn the_tile_pools_bound_each_kind_of_element() {
        // Full tiles of 10 leaves (far: 1); pools of 10 far leaves plus two full tiles' extra.
        let mut tiles = row(10);
        for t in &mut tiles {
            t.full.leaves = 10;
            t.far.leaves = 1;
            t.coarse.leaves = 1;
        }
        let view = looking(Vec3::new(22.0, 2.0, 2.0), Vec3::X);
        let pools =
            crate::render::pool::PoolCaps { tiles: 10, nodes: 0, leaves: 10 + 2 * 9, surfels: u64::MAX };
        let budget = Budget { gpu_bytes: u64::MAX, points: u64::MAX, pools: Some(pools) };
        let r = choose(&tiles, &view, budget).unwrap();
        assert_eq!(r.totals.full_tiles, 2, "the leaf pool holds two full tiles");
        let small = crate::render::pool::PoolCaps { leaves: 9, ..pools };
        let err = choose(&tiles, &view, Budget { pools: Some(small), ..budget }).unwrap_err();
        assert!(err.to_string().contains("pools"), "{err}");
    }

    #[test]
    fn uploads_per_frame_are_bounded_in_priority_order_and_coarser_forms_always_go_through() {
        let tiles = row(10);
        let budget = Budget { gpu_bytes: 10 * 100 + 5 * 900, points: u64::MAX, pools: None };
        // Looking at tiles 0..4 from before them, then at 5..9 from inside 5.
        let before = choose(&tiles, &looking(Vec3::new(-1.0, 2.0, 2.0), Vec3::X), budget).unwrap();
        let next = choose(&tiles, &looking(Vec3::new(22.0, 2.0, 2.0), Vec3::X), budget).unwrap();
        let full = |r: &Residency| -> Vec<usize> {
            let mut v: Vec<usize> =
                r.decisions.iter().filter(|d| d.mode == TileMode::Full).map(|d| d.tile).collect();
            v.sort();
            v
        };
        assert_eq!(full(&before), [0, 1, 2, 3, 4]);
        assert_eq!(full(&next), [5, 6, 7, 8, 9]);
        let (limited, deferred) = limit_uploads(&tiles, &before, next.clone(), 2500);
        // 0..4 go coarse (5 x 100 B), then the nearest two new full tiles fit 2500 B.
        assert_eq!(full(&limited), [5, 6]);
        assert_eq!(deferred, 3);
        assert_eq!(limited.totals.full_tiles, 2);
        assert!(limited.totals.resident_bytes <= next.totals.resident_bytes);
        // At least one change to a finer form goes through whatever the limit.
        let (one, _) = limit_uploads(&tiles, &before, next.clone(), 0);
        assert_eq!(full(&one), [5]);
        let (all, none) = limit_uploads(&tiles, &before, next.clone(), u64::MAX);
        assert_eq!((all, none), (next, 0));
    }
}
