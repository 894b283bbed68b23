//! Step 3, assemble: every tile package's sections copied as stored (checksums checked) into the
//! output, with each tile's coarse levels and rock, the environment, the scene and provenance.

use std::path::Path;

use grotto_format::{Compression, InputFile, Package, PackageWriter, Provenance, Scene, Scope, SectionKind};
use rayon::prelude::*;

use crate::bins::TilePlan;
use crate::build::inspect::{self, Finished};
use crate::build::params::BuildParams;
use crate::build::plan::cut_short;
use crate::build::plan::planned;
use crate::build::summary::BuildSummary;
use crate::build::summary::StepSeconds;
use crate::build::tile::tile_fingerprint;
use crate::build::tile::tile_of_package;
use crate::build::tile::tile_package_path;
use crate::ingest::ScanFormat;
use crate::manifest::{Manifest, ResolvedScan, SeenFrom};
use crate::normals::NormalStats;
use crate::profile::{Profile, Stage};
use crate::tiling::Progress;
use crate::{Error, Result};

/// The package's scan list (what the surfel-scans sections index): each scan's file name, with
/// `#k` where a file format holds several scans.
pub(crate) fn scan_infos(scans: &[ResolvedScan]) -> Vec<grotto_format::ScanInfo> {
    scans
        .iter()
        .map(|s| {
            let file = s
                .path
                .file_name()
                .map_or_else(|| s.path.display().to_string(), |n| n.to_string_lossy().into());
            let name = if s.format == ScanFormat::E57 { format!("{file}#{}", s.index) } else { file };
            grotto_format::ScanInfo { name }
        })
        .collect()
}

pub(crate) fn hash_file(path: &Path) -> Result<InputFile> {
    use std::io::Read;
    let io = |source| Error::Io { path: path.to_path_buf(), source };
    let mut f = std::fs::File::open(path).map_err(io)?;
    let mut h = xxhash_rust::xxh3::Xxh3::new();
    let mut buf = vec![0u8; 1 << 20];
    let mut bytes = 0u64;
    loop {
        let n = f.read(&mut buf).map_err(io)?;
        if n == 0 {
            break;
        }
        h.update(&buf[..n]);
        bytes += n as u64;
    }
    Ok(InputFile { path: path.display().to_string(), bytes, xxh3: format!("{:016x}", h.digest()) })
}

/// Step 3, assemble: copies every tile package into `out` (atomically), with the environment,
/// scene and provenance. Fails, naming them, if tiles are missing or were built with other
/// parameters.
pub fn assemble(
    manifest: &Manifest,
    manifest_path: &Path,
    out: &Path,
    params: &BuildParams,
    progress: &(dyn Fn(Progress) + Sync),
) -> Result<BuildSummary> {
    let (plan, scans) = planned(manifest, params)?;
    let profile = Profile::default();
    let scene = manifest.scene(manifest_path)?;
    let mut summary = assemble_plan(manifest, &plan, &scans, &scene, out, params, progress, &profile)?;
    summary.stages = profile.report();
    summary.cut_short = cut_short(&scans, false)?;
    Ok(summary)
}

// The plan step's results, the output and how to report: bundling them would only rename them.
#[allow(clippy::too_many_arguments)]
pub(crate) fn assemble_plan(
    manifest: &Manifest,
    plan: &TilePlan,
    scans: &[ResolvedScan],
    scene: &Scene,
    out: &Path,
    params: &BuildParams,
    progress: &(dyn Fn(Progress) + Sync),
    profile: &Profile,
) -> Result<BuildSummary> {
    let start = std::time::Instant::now();
    let fingerprint = tile_fingerprint(plan, params);
    let total = plan.tiles.len();
    let mut clock = std::time::Instant::now();
    let finished = check_all_built(plan, &params.work_dir, &fingerprint, progress)?;
    profile.lap(Stage::CheckTiles, &mut clock);
    let levels = tile_levels(&params.work_dir, total, progress)?;
    profile.lap(Stage::Levels, &mut clock);
    let mut writer = PackageWriter::create(out)?;
    let copied = copy_tiles(&mut writer, &params.work_dir, &levels, &finished, progress)?;
    profile.lap(Stage::Assemble, &mut clock);
    let mut inputs = Vec::new();
    let mut env_window = None;
    if let Some(env) = &manifest.environment {
        let path = manifest.resolve_path(&env.map);
        env_window = Some(add_environment(&mut writer, &path, params.sh_window, progress)?);
        inputs.push(hash_file(&path)?);
        profile.lap(Stage::Environment, &mut clock);
    }
    writer.add_scene(&Scene { scans: scan_infos(scans), ..scene.clone() })?;
    if let (Some(spec), Some(survey)) = (&manifest.survey, &manifest.survey_data) {
        writer.add_survey(survey)?;
        inputs.push(hash_file(&manifest.resolve_path(&spec.path))?);
    }
    inputs.extend(hash_scans(scans)?);
    profile.lap(Stage::HashInputs, &mut clock);
    writer.add_provenance(&Provenance {
        tool: "grotto-pack build".into(),
        tool_version: env!("CARGO_PKG_VERSION").into(),
        inputs,
        parameters: provenance_parameters(params, plan, env_window),
    })?;
    let path = writer.finish()?;
    profile.lap(Stage::Assemble, &mut clock);
    let bytes = std::fs::metadata(&path).map_err(|source| Error::Io { path: path.clone(), source })?.len();
    let mut summary = assembled_summary(plan, scans, scene, params, &copied.normals);
    summary.package = path.display().to_string();
    summary.bytes = bytes;
    summary.seam_limited_points = copied.seam_limited_points;
    summary.seconds = start.elapsed().as_secs_f64();
    summary.steps = StepSeconds { assemble: start.elapsed().as_secs_f64(), ..StepSeconds::default() };
    Ok(summary)
}

/// Every tile's record, or an error listing each tile that cannot be used and why (missing,
/// partial, stale, damaged). Every tile is checked whole (fingerprint, checksums, content) here,
/// in parallel, because a work directory shared by many nodes is not trusted.
fn check_all_built(
    plan: &TilePlan,
    work_dir: &Path,
    fingerprint: &str,
    progress: &(dyn Fn(Progress) + Sync),
) -> Result<Vec<Finished>> {
    let total = plan.tiles.len();
    let done = std::sync::atomic::AtomicU64::new(0);
    let checked: Vec<_> = (0..total)
        .into_par_iter()
        .map(|t| {
            let state = inspect::inspect(work_dir, t, &plan.fingerprint, fingerprint);
            let n = done.fetch_add(1, std::sync::atomic::Ordering::Relaxed) + 1;
            progress(Progress { stage: "check tiles", done: n, total: total as u64 });
            state
        })
        .collect();
    let problems: Vec<_> = checked.iter().filter_map(|c| c.as_ref().err().cloned()).collect();
    if !problems.is_empty() {
        return Err(Error::Tiles { work_dir: work_dir.to_path_buf(), total, problems });
    }
    Ok(checked.into_iter().filter_map(|c| c.ok()).collect())
}

/// Each tile's coarse level and rock (format 1.1), so a renderer opening the package reads only
/// the tiles it shows in full. The rock near a border needs the neighbours' walls, so this runs
/// once every tile is built, over every tile package at once (it reads their SVOs only; the maps
/// are dropped before the copy touches the surfels).
fn tile_levels(
    work_dir: &Path,
    total: usize,
    progress: &(dyn Fn(Progress) + Sync),
) -> Result<Vec<grotto_levels::TileLevels>> {
    let packages = (0..total)
        .map(|t| Package::open(tile_package_path(work_dir, t)))
        .collect::<std::result::Result<Vec<_>, _>>()?;
    let tiles =
        packages.iter().enumerate().map(|(t, p)| tile_of_package(p, t)).collect::<Result<Vec<_>>>()?;
    let grid = grotto_levels::TileGrid::of(&tiles);
    let done = std::sync::atomic::AtomicU64::new(0);
    (0..total)
        .into_par_iter()
        .map(|t| {
            let levels = grotto_levels::tile_levels(&tiles, &grid, t)?;
            let n = done.fetch_add(1, std::sync::atomic::Ordering::Relaxed) + 1;
            progress(Progress { stage: "levels", done: n, total: total as u64 });
            Ok(levels)
        })
        .collect::<Result<Vec<_>>>()
}

/// What copying the tiles gathered from their packages' provenance.
struct Copied {
    seam_limited_points: u64,
    normals: NormalStats,
}

/// Copies every tile package's sections into `writer`, then the tile's coarse levels and rock.
fn copy_tiles(
    writer: &mut PackageWriter,
    work_dir: &Path,
    levels: &[grotto_levels::TileLevels],
    finished: &[Finished],
    progress: &(dyn Fn(Progress) + Sync),
) -> Result<Copied> {
    let total = levels.len();
    let mut copied = Copied { seam_limited_points: 0, normals: NormalStats::default() };
    // Two tile packages mapped at a time (copying touches every page of a tile's surfels): the
    // next one's sections are checked (checksums, zstd decoded) on another thread while this one
    // is copied, which was half of the copy's serial time. check_all_built verified the same
    // sections already, but on packages it has dropped: keeping every tile mapped until here
    // would hold all their pages (peak memory), and `copy_section` checks what it copies anyway
    // (the writer carries no damage over). Each check is about 0.06 s at 10^7 points.
    let open_checked = |t: usize| -> Result<Package> {
        let pkg = Package::open(tile_package_path(work_dir, t))?;
        for s in tile_of_package(&pkg, t)?.sections() {
            pkg.check(&s)?;
        }
        Ok(pkg)
    };
    let mut next = (total > 0).then(|| open_checked(0));
    for (t, levels) in levels.iter().enumerate() {
        copied.seam_limited_points += finished[t].seam_limited;
        copied.normals.add(&finished[t].normals);
        let Some(tile_pkg) = next.take() else { break };
        let tile_pkg = tile_pkg?;
        let tile = tile_of_package(&tile_pkg, t)?;
        let index = writer.add_tile(tile.info())?;
        let scope = Scope::Tile(index);
        let (done, following) = rayon::join(
            || tile.sections().try_for_each(|s| writer.copy_section(&tile_pkg, &s, scope).map(drop)),
            || (t + 1 < total).then(|| open_checked(t + 1)),
        );
        done?;
        next = following;
        for (k, coarse) in &levels.coarse {
            writer.add_elements(SectionKind::CoarseNodes, scope, *k, &coarse.nodes, Compression::Auto(3))?;
            writer.add_elements(
                SectionKind::CoarseLeaves,
                scope,
                *k,
                &coarse.leaves,
                Compression::Auto(3),
            )?;
        }
        if let Some(rock) = &levels.rock {
            writer.add_elements(SectionKind::RockBricks, scope, 0, rock, Compression::Auto(3))?;
        }
        progress(Progress { stage: "assemble", done: t as u64 + 1, total: total as u64 });
    }
    Ok(copied)
}

/// The environment map at `path` as SH9 irradiance and the prefiltered BC6H chain; returns the SH
/// window's strength (0 without one).
fn add_environment(
    writer: &mut PackageWriter,
    path: &Path,
    sh_window: bool,
    progress: &(dyn Fn(Progress) + Sync),
) -> Result<f64> {
    progress(Progress { stage: "environment", done: 0, total: 1 });
    let map = crate::env::LatLong::read(path)?;
    let mut sh = map.project_sh9();
    let window = if sh_window { crate::env::window(&mut sh) } else { 0.0 };
    let (levels, blocks) = crate::env::encode_chain(&crate::env::prefilter(&map, 256, 6, 128));
    writer.add_elements(SectionKind::EnvSh9, Scope::Global, 0, &[sh], Compression::Raw)?;
    writer.add_elements(SectionKind::EnvMipLevels, Scope::Global, 0, &levels, Compression::Raw)?;
    writer.add_elements(SectionKind::EnvMipBc6h, Scope::Global, 0, &blocks, Compression::Raw)?;
    progress(Progress { stage: "environment", done: 1, total: 1 });
    Ok(window)
}

/// Every scan file once, in scan order, with its size and hash.
fn hash_scans(scans: &[ResolvedScan]) -> Result<Vec<InputFile>> {
    let mut inputs = Vec::new();
    let mut seen = std::collections::BTreeSet::new();
    for s in scans {
        if seen.insert(s.path.clone()) {
            inputs.push(hash_file(&s.path)?);
        }
    }
    Ok(inputs)
}

/// The options that shaped the package's content, for its provenance.
fn provenance_parameters(
    params: &BuildParams,
    plan: &TilePlan,
    env_window: Option<f64>,
) -> std::collections::BTreeMap<String, serde_json::Value> {
    let tiling_params = params.tiling();
    let mut parameters = std::collections::BTreeMap::new();
    for (k, v) in [
        ("leaf_m", serde_json::json!(params.leaf_m)),
        ("colors", serde_json::json!(params.colors)),
        ("surfels", serde_json::json!(params.surfels)),
        ("k", serde_json::json!(params.k)),
        ("min_tile_extent_m", serde_json::json!(params.min_tile_extent_m)),
        ("max_tile_extent_m", serde_json::json!(params.max_tile_extent_m)),
        ("max_points_per_tile", serde_json::json!(tiling_params.max_points_per_tile)),
        ("halo_m", serde_json::json!(params.halo_m)),
        ("grid_origin_m", serde_json::json!(plan.grid_origin_m())),
        ("quantum_m", serde_json::json!(plan.quantum_m)),
        ("sh_window_strength", serde_json::json!(env_window)),
    ] {
        parameters.insert(k.to_string(), v);
    }
    parameters
}

/// The summary of an assembled package, less what only the caller knows (its path, bytes, times
/// and seams).
fn assembled_summary(
    plan: &TilePlan,
    scans: &[ResolvedScan],
    scene: &Scene,
    params: &BuildParams,
    normals: &NormalStats,
) -> BuildSummary {
    BuildSummary {
        package: String::new(),
        scans: scans.len(),
        points: plan.points,
        invalid_points: plan.invalid_points,
        halo_points: plan.halo_points,
        tiles: plan.tiles.len(),
        bytes: 0,
        seconds: 0.0,
        resumed_tiling: false,
        reused_tiles: 0,
        seam_limited_points: 0,
        orientation: (normals.orientation.points > 0).then_some(normals.orientation),
        input_normals: normals.input_normals,
        input_normals_kept: normals.input_kept,
        keep_input_normals: params.keep_input_normals,
        scans_without_scanner: plan.scanner_known.iter().filter(|k| !**k).count(),
        scans_seen_from_outside: (0..plan.scanner_known.len())
            .filter(|&s| plan.seen_from(s) == Some(SeenFrom::Outside))
            .count(),
        peak_rss_bytes: crate::profile::peak_rss_bytes(),
        leaf_m: params.leaf_m,
        lights: scene.lights.len(),
        cameras: scene.cameras.len(),
        environment: scene.environment.is_some(),
        cut_short: Vec::new(),
        steps: StepSeconds::default(),
        stages: Vec::new(),
    }
}
