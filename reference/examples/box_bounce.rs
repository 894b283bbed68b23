//! What one bounce carries to each face of the colour box: per face, what the runtime's
//! first bounce adds to the leaves' light (bounces 1 minus bounces 0, no tail) over what the
//! reference's does (cut after 1 minus cut after 0; 256 paths per surfel), 1 where the bounce is
//! carried exactly. Leaves on their surfels, as packages have them. Variants of the light: `base`
//! (the lamp under the ceiling), `centre` (the lamp in the middle of the box), `emit-ceiling` (no
//! lamp, the whole ceiling glowing), `emit-patch` (no lamp, the ceiling glowing within 0.3 m of its
//! middle); each further argument a variant of the balanced preset's march: `cones=N`,
//! `aperture=X`, `step=X`, `planes` (cone planes), `nointerleave`.
//!
//! `cargo run --release -p grotto-reference --example box_bounce -- emit-ceiling cones=16 step=0.25`
use glam::Vec3;
use grotto_fixtures::testscenes;
use grotto_reference::PathSettings;
use grotto_reference::SurfelScene;
use grotto_reference::accuracy::breakdown::{luminance as lum, settled};
use grotto_runtime::gpu::{Gpu, GpuOptions};
use grotto_runtime::settings::{Quality, Settings};

fn main() -> anyhow::Result<()> {
    let gpu = Gpu::new(&GpuOptions::default())?;
    let args: Vec<String> = std::env::args().skip(1).collect();
    let variant = args.first().map_or("base", String::as_str);
    let mut data = testscenes::colour_box();
    match variant {
        "base" => {}
        "centre" => data.lights[0].position_m = Vec3::splat(1.3),
        "emit-ceiling" | "emit-patch" => {
            data.lights.clear();
            let leaf = data.leaf_size_m;
            for l in &mut data.leaves {
                let c = l.cell(leaf);
                let near = (Vec3::new(c.x as f32 + 0.5, c.y as f32 + 0.5, 0.0) - Vec3::new(13.0, 13.0, 0.0))
                    .length()
                    < 3.0;
                if c.z == 25 && (variant == "emit-ceiling" || near) {
                    l.emission = [1.0, 1.0, 1.0, 0.0];
                }
            }
        }
        other => anyhow::bail!("variant {other}"),
    }
    testscenes::leaves_on_surfels(&mut data);
    let base = Settings::preset(Quality::Balanced);
    let scene = SurfelScene::from_scene(&data, base.splat_scale);
    let full = PathSettings::for_scene(&data);
    let paths = 256;
    let r0 = scene.leaf_radiance(&data, paths, &PathSettings { max_bounces: 0, ..full }, 2);
    let r1 = scene.leaf_radiance(&data, paths, &PathSettings { max_bounces: 1, ..full }, 3);
    let mut configs: Vec<(String, Settings)> = vec![("balanced".into(), base.clone())];
    for extra in args.iter().skip(1) {
        let (k, v) = extra.split_once('=').unwrap_or((extra, ""));
        let mut s = base.clone();
        match k {
            "cones" => s.cones = v.parse()?,
            "aperture" => s.cone_aperture_scale = v.parse()?,
            "step" => s.step_scale = v.parse()?,
            "planes" => s.cone_planes = true,
            "nointerleave" => s.cone_interleave = false,
            _ => anyhow::bail!("knob {k}"),
        }
        configs.push((extra.clone(), s));
    }
    print!("| {variant} |");
    for f in testscenes::COLOUR_BOX_FACES {
        print!(" {f} |");
    }
    println!();
    for (name, s) in configs {
        let run = |b: u32| -> anyhow::Result<Vec<f64>> {
            let st = Settings { bounces: b, bounce_tail: false, ..s.clone() };
            let light = settled(&gpu, &data, st)?.read_leaf_light()?;
            Ok(light.iter().zip(&data.leaves).map(|(l, leaf)| lum(l.shown(leaf))).collect())
        };
        let (t0, t1) = (run(0)?, run(1)?);
        let mut rt = [0.0f64; 6];
        let mut rf = [0.0f64; 6];
        for (i, leaf) in data.leaves.iter().enumerate() {
            let (Some(a), Some(b)) = (&r0[i], &r1[i]) else { continue };
            let Some(f) = testscenes::colour_box_face(leaf.cell(data.leaf_size_m)) else { continue };
            rt[f] += t1[i] - t0[i];
            rf[f] += lum(b.mean.to_array()) - lum(a.mean.to_array());
        }
        print!("| {name} |");
        for f in 0..6 {
            print!(" {:.3} |", rt[f] / rf[f]);
        }
        println!();
    }
    Ok(())
}
