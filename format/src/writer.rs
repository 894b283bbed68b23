//! Writing a package: sections stream into a temp file beside the target; `finish` appends the
//! section table and tile directory, rewrites the header, syncs, and renames the temp file over the
//! target. Until that rename nothing exists under the final name, so a crash, a full disk or a
//! dropped writer leaves the previous package (if any) untouched; the temp file is removed on drop.

use std::collections::HashSet;
use std::fs::File;
use std::io::{BufWriter, Seek, SeekFrom, Write};
use std::path::{Path, PathBuf};

use xxhash_rust::xxh3::{Xxh3, xxh3_64};

use crate::error::{Error, Result};
use crate::scene::{Provenance, Scene};
use crate::section::TileInfo;
use crate::spec::*;

/// How to store a section.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum Compression {
    /// As is: the runtime can cast it in place from the memory map.
    Raw,
    /// Always zstd at this level.
    Zstd(i32),
    /// zstd at this level if that saves at least 1/8 of the bytes, else raw ("zstd where it pays").
    Auto(i32),
}

/// Streams a package to `path` atomically. Call [`PackageWriter::finish`]; dropping it discards
/// everything written.
#[derive(Debug)]
pub struct PackageWriter {
    target: PathBuf,
    temp: tempfile::TempPath,
    out: BufWriter<File>,
    pos: u64,
    sections: Vec<RawSectionEntry>,
    keys: HashSet<(u32, u32, u32)>,
    tiles: Vec<TileInfo>,
}

impl PackageWriter {
    /// Starts a package that will appear at `path` when finished.
    pub fn create(path: impl AsRef<Path>) -> Result<Self> {
        let target = path.as_ref().to_path_buf();
        let dir = match target.parent() {
            Some(p) if !p.as_os_str().is_empty() => p.to_path_buf(),
            _ => PathBuf::from("."),
        };
        let name = target.file_name().map(|n| n.to_string_lossy().into_owned()).unwrap_or_default();
        let prefix = format!(".{name}.");
        let mut builder = tempfile::Builder::new();
        builder.prefix(&prefix).suffix(".partial");
        // A package is an ordinary file: 0666 minus the umask, not tempfile's private 0600.
        #[cfg(unix)]
        builder.permissions(std::os::unix::fs::PermissionsExt::from_mode(0o666));
        let temp = builder.tempfile_in(&dir).map_err(|source| Error::Io {
            path: target.clone(),
            op: "create a temp file beside",
            source,
        })?;
        let (file, temp) = temp.into_parts();
        let mut w = Self {
            target,
            temp,
            out: BufWriter::with_capacity(1 << 20, file),
            pos: 0,
            sections: Vec::new(),
            keys: HashSet::new(),
            tiles: Vec::new(),
        };
        // Placeholder header, rewritten by finish().
        w.write_all(&[0u8; size_of::<RawHeader>()])?;
        Ok(w)
    }

    fn io(&self, op: &'static str) -> impl FnOnce(std::io::Error) -> Error + '_ {
        move |source| Error::Io { path: self.target.clone(), op, source }
    }

    fn refuse(&self, reason: String) -> Error {
        Error::Write { path: self.target.clone(), reason }
    }

    fn write_all(&mut self, bytes: &[u8]) -> Result<()> {
        self.out.write_all(bytes).map_err(|source| Error::Io {
            path: self.target.clone(),
            op: "write",
            source,
        })?;
        self.pos += bytes.len() as u64;
        Ok(())
    }

    fn pad_to(&mut self, align: u64) -> Result<()> {
        let pad = self.pos.next_multiple_of(align) - self.pos;
        self.write_all(&vec![0u8; pad as usize])
    }

    /// Adds a tile to the directory and returns its index.
    pub fn add_tile(&mut self, info: TileInfo) -> Result<u32> {
        if !(info.origin_m.iter().all(|v| v.is_finite()) && info.extent_m.is_finite() && info.extent_m > 0.0)
        {
            return Err(self.refuse(format!(
                "tile origin {:?} / extent {} is not finite",
                info.origin_m, info.extent_m
            )));
        }
        if info.depth > MAX_SVO_DEPTH {
            return Err(self.refuse(format!("SVO depth {} exceeds {MAX_SVO_DEPTH}", info.depth)));
        }
        if self.tiles.len() as u64 >= u64::from(GLOBAL) - 1 {
            return Err(self.refuse("too many tiles".into()));
        }
        self.tiles.push(info);
        Ok(self.tiles.len() as u32 - 1)
    }

    /// Appends a section of a known kind. `bytes` must be whole elements of the kind.
    pub fn add_section(
        &mut self,
        kind: SectionKind,
        scope: Scope,
        item: u32,
        bytes: &[u8],
        compression: Compression,
    ) -> Result<u32> {
        let element = kind.element().size();
        if !bytes.len().is_multiple_of(element) {
            return Err(self.refuse(format!(
                "{} is {} bytes, not whole {element}-byte elements",
                kind.name(),
                bytes.len()
            )));
        }
        match (kind.is_per_tile(), scope) {
            (true, Scope::Global) => return Err(self.refuse(format!("{} belongs to a tile", kind.name()))),
            (false, Scope::Tile(_)) => {
                return Err(self.refuse(format!("{} belongs to the package", kind.name())));
            }
            _ => {}
        }
        self.add_raw_section(kind as u32, scope, item, bytes, compression)
    }

    /// Appends a section of any kind number, known or not (used to test forward compatibility).
    pub fn add_raw_section(
        &mut self,
        kind: u32,
        scope: Scope,
        item: u32,
        bytes: &[u8],
        compression: Compression,
    ) -> Result<u32> {
        let tile = match scope {
            Scope::Global => GLOBAL,
            Scope::Tile(t) if (t as usize) < self.tiles.len() => t,
            Scope::Tile(t) => return Err(self.refuse(format!("section for tile {t}, which was not added"))),
        };
        self.check_one_surfel_section(kind, tile)?;
        if !self.keys.insert((kind, tile, item)) {
            return Err(self
                .refuse(format!("a section of kind {kind} for tile {tile:#x} item {item} exists already")));
        }
        let compressed = match compression {
            Compression::Raw => None,
            Compression::Zstd(level) | Compression::Auto(level) => {
                let c = zstd::bulk::compress(bytes, level).map_err(self.io("compress a section for"))?;
                let pays = c.len() as u64 * 8 <= bytes.len() as u64 * 7;
                (matches!(compression, Compression::Zstd(_)) || pays).then_some(c)
            }
        };
        let (codec, stored) = match &compressed {
            Some(c) => (Codec::Zstd, c.as_slice()),
            None => (Codec::Raw, bytes),
        };
        self.pad_to(SECTION_ALIGN)?;
        let entry = RawSectionEntry {
            kind,
            codec: codec as u32,
            tile,
            item,
            offset: self.pos,
            stored_len: stored.len() as u64,
            raw_len: bytes.len() as u64,
            checksum: xxh3_64(stored),
        };
        self.write_all(stored)?;
        self.sections.push(entry);
        Ok(self.sections.len() as u32 - 1)
    }

    /// Copies a section of another package as stored (no re-encoding), after checking its checksum
    /// and content, into `scope` here. This is how per-tile packages are assembled into one.
    pub fn copy_section(
        &mut self,
        from: &crate::reader::Package,
        section: &crate::section::SectionInfo,
        scope: Scope,
    ) -> Result<u32> {
        let kind = section
            .kind
            .ok_or_else(|| self.refuse(format!("cannot copy {} (unknown kind)", section.kind_name())))?;
        // Checks checksum and content (decoding zstd once, unless `from` checked it already), so
        // damage is not carried over.
        from.check(section)?;
        match (kind.is_per_tile(), scope) {
            (true, Scope::Global) | (false, Scope::Tile(_)) => {
                return Err(self.refuse(format!("{} cannot go to {scope:?}", kind.name())));
            }
            _ => {}
        }
        let tile = match scope {
            Scope::Global => GLOBAL,
            Scope::Tile(t) if (t as usize) < self.tiles.len() => t,
            Scope::Tile(t) => return Err(self.refuse(format!("section for tile {t}, which was not added"))),
        };
        self.check_one_surfel_section(kind as u32, tile)?;
        if !self.keys.insert((kind as u32, tile, section.item)) {
            return Err(self.refuse(format!(
                "a {} section for tile {tile:#x} item {} exists already",
                kind.name(),
                section.item
            )));
        }
        let stored = from.stored_bytes(section)?;
        self.pad_to(SECTION_ALIGN)?;
        let entry = RawSectionEntry {
            kind: kind as u32,
            codec: section.codec.map_or(Codec::Raw as u32, |c| c as u32),
            tile,
            item: section.item,
            offset: self.pos,
            stored_len: section.stored_len,
            raw_len: section.raw_len,
            checksum: section.checksum,
        };
        self.write_all(stored)?;
        self.sections.push(entry);
        Ok(self.sections.len() as u32 - 1)
    }

    /// A tile stores its surfels one way: full or compact, not both.
    fn check_one_surfel_section(&self, kind: u32, tile: u32) -> Result<()> {
        let (full, compact) = (SectionKind::Surfels as u32, SectionKind::SurfelsCompact as u32);
        let other = match kind {
            k if k == full => compact,
            k if k == compact => full,
            _ => return Ok(()),
        };
        if self.keys.contains(&(other, tile, 0)) {
            return Err(self.refuse(format!("tile {tile} already has its surfels in the other encoding")));
        }
        Ok(())
    }

    /// Adds a section of typed elements.
    pub fn add_elements<T: bytemuck::Pod>(
        &mut self,
        kind: SectionKind,
        scope: Scope,
        item: u32,
        elements: &[T],
        compression: Compression,
    ) -> Result<u32> {
        if size_of::<T>() != kind.element().size() {
            return Err(self.refuse(format!("{} elements are not {} bytes", kind.name(), size_of::<T>())));
        }
        self.add_section(kind, scope, item, bytemuck::cast_slice(elements), compression)
    }

    /// Adds the scene (JSON); returns its section index.
    pub fn add_scene(&mut self, scene: &Scene) -> Result<u32> {
        scene.check().map_err(|r| self.refuse(format!("scene: {r}")))?;
        let json = serde_json::to_vec(scene).map_err(|e| self.refuse(format!("scene: {e}")))?;
        self.add_section(SectionKind::Scene, Scope::Global, 0, &json, Compression::Auto(3))
    }

    /// Adds the provenance (JSON); returns its section index.
    pub fn add_provenance(&mut self, provenance: &Provenance) -> Result<u32> {
        let json = serde_json::to_vec(provenance).map_err(|e| self.refuse(format!("provenance: {e}")))?;
        self.add_section(SectionKind::Provenance, Scope::Global, 0, &json, Compression::Auto(3))
    }

    /// Adds the survey's centreline (JSON); returns its section index.
    pub fn add_survey(&mut self, survey: &crate::survey::Survey) -> Result<u32> {
        survey.check().map_err(|r| self.refuse(format!("survey: {r}")))?;
        let json = serde_json::to_vec(survey).map_err(|e| self.refuse(format!("survey: {e}")))?;
        self.add_section(SectionKind::Survey, Scope::Global, 0, &json, Compression::Auto(3))
    }

    /// Writes the table, directory and header, syncs, and atomically moves the package into place.
    pub fn finish(mut self) -> Result<PathBuf> {
        // The table lists global sections first, then each tile's run; file order stays as written.
        let mut order: Vec<usize> = (0..self.sections.len()).collect();
        order.sort_by_key(|&i| (self.sections[i].tile != GLOBAL, self.sections[i].tile, i));
        let table: Vec<RawSectionEntry> = order.iter().map(|&i| self.sections[i]).collect();
        let mut tiles: Vec<RawTileEntry> = self
            .tiles
            .iter()
            .map(|t| RawTileEntry {
                origin_m: t.origin_m,
                extent_m: t.extent_m,
                grid: t.grid,
                depth: t.depth,
                point_count: t.point_count,
                section_first: 0,
                section_count: 0,
            })
            .collect();
        for (i, e) in table.iter().enumerate() {
            if e.tile != GLOBAL {
                let t = &mut tiles[e.tile as usize];
                if t.section_count == 0 {
                    t.section_first = i as u32;
                }
                t.section_count += 1;
            }
        }
        self.pad_to(SECTION_ALIGN)?;
        let section_table_offset = self.pos;
        self.write_all(bytemuck::cast_slice(&table))?;
        let tile_directory_offset = self.pos;
        self.write_all(bytemuck::cast_slice(&tiles))?;
        let mut h = Xxh3::new();
        h.update(bytemuck::cast_slice(&table));
        h.update(bytemuck::cast_slice(&tiles));
        // 2.0 only where a section needs it, so 1.x readers keep opening everything else.
        let (version_major, version_minor) =
            if table.iter().any(|e| e.kind == SectionKind::SurfelsCompact as u32) {
                (VERSION_MAJOR, VERSION_MINOR)
            } else {
                VERSION_1
            };
        let mut header = RawHeader {
            magic: MAGIC,
            version_major,
            version_minor,
            header_size: size_of::<RawHeader>() as u32,
            section_count: table.len() as u64,
            section_table_offset,
            tile_count: tiles.len() as u64,
            tile_directory_offset,
            file_size: self.pos,
            table_checksum: h.digest(),
            header_checksum: 0,
        };
        header.header_checksum = xxh3_64(bytemuck::bytes_of(&header));
        let mut file = self.out.into_inner().map_err(|e| Error::Io {
            path: self.target.clone(),
            op: "flush",
            source: e.into_error(),
        })?;
        let io = |op, source| Error::Io { path: self.target.clone(), op, source };
        file.seek(SeekFrom::Start(0)).map_err(|e| io("seek", e))?;
        file.write_all(bytemuck::bytes_of(&header)).map_err(|e| io("write the header of", e))?;
        file.sync_all().map_err(|e| io("sync", e))?;
        drop(file);
        self.temp.persist(&self.target).map_err(|e| io("rename the finished temp file to", e.error))?;
        sync_parent_dir(&self.target);
        Ok(self.target)
    }
}

/// Makes the rename durable. Best effort: not every platform or filesystem can sync a directory,
/// and the package is complete either way.
fn sync_parent_dir(path: &Path) {
    #[cfg(unix)]
    if let Some(dir) = path.parent().filter(|p| !p.as_os_str().is_empty()) {
        let _ = File::open(dir).and_then(|d| d.sync_all());
    }
    #[cfg(not(unix))]
    let _ = path;
}
