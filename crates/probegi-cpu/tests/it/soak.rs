//! Long runs: a static field must not drift (10 000 frames in the suite, 50 000 in
//! `scripts/long-checks.sh`; at 2 000 the early window is not yet settled and the
//! drift reads +0.42 % against the 0.5 % bound), and a light toggled for 2 000 frames
//! must leave nothing behind. Tiny volumes (the Cornell box, 3 × 3 × 3 probes,
//! 32 rays) so thousands of frames take seconds; the atlas invariants (finite,
//! non-negative, borders equal to their source texels) are checked as it runs.

use crate::common;

use common::field_energy;
use glam::{UVec3, Vec3};
use probegi_core::ddgi_settings::DdgiVolumeSettings;
use probegi_cpu::{DirectLighting, DirectSettings};
use probegi_field::ddgi_volume::{DdgiVolume, SceneEvent};
use probegi_frame::field_update::VolumeUpdate;
use probegi_scene::builtin::cornell_box;
use probegi_scene::light::PunctualLight;
use probegi_scene::{BvhSettings, BvhTracer};

fn tiny_volume(bounds: (Vec3, Vec3)) -> DdgiVolume {
    let settings = DdgiVolumeSettings { probe_counts: UVec3::splat(3), probe_rays_per_probe: 32, ..Default::default() };
    DdgiVolume::new(settings, bounds)
}

fn assert_atlases_sound(v: &DdgiVolume, frame: u32) {
    assert!(v.irradiance.texels.iter().all(|t| t.is_finite()), "frame {frame}: irradiance not finite");
    assert!(v.distance.texels.iter().all(|t| t.is_finite()), "frame {frame}: distance not finite");
    v.validate();
}

/// The drift soak's length in the test suite.
const SOAK_FRAMES_IN_SUITE: u32 = 10_000;

/// Frames of the drift soak: `PROBEGI_SOAK_FRAMES`, default SOAK_FRAMES_IN_SUITE;
/// `scripts/long-checks.sh` runs 50 000. Energy is compared between the second
/// tenth and the last tenth of the run.
fn soak_frames() -> u32 {
    std::env::var("PROBEGI_SOAK_FRAMES").ok().and_then(|v| v.parse().ok()).unwrap_or(SOAK_FRAMES_IN_SUITE).max(100)
}

#[test]
fn a_static_field_does_not_drift_over_a_long_run() {
    let scene = cornell_box();
    let bvh = BvhTracer::build(&scene.mesh, BvhSettings::default());
    let direct = DirectLighting::new(&scene, &bvh, DirectSettings::default());
    let mut v = tiny_volume(scene.bounds().expect("bounds"));
    let mut passes = Default::default();
    let (mut early, mut late) = (0.0f64, 0.0f64);
    let n = soak_frames();
    let (early_frames, late_frames) = (n / 10..n / 5, n - n / 10..n);
    for f in 0..n {
        v.update(&scene, &bvh, &direct, 17, f, &mut passes);
        if early_frames.contains(&f) {
            early += field_energy(&v);
        } else if late_frames.contains(&f) {
            late += field_energy(&v);
        }
        if f % 500 == 0 {
            assert_atlases_sound(&v, f);
        }
    }
    assert_atlases_sound(&v, n);
    let drift = late / early - 1.0;
    eprintln!(
        "{n} frames: field energy frames {early_frames:?} {:.5}, {late_frames:?} {:.5}: drift {:+.3} %",
        early / early_frames.len() as f64,
        late / late_frames.len() as f64,
        100.0 * drift
    );
    assert!(early > 0.0);
    assert!(drift.abs() < 0.005, "drift {drift}");
}

#[test]
fn a_light_toggled_for_2_000_frames_leaves_no_trace() {
    let dark = cornell_box();
    let mut lit = dark.clone();
    lit.lights.push(PunctualLight::point(Vec3::new(0.5, 1.5, 0.2), Vec3::ONE, 3.0));
    let bvh = BvhTracer::build(&dark.mesh, BvhSettings::default());
    let (direct_dark, direct_lit) = (
        DirectLighting::new(&dark, &bvh, DirectSettings::default()),
        DirectLighting::new(&lit, &bvh, DirectSettings::default()),
    );
    let bounds = dark.bounds().expect("bounds");
    let (mut toggled, mut never) = (tiny_volume(bounds), tiny_volume(bounds));
    let mut passes = Default::default();
    let (mut lit_energy, mut dark_energy) = (0.0f64, f64::INFINITY);
    // Toggled every 20 frames (an irregular 7 extra frames every 5th period) for
    // 1 700 frames, reported as an application would; then 300 frames off.
    let on_at = |f: u32| f < 1_700 && (f / 20 + f / 100).is_multiple_of(2);
    for f in 0..2_000u32 {
        let on = on_at(f);
        if f > 0 && on != on_at(f - 1) {
            toggled.notify_scene_event(SceneEvent::LargeLightChange);
        }
        let (scene, direct) = if on { (&lit, &direct_lit) } else { (&dark, &direct_dark) };
        toggled.update(scene, &bvh, direct, 23, f, &mut passes);
        never.update(&dark, &bvh, &direct_dark, 23, f, &mut passes);
        if f % 100 == 0 {
            assert_atlases_sound(&toggled, f);
        }
        if (1_000..1_700).contains(&f) {
            let e = field_energy(&toggled);
            if on {
                lit_energy = lit_energy.max(e);
            } else {
                dark_energy = dark_energy.min(e);
            }
        }
    }
    assert_atlases_sound(&toggled, 2_000);
    let (a, b) = (field_energy(&toggled), field_energy(&never));
    eprintln!(
        "toggled light: field energy lit up to {lit_energy:.4}, after 300 frames off {a:.5}, never lit {b:.5} ({:+.3} %)",
        100.0 * (a / b - 1.0)
    );
    assert!(lit_energy > 1.5 * b, "the light must matter: {lit_energy} vs {b}");
    assert!((a / b - 1.0).abs() < 0.01, "{a} vs {b}");
}

#[test]
fn a_poisoned_emitter_never_puts_nan_or_inf_into_the_atlases() {
    // Emission 3e38 is finite but overflows to Inf in any product: the shade pass
    // yields non-finite ray radiance, which the blend drops. Loaders refuse such
    // values (`Scene::validate`); the field must survive a scene built past them.
    let mut scene = cornell_box();
    let light = scene.materials.iter_mut().find(|m| m.emissive_factor.max_element() > 0.0).expect("an emitter");
    light.emissive_factor = Vec3::splat(3e38);
    scene.lights.push(PunctualLight::point(Vec3::new(0.0, 1.0, 0.0), Vec3::ONE, 3e38));
    let why = scene.validate().expect_err("absurd emission and intensity are refused on load");
    assert!(why.contains("absurd"), "{why}");
    let bvh = BvhTracer::build(&scene.mesh, BvhSettings::default());
    let direct = DirectLighting::new(&scene, &bvh, DirectSettings::default());
    let mut v = tiny_volume(scene.bounds().expect("bounds"));
    let mut passes = Default::default();
    for f in 0..20 {
        v.update(&scene, &bvh, &direct, 3, f, &mut passes);
        assert_atlases_sound(&v, f);
    }
    // The query over the poisoned field is finite too.
    let e = probegi_core::ddgi_query::irradiance(&v.view(), Vec3::new(0.0, 0.5, 0.0), Vec3::Y, Vec3::Y);
    assert!(e.is_finite(), "{e}");
}
