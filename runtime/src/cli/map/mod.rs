//! `grotto map`: the survey products surveyors draw from a centreline, drawn from the scans. A
//! plan and an extended elevation as orthographic pictures of the scanned walls at a map scale
//! (PNG, and SVG with the overlay as vectors over the same picture), a cross-section at each
//! station (SVG) and `passages.csv` (each station's position, passage width, height and area).
//! The package is read a tile at a time, so memory follows the pictures, not the points.
//!
//! Each station is also checked against the scans: whether it stands in the scanned passage and
//! how far from its middle, so a survey or a scan registered wrongly shows.

mod centreline;
mod draw;
mod overlay;
mod raster;
mod section;

use std::path::{Path, PathBuf};

use glam::{DVec3, Vec3};
use grotto_format::Package;
use grotto_format::survey::Survey;
use serde::Serialize;

use crate::error::{Error, Result};
use centreline::Centreline;
use raster::{Frame2, Raster};

/// Map scales a plan is offered at when none is asked for: the largest whose picture fits.
const STANDARD_SCALES: [u32; 12] = [50, 100, 200, 250, 500, 1000, 2000, 2500, 5000, 10_000, 20_000, 50_000];

/// What `grotto map` is asked for.
#[derive(Clone, Debug)]
pub struct MapOptions {
    pub out_dir: PathBuf,
    /// The map scale's denominator (1:N); `None`: the largest standard scale whose plan fits
    /// `max_px`.
    pub scale: Option<u32>,
    /// Printed resolution: with the scale, what a pixel is on the ground.
    pub dpi: f64,
    /// The longest side a picture may have, pixels.
    pub max_px: u32,
    /// Half the thickness of the slab of points a cross-section is traced from, metres.
    pub slab_m: f64,
    /// How far from its leg a scanned point may lie and still belong to it (and a station to
    /// the scans), metres.
    pub reach_m: f64,
}

impl Default for MapOptions {
    fn default() -> Self {
        MapOptions {
            out_dir: PathBuf::from("map"),
            scale: None,
            dpi: 150.0,
            max_px: 8192,
            slab_m: 0.1,
            reach_m: 10.0,
        }
    }
}

/// One picture written.
#[derive(Clone, Debug, Serialize)]
pub struct Picture {
    pub png: String,
    pub svg: String,
    pub width_px: u32,
    pub height_px: u32,
    pub surfels_drawn: u64,
}

/// One station's passage, as `passages.csv` has it.
#[derive(Clone, Debug, Serialize)]
pub struct StationReport {
    pub station: String,
    pub position_m: [f64; 3],
    /// The cross-section's file, where the scans saw enough of the passage there.
    pub section: Option<String>,
    /// Why there is none, where there is none.
    pub no_section: Option<String>,
    pub width_m: Option<f64>,
    pub height_m: Option<f64>,
    pub area_m2: Option<f64>,
    /// Whether the station stands in the scanned passage's air.
    pub inside: Option<bool>,
    /// From the station to the middle of its cross-section, metres.
    pub from_middle_m: Option<f64>,
    /// From the station to the nearest scanned point, metres (`None`: none within reach).
    pub nearest_scan_m: Option<f64>,
}

/// What `grotto map` wrote and found.
#[derive(Clone, Debug, Serialize)]
pub struct MapSummary {
    pub package: String,
    pub survey: String,
    pub scale: u32,
    pub dpi: f64,
    pub m_per_px: f64,
    pub plan: Picture,
    pub elevation: Picture,
    pub passages_csv: String,
    pub stations: Vec<StationReport>,
    pub surveyed_length_m: f64,
    pub points: u64,
    pub tiles: u32,
    /// Stations far from the scans or outside their passage, by name.
    pub warnings: Vec<String>,
    pub seconds: f64,
}

/// The survey's error for `survey_from` (a file, or the package that holds it).
fn survey_error(survey_from: &str, problem: String) -> Error {
    Error::Survey { path: survey_from.to_owned(), problem }
}

/// The scanned tiles' box (world metres), from the tile directory.
fn scans_box(pkg: &Package) -> Option<(DVec3, DVec3)> {
    let mut lo = DVec3::splat(f64::INFINITY);
    let mut hi = DVec3::splat(f64::NEG_INFINITY);
    for t in pkg.tiles().filter(|t| t.point_count() > 0) {
        let o = DVec3::from_array(t.origin_m());
        lo = lo.min(o);
        hi = hi.max(o + DVec3::splat(t.extent_m()));
    }
    lo.is_finite().then_some((lo, hi))
}

/// Refuses a survey that cannot be the scans' (every station far from them: another
/// coordinate system, or no translation given for a local grid).
fn check_survey_fits(survey: &Survey, survey_from: &str, lo: DVec3, hi: DVec3) -> Result<()> {
    if survey.stations.is_empty() {
        return Err(survey_error(survey_from, "has no stations".into()));
    }
    let away = |p: [f64; 3]| {
        let p = DVec3::from_array(p);
        (lo - p).max(p - hi).max(DVec3::ZERO).length()
    };
    let (nearest, d) = survey
        .stations
        .iter()
        .map(|s| (s, away(s.position_m)))
        .min_by(|a, b| a.1.total_cmp(&b.1))
        .expect("stations is not empty");
    let tolerance_m = 100.0f64.max(0.5 * (hi - lo).length());
    if d > tolerance_m {
        return Err(survey_error(
            survey_from,
            format!(
                "every station lies far from the scans: the nearest, {} at {:.1?}, is {:.0} m outside the scanned box {:.1?} .. {:.1?}. Is the survey in another coordinate system than the scans{}? Give the survey in the scans' system, or its offset ([survey] translation in the manifest).",
                nearest.name,
                nearest.position_m,
                d,
                lo.to_array(),
                hi.to_array(),
                survey.crs.as_deref().map(|c| format!(" (the survey says {c})")).unwrap_or_default()
            ),
        ));
    }
    Ok(())
}

/// The scale and metres per pixel of a plan of `size_m` (east, north).
fn choose_scale(opts: &MapOptions, size_m: [f64; 2]) -> Result<(u32, f64)> {
    let m_per_px = |n: u32| f64::from(n) * 0.0254 / opts.dpi;
    let fits = |n: u32| size_m[0].max(size_m[1]) / m_per_px(n) + 64.0 <= f64::from(opts.max_px);
    if !(opts.dpi.is_finite() && opts.dpi > 0.0) {
        return Err(Error::Setting { name: "dpi", problem: format!("{} is not a resolution", opts.dpi) });
    }
    match opts.scale {
        Some(0) => Err(Error::Setting { name: "scale", problem: "1:0 is not a scale".into() }),
        Some(n) if fits(n) => Ok((n, m_per_px(n))),
        Some(n) => Err(Error::Budget {
            what: format!(
                "a plan of {:.0} x {:.0} m at 1:{n} and {} dpi: {:.0} px on its longer side, over --max-px {}",
                size_m[0],
                size_m[1],
                opts.dpi,
                size_m[0].max(size_m[1]) / m_per_px(n),
                opts.max_px
            ),
            hint: "give a smaller scale (a larger N in --scale 1:N), a lower --dpi, or a larger --max-px"
                .into(),
        }),
        None => {
            // Past the largest standard scale: the scale that just fits.
            let n = STANDARD_SCALES.into_iter().find(|&n| fits(n)).unwrap_or_else(|| {
                (size_m[0].max(size_m[1]) / (f64::from(opts.max_px) - 64.0) / 0.0254 * opts.dpi).ceil() as u32
            });
            Ok((n, m_per_px(n)))
        }
    }
}

/// Points of the cross-sections, per station; stations without one have `None`.
struct Sections {
    points: Vec<Option<Vec<[f32; 2]>>>,
    /// Points offered to each station's slab so far (for the reservoir).
    offered: Vec<u64>,
    nearest_m: Vec<f64>,
}

/// Most points a cross-section keeps, a uniform sample of its slab's (reservoir sampling): an
/// outline of 180 bins needs far fewer than a dense scan's slab holds, and a survey of ten
/// thousand stations then holds at most 640 MiB of them.
const SECTION_POINTS: usize = 8192;

impl Sections {
    /// Offers `uv` to station `k`'s cross-section.
    fn offer(&mut self, k: usize, uv: [f32; 2]) {
        let Some(list) = self.points[k].as_mut() else { return };
        let seen = self.offered[k];
        self.offered[k] += 1;
        if list.len() < SECTION_POINTS {
            list.push(uv);
        } else {
            // Algorithm R with a hash of the count for its random index: the same maps each run.
            let mut h = seen.wrapping_mul(0x9e37_79b9_7f4a_7c15) ^ (k as u64);
            h ^= h >> 29;
            let j = (h % (seen + 1)) as usize;
            if j < SECTION_POINTS {
                list[j] = uv;
            }
        }
    }
}

/// Draws the maps of `pkg` with `survey` (named `survey_from` in messages) into
/// `opts.out_dir`; `progress` gets (tiles read, tiles).
pub fn map(
    pkg: &Package,
    survey: &Survey,
    survey_from: &str,
    opts: &MapOptions,
    progress: &dyn Fn(u32, u32),
) -> Result<MapSummary> {
    let start = web_time::Instant::now();
    let (lo, hi) = scans_box(pkg).ok_or_else(|| Error::Scene {
        package: pkg.path().display().to_string(),
        problem: "has no scanned points to map".into(),
    })?;
    survey.check().map_err(|p| survey_error(survey_from, p))?;
    check_survey_fits(survey, survey_from, lo, hi)?;
    let line = Centreline::new(survey, opts.reach_m);
    if line.legs.is_empty() {
        return Err(survey_error(survey_from, "has no underground legs to map".into()));
    }
    // The map covers the surveyed cave: the stations' box grown by the reach, within the scans'.
    // Tiles are cubes tens of metres wide, most of them rock; scanned passages no leg reaches
    // are left off the pictures (they are not surveyed) but not off the stations' fit.
    let (lo, hi) = {
        let mut s_lo = DVec3::splat(f64::INFINITY);
        let mut s_hi = DVec3::splat(f64::NEG_INFINITY);
        for l in &line.legs {
            s_lo = s_lo.min(l.from_m).min(l.to_m);
            s_hi = s_hi.max(l.from_m).max(l.to_m);
        }
        let reach = DVec3::splat(opts.reach_m);
        ((s_lo - reach).max(lo), (s_hi + reach).min(hi))
    };
    if !(lo.cmplt(hi).all()) {
        return Err(survey_error(survey_from, "its legs lie outside the scanned tiles".into()));
    }
    let (scale, m_per_px) = choose_scale(opts, [hi.x - lo.x, hi.y - lo.y])?;
    let plan_frame = Frame2::covering([lo.x, lo.y], [hi.x, hi.y], m_per_px, 48);
    let elevation_frame = Frame2::covering([0.0, lo.z], [line.extended_m.max(m_per_px), hi.z], m_per_px, 48);
    for f in [plan_frame, elevation_frame] {
        if f.width_px.max(f.height_px) > opts.max_px.saturating_add(128) {
            return Err(Error::Budget {
                what: format!("a map picture of {} x {} px", f.width_px, f.height_px),
                hint: "give a smaller scale (a larger N in --scale 1:N) or a larger --max-px".into(),
            });
        }
    }
    let mut plan = Raster::new(plan_frame, raster::plan_light());
    let mut elevation = Raster::new(elevation_frame, raster::plan_light());
    let mut sections = Sections {
        points: survey
            .stations
            .iter()
            .enumerate()
            .map(|(i, s)| (!s.flags.anonymous && line.direction[i].is_some()).then(Vec::new))
            .collect(),
        offered: vec![0; survey.stations.len()],
        nearest_m: vec![f64::INFINITY; survey.stations.len()],
    };
    let mut points = 0u64;
    let total = pkg.tile_count();
    for (k, tile) in pkg.tiles().enumerate() {
        progress(k as u32, total);
        let Some(surfels) = tile.surfels()? else { continue };
        let colors = crate::scene::data::tile_colors(&tile, surfels.len())?;
        let o = DVec3::from_array(tile.origin_m());
        for (i, s) in surfels.iter().enumerate() {
            let p = o + Vec3::from_array(s.position_tile_m).as_dvec3();
            let n = Vec3::from_array(s.normal);
            let rgb = colors.get(i).copied().unwrap_or([180; 3]);
            points += 1;
            if let Some((xy, depth)) = raster::plan_place(p, n) {
                plan.splat(xy, depth, s.radius_m, n, rgb);
            }
            let Some((leg_index, t, _)) = line.leg_of(p) else { continue };
            let leg = &line.legs[leg_index];
            if let Some((xy, depth, n_picture)) = overlay::elevation_place(leg, t, p, n) {
                elevation.splat(xy, depth, s.radius_m, n_picture, rgb);
            }
            for station in [leg.from, leg.to].into_iter().flatten() {
                let at = DVec3::from_array(survey.stations[station].position_m);
                let q = p - at;
                let d = q.length();
                if d < sections.nearest_m[station] {
                    sections.nearest_m[station] = d;
                }
                let Some(dir) = line.direction[station] else { continue };
                if q.dot(dir).abs() <= opts.slab_m && d <= opts.reach_m {
                    let right = DVec3::new(dir.y, -dir.x, 0.0);
                    sections.offer(station, [q.dot(right) as f32, q.z as f32]);
                }
            }
        }
    }
    progress(total, total);
    std::fs::create_dir_all(opts.out_dir.join("sections"))
        .map_err(|e| crate::cli::export::output_error(&opts.out_dir, e))?;
    let plan_out = overlay::write_plan(&opts.out_dir, &plan, survey, &line, scale)?;
    let elevation_out = overlay::write_elevation(&opts.out_dir, &elevation, survey, &line, scale)?;
    let (stations, warnings) = write_sections(&opts.out_dir, survey, &sections, opts.reach_m)?;
    let passages_csv = opts.out_dir.join("passages.csv");
    crate::cli::export::write_atomically(&passages_csv, passages_table(&stations, survey).as_bytes())?;
    Ok(MapSummary {
        package: pkg.path().display().to_string(),
        survey: survey_from.to_owned(),
        scale,
        dpi: opts.dpi,
        m_per_px,
        plan: plan_out,
        elevation: elevation_out,
        passages_csv: passages_csv.display().to_string(),
        stations,
        surveyed_length_m: survey.surveyed_length_m(),
        points,
        tiles: total,
        warnings,
        seconds: start.elapsed().as_secs_f64(),
    })
}

/// A station's name as a file name: the survey's characters where they are safe, `_` for the
/// rest.
fn file_name(station: &str) -> String {
    station.chars().map(|c| if c.is_ascii_alphanumeric() || "-_.".contains(c) { c } else { '_' }).collect()
}

/// Traces and writes each station's cross-section; the stations' reports and the warnings.
fn write_sections(
    dir: &Path,
    survey: &Survey,
    sections: &Sections,
    reach_m: f64,
) -> Result<(Vec<StationReport>, Vec<String>)> {
    let mut reports = Vec::new();
    let mut warnings = Vec::new();
    for (i, s) in survey.stations.iter().enumerate() {
        let Some(points) = &sections.points[i] else { continue };
        let nearest = sections.nearest_m[i];
        let nearest_scan_m = nearest.is_finite().then_some(nearest);
        if nearest_scan_m.is_none() {
            warnings.push(format!(
                "station {}: no scanned point within {reach_m} m; it lies outside the scans (or the survey is misregistered there)",
                s.name
            ));
        }
        let (outline, no_section) = match section::outline(points) {
            Ok(o) => (Some(o), None),
            Err(why) => (None, Some(why)),
        };
        let mut file = None;
        if let Some(o) = &outline {
            let path = dir.join("sections").join(format!("{}.svg", file_name(&s.name)));
            crate::cli::export::write_atomically(&path, section::svg(&s.name, o, 100.0).as_bytes())?;
            file = Some(path.display().to_string());
            if !o.inside {
                warnings.push(format!(
                    "station {}: stands outside the scanned passage, {:.2} m from its middle",
                    s.name, o.from_middle_m
                ));
            }
        }
        reports.push(StationReport {
            station: s.name.clone(),
            position_m: s.position_m,
            section: file,
            no_section,
            width_m: outline.as_ref().map(|o| o.width_m),
            height_m: outline.as_ref().map(|o| o.height_m),
            area_m2: outline.as_ref().map(|o| o.area_m2),
            inside: outline.as_ref().map(|o| o.inside),
            from_middle_m: outline.as_ref().map(|o| o.from_middle_m),
            nearest_scan_m,
        });
    }
    Ok((reports, warnings))
}

/// `passages.csv`: a row per station, a comment line with the surveyed length last.
fn passages_table(stations: &[StationReport], survey: &Survey) -> String {
    let cell = |v: Option<f64>| v.map(|v| format!("{v:.3}")).unwrap_or_default();
    let quote = |s: &str| {
        if s.contains([',', '"', '\n']) { format!("\"{}\"", s.replace('"', "\"\"")) } else { s.to_owned() }
    };
    let mut out =
        String::from("station,x,y,z,width_m,height_m,area_m2,inside,from_middle_m,nearest_scan_m\n");
    for s in stations {
        out.push_str(&format!(
            "{},{:.3},{:.3},{:.3},{},{},{},{},{},{}\n",
            quote(&s.station),
            s.position_m[0],
            s.position_m[1],
            s.position_m[2],
            cell(s.width_m),
            cell(s.height_m),
            cell(s.area_m2),
            s.inside.map(|b| b.to_string()).unwrap_or_default(),
            cell(s.from_middle_m),
            cell(s.nearest_scan_m)
        ));
    }
    out.push_str(&format!("# surveyed length {:.2} m\n", survey.surveyed_length_m()));
    out
}
