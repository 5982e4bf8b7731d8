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

use std::sync::Arc;
use std::time::{Duration, Instant};

use glam::{Affine3A, Vec2, Vec3, Vec3A};
use obvhs::{
    BvhBuildParams,
    aabb::Aabb,
    cwbvh::{CwBvh, builder::build_cwbvh},
    ray::Ray as ObRay,
    rt_triangle::RtTriangle,
};

use crate::bvh_walk::{self, TraceGuardCounts, TraceGuards};
use crate::mesh::Mesh;
use crate::scene::Scene;
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

/// A material's coverage for alpha testing (the rule in `material.rs`), copied
/// out of its texture so that the tracer needs no scene: `factor` × the
/// bilinear coverage ≥ `cutoff`.
#[derive(Clone, Debug)]
struct CoverageMask {
    width: u32,
    height: u32,
    /// One unorm byte per texel; empty for a constant coverage of 1.
    coverage: Vec<u8>,
    factor: f32,
    cutoff: f32,
}

impl CoverageMask {
    fn opaque_at(&self, uv: Vec2) -> bool {
        let c = if self.coverage.is_empty() {
            1.0
        } else {
            crate::texture::Footprint::at(self.width, self.height, uv)
                .blend(|i| self.coverage[i] as f32 * (1.0 / 255.0))
        };
        self.factor * c >= self.cutoff
    }
}

/// The cut-out materials of a scene: one mask per cut-out material, looked up
/// through each mesh's own per-triangle material ids (the scene's mesh and the
/// prototypes alike).
#[derive(Clone, Debug, Default)]
struct Cutouts {
    masks: Vec<CoverageMask>,
    /// Per material: index into `masks`, or `u32::MAX` for opaque. Empty: all opaque.
    material_mask: Vec<u32>,
}

impl Cutouts {
    fn of_scene(scene: &Scene) -> Self {
        let mut masks = vec![];
        let material_mask: Vec<u32> = scene
            .materials
            .iter()
            .map(|m| {
                let crate::material::AlphaMode::Mask { cutoff } = m.alpha_mode else { return u32::MAX };
                if !m.has_cutout() {
                    return u32::MAX;
                }
                let tex = m.alpha_texture.and_then(|t| scene.textures.get(t));
                masks.push(CoverageMask {
                    width: tex.map_or(1, |t| t.width),
                    height: tex.map_or(1, |t| t.height),
                    coverage: tex.map(|t| t.coverage_plane()).unwrap_or_default(),
                    factor: m.alpha_factor,
                    cutoff,
                });
                (masks.len() - 1) as u32
            })
            .collect();
        if masks.is_empty() { Self::default() } else { Self { masks, material_mask } }
    }

    /// The mask of `mesh`'s triangle `triangle`, or `u32::MAX` when it is opaque.
    fn mask_of(&self, mesh: &Mesh, triangle: u32) -> u32 {
        let material = mesh.triangle_materials.get(triangle as usize);
        material.and_then(|&m| self.material_mask.get(m as usize)).copied().unwrap_or(u32::MAX)
    }
}

/// A cut-out triangle's mask and corner UVs, in a BLAS.
#[derive(Clone, Copy, Debug)]
struct CutTriangle {
    mask: u32,
    uv: [Vec2; 3],
}

/// A BVH over some of the mesh's triangles, in one space (world for the static
/// part, rest space for a moving object).
struct Blas {
    bvh: CwBvh,
    /// Triangles in BVH leaf order: the traversal's primitive id indexes this directly.
    triangles: Vec<RtTriangle>,
    /// Leaf order → `Mesh::triangles` index.
    triangle_ids: Vec<u32>,
    /// Bounds of the triangles, `None` when empty.
    bounds: Option<(Vec3, Vec3)>,
    /// Leaf order → index into `cut`, or `u32::MAX`; empty when nothing is cut out.
    leaf_cut: Vec<u32>,
    cut: Vec<CutTriangle>,
}

impl Blas {
    fn build(mesh: &Mesh, ids: &[u32], pad_m: f32, cutouts: &Cutouts) -> Self {
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
    fn closest(&self, masks: &[CoverageMask], guards: &TraceGuards, r: ObRay) -> Option<(u32, f32)> {
        if self.triangles.is_empty() {
            return None;
        }
        bvh_walk::closest(&self.bvh, guards, r, |r, id| self.intersect(masks, r, id))
    }

    fn occluded(&self, masks: &[CoverageMask], guards: &TraceGuards, r: ObRay) -> bool {
        !self.triangles.is_empty() && bvh_walk::any(&self.bvh, guards, r, |r, id| self.intersect(masks, r, id))
    }

    /// The public hit record of leaf `leaf` hit by `r` (in this BLAS's space) at `t`.
    fn hit(&self, leaf: u32, r: &ObRay, t: f32) -> RayHit {
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

/// A cut-out material's coverage, as [`BvhExport`] carries it: `factor` × the
/// bilinear coverage (wrap addressing, texel centres at half-integers) ≥ `cutoff`.
#[derive(Clone, Debug)]
pub struct BvhCutoutMask {
    pub width: u32,
    pub height: u32,
    /// One unorm byte per texel, row-major; empty for a constant coverage of 1.
    pub coverage: Vec<u8>,
    pub factor: f32,
    pub cutoff: f32,
}

/// A cut-out triangle of [`BvhExport`]: its mask and corner UVs.
#[derive(Clone, Copy, Debug)]
pub struct BvhCutTriangle {
    pub mask: u32,
    pub uv: [Vec2; 3],
}

/// A tracer's BVHs in the flat form a GPU traversal reads (`probegi-wgpu`'s
/// `bvh.wgsl`): obvhs's compressed-wide BVH nodes (Ylitie et al. 2017) of every
/// bottom level one after another, their triangles in leaf order, their alpha
/// cutouts, and the top level when there is one. The same trees the CPU
/// traverses, so both backends visit the same nodes in the same order.
#[derive(Clone, Debug, Default)]
pub struct BvhExport {
    /// 20 little-endian words per node: obvhs `CwBvhNode` (`repr(C)`, 80 bytes):
    /// `p.xyz`, `e[0..3] | imask << 24`, `child_base_idx`, `primitive_base_idx`,
    /// `child_meta[8]`, then `child_min_x[8]`, `child_max_x[8]`, `child_min_y[8]`,
    /// `child_max_y[8]`, `child_min_z[8]`, `child_max_z[8]`. A bottom level's
    /// `child_base_idx` and `primitive_base_idx` are rebased to index this
    /// export's nodes and leaves.
    pub node_words: Vec<u32>,
    /// Per bottom level, its root node (`u32::MAX` for one without triangles);
    /// the static part (`blases[0]`) first.
    pub blas_root_nodes: Vec<u32>,
    /// Per leaf, obvhs `RtTriangle`: `v0`, `e1 = v0 − v1`, `e2 = v2 − v0`, `ng = e1 × e2`.
    pub leaf_triangles: Vec<[Vec3; 4]>,
    /// Leaf order → `Scene::mesh.triangles` index (or the prototype mesh's).
    pub leaf_triangle_ids: Vec<u32>,
    /// Per leaf: index into `cut_triangles`, or `u32::MAX`; empty when nothing is cut out.
    pub leaf_cutouts: Vec<u32>,
    pub cut_triangles: Vec<BvhCutTriangle>,
    pub cutout_masks: Vec<BvhCutoutMask>,
    /// The top level in the rest pose: moving objects at rest, the still
    /// instances; `None` when rays go straight to `blases[0]`.
    pub tlas: Option<TlasExport>,
}

impl BvhCutoutMask {
    fn of(m: &CoverageMask) -> Self {
        Self { width: m.width, height: m.height, coverage: m.coverage.clone(), factor: m.factor, cutoff: m.cutoff }
    }
}

/// obvhs `CwBvhNode`s as `BvhExport::node_words`, child and primitive indices
/// moved by `node_base` and `leaf_base`.
fn node_words_rebased(bvh: &CwBvh, node_base: u32, leaf_base: u32) -> Vec<u32> {
    let mut node_words = Vec::with_capacity(bvh.nodes.len() * 20);
    let le = |b: &[u8]| u32::from_le_bytes([b[0], b[1], b[2], b[3]]);
    for n in &bvh.nodes {
        node_words.extend([n.p.x.to_bits(), n.p.y.to_bits(), n.p.z.to_bits()]);
        node_words.push(le(&[n.e[0], n.e[1], n.e[2], n.imask]));
        node_words.extend([n.child_base_idx.wrapping_add(node_base), n.primitive_base_idx.wrapping_add(leaf_base)]);
        for bytes in [
            &n.child_meta,
            &n.child_min_x,
            &n.child_max_x,
            &n.child_min_y,
            &n.child_max_y,
            &n.child_min_z,
            &n.child_max_z,
        ] {
            node_words.extend([le(&bytes[0..4]), le(&bytes[4..8])]);
        }
    }
    node_words
}

fn node_words(bvh: &CwBvh) -> Vec<u32> {
    node_words_rebased(bvh, 0, 0)
}

impl BvhExport {
    /// Appends one bottom level, its indices rebased past what is already here.
    fn append_blas(&mut self, blas: &Blas) {
        if blas.triangles.is_empty() {
            self.blas_root_nodes.push(u32::MAX);
            return;
        }
        let (node_base, leaf_base) = (self.node_count() as u32, self.leaf_triangles.len() as u32);
        let cut_base = self.cut_triangles.len() as u32;
        self.blas_root_nodes.push(node_base);
        self.node_words.extend(node_words_rebased(&blas.bvh, node_base, leaf_base));
        self.leaf_triangles.extend(blas.triangles.iter().map(|t| [t.v0.into(), t.e1.into(), t.e2.into(), t.ng.into()]));
        self.leaf_triangle_ids.extend(&blas.triangle_ids);
        let had_cutouts = !self.leaf_cutouts.is_empty();
        if !blas.leaf_cut.is_empty() || had_cutouts {
            // Pad the leaves before this level, then this level's (rebased).
            self.leaf_cutouts.resize(leaf_base as usize, u32::MAX);
            if blas.leaf_cut.is_empty() {
                self.leaf_cutouts.resize(self.leaf_triangles.len(), u32::MAX);
            } else {
                self.leaf_cutouts.extend(blas.leaf_cut.iter().map(|&c| if c == u32::MAX { c } else { c + cut_base }));
            }
        }
        self.cut_triangles.extend(blas.cut.iter().map(|c| BvhCutTriangle { mask: c.mask, uv: c.uv }));
    }

    pub fn node_count(&self) -> usize {
        self.node_words.len() / 20
    }
}

/// One BLAS placed in the world for a frame.
struct Instance {
    /// Index into `BvhTracer::blases`.
    blas: usize,
    /// `None` for the identity (the static part).
    local_from_world: Option<Affine3A>,
    /// Index into `Scene::instances`, `u32::MAX` for the scene's own mesh.
    scene_instance: u32,
}

impl Instance {
    /// `r` in this instance's space; `None` where the move overflows (a miss
    /// of this instance).
    fn to_local(&self, r: &ObRay) -> Option<ObRay> {
        match &self.local_from_world {
            None => Some(*r),
            Some(m) => bvh_walk::moved_ray(r, m),
        }
    }
}

/// The top-level structure of one frame: a BVH over instance bounds.
struct Tlas {
    bvh: CwBvh,
    instances: Vec<Instance>,
}

/// What a tracer's top level is built from: the bounds of its bottom levels,
/// its moving objects and its still instances. A device that traces the two
/// levels itself (`probegi-wgpu`) keeps this and places the instances for each
/// frame with [`TlasLayout::export_at`], as [`RayTracer::at_frame`] does.
#[derive(Clone, Debug)]
pub struct TlasLayout {
    /// Bounds of `BvhTracer::blases[k]` (`None`: no triangles).
    blas_bounds: Vec<Option<(Vec3, Vec3)>>,
    /// Scene object index of `blases[k + 1]`.
    object_ids: Vec<usize>,
    /// Still instances: BLAS index, world from local, `Scene::instances` index.
    placed: Vec<(usize, Affine3A, u32)>,
    pad_rel: f32,
}

/// One placed bottom level of [`TlasExport`].
#[derive(Clone, Copy, Debug)]
pub struct TlasInstance {
    /// Index of the bottom level (`BvhExport::blas_root_nodes`).
    pub blas: u32,
    /// `None` for the identity (the static part).
    pub local_from_world: Option<Affine3A>,
    /// Index into `Scene::instances`, `u32::MAX` for the scene's own mesh.
    pub scene_instance: u32,
    /// A moving object (left out of initialisation rounds, which see static geometry).
    pub moving: bool,
}

/// A top level in the flat form a GPU traversal reads: obvhs CWBVH nodes (the
/// layout of `BvhExport::node_words`) over instance bounds, whose primitives are
/// `instances` in leaf order.
#[derive(Clone, Debug, Default)]
pub struct TlasExport {
    pub node_words: Vec<u32>,
    pub instances: Vec<TlasInstance>,
}

impl TlasExport {
    pub fn node_count(&self) -> usize {
        self.node_words.len() / 20
    }
}

impl TlasLayout {
    /// Whether `posed` has the moving objects this layout instances.
    fn follows(&self, posed: &Scene) -> bool {
        self.object_ids.len() == posed.objects.iter().filter(|o| o.is_animated()).count()
            && self.object_ids.iter().all(|&i| posed.objects.get(i).is_some_and(|o| o.is_animated()))
    }

    /// The moving objects' transforms at `frame`.
    fn poses(&self, posed: &Scene, frame: f32) -> Vec<Option<Affine3A>> {
        self.object_ids.iter().map(|&i| Some(posed.objects[i].world_from_rest(frame))).collect()
    }

    /// The top level with the moving objects of `posed` placed at `frame` (the
    /// one [`RayTracer::at_frame`] traces); an error when `posed` is not the
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

    fn export(&self, tlas: &Tlas) -> TlasExport {
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
    fn build(&self, moving: Option<&[Option<Affine3A>]>) -> Tlas {
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

fn pad_m(bounds: Option<(Vec3, Vec3)>, settings: BvhSettings) -> f32 {
    let extent = bounds.map(|(lo, hi)| (hi - lo).max_element()).unwrap_or(1.0);
    extent * settings.bvh_aabb_pad_rel.max(0.0)
}

/// Bounds of the box `[lo, hi]` after an affine transform (its 8 corners).
pub(crate) fn transformed_bounds(m: &Affine3A, lo: Vec3, hi: Vec3) -> (Vec3, Vec3) {
    let mut out = (Vec3::splat(f32::INFINITY), Vec3::splat(f32::NEG_INFINITY));
    for c in 0..8 {
        let p = Vec3::new(
            if c & 1 == 0 { lo.x } else { hi.x },
            if c & 2 == 0 { lo.y } else { hi.y },
            if c & 4 == 0 { lo.z } else { hi.z },
        );
        let q = m.transform_point3(p);
        out = (out.0.min(q), out.1.max(q));
    }
    out
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
        use crate::builtin::{add_box, add_polygon};
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
        crate::builtin::add_box(&mut mesh, Vec3::ZERO, Vec3::ONE, 0);
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
