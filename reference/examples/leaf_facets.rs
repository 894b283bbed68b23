//! How many of a scene's leaves hold two facets: surfels that split into two groups
//! of clearly different normals, as on a convex edge of rock (an opening's rim, a pillar, a
//! ledge) or a thin sheet seen from both sides. Such a leaf has one mean normal and one light in
//! the runtime, lit, gathered and seen as one surface across the diagonal between its facets;
//! on the dogleg those leaves carry 1.35 of their first bounce (docs/reference.md, "Where the
//! light goes wrong"). This sizes what giving leaves their facets would touch in real data.
//!
//! `cargo run --release -p grotto-reference --example leaf_facets -- [SCENE ...]` (the accuracy
//! report's names: "passage", "demo cave", "bunny", dogleg, "colour box"; default: all five; the
//! hand-built two with their leaves on their surfels). A leaf's surfel normals are split by
//! 2-means (seeded with the normal furthest from the mean and the one furthest from that); the
//! leaf counts as two facets where the normals do not agree as one (mean resultant length under
//! `ONE` = 0.9), each group agrees within itself (at least `TIGHT` = 0.9), each holds at least
//! `SHARE` = 20% of the leaf's surfels, and the groups' normals lie at least `ANGLE` = 45 degrees
//! apart. Leaves of fewer than 4 surfels are not judged (2 on the hand-built scenes, which put
//! one surfel on each face of a rock cell).
use glam::{DVec3, IVec3, Vec3};
use grotto_fixtures::testscenes;
use grotto_reference::accuracy::scene_named;
use grotto_runtime::scene::data::SceneData;

fn env(name: &str, default: f64) -> f64 {
    std::env::var(name).ok().and_then(|v| v.parse().ok()).unwrap_or(default)
}

/// Two groups of unit normals: each group's resultant (sum) and count.
fn two_means(normals: &[DVec3]) -> [(DVec3, usize); 2] {
    let mean = normals.iter().sum::<DVec3>();
    let furthest =
        |from: DVec3| *normals.iter().min_by(|a, b| a.dot(from).total_cmp(&b.dot(from))).unwrap_or(&DVec3::Z);
    let mut c = [furthest(mean), DVec3::ZERO];
    c[1] = furthest(c[0]);
    let mut groups = [(DVec3::ZERO, 0usize); 2];
    for _ in 0..10 {
        groups = [(DVec3::ZERO, 0), (DVec3::ZERO, 0)];
        for n in normals {
            let g = usize::from(n.dot(c[1]) > n.dot(c[0]));
            groups[g].0 += *n;
            groups[g].1 += 1;
        }
        for (k, (sum, _)) in groups.iter().enumerate() {
            if sum.length() > 1e-9 {
                c[k] = sum.normalize();
            }
        }
    }
    groups
}

struct Tally {
    judged: usize,
    two: usize,
    surfels: usize,
    surfels_in_two: usize,
    /// Two-facet leaves by the angle between their facets: 45-75, 75-105, 105-150, over 150 degrees.
    by_angle: [usize; 4],
}

fn tally(data: &SceneData, fewest: usize) -> Tally {
    let leaf_m = data.leaf_size_m;
    let (one, tight, share, angle) =
        (env("ONE", 0.9), env("TIGHT", 0.9), env("SHARE", 0.2), env("ANGLE", 45.0).to_radians());
    let mut by_cell = std::collections::HashMap::<IVec3, Vec<DVec3>>::new();
    for s in &data.surfels {
        let p = Vec3::from_slice(&s.position_radius[..3]);
        let n = Vec3::from_slice(&s.normal_spread[..3]).normalize_or_zero();
        if n == Vec3::ZERO {
            continue;
        }
        // A quarter leaf behind the surface: a surfel on a cell face (hand-built scenes) is in
        // the rock's leaf, as the reference assigns it.
        let cell = ((p - n * 0.25 * leaf_m) / leaf_m).floor().as_ivec3();
        by_cell.entry(cell).or_default().push(n.as_dvec3());
    }
    let mut t = Tally { judged: 0, two: 0, surfels: data.surfels.len(), surfels_in_two: 0, by_angle: [0; 4] };
    for normals in by_cell.values().filter(|n| n.len() >= fewest) {
        t.judged += 1;
        let count = normals.len() as f64;
        if normals.iter().sum::<DVec3>().length() / count >= one {
            continue;
        }
        let g = two_means(normals);
        let agrees = g.iter().all(|(sum, k)| *k > 0 && sum.length() / *k as f64 >= tight);
        let shared = g.iter().all(|(_, k)| *k as f64 / count >= share);
        if !(agrees && shared) {
            continue;
        }
        let between = g[0].0.normalize().dot(g[1].0.normalize()).clamp(-1.0, 1.0).acos();
        if between < angle {
            continue;
        }
        t.two += 1;
        t.surfels_in_two += normals.len();
        let deg = between.to_degrees();
        t.by_angle[if deg < 75.0 {
            0
        } else if deg < 105.0 {
            1
        } else if deg < 150.0 {
            2
        } else {
            3
        }] += 1;
    }
    t
}

fn main() -> anyhow::Result<()> {
    let mut names: Vec<String> = std::env::args().skip(1).collect();
    if names.is_empty() {
        names = ["passage", "demo cave", "bunny", "dogleg", "colour box"].map(String::from).to_vec();
    }
    println!(
        "| scene | leaves judged | two facets | share | surfels in them | 45-75 deg | 75-105 | 105-150 | 150+ |"
    );
    println!("|---|---:|---:|---:|---:|---:|---:|---:|---:|");
    for name in &names {
        let mut data = scene_named(name).map_err(anyhow::Error::msg)?;
        let hand_built = matches!(name.as_str(), "dogleg" | "colour box");
        if hand_built {
            testscenes::leaves_on_surfels(&mut data);
        }
        let t = tally(&data, if hand_built { 2 } else { 4 });
        let a = t.by_angle;
        println!(
            "| {name} | {} | {} | {:.1}% | {:.1}% | {} | {} | {} | {} |",
            t.judged,
            t.two,
            100.0 * t.two as f64 / t.judged.max(1) as f64,
            100.0 * t.surfels_in_two as f64 / t.surfels.max(1) as f64,
            a[0],
            a[1],
            a[2],
            a[3]
        );
    }
    Ok(())
}
