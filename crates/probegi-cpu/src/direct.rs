//! Direct-lighting renderer (`probegi render --gi none`): emission seen directly,
//! plus one bounce of light from every light source — punctual lights exactly,
//! area lights with stratified next-event samples, the sky with stratified
//! cosine-weighted visibility samples. No interreflection: that is what the GI
//! methods add.

use glam::{Vec2, Vec3};
use probegi_core::rng::Pcg32;
use probegi_core::sampling::{Frame, sample_cosine_hemisphere};
use probegi_scene::{RayTracer, Scene, SurfacePoint};

use crate::light_sampling::AreaLights;
use crate::shading::{
    PunctualVisibility, ShadingContext, lambert_cos, punctual_direct_with, shadow_ray_along, shadow_ray_to,
};

/// Sample counts of [`DirectLighting`]'s stratified estimates, per pixel (or
/// probe-ray hit) per frame.
#[derive(Clone, Copy, Debug)]
pub struct DirectSettings {
    /// Area-light shadow samples per pixel per frame, stratified on a √n × √n grid
    /// (rounded up to a square). 16 makes a single frame of the Cornell box clean
    /// to the eye; frames accumulate.
    pub direct_area_samples: u32,
    /// Sky visibility samples per pixel per frame (cosine-weighted, stratified).
    pub direct_sky_samples: u32,
}

impl Default for DirectSettings {
    fn default() -> Self {
        Self { direct_area_samples: 16, direct_sky_samples: 16 }
    }
}

/// Stratified point `i` of a `k × k` grid, jittered by `u`.
fn stratum(i: u32, k: u32, u: Vec2) -> Vec2 {
    Vec2::new(((i % k) as f32 + u.x) / k as f32, ((i / k) as f32 + u.y) / k as f32)
}

/// Direct light reflected at a surface point: punctual lights exactly, area
/// lights and the sky by stratified samples, each with a shadow ray.
pub struct DirectLighting<'a> {
    scene: &'a Scene,
    tracer: &'a dyn RayTracer,
    area_lights: std::borrow::Cow<'a, AreaLights>,
    settings: DirectSettings,
}

impl<'a> DirectLighting<'a> {
    /// The closest hit of `ray`, with this lighting's tracer.
    pub fn closest_hit(&self, ray: &probegi_scene::Ray) -> Option<probegi_scene::RayHit> {
        self.tracer.closest_hit(ray)
    }

    /// Whether `ray` hits anything, with this lighting's tracer.
    pub fn occluded(&self, ray: &probegi_scene::Ray) -> bool {
        self.tracer.occluded(ray)
    }

    /// Lighting of `scene` with shadow rays traced by `tracer`; builds the
    /// power-weighted emitter distribution once.
    pub fn new(scene: &'a Scene, tracer: &'a dyn RayTracer, settings: DirectSettings) -> Self {
        Self { scene, tracer, area_lights: std::borrow::Cow::Owned(AreaLights::new(scene)), settings }
    }

    /// The same lighting over `scene`, a later frame of the same scene, traced with
    /// `tracer` (that frame's). The emitter distribution is reused unless an
    /// emissive triangle belongs to a moving object (its area may change).
    pub fn for_frame<'b>(&'b self, scene: &'b Scene, tracer: &'b dyn RayTracer) -> DirectLighting<'b> {
        let emitter_moves = scene
            .objects
            .iter()
            .filter(|o| o.is_animated())
            .any(|o| o.triangles().any(|t| scene.material(scene.mesh.triangle_materials[t]).is_emissive()));
        let area_lights = if emitter_moves {
            std::borrow::Cow::Owned(AreaLights::new(scene))
        } else {
            std::borrow::Cow::Borrowed(self.area_lights.as_ref())
        };
        DirectLighting { scene, tracer, area_lights, settings: self.settings }
    }

    /// Outgoing radiance toward `to_viewer`: emission + direct light (full BSDF).
    /// Returns radiance and rays traced.
    pub fn shade(&self, sp: &SurfacePoint, to_viewer: Vec3, rng: &mut Pcg32) -> (Vec3, u64) {
        let ctx = ShadingContext::new(self.scene, sp, to_viewer);
        let (l, rays) = self.reflected(sp, &ctx, self.settings, true, rng);
        (self.scene.emitted(sp) + l, rays)
    }

    /// Direct light reflected toward the viewer (no emission), with the sample counts
    /// of `settings`: punctual lights exactly (full BSDF), area lights by stratified
    /// NEE (full BSDF, or the diffuse lobe only when `specular_area` is false because
    /// the caller gathers specular reflections of emitters with reflected rays), and
    /// the sky on the diffuse lobe: a constant sky by stratified cosine visibility,
    /// a sky map by samples of its density with shadow rays (0 sky samples leaves
    /// the sky out).
    pub fn reflected(
        &self,
        sp: &SurfacePoint,
        ctx: &ShadingContext,
        settings: DirectSettings,
        specular_area: bool,
        rng: &mut Pcg32,
    ) -> (Vec3, u64) {
        self.reflected_with(sp, ctx, settings, specular_area, None, rng)
    }

    /// [`Self::reflected`], with punctual lights' visibility from `visibility`
    /// where it gives one (the shadowing field) instead of shadow rays.
    pub fn reflected_with(
        &self,
        sp: &SurfacePoint,
        ctx: &ShadingContext,
        settings: DirectSettings,
        specular_area: bool,
        visibility: Option<&PunctualVisibility<'_>>,
        rng: &mut Pcg32,
    ) -> (Vec3, u64) {
        let scene = self.scene;
        let (mut l, mut rays) = punctual_direct_with(scene, self.tracer, sp, ctx, visibility);

        if !self.area_lights.is_empty() && settings.direct_area_samples > 0 {
            let k = (settings.direct_area_samples as f32).sqrt().ceil() as u32;
            let n = k * k;
            let mut sum = Vec3::ZERO;
            for i in 0..n {
                let u = stratum(i, k, rng.next_vec2());
                let Some(s) = self.area_lights.sample(scene, sp.position, rng.next_f32(), u) else { continue };
                let Some(cos) = lambert_cos(sp, s.wi) else { continue };
                if s.radiance == Vec3::ZERO || s.pdf_solid_angle <= 0.0 {
                    continue;
                }
                rays += 1;
                if !self.tracer.occluded(&shadow_ray_to(sp, s.point)) {
                    let f = if specular_area { ctx.eval(s.wi) } else { ctx.eval_diffuse(s.wi) };
                    sum += f * s.radiance * (cos / s.pdf_solid_angle);
                }
            }
            l += sum / n as f32;
        }
        let albedo = ctx.bsdf.diffuse_albedo();

        if let (Some(map), true) = (&scene.sky_map, settings.direct_sky_samples > 0) {
            let (sky, sky_rays) = self.sky_map_direct(map, sp, ctx, settings.direct_sky_samples, rng);
            l += sky;
            rays += sky_rays;
        } else if scene.has_sky() && settings.direct_sky_samples > 0 {
            let k = (settings.direct_sky_samples as f32).sqrt().ceil() as u32;
            let n = k * k;
            let frame = Frame::from_normal(sp.facing_normal());
            let mut visible = 0u32;
            for i in 0..n {
                let wi = frame.to_world(sample_cosine_hemisphere(stratum(i, k, rng.next_vec2())));
                if lambert_cos(sp, wi).is_none() {
                    continue;
                }
                rays += 1;
                if !self.tracer.occluded(&shadow_ray_along(sp, wi, f32::INFINITY)) {
                    visible += 1;
                }
            }
            // ∫ (ρ/π) L_sky V cos dω estimated with pdf cos/π: ρ · L_sky · mean(V).
            l += albedo * scene.sky_radiance * (visible as f32 / n as f32);
        }
        (l, rays)
    }

    /// A sky map's light reflected by the diffuse lobe at `sp`: `samples`
    /// directions drawn from the map's luminance density (stratified on a
    /// √n × √n grid), each with a shadow ray to infinity;
    /// ∫ f_d L V cos dω ≈ mean(f_d L V cos / pdf). The density is positive
    /// wherever the map's bilinear radiance is (`environment_map`), so this one
    /// strategy is unbiased. Returns the radiance and the shadow rays traced.
    fn sky_map_direct(
        &self,
        map: &probegi_scene::SkyMap,
        sp: &SurfacePoint,
        ctx: &ShadingContext,
        samples: u32,
        rng: &mut Pcg32,
    ) -> (Vec3, u64) {
        let k = (samples as f32).sqrt().ceil() as u32;
        let n = k * k;
        let (mut sum, mut rays) = (Vec3::ZERO, 0u64);
        for i in 0..n {
            let u = stratum(i, k, rng.next_vec2());
            let Some(s) = map.sample(u) else { continue };
            let Some(cos) = lambert_cos(sp, s.wi) else { continue };
            rays += 1;
            if !self.tracer.occluded(&shadow_ray_along(sp, s.wi, f32::INFINITY)) {
                sum += ctx.eval_diffuse(s.wi) * s.radiance * (cos / s.pdf_solid_angle);
            }
        }
        (sum / n as f32, rays)
    }
}
