//! The per-frame ray budget (`ray_budget`, `probegi_field::ray_budget`) with
//! `--backend wgpu`'s tracer (the field kept on the device): the device measures
//! each blended probe's change (`probegi_wgpu::probe_change`, from what the
//! blends left beside the texels) and the host chooses from it, so on lavapipe,
//! whose hits equal the CPU's, the changes agree with the CPU's to float
//! rounding, the same probes trace every frame, and the camera renders within
//! the CPU's own seed-to-seed HDR-FLIP.

use std::collections::BTreeMap;
use std::sync::Arc;

use crate::common;
use glam::UVec3;
use probegi_core::ddgi_settings::{DdgiVolumeSettings, ProbeStatesMode};
use probegi_core::image::Image;
use probegi_cpu::{DirectLighting, DirectSettings};
use probegi_field::ProbeBatchTracer;
use probegi_field::ddgi_field_set::DdgiFieldSet;
use probegi_field::ddgi_volume::DdgiVolume;
use probegi_frame::field_update::FieldSetUpdate;
use probegi_scene::{BvhSettings, BvhTracer, load_scene};

const PROBES: u64 = 8 * 3 * 8;
const RAYS: u32 = 64;

fn settings(states: ProbeStatesMode) -> DdgiVolumeSettings {
    DdgiVolumeSettings {
        probe_counts: UVec3::new(8, 3, 8),
        probe_rays_per_probe: RAYS,
        shadow_field: true,
        probe_states: states,
        ray_budget: PROBES * RAYS as u64 / 4,
        ..Default::default()
    }
}

#[test]
fn the_device_measures_the_cpus_changes_and_the_same_probes_trace() {
    for states in [ProbeStatesMode::AllActive, ProbeStatesMode::Usage] {
        changes_match(settings(states));
    }
}

fn changes_match(s: DdgiVolumeSettings) {
    let scene = load_scene("builtin:shadow-box").expect("builtin");
    let Some(gpu) = common::resident_tracer(&scene) else { return };
    let cpu = BvhTracer::for_scene(&scene, BvhSettings::default());
    let direct = DirectLighting::new(&scene, &cpu, DirectSettings::default());
    let bounds = scene.bounds().expect("geometry");
    let new_set = || DdgiFieldSet::single(DdgiVolume::new(s.clone(), bounds));
    let (mut on_cpu, mut on_gpu) = (new_set(), new_set());
    let mut ms = BTreeMap::new();
    let mut worst = 0.0f32;
    for f in 0..12 {
        on_cpu.update_traced_by(&scene, &cpu, None, &direct, 5, f, &mut ms).expect("CPU");
        on_gpu.update_traced_by(&scene, &cpu, Some(&gpu), &direct, 5, f, &mut ms).expect("GPU");
        assert!(on_gpu.field_on_device(), "the GPU kept the field");
        let (c, g) = (&on_cpu.volumes()[0], &on_gpu.volumes()[0]);
        assert_eq!(c.rays_per_frame(), g.rays_per_frame(), "frame {f}: rays");
        for p in 0..c.grid.probe_count() {
            let (a, b) = (c.probe_frames_since_traced(p), g.probe_frames_since_traced(p));
            assert_eq!(a, b, "frame {f}: probe {p} traced {a} vs {b} frames ago");
            worst = worst.max((c.probe_change(p) - g.probe_change(p)).abs());
        }
        assert_eq!(c.probe_states, g.probe_states, "frame {f}: probe states");
    }
    // Probes that waited blend with α^k on both sides (ray_budget_hysteresis_per_frame).
    on_gpu.sync_host_atlases(Some(&gpu as &dyn ProbeBatchTracer)).expect("read back");
    let (ic, ig) = (&on_cpu.volumes()[0].irradiance.texels, &on_gpu.volumes()[0].irradiance.texels);
    let atlas = ic.iter().zip(ig).map(|(a, b)| (*a - *b).abs().max_element()).fold(0.0f32, f32::max);
    assert!(atlas < 1e-3, "irradiance atlases differ by {atlas}");
    let budget = s.ray_budget;
    let rays = on_gpu.volumes()[0].rays_per_frame();
    eprintln!(
        "{:?}: largest change difference {worst:.2e}, atlas difference {atlas:.2e}; last frame {rays} rays (budget {budget})",
        s.probe_states
    );
    assert!(rays <= budget, "the budget holds on the device path: {rays}");
    assert!(worst < 1e-3, "probe changes differ by {worst}");
    assert!(ms.contains_key("probe_change"), "the device measured the changes: {ms:?}");
}

#[test]
fn a_budgeted_field_renders_on_the_gpu_as_on_the_cpu() {
    let scene = load_scene("builtin:shadow-box").expect("builtin");
    let Some(gpu) = common::resident_tracer(&scene) else { return };
    let s = settings(ProbeStatesMode::Jcgt);
    let (a, b) =
        (common::render_ddgi(&scene, 16, 3, s.clone(), None), common::render_ddgi(&scene, 16, 4, s.clone(), None));
    let g = common::render_ddgi(&scene, 16, 3, s, Some(Arc::new(gpu)));
    let flip = |x: &Image, y: &Image| probegi_image::mean_flip_hdr(x, y).expect("same size");
    let (noise, f) = (flip(&a, &b), flip(&a, &g));
    eprintln!("ray budget: HDR-FLIP CPU vs GPU {f:.4}; CPU seed 3 vs 4 {noise:.4}; means {} {}", a.mean(), g.mean());
    assert!(g.first_invalid_pixel().is_none());
    assert!(f < noise.max(0.02) + 0.005, "FLIP {f} above the seed noise {noise}");
}
