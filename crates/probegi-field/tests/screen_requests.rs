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
