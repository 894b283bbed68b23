//! Survex `.3d` files, format version 8 (what Survex 1.2.7 and later write, `cavern` 1.4
//! included; specification: Survex's `doc/3dformat.htm`). Every read is bounds-checked: a
//! truncated or damaged file is an error naming the byte where it went wrong, and a label's
//! length is checked against the bytes left before anything is allocated for it.

use super::{CrossSection, Leg, LegFlags, Station, StationFlags, Survey};

/// The file's first line.
pub(crate) const MAGIC: &[u8] = b"Survex 3D Image File\n";

/// The format version read.
const VERSION: &[u8] = b"v8\n";

/// The style codes 0x00-0x04: 0x00 is normal (tape, compass, clino), and a 0x00 while the style is
/// already normal ends the data. Before the first style code the style is unknown (as in Survex's
/// own reader, img.c), so the 0x00 that cavern writes after the first move sets it.
const STYLE_NORMAL: u8 = 0x00;
const STYLE_UNKNOWN: u8 = 0xff;

struct Reader<'a> {
    bytes: &'a [u8],
    at: usize,
}

impl<'a> Reader<'a> {
    fn take(&mut self, n: usize, what: &str) -> Result<&'a [u8], String> {
        let end = self.at.checked_add(n).filter(|&e| e <= self.bytes.len()).ok_or_else(|| {
            format!(
                "truncated: {what} at byte {} needs {n} bytes, {} are left",
                self.at,
                self.bytes.len() - self.at
            )
        })?;
        let s = &self.bytes[self.at..end];
        self.at = end;
        Ok(s)
    }

    fn u8(&mut self, what: &str) -> Result<u8, String> {
        Ok(self.take(1, what)?[0])
    }

    fn u16(&mut self, what: &str) -> Result<u16, String> {
        let b = self.take(2, what)?;
        Ok(u16::from_le_bytes([b[0], b[1]]))
    }

    fn i32(&mut self, what: &str) -> Result<i32, String> {
        let b = self.take(4, what)?;
        Ok(i32::from_le_bytes([b[0], b[1], b[2], b[3]]))
    }

    fn u32(&mut self, what: &str) -> Result<u32, String> {
        Ok(self.i32(what)? as u32)
    }

    /// A position: three centimetre integers, as metres.
    fn position(&mut self, what: &str) -> Result<[f64; 3], String> {
        let mut p = [0.0; 3];
        for v in &mut p {
            *v = f64::from(self.i32(what)?) / 100.0;
        }
        Ok(p)
    }

    /// Up to the next `stop` byte (not included; the stop is consumed).
    fn until(&mut self, stop: u8, what: &str) -> Result<&'a [u8], String> {
        let rest = &self.bytes[self.at..];
        let n =
            rest.iter().position(|&b| b == stop).ok_or_else(|| format!("truncated: {what} has no end"))?;
        self.at += n + 1;
        Ok(&rest[..n])
    }

    /// A label change: drop `d` bytes from the end of `label`, append `a` from the file.
    fn label(&mut self, label: &mut Vec<u8>) -> Result<(), String> {
        let first = self.u8("a label")?;
        let (d, a) = if first != 0 {
            (usize::from(first >> 4), usize::from(first & 0x0f))
        } else {
            let count = |r: &mut Self| -> Result<usize, String> {
                match r.u8("a label length")? {
                    255 => Ok(r.u32("a label length")? as usize),
                    n => Ok(usize::from(n)),
                }
            };
            (count(self)?, count(self)?)
        };
        if d > label.len() {
            return Err(format!(
                "byte {}: a label drops {d} bytes of a {}-byte name (damaged file)",
                self.at,
                label.len()
            ));
        }
        label.truncate(label.len() - d);
        label.extend_from_slice(self.take(a, "a label's bytes")?);
        Ok(())
    }
}

fn text(b: &[u8]) -> String {
    String::from_utf8_lossy(b).into_owned()
}

/// Parses a `.3d` file's bytes.
pub(crate) fn parse(bytes: &[u8]) -> Result<Survey, String> {
    let mut r = Reader { bytes, at: 0 };
    if r.take(MAGIC.len(), "the file id")? != MAGIC {
        return Err("not a Survex .3d file".into());
    }
    let version = r.until(b'\n', "the version line")?;
    if [version, b"\n"].concat() != VERSION {
        return Err(format!(
            "Survex .3d format {:?}: grotto reads version 8, which Survex 1.2.7 and later write (run cavern \
             again on the .svx)",
            text(version)
        ));
    }
    let meta = r.until(b'\n', "the title and coordinate system")?;
    let mut meta = meta.split(|&b| b == 0);
    let title = meta.next().map(text).unwrap_or_default();
    let crs = meta.next().map(text).filter(|s| !s.is_empty());
    let stamp = r.until(b'\n', "the timestamp")?;
    if !stamp.starts_with(b"@") {
        return Err(format!("the timestamp line {:?} does not start with '@' (damaged file)", text(stamp)));
    }
    let file_flags = r.u8("the file flags")?;
    let mut survey = Survey { title, crs, extended_elevation: file_flags & 0x80 != 0, ..Default::default() };
    let mut label = Vec::new();
    let mut style = STYLE_UNKNOWN;
    let mut here: Option<[f64; 3]> = None;
    loop {
        let at = r.at;
        let code = r.u8("an item (the file ends without its end marker)")?;
        match code {
            0x00 if style == STYLE_NORMAL => break,
            0x00..=0x04 => style = code,
            0x0f => here = Some(r.position("a move")?),
            0x10 => {}
            0x11 => drop(r.take(2, "a date")?),
            0x12 => drop(r.take(3, "a date range")?),
            0x13 => drop(r.take(4, "a date range")?),
            0x1f => drop(r.take(20, "a traverse's error")?),
            0x30..=0x33 => {
                r.label(&mut label)?;
                let mut lrud = [None; 4];
                for v in &mut lrud {
                    *v = if code < 0x32 {
                        Some(r.u16("a passage dimension")?)
                            .filter(|&c| c != 0xffff)
                            .map(|c| f64::from(c as i16) / 100.0)
                    } else {
                        Some(r.i32("a passage dimension")?).filter(|&c| c != -1).map(|c| f64::from(c) / 100.0)
                    };
                }
                survey.cross_sections.push(CrossSection {
                    station: text(&label),
                    lrud_m: lrud,
                    last: code & 1 != 0,
                });
            }
            0x40..=0x7f => {
                let flags = code & 0x3f;
                if flags & 0x20 == 0 {
                    r.label(&mut label)?;
                }
                let to = r.position("a leg")?;
                let from =
                    here.ok_or_else(|| format!("byte {at}: a leg before any position (damaged file)"))?;
                survey.legs.push(Leg {
                    from_m: from,
                    to_m: to,
                    from: None,
                    to: None,
                    survey: text(&label),
                    flags: LegFlags {
                        surface: flags & 1 != 0,
                        duplicate: flags & 2 != 0,
                        splay: flags & 4 != 0,
                    },
                });
                here = Some(to);
            }
            0x80..=0xff => {
                let f = code & 0x7f;
                r.label(&mut label)?;
                let position_m = r.position("a station")?;
                survey.stations.push(Station {
                    name: text(&label),
                    position_m,
                    flags: StationFlags {
                        surface: f & 0x01 != 0,
                        underground: f & 0x02 != 0,
                        entrance: f & 0x04 != 0,
                        exported: f & 0x08 != 0,
                        fixed: f & 0x10 != 0,
                        anonymous: f & 0x20 != 0,
                        wall: f & 0x40 != 0,
                    },
                });
            }
            _ => {
                return Err(format!(
                    "byte {at}: item code {code:#04x} is reserved in format 8 (damaged file)"
                ));
            }
        }
    }
    // Equated stations appear once per name; one position can hold several names.
    survey.link_legs();
    Ok(survey)
}
