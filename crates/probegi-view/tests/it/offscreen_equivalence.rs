//! The headless viewer's frame against `probegi render`'s (issue "`probegi
//! view`…", offscreen equivalence): with no input the fly camera holds the
//! scene's camera, so after N frames the viewer's image, field updating
//! through the same `FrameStepper`, matches `render_frames` of that camera
//! within the backend's own seed-to-seed HDR-FLIP, on the GPU backend
//! (lavapipe) for the Cornell box, the door room and Sponza. A script that
//! flies the camera moves it as the fly camera says and changes the frame.

use std::sync::Arc;

use probegi_core::camera::CameraRays;
use probegi_core::ddgi_settings::DdgiVolumeSettings;
use probegi_core::image::Image;
use probegi_field::{ProbeBatchTracer, ProbeTracerHandle};
use probegi_frame::frame_loop::{GiMethod, RenderSettings, render_frames};
use probegi_scene::{BvhSettings, BvhTracer, Scene, load_scene};
use probegi_view::input_script::InputScript;
use probegi_view::scripted_run::{ScriptedRun, run_scripted};
use probegi_wgpu::GpuContext;
use probegi_wgpu::wgpu_field_backend::WgpuProbeTracer;

const W: u32 = 64;
const H: u32 = 48;
const FRAMES: u32 = 8;

fn settings(scene: &Scene, seed: u64, gpu: Option<Arc<WgpuProbeTracer>>) -> RenderSettings {
    let volume = DdgiVolumeSettings { probe_rays_per_probe: 64, ..scene.volume.clone().unwrap_or_default() };
    RenderSettings {
        width: W,
        height: H,
        frames: FRAMES,
        seed,
        gi: GiMethod::Ddgi(Box::new(volume)),
        probe_tracer: gpu.map(|g| ProbeTracerHandle(g as Arc<dyn ProbeBatchTracer>)),
        ..Default::default()
    }
}

fn gpu(scene: &Scene, bvh: &BvhTracer) -> Option<Arc<WgpuProbeTracer>> {
    let ctx = GpuContext::headless_unless_absent().expect("PROBEGI_REQUIRE_GPU is set")?;
    Some(Arc::new(WgpuProbeTracer::new(ctx, scene, bvh, true).expect("upload").keeping_field(true)))
}

fn view(scene: &Scene, bvh: &BvhTracer, s: &RenderSettings, script: &InputScript) -> (Image, glam::Vec3) {
    let camera = scene.default_camera();
    let run = ScriptedRun {
        script,
        frames: FRAMES,
        frame_dt_s: 1.0 / 60.0,
        fly_speed_m_per_s: 1.0,
        camera_path: scene.camera_path(FRAMES),
    };
    // The viewer takes a device frame's statistics two frames late; `render` waits for each.
    let s = &RenderSettings {
        device_readback_lag_frames: probegi_view::view_session::VIEWER_READBACK_LAG_FRAMES,
        ..s.clone()
    };
    let out = run_scripted(scene, bvh, &camera, s, &run, |_, _| Ok(())).expect("scripted run");
    assert!(out.render.stats.error.is_none(), "{:?}", out.render.stats.error);
    (out.image, out.camera.position_m)
}

fn render(scene: &Scene, bvh: &BvhTracer, s: &RenderSettings) -> Image {
    let rays = CameraRays::new(&scene.default_camera(), W, H);
    let out = render_frames(scene, bvh, &rays, s, |_, _| {});
    assert!(out.stats.error.is_none(), "{:?}", out.stats.error);
    out.image
}

fn flip(a: &Image, b: &Image) -> f32 {
    probegi_image::mean_flip_hdr(a, b).expect("same size")
}

#[test]
fn the_viewers_frame_is_renders_frame_on_the_gpu() {
    for name in ["builtin:cornell-box", "builtin:door-room", "builtin:sponza-sun"] {
        let scene = load_scene(name).expect("scene");
        let bvh = BvhTracer::for_scene(&scene, BvhSettings::default());
        let Some(g) = gpu(&scene, &bvh) else { return };
        let still = InputScript::default();
        let (v, at) = view(&scene, &bvh, &settings(&scene, 3, Some(g.clone())), &still);
        assert_eq!(at, scene.default_camera().position, "{name}: no input, no motion");
        let r = render(&scene, &bvh, &settings(&scene, 3, Some(g.clone())));
        let other_seed = render(&scene, &bvh, &settings(&scene, 4, Some(g)));
        let (f, noise) = (flip(&r, &v), flip(&r, &other_seed));
        eprintln!("{name}: HDR-FLIP view vs render {f:.4}; render seed 3 vs 4 {noise:.4}");
        assert!(v.first_invalid_pixel().is_none() && v.mean().max_element() > 0.0, "{name}: a lit frame");
        assert!(f <= noise.max(0.01), "{name}: the viewer's frame ({f}) is farther than seed noise ({noise})");
    }
}

#[test]
fn a_script_flies_the_camera_and_changes_the_frame() {
    let scene = load_scene("builtin:cornell-box").expect("scene");
    let bvh = BvhTracer::for_scene(&scene, BvhSettings::default());
    let s = settings(&scene, 3, None);
    let script = InputScript::parse("0 key w down\n6 key w up\n", "fly.txt").expect("script");
    let (moved, at) = view(&scene, &bvh, &s, &script);
    // W held for frames 0–5 at 1 m/s, 1/60 s a frame: 0.1 m along the view.
    let start = scene.default_camera();
    let travelled = (at - start.position).length();
    assert!((travelled - 0.1).abs() < 1e-4, "travelled {travelled} m");
    let dir = (start.target - start.position).normalize();
    assert!((at - start.position).normalize().dot(dir) > 0.9999, "along the view");
    let still = render(&scene, &bvh, &s);
    let f = flip(&still, &moved);
    eprintln!("HDR-FLIP after flying 0.1 m: {f:.4}");
    assert!(f > 0.02, "the frame changed: {f}");
}

#[test]
fn a_keyframed_camera_plays_until_the_input_takes_over() {
    // The Cornell box with a camera that dollies in over the frames.
    let mut scene = load_scene("builtin:cornell-box").expect("scene");
    let c = scene.default_camera();
    let key = |frame: f32, z: f32| probegi_scene::CameraKeyframe {
        frame,
        camera: probegi_core::camera::Camera { position: glam::Vec3::new(c.position.x, c.position.y, z), ..c },
    };
    scene.camera_keyframes = vec![key(0.0, c.position.z), key(FRAMES as f32 - 1.0, c.position.z - 1.0)];
    let bvh = BvhTracer::for_scene(&scene, BvhSettings::default());
    let mut s = settings(&scene, 3, None);
    // `render` with the path: the viewer with no input is the same frame, bit for bit.
    s.camera_path = scene.camera_path(FRAMES).iter().map(|c| CameraRays::new(c, W, H)).collect();
    let rendered = render(&scene, &bvh, &s);
    let (played, at) = view(&scene, &bvh, &s, &InputScript::default());
    assert_eq!(played.pixels, rendered.pixels, "the path played as render plays it");
    let _ = at; // with no input the fly camera never moved; the path did
    // A key press from frame 4 on: the camera leaves the path where it was.
    let script = InputScript::parse("4 key e down\n", "up.txt").expect("script");
    let (_, flown) = view(&scene, &bvh, &s, &script);
    assert!(flown.y > c.position.y + 0.05, "flew up from the path: {flown}");
}
