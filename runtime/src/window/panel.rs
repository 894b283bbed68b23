//! The viewer's panel (egui): the knobs a person changes while looking (quality preset,
//! bounces, exposure, shadows, view), and what the runtime is doing (the effect plan as it
//! reports it, fps and per-pass times, the light's convergence, resident tiles and bytes against
//! the budget, the adapter). It reads a [`PanelModel`] and edits [`PanelKnobs`]; the window
//! applies what changed, so the panel never touches the renderer.

use crate::renderer::{LightProgress, Quality, ViewMode};

/// What the panel shows, gathered by the window each frame.
#[derive(Clone, Debug, Default)]
pub struct PanelModel {
    pub adapter: String,
    pub fps: f64,
    pub frame_ms: f64,
    pub light: Option<LightProgress>,
    /// The bounces wait for the camera to rest.
    pub held: bool,
    pub plan: String,
    pub pass_ms: Vec<(&'static str, f64)>,
    /// Tiles held in full, coarse and far (None: the whole package is resident).
    pub tiles: Option<(usize, usize, usize)>,
    pub tile_count: usize,
    pub tile_bytes: u64,
    /// GPU bytes of the tile pools (what `--gpu-memory` bounds), and of the renderer in all.
    pub pool_bytes: u64,
    pub gpu_bytes: u64,
    pub surfels: usize,
    /// Keyframes recorded so far, while recording.
    pub recording: Option<usize>,
    pub orbit: bool,
    pub speed_m_s: f32,
}

/// What the panel can change.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct PanelKnobs {
    /// None: the settings came from the command line's knobs, not a preset as it is.
    pub quality: Option<Quality>,
    pub bounces: u32,
    pub exposure: f32,
    pub shadows: bool,
    pub view: ViewMode,
}

fn bytes(b: u64) -> String {
    crate::gpu::human_bytes(b)
}

/// Draws the panel.
pub fn show(ctx: &egui::Context, m: &PanelModel, k: &mut PanelKnobs) {
    egui::Window::new("grotto").default_pos([8.0, 8.0]).default_width(260.0).resizable(true).show(
        ctx,
        |ui| {
            ui.label(format!("{:.1} fps ({:.1} ms a frame)", m.fps, m.frame_ms));
            let light = match m.light {
                Some(l) if l.converged => format!("light converged ({} bounces)", l.bounces_done),
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
                     centre / fly\nTab: next camera  R: first camera  1-5: view  H: panel\n\
                     K: record a camera path  P: screenshot  F11: full screen  Esc: quit",
                );
            });
        },
    );
}
