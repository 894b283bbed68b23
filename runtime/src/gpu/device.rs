//! The headless GPU context: instance, adapter choice, device with the limits grotto needs, and
//! small helpers (uploads, read-back, captured validation errors).
//!
//! Adapter choice: `WGPU_BACKEND` (e.g. `vulkan`, `gl`) restricts the backends as in every wgpu
//! program; `GROTTO_ADAPTER` picks an adapter whose name contains the given text. Otherwise a
//! discrete GPU is preferred, then integrated, virtual, and the software rasteriser (Mesa's
//! lavapipe or llvmpipe); tests ask for the software adapter first so their results do not depend
//! on the machine. A missing adapter, feature or limit is an [`Error`] that says what to install or
//! change, never a panic.
//!
//! Nothing here uses a 3D storage texture: voxel data lives in storage buffers, which sidesteps the
//! GL backend's gap (it writes only slice 0 of a 3D storage texture).

use std::sync::{Arc, Mutex};

use wgpu::util::DeviceExt;

use crate::error::{Error, Result};

/// Storage buffers one compute stage binds at most: shade's, whose imports declare the most
/// (runtime/tests/shaders.rs reflects every pass and checks this).
pub const STORAGE_BUFFERS_NEEDED: u32 = 8;

/// The tile budget when `--gpu-memory` is not given. wgpu reports no adapter memory, so this is
/// half the largest buffer the adapter allows, at most 2 GiB. Binding limits are checked per
/// buffer as before (`Error::TooLarge` says what to change).
pub fn default_gpu_memory(gpu: &Gpu) -> u64 {
    (gpu.device.limits().max_buffer_size / 2).min(2 << 30)
}

/// What a user can change when the resource named `label` outgrows the adapter.
fn hint_for(label: &str) -> String {
    match label {
        "nodes" | "leaves" | "leaf light" | "faces" | "mip order" => {
            "the package has too many voxels for one binding: build it with a larger leaf size \
             (grotto-pack build --leaf-m), render with --radiance-f16 (halves the radiance pyramid), \
             or use a GPU with larger storage bindings"
        }
        "surfels" => {
            "the package has too many points for one vertex buffer: build it from fewer points (thin \
             the scans) or use a GPU with larger buffers"
        }
        "tiles" => "build the package with a larger leaf size (grotto-pack build --leaf-m)",
        // The rock table, the light grid and the tile index (lookup.wgsl).
        "lookup" => {
            "build the package with a larger leaf size (grotto-pack build --leaf-m), or raise \
             --light-cutoff (shorter light ranges) or use fewer lights"
        }
        "lights" | "shadow atlas" | "shadow depth" | "splat uniforms" => {
            "lower --shadowed-lights or --shadow-map"
        }
        "env atlas" => "rebuild the package with a smaller environment map",
        l if l.starts_with("gbuffer") || l.starts_with("shade") => "render a smaller --size",
        _ => "use a GPU with larger limits",
    }
    .to_string()
}

/// "137.4 MB (131.1 MiB)"-style sizes for error messages.
pub fn human_bytes(b: u64) -> String {
    if b < 1 << 20 {
        format!("{b} bytes")
    } else {
        format!("{:.1} MB ({:.1} MiB)", b as f64 / 1e6, b as f64 / f64::from(1u32 << 20))
    }
}

/// How to choose the adapter.
#[derive(Clone, Debug, Default)]
pub struct GpuOptions {
    /// Put the CPU (software) adapter first, for reproducible tests.
    pub prefer_software: bool,
    /// Restrict to these backends; `None` reads `WGPU_BACKEND` or allows all.
    pub backends: Option<wgpu::Backends>,
    /// Ask the device for this storage-buffer binding size (bytes), at most the adapter's:
    /// smaller, to see what a smaller adapter does with a package; with `webgpu_limits`, larger
    /// than WebGPU's default 128 MiB where the adapter offers it and a memory budget's pools
    /// could use it (engine/memory.rs). Buffers may then be as large as the binding.
    pub max_storage_binding_bytes: Option<u64>,
    /// Ask the device for WebGPU's default limits only (what every browser grants without being
    /// asked for more), to check on a native adapter that the passes fit in a browser.
    pub webgpu_limits: bool,
    /// Ask for pipeline statistics queries where the adapter has them, so the renderer counts
    /// each pass's shader invocations (`grotto bench`; render/counters.rs).
    pub work_counters: bool,
    /// Favour memory over speed in the driver's allocator (`wgpu::MemoryHints::MemoryUsage`:
    /// memory blocks of 4-64 MiB instead of 64-256 MiB), where a memory budget is given: a
    /// transient buffer (an upload's staging, a repack's scratch) then takes a small block, not
    /// a new large one whose pages it touches bit by bit. On a software adapter, and on a
    /// phone's shared memory, those blocks are the process's memory.
    pub lean_memory: bool,
}

/// A device and queue ready for grotto's passes.
#[derive(Debug, Clone)]
pub struct Gpu {
    /// The adapter the device is on (a window asks it what its surface can show).
    pub adapter: wgpu::Adapter,
    pub device: wgpu::Device,
    pub queue: wgpu::Queue,
    pub(crate) info: wgpu::AdapterInfo,
    /// Timestamp queries are used (per-pass GPU times); otherwise, and always on software
    /// adapters, passes are timed on the CPU around a blocking submit each.
    pub(crate) timestamps: bool,
    /// Pipeline statistics queries are on (asked for, and the adapter has them).
    pub(crate) pipeline_statistics: bool,
    errors: Arc<Mutex<Vec<String>>>,
}

#[cfg(not(target_arch = "wasm32"))]
fn rank(t: wgpu::DeviceType, prefer_software: bool) -> u32 {
    use wgpu::DeviceType::*;
    match (t, prefer_software) {
        (Cpu, true) => 0,
        (DiscreteGpu, _) => 1,
        (IntegratedGpu, _) => 2,
        (VirtualGpu, _) => 3,
        (Cpu, false) => 4,
        (Other, _) => 5,
    }
}

impl Gpu {
    /// Opens the best adapter under `opts` and creates a device on it.
    #[cfg(not(target_arch = "wasm32"))]
    pub fn new(opts: &GpuOptions) -> Result<Self> {
        let (instance, backends) =
            Self::instance(opts, wgpu::InstanceDescriptor::new_without_display_handle_from_env());
        Self::open(&instance, backends, opts, |_| true)
    }

    /// An instance from `desc` (read from the environment) with `opts.backends` where given.
    #[cfg(not(target_arch = "wasm32"))]
    fn instance(opts: &GpuOptions, mut desc: wgpu::InstanceDescriptor) -> (wgpu::Instance, wgpu::Backends) {
        if let Some(b) = opts.backends {
            desc.backends = b;
        }
        let backends = desc.backends;
        (wgpu::Instance::new(desc), backends)
    }

    /// As [`Gpu::new`], for a window: the instance knows the window's display, and only adapters
    /// that can present to its surface are considered. Returns the surface too.
    #[cfg(not(target_arch = "wasm32"))]
    pub(crate) fn for_window<W>(opts: &GpuOptions, window: W) -> Result<(Self, wgpu::Surface<'static>)>
    where
        W: wgpu::WindowHandle + wgpu::wgt::WgpuHasDisplayHandle + Clone + 'static,
    {
        let (instance, backends) = Self::instance(
            opts,
            wgpu::InstanceDescriptor::new_with_display_handle_from_env(Box::new(window.clone())),
        );
        let surface = instance
            .create_surface(window)
            .map_err(|e| Error::Device(format!("cannot make a surface for the window: {e}")))?;
        let gpu = Self::open(&instance, backends, opts, |a| a.is_surface_supported(&surface))?;
        Ok((gpu, surface))
    }

    #[cfg(not(target_arch = "wasm32"))]
    fn open(
        instance: &wgpu::Instance,
        backends: wgpu::Backends,
        opts: &GpuOptions,
        accept: impl Fn(&wgpu::Adapter) -> bool,
    ) -> Result<Self> {
        let mut adapters = pollster::block_on(instance.enumerate_adapters(backends));
        adapters.retain(|a| accept(a));
        if let Ok(name) = std::env::var("GROTTO_ADAPTER") {
            let name = name.to_ascii_lowercase();
            adapters.retain(|a| a.get_info().name.to_ascii_lowercase().contains(&name));
        }
        adapters.sort_by_key(|a| {
            let info = a.get_info();
            // Vulkan before GL on the same device: it has no storage-texture gaps and is faster.
            let backend = u32::from(info.backend != wgpu::Backend::Vulkan);
            (rank(info.device_type, opts.prefer_software), backend)
        });
        let adapter =
            adapters.into_iter().next().ok_or_else(|| Error::NoAdapter { tried: format!("{backends:?}") })?;
        pollster::block_on(Self::on_adapter(adapter, opts))
    }

    /// A device on `adapter` with the limits and features grotto needs, or an error that says
    /// what is missing. Async because a browser cannot block: its shell awaits this on the
    /// adapter `navigator.gpu` gave; native callers go through [`Gpu::new`].
    pub async fn on_adapter(adapter: wgpu::Adapter, opts: &GpuOptions) -> Result<Self> {
        let info = adapter.get_info();
        let name = format!("{} ({:?})", info.name, info.backend);
        let mut limits = if opts.webgpu_limits { wgpu::Limits::default() } else { adapter.limits() };
        if let Some(b) = opts.max_storage_binding_bytes {
            let offered = adapter.limits();
            let binding = b.min(offered.max_storage_buffer_binding_size);
            limits.max_storage_buffer_binding_size = binding;
            limits.max_buffer_size = limits.max_buffer_size.max(binding).min(offered.max_buffer_size);
        }
        if limits.max_storage_buffers_per_shader_stage < STORAGE_BUFFERS_NEEDED {
            return Err(Error::Unsupported {
                adapter: name,
                what: format!(
                    "{} storage buffers per shader stage, grotto needs {STORAGE_BUFFERS_NEEDED}",
                    limits.max_storage_buffers_per_shader_stage
                ),
                hint: "use a Vulkan, Metal or DX12 adapter (WGPU_BACKEND=vulkan)".into(),
            });
        }
        let downlevel = adapter.get_downlevel_capabilities();
        if !downlevel.flags.contains(wgpu::DownlevelFlags::COMPUTE_SHADERS) {
            return Err(Error::Unsupported {
                adapter: name,
                what: "no compute shaders".into(),
                hint: "use a Vulkan, Metal, DX12 or OpenGL 4.3 / GLES 3.1 adapter".into(),
            });
        }
        if !downlevel.flags.contains(wgpu::DownlevelFlags::SHADER_F16_IN_F32) {
            return Err(Error::Unsupported {
                adapter: name,
                what: "no pack2x16float / unpack2x16float (the f16 radiance pyramid)".into(),
                hint: "use a Vulkan, Metal, DX12 or GLES 3.0+ adapter".into(),
            });
        }
        let mut features = wgpu::Features::empty();
        // Software adapters are timed on the CPU: lavapipe's timestamps do not enclose a compute
        // dispatch whose pipeline binds no texture (a 20 s propagate dispatch read as 1.4 ms).
        // In a browser the query results could only be read back a frame late; passes go
        // untimed there rather than blocking.
        let timestamps = adapter.features().contains(wgpu::Features::TIMESTAMP_QUERY)
            && info.device_type != wgpu::DeviceType::Cpu
            && !cfg!(target_arch = "wasm32");
        if timestamps {
            features |= wgpu::Features::TIMESTAMP_QUERY;
        }
        let pipeline_statistics = opts.work_counters
            && adapter.features().contains(wgpu::Features::PIPELINE_STATISTICS_QUERY)
            && !cfg!(target_arch = "wasm32");
        if pipeline_statistics {
            features |= wgpu::Features::PIPELINE_STATISTICS_QUERY;
        }
        let (device, queue) = adapter
            .request_device(&wgpu::DeviceDescriptor {
                label: Some("grotto"),
                required_features: features,
                required_limits: limits,
                memory_hints: if opts.lean_memory {
                    wgpu::MemoryHints::MemoryUsage
                } else {
                    wgpu::MemoryHints::Performance
                },
                ..Default::default()
            })
            .await
            .map_err(|e| Error::Device(format!("{name}: {e}")))?;
        let errors = Arc::new(Mutex::new(Vec::new()));
        let sink = errors.clone();
        device.on_uncaptured_error(Arc::new(move |e: wgpu::Error| {
            if let Ok(mut v) = sink.lock() {
                v.push(e.to_string());
            }
        }));
        Ok(Self { adapter, device, queue, info, timestamps, pipeline_statistics, errors })
    }

    /// "name (backend, type)" for logs and reports.
    pub fn describe(&self) -> String {
        format!("{} ({:?}, {:?})", self.info.name, self.info.backend, self.info.device_type)
    }

    /// Turns any validation error the device reported since the last check into an error naming
    /// `pass`.
    pub fn check(&self, pass: &'static str) -> Result<()> {
        let mut v = self.errors.lock().map_err(|_| Error::Device("error sink poisoned".into()))?;
        if v.is_empty() {
            return Ok(());
        }
        let message = v.join("; ");
        v.clear();
        Err(Error::Gpu { pass, message })
    }

    /// Runs `f` inside a validation error scope: an error it causes (creating a pipeline,
    /// finishing a pass's commands) comes back as [`Error::Gpu`] naming `pass`.
    pub fn scoped<T>(&self, pass: &'static str, f: impl FnOnce() -> Result<T>) -> Result<T> {
        let (out, error) = self.capture(f);
        match error {
            Some(message) => Err(Error::Gpu { pass, message }),
            None => out,
        }
    }

    /// `f`'s result and the first validation error what it did caused, where the platform can
    /// wait for it (native). A browser cannot block on the error scope's promise: there errors
    /// reach the uncaptured-error sink a little later and [`Gpu::check`] reports them.
    pub(crate) fn capture<T>(&self, f: impl FnOnce() -> T) -> (T, Option<String>) {
        #[cfg(not(target_arch = "wasm32"))]
        {
            let scope = self.device.push_error_scope(wgpu::ErrorFilter::Validation);
            let out = f();
            let error = pollster::block_on(scope.pop()).map(|e| e.to_string());
            (out, error)
        }
        #[cfg(target_arch = "wasm32")]
        {
            (f(), None)
        }
    }

    /// Checks a buffer of `size` bytes with `usage` against the device's limits before it is
    /// created: wgpu reports an over-limit buffer only as a validation error, and
    /// `create_buffer_init` then panics while mapping the invalid buffer. The error names the
    /// buffer, its size, the limit and what to change.
    pub(crate) fn check_buffer(&self, label: &str, size: u64, usage: wgpu::BufferUsages) -> Result<()> {
        let limits = self.device.limits();
        let mut checks = vec![("largest buffer", limits.max_buffer_size)];
        if usage.contains(wgpu::BufferUsages::STORAGE) {
            checks.push(("largest storage-buffer binding", limits.max_storage_buffer_binding_size));
        }
        if usage.contains(wgpu::BufferUsages::UNIFORM) {
            checks.push(("largest uniform-buffer binding", limits.max_uniform_buffer_binding_size));
        }
        for (limit_name, limit) in checks {
            if size > limit {
                return Err(self.too_large(label, size, limit, limit_name));
            }
        }
        Ok(())
    }

    /// Checks a 2D texture's size against the device's largest texture side.
    pub(crate) fn check_texture(&self, label: &str, width: u32, height: u32) -> Result<()> {
        let limit = self.device.limits().max_texture_dimension_2d;
        if width.max(height) > limit {
            return Err(Error::TooLarge {
                resource: format!("the '{label}' texture ({width}x{height} texels)"),
                limit: format!("its largest texture side, {limit} texels"),
                adapter: self.describe(),
                hint: hint_for(label),
            });
        }
        Ok(())
    }

    fn too_large(&self, label: &str, size: u64, limit: u64, limit_name: &str) -> Error {
        Error::TooLarge {
            resource: format!("the '{label}' buffer ({})", human_bytes(size)),
            limit: format!("its {limit_name}, {}", human_bytes(limit)),
            adapter: self.describe(),
            hint: hint_for(label),
        }
    }

    /// A buffer holding `bytes`, checked first ([`Gpu::check_buffer`]).
    pub fn buffer_init(&self, label: &str, bytes: &[u8], usage: wgpu::BufferUsages) -> Result<wgpu::Buffer> {
        // wgpu refuses zero-sized bindings and shaders expect at least one element: an empty
        // array gets 256 zero bytes, more than any element type.
        let pad = [0u8; 256];
        let contents = if bytes.is_empty() { &pad[..] } else { bytes };
        self.check_buffer(label, contents.len() as u64, usage)?;
        Ok(self.device.create_buffer_init(&wgpu::util::BufferInitDescriptor {
            label: Some(label),
            contents,
            usage,
        }))
    }

    /// An uninitialised buffer of `size` bytes (at least 16), checked first.
    pub(crate) fn buffer(&self, label: &str, size: u64, usage: wgpu::BufferUsages) -> Result<wgpu::Buffer> {
        self.check_buffer(label, size.max(16), usage)?;
        Ok(self.create_buffer_unchecked(label, size, usage))
    }

    /// An uninitialised buffer of `size` bytes (at least 16), its limits checked by the caller.
    fn create_buffer_unchecked(&self, label: &str, size: u64, usage: wgpu::BufferUsages) -> wgpu::Buffer {
        self.device.create_buffer(&wgpu::BufferDescriptor {
            label: Some(label),
            size: size.max(16),
            usage,
            mapped_at_creation: false,
        })
    }

    /// An uninitialised buffer of `size` bytes that shaders bind a window at a time (the surfel
    /// pool: passes/splat.rs), so only the buffer limit applies to the whole.
    pub(crate) fn windowed_buffer(
        &self,
        label: &str,
        size: u64,
        usage: wgpu::BufferUsages,
    ) -> Result<wgpu::Buffer> {
        let whole = usage - wgpu::BufferUsages::STORAGE - wgpu::BufferUsages::UNIFORM;
        self.check_buffer(label, size.max(16), whole)?;
        Ok(self.create_buffer_unchecked(label, size, usage))
    }

    /// A buffer of `count` slots of `slot_size` bytes where each draw binds one slot (a uniform
    /// per shadow face): the binding limits apply to a slot, the buffer limit to the whole.
    pub(crate) fn slotted_buffer(
        &self,
        label: &str,
        slot_size: u64,
        count: u64,
        usage: wgpu::BufferUsages,
    ) -> Result<wgpu::Buffer> {
        self.check_buffer(label, slot_size, usage)?;
        let total = slot_size.saturating_mul(count.max(1)).max(16);
        self.check_buffer(label, total, usage - (wgpu::BufferUsages::UNIFORM | wgpu::BufferUsages::STORAGE))?;
        Ok(self.device.create_buffer(&wgpu::BufferDescriptor {
            label: Some(label),
            size: total,
            usage,
            mapped_at_creation: false,
        }))
    }

    /// A single-level 2D texture, checked first.
    pub(crate) fn texture_2d(
        &self,
        label: &str,
        width: u32,
        height: u32,
        format: wgpu::TextureFormat,
        usage: wgpu::TextureUsages,
    ) -> Result<wgpu::Texture> {
        self.check_texture(label, width, height)?;
        Ok(self.device.create_texture(&wgpu::TextureDescriptor {
            label: Some(label),
            size: wgpu::Extent3d { width: width.max(1), height: height.max(1), depth_or_array_layers: 1 },
            mip_level_count: 1,
            sample_count: 1,
            dimension: wgpu::TextureDimension::D2,
            format,
            usage,
            view_formats: &[],
        }))
    }

    /// Starts copying `size` bytes of `buffer` (which needs COPY_SRC) to the CPU without
    /// waiting: [`PendingRead::take`] has them once the GPU is done. The only read-back a browser
    /// can do (it cannot block on the GPU; the map completes between its frames).
    pub fn start_read(&self, buffer: &wgpu::Buffer, size: u64) -> PendingRead {
        self.start_read_at(buffer, 0, size)
    }

    /// As [`Gpu::start_read`], from byte `offset` (a multiple of 4) of `buffer`.
    fn start_read_at(&self, buffer: &wgpu::Buffer, offset: u64, size: u64) -> PendingRead {
        let size = size.max(4).next_multiple_of(4);
        let staging = self.device.create_buffer(&wgpu::BufferDescriptor {
            label: Some("readback"),
            size,
            usage: wgpu::BufferUsages::MAP_READ | wgpu::BufferUsages::COPY_DST,
            mapped_at_creation: false,
        });
        let mut enc = self.device.create_command_encoder(&Default::default());
        enc.copy_buffer_to_buffer(buffer, offset, &staging, 0, size);
        self.queue.submit([enc.finish()]);
        let state: Arc<Mutex<Option<std::result::Result<(), String>>>> = Arc::new(Mutex::new(None));
        let sink = state.clone();
        staging.slice(..).map_async(wgpu::MapMode::Read, move |r| {
            if let Ok(mut s) = sink.lock() {
                *s = Some(r.map_err(|e| e.to_string()));
            }
        });
        PendingRead { staging, state }
    }

    /// Copies `size` bytes of `buffer` (which needs COPY_SRC) to the CPU, blocking. Not in a
    /// browser, which cannot block on the GPU: there it is an error naming what asked
    /// ([`Gpu::start_read`] is what a browser can do).
    pub fn read_buffer(&self, buffer: &wgpu::Buffer, size: u64) -> Result<Vec<u8>> {
        self.read_range(buffer, 0, size)
    }

    /// As [`Gpu::read_buffer`], `size` bytes from byte `offset` (a multiple of 4).
    pub fn read_range(&self, buffer: &wgpu::Buffer, offset: u64, size: u64) -> Result<Vec<u8>> {
        if cfg!(target_arch = "wasm32") {
            return Err(Error::Unsupported {
                adapter: self.describe(),
                what: format!("a blocking read-back of {size} bytes"),
                hint: "a browser cannot wait for the GPU".into(),
            });
        }
        let read = self.start_read_at(buffer, offset, size);
        self.wait_for("readback", || read.take().transpose())
    }

    /// Blocks until the GPU is done and `arrived` (which looks at a read-back's callback) has its
    /// result. The map's callback runs in whichever thread polls the device: where threads share
    /// one device (the tests do), another thread's poll can take our callback and run it just
    /// after our own wait returned, so the wait alone does not promise it has run.
    pub(crate) fn wait_for<T>(
        &self,
        pass: &'static str,
        mut arrived: impl FnMut() -> Result<Option<T>>,
    ) -> Result<T> {
        self.wait()?;
        self.check(pass)?;
        let start = std::time::Instant::now();
        loop {
            if let Some(done) = arrived()? {
                return Ok(done);
            }
            if start.elapsed() > std::time::Duration::from_secs(30) {
                return Err(Error::Gpu {
                    pass,
                    message: "the read-back had not arrived 30 s after the GPU finished".into(),
                });
            }
            self.device
                .poll(wgpu::PollType::Poll)
                .map_err(|e| Error::Gpu { pass: "wait", message: e.to_string() })?;
            std::thread::sleep(std::time::Duration::from_micros(200));
        }
    }

    /// Blocks until all submitted work is done.
    pub(crate) fn wait(&self) -> Result<()> {
        self.device
            .poll(wgpu::PollType::wait_indefinitely())
            .map_err(|e| Error::Gpu { pass: "wait", message: e.to_string() })?;
        Ok(())
    }
}

/// A read-back under way ([`Gpu::start_read`]).
#[derive(Debug)]
pub struct PendingRead {
    staging: wgpu::Buffer,
    /// Set by the map's callback: whether mapping worked.
    state: Arc<Mutex<Option<std::result::Result<(), String>>>>,
}

impl PendingRead {
    /// The bytes where the GPU has finished (None: not yet; ask again after the next frame).
    pub fn take(&self) -> Option<Result<Vec<u8>>> {
        let done = self.state.lock().ok()?.take()?;
        Some(done.map_err(|message| Error::Gpu { pass: "readback", message }).and_then(|()| {
            let slice = self.staging.slice(..);
            let view = slice
                .get_mapped_range()
                .map_err(|e| Error::Gpu { pass: "readback", message: e.to_string() })?;
            let out = view.to_vec();
            drop(view);
            self.staging.unmap();
            Ok(out)
        }))
    }
}
