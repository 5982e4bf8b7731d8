//! Probe-position optimizer (seed 004 §5, Listing 4; RTXGI `ProbeRelocationCS`).
//! From one distance-only trace per iteration, each probe:
//! - sees more than 25 % backfaces → it is inside geometry: move through the
//!   closest backface, by the largest of 1.99…1.00 × its distance that keeps the
//!   offset within the limit;
//! - otherwise, if a front face is closer than `probe_relocation_min_frontface_rel`
//!   × the minimum spacing and the closest and farthest front faces lie in
//!   different directions (cos ≤ 0.5), step toward the farthest front face.
//!
//! Offsets stay below `probe_relocation_offset_limit_rel` × spacing per axis (RTXGI
//! 0.45), so grid indexing still holds. Deviations: the listing's front-face step
//! `min(0.2, d)` is in its scenes' units; we use `min(0.2 × min spacing, d)`, and
//! the closeness condition (implied by "move away from close front faces", explicit
//! in RTXGI) is a setting.

use glam::Vec3;

use crate::ddgi_settings::DdgiVolumeSettings;

/// A probe whose rays see more than this fraction of backfaces is inside geometry
/// (seed 004 Listing 4's 25 %); `probe_relocation.wgsl` and
/// `probe_classification.wgsl` read it from probegi-wgpu's generated prelude.
pub const INSIDE_GEOMETRY_BACKFACE_FRACTION: f32 = 0.25;

/// The front-face step's limit as a fraction of the minimum spacing (seed 004
/// Listing 4's `min(0.2, d)`, here relative; see the module docs); also in
/// `probe_relocation.wgsl`'s generated prelude.
pub const FRONTFACE_STEP_LIMIT_REL: f32 = 0.2;

/// What one probe's rays saw: directions with hit distances.
#[derive(Clone, Copy, Debug, Default, PartialEq)]
pub struct ProbeRayStats {
    /// Fraction of all the probe's rays (misses included) that hit a backface, in
    /// [0, 1]; above 0.25 it is inside geometry.
    pub backface_fraction: f32,
    /// (unit direction, distance) of the closest backface hit.
    pub closest_backface: Option<(Vec3, f32)>,
    /// (unit direction, distance in metres) of the closest front-face hit; `None` when
    /// no ray hit a front face.
    pub closest_frontface: Option<(Vec3, f32)>,
    /// (unit direction, distance in metres) of the farthest front-face hit (misses
    /// excluded), which a probe steps toward.
    pub farthest_frontface: Option<(Vec3, f32)>,
}

/// Statistics from `signed_distance` per ray direction: positive = front-face hit,
/// negative = backface hit at |d|, infinite = miss.
pub fn probe_ray_stats(dirs: &[Vec3], signed_distance: &[f32]) -> ProbeRayStats {
    let mut s = ProbeRayStats::default();
    let mut backfaces = 0usize;
    for (&d, &t) in dirs.iter().zip(signed_distance) {
        if t.is_nan() {
            continue;
        }
        if t < 0.0 {
            backfaces += 1;
            if s.closest_backface.is_none_or(|(_, c)| -t < c) {
                s.closest_backface = Some((d, -t));
            }
        } else if t.is_finite() {
            if s.closest_frontface.is_none_or(|(_, c)| t < c) {
                s.closest_frontface = Some((d, t));
            }
            if s.farthest_frontface.is_none_or(|(_, c)| t > c) {
                s.farthest_frontface = Some((d, t));
            }
        }
    }
    s.backface_fraction = backfaces as f32 / dirs.len().max(1) as f32;
    s
}

/// Whether the probe's rays say it is inside geometry (seed 004 Listing 4's 25 %).
pub fn is_inside_geometry(stats: &ProbeRayStats) -> bool {
    stats.backface_fraction > INSIDE_GEOMETRY_BACKFACE_FRACTION
}

/// One optimizer iteration: the probe's new offset from its grid point.
pub fn relocation_step(offset: Vec3, stats: &ProbeRayStats, spacing_m: Vec3, settings: &DdgiVolumeSettings) -> Vec3 {
    let limit = spacing_m * settings.probe_relocation_offset_limit_rel;
    let within = |o: Vec3| o.abs().cmplt(limit).all();
    let min_spacing = spacing_m.min_element();
    let mut full = offset;
    if is_inside_geometry(stats) {
        if let Some((dir, dist)) = stats.closest_backface {
            let v = dir * dist;
            for i in 1..=100 {
                full = offset + v * (2.0 - i as f32 * 0.01);
                if within(full) {
                    break;
                }
            }
        }
    } else if let (Some((cdir, cdist)), Some((fdir, fdist))) = (stats.closest_frontface, stats.farthest_frontface)
        && cdist < settings.probe_relocation_min_frontface_rel * min_spacing
        && cdir.dot(fdir) <= 0.5
    {
        full = offset + fdir * fdist.min(FRONTFACE_STEP_LIMIT_REL * min_spacing);
    }
    if within(full) { full } else { offset }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn stats_find_closest_and_farthest() {
        let dirs = [Vec3::X, Vec3::NEG_X, Vec3::Y, Vec3::Z];
        let s = probe_ray_stats(&dirs, &[2.0, -0.5, 5.0, f32::INFINITY]);
        assert_eq!(s.backface_fraction, 0.25);
        assert_eq!(s.closest_backface, Some((Vec3::NEG_X, 0.5)));
        assert_eq!(s.closest_frontface, Some((Vec3::X, 2.0)));
        assert_eq!(s.farthest_frontface, Some((Vec3::Y, 5.0)));
    }

    #[test]
    fn inside_probes_move_through_the_closest_backface_within_the_limit() {
        let settings = DdgiVolumeSettings::default();
        let stats = ProbeRayStats {
            backface_fraction: 0.6,
            closest_backface: Some((Vec3::X, 0.1)),
            closest_frontface: None,
            farthest_frontface: None,
        };
        let o = relocation_step(Vec3::ZERO, &stats, Vec3::ONE, &settings);
        assert!((o - Vec3::new(0.199, 0.0, 0.0)).length() < 1e-5, "{o}");
        // A backface farther than the limit allows cannot be passed: the probe stays.
        let far = ProbeRayStats { closest_backface: Some((Vec3::X, 0.6)), ..stats };
        assert_eq!(relocation_step(Vec3::ZERO, &far, Vec3::ONE, &settings), Vec3::ZERO);
    }

    #[test]
    fn probes_step_away_from_close_front_faces() {
        let settings = DdgiVolumeSettings::default();
        let stats = ProbeRayStats {
            backface_fraction: 0.0,
            closest_backface: None,
            closest_frontface: Some((Vec3::NEG_Y, 0.05)),
            farthest_frontface: Some((Vec3::Y, 3.0)),
        };
        let o = relocation_step(Vec3::ZERO, &stats, Vec3::ONE, &settings);
        assert!((o - Vec3::new(0.0, 0.2, 0.0)).length() < 1e-6, "{o}");
        // Far from every surface: no move.
        let open = ProbeRayStats { closest_frontface: Some((Vec3::NEG_Y, 0.9)), ..stats };
        assert_eq!(relocation_step(Vec3::ZERO, &open, Vec3::ONE, &settings), Vec3::ZERO);
    }
}
