//! Opening a package: every offset, length and count is validated once, with checked arithmetic,
//! before anything is handed out; after that, the structural accessors cannot fail.
//!
//! Open cost is proportional to the section table and tile directory, never to the payload: section
//! bytes are only touched when a section is first read, at which point its checksum and content are
//! checked (once, cached) and zstd sections are decoded. [`Package::verify`] does that for all.

use std::borrow::Cow;
use std::ops::Range;
use std::path::{Path, PathBuf};
use std::sync::OnceLock;

use bytemuck::Pod;
use xxhash_rust::xxh3::{Xxh3, xxh3_64};

use crate::env_chain::EnvChain;
use crate::error::{Error, Problem, Region, Result};
use crate::scene::{Provenance, Scene};
use crate::source::Backing;
use crate::spec::*;

/// Largest header a reader accepts; bounds the work a lying `header_size` can cause.
const MAX_HEADER_SIZE: u32 = 4096;
/// Offset of `header_checksum` inside the header.
const HEADER_CHECKSUM_OFFSET: usize = 64;

/// A typed element of a section: ties a Rust type to the [`ElementType`] the spec gives it.
pub trait Element: Pod {
    const TYPE: ElementType;
}

macro_rules! element {
    ($($t:ty => $e:ident),* $(,)?) => { $(impl Element for $t { const TYPE: ElementType = ElementType::$e; })* };
}
element!(
    SvoNode => SvoNode, f32 => F32, Rgba8 => Rgba8, LeafNdf => LeafNdf, LeafEmission => LeafEmission,
    Surfel => Surfel, Bc1Block => Bc1Block, ShRgb9 => ShRgb9, EnvMipLevel => EnvMipLevel,
    Bc6hBlock => Bc6hBlock, CoarseLeaf => CoarseLeaf, RockBrick => RockBrick, u16 => U16,
);

/// Tile directory fields the caller provides; section references are filled in by the writer (`PackageWriter`).
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct TileInfo {
    pub origin_m: [f64; 3],
    pub extent_m: f64,
    pub grid: [i32; 3],
    pub depth: u32,
    pub point_count: u64,
}

/// A validated section-table entry.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub struct SectionInfo {
    /// Position in the section table.
    pub index: u32,
    /// `None` for kinds this reader does not know (they are skipped, not errors).
    pub kind: Option<SectionKind>,
    pub kind_raw: u32,
    /// Always `Some` for known kinds.
    pub codec: Option<Codec>,
    pub scope: Scope,
    pub item: u32,
    pub offset: u64,
    pub stored_len: u64,
    pub raw_len: u64,
    pub checksum: u64,
}

impl SectionInfo {
    fn from_raw(index: u32, e: &RawSectionEntry) -> Self {
        Self {
            index,
            kind: SectionKind::from_u32(e.kind),
            kind_raw: e.kind,
            codec: Codec::from_u32(e.codec),
            scope: if e.tile == GLOBAL { Scope::Global } else { Scope::Tile(e.tile) },
            item: e.item,
            offset: e.offset,
            stored_len: e.stored_len,
            raw_len: e.raw_len,
            checksum: e.checksum,
        }
    }

    /// Human-readable kind, `unknown(N)` for kinds from a newer writer.
    pub fn kind_name(&self) -> String {
        self.kind.map_or_else(|| format!("unknown({})", self.kind_raw), |k| k.name().to_owned())
    }
}

/// An open, structurally valid package: a whole file, or (in a browser) its directory and the
/// sections fetched so far ([`Package::from_directory`], [`Package::insert`]).
#[derive(Debug)]
pub struct Package {
    path: PathBuf,
    backing: Backing,
    header: RawHeader,
    sections: Box<[RawSectionEntry]>,
    tile_entries: Box<[RawTileEntry]>,
    /// Per section: checksum and content checked (lazily, once).
    checked: Box<[OnceLock<Result<(), Problem>>]>,
}

/// A tile of an open package.
#[derive(Clone, Copy, Debug)]
pub struct Tile<'a> {
    package: &'a Package,
    index: u32,
    raw: &'a RawTileEntry,
}

impl Package {
    /// Memory-maps and validates the package at `path`.
    #[cfg(not(target_arch = "wasm32"))]
    pub fn open(path: impl AsRef<Path>) -> Result<Self> {
        let path = path.as_ref().to_path_buf();
        let io = |op, source| Error::Io { path: path.clone(), op, source };
        let file = std::fs::File::open(&path).map_err(|e| io("open", e))?;
        let len = file.metadata().map_err(|e| io("stat", e))?.len();
        // Some platforms refuse to map an empty file; it is invalid anyway.
        let backing = if len < size_of::<RawHeader>() as u64 {
            Backing::copy_of(&std::fs::read(&path).map_err(|e| io("read", e))?)
        } else {
            Backing::map(&file).map_err(|e| io("memory-map", e))?
        };
        Self::validate(path, backing)
    }

    /// Validates a package held in memory (copied once into 64-byte-aligned storage). `name` is used
    /// in error messages.
    pub fn from_bytes(name: impl Into<PathBuf>, bytes: &[u8]) -> Result<Self> {
        Self::validate(name.into(), Backing::copy_of(bytes))
    }

    fn validate(path: PathBuf, backing: Backing) -> Result<Self> {
        let bytes = backing.whole().unwrap_or_default();
        match check_structure(bytes, bytes.len() as u64, 0, bytes) {
            Ok((header, tables)) => Ok(Self::assemble(path, backing, header, tables)),
            Err(problem) => Err(Error::Invalid { path, problem }),
        }
    }

    fn assemble(
        path: PathBuf,
        backing: Backing,
        header: RawHeader,
        (sections, tile_entries): Tables,
    ) -> Self {
        let checked = (0..sections.len()).map(|_| OnceLock::new()).collect();
        Self { path, backing, header, sections, tile_entries, checked }
    }

    /// Where the section table and tile directory of a `file_len`-byte package lie, from its
    /// first bytes (`head`: the first [`Package::HEAD_BYTES`] bytes, or the whole file where it is
    /// shorter): what a reader over HTTP fetches second. Checks the header.
    pub fn directory_range(name: impl Into<PathBuf>, head: &[u8], file_len: u64) -> Result<Range<u64>> {
        let path = name.into();
        let invalid = |problem| Error::Invalid { path: path.clone(), problem };
        let header = check_header(head, file_len).map_err(invalid)?;
        let (table, tiles) = table_ranges(&header, file_len).map_err(invalid)?;
        Ok(table.start.min(tiles.start)..table.end.max(tiles.end))
    }

    /// Bytes a reader over HTTP fetches first: enough for any header.
    pub const HEAD_BYTES: u64 = MAX_HEADER_SIZE as u64;

    /// A package of `file_len` bytes of which only the directory is here yet: `head` as for
    /// [`Package::directory_range`], and `directory` the bytes at `directory_offset` that cover that
    /// range. Validated as [`Package::open`] validates a file; sections are read once their bytes
    /// were added with [`Package::insert`] (before that, reading one is [`Error::NotFetched`]).
    pub fn from_directory(
        name: impl Into<PathBuf>,
        file_len: u64,
        head: &[u8],
        directory_offset: u64,
        directory: &[u8],
    ) -> Result<Self> {
        let path = name.into();
        match check_structure(head, file_len, directory_offset, directory) {
            // The header and tables are kept as checked; the backing holds sections only.
            Ok((header, tables)) => {
                Ok(Self::assemble(path, Backing::Sparse(Default::default()), header, tables))
            }
            Err(problem) => Err(Error::Invalid { path, problem }),
        }
    }

    /// Adds fetched bytes at `offset` (a multiple of 64, within the file) to a package made with
    /// [`Package::from_directory`]; a whole file has them already. Checked when a section in them
    /// is read, like any other.
    pub fn insert(&mut self, offset: u64, bytes: &[u8]) -> Result<()> {
        let (region, len, file_len) = (Region::Fetched, bytes.len() as u64, self.header.file_size);
        let problem = if !offset.is_multiple_of(SECTION_ALIGN) {
            Some(Problem::Misaligned { region, offset, align: SECTION_ALIGN })
        } else if offset.checked_add(len).is_none_or(|e| e > file_len) {
            Some(Problem::OutOfBounds { region, offset, len, file_len })
        } else {
            None
        };
        if let Some(problem) = problem {
            return Err(self.invalid(problem));
        }
        self.backing.insert(offset, bytes);
        Ok(())
    }

    /// The byte ranges still to fetch for `sections` (each starting at a multiple of 64), nearby
    /// ones merged where less than `gap` bytes lie between them: fewer, larger requests.
    pub fn missing(&self, sections: impl IntoIterator<Item = SectionInfo>, gap: u64) -> Vec<Range<u64>> {
        let mut ranges: Vec<Range<u64>> = sections
            .into_iter()
            .filter(|s| s.stored_len > 0 && self.backing.range(s.offset, s.stored_len).is_none())
            .map(|s| s.offset / SECTION_ALIGN * SECTION_ALIGN..s.offset + s.stored_len)
            .collect();
        ranges.sort_unstable_by_key(|r| r.start);
        let mut out: Vec<Range<u64>> = Vec::new();
        for r in ranges {
            match out.last_mut() {
                Some(last) if r.start <= last.end.saturating_add(gap) => last.end = last.end.max(r.end),
                _ => out.push(r),
            }
        }
        out
    }

    /// Bytes of the file this package holds in memory: the fetched pieces of one made with
    /// [`Package::from_directory`], all of one from bytes, none of a memory-mapped file.
    pub fn held_bytes(&self) -> u64 {
        self.backing.held_bytes()
    }

    pub fn path(&self) -> &Path {
        &self.path
    }

    /// (major, minor) of the file.
    pub fn version(&self) -> (u16, u16) {
        (self.header.version_major, self.header.version_minor)
    }

    pub fn file_size(&self) -> u64 {
        self.header.file_size
    }

    fn raw_sections(&self) -> &[RawSectionEntry] {
        &self.sections
    }

    fn raw_tiles(&self) -> &[RawTileEntry] {
        &self.tile_entries
    }

    pub fn section_count(&self) -> u32 {
        self.raw_sections().len() as u32
    }

    /// Every section, in table order, unknown kinds included.
    pub fn sections(&self) -> impl ExactSizeIterator<Item = SectionInfo> + '_ {
        self.raw_sections().iter().enumerate().map(|(i, e)| SectionInfo::from_raw(i as u32, e))
    }

    pub fn section(&self, index: u32) -> Option<SectionInfo> {
        self.raw_sections().get(index as usize).map(|e| SectionInfo::from_raw(index, e))
    }

    /// The section of `kind` in `scope` with `item`, if the package has one.
    pub fn find(&self, kind: SectionKind, scope: Scope, item: u32) -> Option<SectionInfo> {
        match scope {
            Scope::Global => {
                self.sections().find(|s| s.kind == Some(kind) && s.scope == scope && s.item == item)
            }
            Scope::Tile(t) => self.tile(t)?.find(kind, item),
        }
    }

    pub fn tile_count(&self) -> u32 {
        self.raw_tiles().len() as u32
    }

    pub fn tile(&self, index: u32) -> Option<Tile<'_>> {
        self.raw_tiles().get(index as usize).map(|raw| Tile { package: self, index, raw })
    }

    pub fn tiles(&self) -> impl ExactSizeIterator<Item = Tile<'_>> + '_ {
        self.raw_tiles().iter().enumerate().map(|(i, raw)| Tile { package: self, index: i as u32, raw })
    }

    pub(crate) fn invalid(&self, problem: Problem) -> Error {
        Error::Invalid { path: self.path.clone(), problem }
    }

    /// The bytes of a section as stored in the file (compressed for zstd), unchecked. For copying
    /// sections between packages; readers want [`Package::read`].
    pub fn stored_bytes(&self, s: &SectionInfo) -> Result<&[u8]> {
        self.stored(s)
    }

    /// In bounds (checked at open); absent only from a package whose bytes are still being fetched.
    fn stored(&self, s: &SectionInfo) -> Result<&[u8]> {
        self.backing.range(s.offset, s.stored_len).ok_or_else(|| Error::NotFetched {
            path: self.path.clone(),
            section: s.index,
            kind: s.kind_name(),
            offset: s.offset,
            len: s.stored_len,
        })
    }

    /// The decoded bytes of a section, after its checksum (and, for known kinds, its content) has
    /// been checked. Raw sections are borrowed from the map; zstd sections are decoded each call.
    pub fn read_bytes(&self, s: &SectionInfo) -> Result<Cow<'_, [u8]>> {
        self.read_checked::<u8>(s)
    }

    /// The elements of a section, cast in place for raw sections. Fails if the section does not
    /// hold `T`.
    pub fn read<T: Element>(&self, s: &SectionInfo) -> Result<Cow<'_, [T]>> {
        if s.kind.map(SectionKind::element) != Some(T::TYPE) {
            return Err(self.invalid(Problem::WrongElementType {
                section: s.index,
                kind: s.kind_name(),
                requested: T::TYPE,
            }));
        }
        self.read_checked::<T>(s)
    }

    /// Checks a section's checksum and content as its first read does, once: a section already
    /// checked (by a read or an earlier call) is not decoded again. For copying sections whose
    /// bytes are not needed, and for checking them on another thread first.
    pub fn check(&self, s: &SectionInfo) -> Result<()> {
        let stored = self.stored(s)?;
        self.checked[s.index as usize]
            .get_or_init(|| self.check_section(s, stored).map(drop))
            .clone()
            .map_err(|p| self.invalid(p))
    }

    fn read_checked<T: Pod>(&self, s: &SectionInfo) -> Result<Cow<'_, [T]>> {
        let stored = self.stored(s)?;
        let mut decoded = None;
        let status = self.checked[s.index as usize].get_or_init(|| {
            let data = self.check_section(s, stored)?;
            decoded = Some(data);
            Ok(())
        });
        status.clone().map_err(|p| self.invalid(p))?;
        let data = match decoded {
            Some(d) => d,
            None => decode(s, stored).map_err(|p| self.invalid(p))?,
        };
        Ok(match data {
            Cow::Borrowed(b) => Cow::Borrowed(bytemuck::cast_slice(b)),
            Cow::Owned(v) => Cow::Owned(bytemuck::pod_collect_to_vec(&v)),
        })
    }

    /// Checksum, decode, and content check of one section; returns the decoded bytes.
    fn check_section<'a>(&self, s: &SectionInfo, stored: &'a [u8]) -> Result<Cow<'a, [u8]>, Problem> {
        let computed = xxh3_64(stored);
        if computed != s.checksum {
            return Err(Problem::SectionChecksum {
                section: s.index,
                kind: s.kind_name(),
                stored: s.checksum,
                computed,
            });
        }
        let data = decode(s, stored)?;
        if let Some(kind) = s.kind {
            let tile_depth = match s.scope {
                Scope::Tile(t) => self.raw_tiles()[t as usize].depth,
                Scope::Global => 0,
            };
            // A coarse level k is an SVO k levels shallower than the tile's.
            let depth = match kind {
                SectionKind::CoarseNodes | SectionKind::CoarseLeaves => {
                    match tile_depth.checked_sub(s.item) {
                        Some(d) if s.item > 0 => d,
                        _ => {
                            return Err(Problem::BadContent {
                                section: s.index,
                                kind: kind.name().to_owned(),
                                reason: format!(
                                    "coarse level {} of a tile of depth {tile_depth} (levels are 1..=depth)",
                                    s.item
                                ),
                            });
                        }
                    }
                }
                _ => tile_depth,
            };
            check_content(kind, &data, depth).map_err(|reason| Problem::BadContent {
                section: s.index,
                kind: kind.name().to_owned(),
                reason,
            })?;
        }
        Ok(data)
    }

    /// The scene; an empty scene if the package has none.
    pub fn scene(&self) -> Result<Scene> {
        match self.find(SectionKind::Scene, Scope::Global, 0) {
            Some(s) => self.read_json(&s),
            None => Ok(Scene::default()),
        }
    }

    /// How the package was built, if it says.
    pub fn provenance(&self) -> Result<Option<Provenance>> {
        self.find(SectionKind::Provenance, Scope::Global, 0).map(|s| self.read_json(&s)).transpose()
    }

    fn read_json<T: serde::de::DeserializeOwned>(&self, s: &SectionInfo) -> Result<T> {
        let bytes = self.read_bytes(s)?;
        // Content (including this parse) was checked by read_bytes; a failure here is impossible
        // unless the types diverge, and is still reported rather than unwrapped.
        serde_json::from_slice(&bytes).map_err(|e| {
            self.invalid(Problem::BadContent { section: s.index, kind: s.kind_name(), reason: e.to_string() })
        })
    }

    /// Checks every section's checksum and content. Returns all problems found (empty = valid).
    pub fn verify(&self) -> Vec<Problem> {
        let mut problems: Vec<Problem> = self
            .sections()
            .filter_map(|s| match self.read_bytes(&s) {
                Ok(_) => None,
                Err(Error::Invalid { problem, .. }) => Some(problem),
                Err(other) => Some(Problem::BadContent {
                    section: s.index,
                    kind: s.kind_name(),
                    reason: other.to_string(),
                }),
            })
            .collect();
        // Rules across sections, reported once.
        let coarse = self.tiles().flat_map(|t| {
            let levels: Vec<u32> =
                t.sections().filter(|s| s.kind == Some(SectionKind::CoarseNodes)).map(|s| s.item).collect();
            levels.into_iter().filter_map(move |k| match t.coarse(k) {
                Err(Error::Invalid { problem, .. }) => Some(problem),
                _ => None,
            })
        });
        for p in self.env_chain_problems().into_iter().chain(coarse.collect::<Vec<_>>()) {
            if !problems.contains(&p) {
                problems.push(p);
            }
        }
        problems
    }
}

/// A tile's octree with its leaf attributes, checked to fit together: one attribute per leaf.
#[derive(Clone, Debug)]
pub struct SvoData<'a> {
    pub nodes: Cow<'a, [SvoNode]>,
    pub opacity: Cow<'a, [f32]>,
    pub albedo: Cow<'a, [Rgba8]>,
    pub ndf: Cow<'a, [LeafNdf]>,
    /// Absent when no leaf of the tile emits.
    pub emission: Option<Cow<'a, [LeafEmission]>>,
}

impl SvoData<'_> {
    pub fn leaf_count(&self) -> usize {
        self.opacity.len()
    }
}

/// A tile's coarse level k (format 1.1): an SVO of depth D - k and one [`CoarseLeaf`] per leaf.
#[derive(Clone, Debug)]
pub struct CoarseData<'a> {
    pub nodes: Cow<'a, [SvoNode]>,
    pub leaves: Cow<'a, [CoarseLeaf]>,
}

impl<'a> Tile<'a> {
    /// The tile's coarse level `k` (>= 1), checked to fit together; `Ok(None)` when the package
    /// does not store it (format 1.0 packages, or a level the writer did not make).
    pub fn coarse(&self, k: u32) -> Result<Option<CoarseData<'a>>> {
        let (Some(ns), Some(ls)) =
            (self.find(SectionKind::CoarseNodes, k), self.find(SectionKind::CoarseLeaves, k))
        else {
            return Ok(None);
        };
        let nodes = self.package.read::<SvoNode>(&ns)?;
        let leaves = self.package.read::<CoarseLeaf>(&ls)?;
        // Checked as an SVO of depth D - k on read, so the subtraction holds.
        let depth = self.raw.depth - k;
        let count = nodes.iter().filter(|n| u32::from(n.level) == depth).count();
        if count != leaves.len() {
            return Err(self.package.invalid(Problem::BadContent {
                section: ls.index,
                kind: SectionKind::CoarseLeaves.name().to_owned(),
                reason: format!(
                    "tile {} level {k} has {count} leaves but {} entries",
                    self.index,
                    leaves.len()
                ),
            }));
        }
        Ok(Some(CoarseData { nodes, leaves }))
    }

    /// The rock bricks stored with the tile (format 1.1); `Ok(None)` when the package has none.
    pub fn rock(&self) -> Result<Option<Cow<'a, [RockBrick]>>> {
        self.read::<RockBrick>(SectionKind::RockBricks)
    }

    /// The tile's SVO and leaf attributes; `Ok(None)` when the tile has no SVO section.
    pub fn svo(&self) -> Result<Option<SvoData<'a>>> {
        let Some(nodes) = self.read::<SvoNode>(SectionKind::SvoNodes)? else { return Ok(None) };
        let leaves = nodes.iter().filter(|n| u32::from(n.level) == self.raw.depth).count();
        let bad = |kind: SectionKind, len: usize| {
            self.package.invalid(Problem::BadContent {
                section: self.find(kind, 0).map_or(u32::MAX, |s| s.index),
                kind: kind.name().to_owned(),
                reason: format!("tile {} has {leaves} leaves but {len} entries", self.index),
            })
        };
        let opacity = self.read::<f32>(SectionKind::LeafOpacity)?.unwrap_or_default();
        let albedo = self.read::<Rgba8>(SectionKind::LeafAlbedo)?.unwrap_or_default();
        let ndf = self.read::<LeafNdf>(SectionKind::LeafNdf)?.unwrap_or_default();
        let emission = self.read::<LeafEmission>(SectionKind::LeafEmission)?;
        for (kind, len) in [
            (SectionKind::LeafOpacity, opacity.len()),
            (SectionKind::LeafAlbedo, albedo.len()),
            (SectionKind::LeafNdf, ndf.len()),
            (SectionKind::LeafEmission, emission.as_ref().map_or(leaves, |e| e.len())),
        ] {
            if len != leaves {
                return Err(bad(kind, len));
            }
        }
        Ok(Some(SvoData { nodes, opacity, albedo, ndf, emission }))
    }

    pub fn index(&self) -> u32 {
        self.index
    }

    /// The tile's directory fields as a writer takes them, to copy the tile into another package.
    pub fn info(&self) -> TileInfo {
        TileInfo {
            origin_m: self.origin_m(),
            extent_m: self.extent_m(),
            grid: self.grid(),
            depth: self.depth(),
            point_count: self.point_count(),
        }
    }

    /// World position of the minimum corner, metres.
    pub fn origin_m(&self) -> [f64; 3] {
        self.raw.origin_m
    }

    pub fn extent_m(&self) -> f64 {
        self.raw.extent_m
    }

    pub fn grid(&self) -> [i32; 3] {
        self.raw.grid
    }

    pub fn depth(&self) -> u32 {
        self.raw.depth
    }

    pub fn point_count(&self) -> u64 {
        self.raw.point_count
    }

    /// Edge length of a leaf voxel in metres.
    pub fn leaf_size_m(&self) -> f64 {
        self.raw.extent_m / f64::from(1u32 << self.raw.depth)
    }

    /// This tile's sections (a contiguous run of the table).
    pub fn sections(&self) -> impl ExactSizeIterator<Item = SectionInfo> + 'a {
        let first = self.raw.section_first;
        let package = self.package;
        (first..first + self.raw.section_count).map(move |i| package.section(i).expect("validated at open"))
    }

    pub fn find(&self, kind: SectionKind, item: u32) -> Option<SectionInfo> {
        self.sections().find(|s| s.kind == Some(kind) && s.item == item)
    }

    /// The tile's surfels from whichever section holds them: full precision (`surfels`, in place
    /// from the map where raw) or compact (`surfels-compact` of format 2.0, decoded here: about
    /// 32 bytes of memory for each 6 stored); `Ok(None)` when the tile has neither.
    pub fn surfels(&self) -> Result<Option<Cow<'a, [Surfel]>>> {
        if let Some(full) = self.read::<Surfel>(SectionKind::Surfels)? {
            return Ok(Some(full));
        }
        let Some(s) = self.find(SectionKind::SurfelsCompact, 0) else { return Ok(None) };
        let bytes = self.package.read_bytes(&s)?;
        crate::compact::decode(&bytes, self.leaf_size_m(), self.depth()).map(|v| Some(Cow::Owned(v))).map_err(
            |reason| {
                self.package.invalid(Problem::BadContent {
                    section: s.index,
                    kind: SectionKind::SurfelsCompact.name().to_owned(),
                    reason,
                })
            },
        )
    }

    /// How many surfels the tile holds, from the section table alone (no section is read): exact
    /// for full surfels, scan indices or raw colours, and rounded up to 16 from BC1 colours.
    /// `None` when the tile has no surfel section.
    pub fn surfel_count_from_table(&self) -> Option<u64> {
        let raw = |kind: SectionKind| self.find(kind, 0).map(|s| s.raw_len / kind.element().size() as u64);
        if self.find(SectionKind::Surfels, 0).is_none() && self.find(SectionKind::SurfelsCompact, 0).is_none()
        {
            return None;
        }
        raw(SectionKind::Surfels)
            .or_else(|| raw(SectionKind::SurfelScans))
            .or_else(|| raw(SectionKind::SurfelColorsRaw))
            .or_else(|| raw(SectionKind::SurfelColorsBc1).map(|blocks| blocks * 16))
    }

    /// Reads the tile's section of `kind` (item 0) as `T`; `Ok(None)` when the tile has none.
    pub fn read<T: Element>(&self, kind: SectionKind) -> Result<Option<Cow<'a, [T]>>> {
        self.find(kind, 0).map(|s| self.package.read::<T>(&s)).transpose()
    }
}

/// A section's stored bytes decoded.
fn decode<'a>(s: &SectionInfo, stored: &'a [u8]) -> Result<Cow<'a, [u8]>, Problem> {
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
type Tables = (Box<[RawSectionEntry]>, Box<[RawTileEntry]>);

/// Structural validation (the header, table and directory, nothing else) of a `file_len`-byte
/// package from its first bytes (`head`) and a piece of it (`directory`, at `directory_offset`)
/// that covers the table and directory. A whole file is all three.
fn check_structure(
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
fn check_header(bytes: &[u8], file_len: u64) -> Result<RawHeader, Problem> {
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
fn table_ranges(header: &RawHeader, file_len: u64) -> Result<(Range<u64>, Range<u64>), Problem> {
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
fn check_tables(
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

fn scope_name(scope: Scope) -> String {
    match scope {
        Scope::Global => "the package".to_owned(),
        Scope::Tile(t) => format!("tile {t}"),
    }
}

/// Byte range of an array of `count` records of `size` bytes at `offset`, checked.
fn array_range(
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

fn check_known_entry(s: &SectionInfo, kind: SectionKind) -> Result<(), Problem> {
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

fn check_tile(t: u32, tile: &RawTileEntry, sections: &[RawSectionEntry]) -> Result<(), Problem> {
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
fn check_content(kind: SectionKind, data: &[u8], depth: u32) -> Result<(), String> {
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
            scene.check_finite()
        }
        SectionKind::Provenance => {
            serde_json::from_slice::<Provenance>(data).map(drop).map_err(|e| e.to_string())
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
fn check_svo(nodes: &[SvoNode], depth: u32) -> Result<(), String> {
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

/// Environment chains (rules in env_chain.rs).
impl Package {
    /// Environment `index`'s prefiltered chain, checked: the level table follows the rules above
    /// and the blocks section holds exactly the blocks the levels cover. `Ok(None)` when the
    /// package has neither section (or an empty table); an error when it has only one of them.
    pub fn env_chain(&self, index: u32) -> Result<Option<EnvChain<'_>>> {
        let Some((levels, blocks_s)) = self.env_chain_table(index)? else { return Ok(None) };
        let blocks = self.read::<Bc6hBlock>(&blocks_s)?;
        Ok(Some(EnvChain { levels, blocks }))
    }

    /// The level table of environment `index` and its blocks section, checked against each other
    /// by the section's length alone (the blocks are not decoded).
    fn env_chain_table(&self, index: u32) -> Result<Option<(Cow<'_, [EnvMipLevel]>, SectionInfo)>> {
        let levels_s = self.find(SectionKind::EnvMipLevels, Scope::Global, index);
        let blocks_s = self.find(SectionKind::EnvMipBc6h, Scope::Global, index);
        let missing = |kind: SectionKind, other: SectionKind| {
            self.invalid(Problem::Missing {
                kind: kind.name().to_owned(),
                scope: format!(" for environment {index} (its {} section has none)", other.name()),
            })
        };
        let (levels_s, blocks_s) = match (levels_s, blocks_s) {
            (None, None) => return Ok(None),
            (Some(l), Some(b)) => (l, b),
            (Some(_), None) => return Err(missing(SectionKind::EnvMipBc6h, SectionKind::EnvMipLevels)),
            (None, Some(_)) => return Err(missing(SectionKind::EnvMipLevels, SectionKind::EnvMipBc6h)),
        };
        let levels = self.read::<EnvMipLevel>(&levels_s)?;
        if levels.is_empty() {
            return Ok(None);
        }
        let claimed: u64 = levels.iter().map(|l| u64::from(l.block_count)).sum();
        let held = blocks_s.raw_len / size_of::<Bc6hBlock>() as u64;
        if claimed != held {
            return Err(self.invalid(Problem::BadContent {
                section: blocks_s.index,
                kind: SectionKind::EnvMipBc6h.name().to_owned(),
                reason: format!("holds {held} blocks, environment {index}'s levels cover {claimed}"),
            }));
        }
        Ok(Some((levels, blocks_s)))
    }

    /// Problems of every environment chain as a whole (each section alone is checked by `read`).
    pub(crate) fn env_chain_problems(&self) -> Vec<Problem> {
        self.sections()
            .filter(|s| {
                matches!(s.kind, Some(SectionKind::EnvMipLevels | SectionKind::EnvMipBc6h))
                    && s.scope == Scope::Global
            })
            .map(|s| s.item)
            .collect::<std::collections::BTreeSet<u32>>()
            .into_iter()
            .filter_map(|item| self.env_chain_table(item).err().and_then(|e| e.problem().cloned()))
            .collect()
    }
}
