//! Seeding new probes (issue 32, after Timberdoodle PGI, `../shared/PEERS.md`:
//! "probes that have just become valid are seeded from the coarser cascade
//! instead of from black"). A probe that a tracking window scrolls in starts
//! with no history (`ddgi_volume::scrolling`). With `probe_seeding`, its tiles
//! are filled right after the scroll from the next volume in sampling order
//! (the next coarser cascade, or the next sparser volume of a density set)
//! whose cage around the probe's grid point holds usable probes: per texel,
//! the trilinear mix of those probes' texels of the same index (the same
//! direction: the volumes share tile sizes). Irradiance is mixed as decoded
//! mean radiance and re-encoded; distance moments are mixed as they are (the
//! moments of the mixture). Borders are mixed with the interior, so they still
//! equal their sources.
//!
//! Under the jcgt, usage and all-active schemes a seeded probe is still not
//! read before its first own blend (queries skip probes without history, as
//! before; it blends in the frame it was seeded). Under the screen scheme it
//! is read at once and, unless the camera requests it, waits for its
//! interleaved phase (`ddgi_volume::screen_requests`). Its first blend weighs the seed with the
//! probe's hysteresis (Listing 3's per-texel drops and the edge buffers'
//! cap apply) instead of replacing it. The shadowing field's occlusion maps are
//! not seeded (they stay reset to lit).
//!
//! Each source probe's trilinear weight is multiplied by its Chebyshev
//! visibility of the new probe's position (`probegi_core::ddgi_query::
//! chebyshev_weight`, from the source's distance moments at the nearest
//! interior texel toward it), so a coarse probe behind a wall does not pass on
//! the other side's light. Where no source probe sees the position, the plain
//! trilinear weights apply.
//!
//! *Deviations:* a probe that no later volume covers
//! with a usable probe, or whose tile sizes differ from that volume's, starts
//! from nothing as before. One plan serves both backends: the host applies it
//! to its atlases ([`apply_seeds`]) and a device that holds them runs the same
//! mix (`DeviceVolumeBlend::seeds`).

use glam::{Vec2, Vec3};
use probegi_core::ddgi_query::chebyshev_weight;
use probegi_core::irradiance_encoding::{decode_irradiance, encode_irradiance};
use probegi_core::octahedral::oct_encode;
use probegi_core::probe_atlas::ProbeAtlas;

use crate::ddgi_volume::DdgiVolume;

/// One new probe's seed: a mix of up to eight tiles of another volume.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct ProbeSeed {
    /// The seeded probe's storage slot in its own volume.
    pub probe: u32,
    /// The source volume's index in the set (as given, not sampling order).
    pub source_volume: u32,
    /// The source probes (storage slots); unused entries have weight 0.
    pub source_probes: [u32; 8],
    /// The sources' trilinear weights, summing to 1 (before visibility).
    pub weights: [f32; 8],
    /// The seeded probe's grid position, metres: where visibility is tested.
    pub position_m: Vec3,
    /// The sources' positions (relocation offsets included), metres.
    pub source_positions_m: [Vec3; 8],
}

/// Below this total visibility-weighted share the plain trilinear weights apply.
pub const SEED_VISIBLE_WEIGHT_MIN: f32 = 1e-4;

/// The seeds for the probes reset in `volumes[target]` since its last blend
/// (`reset`), from the volumes after it in `order` (sampling order).
pub fn plan_seeds(volumes: &[DdgiVolume], order: &[usize], target: usize, reset: &[u32]) -> Vec<ProbeSeed> {
    let dst = &volumes[target];
    let later: Vec<usize> = order.iter().skip_while(|&&v| v != target).skip(1).copied().collect();
    let same_tiles = |s: &DdgiVolume| {
        s.irradiance.interior == dst.irradiance.interior && s.distance.interior == dst.distance.interior
    };
    reset
        .iter()
        .filter_map(|&p| {
            let position = dst.grid.probe_position(dst.grid.probe_coords(p as usize));
            later
                .iter()
                .filter(|&&s| same_tiles(&volumes[s]))
                .find_map(|&s| seed_from(&volumes[s], position).map(|(probes, weights)| (s, probes, weights)))
                .map(|(s, source_probes, weights)| ProbeSeed {
                    probe: p,
                    source_volume: s as u32,
                    source_probes,
                    weights,
                    position_m: position,
                    source_positions_m: source_probes.map(|q| volumes[s].probe_positions[q as usize]),
                })
        })
        .collect()
}

/// The usable probes of `source`'s cage around `position_m` (the core's
/// `ProbeGrid::cage`) with their normalised trilinear weights; `None` outside
/// its probe box or when none is usable.
fn seed_from(source: &DdgiVolume, position_m: Vec3) -> Option<([u32; 8], [f32; 8])> {
    let g = &source.grid;
    let a = (position_m - g.origin_m) / g.spacing_m;
    let top = (g.probe_counts.as_vec3() - Vec3::ONE).max(Vec3::ZERO);
    if !(a.cmpge(Vec3::ZERO).all() && a.cmple(top).all()) {
        return None;
    }
    let cage = g.cage(position_m);
    let (mut probes, mut weights) = ([0u32; 8], [0f32; 8]);
    for corner in 0..8 {
        let q = g.probe_index(cage.corner(corner));
        if source.probe_usable(q) && source.probe_has_history(q) {
            probes[corner] = q as u32;
            weights[corner] = cage.trilinear(corner).element_product();
        }
    }
    let sum: f32 = weights.iter().sum();
    if sum <= 1e-6 {
        return None;
    }
    weights.iter_mut().for_each(|w| *w /= sum);
    Some((probes, weights))
}

/// The seed's mix weights: trilinear × each source's Chebyshev visibility of
/// the seeded position, normalised; the trilinear weights where none sees it.
pub fn seed_weights(seed: &ProbeSeed, distance: &ProbeAtlas<Vec2>) -> [f32; 8] {
    let n = distance.interior;
    let w: [f32; 8] = std::array::from_fn(|i| {
        if seed.weights[i] <= 0.0 {
            return 0.0;
        }
        let to = seed.position_m - seed.source_positions_m[i];
        let d = to.length();
        let visible = if d > 1e-4 {
            let moments = distance.tile(seed.source_probes[i] as usize)[nearest_texel(to / d, n)];
            chebyshev_weight(moments, d)
        } else {
            1.0
        };
        seed.weights[i] * visible
    });
    let sum: f32 = w.iter().sum();
    if sum < SEED_VISIBLE_WEIGHT_MIN {
        return seed.weights;
    }
    w.map(|x| x / sum)
}

/// The interior texel of a tile with `n` interior texels per side that holds
/// direction `dir` (nearest, no filtering), as an index into the bordered tile.
pub fn nearest_texel(dir: Vec3, n: u32) -> usize {
    let uv = oct_encode(dir) * 0.5 + Vec2::splat(0.5);
    let texel = |u: f32| ((u * n as f32).floor() as i64).clamp(0, n as i64 - 1) as usize;
    (texel(uv.y) + 1) * (n as usize + 2) + texel(uv.x) + 1
}

/// One seed's mixed tiles (irradiance encoded with `gamma`, distance
/// moments), with [`seed_weights`].
pub fn seed_tiles(
    seed: &ProbeSeed,
    irradiance: &ProbeAtlas<Vec3>,
    distance: &ProbeAtlas<Vec2>,
    gamma: f32,
) -> (Vec<Vec3>, Vec<Vec2>) {
    let mut irr = vec![Vec3::ZERO; irradiance.tile_len()];
    let mut dist = vec![Vec2::ZERO; distance.tile_len()];
    let weights = seed_weights(seed, distance);
    for (&q, &w) in seed.source_probes.iter().zip(&weights).filter(|(_, w)| **w > 0.0) {
        for (out, t) in irr.iter_mut().zip(irradiance.tile(q as usize)) {
            *out += w * decode_irradiance(*t, gamma);
        }
        for (out, t) in dist.iter_mut().zip(distance.tile(q as usize)) {
            *out += w * *t;
        }
    }
    irr.iter_mut().for_each(|t| *t = encode_irradiance(*t, gamma));
    (irr, dist)
}

/// Applies `seeds` of `volumes[target]` to the host atlases (their sources
/// must be current) and marks the probes seeded.
pub fn apply_seeds(volumes: &mut [DdgiVolume], target: usize, seeds: &[ProbeSeed]) {
    for seed in seeds {
        let src = &volumes[seed.source_volume as usize];
        let gamma = volumes[target].settings.probe_irradiance_gamma;
        let (irr, dist) = seed_tiles(seed, &src.irradiance, &src.distance, gamma);
        let dst = &mut volumes[target];
        dst.irradiance.tile_mut(seed.probe as usize).copy_from_slice(&irr);
        dst.distance.tile_mut(seed.probe as usize).copy_from_slice(&dist);
        dst.mark_seeded(seed.probe as usize);
    }
}
