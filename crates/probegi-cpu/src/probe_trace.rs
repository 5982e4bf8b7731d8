//! Trace pass (seed 003 §4.3): every ray of the frame's probe ray batch finds its
//! closest hit, both faces (backface culling off, so probes inside geometry
//! notice), and writes a surfel: the surface it hit (position, normal, material,
//! which face) and the distance. Rays that travel beyond their max distance are
//! misses. The surfels become the seam's hits ([`surfel_hit`]) and feed the shade
//! pass.

use glam::Vec3;
use probegi_scene::{Ray, RayHit, RayTracer, Scene, SurfacePoint};
use rayon::prelude::*;

use probegi_field::seam::{ProbeRayBatch, ProbeRayHit};

/// One probe ray's hit record (the surfel buffer of seed 003 §4.3).
#[derive(Clone, Copy, Debug, Default)]
pub struct Surfel {
    /// `None` for a miss.
    pub surface: Option<SurfacePoint>,
    /// Hit distance in metres (the maximum ray distance for a miss).
    pub distance: f32,
}

/// Traces every ray of `batch` into `surfels` (resized to the batch). Returns the
/// number of rays traced.
pub fn trace_probe_batch(
    scene: &Scene,
    tracer: &dyn RayTracer,
    batch: &ProbeRayBatch,
    surfels: &mut Vec<Surfel>,
) -> u64 {
    surfels.clear();
    surfels.resize(batch.len(), Surfel::default());
    surfels.par_chunks_mut(256).enumerate().for_each(|(c, out)| {
        for (k, s) in out.iter_mut().enumerate() {
            let r = c * 256 + k;
            let max = batch.max_distances_m[r];
            let ray = Ray::segment(batch.origins_m[r], batch.directions[r], max);
            *s = match tracer.closest_hit(&ray) {
                Some(hit) => Surfel { surface: Some(scene.surface_point(&hit)), distance: hit.t },
                None => Surfel { surface: None, distance: max },
            };
        }
    });
    batch.len() as u64
}

/// The surfels of `hits` (one per batch ray, as a [`probegi_field::ProbeBatchTracer`] returns them).
pub fn surfels_from_hits(scene: &Scene, batch: &ProbeRayBatch, hits: &[Option<RayHit>], surfels: &mut Vec<Surfel>) {
    surfels.clear();
    surfels.resize(batch.len(), Surfel::default());
    surfels.par_chunks_mut(256).enumerate().for_each(|(c, out)| {
        for (k, s) in out.iter_mut().enumerate() {
            let r = c * 256 + k;
            *s = match hits[r] {
                Some(hit) => Surfel { surface: Some(scene.surface_point(&hit)), distance: hit.t },
                None => Surfel { surface: None, distance: batch.max_distances_m[r] },
            };
        }
    });
}

/// The seam's record of a surfel: signed distance and facing normal.
pub fn surfel_hit(s: &Surfel) -> ProbeRayHit {
    match &s.surface {
        None => ProbeRayHit::MISS,
        Some(sp) if !sp.front_face => ProbeRayHit::back(s.distance, sp.facing_normal()),
        Some(sp) => ProbeRayHit::front(s.distance, sp.facing_normal()),
    }
}

/// Traces `dirs` from every probe position (distance only, no surface point);
/// returns signed true distances per ray, probe-major (positive front, negative
/// back, ∞ miss).
pub fn trace_probe_distances(
    tracer: &dyn RayTracer,
    probe_positions: &[Vec3],
    dirs: &[Vec3],
    max_distance_m: f32,
) -> Vec<f32> {
    let n = dirs.len();
    let mut out = vec![0.0f32; probe_positions.len() * n];
    out.par_chunks_mut(n).zip(probe_positions.par_iter()).for_each(|(d, &origin)| {
        for (o, &dir) in d.iter_mut().zip(dirs) {
            *o = match tracer.closest_hit(&Ray::segment(origin, dir, max_distance_m)) {
                Some(h) if h.backface => -h.t,
                Some(h) => h.t,
                None => f32::INFINITY,
            };
        }
    });
    out
}

/// Bytes a volume with these settings holds on the CPU backend (atlases,
/// per-probe state, and the per-ray batch, hit and surfel buffers of one frame).
pub fn ddgi_volume_bytes(settings: &probegi_core::ddgi_settings::DdgiVolumeSettings) -> u64 {
    let probes = settings.probe_count();
    let rays = probes * settings.probe_rays_per_probe as u64;
    let per_ray = std::mem::size_of::<Surfel>() + 3 * 12 + 4 + 16 + 1;
    rays * per_ray as u64
        + probes
            * (probegi_core::probe_atlas::tile_texel_count(settings.probe_irradiance_texels) as u64 * 12
                + probegi_core::probe_atlas::tile_texel_count(settings.probe_distance_texels) as u64 * 8
                + 64)
}
