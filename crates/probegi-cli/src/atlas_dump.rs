//! `--dump-atlases DIR`: the DDGI atlases as pictures (seed 000 Fig. 1). Tiles are
//! placed in storage order in rows of `probe_counts.x`, borders included (a
//! tracking window that has scrolled stores its probes rotated; see `probe_grid`).
//! - `irradiance.exr`: decoded mean radiance per texel (linear); `irradiance.png` tone-mapped.
//! - `distance.exr`: R = mean distance, G = mean squared distance, B = 0 (metres);
//!   `distance.png`: mean distance / the volume's distance clamp, as grey.

use std::path::Path;

use anyhow::{Context, Result};
use glam::{Vec2, Vec3};
use probegi_core::image::Image;
use probegi_core::irradiance_encoding::decode_irradiance;
use probegi_core::probe_atlas::{ProbeAtlas, tile_texel_index};
use probegi_field::ddgi_volume::DdgiVolume;

fn atlas_image<T: probegi_core::probe_atlas::Texel>(
    atlas: &ProbeAtlas<T>,
    probes_per_row: u32,
    to_rgb: impl Fn(T) -> Vec3,
) -> Image {
    let t = atlas.tile_size();
    let rows = (atlas.probe_count as u32).div_ceil(probes_per_row);
    let mut img = Image::new(probes_per_row * t, rows * t);
    for p in 0..atlas.probe_count {
        let tile = atlas.tile(p);
        for y in 0..t {
            for x in 0..t {
                let pos = atlas.atlas_texel_position(p, x, y, probes_per_row);
                img.set(pos.x, pos.y, to_rgb(tile[tile_texel_index(atlas.interior, x, y)]));
            }
        }
    }
    img
}

pub fn dump_atlases(dir: &Path, volume: &DdgiVolume) -> Result<()> {
    std::fs::create_dir_all(dir).with_context(|| format!("creating {}", dir.display()))?;
    let per_row = volume.grid.probe_counts.x;
    let gamma = volume.settings.probe_irradiance_gamma;
    let irr = atlas_image(&volume.irradiance, per_row, |e: Vec3| decode_irradiance(e, gamma));
    let clamp = volume.distance_clamp_m();
    let dist = atlas_image(&volume.distance, per_row, |m: Vec2| Vec3::new(m.x, m.y, 0.0));
    let dist_grey = atlas_image(&volume.distance, per_row, |m: Vec2| Vec3::splat(m.x / clamp));
    probegi_image::write_image(&dir.join("irradiance.exr"), &irr)?;
    probegi_image::write_image(&dir.join("irradiance.png"), &irr)?;
    probegi_image::write_image(&dir.join("distance.exr"), &dist)?;
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
