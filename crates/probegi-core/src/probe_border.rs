//! Border pass: refresh every tile's 1-texel guard border from its interior
//! (seed 003 §4.5 and Fig. 4.9, after Engelhardt & Dachsbacher 2008; RTXGI
//! `ProbeBorderUpdate`). Across each edge of the octahedral square the sphere
//! continues mirrored, so:
//! - top row `(x, 0)` ← `(n + 1 − x, 1)`, bottom row `(x, n + 1)` ← `(n + 1 − x, n)`;
//! - left column `(0, y)` ← `(1, n + 1 − y)`, right column `(n + 1, y)` ← `(n, n + 1 − y)`;
//! - corners take the diagonally opposite interior corner: `(0,0)` ← `(n,n)`,
//!   `(n+1,0)` ← `(1,n)`, `(0,n+1)` ← `(n,1)`, `(n+1,n+1)` ← `(1,1)`.
//!
//! (`n` interior texels, tile coordinates with the border at 0 and n + 1.)

use crate::probe_atlas::{Texel, tile_texel_index};

/// The interior tile texel each border texel copies, as `((dst_x, dst_y), (src_x, src_y))`.
pub fn border_sources(interior: u32) -> Vec<((u32, u32), (u32, u32))> {
    let n = interior;
    let mut v = Vec::with_capacity(4 * n as usize + 4);
    for x in 1..=n {
        v.push(((x, 0), (n + 1 - x, 1)));
        v.push(((x, n + 1), (n + 1 - x, n)));
    }
    for y in 1..=n {
        v.push(((0, y), (1, n + 1 - y)));
        v.push(((n + 1, y), (n, n + 1 - y)));
    }
    v.push(((0, 0), (n, n)));
    v.push(((n + 1, 0), (1, n)));
    v.push(((0, n + 1), (n, 1)));
    v.push(((n + 1, n + 1), (1, 1)));
    v
}

/// Copies the guard border of one tile from its interior.
pub fn update_tile_border<T: Texel>(tile: &mut [T], interior: u32) {
    let n = interior;
    let idx = |x: u32, y: u32| tile_texel_index(n, x, y);
    for x in 1..=n {
        tile[idx(x, 0)] = tile[idx(n + 1 - x, 1)];
        tile[idx(x, n + 1)] = tile[idx(n + 1 - x, n)];
    }
    for y in 1..=n {
        tile[idx(0, y)] = tile[idx(1, n + 1 - y)];
        tile[idx(n + 1, y)] = tile[idx(n, n + 1 - y)];
    }
    tile[idx(0, 0)] = tile[idx(n, n)];
    tile[idx(n + 1, 0)] = tile[idx(1, n)];
    tile[idx(0, n + 1)] = tile[idx(n, 1)];
    tile[idx(n + 1, n + 1)] = tile[idx(1, 1)];
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::octahedral::{oct_decode, oct_encode, texel_center_uv};
    use crate::probe_atlas::sample_tile_bilinear;
    use glam::{Vec2, Vec3};

    #[test]
    fn borders_equal_their_source_texels() {
        for n in [1u32, 6, 14] {
            let s = (n + 2) as usize;
            let mut tile: Vec<f32> = (0..s * s).map(|k| k as f32 * 1.5).collect();
            update_tile_border(&mut tile, n);
            for ((dx, dy), (sx, sy)) in border_sources(n) {
                assert!((1..=n).contains(&sx) && (1..=n).contains(&sy), "sources are interior");
                assert_eq!(tile[dy as usize * s + dx as usize], tile[sy as usize * s + sx as usize]);
            }
            assert_eq!(border_sources(n).len(), 4 * n as usize + 4, "every border texel is written");
        }
    }

    #[test]
    fn bilinear_lookups_are_continuous_across_the_octahedral_seams() {
        // Store a smooth function of direction, refresh borders, then sample just
        // inside each edge at mirrored points: both sides are the same direction.
        let n = 14;
        let s = (n + 2) as usize;
        let f = |d: Vec3| Vec3::new(d.x * 0.5 + 0.5, d.y * 0.5 + 0.5, d.z * 0.5 + 0.5);
        let mut tile = vec![Vec3::ZERO; s * s];
        for j in 0..n {
            for i in 0..n {
                tile[(j + 1) as usize * s + (i + 1) as usize] = f(oct_decode(texel_center_uv(i, j, n)));
            }
        }
        update_tile_border(&mut tile, n);
        let eps = 1e-4;
        for k in 0..20 {
            let t = -0.95 + 0.1 * k as f32;
            for (a, b) in [
                (Vec2::new(t, -1.0 + eps), Vec2::new(-t, -1.0 + eps)),
                (Vec2::new(t, 1.0 - eps), Vec2::new(-t, 1.0 - eps)),
                (Vec2::new(-1.0 + eps, t), Vec2::new(-1.0 + eps, -t)),
                (Vec2::new(1.0 - eps, t), Vec2::new(1.0 - eps, -t)),
            ] {
                let (va, vb) = (sample_tile_bilinear(&tile, n, a), sample_tile_bilinear(&tile, n, b));
                assert!((va - vb).length() < 1e-3, "seam at {a} / {b}: {va} vs {vb}");
                // And close to the function itself (bilinear error of a smooth function).
                let d = oct_decode(a);
                assert!((va - f(d)).length() < 0.08, "{a}: {va} vs {}", f(d));
            }
        }
        // Interior lookups reproduce the function closely everywhere.
        for k in 0..200 {
            let d =
                crate::sampling::sample_uniform_sphere(Vec2::new((k as f32 + 0.5) / 200.0, (k as f32 * 0.618).fract()));
            let v = sample_tile_bilinear(&tile, n, oct_encode(d));
            assert!((v - f(d)).length() < 0.08);
        }
    }
}
