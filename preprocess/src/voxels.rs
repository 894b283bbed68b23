//! A tile's sparse voxel octree: scene samples are splatted additively into the leaves they fall in
//! (as in the cave paper), then the node array is laid out by `grotto_format::svo`.
//!
//! Per leaf, from its samples (each a surfel disc covering `area_m2`):
//! - opacity: covered fraction of the leaf's cross-section, `min(1, sum(area) / leaf^2)`;
//! - albedo: area-weighted mean in linear light, stored sRGB-encoded;
//! - NDF: area-weighted mean of unit normals; its length in 0..=1 is the spread (Toksvig); the
//!   weight is the number of samples;
//! - emission: area-weighted mean radiance of emissive samples (area lights).
//!
//! Leaves are cells of `extent / 2^depth` inside the tile; a tile's depth is chosen so all tiles
//! share one leaf size, and samples are only the tile's own points, so a voxel on a tile border
//! gets exactly what it would get in one big tile.

use grotto_format::color::linear_to_srgb8;
use grotto_format::spec::{LeafEmission, LeafNdf, Rgba8, SvoNode};
use grotto_format::svo::{morton_encode, nodes_from_leaves};
use rayon::prelude::*;

/// One scene sample in tile coordinates.
#[derive(Clone, Copy, Debug, PartialEq)]
pub(crate) struct Sample {
    pub(crate) pos_tile_m: [f32; 3],
    pub(crate) normal: [f32; 3],
    pub(crate) area_m2: f32,
    pub(crate) albedo_linear: [f32; 3],
    pub(crate) emission: [f32; 3],
}

/// The octree and its leaf attribute arrays (one entry per leaf, in node order).
#[derive(Clone, Debug, Default, PartialEq)]
pub(crate) struct TileSvo {
    pub(crate) nodes: Vec<SvoNode>,
    pub(crate) opacity: Vec<f32>,
    pub(crate) albedo: Vec<Rgba8>,
    pub(crate) ndf: Vec<LeafNdf>,
    pub(crate) emission: Vec<LeafEmission>,
}

impl TileSvo {
    pub(crate) fn leaf_count(&self) -> usize {
        self.opacity.len()
    }

    pub(crate) fn has_emission(&self) -> bool {
        self.emission.iter().any(|e| e.radiance.iter().any(|&c| c > 0.0))
    }
}

/// Leaf cell of a position, clamped into the tile (positions on the far faces belong to the last
/// cell; halo samples are not passed here).
fn cell(p: f32, inv_leaf: f64, cells: u32) -> u32 {
    ((f64::from(p) * inv_leaf).floor().max(0.0) as u32).min(cells - 1)
}

pub(crate) fn build(samples: &[Sample], extent_m: f64, depth: u32) -> TileSvo {
    if samples.is_empty() {
        return TileSvo::default();
    }
    let cells = 1u32 << depth;
    let inv_leaf = f64::from(cells) / extent_m;
    let leaf_area = (extent_m / f64::from(cells)).powi(2);
    let mut keyed: Vec<(u64, u32)> = samples
        .iter()
        .enumerate()
        .map(|(i, s)| {
            let c = s.pos_tile_m.map(|v| cell(v, inv_leaf, cells));
            (morton_encode(c[0], c[1], c[2]), i as u32)
        })
        .collect();
    // Keys are unique (index last), so the parallel sort's order is the only one.
    keyed.par_sort_unstable();
    let mut leaves = Vec::new();
    let mut out = TileSvo::default();
    let mut start = 0;
    while start < keyed.len() {
        let code = keyed[start].0;
        let end = start + keyed[start..].iter().take_while(|k| k.0 == code).count();
        let (mut area, mut albedo, mut normal, mut emission) = (0f64, [0f64; 3], [0f64; 3], [0f64; 3]);
        for &(_, i) in &keyed[start..end] {
            let s = &samples[i as usize];
            let a = f64::from(s.area_m2.max(0.0));
            area += a;
            for k in 0..3 {
                albedo[k] += a * f64::from(s.albedo_linear[k]);
                normal[k] += a * f64::from(s.normal[k]);
                emission[k] += a * f64::from(s.emission[k]);
            }
        }
        let inv = if area > 0.0 { 1.0 / area } else { 0.0 };
        let mean = normal.map(|c| (c * inv) as f32);
        // Unit normals average to length <= 1; rounding must not push it over.
        let len = mean.iter().map(|c| c * c).sum::<f32>().sqrt();
        let mean = if len > 1.0 { mean.map(|c| c / len) } else { mean };
        leaves.push(code);
        out.opacity.push(((area / leaf_area).min(1.0)) as f32);
        out.albedo.push(Rgba8({
            let c = albedo.map(|c| linear_to_srgb8((c * inv) as f32));
            [c[0], c[1], c[2], 255]
        }));
        out.ndf.push(LeafNdf { mean, weight: (end - start) as f32 });
        out.emission.push(LeafEmission { radiance: emission.map(|c| (c * inv) as f32), reserved: 0.0 });
        start = end;
    }
    out.nodes = nodes_from_leaves(&leaves, depth).expect("sorted unique codes inside the tile");
    out
}

#[cfg(test)]
mod tests {
    use super::*;

    fn sample(p: [f32; 3], n: [f32; 3]) -> Sample {
        Sample {
            pos_tile_m: p,
            normal: n,
            area_m2: 0.01,
            albedo_linear: [0.5, 0.25, 0.125],
            emission: [0.0; 3],
        }
    }

    #[test]
    fn leaves_average_and_cover() {
        // Depth 2 in a 4 m tile: 1 m leaves.
        let s = [
            sample([0.5, 0.5, 0.5], [0.0, 0.0, 1.0]),
            sample([0.6, 0.4, 0.5], [1.0, 0.0, 0.0]),
            sample([3.5, 3.5, 3.9], [0.0, 1.0, 0.0]),
        ];
        let svo = build(&s, 4.0, 2);
        assert_eq!(svo.leaf_count(), 2);
        assert_eq!(svo.nodes.len(), 1 + 2 + 2);
        let first = &svo.ndf[0];
        let len = first.mean.iter().map(|c| c * c).sum::<f32>().sqrt();
        assert!((len - std::f32::consts::FRAC_1_SQRT_2).abs() < 1e-6, "two orthogonal normals: spread");
        assert_eq!(first.weight, 2.0);
        assert!((svo.opacity[0] - 0.02).abs() < 1e-6);
        assert!((svo.opacity[1] - 0.01).abs() < 1e-6);
        // sRGB(0.5 linear) = 188.
        assert_eq!(svo.albedo[0].0, [188, 137, 99, 255]);
        assert!(!svo.has_emission());
        assert_eq!(build(&[], 4.0, 2), TileSvo::default());
    }

    #[test]
    fn one_point_and_far_face_points_stay_inside() {
        let svo = build(&[sample([4.0, 4.0, 4.0], [0.0, 0.0, 1.0])], 4.0, 3);
        assert_eq!(svo.leaf_count(), 1);
        assert_eq!(svo.nodes.last().unwrap().morton, morton_encode(7, 7, 7));
        let svo = build(&[sample([1.0, 1.0, 1.0], [0.0, 0.0, 1.0])], 4.0, 0);
        assert_eq!((svo.nodes.len(), svo.leaf_count()), (1, 1));
    }
}
