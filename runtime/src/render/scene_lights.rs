//! The scene's lights as the renderer holds them: their records on the GPU with room for more,
//! the light grid's room in the lookup buffer, which lights have shadow maps, and the counts the
//! plan reads (point and spot lights, a headlamp, lights in range per grid cell). A light edit
//! in place (render/edit.rs) asks here whether the new lights fit and writes them here.

use crate::gpu::Gpu;
use crate::gpu::types::LightGpu;
use crate::light::setup::LightSetup;

#[derive(Debug)]
pub(super) struct SceneLights {
    /// The lights' records (lights.wgsl): lights, shadow faces' matrices, profiles.
    pub(super) records: wgpu::Buffer,
    /// Words the light grid may take in the lookup buffer.
    pub(super) grid_room: u32,
    /// Whether each scene light (in the scene's order) has a shadow map.
    pub(super) mapped: Vec<bool>,
    pub(super) point: usize,
    pub(super) spot: usize,
    /// The scene's last light is a headlamp added for a lightless scene (the plan says so).
    pub(super) headlamp: bool,
    /// Lights per light-grid cell: mean and largest.
    pub(super) in_range: (f32, u32),
}

impl SceneLights {
    pub(super) fn new(records: wgpu::Buffer, grid_room: u32, setup: &LightSetup, headlamp: bool) -> Self {
        Self {
            records,
            grid_room,
            mapped: setup.mapped.clone(),
            point: setup.point_lights,
            spot: setup.spot_lights,
            headlamp,
            in_range: setup.grid.occupancy(),
        }
    }

    /// Point and spot lights: what inject and the shadow pass light the leaves with.
    pub(super) fn analytic(&self) -> usize {
        self.point + self.spot
    }

    /// Whether `setup`'s light grid and `records` fit the room this renderer was made with.
    pub(super) fn fits(&self, setup: &LightSetup, records: &[LightGpu]) -> bool {
        let room = self.records.size() / size_of::<LightGpu>() as u64;
        setup.grid.words.len() <= self.grid_room as usize && records.len() as u64 <= room
    }

    /// Takes `setup`'s lights: writes their records and keeps their counts.
    pub(super) fn take(&mut self, gpu: &Gpu, setup: LightSetup, records: &[LightGpu], headlamp: bool) {
        gpu.queue.write_buffer(&self.records, 0, bytemuck::cast_slice(records));
        self.point = setup.point_lights;
        self.spot = setup.spot_lights;
        self.headlamp = headlamp;
        self.in_range = setup.grid.occupancy();
        self.mapped = setup.mapped;
    }
}
