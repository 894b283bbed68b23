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
use xxhash_rust::xxh3::xxh3_64;

use crate::env_chain::EnvChain;
use crate::error::{Error, Problem, Region, Result};
use crate::scene::{Provenance, Scene};
use crate::section::{SectionInfo, TileInfo};
use crate::source::Backing;
use crate::spec::*;
use crate::validate::{
    MAX_HEADER_SIZE, Tables, check_content, check_header, check_structure, decode, table_ranges,
};

/// A typed element of a section: ties a Rust type to the [`ElementType`] the spec gives it.
pub trait Element: Pod {
    /// The spec's element type of `Self`.
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

    /// Lets go of the fetched bytes that hold none of `keep`'s sections and returns how many: a
    /// browser's visit then holds what its residency reads, however long it lasts. A piece that
    /// holds a kept section stays whole; a whole file (mapped or copied) lets go of nothing. A
    /// section let go is fetched again ([`Package::missing`]) when it is next wanted.
    pub fn release_fetched(&mut self, keep: impl IntoIterator<Item = SectionInfo>) -> u64 {
        let keep: Vec<Range<u64>> = keep
            .into_iter()
            .filter(|s| s.stored_len > 0)
            .map(|s| s.offset..s.offset.saturating_add(s.stored_len))
            .collect();
        let released = self.backing.release_except(&keep);
        // A section fetched again is checked again: its first check vouched for bytes let go.
        for (entry, checked) in self.sections.iter().zip(self.checked.iter_mut()) {
            if self.backing.range(entry.offset, entry.stored_len).is_none() {
                checked.take();
            }
        }
        released
    }

    /// Hands a memory-mapped package's pages back to the kernel once what needed them was read
    /// (a viewer's change of tiles): the pages a read touched count in the process's resident
    /// memory until the kernel needs them back. A page is read again from the file when next
    /// wanted; a package copied or fetched keeps its bytes ([`Package::release_fetched`]).
    /// Returns whether pages were handed back.
    pub fn release_mapped(&self) -> bool {
        self.backing.release_mapped_pages()
    }

    /// Bytes of the file this package holds in memory: the fetched pieces of one made with
    /// [`Package::from_directory`], all of one from bytes, none of a memory-mapped file.
    pub fn held_bytes(&self) -> u64 {
        self.backing.held_bytes()
    }

    /// The file (or, in a browser, the URL) the package was opened from.
    pub fn path(&self) -> &Path {
        &self.path
    }

    /// (major, minor) of the file.
    pub fn version(&self) -> (u16, u16) {
        (self.header.version_major, self.header.version_minor)
    }

    /// Bytes of the whole package file.
    pub fn file_size(&self) -> u64 {
        self.header.file_size
    }

    fn raw_sections(&self) -> &[RawSectionEntry] {
        &self.sections
    }

    fn raw_tiles(&self) -> &[RawTileEntry] {
        &self.tile_entries
    }

    /// Entries in the section table.
    pub fn section_count(&self) -> u32 {
        self.raw_sections().len() as u32
    }

    /// Every section, in table order, unknown kinds included.
    pub fn sections(&self) -> impl ExactSizeIterator<Item = SectionInfo> + '_ {
        self.raw_sections().iter().enumerate().map(|(i, e)| SectionInfo::from_raw(i as u32, e))
    }

    /// Section `index` of the table, or `None` past its end.
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

    /// Entries in the tile directory.
    pub fn tile_count(&self) -> u32 {
        self.raw_tiles().len() as u32
    }

    /// Tile `index` of the directory, or `None` past its end.
    pub fn tile(&self, index: u32) -> Option<Tile<'_>> {
        self.raw_tiles().get(index as usize).map(|raw| Tile { package: self, index, raw })
    }

    /// Every tile, in directory order.
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

    /// The surveyors' centreline stored with the package (`[survey]` in its manifest), if any.
    pub fn survey(&self) -> Result<Option<crate::survey::Survey>> {
        self.find(SectionKind::Survey, Scope::Global, 0).map(|s| self.read_json(&s)).transpose()
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
    /// Leaves of the SVO (its leaf-NDF elements).
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

    /// The tile's index in the directory.
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

    /// Edge of the tile's cube, metres.
    pub fn extent_m(&self) -> f64 {
        self.raw.extent_m
    }

    /// The tile's cell on the package's tile grid.
    pub fn grid(&self) -> [i32; 3] {
        self.raw.grid
    }

    /// Levels of the tile's SVO (its cube is 2^depth leaves on a side).
    pub fn depth(&self) -> u32 {
        self.raw.depth
    }

    /// Input points the tile was built from (its own, halo excluded).
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

    /// The tile's section of `kind` and `item`, if it has one.
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

    /// The tile's surfels one at a time, as [`Tile::surfels`] reads them but never all decoded
    /// at once: a compact section is decoded as it is walked (a full-precision one is read as a
    /// whole, in place from the map where raw). Returns whether the tile has surfels.
    pub fn for_each_surfel(&self, each: impl FnMut(&Surfel)) -> Result<bool> {
        if let Some(full) = self.read::<Surfel>(SectionKind::Surfels)? {
            full.iter().for_each(each);
            return Ok(true);
        }
        let Some(s) = self.find(SectionKind::SurfelsCompact, 0) else { return Ok(false) };
        let bytes = self.package.read_bytes(&s)?;
        let bad = |reason| {
            self.package.invalid(Problem::BadContent {
                section: s.index,
                kind: SectionKind::SurfelsCompact.name().to_owned(),
                reason,
            })
        };
        let mut each = each;
        crate::compact::decode_each(&bytes, self.leaf_size_m(), self.depth(), |surfel| each(&surfel))
            .map_err(bad)?;
        Ok(true)
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
