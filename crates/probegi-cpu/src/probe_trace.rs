//! Trace pass (seed 003 §4.3): every ray of the frame's probe ray batch finds its
//! closest hit, both faces (backface culling off, so probes inside geometry
//! notice). Rays that travel beyond their max distance are misses. The pass
//! keeps the hits as the tracer returns them (distance, triangle, barycentrics,
//! face): the surfel buffer of seed 003 §4.3 in compact form. The surface point
//! a hit stands for (position, shading normal, material inputs) is built by the
//! pass that reads it: the shade pass for the rays it shades, and
//! [`probe_ray_hit`] for the rounds whose seam hits carry normals. A steady
//! frame's trace therefore costs what the bare closest-hit query costs.

use glam::Vec3;
use probegi_scene::{Ray, RayHit, RayTracer, Scene};
use rayon::prelude::*;

use probegi_field::seam::{ProbeRayBatch, ProbeRayHit};

/// Rays per parallel work item of the trace pass.
const TRACE_CHUNK_RAYS: usize = 256;

/// Traces every ray of `batch` into `hits` (resized to the batch; `None` for a
/// miss). Returns the number of rays traced.
pub fn trace_probe_batch(tracer: &dyn RayTracer, batch: &ProbeRayBatch, hits: &mut Vec<Option<RayHit>>) -> u64 {
    hits.resize(batch.len(), None);
    hits.par_chunks_mut(TRACE_CHUNK_RAYS).enumerate().for_each(|(c, out)| {
        let first = c * TRACE_CHUNK_RAYS;
        for (k, h) in out.iter_mut().enumerate() {
            let r = first + k;
            *h = tracer.closest_hit(&Ray::segment(batch.origins_m[r], batch.directions[r], batch.max_distances_m[r]));
        }
    });
    batch.len() as u64
}

/// Which normal a seam hit carries ([`probegi_field::DdgiFieldSet::hit_normals_needed`]).
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum HitNormal {
    /// None (zero): relocation rounds and update batches read distances only.
    None,
    /// The triangle's plane, facing the ray's origin: what the jcgt
    /// classification of an initialisation round reads (which side of a
    /// surface's plane a probe lies on; [`Scene::facing_geometric_normal`]).
    Plane,
    /// The facing shading normal: the shadowing field's surfels of an update batch.
    Shading,
}

impl HitNormal {
    /// The normal a round reads: none unless the set says it reads one
    /// (`needed`), the plane in an `initialization` round, else the shading normal.
    pub fn for_round(needed: bool, initialization: bool) -> Self {
        match (needed, initialization) {
            (false, _) => Self::None,
            (true, true) => Self::Plane,
            (true, false) => Self::Shading,
        }
    }
}

/// The seam's record of one traced ray: signed distance and the normal
/// `normal` asks for (zero for [`HitNormal::None`]).
pub fn probe_ray_hit(scene: &Scene, hit: &Option<RayHit>, normal: HitNormal) -> ProbeRayHit {
    match hit {
        None => ProbeRayHit::MISS,
        Some(h) => {
            let n = match normal {
                HitNormal::None => Vec3::ZERO,
                HitNormal::Plane => scene.facing_geometric_normal(h),
                HitNormal::Shading => scene.surface_point(h).facing_normal(),
            };
            if h.backface { ProbeRayHit::back(h.t, n) } else { ProbeRayHit::front(h.t, n) }
        }
    }
}

/// The seam hits of `hits` into `out` (see [`probe_ray_hit`]), in parallel.
pub fn probe_ray_hits(scene: &Scene, hits: &[Option<RayHit>], normal: HitNormal, out: &mut Vec<ProbeRayHit>) {
    out.clear();
    hits.par_iter().map(|h| probe_ray_hit(scene, h, normal)).collect_into_vec(out);
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
/// per-probe state, and the per-ray batch, hit and shading buffers of one frame).
pub fn ddgi_volume_bytes(settings: &probegi_core::ddgi_settings::DdgiVolumeSettings) -> u64 {
    let probes = settings.probe_count();
    let rays = probes * settings.probe_rays_per_probe as u64;
    // Batch (origins, directions, max distances, needs_radiance), radiance, seam
    // hit, closest hit, and the shade pass's surface point, query cell, order and
    // field irradiance (sorted, then in batch order).
    let shade = std::mem::size_of::<Option<probegi_scene::SurfacePoint>>() + 4 + 4 + 12 + 12;
    let per_ray = 3 * 12 + 4 + 1 + 16 + std::mem::size_of::<Option<RayHit>>() + shade;
    rays * per_ray as u64
        + probes
            * (probegi_core::probe_atlas::tile_texel_count(settings.probe_irradiance_texels) as u64 * 12
                + probegi_core::probe_atlas::tile_texel_count(settings.probe_distance_texels) as u64 * 8
                + 64)
}
