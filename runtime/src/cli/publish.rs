//! `grotto publish`: a static web site that shows a package in the browser (the web crate's
//! viewer, built by `scripts/build-web.sh`). The site is the viewer bundle (HTML, its JS glue,
//! the wasm), the package copied as it is, and `viewer.json` (which package, the title and the
//! viewer's default options). Nothing runs on the server: any static host that answers HTTP
//! range requests serves it (docs/web.md). The site is written beside its destination and moved
//! into place at the end, so a failed publish leaves the site that was there.

use std::path::{Path, PathBuf};

use grotto_format::Package;

use crate::cli::render_job;
use crate::engine::RenderOptions;
use crate::view::framing::CameraChoice;
use grotto_format::{Poi, Tour};
use serde::Serialize;

use crate::error::{Error, Result};

/// The files a viewer bundle holds (`scripts/build-web.sh` writes them to `target/web`).
pub const BUNDLE_FILES: [&str; 3] = ["index.html", "grotto_web.js", "grotto_web_bg.wasm"];

/// What `grotto publish` is asked.
#[derive(Clone, Debug)]
pub struct PublishOptions {
    pub package: PathBuf,
    /// The site's folder (made, or replaced whole).
    pub out: PathBuf,
    /// The viewer bundle; None: [`default_bundle`].
    pub bundle: Option<PathBuf>,
    /// The page's title (default: the package's file name).
    pub title: Option<String>,
    /// The viewer's defaults (web crate `Options`: camera, preset, bounces...), as JSON.
    pub viewer_options: serde_json::Map<String, serde_json::Value>,
    /// Points of interest and tours (TOML) added to the package's: [`crate::engine::story_file::story_of`].
    pub story: Option<PathBuf>,
    /// The still picture a browser without WebGPU shows (None: none).
    pub picture: Option<Picture>,
    /// A lighting file changing the package's lights (engine/lighting_file.rs): the page and its
    /// picture are lit by it.
    pub lights: Option<PathBuf>,
}

/// The still picture `grotto publish` renders for browsers without WebGPU: the first tour's first
/// stop, else the camera the page opens on, at the page's quality and bounces, anti-aliased.
#[derive(Clone, Debug)]
pub struct Picture {
    pub width: u32,
    pub height: u32,
    pub gpu: crate::gpu::GpuOptions,
}

/// The picture's file in the site.
pub const PICTURE_FILE: &str = "picture.jpg";

/// What was written.
#[derive(Clone, Debug, Serialize)]
pub struct PublishSummary {
    pub site: String,
    pub package_bytes: u64,
    /// The viewer's files (HTML, JS, wasm) and their bytes.
    pub bundle_bytes: u64,
    pub wasm_bytes: u64,
    pub files: Vec<String>,
    /// Points of interest and tours the page offers (the package's and the story file's).
    pub pois: usize,
    pub tours: usize,
    /// The still picture for browsers without WebGPU, and the seconds it took to render.
    pub picture: Option<String>,
    pub picture_s: f64,
}

/// Where the still picture is taken from: the first tour's first stop, else the page's camera
/// (`options["camera"]`), else the package's first camera or a framed view.
fn picture_camera(
    pois: &[Poi],
    tours: &[Tour],
    options: &serde_json::Map<String, serde_json::Value>,
) -> CameraChoice {
    let z_up = [0.0, 0.0, 1.0];
    if let Some(stop) = tours.first().and_then(|t| t.stops.first()) {
        if let Some(p) = stop.poi.as_ref().and_then(|n| pois.iter().find(|p| &p.name == n)) {
            return CameraChoice::Explicit {
                eye_m: p.eye_m,
                look_at_m: p.look_at_m,
                up: z_up,
                fov_y_deg: p.fov_y_deg,
            };
        }
        if let Some(c) = &stop.camera {
            return CameraChoice::Named(c.clone());
        }
        if let (Some(eye_m), Some(look_at_m)) = (stop.eye_m, stop.look_at_m) {
            return CameraChoice::Explicit {
                eye_m,
                look_at_m,
                up: z_up,
                fov_y_deg: stop.fov_y_deg.unwrap_or(60.0),
            };
        }
    }
    match options.get("camera").and_then(|c| c.as_str()) {
        Some(name) => CameraChoice::Named(name.to_owned()),
        None => CameraChoice::Default,
    }
}

/// Renders the still picture into `dir` (the page's quality and bounces, 8 samples a pixel).
fn render_picture(opts: &PublishOptions, picture: &Picture, camera: CameraChoice, dir: &Path) -> Result<()> {
    use crate::settings::{Quality, Settings};
    let o = &opts.viewer_options;
    let quality =
        o.get("quality").and_then(|q| q.as_str()).and_then(Quality::parse).unwrap_or(Quality::Balanced);
    let mut settings = Settings::preset(quality);
    if let Some(b) = o.get("bounces").and_then(serde_json::Value::as_u64) {
        settings.bounces = b.min(64) as u32;
    }
    let render = RenderOptions {
        camera,
        width: picture.width,
        height: picture.height,
        settings,
        exposure: o.get("exposure").and_then(serde_json::Value::as_f64).map(|e| e as f32),
        gpu: picture.gpu.clone(),
        samples: crate::passes::resolve::DEFAULT_STILL_SAMPLES,
        // The picture stands in for the page: its labels and lighting too.
        labels: true,
        lights: opts.lights.clone(),
        ..RenderOptions::defaults(opts.package.clone(), dir.join(PICTURE_FILE))
    };
    render_job::run(&render, |_| {}).map(drop).map_err(|e| {
        output(
            &opts.package,
            format!(
                "the still picture for browsers without WebGPU: {e} (--no-picture publishes without one)"
            ),
        )
    })
}

/// Where the viewer bundle is looked for: `GROTTO_WEB_BUNDLE`, else `web` beside the folder of
/// the running binary (`target/release/grotto` finds `target/web`).
pub(crate) fn default_bundle() -> Option<PathBuf> {
    if let Some(p) = std::env::var_os("GROTTO_WEB_BUNDLE") {
        return Some(PathBuf::from(p));
    }
    let exe = std::env::current_exe().ok()?;
    Some(exe.parent()?.parent()?.join("web"))
}

fn output(path: &Path, reason: impl std::fmt::Display) -> Error {
    Error::Output { path: path.display().to_string(), reason: reason.to_string() }
}

/// Writes the site; see the module docs.
pub fn publish(opts: &PublishOptions) -> Result<PublishSummary> {
    // The package must open and check whole: a browser gets no better error than this.
    let pkg = Package::open(&opts.package)?;
    let problems = pkg.verify();
    if let Some(p) = problems.first() {
        return Err(output(&opts.package, format!("is damaged ({} problems; first: {p})", problems.len())));
    }
    let package_bytes = pkg.file_size();
    let world = pkg.scene()?;
    let (pois, tours) = crate::engine::story_file::story_of(&world, opts.story.as_deref())?;
    let relight =
        opts.lights.as_ref().map(|p| crate::engine::lighting_file::relight_of(&world, p)).transpose()?;
    drop(pkg);
    let bundle = opts.bundle.clone().or_else(default_bundle).ok_or_else(|| {
        output(
            Path::new("viewer bundle"),
            "cannot locate it: pass --bundle DIR (scripts/build-web.sh writes target/web)",
        )
    })?;
    for f in BUNDLE_FILES {
        if !bundle.join(f).is_file() {
            return Err(output(
                &bundle,
                format!(
                    "is not a viewer bundle (no {f}): build it with scripts/build-web.sh (writes target/web), \
                     or pass --bundle DIR / set GROTTO_WEB_BUNDLE"
                ),
            ));
        }
    }
    let file_name = opts
        .package
        .file_name()
        .and_then(|n| n.to_str())
        .filter(|n| !n.is_empty() && n.chars().all(|c| c.is_ascii_alphanumeric() || "._-".contains(c)))
        .map_or_else(|| "cave.grotto".to_owned(), str::to_owned);
    if BUNDLE_FILES.contains(&file_name.as_str()) || file_name == "viewer.json" {
        return Err(output(&opts.package, "its file name is one the site's own files take; rename it"));
    }
    let parent = match opts.out.parent() {
        Some(p) if !p.as_os_str().is_empty() => p.to_path_buf(),
        _ => PathBuf::from("."),
    };
    std::fs::create_dir_all(&parent).map_err(|e| output(&parent, e))?;
    let staging = tempfile::Builder::new()
        .prefix(".grotto-publish-")
        .tempdir_in(&parent)
        .map_err(|e| output(&parent, format!("cannot make a folder beside the site: {e}")))?;
    let mut files = Vec::new();
    let mut bundle_bytes = 0;
    let mut wasm_bytes = 0;
    for f in BUNDLE_FILES {
        let n =
            std::fs::copy(bundle.join(f), staging.path().join(f)).map_err(|e| output(&bundle.join(f), e))?;
        bundle_bytes += n;
        if f.ends_with(".wasm") {
            wasm_bytes = n;
        }
        files.push(f.to_owned());
    }
    std::fs::copy(&opts.package, staging.path().join(&file_name)).map_err(|e| output(&opts.package, e))?;
    files.push(file_name.clone());
    let mut picture_s = 0.0;
    if let Some(p) = &opts.picture {
        let t0 = web_time::Instant::now();
        render_picture(opts, p, picture_camera(&pois, &tours, &opts.viewer_options), staging.path())?;
        picture_s = t0.elapsed().as_secs_f64();
        files.push(PICTURE_FILE.into());
    }
    let title = opts.title.clone().unwrap_or_else(|| file_name.trim_end_matches(".grotto").to_owned());
    let config = serde_json::json!({
        "package": file_name,
        "title": title,
        "options": opts.viewer_options,
        // The page labels, lists and plays these (the package's own, amended by --story).
        "story": { "pois": pois, "tours": tours },
        // What a browser without WebGPU shows.
        "picture": opts.picture.as_ref().map(|_| PICTURE_FILE),
        // The package's lights as --lights changed them (None: the package's own).
        "lighting": relight,
    });
    let text = serde_json::to_string_pretty(&config).map_err(|e| output(&opts.out, e))?;
    std::fs::write(staging.path().join("viewer.json"), text).map_err(|e| output(&opts.out, e))?;
    files.push("viewer.json".into());

    // Into place: the old site (if any) moves aside, the new one takes its name, the old goes.
    let staged = staging.keep();
    let old = parent.join(format!(
        ".grotto-publish-old-{}",
        opts.out.file_name().and_then(|n| n.to_str()).unwrap_or("site")
    ));
    let _ = std::fs::remove_dir_all(&old);
    let had_site = opts.out.exists();
    if had_site {
        std::fs::rename(&opts.out, &old).map_err(|e| output(&opts.out, format!("cannot replace it: {e}")))?;
    }
    if let Err(e) = std::fs::rename(&staged, &opts.out) {
        if had_site {
            let _ = std::fs::rename(&old, &opts.out);
        }
        let _ = std::fs::remove_dir_all(&staged);
        return Err(output(&opts.out, e));
    }
    if had_site {
        let _ = std::fs::remove_dir_all(&old);
    }
    Ok(PublishSummary {
        site: opts.out.display().to_string(),
        package_bytes,
        bundle_bytes,
        wasm_bytes,
        files,
        pois: pois.len(),
        tours: tours.len(),
        picture: opts.picture.as_ref().map(|_| PICTURE_FILE.to_owned()),
        picture_s,
    })
}
