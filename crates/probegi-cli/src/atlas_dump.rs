//! `--dump-atlases DIR`: the DDGI atlases as pictures (`probegi_field::atlas_view`).
//! - `irradiance.exr`: decoded mean radiance per texel (linear); `irradiance.png` tone-mapped.
//! - `distance.exr`: R = mean distance, G = mean squared distance, B = 0 (metres);
//!   `distance.png`: mean distance / the volume's distance clamp, as grey.

use std::path::Path;

use anyhow::{Context, Result};
use probegi_field::atlas_view::{distance_grey_image, distance_moments_image, irradiance_image};
use probegi_field::ddgi_volume::DdgiVolume;

pub fn dump_atlases(dir: &Path, volume: &DdgiVolume) -> Result<()> {
    std::fs::create_dir_all(dir).with_context(|| format!("creating {}", dir.display()))?;
    let irr = irradiance_image(volume);
    let dist_grey = distance_grey_image(volume);
    probegi_image::write_image(&dir.join("irradiance.exr"), &irr)?;
    probegi_image::write_image(&dir.join("irradiance.png"), &irr)?;
    probegi_image::write_image(&dir.join("distance.exr"), &distance_moments_image(volume))?;
    let rgb: Vec<u8> = dist_grey
        .pixels
        .iter()
        .flat_map(|p| {
            let v = probegi_core::color::quantize(p.x);
            [v, v, v]
        })
        .collect();
    probegi_image::io::write_png(&dir.join("distance.png"), dist_grey.width, dist_grey.height, rgb)?;
    Ok(())
}
