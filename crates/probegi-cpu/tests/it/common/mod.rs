//! Helpers shared by the integration tests.

use probegi_core::irradiance_encoding::decode_irradiance;
use probegi_core::probe_atlas::interior_texel_index;
use probegi_field::ddgi_volume::DdgiVolume;

/// Mean of the decoded irradiance atlas over every interior texel of every probe:
/// a field-wide energy figure (mean radiance per texel, summed over RGB, linear).
pub fn field_energy(v: &DdgiVolume) -> f64 {
    let n = v.irradiance.interior;
    let gamma = v.settings.probe_irradiance_gamma;
    let mut sum = 0.0f64;
    for p in 0..v.grid.probe_count() {
        let tile = v.irradiance.tile(p);
        for j in 0..n {
            for i in 0..n {
                let e = decode_irradiance(tile[interior_texel_index(n, i, j)], gamma);
                sum += e.element_sum() as f64;
            }
        }
    }
    sum / (v.grid.probe_count() * (n * n) as usize) as f64
}
