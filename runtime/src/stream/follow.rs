//! Tiles that follow a moving camera, for a package over its GPU budget: the next residency is
//! chosen and its tiles read from the package on a loader thread while frames render
//! ([`Follow`]), then swapped into the renderer's pools in place ([`streaming::swap_tiles`]). `grotto render
//! --path` waits for each frame's tiles; `grotto view` takes them when they are ready, so flying
//! never waits for the disk.

use std::sync::Arc;
use std::thread::JoinHandle;

use crate::error::{Error, Result};
use crate::gpu::Gpu;
use crate::render::Renderer;
use crate::scene::data::{SceneData, SceneLight};
use crate::settings::{ClipBox, Settings};
use crate::stream::residency::{self, Residency};
use crate::stream::streaming::{self, Streaming};
use crate::view::camera::Camera;

/// The renderer for a job's first scene ([`streaming::renderer_for`]), and the loader that keeps its
/// tiles following the camera where the package is over budget (`streaming` and the `first`
/// residency it was chosen with, from [`crate::engine::open`]).
pub(crate) fn start(
    gpu: &Gpu,
    scene: &SceneData,
    settings: Settings,
    streaming: Option<Streaming>,
    first: Option<Residency>,
    upload_per_frame: Option<u64>,
) -> Result<(Renderer, Option<Follow>)> {
    match (streaming, first) {
        (Some(mut st), Some(first)) => {
            let r = streaming::renderer_for(gpu, scene, settings, Some((&mut st, &first)))?;
            Ok((r, Some(Follow::new(st, first, upload_per_frame))))
        }
        _ => Ok((streaming::renderer_for(gpu, scene, settings, None)?, None)),
    }
}

/// A residency chosen on the loader thread: the scene to swap in where the tiles' forms changed,
/// and the changes `--upload-per-frame` left for later.
#[derive(Debug)]
pub(crate) struct Arrived {
    pub(crate) residency: Residency,
    pub(crate) scene: Option<SceneData>,
    pub(crate) deferred: usize,
}

/// The loader thread and the residency the renderer holds.
#[derive(Debug)]
pub(crate) struct Follow {
    streaming: Arc<Streaming>,
    current: Residency,
    loading: Option<JoinHandle<Result<Arrived>>>,
    upload_per_frame: Option<u64>,
}

impl Follow {
    /// `current`: the residency the renderer was made with.
    pub(crate) fn new(streaming: Streaming, current: Residency, upload_per_frame: Option<u64>) -> Self {
        Self { streaming: Arc::new(streaming), current, loading: None, upload_per_frame }
    }

    pub(crate) fn current(&self) -> &Residency {
        &self.current
    }

    /// Whether a residency is being chosen and read.
    pub(crate) fn busy(&self) -> bool {
        self.loading.is_some()
    }

    /// Starts choosing and reading the tiles of `cam` (lit by `lights`, which every load keeps),
    /// unless a load is under way already.
    pub(crate) fn request(
        &mut self,
        cam: &Camera,
        clip: Option<ClipBox>,
        lights: Vec<SceneLight>,
        headlamp: bool,
    ) {
        if self.loading.is_some() {
            return;
        }
        let (st, now, cam, limit) =
            (self.streaming.clone(), self.current.clone(), *cam, self.upload_per_frame);
        self.loading = Some(std::thread::spawn(move || {
            let mut next = st.choose(&cam, clip)?;
            let mut deferred = 0;
            if let Some(max) = limit {
                (next, deferred) = residency::limit_uploads(st.tiles(), &now, next, max);
            }
            let scene =
                if next.modes() == now.modes() { None } else { Some(st.load(&next, lights, headlamp)?) };
            Ok(Arrived { residency: next, scene, deferred })
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
        Ok(Some(arrived))
    }

    /// Gives `scene` (the renderer's, its tile data let go) its tile data again, read from the
    /// package for the residency the renderer holds: for a renderer made anew (another preset,
    /// lights that do not fit in place). Nothing to do where the scene holds its data.
    pub(crate) fn reload_into(&self, scene: &mut SceneData) -> Result<()> {
        if scene.released.is_none() {
            return Ok(());
        }
        let again = self.streaming.load(&self.current, Vec::new(), false)?;
        scene.restore_tile_data(again)
    }

    /// The renderer now holds `r` (its scene swapped in, or unchanged).
    pub(crate) fn accept(&mut self, r: Residency) {
        self.current = r;
    }
}
