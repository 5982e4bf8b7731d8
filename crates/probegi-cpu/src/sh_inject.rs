//! Light injection of the SH probe method (seed 001 §5.2): after the screen
//! update, each probe takes jittered samples of the emissive triangles near it
//! and of the sky, and projects them with the same error form as screen samples.
//!
//! - "A spatial data structure is employed to ensure probes only sample light
//!   sources that are close enough": [`EmitterGrid`], a uniform grid over the
//!   scene in which every cell lists the emitters whose range reaches it. An
//!   emitter's range is where the irradiance it could deliver, L·A/d², falls to
//!   `sh_light_cutoff_irradiance`.
//! - Each nearby emitter gets `sh_light_samples_per_emitter` stratified points;
//!   each stands for its share of the triangle's area, so its weight is the solid
//!   angle that share subtends at the probe (eq. 11 with the emitter as sample).
//! - The sky gets `sh_sky_samples_per_probe` directions of a randomly rotated
//!   spherical Fibonacci set, each 4π/k sr.
//! - `sh_light_sample_weight` scales both against the screen samples (the
//!   paper's "magic number"); with `sh_occlusion` a shadow ray from the probe
//!   drops samples that geometry hides, as it does for screen samples.

use glam::{UVec3, Vec2, Vec3};
use probegi_core::color::luminance;
use probegi_core::fibonacci::{sample_uniform_rotation, spherical_fibonacci};
use probegi_core::rng::Pcg32;
use probegi_core::sampling::sample_uniform_triangle;
use probegi_core::sh_probe_update::{ShSample, sample_toward_probe};
use probegi_core::sh_settings::ShProbeSettings;
use probegi_scene::{Ray, RayTracer, Scene};
use std::f32::consts::PI;

#[derive(Clone, Debug)]
struct Emitter {
    vertices: [Vec3; 3],
    normal: Vec3,
    area_m2: f32,
    radiance: Vec3,
    centroid: Vec3,
    range_m: f32,
}

/// Emissive triangles bucketed by the grid cells their range reaches.
#[derive(Clone, Debug, Default)]
pub struct EmitterGrid {
    emitters: Vec<Emitter>,
    lo: Vec3,
    cell_m: Vec3,
    dims: UVec3,
    cells: Vec<Vec<u32>>,
}

/// Cells per axis of the emitter grid.
const EMITTER_GRID_DIMS: u32 = 8;

impl EmitterGrid {
    /// The emissive triangles of `scene`, each listed in the grid cells within
    /// the range where its irradiance stays above `cutoff_irradiance`.
    pub fn new(scene: &Scene, cutoff_irradiance: f32) -> Self {
        let mesh = &scene.mesh;
        let mut emitters = Vec::new();
        for t in 0..mesh.triangle_count() {
            let mat = scene.material(mesh.triangle_materials[t]);
            if !mat.is_emissive() {
                continue;
            }
            let radiance = mat.mean_emission(&scene.textures);
            let area_m2 = mesh.area(t);
            let lum = luminance(radiance);
            if !(lum > 0.0 && area_m2 > 0.0 && lum.is_finite()) {
                continue;
            }
            let vertices = mesh.vertices(t);
            let centroid = (vertices[0] + vertices[1] + vertices[2]) / 3.0;
            let extent = vertices.iter().map(|v| v.distance(centroid)).fold(0.0, f32::max);
            emitters.push(Emitter {
                vertices,
                normal: mesh.face_normal_scaled(t).normalize_or_zero(),
                area_m2,
                radiance,
                centroid,
                range_m: (lum * area_m2 / cutoff_irradiance).sqrt() + extent,
            });
        }
        let (lo, hi) = scene.bounds().unwrap_or((Vec3::ZERO, Vec3::ONE));
        let dims = UVec3::splat(EMITTER_GRID_DIMS);
        let cell_m = ((hi - lo) / dims.as_vec3()).max(Vec3::splat(1e-6));
        let mut cells = vec![Vec::new(); (dims.x * dims.y * dims.z) as usize];
        for (i, e) in emitters.iter().enumerate() {
            for (c, list) in cells.iter_mut().enumerate() {
                let c = c as u32;
                let idx = UVec3::new(c % dims.x, (c / dims.x) % dims.y, c / (dims.x * dims.y));
                let cell_lo = lo + idx.as_vec3() * cell_m;
                let nearest = e.centroid.clamp(cell_lo, cell_lo + cell_m);
                if nearest.distance(e.centroid) <= e.range_m {
                    list.push(i as u32);
                }
            }
        }
        Self { emitters, lo, cell_m, dims, cells }
    }

    /// Whether the scene has no emitter to inject.
    pub fn is_empty(&self) -> bool {
        self.emitters.is_empty()
    }

    /// Calls `f` for every emitter whose range reaches `p`.
    fn for_each_near(&self, p: Vec3, mut f: impl FnMut(&Emitter)) {
        let g = ((p - self.lo) / self.cell_m).floor();
        let inside = g.cmpge(Vec3::ZERO).all() && g.cmplt(self.dims.as_vec3()).all();
        let mut visit = |i: u32| {
            let e = &self.emitters[i as usize];
            if e.centroid.distance(p) <= e.range_m {
                f(e);
            }
        };
        if inside {
            let c = g.as_uvec3();
            for &i in &self.cells[(c.x + self.dims.x * (c.y + self.dims.y * c.z)) as usize] {
                visit(i);
            }
        } else {
            (0..self.emitters.len() as u32).for_each(visit);
        }
    }
}

/// The injected samples of one probe as (direction from probe, radiance, weight).
/// Returns the shadow rays traced.
pub fn injection_samples(
    scene: &Scene,
    tracer: &dyn RayTracer,
    emitters: &EmitterGrid,
    settings: &ShProbeSettings,
    probe_m: Vec3,
    rng: &mut Pcg32,
    out: &mut Vec<(Vec3, Vec3, f32)>,
) -> u64 {
    let mut rays = 0;
    let scale = settings.sh_light_sample_weight;
    let k = settings.sh_light_samples_per_emitter;
    if k > 0 {
        let side = (k as f32).sqrt().ceil() as u32;
        emitters.for_each_near(probe_m, |e| {
            for i in 0..k {
                let u = Vec2::new(
                    ((i % side) as f32 + rng.next_f32()) / side as f32,
                    ((i / side) as f32 + rng.next_f32()) / side as f32,
                );
                let b = sample_uniform_triangle(u.min(Vec2::splat(1.0 - f32::EPSILON)));
                let point = e.vertices[0] * b.x + e.vertices[1] * b.y + e.vertices[2] * b.z;
                let sample = ShSample {
                    position_m: point,
                    normal: e.normal,
                    radiance: e.radiance,
                    area_m2: e.area_m2 / k as f32,
                };
                let Some((dir, w)) = sample_toward_probe(&sample, probe_m) else { continue };
                if settings.sh_occlusion {
                    rays += 1;
                    let dist = point.distance(probe_m);
                    if tracer.occluded(&Ray::segment(probe_m, dir, dist * (1.0 - 1e-4))) {
                        continue;
                    }
                }
                out.push((dir, e.radiance, w * scale));
            }
        });
    }
    let k = settings.sh_sky_samples_per_probe;
    if k > 0 && scene.has_sky() {
        let rotation = sample_uniform_rotation(Vec3::new(rng.next_f32(), rng.next_f32(), rng.next_f32()));
        for i in 0..k {
            let dir = rotation * spherical_fibonacci(i, k);
            if settings.sh_occlusion {
                rays += 1;
                if tracer.occluded(&Ray::segment(probe_m, dir, f32::INFINITY)) {
                    continue;
                }
            }
            out.push((dir, scene.sky_toward(dir), 4.0 * PI / k as f32 * scale));
        }
    }
    rays
}
