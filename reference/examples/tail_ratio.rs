//! How well the bounce tail estimates the bounces not run: the runtime's leaf light
//! after k bounces (no tail) plus a tail extrapolated with a ratio per leaf (the first tail
//! the runtime had), per tile (over every leaf, or over the tile's settling leaves: passes/tail.wgsl),
//! or one for the whole scene, against the same renderer after 16 bounces (what the tail
//! stands for), as relative RMSE and bias over the leaves. The dogleg also per region.
//!
//! `cargo run --release -p grotto-reference --example tail_ratio [scene] [--leaves-on-surfels]`
//! (scene: colour box, dogleg, furnace, passage; default colour box); `TAIL_K=2` extrapolates
//! after 2 bounces (fast) instead of 3 (balanced).
use grotto_fixtures::testscenes;
use grotto_reference::accuracy::breakdown::settled;
use grotto_runtime::gpu::types::LeafLightGpu;
use grotto_runtime::gpu::{Gpu, GpuOptions};
use grotto_runtime::settings::{Quality, Settings};

type Tail<'a> = &'a dyn Fn(usize, usize) -> f64;

fn main() -> anyhow::Result<()> {
    let gpu = Gpu::new(&GpuOptions::default())?;
    let args: Vec<String> = std::env::args().skip(1).collect();
    let name = args.iter().find(|a| !a.starts_with("--")).cloned().unwrap_or_else(|| "colour box".into());
    let on_surfels = args.iter().any(|a| a == "--leaves-on-surfels");
    let mut data =
        grotto_reference::accuracy::scene_named(&name).map_err(|e| anyhow::anyhow!("{name}: {e}"))?;
    if on_surfels {
        testscenes::leaves_on_surfels(&mut data);
    }
    let k: u32 = std::env::var("TAIL_K").ok().and_then(|v| v.parse().ok()).unwrap_or(3).max(2);
    let base = Settings::preset(Quality::Balanced);
    let run = |b: u32| -> anyhow::Result<Vec<[f64; 3]>> {
        let st = Settings { bounces: b, bounce_tail: false, convergence_tolerance: 0.0, ..base.clone() };
        let light = settled(&gpu, &data, st)?.read_leaf_light()?;
        Ok(light.iter().zip(&data.leaves).map(|(l, leaf)| l.shown(leaf).map(f64::from)).collect())
    };
    let (s1, s2, s3, s16) = (run(k - 2)?, run(k - 1)?, run(k)?, run(16)?);
    // The ratios the tail pass trusts, as the renderer sets them for this scene.
    let trusted = grotto_runtime::render::Renderer::new(&gpu, &data, base.clone())?.params().tail_ratio_max;
    let ratio_max = [trusted[0], trusted[1], trusted[2]];
    let n = data.leaves.len();
    let mut tile_of = vec![0usize; n];
    for (t, tile) in data.tiles.iter().enumerate() {
        for i in tile.leaf_offset..tile.leaf_offset + tile.leaf_count {
            tile_of[i as usize] = t;
        }
    }
    let d = |i: usize, c: usize| (s3[i][c] - s2[i][c], s2[i][c] - s1[i][c]);
    // Sums per tile (all leaves, settling leaves) and over the scene: residual, the one before.
    let nt = data.tiles.len();
    let (mut all, mut settling, mut scene) =
        (vec![[[0.0f32; 3]; 2]; nt], vec![[[0.0f32; 3]; 2]; nt], [[0.0f32; 3]; 2]);
    for i in 0..n {
        for c in 0..3 {
            let (now, before) = d(i, c);
            let (now, before) = (now as f32, before as f32);
            all[tile_of[i]][0][c] += now;
            all[tile_of[i]][1][c] += before;
            scene[0][c] += now;
            scene[1][c] += before;
            if LeafLightGpu::settling(now, before) {
                settling[tile_of[i]][0][c] += now;
                settling[tile_of[i]][1][c] += before;
            }
        }
    }
    let ratio = |s: &[[f32; 3]; 2]| LeafLightGpu::tile_ratio(s[0], s[1], ratio_max);
    let tail = |i: usize, c: usize, r: [f32; 3]| {
        let residual = [0, 1, 2].map(|k| d(i, k).0 as f32);
        f64::from(LeafLightGpu::tail_of(residual, r)[c])
    };
    let per_leaf = |i: usize, c: usize| {
        let own = [0, 1, 2].map(|k| [d(i, k).0 as f32, d(i, k).1 as f32]);
        let r = LeafLightGpu::tile_ratio(own.map(|o| o[0]), own.map(|o| o[1]), ratio_max);
        tail(i, c, r)
    };
    let per_tile = |i: usize, c: usize| tail(i, c, ratio(&all[tile_of[i]]));
    let per_tile_settling = |i: usize, c: usize| tail(i, c, ratio(&settling[tile_of[i]]));
    let global = |i: usize, c: usize| tail(i, c, ratio(&scene));
    let none = |_: usize, _: usize| 0.0;
    let regions: Vec<(&str, Vec<usize>)> = if name == "dogleg" {
        testscenes::DOGLEG_REGIONS
            .iter()
            .enumerate()
            .map(|(r, (region, _, _))| {
                let leaves = (0..n)
                    .filter(|&i| testscenes::dogleg_region(data.leaves[i].cell(data.leaf_size_m)) == Some(r))
                    .collect();
                (*region, leaves)
            })
            .collect()
    } else {
        Vec::new()
    };
    println!(
        "{name}{}: tail after {k} bounces against 16 bounces, {n} leaves in {nt} tiles",
        if on_surfels { " (leaves on surfels)" } else { "" }
    );
    let rows: [(&str, Tail<'_>); 5] = [
        ("none", &none),
        ("ratio per leaf", &per_leaf),
        ("ratio per tile", &per_tile),
        ("per tile, settling leaves", &per_tile_settling),
        ("one ratio for the scene", &global),
    ];
    for (label, f) in rows {
        let stats = |leaves: &mut dyn Iterator<Item = usize>| {
            let (mut e2, mut r2, mut sum, mut want) = (0.0, 0.0, 0.0, 0.0);
            for i in leaves {
                for c in 0..3 {
                    let v = s3[i][c] + f(i, c);
                    e2 += (v - s16[i][c]).powi(2);
                    r2 += s16[i][c].powi(2);
                    sum += v;
                    want += s16[i][c];
                }
            }
            ((e2 / r2).sqrt(), sum / want - 1.0)
        };
        let (e, b) = stats(&mut (0..n));
        let per_region: Vec<String> =
            regions.iter().map(|(r, l)| format!("{r} {:+.3}", stats(&mut l.iter().copied()).1)).collect();
        println!("  {label:26} rel. RMSE {e:.4}, bias {b:+.4}  {}", per_region.join(", "));
    }
    Ok(())
}
