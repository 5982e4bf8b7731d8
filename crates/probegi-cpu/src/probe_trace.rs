//! Trace pass (seed 003 §4.3): every probe ray finds its closest hit, both faces
//! (backface culling off, so probes inside geometry notice), and writes a surfel:
//! the surface it hit (position, normal, material, which face) and the distance.
//! Rays that travel beyond `probe_max_ray_distance_m` are misses.

use glam::Vec3;
use probegi_scene::{Ray, RayTracer, Scene, SurfacePoint};
use rayon::prelude::*;

/// One probe ray's hit record (the surfel buffer of seed 003 §4.3).
#[derive(Clone, Copy, Debug, Default)]
pub struct Surfel {
    /// `None` for a miss.
    pub surface: Option<SurfacePoint>,
    /// Hit distance in metres (the maximum ray distance for a miss).
    pub distance: f32,
}

/// Traces `dirs` from every active probe position into `surfels` (`probes × rays`,
/// probe-major); inactive probes' surfels are left as they were. `active` empty
/// means all. Returns the number of rays traced.
pub fn trace_probe_rays(
    scene: &Scene,
    tracer: &dyn RayTracer,
    probe_positions: &[Vec3],
    active: &[bool],
    dirs: &[Vec3],
    max_distance_m: f32,
    surfels: &mut [Surfel],
) -> u64 {
    let n = dirs.len();
    surfels.par_chunks_mut(n).zip(probe_positions.par_iter()).enumerate().for_each(|(p, (out, &origin))| {
        if active.get(p).is_some_and(|a| !a) {
            return;
        }
        for (s, &dir) in out.iter_mut().zip(dirs) {
            let ray = Ray::segment(origin, dir, max_distance_m);
            *s = match tracer.closest_hit(&ray) {
                Some(hit) => Surfel { surface: Some(scene.surface_point(&hit)), distance: hit.t },
                None => Surfel { surface: None, distance: max_distance_m },
            };
        }
    });
    let count = if active.is_empty() { probe_positions.len() } else { active.iter().filter(|a| **a).count() };
    (count * n) as u64
}

/// Signed true distance of a surfel: positive for a front-face hit, negative for a
/// backface hit, infinite for a miss (the input of relocation and classification).
pub fn signed_distance(s: &Surfel) -> f32 {
    match &s.surface {
        None => f32::INFINITY,
        Some(sp) if !sp.front_face => -s.distance,
        Some(_) => s.distance,
    }
}
