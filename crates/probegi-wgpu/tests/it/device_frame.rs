//! The camera frame kept on the device (`probegi_wgpu::device_frame`, issue 44)
//! against the same frame composed on the host, and what a frame costs in
//! submissions, blocking waits and bytes read back.
//!
//! **Equivalence.** Two tracers on one scene run the same field update and the
//! same camera pass (same seeds, same device: the same per-pixel samples); one
//! brings the camera frame back and lets the CPU's `accumulation` add, reproject,
//! clamp and compose it (`keeping_frame(false)`), the other keeps it on the
//! device (`device_frame.wgsl`). So the images may differ only by arithmetic:
//! - a still camera's running mean in f32 against the CPU's f64 sum over k
//!   frames: each update rounds once or twice, ≤ 2k · 2⁻²⁴ relative (k ≤ 24:
//!   2.9e-6); composing direct + albedo × irradiance adds 2 · 2⁻²⁴;
//! - a moved camera's taps: Catmull-Rom weights and the projection computed
//!   with FMAs on one side and not the other differ by a few ulps of the
//!   pixel coordinate, ≤ 1e-5 of the history's range after the weights'
//!   sum of |w| ≤ 1.6, and the clamp's σ computed in f32 against f64 (the
//!   variance E[x²] − E[x]² loses up to log2(E[x²]/σ²) bits: 1e-5 relative
//!   for the contrasts a 3 × 3 Cornell neighbourhood has).
//!
//! Every pixel must then agree within [`PIXEL_REL_TOL`] = 1e-4 of the image's
//! largest value (ten times the sum above), except where a discrete choice
//! sits within that error of its boundary: the surface test (5 % of depth
//! off the tangent plane), the tangent-plane point (`t` within 0.5–2 × the
//! sample's distance), `facing` against 1e-3, a tap on the image's edge.
//! Those pixels are counted against [`BOUNDARY_PIXELS_MAX`]: 1 % of a moving
//! frame's pixels (a 64 × 64 frame's boundary cases are the silhouette pixels
//! whose plane distance lies within 1e-5 of the threshold: a handful).
//! A wrong pass (a missing clamp, a tap off by a pixel, the history not
//! capped) changes most pixels of a moving frame and fails.
//!
//! **Counts.** In the steady state, on a device that keeps up, a frame kept on
//! the device is one submission (the field update's passes recorded before
//! the camera frame's go with it), waits for the device 0 times with the viewer's readback lag, and reads
//! back the same bytes at every image size (its 48 bytes of statistics; no
//! pixel). (A device slower than the host makes it wait for the oldest frame
//! in flight once the ring holds more than the lag: frame pacing.)

use std::sync::Arc;

use glam::{UVec3, Vec3};
use probegi_core::camera::{Camera, CameraRays};
use probegi_core::ddgi_settings::{DdgiVolumeSettings, ProbeStatesMode};
use probegi_core::image::Image;
use probegi_cpu::DirectSettings;
use probegi_field::{ProbeBatchTracer, ProbeTracerHandle};
use probegi_frame::frame_loop::{FrameStepper, GiMethod, RenderOutput, RenderSettings, render_frames};
use probegi_scene::{BvhSettings, BvhTracer, Scene};
use probegi_wgpu::GpuContext;
use probegi_wgpu::wgpu_field_backend::WgpuProbeTracer;

/// Largest per-pixel difference, relative to the image's largest value, that
/// arithmetic alone explains (see the module docs).
const PIXEL_REL_TOL: f32 = 1e-4;
/// Pixels allowed past that where a discrete choice sits on its boundary, as a
/// fraction of the image.
const BOUNDARY_PIXELS_MAX: f32 = 0.01;

fn tracer(scene: &Scene, keep_frame: bool) -> Option<Arc<WgpuProbeTracer>> {
    let ctx = GpuContext::headless_unless_absent().expect("PROBEGI_REQUIRE_GPU is set")?;
    let bvh = BvhTracer::for_scene(scene, BvhSettings::default());
    let t = WgpuProbeTracer::new(ctx, scene, &bvh, true).expect("upload").keeping_field(true).keeping_frame(keep_frame);
    assert!(t.renders_camera(), "{:?}", t.shading_note);
    Some(Arc::new(t))
}

fn settings(size: u32, frames: u32, path: Vec<CameraRays>, gpu: &Arc<WgpuProbeTracer>) -> RenderSettings {
    RenderSettings {
        width: size,
        height: size,
        frames,
        seed: 7,
        gi: GiMethod::Ddgi(Box::new(DdgiVolumeSettings {
            probe_counts: UVec3::splat(5),
            probe_rays_per_probe: 64,
            ..Default::default()
        })),
        direct: DirectSettings { direct_area_samples: 4, ..Default::default() },
        probe_tracer: Some(ProbeTracerHandle(gpu.clone() as Arc<dyn ProbeBatchTracer>)),
        camera_path: path,
        ..Default::default()
    }
}

fn render(scene: &Scene, size: u32, frames: u32, path: &[CameraRays], gpu: &Arc<WgpuProbeTracer>) -> RenderOutput {
    let bvh = BvhTracer::for_scene(scene, BvhSettings::default());
    let camera = CameraRays::new(&scene.camera.expect("camera"), size, size);
    let out = render_frames(scene, &bvh, &camera, &settings(size, frames, path.to_vec(), gpu), |_, _| {});
    assert!(out.stats.error.is_none(), "{:?}", out.stats.error);
    out
}

/// Pixels of `b` off `a` by more than [`PIXEL_REL_TOL`] of `a`'s largest value.
fn pixels_off(a: &Image, b: &Image) -> usize {
    let scale = a.pixels.iter().fold(0.0f32, |m, p| m.max(p.max_element()));
    a.pixels.iter().zip(&b.pixels).filter(|(x, y)| (**x - **y).abs().max_element() > PIXEL_REL_TOL * scale).count()
}

/// A camera path of the Cornell box: `still` frames at the scene's camera,
/// then a pan and dolly of `moving` frames.
fn cornell_path(scene: &Scene, size: u32, still: u32, moving: u32) -> Vec<CameraRays> {
    let c = scene.camera.expect("camera");
    (0..still + moving)
        .map(|f| {
            let k = f.saturating_sub(still) as f32;
            let camera = Camera { position: c.position + Vec3::new(0.013, 0.004, -0.02) * k, ..c };
            CameraRays::new(&camera, size, size)
        })
        .collect()
}

fn check_frames(name: &str, path_still: u32, path_moving: u32) {
    let scene = probegi_scene::builtin::cornell_box();
    let (Some(host), Some(device)) = (tracer(&scene, false), tracer(&scene, true)) else { return };
    let size = 64;
    let path = cornell_path(&scene, size, path_still, path_moving);
    let frames = path_still + path_moving;
    let (a, b) = (render(&scene, size, frames, &path, &host), render(&scene, size, frames, &path, &device));
    let off = pixels_off(&a.image, &b.image);
    let n = a.image.pixels.len();
    eprintln!(
        "{name}: {off} of {n} pixels past {PIXEL_REL_TOL} of the largest; means {} vs {}",
        a.image.mean(),
        b.image.mean()
    );
    assert!(b.image.first_invalid_pixel().is_none(), "{name}");
    assert!(off as f32 <= BOUNDARY_PIXELS_MAX * n as f32, "{name}: {off} pixels differ");
    // The frames' statistics, reduced on the device and read back late, are the host's.
    let (sa, sb) = (&a.stats, &b.stats);
    assert_eq!(sa.frame_means.len(), sb.frame_means.len(), "{name}: a mean per frame");
    for (f, (ma, mb)) in sa.frame_means.iter().zip(&sb.frame_means).enumerate() {
        // The boundary pixels above move a mean by at most their share of the image.
        let tol = (PIXEL_REL_TOL + BOUNDARY_PIXELS_MAX) * ma.max_element().max(1e-6);
        assert!((*ma - *mb).abs().max_element() <= tol, "{name}: frame {f} mean {ma} vs {mb}");
    }
    assert_eq!(sa.frame_unlit_fraction, sb.frame_unlit_fraction, "{name}: the same pixels unlit");
    assert_eq!(sa.black_frames, sb.black_frames);
    assert_eq!(sa.nonfinite_pixels, sb.nonfinite_pixels);
}

/// A still camera: the device's running means equal the host's sums.
#[test]
fn a_still_frame_kept_on_the_device_is_the_host_composed_frame() {
    check_frames("still camera", 12, 0);
}

/// A moving camera: the device's temporal filter (reprojection, taps, surface
/// test, cap and clamp) is the host's `accumulation`.
#[test]
fn a_moving_frame_kept_on_the_device_is_the_host_filtered_frame() {
    check_frames("moving camera", 4, 10);
}

/// The steady state of a frame kept on the device: no blocking wait with the
/// viewer's lag, and the bytes read back a frame do not grow with the image.
#[test]
fn a_steady_frame_waits_for_nothing_and_reads_back_no_pixel() {
    let scene = probegi_scene::builtin::cornell_box();
    let bvh = BvhTracer::for_scene(&scene, BvhSettings::default());
    let mut per_size = Vec::new();
    for size in [32u32, 96] {
        let Some(gpu) = tracer(&scene, true) else { return };
        let mut s = settings(size, 0, Vec::new(), &gpu);
        s.device_readback_lag_frames = 2;
        let camera = CameraRays::new(&scene.camera.expect("camera"), size, size);
        let mut stepper = FrameStepper::new(&scene, &bvh, &camera, &s);
        // The initialisation rounds (relocation, classification) read back; then the steady state.
        for _ in 0..12 {
            stepper.advance(&camera).expect("frame");
        }
        // Statistics still in flight from the start-up are taken now, so that each
        // measured frame takes exactly the one before it (the counts then do not
        // depend on how far the device lagged during the start-up).
        gpu.device_frame().expect("kept on the device").drain_readouts().expect("readouts");
        let mut frames = Vec::new();
        for _ in 0..6 {
            // A device that keeps up: the frames before have run (a GPU slower than
            // the host makes it wait once the ring is full: frame pacing, not a read-back).
            gpu.ctx.wait().expect("device");
            let before = gpu.ctx.counters();
            stepper.advance(&camera).expect("frame");
            frames.push(gpu.ctx.counters() - before);
        }
        // The measured frames' own statistics still in flight, counted with them.
        let before = gpu.ctx.counters();
        gpu.device_frame().expect("kept on the device").drain_readouts().expect("readouts");
        frames.push(gpu.ctx.counters() - before);
        eprintln!("{size}×{size}: per frame, then the drain {frames:?}");
        for c in &frames[..6] {
            assert_eq!(c.blocking_waits, 0, "{size}: a steady frame waited: {c:?}");
            // The field update's passes and the camera frame's: one submission.
            assert_eq!(c.submissions, 1, "{size}: one submission a frame: {c:?}");
            // The update batch takes the buffers of the one two frames before.
            assert_eq!(c.ray_batches_made, 0, "{size}: a still field allocated a ray batch: {c:?}");
            // Every pass's inputs, outputs and bind groups are the frame before's.
            assert_eq!(c.buffers_made, 0, "{size}: a steady frame made buffers: {c:?}");
            assert_eq!(c.bind_groups_made, 0, "{size}: a steady frame made bind groups: {c:?}");
        }
        per_size.push(frames);
        let image = stepper.image().expect("read back on request");
        assert_eq!(image.pixels.len(), (size * size) as usize);
        assert!(image.mean().max_element() > 0.0);
        check_tone_map(&gpu, &image);
    }
    // Bytes read back over the six frames (whichever frame's poll took them):
    // the same at 32² and 96² pixels (9× the pixels), and six readouts' worth.
    let total = |f: &Vec<probegi_wgpu::GpuCounters>| f.iter().map(|c| c.bytes_down).sum::<u64>();
    assert_eq!(total(&per_size[0]), total(&per_size[1]), "bytes read back grow with the image");
    assert_eq!(total(&per_size[0]) % 6, 0, "six frames' readouts of one size");
    assert!(total(&per_size[1]) < 6 * 4 * 1024, "no pixel comes back: {}", total(&per_size[1]));
    assert_eq!(per_size[0][0].submissions, per_size[1][0].submissions);
}

/// [`settings`] for a 32 × 32 still frame under probe states `states`, with
/// the viewer's read-back lag (2 frames).
fn scheme_settings(states: ProbeStatesMode, gpu: &Arc<WgpuProbeTracer>) -> RenderSettings {
    let mut s = settings(32, 0, Vec::new(), gpu);
    if let GiMethod::Ddgi(v) = &mut s.gi {
        v.probe_states = states;
    }
    s.device_readback_lag_frames = 2;
    s
}

/// Under the screen scheme (the cascades' default) a still camera's field
/// traces the probes whose request countdowns ran out, so its batch changes
/// size from frame to frame: the batches, buffers and bind groups of the
/// frames before serve it anyway (a batch holds up to twice its rays, a kept
/// input up to twice its bytes, or more for a while), and a steady frame makes none.
#[test]
fn a_screen_scheme_frame_makes_no_batch_buffer_or_bind_group_while_its_batch_size_moves() {
    let scene = probegi_scene::builtin::cornell_box();
    let bvh = BvhTracer::for_scene(&scene, BvhSettings::default());
    let Some(gpu) = tracer(&scene, true) else { return };
    let s = scheme_settings(ProbeStatesMode::Screen, &gpu);
    let camera = CameraRays::new(&scene.camera.expect("camera"), 32, 32);
    let mut stepper = FrameStepper::new(&scene, &bvh, &camera, &s);
    for _ in 0..24 {
        stepper.advance(&camera).expect("frame");
    }
    let (mut sizes, mut frames) = (Vec::new(), Vec::new());
    for _ in 0..12 {
        let before = gpu.ctx.counters();
        stepper.advance(&camera).expect("frame");
        frames.push(gpu.ctx.counters() - before);
        sizes.push(gpu.last_batch_rays().expect("a batch on the device"));
    }
    eprintln!("batch rays {sizes:?}");
    sizes.sort_unstable();
    sizes.dedup();
    assert!(sizes.len() >= 2, "the batch kept its size, so this test shows nothing: {sizes:?}");
    for c in &frames {
        assert_eq!(c.submissions, 1, "one submission a frame: {c:?}");
        assert_eq!(c.ray_batches_made, 0, "a steady frame allocated a ray batch: {c:?}");
        assert_eq!(c.buffers_made, 0, "a steady frame made buffers: {c:?}");
        assert_eq!(c.bind_groups_made, 0, "a steady frame made bind groups: {c:?}");
    }
}

/// Under the usage scheme every probe traces every frame and the usage pass
/// counts each batch's hits on the device (`probegi_wgpu::probe_usage`): its
/// inputs, its output (copied behind it into a staging buffer the late
/// read-back reuses) and its bind group are kept from frame to frame, so a
/// steady frame makes no buffer and no bind group, and waits for nothing.
/// The pass made its output buffer and a bind group every frame before.
#[test]
fn a_usage_scheme_frame_makes_no_buffer_or_bind_group_and_waits_for_nothing() {
    let scene = probegi_scene::builtin::cornell_box();
    let bvh = BvhTracer::for_scene(&scene, BvhSettings::default());
    let Some(gpu) = tracer(&scene, true) else { return };
    let s = scheme_settings(ProbeStatesMode::Usage, &gpu);
    let GiMethod::Ddgi(v) = &s.gi else { panic!("a DDGI render") };
    assert!(v.probe_usage_lag_updates > 0, "the default reads the counts late");
    let camera = CameraRays::new(&scene.camera.expect("camera"), 32, 32);
    let mut stepper = FrameStepper::new(&scene, &bvh, &camera, &s);
    for _ in 0..12 {
        stepper.advance(&camera).expect("frame");
    }
    gpu.ctx.wait().expect("the device finishes what was submitted");
    for frame in 0..8 {
        let before = gpu.ctx.counters();
        stepper.advance(&camera).expect("frame");
        let c = gpu.ctx.counters() - before;
        gpu.ctx.wait().expect("the device finishes the frame");
        assert_eq!(c.submissions, 1, "frame {frame}: one submission a frame: {c:?}");
        assert_eq!(c.buffers_made, 0, "frame {frame}: a steady usage frame made buffers: {c:?}");
        assert_eq!(c.bind_groups_made, 0, "frame {frame}: a steady usage frame made bind groups: {c:?}");
        assert_eq!(c.blocking_waits, 0, "frame {frame}: a usage frame waited for its counts: {c:?}");
    }
}

/// The device's tone map (`read_rgba8`, the frame compose pass) is
/// `probegi_core::color::tonemap_rgb8` of the frame, code for code but where
/// `pow` in the sRGB curve, which WGSL computes as exp2(y·log2 x) to a few
/// ulps, rounds across a code's half-way point: ±1 code, and then on a few
/// pixels at most (a code step is 1/255 against a few 1e-7 of error).
fn check_tone_map(gpu: &Arc<WgpuProbeTracer>, image: &Image) {
    let df = gpu.device_frame().expect("the frame is kept on the device");
    let rgba = df.read_rgba8(probegi_field::FrameLayer::Full).expect("tone-mapped frame");
    assert_eq!(rgba.len(), image.pixels.len() * 4);
    let mut off_by_one = 0;
    for (p, px) in image.pixels.iter().enumerate() {
        let want = probegi_core::color::tonemap_rgb8(*px);
        let got = &rgba[4 * p..4 * p + 4];
        assert_eq!(got[3], 255, "alpha");
        for c in 0..3 {
            let d = (got[c] as i32 - want[c] as i32).abs();
            assert!(d <= 1, "pixel {p} channel {c}: {} vs {}", got[c], want[c]);
            off_by_one += d as usize;
        }
    }
    assert!(off_by_one * 100 <= image.pixels.len() * 3, "{off_by_one} channels off by one code");
}

/// The device keeps its frame across renders (the tracer outlives a
/// stepper): a second render on one tracer starts its sums again, and so
/// equals a render on a fresh tracer, pixel for pixel but for rounding.
#[test]
fn a_second_render_on_one_tracer_starts_its_sums_again() {
    let scene = probegi_scene::builtin::cornell_box();
    let (Some(reused), Some(fresh)) = (tracer(&scene, true), tracer(&scene, true)) else { return };
    let path = cornell_path(&scene, 64, 8, 0);
    // The first render ends elsewhere (its camera moved), so that its sums are another view's.
    let _first = render(&scene, 64, 8, &cornell_path(&scene, 64, 2, 6), &reused);
    let (second, alone) = (render(&scene, 64, 8, &path, &reused), render(&scene, 64, 8, &path, &fresh));
    let off = pixels_off(&alone.image, &second.image);
    assert_eq!(off, 0, "{off} pixels of the second render differ from a fresh tracer's");
}
