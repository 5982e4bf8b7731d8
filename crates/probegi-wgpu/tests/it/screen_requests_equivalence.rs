//! The screen scheme (`probe_states = screen`, issue 32 item 4) on
//! `--backend wgpu`: the camera frame on the device marks the probes its
//! pixels' queries read (`camera_frame.wgsl`'s `camera_request_probes`), the
//! CPU marks them from its G-buffer (`DdgiFieldSet::probe_requests_at`), and
//! the two bitsets agree; over a render, the same probes are requested, the
//! same rays are traced, and the images agree within the backends' noise.
//! The device also returns the diffuse albedo its field term used and the
//! primary rays' hit points and normals (the temporal filter's surface),
//! the CPU's at the same pixels.

use std::sync::Arc;

use crate::common;
use glam::{UVec3, Vec3};
use probegi_core::camera::CameraRays;
use probegi_core::ddgi_settings::{DdgiVolumeSettings, ProbeStatesMode, VolumeBlending};
use probegi_cpu::gbuffer::trace_gbuffer;
use probegi_cpu::shading::ShadingContext;
use probegi_field::ddgi_field_set::DdgiFieldSet;
use probegi_field::ddgi_volume::DdgiVolume;
use probegi_field::{CameraFrameOut, ProbeBatchTracer, ProbeTracerHandle};
use probegi_frame::frame_loop::{GiMethod, RenderSettings, render_frames};
use probegi_scene::{BvhSettings, BvhTracer, Scene, load_scene};

const W: u32 = 96;
const H: u32 = 72;

fn screen_settings(counts: UVec3) -> DdgiVolumeSettings {
    DdgiVolumeSettings {
        probe_counts: counts,
        probe_rays_per_probe: 64,
        probe_states: ProbeStatesMode::Screen,
        probe_screen_request_frames: 3,
        ..Default::default()
    }
}

/// Two cascades over the door room: a fine one over part of it and a coarse
/// one over all of it, so the bitset spans two members.
fn two_cascades(scene: &Scene) -> DdgiFieldSet {
    let (lo, hi) = scene.bounds().expect("geometry");
    let fine = DdgiVolumeSettings {
        volume_bounds_m: Some([lo, lo + (hi - lo) * Vec3::new(0.6, 1.0, 0.6)]),
        ..screen_settings(UVec3::new(8, 4, 8))
    };
    let coarse = screen_settings(UVec3::new(6, 3, 6));
    // Given coarse first: the set samples (and numbers the bits) finest first.
    let volumes = vec![DdgiVolume::new(coarse, (lo, hi)), DdgiVolume::new(fine, (lo, hi))];
    DdgiFieldSet::from_volumes(volumes, VolumeBlending::Cascades, None)
}

fn bits(words: &[u32]) -> Vec<usize> {
    (0..words.len() * 32).filter(|&b| words[b / 32] >> (b % 32) & 1 != 0).collect()
}

#[test]
fn the_device_requests_the_probes_the_cpu_requests() {
    let scene = load_scene("builtin:door-room").expect("builtin");
    let Some(gpu) = common::resident_tracer(&scene) else { return };
    let cpu = BvhTracer::for_scene(&scene, BvhSettings::default());
    let set = two_cascades(&scene);
    let camera = CameraRays::new(&scene.camera.expect("camera"), W, H);
    // Frame 0: pixel centres on both backends.
    let (gbuffer, _) = trace_gbuffer(&scene, &cpu, &camera, W, H, 0, 7);
    let points: Vec<(Vec3, Vec3, Vec3)> = gbuffer
        .texels
        .iter()
        .filter_map(|t| t.surface.as_ref().map(|sp| (sp.position, sp.facing_normal(), t.view_dir_world)))
        .collect();
    let host = set.probe_requests_at(&points);
    let mut device = vec![0u32; host.len()];
    let [mut direct, mut irradiance, mut albedo] = [(); 3].map(|_| vec![Vec3::ZERO; (W * H) as usize]);
    let view = set.view();
    let mut position_m = vec![Vec3::ZERO; (W * H) as usize];
    let mut normal = vec![Vec3::ZERO; (W * H) as usize];
    let out = CameraFrameOut {
        direct: &mut direct,
        irradiance_over_pi: &mut irradiance,
        albedo: &mut albedo,
        position_m: &mut position_m,
        normal: &mut normal,
    };
    gpu.camera_frame(&camera, &view, false, 1, 0, false, 0, 7, out, Some(&mut device))
        .expect("the device renders the camera")
        .expect("camera frame");
    // The albedo the device weighed its field term with, against the CPU's at the
    // same pixel centres (the still camera's accumulation reads it).
    let same_albedo = gbuffer
        .texels
        .iter()
        .zip(&albedo)
        .filter(|(t, a)| {
            let cpu = t
                .surface
                .as_ref()
                .map_or(Vec3::ZERO, |sp| ShadingContext::new(&scene, sp, t.view_dir_world).bsdf.diffuse_albedo());
            (cpu - **a).abs().max_element() < 1e-4
        })
        .count();
    assert!(albedo.iter().any(|a| a.max_element() > 0.0), "the device returned no albedo");
    assert!(same_albedo as f32 >= 0.99 * albedo.len() as f32, "{same_albedo} of {} pixels", albedo.len());
    // The hit points, against the CPU's G-buffer points (every pixel of the
    // closed room meets a surface).
    let same_point = gbuffer
        .texels
        .iter()
        .zip(&position_m)
        .filter(|(t, x)| {
            t.surface.as_ref().is_some_and(|sp| sp.position.distance(**x) <= 1e-4 * sp.position.length().max(1.0))
        })
        .count();
    assert!(same_point as f32 >= 0.99 * position_m.len() as f32, "{same_point} of {} points", position_m.len());
    let same_normal = gbuffer
        .texels
        .iter()
        .zip(&normal)
        .filter(|(t, n)| t.surface.as_ref().is_some_and(|sp| sp.facing_geometric_normal().dot(**n) > 0.999))
        .count();
    assert!(same_normal as f32 >= 0.99 * normal.len() as f32, "{same_normal} of {} normals", normal.len());
    let (h, d) = (bits(&host), bits(&device));
    let layout = set.probe_request_layout();
    let in_member = |b: &[usize], m: usize| b.iter().filter(|&&x| x >= layout[m] && x < layout[m + 1]).count();
    eprintln!(
        "requested: host {} (fine {}, coarse {}), device {} of {} probes",
        h.len(),
        in_member(&h, 0),
        in_member(&h, 1),
        d.len(),
        layout[2]
    );
    assert!(in_member(&h, 0) > 20 && in_member(&h, 1) > 20, "both cascades are read");
    assert!(h.len() < layout[2] * 9 / 10, "the camera does not read every probe");
    assert_eq!(h, d, "the device's request bits equal the CPU's");
}

#[test]
fn screen_states_and_rays_agree_over_a_render() {
    let scene = load_scene("builtin:door-room").expect("builtin");
    let Some(gpu) = common::resident_tracer(&scene) else { return };
    let cpu = BvhTracer::for_scene(&scene, BvhSettings::default());
    let camera = CameraRays::new(&scene.camera.expect("camera"), W, H);
    let gpu = Arc::new(gpu);
    let render = |states: ProbeStatesMode, on_gpu: bool| {
        let rs = RenderSettings {
            width: W,
            height: H,
            frames: 10,
            seed: 3,
            gi: GiMethod::Ddgi(Box::new(DdgiVolumeSettings {
                probe_states: states,
                ..screen_settings(UVec3::new(8, 4, 8))
            })),
            probe_tracer: on_gpu.then(|| ProbeTracerHandle(gpu.clone() as Arc<dyn ProbeBatchTracer>)),
            ..Default::default()
        };
        let out = render_frames(&scene, &cpu, &camera, &rs, |_, _| {});
        assert!(out.stats.error.is_none(), "{:?}", out.stats.error);
        out
    };
    let (c, g) = (render(ProbeStatesMode::Screen, false), render(ProbeStatesMode::Screen, true));
    let (all_c, all_g) = (render(ProbeStatesMode::AllActive, false), render(ProbeStatesMode::AllActive, true));
    eprintln!("states: CPU {:?}, GPU {:?}", c.stats.probe_states, g.stats.probe_states);
    assert_eq!(c.stats.probe_states, g.stats.probe_states, "the same probes are requested");
    assert_eq!(c.stats.rays_per_frame, g.stats.rays_per_frame, "the same probes trace");
    let (rays, all_rays) = (c.stats.rays_per_frame.unwrap_or(0), all_c.stats.rays_per_frame.unwrap_or(0));
    assert!(rays < all_rays * 9 / 10, "the screen scheme saves rays: {rays} against {all_rays}");
    let flip = |a: &probegi_core::image::Image, b: &probegi_core::image::Image| {
        probegi_image::compare::mean_flip_hdr(a, b).expect("same size")
    };
    let (screen_flip, all_flip) = (flip(&c.image, &g.image), flip(&all_c.image, &all_g.image));
    eprintln!("CPU vs GPU HDR-FLIP: screen {screen_flip:.4}, all-active {all_flip:.4}; rays {rays} of {all_rays}");
    assert!(screen_flip < all_flip + 0.01, "the backends agree under the screen scheme as under all-active");
}
