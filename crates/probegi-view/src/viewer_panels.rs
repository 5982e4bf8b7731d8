//! The viewer's panels (egui): GI, field settings, views, lights, scene
//! clock, the reference, stats with a live plot of each pass's time, and the
//! key bindings. They read and write a [`PanelState`] and return what the
//! worker must be told, so tests drive them without a window
//! (`tests/it/panels.rs`, `egui_kittest`).

use std::collections::VecDeque;

use egui::{Color32, Ui};
use probegi_core::probe_classification::ProbeStatesMode;

use crate::view_layers::ViewMode;
use crate::viewer_controls::{GiChoice, ViewerControls};
use crate::viewer_worker::{FrameReport, ReferenceReport};

/// Frames the stats plot keeps.
pub const PLOT_FRAMES: usize = 240;

/// The key bindings, as the window and `--help` list them.
pub const KEY_BINDINGS: &[(&str, &str)] = &[
    ("W A S D", "fly forward, left, back, right"),
    ("Q E", "fly down, up"),
    ("right mouse drag", "look around"),
    ("scroll wheel", "fly speed ×1.25 per step"),
    ("R", "reset to the scene's camera"),
    ("Space", "pause or resume the scene clock"),
    ("N", "step the paused scene clock by one frame"),
    ("F5", "path-trace the reference of this view"),
    ("F12", "screenshot: PNG and linear EXR"),
    ("V", "next view"),
    ("Tab", "hide or show the panels"),
    ("Ctrl+R", "reload the scene"),
    ("Esc", "quit"),
];

/// [`KEY_BINDINGS`] as the text `probegi view --help` ends with.
pub fn keys_help() -> String {
    let mut text = String::from("Keys in the window:\n");
    for (key, what) in KEY_BINDINGS {
        text.push_str(&format!("  {key:<18} {what}\n"));
    }
    text
}

/// What the panels show and set.
#[derive(Clone, Debug)]
pub struct PanelState {
    /// The controls as the user set them.
    pub controls: ViewerControls,
    /// The newest frame's figures.
    pub frame: Option<FrameReport>,
    /// Recent frames' pass times, for the plot (newest last).
    pub history: VecDeque<Vec<(&'static str, f64)>>,
    /// The reference's state.
    pub reference: Option<ReferenceReport>,
    /// Samples per pixel of the next reference.
    pub reference_spp: u32,
    /// The status line.
    pub status: String,
    /// The scene's name.
    pub scene_name: String,
    /// The CPU backend renders (SH is offered there).
    pub cpu_backend: bool,
}

impl PanelState {
    /// Panels for `controls`, before the first frame.
    pub fn new(controls: ViewerControls, scene_name: &str, cpu_backend: bool) -> Self {
        Self {
            controls,
            frame: None,
            history: VecDeque::new(),
            reference: None,
            reference_spp: 64,
            status: String::new(),
            scene_name: scene_name.into(),
            cpu_backend,
        }
    }

    /// Takes a new frame's figures in (and its pass times into the plot).
    pub fn push_frame(&mut self, report: FrameReport) {
        let mut passes = report.pass_ms.clone();
        passes.push(("frame", report.frame_ms));
        self.history.push_back(passes);
        while self.history.len() > PLOT_FRAMES {
            self.history.pop_front();
        }
        self.frame = Some(report);
    }
}

/// What a panel asks of the worker.
#[derive(Clone, Debug, PartialEq)]
pub enum PanelAction {
    /// The controls changed.
    Controls,
    /// Path-trace the reference at this many samples per pixel.
    Reference(u32),
    /// Write a screenshot.
    Screenshot,
    /// Step the paused scene clock.
    StepClock,
    /// Reload the scene.
    Reload,
}

/// Every panel, top to bottom, in `ui`; the actions they ask for.
pub fn panels_ui(ui: &mut Ui, state: &mut PanelState) -> Vec<PanelAction> {
    let before = state.controls.clone();
    let mut actions = vec![];
    egui::ScrollArea::vertical().show(ui, |ui| {
        ui.heading(format!("probegi view: {}", state.scene_name));
        egui::CollapsingHeader::new("GI").default_open(true).show(ui, |ui| gi_panel(ui, state));
        egui::CollapsingHeader::new("Field").default_open(true).show(ui, |ui| field_panel(ui, state));
        egui::CollapsingHeader::new("View").default_open(true).show(ui, |ui| view_panel(ui, state));
        egui::CollapsingHeader::new("Lights").default_open(true).show(ui, |ui| lights_panel(ui, state));
        egui::CollapsingHeader::new("Scene clock")
            .default_open(true)
            .show(ui, |ui| clock_panel(ui, state, &mut actions));
        egui::CollapsingHeader::new("Reference")
            .default_open(true)
            .show(ui, |ui| reference_panel(ui, state, &mut actions));
        egui::CollapsingHeader::new("Stats").default_open(true).show(ui, |ui| stats_panel(ui, state));
        egui::CollapsingHeader::new("Keys").default_open(false).show(ui, keys_panel);
        if ui.button("reload scene").clicked() {
            actions.push(PanelAction::Reload);
        }
        if !state.status.is_empty() {
            ui.separator();
            ui.label(&state.status);
        }
    });
    if state.controls != before {
        actions.insert(0, PanelAction::Controls);
    }
    actions
}

fn gi_panel(ui: &mut Ui, state: &mut PanelState) {
    let c = &mut state.controls;
    ui.horizontal(|ui| {
        ui.radio_value(&mut c.gi, GiChoice::None, "none");
        ui.radio_value(&mut c.gi, GiChoice::Ddgi, "DDGI");
        if state.cpu_backend {
            ui.radio_value(&mut c.gi, GiChoice::Sh, "SH probes");
        }
    });
    if c.gi == GiChoice::Ddgi {
        ui.horizontal(|ui| {
            let l = ui.label("cascades (0: the scene's volumes)");
            ui.add(egui::DragValue::new(&mut c.cascades).range(0..=6).clamp_existing_to_range(false)).labelled_by(l.id);
        });
    }
}

fn field_panel(ui: &mut Ui, state: &mut PanelState) {
    let Some(f) = state.controls.field.as_mut() else {
        ui.label("no DDGI field");
        return;
    };
    ui.add(egui::Slider::new(&mut f.hysteresis, 0.0..=1.0).clamping(egui::SliderClamping::Edits).text("hysteresis"));
    ui.checkbox(&mut f.fast_convergence, "fast convergence");
    ui.checkbox(&mut f.glossy_second_order, "second-order glossy");
    ui.horizontal(|ui| {
        let l = ui.label("ray budget (0: off)");
        ui.add(egui::DragValue::new(&mut f.ray_budget).speed(256.0)).labelled_by(l.id);
    });
    ui.separator();
    ui.label("These rebuild the field:");
    ui.horizontal(|ui| {
        let l = ui.label("rays per probe");
        ui.add(egui::DragValue::new(&mut f.rays_per_probe).range(16..=1024).clamp_existing_to_range(false))
            .labelled_by(l.id);
    });
    ui.horizontal(|ui| {
        ui.label("probe states");
        ui.radio_value(&mut f.probe_states, ProbeStatesMode::AllActive, "all active");
        ui.radio_value(&mut f.probe_states, ProbeStatesMode::Jcgt, "jcgt");
        ui.radio_value(&mut f.probe_states, ProbeStatesMode::Usage, "usage");
        ui.radio_value(&mut f.probe_states, ProbeStatesMode::Screen, "screen");
    });
    ui.checkbox(&mut f.relocation, "relocation");
    ui.checkbox(&mut f.shadow_field, "shadowing field");
}

fn view_panel(ui: &mut Ui, state: &mut PanelState) {
    let c = &mut state.controls;
    let has_field = c.field.is_some();
    egui::ComboBox::from_label("view").selected_text(c.view.label()).show_ui(ui, |ui| {
        for mode in ViewMode::ALL.into_iter().filter(|m| has_field || !m.needs_field()) {
            ui.selectable_value(&mut c.view, mode, mode.label());
        }
    });
    let volumes = state.frame.as_ref().map_or(1, |f| f.volumes.max(1));
    if matches!(c.view, ViewMode::IrradianceAtlas | ViewMode::DistanceAtlas) && volumes > 1 {
        ui.add(egui::Slider::new(&mut c.atlas_volume, 0..=volumes - 1).text("volume"));
    }
}

fn lights_panel(ui: &mut Ui, state: &mut PanelState) {
    let c = &mut state.controls;
    if c.lights.is_empty() {
        ui.label("no punctual lights (emitters stay as loaded)");
    }
    for l in &mut c.lights {
        ui.horizontal(|ui| {
            ui.checkbox(&mut l.enabled, &l.name);
            ui.add(
                egui::Slider::new(&mut l.intensity_scale, 0.0..=4.0)
                    .clamping(egui::SliderClamping::Edits)
                    .text("× intensity"),
            );
        });
    }
    ui.add(egui::Slider::new(&mut c.sky_scale, 0.0..=4.0).clamping(egui::SliderClamping::Edits).text("× sky radiance"));
}

fn clock_panel(ui: &mut Ui, state: &mut PanelState, actions: &mut Vec<PanelAction>) {
    let frame = state.frame.as_ref().map_or(0, |f| f.scene_frame);
    ui.horizontal(|ui| {
        ui.label(format!("scene frame {frame}"));
        let label = if state.controls.paused { "play" } else { "pause" };
        if ui.button(label).clicked() {
            state.controls.paused = !state.controls.paused;
        }
        if ui.add_enabled(state.controls.paused, egui::Button::new("step")).clicked() {
            actions.push(PanelAction::StepClock);
        }
    });
    if ui.button("screenshot (PNG + EXR)").clicked() {
        actions.push(PanelAction::Screenshot);
    }
}

fn reference_panel(ui: &mut Ui, state: &mut PanelState, actions: &mut Vec<PanelAction>) {
    ui.horizontal(|ui| {
        let l = ui.label("reference spp");
        ui.add(egui::DragValue::new(&mut state.reference_spp).range(1..=65536).clamp_existing_to_range(false))
            .labelled_by(l.id);
        if ui.button("path-trace this view").clicked() {
            actions.push(PanelAction::Reference(state.reference_spp));
        }
    });
    if let Some(r) = &state.reference {
        if r.progress < 1.0 {
            ui.add(egui::ProgressBar::new(r.progress).show_percentage());
        } else if r.stale {
            ui.label("the view or the scene moved since the reference: FLIP paused (pause the clock with Space)");
        } else if let Some(flip) = r.mean_flip {
            ui.label(format!("mean FLIP against the reference ({} spp): {flip:.3}", r.spp));
        }
    }
}

/// The plot's colour of a pass.
fn pass_colour(i: usize) -> Color32 {
    const COLOURS: [Color32; 8] = [
        Color32::from_rgb(230, 159, 0),
        Color32::from_rgb(86, 180, 233),
        Color32::from_rgb(0, 158, 115),
        Color32::from_rgb(240, 228, 66),
        Color32::from_rgb(0, 114, 178),
        Color32::from_rgb(213, 94, 0),
        Color32::from_rgb(204, 121, 167),
        Color32::from_rgb(200, 200, 200),
    ];
    COLOURS[i % COLOURS.len()]
}

fn stats_panel(ui: &mut Ui, state: &mut PanelState) {
    let Some(f) = &state.frame else {
        ui.label("waiting for the first frame…");
        return;
    };
    ui.label(format!("adapter: {}", f.adapter.as_deref().unwrap_or("CPU")));
    ui.label(format!("frame {} at {}×{}: {:.1} ms", f.frame, f.frame_size.0, f.frame_size.1, f.frame_ms));
    ui.label(format!("probe rays this frame: {}", f.rays));
    let states: Vec<String> = f.probe_states.iter().map(|(k, n)| format!("{k} {n}")).collect();
    if !states.is_empty() {
        ui.label(format!("probes: {}", states.join(", ")));
    }
    if f.hysteresis_scale < 1.0 {
        ui.colored_label(
            Color32::from_rgb(240, 228, 66),
            format!("fast convergence: hysteresis ×{:.2} after a scene change", f.hysteresis_scale),
        );
    }
    let c = f.camera_m;
    ui.label(format!("camera ({:.2}, {:.2}, {:.2}), {:.2} m/s", c.x, c.y, c.z, f.fly_speed_m_per_s));
    pass_plot(ui, state);
}

/// Each pass's milliseconds over the last frames, one line per pass.
fn pass_plot(ui: &mut Ui, state: &PanelState) {
    let mut names: Vec<&'static str> = state.history.iter().flatten().map(|(k, _)| *k).collect();
    names.sort_unstable();
    names.dedup();
    let max_ms = state.history.iter().flatten().map(|(_, v)| *v).fold(1e-3, f64::max);
    let (rect, _) = ui.allocate_exact_size(egui::vec2(ui.available_width().min(320.0), 100.0), egui::Sense::hover());
    let painter = ui.painter_at(rect);
    painter.rect_filled(rect, 2.0, Color32::from_gray(24));
    let n = state.history.len().max(2);
    for (i, name) in names.iter().enumerate() {
        let points: Vec<egui::Pos2> = state
            .history
            .iter()
            .enumerate()
            .filter_map(|(j, frame)| frame.iter().find(|(k, _)| k == name).map(|(_, v)| (j, *v)))
            .map(|(j, v)| {
                let x = rect.left() + rect.width() * j as f32 / (n - 1) as f32;
                egui::pos2(x, rect.bottom() - rect.height() * (v / max_ms) as f32)
            })
            .collect();
        painter.add(egui::Shape::line(points, egui::Stroke::new(1.5, pass_colour(i))));
    }
    ui.label(format!("top of the plot: {max_ms:.1} ms"));
    let last = state.history.back();
    for (i, name) in names.iter().enumerate() {
        let ms = last.and_then(|f| f.iter().find(|(k, _)| k == name)).map_or(0.0, |(_, v)| *v);
        ui.colored_label(pass_colour(i), format!("{name}: {ms:.2} ms"));
    }
}

fn keys_panel(ui: &mut Ui) {
    egui::Grid::new("keys").show(ui, |ui| {
        for (key, what) in KEY_BINDINGS {
            ui.label(*key);
            ui.label(*what);
            ui.end_row();
        }
    });
}
