//! The shade pass's radiance flags apart from its per-probe records
//! (`probegi_wgpu::probe_shade::ShadeProbes`): a probe's rays are shaded only
//! where its flag is set (otherwise radiance 0 with the blend's distance), the
//! flags go up on their own (one bit a probe, in at least
//! `SHADE_RADIANCE_WORDS_MIN` words) while records under a kept identity stay
//! on the device, and a record's own flag (bit 31 of `info`,
//! as `GpuProbeShade::shade` takes it) still counts.
use crate::common;

use glam::Vec3;
use probegi_core::ddgi_settings::DdgiVolumeSettings;
use probegi_core::sampling::sample_uniform_sphere;
use probegi_field::ddgi_field_set::DdgiFieldSet;
use probegi_field::ddgi_volume::DdgiVolume;
use probegi_scene::{BvhSettings, BvhTracer};
use probegi_wgpu::bvh_trace::{GpuBvh, GpuRay, GpuRayTrace};
use probegi_wgpu::ddgi_query::GpuDdgiField;
use probegi_wgpu::gpu_scene::GpuScene;
use probegi_wgpu::probe_shade::{
    GpuProbeShade, SHADE_RADIANCE_WORDS_MIN, ShadeProbe, ShadeProbes, radiance_bits, shade_info, volume_shade_info,
};

/// Probes, rays a probe.
const PROBES: usize = 40;
const RAYS: usize = 16;

/// Radiance a ray of the shade's output (xyz), read back.
fn read_radiance(ctx: &probegi_wgpu::GpuContext, out: &wgpu::Buffer) -> Vec<Vec3> {
    let bytes = ctx.read_back(out).expect("read back");
    let v: &[[f32; 4]] = bytemuck::cast_slice(&bytes);
    v.iter().take(PROBES * RAYS).map(|l| Vec3::new(l[0], l[1], l[2])).collect()
}

/// Whether probe k's rays carry light (any ray of it nonzero).
fn lit(radiance: &[Vec3], k: usize) -> bool {
    radiance[k * RAYS..(k + 1) * RAYS].iter().any(|l| l.max_element() > 0.0)
}

#[test]
fn the_shade_reads_each_probes_radiance_flag_apart_from_its_kept_records() {
    let Some(ctx) = common::context() else { return };
    let scene = probegi_scene::builtin::cornell_box();
    let cpu = BvhTracer::for_scene(&scene, BvhSettings::default());
    let bvh = GpuBvh::upload(&ctx, &cpu.export()).expect("bvh");
    let gpu_scene = GpuScene::upload(&ctx, &scene).expect("scene");
    let settings = DdgiVolumeSettings::default();
    let set = DdgiFieldSet::single(DdgiVolume::new(settings.clone(), scene.bounds().expect("geometry")));
    let field = GpuDdgiField::upload(&ctx, &set.view()).expect("field");
    let shade = GpuProbeShade::new(&ctx).expect("shade pipeline");
    // Each probe's rays from the box's middle over the whole sphere (a
    // turned Fibonacci set): some of every probe's meet the lit floor.
    let (lo, hi) = scene.bounds().expect("geometry");
    let origin = (lo + hi) * 0.5;
    let rays: Vec<GpuRay> = (0..PROBES * RAYS)
        .map(|i| {
            let (k, j) = (i / RAYS, i % RAYS);
            let u = glam::Vec2::new((j as f32 + 0.5) / RAYS as f32, (j as f32 * 0.618_034 + k as f32 * 0.1).fract());
            GpuRay::new(origin, sample_uniform_sphere(u), 0.0, f32::INFINITY)
        })
        .collect();
    let trace = GpuRayTrace::new(&ctx);
    let batch = trace.batch(&ctx, &rays, false).expect("batch");
    let mut encoder = ctx.device.create_command_encoder(&Default::default());
    trace.record(&mut encoder, &bvh, &batch, None);
    ctx.submit(encoder.finish());
    let info = volume_shade_info(false, &settings);
    let records: Vec<ShadeProbe> = (0..PROBES)
        .map(|k| ShadeProbe { first_ray: (k * RAYS) as u32, ray_count: RAYS as u32, info, hit_ao_radius_bits: 0 })
        .collect();
    let make = || records.clone();
    let ids = [u64::MAX - 7];
    let run = |ids: Option<&[u64]>, radiance: &[bool], radiance_id: Option<u64>, make: &dyn Fn() -> Vec<ShadeProbe>| {
        let probes = ShadeProbes { count: PROBES, ids, records: make, radiance, radiance_id };
        let before = ctx.counters();
        let out = shade.shade_on_device(&ctx, &bvh, &field, &gpu_scene, &batch, probes, 3, 1, None).expect("shade");
        let up = (ctx.counters() - before).bytes_up;
        (read_radiance(&ctx, &out), up)
    };
    // Every other probe, then every third: the records under one identity.
    let even: Vec<bool> = (0..PROBES).map(|k| k % 2 == 0).collect();
    let third: Vec<bool> = (0..PROBES).map(|k| k % 3 == 0).collect();
    let (first, _) = run(Some(&ids), &even, Some(u64::MAX - 1), &make);
    let no_records = || -> Vec<ShadeProbe> { panic!("records under a kept identity were made again") };
    let (second, up) = run(Some(&ids), &third, Some(u64::MAX - 2), &no_records);
    for k in 0..PROBES {
        assert_eq!(lit(&first, k), even[k], "probe {k}, every other probe flagged");
        assert_eq!(lit(&second, k), third[k], "probe {k}, every third probe flagged");
    }
    // What went up: the flags' words alone (the uniform block repeats).
    let words = PROBES.div_ceil(32).max(SHADE_RADIANCE_WORDS_MIN);
    assert_eq!(up, 4 * words as u64, "the second shade uploaded more than its flags");
    // The same flags' identity: nothing goes up, and the same rays are lit.
    let (again, up) = run(Some(&ids), &[], Some(u64::MAX - 2), &no_records);
    assert_eq!(up, 0, "kept flags were uploaded again");
    assert_eq!(again, second, "kept flags shade as the flags they were made from");
    // A record's own flag counts where the flags leave it unset (`shade`):
    // records made anew (no identity), no flag set apart.
    let flagged: Vec<ShadeProbe> =
        records.iter().map(|r| ShadeProbe { info: r.info | shade_info(true, false, 0, 0), ..*r }).collect();
    let (own, _) = run(None, &[], None, &|| flagged.clone());
    let wrong = (0..PROBES).filter(|&k| !lit(&own, k)).count();
    assert_eq!(wrong, 0, "{wrong} probes flagged in their records went unshaded");
}

#[test]
fn radiance_bits_put_record_k_at_bit_k_mod_32_of_word_k_div_32() {
    let flags: Vec<bool> = (0..70).map(|k| k == 0 || k == 31 || k == 32 || k == 69).collect();
    assert_eq!(radiance_bits(&flags, 70), vec![1 | 1 << 31, 1, 1 << 5]);
    // Flags past the count are not set; no record still binds one word.
    assert_eq!(radiance_bits(&flags, 32), vec![1 | 1 << 31]);
    assert_eq!(radiance_bits(&[], 0), vec![0]);
    assert_eq!(radiance_bits(&[true], 40), vec![1, 0]);
}
