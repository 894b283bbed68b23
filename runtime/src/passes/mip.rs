//! Anisotropic mipmapping (mip.wgsl): one dispatch per node height, leaves first, so every level
//! reads finished children (wgpu orders dispatches that write and read the same buffer). The node
//! order and the level ranges live in buffers sized for the node pool (pool.rs), rewritten when
//! the resident tiles change ([`Mip::set_order`]).

use crate::error::{Error, Result};
use crate::gpu::Gpu;
use crate::gpu::types::MipRange;

/// Most node heights a scene may have (a tile's SVO is at most 21 levels deep: morton codes).
pub(crate) const MAX_HEIGHTS: usize = 32;

/// Stride of the level ranges in their uniform buffer (wgpu's largest uniform offset alignment).
const RANGE_STRIDE: u64 = 256;

#[derive(Debug)]
pub(crate) struct Mip {
    pipeline: super::ComputePipeline,
    order: wgpu::Buffer,
    ranges: wgpu::Buffer,
    /// One bind group per height, and the nodes of each height in use.
    levels: Vec<wgpu::BindGroup>,
    counts: Vec<u32>,
}

impl Mip {
    /// The pass, with room for `node_capacity` nodes, ordered as `by_height` and `ranges` say.
    pub(crate) fn new(
        gpu: &Gpu,
        shared: &super::Shared,
        node_capacity: u64,
        by_height: &[u32],
        ranges: &[MipRange],
        consts: super::PassConstants,
    ) -> Result<Self> {
        let pipeline = super::compute_pipeline(gpu, "mip", crate::shaders::MIP, "mip", shared, consts)?;
        let layout = super::own_layout(&pipeline, "mip")?;
        let usage = wgpu::BufferUsages::STORAGE | wgpu::BufferUsages::COPY_DST;
        let order = gpu.buffer("mip order", 4 * node_capacity.max(by_height.len() as u64), usage)?;
        let ranges_buf = gpu.buffer(
            "mip ranges",
            RANGE_STRIDE * MAX_HEIGHTS as u64,
            wgpu::BufferUsages::UNIFORM | wgpu::BufferUsages::COPY_DST,
        )?;
        let levels = (0..MAX_HEIGHTS as u64)
            .map(|h| {
                gpu.device.create_bind_group(&wgpu::BindGroupDescriptor {
                    label: Some("mip level"),
                    layout,
                    entries: &[
                        wgpu::BindGroupEntry {
                            binding: 0,
                            resource: wgpu::BindingResource::Buffer(wgpu::BufferBinding {
                                buffer: &ranges_buf,
                                offset: h * RANGE_STRIDE,
                                size: wgpu::BufferSize::new(size_of::<MipRange>() as u64),
                            }),
                        },
                        wgpu::BindGroupEntry { binding: 1, resource: order.as_entire_binding() },
                    ],
                })
            })
            .collect();
        let mut mip = Self { pipeline, order, ranges: ranges_buf, levels, counts: Vec::new() };
        mip.set_order(gpu, by_height, ranges)?;
        Ok(mip)
    }

    /// The nodes to filter, by height (`SceneData::nodes_by_height` or the pools' equivalent).
    pub(crate) fn set_order(&mut self, gpu: &Gpu, by_height: &[u32], ranges: &[MipRange]) -> Result<()> {
        if ranges.len() > MAX_HEIGHTS || 4 * by_height.len() as u64 > self.order.size() {
            return Err(Error::Internal {
                what: "mip",
                message: format!(
                    "{} heights and {} nodes, over the pass's {MAX_HEIGHTS} and {}",
                    ranges.len(),
                    by_height.len(),
                    self.order.size() / 4
                ),
            });
        }
        if !by_height.is_empty() {
            gpu.queue.write_buffer(&self.order, 0, bytemuck::cast_slice(by_height));
        }
        for (h, r) in ranges.iter().enumerate() {
            gpu.queue.write_buffer(&self.ranges, h as u64 * RANGE_STRIDE, bytemuck::bytes_of(r));
        }
        self.counts = ranges.iter().map(|r| r.count).collect();
        Ok(())
    }

    pub(crate) fn record(&self, pass: &mut wgpu::ComputePass<'_>) {
        self.pipeline.bind(pass);
        for (bg, count) in self.levels.iter().zip(&self.counts) {
            pass.set_bind_group(super::OWN_GROUP, bg, &[]);
            super::dispatch_linear(pass, *count);
        }
    }
}
