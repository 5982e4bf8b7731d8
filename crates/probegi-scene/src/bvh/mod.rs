//! [`RayTracer`] over obvhs's compressed-wide BVH (CWBVH, Ylitie et al. 2017).
//!
//! Primitive AABBs are padded before the build: obvhs gets about 10× slower when
//! many triangles lie exactly in axis-aligned planes (Cornell-box walls, architecture),
//! because their boxes have zero extent on one axis and the build's surface-area
//! cost degenerates. The pad is relative to the scene's extent, far below any
//! feature size, and intersection still uses the exact triangles.
//!
//! Moving geometry is instanced (dynamic-scenes issue): a BVH per moving object in
//! its rest space, built once, under a top-level BVH over the instances' bounds
//! that is rebuilt every frame; the static part keeps its one BVH. Instanced
//! meshes (`Scene::prototypes`) get one BVH each in their local space, placed
//! under the same top-level BVH once per `Scene::instances` entry, so a copy
//! costs a top-level leaf, not its triangles.
//!
//! Alpha cutouts (`material.rs`) are tested inside traversal: the intersection
//! closure of a cut-out triangle interpolates its UVs at the hit and reports a
//! miss where the coverage is below the cutoff, so closest-hit and any-hit
//! queries go on past it without re-tracing. Every ray kind goes through here.
//! [`BvhTracer::for_scene`] reads the cutouts from the scene's materials;
//! [`BvhTracer::build`] sees opaque triangles only.
//!
//! Every ray goes through the ray rule of [`crate::bvh_walk`] (NaN, infinite,
//! zero-direction and empty-range rays are misses, counted) and every walk of
//! either level is bounded by its BVH's node count.
//!
//! This module holds [`BvhTracer`] and its per-frame and static-part views; its children:
//! - `cutouts`: alpha-tested traversal support, the cut-out materials' coverage masks.
//! - `blas`: the bottom levels, one CWBVH per mesh part (static, moving object, prototype), and [`BvhSettings`].
//! - `tlas_layout`: the top level over the moving objects and the still instances.
//! - `gpu_export`: the flat form of every level that a GPU traversal reads.

mod blas;
mod cutouts;
mod gpu_export;
mod tlas_layout;

use std::sync::Arc;
use std::time::{Duration, Instant};

use obvhs::ray::Ray as ObRay;

use crate::bvh_walk::{self, TraceGuardCounts, TraceGuards};
use crate::mesh::Mesh;
use crate::ray::{Ray, RayHit};
use crate::scene::Scene;
use crate::tracer::RayTracer;
pub use blas::BvhSettings;
use blas::{Blas, pad_m};
use cutouts::Cutouts;
pub use gpu_export::{BvhCutTriangle, BvhCutoutMask, BvhExport, TlasExport, TlasInstance};
pub use tlas_layout::TlasLayout;
use tlas_layout::{Instance, Tlas};

/// The scene's ray tracer. Static triangles share one BVH built once; each moving
/// object (`BvhTracer::for_scene`) has its own BVH in rest space, built once, and
/// [`RayTracer::at_frame`] places them with a top-level BVH over the instances,
/// rebuilt every frame. With no moving objects, rays go straight to the static BVH.
pub struct BvhTracer {
    /// `blases[0]` is the static part; then one per moving object; then one per
    /// scene prototype.
    blases: Vec<Blas>,
    /// What the top level is built from (moving objects, still instances).
    layout: TlasLayout,
    /// The instances in their rest pose (what this tracer traces by itself).
    rest: Option<Tlas>,
    /// The static BLAS and the still instances, without moving objects: the
    /// static part when both exist.
    static_tlas: Option<Tlas>,
    cutouts: Cutouts,
    /// Shared with the tracers [`RayTracer::at_frame`] rebuilds.
    guards: Arc<TraceGuards>,
    /// Wall time the bottom levels and the rest-pose top level took to build.
    pub build_time: Duration,
}

impl BvhTracer {
    /// One BVH over every triangle of `mesh`, all opaque: geometry that never moves.
    pub fn build(mesh: &Mesh, settings: BvhSettings) -> Self {
        Self::build_static(mesh, Cutouts::default(), settings)
    }

    fn build_static(mesh: &Mesh, cutouts: Cutouts, settings: BvhSettings) -> Self {
        let start = Instant::now();
        let pad = pad_m(mesh.bounds(), settings);
        let ids: Vec<u32> = (0..mesh.triangle_count() as u32).collect();
        let blases = vec![Blas::build(mesh, &ids, pad, &cutouts)];
        let layout = TlasLayout {
            blas_bounds: vec![blases[0].bounds],
            object_ids: vec![],
            placed: vec![],
            pad_rel: settings.bvh_aabb_pad_rel,
        };
        let guards = Arc::default();
        Self { blases, layout, rest: None, static_tlas: None, cutouts, guards, build_time: start.elapsed() }
    }

    /// A static BVH over everything that does not move, plus one per moving object
    /// of `scene` (in the pose `scene` is in, which the loaders leave at rest) and
    /// one per prototype, placed once per instance; with the alpha cutouts of the
    /// scene's materials.
    pub fn for_scene(scene: &Scene, settings: BvhSettings) -> Self {
        let cutouts = Cutouts::of_scene(scene);
        if !scene.has_moving_geometry() && scene.instances.is_empty() {
            return Self::build_static(&scene.mesh, cutouts, settings);
        }
        let start = Instant::now();
        let mesh = &scene.mesh;
        let pad = pad_m(mesh.bounds(), settings);
        let mut moving = vec![false; mesh.triangle_count()];
        let mut blases = vec![];
        let mut object_ids = vec![];
        for (i, o) in scene.objects.iter().enumerate().filter(|(_, o)| o.is_animated()) {
            let ids: Vec<u32> = o.triangles().map(|t| t as u32).collect();
            o.triangles().for_each(|t| moving[t] = true);
            blases.push(Blas::build(mesh, &ids, pad, &cutouts));
            object_ids.push(i);
        }
        let static_ids: Vec<u32> = (0..mesh.triangle_count() as u32).filter(|&t| !moving[t as usize]).collect();
        blases.insert(0, Blas::build(mesh, &static_ids, pad, &cutouts));
        let first_prototype = blases.len();
        for proto in &scene.prototypes {
            let m = &proto.mesh;
            let ids: Vec<u32> = (0..m.triangle_count() as u32).collect();
            blases.push(Blas::build(m, &ids, pad_m(m.bounds(), settings), &cutouts));
        }
        let placed = scene
            .instances
            .iter()
            .enumerate()
            .map(|(i, inst)| (first_prototype + inst.prototype as usize, inst.world_from_local, i as u32))
            .collect();
        let layout = TlasLayout {
            blas_bounds: blases.iter().map(|b| b.bounds).collect(),
            object_ids,
            placed,
            pad_rel: settings.bvh_aabb_pad_rel,
        };
        let rest = vec![None; layout.object_ids.len()];
        let rest = Some(layout.build(Some(&rest)));
        let static_tlas = (!layout.object_ids.is_empty() && !layout.placed.is_empty()).then(|| layout.build(None));
        let guards = Arc::default();
        let mut tracer = Self { blases, layout, rest, static_tlas, cutouts, guards, build_time: Duration::ZERO };
        tracer.build_time = start.elapsed();
        tracer
    }

    /// Triangles over all bottom levels (a prototype's count once, however often it is placed).
    pub fn triangle_count(&self) -> usize {
        self.blases.iter().map(|b| b.triangles.len()).sum()
    }

    /// Every BVH of this tracer in the flat form a GPU traversal reads
    /// ([`BvhExport`]): the bottom levels one after another, and, for a tracer
    /// with a top level (moving objects, instanced meshes), that top level in
    /// its rest pose (`BvhExport::tlas`; [`TlasLayout::export_at`] places it
    /// for a frame).
    pub fn export(&self) -> BvhExport {
        let mut out = BvhExport::default();
        for blas in &self.blases {
            out.append_blas(blas);
        }
        out.cutout_masks = self.cutouts.masks.iter().map(BvhCutoutMask::of).collect();
        out.tlas = self.rest.as_ref().map(|t| self.layout.export(t));
        out
    }

    /// What this tracer's top level is built from, for a device that places the
    /// instances itself each frame; `None` when it has no top level.
    pub fn tlas_layout(&self) -> Option<&TlasLayout> {
        self.rest.as_ref().map(|_| &self.layout)
    }

    /// Triangles whose hits are alpha-tested.
    pub fn cutout_triangle_count(&self) -> usize {
        self.blases.iter().map(|b| b.cut.len()).sum()
    }

    /// Moving objects this tracer instances.
    pub fn instanced_object_count(&self) -> usize {
        self.layout.object_ids.len()
    }

    /// Rays this tracer (and the frame tracers it made) answered without a
    /// full walk: the ray rule's misses and walks cut short (`bvh_walk`).
    pub fn trace_guard_counts(&self) -> TraceGuardCounts {
        self.guards.counts()
    }

    fn closest_in(&self, tlas: Option<&Tlas>, ray: &Ray) -> Option<RayHit> {
        let g = &*self.guards;
        let r = g.usable(ray)?;
        let masks = &self.cutouts.masks[..];
        let Some(tlas) = tlas else {
            let (leaf, t) = self.blases[0].closest(masks, g, r)?;
            return Some(self.blases[0].hit(leaf, &r, t));
        };
        if tlas.instances.is_empty() {
            return None;
        }
        let mut best: Option<(&Instance, u32, ObRay, f32)> = None;
        bvh_walk::closest(&tlas.bvh, g, r, |r, id| {
            let inst = &tlas.instances[id];
            let Some(local) = inst.to_local(r) else { return f32::INFINITY };
            match self.blases[inst.blas].closest(masks, g, local) {
                Some((leaf, t)) => {
                    best = Some((inst, leaf, local, t));
                    t
                }
                None => f32::INFINITY,
            }
        })?;
        let (inst, leaf, local, t) = best?;
        Some(RayHit { instance: inst.scene_instance, ..self.blases[inst.blas].hit(leaf, &local, t) })
    }

    fn occluded_in(&self, tlas: Option<&Tlas>, ray: &Ray) -> bool {
        let g = &*self.guards;
        let Some(r) = g.usable(ray) else { return false };
        let masks = &self.cutouts.masks[..];
        let Some(tlas) = tlas else { return self.blases[0].occluded(masks, g, r) };
        if tlas.instances.is_empty() {
            return false;
        }
        bvh_walk::any(&tlas.bvh, g, r, |r, id| {
            let inst = &tlas.instances[id];
            let hit = inst.to_local(r).is_some_and(|local| self.blases[inst.blas].occluded(masks, g, local));
            if hit { r.tmin } else { f32::INFINITY }
        })
    }
}

/// A tracer with its moving objects placed for one frame.
struct FrameTracer<'a> {
    base: &'a BvhTracer,
    tlas: Tlas,
}

impl RayTracer for FrameTracer<'_> {
    fn closest_hit(&self, ray: &Ray) -> Option<RayHit> {
        self.base.closest_in(Some(&self.tlas), ray)
    }

    fn occluded(&self, ray: &Ray) -> bool {
        self.base.occluded_in(Some(&self.tlas), ray)
    }

    fn static_part<'a>(&'a self) -> Option<Box<dyn RayTracer + 'a>> {
        self.base.static_part()
    }
}

/// The static BVH and the still instances, without the moving objects.
struct StaticPart<'a>(&'a BvhTracer);

impl RayTracer for StaticPart<'_> {
    fn closest_hit(&self, ray: &Ray) -> Option<RayHit> {
        self.0.closest_in(self.0.static_tlas.as_ref(), ray)
    }

    fn occluded(&self, ray: &Ray) -> bool {
        self.0.occluded_in(self.0.static_tlas.as_ref(), ray)
    }
}

impl RayTracer for BvhTracer {
    fn closest_hit(&self, ray: &Ray) -> Option<RayHit> {
        self.closest_in(self.rest.as_ref(), ray)
    }

    fn occluded(&self, ray: &Ray) -> bool {
        self.occluded_in(self.rest.as_ref(), ray)
    }

    /// Places the moving objects at `frame` (a TLAS rebuild over the instances). A
    /// tracer built without the scene's objects (`BvhTracer::build`) cannot follow
    /// them; it then rebuilds one BVH over the posed mesh, which is correct but
    /// costs a full build per frame.
    fn at_frame<'a>(&'a self, posed: &Scene, frame: f32) -> Option<Box<dyn RayTracer + 'a>> {
        if !posed.has_moving_geometry() {
            return None;
        }
        if !self.layout.follows(posed) {
            let settings = BvhSettings { bvh_aabb_pad_rel: self.layout.pad_rel };
            if !posed.instances.is_empty() {
                // A tracer built from the mesh alone never knew the instances: rebuild all.
                let mut at_rest = posed.clone();
                at_rest.objects.clear();
                let rebuilt = BvhTracer::for_scene(&at_rest, settings);
                return Some(Box::new(BvhTracer { guards: self.guards.clone(), ..rebuilt }));
            }
            let rebuilt = BvhTracer::build_static(&posed.mesh, self.cutouts.clone(), settings);
            return Some(Box::new(BvhTracer { guards: self.guards.clone(), ..rebuilt }));
        }
        Some(Box::new(FrameTracer { base: self, tlas: self.layout.build(Some(&self.layout.poses(posed, frame))) }))
    }

    fn static_part<'a>(&'a self) -> Option<Box<dyn RayTracer + 'a>> {
        (!self.layout.object_ids.is_empty()).then(|| Box::new(StaticPart(self)) as Box<dyn RayTracer + 'a>)
    }
}

#[cfg(test)]
mod tests {
    use glam::Vec3;

    use super::*;

    fn one_triangle() -> Mesh {
        Mesh {
            positions: vec![Vec3::new(0.0, 0.0, 0.0), Vec3::new(1.0, 0.0, 0.0), Vec3::new(0.0, 1.0, 0.0)],
            normals: vec![Vec3::Z; 3],
            uvs: vec![glam::Vec2::ZERO; 3],
            triangles: vec![[0, 1, 2]],
            triangle_materials: vec![0],
            ..Default::default()
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

    /// A static floor and box, and a box that slides, turns and grows.
    fn moving_scene() -> Scene {
        use crate::animation::{ObjectAnimation, TransformKeyframe};
        use crate::shapes::{add_box, add_polygon};
        let mut s = Scene { materials: vec![crate::Material::diffuse("m", Vec3::ONE)], ..Default::default() };
        let floor = [
            Vec3::new(-5.0, 0.0, -5.0),
            Vec3::new(-5.0, 0.0, 5.0),
            Vec3::new(5.0, 0.0, 5.0),
            Vec3::new(5.0, 0.0, -5.0),
        ];
        add_polygon(&mut s.mesh, &floor, 0);
        add_box(&mut s.mesh, Vec3::new(2.0, 0.2, 2.0), Vec3::new(3.0, 1.0, 3.0), 0);
        let key = |frame: f32, x: f32, deg: f32, k: f32| TransformKeyframe {
            frame,
            translation: Some(Vec3::new(x, 0.5, 0.0)),
            rotation: Some(glam::Quat::from_rotation_y(deg.to_radians())),
            scale: Some(Vec3::splat(k)),
        };
        let animation = ObjectAnimation {
            keyframes: vec![key(0.0, -3.0, 0.0, 1.0), key(10.0, 3.0, 90.0, 1.5)],
            ..Default::default()
        };
        // Pivot: the box's centre (0, 0.5, 0).
        s.add_object("mover", |m| add_box(m, Vec3::new(-0.5, 0.0, -0.5), Vec3::new(0.5, 1.0, 0.5), 0), animation);
        assert_eq!(s.validate(), Ok(()));
        s
    }

    #[test]
    fn instanced_tracing_matches_a_full_rebuild_of_the_posed_mesh() {
        let base = moving_scene();
        let tracer = BvhTracer::for_scene(&base, BvhSettings::default());
        assert_eq!(tracer.instanced_object_count(), 1);
        let mut posed = base.clone();
        let mut rng = probegi_core::rng::Pcg32::new(7, 1);
        let mut hits = 0;
        for frame in [0.0, 3.5, 10.0] {
            posed.set_frame_from(&base, frame);
            let reference = BvhTracer::build(&posed.mesh, BvhSettings::default());
            let framed = tracer.at_frame(&posed, frame).expect("moving scene");
            for _ in 0..2000 {
                let o = Vec3::new(rng.next_f32() * 8.0 - 4.0, rng.next_f32() * 2.0 + 0.05, rng.next_f32() * 8.0 - 4.0);
                let d = probegi_core::sampling::sample_uniform_sphere(rng.next_vec2());
                let ray = Ray::segment(o, d, 1.0 + 6.0 * rng.next_f32());
                let (a, b) = (framed.closest_hit(&ray), reference.closest_hit(&ray));
                assert_eq!(a.is_some(), b.is_some(), "frame {frame} ray {ray:?}");
                if let (Some(a), Some(b)) = (a, b) {
                    hits += 1;
                    assert_eq!((a.triangle, a.backface), (b.triangle, b.backface), "frame {frame}");
                    assert!((a.t - b.t).abs() < 1e-4 && (a.barycentric - b.barycentric).length() < 1e-3);
                    let p = posed.surface_point(&a).position;
                    assert!((p - ray.at(a.t)).length() < 1e-4, "reconstructed hit off the ray: {p}");
                }
                assert_eq!(framed.occluded(&ray), reference.occluded(&ray));
            }
        }
        assert!(hits > 1000, "{hits}");
    }

    #[test]
    fn a_static_tracer_still_follows_moving_objects_by_rebuilding() {
        let base = moving_scene();
        let stale = BvhTracer::build(&base.mesh, BvhSettings::default());
        let mut posed = base.clone();
        posed.set_frame_from(&base, 10.0);
        // The mover now sits at x = 3 (scaled 1.5): a ray down onto it hits its top.
        let ray = Ray::new(Vec3::new(3.0, 5.0, 0.0), Vec3::NEG_Y);
        assert!(stale.closest_hit(&ray).is_some_and(|h| (h.t - 5.0).abs() < 1e-4), "rest pose: the floor");
        let framed = stale.at_frame(&posed, 10.0).expect("rebuilt");
        let h = framed.closest_hit(&ray).expect("hit");
        assert!((h.t - (5.0 - 1.75)).abs() < 1e-4, "{}", h.t);
    }

    #[test]
    fn directions_with_negative_zeros_hit() {
        let mut mesh = Mesh::default();
        crate::shapes::add_box(&mut mesh, Vec3::ZERO, Vec3::ONE, 0);
        let bvh = BvhTracer::build(&mesh, BvhSettings::default());
        for a in [Vec3::X, Vec3::Y, Vec3::Z, Vec3::NEG_X, Vec3::NEG_Y, Vec3::NEG_Z] {
            let origin = Vec3::splat(0.5) + a * 3.0 + Vec3::new(0.13, 0.21, 0.17) * (Vec3::ONE - a.abs());
            let hit = bvh.closest_hit(&Ray::new(origin, -a)).expect("the box");
            assert!((hit.t - 2.5).abs() < 1e-5, "{a}: t {}", hit.t);
            assert!(bvh.occluded(&Ray::segment(origin, -a, 3.0)));
        }
    }

    #[test]
    fn empty_mesh_misses_everything() {
        let bvh = BvhTracer::build(&Mesh::default(), BvhSettings::default());
        assert!(bvh.closest_hit(&Ray::new(Vec3::ZERO, Vec3::X)).is_none());
        assert!(!bvh.occluded(&Ray::new(Vec3::ZERO, Vec3::X)));
    }
}
