//! The per-frame ray budget (`ray_budget`, seed 003 §8.2; `probegi_field::ray_budget`)
//! on the CPU: a budget that covers every probe changes nothing, bit for bit; a
//! tight one holds on average, and the floor reaches every probe within its
//! interval; after a light switches off, the probes it lit trace more often
//! than the still ones (which wait for the floor).

use std::collections::BTreeMap;

use glam::UVec3;
use probegi_core::ddgi_settings::{DdgiVolumeSettings, ProbeStatesMode};
use probegi_cpu::{DirectLighting, DirectSettings};
use probegi_field::ddgi_field_set::DdgiFieldSet;
use probegi_field::ddgi_volume::DdgiVolume;
use probegi_frame::field_update::FieldSetUpdate;
use probegi_scene::{BvhSettings, BvhTracer, Scene, load_scene};

const RAYS: u32 = 64;

fn settings(budget: u64) -> DdgiVolumeSettings {
    DdgiVolumeSettings {
        probe_counts: UVec3::new(8, 3, 8),
        probe_rays_per_probe: RAYS,
        shadow_field: true,
        probe_states: ProbeStatesMode::AllActive,
        ray_budget: budget,
        // The papers' update from frame 0: with the start-up ramp the shadow
        // box's bounces converge by frame 60, and switching a spot off then
        // changes every probe's bounce light, not mainly those it lit.
        probe_hysteresis_startup_ramp: false,
        ..Default::default()
    }
}

fn new_set(scene: &Scene, s: DdgiVolumeSettings) -> DdgiFieldSet {
    DdgiFieldSet::single(DdgiVolume::new(s, scene.bounds().expect("geometry")))
}

/// Updates `set` for frames `frames`, calling `each` after every frame.
fn run(scene: &Scene, set: &mut DdgiFieldSet, frames: std::ops::Range<u32>, mut each: impl FnMut(u32, &DdgiFieldSet)) {
    let bvh = BvhTracer::for_scene(scene, BvhSettings::default());
    let direct = DirectLighting::new(scene, &bvh, DirectSettings::default());
    let mut ms = BTreeMap::new();
    for f in frames {
        set.update_traced_by(scene, &bvh, None, &direct, 11, f, &mut ms).expect("update");
        each(f, set);
    }
}

#[test]
fn a_budget_that_covers_every_probe_changes_nothing() {
    for states in [ProbeStatesMode::AllActive, ProbeStatesMode::Jcgt, ProbeStatesMode::Usage] {
        covers_everything(states);
    }
}

fn covers_everything(states: ProbeStatesMode) {
    let scene = load_scene("builtin:shadow-box").expect("builtin");
    let with = |budget| DdgiVolumeSettings { probe_states: states, ..settings(budget) };
    let (mut a, mut b) = (new_set(&scene, with(0)), new_set(&scene, with(u64::MAX)));
    // Past the usage scheme's sleeping interval (10), so its own schedule runs.
    run(&scene, &mut a, 0..24, |_, _| {});
    run(&scene, &mut b, 0..24, |_, _| {});
    let (va, vb) = (&a.volumes()[0], &b.volumes()[0]);
    assert!(va.irradiance.texels == vb.irradiance.texels, "{states:?}: irradiance atlases differ");
    assert!(va.distance.texels == vb.distance.texels, "{states:?}: distance atlases differ");
    let occ = |v: &DdgiVolume| v.shadow.as_ref().expect("shadow field").occlusion.texels.clone();
    assert!(occ(va) == occ(vb), "occlusion maps differ");
    // And the budget measured every probe's change (a still field: small, not the initial 1).
    let changes: Vec<f32> = (0..vb.grid.probe_count()).map(|p| vb.probe_change(p)).collect();
    let mean = changes.iter().sum::<f32>() / changes.len() as f32;
    eprintln!("{states:?}: mean probe change after 24 frames: {mean:.4}");
    assert!(changes.iter().all(|c| (0.0..=1.0).contains(c)));
    assert!(mean > 0.0 && mean < 0.5, "mean change {mean}");
}

#[test]
fn a_tight_budget_holds_on_average_and_the_floor_reaches_every_probe() {
    let scene = load_scene("builtin:shadow-box").expect("builtin");
    let probes = 8 * 3 * 8;
    let budget = probes as u64 * RAYS as u64 / 4;
    let s = settings(budget);
    let interval = s.ray_budget_max_interval_frames;
    let mut set = new_set(&scene, s);
    let mut rays = vec![];
    run(&scene, &mut set, 0..40, |f, set| {
        rays.push(set.rays_per_frame());
        let v = &set.volumes()[0];
        for p in 0..v.grid.probe_count() {
            let since = v.probe_frames_since_traced(p);
            assert!(since < interval, "frame {f}: probe {p} has not traced for {since} frames");
        }
    });
    let all = probes as u64 * RAYS as u64;
    assert_eq!(rays[0], all, "the first frame traces every probe (none has history)");
    let mean = rays[1..].iter().sum::<u64>() as f64 / (rays.len() - 1) as f64;
    let worst = *rays[1..].iter().max().expect("frames");
    eprintln!("budget {budget}: mean {mean:.0} rays per frame after the first, most {worst}; all probes {all}");
    assert!(mean <= 1.05 * budget as f64, "mean {mean} over the budget {budget}");
    assert!(mean >= 0.9 * budget as f64, "mean {mean}: the budget is not spent");
    // The floor may exceed the budget on a frame, never trace everything again.
    assert!(worst < all, "a frame traced every probe again");
}

#[test]
fn after_a_light_switches_off_the_probes_it_lit_trace_more_often() {
    let scene = load_scene("builtin:shadow-box").expect("builtin");
    let mut dark = scene.clone();
    dark.lights.truncate(1);
    let probes = 8 * 3 * 8;
    let budget = probes as u64 * RAYS as u64 / 4;
    // Converged first (every probe every frame), then under the budget. No
    // shadowing field: its floor updates come in pairs (the occlusion maps
    // blend from the frame before), which takes the rest of a quarter budget.
    let mut set = new_set(&scene, DdgiVolumeSettings { shadow_field: false, ..settings(0) });
    run(&scene, &mut set, 0..60, |_, _| {});
    set.volumes_mut()[0].settings.ray_budget = budget;
    run(&scene, &mut set, 60..68, |_, _| {});
    let before = set.volumes()[0].irradiance.clone();
    let mut traces = vec![0u32; probes];
    run(&dark, &mut set, 68..74, |_, set| {
        let v = &set.volumes()[0];
        for (p, t) in traces.iter_mut().enumerate() {
            *t += (v.probe_frames_since_traced(p) == 0) as u32;
        }
    });
    // How much each probe's irradiance moved: the probes the second spot lit.
    let v = &set.volumes()[0];
    let moved: Vec<f32> = (0..probes)
        .map(|p| {
            let (a, b) = (before.tile(p), v.irradiance.tile(p));
            a.iter().zip(b).map(|(x, y)| (*x - *y).abs().element_sum()).sum::<f32>()
        })
        .collect();
    let mut order: Vec<usize> = (0..probes).collect();
    order.sort_by(|&a, &b| moved[b].total_cmp(&moved[a]));
    let rate = |ps: &[usize]| ps.iter().map(|&p| traces[p] as f32).sum::<f32>() / (ps.len() as f32 * 6.0);
    let (top, rest) = (rate(&order[..probes / 8]), rate(&order[probes / 2..]));
    eprintln!("after the switch: trace rate of the eighth that changed most {top:.2}, of the still half {rest:.2}");
    assert!(top > 0.7, "the changed probes trace most frames: {top}");
    assert!(rest < 0.1 * top, "the still probes wait for the floor: {rest}");
}

#[test]
fn after_a_scene_event_the_budget_visits_every_probe_in_turn() {
    let scene = load_scene("builtin:shadow-box").expect("builtin");
    let probes = 8 * 3 * 8;
    let budget = probes as u64 * RAYS as u64 / 4;
    let mut set = new_set(&scene, settings(budget));
    run(&scene, &mut set, 0..12, |_, _| {});
    set.notify_scene_event(probegi_field::SceneEvent::LargeLightChange);
    run(&scene, &mut set, 12..16, |_, _| {});
    // A quarter of the probes a frame, round robin: each traced within the 4 frames.
    let v = &set.volumes()[0];
    let waited = (0..probes).map(|p| v.probe_frames_since_traced(p)).max().expect("probes");
    assert!(waited < 4, "a probe waited {waited} frames through the event's window");
}

#[test]
fn under_a_budget_every_probes_occlusion_map_keeps_blending() {
    // The occlusion maps blend from the surfels of the frame before, so the
    // budget traces a probe two frames in a row at least: after two floor
    // intervals every probe's map has blended since the start. A blend's
    // change reaches the budget `ray_budget_change_lag_updates` frames late,
    // so in each of the two rounds a probe that settled keeps its last
    // priority, and its place in the budget, that much longer.
    let scene = load_scene("builtin:shadow-box").expect("builtin");
    let probes = 8 * 3 * 8;
    let mut set = new_set(&scene, settings(probes as u64 * RAYS as u64 / 4));
    let first = |set: &DdgiFieldSet| set.volumes()[0].shadow.as_ref().expect("shadow field").occlusion.clone();
    run(&scene, &mut set, 0..2, |_, _| {});
    let early = first(&set);
    let s = &set.volumes()[0].settings;
    let window = 2 * (s.ray_budget_max_interval_frames + s.ray_budget_change_lag_updates);
    run(&scene, &mut set, 2..2 + window, |_, _| {});
    let late = first(&set);
    let unchanged = (0..probes).filter(|&p| early.tile(p) == late.tile(p)).count();
    assert_eq!(unchanged, 0, "{unchanged} probes' occlusion maps never blended again under the budget");
}
