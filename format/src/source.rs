//! Where a package's bytes live: a read-only memory map of the file, an owned, 64-byte-aligned
//! copy, or the parts of a file fetched so far (a browser reads a package by HTTP range requests,
//! the directory first, then the sections a view needs). Each hands out slices whose base is
//! aligned to at least [`crate::spec::SECTION_ALIGN`] at every 64-aligned file offset, so validated
//! raw sections can be cast in place.
//!
//! This module holds the crate's only `unsafe` (the map, and the advice that hands its read pages
//! back to the kernel). Audit note: a memory map is undefined behaviour in Rust if another process
//! truncates or rewrites the file while it is mapped. grotto never modifies a package in place:
//! the writer builds a temp file and renames it over the target, so a mapped old version keeps its
//! inode. A user who edits a package in place with another tool while it is open is outside what
//! this can guard against (as with every mmap-based reader).
#![allow(unsafe_code)]

use std::collections::BTreeMap;

use bytemuck::{Pod, Zeroable};

/// 64 bytes with 64-byte alignment: the unit of the owned backing store.
#[repr(C, align(64))]
#[derive(Clone, Copy, Pod, Zeroable)]
pub(crate) struct Align64([u8; 64]);

/// Bytes copied into 64-byte-aligned storage.
pub(crate) struct Aligned {
    blocks: Vec<Align64>,
    len: usize,
}

impl Aligned {
    pub(crate) fn copy_of(bytes: &[u8]) -> Self {
        let mut blocks = vec![Align64([0; 64]); bytes.len().div_ceil(64)];
        bytemuck::cast_slice_mut::<Align64, u8>(&mut blocks)[..bytes.len()].copy_from_slice(bytes);
        Self { blocks, len: bytes.len() }
    }

    fn bytes(&self) -> &[u8] {
        &bytemuck::cast_slice::<Align64, u8>(&self.blocks)[..self.len]
    }
}

pub(crate) enum Backing {
    #[cfg(not(target_arch = "wasm32"))]
    Mapped(memmap2::Mmap),
    Owned(Aligned),
    /// Pieces of the file by their offset (a multiple of 64, so alignment carries over).
    Sparse(BTreeMap<u64, Aligned>),
}

impl std::fmt::Debug for Backing {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        match self {
            #[cfg(not(target_arch = "wasm32"))]
            Self::Mapped(m) => write!(f, "Mapped({} bytes)", m.len()),
            Self::Owned(a) => write!(f, "Owned({} bytes)", a.len),
            Self::Sparse(p) => {
                write!(f, "Sparse({} pieces, {} bytes)", p.len(), p.values().map(|a| a.len).sum::<usize>())
            }
        }
    }
}

impl Backing {
    #[cfg(not(target_arch = "wasm32"))]
    pub(crate) fn map(file: &std::fs::File) -> std::io::Result<Self> {
        // SAFETY: the map is read-only and lives as long as `Backing`; see the module note on
        // concurrent modification, the one hazard a map carries.
        let map = unsafe { memmap2::MmapOptions::new().map(file)? };
        #[cfg(unix)]
        {
            // Sections are read where the runtime needs them, not front to back.
            let _ = map.advise(memmap2::Advice::Random);
        }
        Ok(Self::Mapped(map))
    }

    pub(crate) fn copy_of(bytes: &[u8]) -> Self {
        Self::Owned(Aligned::copy_of(bytes))
    }

    /// The whole file, where it is all here.
    pub(crate) fn whole(&self) -> Option<&[u8]> {
        match self {
            #[cfg(not(target_arch = "wasm32"))]
            Self::Mapped(m) => Some(m),
            Self::Owned(a) => Some(a.bytes()),
            Self::Sparse(_) => None,
        }
    }

    /// The bytes `offset..offset + len` of the file, where they are here. A caller checked the
    /// range against the file's length.
    pub(crate) fn range(&self, offset: u64, len: u64) -> Option<&[u8]> {
        let end = offset.checked_add(len)?;
        match self {
            Self::Sparse(pieces) => pieces.range(..=offset).rev().find_map(|(&start, piece)| {
                let bytes = piece.bytes();
                (start + bytes.len() as u64 >= end)
                    .then(|| &bytes[(offset - start) as usize..(end - start) as usize])
            }),
            whole => whole.whole()?.get(offset as usize..end as usize),
        }
    }

    /// Adds a piece at `offset` (a multiple of 64) to a sparse backing; whole files have every
    /// byte already.
    pub(crate) fn insert(&mut self, offset: u64, bytes: &[u8]) {
        if let Self::Sparse(pieces) = self {
            let longer = pieces.get(&offset).is_none_or(|p| p.len < bytes.len());
            if longer {
                pieces.insert(offset, Aligned::copy_of(bytes));
            }
        }
    }

    /// Lets go of a sparse backing's pieces that overlap none of `keep` (file byte ranges) and
    /// returns their bytes; a whole file keeps every byte.
    pub(crate) fn release_except(&mut self, keep: &[std::ops::Range<u64>]) -> u64 {
        let Self::Sparse(pieces) = self else { return 0 };
        let before: u64 = pieces.values().map(|a| a.len as u64).sum();
        pieces.retain(|&start, piece| {
            let end = start + piece.len as u64;
            keep.iter().any(|k| k.start < end && start < k.end)
        });
        before - pieces.values().map(|a| a.len as u64).sum::<u64>()
    }

    /// Hands the pages of a map back to the kernel: they count in the process's resident memory
    /// once read, until the kernel needs them. Nothing changes for a reader: a page is read from
    /// the file again (usually from the page cache) when next touched. A copy or pieces keep their
    /// bytes. Returns whether the pages were handed back.
    pub(crate) fn release_mapped_pages(&self) -> bool {
        match self {
            #[cfg(all(unix, not(target_arch = "wasm32")))]
            // SAFETY: `MADV_DONTNEED` is unchecked in memmap2 because on a private or anonymous
            // map it discards writes. This map is shared, read-only and of a file grotto never
            // changes in place (module note): a page dropped is read back from the file unchanged,
            // so slices handed out before stay valid and read the same bytes.
            Self::Mapped(m) => unsafe { m.unchecked_advise(memmap2::UncheckedAdvice::DontNeed).is_ok() },
            _ => false,
        }
    }

    /// Bytes held in memory (all of a copy, the pieces of a sparse file; a map holds none).
    pub(crate) fn held_bytes(&self) -> u64 {
        match self {
            #[cfg(not(target_arch = "wasm32"))]
            Self::Mapped(_) => 0,
            Self::Owned(a) => a.len as u64,
            Self::Sparse(p) => p.values().map(|a| a.len as u64).sum(),
        }
    }
}
