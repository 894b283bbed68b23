//! Lighting files and photometry, natively on lavapipe, against answers worked out by
//! hand: a lamp of known lumens over a floor gives the inverse-square illuminance in the lux view,
//! and an IES downlight's candela read back from the lit floor are the file's.

use glam::{IVec3, Vec2, Vec3};
use grotto_fixtures::testscenes::carved;
use grotto_runtime::gpu::Gpu;
use grotto_runtime::render::Renderer;
use grotto_runtime::render::probe::ray_through;
use grotto_runtime::scene::data::SceneData;
use grotto_runtime::settings::{IndirectFilter, Settings, ViewMode};
use grotto_runtime::view::camera::Camera;

const W: u32 = 160;
const H: u32 = 160;
/// The floor's top, metres (one 0.1 m leaf of rock; its surfels face up at its top).
const FLOOR_Z_M: f32 = 0.1;

/// A 4 x 4 m floor with nothing above it: no light comes back to it, so what it receives is
/// the lamp's alone.
fn floor() -> SceneData {
    let dims = IVec3::new(40, 40, 24);
    carved("floor", 0.1, 6, dims, &|c: IVec3| c.z >= 1, &|_| Vec3::splat(0.5), Vec3::ZERO, None)
}

/// The floor lit by the lighting file `text` (world = frame here: the floor's origin is 0).
fn lit_floor(text: &str, ies: &str) -> SceneData {
    let mut scene = floor();
    let file = grotto_format::lighting::parse(text, |_| Ok(ies.to_string())).unwrap();
    let relight = grotto_runtime::scene::lighting::merged((&[], &[]), &file).unwrap();
    relight.apply(&mut scene);
    scene
}

/// Lux per pixel and the floor point each pixel sees, from straight above.
fn lux_view(scene: &SceneData) -> Vec<(Vec3, f32)> {
    let gpu = Gpu::new(&grotto_tests::lavapipe()).unwrap();
    let settings = Settings {
        bounces: 0,
        indirect: IndirectFilter::Off,
        view: ViewMode::Lux,
        shadow_map_size: 1024,
        ..Settings::default()
    };
    let mut r = Renderer::new(&gpu, scene, settings).unwrap();
    r.settle(|_, _| {}).unwrap();
    let cam = Camera {
        eye_m: Vec3::new(2.0, 2.0, 3.9),
        look_at_m: Vec3::new(2.0, 2.0, 0.0),
        up: Vec3::Y,
        fov_y_deg: 60.0,
    };
    let (frame, _) = r.render(&cam, W, H).unwrap();
    (0..H)
        .flat_map(|y| (0..W).map(move |x| (x, y)))
        .map(|(x, y)| {
            let ray = ray_through(&cam, W, H, Vec2::new(x as f32 + 0.5, y as f32 + 0.5));
            let t = (FLOOR_Z_M - cam.eye_m.z) / ray.z;
            (cam.eye_m + ray * t, frame.hdr[(y * W + x) as usize][0])
        })
        .collect()
}

/// The pixels seeing floor points whose horizontal distance from `below` is within `r_m` of
/// `at_m`, away from the floor's edge.
fn ring(view: &[(Vec3, f32)], below: Vec3, at_m: f32, r_m: f32) -> Vec<(Vec3, f32)> {
    view.iter()
        .copied()
        .filter(|(p, _)| {
            let h = (p.truncate() - below.truncate()).length();
            (h - at_m).abs() < r_m && p.x > 0.3 && p.x < 3.7 && p.y > 0.3 && p.y < 3.7
        })
        .collect()
}

#[test]
fn a_lamp_of_known_lumens_gives_the_inverse_square_illuminance_in_the_lux_view() {
    let h = 1.5;
    let lamp = Vec3::new(2.0, 2.0, FLOOR_Z_M + h);
    let text = format!(
        "[[light]]\nname = \"lamp\"\nposition = [{}, {}, {}]\nlumens = 1000.0\nkelvin = 4000.0\n",
        lamp.x, lamp.y, lamp.z
    );
    let view = lux_view(&lit_floor(&text, ""));
    // E = I cos(theta) / d^2 with I = 1000 lm / 4 pi sr; cos(theta) = h / d.
    let intensity_cd = 1000.0 / (4.0 * std::f32::consts::PI);
    let mut worst = 0.0f32;
    for (r, expect_name) in [(0.0, "below"), (0.75, "0.75 m out"), (1.5, "1.5 m out")] {
        let pixels = ring(&view, lamp, r, 0.05);
        assert!(pixels.len() > 3, "{expect_name}: {} pixels", pixels.len());
        for (p, lux) in pixels {
            let d = (lamp - p).length();
            let want = intensity_cd * h / (d * d * d);
            let err = (lux - want).abs() / want;
            worst = worst.max(err);
            assert!(err < 0.01, "{expect_name} at {p}: {lux} lx, inverse square {want} lx ({err:.4})");
        }
    }
    eprintln!("worst relative error against the inverse-square law: {worst:.5}");
    // Below the lamp: 1000 / (4 pi 1.5^2) = 35.4 lx.
    let below = ring(&view, lamp, 0.0, 0.03);
    assert!((below[0].1 - 35.37).abs() < 0.36, "{} lx below the lamp", below[0].1);
}

/// A round-symmetric downlight: 400 cd down, 350 at 22.5 degrees, 200 at 45, 50 at 67.5, 0 at 90.
const DOWNLIGHT: &str = "IESNA:LM-63-2002\n[TEST] grotto\nTILT=NONE\n1 -1 1.0 5 1 1 2 0.1 0.1 0.05\n\
    1.0 1.0 12\n0 22.5 45 67.5 90\n0\n400 350 200 50 0\n";

#[test]
fn an_ies_profiles_candela_read_back_from_the_lit_floor_are_the_files() {
    let h = 1.2;
    let lamp = Vec3::new(2.0, 2.0, FLOOR_Z_M + h);
    let text = format!(
        "[[light]]\nname = \"down\"\nposition = [{}, {}, {}]\nies = \"down.ies\"\naim_at = [2.0, 2.0, 0.0]\n",
        lamp.x, lamp.y, lamp.z
    );
    let view = lux_view(&lit_floor(&text, DOWNLIGHT));
    for (theta_deg, candela) in [(0.0f32, 400.0f32), (22.5, 350.0), (45.0, 200.0)] {
        let theta = theta_deg.to_radians();
        let pixels = ring(&view, lamp, h * theta.tan(), 0.02);
        assert!(!pixels.is_empty(), "{theta_deg} degrees: no pixel");
        // Back from illuminance to intensity along each pixel's own direction: I = E d^2 / cos.
        let mut got = Vec::new();
        for (p, lux) in &pixels {
            let d = lamp - *p;
            let (dist, cos) = (d.length(), d.z / d.length());
            let at = cos.acos().to_degrees();
            // The table is linear between its angles: the file's candela at this pixel's angle.
            let want = interpolate(&[(0.0, 400.0), (22.5, 350.0), (45.0, 200.0), (67.5, 50.0)], at);
            got.push((lux * dist * dist / cos, want));
        }
        let (sum_got, sum_want): (f32, f32) = got.iter().fold((0.0, 0.0), |a, g| (a.0 + g.0, a.1 + g.1));
        let err = (sum_got - sum_want).abs() / sum_want;
        eprintln!(
            "{theta_deg} degrees: {:.1} cd read back, {:.1} cd in the file ({err:.4})",
            sum_got / got.len() as f32,
            sum_want / got.len() as f32
        );
        assert!(err < 0.02, "{theta_deg} degrees: {candela} cd in the file, {err:.4} off");
    }
}

fn interpolate(table: &[(f32, f32)], x: f32) -> f32 {
    let i = table.iter().rposition(|t| t.0 <= x).unwrap_or(0).min(table.len() - 2);
    let (a, b) = (table[i], table[i + 1]);
    a.1 + (b.1 - a.1) * (x - a.0) / (b.0 - a.0)
}

/// The colour box lit by a lighting file with two circuits: "lamp" (on) and "side" (off).
fn two_circuits(side_on: bool) -> SceneData {
    let mut scene = grotto_fixtures::testscenes::colour_box();
    let text = format!(
        "[[circuit]]\nname = \"main\"\n[[circuit]]\nname = \"side\"\non = {side_on}\n\
         [[light]]\nname = \"lamp\"\nposition = [1.3, 1.3, 2.2]\npower_w = 30.0\ncircuit = \"main\"\n\
         [[light]]\nname = \"side\"\nkind = \"spot\"\nposition = [0.4, 1.3, 1.2]\naim_at = [2.2, 1.3, 0.3]\n\
         outer_angle_deg = 25.0\nlumens = 4000.0\nkelvin = 2700.0\ncircuit = \"side\"\n"
    );
    let file = grotto_format::lighting::parse(&text, |_| Err("no IES".into())).unwrap();
    grotto_runtime::scene::lighting::merged((&[], &[]), &file).unwrap().apply(&mut scene);
    scene
}

#[test]
fn switching_a_circuit_converges_to_a_fresh_render_of_that_lighting() {
    use grotto_tests::golden;
    let gpu = Gpu::new(&grotto_tests::lavapipe()).unwrap();
    // Room for a lamp added in place, as the viewers keep.
    let settings = Settings { bounces: 64, exposure: 3.0, light_room_faces: 6, ..Settings::default() };
    let cam = {
        let c = &grotto_fixtures::testscenes::colour_box().cameras[0];
        Camera { eye_m: c.eye_m, look_at_m: c.look_at_m, up: c.up, fov_y_deg: c.fov_y_deg }
    };
    let pixels = |f: &grotto_runtime::render::Frame| f.ldr.clone();
    // The side circuit off, converged; then switched on in place.
    let mut scene = two_circuits(false);
    assert_eq!(scene.lights.len(), 1, "the side spot is off");
    let mut r = Renderer::new(&gpu, &scene, settings.clone()).unwrap();
    let cold_off = r.settle(|_, _| {}).unwrap();
    let before = pixels(&r.render(&cam, W, H).unwrap().0);
    assert!(scene.switch_circuit("side", true).unwrap());
    assert_eq!(scene.lights.len(), 2);
    let relit = grotto_runtime::stream::relit(&gpu, &mut r, &mut scene, |_| Ok(())).unwrap();
    let grotto_runtime::stream::Relit::InPlace(edit) = relit else { panic!("not in place: {relit:?}") };
    // The spot added: one light, its one face, and the tiles its light reaches.
    assert_eq!((edit.scope.lights, edit.scope.faces), (1, 1), "{edit:?}");
    assert!(edit.scope.tiles >= 1 && edit.scope.tiles <= edit.scope.of_tiles, "{edit:?}");
    let warm = r.settle(|_, _| {}).unwrap();
    let switched = pixels(&r.render(&cam, W, H).unwrap().0);
    // A fresh renderer of the lighting file with the circuit on from the start.
    let fresh_scene = two_circuits(true);
    let mut fresh = Renderer::new(&gpu, &fresh_scene, settings).unwrap();
    let cold = fresh.settle(|_, _| {}).unwrap();
    let want = pixels(&fresh.render(&cam, W, H).unwrap().0);
    let d = golden::diff(&switched, &want);
    eprintln!(
        "bounces: {cold_off} cold (off), {warm} after the switch from the carried light, {cold} cold (on); {d:?}"
    );
    assert!(golden::within_tolerance(&d), "switched against fresh: {d:?}");
    // The switch changed the picture (the spot lights the floor), and switching back restores it.
    assert!(!golden::within_tolerance(&golden::diff(&before, &want)), "the side spot shows");
    assert!(scene.switch_circuit("side", false).unwrap());
    grotto_runtime::stream::relit(&gpu, &mut r, &mut scene, |_| Ok(())).unwrap();
    r.settle(|_, _| {}).unwrap();
    let back = pixels(&r.render(&cam, W, H).unwrap().0);
    assert!(golden::within_tolerance(&golden::diff(&back, &before)), "switched off again");
    assert!(scene.switch_circuit("nope", true).unwrap_err().contains("main, side"));
}

#[test]
fn circuits_switch_from_the_command_line_and_unknown_ones_are_named() {
    use grotto_runtime::engine::lighting_file::{parse_switch, with_circuits};
    assert_eq!(parse_switch("work=on"), Ok(("work".into(), true)));
    assert_eq!(parse_switch("a=b=off"), Ok(("a=b".into(), false)));
    assert!(parse_switch("work").unwrap_err().contains("NAME=on"));
    let file = "[[circuit]]\nname = \"show\"\n[[circuit]]\nname = \"work\"\non = false\n\
                [[light]]\nname = \"a\"\nposition = [0.0, 0.0, 1.0]\npower_w = 1.0\ncircuit = \"show\"\n\
                [[light]]\nname = \"b\"\nposition = [0.0, 0.0, 1.0]\npower_w = 1.0\ncircuit = \"work\"\n";
    let lighting = grotto_format::lighting::parse(file, |_| Err(String::new())).unwrap();
    let package = grotto_format::Scene::default();
    let r = grotto_runtime::scene::lighting::merged((&[], &[]), &lighting).unwrap();
    let switched = with_circuits(&package, Some(r.clone()), &[("work".into(), true), ("show".into(), false)])
        .unwrap()
        .unwrap();
    let mut scene = floor();
    switched.apply(&mut scene);
    assert_eq!(scene.lights.iter().map(|l| l.name.as_str()).collect::<Vec<_>>(), ["b"]);
    let e = with_circuits(&package, Some(r), &[("stage".into(), true)]).unwrap_err().to_string();
    assert!(e.contains("\"stage\"") && e.contains("show, work"), "{e}");
    let e = with_circuits(&package, None, &[("show".into(), true)]).unwrap_err().to_string();
    assert!(e.contains("no circuits"), "{e}");
}

#[test]
fn each_kind_of_edit_converges_to_a_fresh_render_of_the_saved_lighting_file() {
    use grotto_format::LightShape;
    use grotto_format::lighting::{Lighting, parse, to_toml};
    use grotto_tests::golden;
    let gpu = Gpu::new(&grotto_tests::lavapipe()).unwrap();
    // Room for a lamp added in place, as the viewers keep.
    let settings = Settings { bounces: 64, exposure: 3.0, light_room_faces: 6, ..Settings::default() };
    let c = &grotto_fixtures::testscenes::colour_box().cameras[0];
    let cam = Camera { eye_m: c.eye_m, look_at_m: c.look_at_m, up: c.up, fov_y_deg: c.fov_y_deg };
    // A designer's session: the colour box as two_circuits(true) lights it, edited in place.
    let mut scene = two_circuits(true);
    let mut lighting = scene.lighting.clone().unwrap();
    let mut r = Renderer::new(&gpu, &scene, settings.clone()).unwrap();
    r.settle(|_, _| {}).unwrap();
    type Edit = Box<dyn Fn(&mut grotto_runtime::scene::lighting::Relight)>;
    let find = |r: &mut grotto_runtime::scene::lighting::Relight, n: &str| {
        r.lights.iter().position(|l| l.name == n).unwrap()
    };
    let edits: Vec<(&str, Edit)> = vec![
        (
            "move",
            Box::new(move |r| {
                let i = find(r, "lamp");
                r.lights[i].shape = LightShape::Point { position_m: [0.8, 1.6, 1.9] };
            }),
        ),
        (
            "dim",
            Box::new(move |r| {
                let i = find(r, "lamp");
                r.lights[i].power_w *= 0.3;
            }),
        ),
        (
            "recolour",
            Box::new(move |r| {
                let i = find(r, "lamp");
                r.lights[i].color = grotto_format::photometry::kelvin_rgb(2200.0).unwrap().map(|c| c as f32);
            }),
        ),
        (
            "add",
            Box::new(|r| {
                let mut extra = r.lights[0].clone();
                extra.name = "extra".into();
                extra.shape = LightShape::Point { position_m: [2.0, 0.6, 1.0] };
                extra.power_w = 12.0;
                r.lights.push(extra);
            }),
        ),
        (
            "delete",
            Box::new(move |r| {
                let i = find(r, "side");
                r.lights.remove(i);
                r.circuits.retain(|c| c.name != "side");
            }),
        ),
        ("circuit", Box::new(|r| r.circuits[0].on = false)),
    ];
    for (what, edit) in edits {
        edit(&mut lighting);
        scene.relight(&lighting.lights, &lighting.circuits, &lighting.baked);
        let how = grotto_runtime::stream::relit(&gpu, &mut r, &mut scene, |_| Ok(())).unwrap();
        // In place while some light is left (with none, a new renderer clears the direct light).
        let in_place = matches!(how, grotto_runtime::stream::Relit::InPlace(_));
        assert_eq!(in_place, !scene.lights.is_empty(), "{what}: {how:?}");
        let bounces = r.settle(|_, _| {}).unwrap();
        let got = r.render(&cam, W, H).unwrap().0.ldr;
        // Saved, read back, and rendered from scratch.
        let saved = Lighting {
            replace: true,
            remove: Vec::new(),
            lights: lighting.lights.clone(),
            circuits: lighting.circuits.clone(),
        };
        let text = to_toml(&saved);
        let file = parse(&text, |_| Err("no IES".into())).unwrap();
        let mut fresh_scene = grotto_fixtures::testscenes::colour_box();
        grotto_runtime::scene::lighting::merged((&[], &[]), &file).unwrap().apply(&mut fresh_scene);
        assert_eq!(fresh_scene.lights, scene.lights, "{what}: the saved file gives the same lights");
        let mut fresh = Renderer::new(&gpu, &fresh_scene, settings.clone()).unwrap();
        let cold = fresh.settle(|_, _| {}).unwrap();
        let want = fresh.render(&cam, W, H).unwrap().0.ldr;
        let d = golden::diff(&got, &want);
        eprintln!("{what}: {how:?}; {bounces} bounces after the edit, {cold} from darkness; {d:?}");
        assert!(golden::within_tolerance(&d), "{what}: edited in place against a fresh render: {d:?}");
    }
}

/// A lamp moved in the small cave cut into 4 m tiles: edited in place, its bounces update the
/// tiles whose direct light it changed and their neighbours, fewer leaves than relighting every
/// light does, and the light converges to a fresh render's.
#[test]
fn a_lamp_edit_costs_less_than_a_full_relight_and_ends_at_the_same_light() {
    use grotto_runtime::stream::{Relit, relit};
    use grotto_tests::golden;
    let dir = tempfile::tempdir().unwrap();
    let cave = grotto_fixtures::SmallCave { max_tile_extent_m: 4.0, ..Default::default() };
    let package = grotto_fixtures::small_cave_package(dir.path(), &cave).unwrap();
    let pkg = grotto_format::Package::open(&package).unwrap();
    let mut scene = SceneData::from_package(&pkg).unwrap();
    let gpu = Gpu::new(&grotto_tests::lavapipe()).unwrap();
    let settings = Settings { bounces: 32, shadow_map_size: 128, exposure: 8.0, ..Settings::default() };
    let c = &scene.cameras[0];
    let cam = Camera { eye_m: c.eye_m, look_at_m: c.look_at_m, up: c.up, fov_y_deg: c.fov_y_deg };
    let mut r = Renderer::new(&gpu, &scene, settings.clone()).unwrap();
    r.settle(|_, _| {}).unwrap();
    r.take_bounce_work();
    // The entrance passage's lamp, 30 cm further along.
    let world = pkg.scene().unwrap();
    let mut lights = world.lights.clone();
    let lamp = lights.iter_mut().find(|l| l.name == "lamp-0").expect("the synthetic cave's first lamp");
    let grotto_format::LightShape::Point { position_m } = &mut lamp.shape else { panic!("a point lamp") };
    position_m[0] += 0.3;
    let before = std::mem::take(&mut scene.lights);
    scene.relight(&lights, &world.circuits, &[]);
    let after = scene.lights.clone();
    let Relit::InPlace(edit) = relit(&gpu, &mut r, &mut scene, |_| Ok(())).unwrap() else {
        panic!("not in place")
    };
    assert_eq!((edit.scope.lights, edit.scope.faces), (2, 6), "{edit:?}");
    r.settle(|_, _| {}).unwrap();
    let edited = r.take_bounce_work();
    let got = r.render(&cam, W, H).unwrap().0.ldr;
    // The lamp back, then the same edit as every edit was before: every light's shadow faces,
    // every leaf injected, every tile bouncing, from the same start.
    scene.lights = before;
    relit(&gpu, &mut r, &mut scene, |_| Ok(())).unwrap();
    r.settle(|_, _| {}).unwrap();
    scene.lights = after;
    relit(&gpu, &mut r, &mut scene, |_| Ok(())).unwrap();
    r.invalidate_lights();
    r.take_bounce_work();
    r.settle(|_, _| {}).unwrap();
    let full = r.take_bounce_work();
    let leaves = |w: &[grotto_runtime::light::activity::BounceWork]| w.iter().map(|b| b.leaves).sum::<u64>();
    let tiles = scene.tiles.len();
    eprintln!(
        "{tiles} tiles; edit in place: {:?} tiles a bounce, {} leaves; relighting every light: {:?}, {} leaves",
        edited.iter().map(|b| b.tiles).collect::<Vec<_>>(),
        leaves(&edited),
        full.iter().map(|b| b.tiles).collect::<Vec<_>>(),
        leaves(&full)
    );
    assert!(edited[0].tiles < tiles, "the first bounce after the edit updates only where it changed");
    assert!(leaves(&edited) < leaves(&full), "the edit propagates fewer leaves than a full relight");
    let mut fresh = Renderer::new(&gpu, &scene, settings).unwrap();
    fresh.settle(|_, _| {}).unwrap();
    let want = fresh.render(&cam, W, H).unwrap().0.ldr;
    let d = golden::diff(&got, &want);
    assert!(golden::within_tolerance(&d), "edited in place against a fresh render: {d:?}");
}
