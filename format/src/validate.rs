//! Structural and content validation of a package: the header, section table and tile directory
//! with checked arithmetic (once, at open), and each section's checksum, decoding and content
//! (once, on first read).

use std::borrow::Cow;
use std::ops::Range;

use bytemuck::Pod;
use xxhash_rust::xxh3::Xxh3;

use crate::error::{Problem, Region};
use crate::scene::{Provenance, Scene};
use crate::section::SectionInfo;
use crate::spec::*;

/// Largest header a reader accepts; bounds the work a lying `header_size` can cause.
pub(crate) const MAX_HEADER_SIZE: u32 = 4096;
/// Offset of `header_checksum` inside the header.
const HEADER_CHECKSUM_OFFSET: usize = 64;

/// A section's stored bytes decoded.
pub(crate) fn decode<'a>(s: &SectionInfo, stored: &'a [u8]) -> Result<Cow<'a, [u8]>, Problem> {
    match s.codec {
        Some(Codec::Raw) | None => Ok(Cow::Borrowed(stored)),
        Some(Codec::Zstd) => {
            use std::io::Read;
            let fail =
                |message: String| Problem::Decompress { section: s.index, kind: s.kind_name(), message };
            // The table's length is a claim: reserve only what typical ratios justify and let the
            // buffer grow with bytes that really decode, so a lie costs no memory.
            let hint = s.raw_len.min(s.stored_len.saturating_mul(64)) as usize;
            let mut out = Vec::with_capacity(hint);
            #[cfg(not(target_arch = "wasm32"))]
            let decoder =
                zstd::stream::read::Decoder::with_buffer(stored).map_err(|e| fail(e.to_string()))?;
            #[cfg(target_arch = "wasm32")]
            let decoder = ruzstd::decoding::StreamingDecoder::new(stored).map_err(|e| fail(e.to_string()))?;
            decoder.take(s.raw_len + 1).read_to_end(&mut out).map_err(|e| fail(e.to_string()))?;
            if out.len() as u64 != s.raw_len {
                return Err(fail(format!("decoded {} bytes, table says {}", out.len(), s.raw_len)));
            }
            Ok(Cow::Owned(out))
        }
    }
}

/// The section table and tile directory, checked.
pub(crate) type Tables = (Box<[RawSectionEntry]>, Box<[RawTileEntry]>);

/// Structural validation (the header, table and directory, nothing else) of a `file_len`-byte
/// package from its first bytes (`head`) and a piece of it (`directory`, at `directory_offset`)
/// that covers the table and directory. A whole file is all three.
pub(crate) fn check_structure(
    head: &[u8],
    file_len: u64,
    directory_offset: u64,
    directory: &[u8],
) -> Result<(RawHeader, Tables), Problem> {
    let header = check_header(head, file_len)?;
    let (table, tiles) = table_ranges(&header, file_len)?;
    let part = |r: &Range<u64>, region| {
        let start = r.start.checked_sub(directory_offset);
        let end = r.end.checked_sub(directory_offset);
        match (start, end) {
            (Some(s), Some(e)) if e <= directory.len() as u64 => Ok(&directory[s as usize..e as usize]),
            _ => Err(Problem::OutOfBounds {
                region,
                offset: r.start,
                len: r.end - r.start,
                file_len: directory_offset + directory.len() as u64,
            }),
        }
    };
    let table_bytes = part(&table, Region::SectionTable)?;
    let tile_bytes = part(&tiles, Region::TileDirectory)?;
    let tables = check_tables(&header, (table, table_bytes), (tiles, tile_bytes), file_len)?;
    Ok((header, tables))
}

/// The header of a file of `file_len` bytes, from its first bytes (`bytes`: at least the header's
/// own size, or the whole file where it is shorter).
pub(crate) fn check_header(bytes: &[u8], file_len: u64) -> Result<RawHeader, Problem> {
    let header_len = size_of::<RawHeader>();
    if file_len < header_len as u64 || bytes.len() < header_len {
        return Err(Problem::TooShort { len: file_len, needed: header_len as u64 });
    }
    let header: RawHeader = bytemuck::pod_read_unaligned(&bytes[..header_len]);
    if header.magic != MAGIC {
        return Err(Problem::BadMagic { found: header.magic });
    }
    // Before anything else: a different major may lay the header out differently.
    if !(OLDEST_MAJOR..=VERSION_MAJOR).contains(&header.version_major) {
        return Err(Problem::UnsupportedVersion {
            found_major: header.version_major,
            found_minor: header.version_minor,
            supported_major: VERSION_MAJOR,
            supported_minor: VERSION_MINOR,
        });
    }
    let hs = header.header_size;
    if hs < header_len as u32 || hs > MAX_HEADER_SIZE || u64::from(hs) > file_len {
        return Err(Problem::BadHeaderSize { header_size: hs, minimum: header_len as u32, file_len });
    }
    if bytes.len() < hs as usize {
        return Err(Problem::TooShort { len: bytes.len() as u64, needed: u64::from(hs) });
    }
    let mut h = Xxh3::new();
    h.update(&bytes[..HEADER_CHECKSUM_OFFSET]);
    h.update(&[0u8; 8]);
    h.update(&bytes[HEADER_CHECKSUM_OFFSET + 8..hs as usize]);
    let computed = h.digest();
    if computed != header.header_checksum {
        return Err(Problem::HeaderChecksum { stored: header.header_checksum, computed });
    }
    if header.file_size != file_len {
        return Err(Problem::Truncated { expected: header.file_size, actual: file_len });
    }
    Ok(header)
}

/// Byte ranges of the section table and the tile directory, checked against the file.
pub(crate) fn table_ranges(header: &RawHeader, file_len: u64) -> Result<(Range<u64>, Range<u64>), Problem> {
    let table = array_range(
        Region::SectionTable,
        header.section_table_offset,
        header.section_count,
        size_of::<RawSectionEntry>(),
        file_len,
    )?;
    let tiles = array_range(
        Region::TileDirectory,
        header.tile_directory_offset,
        header.tile_count,
        size_of::<RawTileEntry>(),
        file_len,
    )?;
    // Counts fit u32 (tile and section references are u32); any real file is far below this.
    if header.section_count >= u64::from(u32::MAX) || header.tile_count >= u64::from(GLOBAL) {
        return Err(Problem::Overflow { what: "section or tile count".into() });
    }
    Ok((table, tiles))
}

/// Checks the section table and tile directory (each its range from [`table_ranges`] and its
/// bytes) against each other and the file, and copies them out.
pub(crate) fn check_tables(
    header: &RawHeader,
    (table, table_bytes): (Range<u64>, &[u8]),
    (tiles, tile_bytes): (Range<u64>, &[u8]),
    file_len: u64,
) -> Result<Tables, Problem> {
    let mut h = Xxh3::new();
    h.update(table_bytes);
    h.update(tile_bytes);
    let computed = h.digest();
    if computed != header.table_checksum {
        return Err(Problem::TableChecksum { stored: header.table_checksum, computed });
    }
    // Copied (the table is a small part of any file), so the bytes may come from anywhere.
    let sections: Vec<RawSectionEntry> = bytemuck::pod_collect_to_vec(table_bytes);
    let tile_entries: Vec<RawTileEntry> = bytemuck::pod_collect_to_vec(tile_bytes);
    let mut regions = vec![
        (0, u64::from(header.header_size), Region::Header),
        (table.start, table.end, Region::SectionTable),
        (tiles.start, tiles.end, Region::TileDirectory),
    ];
    for (i, e) in sections.iter().enumerate() {
        let s = SectionInfo::from_raw(i as u32, e);
        let region = Region::Section(s.index);
        let end = s
            .offset
            .checked_add(s.stored_len)
            .ok_or_else(|| Problem::Overflow { what: format!("{region} offset + length") })?;
        if end > file_len {
            return Err(Problem::OutOfBounds { region, offset: s.offset, len: s.stored_len, file_len });
        }
        if !s.offset.is_multiple_of(SECTION_ALIGN) {
            return Err(Problem::Misaligned { region, offset: s.offset, align: SECTION_ALIGN });
        }
        if let Scope::Tile(t) = s.scope
            && u64::from(t) >= header.tile_count
        {
            return Err(Problem::NoSuchTile { section: s.index, tile: t, tile_count: header.tile_count });
        }
        regions.push((s.offset, end, region));
        if let Some(kind) = s.kind {
            check_known_entry(&s, kind)?;
        }
    }

    // Overlaps: sort by start; empty regions overlap nothing.
    regions.retain(|r| r.1 > r.0);
    regions.sort_unstable_by_key(|r| (r.0, r.1));
    for w in regions.windows(2) {
        if w[1].0 < w[0].1 {
            return Err(Problem::Overlap { first: w[0].2, second: w[1].2 });
        }
    }

    // One section per (kind, scope, item) among known kinds.
    let mut keys: Vec<_> = sections
        .iter()
        .enumerate()
        .filter(|(_, e)| SectionKind::from_u32(e.kind).is_some())
        .map(|(i, e)| ((e.kind, e.tile, e.item), i as u32))
        .collect();
    keys.sort_unstable();
    for w in keys.windows(2) {
        if w[0].0 == w[1].0 {
            let s = SectionInfo::from_raw(w[1].1, &sections[w[1].1 as usize]);
            return Err(Problem::DuplicateSection {
                first: w[0].1,
                second: w[1].1,
                kind: s.kind_name(),
                scope: scope_name(s.scope),
                item: s.item,
            });
        }
    }

    for (t, tile) in tile_entries.iter().enumerate() {
        check_tile(t as u32, tile, &sections)?;
    }
    // Every per-tile section sits in its tile's run.
    for (i, e) in sections.iter().enumerate() {
        if e.tile != GLOBAL {
            let tile = &tile_entries[e.tile as usize];
            let run =
                u64::from(tile.section_first)..u64::from(tile.section_first) + u64::from(tile.section_count);
            if !run.contains(&(i as u64)) {
                return Err(Problem::SectionOutsideTileRun { section: i as u32, tile: e.tile });
            }
        }
    }
    Ok((sections.into_boxed_slice(), tile_entries.into_boxed_slice()))
}

pub(crate) fn scope_name(scope: Scope) -> String {
    match scope {
        Scope::Global => "the package".to_owned(),
        Scope::Tile(t) => format!("tile {t}"),
    }
}

/// Byte range of an array of `count` records of `size` bytes at `offset`, checked.
pub(crate) fn array_range(
    region: Region,
    offset: u64,
    count: u64,
    size: usize,
    file_len: u64,
) -> Result<Range<u64>, Problem> {
    let len = count
        .checked_mul(size as u64)
        .ok_or_else(|| Problem::Overflow { what: format!("{region} length ({count} entries)") })?;
    let end = offset.checked_add(len).ok_or_else(|| Problem::Overflow { what: format!("{region} end") })?;
    if end > file_len {
        return Err(Problem::OutOfBounds { region, offset, len, file_len });
    }
    if !offset.is_multiple_of(8) {
        return Err(Problem::Misaligned { region, offset, align: 8 });
    }
    Ok(offset..end)
}

pub(crate) fn check_known_entry(s: &SectionInfo, kind: SectionKind) -> Result<(), Problem> {
    let name = || kind.name().to_owned();
    let codec =
        s.codec.ok_or_else(|| Problem::UnknownCodec { section: s.index, kind: name(), codec: s.kind_raw })?;
    match codec {
        Codec::Raw if s.stored_len != s.raw_len => {
            return Err(Problem::RawLengthMismatch {
                section: s.index,
                kind: name(),
                stored: s.stored_len,
                raw: s.raw_len,
            });
        }
        Codec::Zstd => {
            let limit = s.stored_len.saturating_mul(MAX_ZSTD_RATIO).saturating_add(1 << 16);
            if s.raw_len > limit {
                return Err(Problem::ImplausibleLength {
                    section: s.index,
                    kind: name(),
                    stored: s.stored_len,
                    raw: s.raw_len,
                });
            }
        }
        Codec::Raw => {}
    }
    let element_size = kind.element().size();
    if !s.raw_len.is_multiple_of(element_size as u64) {
        return Err(Problem::BadElementLength {
            section: s.index,
            kind: name(),
            len: s.raw_len,
            element_size,
        });
    }
    match (kind.is_per_tile(), s.scope) {
        (true, Scope::Global) => Err(Problem::WrongScope {
            section: s.index,
            kind: name(),
            found: scope_name(s.scope),
            expected: "a tile",
        }),
        (false, Scope::Tile(_)) => Err(Problem::WrongScope {
            section: s.index,
            kind: name(),
            found: scope_name(s.scope),
            expected: "the package",
        }),
        _ => Ok(()),
    }
}

pub(crate) fn check_tile(t: u32, tile: &RawTileEntry, sections: &[RawSectionEntry]) -> Result<(), Problem> {
    let bad = |reason: String| Problem::BadTile { tile: t, reason };
    if !tile.origin_m.iter().all(|v| v.is_finite()) {
        return Err(bad(format!("origin {:?} is not finite", tile.origin_m)));
    }
    if !(tile.extent_m.is_finite() && tile.extent_m > 0.0) {
        return Err(bad(format!("extent {} m is not a positive number", tile.extent_m)));
    }
    if tile.depth > MAX_SVO_DEPTH {
        return Err(bad(format!("SVO depth {} exceeds {MAX_SVO_DEPTH}", tile.depth)));
    }
    let end = u64::from(tile.section_first) + u64::from(tile.section_count);
    if end > sections.len() as u64 {
        return Err(bad(format!(
            "section run {}..{end} exceeds the {}-entry table",
            tile.section_first,
            sections.len()
        )));
    }
    for i in tile.section_first..end as u32 {
        if sections[i as usize].tile != t {
            return Err(bad(format!("section {i} in its run belongs to another scope")));
        }
    }
    let run = &sections[tile.section_first as usize..end as usize];
    let holds = |kind: SectionKind| run.iter().any(|s| s.kind == kind as u32);
    if holds(SectionKind::Surfels) && holds(SectionKind::SurfelsCompact) {
        return Err(bad("holds both surfels and surfels-compact".into()));
    }
    Ok(())
}

/// Checks that decoded section content is usable without further checks (no NaN, in-range
/// indices), so the runtime can upload it as is.
pub(crate) fn check_content(kind: SectionKind, data: &[u8], depth: u32) -> Result<(), String> {
    fn finite(v: &[f32], what: &str, i: usize) -> Result<(), String> {
        if v.iter().all(|x| x.is_finite()) { Ok(()) } else { Err(format!("{what} {i} is not finite: {v:?}")) }
    }
    fn cast<T: Pod>(data: &[u8]) -> Cow<'_, [T]> {
        // In place when aligned (always for raw sections); a copy only for unaligned decoder output.
        bytemuck::try_cast_slice(data)
            .map_or_else(|_| Cow::Owned(bytemuck::pod_collect_to_vec(data)), Cow::Borrowed)
    }
    match kind {
        SectionKind::SvoNodes | SectionKind::CoarseNodes => check_svo(&cast::<SvoNode>(data), depth),
        SectionKind::CoarseLeaves => {
            for (i, l) in cast::<CoarseLeaf>(data).iter().enumerate() {
                let n = &l.ndf;
                finite(&l.centroid_tile_m, "coarse leaf centroid", i)?;
                finite(&[l.opacity, n.mean[0], n.mean[1], n.mean[2], n.weight], "coarse leaf", i)?;
                finite(&l.emission, "coarse leaf emission", i)?;
                let len = n.mean.iter().map(|c| c * c).sum::<f32>().sqrt();
                if !(0.0..=1.0).contains(&l.opacity)
                    || len > 1.0 + 1e-3
                    || n.weight < 0.0
                    || l.emission.iter().any(|&c| c < 0.0)
                {
                    return Err(format!(
                        "coarse leaf {i}: opacity {}, NDF length {len}, weight {}, emission {:?}",
                        l.opacity, n.weight, l.emission
                    ));
                }
            }
            Ok(())
        }
        SectionKind::RockBricks => {
            // Within one brick of the tile's cube (rock reaches 4 cells, one brick, past a wall).
            let side = (1u64 << depth).div_ceil(u64::from(ROCK_BRICK_LEAVES)) as i64;
            for (i, b) in cast::<RockBrick>(data).iter().enumerate() {
                if b.brick.iter().any(|&c| !(-1..=side).contains(&i64::from(c))) {
                    return Err(format!(
                        "rock brick {i} at {:?} lies outside the tile's {side} bricks and a margin of one",
                        b.brick
                    ));
                }
            }
            Ok(())
        }
        SectionKind::LeafOpacity => {
            for (i, v) in cast::<f32>(data).iter().enumerate() {
                if !(0.0..=1.0).contains(v) {
                    return Err(format!("opacity {i} is {v}, outside 0..=1"));
                }
            }
            Ok(())
        }
        SectionKind::LeafNdf => {
            for (i, n) in cast::<LeafNdf>(data).iter().enumerate() {
                finite(&[n.mean[0], n.mean[1], n.mean[2], n.weight], "NDF", i)?;
                let len = n.mean.iter().map(|c| c * c).sum::<f32>().sqrt();
                if len > 1.0 + 1e-3 || n.weight < 0.0 {
                    return Err(format!("NDF {i} has mean length {len} or negative weight {}", n.weight));
                }
            }
            Ok(())
        }
        SectionKind::LeafEmission => {
            for (i, e) in cast::<LeafEmission>(data).iter().enumerate() {
                finite(&e.radiance, "emission", i)?;
                if e.radiance.iter().any(|&c| c < 0.0) {
                    return Err(format!("emission {i} is negative: {:?}", e.radiance));
                }
            }
            Ok(())
        }
        SectionKind::Surfels => {
            for (i, s) in cast::<Surfel>(data).iter().enumerate() {
                finite(&s.position_tile_m, "surfel position", i)?;
                finite(&s.normal, "surfel normal", i)?;
                finite(&[s.radius_m, s.spread], "surfel radius/spread", i)?;
                let len = s.normal.iter().map(|c| c * c).sum::<f32>().sqrt();
                if (len - 1.0).abs() > 1e-3 || s.radius_m < 0.0 || !(0.0..=1.0).contains(&s.spread) {
                    return Err(format!(
                        "surfel {i}: normal length {len}, radius {} m, spread {}",
                        s.radius_m, s.spread
                    ));
                }
            }
            Ok(())
        }
        SectionKind::EnvSh9 => {
            for (i, sh) in cast::<ShRgb9>(data).iter().enumerate() {
                finite(bytemuck::cast_slice(&sh.coeffs), "SH set", i)?;
            }
            Ok(())
        }
        SectionKind::EnvMipLevels => crate::env_chain::check_levels(&cast::<EnvMipLevel>(data)),
        SectionKind::Scene => {
            let scene: Scene = serde_json::from_slice(data).map_err(|e| e.to_string())?;
            scene.check()
        }
        SectionKind::Provenance => {
            serde_json::from_slice::<Provenance>(data).map(drop).map_err(|e| e.to_string())
        }
        SectionKind::Survey => {
            let survey: crate::survey::Survey = serde_json::from_slice(data).map_err(|e| e.to_string())?;
            survey.check()
        }
        SectionKind::LeafAlbedo
        | SectionKind::SurfelColorsRaw
        | SectionKind::SurfelColorsBc1
        | SectionKind::SurfelScans
        | SectionKind::EnvMipBc6h => Ok(()),
        SectionKind::SurfelsCompact => crate::compact::check(data, depth).map(drop),
    }
}

/// The node array is level by level, sorted by Morton code within a level; the children of the
/// inner nodes, taken in order, are exactly the nodes after the root (no orphans, no sharing) and
/// match their parent's mask; leaves index the attribute arrays in order.
pub(crate) fn check_svo(nodes: &[SvoNode], depth: u32) -> Result<(), String> {
    let Some(root) = nodes.first() else { return Ok(()) };
    if root.level != 0 || root.morton != 0 {
        return Err("node 0 is not the root".into());
    }
    let mut leaf_index = 0u32;
    let mut next_child = 1usize;
    for (i, n) in nodes.iter().enumerate() {
        // Claimed by an earlier parent, which checked its level and Morton code.
        if i >= next_child {
            return Err(format!("node {i} comes before its parent or has none"));
        }
        if u32::from(n.level) > depth {
            return Err(format!("node {i} is at level {}, below the tile depth {depth}", n.level));
        }
        if u32::from(n.level) == depth {
            if n.child_mask != 0 || n.first_child != leaf_index {
                return Err(format!(
                    "leaf node {i} has children or leaf index {} (expected {leaf_index})",
                    n.first_child
                ));
            }
            leaf_index += 1;
            continue;
        }
        let count = n.child_mask.count_ones() as usize;
        if count == 0 || n.first_child as usize != next_child {
            return Err(format!(
                "inner node {i} has mask {:#010b} and first child {}, expected {next_child}",
                n.child_mask, n.first_child
            ));
        }
        let children = nodes
            .get(next_child..next_child + count)
            .ok_or_else(|| format!("node {i}'s children {next_child}..+{count} are out of range"))?;
        let octants = (0..8u64).filter(|o| n.child_mask & (1 << o) != 0);
        for (c, o) in children.iter().zip(octants) {
            if c.level != n.level + 1 || c.morton != (n.morton << 3 | o) {
                return Err(format!("node {i}'s children do not match its mask at octant {o}"));
            }
        }
        next_child += count;
    }
    if next_child != nodes.len() {
        return Err(format!("{} nodes are nobody's children", nodes.len() - next_child));
    }
    Ok(())
}
