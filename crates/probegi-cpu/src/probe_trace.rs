//! Trace pass (seed 003 §4.3): every ray of the frame's probe ray batch finds its
//! closest hit, both faces (backface culling off, so probes inside geometry
//! notice), and writes a surfel: the surface it hit (position, normal, material,
//! which face) and the distance. Rays that travel beyond their max distance are
//! misses. The surfels become the seam's hits ([`surfel_hit`]) and feed the shade
//! pass.

use glam::Vec3;
use probegi_scene::{Ray, RayHit, RayTracer, Scene, SurfacePoint};
use rayon::prelude::*;

use crate::ddgi_field_set::{ProbeRayBatch, ProbeRayHit};

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

/// Work a render hands to another device: every probe ray batch's trace, and
/// optionally its shade and the camera frame, or (`trace_on_device`,
/// `relocate_on_device`, `classify_on_device`, `shade_and_blend_on_device`) the
/// whole update with the atlases kept there. The CLI's `--backend wgpu` plugs
/// in `probegi-wgpu-seam`'s GPU passes here. The hits must be what [`RayTracer::closest_hit`] returns for the ray
/// `Ray::segment(origin, direction, max_distance)` (both faces).
pub trait ProbeBatchTracer: Sync {
    /// Closest hits of every ray of `batch`, in batch order, into `hits` (resized).
    /// `static_only`: an initialisation round, which must see static geometry only.
    fn closest_hits(
        &self,
        batch: &ProbeRayBatch,
        static_only: bool,
        hits: &mut Vec<Option<RayHit>>,
    ) -> Result<(), String>;

    /// Shades the update batch this tracer traced last (the shade pass of
    /// `probe_shade` on another device) into `radiance` (one per batch ray), or
    /// returns `None` to leave the shading to the CPU. `field` is the set as
    /// queries read it, `volumes` the set's volumes (for their shading settings).
    fn shade_batch(
        &self,
        _batch: &ProbeRayBatch,
        _field: &probegi_core::ddgi_volume_blend::DdgiFieldSetView<'_>,
        _volumes: &[crate::ddgi::DdgiVolume],
        _seed: u64,
        _frame: u32,
        _radiance: &mut Vec<Vec3>,
    ) -> Option<Result<(), String>> {
        None
    }

    /// Traces the update batch and keeps its hits on the device, for
    /// [`Self::shade_and_blend_on_device`], or returns `None` to go the host way
    /// ([`Self::closest_hits`]; a tracer that does not keep the field, or a batch
    /// too large for it). With `usage_cage_diagonals_m` (one per volume), returns
    /// per entry of `batch.probes` seed 003's usage counts (usage, relevant,
    /// backfaces; `probegi_core::probe_classification::probe_usage`) with its
    /// volume's cage diagonal; otherwise an empty vector.
    fn trace_on_device(
        &self,
        _batch: &ProbeRayBatch,
        _usage_cage_diagonals_m: Option<&[f32]>,
    ) -> Option<Result<Vec<probegi_core::probe_classification::ProbeUsageCounts>, String>> {
        None
    }

    /// Traces an initialisation batch that is a relocation round
    /// (`HostHits::Relocation`) and runs the iteration on the device: per entry
    /// of `batch.probes` (inputs in `probes`, same order) the new offset. `None`
    /// leaves the round to the host ([`Self::closest_hits`]).
    fn relocate_on_device(
        &self,
        _batch: &ProbeRayBatch,
        _probes: &[crate::ddgi::DeviceRelocationProbe],
    ) -> Option<Result<Vec<Vec3>, String>> {
        None
    }

    /// Traces an initialisation batch that is the classification round
    /// (`HostHits::Classification`) and runs it on the device: per volume of
    /// `plan` (`None`: not classified this round), per probe (inside geometry,
    /// kept). `None` leaves the round to the host ([`Self::closest_hits`]).
    fn classify_on_device(
        &self,
        _batch: &ProbeRayBatch,
        _plan: &[Option<crate::ddgi::DeviceClassification<'_>>],
    ) -> Option<Result<crate::ddgi::DeviceClassificationResults, String>> {
        None
    }

    /// Shades the batch [`Self::trace_on_device`] traced and blends and borders
    /// it by `plan` into the atlases the device holds (seed 003 §4.4–4.5), so
    /// neither the rays' results nor the atlases leave it. `field` is the set as
    /// queries read it (grids, relocation offsets, usable probes); with
    /// `upload_atlases` its atlases are current on the host and replace the
    /// device's first. Returns wall milliseconds by pass (`shade`, `blend`: blend
    /// and border), the host having waited for each.
    #[allow(clippy::too_many_arguments)]
    fn shade_and_blend_on_device(
        &self,
        _batch: &ProbeRayBatch,
        _field: &probegi_core::ddgi_volume_blend::DdgiFieldSetView<'_>,
        _upload_atlases: bool,
        _plan: &[crate::ddgi::DeviceVolumeBlend<'_>],
        _volumes: &[crate::ddgi::DdgiVolume],
        _seed: u64,
        _frame: u32,
    ) -> Result<Vec<(&'static str, f64)>, String> {
        Err("this tracer does not hold a field".into())
    }

    /// Copies the atlases of volume `index` as the device holds them into `volume`'s own.
    fn download_field(&self, _index: usize, _volume: &mut crate::ddgi::DdgiVolume) -> Result<(), String> {
        Err("this tracer does not hold a field".into())
    }

    /// The scene as it is at frame `frame` (an animated scene, posed by
    /// `Scene::set_frame_from`), before the frame's update: a device that keeps
    /// its own copy of what changes (the lights, the moving objects' triangles
    /// and their placement in the top level) updates it here.
    fn pose_scene(&self, _scene: &Scene, _frame: f32) -> Result<(), String> {
        Ok(())
    }

    /// Renders the frame's camera image on the other device (the G-buffer and
    /// camera passes of `frame_loop` under DDGI): per pixel the direct term
    /// (emission, direct light, glossy reflections) into `direct` and the field
    /// term into `indirect`, returning (pixels on a surface with a diffuse
    /// albedo, those of them the field left unlit), or `None` to leave the
    /// camera to the CPU. With `field_on_device` the device's own atlases are
    /// the current ones (`field`'s are stale; its per-probe data is current).
    #[allow(clippy::too_many_arguments)]
    fn camera_frame(
        &self,
        _camera: &probegi_core::camera::CameraRays,
        _field: &probegi_core::ddgi_volume_blend::DdgiFieldSetView<'_>,
        _field_on_device: bool,
        _area_samples: u32,
        _second_order: bool,
        _frame: u32,
        _seed: u64,
        _direct: &mut [Vec3],
        _indirect: &mut [Vec3],
    ) -> Option<Result<(usize, usize), String>> {
        None
    }
}

/// Shareable handle of a [`ProbeBatchTracer`] for render settings.
#[derive(Clone)]
pub struct ProbeTracerHandle(pub std::sync::Arc<dyn ProbeBatchTracer>);

impl std::fmt::Debug for ProbeTracerHandle {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.write_str("ProbeTracerHandle")
    }
}

/// The surfels of `hits` (one per batch ray, as a [`ProbeBatchTracer`] returns them).
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
