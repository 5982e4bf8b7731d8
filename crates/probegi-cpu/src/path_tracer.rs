//! The reference: unbiased path tracing of two-sided surfaces with the shared
//! diffuse + GGX BSDF (`probegi reference`).
//!
//! Estimator per path vertex (Veach 1997, ch. 9):
//! - emissive triangles by next-event estimation (power-weighted triangle, uniform
//!   point) combined with BSDF sampling (`probegi_core::bsdf`) by the power heuristic;
//! - punctual lights (point, spot, directional) by next-event estimation only
//!   (delta lights cannot be hit);
//! - the constant sky by BSDF sampling only. Deliberate: for a constant sky the
//!   cosine-weighted BSDF sample is already proportional to the unoccluded
//!   integrand, so a separate sky light sample would draw from the same density
//!   and MIS between two identical strategies only doubles the rays;
//! - an environment map (`Scene::sky_map`) by next-event estimation drawn from
//!   its luminance density (`probegi_scene::environment_map`) combined with BSDF
//!   sampling by the power heuristic: a small bright sun is found by the light
//!   sample, a glossy reflection of it by the BSDF sample;
//! - Russian roulette from `pt_rr_start_depth`, survival = max throughput channel
//!   (≤ 0.95); hard stop at `pt_max_depth` vertices.
//!
//! Conventions shared with the independent checker: box pixel filter (uniform
//! jitter inside the pixel), vertical field of view, emission from the front face
//! only, sky black unless given. Every pixel draws from its own PCG stream seeded
//! by `(seed, pixel)`, so images are identical for any thread count.

use glam::Vec3;
use probegi_core::camera::CameraRays;
use probegi_core::image::Image;
use probegi_core::rng::{Pcg32, hash_combine};
use probegi_core::sampling::power_heuristic;
use probegi_scene::{Ray, RayTracer, Scene, SurfacePoint};

use crate::light_sampling::AreaLights;
use crate::shading::{ShadingContext, lambert_cos, punctual_direct, shadow_ray_along, shadow_ray_to};

/// Settings of the reference path tracer (`probegi reference`).
#[derive(Clone, Copy, Debug)]
pub struct PathTracerSettings {
    /// Samples per pixel.
    pub pt_spp: u32,
    /// Maximum number of surface interactions per path. 64 leaves < 0.95^64 ≈ 4 %
    /// of the energy of even a 0.95-albedo furnace, and Russian roulette ends
    /// almost every path long before.
    pub pt_max_depth: u32,
    /// First depth at which Russian roulette may end a path.
    pub pt_rr_start_depth: u32,
    /// Next-event estimation with MIS on area lights. Off = BSDF sampling only, an
    /// independent unbiased estimator kept for testing the MIS weights.
    pub pt_light_sampling: bool,
    /// Random seed of every pixel's stream (see the module docs).
    pub seed: u64,
}

impl Default for PathTracerSettings {
    fn default() -> Self {
        Self { pt_spp: 256, pt_max_depth: 64, pt_rr_start_depth: 3, pt_light_sampling: true, seed: 0 }
    }
}

/// What a render produced besides the image.
#[derive(Clone, Copy, Debug, Default)]
pub struct RenderCounters {
    /// Rays traced: camera, bounce and shadow rays.
    pub rays_traced: u64,
}

/// The unbiased reference renderer over a scene and its ray tracer.
pub struct PathTracer<'a> {
    scene: &'a Scene,
    tracer: &'a dyn RayTracer,
    area_lights: AreaLights,
    settings: PathTracerSettings,
}

impl<'a> PathTracer<'a> {
    /// A path tracer of `scene` whose rays `tracer` traces.
    pub fn new(scene: &'a Scene, tracer: &'a dyn RayTracer, settings: PathTracerSettings) -> Self {
        Self { scene, tracer, area_lights: AreaLights::new(scene), settings }
    }

    /// Renders the whole image. `on_row_done` is called once per finished row.
    pub fn render(
        &self,
        camera: &CameraRays,
        width: u32,
        height: u32,
        on_row_done: &(dyn Fn() + Sync),
    ) -> (Image, RenderCounters) {
        let never = std::sync::atomic::AtomicBool::new(false);
        self.render_cancellable(camera, width, height, on_row_done, &never)
            .unwrap_or_else(|| (Image::new(width, height), RenderCounters::default()))
    }

    /// [`Self::render`] that stops early when `cancel` is set (rows not yet
    /// started are skipped): `None` when it was cancelled. Uncancelled, the
    /// image is `render`'s, bit for bit.
    pub fn render_cancellable(
        &self,
        camera: &CameraRays,
        width: u32,
        height: u32,
        on_row_done: &(dyn Fn() + Sync),
        cancel: &std::sync::atomic::AtomicBool,
    ) -> Option<(Image, RenderCounters)> {
        use std::sync::atomic::Ordering::Relaxed;
        let mut img = Image::new(width, height);
        let w = width as usize;
        let spp = self.settings.pt_spp.max(1);
        let rays = crate::parallel::for_each_row(
            &mut img.pixels,
            w,
            |y, row| {
                if cancel.load(Relaxed) {
                    return 0;
                }
                let mut rays = 0u64;
                for (x, px) in row.iter_mut().enumerate() {
                    let pixel = (y * w + x) as u64;
                    let mut rng = Pcg32::new(hash_combine(&[self.settings.seed, pixel]), pixel);
                    let mut sum = glam::DVec3::ZERO;
                    for _ in 0..spp {
                        let j = rng.next_vec2();
                        let dir = camera.ray_dir_world(x as f32 + j.x, y as f32 + j.y);
                        let (l, n) = self.radiance(Ray::new(camera.origin_world, dir), &mut rng);
                        rays += n;
                        // A non-finite sample (degenerate geometry) is dropped, never averaged in.
                        if l.is_finite() {
                            sum += l.as_dvec3();
                        }
                    }
                    *px = (sum / spp as f64).as_vec3();
                }
                rays
            },
            on_row_done,
        );
        (!cancel.load(Relaxed)).then_some((img, RenderCounters { rays_traced: rays }))
    }

    /// One next-event sample of the area lights at `sp`, MIS-weighted against
    /// BSDF sampling. Returns reflected radiance and rays traced.
    fn area_light_nee(&self, sp: &SurfacePoint, ctx: &ShadingContext, rng: &mut Pcg32) -> (Vec3, u64) {
        let (u_select, u_point) = (rng.next_f32(), rng.next_vec2());
        if !self.settings.pt_light_sampling {
            return (Vec3::ZERO, 0);
        }
        let Some(s) = self.area_lights.sample(self.scene, sp.position, u_select, u_point) else {
            return (Vec3::ZERO, 0);
        };
        let Some(cos) = lambert_cos(sp, s.wi) else { return (Vec3::ZERO, 0) };
        if s.radiance == Vec3::ZERO || s.pdf_solid_angle <= 0.0 {
            return (Vec3::ZERO, 0);
        }
        if self.tracer.occluded(&shadow_ray_to(sp, s.point)) {
            return (Vec3::ZERO, 1);
        }
        let w = power_heuristic(s.pdf_solid_angle, ctx.pdf(s.wi));
        (ctx.eval(s.wi) * s.radiance * (cos * w / s.pdf_solid_angle), 1)
    }

    /// One next-event sample of the environment map at `sp`, MIS-weighted
    /// against BSDF sampling (draws two numbers, only when the scene has a map).
    fn sky_map_nee(&self, sp: &SurfacePoint, ctx: &ShadingContext, rng: &mut Pcg32) -> (Vec3, u64) {
        let Some(map) = &self.scene.sky_map else { return (Vec3::ZERO, 0) };
        let u = rng.next_vec2();
        if !self.settings.pt_light_sampling {
            return (Vec3::ZERO, 0);
        }
        let Some(s) = map.sample(u) else { return (Vec3::ZERO, 0) };
        let Some(cos) = lambert_cos(sp, s.wi) else { return (Vec3::ZERO, 0) };
        if s.radiance == Vec3::ZERO || s.pdf_solid_angle <= 0.0 {
            return (Vec3::ZERO, 0);
        }
        if self.tracer.occluded(&shadow_ray_along(sp, s.wi, f32::INFINITY)) {
            return (Vec3::ZERO, 1);
        }
        let w = power_heuristic(s.pdf_solid_angle, ctx.pdf(s.wi));
        (ctx.eval(s.wi) * s.radiance * (cos * w / s.pdf_solid_angle), 1)
    }

    /// The sky a path that left the scene along `dir` adds: an environment map's
    /// MIS-weighted against its own light sample after a BSDF sample.
    fn sky_on_miss(&self, dir: Vec3, prev_bsdf_pdf: Option<f32>) -> Vec3 {
        let scene = self.scene;
        match (&scene.sky_map, prev_bsdf_pdf) {
            (Some(map), Some(pdf)) if self.settings.pt_light_sampling => {
                map.radiance(dir) * power_heuristic(pdf, map.pdf(dir))
            }
            _ => scene.sky_toward(dir),
        }
    }

    /// Radiance arriving along `ray`, and the number of rays traced.
    pub fn radiance(&self, mut ray: Ray, rng: &mut Pcg32) -> (Vec3, u64) {
        let scene = self.scene;
        let mut l = Vec3::ZERO;
        let mut throughput = Vec3::ONE;
        let mut rays = 0u64;
        // Solid-angle density of the BSDF sample that produced `ray`; None for camera rays.
        let mut prev_bsdf_pdf: Option<f32> = None;
        let mut prev_position = ray.origin;
        for depth in 0..self.settings.pt_max_depth {
            rays += 1;
            let Some(hit) = self.tracer.closest_hit(&ray) else {
                l += throughput * self.sky_on_miss(ray.dir, prev_bsdf_pdf);
                break;
            };
            let sp = scene.surface_point(&hit);
            let le = scene.emitted(&sp);
            if le != Vec3::ZERO {
                let w = match prev_bsdf_pdf {
                    Some(pdf) if self.settings.pt_light_sampling => {
                        let light_pdf =
                            self.area_lights.pdf_solid_angle(scene, prev_position, sp.position, sp.triangle);
                        power_heuristic(pdf, light_pdf)
                    }
                    _ => 1.0,
                };
                l += throughput * le * w;
            }
            let ctx = ShadingContext::new(scene, &sp, -ray.dir);
            if ctx.bsdf.diffuse == Vec3::ZERO && !ctx.bsdf.has_specular() {
                break;
            }

            let (ld, n) = self.area_light_nee(&sp, &ctx, rng);
            l += throughput * ld;
            rays += n;
            let (ls, n) = self.sky_map_nee(&sp, &ctx, rng);
            l += throughput * ls;
            rays += n;
            let (lp, n) = punctual_direct(scene, self.tracer, &sp, &ctx);
            l += throughput * lp;
            rays += n;

            // The lobe choice draws a number only when there is a choice, so that
            // diffuse scenes keep their random streams.
            let u_lobe = if ctx.bsdf.has_specular() { rng.next_f32() } else { 1.0 };
            let Some((wi_local, weight, pdf)) = ctx.bsdf.sample(ctx.wo, u_lobe, rng.next_vec2()) else { break };
            let wi = ctx.frame.to_world(wi_local);
            if lambert_cos(&sp, wi).is_none() {
                break;
            }
            throughput *= weight;
            prev_bsdf_pdf = Some(pdf);
            prev_position = sp.position;
            if depth + 1 >= self.settings.pt_rr_start_depth {
                let survive = throughput.max_element().min(0.95);
                if rng.next_f32() >= survive {
                    break;
                }
                throughput /= survive;
            }
            ray = Ray::new(sp.spawn_origin(wi), wi);
        }
        (l, rays)
    }
}
