//! Sampling a set of DDGI volumes: which volumes shade a point, and how much.
//!
//! Two schemes, one per kind of set:
//! - [`VolumeBlending::Density`] (seed 004 §7.4), for hand-placed volumes: volumes
//!   are visited from most to least dense (smallest cell volume first); each has a
//!   weight of 1 over its probe box, falling linearly to 0 over one cell on every
//!   axis ([`volume_blend_weight`]); a volume's weight is scaled by what the denser
//!   ones left, `w·(1 − Σw)`, and once Σw reaches 1 the rest are skipped. The sum
//!   is normalised by Σw (as Algorithm 2 of seed 003 does), so a point inside one
//!   volume's falloff band alone reads that volume unattenuated.
//!   *Deviation:* seed 004 places the falloff inside the last cell (from the
//!   second-to-last plane of probes); we place it over the cell outside the probe
//!   box, as RTXGI's `DDGIGetVolumeBlendWeight` does, so the outermost probes keep
//!   full weight and a volume fitted to the scene bounds (probes at cell centres,
//!   half a cell in from the bounds) covers all of it: a single volume shades
//!   exactly as it did before sets existed. A point farther than one cell outside
//!   every volume's probe box gets **no** field contribution (zero irradiance).
//!   *Camera-aware blending* (seed 004 §7.4, Fig. 13) for volumes that track the
//!   camera: the full-weight box is the probe box tightened by one cell per axis
//!   and centred on the camera, so a plane that leapfrogs in front of the camera
//!   fades in as the camera approaches instead of popping. It applies only to a
//!   member with a sparser one after it to blend into; the last member in
//!   sampling order keeps its whole probe box.
//! - [`VolumeBlending::Cascades`] (seed 003 §6.2.2): nested camera-centred
//!   cascades, finest first, each weighted by Algorithm 1 ([`cascade_field_weight`])
//!   and accumulated by Algorithm 2 until the weight reaches 1. The coarsest cascade
//!   takes weight 1 wherever the finer ones left less than 0.9 (Algorithm 2's
//!   `f < N or wsum > 0.9` test), so it covers the whole scene as the thesis's
//!   enveloping top cascade does.
//!   *Deviation:* Algorithm 1 as printed ramps the weight up over the first cell but
//!   tests `a > R − 1` at the far end, where `R − 1 − a` is always negative, so the
//!   far ramp would be a hard zero; we use `R − 2`, the symmetric ramp over the last
//!   cell that the text ("weights fall off ... at the edges") describes, written as
//!   `clamp(min(a, R − 1 − a), 0, 1)` per axis. The per-axis factors multiply (the
//!   algorithm's loop), not a geometric mean as the prose says.

use glam::Vec3;

use crate::ddgi_query::{DdgiFieldView, irradiance};
pub use crate::ddgi_settings::VolumeBlending;
use crate::probe_grid::ProbeGrid;

/// Seed 004 §7.4 weight of `point` for one volume: 1 inside the full-weight box,
/// falling linearly to 0 one cell outside it on each axis (the axes' factors
/// multiply). The box is the probe box, or with `camera_m` (a volume that tracks
/// the camera) the probe box tightened by one cell and centred on the camera.
pub fn volume_blend_weight(grid: &ProbeGrid, point: Vec3, camera_m: Option<Vec3>) -> f32 {
    let half = grid.spacing_m * (grid.probe_counts.as_vec3() - Vec3::ONE) * 0.5;
    let (centre, half) = match camera_m {
        Some(c) => (c, (half - grid.spacing_m).max(Vec3::ZERO)),
        None => (grid.origin_m + half, half),
    };
    let outside = ((point - centre).abs() - half).max(Vec3::ZERO) / grid.spacing_m;
    let w = (Vec3::ONE - outside).clamp(Vec3::ZERO, Vec3::ONE);
    w.x * w.y * w.z
}

/// Seed 003 Algorithm 1 (with the far-edge fix in the module docs): per axis, the
/// point's grid coordinate `a` gives `clamp(min(a, R − 1 − a), 0, 1)`; the product.
pub fn cascade_field_weight(grid: &ProbeGrid, point: Vec3) -> f32 {
    let a = (point - grid.origin_m) / grid.spacing_m;
    let r = grid.probe_counts.as_vec3() - Vec3::ONE;
    let w = a.min(r - a).clamp(Vec3::ZERO, Vec3::ONE);
    w.x * w.y * w.z
}

/// One volume of a set as the set query reads it.
#[derive(Clone, Copy)]
pub struct SetMember<'a> {
    /// The volume's probe data, queried with [`crate::ddgi_query::irradiance`] wherever
    /// the member has weight.
    pub field: DdgiFieldView<'a>,
    /// The member's index among the set's volumes as given (its place in
    /// sampling order may differ: densest first).
    pub volume: usize,
    /// The volume tracks the camera (camera-aware blending under `Density`).
    pub tracks_camera: bool,
    /// The volume's shadowing-field occlusion maps (seed 003 ch. 5,
    /// `crate::shadow_field`), when it keeps them.
    pub occlusion: Option<&'a crate::probe_atlas::ProbeAtlas<f32>>,
}

/// Everything the set query reads: the members in sampling order (densest or
/// finest first), the scheme, and the camera position for camera-aware blending.
pub struct DdgiFieldSetView<'a> {
    /// The set's volumes in sampling order: densest first under `Density`, finest
    /// cascade first under `Cascades`.
    pub members: Vec<SetMember<'a>>,
    /// The weighting scheme: seed 004 §7.4 density order or seed 003 Algorithms 1–2
    /// cascades (module docs).
    pub blending: VolumeBlending,
    /// Camera position, metres, world space, for camera-aware blending of members that
    /// track the camera (`Density` only); `None` turns it off.
    pub camera_m: Option<Vec3>,
}

/// Member `f`'s share at `point` by the set's scheme, given the weight `wsum` the
/// members before it took (zero once they took it all).
fn member_weight(set: &DdgiFieldSetView<'_>, f: usize, point: Vec3, wsum: f32) -> f32 {
    if wsum >= 1.0 {
        return 0.0;
    }
    let n = set.members.len();
    let m = &set.members[f];
    let w = match set.blending {
        VolumeBlending::Density => {
            // Camera-aware only where a later (sparser) member can take over the
            // band the tightened box leaves; the last member keeps its probe box.
            let camera = if m.tracks_camera && f + 1 < n { set.camera_m } else { None };
            volume_blend_weight(m.field.grid, point, camera)
        }
        VolumeBlending::Cascades => {
            if f + 1 < n || wsum > 0.9 {
                cascade_field_weight(m.field.grid, point)
            } else {
                1.0
            }
        }
    };
    if w > 0.0 { w * (1.0 - wsum).clamp(0.0, 1.0) } else { 0.0 }
}

/// Irradiance at `position` over the whole set (see the module docs). A point that
/// no member weighs gets zero. When one member alone contributes, its value is
/// returned as is (bit-identical to querying that volume).
pub fn field_set_irradiance(set: &DdgiFieldSetView<'_>, position: Vec3, normal: Vec3, view_dir: Vec3) -> Vec3 {
    let mut sum = Vec3::ZERO;
    let mut wsum = 0.0f32;
    let mut only: Option<Vec3> = None;
    let mut contributors = 0;
    for f in 0..set.members.len() {
        let w = member_weight(set, f, position, wsum);
        if w <= 0.0 {
            continue;
        }
        let e = irradiance(&set.members[f].field, position, normal, view_dir);
        sum += e * w;
        wsum += w;
        contributors += 1;
        only = Some(e);
    }
    match (contributors, only) {
        (0, _) => Vec3::ZERO,
        (1, Some(e)) => e,
        _ => sum / wsum,
    }
}

/// The probes a query at `position` reads, as [`field_set_irradiance`] weighs
/// the members: for every member with weight there, the storage slots of the
/// eight corners of its biased point's cage (`ProbeGrid::cage`; usable or
/// not, and not their fallbacks), passed to `visit` as (member index in
/// sampling order, slot). The screen scheme's requests
/// (`crate::probe_classification`, `ProbeStatesMode::Screen`).
pub fn field_set_cage_probes(
    set: &DdgiFieldSetView<'_>,
    position: Vec3,
    normal: Vec3,
    view_dir: Vec3,
    mut visit: impl FnMut(usize, usize),
) {
    let mut wsum = 0.0f32;
    for f in 0..set.members.len() {
        let w = member_weight(set, f, position, wsum);
        if w <= 0.0 {
            continue;
        }
        wsum += w;
        let field = &set.members[f].field;
        let g = field.grid;
        let cage = g.cage(position + crate::ddgi_query::surface_bias(field.settings, g, normal, view_dir));
        for i in 0..8 {
            visit(f, g.probe_index(cage.corner(i)));
        }
    }
}

/// The shadowing field's cage at `position` over the set
/// (`crate::shadow_field::ShadowCage`): from the first member in sampling
/// order that keeps occlusion maps, weighs the point (its probe box and one
/// cell around it, [`volume_blend_weight`]) and has a usable probe there;
/// `None` where none does (the caller traces shadow rays there).
pub fn field_set_shadow_cage<'a>(
    set: &DdgiFieldSetView<'a>,
    position: Vec3,
    normal: Vec3,
    view_dir: Vec3,
) -> Option<crate::shadow_field::ShadowCage<'a>> {
    set.members.iter().find_map(|m| member_shadow_cage(&m.field, m.occlusion?, position, normal, view_dir))
}

/// One member's shadow cage at `position` under [`field_set_shadow_cage`]'s
/// rule: `None` outside its probe box and the cell around it
/// ([`volume_blend_weight`]) or where it has no usable probe.
pub fn member_shadow_cage<'a>(
    field: &DdgiFieldView<'_>,
    occlusion: &'a crate::probe_atlas::ProbeAtlas<f32>,
    position: Vec3,
    normal: Vec3,
    view_dir: Vec3,
) -> Option<crate::shadow_field::ShadowCage<'a>> {
    if volume_blend_weight(field.grid, position, None) <= 0.0 {
        return None;
    }
    let sharpness = field.settings.shadow_field_sharpness;
    crate::shadow_field::ShadowCage::new(field, occlusion, position, normal, view_dir, sharpness)
}

#[cfg(test)]
mod tests {
    use super::*;
    use glam::UVec3;

    fn grid(origin: f32, counts: u32, spacing: f32) -> ProbeGrid {
        ProbeGrid::new(Vec3::splat(origin), UVec3::splat(counts), Vec3::splat(spacing))
    }

    #[test]
    fn volume_weight_is_one_on_the_probe_box_and_falls_over_one_cell_outside() {
        let g = grid(0.0, 5, 1.0); // probe box [0, 4]³
        assert_eq!(volume_blend_weight(&g, Vec3::splat(2.0), None), 1.0);
        assert_eq!(volume_blend_weight(&g, Vec3::new(4.0, 0.0, 2.0), None), 1.0);
        assert!((volume_blend_weight(&g, Vec3::new(4.25, 2.0, 2.0), None) - 0.75).abs() < 1e-6);
        assert!((volume_blend_weight(&g, Vec3::new(4.5, -0.5, 2.0), None) - 0.25).abs() < 1e-6);
        assert_eq!(volume_blend_weight(&g, Vec3::new(5.0, 2.0, 2.0), None), 0.0);
        // Camera-aware: the full box is [1, 3]³ around a centred camera, and follows it.
        let cam = Some(Vec3::splat(2.0));
        assert!((volume_blend_weight(&g, Vec3::new(3.5, 2.0, 2.0), cam) - 0.5).abs() < 1e-6);
        let moved = Some(Vec3::new(2.6, 2.0, 2.0));
        assert!((volume_blend_weight(&g, Vec3::new(3.5, 2.0, 2.0), moved) - 1.0).abs() < 1e-6);
        assert!((volume_blend_weight(&g, Vec3::new(1.1, 2.0, 2.0), moved) - 0.5).abs() < 1e-6);
    }

    /// A view of a uniform field: every probe sees mean radiance `mean`.
    struct Uniform {
        grid: ProbeGrid,
        settings: crate::ddgi_settings::DdgiVolumeSettings,
        irr: crate::probe_atlas::ProbeAtlas<Vec3>,
        dist: crate::probe_atlas::ProbeAtlas<glam::Vec2>,
    }

    impl Uniform {
        fn new(grid: ProbeGrid, mean: f32) -> Self {
            let settings = crate::ddgi_settings::DdgiVolumeSettings::default();
            let n = grid.probe_count();
            let mut irr = crate::probe_atlas::ProbeAtlas::new(n, settings.probe_irradiance_texels);
            let mut dist = crate::probe_atlas::ProbeAtlas::new(n, settings.probe_distance_texels);
            irr.texels.fill(crate::irradiance_encoding::encode_irradiance(Vec3::splat(mean), 5.0));
            dist.texels.fill(glam::Vec2::new(100.0, 1e4));
            Self { grid, settings, irr, dist }
        }

        fn member(&self, tracks_camera: bool) -> SetMember<'_> {
            SetMember {
                occlusion: None,
                volume: 0,
                field: DdgiFieldView {
                    grid: &self.grid,
                    settings: &self.settings,
                    irradiance: &self.irr,
                    distance: &self.dist,
                    probe_offsets_m: &[],
                    probe_usable: &[],
                    probe_fallback: &[],
                    probe_rows_id: None,
                },
                tracks_camera,
            }
        }
    }

    #[test]
    fn a_set_blends_dense_into_sparse_over_one_cell_and_is_zero_beyond_every_volume() {
        let pi = std::f32::consts::PI;
        let dense = Uniform::new(grid(0.0, 5, 1.0), 1.0); // probe box [0, 4]³, E = π
        let sparse = Uniform::new(grid(-8.0, 5, 5.0), 3.0); // [-8, 12]³, E = 3π
        let set = DdgiFieldSetView {
            members: vec![dense.member(false), sparse.member(false)],
            blending: VolumeBlending::Density,
            camera_m: None,
        };
        let at = |x: f32| field_set_irradiance(&set, Vec3::new(x, 2.0, 2.0), Vec3::Y, Vec3::Y).x / pi;
        assert!((at(2.0) - 1.0).abs() < 1e-4, "inside the dense box: dense alone");
        // 0.25 cells outside the dense box: 0.75 dense + 0.25 sparse.
        assert!((at(4.25) - (0.75 + 0.25 * 3.0)).abs() < 1e-3, "{}", at(4.25));
        assert!((at(8.0) - 3.0).abs() < 1e-4, "beyond the dense falloff: sparse alone");
        assert_eq!(at(30.0), 0.0, "outside every volume");
        // Cascades (Algorithm 2): the coarsest covers everything the finer leave.
        let cascades = DdgiFieldSetView { blending: VolumeBlending::Cascades, ..set };
        let at = |x: f32| field_set_irradiance(&cascades, Vec3::new(x, 2.0, 2.0), Vec3::Y, Vec3::Y).x / pi;
        assert!((at(2.0) - 1.0).abs() < 1e-4);
        // x = 3.5: Algorithm 1 gives the fine field 0.5 (last cell), the rest is coarse.
        assert!((at(3.5) - (0.5 + 0.5 * 3.0)).abs() < 1e-3, "{}", at(3.5));
        assert!((at(30.0) - 3.0).abs() < 1e-4, "the coarsest cascade covers the world");
    }

    #[test]
    fn cage_probes_are_the_weighed_members_cage_corners() {
        let dense = Uniform::new(grid(0.0, 5, 1.0), 1.0); // probe box [0, 4]³
        let sparse = Uniform::new(grid(-8.0, 5, 5.0), 3.0); // [-8, 12]³
        let set = DdgiFieldSetView {
            members: vec![dense.member(false), sparse.member(false)],
            blending: VolumeBlending::Density,
            camera_m: None,
        };
        let probes_at = |p: Vec3| {
            let mut v = Vec::new();
            field_set_cage_probes(&set, p, Vec3::Y, Vec3::Y, |m, slot| v.push((m, slot)));
            v
        };
        // Inside the dense box the dense member takes all the weight: its cage alone.
        // Bias: (0.2·n + 0.8·v)·0.75·1 m·0.3 = 0.225 m up; (2.3, 1.275, 2.3) → base (2, 1, 2).
        let inside = probes_at(Vec3::new(2.3, 1.05, 2.3));
        let g = &dense.grid;
        let expect: Vec<(usize, usize)> =
            (0..8).map(|i| (0, g.probe_index(g.cage(Vec3::new(2.3, 1.275, 2.3)).corner(i)))).collect();
        assert_eq!(inside, expect);
        assert!(inside.contains(&(0, g.probe_index(glam::UVec3::new(2, 1, 2)))));
        assert!(inside.contains(&(0, g.probe_index(glam::UVec3::new(3, 2, 3)))));
        // In the dense falloff band both members are read; beyond it the sparse alone.
        let band = probes_at(Vec3::new(4.25, 2.0, 2.0));
        assert_eq!(band.iter().filter(|(m, _)| *m == 0).count(), 8);
        assert_eq!(band.iter().filter(|(m, _)| *m == 1).count(), 8);
        assert!(probes_at(Vec3::new(8.0, 2.0, 2.0)).iter().all(|(m, _)| *m == 1));
        assert!(probes_at(Vec3::splat(30.0)).is_empty(), "no member weighs a point beyond every volume");
    }

    #[test]
    fn cascade_weight_ramps_over_the_first_and_last_cell() {
        let g = grid(0.0, 5, 2.0); // a = x / 2, R − 1 = 4
        assert_eq!(cascade_field_weight(&g, Vec3::splat(4.0)), 1.0);
        assert!((cascade_field_weight(&g, Vec3::new(1.0, 4.0, 4.0)) - 0.5).abs() < 1e-6);
        assert!((cascade_field_weight(&g, Vec3::new(7.0, 4.0, 4.0)) - 0.5).abs() < 1e-6);
        assert_eq!(cascade_field_weight(&g, Vec3::new(8.0, 4.0, 4.0)), 0.0);
        assert_eq!(cascade_field_weight(&g, Vec3::new(-1.0, 4.0, 4.0)), 0.0);
        assert!((cascade_field_weight(&g, Vec3::new(1.0, 1.0, 4.0)) - 0.25).abs() < 1e-6, "axes multiply");
    }
}
