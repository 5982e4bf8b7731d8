//! The shadowing field (seed 003 ch. 5) with `--backend wgpu`'s tracer (the
//! field kept on the device): the device casts the shadow rays from the hits of
//! the previous update batch it kept and blends the occlusion maps it holds
//! (`probegi_wgpu::shadow_field`), so on lavapipe, whose hits equal the CPU's,
//! the maps read back agree with the CPU's to float rounding and the probe
//! states are equal; and the GPU camera, reading the maps through
//! `ddgi_query.wgsl`'s `ddgi_shadow_visibility`, renders the shadow box (seed
//! 003 Fig. 7.10) within the CPU's own seed-to-seed HDR-FLIP.

use std::collections::BTreeMap;
use std::sync::Arc;

use crate::common;
use glam::UVec3;
use probegi_core::ddgi_settings::DdgiVolumeSettings;
use probegi_core::image::Image;
use probegi_cpu::{DirectLighting, DirectSettings};
use probegi_field::ProbeBatchTracer;
use probegi_field::ddgi_field_set::DdgiFieldSet;
use probegi_field::ddgi_volume::DdgiVolume;
use probegi_frame::field_update::FieldSetUpdate;
use probegi_scene::{BvhSettings, BvhTracer, load_scene};

fn settings() -> DdgiVolumeSettings {
    DdgiVolumeSettings {
        probe_counts: UVec3::new(16, 4, 16),
        probe_rays_per_probe: 64,
        shadow_field: true,
        shadow_field_sharpness: 2.0,
        ..Default::default()
    }
}

#[test]
fn gpu_traced_shadow_maps_match_the_cpus() {
    // The seed's field (every surfel), and surfels within one cage diagonal.
    for reach in [0.0, 1.0] {
        maps_match(DdgiVolumeSettings { shadow_field_surfel_reach_rel: reach, ..settings() });
    }
}

/// The occlusion maps after 5 frames with `s`, traced and blended on the CPU
/// and on the device, read back.
fn maps_match(s: DdgiVolumeSettings) {
    let scene = load_scene("builtin:shadow-box").expect("builtin");
    let Some(gpu) = common::resident_tracer(&scene) else { return };
    let cpu = BvhTracer::for_scene(&scene, BvhSettings::default());
    let direct = DirectLighting::new(&scene, &cpu, DirectSettings::default());
    let bounds = scene.bounds().expect("geometry");
    let new_set = || DdgiFieldSet::single(DdgiVolume::new(s.clone(), bounds));
    let (mut on_cpu, mut on_gpu) = (new_set(), new_set());
    let mut ms = BTreeMap::new();
    for f in 0..5 {
        on_cpu.update_traced_by(&scene, &cpu, None, &direct, 5, f, &mut ms).expect("CPU");
        on_gpu.update_traced_by(&scene, &cpu, Some(&gpu), &direct, 5, f, &mut ms).expect("GPU");
    }
    // The device cast the shadow rays and blended the maps it holds: read them back.
    assert!(on_gpu.field_on_device(), "the GPU kept the field");
    on_gpu.sync_host_atlases(Some(&gpu as &dyn ProbeBatchTracer)).expect("read back");
    let (c, g) = (&on_cpu.volumes()[0], &on_gpu.volumes()[0]);
    assert_eq!(c.probe_states, g.probe_states, "probe states");
    let (oc, og) = (&c.shadow.as_ref().expect("cpu").occlusion, &g.shadow.as_ref().expect("gpu").occlusion);
    let worst = oc.texels.iter().zip(&og.texels).map(|(a, b)| (a - b).abs()).fold(0.0f32, f32::max);
    let mean = oc.texels.iter().zip(&og.texels).map(|(a, b)| (a - b).abs()).sum::<f32>() / oc.texels.len() as f32;
    let shadowed = oc.texels.iter().filter(|v| **v < 0.5).count();
    let reach = s.shadow_field_surfel_reach_rel;
    eprintln!("reach {reach}: largest texel difference {worst:.2e}, mean {mean:.2e}; {shadowed} CPU texels below 0.5");
    assert!(shadowed > 100, "the box's maps hold shadow: {shadowed} texels below 0.5");
    assert!(worst < 1e-3, "occlusion maps differ by {worst}");
}

#[test]
fn the_shadow_box_renders_with_the_field_on_the_gpu_as_on_the_cpu() {
    compare_renders("camera", settings(), true);
}

#[test]
fn probe_rays_lit_through_the_field_agree_across_backends() {
    let s = DdgiVolumeSettings { shadow_field_probe_shading: true, ..settings() };
    compare_renders("camera and probe rays", s, false);
}

/// The shadow box rendered with `s` on the CPU (seeds 3 and 4) and the GPU (seed
/// 3); with `against_exact`, also against exact shadow rays.
fn compare_renders(name: &str, s: DdgiVolumeSettings, against_exact: bool) {
    let scene = load_scene("builtin:shadow-box").expect("builtin");
    let Some(gpu) = common::resident_tracer(&scene) else { return };
    let (a, b) =
        (common::render_ddgi(&scene, 8, 3, s.clone(), None), common::render_ddgi(&scene, 8, 4, s.clone(), None));
    let g = common::render_ddgi(&scene, 8, 3, s.clone(), Some(Arc::new(gpu)));
    let flip = |x: &Image, y: &Image| probegi_image::mean_flip_hdr(x, y).expect("same size");
    let (noise, f) = (flip(&a, &b), flip(&a, &g));
    eprintln!("{name}: HDR-FLIP CPU vs GPU {f:.4}; CPU seed 3 vs 4 {noise:.4}; means {} {}", a.mean(), g.mean());
    assert!(g.first_invalid_pixel().is_none());
    assert!(f < noise.max(0.02) + 0.005, "{name}: FLIP {f} above the seed noise {noise}");
    let (ma, mg) = (a.mean(), g.mean());
    assert!((ma - mg).abs().max_element() < 0.02 * ma.max_element(), "{name}: means {ma} vs {mg}");
    if !against_exact {
        return;
    }
    // The GPU camera reads the field, not shadow rays: exact shadows are farther
    // from the CPU's field image than the GPU's field image is.
    let exact = common::render_ddgi(&scene, 8, 3, DdgiVolumeSettings { shadow_field: false, ..s }, None);
    let fe = flip(&a, &exact);
    eprintln!("{name}: HDR-FLIP field vs exact shadow rays (CPU) {fe:.4}");
    assert!(f < 0.5 * fe, "{name}: the GPU image ({f}) is no closer to the field's than exact shadows are ({fe})");
}

#[test]
fn a_scrolling_window_keeps_the_same_shadow_maps_on_the_device() {
    // A tracking window sliding from under a roof into the open, under a point
    // light above the open part: probes that scroll in start over on both
    // backends (a stale device tile would keep the roof's shadow).
    let mut scene = probegi_scene::builtin::half_roofed_ground();
    scene.lights.push(probegi_scene::PunctualLight::point(glam::Vec3::new(30.0, 8.0, 0.0), glam::Vec3::ONE, 400.0));
    let Some(gpu) = common::resident_tracer(&scene) else { return };
    let cpu = BvhTracer::for_scene(&scene, BvhSettings::default());
    let direct = DirectLighting::new(&scene, &cpu, DirectSettings::default());
    let bounds = scene.bounds().expect("bounds");
    let s = DdgiVolumeSettings {
        probe_counts: UVec3::new(7, 3, 3),
        probe_rays_per_probe: 64,
        probe_spacing_m: Some(glam::Vec3::ONE),
        probe_origin_m: Some(glam::Vec3::new(0.0, 0.5, -1.0)),
        probe_relocation: false,
        volume_tracks_camera: true,
        shadow_field: true,
        ..Default::default()
    };
    let start = glam::Vec3::new(14.0, 1.5, 0.0);
    let new_set = || {
        let settings = probegi_core::ddgi_settings::DdgiFieldSetSettings::single(s.clone());
        DdgiFieldSet::new(&settings, bounds, Some(start))
    };
    let (mut on_cpu, mut on_gpu) = (new_set(), new_set());
    let mut ms = BTreeMap::new();
    let mut scrolled = 0;
    for f in 0..30 {
        let target = start + glam::Vec3::new(0.5 * f as f32, 0.0, 0.0);
        scrolled += on_cpu.set_tracking_target(target);
        on_gpu.set_tracking_target(target);
        on_cpu.update_traced_by(&scene, &cpu, None, &direct, 2, f, &mut ms).expect("CPU");
        on_gpu.update_traced_by(&scene, &cpu, Some(&gpu), &direct, 2, f, &mut ms).expect("GPU");
    }
    assert!(on_gpu.field_on_device() && scrolled > 0, "scrolled {scrolled} probes");
    on_gpu.sync_host_atlases(Some(&gpu as &dyn ProbeBatchTracer)).expect("read back");
    let (c, g) = (&on_cpu.volumes()[0], &on_gpu.volumes()[0]);
    let (oc, og) = (&c.shadow.as_ref().expect("cpu").occlusion, &g.shadow.as_ref().expect("gpu").occlusion);
    let worst = oc.texels.iter().zip(&og.texels).map(|(a, b)| (a - b).abs()).fold(0.0f32, f32::max);
    eprintln!("scrolling window ({scrolled} probes scrolled in): largest occlusion texel difference {worst:.2e}");
    assert!(worst < 1e-3, "occlusion maps differ by {worst} after scrolling");
}
