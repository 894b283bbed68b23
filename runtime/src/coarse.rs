//! A tile's coarse level: its SVO cut `k` levels above the leaves, whose nodes there become leaves
//! 2^k package leaves wide, and one oriented splat per such leaf to draw it. What stays resident
//! of a tile that is not (residency.rs): cones that leave the resident tiles still meet walls and
//! the light on them instead of empty space (black holes) or open sky (leaks), and a distant tile
//! is still drawn, from 1/4^k of the surfels.
//!
//! A coarse leaf stands for the leaves under it as the mip pass would see them, reduced to the one
//! opacity a leaf holds: per axis, the leaves' coverage composited along each column of the block
//! (`1 - prod(1 - a)`) and averaged over the columns (mip.wgsl's rule for inner nodes), then the
//! three axes weighted by the squared components of the mean normal (a wall is seen across it).
//! Albedo, normal distribution and emission are the coverage-weighted means of the leaves'
//! (Toksvig's mean normal shortens where the leaves disagree); the leaf's centre is their
//! coverage-weighted centroid, so a coarse wall stays where the wall is, not at a block's centre.

use glam::{UVec3, Vec3};
use grotto_format::color::linear_to_srgb8;
use grotto_format::svo::morton_decode;

use crate::gpu_types::{LeafGpu, SurfelGpu};

/// Levels a coarse tile is cut above its leaves: leaves 8 package leaves wide (0.5 m at 6.25 cm
/// leaves), about 1/64 of the leaves of a surface and 1/64 of its surfels.
pub const COARSE_LEVELS: u32 = 3;

/// A tile at its coarse level.
#[derive(Clone, Debug, Default, PartialEq)]
pub struct CoarseTile {
    /// One per node `k` levels above the leaves, in the order of those nodes (Morton order).
    pub leaves: Vec<LeafGpu>,
    /// One disc per coarse leaf that covers anything.
    pub splats: Vec<SurfelGpu>,
}

/// The coarse level `k` (>= 1) of a tile's leaves: `leaves[i]` has Morton code `codes[i]` in
/// the tile (ascending, as the spec stores them); `leaf_m` is the package's leaf edge.
pub fn coarse_tile(leaves: &[LeafGpu], codes: &[u64], k: u32, leaf_m: f32) -> CoarseTile {
    let side = 1usize << k;
    let edge_m = leaf_m * side as f32;
    let mut out = CoarseTile::default();
    let mut start = 0;
    // Transmittance of each column along x, y and z (indexed by the other two coordinates).
    let mut columns = vec![[1.0f32; 3]; side * side];
    while start < leaves.len() {
        let block = codes[start] >> (3 * k);
        let end = start + codes[start..].iter().take_while(|&&c| c >> (3 * k) == block).count();
        columns.iter_mut().for_each(|c| *c = [1.0; 3]);
        let (mut weight, mut centroid, mut albedo, mut normal, mut emission) =
            (0.0f32, Vec3::ZERO, Vec3::ZERO, Vec3::ZERO, Vec3::ZERO);
        let mut plain_centre = Vec3::ZERO;
        for (l, &code) in leaves[start..end].iter().zip(&codes[start..end]) {
            let local = UVec3::from_array(morton_decode(code)) & UVec3::splat(side as u32 - 1);
            let (x, y, z) = (local.x as usize, local.y as usize, local.z as usize);
            let a = l.albedo_opacity[3].clamp(0.0, 1.0);
            columns[y + side * z][0] *= 1.0 - a;
            columns[x + side * z][1] *= 1.0 - a;
            columns[x + side * y][2] *= 1.0 - a;
            let c = Vec3::from_slice(&l.center_m[..3]);
            plain_centre += c;
            weight += a;
            centroid += a * c;
            albedo += a * Vec3::from_slice(&l.albedo_opacity[..3]);
            normal += a * Vec3::from_slice(&l.normal_mean[..3]);
            emission += a * Vec3::from_slice(&l.emission[..3]);
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
        let opacity = per_axis.dot(axis_weight).clamp(0.0, 1.0);
        out.leaves.push(LeafGpu {
            albedo_opacity: albedo.extend(opacity).to_array(),
            normal_mean: normal.extend(0.0).to_array(),
            center_m: centre.extend(edge_m).to_array(),
            emission: emission.extend(0.0).to_array(),
        });
        if opacity > 0.0 {
            let srgb = albedo.to_array().map(linear_to_srgb8);
            // The block's inscribed disc, scaled by the coverage's square root: the splat pass
            // grows every disc by its splat scale (2 by default) so neighbours overlap, as it
            // does for the package's surfels.
            let radius = 0.5 * edge_m * opacity.sqrt();
            out.splats.push(SurfelGpu {
                position_radius: centre.extend(radius).to_array(),
                normal_spread: normal.normalize_or(Vec3::Z).extend(1.0 - normal.length().min(1.0)).to_array(),
                color: [srgb[0], srgb[1], srgb[2], 0],
            });
        }
        start = end;
    }
    out
}

#[cfg(test)]
mod tests {
    use super::*;
    use grotto_format::svo::morton_encode;

    fn leaf(cell: UVec3, opacity: f32, normal: Vec3, albedo: f32) -> LeafGpu {
        LeafGpu {
            albedo_opacity: [albedo, albedo, albedo, opacity],
            normal_mean: normal.extend(0.0).to_array(),
            center_m: ((cell.as_vec3() + Vec3::splat(0.5)) * 0.1).extend(0.0).to_array(),
            emission: [0.0; 4],
        }
    }

    fn sorted(mut cells: Vec<(u64, LeafGpu)>) -> (Vec<LeafGpu>, Vec<u64>) {
        cells.sort_by_key(|c| c.0);
        (cells.iter().map(|c| c.1).collect(), cells.iter().map(|c| c.0).collect())
    }

    #[test]
    fn a_wall_stays_an_opaque_wall_where_it_was() {
        // A full wall z = 2 across two 4x4x4 blocks (k = 2), opaque leaves facing +z.
        let mut cells = Vec::new();
        for y in 0..4 {
            for x in 0..8 {
                let c = UVec3::new(x, y, 2);
                cells.push((morton_encode(c.x, c.y, c.z), leaf(c, 1.0, Vec3::Z, 0.5)));
            }
        }
        let (leaves, codes) = sorted(cells);
        let coarse = coarse_tile(&leaves, &codes, 2, 0.1);
        assert_eq!(coarse.leaves.len(), 2);
        assert_eq!(coarse.splats.len(), 2);
        for l in &coarse.leaves {
            assert!((l.albedo_opacity[3] - 1.0).abs() < 1e-6, "seen across, a wall is opaque");
            assert!((l.center_m[2] - 0.25).abs() < 1e-6, "centroid on the wall plane: {:?}", l.center_m);
            assert!((l.center_m[3] - 0.4).abs() < 1e-6);
            assert!((l.normal_mean[2] - 1.0).abs() < 1e-6);
            assert!((l.albedo_opacity[0] - 0.5).abs() < 1e-6);
        }
    }

    #[test]
    fn half_covered_blocks_and_empty_leaves_keep_their_share() {
        // One 2x2x2 block (k = 1): two of its four columns along z hold a half-opaque leaf, and an
        // empty leaf with no normal.
        let cells = vec![
            (morton_encode(0, 0, 0), leaf(UVec3::new(0, 0, 0), 0.5, Vec3::Z, 0.2)),
            (morton_encode(1, 0, 0), leaf(UVec3::new(1, 0, 0), 0.5, Vec3::Z, 0.6)),
            (morton_encode(1, 1, 1), leaf(UVec3::new(1, 1, 1), 0.0, Vec3::ZERO, 0.9)),
        ];
        let (leaves, codes) = sorted(cells);
        let coarse = coarse_tile(&leaves, &codes, 1, 0.1);
        assert_eq!(coarse.leaves.len(), 1);
        let l = coarse.leaves[0];
        // Along z: columns (0,0) and (1,0) at 0.5, the others 0 -> 0.25.
        assert!((l.albedo_opacity[3] - 0.25).abs() < 1e-6, "{}", l.albedo_opacity[3]);
        assert!((l.albedo_opacity[0] - 0.4).abs() < 1e-6, "coverage-weighted albedo");
        // A block of nothing but empty leaves covers nothing and draws no splat.
        let empty = coarse_tile(&[leaves[2]], &[codes[2]], 1, 0.1);
        assert_eq!(empty.leaves[0].albedo_opacity[3], 0.0);
        assert!(empty.splats.is_empty());
    }
}
