//! PLY: ascii, binary little and big endian; any scalar type for x/y/z; optional normals and
//! colours (uchar, ushort or float); other elements before or after the vertex element.
//!
//! The header is parsed by `ply-rs-bw`. Its body reader builds a hash map per vertex (hundreds of
//! bytes and several allocations per point), far too slow and large for 10^8-point scans, so the
//! body is streamed here: fixed-size binary records are decoded straight from a reusable buffer,
//! ascii is tokenised line by line. Only the vertex element is kept; elements before it are skipped
//! token by token (ascii) or byte by byte (binary, list lengths read as they come).

use std::fs::File;
use std::io::{BufRead, BufReader, Read};
use std::path::Path;

use ply_rs_bw::parser::{Parser, Reader};
use ply_rs_bw::ply::{DefaultElement, ElementDef, PropertyType as PlyProperty, ScalarType as PlyScalar};

use crate::ingest::source::{NEUTRAL_GREY, PointChunk, PointSource, ScanFormat, SourceInfo, read_error};
use crate::{Error, Result};

#[derive(Clone, Copy, Debug, PartialEq, Eq)]
enum Role {
    X,
    Y,
    Z,
    Nx,
    Ny,
    Nz,
    R,
    G,
    B,
    Other,
}

/// PLY scalar types (ply-rs-bw's are not `Copy`).
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
enum ScalarType {
    Char,
    UChar,
    Short,
    UShort,
    Int,
    UInt,
    Float,
    Double,
}

impl From<&PlyScalar> for ScalarType {
    fn from(t: &PlyScalar) -> Self {
        match t {
            PlyScalar::Char => Self::Char,
            PlyScalar::UChar => Self::UChar,
            PlyScalar::Short => Self::Short,
            PlyScalar::UShort => Self::UShort,
            PlyScalar::Int => Self::Int,
            PlyScalar::UInt => Self::UInt,
            PlyScalar::Float => Self::Float,
            PlyScalar::Double => Self::Double,
        }
    }
}

#[derive(Clone, Copy, Debug, PartialEq, Eq)]
enum PropertyType {
    Scalar(ScalarType),
    List(ScalarType, ScalarType),
}

impl From<&PlyProperty> for PropertyType {
    fn from(p: &PlyProperty) -> Self {
        match p {
            PlyProperty::Scalar(t) => Self::Scalar(t.into()),
            PlyProperty::List(l, e) => Self::List(l.into(), e.into()),
        }
    }
}

#[derive(Clone, Copy, Debug, PartialEq, Eq)]
enum Encoding {
    Ascii,
    BinaryBigEndian,
    BinaryLittleEndian,
}

#[derive(Clone, Debug)]
struct Prop {
    role: Role,
    ty: PropertyType,
}

pub(super) struct PlySource {
    info: SourceInfo,
    input: BufReader<File>,
    encoding: Encoding,
    props: Vec<Prop>,
    /// Byte size of a vertex record when it has no list properties.
    fixed_record: Option<usize>,
    remaining: u64,
    read: u64,
    tokens: Tokens,
    buf: Vec<u8>,
    /// Colour property type (all three share it in practice; the first decides the scale).
    color_ty: Option<ScalarType>,
}

fn scalar_size(t: ScalarType) -> usize {
    match t {
        ScalarType::Char | ScalarType::UChar => 1,
        ScalarType::Short | ScalarType::UShort => 2,
        ScalarType::Int | ScalarType::UInt | ScalarType::Float => 4,
        ScalarType::Double => 8,
    }
}

fn role(name: &str) -> Role {
    match name {
        "x" => Role::X,
        "y" => Role::Y,
        "z" => Role::Z,
        "nx" | "normal_x" => Role::Nx,
        "ny" | "normal_y" => Role::Ny,
        "nz" | "normal_z" => Role::Nz,
        "red" | "r" | "diffuse_red" => Role::R,
        "green" | "g" | "diffuse_green" => Role::G,
        "blue" | "b" | "diffuse_blue" => Role::B,
        _ => Role::Other,
    }
}

fn decode(t: ScalarType, b: &[u8], big: bool) -> f64 {
    macro_rules! num {
        ($ty:ty, $n:expr) => {{
            let a: [u8; $n] = b[..$n].try_into().expect("sized by scalar_size");
            f64::from(if big { <$ty>::from_be_bytes(a) } else { <$ty>::from_le_bytes(a) })
        }};
    }
    match t {
        ScalarType::Char => f64::from(b[0] as i8),
        ScalarType::UChar => f64::from(b[0]),
        ScalarType::Short => num!(i16, 2),
        ScalarType::UShort => num!(u16, 2),
        ScalarType::Int => num!(i32, 4),
        ScalarType::UInt => num!(u32, 4),
        ScalarType::Float => num!(f32, 4),
        ScalarType::Double => num!(f64, 8),
    }
}

/// Whitespace-separated tokens across lines.
#[derive(Default)]
struct Tokens {
    line: String,
    spans: Vec<(usize, usize)>,
    next: usize,
}

impl Tokens {
    fn next<R: BufRead>(&mut self, r: &mut R) -> std::io::Result<Option<&str>> {
        while self.next >= self.spans.len() {
            self.line.clear();
            if r.read_line(&mut self.line)? == 0 {
                return Ok(None);
            }
            self.spans.clear();
            self.next = 0;
            let bytes = self.line.as_bytes();
            let mut i = 0;
            while i < bytes.len() {
                while i < bytes.len() && bytes[i].is_ascii_whitespace() {
                    i += 1;
                }
                let start = i;
                while i < bytes.len() && !bytes[i].is_ascii_whitespace() {
                    i += 1;
                }
                if i > start {
                    self.spans.push((start, i));
                }
            }
        }
        let (a, b) = self.spans[self.next];
        self.next += 1;
        Ok(Some(&self.line[a..b]))
    }
}

impl PlySource {
    pub(super) fn open(path: &Path) -> Result<Self> {
        let err = |reason: String| read_error(path, ScanFormat::Ply, reason);
        let file = File::open(path).map_err(|e| err(e.to_string()))?;
        let file_len = file.metadata().map_err(|e| err(e.to_string()))?.len();
        let mut reader = Reader::new(BufReader::with_capacity(1 << 20, file));
        let header = Parser::<DefaultElement>::new()
            .read_header(&mut reader)
            .map_err(|e| err(format!("header: {e}")))?;
        let mut input = reader.into_inner();
        let elements: Vec<&ElementDef> = header.elements.values().collect();
        let vi = elements
            .iter()
            .position(|e| e.name == "vertex")
            .ok_or_else(|| err("no vertex element".into()))?;
        let vertex = elements[vi];
        let props: Vec<Prop> = vertex
            .properties
            .values()
            .map(|p| Prop { role: role(&p.name), ty: (&p.data_type).into() })
            .collect();
        for needed in [Role::X, Role::Y, Role::Z] {
            match props.iter().find(|p| p.role == needed) {
                Some(Prop { ty: PropertyType::Scalar(_), .. }) => {}
                Some(_) => return Err(err(format!("vertex property {needed:?} is a list"))),
                None => {
                    return Err(err(format!("vertex element has no {:?} property", needed).to_lowercase()));
                }
            }
        }
        let has = |r: Role| props.iter().any(|p| p.role == r && matches!(p.ty, PropertyType::Scalar(_)));
        let has_normals = has(Role::Nx) && has(Role::Ny) && has(Role::Nz);
        let has_color = has(Role::R) && has(Role::G) && has(Role::B);
        let color_ty = props.iter().find(|p| p.role == Role::R).and_then(|p| match p.ty {
            PropertyType::Scalar(t) => Some(t),
            PropertyType::List(..) => None,
        });
        let fixed_record = props.iter().try_fold(0usize, |acc, p| match p.ty {
            PropertyType::Scalar(t) => Some(acc + scalar_size(t)),
            PropertyType::List(..) => None,
        });
        let mut tokens = Tokens::default();
        let encoding = match header.encoding {
            ply_rs_bw::ply::Encoding::Ascii => Encoding::Ascii,
            ply_rs_bw::ply::Encoding::BinaryBigEndian => Encoding::BinaryBigEndian,
            ply_rs_bw::ply::Encoding::BinaryLittleEndian => Encoding::BinaryLittleEndian,
        };
        // Skip the elements before the vertex element.
        for e in &elements[..vi] {
            for i in 0..e.count {
                for p in e.properties.values() {
                    skip_property(&mut input, &mut tokens, encoding, &(&p.data_type).into())
                        .map_err(|m| err(format!("element '{}' {i}: {m}", e.name)))?;
                }
            }
        }
        let count = vertex.count as u64;
        if let (Some(size), Encoding::BinaryBigEndian | Encoding::BinaryLittleEndian) =
            (fixed_record, encoding)
            && count.checked_mul(size as u64).is_none_or(|n| n > file_len)
        {
            return Err(err(format!(
                "header claims {count} vertices of {size} bytes, more than the {file_len}-byte file holds"
            )));
        }
        let name = path.file_stem().map(|s| s.to_string_lossy().into_owned()).unwrap_or_default();
        Ok(Self {
            info: SourceInfo {
                path: path.to_path_buf(),
                format: ScanFormat::Ply,
                name,
                claimed_points: count,
                has_color,
                has_normals,
                dropped_points: 0,
                file_pose: None,
            },
            input,
            encoding,
            props,
            fixed_record,
            remaining: count,
            read: 0,
            tokens,
            buf: Vec::new(),
            color_ty,
        })
    }

    fn truncated(&self, detail: impl std::fmt::Display) -> Error {
        read_error(
            &self.info.path,
            ScanFormat::Ply,
            format!("vertex {} of {}: {detail}", self.read, self.info.claimed_points),
        )
    }

    fn color_scale(&self, v: f64) -> u8 {
        let scaled = match self.color_ty {
            Some(ScalarType::Float | ScalarType::Double) => v * 255.0,
            Some(ScalarType::UShort | ScalarType::Short) => v / 257.0,
            _ => v,
        };
        scaled.round().clamp(0.0, 255.0) as u8
    }

    fn push(&self, chunk: &mut PointChunk, v: &[f64; 9]) {
        chunk.xyz.push([v[0], v[1], v[2]]);
        if self.info.has_normals {
            chunk.normal.push([v[3] as f32, v[4] as f32, v[5] as f32]);
        }
        chunk.rgb.push(if self.info.has_color {
            [self.color_scale(v[6]), self.color_scale(v[7]), self.color_scale(v[8])]
        } else {
            NEUTRAL_GREY
        });
    }
}

fn slot(role: Role) -> Option<usize> {
    match role {
        Role::X => Some(0),
        Role::Y => Some(1),
        Role::Z => Some(2),
        Role::Nx => Some(3),
        Role::Ny => Some(4),
        Role::Nz => Some(5),
        Role::R => Some(6),
        Role::G => Some(7),
        Role::B => Some(8),
        Role::Other => None,
    }
}

fn read_scalar<R: BufRead>(
    r: &mut R,
    tokens: &mut Tokens,
    enc: Encoding,
    t: ScalarType,
) -> Result<f64, String> {
    match enc {
        Encoding::Ascii => {
            let tok = tokens.next(r).map_err(|e| e.to_string())?.ok_or("file ends early")?;
            tok.parse::<f64>().map_err(|_| format!("'{tok}' is not a number"))
        }
        Encoding::BinaryBigEndian | Encoding::BinaryLittleEndian => {
            let mut b = [0u8; 8];
            let n = scalar_size(t);
            r.read_exact(&mut b[..n]).map_err(|_| "file ends early".to_string())?;
            Ok(decode(t, &b, enc == Encoding::BinaryBigEndian))
        }
    }
}

fn list_len(v: f64) -> Result<u64, String> {
    if v >= 0.0 && v.fract() == 0.0 && v <= u32::MAX as f64 {
        Ok(v as u64)
    } else {
        Err(format!("list length {v}"))
    }
}

fn skip_property<R: BufRead>(
    r: &mut R,
    tokens: &mut Tokens,
    enc: Encoding,
    ty: &PropertyType,
) -> Result<(), String> {
    match *ty {
        PropertyType::Scalar(t) => read_scalar(r, tokens, enc, t).map(drop),
        PropertyType::List(lt, et) => {
            let n = list_len(read_scalar(r, tokens, enc, lt)?)?;
            for _ in 0..n {
                read_scalar(r, tokens, enc, et)?;
            }
            Ok(())
        }
    }
}

impl PointSource for PlySource {
    fn info(&self) -> &SourceInfo {
        &self.info
    }

    fn fill_chunk(&mut self, chunk: &mut PointChunk) -> Result<usize> {
        chunk.clear();
        let n = self.remaining.min(chunk.limit() as u64) as usize;
        if n == 0 {
            return Ok(0);
        }
        let big = self.encoding == Encoding::BinaryBigEndian;
        match (self.encoding, self.fixed_record) {
            (Encoding::BinaryBigEndian | Encoding::BinaryLittleEndian, Some(size)) => {
                // Fast path: one read for the whole chunk, decode in place.
                self.buf.resize(n * size, 0);
                if let Err(e) = self.input.read_exact(&mut self.buf) {
                    return Err(self.truncated(format!("file ends early ({e})")));
                }
                let layout: Vec<(Option<usize>, ScalarType, usize)> = {
                    let mut off = 0;
                    self.props
                        .iter()
                        .map(|p| {
                            let PropertyType::Scalar(t) = p.ty else {
                                unreachable!("fixed records have no lists")
                            };
                            let entry = (slot(p.role), t, off);
                            off += scalar_size(t);
                            entry
                        })
                        .collect()
                };
                let buf = std::mem::take(&mut self.buf);
                for rec in buf.chunks_exact(size) {
                    let mut v = [0f64; 9];
                    for &(s, t, off) in &layout {
                        if let Some(s) = s {
                            v[s] = decode(t, &rec[off..], big);
                        }
                    }
                    self.push(chunk, &v);
                }
                self.buf = buf;
                self.read += n as u64;
            }
            _ => {
                for _ in 0..n {
                    let mut v = [0f64; 9];
                    for i in 0..self.props.len() {
                        let ty = self.props[i].ty;
                        let value = match ty {
                            PropertyType::Scalar(t) => {
                                read_scalar(&mut self.input, &mut self.tokens, self.encoding, t)
                            }
                            list => skip_property(&mut self.input, &mut self.tokens, self.encoding, &list)
                                .map(|()| 0.0),
                        }
                        .map_err(|m| self.truncated(m))?;
                        if let Some(s) = slot(self.props[i].role) {
                            v[s] = value;
                        }
                    }
                    self.push(chunk, &v);
                    // Per vertex, so an error names the vertex it happened at.
                    self.read += 1;
                }
            }
        }
        self.remaining -= n as u64;
        Ok(n)
    }
}
