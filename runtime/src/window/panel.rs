//! The viewer's panel (egui): the knobs a person changes while looking (quality preset,
//! bounces, exposure, shadows, view), and what the runtime is doing (the effect plan as it
//! reports it, fps and per-pass times, the light's convergence, resident tiles and bytes against
//! the budget, the adapter). It reads a [`PanelModel`] and edits [`PanelKnobs`]; the window
//! applies what changed, so the panel never touches the renderer.

use glam::Vec3;

use crate::render::LightProgress;

use crate::settings::{ClipBox, Quality, ViewMode};
use crate::view::frame_target::Traded;

/// What the panel shows, gathered by the window each frame.
#[derive(Clone, Debug, Default)]
pub(crate) struct PanelModel {
    pub(crate) adapter: String,
    pub(crate) fps: f64,
    pub(crate) frame_ms: f64,
    /// What the frame-time target trades while moving (None: no target).
    pub(crate) traded: Option<Traded>,
    pub(crate) light: Option<LightProgress>,
    /// The bounces wait for the camera to rest.
    pub(crate) held: bool,
    pub(crate) plan: String,
    pub(crate) pass_ms: Vec<(&'static str, f64)>,
    /// Tiles held in full, coarse and far (None: the whole package is resident).
    pub(crate) tiles: Option<(usize, usize, usize)>,
    pub(crate) tile_count: usize,
    pub(crate) tile_bytes: u64,
    /// GPU bytes of the tile pools (what `--gpu-memory` bounds), and of the renderer in all.
    pub(crate) pool_bytes: u64,
    pub(crate) gpu_bytes: u64,
    pub(crate) surfels: usize,
    /// Keyframes recorded so far, while recording.
    pub(crate) recording: Option<usize>,
    pub(crate) orbit: bool,
    pub(crate) speed_m_s: f32,
    /// The scene's box (frame metres): the clip box's range.
    pub(crate) bounds_m: (Vec3, Vec3),
    pub(crate) eye_m: Vec3,
    /// The scan view's legend: each scan's name and colour (linear RGB).
    pub(crate) scans: Vec<(String, [f32; 3])>,
}

/// The clip box the section tool starts with: the whole scene with everything above the eye cut
/// away (a passage seen from above once the camera rises).
pub(crate) fn section_at_eye(bounds_m: (Vec3, Vec3), eye_m: Vec3) -> ClipBox {
    let (lo, hi) = bounds_m;
    ClipBox { min_m: lo, max_m: Vec3::new(hi.x, hi.y, eye_m.z.clamp(lo.z, hi.z)) }
}

/// What the panel can change.
#[derive(Clone, Copy, Debug, PartialEq)]
pub(crate) struct PanelKnobs {
    /// None: the settings came from the command line's knobs, not a preset as it is.
    pub(crate) quality: Option<Quality>,
    pub(crate) bounces: u32,
    pub(crate) exposure: f32,
    pub(crate) shadows: bool,
    pub(crate) view: ViewMode,
    /// The section tool's box (None: the whole cave shows).
    pub(crate) clip: Option<ClipBox>,
}

fn bytes(b: u64) -> String {
    crate::gpu::human_bytes(b)
}

/// Draws the panel.
pub(crate) fn show(ctx: &egui::Context, m: &PanelModel, k: &mut PanelKnobs) {
    egui::Window::new("grotto").default_pos([8.0, 8.0]).default_width(260.0).resizable(true).show(
        ctx,
        |ui| {
            ui.label(format!("{:.1} fps ({:.1} ms a frame)", m.fps, m.frame_ms));
            if let Some(t) = m.traded {
                ui.label(format!(
                    "target {:.1} ms moving{}: scale {:.2}, detail {:.1}x",
                    t.target_ms,
                    t.draw_ms.map(|d| format!(" (last draw {d:.1} ms)")).unwrap_or_default(),
                    t.scale,
                    t.detail
                ));
            }
            let light = match m.light {
                Some(l) if l.converged => format!("light converged ({} bounces)", l.bounces_done),
                Some(l) if l.shadow_faces_left > 0 => {
                    format!("shadow maps catching up: {} faces to draw", l.shadow_faces_left)
                }
                Some(l) => format!(
                    "light converging: bounce {} of {}{}{}",
                    l.bounces_done,
                    l.bounce_budget,
                    l.last_change.map(|c| format!(", change {c:.1e}")).unwrap_or_default(),
                    if m.held { " (waits while moving)" } else { "" }
                ),
                None => "no frame yet".into(),
            };
            ui.label(light);
            ui.add(egui::ProgressBar::new(m.light.map_or(0.0, |l| l.fraction())).desired_height(6.0));
            ui.separator();
            egui::ComboBox::from_label("quality")
                .selected_text(k.quality.map_or("custom", |q| q.name()))
                .show_ui(ui, |ui| {
                    for q in Quality::ALL {
                        ui.selectable_value(&mut k.quality, Some(q), q.name());
                    }
                });
            ui.add(egui::Slider::new(&mut k.bounces, 0..=32).text("bounces"));
            ui.add(egui::Slider::new(&mut k.exposure, 0.01..=100.0).logarithmic(true).text("exposure"));
            ui.checkbox(&mut k.shadows, "shadow maps");
            egui::ComboBox::from_label("view").selected_text(k.view.name()).show_ui(ui, |ui| {
                for v in ViewMode::ALL {
                    ui.selectable_value(&mut k.view, v, v.name());
                }
            });
            if k.view == ViewMode::Scan {
                scan_legend(ui, m);
            }
            if k.view == ViewMode::Lux {
                lux_legend(ui);
            }
            clip_box(ui, m, k);
            ui.separator();
            match m.tiles {
                Some((full, coarse, far)) => {
                    ui.label(format!("tiles: {full} full, {coarse} coarse, {far} far of {}", m.tile_count))
                }
                None => ui.label(format!("tiles: all {} resident", m.tile_count)),
            };
            ui.label(format!(
                "tile data {} in pools of {}; GPU {} in all; {} surfels",
                bytes(m.tile_bytes),
                bytes(m.pool_bytes),
                bytes(m.gpu_bytes),
                m.surfels
            ));
            ui.label(format!(
                "{}; speed {:.2} m/s{}",
                if m.orbit { "orbit" } else { "fly" },
                m.speed_m_s,
                m.recording.map(|n| format!("; recording ({n} keys)")).unwrap_or_default()
            ));
            ui.small(format!("adapter: {}", m.adapter));
            egui::CollapsingHeader::new("pass times").show(ui, |ui| {
                for (pass, ms) in &m.pass_ms {
                    ui.monospace(format!("{pass:<10}{ms:8.2} ms"));
                }
            });
            egui::CollapsingHeader::new("effect plan").show(ui, |ui| {
                ui.monospace(&m.plan);
            });
            egui::CollapsingHeader::new("controls").show(ui, |ui| {
                ui.small(
                    "drag: look (orbit: turn)  WASD: fly, Q/E down/up  wheel: speed (orbit: \
                     distance)\nright click: orbit the point under the cursor  O: orbit the \
                     centre / fly\nTab: next camera  R: first camera  1-7: view  H: panel\n\
                     C: clip box (section at eye height) on/off  K: record a camera path\n\
                     P: screenshot  F11: full screen  Esc: quit",
                );
            });
        },
    );
}

/// The scan view's legend: a colour swatch and name per scan (the first 24; a survey of more is
/// judged by the colours' differences, not by looking each up).
fn scan_legend(ui: &mut egui::Ui, m: &PanelModel) {
    egui::CollapsingHeader::new(format!("scans ({})", m.scans.len())).default_open(true).show(ui, |ui| {
        if m.scans.is_empty() {
            ui.small("this package stores no scan per point (built before format 1.2): all grey");
        }
        for (name, rgb) in m.scans.iter().take(24) {
            ui.horizontal(|ui| {
                let c = rgb.map(grotto_format::color::linear_to_srgb8);
                let (rect, _) = ui.allocate_exact_size(egui::vec2(12.0, 12.0), egui::Sense::hover());
                ui.painter().rect_filled(rect, 2.0, egui::Color32::from_rgb(c[0], c[1], c[2]));
                ui.small(name);
            });
        }
        if m.scans.len() > 24 {
            ui.small(format!("... {} more", m.scans.len() - 24));
        }
    });
}

/// The lux view's legend (view/lux.rs): the colour scale over its decades.
fn lux_legend(ui: &mut egui::Ui) {
    use crate::view::lux::lux_color;
    let (lo, hi) = (-1.0f32, 4.3f32);
    let (rect, _) = ui.allocate_exact_size(egui::vec2(200.0, 12.0), egui::Sense::hover());
    let n = 100;
    for i in 0..n {
        let l = lo + (hi - lo) * (i as f32 + 0.5) / n as f32;
        let c = lux_color(10f32.powf(l)).map(|v| (v * 255.0).round() as u8);
        let x0 = rect.left() + rect.width() * i as f32 / n as f32;
        let cell = egui::Rect::from_min_max(
            egui::pos2(x0, rect.top()),
            egui::pos2(x0 + rect.width() / n as f32 + 0.5, rect.bottom()),
        );
        ui.painter().rect_filled(cell, 0.0, egui::Color32::from_rgb(c[0], c[1], c[2]));
    }
    ui.small("illuminance: 1  10  100  1k  10k lux (magenta: glare above 14k)");
}

/// The section tool: a box (frame metres, within the scene's) outside which nothing is drawn.
fn clip_box(ui: &mut egui::Ui, m: &PanelModel, k: &mut PanelKnobs) {
    egui::CollapsingHeader::new("clip box").show(ui, |ui| {
        let mut on = k.clip.is_some();
        if ui.checkbox(&mut on, "cut the view to a box (C)").changed() {
            k.clip = on.then(|| section_at_eye(m.bounds_m, m.eye_m));
        }
        let Some(c) = &mut k.clip else { return };
        let (lo, hi) = m.bounds_m;
        for (axis, name) in ["x", "y", "z"].iter().enumerate() {
            ui.horizontal(|ui| {
                ui.label(format!("{name} m"));
                let range = lo[axis]..=hi[axis];
                let step = f64::from((hi[axis] - lo[axis]) / 200.0);
                let mut a = c.min_m[axis];
                let mut b = c.max_m[axis];
                ui.add(egui::DragValue::new(&mut a).range(range.clone()).speed(step));
                ui.add(egui::DragValue::new(&mut b).range(range).speed(step));
                c.min_m[axis] = a.min(b);
                c.max_m[axis] = b.max(a);
            });
        }
        if ui.button("cut above the eye").clicked() {
            c.max_m.z = m.eye_m.z.clamp(lo.z, hi.z);
        }
        ui.small("cuts what is drawn, not the light; tiles outside get no point budget");
    });
}
