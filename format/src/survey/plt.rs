//! Compass plot files (`.plt`, written by Compass's compiler): text lines, each a command letter
//! and its fields. `M` moves to a station and `D` draws a leg to one, each as northing, easting
//! and elevation in decimal feet, then `S` and the station's name, then `P` and its passage
//! dimensions (left, up, down, right, feet; negative where not measured), then optional fields
//! (`I` distance, `F` flags, `Z` error). `N` starts a survey by name, `F` lines name a feature,
//! `X` closes a cave's data, and a Ctrl-Z (0x1a) may end the file. Other lines (bounds `Z`,
//! datum `O`, `G`, ...) carry nothing a centreline needs and are skipped.
//!
//! Flags on a `D` line (the field after `F`): `L` excluded from the length, `P` excluded from the
//! plot, `X` excluded from everything, `C` not adjusted, `S` a splay shot.

use super::{CrossSection, Leg, LegFlags, Station, StationFlags, Survey};

/// Feet to metres (the international foot).
const FOOT_M: f64 = 0.3048;

/// Whether a file's first bytes look like a Compass plot file: printable text whose first line
/// starts with one of the letters a plot file starts with.
pub(crate) fn looks_like_plt(first: &[u8]) -> bool {
    let head = &first[..first.len().min(64)];
    let line = head.split(|&b| b == b'\n').next().unwrap_or_default();
    let text = head.iter().all(|&b| b.is_ascii_graphic() || b.is_ascii_whitespace() || b == 0x1a);
    text && matches!(line.first(), Some(b'Z' | b'S' | b'N' | b'M')) && line.get(1) == Some(&b' ')
}

/// Parses a plot file's bytes.
pub(crate) fn parse(bytes: &[u8]) -> Result<Survey, String> {
    let end = bytes.iter().position(|&b| b == 0x1a).unwrap_or(bytes.len());
    let text = std::str::from_utf8(&bytes[..end])
        .map_err(|e| format!("not text at byte {}: not a Compass plot file", e.valid_up_to()))?;
    let mut survey = Survey::default();
    let mut name = String::new();
    let mut here: Option<[f64; 3]> = None;
    for (k, line) in text.lines().enumerate() {
        let at = |problem: String| format!("line {}: {problem}", k + 1);
        let mut f = line.split_whitespace();
        match f.next() {
            Some("N") => {
                name = f.next().unwrap_or_default().to_string();
                if survey.title.is_empty() {
                    survey.title = name.clone();
                }
            }
            Some(cmd @ ("M" | "D")) => {
                let mut coord = |what: &str| -> Result<f64, String> {
                    let s = f.next().ok_or_else(|| at(format!("{cmd} line without its {what}")))?;
                    let v: f64 = s.parse().map_err(|_| at(format!("{what} {s:?} is not a number")))?;
                    if v.is_finite() {
                        Ok(v * FOOT_M)
                    } else {
                        Err(at(format!("{what} {s:?} is not finite")))
                    }
                };
                let (north, east, up) = (coord("northing")?, coord("easting")?, coord("elevation")?);
                let position_m = [east, north, up];
                let (mut station, mut lrud, mut flags) = (None, [None; 4], LegFlags::default());
                while let Some(field) = f.next() {
                    let Some(letter) = field.chars().next() else { continue };
                    match (letter, &field[letter.len_utf8()..]) {
                        ('S', rest) => {
                            station = Some(if rest.is_empty() { f.next().unwrap_or("") } else { rest })
                        }
                        ('P', rest) => {
                            let first = if rest.is_empty() { f.next() } else { Some(rest) };
                            // Left, up, down, right in the file; left, right, up, down here.
                            let mut luds = [None; 4];
                            for (k, v) in luds.iter_mut().enumerate() {
                                let s = if k == 0 { first } else { f.next() };
                                *v = s
                                    .and_then(|s| s.parse::<f64>().ok())
                                    .filter(|v| v.is_finite() && *v >= 0.0);
                            }
                            lrud = [luds[0], luds[3], luds[1], luds[2]].map(|v| v.map(|v| v * FOOT_M));
                        }
                        ('F', rest) => {
                            let fl = if rest.is_empty() { f.next().unwrap_or("") } else { rest };
                            flags.splay = fl.contains('S');
                            flags.duplicate = fl.contains('L') || fl.contains('X');
                        }
                        _ => {}
                    }
                }
                let station = station.ok_or_else(|| at(format!("{cmd} line without a station (S field)")))?;
                if survey.station(station).is_none() {
                    let flags = StationFlags { underground: true, ..Default::default() };
                    survey.stations.push(Station { name: station.to_string(), position_m, flags });
                }
                if lrud.iter().any(Option::is_some) {
                    survey.cross_sections.push(CrossSection {
                        station: station.to_string(),
                        lrud_m: lrud,
                        last: false,
                    });
                }
                if cmd == "D" {
                    let from_m = here.ok_or_else(|| at("a D (draw) line before any M (move)".into()))?;
                    survey.legs.push(Leg {
                        from_m,
                        to_m: position_m,
                        from: None,
                        to: None,
                        survey: name.clone(),
                        flags,
                    });
                }
                here = Some(position_m);
            }
            _ => {}
        }
    }
    if survey.stations.is_empty() {
        return Err("no stations (no M or D lines): not a Compass plot file, or an empty one".into());
    }
    survey.link_legs();
    Ok(survey)
}

#[cfg(test)]
mod tests {
    use super::*;

    const PLT: &str = "Z -1.0 10.0 -2.0 30.0 -5.0 1.0\r\nS CAVE\r\nN A1 D 7 4 2021 C first trip\r\n\
M 0.00 0.00 0.00 SA1 P -9.00 -9.00 -9.00 -9.00\r\n\
D 0.00 32.81 0.00 SA2 P 3.28 6.56 1.64 4.92 I 32.81\r\n\
D 16.40 32.81 -3.28 SA3 P 2.0 2.0 2.0 2.0 I 16.73 F S\r\nX 0 0 0 0 0 0\r\n\x1a";

    #[test]
    fn a_plot_file_gives_stations_legs_and_dimensions_in_metres() {
        assert!(looks_like_plt(PLT.as_bytes()));
        let s = parse(PLT.as_bytes()).unwrap();
        assert_eq!(s.stations.len(), 3);
        let a2 = s.station("A2").unwrap();
        // 32.81 ft east: 10.0 m.
        assert!((a2.position_m[0] - 10.0).abs() < 0.001 && a2.position_m[1].abs() < 1e-9, "{a2:?}");
        assert_eq!(s.legs.len(), 2);
        assert_eq!((s.legs[0].from, s.legs[0].to), (Some(0), Some(1)));
        assert!(s.legs[1].flags.splay && !s.legs[0].flags.splay);
        // A1's dimensions are missing; A2's are left 1 m, right 1.5 m, up 2 m, down 0.5 m.
        let x = s.cross_sections.iter().find(|c| c.station == "A2").unwrap();
        let lrud: Vec<f64> = x.lrud_m.iter().map(|v| v.unwrap()).collect();
        for (got, want) in lrud.iter().zip([1.0, 1.5, 2.0, 0.5]) {
            assert!((got - want).abs() < 0.001, "{lrud:?}");
        }
        assert!(s.cross_sections.iter().all(|c| c.station != "A1"));
        assert!((s.surveyed_length_m() - 10.0).abs() < 0.01, "the splay is not length");
    }

    #[test]
    fn damaged_plot_files_are_errors_naming_the_line() {
        let bad = "M 0 0 0 SA1\nD 1.0 x 0 SA2\n";
        let e = parse(bad.as_bytes()).unwrap_err();
        assert!(e.contains("line 2") && e.contains("easting"), "{e}");
        let e = parse(b"D 1 1 1 SA2\n").unwrap_err();
        assert!(e.contains("before any M"), "{e}");
        let e = parse(b"N A\nZ 1 2\n").unwrap_err();
        assert!(e.contains("no stations"), "{e}");
        assert!(parse(b"M 0 0 nan SA1\n").is_err());
    }
}
