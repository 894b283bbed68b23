//! Re-indexes the nodes of tiles the pools moved (rebase.wgsl), on the GPU: a node's first child
//! indexes the pools, so a tile moved within them adds its moves to its nodes' indices. Done
//! where the nodes lie, it needs no copy of them on the CPU and no read-back, which a browser
//! cannot wait for. Checked against the CPU's re-indexing ([`rebased`]), which writes a tile's
//! nodes into a new slot.
//!
//! Written here rather than taken from a crate: one small compute shader over grotto's own node
//! layout.

use bytemuck::{Pod, Zeroable};

use crate::error::Result;
use crate::gpu::Gpu;
use crate::gpu::types::NodeGpu;

/// One moved tile's nodes.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub struct RebaseJob {
    /// Its nodes' range in the node pool, where they lie now.
    pub start: u32,
    pub count: u32,
    /// The level of its nodes whose first child is a leaf.
    pub leaf_level: u32,
    /// Its node and leaf offsets before and after the move.
    pub from: (u32, u32),
    pub to: (u32, u32),
}

/// A tile's nodes moved from node and leaf offsets `from` to `to`: the indices inside the tile
/// move with it, to its nodes for inner nodes and to its leaves for the nodes at its leaf level.
pub(crate) fn rebased(nodes: &[NodeGpu], leaf_level: u32, from: (u32, u32), to: (u32, u32)) -> Vec<NodeGpu> {
    nodes
        .iter()
        .map(|n| {
            let first_child = if n.level() == leaf_level {
                n.first_child.wrapping_sub(from.1).wrapping_add(to.1)
            } else {
                n.first_child.wrapping_sub(from.0).wrapping_add(to.0)
            };
            NodeGpu { first_child, ..*n }
        })
        .collect()
}

/// rebase.wgsl's `Job`.
#[repr(C)]
#[derive(Clone, Copy, Debug, Pod, Zeroable)]
struct JobGpu {
    start: u32,
    count: u32,
    leaf_level: u32,
    node_delta: u32,
    leaf_delta: u32,
    before: u32,
    pad: [u32; 2],
}

/// The rebase pipeline.
#[derive(Debug)]
pub struct Rebase {
    pipeline: wgpu::ComputePipeline,
    layout: wgpu::BindGroupLayout,
}

impl Rebase {
    pub fn new(gpu: &Gpu) -> Result<Self> {
        let (pipeline, layout) = super::frame_pipeline(gpu, "rebase", crate::shaders::REBASE, "rebase")?;
        Ok(Self { pipeline, layout })
    }

    /// Re-indexes the nodes of `jobs` in `nodes` (a buffer of `NodeGpu`), in one dispatch
    /// submitted after what the queue holds (the moves that put them there).
    pub fn run(&self, gpu: &Gpu, nodes: &wgpu::Buffer, jobs: &[RebaseJob]) -> Result<()> {
        let mut before = 0u32;
        let gpu_jobs: Vec<JobGpu> = jobs
            .iter()
            .filter(|j| j.count > 0)
            .map(|j| {
                let job = JobGpu {
                    start: j.start,
                    count: j.count,
                    leaf_level: j.leaf_level,
                    node_delta: j.to.0.wrapping_sub(j.from.0),
                    leaf_delta: j.to.1.wrapping_sub(j.from.1),
                    before,
                    pad: [0; 2],
                };
                before += j.count;
                job
            })
            .collect();
        if gpu_jobs.is_empty() {
            return Ok(());
        }
        let jobs_buf =
            gpu.buffer_init("rebase jobs", bytemuck::cast_slice(&gpu_jobs), wgpu::BufferUsages::STORAGE)?;
        let bind_group = gpu.device.create_bind_group(&wgpu::BindGroupDescriptor {
            label: Some("rebase"),
            layout: &self.layout,
            entries: &[
                wgpu::BindGroupEntry { binding: 0, resource: jobs_buf.as_entire_binding() },
                wgpu::BindGroupEntry { binding: 1, resource: nodes.as_entire_binding() },
            ],
        });
        let mut enc =
            gpu.device.create_command_encoder(&wgpu::CommandEncoderDescriptor { label: Some("rebase") });
        {
            let mut pass = enc.begin_compute_pass(&wgpu::ComputePassDescriptor {
                label: Some("rebase"),
                timestamp_writes: None,
            });
            pass.set_pipeline(&self.pipeline);
            pass.set_bind_group(0, &bind_group, &[]);
            super::dispatch_linear(&mut pass, before);
        }
        gpu.queue.submit([enc.finish()]);
        Ok(())
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::gpu::GpuOptions;

    #[test]
    fn moved_tiles_nodes_are_reindexed_as_the_cpu_reindexes_a_tile_for_a_new_slot() {
        let opts = GpuOptions {
            prefer_software: true,
            backends: Some(wgpu::Backends::VULKAN),
            ..Default::default()
        };
        let gpu = Gpu::new(&opts).unwrap();
        // Three tiles' nodes, levels 0..=4 with leaf level 4 and 2, first children anywhere
        // (wrapping past zero too); a fourth range of nodes no job names stays as it was.
        let mut seed = 0x9e37_79b9u32;
        let mut next = || {
            seed ^= seed << 13;
            seed ^= seed >> 17;
            seed ^= seed << 5;
            seed
        };
        let nodes: Vec<NodeGpu> = (0..70_000)
            .map(|_| NodeGpu { first_child: next(), mask_level: (next() % 5) << 8 | (next() & 0xff) })
            .collect();
        let jobs = [
            RebaseJob { start: 0, count: 100, leaf_level: 4, from: (500, 900), to: (0, 10) },
            RebaseJob { start: 100, count: 0, leaf_level: 4, from: (7, 7), to: (1, 1) },
            RebaseJob {
                start: 300,
                count: 65_000,
                leaf_level: 2,
                from: (1000, 2000),
                to: (300, 4_000_000_000),
            },
            RebaseJob { start: 65_300, count: 17, leaf_level: 4, from: (3, 5), to: (65_300, 8) },
        ];
        let usage = wgpu::BufferUsages::STORAGE | wgpu::BufferUsages::COPY_SRC;
        let buffer = gpu.buffer_init("rebase test", bytemuck::cast_slice(&nodes), usage).unwrap();
        Rebase::new(&gpu).unwrap().run(&gpu, &buffer, &jobs).unwrap();
        let back: Vec<NodeGpu> =
            bytemuck::pod_collect_to_vec(&gpu.read_buffer(&buffer, (nodes.len() * 8) as u64).unwrap());
        let mut expected = nodes.clone();
        for j in &jobs {
            let r = j.start as usize..(j.start + j.count) as usize;
            let moved = rebased(&nodes[r.clone()], j.leaf_level, j.from, j.to);
            expected[r].copy_from_slice(&moved);
        }
        assert_eq!(back.len(), expected.len());
        let wrong = back.iter().zip(&expected).position(|(a, b)| a != b);
        assert_eq!(
            wrong,
            None,
            "node {wrong:?}: {:?} against {:?}",
            wrong.map(|i| back[i]),
            wrong.map(|i| expected[i])
        );
    }
}
