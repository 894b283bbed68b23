//! The crate's one error type. Every error names the package it is about; structural problems are a
//! separate enum ([`Problem`]) so tests and callers can match on exactly what was wrong.

use std::fmt;
use std::path::PathBuf;

/// A region of the file, for messages about bounds and overlaps.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum Region {
    Header,
    SectionTable,
    TileDirectory,
    Section(u32),
    /// Bytes fetched for a package read over HTTP.
    Fetched,
}

impl fmt::Display for Region {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        match self {
            Self::Header => f.write_str("header"),
            Self::SectionTable => f.write_str("section table"),
            Self::TileDirectory => f.write_str("tile directory"),
            Self::Section(i) => write!(f, "section {i}"),
            Self::Fetched => f.write_str("fetched range"),
        }
    }
}

/// What is wrong with a package's bytes. `Clone` so a failed lazy check can be cached and reported
/// again without re-reading.
#[derive(Clone, Debug, PartialEq, Eq, thiserror::Error)]
#[non_exhaustive]
pub enum Problem {
    #[error("file is {len} bytes, shorter than the {needed}-byte header")]
    TooShort { len: u64, needed: u64 },
    #[error("not a grotto package (magic bytes {found:02x?}){}", scan_hint(.found))]
    BadMagic { found: [u8; 8] },
    #[error(
        "package format {found_major}.{found_minor} is not one this reader opens (1.x to {supported_major}.{supported_minor}); a newer package needs a newer grotto"
    )]
    UnsupportedVersion { found_major: u16, found_minor: u16, supported_major: u16, supported_minor: u16 },
    #[error("header size {header_size} is invalid (minimum {minimum}, file is {file_len} bytes)")]
    BadHeaderSize { header_size: u32, minimum: u32, file_len: u64 },
    #[error("header checksum mismatch (stored {stored:016x}, computed {computed:016x})")]
    HeaderChecksum { stored: u64, computed: u64 },
    #[error("file is {actual} bytes but its header says {expected}: truncated or extended")]
    Truncated { expected: u64, actual: u64 },
    #[error("{what} overflows 64-bit arithmetic")]
    Overflow { what: String },
    #[error("{region} ({offset}..+{len}) lies outside the {file_len}-byte file")]
    OutOfBounds { region: Region, offset: u64, len: u64, file_len: u64 },
    #[error("{region} at offset {offset} is not aligned to {align} bytes")]
    Misaligned { region: Region, offset: u64, align: u64 },
    #[error("{first} and {second} overlap")]
    Overlap { first: Region, second: Region },
    #[error(
        "section table / tile directory checksum mismatch (stored {stored:016x}, computed {computed:016x})"
    )]
    TableChecksum { stored: u64, computed: u64 },
    #[error("section {section} ({kind}) uses unknown codec {codec}")]
    UnknownCodec { section: u32, kind: String, codec: u32 },
    #[error("section {section} ({kind}) is raw but its stored length {stored} differs from its length {raw}")]
    RawLengthMismatch { section: u32, kind: String, stored: u64, raw: u64 },
    #[error(
        "section {section} ({kind}) claims {raw} bytes from {stored} compressed bytes, more than zstd can expand"
    )]
    ImplausibleLength { section: u32, kind: String, stored: u64, raw: u64 },
    #[error("section {section} ({kind}) is {len} bytes, not a multiple of its {element_size}-byte element")]
    BadElementLength { section: u32, kind: String, len: u64, element_size: usize },
    #[error("section {section} ({kind}) belongs to {found} but must be {expected}")]
    WrongScope { section: u32, kind: String, found: String, expected: &'static str },
    #[error("section {section} names tile {tile} but the package has {tile_count} tiles")]
    NoSuchTile { section: u32, tile: u32, tile_count: u64 },
    #[error("section {section} (tile {tile}) is outside that tile's run in the section table")]
    SectionOutsideTileRun { section: u32, tile: u32 },
    #[error("tile {tile}: {reason}")]
    BadTile { tile: u32, reason: String },
    #[error("sections {first} and {second} are both {kind} for {scope} item {item}")]
    DuplicateSection { first: u32, second: u32, kind: String, scope: String, item: u32 },
    #[error("section {section} ({kind}) checksum mismatch (stored {stored:016x}, computed {computed:016x})")]
    SectionChecksum { section: u32, kind: String, stored: u64, computed: u64 },
    #[error("section {section} ({kind}) does not decompress: {message}")]
    Decompress { section: u32, kind: String, message: String },
    #[error("section {section} ({kind}) has invalid content: {reason}")]
    BadContent { section: u32, kind: String, reason: String },
    #[error("section {section} holds {kind}, not {requested:?}")]
    WrongElementType { section: u32, kind: String, requested: crate::spec::ElementType },
    #[error("the package has no {kind} section{scope}")]
    Missing { kind: String, scope: String },
}

/// The error of every fallible operation in this crate.
#[derive(Debug, thiserror::Error)]
#[non_exhaustive]
pub enum Error {
    /// The package's bytes are malformed.
    #[error("{path}: {problem}")]
    Invalid { path: PathBuf, problem: Problem },
    /// Reading or writing the file failed. The OS error is the `source` (printed by `{:#}` chains).
    #[error("{path}: cannot {op}")]
    Io { path: PathBuf, op: &'static str, source: std::io::Error },
    /// The writer was asked to write something the format cannot hold.
    #[error("{path}: cannot write: {reason}")]
    Write { path: PathBuf, reason: String },
    /// A section of a package read over HTTP whose bytes have not arrived yet
    /// (`Package::from_directory`): the reader fetches `Package::missing` first.
    #[error("{path}: section {section} ({kind}, {offset}..+{len}) has not been fetched")]
    NotFetched { path: PathBuf, section: u32, kind: String, offset: u64, len: u64 },
}

impl Error {
    /// The structural problem, when there is one.
    pub fn problem(&self) -> Option<&Problem> {
        match self {
            Self::Invalid { problem, .. } => Some(problem),
            _ => None,
        }
    }
}

/// The format crate's result: [`Error`] names the package and what is wrong with it.
pub type Result<T, E = Error> = std::result::Result<T, E>;

/// Which scan format a file's first bytes name ("LAS/LAZ", "PLY", "E57"), if any: for a scan
/// given where a package was expected (a user's first try, `grotto render scan.laz`).
pub fn scan_format(first_bytes: &[u8]) -> Option<&'static str> {
    if first_bytes.starts_with(b"LASF") {
        Some("LAS/LAZ")
    } else if first_bytes.starts_with(b"ply\n") || first_bytes.starts_with(b"ply\r") {
        Some("PLY")
    } else if first_bytes.starts_with(b"ASTM-E57") {
        Some("E57")
    } else {
        None
    }
}

/// The bad-magic message's tail for a scan: which format it is and the command that packs it.
fn scan_hint(magic: &[u8; 8]) -> String {
    scan_format(magic).map_or_else(String::new, |kind| {
        let article = if kind == "E57" { "an" } else { "a" };
        format!("; it is {article} {kind} scan: make a package of it first with `grotto-pack build FILE -o FILE.grotto`")
    })
}

#[cfg(test)]
mod scan_hint_tests {
    use super::Problem;

    #[test]
    fn a_scan_where_a_package_was_expected_is_named_with_the_command_that_packs_it() {
        for (magic, kind) in [(*b"LASF\0\0\0\0", "LAS/LAZ"), (*b"ply\nform", "PLY"), (*b"ASTM-E57", "E57")] {
            let message = Problem::BadMagic { found: magic }.to_string();
            assert!(message.starts_with("not a grotto package"), "{message}");
            assert!(message.contains(kind) && message.contains("grotto-pack build FILE"), "{message}");
        }
        let other = Problem::BadMagic { found: *b"GIF89a\0\0" }.to_string();
        assert!(!other.contains("grotto-pack"), "{other}");
    }
}
