//! Ray-generation pass (seed 003 §4.2, seed 004 §2.3): each probe casts
//! `probe_rays_per_probe` rays along a spherical Fibonacci set (seed 003 eq.
//! 4.2–4.3), rotated by one uniformly random rotation per frame so that over
//! frames the probes see the whole sphere. The rotation is reproducible from
//! `(seed, frame)`. All probes share the frame's directions, so the texel-to-ray
//! blend weights are built once per frame, on the first host blend that reads
//! them (a device that blends computes its own: `probegi-wgpu`'s
//! `blend_weights_table`).

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
    /// Interior texels per side of the irradiance and distance tiles, and the
    /// distance exponent k_s, which the weights are for.
    irradiance_interior: u32,
    distance_interior: u32,
    distance_exponent: f32,
    /// The weight tables, built on first use.
    weights: std::sync::OnceLock<(BlendWeights, BlendWeights)>,
}

impl ProbeRayDirections {
    /// `max(0, ω·r)` per irradiance texel (seed 003 eq. 4.12–4.13).
    pub fn irradiance_weights(&self) -> &BlendWeights {
        &self.weights().0
    }

    /// `max(0, ω·r)^k_s` per distance texel (seed 003 eq. 4.14).
    pub fn distance_weights(&self) -> &BlendWeights {
        &self.weights().1
    }

    fn weights(&self) -> &(BlendWeights, BlendWeights) {
        self.weights.get_or_init(|| {
            (
                BlendWeights::new(&self.dirs, self.irradiance_interior, 1.0),
                BlendWeights::new(&self.dirs, self.distance_interior, self.distance_exponent),
            )
        })
    }
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
        dirs,
        irradiance_interior: settings.probe_irradiance_texels,
        distance_interior: settings.probe_distance_texels,
        distance_exponent: settings.probe_distance_exponent,
        weights: std::sync::OnceLock::new(),
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
