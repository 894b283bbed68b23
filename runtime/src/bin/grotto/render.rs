//! `grotto render`: its arguments (shared by bench and view), their parsing into the library's
//! [`RenderOptions`](grotto_runtime::engine::RenderOptions), and the job with its progress bars.

use std::path::PathBuf;
use std::process::ExitCode;

#[derive(clap::Args, Debug)]
pub(crate) struct RenderArgs {
    /// The package (a LAS/LAZ, PLY or E57 scan is packed by grotto-pack first, once, into a cache).
    pub(crate) package: PathBuf,
    /// A camera or point of interest named in the package (default: its first camera; without
    /// one, a view framed on the data, printed so it can be reused with --eye/--look-at).
    #[arg(long, conflicts_with_all = ["eye", "path"])]
    pub(crate) camera: Option<String>,
    /// Eye position, world metres "x,y,z" (with --look-at); negative numbers as written.
    #[arg(long, value_parser = parse_vec3, requires = "look_at", allow_hyphen_values = true)]
    pub(crate) eye: Option<[f64; 3]>,
    /// Point looked at, world metres "x,y,z".
    #[arg(long, value_parser = parse_vec3, requires = "eye", allow_hyphen_values = true)]
    pub(crate) look_at: Option<[f64; 3]>,
    /// Up direction "x,y,z".
    #[arg(long, value_parser = parse_vec3, default_value = "0,0,1", allow_hyphen_values = true)]
    pub(crate) up: [f64; 3],
    /// Headlamp at the camera: "auto" (only when the scene has no lights, emission or
    /// environment map), "on" or "off".
    #[arg(long, default_value = "auto")]
    pub(crate) headlamp: String,
    /// Vertical field of view, degrees (with --eye).
    #[arg(long, default_value_t = 60.0)]
    pub(crate) fov: f64,
    /// Fly through these named cameras, comma-separated (with --frames), or along a camera path
    /// file (one FILE.toml: [[camera]] tables in world metres, as grotto view records them).
    #[arg(long, value_delimiter = ',')]
    pub(crate) path: Vec<String>,
    /// Frames along --path.
    #[arg(long, default_value_t = 30)]
    pub(crate) frames: u32,
    /// A tour of the package (grotto publish's page plays it): an image a stop, what a visitor
    /// sees there once the light has converged; with --tour-fps, the tour as a film (flights
    /// and dwells at that many frames a second).
    #[arg(long, conflicts_with_all = ["camera", "eye", "path"])]
    pub(crate) tour: Option<String>,
    /// Frames a second of a --tour film.
    #[arg(long, requires = "tour")]
    pub(crate) tour_fps: Option<f32>,
    /// Points of interest and tours to add to the package's (TOML: [[poi]], [[tour]] as in a
    /// manifest): --camera and --tour find them, grotto view shows them.
    #[arg(long)]
    pub(crate) story: Option<PathBuf>,
    /// A lighting file (TOML: [[light]] and [[circuit]] in watts or lumens, RGB or kelvin, IES
    /// profiles) changing the package's lights without a rebuild (docs/lighting.md).
    #[arg(long)]
    pub(crate) lights: Option<PathBuf>,
    /// Circuits switched on or off, NAME=on|off[,...] (the lighting file's or the package's).
    #[arg(long, value_delimiter = ',', value_parser = grotto_runtime::engine::lighting_file::parse_switch)]
    pub(crate) circuits: Vec<(String, bool)>,
    /// grotto render: draw the labels of the points of interest in view (not those rock hides) into the
    /// image, as the published page shows them (.png and .jpg). grotto view always shows them.
    #[arg(long)]
    pub(crate) labels: bool,
    /// Image size WIDTHxHEIGHT.
    #[arg(long, default_value = "800x600", value_parser = grotto_runtime::cli::render_job::parse_size)]
    pub(crate) size: (u32, u32),
    /// Output image (.png or .exr); a path sequence appends _NNNN.
    #[arg(long, short, default_value = "render.png")]
    pub(crate) out: PathBuf,
    /// Quality preset: fast, balanced or high (measured error and time: docs/accuracy.md); the
    /// knob options below override single settings of it. Default: balanced for a package; for a
    /// scan given where a package is expected, a time budget of 30 s for the light.
    #[arg(long)]
    pub(crate) quality: Option<String>,
    /// grotto render: seconds the light may take. The first bounce is timed at the fast preset on
    /// this device, and the most accurate preset whose light is predicted to fit is rendered
    /// (predictions from the passes' costs in docs/accuracy.md); what was chosen and given up is
    /// printed. A budget too small for any preset renders the cheapest light and says so.
    #[arg(long, value_parser = parse_seconds, allow_hyphen_values = true,
          conflicts_with_all = ["quality", "bounces", "cones", "aperture", "step", "shadow_map", "gather"])]
    pub(crate) time_budget: Option<f64>,
    /// Bounce budget (propagation passes; stops earlier once converged).
    #[arg(long)]
    pub(crate) bounces: Option<u32>,
    /// Cones per leaf gather (1..=16).
    #[arg(long)]
    pub(crate) cones: Option<u32>,
    /// Cone aperture scale (1 = cones tile the hemisphere).
    #[arg(long)]
    pub(crate) aperture: Option<f32>,
    /// Cone step as a fraction of its diameter.
    #[arg(long)]
    pub(crate) step: Option<f32>,
    /// Longest cone in metres (default: the scene diagonal).
    #[arg(long)]
    pub(crate) max_distance: Option<f32>,
    /// Shadow map size in texels per face.
    #[arg(long)]
    pub(crate) shadow_map: Option<u32>,
    /// Surfel radius multiplier for splatting (discs overlap so sparse sampling leaves no holes).
    #[arg(long, default_value_t = 2.0)]
    pub(crate) splat_scale: f32,
    /// Render without shadow maps.
    #[arg(long)]
    pub(crate) no_shadows: bool,
    /// Run only the bounces counted, without estimating the ones not run as a geometric tail
    /// (the light then stops short of converged in bright closed rock).
    #[arg(long)]
    pub(crate) no_bounce_tail: bool,
    /// Give every leaf the same cone set, not one turned by its cell's parity (which averages misses).
    #[arg(long)]
    pub(crate) no_cone_interleave: bool,
    /// How gather cones meet the rock: rays (seven rays a cone, each ending at the first surface;
    /// the balanced and high presets), march (the composited cone march of voxel cone tracing;
    /// fast) or planes (the march, seeing the finest leaves as half-spaces behind their surface).
    /// Default: the preset's.
    #[arg(long, value_parser = ["rays", "march", "planes"])]
    pub(crate) gather: Option<String>,
    /// Milliseconds a frame may spend redrawing shadow faces out of date (after a change of tiles or
    /// lights), at the measured surfels per millisecond; the rest follow over the next frames and show
    /// together when the last is drawn, so no frame stalls on the whole atlas (0, the default for render
    /// and bench: every face at once; the viewer's default is 8).
    #[arg(long)]
    pub(crate) shadow_ms: Option<f32>,
    /// Shadow-map budget: the N brightest point and spot lights get shadow maps and per-pixel light;
    /// the others are lit per leaf with --shadow-fallback (default 16).
    #[arg(long)]
    pub(crate) shadowed_lights: Option<u32>,
    /// Lights beyond the shadow-map budget: "cone" (SVO shadow cones) or "none" (unshadowed).
    #[arg(long, default_value = "cone")]
    pub(crate) shadow_fallback: String,
    /// What the image shows: lit (default), albedo, normals (0.5 + 0.5 n as colour), light (the light
    /// alone: every albedo 1), level (each tile's level: full green, coarse yellow, far red), or scan (each
    /// point's source scan as a colour, to see misregistration). All but lit and light skip the light passes.
    #[arg(long, default_value = "lit")]
    pub(crate) view: String,
    /// Cut the view to a box, world metres: MINX,MINY,MINZ,MAXX,MAXY,MAXZ (a section: cut the ceiling
    /// away to see a passage from above). Points outside are not drawn and get no point budget; the light
    /// is the whole cave's.
    #[arg(long, value_parser = parse_box, allow_hyphen_values = true)]
    pub(crate) clip: Option<[[f64; 3]; 2]>,
    /// Irradiance (W/m^2) under which a light is culled: bounds each light's range (0: no culling).
    #[arg(long)]
    pub(crate) light_cutoff: Option<f32>,
    /// What the splat passes cull by: "chunks" (default: runs of 1,024 surfels each shadow face
    /// or the camera may see) or "tiles" (whole tiles by their boxes, the coarser draws;
    /// the same image, for measuring the difference).
    #[arg(long, default_value = "chunks")]
    pub(crate) cull: String,
    /// Draw every surfel of far chunks, not every k-th grown to close the surface where their
    /// discs are under the pixel floor anyway (the level of detail by size on screen).
    #[arg(long)]
    pub(crate) no_splat_lod: bool,
    /// Show each pixel's front-most disc alone (each with its own normal and light: scales at
    /// grazing angles), not the blend of every disc of the front surface (the default where the
    /// adapter can blend f16 targets; for comparing).
    #[arg(long)]
    pub(crate) no_splat_blend: bool,
    /// Anti-aliasing for `grotto render`: draw at N times the width and height (1..=4) and
    /// average each N x N block; costs N^2 in G-buffer and shade work.
    #[arg(long, default_value_t = 1)]
    pub(crate) supersample: u32,
    /// Anti-aliasing by samples a pixel, each jittered within it, averaged (1..=64; costs that many frames'
    /// G-buffer and shade work, no more memory). grotto render: default 1 (the pixel centres). grotto view:
    /// gathered at rest, one a frame, default 8. grotto bench: times the resolve pass that adds a sample.
    #[arg(long)]
    pub(crate) samples: Option<u32>,
    /// Replace the package's lights by a lamp string of N 8 W lamps spread over the cave's floors
    /// (to measure how cost grows with the number of lights).
    #[arg(long)]
    pub(crate) lamps: Option<u32>,
    /// Store the radiance pyramid as f16 (half its memory; values above 65504 clamp).
    #[arg(long)]
    pub(crate) radiance_f16: bool,
    /// GPU memory for tiles, e.g. 512M or 2G (default: half the adapter's largest buffer, at
    /// most 2G). A package over it keeps the tiles the view needs in full and every other
    /// tile at its coarse or far level, nearer ones finer.
    #[arg(long, value_parser = grotto_format::parse_bytes)]
    pub(crate) gpu_memory: Option<u64>,
    /// Most surfels drawn (default: no limit); tiles beyond it are drawn from their coarse or far level.
    #[arg(long)]
    pub(crate) point_budget: Option<u64>,
    /// One memory budget for the viewer, CPU and GPU together: phone (512 MiB), laptop (1.5 GiB),
    /// desktop (4 GiB) or a size such as 768M (at least 128M). Half goes to the GPU: the shadow
    /// atlas (fewer lights shadowed, then smaller maps), the image and the tile pools; the
    /// surfels drawn follow too. --gpu-memory, --point-budget, --shadowed-lights and --shadow-map
    /// given as well win. The split is printed.
    #[arg(long, value_parser = grotto_runtime::engine::memory::MemoryBudget::parse)]
    pub(crate) memory: Option<grotto_runtime::engine::memory::MemoryBudget>,
    /// Along a path, run at most this many bounces before a frame whose tiles changed (default:
    /// settle); the rest runs one bounce per frame, so the light converges over frames. Tiles
    /// resident before and after keep their light either way.
    #[arg(long)]
    pub(crate) frame_bounces: Option<u32>,
    /// Along a path, most tile bytes uploaded before a frame, e.g. 16M (default: no limit, every
    /// frame gets the tiles its view wants). Changes to coarser forms always go through; finer
    /// ones go in priority order while they fit, and the rest wait for later frames.
    #[arg(long, value_parser = grotto_format::parse_bytes)]
    pub(crate) upload_per_frame: Option<u64>,
    /// Indirect light filter at pixels: trilinear, tricubic or off.
    #[arg(long)]
    pub(crate) indirect: Option<String>,
    /// Exposure multiplier (default: automatic from the first frame).
    #[arg(long)]
    pub(crate) exposure: Option<f32>,
    /// Relative change under which propagation counts as converged.
    #[arg(long, default_value_t = 1e-3)]
    pub(crate) tolerance: f32,
    /// Prefer the software adapter (Mesa lavapipe/llvmpipe) over a GPU.
    #[arg(long)]
    pub(crate) software: bool,
    /// Print the effect plan: which passes run and why.
    #[arg(long)]
    pub(crate) explain: bool,
    /// Machine-readable summary (plan, per-pass times, dispatch counts) on stdout.
    #[arg(long)]
    pub(crate) json: bool,
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

/// A time in seconds: finite and above zero.
fn parse_seconds(s: &str) -> Result<f64, String> {
    let v: f64 = s.trim().parse().map_err(|e| format!("{s:?}: {e}"))?;
    grotto_runtime::engine::time_budget::check_budget(v).map_err(|e| e.to_string())
}

/// Whether a knob of the light's march (beyond the preset) was given.
pub(crate) fn march_knobs_set(a: &RenderArgs) -> bool {
    a.bounces.is_some()
        || a.cones.is_some()
        || a.aperture.is_some()
        || a.step.is_some()
        || a.shadow_map.is_some()
        || a.indirect.is_some()
        || a.gather.is_some()
}

fn parse_vec3(s: &str) -> Result<[f64; 3], String> {
    parse_floats(s, "x,y,z")
}

fn parse_box(s: &str) -> Result<[[f64; 3]; 2], String> {
    let [x0, y0, z0, x1, y1, z1] = parse_floats(s, "MINX,MINY,MINZ,MAXX,MAXY,MAXZ")?;
    Ok([[x0, y0, z0], [x1, y1, z1]])
}

pub(crate) fn options(a: &RenderArgs) -> anyhow::Result<grotto_runtime::engine::RenderOptions> {
    use grotto_runtime::engine::{Headlamp, RenderOptions};
    use grotto_runtime::settings::{IndirectFilter, Quality, Settings, ShadowFallback};
    use grotto_runtime::view::framing::CameraChoice;
    let quality = match &a.quality {
        Some(q) => {
            Quality::parse(q).ok_or_else(|| anyhow::anyhow!("--quality {q:?}: use fast, balanced or high"))?
        }
        None => Quality::Balanced,
    };
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
    if let Some(g) = &a.gather {
        (settings.cone_rays, settings.cone_planes) = match g.as_str() {
            "rays" => (true, false),
            "march" => (false, false),
            _ => (false, true),
        };
    }
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
    // The image as asked, supersampled: natively it is drawn at its size, and what its targets
    // take beyond their share comes out of the pools.
    let pixels = u64::from(a.size.0) * u64::from(a.size.1) * u64::from(a.supersample.pow(2));
    let memory = a.memory.map(|m| {
        let mut asked = settings.clone();
        asked.shadow_map_size = a.shadow_map.unwrap_or(asked.shadow_map_size);
        let plan = m.plan(pixels, &asked).with_image_as_asked();
        if a.shadow_map.is_none() {
            settings.shadow_map_size = settings.shadow_map_size.min(plan.shadow_map_size);
        }
        if a.shadowed_lights.is_none() {
            settings.shadowed_lights = settings.shadowed_lights.min(plan.shadowed_lights);
        }
        plan
    });
    let camera = match (a.camera.clone(), a.eye, a.look_at) {
        (Some(name), _, _) => CameraChoice::Named(name),
        (None, Some(eye_m), Some(look_at_m)) => {
            CameraChoice::Explicit { eye_m, look_at_m, up: a.up, fov_y_deg: a.fov }
        }
        _ => CameraChoice::Default,
    };
    // A scan is packed into the cache (a package is opened where it is), and its first look is
    // bought with time unless the user chose the light's knobs.
    let package = grotto_runtime::cli::scan_input::package_for(&a.package, |m| eprintln!("{m}"))?;
    let is_scan = package != a.package;
    let time_budget_s = a.time_budget.or_else(|| {
        (is_scan && a.quality.is_none() && !march_knobs_set(a))
            .then_some(grotto_runtime::engine::time_budget::SCAN_DEFAULT_BUDGET_S)
    });
    Ok(RenderOptions {
        time_budget_s,
        package,
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
        gpu: grotto_runtime::gpu::GpuOptions {
            prefer_software: a.software,
            lean_memory: a.gpu_memory.is_some() || memory.is_some(),
            ..Default::default()
        },
        lamp_string: a.lamps,
        headlamp: Headlamp::parse(&a.headlamp)
            .ok_or_else(|| anyhow::anyhow!("--headlamp {:?}: use auto, on or off", a.headlamp))?,
        gpu_memory: a.gpu_memory.or(memory.map(|m| m.pool_bytes)),
        point_budget: a.point_budget.or(memory.map(|m| m.points)),
        memory,
        frame_bounces: a.frame_bounces,
        upload_per_frame: a.upload_per_frame,
        clip_world_m: a.clip,
        supersample: a.supersample,
        samples: a.samples.unwrap_or(1),
        labels: a.labels,
    })
}

pub(crate) fn render(a: RenderArgs) -> anyhow::Result<ExitCode> {
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
            crate::trim_heap();
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
    if let Some(m) = &summary.memory {
        println!("{}", m.describe());
    }
    if summary.residency.is_some() && summary.frames.len() > 1 {
        print_frame_table(&summary.frames);
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

/// The per-frame table of a streamed path: residency, light and uploads by frame.
fn print_frame_table(frames: &[grotto_runtime::cli::render_job::FrameReport]) {
    println!(
        "frame  tile MiB  full  coarse  far  loaded  evicted  surfels  bounces  carried leaves  propagated leaves  \
         uploaded MiB  repacked  shadow faces  deferred"
    );
    for f in frames {
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

/// One bounce of `--explain`'s light work: tiles updated of all, why, which (when few), and what changed.
pub(crate) fn describe_bounce(w: &grotto_runtime::light::activity::BounceWork) -> String {
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
