//! A tile's stored levels and the grid the tiles share: what the packer stores with each tile
//! ([`TileLevels`]), worked out over all tiles at once so the rock sees across borders.

use glam::{IVec3, Vec3};
use grotto_format::spec::{LeafNdf, RockBrick, SvoNode};
use grotto_format::svo::morton_decode;
use grotto_format::{Result, SectionKind, Tile};

use crate::coarse::{CoarseLevel, STORED_LEVELS, coarse_level};
use crate::rock::{CONTEXT_CELLS, ROCK_LEVEL, SurfaceLeaf, in_context, tile_rock};

/// What the packer stores with a tile besides its own data.
#[derive(Clone, Debug, Default, PartialEq)]
pub struct TileLevels {
    /// The levels of [`STORED_LEVELS`] (each at most the tile's depth; one where they meet),
    /// finest first; none for a tile without an SVO.
    pub coarse: Vec<(u32, CoarseLevel)>,
    /// The tile's rock; `None` where it cannot be stored per tile (a tile off the shared leaf
    /// grid or the bricks' grid), so a reader classifies it itself.
    pub rock: Option<Vec<RockBrick>>,
}

/// Where tiles sit on one leaf grid: each tile's origin in leaves from the first tile's origin
/// (`None` off the grid, or with another leaf size) and its side in leaves.
#[derive(Clone, Debug, PartialEq)]
pub struct TileGrid {
    pub(crate) origin_leaf: Vec<Option<IVec3>>,
    pub(crate) side_leaves: Vec<i64>,
}

impl TileGrid {
    /// Where `tiles` sit on the first tile's leaf grid.
    pub fn of(tiles: &[Tile<'_>]) -> Self {
        let first = tiles.first().map(|t| (t.origin_m(), t.leaf_size_m()));
        let origin_leaf = tiles
            .iter()
            .map(|t| {
                let (o0, ls0) = first?;
                let same_leaf = (t.leaf_size_m() - ls0).abs() <= ls0 * 1e-9;
                same_leaf.then(|| origin_leaf(t.origin_m(), o0, ls0)).flatten()
            })
            .collect();
        Self { origin_leaf, side_leaves: tiles.iter().map(|t| 1i64 << t.depth()).collect() }
    }
}

/// A tile corner `origin_m` in leaves of `leaf_m` from `frame_origin_m` (world metres), where it
/// lies on that leaf grid (within 1/1000 of a leaf) and within 2^28 leaves of the frame origin.
pub fn origin_leaf(origin_m: [f64; 3], frame_origin_m: [f64; 3], leaf_m: f64) -> Option<IVec3> {
    let mut out = [0i32; 3];
    for a in 0..3 {
        let v = (origin_m[a] - frame_origin_m[a]) / leaf_m;
        let r = v.round();
        if !((v - r).abs() <= 1e-3 && r.abs() <= f64::from(1 << 28)) {
            return None;
        }
        out[a] = r as i32;
    }
    Some(IVec3::from_array(out))
}

/// The surface leaves of `tile` (frame leaf units, origin `origin_leaf`) that `keep` accepts.
/// Reads only the node array and the NDFs (raw sections in the packer's output, so a tile read
/// as the context of each of its neighbours is mapped, not decoded, each time).
fn surface(tile: &Tile<'_>, origin_leaf: IVec3, keep: impl Fn(Vec3) -> bool) -> Result<Vec<SurfaceLeaf>> {
    let (Some(nodes), Some(ndf)) =
        (tile.read::<SvoNode>(SectionKind::SvoNodes)?, tile.read::<LeafNdf>(SectionKind::LeafNdf)?)
    else {
        return Ok(Vec::new());
    };
    let depth = tile.depth();
    let origin = origin_leaf.as_vec3() + Vec3::splat(0.5);
    Ok(nodes
        .iter()
        .filter(|n| u32::from(n.level) == depth)
        .zip(ndf.iter())
        .map(|(n, ndf)| SurfaceLeaf {
            center_leaf: origin + glam::UVec3::from_array(morton_decode(n.morton)).as_vec3(),
            normal_mean: Vec3::from_array(ndf.mean),
        })
        .filter(|l| keep(l.center_leaf))
        .collect())
}

/// The coarse level and the rock of tile `t` of `tiles` (every tile of one package, so the
/// rock near a border sees the neighbour's walls).
pub fn tile_levels(tiles: &[Tile<'_>], grid: &TileGrid, t: usize) -> Result<TileLevels> {
    let tile = &tiles[t];
    let Some(svo) = tile.svo()? else { return Ok(TileLevels::default()) };
    let depth = tile.depth();
    let mut levels: Vec<u32> = STORED_LEVELS.iter().map(|&k| k.min(depth)).filter(|&k| k > 0).collect();
    levels.dedup();
    let coarse = levels.into_iter().map(|k| (k, coarse_level(&svo, depth, k, tile.leaf_size_m()))).collect();
    let brick = i64::from(grotto_format::spec::ROCK_BRICK_LEAVES);
    let side = grid.side_leaves[t];
    let rock = match grid.origin_leaf[t] {
        Some(o)
            if o.to_array().iter().all(|&c| i64::from(c) % brick == 0)
                && side % brick == 0
                && side < 1 << 28 =>
        {
            let side = side as i32;
            let mut context = surface(tile, o, |_| true)?;
            let reach = i64::from(CONTEXT_CELLS << ROCK_LEVEL);
            for (u, other) in tiles.iter().enumerate() {
                let Some(ou) = grid.origin_leaf[u] else { continue };
                // Cubes within the context margin of each other on every axis.
                let near = (0..3).all(|a| {
                    let (lo, hi) = (i64::from(o[a]) - reach, i64::from(o[a]) + i64::from(side) + reach);
                    i64::from(ou[a]) < hi && i64::from(ou[a]) + grid.side_leaves[u] > lo
                });
                if u != t && near {
                    context.extend(surface(other, ou, |p| in_context(o, side, p))?);
                }
            }
            Some(tile_rock(o, side, &context))
        }
        _ => None,
    };
    Ok(TileLevels { coarse, rock })
}
