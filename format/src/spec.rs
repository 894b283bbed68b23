//! Raw `#[repr(C)]` mirrors of the on-disk structures of format versions 1 and 2 (see `docs/format.md`).
//!
//! Everything here is plain old data: these types are what the bytes *are*, little-endian, with no
//! validation. The checked types in [`crate::reader`] sit above them. Keep this file and
//! `docs/format.md` in sync: every size below is asserted at compile time.

use bytemuck::{Pod, Zeroable};

/// The first eight bytes of every package. The high byte and the trailing newline catch transfers
/// that mangle binary files (the PNG trick).
pub const MAGIC: [u8; 8] = *b"\x89GROTTO\n";
/// Newest major version this crate writes and reads. A file with a larger major is refused.
pub const VERSION_MAJOR: u16 = 2;
/// Minor version of [`VERSION_MAJOR`] this crate writes. Files with a larger minor open; the
/// additions are ignored.
pub const VERSION_MINOR: u16 = 0;
/// Oldest major version this crate reads: 1.x packages (full-precision surfels only) still open.
pub const OLDEST_MAJOR: u16 = 1;
/// The version a package without any 2.0 section is written as, so that 1.x readers still open
/// it: 2.0 changed only how surfels may be stored.
pub const VERSION_1: (u16, u16) = (1, 2);
/// Every section starts at a multiple of this, so a raw section can be cast to any element type in
/// place (the mapping itself is page-aligned).
pub const SECTION_ALIGN: u64 = 64;
/// The `tile` field of a section that belongs to the whole package rather than to one tile.
pub const GLOBAL: u32 = u32::MAX;
/// Deepest SVO a tile may declare: 3 bits per level must fit a 64-bit Morton code.
pub const MAX_SVO_DEPTH: u32 = 21;
/// A zstd frame cannot expand more than this (one 128 KiB RLE block costs at least 4 bytes), so a
/// claimed uncompressed length beyond `stored * MAX_ZSTD_RATIO + 64 KiB` is a lie we refuse before
/// allocating for it.
pub const MAX_ZSTD_RATIO: u64 = 32_768;
/// Most levels of a prefiltered environment chain.
pub const MAX_ENV_MIP_LEVELS: usize = 8;
/// Largest environment chain level, texels: a lat-long map is twice as wide as it is high.
pub const MAX_ENV_MIP_WIDTH: u32 = 8192;
/// Tallest environment mip level a reader accepts, texels (bounds its atlas).
pub const MAX_ENV_MIP_HEIGHT: u32 = 4096;
/// A reader stacks a chain's levels in one atlas as wide as level 0; the atlas may hold at most
/// this many times the texels the levels have (1.5 for a chain that halves each level), so
/// decoding a chain costs a bounded multiple of its stored blocks.
pub const MAX_ENV_ATLAS_RATIO: u64 = 2;
/// Rock cells ([`SectionKind::RockBricks`]) are `2^ROCK_CELL_SHIFT` leaves on a side.
pub const ROCK_CELL_SHIFT: u32 = 1;
/// A rock brick is `2^ROCK_BRICK_SHIFT` rock cells on a side (64 cells, one bit each).
pub const ROCK_BRICK_SHIFT: u32 = 2;
/// Leaves on a side of a rock brick.
pub const ROCK_BRICK_LEAVES: u32 = 1 << (ROCK_CELL_SHIFT + ROCK_BRICK_SHIFT);

/// File header, at offset 0. `header_size` bytes long (72 in version 1.0; a later minor may grow it).
#[repr(C)]
#[derive(Clone, Copy, Debug, PartialEq, Eq, Pod, Zeroable)]
pub struct RawHeader {
    pub magic: [u8; 8],
    pub version_major: u16,
    pub version_minor: u16,
    /// Length of the header in bytes, at least `size_of::<RawHeader>()`.
    pub header_size: u32,
    /// Number of [`RawSectionEntry`] records in the section table.
    pub section_count: u64,
    pub section_table_offset: u64,
    /// Number of [`RawTileEntry`] records in the tile directory.
    pub tile_count: u64,
    pub tile_directory_offset: u64,
    /// Length of the whole file; a shorter file was truncated.
    pub file_size: u64,
    /// XXH3-64 of the section table bytes followed by the tile directory bytes.
    pub table_checksum: u64,
    /// XXH3-64 of the first `header_size` bytes with this field set to zero.
    pub header_checksum: u64,
}

/// One entry of the section table. 48 bytes, 8-aligned.
#[repr(C)]
#[derive(Clone, Copy, Debug, PartialEq, Eq, Pod, Zeroable)]
pub struct RawSectionEntry {
    /// A [`SectionKind`] value; unknown values are skipped by readers.
    pub kind: u32,
    /// A [`Codec`] value.
    pub codec: u32,
    /// Tile index, or [`GLOBAL`].
    pub tile: u32,
    /// Distinguishes several sections of one kind in one scope (e.g. environment map 0, 1, ...).
    pub item: u32,
    /// Byte offset of the stored bytes; a multiple of [`SECTION_ALIGN`].
    pub offset: u64,
    /// Number of stored bytes (compressed length for zstd).
    pub stored_len: u64,
    /// Number of bytes after decoding; equals `stored_len` for raw sections.
    pub raw_len: u64,
    /// XXH3-64 of the stored bytes.
    pub checksum: u64,
}

/// One entry of the tile directory. 64 bytes, 8-aligned.
#[repr(C)]
#[derive(Clone, Copy, Debug, PartialEq, Pod, Zeroable)]
pub struct RawTileEntry {
    /// World position (metres, f64: survey coordinates) of the tile's minimum corner.
    pub origin_m: [f64; 3],
    /// Edge length of the cubic tile in metres (a power of two times the grid's base unit).
    pub extent_m: f64,
    /// Integer position of the tile in the global tile grid of its extent.
    pub grid: [i32; 3],
    /// SVO depth D: leaves are `extent_m / 2^D` wide.
    pub depth: u32,
    /// Number of input points that landed in the tile (halo excluded).
    pub point_count: u64,
    /// First entry of this tile's contiguous run in the section table.
    pub section_first: u32,
    /// Length of that run.
    pub section_count: u32,
}

/// How a section's bytes are stored.
#[repr(u32)]
#[derive(Clone, Copy, Debug, PartialEq, Eq, Hash, PartialOrd, Ord)]
pub enum Codec {
    /// Stored as is; castable in place.
    Raw = 0,
    /// One zstd frame.
    Zstd = 1,
}

impl Codec {
    /// The codec stored as `v`, or `None` for a value the spec does not define.
    pub fn from_u32(v: u32) -> Option<Self> {
        match v {
            0 => Some(Self::Raw),
            1 => Some(Self::Zstd),
            _ => None,
        }
    }

    /// The codec's name as `grotto inspect` prints it.
    pub fn name(self) -> &'static str {
        match self {
            Self::Raw => "raw",
            Self::Zstd => "zstd",
        }
    }
}

/// Where a section lives.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Hash, PartialOrd, Ord)]
pub enum Scope {
    Global,
    Tile(u32),
}

/// What a section holds. Values are stable across versions; new kinds get new numbers.
#[repr(u32)]
#[derive(Clone, Copy, Debug, PartialEq, Eq, Hash, PartialOrd, Ord)]
pub enum SectionKind {
    /// Per tile: [`SvoNode`] array, level by level, contiguous children.
    SvoNodes = 1,
    /// Per tile: `f32` opacity (coverage in 0..=1) per leaf.
    LeafOpacity = 2,
    /// Per tile: [`Rgba8`] albedo per leaf (RGB sRGB-encoded, averaged in linear light).
    LeafAlbedo = 3,
    /// Per tile: [`LeafNdf`] per leaf.
    LeafNdf = 4,
    /// Per tile: [`LeafEmission`] per leaf.
    LeafEmission = 5,
    /// Per tile: [`Surfel`] per point, Morton order.
    Surfels = 6,
    /// Per tile: [`Rgba8`] sRGB colour per surfel.
    SurfelColorsRaw = 7,
    /// Per tile: [`Bc1Block`] per 16 consecutive surfels.
    SurfelColorsBc1 = 8,
    /// Global, `item` = environment map: [`ShRgb9`], 9 RGB SH coefficients of radiance.
    EnvSh9 = 9,
    /// Global, `item` = environment map: [`EnvMipLevel`] per level of the prefiltered chain.
    EnvMipLevels = 10,
    /// Global, `item` = environment map: [`Bc6hBlock`] blocks of all levels.
    EnvMipBc6h = 11,
    /// Global: UTF-8 JSON [`crate::Scene`].
    Scene = 12,
    /// Global: UTF-8 JSON [`crate::Provenance`].
    Provenance = 13,
    /// Per tile, `item` = k >= 1 (format 1.1): [`SvoNode`] array of the tile's coarse level k, the
    /// SVO cut k levels above its leaves (depth D - k), whose nodes at that level are its leaves.
    CoarseNodes = 14,
    /// Per tile, `item` = k (format 1.1): [`CoarseLeaf`] per leaf of coarse level k.
    CoarseLeaves = 15,
    /// Per tile (format 1.1): [`RockBrick`]s, the rock behind the scanned walls near the tile.
    RockBricks = 16,
    /// Per tile (format 1.2): `u16` per surfel, in surfel order, the index of the scan it came
    /// from in [`crate::Scene::scans`] (zstd: neighbours in Morton order mostly share a scan).
    SurfelScans = 17,
    /// Per tile (format 2.0): the tile's surfels in the compact encoding of [`crate::compact`],
    /// bytes; a tile has this or [`SectionKind::Surfels`], not both.
    SurfelsCompact = 18,
    /// Global: UTF-8 JSON [`crate::survey::Survey`], the surveyors' centreline the package was
    /// built with (stations, legs, passage dimensions), in the package's world coordinates.
    /// Readers that do not know it skip it, as every unknown kind.
    Survey = 19,
}

/// The Rust type of one element of a section, used to check casts.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Hash)]
pub enum ElementType {
    SvoNode,
    F32,
    Rgba8,
    LeafNdf,
    LeafEmission,
    Surfel,
    Bc1Block,
    ShRgb9,
    EnvMipLevel,
    Bc6hBlock,
    CoarseLeaf,
    RockBrick,
    U16,
    Utf8Json,
    /// Bytes whose structure the kind's own codec checks.
    Bytes,
}

impl ElementType {
    /// Bytes of one element.
    pub const fn size(self) -> usize {
        match self {
            Self::SvoNode => size_of::<SvoNode>(),
            Self::F32 => size_of::<f32>(),
            Self::Rgba8 => size_of::<Rgba8>(),
            Self::LeafNdf => size_of::<LeafNdf>(),
            Self::LeafEmission => size_of::<LeafEmission>(),
            Self::Surfel => size_of::<Surfel>(),
            Self::Bc1Block => size_of::<Bc1Block>(),
            Self::ShRgb9 => size_of::<ShRgb9>(),
            Self::EnvMipLevel => size_of::<EnvMipLevel>(),
            Self::Bc6hBlock => size_of::<Bc6hBlock>(),
            Self::CoarseLeaf => size_of::<CoarseLeaf>(),
            Self::RockBrick => size_of::<RockBrick>(),
            Self::U16 => size_of::<u16>(),
            Self::Utf8Json | Self::Bytes => 1,
        }
    }
}

impl SectionKind {
    /// Every section kind the spec defines, in numbering order.
    pub const ALL: [SectionKind; 19] = [
        Self::SvoNodes,
        Self::LeafOpacity,
        Self::LeafAlbedo,
        Self::LeafNdf,
        Self::LeafEmission,
        Self::Surfels,
        Self::SurfelColorsRaw,
        Self::SurfelColorsBc1,
        Self::EnvSh9,
        Self::EnvMipLevels,
        Self::EnvMipBc6h,
        Self::Scene,
        Self::Provenance,
        Self::CoarseNodes,
        Self::CoarseLeaves,
        Self::RockBricks,
        Self::SurfelScans,
        Self::SurfelsCompact,
        Self::Survey,
    ];

    /// The kind stored as `v`, or `None` for a value the spec does not define.
    pub fn from_u32(v: u32) -> Option<Self> {
        Self::ALL.into_iter().find(|k| *k as u32 == v)
    }

    /// The kind's name as `grotto inspect` prints it (`svo-nodes`, `leaf-ndf`, ...).
    pub fn name(self) -> &'static str {
        match self {
            Self::SvoNodes => "svo-nodes",
            Self::LeafOpacity => "leaf-opacity",
            Self::LeafAlbedo => "leaf-albedo",
            Self::LeafNdf => "leaf-ndf",
            Self::LeafEmission => "leaf-emission",
            Self::Surfels => "surfels",
            Self::SurfelColorsRaw => "surfel-colors-raw",
            Self::SurfelColorsBc1 => "surfel-colors-bc1",
            Self::EnvSh9 => "env-sh9",
            Self::EnvMipLevels => "env-mip-levels",
            Self::EnvMipBc6h => "env-mip-bc6h",
            Self::Scene => "scene",
            Self::Provenance => "provenance",
            Self::CoarseNodes => "coarse-nodes",
            Self::CoarseLeaves => "coarse-leaves",
            Self::RockBricks => "rock-bricks",
            Self::SurfelScans => "surfel-scans",
            Self::SurfelsCompact => "surfels-compact",
            Self::Survey => "survey",
        }
    }

    /// The element type the kind's sections hold.
    pub fn element(self) -> ElementType {
        match self {
            Self::SvoNodes | Self::CoarseNodes => ElementType::SvoNode,
            Self::LeafOpacity => ElementType::F32,
            Self::LeafAlbedo | Self::SurfelColorsRaw => ElementType::Rgba8,
            Self::LeafNdf => ElementType::LeafNdf,
            Self::LeafEmission => ElementType::LeafEmission,
            Self::Surfels => ElementType::Surfel,
            Self::SurfelColorsBc1 => ElementType::Bc1Block,
            Self::EnvSh9 => ElementType::ShRgb9,
            Self::EnvMipLevels => ElementType::EnvMipLevel,
            Self::EnvMipBc6h => ElementType::Bc6hBlock,
            Self::CoarseLeaves => ElementType::CoarseLeaf,
            Self::RockBricks => ElementType::RockBrick,
            Self::SurfelScans => ElementType::U16,
            Self::SurfelsCompact => ElementType::Bytes,
            Self::Scene | Self::Provenance | Self::Survey => ElementType::Utf8Json,
        }
    }

    /// Whether the kind belongs to a tile (true) or to the whole package (false).
    pub fn is_per_tile(self) -> bool {
        !matches!(
            self,
            Self::EnvSh9
                | Self::EnvMipLevels
                | Self::EnvMipBc6h
                | Self::Scene
                | Self::Provenance
                | Self::Survey
        )
    }
}

/// One SVO node. Nodes are stored level by level (root first), sorted by Morton code within a level;
/// the children of a node are contiguous and in octant order, so `first_child + i` for
/// `i < popcount(child_mask)` addresses them. At the leaf level (`level == depth`), `first_child` is
/// the index into the tile's leaf attribute arrays.
#[repr(C)]
#[derive(Clone, Copy, Debug, PartialEq, Eq, Pod, Zeroable)]
pub struct SvoNode {
    /// Morton code of the node's cell at its own level (3 bits per level, x in the lowest bit).
    pub morton: u64,
    pub first_child: u32,
    /// Bit `o` set when octant `o` (x + 2y + 4z) has a child; zero at the leaf level.
    pub child_mask: u8,
    /// 0 for the root, `depth` for leaves.
    pub level: u8,
    pub reserved: u16,
}

/// Four bytes of colour.
#[repr(C)]
#[derive(Clone, Copy, Debug, PartialEq, Eq, Hash, Pod, Zeroable, Default)]
pub struct Rgba8(pub [u8; 4]);

/// Normal distribution of a leaf, after Toksvig: `mean` is the average of unit normals, so its
/// length `|mean|` in 0..=1 encodes the spread (1 = all normals agree).
#[repr(C)]
#[derive(Clone, Copy, Debug, PartialEq, Pod, Zeroable, Default)]
pub struct LeafNdf {
    pub mean: [f32; 3],
    /// Sum of sample weights that went into the leaf.
    pub weight: f32,
}

/// Emitted radiance of a leaf (area-light samples), linear RGB in W / (sr m^2).
#[repr(C)]
#[derive(Clone, Copy, Debug, PartialEq, Pod, Zeroable, Default)]
pub struct LeafEmission {
    pub radiance: [f32; 3],
    pub reserved: f32,
}

/// A point sample for the G-buffer. Position is relative to the tile origin (f32 is enough there:
/// tiles are at most a few hundred metres wide).
#[repr(C)]
#[derive(Clone, Copy, Debug, PartialEq, Pod, Zeroable, Default)]
pub struct Surfel {
    pub position_tile_m: [f32; 3],
    pub radius_m: f32,
    /// Unit normal, oriented toward the scanner (into the open cave).
    pub normal: [f32; 3],
    /// Spread of the normal distribution around `normal`: 1 - |mean of unit normals| (0 = flat).
    pub spread: f32,
}

/// A BC1 (DXT1) block: two RGB565 endpoints and 16 2-bit indices.
#[repr(C)]
#[derive(Clone, Copy, Debug, PartialEq, Eq, Pod, Zeroable, Default)]
pub struct Bc1Block(pub [u8; 8]);

/// A BC6H (unsigned half float) block.
#[repr(C)]
#[derive(Clone, Copy, Debug, PartialEq, Eq, Pod, Zeroable, Default)]
pub struct Bc6hBlock(pub [u8; 16]);

/// Nine RGB spherical-harmonic coefficients of radiance (bands 0..=2), in the order
/// L00, L1-1, L10, L11, L2-2, L2-1, L20, L21, L22.
#[repr(C)]
#[derive(Clone, Copy, Debug, PartialEq, Pod, Zeroable, Default)]
pub struct ShRgb9 {
    pub coeffs: [[f32; 3]; 9],
}

/// One level of a prefiltered lat-long environment map stored as BC6H blocks.
#[repr(C)]
#[derive(Clone, Copy, Debug, PartialEq, Pod, Zeroable, Default)]
pub struct EnvMipLevel {
    pub width: u32,
    pub height: u32,
    /// First block of this level in the matching [`SectionKind::EnvMipBc6h`] section.
    pub first_block: u32,
    /// `ceil(width / 4) * ceil(height / 4)`.
    pub block_count: u32,
    /// GGX roughness this level was prefiltered for.
    pub roughness: f32,
    pub reserved: [u32; 3],
}

/// A leaf of a tile's coarse level: what the package leaves under it look like from outside
/// (docs/format.md, "Coarse levels").
#[repr(C)]
#[derive(Clone, Copy, Debug, PartialEq, Pod, Zeroable, Default)]
pub struct CoarseLeaf {
    /// Coverage-weighted centroid of the leaves under it, metres from the tile origin.
    pub centroid_tile_m: [f32; 3],
    /// Coverage seen across the leaf, 0..=1.
    pub opacity: f32,
    /// Coverage-weighted mean of the leaves' NDFs; `weight` is the sum of their weights.
    pub ndf: LeafNdf,
    /// Coverage-weighted mean emitted radiance, linear RGB, W / (sr m^2).
    pub emission: [f32; 3],
    /// Coverage-weighted mean albedo, averaged in linear light, sRGB-encoded; A = 255.
    pub albedo: Rgba8,
}

/// 4x4x4 rock cells of 2x2x2 leaves: a brick 8 leaves on a side.
#[repr(C)]
#[derive(Clone, Copy, Debug, PartialEq, Eq, Pod, Zeroable, Default)]
pub struct RockBrick {
    /// Brick position from the tile's minimum corner, in bricks (may be negative).
    pub brick: [i32; 3],
    pub reserved: u32,
    /// Bit `x + 4 (y + 4 z)` set when cell (x, y, z) of the brick is rock; low word first.
    pub bits: [u32; 2],
}

// The sizes in docs/format.md; a change here is a format change.
const _: () = assert!(size_of::<RawHeader>() == 72);
const _: () = assert!(size_of::<RawSectionEntry>() == 48);
const _: () = assert!(size_of::<RawTileEntry>() == 64);
const _: () = assert!(size_of::<SvoNode>() == 16);
const _: () = assert!(size_of::<Rgba8>() == 4);
const _: () = assert!(size_of::<LeafNdf>() == 16);
const _: () = assert!(size_of::<LeafEmission>() == 16);
const _: () = assert!(size_of::<Surfel>() == 32);
const _: () = assert!(size_of::<Bc1Block>() == 8);
const _: () = assert!(size_of::<Bc6hBlock>() == 16);
const _: () = assert!(size_of::<ShRgb9>() == 108);
const _: () = assert!(size_of::<EnvMipLevel>() == 32);
const _: () = assert!(size_of::<CoarseLeaf>() == 48);
const _: () = assert!(size_of::<RockBrick>() == 24);
const _: () = assert!(align_of::<RawSectionEntry>() == 8 && align_of::<RawTileEntry>() == 8);
