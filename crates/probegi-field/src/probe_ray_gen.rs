//! Ray-generation pass (seed 003 §4.2, seed 004 §2.3): each probe casts
//! `probe_rays_per_probe` rays along a spherical Fibonacci set (seed 003 eq.
//! 4.2–4.3), rotated by one uniformly random rotation per frame so that over
//! frames the probes see the whole sphere. The rotation is reproducible from
//! `(seed, frame)`. All probes share the frame's directions, so the texel-to-ray
//! blend weights are built here once per frame.

use glam::Vec3;
use probegi_core::ddgi_settings::DdgiVolumeSettings;
use probegi_core::fibonacci::{sample_uniform_rotation, spherical_fibonacci};
use probegi_core::probe_blend::BlendWeights;
use probegi_core::rng::{Pcg32, hash_combine};

/// One frame's probe-ray directions and the blend weights that go with them.
#[derive(Clone, Debug, Default)]
pub struct ProbeRayDirections {
    /// Unit world directions, shared by every probe this frame.
    pub dirs: Vec<Vec3>,
    /// `max(0, ω·r)` per irradiance texel (seed 003 eq. 4.12–4.13).
    pub irradiance_weights: BlendWeights,
    /// `max(0, ω·r)^k_s` per distance texel (seed 003 eq. 4.14).
    pub distance_weights: BlendWeights,
}

/// The frame's rotated spherical Fibonacci directions alone (distance-only traces
/// need no blend weights).
pub fn probe_ray_directions(settings: &DdgiVolumeSettings, seed: u64, frame: u32) -> Vec<Vec3> {
    rotated_fibonacci(probe_ray_rotation(seed, frame), settings.probe_rays_per_probe)
}

/// `n` spherical Fibonacci directions rotated by `rotation` (how a batch's
/// `GeneratedProbeRays` are made into rays on the host).
pub fn rotated_fibonacci(rotation: glam::Quat, n: u32) -> Vec<Vec3> {
    (0..n).map(|i| (rotation * spherical_fibonacci(i, n)).normalize()).collect()
}

/// The frame's random rotation of the Fibonacci set, reproducible from `(seed,
/// frame)` (what a GPU ray generation pass is given).
pub fn probe_ray_rotation(seed: u64, frame: u32) -> glam::Quat {
    let mut rng = Pcg32::new(hash_combine(&[seed, frame as u64, 0x7261_7973]), frame as u64);
    sample_uniform_rotation(Vec3::new(rng.next_f32(), rng.next_f32(), rng.next_f32()))
}

/// The frame's rotated spherical Fibonacci directions for a volume and the
/// blend weights of each direction (what the host plan traces).
pub fn generate_probe_rays(settings: &DdgiVolumeSettings, seed: u64, frame: u32) -> ProbeRayDirections {
    let dirs = probe_ray_directions(settings, seed, frame);
    ProbeRayDirections {
        irradiance_weights: BlendWeights::new(&dirs, settings.probe_irradiance_texels, 1.0),
        distance_weights: BlendWeights::new(&dirs, settings.probe_distance_texels, settings.probe_distance_exponent),
        dirs,
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn directions_rotate_per_frame_reproducibly() {
        let s = DdgiVolumeSettings { probe_rays_per_probe: 64, ..Default::default() };
        let a = generate_probe_rays(&s, 1, 0);
        let b = generate_probe_rays(&s, 1, 0);
        let c = generate_probe_rays(&s, 1, 1);
        assert_eq!(a.dirs, b.dirs);
        assert_ne!(a.dirs, c.dirs);
        // A rotation keeps the set's shape: the angle between rays 0 and 1 is unchanged.
        assert!((a.dirs[0].dot(a.dirs[1]) - c.dirs[0].dot(c.dirs[1])).abs() < 1e-5);
    }
}
