//! Shade pass (seed 000 §3, seed 003 §4.4, seed 004 §4.1): the radiance each
//! probe ray of the batch carries back to its probe, for the rays the field set
//! asks for (`ProbeRayBatch::needs_radiance`: rays of probes that update this
//! frame; backface hits are zero by the set's rule and not shaded here).
//!
//! - Miss: the sky radiance.
//! - Front hit: direct light reflected toward the probe with the hit's full BSDF
//!   (punctual lights exactly, area lights with `probe_area_light_samples` NEE
//!   samples, shadow rays) plus diffuse albedo/π × the set's own previous
//!   irradiance at the hit — the recursion that accumulates one more bounce per
//!   frame — plus, with `glossy_second_order`, the hit's specular reflection of the
//!   field (`glossy`), so light bouncing off glossy objects reaches the field.
//!
//! Deliberate deviations, both to avoid counting light twice:
//! - The emission of the hit surface is *not* added. Emissive triangles are
//!   sampled as area lights wherever the field is used (camera pixels and probe
//!   hits), so the field must hold only light that has bounced at least once; a
//!   probe ray that recorded an emitter's Le would deliver that direct light a
//!   second time through the query. (RTXGI has no sampled area lights and records
//!   emission instead.)
//! - The sky is not sampled at hits: probe misses record it, so the field carries
//!   sky light to every surface (as RTXGI does), and the camera pass adds no
//!   separate sky term.

use glam::Vec3;
use probegi_core::ddgi_volume_blend::{DdgiFieldSetView, field_set_irradiance};
use probegi_core::rng::{Pcg32, hash_combine};
use probegi_scene::{RayHit, Scene};
use rayon::prelude::*;
use std::f32::consts::FRAC_1_PI;

use crate::direct::{DirectLighting, DirectSettings};
use crate::shading::ShadingContext;
use probegi_field::ddgi_volume::DdgiVolume;
use probegi_field::seam::ProbeRayBatch;

/// What the shade pass reads.
pub struct ProbeShadeInputs<'a> {
    /// The scene the batch was traced in (materials, sky).
    pub scene: &'a Scene,
    /// Direct light at the hits, with its shadow rays.
    pub direct: &'a DirectLighting<'a>,
    /// The set as queries read it (the previous frame's field).
    pub field: &'a DdgiFieldSetView<'a>,
    /// The set's volumes, for per-volume settings and RNG streams.
    pub volumes: &'a [DdgiVolume],
    /// The probe ray batch: rays, and which of them need radiance.
    pub batch: &'a ProbeRayBatch,
    /// The closest hit of each batch ray, in batch order (`None`: a miss). The
    /// shade pass builds the surface point of each front hit it shades.
    pub hits: &'a [Option<RayHit>],
    /// The render's seed, mixed into each volume's streams.
    pub seed: u64,
    /// The frame index, mixed into every probe's stream.
    pub frame: u32,
}

/// Fills `radiance` (one per batch ray; rays not asked for get zero). Returns the
/// shadow rays traced. Each probe's rays draw from their own PCG stream, seeded
/// from (volume's seed, frame, probe), so results do not depend on threads.
pub fn shade_probe_rays(inputs: &ProbeShadeInputs<'_>, radiance: &mut Vec<Vec3>) -> u64 {
    let batch = inputs.batch;
    radiance.clear();
    radiance.resize(batch.len(), Vec3::ZERO);
    // Split the output per batch probe (contiguous, in order).
    let mut chunks: Vec<&mut [Vec3]> = Vec::with_capacity(batch.probes.len());
    let mut rest: &mut [Vec3] = radiance;
    for bp in &batch.probes {
        let (a, b) = rest.split_at_mut(bp.ray_count as usize);
        chunks.push(a);
        rest = b;
    }
    chunks
        .into_par_iter()
        .zip(batch.probes.par_iter())
        .map(|(out, bp)| {
            let volume = &inputs.volumes[bp.volume as usize];
            let settings = &volume.settings;
            let area = DirectSettings { direct_area_samples: settings.probe_area_light_samples, direct_sky_samples: 0 };
            let probe = bp.probe as u64;
            let seed = volume.stream_seed(inputs.seed);
            let mut rng = Pcg32::new(hash_combine(&[seed, inputs.frame as u64, probe, 0x5ade]), probe);
            let mut rays = 0u64;
            for (k, r) in out.iter_mut().enumerate() {
                let i = bp.first_ray as usize + k;
                if !batch.needs_radiance[i] {
                    continue;
                }
                let dir = batch.directions[i];
                *r = match &inputs.hits[i] {
                    None => inputs.scene.sky_radiance,
                    Some(hit) if hit.backface => Vec3::ZERO,
                    Some(hit) => {
                        let sp = &inputs.scene.surface_point(hit);
                        let ctx = ShadingContext::new(inputs.scene, sp, -dir);
                        let (direct, k) = inputs.direct.reflected(sp, &ctx, area, true, &mut rng);
                        rays += k;
                        let e = field_set_irradiance(inputs.field, sp.position, sp.facing_normal(), -dir);
                        let mut l = direct + ctx.bsdf.diffuse_albedo() * FRAC_1_PI * e;
                        if settings.glossy_second_order {
                            l += crate::glossy::second_order_specular(inputs.field, sp, &ctx, dir);
                        }
                        if l.is_finite() { l } else { Vec3::NAN }
                    }
                };
            }
            rays
        })
        .sum()
}
