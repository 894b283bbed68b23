//! `grotto-reference`: ground-truth renders of a package (converged Monte Carlo path tracing on
//! its surfels), to judge the runtime's images.

use std::path::PathBuf;

use anyhow::Context;
use clap::Parser;
use glam::Vec3;
use grotto_reference::{PathSettings, SurfelScene};
use grotto_runtime::render::Frame;
use grotto_runtime::view::camera::Camera;

/// Ground truth for grotto: path-traced reference renders, and the accuracy-vs-time sweep.
#[derive(Parser, Debug)]
#[command(name = "grotto-reference", version)]
enum Cli {
    Render(RenderArgs),
    Accuracy(AccuracyArgs),
    Lights(LightsArgs),
    Mitsuba(MitsubaArgs),
    Truth(TruthArgs),
    Breakdown(BreakdownArgs),
}

/// Where the light carried through passages goes wrong: the runtime's outgoing radiance
/// per leaf against the reference's, per region (the dogleg's lit room, three corridors and hidden
/// chamber, the long passage's stretches, or the colour box's faces) and per bounce; written as
/// Markdown to OUT.
#[derive(clap::Args, Debug)]
struct BreakdownArgs {
    /// The scene to break down.
    #[arg(long, value_enum, default_value = "dogleg")]
    scene: grotto_reference::accuracy::breakdown::BreakdownScene,
    /// The report to write [default: docs/accuracy-passages.md for the dogleg,
    /// docs/accuracy-passage-long.md for the passage, docs/accuracy-colour-box.md for the colour
    /// box].
    #[arg(long)]
    out: Option<PathBuf>,
    /// Reference paths per surfel.
    #[arg(long, default_value_t = 256)]
    paths: u32,
    /// Prefer the software adapter.
    #[arg(long)]
    software: bool,
    /// Leaves on their surfels' centroid, as `grotto-pack` places them, instead of at their
    /// cells' centres as the hand-built scene has them (what that half leaf costs; hand-built
    /// scenes only).
    #[arg(long)]
    leaves_on_surfels: bool,
    /// Every runtime configuration with cone planes on (`grotto --cone-planes`).
    #[arg(long)]
    cone_planes: bool,
    /// Every runtime configuration with each gather cone followed as rays (`Settings::cone_rays`).
    #[arg(long, conflicts_with = "composited")]
    cone_rays: bool,
    /// Every runtime configuration with the composited cone march at aperture 0.5, as the
    /// balanced and high presets gathered before they followed rays.
    #[arg(long)]
    composited: bool,
    /// The reference traces each disc cut to its leaf cell: a hand-built scene's carved faces
    /// themselves (uncut, a disc reaches a quarter leaf into every opening; hand-built scenes
    /// only).
    #[arg(long)]
    clip_discs: bool,
    /// Print the figures as JSON (the report is still written).
    #[arg(long)]
    json: bool,
}

/// The true-surface benchmark's scenes: mesh the synthetic cave's exact surface
/// (OUT/mesh.ply, linear vertex albedo) and write a Mitsuba 3 scene of it per camera and
/// transport (OUT/CAMERA-direct.xml, OUT/CAMERA-full.xml) with the package's lights, plus
/// OUT/cameras.json (each camera in world coordinates, for `grotto render --eye`).
/// `scripts/truth-check.py OUT` renders them and compares grotto's pictures with them.
#[derive(clap::Args, Debug)]
struct TruthArgs {
    /// The synthetic dataset the package was built from (its synth.json).
    #[arg(long, default_value = "out/demo-scans")]
    synth: PathBuf,
    /// The package built from it.
    #[arg(long, default_value = "out/demo.grotto")]
    package: PathBuf,
    /// Folder to write into.
    #[arg(long, default_value = "target/truth")]
    out: PathBuf,
    /// Mesh cell, metres (the surface nets' grid; a leaf is 0.25 m).
    #[arg(long, default_value_t = 0.04)]
    cell: f64,
    /// Image size WIDTHxHEIGHT.
    #[arg(long, default_value = "640x480")]
    size: String,
    /// Mitsuba samples per pixel for the direct light and for full transport.
    #[arg(long, default_value_t = 2048)]
    spp_direct: u32,
    #[arg(long, default_value_t = 256)]
    spp_full: u32,
}

/// Write the furnace, the colour box and the dogleg for Mitsuba 3 (SLUG.xml) beside this
/// reference's own render of each (SLUG.json: per-pixel mean and standard error), for
/// scripts/mitsuba-check.py to compare (docs/reference-mitsuba.md).
#[derive(clap::Args, Debug)]
struct MitsubaArgs {
    /// Folder to write into.
    #[arg(long, default_value = "target/mitsuba")]
    out: PathBuf,
    /// Image size WIDTHxHEIGHT.
    #[arg(long, default_value = "96x72")]
    size: String,
    /// Paths per pixel of this reference's render.
    #[arg(long, default_value_t = 1024)]
    spp: u32,
    /// Samples per pixel written into the Mitsuba scenes.
    #[arg(long, default_value_t = 1024)]
    mitsuba_spp: u32,
}

/// The many-lights measurement: the demo cave relit by a lamp string, its path-traced reference,
/// and the runtime with the shadow-map budget, its fallback and the light cutoff varied; writes
/// the report (docs/lights-accuracy.md).
#[derive(clap::Args, Debug)]
struct LightsArgs {
    /// The report to write.
    #[arg(long, default_value = "docs/lights-accuracy.md")]
    out: PathBuf,
    /// Lamps in the string.
    #[arg(long, default_value_t = 64)]
    lamps: usize,
    /// Image size WIDTHxHEIGHT.
    #[arg(long, default_value = "96x72")]
    size: String,
    /// Reference paths per pixel.
    #[arg(long, default_value_t = 256)]
    spp: u32,
    /// Prefer the software adapter.
    #[arg(long)]
    software: bool,
}

/// Run the runtime over every quality knob and preset on the built-in scenes, compare each image
/// with the path-traced reference, and write the report (docs/accuracy.md) and raw rows (JSON).
#[derive(clap::Args, Debug)]
struct AccuracyArgs {
    /// The report to write (its JSON beside it, its plots in the folder of its name) [default:
    /// docs/accuracy.md, docs/accuracy-hand-built-on-surfels.md with --leaves-on-surfels,
    /// docs/accuracy-hand-built.md with --hand-built].
    #[arg(long)]
    out: Option<PathBuf>,
    /// Image size WIDTHxHEIGHT.
    #[arg(long, default_value = "96x72")]
    size: String,
    /// Reference paths per pixel.
    #[arg(long, default_value_t = 1024)]
    spp: u32,
    /// Prefer the software adapter.
    #[arg(long)]
    software: bool,
    /// Only this scene (furnace, "colour box (scanned)", "dogleg (scanned)", passage, bunny, "cave
    /// with sky", "demo cave", or the hand-built "colour box" or dogleg); the report then covers it
    /// alone.
    #[arg(long)]
    scene: Option<String>,
    /// Only the configs (rows) with this name, for example "balanced" or "bounces 4, no tail";
    /// repeat for more. The report then covers them alone.
    #[arg(long = "config")]
    configs: Vec<String>,
    /// Write each run's error map here (SCENE-CONFIG.png: the reference, the runtime and their
    /// difference side by side; SCENE-CONFIG-cutK.png against the reference cut after K bounces
    /// for the rows judged against one; each also as .exr in linear radiance, the difference as
    /// luminance), to see where an error sits.
    #[arg(long)]
    error_maps: Option<PathBuf>,
    /// Keep the reference renders in this folder and reuse them while the scene, the size and the
    /// paths per pixel are unchanged (iterating on the runtime with --config).
    #[arg(long)]
    reference_cache: Option<PathBuf>,
    /// Only the hand-built scenes (colour box, dogleg), with their leaves on their surfels'
    /// centroid as grotto-pack places a package's, instead of at their cells' centres, half a
    /// leaf behind the surface (what that half leaf adds to or hides in their error).
    #[arg(long)]
    leaves_on_surfels: bool,
    /// Only the hand-built scenes (colour box, dogleg) as they are built by hand, leaves at their
    /// cells' centres, instead of as a survey delivers them (the report's: their rock faces
    /// sampled by scans and built by grotto-pack).
    #[arg(long, conflicts_with = "leaves_on_surfels")]
    hand_built: bool,
}

/// Render a package's camera by path tracing its surfels (the runtime's scene, no voxels): linear
/// radiance to EXR, or tonemapped PNG; prints the mean standard error of the estimate.
#[derive(clap::Args, Debug)]
struct RenderArgs {
    package: PathBuf,
    /// A camera named in the package (default: its first).
    #[arg(long)]
    camera: Option<String>,
    /// Image size WIDTHxHEIGHT.
    #[arg(long, default_value = "160x120")]
    size: String,
    /// Paths per pixel.
    #[arg(long, default_value_t = 256)]
    spp: u32,
    #[arg(long, default_value_t = 1)]
    seed: u64,
    /// Surfel radius scale (the runtime's --splat-scale).
    #[arg(long, default_value_t = 2.0)]
    splat_scale: f32,
    /// Exposure for the PNG's tonemap.
    #[arg(long, default_value_t = 1.0)]
    exposure: f32,
    /// Output image: .exr (linear) or .png (tonemapped).
    #[arg(long, short, default_value = "reference.exr")]
    out: PathBuf,
    /// Machine-readable summary.
    #[arg(long)]
    json: bool,
}

fn main() -> anyhow::Result<()> {
    match Cli::parse() {
        Cli::Render(a) => render(a),
        Cli::Accuracy(a) => accuracy(a),
        Cli::Lights(a) => lights(a),
        Cli::Mitsuba(a) => mitsuba(a),
        Cli::Truth(a) => truth(a),
        Cli::Breakdown(a) => breakdown(a),
    }
}

fn breakdown(a: BreakdownArgs) -> anyhow::Result<()> {
    use grotto_reference::accuracy::breakdown;
    let gpu = grotto_runtime::gpu::Gpu::new(&grotto_runtime::gpu::GpuOptions {
        prefer_software: a.software,
        ..Default::default()
    })?;
    let t0 = std::time::Instant::now();
    let bar = indicatif::ProgressBar::new_spinner().with_style(
        indicatif::ProgressStyle::with_template("{spinner} [{elapsed_precise}] {msg}")
            .unwrap_or_else(|_| indicatif::ProgressStyle::default_spinner()),
    );
    bar.enable_steady_tick(std::time::Duration::from_millis(200));
    let options = breakdown::BreakdownOptions {
        paths: a.paths,
        leaves_on_surfels: a.leaves_on_surfels,
        cone_planes: a.cone_planes,
        cone_rays: a.cone_rays,
        composited: a.composited,
        clip_discs: a.clip_discs,
    };
    let b = breakdown::breakdown(&gpu, a.scene, options, |what| bar.set_message(what.to_string()))?;
    bar.finish_and_clear();
    let out = a.out.clone().unwrap_or_else(|| PathBuf::from(a.scene.default_out()));
    let regions = a.scene.regions_described();
    let md = format!(
        "# Where the {}'s light goes wrong\n\nGenerated by `cargo run --release -p grotto-reference -- breakdown --scene {} --paths {}{}{}{}{}{} --out {}` (do not edit by hand). Device: {}.{}{}{}{}{} The runtime's outgoing radiance per leaf (luminance) against the reference's, path traced from each leaf's surfels ({} paths per surfel), summed over {regions}.\n\n{}",
        b.scene,
        clap::ValueEnum::to_possible_value(&a.scene)
            .map_or_else(|| b.scene.clone(), |v| v.get_name().to_owned()),
        a.paths,
        if a.leaves_on_surfels { " --leaves-on-surfels" } else { "" },
        if a.cone_planes { " --cone-planes" } else { "" },
        if a.cone_rays { " --cone-rays" } else { "" },
        if a.composited { " --composited" } else { "" },
        if a.clip_discs { " --clip-discs" } else { "" },
        out.display(),
        gpu.describe(),
        if a.leaves_on_surfels {
            " Leaves moved onto their surfels' centroid, as packages have them (the hand-built scene puts them at their cells' centres, half a leaf behind the surface)."
        } else {
            ""
        },
        if a.cone_planes {
            " Every runtime configuration with cone planes on (docs/runtime.md, \"Cone planes\")."
        } else {
            ""
        },
        if a.cone_rays {
            " Every runtime configuration with each gather cone followed as rays (`Settings::cone_rays`; docs/reference.md, \"Where the light goes wrong\")."
        } else {
            ""
        },
        if a.composited {
            " Every runtime configuration with the composited cone march at aperture 0.5, as the balanced and high presets gathered before they followed rays."
        } else {
            ""
        },
        if a.clip_discs {
            " The reference's discs cut to their leaf cells: the carved faces themselves, no disc reaching into an opening."
        } else {
            ""
        },
        a.paths,
        breakdown::markdown(&b)
    );
    grotto_runtime::cli::export::write_atomically(&out, md.as_bytes())?;
    if a.json {
        println!("{}", serde_json::to_string_pretty(&b)?);
    } else {
        println!("{md}");
    }
    eprintln!("wrote {} in {:.0} s", out.display(), t0.elapsed().as_secs_f64());
    Ok(())
}

/// The image size of a sweep and the device its runtime runs on.
fn size_and_gpu(size: &str, software: bool) -> anyhow::Result<((u32, u32), grotto_runtime::gpu::Gpu)> {
    let wh = grotto_runtime::cli::render_job::parse_size(size).map_err(anyhow::Error::msg)?;
    let gpu = grotto_runtime::gpu::Gpu::new(&grotto_runtime::gpu::GpuOptions {
        prefer_software: software,
        ..Default::default()
    })?;
    Ok((wh, gpu))
}

fn lights(a: LightsArgs) -> anyhow::Result<()> {
    use grotto_reference::accuracy;
    let ((w, h), gpu) = size_and_gpu(&a.size, a.software)?;
    let t0 = std::time::Instant::now();
    let bar = indicatif::ProgressBar::new_spinner().with_style(
        indicatif::ProgressStyle::with_template("{spinner} [{elapsed_precise}] {msg}")
            .unwrap_or_else(|_| indicatif::ProgressStyle::default_spinner()),
    );
    bar.enable_steady_tick(std::time::Duration::from_millis(200));
    let (scene, rows) = accuracy::lights_sweep(&gpu, a.lamps, w, h, a.spp, |what| {
        bar.set_message(what.to_string());
    })
    .map_err(anyhow::Error::msg)?;
    bar.finish_and_clear();
    let command = format!(
        "cargo run --release -p grotto-reference -- lights --lamps {} --size {w}x{h} --spp {}",
        a.lamps, a.spp
    );
    let md = accuracy::lights_report(&scene, &rows, &gpu.describe(), w, h, &command);
    grotto_runtime::cli::export::write_atomically(&a.out, md.as_bytes())?;
    println!("{md}");
    eprintln!("wrote {} in {:.0} s", a.out.display(), t0.elapsed().as_secs_f64());
    Ok(())
}

fn mitsuba(a: MitsubaArgs) -> anyhow::Result<()> {
    use grotto_reference::accuracy;
    let (w, h) = grotto_runtime::cli::render_job::parse_size(&a.size).map_err(anyhow::Error::msg)?;
    std::fs::create_dir_all(&a.out).with_context(|| format!("creating {}", a.out.display()))?;
    let mut index = Vec::new();
    for (name, description, data) in accuracy::closed_scenes() {
        let cam = data.cameras.first().with_context(|| format!("scene {name} has no camera"))?;
        let camera = Camera::from_scene(cam);
        let splat = grotto_runtime::settings::Settings::default().splat_scale;
        let slug = accuracy::slug(name);
        // The reference's discs, for the path tracer; and, where the surfels are the voxel faces
        // of a hand-built scene (one per open face, axis-aligned), those faces: the exact
        // surface the discs stand for.
        let mut scene = SurfelScene::from_scene(&data, splat);
        let on_faces = scene.discs().iter().all(|d| d.normal.abs().max_element() > 0.9999);
        let mut shapes = vec![("discs", grotto_reference::mitsuba::Shapes::Discs)];
        if on_faces {
            shapes.push(("faces", grotto_reference::mitsuba::Shapes::Faces { side_m: data.leaf_size_m }));
        }
        let mut entry = serde_json::json!({ "slug": slug, "mitsuba": {}, "reference": {} });
        for (what, s) in shapes {
            let xml = grotto_reference::mitsuba::scene_xml(&scene, s, &camera, w, h, a.mitsuba_spp)
                .with_context(|| format!("scene {name}"))?;
            let file = format!("{slug}-{what}.xml");
            grotto_runtime::cli::export::write_atomically(&a.out.join(&file), xml.as_bytes())?;
            entry["mitsuba"][what] = file.into();
        }
        // The reference as the report uses it (shadow rays a quarter leaf off the surface, bounce
        // rays a hair), with shadow rays a hair off too, and as it was before this check (bounce
        // rays a quarter leaf off as well): what each choice changes. One scene, its offsets
        // changed between renders.
        let quarter = 0.25 * data.leaf_size_m;
        for (what, shadow_m, bounce_m) in [
            ("quarter leaf", quarter, 0.0),
            ("hair", 0.0, 0.0),
            ("quarter leaf, bounces too", quarter, quarter),
        ] {
            scene = scene.with_ray_offsets(shadow_m, bounce_m);
            let t0 = std::time::Instant::now();
            let est = scene.render(&camera, w, h, a.spp, &PathSettings::for_scene(&data), 1);
            let seconds = t0.elapsed().as_secs_f64();
            let file = format!("{slug}-{}.json", what.replace([' ', ','], "-"));
            let json = serde_json::json!({
                "name": name,
                "description": description,
                "offset": what,
                "width": w,
                "height": h,
                "spp": a.spp,
                "seconds": seconds,
                "discs": scene.discs().len(),
                "mean": est.iter().map(|e| e.mean.to_array()).collect::<Vec<_>>(),
                "std_err": est.iter().map(|e| e.std_err.to_array()).collect::<Vec<_>>(),
            });
            grotto_runtime::cli::export::write_atomically(&a.out.join(&file), json.to_string().as_bytes())?;
            entry["reference"][what] = file.into();
            eprintln!(
                "{name}: {} discs, reference ({what} offset) {} spp in {seconds:.1} s",
                scene.discs().len(),
                a.spp
            );
        }
        index.push(entry);
    }
    let command = format!(
        "cargo run --release -p grotto-reference -- mitsuba --out {} --size {w}x{h} --spp {} --mitsuba-spp {}",
        a.out.display(),
        a.spp,
        a.mitsuba_spp
    );
    let written = index.len();
    let index = serde_json::json!({ "scenes": index, "command": command });
    grotto_runtime::cli::export::write_atomically(&a.out.join("index.json"), index.to_string().as_bytes())?;
    println!("wrote {written} scenes to {}", a.out.display());
    Ok(())
}

fn accuracy(a: AccuracyArgs) -> anyhow::Result<()> {
    use grotto_reference::accuracy;
    let ((w, h), gpu) = size_and_gpu(&a.size, a.software)?;
    eprintln!("reference renders ({} spp, {w}x{h})...", a.spp);
    let mut scenes = if a.leaves_on_surfels || a.hand_built {
        // The hand-built scenes alone: as built, or with their leaves moved.
        let picked: Vec<_> = accuracy::CARVED_SCENES
            .into_iter()
            .filter(|carved| a.scene.as_deref().is_none_or(|o| o == *carved))
            .collect();
        anyhow::ensure!(
            !picked.is_empty(),
            "{}: no hand-built scene named {:?} (they are: {})",
            if a.hand_built { "--hand-built" } else { "--leaves-on-surfels" },
            a.scene.as_deref().unwrap_or_default(),
            accuracy::CARVED_SCENES.join(", ")
        );
        let mut scenes: Vec<_> = picked
            .into_iter()
            .flat_map(|name| accuracy::scenes_cached(w, h, a.spp, Some(name), a.reference_cache.as_deref()))
            .collect();
        if a.leaves_on_surfels {
            scenes.iter_mut().for_each(accuracy::SweepScene::put_leaves_on_surfels);
        }
        scenes
    } else {
        accuracy::scenes_cached(w, h, a.spp, a.scene.as_deref(), a.reference_cache.as_deref())
    };
    anyhow::ensure!(!scenes.is_empty(), "no scene named {:?}", a.scene);
    let mut configs = accuracy::configs();
    if !a.configs.is_empty() {
        let known: Vec<String> = configs
            .iter()
            .map(|c| c.name.clone())
            .chain(scenes.iter().flat_map(|s| s.variants.iter().map(|v| v.name.clone())))
            .collect();
        for name in &a.configs {
            anyhow::ensure!(
                known.contains(name),
                "no config named {name:?}; the configs are: {}",
                known.join(", ")
            );
        }
        configs.retain(|c| a.configs.contains(&c.name));
        for s in &mut scenes {
            s.variants.retain(|v| a.configs.contains(&v.name));
        }
    }
    let bar = indicatif::ProgressBar::new((scenes.len() * configs.len()) as u64);
    let rows = accuracy::sweep(&gpu, &scenes, &configs, w, h, a.error_maps.as_deref(), |scene, config| {
        bar.set_message(format!("{scene}: {config}"));
        bar.inc(1);
    })?;
    bar.finish_and_clear();
    let mut command = format!(
        "cargo run --release -p grotto-reference -- accuracy --size {w}x{h} --spp {}{}{}",
        a.spp,
        if a.software { " --software" } else { "" },
        if a.leaves_on_surfels { " --leaves-on-surfels" } else { "" },
    );
    if a.hand_built {
        command.push_str(" --hand-built");
    }
    // A partial report says which part it is.
    for (flag, value) in
        a.scene.iter().map(|s| ("--scene", s)).chain(a.configs.iter().map(|c| ("--config", c)))
    {
        command.push_str(&format!(" {flag} {value:?}"));
    }
    let default_out = PathBuf::from(if a.leaves_on_surfels {
        "docs/accuracy-hand-built-on-surfels.md"
    } else if a.hand_built {
        "docs/accuracy-hand-built.md"
    } else {
        "docs/accuracy.md"
    });
    let out = a.out.clone().unwrap_or_else(|| default_out.clone());
    if out != default_out {
        command.push_str(&format!(" --out {}", out.display()));
    }
    let plots = out.with_extension("");
    let plots_name = plots.file_name().map_or_else(String::new, |n| n.to_string_lossy().into_owned());
    let mut md = accuracy::report(&scenes, &rows, &gpu.describe(), w, h, &command, &plots_name);
    // The true-surface benchmark beside it (scripts/truth-check.py writes accuracy-truth.json),
    // where the report has the scene it is about.
    let truth_json = out.with_file_name("accuracy-truth.json");
    let has_demo_cave = scenes.iter().any(|s| s.name == "demo cave");
    if let Some(text) = has_demo_cave.then(|| std::fs::read_to_string(&truth_json).ok()).flatten() {
        let truth: serde_json::Value =
            serde_json::from_str(&text).with_context(|| truth_json.display().to_string())?;
        md = accuracy::with_truth(&md, &truth);
    }
    let json = out.with_extension("json");
    grotto_runtime::cli::export::write_atomically(&out, md.as_bytes())?;
    std::fs::create_dir_all(&plots).with_context(|| format!("creating {}", plots.display()))?;
    for sc in &scenes {
        let path = plots.join(format!("{}.svg", accuracy::slug(&sc.name)));
        grotto_runtime::cli::export::write_atomically(&path, accuracy::plot_svg(&sc.name, &rows).as_bytes())?;
    }
    grotto_runtime::cli::export::write_atomically(&json, serde_json::to_string_pretty(&rows)?.as_bytes())?;
    println!("wrote {} and {} ({} runs)", out.display(), json.display(), rows.len());
    Ok(())
}

fn render(cli: RenderArgs) -> anyhow::Result<()> {
    let (w, h) = grotto_runtime::cli::render_job::parse_size(&cli.size).map_err(anyhow::Error::msg)?;
    grotto_runtime::cli::image_out::kind_of(&cli.out)?;
    let scene_data = grotto_runtime::engine::load_scene(&cli.package)
        .with_context(|| cli.package.display().to_string())?;
    let cam = match &cli.camera {
        Some(name) => scene_data
            .cameras
            .iter()
            .find(|c| &c.name == name)
            .with_context(|| format!("no camera named {name:?} in {}", cli.package.display()))?,
        None => {
            scene_data.cameras.first().with_context(|| format!("{} has no cameras", cli.package.display()))?
        }
    };
    let camera = Camera::from_scene(cam);
    camera.validate()?;
    let t0 = std::time::Instant::now();
    let scene = SurfelScene::from_scene(&scene_data, cli.splat_scale);
    let bar = indicatif::ProgressBar::new(u64::from(h));
    if cli.json {
        bar.set_draw_target(indicatif::ProgressDrawTarget::hidden());
    }
    let est = scene.render_with_progress(
        &camera,
        w,
        h,
        cli.spp,
        &PathSettings::for_scene(&scene_data),
        cli.seed,
        |rows| bar.set_position(u64::from(rows)),
    );
    bar.finish_and_clear();
    let frame = Frame {
        width: w,
        height: h,
        hdr: est.iter().map(|e| [e.mean.x, e.mean.y, e.mean.z, 1.0]).collect(),
        ldr: est
            .iter()
            .map(|e| {
                let c = e.mean * cli.exposure;
                [
                    grotto_reference::aces_srgb(c.x),
                    grotto_reference::aces_srgb(c.y),
                    grotto_reference::aces_srgb(c.z),
                    255,
                ]
            })
            .collect(),
    };
    grotto_runtime::cli::image_out::write_frame(&frame, &cli.out)?;
    let mean = est.iter().map(|e| e.mean).sum::<Vec3>() / est.len() as f32;
    let se = est.iter().map(|e| e.std_err).sum::<Vec3>() / est.len() as f32;
    let secs = t0.elapsed().as_secs_f64();
    if cli.json {
        println!(
            "{{\"image\": {:?}, \"width\": {w}, \"height\": {h}, \"spp\": {}, \"mean\": {:?}, \"mean_std_err\": {:?}, \"seconds\": {secs:.3}}}",
            cli.out.display().to_string(),
            cli.spp,
            mean.to_array(),
            se.to_array()
        );
    } else {
        println!(
            "wrote {} ({w}x{h}, {} spp, {} discs) in {secs:.1} s: mean radiance {:.4}, mean standard error {:.4} ({:.2}%)",
            cli.out.display(),
            cli.spp,
            scene.discs().len(),
            mean.y,
            se.y,
            100.0 * se.y / mean.y.max(1e-12)
        );
    }
    Ok(())
}

fn truth(a: TruthArgs) -> anyhow::Result<()> {
    use grotto_reference::truth::{self, Transport};
    let (w, h) = grotto_runtime::cli::render_job::parse_size(&a.size).map_err(anyhow::Error::msg)?;
    let json = std::fs::read_to_string(a.synth.join("synth.json"))
        .with_context(|| format!("{}: no synth.json (build it with grotto-pack synth)", a.synth.display()))?;
    let params: grotto_preprocess::synth::SynthParams =
        serde_json::from_str(&json).with_context(|| format!("{}/synth.json", a.synth.display()))?;
    let scene =
        grotto_runtime::engine::load_scene(&a.package).with_context(|| a.package.display().to_string())?;
    let frame = glam::DVec3::from_array(scene.frame_origin_m);
    let frame_from_local = glam::DVec3::from_array(params.offset_m) - frame;
    let cave = grotto_preprocess::synth::SynthCave::new(&params);
    std::fs::create_dir_all(&a.out)?;
    let bar = indicatif::ProgressBar::new(0).with_message("meshing the true surface");
    let t0 = std::time::Instant::now();
    let mesh = truth::mesh_cave(&cave, a.cell, frame_from_local, |done, total| {
        bar.set_length(total as u64);
        bar.set_position(done as u64);
    });
    bar.finish_and_clear();
    truth::write_ply(&mesh, &a.out.join("mesh.ply"))?;
    eprintln!(
        "mesh: {} triangles at {} m cells in {:.1} s",
        mesh.triangles.len(),
        a.cell,
        t0.elapsed().as_secs_f64()
    );
    // The package's cameras, and a close-up of a wall seen at a grazing angle: from the second
    // scanner station, along the passage turned 25 degrees toward a wall.
    let mut cameras: Vec<(String, Camera)> =
        scene.cameras.iter().map(|c| (c.name.clone(), Camera::from_scene(c))).collect();
    let station = cave.stations.get(1).copied().unwrap_or([0.0, 0.0, 1.0]);
    let along = cave.path.windows(2).min_by(|p, q| {
        let d = |s: &[[f64; 3]]| glam::DVec3::from_array(s[0]).distance(glam::DVec3::from_array(station));
        d(p).total_cmp(&d(q))
    });
    let dir = along.map_or(glam::DVec3::X, |s| {
        (glam::DVec3::from_array(s[1]) - glam::DVec3::from_array(s[0])).normalize()
    });
    let turned =
        glam::DQuat::from_rotation_z(25f64.to_radians()) * glam::DVec3::new(dir.x, dir.y, 0.0).normalize();
    let eye = glam::DVec3::from_array(station) + frame_from_local;
    cameras.push((
        "glancing wall".into(),
        Camera {
            eye_m: eye.as_vec3(),
            look_at_m: (eye + turned * 3.0 - glam::DVec3::Z * 0.4).as_vec3(),
            up: Vec3::Z,
            fov_y_deg: 50.0,
        },
    ));
    let mut listed = Vec::new();
    for (name, cam) in &cameras {
        let slug = name.replace(' ', "-");
        for (transport, spp) in [(Transport::Direct, a.spp_direct), (Transport::Full, a.spp_full)] {
            let xml = truth::scene_xml("mesh.ply", &scene.lights, cam, (w, h, spp), transport)?;
            std::fs::write(a.out.join(format!("{slug}-{}.xml", transport.name())), xml)?;
        }
        let world = |v: Vec3| (v.as_dvec3() + frame).to_array();
        listed.push(serde_json::json!({
            "name": name, "slug": slug,
            "eye_world_m": world(cam.eye_m), "look_at_world_m": world(cam.look_at_m),
            "up": cam.up.to_array(), "fov_y_deg": cam.fov_y_deg,
        }));
    }
    let summary = serde_json::json!({
        "package": a.package.display().to_string(), "width": w, "height": h, "cell_m": a.cell,
        "triangles": mesh.triangles.len(), "lights": scene.lights.len(),
        "spp_direct": a.spp_direct, "spp_full": a.spp_full, "cameras": listed,
    });
    std::fs::write(a.out.join("cameras.json"), serde_json::to_string_pretty(&summary)?)?;
    eprintln!("wrote {} cameras x 2 Mitsuba scenes to {}", cameras.len(), a.out.display());
    Ok(())
}
