//! Alpha cutouts for traversal: each cut-out material's coverage copied out of
//! its texture (the rule in `material.rs`), looked up per triangle, so that the
//! intersection closure of a BLAS can reject a hit below the cutoff.

use glam::Vec2;

use crate::mesh::Mesh;
use crate::scene::Scene;

/// A material's coverage for alpha testing (the rule in `material.rs`), copied
/// out of its texture so that the tracer needs no scene: `factor` × the
/// bilinear coverage ≥ `cutoff`.
#[derive(Clone, Debug)]
pub(super) struct CoverageMask {
    pub(super) width: u32,
    pub(super) height: u32,
    /// One unorm byte per texel; empty for a constant coverage of 1.
    pub(super) coverage: Vec<u8>,
    pub(super) factor: f32,
    pub(super) cutoff: f32,
}

impl CoverageMask {
    pub(super) fn opaque_at(&self, uv: Vec2) -> bool {
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
pub(super) struct Cutouts {
    pub(super) masks: Vec<CoverageMask>,
    /// Per material: index into `masks`, or `u32::MAX` for opaque. Empty: all opaque.
    material_mask: Vec<u32>,
}

impl Cutouts {
    pub(super) fn of_scene(scene: &Scene) -> Self {
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
    pub(super) fn mask_of(&self, mesh: &Mesh, triangle: u32) -> u32 {
        let material = mesh.triangle_materials.get(triangle as usize);
        material.and_then(|&m| self.material_mask.get(m as usize)).copied().unwrap_or(u32::MAX)
    }
}

/// A cut-out triangle's mask and corner UVs, in a BLAS.
#[derive(Clone, Copy, Debug)]
pub(super) struct CutTriangle {
    pub(super) mask: u32,
    pub(super) uv: [Vec2; 3],
}
