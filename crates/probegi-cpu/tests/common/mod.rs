//! Helpers shared by the integration tests.

use probegi_cpu::ddgi::DdgiVolume;

/// Mean of the decoded irradiance atlas over every interior texel of every probe:
/// a field-wide energy figure (mean radiance per texel, summed over RGB, linear).
pub fn field_energy(v: &DdgiVolume) -> f64 {
    let n = v.irradiance.interior as usize;
    let s = n + 2;
    let gamma = v.settings.probe_irradiance_gamma;
    let mut sum = 0.0f64;
    for p in 0..v.grid.probe_count() {
        let tile = v.irradiance.tile(p);
        for j in 1..=n {
            for i in 1..=n {
                let e = tile[j * s + i];
                sum += (e.x.powf(gamma) + e.y.powf(gamma) + e.z.powf(gamma)) as f64;
            }
        }
    }
    sum / (v.grid.probe_count() * n * n) as f64
}
