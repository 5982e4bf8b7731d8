//! Seed 004's production extensions and seed 003's usage culling: relocation,
//! probe states, fast convergence.

use crate::common;

use common::field_energy;
use glam::{UVec3, Vec3};
use probegi_core::ddgi_query::irradiance;
use probegi_core::ddgi_settings::{DdgiVolumeSettings, ProbeStatesMode};
use probegi_core::probe_classification::ProbeState;
use probegi_cpu::{DirectLighting, DirectSettings};
use probegi_field::ddgi_volume::{DdgiVolume, SceneEvent};
use probegi_frame::field_update::VolumeUpdate;
use probegi_scene::builtin::{add_box, add_polygon, cornell_box};
use probegi_scene::{BvhSettings, BvhTracer, Material, Scene};

fn run(volume: &mut DdgiVolume, scene: &Scene, frames: std::ops::Range<u32>) {
    let bvh = BvhTracer::build(&scene.mesh, BvhSettings::default());
    let direct = DirectLighting::new(scene, &bvh, DirectSettings::default());
    let mut passes = Default::default();
    for f in frames {
        volume.update(scene, &bvh, &direct, 9, f, &mut passes);
    }
}

#[test]
fn a_probe_inside_a_thin_wall_is_moved_out_of_it() {
    // A 0.1 m wall through x ∈ [0.95, 1.05]; the probe at x = 1 sits inside it.
    let mut scene = Scene { materials: vec![Material::diffuse("wall", Vec3::splat(0.5))], ..Default::default() };
    add_box(&mut scene.mesh, Vec3::new(0.96, -2.0, -2.0), Vec3::new(1.04, 2.0, 2.0), 0);
    let settings = DdgiVolumeSettings {
        probe_counts: UVec3::new(3, 1, 1),
        probe_origin_m: Some(Vec3::ZERO),
        probe_spacing_m: Some(Vec3::ONE),
        probe_rays_per_probe: 64,
        ..Default::default()
    };
    let bvh = BvhTracer::build(&scene.mesh, BvhSettings::default());
    let off =
        DdgiVolume::new(DdgiVolumeSettings { probe_relocation: false, ..settings.clone() }, (Vec3::ZERO, Vec3::ONE));
    assert_eq!(off.count_probes_inside_geometry(&bvh, 1), 1, "the middle probe starts inside");
    let mut v = DdgiVolume::new(settings, (Vec3::ZERO, Vec3::ONE));
    run(&mut v, &scene, 0..1);
    let x = v.probe_positions[1].x;
    assert!(!(0.96..=1.04).contains(&x), "probe still inside the wall at x = {x}");
    assert!(v.probe_offsets[1].abs().max_element() < 0.45 + 1e-6, "offset within the limit");
    assert_eq!(v.count_probes_inside_geometry(&bvh, 1), 0);
    assert_ne!(v.probe_states[1], ProbeState::Off);
}

#[test]
fn jcgt_states_sleep_far_probes_and_wake_them_around_a_moved_box() {
    // A floor at y = 0 and probes up to 3 m above it: the high ones have no surface
    // within a spacing and sleep; a dynamic box moved among them wakes them.
    let mut scene = Scene { materials: vec![Material::diffuse("floor", Vec3::splat(0.5))], ..Default::default() };
    add_polygon(
        &mut scene.mesh,
        &[Vec3::new(-5.0, 0.0, -5.0), Vec3::new(-5.0, 0.0, 5.0), Vec3::new(5.0, 0.0, 5.0), Vec3::new(5.0, 0.0, -5.0)],
        0,
    );
    let settings = DdgiVolumeSettings {
        probe_counts: UVec3::new(4, 4, 4),
        probe_origin_m: Some(Vec3::new(-1.5, 0.5, -1.5)),
        probe_spacing_m: Some(Vec3::ONE),
        probe_rays_per_probe: 64,
        ..Default::default()
    };
    let mut v = DdgiVolume::new(settings, (Vec3::splat(-5.0), Vec3::splat(5.0)));
    run(&mut v, &scene, 0..2);
    let counts = v.state_counts();
    assert_eq!(counts.get("vigilant"), Some(&16), "{counts:?}: the bottom layer sees the floor");
    assert_eq!(counts.get("sleeping"), Some(&48), "{counts:?}");
    assert_eq!(v.active_probe_count(), 16, "only vigilant probes traced");

    // Box at the top layer's height: wakes the probes around it.
    let woken = v.wake_probes_near(&[(Vec3::new(-0.2, 3.3, -0.2), Vec3::new(0.2, 3.7, 0.2))]);
    assert!(woken >= 4, "woke {woken}");
    // Newly Awake probes hold no blend of their own yet: queries must not read them.
    let newly: Vec<usize> = (0..64).filter(|&p| v.probe_states[p] == ProbeState::NewlyAwake).collect();
    assert_eq!(newly.len(), woken);
    assert!(newly.iter().all(|&p| !v.probe_usable(p)));
    run(&mut v, &scene, 2..3);
    assert!(newly.iter().all(|&p| v.probe_usable(p)), "usable after their first blend");
    assert_eq!(v.state_counts().get("awake"), Some(&woken));
    // The box leaves: they go back to sleep.
    v.wake_probes_near(&[]);
    assert_eq!(v.state_counts().get("awake"), None);
}

fn floor_points() -> Vec<Vec3> {
    (0..25).map(|i| Vec3::new(-0.8 + 0.4 * (i % 5) as f32, 0.001, -0.8 + 0.4 * (i / 5) as f32)).collect()
}

fn floor_irradiance(v: &DdgiVolume) -> Vec<Vec3> {
    floor_points().iter().map(|&p| irradiance(&v.view(), p, Vec3::Y, Vec3::Y)).collect()
}

fn rel_error(a: &[Vec3], b: &[Vec3]) -> f32 {
    let num: f32 = a.iter().zip(b).map(|(x, y)| (*x - *y).length()).sum();
    let den: f32 = b.iter().map(|y| y.length()).sum();
    num / den
}

/// Frames after the light returns until the floor's indirect irradiance is within
/// 10 % of the never-toggled, converged field, and the error after 300 frames.
fn light_toggle(fast: bool) -> (u32, f32) {
    let lit = cornell_box();
    let mut dark = lit.clone();
    for m in &mut dark.materials {
        m.emissive_factor = Vec3::ZERO;
    }
    let settings = DdgiVolumeSettings {
        probe_rays_per_probe: 64,
        probe_fast_convergence: fast,
        probe_counts: UVec3::splat(6),
        ..Default::default()
    };
    let bounds = lit.bounds().expect("bounds");
    let mut steady = DdgiVolume::new(settings.clone(), bounds);
    run(&mut steady, &lit, 0..390);
    let converged = floor_irradiance(&steady);

    let mut v = DdgiVolume::new(settings, bounds);
    run(&mut v, &lit, 0..60);
    if fast {
        v.notify_scene_event(SceneEvent::LargeLightChange);
    }
    run(&mut v, &dark, 60..90);
    if fast {
        v.notify_scene_event(SceneEvent::LargeLightChange);
    }
    let mut frames = None;
    for f in 90..390 {
        run(&mut v, &lit, f..f + 1);
        if frames.is_none() && rel_error(&floor_irradiance(&v), &converged) < 0.10 {
            frames = Some(f - 89);
        }
    }
    (frames.unwrap_or(u32::MAX), rel_error(&floor_irradiance(&v), &converged))
}

#[test]
fn energy_returns_after_the_light_is_toggled_and_heuristics_converge_faster() {
    let (fast_frames, fast_err) = light_toggle(true);
    let (slow_frames, slow_err) = light_toggle(false);
    eprintln!("light back on: within 10 % after {fast_frames} frames with heuristics, {slow_frames} without");
    eprintln!("after 300 frames: error {fast_err:.4} with, {slow_err:.4} without");
    assert!(fast_frames <= slow_frames, "heuristics must not slow convergence");
    assert!(fast_frames < u32::MAX && slow_frames < u32::MAX, "both converge");
    // The known RTXGI bug: energy must come back fully.
    assert!(fast_err < 0.01, "energy did not return with the heuristics: {fast_err}");
    assert!(slow_err < 0.02, "energy did not return without the heuristics: {slow_err}");
}

#[test]
fn usage_states_cull_probes_buried_in_the_boxes() {
    let scene = cornell_box();
    let settings = DdgiVolumeSettings {
        probe_rays_per_probe: 64,
        probe_relocation: false,
        probe_states: ProbeStatesMode::Usage,
        ..Default::default()
    };
    let mut v = DdgiVolume::new(settings, scene.bounds().expect("bounds"));
    run(&mut v, &scene, 0..3);
    let counts = v.state_counts();
    let dead = counts.get("dead").copied().unwrap_or(0);
    assert!(dead >= 10, "probes inside the two boxes must be DEAD: {counts:?}");
    assert!(counts.get("alive").copied().unwrap_or(0) > 300, "{counts:?}");
    // A dead probe is not updated again and the query skips it.
    let p = v.probe_states.iter().position(|s| *s == ProbeState::Dead).expect("a dead probe");
    let before = v.irradiance.tile(p).to_vec();
    run(&mut v, &scene, 3..4);
    assert_eq!(v.irradiance.tile(p), &before[..]);
    assert!(!v.probe_usable(p));
    // Every probe traces every frame (seed 003 §6.1: culling skips the update only).
    assert_eq!(v.rays_per_frame(), v.grid.probe_count() as u64 * 64);
}

/// A floor at y = 0 and a 3 × 3 × 3 grid 1 m apart from y = 0.5; `covered` adds a
/// box around the middle probe (1, 1, 1) at (0, 1.5, 0).
fn usage_scene(covered: bool) -> Scene {
    let mut scene = Scene { materials: vec![Material::diffuse("grey", Vec3::splat(0.5))], ..Default::default() };
    add_polygon(
        &mut scene.mesh,
        &[Vec3::new(-5.0, 0.0, -5.0), Vec3::new(-5.0, 0.0, 5.0), Vec3::new(5.0, 0.0, 5.0), Vec3::new(5.0, 0.0, -5.0)],
        0,
    );
    if covered {
        add_box(&mut scene.mesh, Vec3::new(-0.3, 1.2, -0.3), Vec3::new(0.3, 1.8, 0.3), 0);
    }
    scene.sky_radiance = Vec3::splat(1.0);
    scene
}

/// A 3³ usage-scheme volume; `lag`: `probe_usage_lag_updates` (0: seed 003
/// §6.1's rule, the classification from the frame's own rays, which these
/// tests time frame by frame).
fn usage_volume_lagging(min_alive: u32, lag: u32) -> DdgiVolume {
    let settings = DdgiVolumeSettings {
        probe_counts: UVec3::splat(3),
        probe_origin_m: Some(Vec3::new(-1.0, 0.5, -1.0)),
        probe_spacing_m: Some(Vec3::ONE),
        probe_rays_per_probe: 128,
        probe_relocation: false,
        probe_states: ProbeStatesMode::Usage,
        probe_alive_min_frames: min_alive,
        probe_usage_lag_updates: lag,
        ..Default::default()
    };
    DdgiVolume::new(settings, (Vec3::splat(-5.0), Vec3::splat(5.0)))
}

fn usage_volume(min_alive: u32) -> DdgiVolume {
    usage_volume_lagging(min_alive, 0)
}

#[test]
fn a_probe_covered_from_frame_0_leaves_dead_once_uncovered() {
    // The box covers the middle probe from the very first frame (as a moving object
    // passing there at frame 0 would), then it is gone.
    // With the counts read `lag` updates late it dies and leaves DEAD that
    // many frames after the rays say so.
    let middle = 13;
    for lag in [0, 2] {
        let mut v = usage_volume_lagging(10, lag);
        run(&mut v, &usage_scene(true), 0..3 + lag);
        assert_eq!(v.probe_states[middle], ProbeState::Dead, "lag {lag}: {:?}", v.state_counts());
        assert!(!v.probe_usable(middle));
        run(&mut v, &usage_scene(false), 3 + lag..3 + 2 * lag);
        assert_eq!(v.probe_states[middle], ProbeState::Dead, "lag {lag}: the counts from under the box still come");
        run(&mut v, &usage_scene(false), 3 + 2 * lag..4 + 2 * lag);
        assert_ne!(v.probe_states[middle], ProbeState::Dead, "lag {lag}: usage says it is free: it must leave DEAD");
        assert!(v.probe_usable(middle), "lag {lag}: blended (history replaced) in the frame it left DEAD");
        // Its atlas now holds the open sky above the floor, not the box's dark inside.
        let up = irradiance(&v.view(), Vec3::new(0.0, 1.5, 0.0), Vec3::Y, Vec3::Y);
        assert!(up.x > 0.5 * std::f32::consts::PI, "lag {lag}: {up}");
    }
}

#[test]
fn alive_probes_stay_alive_for_the_minimum_time_then_sleep() {
    // The floor makes the bottom layer ALIVE; then the floor is gone (an empty scene)
    // and those probes have no relevant samples.
    let empty = Scene { materials: vec![Material::diffuse("grey", Vec3::splat(0.5))], ..Default::default() };
    let bottom = 4; // (1, 0, 1)
    let mut v = usage_volume(6);
    run(&mut v, &usage_scene(false), 0..2);
    assert_eq!(v.probe_states[bottom], ProbeState::Alive);
    for f in 2..6 {
        run(&mut v, &empty, f..f + 1);
        assert_eq!(v.probe_states[bottom], ProbeState::Alive, "frame {f}: within the minimum time");
    }
    run(&mut v, &empty, 6..8);
    assert_eq!(v.probe_states[bottom], ProbeState::UsageSleeping);
    // SLEEPING probes still trace every frame; they blend every 10th.
    assert_eq!(v.rays_per_frame(), 27 * 128);
    let before = v.irradiance.tile(bottom).to_vec();
    run(&mut v, &empty, 8..10);
    assert_eq!(v.irradiance.tile(bottom), &before[..], "frames 8, 9: not blended");
    run(&mut v, &empty, 10..11);
    assert_ne!(v.irradiance.tile(bottom), &before[..], "frame 10: blended");
}

#[test]
fn listing_3_thresholds_do_not_bias_a_noisy_converged_field() {
    // Few rays make every texel noisy, so the per-texel thresholds fire on noise
    // alone; the converged field must stay where the plain blend puts it.
    let scene = cornell_box();
    for rays in [16u32, 64] {
        let mean_over = |fast: bool| {
            let settings = DdgiVolumeSettings {
                probe_rays_per_probe: rays,
                probe_fast_convergence: fast,
                probe_counts: UVec3::splat(4),
                ..Default::default()
            };
            let mut v = DdgiVolume::new(settings, scene.bounds().expect("bounds"));
            run(&mut v, &scene, 0..300);
            let mut sum = 0.0;
            for f in 300..400 {
                run(&mut v, &scene, f..f + 1);
                sum += field_energy(&v);
            }
            sum / 100.0
        };
        let (fast, plain) = (mean_over(true), mean_over(false));
        eprintln!(
            "{rays} rays: field energy {fast:.5} with heuristics, {plain:.5} without ({:+.2} %)",
            100.0 * (fast / plain - 1.0)
        );
        assert!((fast / plain - 1.0).abs() < 0.02, "{rays} rays: {fast} vs {plain}");
    }
}

#[test]
fn settled_probes_skip_relocation_rounds_without_changing_an_offset() {
    // The relocation rounds share one set of directions, so a probe whose round
    // left it in place skips the rounds after (`init_rounds`). Against every
    // probe traced in every round by hand with the same directions, the offsets
    // must be the same, for fewer rays. The classification round reads the same
    // directions, so it traces again only the probes the last round moved.
    use probegi_core::probe_relocation::{probe_ray_stats, relocation_step};
    use probegi_cpu::probe_trace::trace_probe_distances;
    use probegi_field::ddgi_field_set::DdgiFieldSet;
    use probegi_field::probe_ray_gen::{probe_ray_rotation, rotated_fibonacci};
    use probegi_frame::field_update::FieldSetUpdate;
    let scene = cornell_box();
    let bvh = BvhTracer::build(&scene.mesh, BvhSettings::default());
    let direct = DirectLighting::new(&scene, &bvh, DirectSettings::default());
    // Cells of 0.125 m: probes near walls and the boxes, some inside the boxes.
    let settings = DdgiVolumeSettings { probe_counts: UVec3::splat(8), probe_rays_per_probe: 64, ..Default::default() };
    let bounds = scene.bounds().expect("geometry");
    let mut set = DdgiFieldSet::single(DdgiVolume::new(settings.clone(), bounds));
    set.update(&scene, &bvh, &direct, 5, 0, &mut Default::default());
    let v = &set.volumes()[0];

    let rays = settings.probe_init_rays_per_probe;
    let dirs = rotated_fibonacci(probe_ray_rotation(v.stream_seed(5), u32::MAX), rays);
    let grid_points: Vec<Vec3> =
        (0..v.grid.probe_count()).map(|p| v.grid.probe_position(v.grid.probe_coords(p))).collect();
    let mut offsets = vec![Vec3::ZERO; grid_points.len()];
    let (mut moved_after_first, mut moves) = (0, 0);
    for round in 0..settings.probe_relocation_iterations {
        let positions: Vec<Vec3> = grid_points.iter().zip(&offsets).map(|(g, o)| *g + *o).collect();
        let d = trace_probe_distances(&bvh, &positions, &dirs, settings.probe_max_ray_distance_m);
        for (p, o) in offsets.iter_mut().enumerate() {
            let next = relocation_step(
                *o,
                &probe_ray_stats(&dirs, &d[p * rays as usize..][..rays as usize]),
                v.grid.spacing_m,
                &settings,
            );
            moved_after_first += (round > 0 && next != *o) as usize;
            moves += (next != *o) as u64;
            *o = next;
        }
    }
    let moved = offsets.iter().filter(|o| **o != Vec3::ZERO).count();
    assert!(moved > 10, "only {moved} probes moved: the case does not exercise relocation");
    for (p, (host, by_hand)) in v.probe_offsets.iter().zip(&offsets).enumerate() {
        assert_eq!(host, by_hand, "probe {p}: offset with settled probes skipped vs every round in full");
    }
    // Every probe traces the first relocation round; after it a probe traces
    // once for each move, in the round after it (the classification round
    // after the fifth): (probes + moves) × rays in all.
    let probes = v.grid.probe_count() as u64;
    let full = (settings.probe_relocation_iterations as u64 + 1) * probes * rays as u64;
    assert_eq!(set.last_init_rays, (probes + moves) * rays as u64, "{moves} moves");
    assert!(set.last_init_rays < full / 3, "{} initialisation rays of {full}", set.last_init_rays);
    eprintln!(
        "{moved} probes moved ({moved_after_first} moves after the first round); {} of {full} rays",
        set.last_init_rays
    );
}
