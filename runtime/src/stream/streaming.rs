//! Tiles chosen for a camera and brought into the renderer, the same on every platform: which
//! tiles a view keeps in which form ([`Streaming::choose`]), which package sections those forms
//! read ([`sections_for`]: what a browser fetches by HTTP range before it can load them), the
//! scene of a residency ([`Streaming::load`]), a renderer whose pools fit the budget
//! ([`renderer_for`]) and the swap of one residency's tiles for another's ([`swap_tiles`]).
//! Threads (follow.rs) and HTTP (the web crate) stay in the shells around this.

use glam::Vec3;
use grotto_format::{Package, Scope, SectionInfo, SectionKind};

use crate::error::{Error, Result};
use crate::gpu::Gpu;
use crate::render::pool::{POOL_HEADROOM, PoolCaps};
use crate::render::{Renderer, SceneUpdate};
use crate::scene::data::{HeldTiles, SceneData, SceneLight, TileMode};
use crate::scene::rock::RockTable;
use crate::settings::{ClipBox, Settings};
use crate::stream::residency::{self, Budget, Residency, TileFootprint};
use crate::view::camera::Camera;

/// What a view over budget keeps to choose tiles again as its camera moves.
#[derive(Debug)]
pub struct Streaming {
    pkg: Package,
    tiles: Vec<TileFootprint>,
    budget: Budget,
    aspect: f32,
    lights_m: Vec<Vec3>,
    light_reach_m: f32,
    /// `--gpu-memory`: the renderer's tile pools take this much (`budget` keeps their headroom
    /// free).
    pool_bytes: u64,
    /// Read (format 1.1) or classified once: every load holds every tile in some form, so every
    /// load has the same rock (`from_package_with_rock`).
    rock: RockTable,
}

impl Streaming {
    /// Every tile of `pkg` at its far level (the first scene to show, small enough to fetch
    /// before anything else), and what chooses finer tiles from then on. `tiles`: the package's
    /// [`residency::footprints`]; `budget` its `gpu_bytes` and `points` (`--gpu-memory`,
    /// `--point-budget`); `aspect` the image's; `adjust` changes the far scene's lights before
    /// they are kept for residency (`--lamps`).
    pub fn far_first(
        pkg: Package,
        tiles: Vec<TileFootprint>,
        budget: Budget,
        aspect: f32,
        settings: &Settings,
        adjust: impl FnOnce(&mut SceneData),
    ) -> Result<(SceneData, Self)> {
        let mut far = SceneData::from_package_with(&pkg, |_| TileMode::Far)?;
        adjust(&mut far);
        let largest_tile_m = tiles.iter().map(|t| (t.max_m - t.min_m).max_element()).fold(0.0, f32::max);
        // Residency fills the pools but for their headroom (pool.rs).
        let fill = Budget { gpu_bytes: (budget.gpu_bytes as f64 * (1.0 - POOL_HEADROOM)) as u64, ..budget };
        let streaming = Self {
            pkg,
            tiles,
            budget: fill,
            aspect,
            lights_m: far.lights.iter().map(|l| l.position_m).collect(),
            light_reach_m: settings.max_distance_m.unwrap_or(largest_tile_m),
            rock: far.rock.clone(),
            pool_bytes: budget.gpu_bytes,
        };
        Ok((far, streaming))
    }

    /// Every tile of the package with its box and its costs full, coarse and far.
    pub fn tiles(&self) -> &[TileFootprint] {
        &self.tiles
    }

    pub(crate) fn tile_count(&self) -> usize {
        self.tiles.len()
    }

    /// The package tiles are read from.
    pub fn package(&self) -> &Package {
        &self.pkg
    }

    /// The package, to add the byte ranges a browser fetched ([`Package::insert`]).
    pub fn package_mut(&mut self) -> &mut Package {
        &mut self.pkg
    }

    /// `--gpu-memory`: what the renderer's tile pools take.
    pub(crate) fn pool_bytes(&self) -> u64 {
        self.pool_bytes
    }

    /// Residency keeps within these pools from now on (with their headroom taken off already).
    pub(crate) fn set_pool_limits(&mut self, caps: PoolCaps) {
        self.budget.pools = Some(caps);
    }

    /// The residency for a camera, whose view `clip` cuts.
    pub fn choose(&self, cam: &Camera, clip: Option<ClipBox>) -> Result<Residency> {
        let view = residency::View {
            eye_m: cam.eye_m,
            forward: cam.look_at_m - cam.eye_m,
            up: cam.up,
            fov_y_rad: cam.fov_y_deg.to_radians(),
            aspect: self.aspect,
            lights_m: self.lights_m.clone(),
            light_reach_m: self.light_reach_m,
            clip,
        };
        residency::choose(&self.tiles, &view, self.budget)
    }

    /// Every tile at its far level: what [`Streaming::far_first`]'s scene holds.
    pub fn far_residency(&self) -> Residency {
        let decisions = self
            .tiles
            .iter()
            .map(|t| residency::Decision {
                tile: t.index,
                relevance: residency::Relevance::Other,
                distance_m: 0.0,
                mode: TileMode::Far,
            })
            .collect();
        let far_bytes: u64 = self.tiles.iter().map(|t| t.far.bytes).sum();
        let totals = residency::ResidencyTotals {
            budget: self.budget,
            resident_bytes: far_bytes,
            coarse_bytes: far_bytes,
            surfels: self.tiles.iter().map(|t| t.far.surfels).sum(),
            full_tiles: 0,
            coarse_tiles: 0,
            far_tiles: self.tiles.len(),
            visible_coarse: 0,
        };
        Residency { decisions, totals }
    }

    /// The sections [`Streaming::load`] reads for `r`.
    pub fn sections_for(&self, r: &Residency) -> Vec<SectionInfo> {
        sections_for(&self.pkg, &r.modes(), true)
    }

    /// The scene of a residency with the job's `lights` (`--lamps`, a headlamp: chosen once).
    pub fn load(&self, r: &Residency, lights: Vec<SceneLight>, headlamp: bool) -> Result<SceneData> {
        let mut scene = SceneData::from_package_with_rock(&self.pkg, r.mode_of(), self.rock.clone())?;
        (scene.lights, scene.headlamp) = (lights, headlamp);
        // The scene holds what it read: a map's pages need not count in the process's memory.
        self.pkg.release_mapped();
        Ok(scene)
    }

    /// As [`Streaming::load`], reading only the tile forms the renderer does not hold (`held`:
    /// [`SceneData::held_tiles`] of its scene); the others are in the scene as summaries
    /// ([`SceneData::absent`]). Memory then follows the change, not the residency.
    pub fn load_changes(
        &self,
        r: &Residency,
        lights: Vec<SceneLight>,
        headlamp: bool,
        held: &HeldTiles,
    ) -> Result<SceneData> {
        let mut scene = SceneData::from_package_with_held(&self.pkg, r.mode_of(), self.rock.clone(), held)?;
        (scene.lights, scene.headlamp) = (lights, headlamp);
        self.pkg.release_mapped();
        Ok(scene)
    }

    /// As [`Streaming::load_changes`] of `next` over `current` (the residency the renderer holds),
    /// where a damaged section fails the load: each tile at fault ([`damaged_tiles`]) keeps the
    /// form it had and the rest is loaded. Returns the scene, the residency it holds (`next`, its
    /// damaged tiles held back) and the tiles held back. An error where no one tile is at fault.
    pub fn load_changes_holding_damaged(
        &self,
        current: &Residency,
        next: Residency,
        (lights, headlamp): (Vec<SceneLight>, bool),
        held: &HeldTiles,
    ) -> Result<(SceneData, Residency, Vec<DamagedTile>)> {
        match self.load_changes(&next, lights.clone(), headlamp, held) {
            Ok(scene) => Ok((scene, next, Vec::new())),
            Err(e @ Error::Package(_)) => {
                let damaged = damaged_tiles(&self.pkg, current, &next);
                if damaged.is_empty() {
                    return Err(e);
                }
                let caps = damaged.iter().map(|d| (d.tile, d.was)).collect();
                let next = residency::cap_modes(&self.tiles, next, &caps);
                let scene = self.load_changes(&next, lights, headlamp, held)?;
                Ok((scene, next, damaged))
            }
            Err(e) => Err(e),
        }
    }
}

/// A tile whose form in a new residency failed to load on its own (a damaged section): held at
/// the form it had, the rest of the view streaming on.
#[derive(Clone, Debug, PartialEq)]
pub struct DamagedTile {
    pub tile: usize,
    /// The form it keeps: the one it had.
    pub was: TileMode,
    /// What was wrong, as the package reader said it.
    pub problem: String,
}

impl std::fmt::Display for DamagedTile {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        let form = match self.was {
            TileMode::Full => "full",
            TileMode::Coarse => "coarse",
            TileMode::Far => "far",
            TileMode::Skip => "absent",
        };
        write!(
            f,
            "tile {} is damaged in the package ({}); it stays at its {form} form",
            self.tile, self.problem
        )
    }
}

/// The tiles `next` changes from `current` that fail to load on their own, each with the form
/// it had and why. A load reads many tiles and its error names a section; loading each changed
/// tile alone names the tiles to hold back. Empty where each loads alone (the fault is then in a
/// global section, or not in the package).
pub fn damaged_tiles(pkg: &Package, current: &Residency, next: &Residency) -> Vec<DamagedTile> {
    let now = current.modes();
    let mut found = Vec::new();
    for (tile, mode) in next.modes().into_iter().enumerate() {
        let was = now.get(tile).copied().unwrap_or(TileMode::Far);
        if mode == was || mode == TileMode::Skip {
            continue;
        }
        if let Err(e) = SceneData::from_package_with(pkg, |i| if i == tile { mode } else { TileMode::Skip }) {
            found.push(DamagedTile { tile, was, problem: e.to_string() });
        }
    }
    found
}

/// The sections reading `pkg`'s tiles in these modes (indexed by tile; missing: skipped) reads,
/// globals included: what a package fetched by byte ranges must hold before
/// [`SceneData::from_package_with`] (`rock_known: false`) or [`Streaming::load`] (`rock_known:
/// true`, the rock classified already) can read it. The residency footprints
/// ([`residency::footprints`]) need only the directory and the scene where every tile stores its
/// coarse levels (format 1.1 on); otherwise they read each tile's SVO nodes, listed here for
/// every tile.
pub fn sections_for(pkg: &Package, modes: &[TileMode], rock_known: bool) -> Vec<SectionInfo> {
    let mut out: Vec<SectionInfo> = pkg.sections().filter(|s| s.scope == Scope::Global).collect();
    let has = |t: u32, kind, item| pkg.find(kind, Scope::Tile(t), item).is_some();
    // The rock is read from every loaded tile's rock bricks; where a loaded tile with an SVO has
    // none, it is classified from every loaded tile's full leaves instead.
    let loaded: Vec<u32> = (0..pkg.tile_count()).filter(|&t| mode(modes, t) != TileMode::Skip).collect();
    let classify = !rock_known
        && loaded.iter().any(|&t| has(t, SectionKind::SvoNodes, 0) && !has(t, SectionKind::RockBricks, 0));
    for t in 0..pkg.tile_count() {
        let Some(tile) = pkg.tile(t) else { continue };
        let coarse_stored = |k| has(t, SectionKind::CoarseNodes, k) && has(t, SectionKind::CoarseLeaves, k);
        let all_coarse = [TileMode::Coarse, TileMode::Far]
            .iter()
            .all(|m| m.leaf_lod(tile.depth()) == 0 || coarse_stored(m.leaf_lod(tile.depth())));
        let m = mode(modes, t);
        let k = m.leaf_lod(tile.depth());
        let full = m == TileMode::Full || (m != TileMode::Skip && (classify || !coarse_stored(k)));
        for s in tile.sections() {
            let Some(kind) = s.kind else { continue };
            let wanted = match kind {
                // Footprints read the nodes where a level is not stored.
                SectionKind::SvoNodes => full || !all_coarse,
                SectionKind::LeafOpacity
                | SectionKind::LeafAlbedo
                | SectionKind::LeafNdf
                | SectionKind::LeafEmission => full,
                SectionKind::Surfels
                | SectionKind::SurfelsCompact
                | SectionKind::SurfelColorsRaw
                | SectionKind::SurfelColorsBc1
                | SectionKind::SurfelScans => m == TileMode::Full,
                SectionKind::CoarseNodes | SectionKind::CoarseLeaves => k > 0 && s.item == k,
                SectionKind::RockBricks => m != TileMode::Skip && !rock_known,
                _ => false,
            };
            if wanted {
                out.push(s);
            }
        }
    }
    out
}

fn mode(modes: &[TileMode], tile: u32) -> TileMode {
    modes.get(tile as usize).copied().unwrap_or(TileMode::Skip)
}

/// The renderer for a first scene. With `streaming` and the residency `sized_for`, its pools take
/// the whole `--gpu-memory` in the mix of that residency's tiles (the first view's: natively the
/// scene itself, in a browser the view the far scene is drawn for while its tiles arrive), so the
/// tiles of later views replace these in place (pool.rs), and residency keeps within each pool
/// from then on. Without, a renderer for the scene as it is.
pub fn renderer_for(
    gpu: &Gpu,
    scene: &SceneData,
    settings: Settings,
    streaming: Option<(&mut Streaming, &Residency)>,
) -> Result<Renderer> {
    let Some((st, sized_for)) = streaming else { return Renderer::new(gpu, scene, settings) };
    let tiles = st.tile_count() as u64;
    let used = sized_for.decisions.iter().fold(PoolCaps { tiles, ..Default::default() }, |acc, d| {
        let c = st.tiles.iter().find(|t| t.index == d.tile).map(|t| t.cost(d.mode)).unwrap_or_default();
        PoolCaps {
            tiles: acc.tiles,
            nodes: acc.nodes + c.nodes,
            leaves: acc.leaves + c.leaves,
            surfels: acc.surfels + c.surfels,
        }
    });
    let used = used.at_least(PoolCaps { tiles, ..PoolCaps::of(scene) });
    // Each pool also fits the device's largest binding (a browser's is often WebGPU's default).
    let limits = gpu.device.limits();
    let binding = limits.max_storage_buffer_binding_size.min(limits.max_buffer_size);
    let caps = PoolCaps::filling(used, st.pool_bytes(), settings.radiance_f16).within_binding(
        used,
        binding,
        settings.radiance_f16,
    );
    let r = Renderer::with_pools(gpu, scene, settings, caps)?;
    st.set_pool_limits(r.pool_caps().less(POOL_HEADROOM));
    Ok(r)
}

/// How a change of tiles reached the renderer.
#[derive(Clone, Debug, Default)]
pub struct Swapped {
    /// Written in place into the pools (None where the renderer was made anew).
    pub update: Option<SceneUpdate>,
    /// The pools could not take the scene (its lights or bounds differ): a new renderer, with the
    /// light of tiles resident before and after carried through a read-back (natively; a
    /// browser cannot block on one, and lights the new renderer from the start).
    pub made_anew: bool,
    /// Leaves whose light was kept.
    pub carried_leaves: usize,
}

/// Puts `new_scene` into the renderer in place of `scene` (which it replaces): only the new tile
/// forms are written; tiles resident before and after keep their place and light. `new_scene`
/// may leave out the forms the renderer holds ([`Streaming::load_changes`]), and leave its full
/// tiles' surfels in `pkg`, its package, to be decoded as they are written; where the renderer
/// must be made anew after all, `reload` reads the residency whole. The light is not settled
/// here: the caller decides how many bounces to spend.
pub fn swap_tiles(
    gpu: &Gpu,
    r: &mut Renderer,
    scene: &mut SceneData,
    (mut new_scene, pkg): (SceneData, &Package),
    reload: impl FnOnce() -> Result<SceneData>,
) -> Result<Swapped> {
    // The lights are the scene's as they are now, with their circuits' state (a residency asked
    // for before a circuit was switched arrives with the lights of then), and so is the story (a
    // story file's amendments).
    new_scene.take_lights_and_story(scene);
    let updated = r.update_scene(&new_scene, Some(pkg))?;
    // The surfels decoded as they were written read the map again.
    pkg.release_mapped();
    if let Some(u) = updated {
        *scene = new_scene;
        return Ok(Swapped { carried_leaves: u.carried_leaves, update: Some(u), made_anew: false });
    }
    if !new_scene.holds_all_tiles() {
        let whole = reload()?;
        new_scene.restore_tile_data(whole)?;
    }
    let carried_leaves = anew(gpu, r, scene, &new_scene, !cfg!(target_arch = "wasm32"))?;
    *scene = new_scene;
    Ok(Swapped { update: None, made_anew: true, carried_leaves })
}

/// A new renderer for `new` in `r`'s pools (same capacities and clip box), seeded with the light
/// `r` held for `old`'s tiles where `carry` (a read-back: natively only). Returns the leaves
/// whose light was carried.
fn anew(gpu: &Gpu, r: &mut Renderer, old: &SceneData, new: &SceneData, carry: bool) -> Result<usize> {
    let carried = if carry { Some(r.light_by_tile(old)?) } else { None };
    let (caps, clip) = (r.pool_caps(), r.clip());
    *r = Renderer::with_pools(gpu, new, r.settings().clone(), caps)?;
    r.set_clip(clip);
    match carried {
        Some(c) => r.seed_light(new, &c),
        None => Ok(0),
    }
}

/// After `scene`'s lights changed (a lamp edited, a circuit switched: SceneData::relight,
/// switch_circuit): the renderer takes the new lights in place where they fit
/// ([`Renderer::edit_lights`]: the shadow faces, direct light and first bounces of the changed
/// lights' reach only, every other leaf's light kept as the start). Where they do not (more
/// shadow faces or light records than the renderer has room for, no light left), a renderer for
/// the new lights in the same pools: natively every leaf's light is carried over as the start
/// (a browser cannot block on the read-back and starts from darkness), shadow maps and direct
/// light are made again for every light. Says which it did. `reload` gives a scene whose tile
/// data was let go ([`SceneData::release_tile_data`]) its data again, for the new renderer.
pub fn relit(
    gpu: &Gpu,
    r: &mut Renderer,
    scene: &mut SceneData,
    reload: impl FnOnce(&mut SceneData) -> Result<()>,
) -> Result<Relit> {
    if let Some(edit) = r.edit_lights(scene)? {
        return Ok(Relit::InPlace(edit));
    }
    reload(scene)?;
    // The tiles are the same; only the lights changed. Nothing lights the scene now: nothing
    // propagates, so nothing may be carried (the old light would stay on the walls).
    let carried = anew(gpu, r, scene, scene, !cfg!(target_arch = "wasm32") && scene.has_own_light())?;
    r.invalidate_lights();
    Ok(Relit::Anew { carried_leaves: carried })
}

/// What [`relit`] did.
#[derive(Clone, Debug, PartialEq, serde::Serialize)]
#[serde(rename_all = "snake_case")]
pub enum Relit {
    /// The renderer took the lights in place.
    InPlace(crate::render::LightEdit),
    /// A new renderer in the same pools, with the leaves whose light it carried.
    Anew { carried_leaves: usize },
}
