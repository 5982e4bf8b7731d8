//! `ddgi_volume::steady_frames`: a still field's update keeps the last plan,
//! and gives the batches, blend plans and volumes the full plan gives, frame
//! by frame, through scene events, woken probes, a settings change, probes
//! moved through public fields (in place, and in a clone put in the volume's
//! place), a window that scrolls, a state changed through a public field and
//! an update left unfinished. The frame counters a kept plan leaves owing read and settle
//! as the full plan's.

use glam::{UVec3, Vec3};
use probegi_core::ddgi_settings::{DdgiVolumeSettings, ProbeStatesMode};
use probegi_core::probe_classification::ProbeState;
use probegi_field::ddgi_field_set::ProbeRayBatchKind;
use probegi_field::{DdgiFieldSet, DdgiVolume, ProbeRayHit, SceneEvent, UpdateStep};

/// Two volumes over a 4 m box: a tracking all-active window and a jcgt grid
/// (every init ray a miss, so its probes sleep until woken).
fn two_volumes(keep_plans: bool) -> DdgiFieldSet {
    let window = DdgiVolumeSettings {
        probe_counts: UVec3::new(4, 3, 4),
        probe_rays_per_probe: 24,
        probe_states: ProbeStatesMode::AllActive,
        volume_tracks_camera: true,
        probe_spacing_m: Some(Vec3::splat(0.5)),
        ..Default::default()
    };
    let grid = DdgiVolumeSettings {
        probe_counts: UVec3::new(5, 2, 4),
        probe_rays_per_probe: 32,
        probe_states: ProbeStatesMode::Jcgt,
        ..Default::default()
    };
    let bounds = (Vec3::ZERO, Vec3::splat(4.0));
    let camera = Vec3::splat(2.0);
    let volumes = vec![DdgiVolume::placed(window, bounds, Some(camera)), DdgiVolume::new(grid, bounds)];
    let mut set = DdgiFieldSet::from_volumes(volumes, Default::default(), Some(camera));
    set.set_update_rays_on_device(true);
    set.set_steady_plans(keep_plans);
    set
}

/// One frame's batch and blend plan, printed (every field bit for bit but
/// their identities), and the identities: each volume's ray records' and
/// blend plan's.
struct Update {
    printed: String,
    record_ids: Vec<Option<u64>>,
    blend_ids: Vec<Option<u64>>,
}

/// One update as a device that keeps the hits and atlases drives it.
fn device_update(set: &mut DdgiFieldSet, frame: u32) -> Update {
    set.begin_update(9, frame);
    while set.ray_batch().kind == ProbeRayBatchKind::Initialization {
        let misses = vec![ProbeRayHit::MISS; set.ray_batch().len()];
        set.submit_hits(&misses).expect("init round");
    }
    let b = set.ray_batch();
    let generated: Vec<_> =
        b.generated.iter().map(|g| (g.volume, g.first_probe, g.probe_count, g.rays_per_probe, g.rotation)).collect();
    let batch = format!(
        "{} {:?} {:?} {generated:?} {:?} {:?}",
        b.len(),
        b.probes,
        b.probe_origins_m,
        b.expanded().directions,
        set.hits_needed_on_host()
    );
    let record_ids = b.generated.iter().map(|g| g.plan_id).collect();
    assert_eq!(set.submit_device_hits(&[]), Ok(UpdateStep::ShadeRays));
    let mut plan = set.device_blend_plan().expect("plan");
    let blend_ids = plan.iter().map(|p| p.probe_blend_id).collect();
    plan.iter_mut().for_each(|p| p.probe_blend_id = None);
    let plan = format!("{:?} {plan:?}", set.ray_batch().probe_needs_radiance);
    assert_eq!(set.submit_device_blend(&[]), Ok(UpdateStep::Done));
    Update { printed: format!("{batch}\n{plan}"), record_ids, blend_ids }
}

/// Per member of `set`'s view, its rows' identity and its rows (offsets bit
/// for bit, usable flags, fallback table).
fn rows_and_ids(set: &DdgiFieldSet) -> Vec<(Option<u64>, String)> {
    let view = set.view();
    let row = |f: &probegi_core::ddgi_query::DdgiFieldView<'_>| {
        let offsets: Vec<[u32; 3]> = f.probe_offsets_m.iter().map(|o| o.to_array().map(f32::to_bits)).collect();
        format!("{offsets:?} {:?} {:?}", f.probe_usable, f.probe_fallback)
    };
    view.members.iter().map(|m| (m.field.probe_rows_id, row(&m.field))).collect()
}

#[test]
fn a_kept_plan_gives_the_full_plans_batches_and_volumes_through_changes() {
    let (mut kept, mut full) = (two_volumes(true), two_volumes(false));
    let (mut kept_frames, mut last) = (Vec::new(), None);
    let (mut rows_before, mut rows_changed) = (rows_and_ids(&kept), 0);
    for frame in 0..24u32 {
        for set in [&mut kept, &mut full] {
            match frame {
                5 => set.notify_scene_event(SceneEvent::LargeLightChange),
                // Probes of the jcgt grid wake (Newly Awake, then Awake).
                8 => assert!(set.wake_probes_near(&[(Vec3::new(1.0, 0.5, 1.0), Vec3::new(1.5, 1.0, 1.5))]) > 0),
                12 => set.volumes_mut()[1].settings.probe_hysteresis = 0.9,
                // A probe moved through the volume's public offsets and positions.
                13 => {
                    let v = &mut set.volumes_mut()[1];
                    v.probe_offsets[3] += Vec3::new(0.0, 0.1, 0.0);
                    v.probe_positions[3] += Vec3::new(0.0, 0.1, 0.0);
                }
                // A clone with another probe moved, put in the volume's place.
                14 => {
                    let mut v = set.volumes()[1].clone();
                    v.probe_offsets[4] += Vec3::new(0.1, 0.0, 0.0);
                    v.probe_positions[4] += Vec3::new(0.1, 0.0, 0.0);
                    set.volumes_mut()[1] = v;
                }
                // The window scrolls a plane in (initialisation rounds for it).
                15 => assert!(set.set_tracking_target(Vec3::new(3.2, 2.0, 2.0)) > 0),
                // An Awake probe put to sleep through the volume's public states.
                17 => {
                    let states = &mut set.volumes_mut()[1].probe_states;
                    let awake = states.iter().position(|s| *s == ProbeState::Awake).expect("an awake probe");
                    states[awake] = ProbeState::Sleeping;
                }
                // An update begun and left unfinished: its plan's blend never ran.
                18 => {
                    set.begin_update(9, frame);
                }
                // The per-probe ramp reads every probe's blend count: none is kept from here.
                20 => set.volumes_mut().iter_mut().for_each(|v| v.settings.probe_hysteresis_ramp = true),
                _ => {}
            }
        }
        let (a, b) = (device_update(&mut kept, frame), device_update(&mut full, frame));
        // The rows' identities a set's view gives: one identity, one set of rows.
        let rows_now = rows_and_ids(&kept);
        for (now, before) in rows_now.iter().zip(&rows_before) {
            assert!(now.0 != before.0 || now.1 == before.1, "frame {frame}: rows changed under one identity");
            rows_changed += (now.1 != before.1) as u32;
        }
        rows_before = rows_now;
        assert_eq!(a.printed, b.printed, "frame {frame}: batch and blend plan");
        // The frame counters a kept plan owes read as the full plan's, and
        // settle to them.
        for (k, f) in kept.volumes().iter().zip(full.volumes()) {
            let since =
                |v: &DdgiVolume| (0..v.grid.probe_count()).map(|p| v.probe_frames_since_traced(p)).collect::<Vec<_>>();
            assert_eq!(since(k), since(f), "frame {frame}: frames since traced");
        }
        let mut settled = kept.volumes().to_vec();
        settled.iter_mut().for_each(DdgiVolume::settle_steady_counts);
        assert_eq!(format!("{settled:?}"), format!("{:?}", full.volumes()), "frame {frame}: volumes");
        assert!(!full.update_kept_plan());
        // A full plan's records and blend plan are new; a kept one's keep their ids.
        assert!(b.blend_ids.iter().all(|id| id.is_none()));
        let last_ids = last.replace((a.record_ids.clone(), a.blend_ids.clone()));
        if kept.update_kept_plan() {
            kept_frames.push(frame);
            assert!(a.blend_ids.iter().all(|id| id.is_some()), "frame {frame}");
            let (records, blends) = last_ids.expect("a frame before");
            assert_eq!(a.record_ids, records, "frame {frame}");
            assert!(blends.iter().all(|id| id.is_none()) || blends == a.blend_ids, "frame {frame}");
        } else {
            assert!(a.blend_ids.iter().all(|id| id.is_none()), "frame {frame}");
            assert!(last_ids.is_none_or(|(records, _)| records.iter().all(|r| !a.record_ids.contains(r))));
        }
    }
    // Frames 0 and 1 are first blends (a history begins); 8 and 9 wake probes
    // (Newly Awake, then Awake), 12 changes a setting, 13 moves a probe, 14
    // puts a clone with a moved probe in place, 15 and 16 scroll and give the
    // scrolled-in probes their first blend, 17 changes a state, 18 follows an
    // unfinished update; from 20 the ramp is on.
    let want: Vec<u32> = (2..20).filter(|f| ![8, 9, 12, 13, 14, 15, 16, 17, 18].contains(f)).collect();
    assert_eq!(kept_frames, want);
    // The rows changed (first blends, the moved probe, the scroll), each time
    // under a new identity.
    assert!(rows_changed >= 3, "{rows_changed}");
    assert!(kept.volumes()[1].state_counts().get("awake").is_some_and(|n| *n > 0));
}

#[test]
fn a_kept_plan_needs_a_device_that_makes_the_rays() {
    // A host that traces from per-ray arrays plans every frame in full.
    let mut set = two_volumes(true);
    set.set_update_rays_on_device(false);
    for frame in 0..4 {
        let mut step = set.begin_update(9, frame);
        while step == UpdateStep::TraceRays {
            let misses = vec![ProbeRayHit::MISS; set.ray_batch().len()];
            step = set.submit_hits(&misses).expect("hits");
        }
        assert!(!set.update_kept_plan());
        let radiance = vec![Vec3::ONE; set.ray_batch().len()];
        assert_eq!(set.submit_radiance(&radiance), Ok(UpdateStep::Done));
    }
}

/// A usage-scheme grid over a 4 m box, and the counts a device would read
/// back for `batch` (`lag` batches later): per probe entry, by probe parity
/// and batch, so states move every few frames (Alive, Usage Sleeping and
/// Dead all come and go).
fn usage_grid(keep_plans: bool) -> DdgiFieldSet {
    let grid = DdgiVolumeSettings {
        probe_counts: UVec3::new(5, 3, 4),
        probe_rays_per_probe: 16,
        probe_states: ProbeStatesMode::Usage,
        probe_alive_min_frames: 2,
        probe_sleeping_update_interval: 3,
        ..Default::default()
    };
    let mut set = DdgiFieldSet::single(DdgiVolume::new(grid, (Vec3::ZERO, Vec3::splat(4.0))));
    set.set_update_rays_on_device(true);
    set.set_steady_plans(keep_plans);
    set
}

fn usage_counts(batch: u64, probes: usize) -> probegi_field::DeviceUsageCounts {
    let counts = (0..probes as u64)
        .map(|k| match (k + batch / 2) % 5 {
            0 => (-6, 10, 8),   // Dead
            1 | 2 => (3, 4, 0), // Alive
            _ => (0, 0, 0),     // Usage Sleeping
        })
        .collect();
    probegi_field::DeviceUsageCounts { batch, counts }
}

/// As [`device_update`] under the usage scheme, with the device's counts
/// handed over `lag` batches late (`on_device`: those still there).
fn usage_update(
    set: &mut DdgiFieldSet,
    frame: u32,
    on_device: &mut std::collections::VecDeque<probegi_field::DeviceUsageCounts>,
) -> (String, Vec<Option<u64>>, u64) {
    set.begin_update(9, frame);
    while set.ray_batch().kind == ProbeRayBatchKind::Initialization {
        let misses = vec![ProbeRayHit::MISS; set.ray_batch().len()];
        set.submit_hits(&misses).expect("init round");
    }
    let request = set.device_usage_request().expect("the usage scheme asks for counts");
    on_device.push_back(usage_counts(request.batch, set.ray_batch().probes.len()));
    let due: Vec<_> = match on_device.len() > request.lag_updates as usize {
        true => on_device.pop_front().into_iter().collect(),
        false => vec![],
    };
    let b = set.ray_batch();
    let generated: Vec<_> =
        b.generated.iter().map(|g| (g.volume, g.first_probe, g.probe_count, g.rays_per_probe, g.rotation)).collect();
    let batch =
        format!("{} {:?} {:?} {generated:?} {:?}", b.len(), b.probes, b.probe_origins_m, b.expanded().directions);
    let record_ids = b.generated.iter().map(|g| g.plan_id).collect();
    assert_eq!(set.submit_device_hits(&due), Ok(UpdateStep::ShadeRays));
    let radiance_id = set.ray_batch().probe_needs_radiance_id();
    let plan = set.device_blend_plan().expect("plan");
    let plan = format!("{:?} {plan:?}", set.ray_batch().probe_needs_radiance);
    assert_eq!(set.submit_device_blend(&[]), Ok(UpdateStep::Done));
    (format!("{batch}\n{plan}"), record_ids, radiance_id)
}

#[test]
fn a_usage_schemes_kept_trace_plan_gives_the_full_plans_batches_states_and_blends() {
    // Under the usage scheme every probe traces every frame while the states
    // move with the counts: the trace plan is kept (the batch's probes and
    // records' identities), the rest planned in full, and everything equals
    // a set that plans every frame in full, through moving states, a setting
    // changed, a probe moved, an update left unfinished and a frame in which
    // not every probe traces (one put Off through the public states).
    let (mut kept, mut full) = (usage_grid(true), usage_grid(false));
    let mut devices = [std::collections::VecDeque::new(), std::collections::VecDeque::new()];
    // The last frame's record identities, radiance flags and their identity.
    type Last = Option<(Vec<Option<u64>>, String, u64)>;
    let (mut kept_frames, mut last): (Vec<u32>, Last) = (Vec::new(), None);
    let mut states_seen = std::collections::BTreeSet::new();
    for frame in 0..30u32 {
        for set in [&mut kept, &mut full] {
            match frame {
                10 => set.volumes_mut()[0].settings.probe_hysteresis = 0.9,
                13 => {
                    let v = &mut set.volumes_mut()[0];
                    v.probe_offsets[3] += Vec3::new(0.0, 0.1, 0.0);
                    v.probe_positions[3] += Vec3::new(0.0, 0.1, 0.0);
                }
                16 => {
                    set.begin_update(9, frame);
                }
                20 => set.volumes_mut()[0].probe_states[5] = ProbeState::Off,
                _ => {}
            }
        }
        let [dk, df] = &mut devices;
        let (a, a_ids, a_radiance) = usage_update(&mut kept, frame, dk);
        let (b, _, _) = usage_update(&mut full, frame, df);
        assert_eq!(a, b, "frame {frame}: batch and blend plan");
        assert_eq!(format!("{:?}", kept.volumes()), format!("{:?}", full.volumes()), "frame {frame}: volumes");
        assert!(!full.update_kept_trace_plan() && !kept.update_kept_plan());
        states_seen.extend(kept.volumes()[0].state_counts().into_keys());
        let flags = format!("{:?}", kept.ray_batch().probe_needs_radiance);
        let before = last.replace((a_ids.clone(), flags.clone(), a_radiance));
        if kept.update_kept_trace_plan() {
            kept_frames.push(frame);
            let (ids, last_flags, last_radiance) = before.expect("a frame before");
            assert_eq!(a_ids, ids, "frame {frame}: a kept trace keeps its records' identities");
            // The flags' identity: the same where the flags repeat, new where not.
            assert_eq!(flags == last_flags, a_radiance == last_radiance, "frame {frame}: radiance flags' identity");
        } else if let Some((ids, _, last_radiance)) = before {
            assert!(ids.iter().all(|r| !a_ids.contains(r)), "frame {frame}: a full plan's records are new");
            assert_ne!(a_radiance, last_radiance, "frame {frame}");
        }
    }
    // Frame 0 initialises and plans; 10 changes a setting, 13 moves a probe,
    // 16 follows an unfinished update; at 20 a probe is Off, so it traces
    // not, and the counts traced before (two batches late) classify it
    // again in the same update: 21 plans it back in, and 22 keeps that.
    let want: Vec<u32> = (1..30).filter(|f| ![10, 13, 16, 20, 21].contains(f)).collect();
    assert_eq!(kept_frames, want);
    for state in ["alive", "sleeping", "dead"] {
        assert!(states_seen.iter().any(|s| s.contains(state)), "{state} never seen: {states_seen:?}");
    }
}
