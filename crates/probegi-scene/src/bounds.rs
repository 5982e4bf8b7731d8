//! Axis-aligned bounds shared by the scene model and the BVH's top level.

use glam::{Affine3A, Vec3};

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
