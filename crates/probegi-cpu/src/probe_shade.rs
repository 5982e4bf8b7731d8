//! Shade pass (seed 000 §3, seed 003 §4.4, seed 004 §4.1): the radiance each
//! probe ray carries back to its probe.
//!
//! - Miss: the sky radiance.
//! - Backface hit: zero radiance, distance shortened to 20 % and marked negative
//!   (seed 004 §4.1; RTXGI stores `-0.2·t`), so the probe reads as shadowed there.
//! - Front hit: direct light reflected toward the probe with the hit's full BSDF
//!   (punctual lights exactly, area lights with `probe_area_light_samples` NEE
//!   samples, shadow rays) plus diffuse albedo/π × the field's own previous
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
use probegi_core::ddgi_query::{DdgiFieldView, irradiance};
use probegi_core::rng::{Pcg32, hash_combine};
use probegi_scene::Scene;
use rayon::prelude::*;
use std::f32::consts::FRAC_1_PI;

use crate::direct::{DirectLighting, DirectSettings};
use crate::probe_trace::Surfel;
use crate::shading::ShadingContext;

pub struct ProbeShadeInputs<'a> {
    pub scene: &'a Scene,
    pub direct: &'a DirectLighting<'a>,
    pub field: DdgiFieldView<'a>,
    pub dirs: &'a [Vec3],
    pub surfels: &'a [Surfel],
    /// Probes to shade this frame; empty = all.
    pub active: &'a [bool],
    pub seed: u64,
    pub frame: u32,
}

/// Fills `radiance` and signed `distance` (probe-major, like `surfels`). Returns
/// the shadow rays traced.
pub fn shade_probe_rays(inputs: &ProbeShadeInputs<'_>, radiance: &mut [Vec3], distance: &mut [f32]) -> u64 {
    let n = inputs.dirs.len();
    let area =
        DirectSettings { direct_area_samples: inputs.field.settings.probe_area_light_samples, direct_sky_samples: 0 };
    radiance
        .par_chunks_mut(n)
        .zip(distance.par_chunks_mut(n))
        .zip(inputs.surfels.par_chunks(n))
        .enumerate()
        .map(|(probe, ((rad, dist), surfels))| {
            let mut rays = 0u64;
            if inputs.active.get(probe).is_some_and(|a| !a) {
                return 0;
            }
            let mut rng =
                Pcg32::new(hash_combine(&[inputs.seed, inputs.frame as u64, probe as u64, 0x5ade]), probe as u64);
            for ((r, d), (s, &dir)) in rad.iter_mut().zip(dist.iter_mut()).zip(surfels.iter().zip(inputs.dirs)) {
                match &s.surface {
                    None => {
                        *r = inputs.scene.sky_radiance;
                        *d = s.distance;
                    }
                    Some(sp) if !sp.front_face => {
                        *r = Vec3::ZERO;
                        *d = -0.2 * s.distance;
                    }
                    Some(sp) => {
                        let ctx = ShadingContext::new(inputs.scene, sp, -dir);
                        let (direct, k) = inputs.direct.reflected(sp, &ctx, area, true, &mut rng);
                        rays += k;
                        let e = irradiance(&inputs.field, sp.position, sp.facing_normal(), -dir);
                        let mut l = direct + ctx.bsdf.diffuse_albedo() * FRAC_1_PI * e;
                        if inputs.field.settings.glossy_second_order {
                            l += crate::glossy::second_order_specular(&inputs.field, sp, &ctx, dir);
                        }
                        *r = if l.is_finite() { l } else { Vec3::NAN };
                        *d = s.distance;
                    }
                }
            }
            rays
        })
        .sum()
}
