//! `grotto`: inspect, verify (and, as the runtime grows, render) .grotto packages.

use std::path::PathBuf;
use std::process::ExitCode;

use clap::{Parser, Subcommand};
use grotto_format::Package;
use grotto_runtime::cli::inspect;

#[derive(Parser, Debug)]
#[command(name = "grotto", version, about = "Inspect, verify and render .grotto cave packages")]
struct Cli {
    #[command(subcommand)]
    command: Command,
}

#[derive(Subcommand, Debug)]
enum Command {
    /// Describe a package: version, tiles, sections, sizes, compression ratios, scene.
    Inspect {
        package: PathBuf,
        /// List every section.
        #[arg(long)]
        sections: bool,
        /// Load the scene as the renderer does and report the GPU bytes of every buffer whose
        /// size follows the content (nodes, leaves, surfels, rock...), no GPU needed.
        #[arg(long)]
        gpu_memory: bool,
        /// Machine-readable output.
        #[arg(long)]
        json: bool,
    },
    /// Export the merged points with normals, colours, radii and spread (PLY or LAS, by extension).
    Export {
        package: PathBuf,
        /// Output point file: .ply or .las.
        #[arg(long)]
        points: PathBuf,
        /// Machine-readable output.
        #[arg(long)]
        json: bool,
    },
    /// Render a package with global illumination to PNG (tonemapped) or EXR (linear radiance).
    ///
    /// Plans the passes from the scene (see --explain), propagates light until it converges or the
    /// bounce budget is spent, then renders the camera (or a path through named cameras).
    Render(Box<RenderArgs>),
    /// Time every pass (GPU timestamps where the adapter has them) on a package: shadow maps,
    /// injection, one bounce (mip + propagate), G-buffer and shading, repeated; median per pass.
    Bench(Box<BenchArgs>),
    /// Explore a package in a window with a panel (quality, bounces, exposure, shadows, view; the
    /// effect plan, fps and pass times, resident tiles). Mouse drag looks, WASD flies (Q/E
    /// down/up), the wheel sets the speed; a right click orbits the point under the cursor, O the
    /// centre (O again: fly); Tab next named camera, R the first; 1-7 views (lit, albedo, normals,
    /// light, level, scan, lux); C clip box; M measure; G / N / B tours; L lighting mode; H panel;
    /// K records a camera path; P screenshot; F11 full screen; Esc quits.
    /// Tiles follow the camera; the light waits while it moves and converges when it rests. Takes
    /// the render options (--size is the window's size).
    View(Box<ViewArgs>),
    /// Write a static web site that shows a package in the browser (WebGPU): the viewer, the
    /// package as it is, and viewer.json. The viewer fetches the package by HTTP range requests
    /// (directory first, then the tiles the view needs), so any static host that answers ranges
    /// serves it (docs/web.md). Needs the viewer bundle scripts/build-web.sh builds.
    Publish(Box<PublishArgs>),
    /// Check a package's structure and every checksum and section; exits non-zero on any problem.
    Verify {
        package: PathBuf,
        /// Machine-readable output.
        #[arg(long)]
        json: bool,
    },
}

#[derive(clap::Args, Debug)]
struct PublishArgs {
    package: PathBuf,
    /// The site's folder (made; replaced whole if it exists).
    #[arg(long)]
    out: PathBuf,
    /// The viewer bundle (default: $GROTTO_WEB_BUNDLE, else `web` beside the binary's folder,
    /// where scripts/build-web.sh puts it: target/web).
    #[arg(long)]
    bundle: Option<PathBuf>,
    /// The page's title (default: the package's name).
    #[arg(long)]
    title: Option<String>,
    /// The camera the page opens on (default: the package's first).
    #[arg(long)]
    camera: Option<String>,
    /// Quality preset the page starts with: fast, balanced, high (as grotto render --quality).
    #[arg(long)]
    quality: Option<String>,
    /// Most light bounces.
    #[arg(long)]
    bounces: Option<u32>,
    /// Fixed exposure (default: automatic, as grotto render).
    #[arg(long)]
    exposure: Option<f32>,
    /// Points of interest and tours to add to the package's (TOML: [[poi]], [[tour]] as in a
    /// manifest, docs/manifest.md); one named as one of the package's replaces it.
    #[arg(long)]
    story: Option<PathBuf>,
    /// A lighting file changing the package's lights ([[light]], [[circuit]]; docs/runtime.md):
    /// the page and its picture are lit by it.
    #[arg(long)]
    lights: Option<PathBuf>,
    /// Size WIDTHxHEIGHT of the still picture a browser without WebGPU shows (rendered here,
    /// at the first tour stop or the page's camera).
    #[arg(long, default_value = "800x600", value_parser = grotto_runtime::cli::render_job::parse_size)]
    picture: (u32, u32),
    /// Publish without the still picture (no GPU here to render it).
    #[arg(long)]
    no_picture: bool,
    /// Render the picture on the software rasteriser.
    #[arg(long)]
    software: bool,
    /// Machine-readable output.
    #[arg(long)]
    json: bool,
}

fn publish(a: PublishArgs) -> anyhow::Result<ExitCode> {
    use grotto_runtime::cli::publish;
    if let Some(q) = &a.quality {
        anyhow::ensure!(
            grotto_runtime::settings::Quality::parse(q).is_some(),
            "--quality {q}: expected fast, balanced or high"
        );
    }
    let mut viewer_options = serde_json::Map::new();
    if let Some(c) = a.camera {
        viewer_options.insert("camera".into(), c.into());
    }
    if let Some(q) = a.quality {
        viewer_options.insert("quality".into(), q.into());
    }
    if let Some(b) = a.bounces {
        viewer_options.insert("bounces".into(), b.into());
    }
    if let Some(e) = a.exposure {
        anyhow::ensure!(e.is_finite() && e > 0.0, "--exposure {e}: expected a number > 0");
        viewer_options.insert("exposure".into(), e.into());
    }
    let summary = publish::publish(&publish::PublishOptions {
        package: grotto_runtime::cli::scan_input::package_for(&a.package, |m| eprintln!("{m}"))?,
        out: a.out,
        bundle: a.bundle,
        title: a.title,
        viewer_options,
        story: a.story,
        lights: a.lights,
        picture: (!a.no_picture).then(|| publish::Picture {
            width: a.picture.0,
            height: a.picture.1,
            gpu: grotto_runtime::gpu::GpuOptions { prefer_software: a.software, ..Default::default() },
        }),
    })?;
    if a.json {
        println!("{}", serde_json::to_string_pretty(&summary)?);
    } else {
        let mb = |b: u64| b as f64 / 1e6;
        println!(
            "wrote {}: {} ({:.2} MB package, {:.2} MB viewer of which {:.2} MB wasm; {} points of \
             interest, {} tours); serve it from any static host that answers range requests (docs/web.md)",
            summary.site,
            summary.files.join(", "),
            mb(summary.package_bytes),
            mb(summary.bundle_bytes),
            mb(summary.wasm_bytes),
            summary.pois,
            summary.tours
        );
    }
    Ok(ExitCode::SUCCESS)
}

#[derive(clap::Args, Debug)]
struct RenderArgs {
    /// The package (a LAS/LAZ, PLY or E57 scan is packed by grotto-pack first, once, into a cache).
    package: PathBuf,
    /// A camera or point of interest named in the package (default: its first camera; without
    /// one, a view framed on the data, printed so it can be reused with --eye/--look-at).
    #[arg(long, conflicts_with_all = ["eye", "path"])]
    camera: Option<String>,
    /// Eye position, world metres "x,y,z" (with --look-at); negative numbers as written.
    #[arg(long, value_parser = parse_vec3, requires = "look_at", allow_hyphen_values = true)]
    eye: Option<[f64; 3]>,
    /// Point looked at, world metres "x,y,z".
    #[arg(long, value_parser = parse_vec3, requires = "eye", allow_hyphen_values = true)]
    look_at: Option<[f64; 3]>,
    /// Up direction "x,y,z".
    #[arg(long, value_parser = parse_vec3, default_value = "0,0,1", allow_hyphen_values = true)]
    up: [f64; 3],
    /// Headlamp at the camera: "auto" (only when the scene has no lights, emission or
    /// environment map), "on" or "off".
    #[arg(long, default_value = "auto")]
    headlamp: String,
    /// Vertical field of view, degrees (with --eye).
    #[arg(long, default_value_t = 60.0)]
    fov: f64,
    /// Fly through these named cameras, comma-separated (with --frames), or along a camera path
    /// file (one FILE.toml: [[camera]] tables in world metres, as grotto view records them).
    #[arg(long, value_delimiter = ',')]
    path: Vec<String>,
    /// Frames along --path.
    #[arg(long, default_value_t = 30)]
    frames: u32,
    /// A tour of the package (grotto publish's page plays it): an image a stop, what a visitor
    /// sees there once the light has converged; with --tour-fps, the tour as a film (flights
    /// and dwells at that many frames a second).
    #[arg(long, conflicts_with_all = ["camera", "eye", "path"])]
    tour: Option<String>,
    /// Frames a second of a --tour film.
    #[arg(long, requires = "tour")]
    tour_fps: Option<f32>,
    /// Points of interest and tours to add to the package's (TOML: [[poi]], [[tour]] as in a
    /// manifest): --camera and --tour find them, grotto view shows them.
    #[arg(long)]
    story: Option<PathBuf>,
    /// A lighting file (TOML: [[light]] and [[circuit]] in watts or lumens, RGB or kelvin, IES
    /// profiles) changing the package's lights without a rebuild (docs/runtime.md).
    #[arg(long)]
    lights: Option<PathBuf>,
    /// Circuits switched on or off, NAME=on|off[,...] (the lighting file's or the package's).
    #[arg(long, value_delimiter = ',', value_parser = grotto_runtime::engine::lighting_file::parse_switch)]
    circuits: Vec<(String, bool)>,
    /// grotto render: draw the labels of the points of interest in view (not those rock hides) into the
    /// image, as the published page shows them (.png and .jpg). grotto view always shows them.
    #[arg(long)]
    labels: bool,
    /// Image size WIDTHxHEIGHT.
    #[arg(long, default_value = "800x600", value_parser = grotto_runtime::cli::render_job::parse_size)]
    size: (u32, u32),
    /// Output image (.png or .exr); a path sequence appends _NNNN.
    #[arg(long, short, default_value = "render.png")]
    out: PathBuf,
    /// Quality preset: fast, balanced or high (measured error and time: docs/accuracy.md); the
    /// knob options below override single settings of it.
    #[arg(long, default_value = "balanced")]
    quality: String,
    /// Bounce budget (propagation passes; stops earlier once converged).
    #[arg(long)]
    bounces: Option<u32>,
    /// Cones per leaf gather (1..=16).
    #[arg(long)]
    cones: Option<u32>,
    /// Cone aperture scale (1 = cones tile the hemisphere).
    #[arg(long)]
    aperture: Option<f32>,
    /// Cone step as a fraction of its diameter.
    #[arg(long)]
    step: Option<f32>,
    /// Longest cone in metres (default: the scene diagonal).
    #[arg(long)]
    max_distance: Option<f32>,
    /// Shadow map size in texels per face.
    #[arg(long)]
    shadow_map: Option<u32>,
    /// Surfel radius multiplier for splatting (discs overlap so sparse sampling leaves no holes).
    #[arg(long, default_value_t = 2.0)]
    splat_scale: f32,
    /// Render without shadow maps.
    #[arg(long)]
    no_shadows: bool,
    /// Run only the bounces counted, without estimating the ones not run as a geometric tail
    /// (the light then stops short of converged in bright closed rock).
    #[arg(long)]
    no_bounce_tail: bool,
    /// Give every leaf the same cone set, not one turned by its cell's parity (which averages misses).
    #[arg(long)]
    no_cone_interleave: bool,
    /// Cones see the finest leaves as half-spaces behind their surface, not cubes (knob "cone planes").
    #[arg(long)]
    cone_planes: bool,
    /// Follow each gather cone as rays that end at the first surface (knob "cone rays").
    #[arg(long)]
    cone_rays: bool,
    /// Milliseconds a frame may spend redrawing shadow faces out of date (after a change of tiles or
    /// lights), at the measured surfels per millisecond; the rest follow over the next frames and show
    /// together when the last is drawn, so no frame stalls on the whole atlas (0, the default for render
    /// and bench: every face at once; the viewer's default is 8).
    #[arg(long)]
    shadow_ms: Option<f32>,
    /// Shadow-map budget: the N brightest point and spot lights get shadow maps and per-pixel light;
    /// the others are lit per leaf with --shadow-fallback (default 16).
    #[arg(long)]
    shadowed_lights: Option<u32>,
    /// Lights beyond the shadow-map budget: "cone" (SVO shadow cones) or "none" (unshadowed).
    #[arg(long, default_value = "cone")]
    shadow_fallback: String,
    /// What the image shows: lit (default), albedo, normals (0.5 + 0.5 n as colour), light (the light
    /// alone: every albedo 1), level (each tile's level: full green, coarse yellow, far red), or scan (each
    /// point's source scan as a colour, to see misregistration). All but lit and light skip the light passes.
    #[arg(long, default_value = "lit")]
    view: String,
    /// Cut the view to a box, world metres: MINX,MINY,MINZ,MAXX,MAXY,MAXZ (a section: cut the ceiling
    /// away to see a passage from above). Points outside are not drawn and get no point budget; the light
    /// is the whole cave's.
    #[arg(long, value_parser = parse_box, allow_hyphen_values = true)]
    clip: Option<[[f64; 3]; 2]>,
    /// Irradiance (W/m^2) under which a light is culled: bounds each light's range (0: no culling).
    #[arg(long)]
    light_cutoff: Option<f32>,
    /// What the splat passes cull by: "chunks" (default: runs of 1,024 surfels each shadow face
    /// or the camera may see) or "tiles" (whole tiles by their boxes, the coarser draws;
    /// the same image, for measuring the difference).
    #[arg(long, default_value = "chunks")]
    cull: String,
    /// Draw every surfel of far chunks, not every k-th grown to close the surface where their
    /// discs are under the pixel floor anyway (the level of detail by size on screen).
    #[arg(long)]
    no_splat_lod: bool,
    /// Show each pixel's front-most disc alone (each with its own normal and light: scales at
    /// grazing angles), not the blend of every disc of the front surface (the default where the
    /// adapter can blend f16 targets; for comparing).
    #[arg(long)]
    no_splat_blend: bool,
    /// Anti-aliasing for `grotto render`: draw at N times the width and height (1..=4) and
    /// average each N x N block; costs N^2 in G-buffer and shade work.
    #[arg(long, default_value_t = 1)]
    supersample: u32,
    /// Anti-aliasing by samples a pixel, each jittered within it, averaged (1..=64; costs that many frames'
    /// G-buffer and shade work, no more memory). grotto render: default 1 (the pixel centres). grotto view:
    /// gathered at rest, one a frame, default 8. grotto bench: times the resolve pass that adds a sample.
    #[arg(long)]
    samples: Option<u32>,
    /// Replace the package's lights by a lamp string of N 8 W lamps spread over the cave's floors
    /// (to measure how cost grows with the number of lights).
    #[arg(long)]
    lamps: Option<u32>,
    /// Store the radiance pyramid as f16 (half its memory; values above 65504 clamp).
    #[arg(long)]
    radiance_f16: bool,
    /// GPU memory for tiles, e.g. 512M or 2G (default: half the adapter's largest buffer, at
    /// most 2G). A package over it keeps the tiles the view needs in full and every other
    /// tile at its coarse or far level, nearer ones finer.
    #[arg(long, value_parser = grotto_format::parse_bytes)]
    gpu_memory: Option<u64>,
    /// Most surfels drawn (default: no limit); tiles beyond it are drawn from their coarse or far level.
    #[arg(long)]
    point_budget: Option<u64>,
    /// Along a path, run at most this many bounces before a frame whose tiles changed (default:
    /// settle); the rest runs one bounce per frame, so the light converges over frames. Tiles
    /// resident before and after keep their light either way.
    #[arg(long)]
    frame_bounces: Option<u32>,
    /// Along a path, most tile bytes uploaded before a frame, e.g. 16M (default: no limit, every
    /// frame gets the tiles its view wants). Changes to coarser forms always go through; finer
    /// ones go in priority order while they fit, and the rest wait for later frames.
    #[arg(long, value_parser = grotto_format::parse_bytes)]
    upload_per_frame: Option<u64>,
    /// Indirect light filter at pixels: trilinear, tricubic or off.
    #[arg(long)]
    indirect: Option<String>,
    /// Exposure multiplier (default: automatic from the first frame).
    #[arg(long)]
    exposure: Option<f32>,
    /// Relative change under which propagation counts as converged.
    #[arg(long, default_value_t = 1e-3)]
    tolerance: f32,
    /// Prefer the software adapter (Mesa lavapipe/llvmpipe) over a GPU.
    #[arg(long)]
    software: bool,
    /// Print the effect plan: which passes run and why.
    #[arg(long)]
    explain: bool,
    /// Machine-readable summary (plan, per-pass times, dispatch counts) on stdout.
    #[arg(long)]
    json: bool,
}

#[derive(clap::Args, Debug)]
struct BenchArgs {
    #[command(flatten)]
    render: RenderArgs,
    /// Repetitions (the median is reported).
    #[arg(long, default_value_t = 3)]
    reps: u32,
    /// Instead of pass times: what light edits cost. Each `[[light]]` of this lighting file is
    /// added to the scene's lights and removed again, each change settled (in place where it
    /// fits), then every light is relit for comparison: wall time, bounces, leaves, faces.
    #[arg(long, value_name = "FILE.toml")]
    edit_lights: Option<PathBuf>,
}

/// `N` finite comma-separated numbers.
fn parse_floats<const N: usize>(s: &str, expected: &str) -> Result<[f64; N], String> {
    let v: Vec<f64> = s
        .split(',')
        .map(|t| t.trim().parse::<f64>().map_err(|e| format!("{t:?}: {e}")))
        .collect::<Result<_, _>>()?;
    match <[f64; N]>::try_from(v) {
        Ok(a) if a.iter().all(|c| c.is_finite()) => Ok(a),
        _ => Err(format!("expected {N} finite numbers {expected}, got {s:?}")),
    }
}

fn parse_vec3(s: &str) -> Result<[f64; 3], String> {
    parse_floats(s, "x,y,z")
}

fn parse_box(s: &str) -> Result<[[f64; 3]; 2], String> {
    let [x0, y0, z0, x1, y1, z1] = parse_floats(s, "MINX,MINY,MINZ,MAXX,MAXY,MAXZ")?;
    Ok([[x0, y0, z0], [x1, y1, z1]])
}

fn options(a: &RenderArgs) -> anyhow::Result<grotto_runtime::engine::RenderOptions> {
    use grotto_runtime::engine::{Headlamp, RenderOptions};
    use grotto_runtime::settings::{IndirectFilter, Quality, Settings, ShadowFallback};
    use grotto_runtime::view::framing::CameraChoice;
    let quality = Quality::parse(&a.quality)
        .ok_or_else(|| anyhow::anyhow!("--quality {:?}: use fast, balanced or high", a.quality))?;
    let mut settings = Settings::preset(quality);
    if let Some(i) = &a.indirect {
        settings.indirect = match i.as_str() {
            "trilinear" => IndirectFilter::Trilinear,
            "tricubic" => IndirectFilter::Tricubic,
            "off" => IndirectFilter::Off,
            other => anyhow::bail!("--indirect {other:?}: use trilinear, tricubic or off"),
        };
    }
    settings.cones = a.cones.unwrap_or(settings.cones);
    settings.cone_aperture_scale = a.aperture.unwrap_or(settings.cone_aperture_scale);
    settings.step_scale = a.step.unwrap_or(settings.step_scale);
    settings.bounces = a.bounces.unwrap_or(settings.bounces);
    settings.shadow_map_size = a.shadow_map.unwrap_or(settings.shadow_map_size);
    settings.max_distance_m = a.max_distance;
    settings.convergence_tolerance = a.tolerance;
    settings.shadows = !a.no_shadows;
    settings.shadow_frame_ms = a.shadow_ms.unwrap_or(0.0);
    settings.bounce_tail = !a.no_bounce_tail;
    settings.cone_interleave = !a.no_cone_interleave;
    settings.cone_planes = a.cone_planes;
    settings.cone_rays = a.cone_rays;
    settings.shadowed_lights = a.shadowed_lights.unwrap_or(settings.shadowed_lights);
    settings.shadow_fallback = ShadowFallback::parse(&a.shadow_fallback)
        .ok_or_else(|| anyhow::anyhow!("--shadow-fallback {:?}: use cone or none", a.shadow_fallback))?;
    settings.view = grotto_runtime::settings::ViewMode::parse(&a.view).ok_or_else(|| {
        anyhow::anyhow!("--view {:?}: use lit, albedo, normals, light, level or scan", a.view)
    })?;
    settings.light_cutoff_w_m2 = a.light_cutoff.unwrap_or(settings.light_cutoff_w_m2);
    settings.radiance_f16 = a.radiance_f16;
    settings.cull_chunks = match a.cull.as_str() {
        "chunks" => true,
        "tiles" => false,
        other => anyhow::bail!("--cull {other:?}: use chunks or tiles"),
    };
    settings.splat_scale = a.splat_scale;
    settings.splat_lod = !a.no_splat_lod;
    settings.splat_blend = !a.no_splat_blend;
    let camera = match (a.camera.clone(), a.eye, a.look_at) {
        (Some(name), _, _) => CameraChoice::Named(name),
        (None, Some(eye_m), Some(look_at_m)) => {
            CameraChoice::Explicit { eye_m, look_at_m, up: a.up, fov_y_deg: a.fov }
        }
        _ => CameraChoice::Default,
    };
    Ok(RenderOptions {
        package: grotto_runtime::cli::scan_input::package_for(&a.package, |m| eprintln!("{m}"))?,
        camera,
        path: a.path.clone(),
        tour: a.tour.clone(),
        tour_fps: a.tour_fps,
        story: a.story.clone(),
        lights: a.lights.clone(),
        circuits: a.circuits.clone(),
        frames: a.frames,
        width: a.size.0,
        height: a.size.1,
        out: a.out.clone(),
        settings,
        exposure: a.exposure,
        gpu: grotto_runtime::gpu::GpuOptions { prefer_software: a.software, ..Default::default() },
        lamp_string: a.lamps,
        headlamp: Headlamp::parse(&a.headlamp)
            .ok_or_else(|| anyhow::anyhow!("--headlamp {:?}: use auto, on or off", a.headlamp))?,
        gpu_memory: a.gpu_memory,
        point_budget: a.point_budget,
        frame_bounces: a.frame_bounces,
        upload_per_frame: a.upload_per_frame,
        clip_world_m: a.clip,
        supersample: a.supersample,
        samples: a.samples.unwrap_or(1),
        labels: a.labels,
    })
}

#[derive(clap::Args, Debug)]
struct ViewArgs {
    #[command(flatten)]
    render: RenderArgs,
    /// Draw at the window's size times this (software adapters are slow per pixel).
    #[arg(long, default_value_t = 0.5)]
    render_scale: f32,
    /// Where P writes its screenshot (default grotto-view-N.png). With --after-frames the viewer
    /// writes it by itself and exits.
    #[arg(long)]
    screenshot: Option<PathBuf>,
    /// Write the screenshot after this many frames, once the camera rests and the light has
    /// converged (so it matches grotto render of the same camera), and exit (scripts, tests).
    #[arg(long)]
    after_frames: Option<u32>,
    /// Record a camera path from the start and write it here on exit (K starts and stops a
    /// recording by hand); grotto render --path FILE.toml flies along it.
    #[arg(long)]
    record_path: Option<PathBuf>,
    /// Milliseconds a frame at rest may take: the light gets the bounces that fit beside the
    /// frame (while the camera moves, bounces wait).
    #[arg(long, default_value_t = 33.0)]
    frame_budget_ms: f64,
    /// Frames a second to hold while the camera moves, by drawing at a smaller render scale and
    /// then thinning far surfels harder (the panel shows what was traded; at rest the frame is
    /// drawn in full). 0: no target, moving frames draw at --render-scale whatever they cost.
    #[arg(long, default_value_t = 60.0)]
    target_fps: f64,
    /// Start with the panel hidden (H toggles it).
    #[arg(long)]
    no_panel: bool,
}

/// The viewer's shadow budget unless `--shadow-ms` says otherwise: half a 60 fps frame.
const VIEW_SHADOW_MS: f32 = 8.0;

fn view(v: ViewArgs) -> anyhow::Result<ExitCode> {
    anyhow::ensure!(
        v.render.supersample == 1,
        "--supersample is for grotto render (the viewer draws at --render-scale)"
    );
    let mut render = options(&v.render)?;
    render.settings.still_samples =
        v.render.samples.unwrap_or(grotto_runtime::passes::resolve::DEFAULT_STILL_SAMPLES);
    render.settings.validate()?;
    render.settings.shadow_frame_ms = v.render.shadow_ms.unwrap_or(VIEW_SHADOW_MS);
    // A designer adds lamps in lighting mode: room for one more point light's faces.
    render.settings.light_room_faces = 6;
    let a = &v.render;
    // The panel names the preset only where no knob changed it.
    let knobs_set = a.bounces.is_some()
        || a.cones.is_some()
        || a.aperture.is_some()
        || a.step.is_some()
        || a.shadow_map.is_some()
        || a.indirect.is_some();
    let quality = grotto_runtime::settings::Quality::parse(&a.quality).filter(|_| !knobs_set);
    let summary = grotto_runtime::window::run(grotto_runtime::window::ViewOptions {
        render,
        quality,
        render_scale: v.render_scale,
        screenshot: v.screenshot,
        after_frames: v.after_frames,
        record_path: v.record_path,
        frame_budget_ms: v.frame_budget_ms,
        frame_target_ms: (v.target_fps.is_finite() && v.target_fps > 0.0).then(|| 1000.0 / v.target_fps),
        panel: !v.no_panel,
    })?;
    // --json: frames, frame times moving and at rest, frames the light took to converge.
    if v.render.json {
        println!("{}", serde_json::to_string_pretty(&summary)?);
        return Ok(ExitCode::SUCCESS);
    }
    let log = &summary.log;
    let ms = |v: &[f64]| {
        grotto_runtime::window::FrameLog::percentiles(v)
            .map_or("none".to_string(), |(m, p)| format!("median {m:.1} ms, p95 {p:.1} ms"))
    };
    println!(
        "{} frames in {:.1} s on {}; moving: {} frames, {}; at rest: {} frames, {}; light converged \
         {} times, after {:?} frames ({:.1?} s){}{}",
        summary.frames,
        summary.seconds,
        summary.device,
        log.moving_ms.len(),
        ms(&log.moving_ms),
        log.rest_ms.len(),
        ms(&log.rest_ms),
        log.converge_frames.len(),
        log.converge_frames,
        log.converge_s,
        if summary.screenshots.is_empty() {
            String::new()
        } else {
            format!("; wrote {}", summary.screenshots.join(", "))
        },
        summary.paths.iter().map(|(p, n)| format!("; camera path {p} ({n} keys)")).collect::<String>(),
    );
    Ok(ExitCode::SUCCESS)
}

fn bench(b: BenchArgs) -> anyhow::Result<ExitCode> {
    anyhow::ensure!(
        b.render.supersample == 1,
        "--supersample is for grotto render (bench the larger --size instead)"
    );
    let opts = options(&b.render)?;
    if let Some(file) = &b.edit_lights {
        return bench_edits(&opts, file, (b.render.json, b.render.explain));
    }
    let report = grotto_runtime::cli::bench_job::bench(&opts, b.reps)?;
    if b.render.json {
        println!("{}", serde_json::to_string_pretty(&report)?);
    } else {
        println!(
            "{} on {} ({}): {} tiles, depth {}, {} leaves, {} nodes, {} surfels, {} lights, {}x{}",
            report.package,
            report.device,
            if report.timestamps { "GPU timestamps" } else { "CPU wall" },
            report.tiles,
            report.max_depth,
            report.leaves,
            report.nodes,
            report.surfels,
            report.lights,
            report.width,
            report.height
        );
        let count = |v: Option<u64>| v.map_or_else(|| "-".to_string(), |n| n.to_string());
        println!(
            "  {:10} {:>10}  {:>6} {:>10} {:>12} {:>12} {:>12} {:>12}",
            "pass", "ms", "draws", "surfels", "vertices", "primitives", "fragments", "invocations"
        );
        for (pass, ms) in &report.median_ms {
            let w = report.work.get(pass).copied().unwrap_or_default();
            println!(
                "  {pass:10} {ms:10.2}  {:>6} {:>10} {:>12} {:>12} {:>12} {:>12}",
                w.draws,
                w.surfels,
                count(w.vertex_invocations),
                count(w.primitives_out),
                count(w.fragment_invocations),
                count(w.compute_invocations)
            );
        }
        println!(
            "  a repetition: {} submits, {} bytes written to GPU buffers",
            report.submits, report.upload_bytes
        );
    }
    Ok(ExitCode::SUCCESS)
}

fn bench_edits(
    opts: &grotto_runtime::engine::RenderOptions,
    file: &std::path::Path,
    (json, explain): (bool, bool),
) -> anyhow::Result<ExitCode> {
    let report = grotto_runtime::cli::bench_job::bench_light_edits(opts, file)?;
    if json {
        println!("{}", serde_json::to_string_pretty(&report)?);
    } else {
        print!("{}", report.table(explain));
    }
    Ok(ExitCode::SUCCESS)
}

fn render(a: RenderArgs) -> anyhow::Result<ExitCode> {
    use grotto_runtime::cli::render_job::{self, Progress};
    let opts = options(&a)?;
    let bounce_bar = indicatif::ProgressBar::new(u64::from(opts.settings.bounces)).with_style(
        indicatif::ProgressStyle::with_template("{prefix:>9} [{bar:30}] {pos}/{len} {msg}")
            .unwrap_or_else(|_| indicatif::ProgressStyle::default_bar()),
    );
    bounce_bar.set_prefix("bounces");
    let frame_bar = indicatif::ProgressBar::hidden();
    let quiet = a.json;
    if quiet {
        bounce_bar.set_draw_target(indicatif::ProgressDrawTarget::hidden());
    }
    let summary = render_job::run(&opts, |p| match p {
        Progress::Bounce { done, change, .. } => {
            bounce_bar.set_position(u64::from(done));
            if let Some(c) = change {
                bounce_bar.set_message(format!("change {c:.1e}"));
            }
        }
        Progress::Frame { done, total } => {
            if total > 1 && !quiet && frame_bar.is_hidden() {
                frame_bar.set_draw_target(indicatif::ProgressDrawTarget::stderr());
                frame_bar.set_length(u64::from(total));
                frame_bar.set_style(
                    indicatif::ProgressStyle::with_template("{prefix:>9} [{bar:30}] {pos}/{len} {eta}")
                        .unwrap_or_else(|_| indicatif::ProgressStyle::default_bar()),
                );
                frame_bar.set_prefix("frames");
            }
            frame_bar.set_position(u64::from(done));
        }
    })?;
    bounce_bar.finish_and_clear();
    frame_bar.finish_and_clear();
    for w in &summary.warnings {
        eprintln!("warning: {w}");
    }
    if a.json {
        println!("{}", serde_json::to_string_pretty(&summary)?);
        return Ok(ExitCode::SUCCESS);
    }
    for n in &summary.notes {
        println!("{n}");
    }
    if summary.residency.is_some() && summary.frames.len() > 1 {
        println!(
            "frame  tile MiB  full  coarse  far  loaded  evicted  surfels  bounces  carried leaves  propagated leaves  \
             uploaded MiB  repacked  shadow faces  deferred"
        );
        for f in &summary.frames {
            let uploaded = f.update.as_ref().map_or(0, |u| u.upload_bytes);
            let repacked = if f.update.as_ref().is_some_and(|u| u.repacked) {
                "yes"
            } else if f.made_anew {
                "new"
            } else {
                ""
            };
            println!(
                "{:5}  {:8.1}  {:4}  {:6}  {:3}  {:6}  {:7}  {:7}  {:7}  {:14}  {:17}  {:12.1}  {:>8}  {:>12}  {:8}",
                f.frame,
                f.tile_bytes as f64 / f64::from(1u32 << 20),
                f.full_tiles,
                f.coarse_tiles,
                f.far_tiles,
                f.loaded,
                f.evicted,
                f.surfels,
                f.bounces,
                f.carried_leaves,
                f.propagated_leaves,
                uploaded as f64 / f64::from(1u32 << 20),
                repacked,
                format!("{} of {}", f.shadow_faces, f.shadow_faces_total),
                f.deferred
            );
        }
    }
    if a.explain {
        if let Some(r) = &summary.residency {
            println!("{}", r.explain(24));
        }
        println!("light work by frame (propagation updates only the tiles whose light may still change):");
        for f in &summary.frames {
            for (k, w) in f.bounce_work.iter().enumerate() {
                println!("  frame {} bounce {}: {}", f.frame, k + 1, describe_bounce(w));
            }
        }
        println!("effect plan, first update:\n{}", summary.first_plan.explain());
        println!("effect plan, last frame:\n{}", summary.last_plan.explain());
    }
    let times: Vec<String> =
        summary.stats.last_ms.iter().map(|(p, ms)| format!("{} {ms:.1} ms", p.name())).collect();
    println!(
        "rendered {} ({}x{}, {} pixels uncovered) on {}: {} tiles, {} leaves, {} surfels; {} bounces (last change {}) in {:.1} s, frames in {:.1} s; exposure {:.3}",
        summary.images.join(", "),
        summary.width,
        summary.height,
        summary.uncovered_pixels,
        summary.device,
        summary.tiles,
        summary.leaves,
        summary.surfels,
        summary.bounces,
        summary.last_change.map_or("-".into(), |c| format!("{c:.1e}")),
        summary.settle_s,
        summary.render_s,
        summary.exposure
    );
    println!(
        "last pass times ({}): {}",
        if summary.timestamps { "GPU timestamps" } else { "CPU wall" },
        times.join(", ")
    );
    Ok(ExitCode::SUCCESS)
}

/// One bounce of `--explain`'s light work: tiles updated of all, why, which (when few), and what changed.
fn describe_bounce(w: &grotto_runtime::light::activity::BounceWork) -> String {
    let list = w.tile_list.as_ref().map_or(String::new(), |l| {
        format!(" [tiles {}]", l.iter().map(u32::to_string).collect::<Vec<_>>().join(" "))
    });
    format!(
        "{} of {} tiles, {} leaves ({}){list}; {} still changing, largest change {:.1e}",
        w.tiles,
        w.of_tiles,
        w.leaves,
        grotto_runtime::light::activity::describe_counts(&w.why),
        w.changed,
        w.max_change
    )
}

fn main() -> ExitCode {
    match run(Cli::parse()) {
        Ok(code) => code,
        Err(e) => {
            eprintln!("error: {e:#}");
            ExitCode::FAILURE
        }
    }
}

fn run(cli: Cli) -> anyhow::Result<ExitCode> {
    match cli.command {
        Command::Inspect { package, gpu_memory: true, json, .. } => {
            let t0 = std::time::Instant::now();
            let scene = grotto_runtime::engine::load_scene(&package)?;
            let bytes = scene.buffer_bytes(false);
            let load_s = t0.elapsed().as_secs_f64();
            if json {
                let report = serde_json::json!({
                    "package": package.display().to_string(),
                    "tiles": scene.tiles.len(), "nodes": scene.nodes.len(),
                    "leaves": scene.leaves.len(), "surfels": scene.surfels.len(),
                    "rock_bricks": scene.rock.bricks(),
                    "bytes": bytes, "total_bytes": bytes.total(), "load_s": load_s,
                });
                println!("{}", serde_json::to_string_pretty(&report)?);
            } else {
                let mib = |b: u64| b as f64 / f64::from(1u32 << 20);
                println!(
                    "{}: {} tiles, {} nodes, {} leaves, {} surfels (scene loaded in {load_s:.1} s)",
                    package.display(),
                    scene.tiles.len(),
                    scene.nodes.len(),
                    scene.leaves.len(),
                    scene.surfels.len()
                );
                for (name, b) in [
                    ("tiles", bytes.tile_buffers.tiles),
                    ("nodes", bytes.tile_buffers.nodes),
                    ("leaves", bytes.tile_buffers.leaves),
                    ("leaf light", bytes.tile_buffers.leaf_light),
                    ("radiance pyramid", bytes.tile_buffers.faces),
                    ("mip order", bytes.tile_buffers.mip_order),
                    ("surfels", bytes.tile_buffers.surfels),
                    ("rock", bytes.rock),
                ] {
                    println!("  {name:18} {:10.2} MiB", mib(b));
                }
                println!("  {:18} {:10.2} MiB", "total", mib(bytes.total()));
                println!(
                    "  rock: {} bricks; as dense per-tile grids it took {:.2} MiB",
                    scene.rock.bricks(),
                    mib(bytes.rock_dense_grid)
                );
            }
            Ok(ExitCode::SUCCESS)
        }
        Command::Inspect { package, sections, json, .. } => {
            let pkg = Package::open(&package)?;
            let report = inspect::inspect(&pkg);
            if json {
                println!("{}", serde_json::to_string_pretty(&report)?);
            } else {
                print!("{}", inspect::render_text(&report, sections));
            }
            Ok(ExitCode::SUCCESS)
        }
        Command::Export { package, points, json } => {
            let pkg = Package::open(&package)?;
            let summary = grotto_runtime::cli::export::export_points(&pkg, &points)?;
            if json {
                println!("{}", serde_json::to_string_pretty(&summary)?);
            } else {
                println!("wrote {}: {} points from {} tiles", summary.path, summary.points, summary.tiles);
            }
            Ok(ExitCode::SUCCESS)
        }
        Command::Render(args) => render(*args),
        Command::Bench(args) => bench(*args),
        Command::View(args) => view(*args),
        Command::Publish(args) => publish(*args),
        Command::Verify { package, json } => {
            let report = match Package::open(&package) {
                Ok(pkg) => inspect::verify(&pkg),
                // Structural damage: the package does not open; report it the same way.
                Err(e) => inspect::Verification {
                    path: package.display().to_string(),
                    sections: 0,
                    bytes_checked: 0,
                    problems: vec![match &e {
                        grotto_format::Error::Invalid { problem, .. } => problem.to_string(),
                        grotto_format::Error::Io { op, source, .. } => format!("cannot {op}: {source}"),
                        other => other.to_string(),
                    }],
                },
            };
            if json {
                println!("{}", serde_json::to_string_pretty(&report)?);
            } else if report.problems.is_empty() {
                println!(
                    "{}: ok ({} sections, {} bytes checked)",
                    report.path, report.sections, report.bytes_checked
                );
            } else {
                for p in &report.problems {
                    eprintln!("{}: {p}", report.path);
                }
                eprintln!("{}: INVALID ({} problems)", report.path, report.problems.len());
            }
            Ok(if report.problems.is_empty() { ExitCode::SUCCESS } else { ExitCode::FAILURE })
        }
    }
}
