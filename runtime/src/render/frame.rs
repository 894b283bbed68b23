//! The frame scheduler: the plan's inputs gathered from the renderer's parts, the passes recorded
//! in one command buffer and error scope (a failing frame records each alone to name it), each
//! part told which passes ran, and the frame read back.

use web_time::Instant;

use crate::error::{Error, Result};
use crate::gpu::types::{Params, SplatUniform, flags};
use crate::light::plan::{self, EffectPlan, Pass, PlanInputs};
use crate::view::camera::Camera;

use crate::passes::splat::SplatRun;
use crate::render::chunks::{Lod, Viewer};
use crate::render::counters::PassWork;
use crate::render::renderer::Renderer;
use crate::settings::{IndirectFilter, ViewMode};

impl Renderer {
    pub(super) fn inputs(&self, frame: Option<(&Camera, u32, u32)>) -> PlanInputs {
        let gbuffer_valid = frame.is_some_and(|(c, w, h)| self.targets.shows(c, w, h));
        PlanInputs {
            headlamp: self.lights.headlamp,
            point_lights: self.lights.point,
            spot_lights: self.lights.spot,
            shadows_enabled: self.settings.shadows,
            shadowed: self.shadows.shadowed(),
            shadow_budget: self.settings.shadowed_lights,
            fallback: self.settings.shadow_fallback.describe(),
            lights_in_range: self.lights.in_range,
            specular_materials: self.specular_materials,
            specular_surfels: self.specular_surfels,
            emissive_leaves: self.emissive,
            environment: self.environment,
            ambient: self.settings.background.iter().any(|&b| b > 0.0),
            env_valid: self.light.env_valid,
            direct_valid: self.light.direct_valid,
            light_edit: self.light.light_edit.as_ref().map(|e| e.scope.clone()),
            shadow_catch_up: self.shadow_catch_up(),
            bounces_done: self.stats_now.bounces_done,
            bounce_budget: self.settings.bounces,
            last_change: self.stats_now.last_change,
            convergence_tolerance: self.settings.convergence_tolerance,
            tiles_pending: self.light.activity.pending_tiles(),
            tiles_total: self.light.activity.tiles(),
            tiles_why: self.light.activity.pending_why(),
            frame: frame.is_some(),
            gbuffer_valid,
            splats: if self.targets.gbuffer.blends() {
                "blended splats: the front-most disc, then every disc within a radius behind it that faces as it does"
            } else if self.settings.splat_blend {
                "front-most discs: the adapter cannot blend f16 targets"
            } else {
                "front-most discs (splat blending off)"
            },
            plain_view: (!self.settings.view.shows_light()).then(|| self.settings.view.name()),
            light_held: self.light.held_because(),
            bounce_part: self.light.bounce_at.map(|next| (next, self.light.active_items())),
            still: self.targets.stills.next.filter(|_| frame.is_some()),
        }
    }

    /// The plan the next [`Renderer::update_light`] (no camera) or [`Renderer::render`] would run.
    pub fn plan(&self, frame: Option<(&Camera, u32, u32)>) -> EffectPlan {
        let mut p = plan::plan(&self.inputs(frame));
        for step in &mut p.steps {
            if !step.run && self.forced.contains(&step.pass) {
                // Shade needs a G-buffer and the light passes need nothing: any pass may be forced
                // except gbuffer/shade without a frame.
                if frame.is_some() || !matches!(step.pass, Pass::Gbuffer | Pass::Shade) {
                    step.run = true;
                    step.reason = format!("forced (plan said: {})", step.reason);
                }
            }
        }
        p
    }

    /// Runs these passes even where the plan would skip them (tests prove skipping changes
    /// nothing; `--force` on the command line does the same for a user who doubts the plan).
    pub fn set_forced(&mut self, passes: &[Pass]) {
        self.forced = passes.to_vec();
    }

    /// Renders one frame (running whatever light work the plan asks for first: progressive, at
    /// most one bounce per frame).
    pub fn render(&mut self, camera: &Camera, width: u32, height: u32) -> Result<(Frame, EffectPlan)> {
        let p = self.draw(camera, width, height)?;
        Ok((self.read_frame()?, p))
    }

    /// The buffer the last frame's HDR radiance is in (4 f32 a pixel, rows top to bottom, from
    /// its start) and its bytes there: what a browser reads back without blocking for its
    /// exposure.
    pub fn hdr_output(&self) -> Option<(&wgpu::Buffer, u64)> {
        self.targets.view.as_ref().map(|v| (&v.outputs.frame, v.outputs.hdr_bytes()))
    }

    /// The last frame [`Renderer::draw`] (or render) made, read back.
    pub(crate) fn read_frame(&self) -> Result<Frame> {
        let view = self.targets.get("shade")?;
        let (width, height) = (view.targets.width, view.targets.height);
        let pixels = u64::from(width) * u64::from(height);
        let bytes = self.gpu.read_buffer(&view.outputs.frame, view.outputs.frame.size())?;
        let (hdr_bytes, ldr_bytes) = bytes.split_at(view.outputs.hdr_bytes() as usize);
        let hdr: Vec<[f32; 4]> = bytemuck::pod_collect_to_vec(hdr_bytes);
        let ldr: Vec<[u8; 4]> = bytemuck::pod_collect_to_vec(&ldr_bytes[..(pixels * 4) as usize]);
        Ok(Frame { width, height, hdr, ldr })
    }

    /// The last frame at the exposure now set ([`Renderer::set_exposure`]), read back:
    /// its pixels tonemapped again from their radiance (passes/expose.rs), the same pixels a frame
    /// drawn at that exposure has, without drawing it again. What automatic exposure needs once
    /// the first frame has measured the light. A frame of a view without light or on a fixed scale
    /// (lux) is returned as it is (no exposure changes it); a still frame's mean of several
    /// samples, which no tone map of its mean radiance gives, is drawn again at one sample.
    pub fn expose(&mut self) -> Result<Frame> {
        let exposure = self.settings.exposure;
        let view = self.targets.get("expose")?;
        let (camera, width, height) = (view.camera, view.targets.width, view.targets.height);
        if !view.shaded.exposed() {
            return self.read_frame();
        }
        if self.targets.stills.still.as_ref().is_some_and(|(_, samples)| *samples > 1) {
            return Ok(self.render(&camera, width, height)?.0);
        }
        if self.targets.stills.expose.is_none() {
            let gpu = &self.gpu;
            self.targets.stills.expose =
                Some(gpu.scoped("expose", || crate::passes::expose::Expose::new(gpu))?);
        }
        if let Some(expose) = &self.targets.stills.expose {
            expose.run(&self.gpu, &self.targets.get("expose")?.outputs.frame, width, height, exposure)?;
        }
        // A still frame begun at the old exposure no longer matches what the frame shows.
        self.targets.stills.still = None;
        self.read_frame()
    }

    /// Renders one frame as [`Renderer::render`] does, leaving it on the GPU ([`Renderer::ldr_output`])
    /// instead of reading it back: what a window presents.
    pub fn draw(&mut self, camera: &Camera, width: u32, height: u32) -> Result<EffectPlan> {
        camera.validate()?;
        Self::check_size(width, height)?;
        self.poll_light()?;
        // One sample a pixel at the centres: any still frame gathered so far is over.
        self.targets.stills.still = None;
        self.targets.stills.next = None;
        self.targets.stills.jitter_px = [0.0; 2];
        let p = self.plan(Some((camera, width, height)));
        self.execute(&p, Some((camera, width, height)), None)?;
        Ok(p)
    }

    /// Checks a frame's size (what every draw asks).
    pub(super) fn check_size(width: u32, height: u32) -> Result<()> {
        if width == 0 || height == 0 || width > 16384 || height > 16384 {
            return Err(Error::Setting {
                name: "size",
                problem: format!("{width}x{height} is outside 1..=16384"),
            });
        }
        Ok(())
    }

    /// The distance in metres from the eye to the surface at pixel `(x, y)` of the last frame
    /// (its own size, rows top to bottom); None where the background shows or outside the frame.
    pub fn distance_at(&self, x: u32, y: u32) -> Result<Option<f32>> {
        let view = self.targets.get("pick")?;
        if x >= view.targets.width || y >= view.targets.height {
            return Ok(None);
        }
        let buf =
            self.gpu.buffer("pick", 256, wgpu::BufferUsages::COPY_SRC | wgpu::BufferUsages::COPY_DST)?;
        let mut enc = self.gpu.device.create_command_encoder(&Default::default());
        crate::render::probe::copy_distance(&mut enc, &view.targets.distance, (x, y), &buf, 0);
        self.gpu.queue.submit([enc.finish()]);
        let b = self.gpu.read_buffer(&buf, 4)?;
        // The G-buffer packs the f32's bits into RGBA8 (packing.wgsl); cleared pixels are 0.
        let d = f32::from_bits(u32::from_le_bytes([b[0], b[1], b[2], b[3]]));
        Ok((d.is_finite() && d > 0.0).then_some(d))
    }

    /// The last frame's tonemapped pixels (one packed RGBA8 u32 a pixel, rows top to bottom, from
    /// word `first_word` of `buffer`) and its size; `None` before the first frame.
    pub fn ldr_output(&self) -> Option<LdrOutput<'_>> {
        self.targets.view.as_ref().map(|v| LdrOutput {
            buffer: &v.outputs.frame,
            first_word: v.outputs.ldr_first_word(),
            width: v.targets.width,
            height: v.targets.height,
        })
    }

    pub(super) fn frame_params(&self, frame: Option<(&Camera, u32, u32)>) -> Params {
        let mut p = self.base_params;
        let s = &self.settings;
        // Auto exposure sets it after the light has settled (`set_exposure`).
        p.exposure = s.exposure;
        let mut f = flags::EMISSION;
        if !self.light.direct_valid || (self.environment && !self.light.env_valid) {
            f |= flags::NEW_SERIES;
        }
        if s.direct && p.light_count > 0 {
            f |= flags::DIRECT;
        }
        if self.light.light_edit.is_some() {
            f |= flags::INJECT_ACTIVE;
        }
        if s.direct && s.shadows && self.shadows.shadowed() < p.light_count as usize {
            f |= flags::FAR_LIGHTS;
        }
        if s.shadows && self.shadows.face_count() > 0 {
            f |= flags::SHADOWS;
        }
        match s.indirect {
            IndirectFilter::Trilinear => f |= flags::INDIRECT,
            IndirectFilter::Tricubic => f |= flags::INDIRECT | flags::TRICUBIC,
            IndirectFilter::Off => {}
        }
        if self.environment {
            f |= flags::ENV;
        }
        if self.specular_surfels > 0 {
            f |= flags::SPECULAR;
        }
        if s.cone_interleave {
            f |= flags::CONE_INTERLEAVE;
        }
        if s.cone_planes {
            f |= flags::CONE_PLANES;
        }
        if s.cone_rays {
            f |= flags::CONE_RAYS;
        }
        if self.targets.gbuffer.blends() {
            f |= flags::BLEND;
        }
        f |= match s.view {
            ViewMode::Lit => 0,
            ViewMode::Albedo => flags::VIEW_ALBEDO,
            ViewMode::Normals => flags::VIEW_NORMALS,
            ViewMode::Light => flags::VIEW_LIGHT,
            ViewMode::Lux => flags::VIEW_LIGHT | flags::VIEW_LUX,
            ViewMode::Level => flags::VIEW_LEVEL,
            ViewMode::Scan => flags::VIEW_SCAN,
        };
        p.flags = f;
        if let Some((c, w, h)) = frame {
            p.width = w;
            p.height = h;
            let forward = (c.look_at_m - c.eye_m).normalize();
            let right = forward.cross(c.up).normalize();
            let up = right.cross(forward);
            let tan = (c.fov_y_deg.to_radians() * 0.5).tan();
            let forward = crate::passes::resolve::jittered_forward(
                forward,
                (right, up),
                tan,
                self.targets.stills.jitter_px,
                (w, h),
            );
            p.camera_eye_m = c.eye_m.extend(0.0).to_array();
            p.camera_forward = forward.extend(tan).to_array();
            p.camera_right = right.extend(w as f32 / h as f32).to_array();
            p.camera_up = up.extend(0.0).to_array();
        }
        p
    }

    /// The resolve's sums where the plan runs it; a change of light ends the still frame.
    fn prepare_still(&mut self, plan: &EffectPlan) -> Result<()> {
        if plan.runs(Pass::Resolve) {
            let resolve = &self.targets.stills.resolve;
            let gpu = &self.gpu;
            if let Some(v) = self.targets.view.as_mut()
                && v.sums.is_none()
            {
                v.sums = Some(resolve.sums(gpu, &v.outputs.frame, v.targets.width, v.targets.height)?);
            }
            self.stats_now.last_upload_bytes += 16;
        }
        if [Pass::Shadow, Pass::Inject, Pass::Mip, Pass::Env, Pass::Propagate].iter().any(|&p| plan.runs(p)) {
            // The light changes: a still frame gathered so far shows the old light.
            self.targets.stills.still = None;
        }
        Ok(())
    }

    pub(super) fn timestamp_pair(&self, pass: Pass) -> Option<(&wgpu::QuerySet, u32)> {
        self.counters.time_pair(pass)
    }

    /// Writes the camera's splat uniform and (re)makes the view's targets when the size changed.
    pub(super) fn prepare_view(&mut self, camera: &Camera, w: u32, h: u32) -> Result<()> {
        let near = (0.02 * self.leaf_size_m).max(1e-4);
        let far = (camera.eye_m.length() + self.scene_diag_m) * 2.0 + 1.0;
        let m = camera.view_proj(w, h, near, far);
        let u = SplatUniform {
            view_proj: crate::passes::resolve::jittered_view_proj(m, self.targets.stills.jitter_px, w, h)
                .to_cols_array_2d(),
            eye_m: camera.eye_m.extend(1.0).to_array(),
            viewport: [
                w as f32,
                h as f32,
                self.settings.min_splat_px,
                1.0 / (camera.fov_y_deg.to_radians() * 0.5).tan(),
            ],
            splat: [
                self.settings.splat_scale,
                f32::from(u8::from(self.settings.view == ViewMode::Scan)),
                0.0,
                0.0,
            ],
            clip_min_m: self.targets.clip().map_or([0.0; 4], |c| c.min_m.extend(1.0).to_array()),
            clip_max_m: self.targets.clip().map_or([0.0; 4], |c| c.max_m.extend(1.0).to_array()),
            pad: [[0.0; 4]; 7],
        };
        self.targets.prepare(&self.gpu, camera, (w, h), (&u, m), self.settings.view)
    }

    pub(super) fn encoder(&self) -> wgpu::CommandEncoder {
        self.gpu.device.create_command_encoder(&wgpu::CommandEncoderDescriptor { label: Some("frame") })
    }

    /// The pool runs `viewer` may see, culled as the settings say.
    pub(super) fn runs_seen(&self, viewer: Option<&Viewer<'_>>) -> Vec<SplatRun> {
        let sizes = (self.leaf_size_m, self.settings.splat_scale);
        self.pools.runs_seen(viewer, sizes, self.settings.cull_chunks)
    }

    /// The level of detail for an eye at `eye_m` whose pixels are `focal_px` per unit of tangent,
    /// with its pixel floor times `detail`; None where the settings or the adapter draw every
    /// surfel.
    pub(super) fn lod(&self, eye_m: glam::Vec3, focal_px: f32, detail: f32) -> Option<Lod> {
        (self.settings.splat_lod && self.splats.pulls()).then_some(Lod {
            eye_m,
            focal_px,
            floor_px: self.settings.min_splat_px * detail,
        })
    }

    /// Records one pass into `enc`; returns its draw calls and surfels drawn (splat passes).
    pub(super) fn record(&self, enc: &mut wgpu::CommandEncoder, pass: Pass) -> Result<PassWork> {
        let ts = self.timestamp_pair(pass);
        let stats = self.counters.work_slot(pass);
        let mut work = PassWork::default();
        let render_ts = ts.map(|(set, i)| wgpu::RenderPassTimestampWrites {
            query_set: set,
            beginning_of_pass_write_index: Some(i),
            end_of_pass_write_index: Some(i + 1),
        });
        match pass {
            Pass::Shadow => {
                work = self.shadows.record(enc, &self.splats, (render_ts, stats));
            }
            Pass::Gbuffer => {
                let v = self.targets.get("gbuffer")?;
                let (w, h) = (v.targets.width, v.targets.height);
                let focal_px = h as f32 * 0.5 / (v.camera.fov_y_deg.to_radians() * 0.5).tan();
                let viewer = self.targets.camera_view_proj.as_ref().map(|m| Viewer {
                    view_proj: m,
                    // Thinned discs grow up to the detail's floor, past the viewport's edge too.
                    grow_ndc: Viewer::grow_for(w, h, self.settings.min_splat_px * self.targets.lod_detail()),
                    light: None,
                    lod: self.lod(v.camera.eye_m, focal_px, self.targets.lod_detail()),
                });
                let runs = self.runs_seen(viewer.as_ref());
                work.draws = runs.len() as u64;
                work.surfels = runs.iter().map(SplatRun::drawn).sum();
                self.targets.gbuffer.record(enc, &v.targets, &self.splats, &runs, (render_ts, stats));
            }
            compute => {
                let tw = ts.map(|(set, i)| wgpu::ComputePassTimestampWrites {
                    query_set: set,
                    beginning_of_pass_write_index: Some(i),
                    end_of_pass_write_index: Some(i + 1),
                });
                let mut cp = enc.begin_compute_pass(&wgpu::ComputePassDescriptor {
                    label: Some(compute.name()),
                    timestamp_writes: tw,
                });
                if let Some((set, i)) = stats {
                    cp.begin_pipeline_statistics_query(set, i);
                }
                match compute {
                    Pass::Inject => {
                        // After an edit in place, the active tiles' leaves (frame_params' flag).
                        let edit = self.light.light_edit.is_some();
                        let n = if edit { self.light.active_items() } else { self.leaf_count };
                        self.light.inject.record(&mut cp, n, edit)
                    }
                    Pass::Env => self.light.env.record(&mut cp, self.leaf_count),
                    Pass::Mip => self.light.mip.record(&mut cp),
                    Pass::Propagate => {
                        // The slice that ends the bounce ends it with the tail (propagate.rs).
                        let (first, end) = self.light.slice_run;
                        self.light.propagate.record(&mut cp, end - first, self.light.finishing_tiles())
                    }
                    Pass::Shade => {
                        let v = self.targets.get("shade")?;
                        self.targets.shade.record(&mut cp, &v.outputs, v.targets.width, v.targets.height);
                    }
                    Pass::Resolve => {
                        let v = self.targets.get("resolve")?;
                        let sums = v.sums.as_ref().ok_or(Error::Internal {
                            what: "resolve",
                            message: "no sums were made for the view".into(),
                        })?;
                        let (sample, _) = self.targets.stills.next.unwrap_or((0, 1));
                        self.targets.stills.resolve.record(&self.gpu, &mut cp, sums, sample);
                    }
                    Pass::Shadow | Pass::Gbuffer => {}
                }
                if stats.is_some() {
                    cp.end_pipeline_statistics_query();
                }
            }
        }
        Ok(work)
    }

    /// Records and submits the plan's passes (one encoder, or one per pass where the adapter has
    /// no timestamp queries and each is timed on the CPU); `ran` collects the passes recorded.
    pub(super) fn record_frame(&mut self, plan: &EffectPlan, ran: &mut Vec<Pass>) -> Result<()> {
        let mut enc = self.encoder();
        if self.light.clears_changes(plan) {
            enc.clear_buffer(&self.light.changes, 0, None);
        }
        for step in plan.steps.iter().filter(|s| s.run) {
            let recorded = Instant::now();
            let work = self.record(&mut enc, step.pass)?;
            self.stats_now.work.insert(step.pass, work);
            *self.stats_now.dispatches.entry(step.pass).or_default() += 1;
            ran.push(step.pass);
            if !self.counters.timed_on_gpu() && !cfg!(target_arch = "wasm32") {
                // No timestamp queries: time each pass on the CPU, recording to completion of its
                // own blocking submit (not in a browser, which cannot block).
                let done = std::mem::replace(&mut enc, self.encoder());
                self.gpu.queue.submit([done.finish()]);
                self.stats_now.last_submits += 1;
                self.gpu.wait()?;
                let ms = recorded.elapsed().as_secs_f64() * 1e3;
                self.stats_now.last_ms.insert(step.pass, ms);
            }
        }
        self.counters.resolve(&mut enc, ran);
        self.gpu.queue.submit([enc.finish()]);
        self.stats_now.last_submits += 1;
        self.gpu.wait()
    }

    /// Runs `plan`; its propagation runs at most `slice` invocations of the bounce (None: the
    /// rest of it).
    pub(super) fn execute(
        &mut self,
        plan: &EffectPlan,
        frame: Option<(&Camera, u32, u32)>,
        slice: Option<u32>,
    ) -> Result<()> {
        let params = self.frame_params(frame);
        self.gpu.queue.write_buffer(&self.params, 0, bytemuck::bytes_of(&params));
        self.stats_now.last_submits = 0;
        self.stats_now.last_upload_bytes = size_of::<Params>() as u64;
        self.stats_now.last_upload_bytes += self.light.write_active(&self.gpu, plan, slice);
        if plan.runs(Pass::Shadow) {
            self.static_bytes += self.shadows.choose_batch(&self.gpu, self.settings.shadow_frame_ms)?;
        }
        if let Some((camera, w, h)) = frame
            && plan.runs(Pass::Gbuffer)
        {
            self.prepare_view(camera, w, h)?;
            self.stats_now.last_upload_bytes += size_of::<SplatUniform>() as u64;
        }
        self.prepare_still(plan)?;
        // The frame runs inside one validation error scope; when it catches an error, each pass
        // is recorded again alone in a scope of its own (and not submitted) to name the culprit.
        // A command buffer per pass would name it directly, but costs lavapipe time on every frame
        // (tried: frames of the bunny at 64x48 went from 0.1 s to 1.5 s), so the fast path stays
        // one encoder and only a failing frame pays for the search.
        let mut ran: Vec<Pass> = Vec::new();
        let gpu = self.gpu.clone();
        let (outcome, error) = gpu.capture(|| self.record_frame(plan, &mut ran));
        if let Some(e) = error {
            let culprit = ran.iter().copied().find(|&pass| {
                self.gpu
                    .scoped(pass.name(), || {
                        let mut enc = self.encoder();
                        self.record(&mut enc, pass)?;
                        enc.finish();
                        Ok(())
                    })
                    .is_err()
            });
            return Err(Error::Gpu { pass: culprit.map_or("frame", Pass::name), message: e.to_string() });
        }
        outcome?;
        self.gpu.check("frame")?;
        self.counters.read(&self.gpu, &ran, &mut self.stats_now)?;
        if ran.contains(&Pass::Shadow) {
            self.shadows.ran(self.stats_now.last_ms.get(&Pass::Shadow).copied());
        }
        self.targets.ran(&ran, self.settings.view);
        let lights = self.lights.analytic() > 0;
        let direct_done = self.shadow_faces_left() == 0;
        if self.light.ran(&self.gpu, &ran, lights, direct_done) {
            self.wait_for_light()?;
        }
        Ok(())
    }
}

/// One rendered image.
#[derive(Clone, Debug)]
pub struct Frame {
    pub width: u32,
    pub height: u32,
    /// Linear radiance, rows top to bottom; alpha is 1 where a surfel covers the pixel, 0 where the
    /// background shows.
    pub hdr: Vec<[f32; 4]>,
    /// Tonemapped sRGB8 RGBA.
    pub ldr: Vec<[u8; 4]>,
}

/// A frame on the GPU, for a viewer to present ([`Renderer::ldr_output`]).
#[derive(Clone, Copy, Debug)]
pub struct LdrOutput<'a> {
    pub(crate) buffer: &'a wgpu::Buffer,
    pub(crate) first_word: u32,
    pub(crate) width: u32,
    pub(crate) height: u32,
}

impl Frame {
    /// The frame at 1/`factor` of its size, each pixel the mean of a `factor` x `factor` block:
    /// supersampling's resolve (`grotto render --supersample`). Radiance and coverage average
    /// linearly; the tonemapped colour averages in linear light after the tonemap, as a display
    /// would blend the sub-pixels (a bright lamp's edge does not dominate the pixel). Edges that
    /// do not fill a block are dropped.
    pub fn downsampled(&self, factor: u32) -> Frame {
        use grotto_format::color::{linear_to_srgb8, srgb8_to_linear};
        let f = factor.max(1) as usize;
        let (w, h) = (self.width as usize / f, self.height as usize / f);
        let mut hdr = Vec::with_capacity(w * h);
        let mut ldr = Vec::with_capacity(w * h);
        let n = (f * f) as f32;
        for by in 0..h {
            for bx in 0..w {
                let (mut sum_hdr, mut sum_ldr) = ([0f32; 4], [0f32; 4]);
                for y in by * f..(by + 1) * f {
                    for x in bx * f..(bx + 1) * f {
                        let i = y * self.width as usize + x;
                        for (s, v) in sum_hdr.iter_mut().zip(self.hdr[i]) {
                            *s += v;
                        }
                        let [r, g, b, a] = self.ldr[i];
                        for (s, v) in sum_ldr.iter_mut().zip([r, g, b].map(srgb8_to_linear)) {
                            *s += v;
                        }
                        sum_ldr[3] += f32::from(a);
                    }
                }
                hdr.push(sum_hdr.map(|v| v / n));
                let l = sum_ldr.map(|v| v / n);
                ldr.push([
                    linear_to_srgb8(l[0]),
                    linear_to_srgb8(l[1]),
                    linear_to_srgb8(l[2]),
                    l[3].round() as u8,
                ]);
            }
        }
        Frame { width: w as u32, height: h as u32, hdr, ldr }
    }
}

#[cfg(test)]
mod tests {
    use super::Frame;

    #[test]
    fn a_downsampled_frame_averages_its_blocks_in_linear_light() {
        // A 4x2 frame: left block half black, half white; right block all mid grey.
        let white = ([1.0, 1.0, 1.0, 1.0], [255, 255, 255, 255]);
        let black = ([0.0, 0.0, 0.0, 0.0], [0, 0, 0, 255]);
        let grey = ([0.5, 0.5, 0.5, 1.0], [188, 188, 188, 255]);
        let px = [white, black, grey, grey, black, white, grey, grey];
        let frame = Frame {
            width: 4,
            height: 2,
            hdr: px.iter().map(|p| p.0).collect(),
            ldr: px.iter().map(|p| p.1).collect(),
        };
        let half = frame.downsampled(2);
        assert_eq!((half.width, half.height), (2, 1));
        assert_eq!(half.hdr[0], [0.5, 0.5, 0.5, 0.5]);
        // Half white and half black light is linear 0.5: sRGB 188, not 128.
        assert_eq!(half.ldr[0], [188, 188, 188, 255]);
        assert_eq!(half.ldr[1], [188, 188, 188, 255]);
        assert_eq!(frame.downsampled(1).ldr, frame.ldr);
    }
}
