//! The DDGI field with its probe rays traced (and shaded) on the GPU, through the
//! field set's seam, against the same field on the CPU.
//!
//! - Trace only (`WgpuProbeTracer` with CPU shading): on lavapipe the GPU's hits
//!   equal the CPU's, so the atlases agree to float reordering at most (bound
//!   1e-3 of the largest texel, leaving room for adapters that round a grazing
//!   ray onto a neighbouring triangle); probe states are equal; relocation
//!   offsets agree within the hit-distance error of the ray each probe stepped
//!   along (`assert_offsets_agree`); reruns are bit-identical.
//! - Trace and shade on the GPU: the shade's random numbers differ from the CPU's
//!   (see `probegi_wgpu::probe_shade`), so single texels differ by Monte Carlo
//!   noise. The tolerance is that noise: the GPU field must be no farther from
//!   the CPU field than the CPU field is from itself under another seed (×1.5),
//!   after 1 frame and after 100; the furnace converges to its analytic answer;
//!   images agree within HDR-FLIP 0.02.

use crate::common;

use probegi_frame::field_update::FieldSetUpdate;
use std::collections::BTreeMap;
use std::sync::Arc;

use common::trace_error::{self, UNIT_ROUNDOFF};
use glam::UVec3;
use probegi_core::camera::CameraRays;
use probegi_core::ddgi_settings::DdgiVolumeSettings;
use probegi_core::image::Image;
use probegi_cpu::{DirectLighting, DirectSettings};
use probegi_field::ddgi_field_set::DdgiFieldSet;
use probegi_field::ddgi_volume::DdgiVolume;
use probegi_field::{ProbeBatchTracer, ProbeTracerHandle};
use probegi_frame::frame_loop::{GiMethod, RenderSettings, render_frames};
use probegi_scene::{BvhSettings, BvhTracer, Ray, RayTracer, Scene};
use probegi_wgpu::GpuContext;
use probegi_wgpu::wgpu_field_backend::WgpuProbeTracer;

fn gpu(scene: &Scene, shade: bool) -> Option<WgpuProbeTracer> {
    let ctx = GpuContext::headless_unless_absent().expect("PROBEGI_REQUIRE_GPU is set")?;
    // The field on the GPU, the camera on the CPU (tests/it/camera_equivalence.rs has the GPU camera).
    let bvh = BvhTracer::for_scene(scene, BvhSettings::default());
    let t = WgpuProbeTracer::with_camera(ctx, scene, &bvh, shade, false).expect("upload");
    assert_eq!(t.shades(), shade, "{:?}", t.shading_note);
    Some(t)
}

fn settings() -> DdgiVolumeSettings {
    DdgiVolumeSettings { probe_counts: UVec3::splat(6), probe_rays_per_probe: 128, ..Default::default() }
}

/// Largest texel difference over the largest texel, for both atlases.
fn max_difference(a: &DdgiVolume, b: &DdgiVolume) -> (f32, f32) {
    let rel = |x: &[f32], y: &[f32]| {
        let scale = x.iter().fold(0f32, |m, v| m.max(v.abs())).max(1e-6);
        x.iter().zip(y).fold(0f32, |m, (p, q)| m.max((p - q).abs())) / scale
    };
    let (ia, ib) = (flat3(a), flat3(b));
    (rel(&ia, &ib), rel(&flat2(a), &flat2(b)))
}

fn flat3(v: &DdgiVolume) -> Vec<f32> {
    v.irradiance.texels.iter().flat_map(|t| t.to_array()).collect()
}

fn flat2(v: &DdgiVolume) -> Vec<f32> {
    v.distance.texels.iter().flat_map(|t| t.to_array()).collect()
}

/// RMS texel difference of the irradiance atlases.
fn rms_difference(a: &DdgiVolume, b: &DdgiVolume) -> f32 {
    let (x, y) = (flat3(a), flat3(b));
    (x.iter().zip(&y).map(|(p, q)| (p - q) * (p - q)).sum::<f32>() / x.len() as f32).sqrt()
}

/// Relocation offsets traced on the CPU (`c`) and on the device (`g`), both
/// stepped on the host (`probegi_core::probe_relocation::relocation_step`) from
/// the hit distances each side traced, over the volume's relocation rounds.
/// A round's step is the stepping ray's direction times its hit distance t
/// times s = |step|/t ≤ 2 (inside geometry: s = 2 − i/100; near a front face:
/// min(t, cap)/t ≤ 1, continuous in t). The device's t differs from the CPU's
/// by the ray's `trace_error` bound Δt, and by |Δ|/cos θ where its probe already
/// stands Δ away (the plane's distance moves by at most |Δ|). So after round k
///   Δₖ ≤ Δₖ₋₁·(1 + sₖ/cos θₖ) + sₖ·Δtₖ + 4u·|offsetₖ|,
/// the last term one rounding of each of the step's two products taking
/// another value. The rounds are replayed on the CPU (k rounds for k = 1…n,
/// the same rays as the first k of n), each step's ray found again from the
/// probe's position along the step. A discrete choice (which ray is closest,
/// which i, a threshold) taking another value would move the probe by far
/// more and fails here.
fn assert_offsets_agree(scene: &Scene, cpu: &BvhTracer, c: &DdgiVolume, g: &DdgiVolume) {
    let direct = DirectLighting::new(scene, cpu, DirectSettings::default());
    let rounds = c.settings.probe_relocation_iterations;
    let after: Vec<Vec<glam::Vec3>> = (1..=rounds)
        .map(|k| {
            let s = DdgiVolumeSettings { probe_relocation_iterations: k, ..c.settings.clone() };
            let mut set = DdgiFieldSet::single(DdgiVolume::new(s, scene.bounds().expect("geometry")));
            set.update(scene, cpu, &direct, 5, 0, &mut BTreeMap::new());
            set.volumes()[0].probe_offsets.clone()
        })
        .collect();
    assert_eq!(after.last(), Some(&c.probe_offsets), "the replayed rounds end where the CPU field did");
    let (mut differing, mut worst_share) = (0, 0f64);
    for (p, (a, b)) in c.probe_offsets.iter().zip(&g.probe_offsets).enumerate() {
        let grid_position = c.grid.probe_position(c.grid.probe_coords(p));
        let mut bound = 0f64;
        let mut offset = glam::Vec3::ZERO;
        for next in after.iter().map(|o| o[p]) {
            let step = next - offset;
            if step != glam::Vec3::ZERO {
                let ray = Ray::new(grid_position + offset, step.normalize());
                let hit = cpu.closest_hit(&ray).expect("a probe steps towards a surface");
                let tol = trace_error::hit_tolerance(&ray, hit.t, &trace_error::world_triangle(scene, 0.0, &hit));
                let s = step.length() as f64 / hit.t as f64;
                bound = bound * (1.0 + s / tol.cos) + s * tol.dt + 4.0 * UNIT_ROUNDOFF * next.length() as f64;
            }
            offset = next;
        }
        let d = (*a - *b).length() as f64;
        if d > 0.0 {
            differing += 1;
            worst_share = worst_share.max(d / bound);
        }
        assert!(d <= bound, "probe {p}: offsets {a} (CPU) and {b} (GPU) differ by {d:e} > {bound:e}");
    }
    eprintln!(
        "relocation: {differing} of {} offsets differ, the largest by {worst_share:.3} of its bound",
        c.probe_offsets.len()
    );
}

#[test]
fn gpu_traced_cornell_atlases_match_after_1_and_100_frames_and_reruns_are_bit_identical() {
    let scene = probegi_scene::builtin::cornell_box();
    let Some(gpu) = gpu(&scene, false) else { return };
    let cpu = BvhTracer::for_scene(&scene, BvhSettings::default());
    let direct = DirectLighting::new(&scene, &cpu, DirectSettings::default());
    let bounds = scene.bounds().expect("geometry");
    let new_set = || DdgiFieldSet::single(DdgiVolume::new(settings(), bounds));
    let (mut on_cpu, mut on_gpu, mut rerun) = (new_set(), new_set(), new_set());
    let mut ms = BTreeMap::new();
    for f in 0..100 {
        on_cpu.update(&scene, &cpu, &direct, 5, f, &mut ms);
        on_gpu.update_traced_by(&scene, &cpu, Some(&gpu), &direct, 5, f, &mut ms).expect("GPU trace");
        if f < 3 {
            rerun.update_traced_by(&scene, &cpu, Some(&gpu), &direct, 5, f, &mut ms).expect("GPU trace");
        }
        if f == 0 || f == 99 {
            let (c, g) = (&on_cpu.volumes()[0], &on_gpu.volumes()[0]);
            let (di, dd) = max_difference(c, g);
            eprintln!("GPU trace, after {} frames: irradiance {di:.2e}, distance {dd:.2e} of the largest texel", f + 1);
            assert!(di < 1e-3 && dd < 1e-3, "frame {f}: {di:e} {dd:e}");
            assert_eq!(c.probe_states, g.probe_states, "probe states, frame {f}");
            assert_offsets_agree(&scene, &cpu, c, g);
            g.validate();
        }
        if f == 2 {
            let (a, b) = (&on_gpu.volumes()[0], &rerun.volumes()[0]);
            assert_eq!(a.irradiance.texels, b.irradiance.texels, "a GPU rerun is bit-identical");
            assert_eq!(a.distance.texels, b.distance.texels);
        }
    }
}

#[test]
fn gpu_shaded_cornell_atlases_are_within_the_cpu_seed_noise_after_1_and_100_frames() {
    shaded_within_seed_noise(settings(), 100);
}

#[test]
fn hit_ao_shades_alike_on_both_backends_and_darkens_the_field() {
    // Timberdoodle PGI's short-range AO on hit radiance (`probe_hit_ao_radius_rel`):
    // one random ray per hit, from each backend's own streams, so the
    // backends agree within seed noise; and it takes light out of the field.
    let ao = DdgiVolumeSettings { probe_hit_ao_radius_rel: 1.0, ..settings() };
    let (Some(with), Some(without)) = (shaded_within_seed_noise(ao, 30), shaded_within_seed_noise(settings(), 30))
    else {
        return;
    };
    eprintln!("hit AO: atlas mean {with:.4} against {without:.4} without");
    assert!(with < 0.99 * without, "{with} vs {without}");
}

#[test]
fn the_near_field_hit_ao_shades_alike_on_both_backends_and_gives_back_the_occluders_light() {
    // `probe_hit_ao_near_field`: an occluded AO ray carries the occluder's
    // radiance (its direct light and field term), on each backend from its own
    // streams, so they agree within seed noise; the field keeps more light
    // than under the plain AO, which counts an occluded ray as black. The
    // plain AO takes 1.3 % of this atlas (0.4249 against 0.4306 without AO);
    // the near-field form gives it back (0.4306), so 1 % tells them apart.
    let near = DdgiVolumeSettings { probe_hit_ao_radius_rel: 1.0, probe_hit_ao_near_field: true, ..settings() };
    let plain = DdgiVolumeSettings { probe_hit_ao_radius_rel: 1.0, ..settings() };
    let (Some(near), Some(plain)) = (shaded_within_seed_noise(near, 30), shaded_within_seed_noise(plain, 30)) else {
        return;
    };
    eprintln!("near-field hit AO: atlas mean {near:.4} against {plain:.4} for the plain AO");
    assert!(near > 1.01 * plain, "{near} vs {plain}");
}

/// The GPU-shaded field against the CPU's after 1 and `frames` frames, within
/// the CPU's own seed-to-seed noise (×1.5); returns the GPU atlas's mean.
fn shaded_within_seed_noise(volume: DdgiVolumeSettings, frames: u32) -> Option<f32> {
    let scene = probegi_scene::builtin::cornell_box();
    let gpu = gpu(&scene, true)?;
    let cpu = BvhTracer::for_scene(&scene, BvhSettings::default());
    let direct = DirectLighting::new(&scene, &cpu, DirectSettings::default());
    let bounds = scene.bounds().expect("geometry");
    let new_set = || DdgiFieldSet::single(DdgiVolume::new(volume.clone(), bounds));
    let (mut a, mut b, mut g, mut g2) = (new_set(), new_set(), new_set(), new_set());
    let mut ms = BTreeMap::new();
    let mut gpu_mean = 0.0;
    for f in 0..frames {
        a.update(&scene, &cpu, &direct, 5, f, &mut ms);
        b.update(&scene, &cpu, &direct, 6, f, &mut ms);
        g.update_traced_by(&scene, &cpu, Some(&gpu), &direct, 5, f, &mut ms).expect("GPU");
        if f < 2 {
            g2.update_traced_by(&scene, &cpu, Some(&gpu), &direct, 5, f, &mut ms).expect("GPU");
        }
        if f == 1 {
            assert_eq!(g.volumes()[0].irradiance.texels, g2.volumes()[0].irradiance.texels, "bit-identical rerun");
        }
        if f == 0 || f == frames - 1 {
            let (va, vb, vg) = (&a.volumes()[0], &b.volumes()[0], &g.volumes()[0]);
            let noise = rms_difference(va, vb);
            let gpu_cpu = rms_difference(va, vg);
            let mean = |v: &DdgiVolume| flat3(v).iter().sum::<f32>() / flat3(v).len() as f32;
            eprintln!(
                "GPU shade, after {} frames: RMS texel difference GPU–CPU {gpu_cpu:.4}, CPU seed 5–6 {noise:.4}; \
                 atlas means CPU {:.4}, GPU {:.4}",
                f + 1,
                mean(va),
                mean(vg)
            );
            assert!(gpu_cpu <= 1.5 * noise, "frame {f}: {gpu_cpu} vs seed noise {noise}");
            assert!((mean(va) - mean(vg)).abs() < 0.02 * mean(va), "atlas means");
            assert_eq!(va.probe_states, vg.probe_states, "probe states");
            vg.validate();
            gpu_mean = mean(vg);
        }
    }
    Some(gpu_mean)
}

fn render(scene: &Scene, size: u32, frames: u32, s: DdgiVolumeSettings, gpu: Option<Arc<WgpuProbeTracer>>) -> Image {
    let cpu = BvhTracer::for_scene(scene, BvhSettings::default());
    let camera = CameraRays::new(&scene.camera.expect("camera"), size, size);
    let rs = RenderSettings {
        width: size,
        height: size,
        frames,
        seed: 3,
        gi: GiMethod::Ddgi(Box::new(s)),
        probe_tracer: gpu.map(|g| ProbeTracerHandle(g as Arc<dyn ProbeBatchTracer>)),
        ..Default::default()
    };
    let out = render_frames(scene, &cpu, &camera, &rs, |_, _| {});
    assert!(out.stats.error.is_none(), "{:?}", out.stats.error);
    out.image
}

#[test]
fn furnace_converges_to_le_over_one_minus_rho_on_the_gpu() {
    let scene = probegi_scene::builtin::furnace_box(0.5, 1.0);
    for shade in [false, true] {
        let Some(gpu) = gpu(&scene, shade) else { return };
        let s = DdgiVolumeSettings {
            probe_counts: UVec3::splat(3),
            probe_rays_per_probe: 128,
            probe_hysteresis: 0.8,
            ..Default::default()
        };
        let mean = render(&scene, 16, 80, s, Some(Arc::new(gpu))).mean();
        eprintln!("furnace, GPU trace{}: mean {mean}", if shade { " and shade" } else { "" });
        assert!((mean.x - 2.0).abs() < 0.04, "furnace mean {mean}, want 2.0 within 2 %");
    }
}

#[test]
fn cornell_and_door_room_images_agree_across_backends_within_flip_0_02() {
    for (name, scene, s) in [
        ("cornell box", probegi_scene::builtin::cornell_box(), settings()),
        (
            "door room",
            probegi_scene::load_scene("builtin:door-room").expect("built in"),
            DdgiVolumeSettings {
                probe_counts: UVec3::new(6, 3, 6),
                probe_origin_m: Some(glam::Vec3::new(-0.5, 0.5, -0.5)),
                probe_spacing_m: Some(glam::Vec3::ONE),
                probe_rays_per_probe: 128,
                ..Default::default()
            },
        ),
    ] {
        let a = render(&scene, 48, 40, s.clone(), None);
        for shade in [false, true] {
            let Some(gpu) = gpu(&scene, shade) else { return };
            let b = render(&scene, 48, 40, s.clone(), Some(Arc::new(gpu)));
            let f = probegi_image::mean_flip_hdr(&a, &b).expect("same size");
            eprintln!("{name}: HDR-FLIP CPU vs GPU trace{} {f:.5}", if shade { " + shade" } else { "" });
            assert!(f < 0.02, "{name}: FLIP {f}");
            assert!(b.first_invalid_pixel().is_none());
        }
    }
}

/// The moving-box room (`scenes/moving-box.toml`: a box that slides, turns and
/// grows over frames 0–60) rendered through the frame loop, which poses the
/// scene and places the device's top level each frame: with the probe rays
/// traced on the GPU (CPU shading) the atlases after 40 frames equal the CPU's
/// to float reordering (bound 1e-3 of the largest texel, as above), the probe
/// states too, and the probes the box passes were woken on both.
#[test]
fn a_moving_box_gives_the_same_field_through_the_gpu_top_level() {
    let path = common::repo_file("scenes/moving-box.toml");
    let scene = probegi_scene::load_scene(&path).expect("moving box");
    assert!(scene.has_moving_geometry());
    let Some(gpu) = gpu(&scene, false) else { return };
    // A BVH over the mesh alone cannot place the box on the device: refused.
    let flat = BvhTracer::build(&scene.mesh, BvhSettings::default());
    let ctx = GpuContext::headless_unless_absent().expect("device").expect("device");
    let refused = WgpuProbeTracer::new(ctx, &scene, &flat, true).err().expect("refused").to_string();
    assert!(refused.contains("moving objects"), "{refused}");
    let mut s = scene.volume.clone().expect("volume");
    s.probe_rays_per_probe = 64;
    let run = |tracer: Option<Arc<WgpuProbeTracer>>| {
        let cpu = BvhTracer::for_scene(&scene, BvhSettings::default());
        let camera = CameraRays::new(&scene.camera.expect("camera"), 16, 16);
        let rs = RenderSettings {
            width: 16,
            height: 16,
            frames: 40,
            seed: 3,
            gi: GiMethod::Ddgi(Box::new(s.clone())),
            probe_tracer: tracer.map(|g| ProbeTracerHandle(g as Arc<dyn ProbeBatchTracer>)),
            ..Default::default()
        };
        let out = render_frames(&scene, &cpu, &camera, &rs, |_, _| {});
        assert!(out.stats.error.is_none(), "{:?}", out.stats.error);
        out
    };
    let (a, b) = (run(None), run(Some(Arc::new(gpu))));
    assert!(a.stats.probes_woken > 0, "the box wakes probes");
    assert_eq!(a.stats.probes_woken, b.stats.probes_woken);
    let (va, vb) = (&a.ddgi.as_ref().expect("field").volumes()[0], &b.ddgi.as_ref().expect("field").volumes()[0]);
    assert_eq!(va.probe_states, vb.probe_states);
    let (di, dd) = max_difference(va, vb);
    eprintln!("moving box, 40 frames, GPU trace vs CPU: irradiance {di:.2e}, distance {dd:.2e} of the largest texel");
    assert!(di < 1e-3 && dd < 1e-3, "{di:e} {dd:e}");
}
