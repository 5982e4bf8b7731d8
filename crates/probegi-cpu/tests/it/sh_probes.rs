//! The screen-space SH probe method (seed 001) against known answers, the
//! path-traced reference and its own documented limits.

use std::path::PathBuf;

use glam::Vec3;
use probegi_core::camera::{Camera, CameraRays};
use probegi_core::image::Image;
use probegi_core::sh_settings::ShProbeSettings;
use probegi_frame::frame_loop::{GiMethod, RenderOutput, RenderSettings, render_frames};
use probegi_image::{LoadedImage, mean_flip_hdr, read_image};
use probegi_scene::builtin::{cornell_box, furnace_box};
use probegi_scene::{BvhSettings, BvhTracer, Scene};

fn render_with(scene: &Scene, camera: &Camera, size: u32, frames: u32, gi: GiMethod, seed: u64) -> RenderOutput {
    let bvh = BvhTracer::build(&scene.mesh, BvhSettings::default());
    let rays = CameraRays::new(camera, size, size);
    let settings = RenderSettings { width: size, height: size, frames, seed, gi, ..Default::default() };
    render_frames(scene, &bvh, &rays, &settings, |_, _| {})
}

fn render(scene: &Scene, size: u32, frames: u32, gi: GiMethod) -> RenderOutput {
    render_with(scene, &scene.camera.expect("camera"), size, frames, gi, 11)
}

fn sh(settings: ShProbeSettings) -> GiMethod {
    GiMethod::Sh(Box::new(settings))
}

/// The default: emitters through the camera pass's own light sampling; probes carry bounced light.
fn no_injection() -> ShProbeSettings {
    let s = ShProbeSettings::default();
    assert!(!s.sh_light_injection);
    s
}

fn expected_cornell_64() -> Image {
    let path = PathBuf::from(env!("CARGO_MANIFEST_DIR")).join("tests/expected/cornell-box-64.exr");
    match read_image(&path).expect("expected image") {
        LoadedImage::Hdr(img) => img,
        LoadedImage::Srgb8 { .. } => panic!("expected an EXR"),
    }
}

fn flip(a: &Image, b: &Image) -> f32 {
    mean_flip_hdr(a, b).expect("same size")
}

#[test]
fn furnace_box_approaches_le_over_one_minus_rho_as_the_camera_sees_more() {
    // Every surface emits 1 with albedo 0.5: L = 2 everywhere. Probes learn only the
    // directions the screen samples come from (seed 001 §7.3), so a camera that sees
    // more of the box gets closer to 2; none may overshoot.
    let scene = furnace_box(0.5, 1.0);
    let mut means = Vec::new();
    for fov_y_deg in [90.0, 150.0] {
        let camera = Camera { fov_y_deg, ..scene.camera.expect("camera") };
        let out = render_with(&scene, &camera, 24, 120, sh(no_injection()), 11);
        assert!(out.image.first_invalid_pixel().is_none());
        let mean = out.image.mean().x;
        eprintln!("furnace SH mean with a {fov_y_deg}° camera: {mean}");
        means.push(mean);
    }
    assert!(means[0] > 1.7 && means[0] < 2.0, "{means:?}");
    // Measured 1.80 and 1.83: the probes just outside the walls, which the trilinear
    // cage of every wall point includes, see only the far walls through the near one.
    assert!(means[1] > means[0] && means[1] < 2.0, "{means:?}");
}

#[test]
fn cornell_box_sh_is_far_closer_to_the_reference_than_direct_only() {
    let reference = expected_cornell_64();
    let scene = cornell_box();
    let direct = flip(&reference, &render(&scene, 64, 16, GiMethod::None).image);
    let out = render(&scene, 64, 100, sh(no_injection()));
    let f = flip(&reference, &out.image);
    eprintln!("Cornell 64²: SH {f:.4}, direct only {direct:.4}");
    assert!(f < 0.22, "SH FLIP {f}");
    assert!(f < 0.5 * direct, "SH {f} against direct-only {direct}");
    let p = out.sh.expect("probes");
    // 20×20 screen samples; the few on the open front see nothing and are dropped.
    assert!((360..=400).contains(&p.last_sample_count), "{}", p.last_sample_count);
    for c in &p.cascades.cascades {
        assert!(c.coeffs.iter().all(|s| s.is_finite()));
    }
}

#[test]
fn light_injection_lights_the_box_with_its_emitter_alone() {
    // Paper mode: the camera pass has no area-light sampling, so every bit of light on
    // the walls comes through the probes. Measured: 1.6–1.7 × the reference mean, the
    // L2 ringing of a small bright emitter and the trilinear blend of probes whose
    // irradiance falls as 1/d² near it (see the issue-5 note). The bound catches a
    // lost or runaway field.
    let reference = expected_cornell_64().mean();
    let scene = cornell_box();
    let on =
        render(&scene, 64, 100, sh(ShProbeSettings { sh_light_injection: true, ..Default::default() })).image.mean();
    let ratio = on / reference;
    eprintln!("Cornell mean with injection / reference = {ratio}");
    assert!(ratio.max_element() < 2.0 && ratio.min_element() > 0.75, "{ratio}");
}

#[test]
fn occlusion_setting_traces_a_ray_per_sample_and_probe() {
    let scene = cornell_box();
    let cheap = render(&scene, 32, 2, sh(no_injection()));
    let occl = render(&scene, 32, 2, sh(ShProbeSettings { sh_occlusion: true, ..no_injection() }));
    let probes = cheap.stats.probes.expect("probes") as u64;
    let extra = occl.stats.rays_traced - cheap.stats.rays_traced;
    // Samples facing away from a probe trace nothing; most of 400 face most probes.
    assert!(extra > probes * 400 / 4 && extra <= 2 * probes * 400, "{extra} extra rays for {probes} probes");
}

/// Probe irradiance at a floor point near the red wall, from a render with `camera`.
fn floor_irradiance_near_red_wall(camera: &Camera) -> Vec3 {
    let scene = cornell_box();
    let settings = ShProbeSettings { sh_probe_jitter: true, ..no_injection() };
    let out = render_with(&scene, camera, 48, 80, sh(settings), 3);
    out.sh.expect("probes").cascades.irradiance(Vec3::new(-0.7, 0.01, 0.2), Vec3::Y)
}

#[test]
fn bounce_light_from_off_screen_surfaces_fades() {
    // Seed 001 §7.3: probes learn only from what the camera sees. Turn the camera
    // toward the green wall so the red wall leaves the screen: the red bleed on the
    // floor beside the red wall must fade.
    let full = floor_irradiance_near_red_wall(&Camera::default());
    let turned = Camera { target: Vec3::new(1.0, 0.6, 0.0), position: Vec3::new(-0.3, 1.0, 1.5), ..Camera::default() };
    let away = floor_irradiance_near_red_wall(&turned);
    let (r_full, r_away) = (full.x / full.y, away.x / away.y);
    eprintln!("red/green of floor irradiance by the red wall: red wall on screen {r_full}, off screen {r_away}");
    assert!(r_full > 1.3, "the red wall on screen must bleed: {full}");
    assert!(r_away < 0.8 * r_full, "the bleed must fade off screen: {away} vs {full}");
}

#[test]
fn sh_renders_are_identical_for_any_thread_count() {
    let scene = cornell_box();
    let run = |threads| {
        let pool = rayon::ThreadPoolBuilder::new().num_threads(threads).build().expect("pool");
        pool.install(|| {
            render(&scene, 24, 6, sh(ShProbeSettings { sh_light_injection: true, ..Default::default() })).image
        })
    };
    assert_eq!(run(1).pixels, run(3).pixels);
}
