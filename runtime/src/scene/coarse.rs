//! A tile's coarse level on the GPU: its leaves ([`grotto_levels::coarse`], stored by the packer
//! or derived at load) as [`LeafGpu`]s, and one oriented splat per leaf that covers anything, so a
//! tile held coarse (residency.rs) is still drawn, from about 1/64 of its surfels.

use glam::Vec3;
use grotto_format::color::srgb8_to_linear;
use grotto_format::spec::CoarseLeaf;

use crate::gpu::types::{LeafGpu, SurfelGpu};

pub(crate) use grotto_levels::coarse::{COARSE_LEVELS, CoarseLevel, FAR_LEVELS, coarse_level};

/// A tile at its coarse level, as the passes read it.
#[derive(Clone, Debug, Default, PartialEq)]
pub(crate) struct CoarseTile {
    /// One per coarse leaf, in the order of the coarse SVO's leaves.
    pub(crate) leaves: Vec<LeafGpu>,
    /// One disc per coarse leaf that covers anything.
    pub(crate) splats: Vec<SurfelGpu>,
}

/// The GPU form of coarse `leaves` `k` levels above package leaves of `leaf_m`, in a tile whose
/// origin is `tile_origin_m` in the frame.
pub(crate) fn gpu_tile(leaves: &[CoarseLeaf], k: u32, leaf_m: f32, tile_origin_m: Vec3) -> CoarseTile {
    let edge_m = leaf_m * (1u32 << k) as f32;
    let mut out = CoarseTile { leaves: Vec::with_capacity(leaves.len()), splats: Vec::new() };
    for l in leaves {
        let centre = tile_origin_m + Vec3::from_array(l.centroid_tile_m);
        let normal = Vec3::from_array(l.ndf.mean);
        let albedo = l.albedo.0;
        out.leaves.push(LeafGpu {
            albedo_opacity: [
                srgb8_to_linear(albedo[0]),
                srgb8_to_linear(albedo[1]),
                srgb8_to_linear(albedo[2]),
                l.opacity,
            ],
            normal_mean: normal.extend(0.0).to_array(),
            // The leaf's edge rides in w: cones start outside a coarse leaf, not inside it.
            center_m: centre.extend(edge_m).to_array(),
            emission: Vec3::from_array(l.emission).extend(0.0).to_array(),
        });
        if l.opacity > 0.0 {
            // The block's inscribed disc, scaled by the coverage's square root: the splat pass
            // grows every disc by its splat scale (2 by default) so neighbours overlap, as it
            // does for the package's surfels.
            let radius = 0.5 * edge_m * l.opacity.sqrt();
            out.splats.push(SurfelGpu {
                position_radius: centre.extend(radius).to_array(),
                normal_spread: normal.normalize_or(Vec3::Z).extend(1.0 - normal.length().min(1.0)).to_array(),
                color: [albedo[0], albedo[1], albedo[2], 0],
                scan: crate::gpu::types::NO_SCAN,
            });
        }
    }
    out
}

#[cfg(test)]
mod tests {
    use super::*;
    use grotto_format::spec::{LeafNdf, Rgba8};

    #[test]
    fn coarse_leaves_sit_in_the_frame_with_their_edge_and_draw_only_where_they_cover() {
        let leaf = |opacity: f32| CoarseLeaf {
            centroid_tile_m: [0.25, 0.5, 0.75],
            opacity,
            ndf: LeafNdf { mean: [0.0, 0.0, 0.5], weight: 3.0 },
            emission: [1.0, 2.0, 3.0],
            albedo: Rgba8([255, 0, 128, 255]),
        };
        let t = gpu_tile(&[leaf(0.25), leaf(0.0)], 3, 0.1, Vec3::new(10.0, 20.0, 30.0));
        assert_eq!(t.leaves.len(), 2);
        assert_eq!(t.leaves[0].center_m, [10.25, 20.5, 30.75, 0.8]);
        assert_eq!(t.leaves[0].albedo_opacity[..2], [1.0, 0.0]);
        assert_eq!(t.leaves[0].emission[..3], [1.0, 2.0, 3.0]);
        assert_eq!(t.splats.len(), 1, "a leaf that covers nothing draws nothing");
        let s = t.splats[0];
        assert!((s.position_radius[3] - 0.5 * 0.8 * 0.5).abs() < 1e-6);
        assert_eq!(s.normal_spread, [0.0, 0.0, 1.0, 0.5]);
        assert_eq!(s.color, [255, 0, 128, 0]);
    }
}
