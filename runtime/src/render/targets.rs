//! The view's targets as one part of the renderer: the G-buffer and shade passes, the targets of
//! the current size and what they show, still frames (anti-aliasing at rest) and exposure after
//! the fact, the clip box and the detail a viewer trades while moving. Whether the G-buffer still
//! shows what the next frame asks for is decided here ([`ViewTargets::shows`]); the renderer's
//! scheduler records the passes and reports which ran ([`ViewTargets::ran`]).

use glam::Mat4;

use crate::error::{Error, Result};
use crate::gpu::Gpu;
use crate::gpu::types::SplatUniform;
use crate::light::plan::Pass;
use crate::passes::{self, gbuffer, shade};
use crate::settings::{ClipBox, ViewMode};
use crate::view::camera::Camera;

/// The G-buffer and shade passes, the current view's targets and the still frame under way.
#[derive(Debug)]
pub(super) struct ViewTargets {
    pub(super) gbuffer: gbuffer::Gbuffer,
    pub(super) shade: shade::Shade,
    /// The targets of the last frame's size, and what they show; `None` before the first frame.
    pub(super) view: Option<View>,
    /// Anti-aliasing at rest (passes/resolve.rs, render/still.rs).
    pub(super) stills: Stills,
    /// The camera's view-projection of the G-buffer (tiles outside it are not drawn).
    pub(super) camera_view_proj: Option<Mat4>,
    /// Something the G-buffer shows changed since it was drawn (tiles, detail, clip, view mode).
    stale: bool,
    /// Multiplies the level of detail's pixel floor for the camera's view (a viewer trading
    /// detail for time while moving: view/frame_target.rs).
    lod_detail: f32,
    clip: Option<ClipBox>,
}

impl ViewTargets {
    pub(super) fn new(gbuffer: gbuffer::Gbuffer, shade: shade::Shade, stills: Stills) -> Self {
        Self {
            gbuffer,
            shade,
            view: None,
            stills,
            camera_view_proj: None,
            stale: false,
            lod_detail: 1.0,
            clip: None,
        }
    }

    /// The current view, or an error naming `pass` where no frame was drawn yet.
    pub(super) fn get(&self, pass: &'static str) -> Result<&View> {
        self.view.as_ref().ok_or(Error::Internal { what: pass, message: "no view was prepared".into() })
    }

    /// Whether the G-buffer holds `camera` at `width` x `height` as it is now (same jitter,
    /// nothing changed since it was drawn).
    pub(super) fn shows(&self, camera: &Camera, width: u32, height: u32) -> bool {
        self.view.as_ref().is_some_and(|v| {
            !self.stale
                && v.camera == *camera
                && v.jitter_px == self.stills.jitter_px
                && v.targets.width == width
                && v.targets.height == height
        })
    }

    /// The G-buffer must be drawn again (the tiles it drew changed).
    pub(super) fn invalidate(&mut self) {
        self.stale = true;
    }

    /// Whether something the G-buffer shows changed since it was drawn.
    pub(super) fn is_stale(&self) -> bool {
        self.stale
    }

    pub(super) fn lod_detail(&self) -> f32 {
        self.lod_detail
    }

    /// The detail factor (at least 1; not finite: 1).
    pub(super) fn set_lod_detail(&mut self, detail: f32) {
        let detail = if detail.is_finite() { detail.max(1.0) } else { 1.0 };
        if detail != self.lod_detail {
            self.lod_detail = detail;
            self.stale = true;
        }
    }

    pub(super) fn clip(&self) -> Option<ClipBox> {
        self.clip
    }

    pub(super) fn set_clip(&mut self, clip: Option<ClipBox>) {
        if clip != self.clip {
            self.stale = true;
        }
        self.clip = clip;
    }

    /// The view mode changes from `old` to `new`: the scan view colours the G-buffer's albedo,
    /// the others only shade it differently.
    pub(super) fn change_mode(&mut self, old: ViewMode, new: ViewMode) {
        if (new == ViewMode::Scan) != (old == ViewMode::Scan) {
            self.stale = true;
        }
    }

    /// GPU bytes of the current view's G-buffer, outputs and anti-aliasing sums.
    pub(super) fn bytes(&self) -> u64 {
        self.view.as_ref().map_or(0, |v| {
            let px = u64::from(v.targets.width) * u64::from(v.targets.height);
            px * 4 * 4 + v.outputs.frame.size() + v.sums.as_ref().map_or(0, |s| s.bytes())
        })
    }

    /// Writes the camera's splat uniform (`view_proj` is the unjittered one) and (re)makes the
    /// targets where the size changed (new targets count as shaded in `mode`).
    pub(super) fn prepare(
        &mut self,
        gpu: &Gpu,
        camera: &Camera,
        (w, h): (u32, u32),
        (uniform, view_proj): (&SplatUniform, Mat4),
        mode: ViewMode,
    ) -> Result<()> {
        self.gbuffer.set_camera(gpu, uniform);
        self.camera_view_proj = Some(view_proj);
        let reuse = self.view.as_ref().is_some_and(|v| v.targets.width == w && v.targets.height == h);
        if !reuse {
            // The largest per-view buffer first, before any target is allocated.
            let pixels = u64::from(w) * u64::from(h);
            gpu.check_buffer("shade hdr", pixels * 16, wgpu::BufferUsages::STORAGE)?;
            let targets = self.gbuffer.targets(gpu, w, h)?;
            let outputs = self.shade.outputs(gpu, &targets)?;
            self.view = Some(View {
                camera: *camera,
                jitter_px: self.stills.jitter_px,
                targets,
                outputs,
                shaded: mode,
                sums: None,
            });
        } else if let Some(v) = self.view.as_mut() {
            v.camera = *camera;
            v.jitter_px = self.stills.jitter_px;
        }
        Ok(())
    }

    /// What the passes in `ran` leave behind: a G-buffer drawn is current, pixels shaded show
    /// `mode`.
    pub(super) fn ran(&mut self, ran: &[Pass], mode: ViewMode) {
        if ran.contains(&Pass::Gbuffer) {
            self.stale = false;
        }
        if ran.contains(&Pass::Shade)
            && let Some(v) = self.view.as_mut()
        {
            v.shaded = mode;
        }
    }
}

#[derive(Debug)]
pub(super) struct View {
    pub(super) camera: Camera,
    /// The sub-pixel offset the G-buffer was drawn at (anti-aliasing at rest).
    pub(super) jitter_px: [f32; 2],
    pub(super) targets: gbuffer::Targets,
    pub(super) outputs: shade::Outputs,
    /// The view the frame's pixels were last shaded in ([`Renderer::expose`] re-tonemaps only a
    /// lit one).
    pub(super) shaded: ViewMode,
    /// Anti-aliasing's sums, from the first still frame of this size.
    pub(super) sums: Option<passes::resolve::Sums>,
}

/// Anti-aliasing at rest: the pass, the sub-pixel offset the next frame draws at, the still frame
/// gathered so far (what it was gathered for, and its samples), and the next frame's place in it
/// (sample, of) for the plan. Beside it the other change to a finished frame, its exposure
/// (made on first use: viewers never call it).
#[derive(Debug)]
pub(super) struct Stills {
    pub(super) resolve: passes::resolve::Resolve,
    pub(super) expose: Option<passes::expose::Expose>,
    pub(super) jitter_px: [f32; 2],
    pub(super) still: Option<(StillKey, u32)>,
    pub(super) next: Option<(u32, u32)>,
}

impl Stills {
    pub(super) fn new(gpu: &Gpu) -> Result<Self> {
        let resolve = gpu.scoped("resolve", || passes::resolve::Resolve::new(gpu))?;
        Ok(Self { resolve, expose: None, jitter_px: [0.0; 2], still: None, next: None })
    }
}

/// What a still frame was gathered for: the same key, the same image.
#[derive(Clone, Debug, PartialEq)]
pub(super) struct StillKey {
    pub(super) camera: Camera,
    pub(super) size: (u32, u32),
    pub(super) clip: Option<ClipBox>,
    pub(super) detail_bits: u32,
    pub(super) of: u32,
    /// The frame's parameters without the jitter (bytes: they hold floats).
    pub(super) params: Vec<u8>,
}
