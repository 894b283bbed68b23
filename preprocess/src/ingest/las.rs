//! LAS 1.0-1.4 (point formats 0-10) and LAZ, through the `las` crate (parallel LAZ decoding).
//! Normals stored in the extra bytes (LAS 1.4 "Extra Bytes" descriptors named NormalX/nx/...) are
//! read with their data type, scale and offset.
//!
//! Colours: LAS stores 16-bit RGB, but many writers put 8-bit values in those fields. The first
//! [`COLOR_PROBE`] points decide: if no channel exceeds 255 the file is taken as 8-bit. Files
//! without colour get their intensity as grey (its 99th percentile over the probe as white), or a
//! neutral grey. The probe is the source's first batch of points, decoded once (a second reader
//! for it decoded 2^20 LAZ points twice on every open); a source opened for positions alone
//! ([`super::open_positions`]) skips it.

use std::fs::File;
use std::io::BufReader;
use std::path::Path;

use las::{LazParallelism, PointData, Reader, ReaderOptions};

use crate::Result;
use crate::ingest::source::{
    NEUTRAL_GREY, PointChunk, PointSource, ScanFormat, SourceInfo, guard, read_error,
};

const COLOR_PROBE: u64 = 1 << 20;

pub(super) struct LasSource {
    info: SourceInfo,
    reader: Reader,
    data: PointData,
    remaining: u64,
    /// Set when the decoder panicked; its state is not trusted again.
    poisoned: bool,
    /// Decoded points not yet handed out (LAZ decodes several chunks at once).
    batch_xyz: Vec<[f64; 3]>,
    batch_rgb: Vec<[u8; 3]>,
    batch_normal: Vec<[f32; 3]>,
    cursor: usize,
    /// Where a normal sits in each record's extra bytes, when the file stores one there.
    normal_fields: Option<[ExtraField; 3]>,
    /// Set by the first batch (the probe), unless opened for positions alone.
    scales: Option<Scales>,
}

#[derive(Clone, Copy, Debug)]
struct Scales {
    /// Divide raw colour by this to get 0..=255.
    color_div: f32,
    /// Divisor of intensity to an 8-bit grey (its 99th percentile maps to 255); `None` when the
    /// file has no intensity (all zero).
    grey_div: Option<f32>,
}

/// A `las` reader; call only after [`preflight`] accepted the file.
fn open_reader(path: &Path, format: ScanFormat) -> Result<Reader> {
    guard(path, format, || open_reader_unguarded(path, format))
}

/// Points the header claims and whether the format has colour, from the raw header.
fn claimed_and_color(raw: &las::raw::Header) -> (u64, bool) {
    let claimed = raw.large_file.map_or(u64::from(raw.number_of_point_records), |l| {
        l.number_of_point_records.max(u64::from(raw.number_of_point_records))
    });
    let has_color = las::point::Format::new(raw.point_data_record_format & 0x3F).is_ok_and(|f| f.has_color);
    (claimed, has_color)
}

/// What the header says, without decoding points.
pub(super) fn header_info(path: &Path, format: ScanFormat) -> Result<SourceInfo> {
    let (raw, dropped_points) = preflight(path, format)?;
    let (claimed, has_color) = claimed_and_color(&raw);
    Ok(SourceInfo {
        path: path.to_path_buf(),
        format,
        name: path.file_stem().map(|s| s.to_string_lossy().into_owned()).unwrap_or_default(),
        claimed_points: claimed - dropped_points,
        has_color,
        has_normals: false,
        dropped_points,
        file_pose: None,
    })
}

/// Walks the header, VLR and EVLR records with checked arithmetic against the file's length before
/// the `las` crate sees the file: it sizes record buffers from their length fields, so a lying
/// length (found by fuzzing: 7e18 bytes) would abort the process on allocation, which no error
/// handling can catch.
///
/// Also refuses an uncompressed file that cannot hold the records its header claims, except one
/// that ends inside its last record. Returns the raw header and the points dropped (1 for such a
/// file, else 0).
fn preflight(path: &Path, format: ScanFormat) -> Result<(las::raw::Header, u64)> {
    let err = |reason: String| read_error(path, format, reason);
    let mut file = File::open(path).map_err(|e| err(e.to_string()))?;
    let file_len = file.metadata().map_err(|e| err(e.to_string()))?.len();
    let raw = las::raw::Header::read_from(BufReader::new(&file)).map_err(|e| err(e.to_string()))?;
    let offset = u64::from(raw.offset_to_point_data);
    if offset > file_len || u64::from(raw.header_size) > offset {
        return Err(err(format!(
            "header says points start at byte {offset} (header {} bytes) in a {file_len}-byte file",
            raw.header_size
        )));
    }
    let (claimed, _) = claimed_and_color(&raw);
    let compressed = raw.point_data_record_format & 0xC0 != 0;
    let dropped = if compressed {
        0
    } else {
        records_dropped(claimed, u64::from(raw.point_data_record_length), offset, file_len).map_err(err)?
    };
    let mut walk = |start: u64, count: u64, header: u64, limit: u64, what: &str| {
        walk_records(&mut file, RecordArea { start, count, header, limit, what }).map_err(err)
    };
    let laszip = walk(
        u64::from(raw.header_size),
        u64::from(raw.number_of_variable_length_records),
        54,
        offset,
        "VLR",
    )?;
    if let Some(evlr) = raw.evlr {
        walk(evlr.start_of_first_evlr, u64::from(evlr.number_of_evlrs), 60, file_len, "EVLR")?;
    }
    if compressed && offset + 8 <= file_len {
        check_laz_tables(&mut file, path, format, LazArea { offset, file_len, claimed, laszip })?;
    }
    Ok((raw, dropped))
}

/// Points an uncompressed file of `file_len` bytes drops of the `claimed` records of `record`
/// bytes from `offset`: 0 when they fit, 1 for a file that ends inside its last record (a copy cut
/// short keeps its complete records); any other shortfall (a count that lies, records missing
/// whole) is refused.
fn records_dropped(
    claimed: u64,
    record: u64,
    offset: u64,
    file_len: u64,
) -> std::result::Result<u64, String> {
    if claimed.checked_mul(record).and_then(|b| b.checked_add(offset)).is_some_and(|n| n <= file_len) {
        return Ok(0);
    }
    let (complete, partial) = ((file_len - offset) / record.max(1), (file_len - offset) % record.max(1));
    if claimed >= 1 && complete == claimed - 1 && partial > 0 {
        Ok(1)
    } else {
        Err(format!(
            "header claims {claimed} points of {record} bytes, but the {file_len}-byte file holds at most {complete}"
        ))
    }
}

/// A run of variable-length records: `count` records from byte `start`, each a `header`-byte
/// header (54 for VLRs, with a u16 length at 20; 60 for EVLRs, with a u64 length at 20) and its
/// data, all before `limit`.
struct RecordArea<'a> {
    start: u64,
    count: u64,
    header: u64,
    limit: u64,
    what: &'a str,
}

/// Walks the records of `area` with checked arithmetic; returns where the LASzip VLR's data is
/// (offset and length), if there is one.
fn walk_records(file: &mut File, area: RecordArea<'_>) -> std::result::Result<Option<(u64, u64)>, String> {
    use std::io::{Read, Seek, SeekFrom};
    let RecordArea { start, count, header, limit, what } = area;
    let mut pos = start;
    let mut laszip = None;
    for i in 0..count {
        let end_of_header = pos.checked_add(header).filter(|&e| e <= limit);
        let Some(end_of_header) = end_of_header else {
            return Err(format!(
                "{what} {i} of {count} starts at byte {pos}, past the end of its area ({limit})"
            ));
        };
        let mut record = [0u8; 28];
        file.seek(SeekFrom::Start(pos)).map_err(|e| e.to_string())?;
        file.read_exact(&mut record).map_err(|e| e.to_string())?;
        let len = if header == 54 {
            u64::from(u16::from_le_bytes([record[20], record[21]]))
        } else {
            u64::from_le_bytes(record[20..28].try_into().expect("8 bytes"))
        };
        if record[2..16].starts_with(b"laszip encoded")
            && u16::from_le_bytes([record[18], record[19]]) == 22204
        {
            laszip = Some((end_of_header, len));
        }
        pos = end_of_header
            .checked_add(len)
            .filter(|&e| e <= limit)
            .ok_or_else(|| format!("{what} {i} claims {len} bytes, more than the file holds"))?;
    }
    Ok(laszip)
}

/// Where a LAZ file's points and LASzip VLR are, and what its header claims.
#[derive(Clone, Copy)]
struct LazArea {
    offset: u64,
    file_len: u64,
    claimed: u64,
    laszip: Option<(u64, u64)>,
}

/// LAZ: the chunk table's entry count sizes an allocation in the laz crate (found by fuzzing:
/// 58 GB). Every chunk takes at least a byte, so more chunks than bytes is a lie.
fn check_laz_tables(file: &mut File, path: &Path, format: ScanFormat, area: LazArea) -> Result<()> {
    use std::io::{Read, Seek, SeekFrom};
    let err = |reason: String| read_error(path, format, reason);
    let LazArea { offset, file_len, claimed, laszip } = area;
    let mut read_i64 = |at: u64| -> Option<i64> {
        let mut b = [0u8; 8];
        file.seek(SeekFrom::Start(at)).ok()?;
        file.read_exact(&mut b).ok()?;
        Some(i64::from_le_bytes(b))
    };
    let table = match read_i64(offset) {
        // Written last by streaming writers: the offset is then in the file's last 8 bytes.
        Some(-1) if file_len >= 8 => read_i64(file_len - 8),
        other => other,
    };
    if let Some(table) =
        table.and_then(|t| u64::try_from(t).ok()).filter(|&t| t.checked_add(8).is_some_and(|e| e <= file_len))
    {
        let mut b = [0u8; 4];
        if file.seek(SeekFrom::Start(table + 4)).is_ok() && file.read_exact(&mut b).is_ok() {
            let chunks = u64::from(u32::from_le_bytes(b));
            if chunks > file_len {
                return Err(err(format!("LAZ chunk table claims {chunks} chunks in a {file_len}-byte file")));
            }
        }
    }
    // The entries' byte counts size the parallel decoder's buffers (found by fuzzing: a 9 KB
    // file took 3.7 GB): together they cannot exceed the file.
    let Some((at, len)) = laszip.filter(|(_, len)| *len <= 1 << 16) else { return Ok(()) };
    let mut data = vec![0u8; len as usize];
    file.seek(SeekFrom::Start(at)).map_err(|e| err(e.to_string()))?;
    file.read_exact(&mut data).map_err(|e| err(e.to_string()))?;
    let (vlr, entries) = guard(path, format, || {
        let vlr = laz::LazVlr::read_from(&data[..]).map_err(|e| err(e.to_string()))?;
        let mut src = BufReader::new(&*file);
        src.seek(SeekFrom::Start(offset)).map_err(|e| err(e.to_string()))?;
        // A file without a readable chunk table is left to the decoder to refuse.
        let table = laz::laszip::ChunkTable::read_from(&mut src, &vlr).ok();
        Ok((vlr, table))
    })?;
    let Some(entries) = entries else { return Ok(()) };
    check_layered_chunks(file, offset + 8, entries.as_ref(), &vlr).map_err(err)?;
    // Per-chunk point counts size the decoder's output buffers (found by fuzzing: 142
    // GB). No chunk holds more points than the file claims, nor more than 256 points per
    // compressed byte (real LASzip stays far below 1 point per byte).
    // Fixed-size tables list every chunk at the declared chunk size (LASzip's default is
    // 50 000), even the last; a declared size beyond 5 million points is refused.
    let fixed = if vlr.uses_variable_size_chunks() { 0 } else { u64::from(vlr.chunk_size()) };
    if fixed > 5_000_000 {
        return Err(err(format!("LAZ chunk size {fixed} points is beyond any LASzip writer's")));
    }
    let allowed = claimed.max(fixed).max(1);
    for (i, c) in entries.as_ref().iter().enumerate() {
        if c.point_count > allowed || c.point_count > c.byte_count.saturating_mul(256).max(1) {
            return Err(err(format!(
                "LAZ chunk {i} claims {} points in {} bytes (the file claims {claimed})",
                c.point_count, c.byte_count
            )));
        }
    }
    let bytes = entries.as_ref().iter().try_fold(0u64, |acc, e| acc.checked_add(e.byte_count));
    if bytes.is_none_or(|b| b > file_len) {
        return Err(err(format!(
            "LAZ chunk table's {} chunks claim {} bytes in a {file_len}-byte file",
            entries.len(),
            bytes.map_or_else(|| "more than 2^64".into(), |b| b.to_string())
        )));
    }
    Ok(())
}

/// LAS 1.4 layered LAZ chunks start with the first point raw, a u32 point count and one u32 byte
/// size per layer; the laz crate allocates each size before reading it (found by fuzzing: 3.7 GB
/// for a 9 KB file). Each chunk's layers must fit in the chunk.
fn check_layered_chunks(
    file: &mut File,
    first_chunk: u64,
    entries: &[laz::laszip::ChunkTableEntry],
    vlr: &laz::LazVlr,
) -> std::result::Result<(), String> {
    use std::io::{Read, Seek, SeekFrom};

    use laz::LazItemType as T;
    let mut layers = 0u64;
    for item in vlr.items() {
        layers += match item.item_type() {
            T::Point14 => 9,
            T::RGB14 | T::WavePacket14 => 1,
            T::RGBNIR14 => 2,
            T::Byte14(n) => u64::from(n),
            // Pre-1.4 items are not layered.
            _ => return Ok(()),
        };
    }
    let first_point = vlr.items_size();
    let mut start = first_chunk;
    let mut sizes = vec![0u8; (layers * 4) as usize];
    for (i, chunk) in entries.iter().enumerate() {
        let header = first_point + 4 + layers * 4;
        if chunk.byte_count >= header
            && file.seek(SeekFrom::Start(start + first_point + 4)).is_ok()
            && file.read_exact(&mut sizes).is_ok()
        {
            let total: u64 = sizes
                .chunks_exact(4)
                .map(|b| u64::from(u32::from_le_bytes(b.try_into().expect("4 bytes"))))
                .sum();
            if header + total > chunk.byte_count {
                return Err(format!(
                    "LAZ chunk {i} declares {total} bytes of layers in a {}-byte chunk",
                    chunk.byte_count
                ));
            }
        }
        start = start.saturating_add(chunk.byte_count);
    }
    Ok(())
}

fn open_reader_unguarded(path: &Path, format: ScanFormat) -> Result<Reader> {
    let file = File::open(path).map_err(|e| read_error(path, format, e))?;
    Reader::with_options(BufReader::new(file), ReaderOptions::default().with_laz_parallelism(LazParallelism::Yes))
        .map_err(|e| {
            let message = e.to_string();
            if message.contains("PointWise") {
                // laz-rs reads only chunked LASzip streams; the old point-wise layout needs a
                // re-compression, which every LASzip-based tool does.
                read_error(path, format, "uses the non-chunked point-wise LASzip compressor, which is not supported; re-compress it (e.g. `laszip -i in.laz -o out.laz` or `pdal translate`)")
            } else {
                read_error(path, format, message)
            }
        })
}

impl LasSource {
    /// `probe`: tell 8-bit from 16-bit colour on the first batch; without it colours and
    /// intensities are taken as 8-bit (for callers that read positions only).
    pub(super) fn open(path: &Path, format: ScanFormat, probe: bool) -> Result<Self> {
        let info = header_info(path, format)?;
        let reader = open_reader(path, format)?;
        // Without the record the file cuts short (`SourceInfo::dropped_points`).
        let claimed = reader.header().number_of_points().saturating_sub(info.dropped_points);
        let point_format = *reader.header().point_format();
        let data = las::PointDataBuilder::new().for_header(reader.header()).build();
        let normal_fields = normal_fields(reader.header());
        Ok(Self {
            info: SourceInfo {
                claimed_points: claimed,
                has_color: point_format.has_color,
                has_normals: normal_fields.is_some(),
                ..info
            },
            reader,
            data,
            remaining: claimed,
            poisoned: false,
            batch_xyz: Vec::new(),
            batch_rgb: Vec::new(),
            batch_normal: Vec::new(),
            cursor: 0,
            normal_fields,
            scales: (!probe).then_some(Scales { color_div: 1.0, grey_div: None }),
        })
    }
}

/// One scalar of the LAS 1.4 "Extra Bytes" records, placed in a point record.
#[derive(Clone, Copy, Debug)]
struct ExtraField {
    /// Byte offset in the whole point record.
    at: usize,
    /// LAS extra-bytes data type (1..=10: u8, i8, u16, i16, u32, i32, u64, i64, f32, f64).
    kind: u8,
    scale: f64,
    offset: f64,
}

impl ExtraField {
    /// Byte size of a scalar data type.
    fn size(kind: u8) -> Option<usize> {
        match kind {
            1 | 2 => Some(1),
            3 | 4 => Some(2),
            5 | 6 | 9 => Some(4),
            7 | 8 | 10 => Some(8),
            _ => None,
        }
    }

    /// The value in `record` (its bounds were checked against the record length at open).
    fn read(&self, record: &[u8]) -> f64 {
        let b = |n: usize| &record[self.at..self.at + n];
        let raw = match self.kind {
            1 => f64::from(b(1)[0]),
            2 => f64::from(b(1)[0] as i8),
            3 => f64::from(u16::from_le_bytes([b(2)[0], b(2)[1]])),
            4 => f64::from(i16::from_le_bytes([b(2)[0], b(2)[1]])),
            5 => f64::from(u32::from_le_bytes(b(4).try_into().unwrap_or_default())),
            6 => f64::from(i32::from_le_bytes(b(4).try_into().unwrap_or_default())),
            7 => u64::from_le_bytes(b(8).try_into().unwrap_or_default()) as f64,
            8 => i64::from_le_bytes(b(8).try_into().unwrap_or_default()) as f64,
            9 => f64::from(f32::from_le_bytes(b(4).try_into().unwrap_or_default())),
            _ => f64::from_le_bytes(b(8).try_into().unwrap_or_default()),
        };
        raw * self.scale + self.offset
    }
}

/// The fields the "Extra Bytes" VLR (LAS 1.4 R15: user "LASF_Spec", record 4, 192-byte
/// descriptors laid out in order after the standard fields) describes: each descriptor with its
/// byte offset and size within the extra bytes. None when there is no such VLR or a descriptor's
/// type has no known size (the ones after it cannot be placed).
fn extra_layout(header: &las::Header) -> Option<Vec<(&[u8], usize, usize)>> {
    let vlr = header.all_vlrs().find(|v| v.user_id == "LASF_Spec" && v.record_id == 4)?;
    let mut at = 0usize;
    let mut out = Vec::new();
    for d in vlr.data.chunks_exact(192) {
        let (kind, options) = (d[2], d[3]);
        let size = match kind {
            // Undocumented bytes: the options field holds their count.
            0 => usize::from(options),
            1..=10 => ExtraField::size(kind)?,
            // Deprecated arrays of 2 or 3 scalars.
            11..=20 => ExtraField::size(kind - 10)? * 2,
            21..=30 => ExtraField::size(kind - 20)? * 3,
            _ => return None,
        };
        out.push((d, at, size));
        at += size;
    }
    Some(out)
}

/// The normal's three fields among a file's extra bytes ([`extra_layout`]), named as PDAL and
/// CloudCompare write them ("NormalX", "nx", "normal_x", any case), scalar types only. None when
/// the file has none.
fn normal_fields(header: &las::Header) -> Option<[ExtraField; 3]> {
    let format = header.point_format();
    let extra_len = usize::from(format.extra_bytes);
    // The extra bytes close each record.
    let extra_start = usize::from(format.len()) - extra_len;
    let mut found: [Option<ExtraField>; 3] = [None; 3];
    for (d, at, size) in extra_layout(header)? {
        let (kind, options) = (d[2], d[3]);
        let name: String = d[4..36]
            .iter()
            .take_while(|&&c| c != 0)
            .filter(|c| c.is_ascii_alphanumeric())
            .map(|c| c.to_ascii_lowercase() as char)
            .collect();
        let axis = match name.as_str() {
            "normalx" | "nx" => Some(0),
            "normaly" | "ny" => Some(1),
            "normalz" | "nz" => Some(2),
            _ => None,
        };
        if let Some(a) = axis
            && (1..=10).contains(&kind)
            && at + size <= extra_len
        {
            let f64_at = |o: usize| f64::from_le_bytes(d[o..o + 8].try_into().unwrap_or_default());
            // Options bit 3: scale given; bit 4: offset given.
            let scale = if options & 8 != 0 { f64_at(112) } else { 1.0 };
            let offset = if options & 16 != 0 { f64_at(136) } else { 0.0 };
            if scale.is_finite() && offset.is_finite() {
                found[a] = Some(ExtraField { at: extra_start + at, kind, scale, offset });
            }
        }
    }
    Some([found[0]?, found[1]?, found[2]?])
}

/// Tells 8-bit from 16-bit colour (and intensity) values by the first COLOR_PROBE points of
/// `data`, the source's first batch.
fn probe_scales(data: &PointData, has_color: bool) -> Scales {
    let probe = COLOR_PROBE as usize;
    let max_color =
        data.rgb().map_or(0, |rgb| rgb.take(probe).map(|(r, g, b)| r.max(g).max(b)).max().unwrap_or(0));
    let div = |max: u16| if max <= 255 { 1.0 } else { 257.0 };
    // Intensity is not calibrated: sensors write 8, 12 or 16 bits, or a range of their own (a
    // 16-bit scale made most of an airborne file with values up to 600 black). Its 99th
    // percentile over the probe is white.
    let mut intensity: Vec<u16> = data.intensity().take(probe).filter(|&i| i > 0).collect();
    let white = if intensity.is_empty() {
        0
    } else {
        let k = (intensity.len() - 1) * 99 / 100;
        *intensity.select_nth_unstable(k).1
    };
    Scales {
        color_div: if has_color { div(max_color) } else { 1.0 },
        grey_div: (white > 0).then(|| f32::from(white) / 255.0),
    }
}

impl PointSource for LasSource {
    fn info(&self) -> &SourceInfo {
        &self.info
    }

    fn fill_chunk(&mut self, chunk: &mut PointChunk) -> Result<usize> {
        chunk.clear();
        if self.cursor == self.batch_xyz.len() {
            // LASzip chunks hold 50 000 points: decoding several requests' worth at once lets the
            // parallel decoder spread chunks over the cores.
            let batch =
                if self.info.format == ScanFormat::Laz { chunk.limit() * LAZ_BATCH } else { chunk.limit() };
            self.decode_batch(batch)?;
        }
        let end = (self.cursor + chunk.limit()).min(self.batch_xyz.len());
        chunk.xyz.extend_from_slice(&self.batch_xyz[self.cursor..end]);
        chunk.rgb.extend_from_slice(&self.batch_rgb[self.cursor..end]);
        if !self.batch_normal.is_empty() {
            chunk.normal.extend_from_slice(&self.batch_normal[self.cursor..end]);
        }
        self.cursor = end;
        Ok(chunk.len())
    }
}

/// Requests' worth of points decoded at once from LAZ.
pub const LAZ_BATCH: usize = 8;

impl LasSource {
    fn decode_batch(&mut self, batch: usize) -> Result<()> {
        self.batch_xyz.clear();
        self.batch_rgb.clear();
        self.batch_normal.clear();
        self.cursor = 0;
        if self.remaining == 0 {
            return Ok(());
        }
        let done = self.info.claimed_points - self.remaining;
        let (path, format) = (&self.info.path, self.info.format);
        if self.poisoned {
            return Err(read_error(
                path,
                format,
                format!("after {done} points: reading stopped at corrupt data"),
            ));
        }
        // The first batch is the colour probe: at least COLOR_PROBE points.
        let batch = if self.scales.is_none() { batch.max(COLOR_PROBE as usize) } else { batch };
        let want = self.remaining.min(batch as u64);
        let (reader, data) = (&mut self.reader, &mut self.data);
        let n = guard(path, format, || {
            reader
                .fill_points(want, data)
                .map_err(|e| read_error(path, format, format!("after {done} points: {e}")))
        })
        .inspect_err(|_| self.poisoned = true)?;
        if n == 0 {
            return Err(read_error(
                path,
                format,
                format!("ends after {done} of the {} points its header claims", self.info.claimed_points),
            ));
        }
        self.remaining -= n;
        let data = &self.data;
        let Scales { color_div, grey_div } =
            *self.scales.get_or_insert_with(|| probe_scales(data, self.info.has_color));
        self.batch_xyz.extend(data.x().zip(data.y()).zip(data.z()).map(|((x, y), z)| [x, y, z]));
        if let Some(fields) = &self.normal_fields {
            self.batch_normal.extend(
                data.raw_bytes()
                    .chunks_exact(data.record_len())
                    .map(|rec| fields.each_ref().map(|f| f.read(rec) as f32)),
            );
        }
        let to_u8 = |v: u16, div: f32| (f32::from(v) / div).round().min(255.0) as u8;
        match data.rgb() {
            Some(rgb) => self.batch_rgb.extend(rgb.map(|(r, g, b)| [r, g, b].map(|c| to_u8(c, color_div)))),
            None => match grey_div {
                Some(div) => self.batch_rgb.extend(data.intensity().map(|i| [to_u8(i, div); 3])),
                None => self.batch_rgb.resize(self.batch_xyz.len(), NEUTRAL_GREY),
            },
        }
        Ok(())
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    /// One 192-byte extra-bytes descriptor.
    fn descriptor(name: &str, kind: u8, scale: Option<f64>) -> Vec<u8> {
        let mut d = vec![0u8; 192];
        d[2] = kind;
        d[3] = if scale.is_some() { 8 } else { 0 };
        d[4..4 + name.len()].copy_from_slice(name.as_bytes());
        if let Some(s) = scale {
            d[112..120].copy_from_slice(&s.to_le_bytes());
        }
        d
    }

    #[test]
    fn normals_in_extra_bytes_are_read_as_pdal_and_cloudcompare_write_them() {
        let dir = tempfile::tempdir().unwrap();
        // A user field first (so the normal's offsets must be summed), then nx as a scaled i16,
        // NormalY and normal_z as f32.
        let mut data = descriptor("Amplitude", 3, None);
        data.extend(descriptor("nx", 4, Some(1.0 / 32767.0)));
        data.extend(descriptor("NormalY", 9, None));
        data.extend(descriptor("normal_z", 9, None));
        let mut builder = las::Builder::from((1, 4));
        builder.point_format = las::point::Format::new(0).unwrap();
        builder.point_format.extra_bytes = 2 + 2 + 4 + 4;
        builder.vlrs.push(las::Vlr {
            user_id: "LASF_Spec".into(),
            record_id: 4,
            description: "extra bytes".into(),
            data,
        });
        let path = dir.path().join("normals.las");
        let want: Vec<[f32; 3]> = (0..50)
            .map(|i| {
                let a = i as f32 * 0.1;
                [a.cos() * 0.6, a.sin() * 0.6, 0.8]
            })
            .collect();
        {
            let mut w = las::Writer::from_path(&path, builder.into_header().unwrap()).unwrap();
            for (i, n) in want.iter().enumerate() {
                let mut extra = 7u16.to_le_bytes().to_vec();
                extra.extend(((n[0] * 32767.0).round() as i16).to_le_bytes());
                extra.extend(n[1].to_le_bytes());
                extra.extend(n[2].to_le_bytes());
                let p = las::Point { x: i as f64, y: 0.0, z: 1.0, extra_bytes: extra, ..Default::default() };
                w.write_point(p).unwrap();
            }
            w.close().unwrap();
        }
        let mut src = crate::ingest::open(&path, ScanFormat::Las, 0).unwrap();
        assert!(src.info().has_normals);
        let mut chunk = PointChunk::new(16);
        let mut got = Vec::new();
        while src.fill_chunk(&mut chunk).unwrap() > 0 {
            assert_eq!(chunk.normal.len(), chunk.len());
            got.extend_from_slice(&chunk.normal);
        }
        assert_eq!(got.len(), want.len());
        for (g, w) in got.iter().zip(&want) {
            for a in 0..3 {
                assert!((g[a] - w[a]).abs() < 1e-4, "{g:?} vs {w:?}");
            }
        }
    }

    #[test]
    fn extra_bytes_layouts_of_real_files_add_up_to_their_records() {
        // laspy's and lazrs's test files: a deprecated 3-array, undocumented bytes, scalars.
        let Some(data) = std::env::var_os("GROTTO_SHARED_DATA")
            .map(std::path::PathBuf::from)
            .or_else(|| Some(Path::new(env!("CARGO_MANIFEST_DIR")).join("../../shared/data")))
            .filter(|d| d.is_dir())
        else {
            assert!(std::env::var_os("GROTTO_SKIP_SHARED_DATA").is_some(), "../shared/data is missing");
            return;
        };
        for name in ["laspy_extrabytes.las", "lazrs_extra-bytes.las", "lazrs_extra-bytes.laz"] {
            let path = data.join("las").join(name);
            let reader = Reader::from_path(&path).unwrap();
            let header = reader.header();
            let layout = extra_layout(header).unwrap_or_else(|| panic!("{name}: no layout"));
            let total: usize = layout.iter().map(|(_, _, size)| size).sum();
            assert_eq!(total, usize::from(header.point_format().extra_bytes), "{name}");
            assert!(normal_fields(header).is_none());
        }
    }
}
