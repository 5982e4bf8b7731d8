//! Octahedral mapping of the unit sphere to the square `[-1, 1]²` (Cigolle et al.
//! 2014, "A Survey of Efficient Representations for Independent Unit Vectors"),
//! as DDGI stores probe texels (seed 003 §4.1, seed 004 Table 2). The +z
//! hemisphere fills the inner diamond; −z folds into the corners. Signs use
//! "sign not zero" (RTXGI `DDGIGetOctahedralCoordinates`).

use glam::{Vec2, Vec3};

fn sign_not_zero(v: Vec2) -> Vec2 {
    Vec2::new(if v.x >= 0.0 { 1.0 } else { -1.0 }, if v.y >= 0.0 { 1.0 } else { -1.0 })
}

/// Unit direction → octahedral coordinates in `[-1, 1]²`.
pub fn oct_encode(dir: Vec3) -> Vec2 {
    let l1 = dir.x.abs() + dir.y.abs() + dir.z.abs();
    if l1.is_nan() || l1 <= 0.0 {
        return Vec2::ZERO;
    }
    let uv = Vec2::new(dir.x, dir.y) / l1;
    if dir.z < 0.0 { (Vec2::ONE - Vec2::new(uv.y.abs(), uv.x.abs())) * sign_not_zero(uv) } else { uv }
}

/// Octahedral coordinates in `[-1, 1]²` → unit direction.
pub fn oct_decode(uv: Vec2) -> Vec3 {
    let mut d = Vec3::new(uv.x, uv.y, 1.0 - uv.x.abs() - uv.y.abs());
    if d.z < 0.0 {
        let xy = (Vec2::ONE - Vec2::new(d.y.abs(), d.x.abs())) * sign_not_zero(Vec2::new(d.x, d.y));
        d.x = xy.x;
        d.y = xy.y;
    }
    d.normalize()
}

/// Octahedral coordinates of the centre of interior texel `(i, j)` of an `n × n` map.
pub fn texel_center_uv(i: u32, j: u32, n: u32) -> Vec2 {
    Vec2::new((i as f32 + 0.5) / n as f32, (j as f32 + 0.5) / n as f32) * 2.0 - Vec2::ONE
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::sampling::sample_uniform_sphere;

    #[test]
    fn round_trip_is_accurate_over_the_sphere() {
        let n = 64;
        let mut worst = 0.0f32;
        for i in 0..n * n {
            let u = Vec2::new(((i % n) as f32 + 0.5) / n as f32, ((i / n) as f32 + 0.5) / n as f32);
            let d = sample_uniform_sphere(u);
            let uv = oct_encode(d);
            assert!(uv.abs().max_element() <= 1.0 + 1e-6);
            worst = worst.max((oct_decode(uv) - d).length());
        }
        assert!(worst < 1e-5, "worst round-trip error {worst}");
        for d in [Vec3::X, Vec3::NEG_X, Vec3::Y, Vec3::NEG_Y, Vec3::Z, Vec3::NEG_Z] {
            assert!((oct_decode(oct_encode(d)) - d).length() < 1e-6, "{d}");
        }
    }

    #[test]
    fn square_corners_are_the_negative_pole_and_edges_mirror() {
        for c in [Vec2::new(1.0, 1.0), Vec2::new(-1.0, 1.0), Vec2::new(1.0, -1.0), Vec2::new(-1.0, -1.0)] {
            assert!((oct_decode(c) - Vec3::NEG_Z).length() < 1e-6);
        }
        // Points mirrored across the edge v = -1 decode to the same direction.
        let a = oct_decode(Vec2::new(0.3, -1.0));
        let b = oct_decode(Vec2::new(-0.3, -1.0));
        assert!((a - b).length() < 1e-6);
    }
}
