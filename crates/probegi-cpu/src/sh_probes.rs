//! The SH probe volume of seed 001 on the CPU: camera-centred cascades of L2 SH
//! probes (`probegi_core::sh_cascades`) updated every frame from the lit frame,
//! with no probe rays (§5–6). Per frame, after the camera pass:
//! 1. `sh_screen_samples`: 20×20 stratified samples of the frame
//!    ([`crate::sh_screen_samples`]);
//! 2. `sh_update`: every probe, jittered within its cell (§6.2), projects the
//!    prediction error of every sample that faces it, weighted by eq. 11
//!    (`probegi_core::sh_probe_update`, eq. 7), eight samples at a time from
//!    structure-of-arrays blocks built once per frame
//!    (`progressive_update_toward`); or, with `sh_occlusion` (§7.3), one sample
//!    at a time, each testing visibility with a shadow ray;
//! 3. `sh_inject`: with `sh_light_injection`, each probe then projects samples of
//!    nearby emitters and of the sky ([`crate::sh_inject`], §5.2).
//!
//! The next frame's camera pass reads the probes, so bounces accumulate (§5.1).

use std::collections::BTreeMap;
use std::time::Instant;

use glam::{IVec3, Vec3};
use probegi_core::camera::CameraRays;
use probegi_core::rng::{Pcg32, hash_combine};
use probegi_core::sh::progressive_update;
use probegi_core::sh_cascades::ShCascades;
use probegi_core::sh_probe_update::{ShSampleBlocks, progressive_update_toward, sample_toward_probe};
use probegi_core::sh_settings::ShProbeSettings;
use probegi_scene::{Ray, RayTracer, Scene};
use rayon::prelude::*;

use crate::direct::{DirectLighting, DirectSettings};
use crate::gbuffer::GBuffer;
use crate::sh_inject::{EmitterGrid, injection_samples};
use crate::sh_screen_samples::{ScreenSample, ScreenSampleInputs, take_screen_samples};

/// Names of the passes that make up an SH probe update.
pub const SH_UPDATE_PASSES: [&str; 2] = ["sh_screen_samples", "sh_update"];

/// Seed 001's SH probes on the CPU: the cascades and what their update needs.
pub struct ShProbes {
    /// The settings the probes were made with.
    pub settings: ShProbeSettings,
    /// The probe cascades the camera pass reads.
    pub cascades: ShCascades,
    emitters: EmitterGrid,
    /// Screen samples of the last update (for tests and statistics).
    pub last_sample_count: usize,
    /// Updates run so far.
    pub frames_updated: u32,
}

impl ShProbes {
    /// Cascades sized from the settings; an absent spacing is fitted so that the
    /// coarsest cascade around `camera_m` contains the whole scene.
    pub fn new(settings: ShProbeSettings, scene: &Scene, camera_m: Vec3) -> Self {
        let (lo, hi) = scene.bounds().unwrap_or((Vec3::splat(-1.0), Vec3::ONE));
        let counts = settings.sh_cascade_probe_counts;
        let ratio = settings.sh_cascade_spacing_ratio;
        let spacing = settings.sh_cascade_spacing_m.unwrap_or_else(|| {
            ShCascades::spacing_to_cover(camera_m, lo, hi, settings.sh_cascade_count, counts, ratio)
        });
        let mut cascades = ShCascades::new(settings.sh_cascade_count, counts, spacing, ratio);
        cascades.view_offset_rel = settings.sh_cascade_view_offset_rel;
        let emitters = if settings.sh_light_injection {
            EmitterGrid::new(scene, settings.sh_light_cutoff_irradiance)
        } else {
            EmitterGrid::default()
        };
        Self { settings, cascades, emitters, last_sample_count: 0, frames_updated: 0 }
    }

    /// The camera pass's light sampling: with light injection, emitters and sky
    /// reach surfaces through the probes, so only punctual lights are direct.
    pub fn camera_direct_settings(&self, direct: DirectSettings) -> DirectSettings {
        if self.settings.sh_light_injection {
            DirectSettings { direct_area_samples: 0, direct_sky_samples: 0 }
        } else {
            direct
        }
    }

    /// Moves the cascades to the camera (before the camera pass reads them).
    pub fn recentre(&mut self, camera_m: Vec3, view_dir: Vec3) -> usize {
        self.cascades.recentre(camera_m, view_dir)
    }

    /// One update from the frame just lit. Returns rays traced.
    #[allow(clippy::too_many_arguments)]
    pub fn update(
        &mut self,
        scene: &Scene,
        tracer: &dyn RayTracer,
        direct: &DirectLighting<'_>,
        direct_settings: DirectSettings,
        camera: &CameraRays,
        gbuffer: &GBuffer,
        seed: u64,
        frame: u32,
        pass_totals: &mut BTreeMap<&'static str, f64>,
    ) -> u64 {
        let t = Instant::now();
        let (samples, mut rays) = take_screen_samples(&ScreenSampleInputs {
            scene,
            direct,
            direct_settings: self.camera_direct_settings(direct_settings),
            probes: &self.cascades,
            include_emission: self.settings.sh_light_injection,
            camera,
            gbuffer,
            tiles: self.settings.sh_screen_samples,
            seed,
            frame,
        });
        *pass_totals.entry("sh_screen_samples").or_default() += t.elapsed().as_secs_f64() * 1e3;
        self.last_sample_count = samples.len();

        let t = Instant::now();
        let settings = &self.settings;
        let emitters = &self.emitters;
        // Without occlusion every probe reads the same samples: once, in lanes.
        let blocks = if settings.sh_occlusion {
            ShSampleBlocks::default()
        } else {
            ShSampleBlocks::new(samples.iter().map(|s| &s.sample))
        };
        for (k, cascade) in self.cascades.cascades.iter_mut().enumerate() {
            let spacing = cascade.spacing_m;
            let slots = &cascade.slot_lattice;
            rays += cascade
                .coeffs
                .par_iter_mut()
                .enumerate()
                .map_init(Vec::new, |light_samples, (slot, coeffs)| {
                    let lattice: IVec3 = slots[slot];
                    let key = hash_combine(&[seed, frame as u64, k as u64, slot as u64, 0x54]);
                    let mut rng = Pcg32::new(key, slot as u64);
                    let jitter = if settings.sh_probe_jitter {
                        Vec3::new(rng.next_f32(), rng.next_f32(), rng.next_f32()) - Vec3::splat(0.5)
                    } else {
                        Vec3::ZERO
                    };
                    let probe = (lattice.as_vec3() + jitter) * spacing;
                    let probe_inputs =
                        ProbeInputs { scene, tracer, emitters, settings, samples: &samples, blocks: &blocks };
                    update_probe(&probe_inputs, probe, coeffs, &mut rng, light_samples)
                })
                .sum::<u64>();
        }
        *pass_totals.entry("sh_update").or_default() += t.elapsed().as_secs_f64() * 1e3;
        self.frames_updated += 1;
        rays
    }
}

/// What every probe's update reads.
struct ProbeInputs<'a> {
    scene: &'a Scene,
    tracer: &'a dyn RayTracer,
    emitters: &'a EmitterGrid,
    settings: &'a ShProbeSettings,
    samples: &'a [ScreenSample],
    /// `samples` in lanes (empty with `sh_occlusion`, whose shadow rays go one sample at a time).
    blocks: &'a ShSampleBlocks,
}

/// Screen update then light injection of one probe; `light` is a reused buffer.
/// Returns rays traced.
fn update_probe(
    inputs: &ProbeInputs<'_>,
    probe: Vec3,
    coeffs: &mut probegi_core::sh::ShRgb9,
    rng: &mut Pcg32,
    light: &mut Vec<(Vec3, Vec3, f32)>,
) -> u64 {
    let ProbeInputs { scene, tracer, emitters, settings, blocks, .. } = *inputs;
    let mut rays = 0u64;
    if settings.sh_occlusion {
        rays += occluded_screen_update(inputs, probe, coeffs);
    } else {
        progressive_update_toward(coeffs, probe, blocks, settings.sh_hysteresis);
    }
    if settings.sh_light_injection && (!emitters.is_empty() || scene.has_sky()) {
        light.clear();
        rays += injection_samples(scene, tracer, emitters, settings, probe, rng, light);
        progressive_update(coeffs, light.iter().copied(), settings.sh_hysteresis);
    }
    rays
}

/// The screen update with `sh_occlusion` (§7.3): a shadow ray from each sample
/// that faces the probe; occluded samples send nothing. Returns rays traced.
fn occluded_screen_update(inputs: &ProbeInputs<'_>, probe: Vec3, coeffs: &mut probegi_core::sh::ShRgb9) -> u64 {
    let ProbeInputs { tracer, settings, samples, .. } = *inputs;
    let mut rays = 0u64;
    let weighted = samples.iter().filter_map(|s| {
        let (dir, w) = sample_toward_probe(&s.sample, probe)?;
        rays += 1;
        let origin = s.surface.spawn_origin(-dir);
        let to = probe - origin;
        let d = to.length();
        let occluded = tracer.occluded(&Ray::segment(origin, to / d, d * (1.0 - 1e-4)));
        (!occluded).then_some((dir, s.sample.radiance, w))
    });
    progressive_update(coeffs, weighted, settings.sh_hysteresis);
    rays
}
