//! The frame and the plan: bounces in slices, skipped passes that change nothing, exposure after
//! the fact, static lights run once, validation errors named by pass, views without light.

use super::*;

#[test]
fn a_bounce_in_slices_ends_where_the_whole_bounce_ends_to_the_bit() {
    // The viewer splits a bounce over frames (Renderer::update_light_slice); every leaf gathers
    // from the pyramid the bounce's mip made, so the slices give the same light as one dispatch.
    let scene = testscenes::dogleg();
    let settings = Settings { bounces: 3, cones: 9, convergence_tolerance: 0.0, ..Default::default() };
    let mut whole = Renderer::new(gpu(), &scene, settings.clone()).unwrap();
    whole.settle(|_, _| {}).unwrap();
    let mut sliced = Renderer::new(gpu(), &scene, settings).unwrap();
    let leaves = scene.leaves.len() as u32;
    let slice = leaves / 5 + 7;
    let mut calls = 0;
    while !sliced.light_progress().converged {
        let before = sliced.stats().bounces_done;
        let ran = sliced.update_light_slice(slice).unwrap();
        assert!(ran <= slice, "a slice runs at most its leaves");
        calls += 1;
        // Mid-bounce the plan keeps the pyramid and says where the bounce stands.
        if sliced.stats().bounces_done == before && !sliced.light_progress().converged {
            let p = sliced.plan(None);
            assert!(!p.runs(Pass::Mip) && p.explain().contains("continued"), "{}", p.explain());
        }
        assert!(calls < 100, "the sliced bounces end");
    }
    assert_eq!(sliced.stats().bounces_done, 3);
    assert!(calls >= 3 * 5, "each bounce took several slices ({calls} calls)");
    let (a, b) = (whole.read_leaf_light().unwrap(), sliced.read_leaf_light().unwrap());
    let first_diff = a.iter().zip(&b).position(|(p, q)| p.out != q.out);
    assert_eq!(first_diff, None, "leaf light differs");
    assert_eq!(whole.stats().last_change, sliced.stats().last_change);
    // A held renderer runs no bounce, and says why.
    let mut held = Renderer::new(gpu(), &scene, Settings { bounces: 3, ..Default::default() }).unwrap();
    held.hold_light(Some("the camera is moving"));
    let p = held.update_light().unwrap();
    assert!(p.runs(Pass::Inject) && !p.runs(Pass::Propagate), "{}", p.explain());
    assert!(p.explain().contains("the camera is moving: bounce 1 waits"));
    assert_eq!(held.stats().bounces_done, 0);
}

fn max_abs_diff(a: &[[f32; 4]], b: &[[f32; 4]]) -> f32 {
    a.iter().zip(b).flat_map(|(p, q)| (0..3).map(move |k| (p[k] - q[k]).abs())).fold(0.0, f32::max)
}

#[test]
fn skipped_passes_are_not_dispatched_and_change_nothing() {
    use grotto_runtime::view::camera::Camera;
    // Emission only: no point or spot lights, so no shadow maps and no injection.
    let scene = testscenes::furnace_sphere(4, 5.0, 0.5, 1.0);
    let cam =
        Camera { eye_m: Vec3::splat(0.8), look_at_m: Vec3::new(1.2, 0.9, 0.7), up: Vec3::Z, fov_y_deg: 70.0 };
    let settings = Settings { bounces: 64, exposure: 0.1, ..Default::default() };
    let mut r = Renderer::new(gpu(), &scene, settings.clone()).unwrap();
    let explained = r.plan(Some((&cam, 64, 48))).explain();
    assert!(explained.contains("skip  shadow") && explained.contains("skip  inject"), "{explained}");
    r.settle(|_, _| {}).unwrap();
    let bounces = r.stats().bounces_done;
    assert!(bounces < 64, "propagation must stop once converged, ran {bounces}");
    let (a, plan) = r.render(&cam, 64, 48).unwrap();
    assert!(!plan.runs(Pass::Propagate) && !plan.runs(Pass::Mip), "{}", plan.explain());
    // The same frame again: the G-buffer is kept too.
    let (b, plan) = r.render(&cam, 64, 48).unwrap();
    assert!(!plan.runs(Pass::Gbuffer));
    assert_eq!(a.hdr, b.hdr);
    // A new exposure (auto exposure sets it after settling) changes the tonemapped frame only.
    r.set_exposure(0.4);
    let (brighter, _) = r.render(&cam, 64, 48).unwrap();
    r.set_exposure(settings.exposure);
    assert_eq!(brighter.hdr, a.hdr);
    let mean = |f: &grotto_runtime::render::Frame| {
        f.ldr.iter().map(|p| f64::from(p[0])).sum::<f64>() / f.ldr.len() as f64
    };
    assert!(
        mean(&brighter) > mean(&a) + 10.0,
        "exposure 0.4 against 0.1: {} vs {}",
        mean(&brighter),
        mean(&a)
    );
    let d = &r.stats().dispatches;
    assert_eq!(d.get(&Pass::Shadow), None);
    assert_eq!(d.get(&Pass::Inject), None);
    assert_eq!(d.get(&Pass::Mip).copied(), Some(u64::from(bounces)));
    assert_eq!(d.get(&Pass::Propagate).copied(), Some(u64::from(bounces)));
    assert_eq!(d.get(&Pass::Gbuffer).copied(), Some(1));
    assert_eq!(d.get(&Pass::Shade).copied(), Some(3));

    // Forcing the skipped passes: shadow, inject, gbuffer and one more bounce.
    r.set_forced(&[Pass::Shadow, Pass::Inject, Pass::Gbuffer, Pass::Mip, Pass::Env, Pass::Propagate]);
    let (c, plan) = r.render(&cam, 64, 48).unwrap();
    // All but the resolve, which only a still frame's samples have to add (draw_still).
    assert!(plan.steps.iter().filter(|s| s.pass != Pass::Resolve).all(|s| s.run), "{}", plan.explain());
    let d = &r.stats().dispatches;
    assert_eq!(d.get(&Pass::Shadow).copied(), Some(1));
    assert_eq!(d.get(&Pass::Inject).copied(), Some(1));
    // Shadow and inject with no lights change nothing; the extra bounce changes the converged
    // radiance by less than the convergence tolerance.
    let scale = a.hdr.iter().map(|p| p[0]).fold(0.0, f32::max);
    let diff = max_abs_diff(&a.hdr, &c.hdr);
    eprintln!("forced passes changed the image by {diff:.2e} (peak {scale:.3})");
    assert!(diff <= settings.convergence_tolerance * scale);
}

#[test]
fn a_frame_exposed_again_is_the_frame_drawn_at_that_exposure() {
    use grotto_runtime::settings::ViewMode;
    use grotto_runtime::view::camera::Camera;
    let scene = testscenes::furnace_sphere(4, 5.0, 0.5, 1.0);
    let cam =
        Camera { eye_m: Vec3::splat(0.8), look_at_m: Vec3::new(1.2, 0.9, 0.7), up: Vec3::Z, fov_y_deg: 70.0 };
    let mut r = Renderer::new(gpu(), &scene, Settings { exposure: 0.1, ..Default::default() }).unwrap();
    r.settle(|_, _| {}).unwrap();
    let (dim, _) = r.render(&cam, 64, 48).unwrap();
    let shades = r.stats().dispatches.get(&Pass::Shade).copied();
    r.set_exposure(0.4);
    let exposed = r.expose().unwrap();
    assert_eq!(r.stats().dispatches.get(&Pass::Shade).copied(), shades, "exposing must not shade again");
    let (drawn, _) = r.render(&cam, 64, 48).unwrap();
    assert_eq!(exposed.hdr, drawn.hdr);
    assert_eq!(exposed.ldr, drawn.ldr, "the tone map again must give the pixels a frame drawn at 0.4 has");
    assert_ne!(exposed.ldr, dim.ldr);
    // A view without light does not take the exposure: exposing it leaves its pixels, also once
    // the lit view is chosen again but not yet drawn (the frame is still the normals').
    r.set_view(ViewMode::Normals);
    let (normals, _) = r.render(&cam, 64, 48).unwrap();
    r.set_exposure(1.6);
    assert_eq!(r.expose().unwrap().ldr, normals.ldr);
    r.set_view(ViewMode::Lit);
    assert_eq!(r.expose().unwrap().ldr, normals.ldr);
}

#[test]
fn lights_and_shadows_run_once_for_static_lights() {
    let scene = testscenes::dogleg();
    let mut r = Renderer::new(gpu(), &scene, Settings { bounces: 2, ..Default::default() }).unwrap();
    let cam = grotto_runtime::view::camera::Camera::from_scene(&scene.cameras[0]);
    let (first, plan) = r.render(&cam, 64, 48).unwrap();
    assert!(plan.runs(Pass::Shadow) && plan.runs(Pass::Inject));
    let (_, plan) = r.render(&cam, 64, 48).unwrap();
    assert!(!plan.runs(Pass::Shadow) && !plan.runs(Pass::Inject) && plan.runs(Pass::Propagate));
    let (third, plan) = r.render(&cam, 64, 48).unwrap();
    assert!(!plan.runs(Pass::Propagate), "bounce budget of 2 spent: {}", plan.explain());
    assert_eq!(r.stats().dispatches.get(&Pass::Shadow).copied(), Some(1));
    // Shadowed direct light: room A is lit, the hidden chamber is not; bounces add light.
    let sum = |f: &grotto_runtime::render::Frame| f.hdr.iter().map(|p| p[1] as f64).sum::<f64>();
    assert!(sum(&third) > sum(&first));
    r.invalidate_lights();
    let (_, plan) = r.render(&cam, 64, 48).unwrap();
    assert!(plan.runs(Pass::Shadow) && plan.runs(Pass::Inject));
}

#[test]
fn a_validation_error_names_the_pass_whose_scope_caught_it() {
    let g = gpu();
    // MAP_READ goes only with COPY_DST: wgpu reports this buffer as a validation error, which the
    // scope turns into an error naming the pass.
    let err = g
        .scoped("probe", || {
            Ok(g.device.create_buffer(&wgpu::BufferDescriptor {
                label: Some("invalid"),
                size: 16,
                usage: wgpu::BufferUsages::MAP_READ | wgpu::BufferUsages::STORAGE,
                mapped_at_creation: false,
            }))
        })
        .unwrap_err();
    assert!(matches!(err, grotto_runtime::Error::Gpu { pass: "probe", .. }), "{err}");
    // Nothing leaks to the device-wide check, and a clean scope passes.
    g.check("after").unwrap();
    assert!(g.scoped("clean", || Ok(())).is_ok());
}

#[test]
fn views_without_light_skip_the_light_passes_and_show_albedo_normals_and_level() {
    use grotto_runtime::render::Frame;
    use grotto_runtime::settings::ViewMode;
    use grotto_runtime::view::camera::Camera;
    let scene = testscenes::dogleg();
    let cam = Camera::from_scene(&scene.cameras[0]);
    let render = |view| {
        let settings = Settings { bounces: 2, exposure: 4.0, view, ..Default::default() };
        let mut r = Renderer::new(gpu(), &scene, settings).unwrap();
        r.settle(|_, _| {}).unwrap();
        let (f, plan) = r.render(&cam, 64, 48).unwrap();
        (f, plan, r.stats().dispatches.clone())
    };
    let covered = |f: &Frame| -> Vec<[u8; 4]> {
        f.hdr.iter().zip(&f.ldr).filter(|(h, _)| h[3] >= 0.5).map(|(_, l)| *l).collect()
    };
    for view in [ViewMode::Albedo, ViewMode::Normals, ViewMode::Level] {
        let (f, plan, d) = render(view);
        for pass in [Pass::Shadow, Pass::Inject, Pass::Mip, Pass::Propagate] {
            assert!(!plan.runs(pass) && !d.contains_key(&pass), "{view:?}: {}", plan.explain());
        }
        let px = covered(&f);
        assert!(px.len() > 64 * 48 / 4, "{view:?}: {} pixels covered", px.len());
        match view {
            // Every pixel shows a surfel's own colour (sRGB, through the 8-bit G-buffer).
            ViewMode::Albedo => {
                let mut colors: Vec<[u8; 4]> = scene.surfels.iter().map(|s| s.color).collect();
                colors.sort();
                colors.dedup();
                let near = |p: &[u8; 4]| {
                    colors.iter().any(|c| (0..3).all(|k| (i32::from(p[k]) - i32::from(c[k])).abs() <= 3))
                };
                assert!(px.iter().all(near), "albedo view shows colours no surfel has");
            }
            // 0.5 + 0.5 n: unit normals.
            ViewMode::Normals => {
                let n =
                    |p: &[u8; 4]| Vec3::from_array([0, 1, 2].map(|k| f32::from(p[k]) / 255.0 * 2.0 - 1.0));
                assert!(
                    px.iter().all(|p| (n(p).length() - 1.0).abs() < 0.05),
                    "normals view: not unit normals"
                );
                let first = n(&px[0]);
                assert!(px.iter().any(|p| n(p).dot(first) < 0.5), "normals view: walls of every direction");
            }
            // Every tile is held in full: green, shaded.
            ViewMode::Level => {
                assert!(px.iter().all(|p| p[1] > p[0] && p[1] > p[2]), "level view: full tiles are green");
            }
            _ => unreachable!(),
        }
    }
    // The light view: the same light on white walls, so at least as bright as the lit view.
    let (lit, _, _) = render(ViewMode::Lit);
    let (light, plan, _) = render(ViewMode::Light);
    let sum = |f: &Frame| f.hdr.iter().map(|p| f64::from(p[0] + p[1] + p[2])).sum::<f64>();
    assert!(plan.steps.iter().all(|s| s.pass != Pass::Propagate || !s.reason.contains("view")));
    assert!(sum(&light) > sum(&lit), "light view {} against lit {}", sum(&light), sum(&lit));
}
