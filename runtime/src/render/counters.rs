//! Work counts of each pass that do not depend on how fast the adapter is: draw calls and
//! surfels drawn (counted as the passes are recorded), and, where the adapter has pipeline
//! statistics queries and the caller asked for them ([`crate::gpu::GpuOptions::work_counters`]),
//! the shader invocations the GPU ran (vertices, primitives out of clipping, fragments, compute
//! invocations). `grotto bench --json` reports them; docs/benchmarks.md tabulates them.

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
pub(super) struct StatQueries {
    set: wgpu::QuerySet,
    resolved: wgpu::Buffer,
}

impl StatQueries {
    /// The queries, where the device has the feature (asked for by `work_counters`).
    pub(super) fn new(gpu: &Gpu) -> Option<Self> {
        gpu.pipeline_statistics.then(|| {
            let set = gpu.device.create_query_set(&wgpu::QuerySetDescriptor {
                label: Some("pass work"),
                ty: wgpu::QueryType::PipelineStatistics(STATS),
                count: Pass::ALL.len() as u32,
            });
            let resolved = gpu.device.create_buffer(&wgpu::BufferDescriptor {
                label: Some("pass work"),
                size: STRIDE * Pass::ALL.len() as u64,
                usage: wgpu::BufferUsages::QUERY_RESOLVE | wgpu::BufferUsages::COPY_SRC,
                mapped_at_creation: false,
            });
            Self { set, resolved }
        })
    }

    /// The query set and index that `pass` counts into.
    pub(super) fn slot(&self, pass: Pass) -> (&wgpu::QuerySet, u32) {
        (&self.set, index(pass))
    }

    /// Resolves the queries of the passes `ran` into the readback buffer.
    pub(super) fn resolve(&self, enc: &mut wgpu::CommandEncoder, ran: &[Pass]) {
        for &p in ran {
            let i = index(p);
            enc.resolve_query_set(&self.set, i..i + 1, &self.resolved, u64::from(i) * STRIDE);
        }
    }

    /// Reads the counts of the passes `ran` back into `work`.
    pub(super) fn read(&self, gpu: &Gpu, ran: &[Pass], work: &mut BTreeMap<Pass, PassWork>) -> Result<()> {
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
