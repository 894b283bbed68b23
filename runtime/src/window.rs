//! `grotto view`: a window (winit) on the same renderer `grotto render` uses, with fly controls.
//! A thin shell: it opens the package as a render job would ([`render_job::prepare`]), renders
//! each frame with [`Renderer::draw`] (the light converging a bounce a frame, as the effect plan
//! says) and presents the renderer's tonemapped output through a small blit (window.wgsl).
//!
//! Controls: mouse drag looks around, WASD flies (Q/E down/up), the wheel sets the speed, Tab
//! jumps to the next named camera, R goes back to the first, 1-5 switch the view (lit, albedo,
//! normals, light, level), F11 toggles full screen, P writes a screenshot, Esc quits.
//! `--screenshot PATH --after-frames N` renders N frames, writes the last and exits (scripts, tests).

use std::path::PathBuf;
use std::sync::Arc;
use std::time::Instant;

use glam::Vec3;
use winit::application::ApplicationHandler;
use winit::event::{ElementState, MouseButton, MouseScrollDelta, WindowEvent};
use winit::event_loop::{ActiveEventLoop, EventLoop};
use winit::keyboard::{KeyCode, PhysicalKey};
use winit::window::{Fullscreen, Window, WindowId};

use crate::camera::Camera;
use crate::error::{Error, Result};
use crate::gpu::Gpu;
use crate::image_out;
use crate::render_job::{self, RenderOptions};
use crate::renderer::{Renderer, ViewMode};

/// What `grotto view` is asked.
#[derive(Clone, Debug)]
pub struct ViewOptions {
    /// The package, camera, settings, GPU and budgets, as `grotto render` takes them; `width` and
    /// `height` are the window's first inner size.
    pub render: RenderOptions,
    /// The renderer draws at the window's size times this (software adapters are slow per pixel).
    pub render_scale: f32,
    /// Write the frame after `after_frames` frames to this path and exit.
    pub screenshot: Option<PathBuf>,
    pub after_frames: u32,
}

/// What a viewing session did.
#[derive(Clone, Debug, Default)]
pub struct ViewSummary {
    pub device: String,
    pub frames: u32,
    pub seconds: f64,
    pub screenshots: Vec<String>,
}

/// Opens the window and runs until it is closed (or the screenshot is written).
pub fn run(opts: ViewOptions) -> Result<ViewSummary> {
    let event_loop = EventLoop::new().map_err(|e| Error::NoDisplay(e.to_string()))?;
    let mut app =
        App { opts, state: None, error: None, summary: ViewSummary::default(), started: Instant::now() };
    event_loop.run_app(&mut app).map_err(|e| Error::NoDisplay(e.to_string()))?;
    if let Some(e) = app.error {
        return Err(e);
    }
    app.summary.seconds = app.started.elapsed().as_secs_f64();
    Ok(app.summary)
}

struct App {
    opts: ViewOptions,
    state: Option<State>,
    error: Option<Error>,
    summary: ViewSummary,
    started: Instant,
}

/// The window, its surface and the renderer.
struct State {
    window: Arc<Window>,
    gpu: Gpu,
    surface: wgpu::Surface<'static>,
    config: wgpu::SurfaceConfiguration,
    blit: Blit,
    renderer: Renderer,
    cameras: Vec<Camera>,
    camera_index: usize,
    fly: Fly,
    /// Keys held (W, A, S, D, Q, E), the mouse button, the last cursor position.
    held: [bool; 6],
    dragging: bool,
    cursor: Option<(f64, f64)>,
    last_frame: Instant,
}

/// A fly camera: eye, heading and pitch (z up), speed in metres a second.
#[derive(Clone, Copy, Debug)]
struct Fly {
    eye_m: Vec3,
    yaw_rad: f32,
    pitch_rad: f32,
    speed_m_s: f32,
    fov_y_deg: f32,
}

impl Fly {
    fn from_camera(c: &Camera, scene_size_m: f32) -> Self {
        let d = (c.look_at_m - c.eye_m).normalize_or(Vec3::X);
        Self {
            eye_m: c.eye_m,
            yaw_rad: d.y.atan2(d.x),
            pitch_rad: d.z.clamp(-1.0, 1.0).asin(),
            speed_m_s: (scene_size_m / 20.0).max(0.5),
            fov_y_deg: c.fov_y_deg,
        }
    }

    fn forward(&self) -> Vec3 {
        let (sy, cy) = self.yaw_rad.sin_cos();
        let (sp, cp) = self.pitch_rad.sin_cos();
        Vec3::new(cy * cp, sy * cp, sp)
    }

    fn camera(&self) -> Camera {
        Camera {
            eye_m: self.eye_m,
            look_at_m: self.eye_m + self.forward(),
            up: Vec3::Z,
            fov_y_deg: self.fov_y_deg,
        }
    }
}

/// The presenting pipeline and its uniform.
struct Blit {
    pipeline: wgpu::RenderPipeline,
    layout: wgpu::BindGroupLayout,
    uniform: wgpu::Buffer,
}

impl Blit {
    fn new(gpu: &Gpu, format: wgpu::TextureFormat) -> Result<Self> {
        let src = crate::shaders::compose(crate::shaders::WINDOW)?;
        let module = gpu.device.create_shader_module(wgpu::ShaderModuleDescriptor {
            label: Some("window"),
            source: wgpu::ShaderSource::Wgsl(src.into()),
        });
        let entry = |binding, ty| wgpu::BindGroupLayoutEntry {
            binding,
            visibility: wgpu::ShaderStages::FRAGMENT,
            ty: wgpu::BindingType::Buffer { ty, has_dynamic_offset: false, min_binding_size: None },
            count: None,
        };
        let layout = gpu.device.create_bind_group_layout(&wgpu::BindGroupLayoutDescriptor {
            label: Some("window"),
            entries: &[
                entry(0, wgpu::BufferBindingType::Storage { read_only: true }),
                entry(1, wgpu::BufferBindingType::Uniform),
            ],
        });
        let pl = gpu.device.create_pipeline_layout(&wgpu::PipelineLayoutDescriptor {
            label: Some("window"),
            bind_group_layouts: &[Some(&layout)],
            immediate_size: 0,
        });
        let pipeline = gpu.device.create_render_pipeline(&wgpu::RenderPipelineDescriptor {
            label: Some("window"),
            layout: Some(&pl),
            vertex: wgpu::VertexState {
                module: &module,
                entry_point: Some("vs"),
                compilation_options: Default::default(),
                buffers: &[],
            },
            primitive: Default::default(),
            depth_stencil: None,
            multisample: Default::default(),
            fragment: Some(wgpu::FragmentState {
                module: &module,
                entry_point: Some("fs"),
                compilation_options: Default::default(),
                targets: &[Some(format.into())],
            }),
            multiview_mask: None,
            cache: None,
        });
        let uniform =
            gpu.buffer("window blit", 32, wgpu::BufferUsages::UNIFORM | wgpu::BufferUsages::COPY_DST)?;
        gpu.check("window")?;
        Ok(Self { pipeline, layout, uniform })
    }
}

impl App {
    fn start(&mut self, event_loop: &ActiveEventLoop) -> Result<()> {
        let o = &self.opts.render;
        let attrs = Window::default_attributes()
            .with_title(format!("grotto view {}", o.package.display()))
            .with_inner_size(winit::dpi::PhysicalSize::new(o.width, o.height));
        let window = Arc::new(event_loop.create_window(attrs).map_err(|e| Error::NoDisplay(e.to_string()))?);
        let (gpu, surface) = Gpu::for_window(&o.gpu, window.clone())?;
        let caps = surface.get_capabilities(&gpu.adapter);
        // A plain (non-sRGB) format shows the renderer's sRGB bytes as they are.
        let format = caps
            .formats
            .iter()
            .copied()
            .find(|f| !f.is_srgb())
            .or_else(|| caps.formats.first().copied())
            .ok_or_else(|| Error::Device("the window's surface offers no format".into()))?;
        let size = window.inner_size();
        let config = wgpu::SurfaceConfiguration {
            usage: wgpu::TextureUsages::RENDER_ATTACHMENT,
            format,
            color_space: wgpu::SurfaceColorSpace::Auto,
            width: size.width.max(1),
            height: size.height.max(1),
            present_mode: wgpu::PresentMode::Fifo,
            desired_maximum_frame_latency: 2,
            alpha_mode: caps.alpha_modes.first().copied().unwrap_or(wgpu::CompositeAlphaMode::Auto),
            view_formats: Vec::new(),
        };
        surface.configure(&gpu.device, &config);
        let blit = Blit::new(&gpu, format)?;
        let prepared = render_job::prepare(o, &gpu)?;
        let mut settings = o.settings.clone();
        settings.exposure = o.exposure.unwrap_or(1.0);
        let renderer = Renderer::new(&gpu, &prepared.scene, settings)?;
        let (lo, hi) = prepared.scene.bounds_leaf();
        let size_m = ((hi - lo) * prepared.scene.leaf_size_m).max_element();
        let fly = Fly::from_camera(&prepared.cameras[0], size_m);
        window.request_redraw();
        self.summary.device = gpu.describe();
        self.state = Some(State {
            window,
            gpu,
            surface,
            config,
            blit,
            renderer,
            cameras: prepared.cameras,
            camera_index: 0,
            fly,
            held: [false; 6],
            dragging: false,
            cursor: None,
            last_frame: Instant::now(),
        });
        Ok(())
    }

    fn frame(&mut self, event_loop: &ActiveEventLoop) -> Result<()> {
        let Some(s) = self.state.as_mut() else { return Ok(()) };
        let now = Instant::now();
        let dt = now.duration_since(s.last_frame).as_secs_f32().min(0.25);
        s.last_frame = now;
        let f = s.fly.forward();
        let right = f.cross(Vec3::Z).normalize_or(Vec3::X);
        let axes = [f, -right, -f, right, -Vec3::Z, Vec3::Z];
        let step: Vec3 = s.held.iter().zip(axes).filter(|(h, _)| **h).map(|(_, a)| a).sum();
        s.fly.eye_m += step * s.fly.speed_m_s * dt;
        let scale = self.opts.render_scale.clamp(0.05, 1.0);
        let (w, h) = (
            ((s.config.width as f32 * scale) as u32).max(1),
            ((s.config.height as f32 * scale) as u32).max(1),
        );
        let cam = s.fly.camera();
        if self.summary.frames == 0 && self.opts.render.exposure.is_none() {
            // Automatic exposure from the first frame, as `grotto render` does, kept after.
            let first = s.renderer.render(&cam, w, h)?.0;
            s.renderer.set_exposure(render_job::auto_exposure(&first.hdr));
        }
        s.renderer.draw(&cam, w, h)?;
        let Some((ldr, src_w, src_h)) = s.renderer.ldr_output() else { return Ok(()) };
        let frame = match s.surface.get_current_texture() {
            wgpu::CurrentSurfaceTexture::Success(t) | wgpu::CurrentSurfaceTexture::Suboptimal(t) => t,
            wgpu::CurrentSurfaceTexture::Outdated | wgpu::CurrentSurfaceTexture::Lost => {
                s.surface.configure(&s.gpu.device, &s.config);
                return Ok(());
            }
            _ => return Ok(()),
        };
        let u: [u32; 8] =
            [src_w, src_h, s.config.width, s.config.height, u32::from(s.config.format.is_srgb()), 0, 0, 0];
        s.gpu.queue.write_buffer(&s.blit.uniform, 0, bytemuck::cast_slice(&u));
        let group = s.gpu.device.create_bind_group(&wgpu::BindGroupDescriptor {
            label: Some("window"),
            layout: &s.blit.layout,
            entries: &[
                wgpu::BindGroupEntry { binding: 0, resource: ldr.as_entire_binding() },
                wgpu::BindGroupEntry { binding: 1, resource: s.blit.uniform.as_entire_binding() },
            ],
        });
        let view = frame.texture.create_view(&Default::default());
        let mut enc = s.gpu.device.create_command_encoder(&Default::default());
        {
            let mut pass = enc.begin_render_pass(&wgpu::RenderPassDescriptor {
                label: Some("window"),
                color_attachments: &[Some(wgpu::RenderPassColorAttachment {
                    view: &view,
                    depth_slice: None,
                    resolve_target: None,
                    ops: wgpu::Operations {
                        load: wgpu::LoadOp::Clear(wgpu::Color::BLACK),
                        store: wgpu::StoreOp::Store,
                    },
                })],
                depth_stencil_attachment: None,
                timestamp_writes: None,
                occlusion_query_set: None,
                multiview_mask: None,
            });
            pass.set_pipeline(&s.blit.pipeline);
            pass.set_bind_group(0, &group, &[]);
            pass.draw(0..3, 0..1);
        }
        s.gpu.queue.submit([enc.finish()]);
        s.window.pre_present_notify();
        s.gpu.queue.present(frame);
        s.gpu.check("window")?;
        self.summary.frames += 1;
        if let Some(path) = &self.opts.screenshot
            && self.summary.frames >= self.opts.after_frames.max(1)
        {
            // The frame just presented, read back (not drawn again).
            image_out::write_frame(&s.renderer.read_frame()?, path)?;
            self.summary.screenshots.push(path.display().to_string());
            event_loop.exit();
            return Ok(());
        }
        s.window.request_redraw();
        Ok(())
    }

    fn key(&mut self, event_loop: &ActiveEventLoop, code: KeyCode, pressed: bool) -> Result<()> {
        let Some(s) = self.state.as_mut() else { return Ok(()) };
        let held = [KeyCode::KeyW, KeyCode::KeyA, KeyCode::KeyS, KeyCode::KeyD, KeyCode::KeyQ, KeyCode::KeyE];
        if let Some(k) = held.iter().position(|c| *c == code) {
            s.held[k] = pressed;
            return Ok(());
        }
        if !pressed {
            return Ok(());
        }
        let views = [KeyCode::Digit1, KeyCode::Digit2, KeyCode::Digit3, KeyCode::Digit4, KeyCode::Digit5];
        if let Some(k) = views.iter().position(|c| *c == code) {
            s.renderer.set_view(ViewMode::ALL[k]);
            return Ok(());
        }
        let speed = s.fly.speed_m_s;
        match code {
            KeyCode::Escape => event_loop.exit(),
            KeyCode::Tab | KeyCode::KeyR => {
                s.camera_index =
                    if code == KeyCode::KeyR { 0 } else { (s.camera_index + 1) % s.cameras.len() };
                s.fly = Fly { speed_m_s: speed, ..Fly::from_camera(&s.cameras[s.camera_index], 0.0) };
            }
            KeyCode::F11 => {
                let full = s.window.fullscreen().is_none().then_some(Fullscreen::Borderless(None));
                s.window.set_fullscreen(full);
            }
            KeyCode::KeyP => {
                let (w, h) = (s.config.width, s.config.height);
                let shot = s.renderer.render(&s.fly.camera(), w, h)?.0;
                let path = PathBuf::from(format!("grotto-view-{}.png", self.summary.screenshots.len()));
                image_out::write_frame(&shot, &path)?;
                self.summary.screenshots.push(path.display().to_string());
            }
            _ => {}
        }
        Ok(())
    }

    fn fail(&mut self, event_loop: &ActiveEventLoop, e: Error) {
        self.error = Some(e);
        event_loop.exit();
    }
}

impl ApplicationHandler for App {
    fn resumed(&mut self, event_loop: &ActiveEventLoop) {
        if self.state.is_none()
            && let Err(e) = self.start(event_loop)
        {
            self.fail(event_loop, e);
        }
    }

    fn window_event(&mut self, event_loop: &ActiveEventLoop, _id: WindowId, event: WindowEvent) {
        let outcome = match event {
            WindowEvent::CloseRequested => {
                event_loop.exit();
                Ok(())
            }
            WindowEvent::Resized(size) => {
                if let Some(s) = self.state.as_mut() {
                    s.config.width = size.width.max(1);
                    s.config.height = size.height.max(1);
                    s.surface.configure(&s.gpu.device, &s.config);
                    s.window.request_redraw();
                }
                Ok(())
            }
            WindowEvent::RedrawRequested => self.frame(event_loop),
            WindowEvent::KeyboardInput { event, .. } => match event.physical_key {
                PhysicalKey::Code(code) => self.key(event_loop, code, event.state == ElementState::Pressed),
                PhysicalKey::Unidentified(_) => Ok(()),
            },
            WindowEvent::MouseInput { state, button: MouseButton::Left, .. } => {
                if let Some(s) = self.state.as_mut() {
                    s.dragging = state == ElementState::Pressed;
                }
                Ok(())
            }
            WindowEvent::CursorMoved { position, .. } => {
                if let Some(s) = self.state.as_mut() {
                    if let (true, Some((x, y))) = (s.dragging, s.cursor) {
                        let k = 0.005;
                        s.fly.yaw_rad -= (position.x - x) as f32 * k;
                        s.fly.pitch_rad = (s.fly.pitch_rad - (position.y - y) as f32 * k).clamp(-1.5, 1.5);
                    }
                    s.cursor = Some((position.x, position.y));
                }
                Ok(())
            }
            WindowEvent::MouseWheel { delta, .. } => {
                if let Some(s) = self.state.as_mut() {
                    let lines = match delta {
                        MouseScrollDelta::LineDelta(_, y) => y,
                        MouseScrollDelta::PixelDelta(p) => p.y as f32 / 40.0,
                    };
                    s.fly.speed_m_s = (s.fly.speed_m_s * 1.25f32.powf(lines)).clamp(0.01, 1000.0);
                }
                Ok(())
            }
            _ => Ok(()),
        };
        if let Err(e) = outcome {
            self.fail(event_loop, e);
        }
    }
}
