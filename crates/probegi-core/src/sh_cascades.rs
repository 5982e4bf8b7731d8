//! Probe placement of seed 001 §6.2–6.3: nested grids ("cascades") of SH probes
//! centred on the camera at quantized positions, and the interpolation of the
//! nearby probes at shading time (§3.2).
//!
//! Cascade k has spacing `s₀ · ratioᵏ` and the same probe counts. Its probes sit
//! on the world lattice `i · s` (i integer), and the grid is the block of
//! `counts` lattice points whose centre is the lattice point nearest the camera,
//! so the grid moves in whole cells.
//!
//! **When a cascade shifts** (seed 001 copies nothing): storage is toroidal,
//! slot = lattice index mod counts (as Halen et al.'s surfel cascades), so a probe
//! whose lattice point stays inside the grid keeps its coefficients without any
//! copy. A slot whose lattice point left is reused by a point that entered; its
//! coefficients are reset to the next coarser cascade's interpolated SH at the
//! new position (zero in the coarsest), so entering probes start from the
//! best estimate available instead of from black or from the stale light of
//! the far side of the grid. Tested below.
//!
//! Shading reads the finest cascade whose probe block contains the point, with
//! trilinear weights on the SH coefficients (seed 001 §3.2), and blends linearly
//! into the next coarser cascade over the outermost cell so the cascade boundary
//! does not show.

use glam::{IVec3, UVec3, Vec3};

use crate::sh::ShRgb9;

/// One cascade: a camera-centred grid of SH probes with toroidal storage.
#[derive(Clone, Debug)]
pub struct ShCascade {
    /// Distance between neighbouring probes on every axis, metres (`s₀ · ratioᵏ` for
    /// cascade k).
    pub spacing_m: f32,
    /// Probes per axis of the grid, and storage slots per axis of its torus.
    pub counts: UVec3,
    /// Lattice index of the grid's minimum-corner probe.
    pub origin_lattice: IVec3,
    /// Lattice index each storage slot holds (`IVec3::MIN` before the first centring).
    pub slot_lattice: Vec<IVec3>,
    /// Radiance SH per slot.
    pub coeffs: Vec<ShRgb9>,
}

impl ShCascade {
    /// An unplaced cascade of `counts` probes `spacing_m` apart with zero SH; it
    /// contains no point until [`ShCascades::recentre`] places it.
    pub fn new(spacing_m: f32, counts: UVec3) -> Self {
        let n = counts.x as usize * counts.y as usize * counts.z as usize;
        Self {
            spacing_m,
            counts,
            origin_lattice: IVec3::MIN,
            slot_lattice: vec![IVec3::MIN; n],
            coeffs: vec![ShRgb9::default(); n],
        }
    }

    /// Storage slot of a lattice point (toroidal addressing).
    pub fn slot(&self, lattice: IVec3) -> usize {
        let c = self.counts.as_ivec3();
        let m = lattice.rem_euclid(c);
        (m.x + c.x * (m.y + c.y * m.z)) as usize
    }

    /// World position of a lattice point.
    pub fn lattice_position(&self, lattice: IVec3) -> Vec3 {
        lattice.as_vec3() * self.spacing_m
    }

    /// The minimum-corner lattice index of the grid centred on `camera_m`.
    pub fn centred_origin(&self, camera_m: Vec3) -> IVec3 {
        (camera_m / self.spacing_m).round().as_ivec3() - (self.counts / 2).as_ivec3()
    }

    /// Continuous grid coordinates of a point (0 at the origin probe).
    fn grid_coords(&self, position_m: Vec3) -> Vec3 {
        position_m / self.spacing_m - self.origin_lattice.as_vec3()
    }

    /// Whether the probe block (its convex hull) contains the point.
    pub fn contains(&self, position_m: Vec3) -> bool {
        if self.origin_lattice == IVec3::MIN {
            return false;
        }
        let g = self.grid_coords(position_m);
        let hi = (self.counts - UVec3::ONE).as_vec3();
        g.cmpge(Vec3::ZERO).all() && g.cmple(hi).all()
    }

    /// Trilinear interpolation of the 8 surrounding probes' SH (seed 001 §3.2),
    /// or `None` outside the probe block.
    pub fn interpolate(&self, position_m: Vec3) -> Option<ShRgb9> {
        if !self.contains(position_m) {
            return None;
        }
        let g = self.grid_coords(position_m);
        let base = g.floor().as_ivec3().min((self.counts - UVec3::new(2, 2, 2)).as_ivec3());
        let f = g - base.as_vec3();
        let mut out = ShRgb9::default();
        for corner in 0..8 {
            let o = IVec3::new(corner & 1, (corner >> 1) & 1, (corner >> 2) & 1);
            let t = Vec3::select(o.cmpeq(IVec3::ONE), f, Vec3::ONE - f);
            let w = t.x * t.y * t.z;
            if w == 0.0 {
                continue;
            }
            let c = &self.coeffs[self.slot(self.origin_lattice + base + o)];
            for (a, b) in out.c.iter_mut().zip(c.c) {
                *a += b * w;
            }
        }
        Some(out)
    }

    /// 1 deep inside the block, falling to 0 at its boundary over the outermost cell.
    fn interior_weight(&self, position_m: Vec3) -> f32 {
        let g = self.grid_coords(position_m);
        let hi = (self.counts - UVec3::ONE).as_vec3();
        g.min(hi - g).min_element().clamp(0.0, 1.0)
    }
}

/// Camera-centred nested cascades.
#[derive(Clone, Debug)]
pub struct ShCascades {
    /// Finest first.
    pub cascades: Vec<ShCascade>,
    /// Each cascade's centre moves this fraction of its half-extent (smallest
    /// axis) along the view direction; 0 centres it on the camera (the paper).
    pub view_offset_rel: f32,
}

impl ShCascades {
    /// `count` nested cascades (at least one) of `counts` probes each, cascade k spaced
    /// `spacing_m · spacing_ratioᵏ` metres; unplaced until [`Self::recentre`].
    pub fn new(count: u32, counts: UVec3, spacing_m: f32, spacing_ratio: f32) -> Self {
        let cascades =
            (0..count.max(1)).map(|k| ShCascade::new(spacing_m * spacing_ratio.powi(k as i32), counts)).collect();
        Self { cascades, view_offset_rel: 0.0 }
    }

    /// The finest spacing for which the coarsest cascade, centred on `camera_m`,
    /// contains every point of the box `lo..hi` with a cell to spare.
    pub fn spacing_to_cover(camera_m: Vec3, lo: Vec3, hi: Vec3, count: u32, counts: UVec3, spacing_ratio: f32) -> f32 {
        let reach = (hi - camera_m).abs().max((camera_m - lo).abs());
        let half_cells = ((counts / 2).as_vec3() - Vec3::splat(1.5)).max(Vec3::splat(0.5));
        let coarsest = (reach / half_cells).max_element().max(1e-4);
        coarsest / spacing_ratio.powi(count.max(1) as i32 - 1)
    }

    /// Moves every cascade to the quantized position around the camera (pushed
    /// along `view_dir` by `view_offset_rel`); see the module doc for what happens
    /// to the data. Returns the probes reset.
    pub fn recentre(&mut self, camera_m: Vec3, view_dir: Vec3) -> usize {
        let mut reset = 0;
        for k in (0..self.cascades.len()).rev() {
            let (finer, coarser) = self.cascades.split_at_mut(k + 1);
            let cascade = &mut finer[k];
            let coarser = coarser.first();
            let half_extent = (cascade.counts / 2).min_element() as f32 * cascade.spacing_m;
            let centre = camera_m + view_dir * (self.view_offset_rel * half_extent);
            let origin = cascade.centred_origin(centre);
            if origin == cascade.origin_lattice {
                continue;
            }
            cascade.origin_lattice = origin;
            let c = cascade.counts.as_ivec3();
            for z in 0..c.z {
                for y in 0..c.y {
                    for x in 0..c.x {
                        let lattice = origin + IVec3::new(x, y, z);
                        let slot = cascade.slot(lattice);
                        if cascade.slot_lattice[slot] == lattice {
                            continue;
                        }
                        let p = cascade.lattice_position(lattice);
                        cascade.coeffs[slot] = coarser.and_then(|c| c.interpolate(p)).unwrap_or_default();
                        cascade.slot_lattice[slot] = lattice;
                        reset += 1;
                    }
                }
            }
        }
        reset
    }

    /// Interpolated radiance SH at a point: the finest cascade containing it,
    /// blended into the next coarser one over its outermost cell. Zero outside all.
    pub fn radiance_sh(&self, position_m: Vec3) -> ShRgb9 {
        for (k, cascade) in self.cascades.iter().enumerate() {
            let Some(fine) = cascade.interpolate(position_m) else { continue };
            let t = cascade.interior_weight(position_m);
            let coarse = if t < 1.0 { self.cascades.get(k + 1).and_then(|c| c.interpolate(position_m)) } else { None };
            return match coarse {
                Some(mut c) => {
                    for (a, b) in c.c.iter_mut().zip(fine.c) {
                        *a = *a * (1.0 - t) + b * t;
                    }
                    c
                }
                None => fine,
            };
        }
        ShRgb9::default()
    }

    /// Irradiance on a surface with unit normal `n` (seed 001 eq. 5 with the
    /// cosine-lobe convolution), clamped at zero against L2 ringing.
    pub fn irradiance(&self, position_m: Vec3, n: Vec3) -> Vec3 {
        self.radiance_sh(position_m).irradiance(n).max(Vec3::ZERO)
    }

    /// Total number of probes (storage slots) over all cascades.
    pub fn probe_count(&self) -> usize {
        self.cascades.iter().map(|c| c.coeffs.len()).sum()
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn constant(v: f32) -> ShRgb9 {
        let mut s = ShRgb9::default();
        s.c[0] = Vec3::splat(v);
        s
    }

    #[test]
    fn grids_centre_on_the_camera_in_whole_cells() {
        let mut c = ShCascades::new(2, UVec3::new(4, 4, 4), 0.5, 2.0);
        c.recentre(Vec3::new(0.2, 0.1, -0.2), Vec3::Z);
        assert_eq!(c.cascades[0].origin_lattice, IVec3::new(-2, -2, -2));
        assert_eq!(c.cascades[1].origin_lattice, IVec3::new(-2, -2, -2));
        // A move smaller than half a cell keeps the grid where it is.
        assert_eq!(c.recentre(Vec3::new(0.2, 0.2, -0.2), Vec3::Z), 0);
        assert!(c.cascades[0].contains(Vec3::splat(0.4)) && !c.cascades[0].contains(Vec3::splat(0.6)));
        assert!(c.cascades[1].contains(Vec3::splat(0.9)) && !c.cascades[1].contains(Vec3::splat(1.1)));
        // Pushed along the view by its half-extent, the fine grid starts at the camera.
        c.view_offset_rel = 1.0;
        c.recentre(Vec3::ZERO, Vec3::X);
        assert_eq!(c.cascades[0].origin_lattice, IVec3::new(0, -2, -2));
    }

    #[test]
    fn fitted_spacing_puts_the_scene_inside_the_coarsest_cascade() {
        let (lo, hi) = (Vec3::new(-1.0, 0.0, -1.0), Vec3::new(1.0, 2.0, 1.0));
        let cam = Vec3::new(0.0, 1.0, 3.9);
        let counts = UVec3::new(16, 8, 16);
        let s = ShCascades::spacing_to_cover(cam, lo, hi, 2, counts, 2.0);
        let mut c = ShCascades::new(2, counts, s, 2.0);
        c.recentre(cam, Vec3::NEG_Z);
        for corner in 0..8 {
            let p = Vec3::select(glam::BVec3::new(corner & 1 == 1, corner & 2 == 2, corner & 4 == 4), hi, lo);
            assert!(c.cascades[1].contains(p), "{p} outside");
        }
    }

    #[test]
    fn a_shift_keeps_probes_that_stay_and_seeds_entering_ones_from_the_coarser_cascade() {
        let mut c = ShCascades::new(2, UVec3::new(4, 4, 4), 1.0, 2.0);
        c.recentre(Vec3::ZERO, Vec3::Z);
        for (i, s) in c.cascades[0].coeffs.iter_mut().enumerate() {
            *s = constant(10.0 + i as f32);
        }
        for s in &mut c.cascades[1].coeffs {
            *s = constant(3.0);
        }
        let before: Vec<(IVec3, ShRgb9)> =
            c.cascades[0].slot_lattice.iter().copied().zip(c.cascades[0].coeffs.iter().copied()).collect();
        // One cell along +x: the fine grid moves, the coarse one (spacing 2) does not.
        let reset = c.recentre(Vec3::new(0.9, 0.0, 0.0), Vec3::Z);
        assert_eq!(reset, 16, "one 4×4 slab enters the fine cascade");
        let fine = &c.cascades[0];
        for (lattice, coeffs) in before {
            let slot = fine.slot(lattice);
            if fine.slot_lattice[slot] == lattice {
                assert_eq!(fine.coeffs[slot], coeffs, "probe at {lattice} stayed and must keep its data");
            } else {
                assert_eq!(lattice.x, -2, "only the slab at x = −2 leaves");
                assert_eq!(fine.coeffs[slot], constant(3.0), "entering probe starts from the coarse cascade");
                assert_eq!(fine.slot_lattice[slot].x, 2);
            }
        }
    }

    #[test]
    fn interpolation_reproduces_linear_fields_and_blends_into_the_coarser_cascade() {
        let mut c = ShCascades::new(2, UVec3::new(4, 4, 4), 1.0, 2.0);
        c.recentre(Vec3::ZERO, Vec3::Z);
        for cascade in &mut c.cascades {
            for slot in 0..cascade.coeffs.len() {
                let p = cascade.lattice_position(cascade.slot_lattice[slot]);
                cascade.coeffs[slot] = constant(5.0 + p.x + 2.0 * p.y - p.z);
            }
        }
        for p in [Vec3::new(0.25, -0.5, 0.75), Vec3::new(-1.9, 0.9, 0.1), Vec3::new(1.5, 1.5, -3.0)] {
            let got = c.radiance_sh(p).c[0].x;
            let want = 5.0 + p.x + 2.0 * p.y - p.z;
            assert!((got - want).abs() < 1e-4, "{p}: {got} vs {want}");
        }
        assert_eq!(c.radiance_sh(Vec3::splat(100.0)), ShRgb9::default());
    }
}
