//! The viewer's panels under `egui_kittest` (issue "`probegi view`…"): each
//! panel renders, a setting changed in the panel changes the field's
//! settings struct, and a light switched off in the panel changes the frame
//! and sets the fast-convergence heuristics going. Snapshot images of the
//! panels are kept in `tests/snapshots/` (refresh with `UPDATE_SNAPSHOTS=1`).

use egui_kittest::Harness;
use egui_kittest::kittest::Queryable;
use probegi_core::ddgi_settings::DdgiVolumeSettings;
use probegi_frame::frame_loop::{GiMethod, RenderSettings};
use probegi_scene::{BvhSettings, BvhTracer, Scene, load_scene};
use probegi_view::view_session::ViewSession;
use probegi_view::viewer_controls::{GiChoice, ViewerControls};
use probegi_view::viewer_panels::{PanelAction, PanelState, panels_ui};
use probegi_view::viewer_worker::FrameReport;

fn door_room() -> Scene {
    load_scene("builtin:door-room").expect("built-in scene")
}

fn settings(scene: &Scene) -> RenderSettings {
    let volume = DdgiVolumeSettings { probe_rays_per_probe: 32, ..scene.volume.clone().unwrap_or_default() };
    RenderSettings { width: 32, height: 24, gi: GiMethod::Ddgi(Box::new(volume)), ..Default::default() }
}

fn frame_report() -> FrameReport {
    FrameReport {
        frame: 12,
        scene_frame: 12,
        width: 32,
        height: 24,
        frame_size: (32, 24),
        frame_ms: 41.5,
        pass_ms: vec![("trace", 10.0), ("shade", 20.0), ("blend", 3.0), ("camera", 8.0)],
        rays: 3456,
        probe_states: [("active", 100), ("sleeping", 8)].into_iter().collect(),
        volumes: 1,
        hysteresis_scale: 0.5,
        adapter: Some("llvmpipe".into()),
        fly_speed_m_per_s: 1.2,
        ..Default::default()
    }
}

/// Panels over the door room's controls, one frame's stats in.
fn panel_state(scene: &Scene) -> PanelState {
    let s = settings(scene);
    let bvh = BvhTracer::for_scene(scene, BvhSettings::default());
    let session = ViewSession::new(scene, &bvh, &scene.default_camera(), &s, 1.0, vec![]);
    let controls = ViewerControls::new(GiChoice::Ddgi, 0, scene, session.stepper().field());
    let mut state = PanelState::new(controls, "builtin:door-room", true);
    for _ in 0..3 {
        state.push_frame(frame_report());
    }
    state
}

fn harness(state: PanelState) -> Harness<'static, (PanelState, Vec<PanelAction>)> {
    Harness::builder().with_size(egui::vec2(420.0, 1100.0)).build_ui_state(
        |ui, (state, actions): &mut (PanelState, Vec<PanelAction>)| {
            actions.extend(panels_ui(ui, state));
        },
        (state, vec![]),
    )
}

#[test]
fn every_panel_renders_with_its_figures() {
    let scene = door_room();
    let mut h = harness(panel_state(&scene));
    h.run();
    for label in [
        "hysteresis",
        "fast convergence",
        "rays per probe",
        "relocation",
        "shadowing field",
        "× sky radiance",
        "sun 0",
        "path-trace this view",
        "adapter: llvmpipe",
        "probe rays this frame: 3456",
        "probes: active 100, sleeping 8",
        "fast convergence: hysteresis ×0.50 after a scene change",
    ] {
        assert!(h.query_all_by_label_contains(label).next().is_some(), "the panels show `{label}`");
    }
    h.snapshot("panels");
}

#[test]
fn a_panel_setting_reaches_the_field_settings() {
    let scene = door_room();
    let s = settings(&scene);
    let bvh = BvhTracer::for_scene(&scene, BvhSettings::default());
    let mut session = ViewSession::new(&scene, &bvh, &scene.default_camera(), &s, 1.0, vec![]);
    let state = panel_state(&scene);
    let before = state.controls.field.expect("a DDGI field");
    assert!(before.fast_convergence, "the seeds' default");
    let mut h = harness(state);
    h.run();
    h.get_by_label("fast convergence").click();
    h.run();
    let (state, actions) = h.state();
    assert!(actions.contains(&PanelAction::Controls), "{actions:?}");
    let after = state.controls.field.expect("a DDGI field");
    assert!(!after.fast_convergence);
    assert!(!state.controls.needs_rebuild(&panel_state(&scene).controls), "a live setting");
    let set = session.stepper_mut().field_mut().expect("DDGI");
    after.apply_live(set);
    assert!(set.volumes().iter().all(|v| !v.settings.probe_fast_convergence));
    // A structural one asks for a new field.
    let mut h = harness(panel_state(&scene));
    h.run();
    h.get_by_label("relocation").click();
    h.run();
    assert!(h.state().0.controls.needs_rebuild(&panel_state(&scene).controls));
}

#[test]
fn switching_the_sun_off_in_the_panel_darkens_the_frame_and_speeds_the_field_up() {
    let scene = door_room();
    let s = settings(&scene);
    let bvh = BvhTracer::for_scene(&scene, BvhSettings::default());
    let mut session = ViewSession::new(&scene, &bvh, &scene.default_camera(), &s, 1.0, vec![]);
    let mut lit = None;
    for _ in 0..6 {
        lit = Some(session.frame(1.0 / 60.0).expect("frame"));
    }
    let lit = lit.expect("frames");
    let mut h = harness(panel_state(&scene));
    h.run();
    h.get_by_label("sun 0").click();
    h.run();
    let (state, actions) = h.state();
    assert!(actions.contains(&PanelAction::Controls));
    assert!(!state.controls.lights[0].enabled && state.controls.edits_scene());
    session.stepper_mut().set_scene_edit(Some(state.controls.scene_edit()));
    let dark = session.frame(1.0 / 60.0).expect("frame");
    let field = session.stepper().field().expect("DDGI");
    let scale = field.volumes()[0].irradiance_hysteresis_scale();
    assert_eq!(scale, 0.5, "the light change set seed 004's large-light heuristic going");
    let (l, d) = (lit.mean().element_sum(), dark.mean().element_sum());
    assert!(d < 0.5 * l, "the sun off darkens the frame: {l} → {d}");
}
