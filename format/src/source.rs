//! Where a package's bytes live: a read-only memory map of the file, or an owned, 64-byte-aligned
//! copy. Both hand out one `&[u8]` whose base is aligned to at least [`crate::spec::SECTION_ALIGN`],
//! so validated raw sections can be cast in place.
//!
//! This module holds the crate's only `unsafe` (the map). Audit note: a memory map is undefined
//! behaviour in Rust if another process truncates or rewrites the file while it is mapped. grotto
//! never modifies a package in place: the writer builds a temp file and renames it over the target,
//! so a mapped old version keeps its inode. A user who edits a package in place with another tool
//! while it is open is outside what this can guard against (as with every mmap-based reader).
#![allow(unsafe_code)]

use std::fs::File;

use bytemuck::{Pod, Zeroable};

/// 64 bytes with 64-byte alignment: the unit of the owned backing store.
#[repr(C, align(64))]
#[derive(Clone, Copy, Pod, Zeroable)]
pub(crate) struct Align64([u8; 64]);

pub(crate) enum Backing {
    Mapped(memmap2::Mmap),
    Owned { blocks: Vec<Align64>, len: usize },
}

impl std::fmt::Debug for Backing {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        match self {
            Self::Mapped(m) => write!(f, "Mapped({} bytes)", m.len()),
            Self::Owned { len, .. } => write!(f, "Owned({len} bytes)"),
        }
    }
}

impl Backing {
    pub(crate) fn map(file: &File) -> std::io::Result<Self> {
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
        let mut blocks = vec![Align64([0; 64]); bytes.len().div_ceil(64)];
        bytemuck::cast_slice_mut::<Align64, u8>(&mut blocks)[..bytes.len()].copy_from_slice(bytes);
        Self::Owned { blocks, len: bytes.len() }
    }

    pub(crate) fn bytes(&self) -> &[u8] {
        match self {
            Self::Mapped(m) => m,
            Self::Owned { blocks, len } => &bytemuck::cast_slice::<Align64, u8>(blocks)[..*len],
        }
    }
}
