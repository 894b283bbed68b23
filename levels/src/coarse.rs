//! A tile's coarse level: its SVO cut `k` levels above the leaves, whose nodes there become leaves
//! 2^k package leaves wide. It is what stays resident of a tile the runtime does not hold in full:
//! cones that leave the resident tiles still meet walls and the light on them instead of empty
//! space (black holes) or open sky (leaks), and a distant tile is still drawn, from about 1/4^k
//! of the surfels.
//!
//! A coarse leaf stands for the leaves under it as the mip pass would see them, reduced to the one
//! opacity a leaf holds: per axis, the leaves' coverage composited along each column of the block
//! (`1 - prod(1 - a)`) and averaged over the columns (mip.wgsl's rule for inner nodes), then the
//! three axes weighted by the squared components of the mean normal (a wall is seen across it).
//! Albedo (in linear light), normal distribution and emission are the coverage-weighted means of
//! the leaves' (Toksvig's mean normal shortens where the leaves disagree); the leaf's centroid is
//! their coverage-weighted centroid, so a coarse wall stays where the wall is, not at a block's
//! centre.

use glam::{UVec3, Vec3};
use grotto_format::SvoData;
use grotto_format::color::{linear_to_srgb8, srgb8_to_linear};
use grotto_format::spec::{CoarseLeaf, LeafNdf, Rgba8, SvoNode};
use grotto_format::svo::morton_decode;

/// Levels a coarse tile is cut above its leaves: leaves 8 package leaves wide (0.5 m at 6.25 cm
/// leaves), about 1/64 of the leaves of a surface and 1/64 of its surfels. The packer stores this
/// level (`item` 3 of the coarse sections).
pub const COARSE_LEVELS: u32 = 3;

/// Levels the far level is cut above the leaves: leaves 64 package leaves wide (4 m at 6.25 cm
/// leaves), about 1/4096 of a surface's leaves, so even a cave of 10^10 points keeps every tile
/// resident in a few hundred MB and draws it from a few million splats. The packer stores it
/// too (`item` 6).
pub const FAR_LEVELS: u32 = 6;

/// The levels the packer stores, finest first.
pub(crate) const STORED_LEVELS: [u32; 2] = [COARSE_LEVELS, FAR_LEVELS];

/// A tile at a coarse level: an SVO of depth `D - k` and one leaf per node at that depth.
#[derive(Clone, Debug, Default, PartialEq)]
pub struct CoarseLevel {
    pub nodes: Vec<SvoNode>,
    pub leaves: Vec<CoarseLeaf>,
}

/// Coarse level `k` (1..=depth) of a tile of SVO depth `depth` whose leaves are `leaf_m` wide.
pub fn coarse_level(svo: &SvoData<'_>, depth: u32, k: u32, leaf_m: f64) -> CoarseLevel {
    let k = k.min(depth);
    let top = depth - k;
    let mut out = CoarseLevel::default();
    // Levels are stored root first, so the coarse SVO is the nodes down to level `top`, whose
    // nodes become leaves indexed in order.
    for n in svo.nodes.iter().take_while(|n| u32::from(n.level) <= top) {
        let mut n = *n;
        if u32::from(n.level) == top {
            n.child_mask = 0;
            n.first_child = out.leaves.len() as u32;
            out.leaves.push(CoarseLeaf::default());
        }
        out.nodes.push(n);
    }
    let leaf_nodes: Vec<&SvoNode> = svo.nodes.iter().filter(|n| u32::from(n.level) == depth).collect();
    let side = 1usize << k;
    let leaf_m = leaf_m as f32;
    // Transmittance of each column along x, y and z (indexed by the other two coordinates).
    let mut columns = vec![[1.0f32; 3]; side * side];
    let mut start = 0;
    let mut block_index = 0;
    while start < leaf_nodes.len() {
        let block = leaf_nodes[start].morton >> (3 * k);
        let end = start + leaf_nodes[start..].iter().take_while(|n| n.morton >> (3 * k) == block).count();
        columns.iter_mut().for_each(|c| *c = [1.0; 3]);
        let (mut weight, mut centroid, mut albedo, mut normal, mut emission) =
            (0.0f32, Vec3::ZERO, Vec3::ZERO, Vec3::ZERO, Vec3::ZERO);
        let (mut plain_centre, mut ndf_weight) = (Vec3::ZERO, 0.0f32);
        for (li, n) in (start..end).zip(&leaf_nodes[start..end]) {
            let cell = UVec3::from_array(morton_decode(n.morton));
            let local = cell & UVec3::splat(side as u32 - 1);
            let (x, y, z) = (local.x as usize, local.y as usize, local.z as usize);
            let a = svo.opacity[li].clamp(0.0, 1.0);
            columns[y + side * z][0] *= 1.0 - a;
            columns[x + side * z][1] *= 1.0 - a;
            columns[x + side * y][2] *= 1.0 - a;
            let c = (cell.as_vec3() + Vec3::splat(0.5)) * leaf_m;
            let Rgba8(rgba) = svo.albedo[li];
            let e = svo.emission.as_ref().map_or([0.0; 3], |e| e[li].radiance);
            plain_centre += c;
            ndf_weight += svo.ndf[li].weight;
            weight += a;
            centroid += a * c;
            albedo +=
                a * Vec3::new(srgb8_to_linear(rgba[0]), srgb8_to_linear(rgba[1]), srgb8_to_linear(rgba[2]));
            normal += a * Vec3::from_array(svo.ndf[li].mean);
            emission += a * Vec3::from_array(e);
        }
        let n = (end - start) as f32;
        let (centre, albedo, normal, emission) = if weight > 0.0 {
            (centroid / weight, albedo / weight, normal / weight, emission / weight)
        } else {
            (plain_centre / n, Vec3::ZERO, Vec3::ZERO, Vec3::ZERO)
        };
        let mut per_axis = [0.0f32; 3];
        for c in &columns {
            for a in 0..3 {
                per_axis[a] += 1.0 - c[a];
            }
        }
        let per_axis = Vec3::from_array(per_axis) / (side * side) as f32;
        let axis_weight = match normal.try_normalize() {
            Some(d) if normal.length() > 0.2 => d * d,
            _ => Vec3::splat(1.0 / 3.0),
        };
        let srgb = albedo.to_array().map(linear_to_srgb8);
        // Every block with a leaf has its node at level `top`, in the same (Morton) order.
        if let Some(slot) = out.leaves.get_mut(block_index) {
            *slot = CoarseLeaf {
                centroid_tile_m: centre.to_array(),
                opacity: per_axis.dot(axis_weight).clamp(0.0, 1.0),
                // A mean of vectors no longer than 1 is no longer than 1; the clamp keeps
                // rounding from pushing it past the reader's bound.
                ndf: LeafNdf { mean: normal.clamp_length_max(1.0).to_array(), weight: ndf_weight },
                emission: emission.max(Vec3::ZERO).to_array(),
                albedo: Rgba8([srgb[0], srgb[1], srgb[2], 255]),
            };
        }
        block_index += 1;
        start = end;
    }
    out
}

#[cfg(test)]
mod tests {
    use super::*;
    use grotto_format::spec::LeafEmission;
    use grotto_format::svo::{morton_encode, nodes_from_leaves};
    use std::borrow::Cow;

    struct Leaf {
        cell: UVec3,
        opacity: f32,
        normal: Vec3,
        albedo: u8,
    }

    /// A tile of depth 3 holding `leaves` (any order).
    fn svo(mut leaves: Vec<Leaf>) -> SvoData<'static> {
        leaves.sort_by_key(|l| morton_encode(l.cell.x, l.cell.y, l.cell.z));
        let codes: Vec<u64> = leaves.iter().map(|l| morton_encode(l.cell.x, l.cell.y, l.cell.z)).collect();
        SvoData {
            nodes: Cow::Owned(nodes_from_leaves(&codes, 3).unwrap()),
            opacity: Cow::Owned(leaves.iter().map(|l| l.opacity).collect()),
            albedo: Cow::Owned(leaves.iter().map(|l| Rgba8([l.albedo, l.albedo, l.albedo, 255])).collect()),
            ndf: Cow::Owned(
                leaves.iter().map(|l| LeafNdf { mean: l.normal.to_array(), weight: 1.0 }).collect(),
            ),
            emission: Some(Cow::Owned(vec![LeafEmission::default(); leaves.len()])),
        }
    }

    #[test]
    fn a_wall_stays_an_opaque_wall_where_it_was() {
        // A full wall z = 2 across two 4x4x4 blocks (k = 2), opaque leaves facing +z.
        let mut leaves = Vec::new();
        for y in 0..4 {
            for x in 0..8 {
                leaves.push(Leaf { cell: UVec3::new(x, y, 2), opacity: 1.0, normal: Vec3::Z, albedo: 188 });
            }
        }
        let coarse = coarse_level(&svo(leaves), 3, 2, 0.1);
        assert_eq!(coarse.leaves.len(), 2);
        // The coarse SVO is a valid SVO of depth 1: root and two leaves.
        assert_eq!(coarse.nodes.len(), 3);
        assert!(coarse.nodes[1..].iter().enumerate().all(|(i, n)| n.level == 1 && n.first_child == i as u32));
        for l in &coarse.leaves {
            assert!((l.opacity - 1.0).abs() < 1e-6, "seen across, a wall is opaque");
            assert!((l.centroid_tile_m[2] - 0.25).abs() < 1e-6, "centroid on the wall plane: {l:?}");
            assert!((l.ndf.mean[2] - 1.0).abs() < 1e-6);
            assert_eq!(l.albedo.0[0], 188, "mean of equal albedos, through linear light and back");
            assert_eq!(l.ndf.weight, 16.0);
        }
    }

    #[test]
    fn half_covered_blocks_and_empty_leaves_keep_their_share() {
        // One 2x2x2 block (k = 1): two of its four columns along z hold a half-opaque leaf, and an
        // empty leaf with no normal.
        let leaves = vec![
            Leaf { cell: UVec3::new(0, 0, 0), opacity: 0.5, normal: Vec3::Z, albedo: 50 },
            Leaf { cell: UVec3::new(1, 0, 0), opacity: 0.5, normal: Vec3::Z, albedo: 150 },
            Leaf { cell: UVec3::new(1, 1, 1), opacity: 0.0, normal: Vec3::ZERO, albedo: 250 },
        ];
        let coarse = coarse_level(&svo(leaves), 3, 1, 0.1);
        assert_eq!(coarse.leaves.len(), 1);
        let l = coarse.leaves[0];
        // Along z: columns (0,0) and (1,0) at 0.5, the others 0 -> 0.25.
        assert!((l.opacity - 0.25).abs() < 1e-6, "{}", l.opacity);
        let mean = (srgb8_to_linear(50) + srgb8_to_linear(150)) / 2.0;
        assert_eq!(l.albedo.0[0], linear_to_srgb8(mean), "coverage-weighted albedo in linear light");
        // A block of nothing but empty leaves covers nothing.
        let empty = coarse_level(
            &svo(vec![Leaf { cell: UVec3::new(5, 5, 5), opacity: 0.0, normal: Vec3::ZERO, albedo: 9 }]),
            3,
            1,
            0.1,
        );
        assert_eq!(empty.leaves[0].opacity, 0.0);
        assert_eq!(empty.leaves[0].albedo.0[..3], [0, 0, 0]);
    }
}
