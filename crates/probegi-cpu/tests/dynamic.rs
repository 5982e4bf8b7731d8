//! Dynamic scenes: animated lights. The field must follow a light that moves and
//! give its energy back when it switches off.

use glam::{UVec3, Vec3};
use probegi_core::camera::CameraRays;
use probegi_core::ddgi_settings::DdgiVolumeSettings;
use probegi_core::image::Image;
use probegi_cpu::DirectSettings;
use probegi_cpu::frame_loop::{GiMethod, RenderSettings, render_frames};
use probegi_image::mean_flip_hdr;
use probegi_scene::builtin::cornell_box;
use probegi_scene::light::{LightKeyframe, PunctualLight};
use probegi_scene::{BvhSettings, BvhTracer, Scene};

fn ddgi_render(scene: &Scene, frames: u32, sequence: &mut Vec<Image>) -> Image {
    let bvh = BvhTracer::build(&scene.mesh, BvhSettings::default());
    let camera = CameraRays::new(&scene.camera.expect("camera"), 32, 32);
    let volume = DdgiVolumeSettings { probe_counts: UVec3::splat(4), probe_rays_per_probe: 64, ..Default::default() };
    let settings = RenderSettings {
        width: 32,
        height: 32,
        frames,
        seed: 5,
        gi: GiMethod::Ddgi(Box::new(volume)),
        direct: DirectSettings::default(),
        show_probes: false,
    };
    render_frames(scene, &bvh, &camera, &settings, |_, image| sequence.push(image())).image
}

fn with_light(light: PunctualLight) -> Scene {
    let mut s = cornell_box();
    s.lights.push(light);
    s
}

fn key(frame: f32, position: Option<Vec3>, intensity: Option<f32>) -> LightKeyframe {
    LightKeyframe { frame, position, direction: None, intensity }
}

/// Still lights get one key that changes nothing, so the scene counts as animated
/// and renders exactly as the moving one does: no accumulation, same noise.
fn still(position: Vec3) -> PunctualLight {
    let mut l = PunctualLight::point(position, Vec3::ONE, 2.0);
    l.keyframes = vec![key(0.0, None, Some(2.0))];
    l
}

#[test]
fn the_field_follows_a_moving_light_and_returns_its_energy_when_it_switches_off() {
    let (from, to) = (Vec3::new(-0.6, 1.4, 0.0), Vec3::new(0.6, 1.4, 0.0));
    let mut moving = PunctualLight::point(from, Vec3::ONE, 2.0);
    moving.keyframes = vec![
        key(0.0, Some(from), None),
        key(20.0, Some(to), None),
        key(150.0, None, Some(2.0)),
        key(151.0, None, Some(0.0)),
    ];
    let scene = with_light(moving);
    assert!(scene.is_animated());
    let mut frames = Vec::new();
    let last = ddgi_render(&scene, 300, &mut frames);
    assert_eq!(frames.len(), 300);
    assert_eq!(frames[299].pixels, last.pixels, "the last sequence frame is the final image");

    let mut at_rest = Vec::new();
    ddgi_render(&with_light(still(to)), 150, &mut at_rest);
    let mut off = still(to);
    off.intensity = 0.0;
    off.keyframes[0].intensity = Some(0.0);
    let dark = ddgi_render(&with_light(off), 150, &mut Vec::new());
    // At rest at `to` since frame 20: by frame 149 the field matches a still light there.
    let settled = mean_flip_hdr(&at_rest[149], &frames[149]).expect("size");
    // Switched off at frame 151: by frame 299 it matches the box without the light.
    let returned = mean_flip_hdr(&dark, &last).expect("size");
    // Mid-sweep the image differs from the light at rest.
    let mid_sweep = mean_flip_hdr(&at_rest[10], &frames[10]).expect("size");
    eprintln!("means {} {} / {} {}", at_rest[149].mean(), frames[149].mean(), dark.mean(), last.mean());
    eprintln!("FLIP: settled {settled:.4}, light off {returned:.4}, mid-sweep {mid_sweep:.4}");
    // Measured: FLIP 0.050 settled, 0.127 light off, 0.41 mid-sweep (32², one frame's
    // direct noise each). Means: within 1 % at rest; 6–10 % *below* the box without
    // the light after it switched off (not yet explained, see the issue-6 note).
    let rel = |a: Vec3, b: Vec3| ((a - b).abs() / b).max_element();
    assert!(rel(frames[149].mean(), at_rest[149].mean()) < 0.03, "settled means");
    assert!(rel(last.mean(), dark.mean()) < 0.12, "means after the light switched off");
    assert!(settled < 0.08 && returned < 0.16, "{settled} {returned}");
    assert!(mid_sweep > 5.0 * settled, "{mid_sweep} vs {settled}");
}
