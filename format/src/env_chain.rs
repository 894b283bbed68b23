//! The prefiltered environment chain (`env-mip-levels` + `env-mip-bc6h`): the rules its level
//! table must follow (docs/format.md, "EnvMipLevel") and the checked view of both sections that
//! `Package::env_chain` (reader.rs) hands out.
//!
//! The rules bound what a reader allocates to decode the chain: at most
//! [`MAX_ENV_MIP_LEVELS`] levels no larger than [`MAX_ENV_MIP_WIDTH`] x [`MAX_ENV_MIP_HEIGHT`],
//! never growing from one level to the next, stacked in an atlas at most [`MAX_ENV_ATLAS_RATIO`]
//! times the texels they hold. A table claiming an 8192-wide base and seven 4x4096 levels (147
//! KiB of blocks, a 3.8 GB atlas) is refused here, so `verify` reports it and no tool sizes
//! anything from it.

use std::borrow::Cow;

use crate::spec::{
    Bc6hBlock, EnvMipLevel, MAX_ENV_ATLAS_RATIO, MAX_ENV_MIP_HEIGHT, MAX_ENV_MIP_LEVELS, MAX_ENV_MIP_WIDTH,
};

/// A checked environment chain: levels that follow the rules and blocks that are exactly theirs.
#[derive(Clone, Debug)]
pub struct EnvChain<'a> {
    pub levels: Cow<'a, [EnvMipLevel]>,
    pub blocks: Cow<'a, [Bc6hBlock]>,
}

impl EnvChain<'_> {
    /// Width of the atlas the levels stack into (level 0's width).
    pub fn atlas_width(&self) -> u32 {
        self.levels.first().map_or(0, |l| l.width)
    }

    /// Height of that atlas: the levels' heights added.
    pub fn atlas_height(&self) -> u32 {
        // At most 8 levels of at most 4096 rows: cannot overflow.
        self.levels.iter().map(|l| l.height).sum()
    }

    /// Each level's first row in the atlas.
    pub fn level_rows(&self) -> impl Iterator<Item = u32> + '_ {
        self.levels.iter().scan(0u32, |row, l| {
            let first = *row;
            *row += l.height;
            Some(first)
        })
    }
}

/// The level table for consecutive levels of these (width, height, roughness): each level's
/// block count and first block as the rules require (what a writer stores).
pub fn level_table(dims: impl IntoIterator<Item = (u32, u32, f32)>) -> Vec<EnvMipLevel> {
    let mut first_block = 0;
    dims.into_iter()
        .map(|(width, height, roughness)| {
            let block_count = width.div_ceil(4) * height.div_ceil(4);
            let level = EnvMipLevel { width, height, first_block, block_count, roughness, reserved: [0; 3] };
            first_block += block_count;
            level
        })
        .collect()
}

/// The level table's own rules (checked when the section is first read).
pub(crate) fn check_levels(levels: &[EnvMipLevel]) -> Result<(), String> {
    if levels.len() > MAX_ENV_MIP_LEVELS {
        return Err(format!("{} levels, at most {MAX_ENV_MIP_LEVELS}", levels.len()));
    }
    let mut next_block = 0u64;
    let mut level_texels = 0u64;
    let mut prev: Option<&EnvMipLevel> = None;
    for (i, l) in levels.iter().enumerate() {
        let blocks = u64::from(l.width.div_ceil(4)) * u64::from(l.height.div_ceil(4));
        if l.width == 0 || l.height == 0 || blocks != u64::from(l.block_count) {
            return Err(format!("level {i} is {}x{} with {} blocks", l.width, l.height, l.block_count));
        }
        if l.width > MAX_ENV_MIP_WIDTH || l.height > MAX_ENV_MIP_HEIGHT {
            return Err(format!(
                "level {i} is {}x{}, larger than {MAX_ENV_MIP_WIDTH}x{MAX_ENV_MIP_HEIGHT}",
                l.width, l.height
            ));
        }
        if u64::from(l.first_block) != next_block {
            return Err(format!("level {i} starts at block {}, expected {next_block}", l.first_block));
        }
        if !(l.roughness.is_finite() && (0.0..=1.0).contains(&l.roughness)) {
            return Err(format!("level {i} has roughness {}, outside 0..=1", l.roughness));
        }
        if let Some(p) = prev {
            if l.width > p.width || l.height > p.height {
                return Err(format!(
                    "level {i} ({}x{}) is larger than level {} ({}x{})",
                    l.width,
                    l.height,
                    i - 1,
                    p.width,
                    p.height
                ));
            }
            if l.roughness < p.roughness {
                return Err(format!("level {i}'s roughness {} is below level {}'s", l.roughness, i - 1));
            }
        }
        next_block += blocks;
        level_texels += u64::from(l.width) * u64::from(l.height);
        prev = Some(l);
    }
    let width = levels.first().map_or(0, |l| u64::from(l.width));
    let atlas = width * levels.iter().map(|l| u64::from(l.height)).sum::<u64>();
    if atlas > MAX_ENV_ATLAS_RATIO * level_texels {
        return Err(format!(
            "the levels stack into a {atlas}-texel atlas for {level_texels} texels (at most {MAX_ENV_ATLAS_RATIO}x)"
        ));
    }
    Ok(())
}
