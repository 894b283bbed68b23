//! The sweep's scenes and their reference images (cached on disk by content).

use glam::Vec3;
use grotto_fixtures::testscenes;
use grotto_preprocess::build::{ColorCodec, SurfelCodec};
use grotto_runtime::scene::data::SceneData;
use grotto_runtime::settings::Settings;
use grotto_runtime::view::camera::Camera;

use crate::accuracy::configs::TRUNCATED_BOUNCES;
use crate::accuracy::configs::Variant;
use crate::accuracy::configs::slug;
use crate::tracer::{Estimate, PathSettings, SurfelScene};

/// A scene of the sweep and its reference image.
#[derive(Debug)]
pub struct SweepScene {
    pub name: String,
    pub(crate) description: String,
    pub(crate) data: SceneData,
    pub(crate) camera: Camera,
    pub(crate) reference: Vec<Estimate>,
    pub(crate) reference_s: f64,
    pub(crate) spp: u32,
    /// References cut after k indirect bounces, for k in `TRUNCATED_BOUNCES`: the runtime with k
    /// bounces is compared with these to judge propagation alone, without the missing bounces.
    pub(crate) truncated: Vec<(u32, Vec<Estimate>)>,
    /// The same surfels built into other packages (SVO depth, colour codec, surfel encoding, SH
    /// window), each rendered with the balanced preset and judged against this scene's reference.
    pub variants: Vec<Variant>,
}

/// The scenes built by `testscenes::carved`: leaves at their cells' centres, surfels on the open
/// faces, half a leaf in front of them.
pub const CARVED_SCENES: [&str; 2] = ["colour box", "dogleg"];

impl SweepScene {
    /// Moves a carved scene's leaves (one of [`CARVED_SCENES`]) onto their surfels' centroid, as
    /// grotto-pack places a package's (`testscenes::leaves_on_surfels`), and says so in its
    /// description. The reference, traced from the surfels, is the same.
    pub fn put_leaves_on_surfels(&mut self) {
        testscenes::leaves_on_surfels(&mut self.data);
        for v in &mut self.variants {
            testscenes::leaves_on_surfels(&mut v.data);
        }
        self.description.push_str(
            "; leaves moved onto their surfels' centroid, as packages have them (`--leaves-on-surfels`; the scene puts them at their cells' centres, half a leaf behind the surface)",
        );
    }
}

/// The closed scenes (name, description, scene): the hand-built furnace shell, colour box and
/// hidden-chamber dogleg, and the scanned long passage (also rendered by Mitsuba 3 to check the
/// reference: mitsuba.rs).
pub fn closed_scenes() -> Vec<(&'static str, &'static str, SceneData)> {
    closed_scenes_named(None, true)
}

/// One accuracy scene's data by its report name (the closed scenes, "bunny", "demo cave" with raw
/// colours and full surfels at 0.25 m, as the report's): for examples that study one scene.
pub fn scene_named(name: &str) -> Result<SceneData, String> {
    match name {
        "bunny" => bunny(),
        "passage" => scanned_passage(),
        "demo cave" => demo_cave(ColorCodec::Raw, SurfelCodec::Full, 0.25, None, false),
        other => closed_scenes_named(Some(other), false)
            .into_iter()
            .find(|s| s.0 == other)
            .map(|s| s.2)
            .ok_or_else(|| format!("no scene {other:?}")),
    }
}

/// The closed scenes, or only the one named `only`: the furnace, the colour box and the dogleg
/// hand-built (`hand_built`, or named) or as a survey delivers them (the report's), and the
/// passage. The scanned scenes are built through the preprocessor, which a run for another scene
/// should not wait for.
fn closed_scenes_named(only: Option<&str>, hand_built: bool) -> Vec<(&'static str, &'static str, SceneData)> {
    let mut furnace = testscenes::furnace_sphere(5, 11.0, 0.8, 1.0);
    let c = Vec3::splat(1.6);
    furnace.cameras.push(grotto_runtime::scene::data::SceneCamera {
        name: "inside".into(),
        eye_m: c,
        look_at_m: c + Vec3::new(1.0, 0.3, -0.2),
        up: Vec3::Z,
        fov_y_deg: 70.0,
    });
    let mut scenes =
        vec![("furnace", "closed shell, emission 1, albedo 0.8 (exact radiance 5 everywhere)", furnace)];
    let named = |name: &str| only == Some(name);
    if hand_built || named("colour box") {
        scenes.push((
            "colour box",
            "closed box, red and green walls, one 30 W lamp: colour bleeding; hand-built (leaves at their cells' centres)",
            testscenes::colour_box(),
        ));
    }
    if hand_built || named("dogleg") {
        scenes.push((
            "dogleg",
            "rock, a lit room and a chamber behind three right-angle corridors, one 200 W lamp; hand-built (leaves at their cells' centres)",
            testscenes::dogleg(),
        ));
    }
    // Built through the preprocessor: the report's rooms, as a survey delivers them.
    for name in SCANNED_CARVED_SCENES {
        if (!hand_built && only.is_none()) || named(name) {
            match scanned_carved(name) {
                Ok((description, data)) => scenes.push((name, description, data)),
                Err(e) => eprintln!("{name} scene skipped: {e}"),
            }
        }
    }
    match only.is_none_or(|o| o == "passage").then(scanned_passage) {
        None => {}
        Some(Ok(data)) => scenes.push((
            "passage",
            "a 30 m tube of wandering width with a flat floor, 18 m straight then round a bend, lit by one 100 W lamp 1 m from its closed end; albedo 0.7; its smooth surface sampled every 5 cm by six scans at survey coordinates and built by grotto-pack with 0.25 m leaves",
            data,
        )),
        Some(Err(e)) => eprintln!("passage scene skipped: {e}"),
    }
    scenes.retain(|d| only.is_none_or(|o| o == d.0));
    scenes
}

/// The long passage scanned and built through the preprocessor
/// (`grotto_fixtures::scanned_passage`).
pub fn scanned_passage() -> Result<SceneData, String> {
    let dir = tempfile::tempdir().map_err(|e| e.to_string())?;
    let out = grotto_fixtures::scanned_passage::passage_package(dir.path()).map_err(|e| e.to_string())?;
    let pkg = grotto_format::Package::open(&out).map_err(|e| e.to_string())?;
    SceneData::from_package(&pkg).map_err(|e| e.to_string())
}

/// The carved scenes as a survey would deliver them ([`scanned_carved`]), by report name, in the
/// order of [`CARVED_SCENES`].
pub const SCANNED_CARVED_SCENES: [&str; 2] = ["colour box (scanned)", "dogleg (scanned)"];

/// One of [`SCANNED_CARVED_SCENES`]: the carved scene's rock faces sampled by scans and built
/// through the preprocessor (`grotto_fixtures::scanned_carved`), with its description.
pub fn scanned_carved(name: &str) -> Result<(&'static str, SceneData), String> {
    use glam::IVec3;
    use grotto_fixtures::scanned_carved::{CarvedSurvey, carved_package};
    let dogleg_rooms = testscenes::DOGLEG_REGIONS.map(|r| (r.1, r.2));
    let (description, survey) = match name {
        "dogleg (scanned)" => (
            "the dogleg's rock faces sampled every 5 cm (5 x 5 points a leaf face), one scan per room and corridor, built by grotto-pack with 0.25 m leaves",
            CarvedSurvey {
                name: "dogleg",
                leaf_m: 0.25,
                dims: testscenes::DOGLEG_DIMS,
                air: &testscenes::dogleg_air,
                albedo: &|_| Vec3::splat(0.8),
                rooms: &dogleg_rooms,
                points_per_edge: 5,
                package_leaf_m: 0.25,
                scene: testscenes::dogleg(),
            },
        ),
        "colour box (scanned)" => (
            "the colour box's faces sampled every 2 cm (5 x 5 points a 0.1 m cell face), one scan, built by grotto-pack with 0.125 m leaves (a package's leaf is a power of two of metres)",
            CarvedSurvey {
                name: "colour-box",
                leaf_m: 0.1,
                dims: IVec3::splat(testscenes::COLOUR_BOX_CELLS),
                air: &testscenes::colour_box_air,
                albedo: &testscenes::colour_box_albedo,
                rooms: &[([1, 1, 1], [testscenes::COLOUR_BOX_CELLS - 1; 3])],
                points_per_edge: 5,
                package_leaf_m: 0.125,
                scene: testscenes::colour_box(),
            },
        ),
        other => return Err(format!("no scanned scene {other:?}")),
    };
    let dir = tempfile::tempdir().map_err(|e| e.to_string())?;
    let out = carved_package(dir.path(), &survey).map_err(|e| e.to_string())?;
    let pkg = grotto_format::Package::open(&out).map_err(|e| e.to_string())?;
    Ok((description, SceneData::from_package(&pkg).map_err(|e| e.to_string())?))
}

/// The report's scenes: the furnace shell, the colour box and the hidden-chamber dogleg as a
/// survey delivers them, the scanned passage, the bunny and the synthetic demo cave with and
/// without sky; `only` keeps the one with that name (the hand-built "colour box" and "dogleg"
/// too).
pub fn scenes(width: u32, height: u32, spp: u32, only: Option<&str>) -> Vec<SweepScene> {
    scenes_cached(width, height, spp, only, None)
}

/// [`scenes`], with the reference renders kept in `cache` (a folder) and read back while the scene,
/// the image size and the paths per pixel are the same: for iterating on the runtime with
/// `--config`, where the references would otherwise dominate. The key hashes the scene's surfels,
/// lights, camera and environment, and the path tracer's version below (bump it with any change
/// to the path tracer).
pub fn scenes_cached(
    width: u32,
    height: u32,
    spp: u32,
    only: Option<&str>,
    cache: Option<&std::path::Path>,
) -> Vec<SweepScene> {
    let mut out = Vec::new();
    let defs = closed_scenes_named(only, false);
    let mut defs: Vec<_> = defs.into_iter().map(|(a, b, c)| (a, b, c, Vec::new())).collect();
    if only.is_none_or(|o| o == "bunny") {
        match bunny() {
            Ok(data) => defs.push((
                "bunny",
                "a real scan: the Stanford bunny's ten range scans (362k points) merged with the poses of bun.conf, 2 mm leaves, one lamp above and in front; indirect light is its own interreflection",
                data,
                Vec::new(),
            )),
            Err(e) => eprintln!("bunny scene skipped: {e}"),
        }
    }
    if only.is_none_or(|o| o == "cave with sky") {
        let sky = shared_data().join("envmaps/probulator_ennis.hdr");
        match demo_cave(ColorCodec::Raw, SurfelCodec::Full, 0.25, Some(&sky), false).and_then(|raw| {
            let windowed = demo_cave(ColorCodec::Raw, SurfelCodec::Full, 0.25, Some(&sky), true)?;
            Ok((raw, windowed))
        }) {
            Ok((raw, windowed)) => defs.push((
                "cave with sky",
                "the demo cave lit also by an environment map (probulator ennis.hdr, whose bright window makes SH irradiance ring negative: windowed at s = 0.124) through its entrance, SH unwindowed; the reference sees the same 9 unwindowed coefficients as its sky",
                raw,
                vec![Variant { name: "SH windowed".into(), knob: "sh window".into(), data: windowed }],
            )),
            Err(e) => eprintln!("cave with sky scene skipped: {e}"),
        }
    }
    if only.is_none_or(|o| o == "demo cave") {
        match demo_cave_variants() {
            Ok((data, variants)) => defs.push((
                "demo cave",
                "the synthetic demo cave (80k points, 0.25 m leaves, raw colours, 14 lamps), camera at the entrance: a passage lit mostly indirectly",
                data,
                variants,
            )),
            Err(e) => eprintln!("demo cave scene skipped: {e}"),
        }
    }
    for (name, description, data, variants) in defs {
        let camera = Camera::from_scene(&data.cameras[0]);
        let scene = SurfelScene::from_scene(&data, Settings::default().splat_scale);
        let key = reference_key(&data, width, height, spp);
        let (reference, reference_s) = cached_render(cache, name, key, "full", width * height, || {
            scene.render(&camera, width, height, spp, &PathSettings::for_scene(&data), 1)
        });
        let truncated = TRUNCATED_BOUNCES
            .iter()
            .map(|&k| {
                let cut = PathSettings { max_bounces: k + 1, ..PathSettings::for_scene(&data) };
                let (est, _) = cached_render(cache, name, key, &format!("cut{k}"), width * height, || {
                    scene.render(&camera, width, height, spp, &cut, 2)
                });
                (k, est)
            })
            .collect();
        out.push(SweepScene {
            name: name.into(),
            description: description.into(),
            data,
            camera,
            reference,
            reference_s,
            spp,
            truncated,
            variants,
        });
    }
    out
}

/// The path tracer's version in [`scenes_cached`]'s key.
pub(crate) const REFERENCE_CACHE_VERSION: u64 = 1;

/// FNV-1a over what a reference render depends on.
pub(crate) fn reference_key(data: &SceneData, width: u32, height: u32, spp: u32) -> u64 {
    let mut h = 0xcbf2_9ce4_8422_2325u64;
    let mut eat = |bytes: &[u8]| {
        for &b in bytes {
            h = (h ^ u64::from(b)).wrapping_mul(0x100_0000_01b3);
        }
    };
    eat(&REFERENCE_CACHE_VERSION.to_le_bytes());
    eat(&[width, height, spp].map(u32::to_le_bytes).concat());
    eat(bytemuck::cast_slice(&data.surfels));
    eat(format!("{:?}{:?}{:?}{:?}", data.lights, data.cameras, data.environment_sh, data.materials)
        .as_bytes());
    h
}

/// `render()` and the seconds it took, or both from `cache` where a file with this key holds
/// them (the seconds then are the render's when it was made); a fresh render is written there
/// (a failed write only costs the next run a render). The file: the seconds as f64, then the
/// image's `Estimate`s, little-endian.
pub(crate) fn cached_render(
    cache: Option<&std::path::Path>,
    scene: &str,
    key: u64,
    what: &str,
    pixels: u32,
    render: impl FnOnce() -> Vec<Estimate>,
) -> (Vec<Estimate>, f64) {
    let path = cache.map(|dir| dir.join(format!("{}-{what}-{key:016x}.f32", slug(scene))));
    if let Some(bytes) = path.as_ref().and_then(|p| std::fs::read(p).ok())
        && bytes.len() == 8 + pixels as usize * size_of::<Estimate>()
    {
        let seconds = f64::from_le_bytes(bytes[..8].try_into().expect("8 bytes"));
        return (bytemuck::pod_collect_to_vec(&bytes[8..]), seconds);
    }
    let t0 = std::time::Instant::now();
    let est = render();
    let seconds = t0.elapsed().as_secs_f64();
    if let Some(path) = path
        && path.parent().is_some_and(|dir| std::fs::create_dir_all(dir).is_ok())
    {
        let bytes = [&seconds.to_le_bytes()[..], bytemuck::cast_slice(&est)].concat();
        let _ = grotto_runtime::cli::export::write_atomically(&path, &bytes);
    }
    (est, seconds)
}

/// A small synthetic cave built through the whole pipeline (synth -> package -> scene).
pub fn demo_cave(
    colors: ColorCodec,
    surfels: SurfelCodec,
    leaf_m: f64,
    sky: Option<&std::path::Path>,
    sh_window: bool,
) -> Result<SceneData, String> {
    let dir = tempfile::tempdir().map_err(|e| e.to_string())?;
    let cave = grotto_fixtures::SmallCave {
        colors,
        surfels,
        leaf_m,
        sky: sky.map(std::path::Path::to_path_buf),
        sh_window,
        ..Default::default()
    };
    let out = grotto_fixtures::small_cave_package(dir.path(), &cave).map_err(|e| e.to_string())?;
    let pkg = grotto_format::Package::open(&out).map_err(|e| e.to_string())?;
    let mut scene = SceneData::from_package(&pkg).map_err(|e| e.to_string())?;
    // The entrance camera first: it looks down a passage the lamps light mostly indirectly.
    scene.cameras.sort_by_key(|c| c.name != "entrance");
    Ok(scene)
}

/// `../shared/data` beside the repository (the real third-party scans).
pub fn shared_data() -> std::path::PathBuf {
    std::path::Path::new(env!("CARGO_MANIFEST_DIR")).join("../../shared/data")
}

/// The Stanford bunny's range scans, registered by bun.conf and built into a package with 2 mm
/// leaves; a lamp and a camera are placed from its bounds (the scans carry neither).
pub fn bunny() -> Result<SceneData, String> {
    use grotto_preprocess::build::{self, BuildParams};
    let conf = shared_data().join("ply/stanford-bunny/data/bun.conf");
    let manifest = grotto_preprocess::manifest::Manifest::load(&conf).map_err(|e| e.to_string())?;
    let dir = tempfile::tempdir().map_err(|e| e.to_string())?;
    let out = dir.path().join("bunny.grotto");
    let bp = BuildParams {
        work_dir: dir.path().join("work"),
        memory_budget_bytes: 256 << 20,
        threads: 2,
        // The tile cap docs/accuracy.md was measured with (3/4 budget / threads / 256 B then).
        max_tile_points: 393_216,
        leaf_m: 1.0 / 512.0,
        colors: ColorCodec::Raw,
        surfels: SurfelCodec::Full,
        min_tile_extent_m: 1.0 / 16.0,
        max_tile_extent_m: 0.25,
        halo_m: 0.004,
        ..BuildParams::default()
    };
    build::build(&manifest, &conf, &out, &bp, &|_| {}).map_err(|e| e.to_string())?;
    let pkg = grotto_format::Package::open(&out).map_err(|e| e.to_string())?;
    let mut scene = SceneData::from_package(&pkg).map_err(|e| e.to_string())?;
    let (lo, hi) = scene.surfels.iter().fold((Vec3::MAX, Vec3::MIN), |(lo, hi), s| {
        let p = Vec3::from_slice(&s.position_radius[..3]);
        (lo.min(p), hi.max(p))
    });
    let (c, size) = ((lo + hi) * 0.5, (hi - lo).max_element());
    let light_m = c + Vec3::new(0.6, 1.2, 1.0) * size;
    scene.lights.push(grotto_runtime::scene::data::SceneLight {
        name: "lamp".into(),
        position_m: light_m,
        // About 3 W/m^2 on the bunny.
        intensity_w_sr: Vec3::splat(3.0 * (light_m - c).length_squared()),
        spot: None,
        profile: None,
    });
    scene.cameras.push(grotto_runtime::scene::data::SceneCamera {
        name: "front".into(),
        eye_m: c + Vec3::new(0.3, 0.25, 1.8) * size,
        look_at_m: c,
        up: Vec3::Y,
        fov_y_deg: 45.0,
    });
    Ok(scene)
}

/// The demo cave with raw colours, full-precision surfels and 0.25 m leaves (the reference's
/// scene), and the package knobs around it: one SVO level coarser and finer, BC1 colours (the
/// default ISPC kernel refined by cluster fit, ISPC alone as `--colors bc1-fast` and cluster fit
/// alone as `--colors bc1-cluster`), compact surfels (format 2.0, what `grotto-pack build` writes
/// by default).
pub(crate) fn demo_cave_variants() -> Result<(SceneData, Vec<Variant>), String> {
    let base = demo_cave(ColorCodec::Raw, SurfelCodec::Full, 0.25, None, true)?;
    let mut variants = Vec::new();
    for (name, knob, colors, surfels, leaf_m) in [
        ("leaf 0.5 m (depth -1)", "svo depth", ColorCodec::Raw, SurfelCodec::Full, 0.5),
        ("leaf 0.125 m (depth +1)", "svo depth", ColorCodec::Raw, SurfelCodec::Full, 0.125),
        ("BC1 colours", "colours", ColorCodec::Bc1, SurfelCodec::Full, 0.25),
        ("BC1 colours, ISPC", "colours", ColorCodec::Bc1Fast, SurfelCodec::Full, 0.25),
        ("BC1 colours, cluster fit", "colours", ColorCodec::Bc1Cluster, SurfelCodec::Full, 0.25),
        ("compact surfels", "surfels", ColorCodec::Raw, SurfelCodec::Compact, 0.25),
    ] {
        let v = demo_cave(colors, surfels, leaf_m, None, true)?;
        if v.surfels.len() != base.surfels.len() {
            return Err(format!(
                "{name}: {} surfels against {} in the reference scene",
                v.surfels.len(),
                base.surfels.len()
            ));
        }
        variants.push(Variant { name: name.into(), knob: knob.into(), data: v });
    }
    Ok((base, variants))
}
