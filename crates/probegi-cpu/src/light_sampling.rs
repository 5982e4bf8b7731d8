//! Light sampling shared by every CPU renderer: next-event estimation on emissive
//! triangles (chosen proportional to emitted power, then uniform by area) and the
//! exact incident irradiance of punctual lights (glTF KHR_lights_punctual).

use glam::{Vec2, Vec3};
use probegi_core::punctual::{range_window, spot_cone_attenuation};
use probegi_core::sampling::{Distribution1d, sample_uniform_triangle};
use probegi_scene::{LightKind, PunctualLight, Scene};

/// A point sampled on an area light, seen from a shading point.
#[derive(Clone, Copy, Debug)]
pub struct AreaLightSample {
    /// The sampled point on the emitter, world space.
    pub point: Vec3,
    /// Unit direction from the shading point to `point`.
    pub wi: Vec3,
    /// Distance from the shading point to `point`, metres.
    pub distance: f32,
    /// Radiance leaving `point` toward the shading point (zero from the back face).
    pub radiance: Vec3,
    /// Density of this direction per steradian at the shading point.
    pub pdf_solid_angle: f32,
}

/// Emissive triangles as a power-weighted discrete distribution.
#[derive(Clone, Debug, Default)]
pub struct AreaLights {
    /// Scene triangle index of each emitter.
    emitters: Vec<u32>,
    distribution: Distribution1d,
    /// Selection probability divided by area, per scene triangle (0 for non-emitters).
    pdf_area_by_triangle: Vec<f32>,
}

impl AreaLights {
    /// The emissive triangles of `scene` with a positive, finite emitted power.
    pub fn new(scene: &Scene) -> Self {
        let mesh = &scene.mesh;
        let (emitters, weights) = scene.emitter_powers();
        let distribution = Distribution1d::new(&weights);
        let mut pdf_area_by_triangle = vec![0.0; mesh.triangle_count()];
        for (i, &t) in emitters.iter().enumerate() {
            pdf_area_by_triangle[t as usize] = distribution.pmf(i) / mesh.area(t as usize);
        }
        Self { emitters, distribution, pdf_area_by_triangle }
    }

    /// Whether there is no emitter to sample.
    pub fn is_empty(&self) -> bool {
        self.emitters.is_empty()
    }

    /// Number of emissive triangles in the distribution.
    pub fn len(&self) -> usize {
        self.emitters.len()
    }

    /// Samples a point on an emitter as seen from `from`. `u_select` picks the
    /// triangle, `u_point` the point on it.
    pub fn sample(&self, scene: &Scene, from: Vec3, u_select: f32, u_point: Vec2) -> Option<AreaLightSample> {
        let (i, _) = self.distribution.sample_discrete(u_select)?;
        let tri = self.emitters[i] as usize;
        let mesh = &scene.mesh;
        let b = sample_uniform_triangle(u_point);
        let [p0, p1, p2] = mesh.vertices(tri);
        let point = p0 * b.x + p1 * b.y + p2 * b.z;
        let to = point - from;
        let dist2 = to.length_squared();
        if dist2 <= 0.0 {
            return None;
        }
        let distance = dist2.sqrt();
        let wi = to / distance;
        let n = mesh.face_normal_scaled(tri).normalize_or_zero();
        let cos_light = -wi.dot(n);
        if cos_light <= 0.0 {
            return None; // the back face does not emit
        }
        let at = mesh.attributes_at(tri, b);
        let radiance = scene.material(mesh.triangle_materials[tri]).emission(&scene.textures, &at);
        let pdf_solid_angle = self.pdf_area_by_triangle[tri] * dist2 / cos_light;
        Some(AreaLightSample { point, wi, distance, radiance, pdf_solid_angle })
    }

    /// Density per steradian with which [`Self::sample`] would pick the direction from
    /// `from` to `point` on `triangle` (for MIS when a BSDF ray hits an emitter).
    pub fn pdf_solid_angle(&self, scene: &Scene, from: Vec3, point: Vec3, triangle: u32) -> f32 {
        let pdf_area = self.pdf_area_by_triangle.get(triangle as usize).copied().unwrap_or(0.0);
        if pdf_area == 0.0 {
            return 0.0;
        }
        let to = point - from;
        let dist2 = to.length_squared();
        let n = scene.mesh.face_normal_scaled(triangle as usize).normalize_or_zero();
        let cos_light = (-to.normalize_or_zero().dot(n)).abs();
        if cos_light <= 0.0 { 0.0 } else { pdf_area * dist2 / cos_light }
    }
}

/// Light arriving at a point from a punctual light, before the cosine and visibility.
#[derive(Clone, Copy, Debug)]
pub struct PunctualIncident {
    /// Unit direction toward the light.
    pub wi: Vec3,
    /// Distance to the light (infinite for directional lights).
    pub distance: f32,
    /// Irradiance on a surface facing the light, W·m⁻² per channel.
    pub irradiance: Vec3,
}

/// Incident light from `light` at `point`, or `None` if it contributes nothing.
pub fn punctual_incident(light: &PunctualLight, point: Vec3) -> Option<PunctualIncident> {
    let power = light.color * light.intensity;
    let (wi, distance, irradiance) = match light.kind {
        LightKind::Directional => (-light.direction.normalize(), f32::INFINITY, power),
        LightKind::Point | LightKind::Spot => {
            let to = light.position - point;
            let d2 = to.length_squared();
            if d2 <= 0.0 {
                return None;
            }
            let d = d2.sqrt();
            let wi = to / d;
            let mut e = power * range_window(d, light.range) / d2;
            if light.kind == LightKind::Spot {
                let cos_angle = light.direction.normalize().dot(-wi);
                e *= spot_cone_attenuation(cos_angle, light.inner_cone_angle, light.outer_cone_angle);
            }
            (wi, d, e)
        }
    };
    (irradiance.max_element() > 0.0).then_some(PunctualIncident { wi, distance, irradiance })
}
