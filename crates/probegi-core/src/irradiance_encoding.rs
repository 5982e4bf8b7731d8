//! The perceptual encoding of irradiance texels (seed 004 §4.2, Listings 1–2): the
//! one place it is defined. The blend stores `mean^(1/γ)` per channel
//! ([`encode_irradiance`]); the query blends `e^(γ/2)` ([`decode_irradiance_half`])
//! across the cage and squares the normalised sum, which is Listing 2's order of
//! operations; dumps and visualisations read `e^γ` ([`decode_irradiance`]).
//! γ = `probe_irradiance_gamma` (default 5).

use glam::Vec3;

/// `mean^(1/γ)` per channel; negative means are clamped to 0 first.
pub fn encode_irradiance(mean: Vec3, gamma: f32) -> Vec3 {
    let m = mean.max(Vec3::ZERO);
    let inv = 1.0 / gamma;
    Vec3::new(m.x.powf(inv), m.y.powf(inv), m.z.powf(inv))
}

/// `e^γ` per channel: the mean radiance a texel holds.
pub fn decode_irradiance(encoded: Vec3, gamma: f32) -> Vec3 {
    let e = encoded.max(Vec3::ZERO);
    Vec3::new(e.x.powf(gamma), e.y.powf(gamma), e.z.powf(gamma))
}

/// `e^(γ/2)` per channel, the partial decode the query blends (seed 004 Listing 2).
/// γ = 5 takes the exact `e²·√e` path instead of `powf`.
pub fn decode_irradiance_half(encoded: Vec3, gamma: f32) -> Vec3 {
    let e = encoded;
    let half = 0.5 * gamma;
    if half == 2.5 {
        e * e * Vec3::new(e.x.sqrt(), e.y.sqrt(), e.z.sqrt())
    } else {
        Vec3::new(e.x.powf(half), e.y.powf(half), e.z.powf(half))
    }
}

/// The last step of the query's decode: the square of the normalised half-decoded
/// blend, the mean radiance of the cage.
pub fn finish_half_decode(blended_half: Vec3) -> Vec3 {
    blended_half * blended_half
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn encode_and_both_decodes_round_trip() {
        for gamma in [1.0, 2.2, 5.0] {
            for m in [Vec3::new(0.0, 0.5, 3.0), Vec3::splat(1e-4), Vec3::splat(200.0)] {
                let e = encode_irradiance(m, gamma);
                assert!((decode_irradiance(e, gamma) - m).abs().max_element() <= 1e-4 * m.max_element().max(1.0));
                let h = finish_half_decode(decode_irradiance_half(e, gamma));
                assert!((h - m).abs().max_element() <= 1e-4 * m.max_element().max(1.0), "{gamma} {m} {h}");
            }
        }
        assert_eq!(encode_irradiance(Vec3::splat(-1.0), 5.0), Vec3::ZERO);
    }
}
