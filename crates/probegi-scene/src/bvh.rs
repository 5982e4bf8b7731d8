//! [`RayTracer`] over obvhs's compressed-wide BVH (CWBVH, Ylitie et al. 2017).
//!
//! Primitive AABBs are padded before the build: obvhs gets about 10× slower when
//! many triangles lie exactly in axis-aligned planes (Cornell-box walls, architecture),
//! because their boxes have zero extent on one axis and the build's surface-area
//! cost degenerates. The pad is relative to the scene's extent, far below any
//! feature size, and intersection still uses the exact triangles.

use std::time::{Duration, Instant};

use glam::{Vec2, Vec3A};
use obvhs::{
    BvhBuildParams,
    aabb::Aabb,
    cwbvh::{CwBvh, builder::build_cwbvh},
    ray::{Ray as ObRay, RayHit as ObRayHit},
    rt_triangle::RtTriangle,
};

use crate::mesh::Mesh;
use crate::tracer::{Ray, RayHit, RayTracer};

/// How the BVH is built.
#[derive(Clone, Copy, Debug)]
pub struct BvhSettings {
    /// Each primitive AABB grows by this fraction of the scene's largest extent on
    /// every side. 0 disables padding (only useful to measure what it buys).
    pub bvh_aabb_pad_rel: f32,
}

impl Default for BvhSettings {
    fn default() -> Self {
        Self { bvh_aabb_pad_rel: 1e-5 }
    }
}

pub struct BvhTracer {
    bvh: CwBvh,
    /// Triangles in BVH leaf order: the traversal's primitive id indexes this directly.
    triangles: Vec<RtTriangle>,
    /// Leaf order → `Mesh::triangles` index.
    triangle_ids: Vec<u32>,
    pub build_time: Duration,
}

impl BvhTracer {
    pub fn build(mesh: &Mesh, settings: BvhSettings) -> Self {
        let start = Instant::now();
        let tris: Vec<RtTriangle> = (0..mesh.triangle_count())
            .map(|i| {
                let [a, b, c] = mesh.vertices(i);
                RtTriangle::new(a.into(), b.into(), c.into())
            })
            .collect();
        if tris.is_empty() {
            return Self {
                bvh: CwBvh::default(),
                triangles: vec![],
                triangle_ids: vec![],
                build_time: start.elapsed(),
            };
        }
        let extent = mesh.bounds().map(|(lo, hi)| (hi - lo).max_element()).unwrap_or(1.0);
        let pad = Vec3A::splat(extent * settings.bvh_aabb_pad_rel.max(0.0));
        let aabbs: Vec<Aabb> = tris
            .iter()
            .map(|t| {
                let b = t.aabb();
                Aabb::new(b.min - pad, b.max + pad)
            })
            .collect();
        let bvh = build_cwbvh(&aabbs, BvhBuildParams::medium_build(), &mut Duration::default());
        let triangles = bvh.primitive_indices.iter().map(|&i| tris[i as usize]).collect();
        let triangle_ids = bvh.primitive_indices.clone();
        Self { bvh, triangles, triangle_ids, build_time: start.elapsed() }
    }

    pub fn triangle_count(&self) -> usize {
        self.triangles.len()
    }
}

fn to_obvhs(ray: &Ray) -> ObRay {
    ObRay::new(ray.origin.into(), ray.dir.into(), ray.t_min, ray.t_max)
}

impl RayTracer for BvhTracer {
    fn closest_hit(&self, ray: &Ray) -> Option<RayHit> {
        if self.triangles.is_empty() {
            return None;
        }
        let r = to_obvhs(ray);
        let mut hit = ObRayHit::none();
        if !self.bvh.ray_traverse(r, &mut hit, |r, id| self.triangles[id].intersect(r)) {
            return None;
        }
        let tri = &self.triangles[hit.primitive_id as usize];
        let bary = tri.compute_barycentric(&r);
        // RtTriangle::ng is the negated counter-clockwise normal.
        let backface = tri.ng.dot(r.direction) < 0.0;
        Some(RayHit {
            t: hit.t,
            triangle: self.triangle_ids[hit.primitive_id as usize],
            barycentric: Vec2::new(bary.x, bary.y),
            backface,
        })
    }

    fn occluded(&self, ray: &Ray) -> bool {
        if self.triangles.is_empty() {
            return false;
        }
        !self.bvh.ray_traverse_miss(to_obvhs(ray), |r, id| self.triangles[id].intersect(r))
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use glam::Vec3;

    fn one_triangle() -> Mesh {
        Mesh {
            positions: vec![Vec3::new(0.0, 0.0, 0.0), Vec3::new(1.0, 0.0, 0.0), Vec3::new(0.0, 1.0, 0.0)],
            normals: vec![Vec3::Z; 3],
            uvs: vec![glam::Vec2::ZERO; 3],
            triangles: vec![[0, 1, 2]],
            triangle_materials: vec![0],
        }
    }

    #[test]
    fn barycentrics_reconstruct_the_hit_point_and_backfaces_are_flagged() {
        let mesh = one_triangle();
        let bvh = BvhTracer::build(&mesh, BvhSettings::default());
        let p = Vec3::new(0.2, 0.3, 0.0);
        // From +Z: the CCW side, front face.
        let ray = Ray::new(p + Vec3::Z, Vec3::NEG_Z);
        let hit = bvh.closest_hit(&ray).expect("hit");
        assert!((hit.t - 1.0).abs() < 1e-6);
        assert!(!hit.backface);
        let [a, b, c] = mesh.vertices(0);
        let w = 1.0 - hit.barycentric.x - hit.barycentric.y;
        let q = a * w + b * hit.barycentric.x + c * hit.barycentric.y;
        assert!((q - p).length() < 1e-6, "{q}");
        // From -Z: back face.
        let hit = bvh.closest_hit(&Ray::new(p - Vec3::Z, Vec3::Z)).expect("hit");
        assert!(hit.backface);
        assert!(bvh.occluded(&Ray::segment(p - Vec3::Z, Vec3::Z, 2.0)));
        assert!(!bvh.occluded(&Ray::segment(p - Vec3::Z, Vec3::Z, 0.5)));
        assert!(bvh.closest_hit(&Ray::new(Vec3::new(2.0, 2.0, 1.0), Vec3::NEG_Z)).is_none());
    }

    #[test]
    fn empty_mesh_misses_everything() {
        let bvh = BvhTracer::build(&Mesh::default(), BvhSettings::default());
        assert!(bvh.closest_hit(&Ray::new(Vec3::ZERO, Vec3::X)).is_none());
        assert!(!bvh.occluded(&Ray::new(Vec3::ZERO, Vec3::X)));
    }
}
