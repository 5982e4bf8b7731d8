//! Bottom levels: one CWBVH over some of a mesh's triangles in one space (the
//! static part in world space, a moving object in rest space, a prototype in
//! its local space), with padded primitive AABBs and per-leaf cutouts.

use std::time::Duration;

use glam::{Vec2, Vec3, Vec3A};
use obvhs::{
    BvhBuildParams,
    aabb::Aabb,
    cwbvh::{CwBvh, builder::build_cwbvh},
    ray::Ray as ObRay,
    rt_triangle::RtTriangle,
};

use super::cutouts::{CoverageMask, CutTriangle, Cutouts};
use crate::bvh_walk::{self, TraceGuards};
use crate::mesh::Mesh;
use crate::ray::RayHit;

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

/// A BVH over some of the mesh's triangles, in one space (world for the static
/// part, rest space for a moving object).
pub(super) struct Blas {
    pub(super) bvh: CwBvh,
    /// Triangles in BVH leaf order: the traversal's primitive id indexes this directly.
    pub(super) triangles: Vec<RtTriangle>,
    /// Leaf order → `Mesh::triangles` index.
    pub(super) triangle_ids: Vec<u32>,
    /// Bounds of the triangles, `None` when empty.
    pub(super) bounds: Option<(Vec3, Vec3)>,
    /// Leaf order → index into `cut`, or `u32::MAX`; empty when nothing is cut out.
    pub(super) leaf_cut: Vec<u32>,
    pub(super) cut: Vec<CutTriangle>,
}

impl Blas {
    pub(super) fn build(mesh: &Mesh, ids: &[u32], pad_m: f32, cutouts: &Cutouts) -> Self {
        let tris: Vec<RtTriangle> = ids
            .iter()
            .map(|&i| {
                let [a, b, c] = mesh.vertices(i as usize);
                RtTriangle::new(a.into(), b.into(), c.into())
            })
            .collect();
        if tris.is_empty() {
            return Self {
                bvh: CwBvh::default(),
                triangles: vec![],
                triangle_ids: vec![],
                bounds: None,
                leaf_cut: vec![],
                cut: vec![],
            };
        }
        let pad = Vec3A::splat(pad_m);
        let aabbs: Vec<Aabb> = tris
            .iter()
            .map(|t| {
                let b = t.aabb();
                Aabb::new(b.min - pad, b.max + pad)
            })
            .collect();
        let bounds = aabbs.iter().skip(1).fold(aabbs[0], |acc, b| acc.union(b));
        let bvh = build_cwbvh(&aabbs, BvhBuildParams::medium_build(), &mut Duration::default());
        let triangles = bvh.primitive_indices.iter().map(|&i| tris[i as usize]).collect();
        let triangle_ids: Vec<u32> = bvh.primitive_indices.iter().map(|&i| ids[i as usize]).collect();
        let (mut leaf_cut, mut cut) = (vec![], vec![]);
        if triangle_ids.iter().any(|&t| cutouts.mask_of(mesh, t) != u32::MAX) {
            leaf_cut = triangle_ids
                .iter()
                .map(|&t| match cutouts.mask_of(mesh, t) {
                    u32::MAX => u32::MAX,
                    mask => {
                        let uv = mesh.triangles[t as usize].map(|v| mesh.uvs[v as usize]);
                        cut.push(CutTriangle { mask, uv });
                        (cut.len() - 1) as u32
                    }
                })
                .collect();
        }
        Self { bvh, triangles, triangle_ids, bounds: Some((bounds.min.into(), bounds.max.into())), leaf_cut, cut }
    }

    /// Distance to leaf `id` along `r`, `INFINITY` for a miss or a cut-out point.
    #[inline(always)]
    fn intersect(&self, masks: &[CoverageMask], r: &ObRay, id: usize) -> f32 {
        let tri = &self.triangles[id];
        let t = tri.intersect(r);
        if t == f32::INFINITY || self.leaf_cut.is_empty() {
            return t;
        }
        let Some(c) = self.cut.get(self.leaf_cut[id] as usize) else { return t };
        let b = tri.compute_barycentric(r);
        let uv = c.uv[0] * (1.0 - b.x - b.y) + c.uv[1] * b.x + c.uv[2] * b.y;
        if masks[c.mask as usize].opaque_at(uv) { t } else { f32::INFINITY }
    }

    /// Closest hit along `r` (leaf index and t).
    pub(super) fn closest(&self, masks: &[CoverageMask], guards: &TraceGuards, r: ObRay) -> Option<(u32, f32)> {
        if self.triangles.is_empty() {
            return None;
        }
        bvh_walk::closest(&self.bvh, guards, r, |r, id| self.intersect(masks, r, id))
    }

    pub(super) fn occluded(&self, masks: &[CoverageMask], guards: &TraceGuards, r: ObRay) -> bool {
        !self.triangles.is_empty() && bvh_walk::any(&self.bvh, guards, r, |r, id| self.intersect(masks, r, id))
    }

    /// The public hit record of leaf `leaf` hit by `r` (in this BLAS's space) at `t`.
    pub(super) fn hit(&self, leaf: u32, r: &ObRay, t: f32) -> RayHit {
        let tri = &self.triangles[leaf as usize];
        let bary = tri.compute_barycentric(r);
        // RtTriangle::ng is the negated counter-clockwise normal. Instance transforms
        // have positive scale, so the side is the same in rest and world space.
        let backface = tri.ng.dot(r.direction) < 0.0;
        RayHit {
            t,
            triangle: self.triangle_ids[leaf as usize],
            barycentric: Vec2::new(bary.x, bary.y),
            backface,
            instance: u32::MAX,
        }
    }
}

pub(super) fn pad_m(bounds: Option<(Vec3, Vec3)>, settings: BvhSettings) -> f32 {
    let extent = bounds.map(|(lo, hi)| (hi - lo).max_element()).unwrap_or(1.0);
    extent * settings.bvh_aabb_pad_rel.max(0.0)
}
