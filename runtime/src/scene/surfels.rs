//! A tile's surfels as the GPU holds them, made from the package's: the frame's position, the
//! colour, the scan and the specular material slot of each. A change of tiles may leave a full
//! tile's surfels in the package ([`SurfelsInPackage`]) and have the renderer decode them into
//! its pools a piece at a time (`SceneData::surfels_from_package`, load.rs): a tile of two million
//! points is then never held decoded on the CPU, where it was the largest thing a viewer held
//! while its tiles changed.

use std::borrow::Cow;

use glam::DVec3;
use grotto_format::SectionKind;
use grotto_format::spec::{Bc1Block, Rgba8, Surfel};

use crate::gpu::types::{NO_SCAN, SurfelGpu};
use crate::scene::summary::MAX_MATERIALS;

/// Surfels a piece of `SceneData::surfels_from_package` holds at most: an upload's piece of them
/// (gpu/upload.rs), a whole number of the renderer's surfel chunks (render/chunks.rs). Each piece
/// is held twice while it is written (decoded here, and as the upload's staging copy).
pub(crate) const PIECE_SURFELS: usize = 200 * 1024;
const _: () = assert!(PIECE_SURFELS * size_of::<SurfelGpu>() <= crate::gpu::upload::UPLOAD_PIECE_BYTES);

/// A specular material's region in the frame, with the least normal z a surfel in it needs.
#[derive(Clone, Debug, PartialEq)]
pub struct MaterialRegion {
    lo_m: DVec3,
    hi_m: DVec3,
    min_normal_z: f32,
}

/// What a scene knows of a full tile whose surfels it left in the package: which tile, how many
/// surfels it has, and how many of them each specular material takes (counted as the load read
/// them once to place the tile's leaves).
#[derive(Clone, Debug, Default, PartialEq)]
pub struct SurfelsInPackage {
    pub(crate) tile: u32,
    pub(crate) surfels: u32,
    pub(crate) material_surfels: [u32; MAX_MATERIALS],
}

impl MaterialRegion {
    /// A package material's region in the frame whose origin is `frame_origin_m`.
    pub(crate) fn in_frame(region: &grotto_format::MaterialRegion, frame_origin_m: [f64; 3]) -> Self {
        let frame = DVec3::from_array(frame_origin_m);
        Self {
            lo_m: DVec3::from_array(region.min_m) - frame,
            hi_m: DVec3::from_array(region.max_m) - frame,
            min_normal_z: region.min_normal_z,
        }
    }
}

/// The material slot (1..=7; 0 diffuse) of a surfel in the frame: the last region holding it.
pub(crate) fn material_slot(regions: &[MaterialRegion], s: &SurfelGpu) -> u8 {
    let p = glam::Vec3::from_slice(&s.position_radius[..3]).as_dvec3();
    let facing = s.normal_spread[2];
    regions
        .iter()
        .rposition(|r| p.cmpge(r.lo_m).all() && p.cmple(r.hi_m).all() && facing >= r.min_normal_z)
        .map_or(0, |k| k as u8 + 1)
}

/// Each of a tile's `surfels` surfels' scan index (format 1.2: the tile's surfel-scans section),
/// as stored; `None` where the package has none (every surfel then stands for no one scan). A
/// section of another length, or an index past the scene's `scans`, is a damaged package.
pub(crate) fn scan_indices<'a>(
    tile: &grotto_format::Tile<'a>,
    surfels: usize,
    scans: usize,
) -> Result<Option<Cow<'a, [u16]>>, String> {
    let Some(stored) = tile.read::<u16>(SectionKind::SurfelScans).map_err(|e| e.to_string())? else {
        return Ok(None);
    };
    if stored.len() != surfels {
        return Err(format!(
            "tile {} has {} surfel scan indices for {surfels} surfels",
            tile.index(),
            stored.len()
        ));
    }
    if let Some(bad) = stored.iter().find(|&&s| usize::from(s) >= scans) {
        return Err(format!("tile {} names scan {bad}, but the scene lists {scans} scans", tile.index()));
    }
    Ok(Some(stored))
}

/// Surfel `k`'s scan index for the GPU ([`NO_SCAN`] without the section).
pub(crate) fn scan_of(stored: Option<&[u16]>, k: usize) -> u32 {
    stored.and_then(|s| s.get(k)).map_or(NO_SCAN, |&s| u32::from(s))
}

/// A tile's surfel colours as the package stores them, decoded a run at a time: a tile's
/// colours are never decoded whole where its surfels are written in pieces.
pub(crate) enum SurfelColors<'a> {
    Bc1(Cow<'a, [Bc1Block]>),
    Raw(Cow<'a, [Rgba8]>),
    /// The package has none: grey.
    Grey,
}

impl<'a> SurfelColors<'a> {
    pub(crate) fn of(tile: &grotto_format::Tile<'a>) -> grotto_format::Result<Self> {
        if let Some(bc1) = tile.read::<Bc1Block>(SectionKind::SurfelColorsBc1)? {
            return Ok(Self::Bc1(bc1));
        }
        Ok(tile.read::<Rgba8>(SectionKind::SurfelColorsRaw)?.map_or(Self::Grey, Self::Raw))
    }

    /// The sRGB colours of surfels `first..first + n` (fewer where the section ends first).
    pub(crate) fn run(&self, first: usize, n: usize) -> Vec<[u8; 3]> {
        match self {
            Self::Bc1(blocks) => {
                let (b0, skip) = (first / 16, first % 16);
                let b1 = (first + n).div_ceil(16).min(blocks.len());
                let mut c = grotto_format::color::decode_bc1(blocks.get(b0..b1).unwrap_or(&[]), skip + n);
                c.drain(..skip.min(c.len()));
                c
            }
            Self::Raw(raw) => raw.iter().skip(first).take(n).map(|c| [c.0[0], c.0[1], c.0[2]]).collect(),
            Self::Grey => vec![[180; 3]; n],
        }
    }
}

/// A package surfel in the frame (`shift_m`: its tile's corner from the frame origin), through
/// f64 so a survey's large coordinates lose nothing; its colour, scan and slot come later.
pub(crate) fn frame_surfel(s: &Surfel, shift_m: DVec3) -> SurfelGpu {
    let p = (DVec3::from_array(s.position_tile_m.map(f64::from)) + shift_m).as_vec3();
    SurfelGpu {
        position_radius: p.extend(s.radius_m).to_array(),
        normal_spread: [s.normal[0], s.normal[1], s.normal[2], s.spread],
        color: [0; 4],
        scan: 0,
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn the_last_region_holding_a_surfel_gives_its_slot() {
        let region = |lo: f64, hi: f64, min_normal_z: f32| MaterialRegion {
            lo_m: DVec3::splat(lo),
            hi_m: DVec3::splat(hi),
            min_normal_z,
        };
        let regions = [region(0.0, 10.0, -1.0), region(4.0, 6.0, 0.5)];
        let at = |p: f32, nz: f32| SurfelGpu {
            position_radius: [p, p, p, 0.1],
            normal_spread: [0.0, 0.0, nz, 0.0],
            ..Default::default()
        };
        assert_eq!(material_slot(&regions, &at(1.0, 0.0)), 1);
        assert_eq!(material_slot(&regions, &at(5.0, 1.0)), 2, "the later region wins");
        assert_eq!(material_slot(&regions, &at(5.0, 0.0)), 1, "too steep for the pool");
        assert_eq!(material_slot(&regions, &at(11.0, 1.0)), 0);
        assert_eq!(material_slot(&regions, &at(f32::NAN, 1.0)), 0);
    }
}
