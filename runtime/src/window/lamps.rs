//! `grotto view`'s lighting mode (L): a designer places, moves, aims, dims, recolours and deletes
//! lamps and switches circuits, with undo (Z), and saves the result as a lighting file (V) that
//! `--lights` reads back to the same lights (grotto_format::lighting::to_toml). A click on the
//! cave places a new lamp a chosen distance off the surface toward the eye, or moves or aims the
//! selected one where the panel says so; the surface point comes from the G-buffer's distance,
//! read back without blocking (the guide's probe). Every edit relights the renderer in place
//! (stream::relit: the light converges again from what it was).

use std::path::{Path, PathBuf};

use glam::Vec3;
use grotto_format::lighting::{Lighting, to_toml};
use grotto_format::{Light, LightShape};
use winit::keyboard::KeyCode;

use crate::error::{Error, Result};
use crate::scene::data::{Relight, SceneData};
use crate::window::State;

/// An edit the panel asks for: what it does (for the panel's line) and the change.
pub(super) type PanelEdit = (String, Box<dyn FnOnce(&mut Relight)>);

/// What the next click on the cave does.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
enum Click {
    Add,
    Move,
    Aim,
}

pub(super) struct LampEditor {
    pub(super) on: bool,
    selected: Option<String>,
    undo: Vec<Relight>,
    click: Click,
    /// A new lamp's distance off the surface, metres, and its flux and colour temperature.
    offset_m: f32,
    lumens: f32,
    kelvin: f32,
    /// The package's own lights (what a saved file adds to, replaces or removes).
    package: Vec<Light>,
    save_to: PathBuf,
    /// Files written (for the session's summary).
    pub(super) saved: Vec<String>,
    /// What the last action did, and what the renderer redid for it, for the panel.
    said: String,
    redone: String,
    /// The IES file the panel's "profile" button gives the selected lamp.
    ies_path: String,
}

impl LampEditor {
    /// For a session started with `lights` (`--lights`; saved back to it, else to the next free
    /// `grotto-lights-N.toml`) on a package whose own lights are `package`.
    pub(super) fn new(lights: Option<PathBuf>, package: Vec<Light>) -> Self {
        Self {
            on: false,
            selected: None,
            undo: Vec::new(),
            click: Click::Add,
            offset_m: 0.5,
            lumens: 1000.0,
            kelvin: 3000.0,
            package,
            save_to: lights.unwrap_or_else(|| super::next_name("grotto-lights", "toml")),
            saved: Vec::new(),
            said: String::new(),
            redone: String::new(),
            ies_path: String::new(),
        }
    }

    /// The scene's lighting to edit: its own, or one made of the package's lights.
    fn lighting(&self, scene: &SceneData) -> Relight {
        scene.lighting.clone().unwrap_or_else(|| Relight::of_package(&self.package, &[]))
    }

    /// Applies `edit` to the scene's lighting, keeping the lighting before it for undo.
    fn edit(&mut self, scene: &mut SceneData, what: &str, edit: impl FnOnce(&mut Relight)) {
        let before = self.lighting(scene);
        let mut after = before.clone();
        edit(&mut after);
        self.undo.push(before);
        scene.relight(&after.lights, &after.circuits, &after.baked);
        self.said = what.to_string();
    }

    /// A surface point picked in lighting mode, seen from `eye_m` (frame metres).
    fn placed(&mut self, scene: &mut SceneData, point_m: Vec3, eye_m: Vec3) {
        let origin = glam::DVec3::from_array(scene.frame_origin_m);
        let world = |p: Vec3| (origin + p.as_dvec3()).to_array();
        let at = point_m + (eye_m - point_m).normalize_or_zero() * self.offset_m;
        let selected = self.selected.clone();
        match (self.click, selected) {
            (Click::Move, Some(name)) => self.edit(scene, &format!("moved {name}"), |r| {
                if let Some(l) = r.lights.iter_mut().find(|l| l.name == name) {
                    match &mut l.shape {
                        LightShape::Point { position_m } | LightShape::Spot { position_m, .. } => {
                            *position_m = world(at)
                        }
                        LightShape::Area { center_m, .. } => *center_m = world(at),
                    }
                }
            }),
            (Click::Aim, Some(name)) => self.edit(scene, &format!("aimed {name}"), |r| {
                if let Some(l) = r.lights.iter_mut().find(|l| l.name == name) {
                    let from = match l.shape {
                        LightShape::Point { position_m } | LightShape::Spot { position_m, .. } => position_m,
                        LightShape::Area { center_m, .. } => center_m,
                    };
                    let d = (origin + point_m.as_dvec3() - glam::DVec3::from_array(from)).normalize_or_zero();
                    let d = d.as_vec3().to_array();
                    if let LightShape::Spot { direction, .. } = &mut l.shape {
                        *direction = d;
                    }
                    if let Some(p) = &mut l.profile {
                        p.aim = d;
                    }
                }
            }),
            _ => {
                let lighting = self.lighting(scene);
                let name = (1..)
                    .map(|i| format!("lamp-{i}"))
                    .find(|n| !lighting.lights.iter().any(|l| &l.name == n));
                let name = name.unwrap_or_default();
                let color = grotto_format::photometry::kelvin_rgb(f64::from(self.kelvin)).unwrap_or([1.0; 3]);
                let power_w =
                    grotto_format::photometry::watts_of_lumens(f64::from(self.lumens), color).unwrap_or(0.0);
                let lamp = Light {
                    name: name.clone(),
                    shape: LightShape::Point { position_m: world(at) },
                    color: color.map(|c| c as f32),
                    power_w: power_w as f32,
                    circuit: None,
                    profile: None,
                };
                self.edit(scene, &format!("placed {name}"), |r| r.lights.push(lamp));
                self.selected = Some(name);
            }
        }
        self.click = Click::Add;
    }

    /// The lighting file of the session's lights: the package's kept as they are, the rest
    /// written (replace = false), the package's deleted ones removed.
    fn file(&self, scene: &SceneData) -> Lighting {
        let now = self.lighting(scene);
        let lights: Vec<Light> = now.lights.iter().filter(|l| !self.package.contains(l)).cloned().collect();
        let remove = (self.package.iter())
            .filter(|p| !now.lights.iter().any(|l| l.name == p.name))
            .map(|p| p.name.clone())
            .collect();
        Lighting { replace: false, remove, lights, circuits: now.circuits }
    }

    fn save(&mut self, scene: &SceneData) -> Result<()> {
        let text = to_toml(&self.file(scene));
        let path = self.save_to.clone();
        crate::cli::export::atomically(&path, |mut f| {
            std::io::Write::write_all(&mut f, text.as_bytes())
                .map_err(|e| crate::cli::export::output_error(&path, e))
        })?;
        self.said = format!("saved {}", path.display());
        self.saved.push(path.display().to_string());
        Ok(())
    }

    /// The panel: the selected lamp's power, colour, kind and cone, what the next click does,
    /// undo and save. Returns an edit to apply (what, and the change).
    pub(super) fn show(&mut self, ctx: &egui::Context, scene: &SceneData) -> Option<PanelEdit> {
        if !self.on {
            return None;
        }
        let mut out: Option<PanelEdit> = None;
        // Drawn every frame: the scene's lighting borrowed, a copy only where it has none.
        let owned;
        let lighting = match &scene.lighting {
            Some(l) => l,
            None => {
                owned = Relight::of_package(&self.package, &[]);
                &owned
            }
        };
        egui::Window::new("lighting").default_pos([8.0, 260.0]).default_width(240.0).show(ctx, |ui| {
            ui.label("click the cave: place a lamp (or move / aim the selected one)");
            ui.add(egui::Slider::new(&mut self.offset_m, 0.1..=3.0).text("off the surface, m"));
            ui.add(
                egui::Slider::new(&mut self.lumens, 10.0..=100_000.0).logarithmic(true).text("new lamp, lm"),
            );
            ui.add(egui::Slider::new(&mut self.kelvin, 1800.0..=6500.0).text("new lamp, K"));
            ui.separator();
            egui::ComboBox::from_label("lamp")
                .selected_text(self.selected.clone().unwrap_or_default())
                .show_ui(ui, |ui| {
                    for l in &lighting.lights {
                        ui.selectable_value(&mut self.selected, Some(l.name.clone()), &l.name);
                    }
                });
            if let Some(l) =
                self.selected.as_ref().and_then(|n| lighting.lights.iter().find(|l| &l.name == n))
            {
                let name = l.name.clone();
                let mut watts = l.power_w;
                if ui
                    .add(egui::Slider::new(&mut watts, 0.01..=500.0).logarithmic(true).text("watts"))
                    .drag_stopped()
                {
                    let n = name.clone();
                    out = Some((
                        format!("{name}: {watts:.2} W"),
                        Box::new(move |r| set(r, &n, |l| l.power_w = watts)),
                    ));
                }
                let mut kelvin = 3000.0f32;
                if ui.add(egui::Slider::new(&mut kelvin, 1800.0..=6500.0).text("recolour, K")).drag_stopped()
                {
                    let c = grotto_format::photometry::kelvin_rgb(f64::from(kelvin)).unwrap_or([1.0; 3]);
                    let n = name.clone();
                    out = Some((
                        format!("{name}: {kelvin:.0} K"),
                        Box::new(move |r| set(r, &n, |l| l.color = c.map(|v| v as f32))),
                    ));
                }
                ui.horizontal(|ui| {
                    if ui.button("move (click)").clicked() {
                        self.click = Click::Move;
                    }
                    if ui.button("aim (click)").clicked() {
                        self.click = Click::Aim;
                    }
                    if ui.button("spot").clicked() {
                        let n = name.clone();
                        out = Some((format!("{name}: a spot"), Box::new(move |r| set(r, &n, to_spot))));
                    }
                });
                ui.horizontal(|ui| {
                    ui.add(
                        egui::TextEdit::singleline(&mut self.ies_path)
                            .desired_width(120.0)
                            .hint_text("file.ies"),
                    );
                    if ui.button("IES profile").clicked() {
                        let mut lamp = l.clone();
                        match profiled(&mut lamp, Path::new(&self.ies_path)) {
                            Ok(()) => {
                                let n = name.clone();
                                out = Some((
                                    format!("{name}: profile {}", self.ies_path),
                                    Box::new(move |r| set(r, &n, |l| *l = lamp)),
                                ));
                            }
                            Err(e) => self.said = format!("{}: {e}", self.ies_path),
                        }
                    }
                });
                if ui.button("delete (Del)").clicked() {
                    let n = name.clone();
                    out = Some((
                        format!("deleted {name}"),
                        Box::new(move |r| r.lights.retain(|l| l.name != n)),
                    ));
                }
            }
            ui.separator();
            ui.label(format!(
                "next click: {:?}; Z undo ({}); V save to {}",
                self.click,
                self.undo.len(),
                self.save_to.display()
            ));
            ui.small(&self.said);
            ui.small(&self.redone);
        });
        out
    }
}

/// Applies `f` to the light named `name`.
fn set(r: &mut Relight, name: &str, f: impl FnOnce(&mut Light)) {
    if let Some(l) = r.lights.iter_mut().find(|l| l.name == name) {
        f(l);
    }
}

/// `l` shaped by the IES file at `path` (type C; a spot becomes a point lamp aimed along its axis,
/// since a profile shapes the beam itself). Saved as `ies = "path"`, which a lighting file reads
/// relative to its own folder.
fn profiled(l: &mut Light, path: &Path) -> std::result::Result<(), String> {
    let text = crate::engine::lighting_file::read_ies(path)?;
    let ies = grotto_format::ies::parse(&text).map_err(|e| format!("line {}: {}", e.line, e.problem))?;
    let (profile, _lumens) = ies.profile()?;
    let (position_m, aim) = match l.shape {
        LightShape::Point { position_m } => {
            (position_m, l.profile.as_ref().map_or([0.0, 0.0, -1.0], |p| p.aim))
        }
        LightShape::Spot { position_m, direction, .. } => (position_m, direction),
        _ => return Err("an IES profile shapes a point lamp".into()),
    };
    l.shape = LightShape::Point { position_m };
    l.profile =
        Some(grotto_format::LightProfile { aim, turn_deg: 0.0, profile, source: path.display().to_string() });
    Ok(())
}

/// A point lamp made a spot pointing down (30 degrees, soft), aimed by the next "aim" click.
fn to_spot(l: &mut Light) {
    if let LightShape::Point { position_m } = l.shape {
        l.shape = LightShape::Spot {
            position_m,
            direction: [0.0, 0.0, -1.0],
            inner_angle_rad: 15f32.to_radians(),
            outer_angle_rad: 30f32.to_radians(),
        };
        l.profile = None;
    }
}

/// After the frame's input and panel: picked points, the panel's edit or a circuit switched,
/// and the renderer relit if the lights changed.
pub(super) fn update(s: &mut State, panel_edit: Option<PanelEdit>) -> Result<()> {
    let mut changed = false;
    for (point, eye) in std::mem::take(&mut s.story.guide.placed) {
        s.lamps.placed(&mut s.scene, point, eye);
        changed = true;
    }
    if let Some((what, edit)) = panel_edit {
        s.lamps.edit(&mut s.scene, &what, edit);
        changed = true;
    }
    if let Some((name, on)) = s.story.switch.take() {
        changed |=
            s.scene.switch_circuit(&name, on).map_err(|e| Error::Setting { name: "circuit", problem: e })?;
    }
    if changed {
        relit(s)?;
    }
    Ok(())
}

/// The renderer takes the scene's new lights; the panel says how much the edit redoes.
fn relit(s: &mut State) -> Result<()> {
    let follow = &s.follow;
    let how = crate::stream::relit(&s.gpu, &mut s.renderer, &mut s.scene, |scene| match follow {
        Some(f) => f.reload_into(scene),
        None => Ok(()),
    })?;
    super::let_go_of_tiles(s);
    let redo = match how {
        crate::stream::Relit::InPlace(e) => format!(
            "in place: {} light(s) changed, {} shadow face(s), direct light in {} of {} tiles",
            e.scope.lights, e.scope.faces, e.scope.tiles, e.scope.of_tiles
        ),
        crate::stream::Relit::Anew { .. } => "every light relit (no room in place)".into(),
    };
    s.lamps.redone = redo;
    Ok(())
}

/// Lighting mode's keys; returns whether one was used.
pub(super) fn key(s: &mut State, code: KeyCode) -> Result<bool> {
    let e = &mut s.lamps;
    match code {
        KeyCode::KeyL => e.on = !e.on,
        KeyCode::KeyZ if e.on => {
            if let Some(before) = e.undo.pop() {
                s.scene.relight(&before.lights, &before.circuits, &before.baked);
                e.said = "undone".into();
                relit(s)?;
            }
        }
        KeyCode::Delete | KeyCode::Backspace if e.on => {
            if let Some(name) = e.selected.take() {
                e.edit(&mut s.scene, &format!("deleted {name}"), |r| r.lights.retain(|l| l.name != name));
                relit(s)?;
            }
        }
        KeyCode::KeyV if e.on => {
            // A lamp clicked before V is in the file, though its frame may still be drawing.
            super::story::answer_clicks(s)?;
            update(s, None)?;
            s.lamps.save(&s.scene)?
        }
        _ => return Ok(false),
    }
    Ok(true)
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn a_spot_takes_an_ies_profile_aimed_along_its_axis_and_a_bad_file_is_named() {
        let dir = Path::new(env!("CARGO_MANIFEST_DIR")).join("../docs/examples");
        let mut lamp = Light {
            name: "wash".into(),
            shape: LightShape::Spot {
                position_m: [1.0, 2.0, 3.0],
                direction: [0.0, 1.0, 0.0],
                inner_angle_rad: 0.2,
                outer_angle_rad: 0.4,
            },
            color: [1.0; 3],
            power_w: 5.0,
            circuit: None,
            profile: None,
        };
        profiled(&mut lamp, &dir.join("downlight.ies")).unwrap();
        assert_eq!(lamp.shape, LightShape::Point { position_m: [1.0, 2.0, 3.0] });
        let p = lamp.profile.as_ref().unwrap();
        assert_eq!(p.aim, [0.0, 1.0, 0.0]);
        assert!(p.source.ends_with("downlight.ies") && p.profile.relative.iter().all(|v| v.is_finite()));
        // Not an IES file: refused with what is wrong, the lamp as it was.
        let e = profiled(&mut lamp, &dir.join("show-lighting.toml")).unwrap_err();
        assert!(e.contains("TILT"), "{e}");
        assert!(profiled(&mut lamp, &dir.join("missing.ies")).is_err());
    }
}
