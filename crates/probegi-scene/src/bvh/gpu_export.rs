//! GPU export: a tracer's BVHs in the flat form `probegi-wgpu`'s `bvh.wgsl`
//! reads, bottom levels one after another with rebased indices, their cutouts,
//! and the top level.

use glam::{Affine3A, Vec2, Vec3};
use obvhs::cwbvh::CwBvh;

use super::blas::Blas;
use super::cutouts::CoverageMask;

/// A cut-out material's coverage, as [`BvhExport`] carries it: `factor` × the
/// bilinear coverage (wrap addressing, texel centres at half-integers) ≥ `cutoff`.
#[derive(Clone, Debug)]
pub struct BvhCutoutMask {
    /// Coverage texture width in texels (1 for a constant coverage).
    pub width: u32,
    /// Coverage texture height in texels (1 for a constant coverage).
    pub height: u32,
    /// One unorm byte per texel, row-major; empty for a constant coverage of 1.
    pub coverage: Vec<u8>,
    /// The material's alpha factor, multiplied into the coverage.
    pub factor: f32,
    /// The alpha-mask cutoff: a hit counts where factor × coverage ≥ this.
    pub cutoff: f32,
}

/// A cut-out triangle of [`BvhExport`]: its mask and corner UVs.
#[derive(Clone, Copy, Debug)]
pub struct BvhCutTriangle {
    /// Index into `BvhExport::cutout_masks`.
    pub mask: u32,
    /// The triangle's corner UVs, vertices 0, 1, 2.
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
    /// The cut-out triangles, indexed by `leaf_cutouts`.
    pub cut_triangles: Vec<BvhCutTriangle>,
    /// One coverage mask per cut-out material, indexed by `BvhCutTriangle::mask`.
    pub cutout_masks: Vec<BvhCutoutMask>,
    /// The top level in the rest pose: moving objects at rest, the still
    /// instances; `None` when rays go straight to `blases[0]`.
    pub tlas: Option<TlasExport>,
}

impl BvhCutoutMask {
    pub(super) fn of(m: &CoverageMask) -> Self {
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

pub(super) fn node_words(bvh: &CwBvh) -> Vec<u32> {
    node_words_rebased(bvh, 0, 0)
}

impl BvhExport {
    /// Appends one bottom level, its indices rebased past what is already here.
    pub(super) fn append_blas(&mut self, blas: &Blas) {
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

    /// Nodes in `node_words` (20 words each), every bottom level together.
    pub fn node_count(&self) -> usize {
        self.node_words.len() / 20
    }
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
    /// The top-level nodes, 20 words each, laid out as `BvhExport::node_words`.
    pub node_words: Vec<u32>,
    /// The placed bottom levels, in leaf order: the top level's primitive id indexes this.
    pub instances: Vec<TlasInstance>,
}

impl TlasExport {
    /// Nodes in `node_words` (20 words each).
    pub fn node_count(&self) -> usize {
        self.node_words.len() / 20
    }
}
