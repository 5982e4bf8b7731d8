//! The device-resident update (`WgpuProbeTracer::keeping_field`): trace, shade,
//! blend and border on the GPU with the atlases living there, against the same
//! GPU trace and shade blended on the host (`tests/it/field_equivalence.rs` holds
//! that path to the CPU backend).
//!
//! Both paths see the same hits and the same shaded radiance (the shade's random
//! numbers depend on seed, frame and ray only), and the blend sums the CPU's own
//! weight tables in the CPU's order, so the atlases differ only by float
//! contraction on the device (`a*b + c` fused or not), fed back through the
//! field's own light: bound 1e-5 of the largest texel after 1 and 100 frames
//! (measured on lavapipe: irradiance 4.4e-7, distance 0).
//! Probe states, which the host classifies from counts the device makes under
//! the usage scheme, must be equal, and so must the relocation offsets, which
//! the device computes from the initialisation rounds' hits (to 1e-6 m); reruns
//! bit-identical.

use crate::common;

use probegi_frame::field_update::FieldSetUpdate;
use std::collections::BTreeMap;

use glam::UVec3;
use probegi_core::ddgi_settings::{DdgiVolumeSettings, ProbeStatesMode};
use probegi_core::probe_classification::probe_usage;
use probegi_cpu::{DirectLighting, DirectSettings};
use probegi_field::ddgi_field_set::{DdgiFieldSet, HostHits, UpdateStep};
use probegi_field::ddgi_volume::DdgiVolume;
use probegi_field::{DeviceUsageRequest, ProbeBatchTracer};
use probegi_scene::{BvhSettings, BvhTracer, Scene};
use probegi_wgpu::GpuContext;
use probegi_wgpu::wgpu_field_backend::WgpuProbeTracer;

fn gpu(scene: &Scene, bvh: &BvhTracer, keep: bool) -> Option<WgpuProbeTracer> {
    gpu_generating(scene, bvh, keep, false)
}

/// With `generate`, the device makes the update rays itself (`probe_ray_gen`).
fn gpu_generating(scene: &Scene, bvh: &BvhTracer, keep: bool, generate: bool) -> Option<WgpuProbeTracer> {
    let ctx = GpuContext::headless_unless_absent().expect("PROBEGI_REQUIRE_GPU is set")?;
    let t = WgpuProbeTracer::with_camera(ctx, scene, bvh, true, false)
        .expect("upload")
        .keeping_field(keep)
        .generating_rays(generate);
    assert_eq!(t.keeps_field(), keep);
    Some(t)
}

/// Largest texel difference over the largest texel, irradiance and distance.
fn max_difference(a: &DdgiVolume, b: &DdgiVolume) -> (f32, f32) {
    fn rel(x: &[f32], y: &[f32]) -> f32 {
        let scale = x.iter().fold(0f32, |m, v| m.max(v.abs())).max(1e-6);
        x.iter().zip(y).fold(0f32, |m, (p, q)| m.max((p - q).abs())) / scale
    }
    let i = |v: &DdgiVolume| v.irradiance.texels.iter().flat_map(|t| t.to_array()).collect::<Vec<f32>>();
    let d = |v: &DdgiVolume| v.distance.texels.iter().flat_map(|t| t.to_array()).collect::<Vec<f32>>();
    (rel(&i(a), &i(b)), rel(&d(a), &d(b)))
}

/// The host blend against the device's; `generate`: the device makes its own
/// update rays, and texels may differ by `bound` (of the largest) instead of 1e-5.
fn run_pair(settings: DdgiVolumeSettings, frames: u32, check_at: &[u32], generate: bool, bound: (f32, f32)) {
    let scene = probegi_scene::builtin::cornell_box();
    let bvh = BvhTracer::for_scene(&scene, BvhSettings::default());
    let (Some(host), Some(device), Some(again)) = (
        gpu(&scene, &bvh, false),
        gpu_generating(&scene, &bvh, true, generate),
        gpu_generating(&scene, &bvh, true, generate),
    ) else {
        return;
    };
    let direct = DirectLighting::new(&scene, &bvh, DirectSettings::default());
    let bounds = scene.bounds().expect("geometry");
    let new_set = || DdgiFieldSet::single(DdgiVolume::new(settings.clone(), bounds));
    let (mut on_host, mut on_device, mut rerun) = (new_set(), new_set(), new_set());
    let mut ms = BTreeMap::new();
    for f in 0..frames {
        on_host.update_traced_by(&scene, &bvh, Some(&host), &direct, 5, f, &mut ms).expect("host blend");
        on_device.update_traced_by(&scene, &bvh, Some(&device), &direct, 5, f, &mut ms).expect("device blend");
        assert!(on_device.field_on_device() && !on_host.field_on_device());
        let (h, d) = (&on_host.volumes()[0], &on_device.volumes()[0]);
        assert_eq!(h.probe_states, d.probe_states, "probe states, frame {f}");
        let moved = h.probe_offsets.iter().filter(|o| **o != glam::Vec3::ZERO).count();
        let worst = h
            .probe_offsets
            .iter()
            .zip(&d.probe_offsets)
            .map(|(a, b)| (*a - *b).abs().max_element())
            .fold(0.0, f32::max);
        if f == 0 {
            eprintln!("relocation: {moved} probes moved; device vs host offsets differ by {worst:.1e} m at most");
            assert!(!h.settings.probe_relocation || moved > 0, "the Cornell box's walls and blocks move probes");
        }
        assert!(worst <= 1e-6, "relocation offsets differ by {worst} m, frame {f}");
        if f < 3 {
            rerun.update_traced_by(&scene, &bvh, Some(&again), &direct, 5, f, &mut ms).expect("device blend");
        }
        if check_at.contains(&f) {
            on_device.sync_host_atlases(Some(&device)).expect("read back");
            assert!(!on_device.field_on_device());
            let (h, d) = (&on_host.volumes()[0], &on_device.volumes()[0]);
            let (di, dd) = max_difference(h, d);
            eprintln!(
                "{:?} states, after {} frames: device vs host blend: irradiance {di:.2e}, distance {dd:.2e} of the largest texel; states {:?}",
                settings.probe_states,
                f + 1,
                d.state_counts()
            );
            assert!(di < bound.0 && dd < bound.1, "frame {f}: {di:e} {dd:e}");
            d.validate();
        }
        if f == 0 {
            // The device ran the initialisation rounds; the host path read the hits back.
            let (reloc, classify) = device.init_rounds_on_device();
            let s = &settings;
            let want_reloc = if s.probe_relocation { s.probe_relocation_iterations } else { 0 };
            assert_eq!(reloc, want_reloc, "relocation iterations on the device");
            assert_eq!(classify, (s.probe_states == ProbeStatesMode::Jcgt) as u32, "classification rounds");
            assert_eq!(host.init_rounds_on_device(), (0, 0));
        }
        if f == 2 {
            rerun.sync_host_atlases(Some(&again)).expect("read back");
            on_device.sync_host_atlases(Some(&device)).expect("read back");
            let (a, b) = (&on_device.volumes()[0], &rerun.volumes()[0]);
            assert_eq!(a.irradiance.texels, b.irradiance.texels, "a device rerun is bit-identical");
            assert_eq!(a.distance.texels, b.distance.texels);
        }
    }
}

#[test]
fn a_field_kept_on_the_gpu_matches_the_host_blend_after_1_and_100_frames() {
    let settings =
        DdgiVolumeSettings { probe_counts: UVec3::splat(6), probe_rays_per_probe: 128, ..Default::default() };
    run_pair(settings, 100, &[0, 99], false, (1e-5, 1e-5));
}

#[test]
fn jcgt_states_without_relocation_are_classified_on_the_gpu_as_on_the_host() {
    // The chain with no relocation round: the classification traces every
    // probe once and reads its own kept hits (`DeviceField::initialise`).
    let settings = DdgiVolumeSettings {
        probe_counts: UVec3::splat(8),
        probe_rays_per_probe: 64,
        probe_relocation: false,
        ..Default::default()
    };
    run_pair(settings, 2, &[1], false, (1e-5, 1e-5));
}

#[test]
fn a_field_kept_on_the_gpu_with_pgi_safeguards_matches_the_host_blend() {
    // Timberdoodle PGI's firefly clamp and adaptive per-texel hysteresis: the
    // device keeps its own per-texel states, the host its own; same bound.
    let settings = DdgiVolumeSettings {
        probe_counts: UVec3::splat(6),
        probe_rays_per_probe: 128,
        probe_firefly_clamp_ratio: 32.0,
        probe_adaptive_hysteresis: true,
        ..Default::default()
    };
    run_pair(settings, 100, &[0, 99], false, (1e-5, 1e-5));
}

#[test]
fn the_adaptive_hysteresis_turned_on_while_the_device_holds_the_field_starts_its_states() {
    // The resident field holds no per-texel states until a member asks for
    // them; turning `probe_adaptive_hysteresis` on mid-run allocates them
    // (zeroed) instead of failing the frame, on both paths alike.
    let scene = probegi_scene::builtin::cornell_box();
    let bvh = BvhTracer::for_scene(&scene, BvhSettings::default());
    let (Some(host), Some(device)) = (gpu(&scene, &bvh, false), gpu(&scene, &bvh, true)) else { return };
    let direct = DirectLighting::new(&scene, &bvh, DirectSettings::default());
    let settings = DdgiVolumeSettings { probe_counts: UVec3::splat(4), probe_rays_per_probe: 64, ..Default::default() };
    let new_set = || DdgiFieldSet::single(DdgiVolume::new(settings.clone(), scene.bounds().expect("geometry")));
    let (mut on_host, mut on_device) = (new_set(), new_set());
    let mut ms = BTreeMap::new();
    for f in 0..12 {
        if f == 6 {
            on_host.volumes_mut()[0].settings.probe_adaptive_hysteresis = true;
            on_device.volumes_mut()[0].settings.probe_adaptive_hysteresis = true;
        }
        on_host.update_traced_by(&scene, &bvh, Some(&host), &direct, 5, f, &mut ms).expect("host blend");
        on_device.update_traced_by(&scene, &bvh, Some(&device), &direct, 5, f, &mut ms).expect("device blend");
        assert!(on_device.field_on_device(), "frame {f}");
    }
    on_device.sync_host_atlases(Some(&device)).expect("read back");
    let (di, dd) = max_difference(&on_host.volumes()[0], &on_device.volumes()[0]);
    assert!(di < 1e-5 && dd < 1e-5, "{di:e} {dd:e}");
}

#[test]
fn a_field_kept_on_the_gpu_with_its_own_rays_stays_within_the_ray_directions_rounding() {
    // The device generates the update rays (probe_ray_gen.wgsl): directions within
    // 2.4e-5 of the host's, so a ray grazing an edge may hit the other surface and
    // its distance texels move: measured 6.3e-4 after 1 frame and 3.2e-5 after
    // 100, irradiance 1.7e-5 and 7.3e-5 (bounds about 4× those).
    let settings =
        DdgiVolumeSettings { probe_counts: UVec3::splat(6), probe_rays_per_probe: 128, ..Default::default() };
    run_pair(settings, 100, &[0, 99], true, (3e-4, 3e-3));
}

/// Seed 003's usage scheme on the Cornell box, 8³ probes × 64 rays; relocation
/// off, so the probes inside the blocks stay there and go DEAD.
fn usage_settings() -> DdgiVolumeSettings {
    DdgiVolumeSettings {
        probe_counts: UVec3::splat(8),
        probe_rays_per_probe: 64,
        probe_states: ProbeStatesMode::Usage,
        probe_relocation: false,
        ..Default::default()
    }
}

#[test]
fn usage_states_from_gpu_counts_match_the_host_ones() {
    let settings = usage_settings();
    run_pair(settings, 12, &[0, 11], false, (1e-5, 1e-5));
}

#[test]
fn usage_states_with_counts_read_at_once_match_the_host_ones() {
    // `probe_usage_lag_updates` 0: seed 003's same-batch classification, the
    // device's counts waited for inside the update.
    let settings = DdgiVolumeSettings { probe_usage_lag_updates: 0, ..usage_settings() };
    run_pair(settings, 12, &[0, 11], false, (1e-5, 1e-5));
}

/// The blocking waits of each of `frames` updates of `set` on `device` after
/// frame 0 (whose initialisation rounds read back once), the device having
/// finished the earlier frames before each (the test waits outside the update).
fn waits_by_frame(
    device: &WgpuProbeTracer,
    set: &mut DdgiFieldSet,
    scene: &Scene,
    bvh: &BvhTracer,
    direct: &DirectLighting,
    frames: u32,
) -> Vec<u64> {
    let mut waits = Vec::new();
    for f in 0..frames {
        device.ctx.wait().expect("the device finishes the earlier frames");
        let before = device.ctx.counters();
        set.update_traced_by(scene, bvh, Some(device), direct, 3, f, &mut BTreeMap::new()).expect("frame");
        waits.extend((f >= 1).then(|| (device.ctx.counters() - before).blocking_waits));
    }
    waits
}

#[test]
fn usage_counts_come_back_late_and_an_update_never_waits_for_them() {
    // Issue "The field update at the seeds' GPU rates…", goal 2: under the
    // usage scheme the host reads the counts back `probe_usage_lag_updates`
    // batches late. Once the device has finished the earlier batches (the
    // test waits for it outside the update), an update blocks on nothing.
    // With the counts read at once (lag 0) it may wait once (not on
    // lavapipe, whose submission runs the work before it returns).
    let scene = probegi_scene::builtin::cornell_box();
    let bvh = BvhTracer::for_scene(&scene, BvhSettings::default());
    let direct = DirectLighting::new(&scene, &bvh, DirectSettings::default());
    for (lag, most_waits) in [(2, 0), (1, 0), (0, 1)] {
        let Some(device) = gpu(&scene, &bvh, true) else { return };
        let settings = DdgiVolumeSettings { probe_usage_lag_updates: lag, ..usage_settings() };
        let mut set = DdgiFieldSet::single(DdgiVolume::new(settings, scene.bounds().expect("geometry")));
        let waits = waits_by_frame(&device, &mut set, &scene, &bvh, &direct, 6);
        assert!(waits.iter().all(|&w| w <= most_waits), "lag {lag}: blocking waits by frame {waits:?}");
        // The states moved on from the start-up's (every probe Alive): the counts arrived.
        let counts = set.volumes()[0].state_counts();
        assert!(counts.get("dead").copied().unwrap_or(0) > 0, "lag {lag}: {counts:?}");
    }
}

#[test]
fn probe_changes_come_back_late_and_a_budgeted_update_never_waits_for_them() {
    // Goal 2 again, for the ray budget: the device measures each blended
    // probe's change after its blend and the host reads the changes back
    // `ray_budget_change_lag_updates` batches late. With the device done
    // with the earlier batches, a budgeted update blocks on nothing; read at
    // once (lag 0) it may wait (not on lavapipe, which finishes the work
    // inside the submission). Half the probes' rays a frame.
    let scene = probegi_scene::builtin::cornell_box();
    let bvh = BvhTracer::for_scene(&scene, BvhSettings::default());
    let direct = DirectLighting::new(&scene, &bvh, DirectSettings::default());
    for (lag, most_waits) in [(2, 0), (1, 0), (0, 1)] {
        let Some(device) = gpu(&scene, &bvh, true) else { return };
        let settings = DdgiVolumeSettings {
            probe_counts: UVec3::splat(6),
            probe_rays_per_probe: 32,
            probe_relocation: false,
            probe_states: ProbeStatesMode::AllActive,
            ray_budget: 6 * 6 * 6 * 32 / 2,
            ray_budget_change_lag_updates: lag,
            ..Default::default()
        };
        let mut set = DdgiFieldSet::single(DdgiVolume::new(settings, scene.bounds().expect("geometry")));
        let waits = waits_by_frame(&device, &mut set, &scene, &bvh, &direct, 6);
        assert!(waits.iter().all(|&w| w <= most_waits), "lag {lag}: blocking waits by frame {waits:?}");
        // The changes arrived: the first blends' full change gave way to measured ones.
        let v = &set.volumes()[0];
        let measured = (0..v.grid.probe_count()).filter(|&p| v.probe_change(p) < 1.0).count();
        assert!(measured > 0, "lag {lag}: no change came back");
    }
}

/// A usage-scheme set (`usage_settings`) over `scene`, its frame 0 updated
/// on `device` and frame 1's update batch planned (to trace).
fn usage_set_at_frame_1(scene: &Scene, bvh: &BvhTracer, device: &WgpuProbeTracer) -> DdgiFieldSet {
    let direct = DirectLighting::new(scene, bvh, DirectSettings::default());
    let mut set = DdgiFieldSet::single(DdgiVolume::new(usage_settings(), scene.bounds().expect("geometry")));
    set.update_traced_by(scene, bvh, Some(device), &direct, 3, 0, &mut BTreeMap::new()).expect("frame 0");
    assert_eq!(set.begin_update(3, 1), UpdateStep::TraceRays);
    set
}

#[test]
fn a_batch_counted_again_comes_back_once() {
    // An update that fails after the count is retried under the same batch
    // number: the second count replaces the first, so the set gets each
    // batch once (a second would be refused as a batch it no longer waits for).
    let scene = probegi_scene::builtin::cornell_box();
    let bvh = BvhTracer::for_scene(&scene, BvhSettings::default());
    let Some(device) = gpu(&scene, &bvh, true) else { return };
    let set = usage_set_at_frame_1(&scene, &bvh, &device);
    let request = set.device_usage_request().expect("usage");
    let dev: &dyn probegi_field::DeviceField = &device;
    let count = |request: &DeviceUsageRequest| {
        let back = dev.trace_resident(set.ray_batch(), Some(request)).expect("keeps the field").expect("trace");
        back.iter().map(|c| (c.batch, c.counts.len())).collect::<Vec<_>>()
    };
    let probes = set.ray_batch().probes.len();
    // Lag 2: frame 0's batch is due at batch 2, this one's at 3.
    assert_eq!(count(&request), []);
    assert_eq!(count(&request), [], "the same batch again");
    let later = |batch| DeviceUsageRequest { batch, ..request.clone() };
    assert_eq!(count(&later(request.batch + 1)), [(request.batch - 1, probes)]);
    assert_eq!(count(&later(request.batch + 2)), [(request.batch, probes)], "once");
}

#[test]
fn gpu_usage_counts_equal_the_core_function_over_the_same_hits() {
    let scene = probegi_scene::builtin::cornell_box();
    let bvh = BvhTracer::for_scene(&scene, BvhSettings::default());
    let Some(device) = gpu(&scene, &bvh, true) else { return };
    let set = usage_set_at_frame_1(&scene, &bvh, &device);
    assert_eq!(set.hits_needed_on_host(), HostHits::ProbeUsage);
    let diagonal = set.volumes()[0].grid.spacing_m.length();
    // Lag 0: this batch's own counts, read back at once.
    let request = DeviceUsageRequest { lag_updates: 0, ..set.device_usage_request().expect("usage") };
    assert_eq!(request.cage_diagonals_m, [diagonal]);
    let batch = set.ray_batch();
    let back = probegi_field::DeviceField::trace_resident(&device, batch, Some(&request))
        .expect("keeps the field")
        .expect("trace");
    // (Frame 0's batch, two batches from due, comes back with it.)
    assert_eq!(back.iter().map(|c| c.batch).collect::<Vec<_>>(), [request.batch - 1, request.batch]);
    let counts = &back[1].counts;
    let mut hits = Vec::new();
    device.closest_hits(batch, false, &mut hits).expect("trace");
    assert_eq!(counts.len(), batch.probes.len());
    let (mut dead, mut mismatches) = (0, 0);
    for (bp, c) in batch.probes.iter().zip(counts) {
        let rays = bp.first_ray as usize..(bp.first_ray + bp.ray_count) as usize;
        let signed = hits[rays].iter().map(|h| match h {
            Some(h) if h.backface => -h.t,
            Some(h) => h.t,
            None => f32::INFINITY,
        });
        let cpu = probe_usage(signed, diagonal);
        mismatches += (cpu != *c) as usize;
        dead += (c.1 > 0 && c.2 * 2 > c.1) as usize;
    }
    eprintln!("{} probes: {dead} with mostly backfaces (DEAD), {mismatches} count mismatches", counts.len());
    assert_eq!(mismatches, 0);
    assert!(dead > 0, "some probes lie inside the blocks");
}

#[test]
fn the_usage_pass_reads_no_cage_diagonal_past_the_table_it_is_given() {
    // The usage pass keeps its cage-diagonal buffer from batch to batch,
    // rewriting it in place: after a table of two volumes, a table of one
    // must give a probe of the second volume r = 0 (no front hit counts), as
    // a volume past the end always has, not the second volume's stale r.
    let scene = probegi_scene::builtin::cornell_box();
    let bvh = BvhTracer::for_scene(&scene, BvhSettings::default());
    let Some(device) = gpu(&scene, &bvh, true) else { return };
    let set = usage_set_at_frame_1(&scene, &bvh, &device);
    // The batch's probes as a second volume's, with no identity to keep them by.
    let mut batch = set.ray_batch().clone();
    batch.probes.iter_mut().for_each(|p| p.volume = 1);
    batch.generated.iter_mut().for_each(|g| g.plan_id = None);
    let request = DeviceUsageRequest { lag_updates: 0, ..set.device_usage_request().expect("usage") };
    let counts = |diagonals: Vec<f32>, batch_number: u64| {
        let r = DeviceUsageRequest { cage_diagonals_m: diagonals, batch: batch_number, ..request.clone() };
        let back = probegi_field::DeviceField::trace_resident(&device, &batch, Some(&r))
            .expect("keeps the field")
            .expect("trace");
        let own = back.into_iter().find(|c| c.batch == batch_number).expect("this batch's counts");
        own.counts.iter().map(|c| c.0.max(0) as u64).sum::<u64>()
    };
    let front_hits_within = counts(vec![1.0, 100.0], request.batch);
    assert!(front_hits_within > 0, "a 100 m diagonal counts the box's front hits");
    assert_eq!(counts(vec![1.0], request.batch + 1), 0, "a volume past the table has r = 0");
}

#[test]
fn sponza_is_relocated_and_classified_on_the_gpu_as_on_the_host() {
    // The shared Sponza at 16×8×16 is where the covering pass matters (thick walls
    // whose nearest probes lie behind them; see probegi_core::probe_classification).
    // A covering pass run as one long invocation was cut short on lavapipe (49
    // states wrong); the order-free pass (`cover_proposals`) runs as short
    // dispatches and must keep the host's probes exactly.
    let scene = probegi_scene::load_scene(&common::shared("dabrovic-sponza/sponza.obj")).expect("the shared Sponza");
    let bvh = BvhTracer::for_scene(&scene, BvhSettings::default());
    let (Some(host), Some(device)) = (gpu(&scene, &bvh, false), gpu(&scene, &bvh, true)) else { return };
    let direct = DirectLighting::new(&scene, &bvh, DirectSettings::default());
    let settings =
        DdgiVolumeSettings { probe_counts: UVec3::new(16, 8, 16), probe_rays_per_probe: 64, ..Default::default() };
    let bounds = scene.bounds().expect("geometry");
    let mut sets = [0, 1].map(|_| DdgiFieldSet::single(DdgiVolume::new(settings.clone(), bounds)));
    for (set, t) in sets.iter_mut().zip([&host, &device]) {
        set.update_traced_by(&scene, &bvh, Some(t), &direct, 7, 0, &mut BTreeMap::new()).expect("frame 0");
    }
    let (h, d) = (&sets[0].volumes()[0], &sets[1].volumes()[0]);
    let moved = h.probe_offsets.iter().filter(|o| **o != glam::Vec3::ZERO).count();
    let worst =
        h.probe_offsets.iter().zip(&d.probe_offsets).map(|(a, b)| (*a - *b).abs().max_element()).fold(0.0, f32::max);
    let differ = h.probe_states.iter().zip(&d.probe_states).filter(|(a, b)| a != b).count();
    eprintln!(
        "Sponza: {moved} probes relocated (offsets differ by {worst:.1e} m at most); states {:?}; {differ} differ",
        d.state_counts()
    );
    assert!(device.init_rounds_on_device().1 == 1 && moved > 0);
    assert!(worst <= 1e-6, "offsets differ by {worst} m");
    assert_eq!(differ, 0, "probe states");

    // The same rounds with rays the device makes itself (what `render` runs):
    // directions within 2.4e-5 of the host's, so a ray that grazes an edge may
    // hit the other surface and move its probe differently, or flip a state.
    // Such probes are counted, against 1 % of the grid.
    let Some(generating) = gpu_generating(&scene, &bvh, true, true) else { return };
    let mut set = DdgiFieldSet::single(DdgiVolume::new(settings, bounds));
    set.update_traced_by(&scene, &bvh, Some(&generating), &direct, 7, 0, &mut BTreeMap::new()).expect("frame 0");
    let g = &set.volumes()[0];
    let offsets_apart =
        h.probe_offsets.iter().zip(&g.probe_offsets).filter(|(a, b)| (**a - **b).abs().max_element() > 1e-5).count();
    let states_apart = h.probe_states.iter().zip(&g.probe_states).filter(|(a, b)| a != b).count();
    eprintln!("rays made on the device: {offsets_apart} offsets and {states_apart} states differ from the host's");
    let bound = h.grid.probe_count() / 100;
    assert!(offsets_apart <= bound && states_apart <= bound, "{offsets_apart} offsets, {states_apart} states apart");
}

#[test]
fn cascades_kept_on_the_gpu_converge_in_the_furnace() {
    // Seed 003 §6.2: three camera-centred cascades under Algorithm 2, every one
    // blended into the device's field (one ray batch, three atlas ranges of one
    // buffer), the camera frame reading it there: L = Le / (1 − ρ) = 2.
    use probegi_core::camera::CameraRays;
    use probegi_core::ddgi_settings::DdgiFieldSetSettings;
    use probegi_field::ProbeTracerHandle;
    use probegi_frame::frame_loop::{GiMethod, RenderSettings, render_frames};
    let scene = probegi_scene::builtin::furnace_box(0.5, 1.0);
    let bvh = BvhTracer::for_scene(&scene, BvhSettings::default());
    let Some(ctx) = GpuContext::headless_unless_absent().expect("PROBEGI_REQUIRE_GPU is set") else { return };
    let gpu = WgpuProbeTracer::new(ctx, &scene, &bvh, true).expect("upload").keeping_field(true);
    assert!(gpu.keeps_field() && gpu.renders_camera());
    let gpu = std::sync::Arc::new(gpu);
    let camera = scene.camera.expect("camera");
    let rays = CameraRays::new(&camera, 24, 24);
    let base = DdgiVolumeSettings {
        probe_hysteresis: 0.8,
        probe_counts: UVec3::splat(5),
        probe_rays_per_probe: 64,
        ..Default::default()
    };
    let (lo, hi) = scene.bounds().expect("bounds");
    let set = DdgiFieldSetSettings::cascades(3, &base, (hi - lo) / 8.0, 2.0);
    let settings = RenderSettings {
        width: 24,
        height: 24,
        frames: 80,
        seed: 2,
        gi: GiMethod::DdgiSet(Box::new(set)),
        probe_tracer: Some(ProbeTracerHandle(gpu.clone())),
        ..Default::default()
    };
    let out = render_frames(&scene, &bvh, &rays, &settings, |_, _| {});
    assert_eq!(out.stats.error, None);
    let mean = out.image.mean();
    eprintln!(
        "furnace under 3 cascades kept on the GPU: image mean {mean} (analytic 2); field {} KiB on the device",
        gpu.field_bytes() / 1024
    );
    assert!((mean.x - 2.0).abs() < 0.06, "mean {mean}, want 2 within 3 %");
    let set = out.ddgi.expect("set");
    assert!(!set.field_on_device(), "the render reads the field back at its end");
    assert_eq!(set.volumes().len(), 3);
    for v in set.volumes() {
        v.validate();
        assert!(v.irradiance.texels.iter().any(|t| t.x > 0.0), "every cascade was blended on the device");
    }
}

#[test]
fn a_coarse_first_set_blends_every_volume_into_its_own_atlases_on_the_gpu() {
    // Two volumes given coarse first: the query samples the dense one first, so
    // sampling order and the set's order differ, and with equal probe counts a
    // mix-up of the two would swap atlases silently.
    use probegi_core::ddgi_settings::DdgiFieldSetSettings;
    use probegi_core::ddgi_volume_blend::VolumeBlending;
    let scene = probegi_scene::builtin::cornell_box();
    let bvh = BvhTracer::for_scene(&scene, BvhSettings::default());
    let (Some(host), Some(device)) = (gpu(&scene, &bvh, false), gpu(&scene, &bvh, true)) else { return };
    let direct = DirectLighting::new(&scene, &bvh, DirectSettings::default());
    let (lo, hi) = scene.bounds().expect("bounds");
    let (mid, q) = ((lo + hi) * 0.5, (hi - lo) * 0.25);
    let small = DdgiVolumeSettings { probe_counts: UVec3::splat(4), probe_rays_per_probe: 64, ..Default::default() };
    let coarse = DdgiVolumeSettings { volume_bounds_m: Some([lo, hi]), ..small.clone() };
    let dense = DdgiVolumeSettings { volume_bounds_m: Some([mid - q, mid + q]), ..small };
    let settings = DdgiFieldSetSettings { volumes: vec![coarse, dense], blending: VolumeBlending::Density };
    let mut sets = [0, 1].map(|_| DdgiFieldSet::new(&settings, (lo, hi), None));
    assert_eq!(sets[0].view().members[0].volume, 1, "the dense volume is sampled first");
    let mut ms = BTreeMap::new();
    for f in 0..8 {
        for (set, t) in sets.iter_mut().zip([&host, &device]) {
            set.update_traced_by(&scene, &bvh, Some(t), &direct, 9, f, &mut ms).expect("update");
        }
    }
    sets[1].sync_host_atlases(Some(&device)).expect("read back");
    for (v, (h, d)) in sets[0].volumes().iter().zip(sets[1].volumes()).enumerate() {
        let (di, dd) = max_difference(h, d);
        eprintln!("volume {v}: device vs host blend: irradiance {di:.1e}, distance {dd:.1e} of the largest texel");
        assert!(di < 1e-5 && dd < 1e-5, "volume {v}: {di:e} {dd:e}");
        assert_eq!(h.probe_states, d.probe_states);
    }
}

#[test]
fn an_update_on_the_device_needs_no_cpu_lighting_and_is_the_same_update() {
    // `FieldSetUpdate::update_on_device` (what the frame loop runs where the
    // device keeps the field) against `update_traced_by` with the CPU's
    // lighting on a second device: the same states and atlases bit for bit,
    // since both run the same device passes; on a tracer that keeps no field
    // it is an error, not a CPU fallback.
    let scene = probegi_scene::builtin::cornell_box();
    let bvh = BvhTracer::for_scene(&scene, BvhSettings::default());
    let (Some(a), Some(b), Some(host)) = (gpu(&scene, &bvh, true), gpu(&scene, &bvh, true), gpu(&scene, &bvh, false))
    else {
        return;
    };
    let direct = DirectLighting::new(&scene, &bvh, DirectSettings::default());
    let settings = DdgiVolumeSettings { probe_counts: UVec3::splat(4), probe_rays_per_probe: 64, ..Default::default() };
    let bounds = scene.bounds().expect("geometry");
    let mut sets = [0, 1].map(|_| DdgiFieldSet::single(DdgiVolume::new(settings.clone(), bounds)));
    for f in 0..3 {
        let mut ms = BTreeMap::new();
        sets[0].update_on_device(&scene, &bvh, &a, 3, f, &mut ms).expect("update on the device");
        sets[1].update_traced_by(&scene, &bvh, Some(&b), &direct, 3, f, &mut ms).expect("update traced by");
    }
    for (set, t) in sets.iter_mut().zip([&a, &b]) {
        set.sync_host_atlases(Some(t)).expect("read back");
    }
    let (x, y) = (&sets[0].volumes()[0], &sets[1].volumes()[0]);
    assert_eq!(x.probe_states, y.probe_states);
    assert_eq!(max_difference(x, y), (0.0, 0.0), "atlases");
    let mut other = DdgiFieldSet::single(DdgiVolume::new(settings, bounds));
    let err = other.update_on_device(&scene, &bvh, &host, 3, 0, &mut BTreeMap::new());
    assert!(err.is_err_and(|e| e.to_string().contains("keeps no field")), "a tracer without a field");
}

#[test]
fn initialisation_rounds_on_a_device_that_makes_its_rays_upload_no_ray() {
    // With the device generating the rays (`generating_rays`), the start-up's
    // relocation and classification batches are planned per probe as the
    // update's are: what goes up in frame 0 is O(probes), not one origin and
    // direction a ray. Sponza at 16×8×16: 2 048 probes × 32 rays a round;
    // measured 0.59 MB besides the field against 7.9 MB of rays before.
    let scene = probegi_scene::load_scene(&common::shared("dabrovic-sponza/sponza.obj")).expect("the shared Sponza");
    let bvh = BvhTracer::for_scene(&scene, BvhSettings::default());
    let Some(device) = gpu_generating(&scene, &bvh, true, true) else { return };
    let direct = DirectLighting::new(&scene, &bvh, DirectSettings::default());
    let settings = DdgiVolumeSettings { probe_counts: UVec3::new(16, 8, 16), ..Default::default() };
    let mut set = DdgiFieldSet::single(DdgiVolume::new(settings, scene.bounds().expect("geometry")));
    let before = device.ctx.counters();
    set.update_traced_by(&scene, &bvh, Some(&device), &direct, 7, 0, &mut BTreeMap::new()).expect("frame 0");
    let up = (device.ctx.counters() - before).bytes_up;
    let (reloc, classify) = device.init_rounds_on_device();
    assert!(reloc >= 1 && classify == 1, "rounds on the device: {reloc} relocation, {classify} classification");
    // One round's rays as uploaded before: 32 bytes a ray (origin, t_min, direction, t_max).
    let one_round = set.last_init_rays / (reloc as u64 + 1) * 32;
    eprintln!(
        "frame 0 uploaded {up} bytes, the resident field {}; {} initialisation rays; a round's rays {one_round} bytes",
        device.field_bytes(),
        set.last_init_rays
    );
    // Besides the resident field (its atlases go up whole on the first update)
    // only per-probe data: less than one round's rays (each round uploaded
    // its rays before, 7.9 MB here).
    let besides = up - device.field_bytes();
    assert!(besides < one_round, "frame 0 uploaded {besides} bytes besides the field: a round's rays are {one_round}");
}

#[test]
fn a_still_field_on_the_device_uploads_no_per_probe_record_again() {
    // The render path (the device keeps the field and makes the rays) in a
    // still scene: once the probes' states have settled, each update's
    // per-probe records (ray generation, shading, blend plan, the query's
    // offsets and flags) repeat the last frame's, and the device keeps them
    // (`GpuContext::buffer_rewritten`): what goes up is the passes' parameter
    // blocks and the blend's ray directions, which turn with the frame's
    // rays, where it was 16 bytes a probe for each
    // record (110 KB a frame here). The start-up ramp's cap is a parameter, so this holds from the
    // second frame on, ramp or not.
    let scene = probegi_scene::builtin::cornell_box();
    let bvh = BvhTracer::for_scene(&scene, BvhSettings::default());
    let Some(device) = gpu_generating(&scene, &bvh, true, true) else { return };
    let direct = DirectLighting::new(&scene, &bvh, DirectSettings::default());
    let settings =
        DdgiVolumeSettings { probe_counts: UVec3::new(12, 12, 12), probe_rays_per_probe: 16, ..Default::default() };
    assert!(settings.probe_hysteresis_startup_ramp, "the default: the ramp runs through the frames below");
    let mut set = DdgiFieldSet::single(DdgiVolume::new(settings, scene.bounds().expect("geometry")));
    let update = |set: &mut DdgiFieldSet, f: u32| {
        set.update_traced_by(&scene, &bvh, Some(&device), &direct, 5, f, &mut BTreeMap::new()).expect("update");
    };
    for f in 0..3 {
        update(&mut set, f);
    }
    let (frames, before) = (8, device.ctx.counters());
    for f in 3..3 + frames {
        update(&mut set, f);
    }
    device.ctx.wait().expect("wait");
    let d = device.ctx.counters() - before;
    let (up, kept) = (d.bytes_up / frames as u64, d.bytes_kept / frames as u64);
    let probes = set.probe_count() as u64;
    let tracing = set.ray_batch().probes.len() as u64;
    eprintln!("{probes} probes, {tracing} tracing: {up} bytes up a frame, {kept} kept");
    assert!(tracing > probes / 4, "most probes of the box trace: {tracing} of {probes}");
    // Kept: the blend plan (16 bytes a probe), ray generation and shading (16
    // a tracing probe each).
    assert!(kept >= 16 * (probes + 2 * tracing), "kept {kept} bytes a frame");
    // Up: parameter blocks and weights, below half of one record of 16 bytes a probe.
    assert!(up < 16 * probes / 2, "{up} bytes up a frame");
}

#[test]
fn the_initialisation_rounds_run_chained_in_one_submission_with_one_read_back() {
    // Issue "The field update at the seeds' GPU rates…", goal 3: every
    // relocation round and the classification for every probe, recorded back
    // to back; the host reads back each probe's offset and (inside, kept)
    // once, 32 bytes a probe, and the states equal the host's rounds.
    let scene = probegi_scene::load_scene(&common::shared("dabrovic-sponza/sponza.obj")).expect("the shared Sponza");
    let bvh = BvhTracer::for_scene(&scene, BvhSettings::default());
    let (Some(host), Some(device)) = (gpu(&scene, &bvh, false), gpu(&scene, &bvh, true)) else { return };
    let direct = DirectLighting::new(&scene, &bvh, DirectSettings::default());
    let settings = DdgiVolumeSettings { probe_counts: UVec3::new(16, 8, 16), ..Default::default() };
    let bounds = scene.bounds().expect("geometry");
    let mut chained = DdgiFieldSet::single(DdgiVolume::new(settings.clone(), bounds));
    chained.begin_update(7, 0);
    let plan = chained.device_init_plan().expect("the first initialisation round");
    let dev: &dyn probegi_field::DeviceField = &device;
    let before = device.ctx.counters();
    let results = dev.initialise(&plan).expect("the device chains the rounds").expect("chain");
    let d = device.ctx.counters() - before;
    drop(plan);
    let probes = settings.probe_count();
    eprintln!("chained start-up: {d:?}");
    assert_eq!((d.submissions, d.blocking_waits), (1, 1), "one submission, one wait");
    assert_eq!(d.bytes_down, probes * 32, "an offset and a state a probe");
    assert_eq!(chained.submit_device_init(&results).expect("results"), UpdateStep::TraceRays);
    assert_eq!(chained.ray_batch().kind, probegi_field::ddgi_field_set::ProbeRayBatchKind::Update);

    // The host's rounds (the GPU traces each, the host relocates and classifies).
    let mut by_rounds = DdgiFieldSet::single(DdgiVolume::new(settings, bounds));
    by_rounds.update_traced_by(&scene, &bvh, Some(&host), &direct, 7, 0, &mut BTreeMap::new()).expect("frame 0");
    let (c, h) = (&chained.volumes()[0], &by_rounds.volumes()[0]);
    let moved = h.probe_offsets.iter().filter(|o| **o != glam::Vec3::ZERO).count();
    let worst =
        h.probe_offsets.iter().zip(&c.probe_offsets).map(|(a, b)| (*a - *b).abs().max_element()).fold(0.0, f32::max);
    assert!(moved > 0 && worst <= 1e-6, "{moved} probes moved; offsets differ by {worst} m");
    // The host's field has blended frame 0 since: its Newly * probes moved on.
    let differ = c.probe_states.iter().zip(&h.probe_states).filter(|(a, b)| a.after_update() != **b).count();
    assert_eq!(differ, 0, "probe states");
    assert_eq!(chained.last_init_rays, by_rounds.last_init_rays, "the same rounds skipped and kept");
}

#[test]
fn a_usage_schemes_kept_trace_on_the_device_blends_as_full_plans() {
    // Under the usage scheme a still field keeps its trace plan alone
    // (`DdgiFieldSet::update_kept_trace_plan`): the batch's probe records
    // and their identities stay, so the device keeps the ray generation's
    // and the usage pass's records, while the states, the shade's radiance
    // flags (their own identity, `ProbeRayBatch::probe_needs_radiance_id`)
    // and the blend plan move every frame. Against the same device passes
    // planned every frame in full (`set_steady_plans(false)`), the states and
    // the atlases are bit-identical; a shade that kept stale radiance flags
    // would leave the Usage Sleeping probes' rays unshaded (zero radiance) in
    // the frames they blend, and differ. The two sets run one after the other:
    // on one device (the tests share one) their kept records would replace
    // each other's every frame and hide a stale one.
    let scene = probegi_scene::builtin::cornell_box();
    let bvh = BvhTracer::for_scene(&scene, BvhSettings::default());
    let (Some(kept), Some(full)) = (gpu_generating(&scene, &bvh, true, true), gpu_generating(&scene, &bvh, true, true))
    else {
        return;
    };
    let direct = DirectLighting::new(&scene, &bvh, DirectSettings::default());
    // 12³ probes in the box: the inner ones see few hits within a cage
    // diagonal, so some sleep (Usage Sleeping blends every third frame).
    let settings = DdgiVolumeSettings {
        probe_counts: UVec3::splat(12),
        probe_rays_per_probe: 16,
        probe_states: ProbeStatesMode::Usage,
        probe_sleeping_update_interval: 3,
        probe_alive_min_frames: 2,
        ..Default::default()
    };
    let bounds = scene.bounds().expect("geometry");
    let mut sets = [0, 1].map(|_| DdgiFieldSet::single(DdgiVolume::new(settings.clone(), bounds)));
    sets[1].set_steady_plans(false);
    let mut runs = Vec::new();
    for (set, t) in sets.iter_mut().zip([&kept, &full]) {
        let (mut kept_frames, mut states, mut flags) = (0, Vec::new(), Vec::new());
        for f in 0..16 {
            if f == 7 {
                // A full plan off the sleepers' phase: its records say that
                // the Usage Sleeping probes need no radiance (frame 0's all do).
                set.volumes_mut()[0].settings.probe_hysteresis = 0.96;
            }
            set.update_traced_by(&scene, &bvh, Some(t), &direct, 5, f, &mut BTreeMap::new()).expect("update");
            kept_frames += set.update_kept_trace_plan() as u32;
            states.push(set.volumes()[0].probe_states.clone());
            flags.push(set.ray_batch().probe_needs_radiance.clone());
        }
        set.sync_host_atlases(Some(t)).expect("read back");
        runs.push((kept_frames, states, flags));
    }
    let [(kept_frames, states, flags), (full_kept, full_states, full_flags)] = <[_; 2]>::try_from(runs).expect("two");
    assert_eq!(full_kept, 0);
    assert_eq!(kept_frames, 14, "every frame but 0 and 7 keeps its trace");
    assert_eq!(states, full_states, "states frame by frame");
    assert_eq!(flags, full_flags, "radiance flags frame by frame");
    // Flags that turn on under a kept trace after frame 7's full plan: what
    // stale records would miss (before it, frame 0's records say every probe
    // needs radiance, so staleness there changes nothing).
    let turned_on = flags[7..].windows(2).filter(|w| w[0].iter().zip(&w[1]).any(|(a, b)| !a && *b)).count();
    assert!(turned_on >= 3, "probes' radiance flags turned on in {turned_on} frames: the test shows nothing");
    let (a, b) = (&sets[0].volumes()[0], &sets[1].volumes()[0]);
    eprintln!("needed per frame {:?}", flags.iter().map(|f| f.iter().filter(|x| **x).count()).collect::<Vec<_>>());
    eprintln!("kept traces {kept_frames}, flags turned on in {turned_on} frames, states {:?}", a.state_counts());
    assert_eq!(max_difference(a, b), (0.0, 0.0), "kept traces against full plans on the device");
}

#[test]
fn kept_plans_on_the_device_blend_as_full_plans_through_a_shading_change() {
    // A still field keeps its plan (`DdgiFieldSet::update_kept_plan`), and
    // the device keeps what it made of it: the ray generation's, the shade's
    // and the blend's per-probe records, by the plan's identity, and the
    // blend's check of its entries. Against the same device passes re-planned
    // every frame (`set_steady_plans(false)`), the atlases are bit-identical,
    // through a change of the shading (the hit AO switched on at frame 12,
    // which every shade record carries) that must renew them.
    //
    // Both device sets carry identities; the host blend over a shade given
    // its records every frame (no identity) holds the device's reuse of them:
    // they differ by the device rays' rounding only
    // (`a_field_kept_on_the_gpu_with_its_own_rays_stays_within_the_ray_directions_rounding`:
    // 7.3e-5 of the largest irradiance texel at 128 rays; twice that a flipped
    // ray at 64 rays, and twice again with an AO ray per hit that may flip:
    // bound 1.2e-3, measured 5.2e-4). Records kept past the AO switch would
    // miss the AO's darkening, several per cent of the light.
    let scene = probegi_scene::builtin::cornell_box();
    let bvh = BvhTracer::for_scene(&scene, BvhSettings::default());
    let (Some(kept), Some(full), Some(host)) =
        (gpu_generating(&scene, &bvh, true, true), gpu_generating(&scene, &bvh, true, true), gpu(&scene, &bvh, false))
    else {
        return;
    };
    let direct = DirectLighting::new(&scene, &bvh, DirectSettings::default());
    let settings = DdgiVolumeSettings { probe_counts: UVec3::splat(6), probe_rays_per_probe: 64, ..Default::default() };
    let bounds = scene.bounds().expect("geometry");
    let mut sets = [0, 1, 2].map(|_| DdgiFieldSet::single(DdgiVolume::new(settings.clone(), bounds)));
    sets[1].set_steady_plans(false);
    let mut kept_frames = [0u32; 2];
    for f in 0..24 {
        if f == 12 {
            for set in &mut sets {
                set.volumes_mut()[0].settings.probe_hit_ao_radius_rel = 0.5;
            }
        }
        let mut ms = BTreeMap::new();
        for (set, t) in sets.iter_mut().zip([&kept, &full, &host]) {
            set.update_traced_by(&scene, &bvh, Some(t), &direct, 5, f, &mut ms).expect("update");
        }
        assert!(!sets[1].update_kept_plan() && !sets[2].update_kept_plan());
        kept_frames[(f >= 12) as usize] += sets[0].update_kept_plan() as u32;
        assert!(f != 12 || !sets[0].update_kept_plan(), "a settings change plans again");
    }
    assert!(kept_frames.iter().all(|k| *k >= 4), "kept plans before and after the change: {kept_frames:?}");
    for (set, t) in sets.iter_mut().zip([&kept, &full, &host]) {
        set.sync_host_atlases(Some(t)).expect("read back");
    }
    let [a, b, c] = [0, 1, 2].map(|i| &sets[i].volumes()[0]);
    assert_eq!(a.probe_states, b.probe_states);
    assert_eq!(a.probe_states, c.probe_states);
    assert_eq!(max_difference(a, b), (0.0, 0.0), "kept plans against full plans on the device");
    let (di, dd) = max_difference(a, c);
    eprintln!("kept plans {kept_frames:?}; against the host blend: irradiance {di:.1e}, distance {dd:.1e}");
    assert!(di < 1.2e-3 && dd < 3e-3, "{di:e} {dd:e}");
}
