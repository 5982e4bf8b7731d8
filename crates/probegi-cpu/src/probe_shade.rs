//! Shade pass (seed 000 §3, seed 003 §4.4, seed 004 §4.1): the radiance each
//! probe ray of the batch carries back to its probe, for the rays the field set
//! asks for (`ProbeRayBatch::needs_radiance`: rays of probes that update this
//! frame; backface hits are zero by the set's rule and not shaded here).
//!
//! - Miss: the sky radiance.
//! - Front hit: direct light reflected toward the probe with the hit's full BSDF
//!   (punctual lights exactly, area lights with `probe_area_light_samples` NEE
//!   samples, shadow rays; with `shadow_field_probe_shading`, punctual lights'
//!   visibility from the shadowing field instead) plus diffuse albedo/π × the set's own previous
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
use probegi_core::ddgi_volume_blend::{DdgiFieldSetView, field_set_irradiance, field_set_shadow_cage};
use probegi_core::rng::{Pcg32, hash_combine};
use probegi_scene::{RayHit, Scene, SurfacePoint};
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
///
/// Three steps, parallel but for the counting sort's two serial passes over the
/// rays: the surface point of every front hit to shade;
/// the field's irradiance at those points, queried in the order of the cell
/// they lie in (`batched_field_irradiance`); then per probe, direct light and
/// the BSDF. The query is a pure function of the point, so its order changes
/// no result, only how often the 8-probe cages' atlas tiles are still in cache.
pub fn shade_probe_rays(inputs: &ProbeShadeInputs<'_>, radiance: &mut Vec<Vec3>) -> u64 {
    let batch = inputs.batch;
    let points = shaded_surface_points(inputs);
    let field_e = batched_field_irradiance(inputs, &points);
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
            // A sky map lights the hits by NEE (the misses carry none of it),
            // unless the volume's misses read it; a constant sky reaches them
            // through the field's misses.
            let on_miss = settings.probe_sky_map_on_miss;
            let sky_samples =
                if inputs.scene.sky_map.is_some() && !on_miss { settings.probe_sky_light_samples } else { 0 };
            let area = DirectSettings {
                direct_area_samples: settings.probe_area_light_samples,
                direct_sky_samples: sky_samples,
            };
            let ao_radius_m = settings.probe_hit_ao_radius_rel * volume.grid.min_spacing_m();
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
                *r = match (&inputs.hits[i], &points[i]) {
                    (None, _) if on_miss => inputs.scene.sky_toward(dir),
                    (None, _) => inputs.scene.sky_on_probe_miss(dir),
                    (Some(_), None) => Vec3::ZERO,
                    (Some(_), Some(sp)) => {
                        let ctx = ShadingContext::new(inputs.scene, sp, -dir);
                        let cage = settings
                            .shadow_field_probe_shading
                            .then(|| field_set_shadow_cage(inputs.field, sp.position, sp.facing_normal(), -dir))
                            .flatten();
                        let from_field = move |_: &SurfacePoint, wi: Vec3| cage.map(|c| c.visibility(wi));
                        let visibility = settings
                            .shadow_field_probe_shading
                            .then_some(&from_field as &crate::shading::PunctualVisibility<'_>);
                        let (direct, k) = inputs.direct.reflected_with(sp, &ctx, area, true, visibility, &mut rng);
                        rays += k;
                        let near_field = settings.probe_hit_ao_near_field;
                        let (e, k) = hit_ao_irradiance(inputs, area, near_field, sp, field_e[i], ao_radius_m, &mut rng);
                        rays += k;
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

/// `probe_hit_ao_radius_rel`'s sample at a front hit (Timberdoodle PGI's
/// short-range AO on hit radiance): 1 when one cosine-distributed ray around
/// the facing normal leaves `sp` unoccluded for `radius_m`, else 0 (two
/// draws from `rng`, after the direct light's). `probe_shade.wgsl`'s
/// `probe_hit_ao` is its twin.
pub fn hit_ao(direct: &DirectLighting<'_>, sp: &SurfacePoint, radius_m: f32, rng: &mut Pcg32) -> f32 {
    if direct.occluded(&hit_ao_ray(sp, radius_m, rng).1) { 0.0 } else { 1.0 }
}

/// The hit AO's ray at `sp`: its cosine-distributed direction around the
/// facing normal (two draws from `rng`) and the segment of `radius_m` along it.
fn hit_ao_ray(sp: &SurfacePoint, radius_m: f32, rng: &mut Pcg32) -> (Vec3, probegi_scene::Ray) {
    let u = glam::Vec2::new(rng.next_f32(), rng.next_f32());
    let frame = probegi_core::sampling::Frame::from_normal(sp.facing_normal());
    let wi = frame.to_world(probegi_core::sampling::sample_cosine_hemisphere(u));
    (wi, crate::shading::shadow_ray_along(sp, wi, radius_m))
}

/// The field's irradiance `field_e` at a front hit `sp` through
/// `probe_hit_ao_radius_rel`'s sample of `radius_m` ([`hit_ao`]'s ray; 0: no
/// sample, `field_e` as it is), and the rays it traced. When the ray escapes,
/// `field_e`; when it hits within `radius_m`, zero (the plain AO) or, with
/// `near_field` (`probe_hit_ao_near_field`), π × the occluder's radiance
/// toward `sp`, shaded as this pass shades a hit: its direct light by shadow
/// rays (`area`'s samples), emission, and albedo/π × the field's irradiance
/// there, no glossy term (a back face: zero, the ray is inside geometry).
/// `probe_shade.wgsl`'s `probe_hit_ao_near_field` is its twin.
fn hit_ao_irradiance(
    inputs: &ProbeShadeInputs<'_>,
    area: DirectSettings,
    near_field: bool,
    sp: &SurfacePoint,
    field_e: Vec3,
    radius_m: f32,
    rng: &mut Pcg32,
) -> (Vec3, u64) {
    if radius_m <= 0.0 {
        return (field_e, 0);
    }
    if !near_field {
        return (field_e * hit_ao(inputs.direct, sp, radius_m, rng), 1);
    }
    let (wi, ray) = hit_ao_ray(sp, radius_m, rng);
    match inputs.direct.closest_hit(&ray) {
        None => (field_e, 1),
        Some(h) if h.backface => (Vec3::ZERO, 1),
        Some(h) => {
            let q = inputs.scene.surface_point(&h);
            let ctx = ShadingContext::new(inputs.scene, &q, -wi);
            let (direct, k) = inputs.direct.reflected_with(&q, &ctx, area, true, None, rng);
            let e_q = field_set_irradiance(inputs.field, q.position, q.facing_normal(), -wi);
            (std::f32::consts::PI * direct + ctx.bsdf.diffuse_albedo() * e_q, 1 + k)
        }
    }
}

/// Rays per parallel work item of the per-ray steps.
const SHADE_CHUNK_RAYS: usize = 512;

/// The surface point of every ray the shade pass shades at a surface: asked for
/// (`needs_radiance`) and a front hit; `None` for every other ray (misses take
/// the sky, back faces zero).
fn shaded_surface_points(inputs: &ProbeShadeInputs<'_>) -> Vec<Option<SurfacePoint>> {
    let batch = inputs.batch;
    let mut points = vec![None; batch.len()];
    points.par_chunks_mut(SHADE_CHUNK_RAYS).enumerate().for_each(|(c, out)| {
        for (k, p) in out.iter_mut().enumerate() {
            let i = c * SHADE_CHUNK_RAYS + k;
            if let (true, Some(hit)) = (batch.needs_radiance[i], &inputs.hits[i])
                && !hit.backface
            {
                *p = Some(inputs.scene.surface_point(hit));
            }
        }
    });
    points
}

/// The field set's irradiance (`field_set_irradiance`, the previous frame's
/// field) at every point of `points`, in batch order (zero where there is none).
/// The points are queried grouped by the cell of the first member's grid they
/// lie in (a counting sort): probe rays of one probe scatter over the scene, so
/// in batch order consecutive queries read unrelated cages, while in cell order
/// they read the same eight probes' tiles.
fn batched_field_irradiance(inputs: &ProbeShadeInputs<'_>, points: &[Option<SurfacePoint>]) -> Vec<Vec3> {
    let mut field_e = vec![Vec3::ZERO; points.len()];
    let Some(first) = inputs.field.members.first() else { return field_e };
    let grid = first.field.grid;
    let cell_of = |p: Vec3| {
        let b = grid.base_probe(p).as_uvec3();
        b.x as usize + grid.probe_counts.x as usize * (b.y as usize + grid.probe_counts.y as usize * b.z as usize)
    };
    let cells = grid.probe_count();
    let keys: Vec<u32> =
        points.par_iter().map(|p| p.as_ref().map_or(u32::MAX, |sp| cell_of(sp.position) as u32)).collect();
    let mut starts = vec![0u32; cells + 1];
    for &k in keys.iter().filter(|&&k| k != u32::MAX) {
        starts[k as usize + 1] += 1;
    }
    for c in 0..cells {
        starts[c + 1] += starts[c];
    }
    let mut order = vec![0u32; starts[cells] as usize];
    let mut next = starts;
    for (i, &k) in keys.iter().enumerate().filter(|(_, k)| **k != u32::MAX) {
        order[next[k as usize] as usize] = i as u32;
        next[k as usize] += 1;
    }
    let sorted: Vec<Vec3> = order
        .par_iter()
        .with_min_len(SHADE_CHUNK_RAYS)
        .map(|&i| {
            let (sp, dir) = (&points[i as usize], inputs.batch.directions[i as usize]);
            sp.as_ref()
                .map_or(Vec3::ZERO, |sp| field_set_irradiance(inputs.field, sp.position, sp.facing_normal(), -dir))
        })
        .collect();
    for (&i, e) in order.iter().zip(sorted) {
        field_e[i as usize] = e;
    }
    field_e
}
