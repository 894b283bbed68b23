//! What a scene knows of a tile whose nodes, leaves and surfels it does not hold because a
//! renderer does ([`TileSummary`]), and the key of a tile form ([`TileKey`]): what lets a change
//! of tiles read only the tiles that change (`SceneData::from_package_with_held`), and a viewer
//! keep on the CPU nothing its GPU holds (`SceneData::release_tile_data`).

use glam::Vec3;

use crate::gpu::types::{LeafGpu, NodeGpu, SurfelGpu, TileGpu};

/// Most specular materials a scene may assign (slots 1..=7 of the surfel colour's alpha).
pub(crate) const MAX_MATERIALS: usize = 7;

/// A tile form: where the tile is (its corner in frame leaves), its SVO depth, and the level it
/// is held at. Two scenes holding the same key hold the same nodes, leaves and surfels.
pub type TileKey = ([i32; 3], u32, u32);

/// The key of a tile record.
pub(crate) fn key(t: &TileGpu) -> TileKey {
    (t.origin_leaf, t.depth, t.leaf_lod)
}

/// Summaries of the tile forms a renderer holds, by key: what a load leaves out.
pub type HeldTiles = std::collections::HashMap<TileKey, TileSummary>;

/// What the renderer needs of a tile it holds without the scene holding its data: its element
/// counts, the shape of its node tree (for the mip order), and what the light's parameters are
/// made from.
#[derive(Clone, Debug, Default, PartialEq)]
pub struct TileSummary {
    /// Nodes at each level from the tile's root down to the level it is held at. Nodes are
    /// breadth-first, so each level's nodes follow the level above's.
    pub(crate) nodes_by_level: Vec<u32>,
    pub(crate) leaves: u32,
    pub(crate) surfels: u32,
    /// Whether any of its leaves emits.
    pub(crate) emission: bool,
    /// The box around its leaves' cells in frame leaves (a coarse leaf's whole cell); None
    /// without leaves.
    pub(crate) occupied_leaf: Option<(Vec3, Vec3)>,
    /// Its leaves' largest finite albedo per channel.
    pub(crate) albedo_max: [f32; 3],
    /// Its surfels assigned to each specular material slot (1..=7, at 0..=6).
    pub(crate) material_surfels: [u32; MAX_MATERIALS],
}

impl TileSummary {
    pub(crate) fn nodes(&self) -> u32 {
        self.nodes_by_level.iter().sum()
    }

    /// The summary of a tile held at `leaf_level` from its data: its nodes down to that level,
    /// its leaves and its surfels.
    pub(crate) fn of(
        leaf_level: u32,
        nodes: &[NodeGpu],
        leaves: &[LeafGpu],
        surfels: &[SurfelGpu],
        leaf_size_m: f32,
    ) -> Self {
        let mut nodes_by_level = vec![0u32; leaf_level as usize + 1];
        for n in nodes {
            if let Some(c) = nodes_by_level.get_mut(n.level() as usize) {
                *c += 1;
            }
        }
        let mut material_surfels = [0u32; MAX_MATERIALS];
        for s in surfels {
            if let Some(c) = usize::from(s.color[3]).checked_sub(1).and_then(|k| material_surfels.get_mut(k))
            {
                *c += 1;
            }
        }
        Self {
            nodes_by_level,
            leaves: leaves.len() as u32,
            surfels: surfels.len() as u32,
            emission: leaves.iter().any(|l| l.emission[..3].iter().any(|&e| e > 0.0)),
            occupied_leaf: cells_box(leaf_size_m, leaves),
            albedo_max: albedo_max(leaves),
            material_surfels,
        }
    }
}

/// The box around `leaves`' cells in frame leaves (a coarse leaf's whole cell); None when empty.
pub(crate) fn cells_box(leaf_size_m: f32, leaves: &[LeafGpu]) -> Option<(Vec3, Vec3)> {
    let leaf_m = leaf_size_m.max(1e-9);
    let mut lo = Vec3::splat(f32::MAX);
    let mut hi = Vec3::splat(f32::MIN);
    for l in leaves {
        let edge = (l.center_m[3] / leaf_m).round().max(1.0);
        let cell_lo = (Vec3::from_slice(&l.center_m[..3]) / (leaf_m * edge)).floor() * edge;
        lo = lo.min(cell_lo);
        hi = hi.max(cell_lo + edge);
    }
    (!leaves.is_empty()).then_some((lo, hi))
}

/// The largest finite albedo of `leaves` per channel.
pub(crate) fn albedo_max(leaves: &[LeafGpu]) -> [f32; 3] {
    let mut m = [0.0f32; 3];
    for l in leaves {
        for (k, v) in m.iter_mut().enumerate() {
            let a = l.albedo_opacity[k];
            if a.is_finite() {
                *v = v.max(a);
            }
        }
    }
    m
}
