//! The DDGI atlases as pictures (seed 000 Fig. 1), for `probegi render
//! --dump-atlases` and the viewer's atlas views. Tiles are placed in storage
//! order in rows of `probe_counts.x`, borders included (a tracking window
//! that has scrolled stores its probes rotated; see `probe_grid`).

use glam::{Vec2, Vec3};
use probegi_core::image::Image;
use probegi_core::irradiance_encoding::decode_irradiance;
use probegi_core::probe_atlas::{ProbeAtlas, Texel, tile_texel_index};

use crate::ddgi_volume::DdgiVolume;

/// `atlas` as an image, each texel through `to_rgb`.
fn atlas_image<T: Texel>(atlas: &ProbeAtlas<T>, probes_per_row: u32, to_rgb: impl Fn(T) -> Vec3) -> Image {
    let t = atlas.tile_size();
    let rows = (atlas.probe_count as u32).div_ceil(probes_per_row.max(1));
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

/// The irradiance atlas, decoded to linear mean radiance per texel.
pub fn irradiance_image(volume: &DdgiVolume) -> Image {
    let gamma = volume.settings.probe_irradiance_gamma;
    atlas_image(&volume.irradiance, volume.grid.probe_counts.x, |e: Vec3| decode_irradiance(e, gamma))
}

/// The distance atlas: R = mean distance, G = mean squared distance, B = 0 (metres).
pub fn distance_moments_image(volume: &DdgiVolume) -> Image {
    atlas_image(&volume.distance, volume.grid.probe_counts.x, |m: Vec2| Vec3::new(m.x, m.y, 0.0))
}

/// The distance atlas as grey: mean distance over the volume's distance clamp.
pub fn distance_grey_image(volume: &DdgiVolume) -> Image {
    let clamp = volume.distance_clamp_m();
    atlas_image(&volume.distance, volume.grid.probe_counts.x, |m: Vec2| Vec3::splat(m.x / clamp))
}
