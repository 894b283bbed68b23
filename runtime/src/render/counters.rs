//! Work counts of each pass that do not depend on how fast the adapter is: draw calls and
//! surfels drawn (counted as the passes are recorded), and, where the adapter has pipeline
//! statistics queries and the caller asked for them ([`crate::gpu::GpuOptions::work_counters`]),
//! the shader invocations the GPU ran (vertices, primitives out of clipping, fragments, compute
//! invocations). `grotto bench --json` reports them; docs/benchmarks.md tabulates them. Beside
//! them, each pass's GPU time from timestamp queries where the adapter has them
//! ([`PassCounters`] holds both query sets for the scheduler, render/frame.rs).

use std::collections::BTreeMap;

use serde::Serialize;

use crate::error::Result;
use crate::gpu::Gpu;
use crate::light::plan::Pass;

/// What one run of a pass did.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq, Serialize)]
pub struct PassWork {
    /// Draw calls (splat passes: one per run of surfels per face or view).
    pub draws: u64,
    /// Surfels drawn (six vertices each), over all faces.
    pub surfels: u64,
    /// From pipeline statistics queries, where the adapter has them and they were asked for.
    pub vertex_invocations: Option<u64>,
    pub primitives_out: Option<u64>,
    pub fragment_invocations: Option<u64>,
    pub compute_invocations: Option<u64>,
}

/// The statistics the queries collect, in the order the GPU writes them (wgpu writes the enabled
/// statistics in the order of their bits).
const STATS: wgpu::PipelineStatisticsTypes = wgpu::PipelineStatisticsTypes::VERTEX_SHADER_INVOCATIONS
    .union(wgpu::PipelineStatisticsTypes::CLIPPER_PRIMITIVES_OUT)
    .union(wgpu::PipelineStatisticsTypes::FRAGMENT_SHADER_INVOCATIONS)
    .union(wgpu::PipelineStatisticsTypes::COMPUTE_SHADER_INVOCATIONS);

/// Resolved queries land this far apart (wgpu's `QUERY_RESOLVE_BUFFER_ALIGNMENT`).
const STRIDE: u64 = wgpu::QUERY_RESOLVE_BUFFER_ALIGNMENT;

/// One pipeline statistics query per pass.
#[derive(Debug)]
struct StatQueries {
    set: wgpu::QuerySet,
    resolved: wgpu::Buffer,
}

impl StatQueries {
    /// The queries, where the device has the feature (asked for by `work_counters`).
    fn new(gpu: &Gpu) -> Option<Self> {
        gpu.pipeline_statistics.then(|| {
            let ty = wgpu::QueryType::PipelineStatistics(STATS);
            let (set, resolved) = query_set(gpu, "pass work", ty, Pass::ALL.len() as u32, STRIDE);
            Self { set, resolved }
        })
    }

    /// The query set and index that `pass` counts into.
    fn slot(&self, pass: Pass) -> (&wgpu::QuerySet, u32) {
        (&self.set, index(pass))
    }

    /// Resolves the queries of the passes `ran` into the readback buffer.
    fn resolve(&self, enc: &mut wgpu::CommandEncoder, ran: &[Pass]) {
        for &p in ran {
            let i = index(p);
            enc.resolve_query_set(&self.set, i..i + 1, &self.resolved, u64::from(i) * STRIDE);
        }
    }

    /// Reads the counts of the passes `ran` back into `work`.
    fn read(&self, gpu: &Gpu, ran: &[Pass], work: &mut BTreeMap<Pass, PassWork>) -> Result<()> {
        let bytes = gpu.read_buffer(&self.resolved, STRIDE * Pass::ALL.len() as u64)?;
        for &p in ran {
            let at = (u64::from(index(p)) * STRIDE) as usize;
            let v: [u64; 4] = bytemuck::pod_read_unaligned(&bytes[at..at + 32]);
            let w = work.entry(p).or_default();
            w.vertex_invocations = Some(v[0]);
            w.primitives_out = Some(v[1]);
            w.fragment_invocations = Some(v[2]);
            w.compute_invocations = Some(v[3]);
        }
        Ok(())
    }
}

/// Timestamp queries around each pass, where the adapter has them.
#[derive(Debug)]
struct PassTimes {
    set: wgpu::QuerySet,
    resolved: wgpu::Buffer,
}

impl PassTimes {
    fn new(gpu: &Gpu) -> Option<Self> {
        gpu.timestamps.then(|| {
            let count = 2 * Pass::ALL.len() as u32;
            let (set, resolved) = query_set(gpu, "pass times", wgpu::QueryType::Timestamp, count, 8);
            Self { set, resolved }
        })
    }
}

/// The queries a frame's passes write into: their GPU times and, where asked for, their work.
#[derive(Debug)]
pub(super) struct PassCounters {
    times: Option<PassTimes>,
    work: Option<StatQueries>,
}

impl PassCounters {
    pub(super) fn new(gpu: &Gpu) -> Self {
        Self { times: PassTimes::new(gpu), work: StatQueries::new(gpu) }
    }

    /// Whether the GPU times the passes itself; without, the scheduler times each pass on the
    /// CPU, each in a blocking submit of its own.
    pub(super) fn timed_on_gpu(&self) -> bool {
        self.times.is_some()
    }

    /// The timestamp query set and the first of the two indices `pass` writes.
    pub(super) fn time_pair(&self, pass: Pass) -> Option<(&wgpu::QuerySet, u32)> {
        self.times.as_ref().map(|t| (&t.set, 2 * index(pass)))
    }

    /// The statistics query set and index `pass` counts into.
    pub(super) fn work_slot(&self, pass: Pass) -> Option<(&wgpu::QuerySet, u32)> {
        self.work.as_ref().map(|q| q.slot(pass))
    }

    /// Resolves the queries of the passes `ran` at the end of the frame's commands.
    pub(super) fn resolve(&self, enc: &mut wgpu::CommandEncoder, ran: &[Pass]) {
        if ran.is_empty() {
            return;
        }
        if let Some(t) = &self.times {
            enc.resolve_query_set(&t.set, 0..2 * Pass::ALL.len() as u32, &t.resolved, 0);
        }
        if let Some(q) = &self.work {
            q.resolve(enc, ran);
        }
    }

    /// Reads the times and work of the passes `ran` into `stats` (after the frame's submit).
    pub(super) fn read(&self, gpu: &Gpu, ran: &[Pass], stats: &mut PassStats) -> Result<()> {
        if ran.is_empty() {
            return Ok(());
        }
        if let Some(t) = &self.times {
            let bytes = gpu.read_buffer(&t.resolved, 16 * Pass::ALL.len() as u64)?;
            let ticks: Vec<u64> = bytemuck::pod_collect_to_vec(&bytes);
            let period = f64::from(gpu.queue.get_timestamp_period());
            for &pass in ran {
                let i = index(pass) as usize;
                let dt = ticks[2 * i + 1].saturating_sub(ticks[2 * i]) as f64 * period / 1e6;
                stats.last_ms.insert(pass, dt);
            }
        }
        if let Some(q) = &self.work {
            q.read(gpu, ran, &mut stats.work)?;
        }
        Ok(())
    }
}

/// `count` queries of type `ty` and the buffer they resolve into, `stride` bytes each.
fn query_set(
    gpu: &Gpu,
    label: &'static str,
    ty: wgpu::QueryType,
    count: u32,
    stride: u64,
) -> (wgpu::QuerySet, wgpu::Buffer) {
    let set = gpu.device.create_query_set(&wgpu::QuerySetDescriptor { label: Some(label), ty, count });
    let resolved = gpu.device.create_buffer(&wgpu::BufferDescriptor {
        label: Some(label),
        size: stride * u64::from(count),
        usage: wgpu::BufferUsages::QUERY_RESOLVE | wgpu::BufferUsages::COPY_SRC,
        mapped_at_creation: false,
    });
    (set, resolved)
}

fn index(pass: Pass) -> u32 {
    Pass::ALL.iter().position(|p| *p == pass).unwrap_or(0) as u32
}

/// Per-pass counters and the last measured GPU time.
#[derive(Clone, Debug, Default, Serialize)]
pub struct PassStats {
    /// How many times each pass was recorded (a skipped pass stays at zero).
    pub dispatches: BTreeMap<Pass, u64>,
    /// GPU milliseconds of each pass's last run (timestamp queries), or, where the adapter has
    /// none, CPU wall time from recording the pass to the end of its own blocking submit.
    pub last_ms: BTreeMap<Pass, f64>,
    pub bounces_done: u32,
    pub last_change: Option<f32>,
    /// Leaves updated by all propagation bounces so far (a bounce updates only the tiles whose
    /// light may still change: activity.rs).
    pub propagated_leaves: u64,
    /// What each pass's last run did (render/counters.rs).
    pub work: BTreeMap<Pass, PassWork>,
    /// Command buffers submitted and bytes written to GPU buffers by the last frame (a call of
    /// `render` or a light update; scene updates count their own bytes).
    pub last_submits: u64,
    pub last_upload_bytes: u64,
}
