//! Where light carried through passages goes wrong: the runtime's outgoing radiance
//! per leaf against the reference's (path traced from each leaf's surfels), summed per region of
//! the dogleg (the lit room, the three corridors, the hidden chamber) or of the long passage
//! (stretches along it) and per bounce: each run with k bounces and no tail against the reference
//! cut after k bounces, what each bounce adds against what the reference's k-th bounce adds, and
//! the presets against full transport. Leaves, not pixels: the dogleg's camera sees only the lit
//! room and the first corridor, the light that reaches the rest is judged where it lands.

use grotto_fixtures::testscenes;
use grotto_runtime::gpu::Gpu;
use grotto_runtime::render::Renderer;
use grotto_runtime::scene::data::SceneData;
use grotto_runtime::settings::{Quality, Settings};
use serde::Serialize;

use crate::tracer::{Estimate, PathSettings, SurfelScene};

/// Bounce counts judged against a reference cut after as many bounces.
pub const CUT_BOUNCES: [u32; 5] = [0, 1, 2, 3, 4];

/// One region's figures for one runtime configuration.
#[derive(Clone, Debug, Serialize)]
pub struct RegionError {
    pub region: String,
    /// Leaves of the region both sides measure.
    pub leaves: usize,
    /// sum(runtime) / sum(reference) - 1 over the region's leaves (luminance: mean of r, g, b).
    pub bias: f64,
    /// sqrt(sum (runtime - reference)^2 / sum reference^2) over the region's leaves.
    pub rel_rmse: f64,
    /// The reference's own noise on the same scale.
    pub reference_noise: f64,
}

/// One runtime configuration against its reference, per region.
#[derive(Clone, Debug, Serialize)]
pub struct BreakdownRow {
    pub config: String,
    /// "cut after k bounces" or "full transport".
    pub against: String,
    pub regions: Vec<RegionError>,
}

/// What bounce k adds to a region's light, runtime against reference.
#[derive(Clone, Debug, Serialize)]
pub struct BounceShare {
    pub bounce: u32,
    pub region: String,
    /// (runtime after k - after k-1) / (reference after k - after k-1), summed over the region.
    pub share: f64,
}

/// The whole breakdown of one scene.
#[derive(Clone, Debug, Serialize)]
pub struct Breakdown {
    pub scene: String,
    pub paths_per_surfel: u32,
    /// Each region's share of the reference's light (full transport), for weighing its error.
    pub light_share: Vec<(String, f64)>,
    pub rows: Vec<BreakdownRow>,
    pub bounces: Vec<BounceShare>,
    /// Per region, the 10th, 25th, 50th, 75th and 90th percentiles of the leaves' ratio runtime /
    /// reference for the direct light alone (bounces 0 against the reference cut there): whether
    /// a region's direct error is every leaf a little or some leaves a lot.
    pub direct_ratio_percentiles: Vec<(String, [f64; 5])>,
}

/// The scenes a breakdown is made for.
#[derive(Clone, Copy, Debug, PartialEq, Eq, clap::ValueEnum)]
pub enum BreakdownScene {
    /// The lit room, three corridors and the hidden chamber ([`testscenes::dogleg`]).
    Dogleg,
    /// 30 m of passage lit at one end, scanned ([`grotto_fixtures::scanned_passage`]).
    Passage,
    /// The closed box with red and green walls and one lamp under the ceiling
    /// ([`testscenes::colour_box`]), face by face, the ceiling near the lamp apart.
    ColourBox,
    /// The dogleg as a survey delivers it: its rock faces scanned and built by grotto-pack
    /// (the accuracy report's "dogleg (scanned)").
    DoglegScanned,
    /// The colour box as a survey delivers it (the accuracy report's "colour box (scanned)").
    ColourBoxScanned,
}

/// Where the long passage's regions end along its centreline, metres from the lit end: 6 m
/// stretches down the straight leg, the bend (18 to 22.7 m) and the leg after it.
const PASSAGE_REGION_ENDS_M: [(&str, f32); 5] =
    [("0-6 m", 6.0), ("6-12 m", 12.0), ("12-18 m", 18.0), ("bend", 22.7), ("past the bend", f32::INFINITY)];

/// The colour box's regions: its faces, the ceiling near the lamp apart.
const COLOUR_BOX_REGIONS: [&str; 7] =
    ["ceiling near the lamp", "ceiling, rest", "floor", "red wall", "green wall", "back wall", "front wall"];

/// Which of [`COLOUR_BOX_REGIONS`] a rock cell of the colour box belongs to: its face
/// ([`testscenes::colour_box_face`]), the ceiling split at 0.5 m from the point above the lamp
/// (`lamp_m` in the carved scene's frame).
fn colour_box_region(lamp_m: glam::Vec3, cell_m: f32, c: glam::IVec3) -> Option<usize> {
    let face = testscenes::colour_box_face(c)?;
    if face > 0 {
        return Some(face + 1);
    }
    let centre_m = (c.as_vec3() + 0.5) * cell_m;
    Some(if (centre_m.truncate() - lamp_m.truncate()).length() < 0.5 { 0 } else { 1 })
}

/// The carved scene's cell a scanned leaf belongs to: a quarter of the carved cell behind its
/// surface, in the carved scene's frame (`scanned_carved::ORIGIN_M`), so a leaf on a face finds
/// the rock cell whose face it is.
fn carved_cell(
    scene: &SceneData,
    leaf: &grotto_runtime::gpu::types::LeafGpu,
    carved_leaf_m: f32,
) -> glam::IVec3 {
    use glam::{DVec3, Vec3};
    let shift = (DVec3::from_array(scene.frame_origin_m)
        - DVec3::from_array(grotto_fixtures::scanned_carved::ORIGIN_M))
    .as_vec3();
    let p = Vec3::from_slice(&leaf.center_m[..3])
        - Vec3::from_slice(&leaf.normal_mean[..3]) * 0.25 * carved_leaf_m;
    ((p + shift) / carved_leaf_m).floor().as_ivec3()
}

impl BreakdownScene {
    pub fn name(self) -> &'static str {
        match self {
            Self::Dogleg => "dogleg",
            Self::Passage => "passage",
            Self::ColourBox => "colour box",
            Self::DoglegScanned => "dogleg (scanned)",
            Self::ColourBoxScanned => "colour box (scanned)",
        }
    }

    /// Where `breakdown` writes its report unless told otherwise.
    pub fn default_out(self) -> &'static str {
        match self {
            Self::Dogleg => "docs/accuracy-passages.md",
            Self::Passage => "docs/accuracy-passage-long.md",
            Self::ColourBox => "docs/accuracy-colour-box.md",
            Self::DoglegScanned => "docs/accuracy-passages-scanned.md",
            Self::ColourBoxScanned => "docs/accuracy-colour-box-scanned.md",
        }
    }

    /// The report's sentence on what a region is.
    pub fn regions_described(self) -> &'static str {
        match self {
            Self::Dogleg => {
                "each region of the dogleg (an air box and the rock cells around it, `testscenes::DOGLEG_REGIONS`): the lit room, the three corridors in the order light reaches them, and the chamber behind them. Leaves, not pixels: the report's camera sees only the lit room and the first corridor"
            }
            Self::Passage => {
                "each stretch of the long passage (scanned and built by grotto-pack, `grotto_fixtures::scanned_passage`; a leaf belongs to the stretch its nearest point of the centreline lies in, metres from the lit end): three 6 m stretches of the straight leg, the bend and the 7 m past it, where only light that bounced arrives"
            }
            Self::ColourBox => {
                "each face of the colour box (`testscenes::colour_box`, 2.4 m inside, the lamp 0.3 m under the ceiling's middle), the ceiling within 0.5 m of the point above the lamp apart from the rest of it"
            }
            Self::DoglegScanned => {
                "each region of the dogleg as a survey delivers it (its rock faces scanned and built by grotto-pack, `grotto_fixtures::scanned_carved`; a leaf belongs to the region of the carved cell a quarter cell behind it): the lit room, the three corridors in the order light reaches them, and the chamber behind them"
            }
            Self::ColourBoxScanned => {
                "each face of the colour box as a survey delivers it (scanned and built by grotto-pack with 0.125 m leaves, `grotto_fixtures::scanned_carved`; a leaf belongs to the face of the carved cell a quarter cell behind it), the ceiling within 0.5 m of the point above the lamp apart from the rest of it"
            }
        }
    }

    /// The scene: the hand-built dogleg, the scanned passage (as the accuracy report has them).
    pub fn data(self) -> Result<SceneData, String> {
        match self {
            Self::Dogleg => Ok(testscenes::dogleg()),
            Self::Passage => crate::accuracy::scanned_passage(),
            Self::ColourBox => Ok(testscenes::colour_box()),
            Self::DoglegScanned | Self::ColourBoxScanned => {
                crate::accuracy::scanned_carved(self.name()).map(|(_, data)| data)
            }
        }
    }

    /// The scene's leaves per region: the dogleg's [`testscenes::DOGLEG_REGIONS`], the passage's
    /// stretches by distance along its centreline.
    pub fn regions(self, scene: &SceneData) -> Vec<(String, Vec<usize>)> {
        let names: Vec<&str> = match self {
            Self::Dogleg | Self::DoglegScanned => {
                testscenes::DOGLEG_REGIONS.iter().map(|(name, _, _)| *name).collect()
            }
            Self::Passage => PASSAGE_REGION_ENDS_M.iter().map(|(name, _)| *name).collect(),
            Self::ColourBox | Self::ColourBoxScanned => COLOUR_BOX_REGIONS.to_vec(),
        };
        // The carved scene's cell, built once (not per leaf).
        let carved = match self {
            Self::Dogleg | Self::DoglegScanned => testscenes::dogleg().leaf_size_m,
            Self::ColourBox | Self::ColourBoxScanned => testscenes::colour_box().leaf_size_m,
            Self::Passage => 0.0,
        };
        // The lamp in the carved scene's frame.
        let lamp_m = scene.lights.first().map_or(glam::Vec3::ZERO, |l| {
            let shift = glam::DVec3::from_array(scene.frame_origin_m)
                - glam::DVec3::from_array(grotto_fixtures::scanned_carved::ORIGIN_M);
            if self == Self::ColourBoxScanned { l.position_m + shift.as_vec3() } else { l.position_m }
        });
        let mut regions: Vec<(String, Vec<usize>)> =
            names.iter().map(|n| ((*n).to_owned(), Vec::new())).collect();
        for (i, leaf) in scene.leaves.iter().enumerate() {
            let region = match self {
                Self::Dogleg => testscenes::dogleg_region(leaf.cell(scene.leaf_size_m)),
                Self::Passage => {
                    let own = grotto_fixtures::scanned_passage::passage_frame_m(
                        scene,
                        glam::Vec3::from_slice(&leaf.center_m[..3]),
                    );
                    let along_m = testscenes::passage_position_m(own).1;
                    PASSAGE_REGION_ENDS_M.iter().position(|(_, end)| along_m < *end)
                }
                Self::ColourBox => colour_box_region(lamp_m, carved, leaf.cell(scene.leaf_size_m)),
                Self::DoglegScanned => testscenes::dogleg_region(carved_cell(scene, leaf, carved)),
                Self::ColourBoxScanned => colour_box_region(lamp_m, carved, carved_cell(scene, leaf, carved)),
            };
            if let Some(r) = region {
                regions[r].1.push(i);
            }
        }
        regions
    }
}

/// A radiance's luminance as the breakdown weighs it: the mean of r, g and b.
pub fn luminance(v: [f32; 3]) -> f64 {
    (f64::from(v[0]) + f64::from(v[1]) + f64::from(v[2])) / 3.0
}

/// A region's error: `runtime` per leaf against `reference` per leaf (leaves without a reference
/// value, which no surfel reaches, are left out).
fn region_error(
    name: &str,
    leaves: &[usize],
    runtime: &[f64],
    reference: &[Option<Estimate>],
) -> RegionError {
    let (mut sum_rt, mut sum_ref, mut sq_err, mut sq_ref, mut sq_se, mut n) = (0.0, 0.0, 0.0, 0.0, 0.0, 0);
    for &i in leaves {
        let Some(e) = &reference[i] else { continue };
        let want = luminance(e.mean.to_array());
        let se = luminance(e.std_err.to_array());
        sum_rt += runtime[i];
        sum_ref += want;
        sq_err += (runtime[i] - want).powi(2);
        sq_ref += want * want;
        sq_se += se * se;
        n += 1;
    }
    let ratio = |a: f64, b: f64| if b > 0.0 { a / b } else { f64::NAN };
    RegionError {
        region: name.to_owned(),
        leaves: n,
        bias: ratio(sum_rt, sum_ref) - 1.0,
        rel_rmse: ratio(sq_err, sq_ref).sqrt(),
        reference_noise: ratio(sq_se, sq_ref).sqrt(),
    }
}

/// The balanced preset with `bounces` bounces run and no tail: what is judged against the
/// reference cut after as many bounces.
pub fn balanced_cut(bounces: u32) -> Settings {
    Settings { bounces, bounce_tail: false, ..Settings::preset(Quality::Balanced) }
}

/// What a breakdown varies besides its scene.
#[derive(Clone, Copy, Debug, Default)]
pub struct BreakdownOptions {
    /// Reference paths per surfel.
    pub paths: u32,
    /// Leaves on their surfels' centroid ([`testscenes::leaves_on_surfels`]), as a built package
    /// has them, instead of at their cells' centres (hand-built scenes only).
    pub leaves_on_surfels: bool,
    /// Every runtime configuration with [`Settings::cone_planes`] on.
    pub cone_planes: bool,
    /// Every runtime configuration with [`Settings::cone_rays`] on.
    pub cone_rays: bool,
    /// Every runtime configuration with the composited cone march at aperture 0.5, the balanced
    /// and high presets' gather before they followed rays (what rays changed).
    pub composited: bool,
    /// The reference's discs cut to their leaf cells (`SurfelScene::clip_discs_to_cells`; a
    /// hand-built scene's carved faces; hand-built scenes only).
    pub clip_discs: bool,
}

/// A renderer of `data` with `settings`, its light settled (for reading the leaves' light).
pub fn settled(gpu: &Gpu, data: &SceneData, settings: Settings) -> grotto_runtime::Result<Renderer> {
    let mut r = Renderer::new(gpu, data, settings)?;
    r.settle(|_, _| {})?;
    Ok(r)
}

/// The radiance each leaf shows (luminance) after settling with `settings`: the bounces run and
/// the tail's estimate of the rest, as the shade pass adds them up.
fn runtime_leaves(gpu: &Gpu, data: &SceneData, settings: Settings) -> grotto_runtime::Result<Vec<f64>> {
    let light = settled(gpu, data, settings)?.read_leaf_light()?;
    Ok(light.iter().zip(&data.leaves).map(|(l, leaf)| luminance(l.shown(leaf))).collect())
}

/// The scene of a breakdown, its leaves moved where `options` say.
fn breakdown_scene(which: BreakdownScene, options: &BreakdownOptions) -> grotto_runtime::Result<SceneData> {
    let mut data = which
        .data()
        .map_err(|problem| grotto_runtime::Error::Scene { package: which.name().into(), problem })?;
    let built = matches!(
        which,
        BreakdownScene::Passage | BreakdownScene::DoglegScanned | BreakdownScene::ColourBoxScanned
    );
    if built && (options.leaves_on_surfels || options.clip_discs) {
        return Err(grotto_runtime::Error::Scene {
            package: which.name().into(),
            problem: "--leaves-on-surfels and --clip-discs are for the hand-built scenes, whose surfels lie one on each face of a rock cell; a package's leaves already lie on their surfels".into(),
        });
    }
    if options.leaves_on_surfels {
        testscenes::leaves_on_surfels(&mut data);
    }
    Ok(data)
}

/// A runtime configuration with the gather `options` ask for every run to use.
fn with_gather(s: Settings, options: &BreakdownOptions) -> Settings {
    let s = if options.composited && s.cone_rays {
        Settings { cone_rays: false, cone_aperture_scale: 0.5, ..s }
    } else {
        s
    };
    Settings {
        cone_planes: s.cone_planes || options.cone_planes,
        cone_rays: s.cone_rays || options.cone_rays,
        ..s
    }
}

/// A scene's breakdown as `options` say. `progress` gets each step.
pub fn breakdown(
    gpu: &Gpu,
    which: BreakdownScene,
    options: BreakdownOptions,
    progress: impl Fn(&str),
) -> grotto_runtime::Result<Breakdown> {
    let (paths, clip_discs) = (options.paths, options.clip_discs);
    let data = breakdown_scene(which, &options)?;
    let regions = which.regions(&data);
    let planes = |s: Settings| with_gather(s, &options);
    let base = planes(Settings::preset(Quality::Balanced));
    let mut scene = SurfelScene::from_scene(&data, base.splat_scale);
    if clip_discs {
        scene.clip_discs_to_cells(data.leaf_size_m);
    }
    let full_settings = PathSettings::for_scene(&data);
    progress("reference, full transport");
    let full = scene.leaf_radiance(&data, paths, &full_settings, 1);
    let mut cut = Vec::new();
    for k in CUT_BOUNCES {
        progress(&format!("reference cut after {k} bounces"));
        let settings = PathSettings { max_bounces: k, ..full_settings };
        cut.push(scene.leaf_radiance(&data, paths, &settings, 2 + u64::from(k)));
    }
    let per_region = |config: &str, against: &str, rt: &[f64], reference: &[Option<Estimate>]| BreakdownRow {
        config: config.to_owned(),
        against: against.to_owned(),
        regions: regions.iter().map(|(name, leaves)| region_error(name, leaves, rt, reference)).collect(),
    };
    let mut rows = Vec::new();
    let mut runtime_cut = Vec::new();
    for (k, reference) in CUT_BOUNCES.iter().zip(&cut) {
        progress(&format!("runtime, {k} bounces, no tail"));
        let rt = runtime_leaves(gpu, &data, planes(balanced_cut(*k)))?;
        rows.push(per_region(
            &format!("bounces {k}, no tail"),
            &format!("cut after {k} bounces"),
            &rt,
            reference,
        ));
        runtime_cut.push(rt);
    }
    let fulls = [
        ("balanced (3 bounces + tail)", base.clone()),
        ("balanced, no tail", Settings { bounce_tail: false, ..base.clone() }),
        ("balanced, 16 bounces", Settings { bounces: 16, ..base.clone() }),
        ("high", planes(Settings::preset(Quality::High))),
    ];
    for (name, settings) in fulls {
        progress(&format!("runtime, {name}"));
        rows.push(per_region(name, "full transport", &runtime_leaves(gpu, &data, settings)?, &full));
    }
    let sum = |values: &[f64], leaves: &[usize], reference: &[Option<Estimate>]| -> f64 {
        leaves.iter().filter(|&&i| reference[i].is_some()).map(|&i| values[i]).sum()
    };
    let ref_lum = |e: &[Option<Estimate>]| -> Vec<f64> {
        e.iter().map(|x| x.as_ref().map_or(0.0, |e| luminance(e.mean.to_array()))).collect()
    };
    let cut_lum: Vec<Vec<f64>> = cut.iter().map(|c| ref_lum(c)).collect();
    let mut bounces = Vec::new();
    for k in 1..CUT_BOUNCES.len() {
        for (name, leaves) in &regions {
            let added_ref = sum(&cut_lum[k], leaves, &full) - sum(&cut_lum[k - 1], leaves, &full);
            let added_rt = sum(&runtime_cut[k], leaves, &full) - sum(&runtime_cut[k - 1], leaves, &full);
            bounces.push(BounceShare {
                bounce: CUT_BOUNCES[k],
                region: name.clone(),
                share: if added_ref > 0.0 { added_rt / added_ref } else { f64::NAN },
            });
        }
    }
    let direct_ref = &cut_lum[0];
    let direct_ratio_percentiles = regions
        .iter()
        .map(|(name, leaves)| {
            let mut ratios: Vec<f64> = leaves
                .iter()
                .filter(|&&i| direct_ref[i] > 1e-6)
                .map(|&i| runtime_cut[0][i] / direct_ref[i])
                .collect();
            ratios.sort_by(f64::total_cmp);
            let at = |q: f64| {
                if ratios.is_empty() {
                    f64::NAN
                } else {
                    ratios[((ratios.len() - 1) as f64 * q).round() as usize]
                }
            };
            (name.clone(), [at(0.1), at(0.25), at(0.5), at(0.75), at(0.9)])
        })
        .collect();
    let full_lum = ref_lum(&full);
    let total: f64 = regions.iter().map(|(_, l)| sum(&full_lum, l, &full)).sum();
    let light_share =
        regions.iter().map(|(name, l)| (name.clone(), sum(&full_lum, l, &full) / total)).collect();
    Ok(Breakdown {
        scene: which.name().into(),
        paths_per_surfel: paths,
        light_share,
        rows,
        bounces,
        direct_ratio_percentiles,
    })
}

/// The breakdown as Markdown tables.
pub fn markdown(b: &Breakdown) -> String {
    let names: Vec<&str> = b.light_share.iter().map(|(n, _)| n.as_str()).collect();
    let header = |first: &str| {
        format!(
            "| {first} | {} |\n|---|{}\n",
            names.join(" | "),
            names.iter().map(|_| "---:|").collect::<String>()
        )
    };
    let mut out = String::new();
    out.push_str(&header("region"));
    out.push_str(&format!(
        "| share of the reference's light | {} |\n",
        b.light_share.iter().map(|(_, s)| format!("{:.1}%", 100.0 * s)).collect::<Vec<_>>().join(" | ")
    ));
    let leaves = b.rows.first().map(|r| r.regions.iter().map(|e| e.leaves.to_string()).collect::<Vec<_>>());
    out.push_str(&format!("| leaves | {} |\n", leaves.unwrap_or_default().join(" | ")));
    out.push_str("\nBias (sum of the runtime's leaf radiance over the reference's, minus 1) and relative RMSE over the region's leaves, each run against its reference:\n\n");
    out.push_str(&header("run (against)"));
    for row in &b.rows {
        let cells: Vec<String> =
            row.regions
                .iter()
                .map(|e| {
                    if e.bias.is_finite() {
                        format!("{:+.3} / {:.3}", e.bias, e.rel_rmse)
                    } else {
                        "-".into()
                    }
                })
                .collect();
        out.push_str(&format!("| {} ({}) | {} |\n", row.config, row.against, cells.join(" | ")));
    }
    out.push_str("\n(- : the reference carries no light there after so few bounces.) The reference's own noise on the relative RMSE scale, largest over the runs, per region: ");
    let noise: Vec<String> = (0..names.len())
        .map(|k| {
            let n = b
                .rows
                .iter()
                .map(|r| r.regions[k].reference_noise)
                .filter(|v| v.is_finite())
                .fold(0.0, f64::max);
            format!("{} {n:.3}", names[k])
        })
        .collect();
    out.push_str(&noise.join(", "));
    out.push_str(".\n");
    out.push_str("\nWhat bounce k adds to a region, the runtime's (bounces k minus bounces k - 1, no tail) over the reference's (cut after k minus cut after k - 1): 1 carries the bounce's light exactly.\n\n");
    out.push_str(&header("bounce"));
    let mut k = 0;
    for s in &b.bounces {
        if s.bounce != k {
            if k != 0 {
                out.push_str(" |\n");
            }
            k = s.bounce;
            out.push_str(&format!("| {k}"));
        }
        if s.share.is_finite() {
            out.push_str(&format!(" | {:.3}", s.share));
        } else {
            out.push_str(" | -");
        }
    }
    out.push_str(" |\n");
    out.push_str("\nThe direct light alone, leaf by leaf: percentiles of the runtime's leaf radiance over the reference's (bounces 0 against the reference cut there), over the leaves the reference lights:\n\n");
    out.push_str(&header("percentile"));
    for (k, q) in ["10th", "25th", "50th", "75th", "90th"].iter().enumerate() {
        let cells: Vec<String> = b
            .direct_ratio_percentiles
            .iter()
            .map(|(_, p)| if p[k].is_finite() { format!("{:.3}", p[k]) } else { "-".into() })
            .collect();
        out.push_str(&format!("| {q} | {} |\n", cells.join(" | ")));
    }
    out
}
