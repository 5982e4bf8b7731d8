//! `probe_hysteresis_ramp`: a new probe's first blends average its samples
//! equally (hysteresis 1 − 1/(n + 1) for blend n), then the papers' α.

use glam::{UVec3, Vec3};
use probegi_core::ddgi_settings::{DdgiVolumeSettings, ProbeStatesMode};
use probegi_field::ddgi_field_set::ProbeRayBatchKind;
use probegi_field::{DdgiFieldSet, DdgiVolume, ProbeRayHit, UpdateStep};

fn update(set: &mut DdgiFieldSet, frame: u32, sky: f32) {
    let mut step = set.begin_update(1, frame);
    while set.ray_batch().kind == ProbeRayBatchKind::Initialization {
        let misses = vec![ProbeRayHit::MISS; set.ray_batch().len()];
        step = set.submit_hits(&misses).expect("init round");
    }
    assert_eq!(step, UpdateStep::TraceRays);
    let misses = vec![ProbeRayHit::MISS; set.ray_batch().len()];
    set.submit_hits(&misses).expect("hits");
    let radiance = vec![Vec3::splat(sky); set.ray_batch().len()];
    assert_eq!(set.submit_radiance(&radiance), Ok(UpdateStep::Done));
}

#[test]
fn a_new_probe_averages_its_first_samples_then_blends_at_alpha() {
    let settings = |ramp: bool| DdgiVolumeSettings {
        probe_counts: UVec3::new(2, 2, 2),
        probe_rays_per_probe: 16,
        probe_states: ProbeStatesMode::AllActive,
        probe_fast_convergence: false,
        probe_relocation: false,
        probe_hysteresis_ramp: ramp,
        probe_hysteresis_startup_ramp: false,
        ..Default::default()
    };
    let texel = |set: &DdgiFieldSet| {
        let a = &set.volumes()[0].irradiance;
        a.tile(0)[a.interior as usize + 3].x
    };
    let bounds = (Vec3::ZERO, Vec3::ONE);
    let (mut ramp, mut plain) = (
        DdgiFieldSet::single(DdgiVolume::new(settings(true), bounds)),
        DdgiFieldSet::single(DdgiVolume::new(settings(false), bounds)),
    );
    // A black first frame, then a sky of 1 (γ-encoded 1): the running mean of
    // k + 1 samples is k / (k + 1); without the ramp, 1 − α^k.
    for k in 0..60u32 {
        let sky = if k == 0 { 0.0 } else { 1.0 };
        update(&mut ramp, k, sky);
        update(&mut plain, k, sky);
        let alpha: f32 = 0.97;
        let want_plain = 1.0 - alpha.powi(k as i32);
        assert!((texel(&plain) - want_plain).abs() < 1e-4, "frame {k}: {} vs {want_plain}", texel(&plain));
        if k <= 33 {
            let want = k as f32 / (k as f32 + 1.0);
            assert!((texel(&ramp) - want).abs() < 1e-4, "frame {k}: {} vs {want}", texel(&ramp));
        }
    }
    // Past 33 blends the ramp's hysteresis is α again: the gap to 1 shrinks by α a frame.
    let (g59, g_plain) = (1.0 - texel(&ramp), 1.0 - texel(&plain));
    assert!(g59 < 0.25 * g_plain, "the ramp converged faster: {g59} against {g_plain}");
}

/// `probe_hysteresis_startup_ramp` (on by default): the volume's first 33
/// blends average its frames equally, then α; a probe that scrolls in after
/// the start-up blends as the papers do (hysteresis 0, then α), unramped.
#[test]
fn the_start_up_ramp_averages_the_volumes_first_frames_and_no_later_probe() {
    let settings = DdgiVolumeSettings {
        probe_counts: UVec3::splat(4),
        probe_spacing_m: Some(Vec3::ONE),
        volume_tracks_camera: true,
        probe_rays_per_probe: 16,
        probe_states: ProbeStatesMode::AllActive,
        probe_fast_convergence: false,
        probe_relocation: false,
        ..Default::default()
    };
    assert!(settings.probe_hysteresis_startup_ramp && !settings.probe_hysteresis_ramp, "the defaults");
    let bounds = (Vec3::splat(-50.0), Vec3::splat(50.0));
    let mut set = DdgiFieldSet::single(DdgiVolume::placed(settings, bounds, Some(Vec3::ZERO)));
    let texel = |set: &DdgiFieldSet, p: usize| {
        let a = &set.volumes()[0].irradiance;
        a.tile(p)[a.interior as usize + 3].x
    };
    let alpha: f32 = 0.97;
    // A black first frame, then a sky of 1: the running mean of k + 1 samples
    // is k / (k + 1) while the ramp lasts; then the gap to 1 shrinks by α a frame.
    for k in 0..45u32 {
        update(&mut set, k, if k == 0 { 0.0 } else { 1.0 });
        let want = if k <= 33 { k as f32 / (k as f32 + 1.0) } else { 1.0 - (1.0 / 34.0) * alpha.powi(k as i32 - 33) };
        assert!((texel(&set, 0) - want).abs() < 1e-4, "frame {k}: {} vs {want}", texel(&set, 0));
    }
    // One cell along +x: a plane of 16 probes scrolls in, fresh.
    assert_eq!(set.set_tracking_target(Vec3::new(1.0, 0.0, 0.0)), 16);
    let v = &set.volumes()[0];
    let fresh: Vec<usize> = (0..v.grid.probe_count()).filter(|&p| !v.probe_has_history(p)).collect();
    assert_eq!(fresh.len(), 16);
    // Its first blend replaces the tile (sky 0.5, γ-encoded 0.5^(1/5)); its
    // second keeps α of it under a sky of 1, as without any ramp.
    let half = 0.5f32.powf(1.0 / 5.0);
    update(&mut set, 45, 0.5);
    assert!((texel(&set, fresh[0]) - half).abs() < 1e-4, "hysteresis 0 first: {}", texel(&set, fresh[0]));
    update(&mut set, 46, 1.0);
    let want = alpha * half + (1.0 - alpha);
    assert!((texel(&set, fresh[0]) - want).abs() < 1e-4, "then α: {} vs {want}", texel(&set, fresh[0]));
}
