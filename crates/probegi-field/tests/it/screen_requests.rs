//! The screen scheme (`probe_states = screen`, issue 32 item 4) through the
//! seam: requested probes trace every frame for their countdown, the rest
//! once per idle interval in an interleaved phase, and a probe's blend
//! stands for the frames since its last, so idle and requested probes
//! converge alike in wall-clock frames.

use glam::{UVec3, Vec3};
use probegi_core::ddgi_settings::{DdgiVolumeSettings, ProbeStatesMode};
use probegi_core::probe_classification::ProbeState;
use probegi_field::ddgi_field_set::ProbeRayBatchKind;
use probegi_field::{DdgiFieldSet, DdgiVolume, ProbeRayHit, UpdateStep};

const REQUEST_FRAMES: u32 = 5;
const IDLE_INTERVAL: u32 = 4;

fn screen_set() -> DdgiFieldSet {
    let s = DdgiVolumeSettings {
        probe_counts: UVec3::new(6, 3, 5),
        probe_rays_per_probe: 16,
        probe_states: ProbeStatesMode::Screen,
        probe_screen_request_frames: REQUEST_FRAMES,
        probe_screen_idle_interval_frames: IDLE_INTERVAL,
        probe_fast_convergence: false,
        probe_relocation: false,
        // The α^f arithmetic below counts from frame 0: no start-up ramp.
        probe_hysteresis_startup_ramp: false,
        ..Default::default()
    };
    DdgiFieldSet::single(DdgiVolume::new(s, (Vec3::ZERO, Vec3::new(6.0, 3.0, 5.0))))
}

/// One update where every ray misses and reads `sky`; returns the probes
/// that traced.
fn update(set: &mut DdgiFieldSet, frame: u32, sky: f32) -> Vec<u32> {
    let mut step = set.begin_update(1, frame);
    while set.ray_batch().kind == ProbeRayBatchKind::Initialization {
        let misses = vec![ProbeRayHit::MISS; set.ray_batch().len()];
        step = set.submit_hits(&misses).expect("init round");
    }
    assert_eq!(step, UpdateStep::TraceRays);
    let traced: Vec<u32> = set.ray_batch().probes.iter().map(|p| p.probe).collect();
    let misses = vec![ProbeRayHit::MISS; set.ray_batch().len()];
    assert_eq!(set.submit_hits(&misses), Ok(UpdateStep::ShadeRays));
    let radiance = vec![Vec3::splat(sky); set.ray_batch().len()];
    assert_eq!(set.submit_radiance(&radiance), Ok(UpdateStep::Done));
    traced
}

/// The γ-encoded irradiance of an interior texel of probe `p`.
fn texel(set: &DdgiFieldSet, p: usize) -> f32 {
    let atlas = &set.volumes()[0].irradiance;
    let side = atlas.interior as usize + 2;
    atlas.tile(p)[side + 1].x
}

#[test]
fn requested_probes_trace_every_frame_and_idle_ones_once_per_interval() {
    let mut set = screen_set();
    let probes = set.probe_count();
    // Frame 0: every probe traces for its first blend.
    assert_eq!(update(&mut set, 0, 0.0).len(), probes);
    // A camera pixel at (2.5, 1.2, 2.5) facing +y, seen from above, reads one cage.
    let point = (Vec3::new(2.5, 1.2, 2.5), Vec3::Y, Vec3::Y);
    let words = set.probe_requests_at(&[point]);
    let requested: Vec<u32> = (0..probes as u32).filter(|&b| words[b as usize / 32] >> (b % 32) & 1 != 0).collect();
    assert_eq!(requested.len(), 8, "one cage");
    set.submit_probe_requests(&words).expect("layout");
    assert!(set.submit_probe_requests(&[]).is_err(), "a bitset of the wrong length is refused");

    let mut traces = vec![0u32; probes];
    let mut traced_at = vec![0u32; probes];
    for frame in 1..=IDLE_INTERVAL {
        let traced = update(&mut set, frame, 1.0);
        assert!(requested.iter().all(|p| traced.contains(p)), "frame {frame}: requested probes trace");
        let idle = traced.len() - requested.len();
        // (x + 2y) mod 4 over a 6×3 lattice (4z drops out for interval 4): 15–25
        // of the 82 idle probes a frame.
        assert!((15..=25).contains(&idle), "frame {frame}: {idle} idle probes traced");
        traced.iter().for_each(|&p| traces[p as usize] += 1);
        traced.iter().for_each(|&p| traced_at[p as usize] = frame);
    }
    for (p, &n) in traces.iter().enumerate() {
        let want = if requested.contains(&(p as u32)) { IDLE_INTERVAL } else { 1 };
        assert_eq!(n, want, "probe {p} traced {n} times in {IDLE_INTERVAL} frames");
    }
    // Frames of sky 1 after a black start: a requested probe blended every
    // frame at α, an idle probe once, in frame f, at α^f, standing for the f
    // frames since frame 0: both hold 1 − α^f (γ-encoded; 1 encodes to 1).
    let alpha: f32 = DdgiVolumeSettings::default().probe_hysteresis;
    for (p, &f) in traced_at.iter().enumerate() {
        let want = 1.0 - alpha.powi(f as i32);
        assert!((texel(&set, p) - want).abs() < 1e-4, "probe {p}: {} against {want}", texel(&set, p));
    }
    assert!(
        traced_at.iter().filter(|f| **f == IDLE_INTERVAL).count() > requested.len(),
        "idle probes in the last phase"
    );
    // The countdown runs out without new requests: the probes turn Idle.
    let v = &set.volumes()[0];
    assert_eq!(v.probe_states[requested[0] as usize], ProbeState::Requested);
    assert_eq!(v.probe_request_countdown(requested[0] as usize), REQUEST_FRAMES - IDLE_INTERVAL + 1);
    for frame in IDLE_INTERVAL + 1..=REQUEST_FRAMES + 1 {
        update(&mut set, frame, 1.0);
    }
    let v = &set.volumes()[0];
    assert!(requested.iter().all(|&p| v.probe_states[p as usize] == ProbeState::Idle));
    assert_eq!(v.state_counts().get("idle"), Some(&probes));
}

#[test]
fn other_schemes_ignore_requests() {
    let mut set = screen_set();
    set.volumes_mut()[0].settings.probe_states = ProbeStatesMode::AllActive;
    assert!(!set.wants_probe_requests());
    let probes = set.probe_count();
    update(&mut set, 0, 0.0);
    set.request_probes_at(&[(Vec3::new(2.5, 1.2, 2.5), Vec3::Y, Vec3::Y)]);
    assert_eq!(update(&mut set, 1, 1.0).len(), probes);
    assert!(set.volumes()[0].probe_states.iter().all(|s| *s == ProbeState::Active));
}

/// Two tracking cascades under the screen scheme, every probe blended once
/// under a sky of 1; with `seeding`, the probes the fine window scrolls in
/// take their tiles from the coarse one.
fn scrolled_cascades(seeding: bool) -> (DdgiFieldSet, Vec<usize>) {
    let cascade = |spacing: f32| DdgiVolumeSettings {
        probe_counts: UVec3::splat(4),
        probe_spacing_m: Some(Vec3::splat(spacing)),
        volume_tracks_camera: true,
        probe_rays_per_probe: 16,
        probe_states: ProbeStatesMode::Screen,
        probe_fast_convergence: false,
        probe_relocation: false,
        probe_seeding: seeding,
        ..Default::default()
    };
    let bounds = (Vec3::splat(-50.0), Vec3::splat(50.0));
    let volumes = vec![
        DdgiVolume::placed(cascade(1.0), bounds, Some(Vec3::ZERO)),
        DdgiVolume::placed(cascade(4.0), bounds, Some(Vec3::ZERO)),
    ];
    let mut set =
        DdgiFieldSet::from_volumes(volumes, probegi_core::ddgi_settings::VolumeBlending::Cascades, Some(Vec3::ZERO));
    for frame in 0..3 {
        update(&mut set, frame, 1.0);
    }
    // One fine cell along +x: a plane of 16 probes scrolls in; the coarse window stays.
    assert_eq!(set.set_tracking_target(Vec3::new(1.0, 0.0, 0.0)), 16);
    let fine = &set.volumes()[0];
    let reset: Vec<usize> = (0..fine.grid.probe_count()).filter(|&p| !fine.probe_has_history(p)).collect();
    assert_eq!(reset.len(), 16);
    (set, reset)
}

#[test]
fn seeded_probes_are_read_at_once_and_wait_for_their_phase() {
    let (mut seeded, reset) = scrolled_cascades(true);
    let (mut plain, _) = scrolled_cascades(false);
    // Frame 3: without seeds every new probe traces for its first blend; seeded
    // ones wait for their idle phase (interval 8: a few of them a frame).
    let fine_traces =
        |traced: &[(u32, u32)]| traced.iter().filter(|(v, p)| *v == 0 && reset.contains(&(*p as usize))).count();
    let traced = |set: &mut DdgiFieldSet| {
        let mut step = set.begin_update(1, 3);
        while set.ray_batch().kind == ProbeRayBatchKind::Initialization {
            let misses = vec![ProbeRayHit::MISS; set.ray_batch().len()];
            step = set.submit_hits(&misses).expect("init round");
        }
        assert_eq!(step, UpdateStep::TraceRays);
        let t: Vec<(u32, u32)> = set.ray_batch().probes.iter().map(|p| (p.volume, p.probe)).collect();
        let misses = vec![ProbeRayHit::MISS; set.ray_batch().len()];
        set.submit_hits(&misses).expect("hits");
        let radiance = vec![Vec3::ONE; set.ray_batch().len()];
        set.submit_radiance(&radiance).expect("blend");
        t
    };
    let (t_plain, t_seeded) = (traced(&mut plain), traced(&mut seeded));
    assert_eq!(fine_traces(&t_plain), 16, "unseeded new probes trace at once");
    let waiting = 16 - fine_traces(&t_seeded);
    assert!(waiting >= 8, "{waiting} of 16 seeded probes wait for their phase");
    // Those that waited are readable with the coarse cascade's light (sky 1, encoded 1).
    let fine = &seeded.volumes()[0];
    for &p in reset.iter().filter(|&&p| !t_seeded.contains(&(0, p as u32))) {
        assert!(fine.probe_usable(p), "seeded probe {p} is readable before its first blend");
        // Sky 1 blended from frame 0 with hysteresis 0 first: every coarse texel is 1.
        assert!(
            (texel(&seeded, p) - 1.0).abs() < 1e-3,
            "seeded probe {p} holds the coarse light: {}",
            texel(&seeded, p)
        );
    }
    fine.validate();
}

/// With a shadowing field, whose occlusion maps blend from a probe's
/// surfels of the frame before, an Idle probe traces in pairs of frames.
#[test]
fn idle_probes_trace_in_pairs_with_a_shadowing_field() {
    let mut set = screen_set();
    set.volumes_mut()[0] = DdgiVolume::new(
        DdgiVolumeSettings { shadow_field: true, ..set.volumes()[0].settings.clone() },
        (Vec3::ZERO, Vec3::new(6.0, 3.0, 5.0)),
    );
    let probes = set.probe_count();
    update(&mut set, 0, 0.0);
    let mut traced_in = vec![Vec::new(); probes];
    for frame in 1..=2 * IDLE_INTERVAL + 1 {
        update(&mut set, frame, 1.0).iter().for_each(|&p| traced_in[p as usize].push(frame));
    }
    for (p, frames) in traced_in.iter().enumerate() {
        // Two traces per interval, each next to another.
        let inside: Vec<u32> = frames.iter().copied().filter(|f| (2..=2 * IDLE_INTERVAL).contains(f)).collect();
        assert!((3..=4).contains(&inside.len()), "probe {p}: traced in {frames:?}");
        for f in inside {
            assert!(
                frames.contains(&(f - 1)) || frames.contains(&(f + 1)),
                "probe {p}: traced in {frames:?}, not in pairs"
            );
        }
    }
}
