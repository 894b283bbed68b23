//! Tiles that follow a moving camera, for a package over its GPU budget: the next residency is
//! chosen and its tiles read from the package on a loader thread while frames render
//! ([`Follow`]), then swapped into the renderer's pools in place ([`streaming::swap_tiles`]). `grotto render
//! --path` waits for each frame's tiles; `grotto view` takes them when they are ready, so flying
//! never waits for the disk.

use std::collections::BTreeMap;
use std::sync::Arc;
use std::thread::JoinHandle;

use crate::error::{Error, Result};
use crate::gpu::Gpu;
use crate::render::Renderer;
use crate::scene::data::{HeldTiles, SceneData, SceneLight, TileMode};
use crate::settings::{ClipBox, Settings};
use crate::stream::residency::{self, Residency};
use crate::stream::streaming::{self, DamagedTile, Streaming};
use crate::view::camera::Camera;

/// The renderer for a job's first scene ([`streaming::renderer_for`]), and the loader that keeps its
/// tiles following the camera where the package is over budget (`streaming` and the `first`
/// residency it was chosen with, from [`crate::engine::open`]). Over budget, `scene` is the far
/// scene [`crate::engine::open`] gives: the renderer is made from it, with pools for `first`, and
/// `first`'s tiles are then read and written a few at a time ([`Follow::fill`]), so the first
/// residency is never held whole on the CPU. `scene` ends as the first residency's, its tile
/// data let go. `steps`: `--upload-per-frame` and a loader step's bytes
/// ([`crate::engine::RenderOptions::loader_steps`]).
pub(crate) fn start(
    gpu: &Gpu,
    scene: &mut SceneData,
    settings: Settings,
    streaming: Option<Streaming>,
    first: Option<Residency>,
    steps: (Option<u64>, u64),
) -> Result<(Renderer, Option<Follow>)> {
    match (streaming, first) {
        (Some(mut st), Some(first)) => {
            let far = st.far_residency();
            let mut r = streaming::renderer_for(gpu, scene, settings, Some((&mut st, &first)))?;
            scene.release_tile_data();
            st.package().release_mapped();
            let mut follow = Follow::new(st, far, steps);
            follow.fill(gpu, &mut r, scene, &first)?;
            Ok((r, Some(follow)))
        }
        _ => Ok((streaming::renderer_for(gpu, scene, settings, None)?, None)),
    }
}

/// Tile bytes (as residency counts them) one loader step reads at most, but for a single tile
/// larger than this: what the CPU holds of a change of tiles while it is written. A memory
/// budget (`--memory`) gives its own (`MemoryPlan::step_bytes`).
pub(crate) const STEP_BYTES: u64 = 64 << 20;

/// A residency chosen on the loader thread: the scene to swap in where the tiles' forms changed,
/// and the changes `--upload-per-frame` left for later.
#[derive(Debug)]
pub(crate) struct Arrived {
    pub(crate) residency: Residency,
    pub(crate) scene: Option<SceneData>,
    pub(crate) deferred: usize,
    /// Changes left for the same view beyond this step (a loader step's bytes): asked for again,
    /// they arrive in later steps.
    pub(crate) rest: usize,
    /// Tiles found damaged by this load, held at the form they had.
    damaged: Vec<DamagedTile>,
}

/// The loader thread and the residency the renderer holds.
#[derive(Debug)]
pub(crate) struct Follow {
    streaming: Arc<Streaming>,
    current: Residency,
    loading: Option<JoinHandle<Result<Arrived>>>,
    upload_per_frame: Option<u64>,
    /// Tile bytes a step reads at most, but for one larger tile ([`STEP_BYTES`]).
    step_bytes: u64,
    /// Tiles held back as damaged, and the finest form each may take: every later residency
    /// keeps them there.
    damaged: BTreeMap<usize, TileMode>,
    /// What was found damaged and not yet said ([`Follow::take_notices`]).
    notices: Vec<String>,
}

impl Follow {
    /// `current`: the residency the renderer was made with; `--upload-per-frame` and the bytes of
    /// a loader step.
    pub(crate) fn new(
        streaming: Streaming,
        current: Residency,
        (upload_per_frame, step_bytes): (Option<u64>, u64),
    ) -> Self {
        Self {
            streaming: Arc::new(streaming),
            current,
            loading: None,
            upload_per_frame,
            step_bytes,
            damaged: BTreeMap::new(),
            notices: Vec::new(),
        }
    }

    pub(crate) fn current(&self) -> &Residency {
        &self.current
    }

    /// Whether a residency is being chosen and read.
    pub(crate) fn busy(&self) -> bool {
        self.loading.is_some()
    }

    /// Starts choosing and reading the tiles of `cam` (lit by `lights`, which every load keeps),
    /// unless a load is under way already. Only the forms not in `held` (what the renderer holds:
    /// [`SceneData::held_tiles`]) are read.
    pub(crate) fn request(
        &mut self,
        cam: &Camera,
        clip: Option<ClipBox>,
        (lights, headlamp): (Vec<SceneLight>, bool),
        held: HeldTiles,
    ) {
        if self.loading.is_some() {
            return;
        }
        let (st, now, cam, limit, caps, step) = (
            self.streaming.clone(),
            self.current.clone(),
            *cam,
            self.upload_per_frame,
            self.damaged.clone(),
            self.step_bytes,
        );
        self.loading = Some(std::thread::spawn(move || {
            let mut next = residency::cap_modes(st.tiles(), st.choose(&cam, clip)?, &caps);
            let (mut deferred, mut rest) = (0, 0);
            match limit {
                // Changes past a frame's upload bound wait for later frames' views.
                Some(max) => (next, deferred) = residency::limit_uploads(st.tiles(), &now, next, max),
                // Otherwise a change is read a step at a time, the rest asked for again for the
                // same view: the CPU holds one step's tiles, not a whole change's (a large
                // package's change of view may be many tiles of 90 MB).
                None => (next, rest) = residency::limit_uploads(st.tiles(), &now, next, step),
            }
            if next.modes() == now.modes() {
                return Ok(Arrived { residency: next, scene: None, deferred, rest, damaged: Vec::new() });
            }
            let (scene, next, damaged) =
                st.load_changes_holding_damaged(&now, next, (lights, headlamp), &held)?;
            Ok(Arrived { residency: next, scene: Some(scene), deferred, rest, damaged })
        }));
    }

    /// The requested residency where the loader has finished, without waiting.
    pub(crate) fn poll(&mut self) -> Result<Option<Arrived>> {
        match &self.loading {
            Some(h) if h.is_finished() => self.wait(),
            _ => Ok(None),
        }
    }

    /// The requested residency, waiting for the loader; None where none was requested.
    pub(crate) fn wait(&mut self) -> Result<Option<Arrived>> {
        let Some(h) = self.loading.take() else { return Ok(None) };
        let arrived = h.join().map_err(|_| Error::Internal {
            what: "tile loader",
            message: "the loader thread panicked".into(),
        })??;
        self.hold_back(&arrived.damaged);
        Ok(Some(arrived))
    }

    /// Keeps `damaged` tiles at the form they had from now on, and says so once.
    fn hold_back(&mut self, damaged: &[DamagedTile]) {
        for d in damaged {
            self.damaged.insert(d.tile, d.was);
            self.notices.push(d.to_string());
        }
    }

    /// What was found damaged since the last call, one line a tile.
    pub(crate) fn take_notices(&mut self) -> Vec<String> {
        std::mem::take(&mut self.notices)
    }

    /// Gives `scene` (the renderer's, its tile data let go) its tile data again, read from the
    /// package for the residency the renderer holds: for a renderer made anew (another preset,
    /// lights that do not fit in place). Nothing to do where the scene holds its data.
    pub(crate) fn reload_into(&self, scene: &mut SceneData) -> Result<()> {
        if scene.holds_all_tiles() {
            return Ok(());
        }
        let again = self.streaming.load(&self.current, Vec::new(), false)?;
        scene.restore_tile_data(again)
    }

    /// The package the tiles are read from.
    pub(crate) fn package(&self) -> &grotto_format::Package {
        self.streaming.package()
    }

    /// Reads residency `r` whole (for [`streaming::swap_tiles`] where the renderer must be made
    /// anew).
    pub(crate) fn load_whole(&self, r: &Residency) -> Result<SceneData> {
        self.streaming.load(r, Vec::new(), false)
    }

    /// Brings the renderer from the residency it holds to `target`, reading and writing a few
    /// tiles at a time (a loader step's bytes at most, but for one larger tile): each step's
    /// tiles take their forms in `target`, the others keep theirs, so every step's residency is
    /// within `target`'s pools (a tile held coarser costs no more). `scene` is the renderer's,
    /// with its tile data let go; it ends as `target`'s (its lights and story kept:
    /// [`streaming::swap_tiles`]), but for tiles found damaged, which keep the form they had.
    /// The light is not settled here.
    pub(crate) fn fill(
        &mut self,
        gpu: &Gpu,
        r: &mut Renderer,
        scene: &mut SceneData,
        target: &Residency,
    ) -> Result<()> {
        let mut step = self.current.clone();
        let mut before = step.clone();
        let held = step.modes();
        let mut pending = 0u64;
        let changes: Vec<&residency::Decision> = target
            .decisions
            .iter()
            .filter(|d| held.get(d.tile).copied().unwrap_or(TileMode::Skip) != d.mode)
            .collect();
        for (k, d) in changes.iter().enumerate() {
            if let Some(mine) = step.decisions.iter_mut().find(|m| m.tile == d.tile) {
                mine.mode = d.mode;
            }
            let footprint = self.streaming.tiles().iter().find(|t| t.index == d.tile);
            pending += footprint.map_or(0, |t| t.cost(d.mode).bytes);
            if pending < self.step_bytes && k + 1 < changes.len() {
                continue;
            }
            pending = 0;
            let (next, loaded, damaged) = self.streaming.load_changes_holding_damaged(
                &before,
                step,
                (Vec::new(), false),
                &scene.held_tiles(),
            )?;
            self.hold_back(&damaged);
            let whole = || self.streaming.load(&loaded, Vec::new(), false);
            streaming::swap_tiles(gpu, r, scene, (next, self.streaming.package()), whole)?;
            scene.release_tile_data();
            (before, step) = (loaded.clone(), loaded);
        }
        // The target, less what was found damaged (its totals counted again).
        self.current = residency::cap_modes(self.streaming.tiles(), target.clone(), &self.damaged);
        Ok(())
    }

    /// The renderer now holds `r` (its scene swapped in, or unchanged).
    pub(crate) fn accept(&mut self, r: Residency) {
        self.current = r;
    }
}
