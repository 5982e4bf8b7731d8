//! Top level: the bounds of the bottom levels, the moving objects and the
//! still instances ([`TlasLayout`]), from which a BVH over instance bounds is
//! built once for the rest pose and again for every frame.

use std::time::Duration;

use glam::{Affine3A, Vec3, Vec3A};
use obvhs::{
    BvhBuildParams,
    aabb::Aabb,
    cwbvh::{CwBvh, builder::build_cwbvh},
    ray::Ray as ObRay,
};

use super::gpu_export::{TlasExport, TlasInstance, node_words};
use crate::bounds::transformed_bounds;
use crate::bvh_walk;
use crate::scene::Scene;

/// One BLAS placed in the world for a frame.
pub(super) struct Instance {
    /// Index into `BvhTracer::blases`.
    pub(super) blas: usize,
    /// `None` for the identity (the static part).
    local_from_world: Option<Affine3A>,
    /// Index into `Scene::instances`, `u32::MAX` for the scene's own mesh.
    pub(super) scene_instance: u32,
}

impl Instance {
    /// `r` in this instance's space; `None` where the move overflows (a miss
    /// of this instance).
    pub(super) fn to_local(&self, r: &ObRay) -> Option<ObRay> {
        match &self.local_from_world {
            None => Some(*r),
            Some(m) => bvh_walk::moved_ray(r, m),
        }
    }
}

/// The top-level structure of one frame: a BVH over instance bounds.
pub(super) struct Tlas {
    pub(super) bvh: CwBvh,
    pub(super) instances: Vec<Instance>,
}

/// What a tracer's top level is built from: the bounds of its bottom levels,
/// its moving objects and its still instances. A device that traces the two
/// levels itself (`probegi-wgpu`) keeps this and places the instances for each
/// frame with [`TlasLayout::export_at`], as [`RayTracer::at_frame`](crate::RayTracer::at_frame) does.
#[derive(Clone, Debug)]
pub struct TlasLayout {
    /// Bounds of `BvhTracer::blases[k]` (`None`: no triangles).
    pub(super) blas_bounds: Vec<Option<(Vec3, Vec3)>>,
    /// Scene object index of `blases[k + 1]`.
    pub(super) object_ids: Vec<usize>,
    /// Still instances: BLAS index, world from local, `Scene::instances` index.
    pub(super) placed: Vec<(usize, Affine3A, u32)>,
    pub(super) pad_rel: f32,
}

impl TlasLayout {
    /// Whether `posed` has the moving objects this layout instances.
    pub(super) fn follows(&self, posed: &Scene) -> bool {
        self.object_ids.len() == posed.objects.iter().filter(|o| o.is_animated()).count()
            && self.object_ids.iter().all(|&i| posed.objects.get(i).is_some_and(|o| o.is_animated()))
    }

    /// The moving objects' transforms at `frame`.
    pub(super) fn poses(&self, posed: &Scene, frame: f32) -> Vec<Option<Affine3A>> {
        self.object_ids.iter().map(|&i| Some(posed.objects[i].world_from_rest(frame))).collect()
    }

    /// The top level with the moving objects of `posed` placed at `frame` (the
    /// one [`RayTracer::at_frame`](crate::RayTracer::at_frame) traces); an error when `posed` is not the
    /// scene this layout's tracer was built for.
    pub fn export_at(&self, posed: &Scene, frame: f32) -> Result<TlasExport, String> {
        if !self.follows(posed) {
            return Err(format!(
                "scene {} has other moving objects than the {} its BVH was built with",
                posed.name,
                self.object_ids.len()
            ));
        }
        Ok(self.export(&self.build(Some(&self.poses(posed, frame)))))
    }

    /// Whether the layout has moving objects (its top level changes per frame).
    pub fn moves(&self) -> bool {
        !self.object_ids.is_empty()
    }

    pub(super) fn export(&self, tlas: &Tlas) -> TlasExport {
        TlasExport {
            node_words: node_words(&tlas.bvh),
            instances: tlas
                .instances
                .iter()
                .map(|i| TlasInstance {
                    blas: i.blas as u32,
                    local_from_world: i.local_from_world,
                    scene_instance: i.scene_instance,
                    moving: (1..=self.object_ids.len()).contains(&i.blas),
                })
                .collect(),
        }
    }

    /// The top-level BVH over the static part, the moving objects placed by
    /// `moving` (`None` entries: at rest; `None` altogether: left out) and the
    /// still instances.
    pub(super) fn build(&self, moving: Option<&[Option<Affine3A>]>) -> Tlas {
        let mut instances = vec![];
        let mut aabbs = vec![];
        let pad = Vec3A::splat(self.pad_rel.max(0.0));
        let mut add = |blas: usize, xf: Option<Affine3A>, scene_instance: u32| {
            let Some((lo, hi)) = self.blas_bounds[blas] else { return };
            let (lo, hi) = match xf {
                None => (lo, hi),
                Some(m) => transformed_bounds(&m, lo, hi),
            };
            let extent = (hi - lo).max_element().max(1e-6);
            aabbs.push(Aabb::new(Vec3A::from(lo) - pad * extent, Vec3A::from(hi) + pad * extent));
            instances.push(Instance { blas, local_from_world: xf.map(|m| m.inverse()), scene_instance });
        };
        add(0, None, u32::MAX);
        if let Some(moving) = moving {
            for (k, &xf) in moving.iter().enumerate().take(self.object_ids.len()) {
                add(k + 1, xf, u32::MAX);
            }
        }
        for &(blas, xf, i) in &self.placed {
            add(blas, Some(xf), i);
        }
        let bvh = if aabbs.is_empty() {
            CwBvh::default()
        } else {
            build_cwbvh(&aabbs, BvhBuildParams::fastest_build(), &mut Duration::default())
        };
        let instances = if aabbs.is_empty() {
            instances
        } else {
            let mut slots: Vec<Option<Instance>> = instances.into_iter().map(Some).collect();
            bvh.primitive_indices.iter().filter_map(|&i| slots[i as usize].take()).collect()
        };
        Tlas { bvh, instances }
    }
}
