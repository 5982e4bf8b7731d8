//! The GPU blend and border passes against the CPU's (`probegi_core::probe_blend`,
//! `probegi_core::probe_border`), on whatever adapter wgpu finds; CI runs them on
//! Mesa's lavapipe. Without an adapter the tests say so and pass, unless
//! `PROBEGI_REQUIRE_GPU=1` (which `scripts/test.sh` sets once lavapipe is installed).

use crate::common;

use common::context;
use glam::{Vec2, Vec3};
use probegi_core::ddgi_settings::DdgiVolumeSettings;
use probegi_core::fibonacci::{sample_uniform_rotation, spherical_fibonacci};
use probegi_core::probe_atlas::ProbeAtlas;
use probegi_core::probe_blend::{BlendWeights, IrradianceBlendRule, blend_distance_tile, blend_irradiance_tile};
use probegi_core::probe_border::update_tile_border;
use probegi_core::rng::Pcg32;
use probegi_wgpu::probe_blend::{BlendFrame, GpuProbeBlend, GpuVolumeAtlases};

struct Frame {
    dirs: Vec<Vec3>,
    radiance: Vec<Vec3>,
    distance: Vec<f32>,
    hysteresis: Vec<Option<f32>>,
}

/// A frame of rays: rotated spherical Fibonacci directions, radiance over three
/// decades with a few NaN/Inf rays, signed distances (backfaces negative, misses
/// long), probes with and without history and some that do not update.
fn frame(rng: &mut Pcg32, probes: usize, rays: u32, f: u32) -> Frame {
    let rot = sample_uniform_rotation(Vec3::new(rng.next_f32(), rng.next_f32(), rng.next_f32()));
    let dirs: Vec<Vec3> = (0..rays).map(|i| (rot * spherical_fibonacci(i, rays)).normalize()).collect();
    let n = probes * rays as usize;
    // Every tenth frame another third of the probes see a 1000× flash (the firefly clamp's case).
    let flash = |k: usize| if f % 10 == 5 && (k / rays as usize).is_multiple_of(3) { 1000.0 } else { 1.0 };
    let radiance = (0..n)
        .map(|k| match k % 97 {
            13 => Vec3::NAN,
            41 => Vec3::new(f32::INFINITY, 1.0, 0.0),
            // A third of the probes see still light (the adaptive states rise there).
            _ if (k / rays as usize) % 3 == 1 => Vec3::new(0.5, 0.25, 1.0),
            _ => {
                Vec3::new(rng.next_f32(), rng.next_f32(), rng.next_f32())
                    * 10f32.powf(3.0 * rng.next_f32() - 2.0)
                    * flash(k)
            }
        })
        .collect();
    let distance = (0..n)
        .map(|k| {
            let t = 20.0 * rng.next_f32();
            if k % 5 == 0 { -0.2 * t } else { t }
        })
        .collect();
    let hysteresis = (0..probes)
        .map(|p| match (p + f as usize) % 7 {
            0 => None,
            1 => Some(0.0),
            _ => Some(0.97),
        })
        .collect();
    Frame { dirs, radiance, distance, hysteresis }
}

/// The CPU's atlases and, with `probe_adaptive_hysteresis`, its per-texel states.
struct CpuField {
    irradiance: ProbeAtlas<Vec3>,
    distance: ProbeAtlas<Vec2>,
    texel_hysteresis: Vec<f32>,
}

fn cpu_blend(s: &DdgiVolumeSettings, fr: &Frame, cpu: &mut CpuField, clamp: f32) {
    let rays = fr.dirs.len();
    let (irr, dist) = (&mut cpu.irradiance, &mut cpu.distance);
    let wi = BlendWeights::new(&fr.dirs, irr.interior, 1.0);
    let wd = BlendWeights::new(&fr.dirs, dist.interior, s.probe_distance_exponent);
    let rule = IrradianceBlendRule::from_settings(s);
    let (ni, nd) = (irr.interior, dist.interior);
    let tile = irr.tile_len();
    for (p, h) in fr.hysteresis.iter().enumerate() {
        let Some(h) = *h else { continue };
        let r = p * rays..(p + 1) * rays;
        let state = cpu.texel_hysteresis.get_mut(p * tile..(p + 1) * tile).unwrap_or_default();
        blend_irradiance_tile(irr.tile_mut(p), ni, &wi, &fr.radiance[r.clone()], (h * 0.85, 1), &rule, state);
        blend_distance_tile(dist.tile_mut(p), nd, &wd, &fr.distance[r], h * 0.5, clamp);
        update_tile_border(irr.tile_mut(p), ni);
        update_tile_border(dist.tile_mut(p), nd);
    }
}

fn gpu_frame<'a>(s: &'a DdgiVolumeSettings, fr: &'a Frame, clamp: f32) -> BlendFrame<'a> {
    BlendFrame {
        settings: s,
        ray_dirs: &fr.dirs,
        ray_radiance: &fr.radiance,
        ray_distance: &fr.distance,
        probe_hysteresis: &fr.hysteresis,
        irradiance_scale: 0.85,
        visibility_scale: 0.5,
        distance_clamp_m: clamp,
    }
}

/// Largest |a − b| relative to max(1, |a|) over both atlases.
fn max_error(a: &(ProbeAtlas<Vec3>, ProbeAtlas<Vec2>), b: &(ProbeAtlas<Vec3>, ProbeAtlas<Vec2>)) -> (f32, f32) {
    let e3 = a.0.texels.iter().zip(&b.0.texels).map(|(x, y)| ((*x - *y).abs() / x.abs().max(Vec3::ONE)).max_element());
    let e2 = a.1.texels.iter().zip(&b.1.texels).map(|(x, y)| ((*x - *y).abs() / x.abs().max(Vec2::ONE)).max_element());
    (e3.fold(0.0, f32::max), e2.fold(0.0, f32::max))
}

#[test]
fn gpu_blend_and_border_match_the_cpu_after_1_and_100_frames_and_repeat_bit_for_bit() {
    blend_matches_the_cpu(96, 100, DdgiVolumeSettings::default());
}

#[test]
fn a_probe_with_more_rays_than_workgroup_memory_holds_blends_from_the_batch() {
    // `blend_probe` stages up to 512 rays a probe in workgroup memory; a volume
    // with more reads them from the batch (the other branch), to the same bound.
    blend_matches_the_cpu(600, 10, DdgiVolumeSettings::default());
}

#[test]
fn pgi_safeguards_blend_as_on_the_cpu() {
    // Timberdoodle PGI's firefly clamp and adaptive per-texel hysteresis: the
    // frames' radiance spans three decades, so the clamp cuts and the states
    // rise and fall every frame.
    let s = DdgiVolumeSettings {
        probe_firefly_clamp_ratio: 32.0,
        probe_adaptive_hysteresis: true,
        probe_adaptive_hysteresis_tolerance: 0.05,
        ..DdgiVolumeSettings::default()
    };
    let safeguarded = blend_matches_the_cpu(96, 100, s);
    // They act: against the papers' blend of the same frames, texels differ.
    let Some(plain) = blend_matches_the_cpu(96, 100, DdgiVolumeSettings::default()) else { return };
    let safeguarded = safeguarded.expect("an adapter");
    let differ = plain.irradiance.texels.iter().zip(&safeguarded.irradiance.texels);
    let differ = differ.filter(|(a, b)| (**a - **b).abs().max_element() > 0.01 * a.max_element()).count();
    assert!(differ * 4 > plain.irradiance.texels.len(), "{differ} of {} texels changed", plain.irradiance.texels.len());
    let hs = &safeguarded.texel_hysteresis;
    // Still probes' states climb between their restarts (every 7th frame); noisy ones stay low.
    assert!(hs.iter().any(|h| *h > 0.4) && hs.iter().any(|h| *h > 0.0 && *h < 0.2), "{hs:?}");
}

/// The GPU blend of `rays` rays a probe against the CPU's over `frames` frames
/// (checked after the first and the last), and two runs bit for bit.
fn blend_matches_the_cpu(rays: u32, frames: u32, s: DdgiVolumeSettings) -> Option<CpuField> {
    let ctx = context()?;
    let (probes, clamp) = (37usize, 12.0f32);
    let irradiance = ProbeAtlas::new(probes, s.probe_irradiance_texels);
    let states = if s.probe_adaptive_hysteresis { irradiance.texels.len() } else { 0 };
    let mut cpu = CpuField {
        irradiance,
        distance: ProbeAtlas::new(probes, s.probe_distance_texels),
        texel_hysteresis: vec![0.0; states],
    };
    let blend = GpuProbeBlend::new(&ctx);
    let gpu = GpuVolumeAtlases::new(&ctx, probes, s.probe_irradiance_texels, s.probe_distance_texels);
    let again = GpuVolumeAtlases::new(&ctx, probes, s.probe_irradiance_texels, s.probe_distance_texels);
    gpu.upload(&ctx, &cpu.irradiance, &cpu.distance);
    again.upload(&ctx, &cpu.irradiance, &cpu.distance);
    let mut rng = Pcg32::new(7, 1);
    let mut worst = (0.0f32, 0.0f32);
    for f in 0..frames {
        let fr = frame(&mut rng, probes, rays, f);
        cpu_blend(&s, &fr, &mut cpu, clamp);
        blend.run(&ctx, &gpu, &gpu_frame(&s, &fr, clamp)).expect("blend");
        blend.run(&ctx, &again, &gpu_frame(&s, &fr, clamp)).expect("blend");
        if f == 0 || f == frames - 1 {
            let got = gpu.download(&ctx).expect("download");
            let (ei, ed) = max_error(&(cpu.irradiance.clone(), cpu.distance.clone()), &got);
            eprintln!("after {} frame(s): irradiance {ei:.2e}, distance {ed:.2e} (relative, max over texels)", f + 1);
            worst = (worst.0.max(ei), worst.1.max(ed));
            assert!(got.0.texels.iter().all(|t| t.is_finite()) && got.1.texels.iter().all(|t| t.is_finite()));
            assert!(got.0.texels.iter().any(|t| t.max_element() > 0.0), "the blend wrote something");
            // The same inputs on the same adapter: the same atlases, bit for bit.
            let twin = again.download(&ctx).expect("download");
            assert!(got.0 == twin.0 && got.1 == twin.1, "two runs of the same frames differ");
        }
    }
    // f32 sums in the same ray order; pow/sqrt/normalize differ by a few ulps
    // between the CPU's libm and the shader compiler's, and 100 frames of
    // hysteresis carry that forward without growing it.
    assert!(worst.0 < 1e-4 && worst.1 < 1e-4, "GPU vs CPU: {worst:?}");
    Some(cpu)
}

#[test]
fn bad_inputs_are_errors() {
    let Some(ctx) = context() else { return };
    let s = DdgiVolumeSettings::default();
    let blend = GpuProbeBlend::new(&ctx);
    let atlases = GpuVolumeAtlases::new(&ctx, 4, 6, 14);
    let dirs = vec![Vec3::Z; 8];
    let frame = BlendFrame {
        settings: &s,
        ray_dirs: &dirs,
        ray_radiance: &[Vec3::ONE; 3],
        ray_distance: &[1.0; 32],
        probe_hysteresis: &[None; 4],
        irradiance_scale: 1.0,
        visibility_scale: 1.0,
        distance_clamp_m: 1.0,
    };
    assert!(blend.run(&ctx, &atlases, &frame).is_err());
}

/// The blend uploads one 16-byte entry per probe that blends, none for the
/// others (the screen scheme blends an eighth of its probes a frame): two
/// blends of the same rays, one with every probe and one with three, differ in
/// the bytes the passes hand the device (uploaded or kept) by 16 a probe left out.
#[test]
fn the_blend_uploads_an_entry_per_blending_probe_alone() {
    let Some(ctx) = context() else { return };
    let s = DdgiVolumeSettings::default();
    let (probes, rays) = (37usize, 16u32);
    let blend = GpuProbeBlend::new(&ctx);
    let atlases = GpuVolumeAtlases::new(&ctx, probes, s.probe_irradiance_texels, s.probe_distance_texels);
    let fr = frame(&mut Pcg32::new(3, 1), probes, rays, 2);
    let every: Vec<Option<f32>> = vec![Some(0.97); probes];
    let three: Vec<Option<f32>> = (0..probes).map(|p| [3, 10, 30].contains(&p).then_some(0.97)).collect();
    let handed = |hysteresis: &[Option<f32>]| {
        let before = ctx.counters();
        let frame = BlendFrame { probe_hysteresis: hysteresis, ..gpu_frame(&s, &fr, 0.0) };
        blend.run(&ctx, &atlases, &frame).expect("blend");
        let d = ctx.counters() - before;
        d.bytes_up + d.bytes_kept
    };
    // Each plan twice: the second finds the buffers sized (a new one leaves
    // room to grow, which the first would count).
    let all = [handed(&every), handed(&every)][1];
    let few = [handed(&three), handed(&three)][1];
    assert_eq!(all - few, 16 * (probes as u64 - 3), "every probe's entry: {all} bytes, three: {few}");
}

/// A blend in which no probe blends is no error and changes no texel (the
/// public `run`/`prepare_resident`; the field's own update records nothing
/// for such a volume).
#[test]
fn a_blend_in_which_no_probe_blends_leaves_the_atlases_as_they_were() {
    let Some(ctx) = context() else { return };
    let s = DdgiVolumeSettings::default();
    let (probes, rays) = (5usize, 16u32);
    let blend = GpuProbeBlend::new(&ctx);
    let atlases = GpuVolumeAtlases::new(&ctx, probes, s.probe_irradiance_texels, s.probe_distance_texels);
    let fr = frame(&mut Pcg32::new(9, 1), probes, rays, 2);
    let every = vec![Some(0.0); probes];
    blend.run(&ctx, &atlases, &BlendFrame { probe_hysteresis: &every, ..gpu_frame(&s, &fr, 0.0) }).expect("blend");
    let before = atlases.download(&ctx).expect("download");
    let none = vec![None; probes];
    blend.run(&ctx, &atlases, &BlendFrame { probe_hysteresis: &none, ..gpu_frame(&s, &fr, 0.0) }).expect("no blend");
    let after = atlases.download(&ctx).expect("download");
    assert!(before.0.texels.iter().any(|t| t.max_element() > 0.0), "the first blend wrote light");
    assert_eq!(max_error(&before, &after), (0.0, 0.0));
}
