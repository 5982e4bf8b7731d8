//! Probe atlases: one octahedral map per probe, each with a 1-texel guard border
//! (seed 003 Fig. 4.9 / seed 004 Fig. 9a, after Engelhardt & Dachsbacher 2008).
//!
//! Layout (the one place it is written down): **tile-major**. Probe `p`'s tile is
//! `tile × tile` texels with `tile = interior + 2`, stored contiguously at
//! `texels[p·tile² ..]`, row-major inside the tile, row 0 first. Interior texel
//! `(i, j)`, `0 ≤ i, j < interior`, is tile texel `(i + 1, j + 1)` and holds the
//! direction `oct_decode(texel_center_uv(i, j))`. One probe's texels are together,
//! so blending a probe touches one cache-friendly span (a GPU backend maps tiles to
//! a 2D atlas with [`ProbeAtlas::atlas_texel_position`]).
//!
//! Border rule (`probe_border`): the border texels repeat the interior mirrored
//! across each edge, so bilinear lookups near an edge blend with the texels that
//! are their neighbours on the sphere.

use glam::{UVec2, Vec2};

/// Texels per tile side for `interior` interior texels: the interior plus a
/// one-texel guard border on each side.
pub const fn tile_side(interior: u32) -> u32 {
    interior + 2
}

/// Texels in one tile, border included.
pub const fn tile_texel_count(interior: u32) -> usize {
    let s = tile_side(interior) as usize;
    s * s
}

/// Tile-local index of tile texel `(x, y)` (border coordinates: 0 and `interior + 1` are the border).
pub const fn tile_texel_index(interior: u32, x: u32, y: u32) -> usize {
    y as usize * tile_side(interior) as usize + x as usize
}

/// Tile-local index of interior texel `(i, j)`, `0 ≤ i, j < interior`.
pub const fn interior_texel_index(interior: u32, i: u32, j: u32) -> usize {
    tile_texel_index(interior, i + 1, j + 1)
}

/// Values a tile can hold and bilinearly filter.
pub trait Texel: Copy + Default + std::ops::Add<Output = Self> + std::ops::Mul<f32, Output = Self> {}
impl Texel for glam::Vec2 {}
impl Texel for glam::Vec3 {}
impl Texel for f32 {}

/// One octahedral tile per probe, `(interior + 2)²` texels each with the guard border,
/// stored tile-major (layout in the module docs).
#[derive(Clone, Debug, PartialEq)]
pub struct ProbeAtlas<T> {
    /// Number of tiles: one per probe, tile `p` for the probe in the grid's storage
    /// slot `p`.
    pub probe_count: usize,
    /// Interior texels per side.
    pub interior: u32,
    /// Every tile's texels: probe `p`'s tile is
    /// `texels[p · tile_len() .. (p + 1) · tile_len()]`, row-major, border included.
    pub texels: Vec<T>,
}

impl<T: Texel> ProbeAtlas<T> {
    /// An atlas of `probe_count` tiles with `interior × interior` interior texels each,
    /// every texel `T::default()` (zero).
    pub fn new(probe_count: usize, interior: u32) -> Self {
        Self { probe_count, interior, texels: vec![T::default(); probe_count * tile_texel_count(interior)] }
    }

    /// Texels per tile side, border included.
    pub fn tile_size(&self) -> u32 {
        tile_side(self.interior)
    }

    /// Texels in one tile, border included: `(interior + 2)²`.
    pub fn tile_len(&self) -> usize {
        tile_texel_count(self.interior)
    }

    /// Bytes one probe's tile occupies.
    pub fn tile_bytes(interior: u32) -> usize {
        tile_texel_count(interior) * std::mem::size_of::<T>()
    }

    /// The tile of the probe in storage slot `probe`, border included, row-major;
    /// panics past the last probe.
    pub fn tile(&self, probe: usize) -> &[T] {
        let n = self.tile_len();
        &self.texels[probe * n..(probe + 1) * n]
    }

    /// The tile of the probe in storage slot `probe`, for writing (border included,
    /// row-major); panics past the last probe.
    pub fn tile_mut(&mut self, probe: usize) -> &mut [T] {
        let n = self.tile_len();
        &mut self.texels[probe * n..(probe + 1) * n]
    }

    /// Bilinear lookup in probe `probe`'s map at octahedral coordinates `uv ∈ [-1,1]²`.
    /// Relies on the guard border being current.
    pub fn sample_bilinear(&self, probe: usize, uv: Vec2) -> T {
        sample_tile_bilinear(self.tile(probe), self.interior, uv)
    }

    /// Where tile texel `(x, y)` of `probe` lands in a 2D atlas image that places
    /// tiles in rows of `probes_per_row` (used for dumps and, later, GPU textures).
    pub fn atlas_texel_position(&self, probe: usize, x: u32, y: u32, probes_per_row: u32) -> UVec2 {
        let t = self.tile_size();
        let (px, py) = (probe as u32 % probes_per_row, probe as u32 / probes_per_row);
        UVec2::new(px * t + x, py * t + y)
    }
}

/// The four texels and weights of a bilinear lookup at octahedral coordinates `uv`
/// in a tile with `interior` texels per side. The same footprint serves every
/// probe's tile (the query reads 8 probes in one normal direction).
#[derive(Clone, Copy, Debug)]
pub struct BilinearFootprint {
    /// Tile-local indices of texels (x0,y0), (x0+1,y0), (x0,y0+1), (x0+1,y0+1).
    pub indices: [usize; 4],
    /// Bilinear weights of the texels in `indices`, in the same order: each in [0, 1],
    /// summing to 1.
    pub weights: [f32; 4],
}

impl BilinearFootprint {
    /// The footprint of a lookup at octahedral coordinates `uv` (clamped to [-1, 1]²)
    /// in a tile with `interior` texels per side.
    pub fn new(interior: u32, uv: Vec2) -> Self {
        let size = tile_side(interior);
        let n = interior as f32;
        // Continuous tile coordinates: interior texel i covers [i + 1, i + 2); centres at i + 1.5.
        let c = (uv.clamp(Vec2::splat(-1.0), Vec2::ONE) * 0.5 + Vec2::splat(0.5)) * n + Vec2::splat(0.5);
        // c ≥ 0.5, so truncation is floor.
        let x0 = (c.x as u32).min(size - 2);
        let y0 = (c.y as u32).min(size - 2);
        let fx = (c.x - x0 as f32).clamp(0.0, 1.0);
        let fy = (c.y - y0 as f32).clamp(0.0, 1.0);
        let s = size as usize;
        let i00 = tile_texel_index(interior, x0, y0);
        Self {
            indices: [i00, i00 + 1, i00 + s, i00 + s + 1],
            weights: [(1.0 - fx) * (1.0 - fy), fx * (1.0 - fy), (1.0 - fx) * fy, fx * fy],
        }
    }

    /// The filtered value of `tile` (one probe's tile, of the interior this footprint
    /// was built for): Σ weight · texel.
    pub fn sample<T: Texel>(&self, tile: &[T]) -> T {
        tile[self.indices[0]] * self.weights[0]
            + tile[self.indices[1]] * self.weights[1]
            + tile[self.indices[2]] * self.weights[2]
            + tile[self.indices[3]] * self.weights[3]
    }
}

/// Bilinear lookup in one tile (`interior + 2` texels per side) at `uv ∈ [-1,1]²`.
pub fn sample_tile_bilinear<T: Texel>(tile: &[T], interior: u32, uv: Vec2) -> T {
    BilinearFootprint::new(interior, uv).sample(tile)
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::octahedral::texel_center_uv;

    #[test]
    fn texel_centres_sample_exactly_their_texel() {
        let mut a = ProbeAtlas::<f32>::new(2, 6);
        for (k, t) in a.texels.iter_mut().enumerate() {
            *t = k as f32;
        }
        for j in 0..6 {
            for i in 0..6 {
                let want = a.tile(1)[interior_texel_index(6, i, j)];
                assert_eq!(interior_texel_index(6, i, j), ((j + 1) * 8 + i + 1) as usize);
                assert_eq!(a.sample_bilinear(1, texel_center_uv(i, j, 6)), want);
            }
        }
    }

    #[test]
    fn atlas_positions_place_tiles_in_rows() {
        let a = ProbeAtlas::<f32>::new(6, 6);
        assert_eq!(a.atlas_texel_position(0, 0, 0, 4), UVec2::new(0, 0));
        assert_eq!(a.atlas_texel_position(5, 2, 3, 4), UVec2::new(10, 11));
    }
}
