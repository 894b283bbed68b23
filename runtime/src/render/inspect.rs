//! Reading and writing the light state and running single passes: how the GPU-vs-CPU tests and
//! the reference's breakdown check the light transport. Part of the public API because checking
//! a pass needs the same renderer a frame uses, not a build of it with extra hooks; nothing here
//! runs in a frame, and all it keeps is a handle on the faces buffer (the node count comes from
//! the pools).

use crate::error::Result;
use crate::gpu::types::LeafLightGpu;
use crate::light::activity::Why;
use crate::light::plan::{self, EffectPlan, Pass};
use crate::render::renderer::Renderer;

impl Renderer {
    /// Each leaf's light state (direct, gather, out), in leaf order.
    pub fn read_leaf_light(&self) -> Result<Vec<LeafLightGpu>> {
        self.pools.read_light(&self.gpu, self.leaf_count)
    }

    /// Overwrites each leaf's light state: a known radiance field before a mip or a gather.
    pub fn write_leaf_light(&mut self, state: &[LeafLightGpu]) -> Result<()> {
        if state.len() != self.leaf_count as usize {
            return Err(crate::Error::Setting {
                name: "leaf light",
                problem: "length differs from the leaf count".into(),
            });
        }
        self.pools.write_light(&self.gpu, 0, state);
        self.stats_now.last_change = None;
        self.light.set_all_active(Why::Start);
        Ok(())
    }

    /// The six anisotropic values of every node (after a mip pass).
    pub fn read_faces(&self) -> Result<Vec<[f32; 4]>> {
        let n = self.pools.node_end() as usize * 6;
        if self.settings.radiance_f16 {
            let bytes = self.gpu.read_buffer(&self.faces, n as u64 * 8)?;
            let halves: Vec<half::f16> = bytemuck::pod_collect_to_vec(&bytes[..n * 8]);
            return Ok(halves.chunks_exact(4).map(|c| [0, 1, 2, 3].map(|k| c[k].to_f32())).collect());
        }
        let bytes = self.gpu.read_buffer(&self.faces, n as u64 * 16)?;
        Ok(bytemuck::pod_collect_to_vec(&bytes[..n * 16]))
    }

    /// Runs only the mip pass.
    pub fn run_mip(&mut self) -> Result<()> {
        let p =
            EffectPlan { steps: vec![plan::Step { pass: Pass::Mip, run: true, reason: "requested".into() }] };
        self.execute(&p, None, None)
    }

    /// Runs only mip + propagate: one bounce over every tile, whatever the plan says.
    pub fn run_bounce(&mut self) -> Result<()> {
        self.light.set_all_active(Why::Verify);
        let p = EffectPlan {
            steps: vec![
                plan::Step { pass: Pass::Mip, run: true, reason: "requested".into() },
                plan::Step { pass: Pass::Propagate, run: true, reason: "requested".into() },
            ],
        };
        self.execute(&p, None, None)
    }
}
