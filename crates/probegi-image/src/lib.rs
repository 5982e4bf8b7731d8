//! probegi-image: image files (EXR, PNG, animated GIF previews), FLIP comparison and
//! line plots.
//!
//! - [`io`]: reading and writing `.exr` (linear) and `.png` (tone-mapped sRGB) files.
//! - [`compare`]: FLIP between two images and the contact sheet (`probegi compare`).
//! - [`gif`]: looping animated GIF previews (`probegi render --gif`).
//! - [`plot`]: line plots as PNG (`probegi lag`).

#![warn(missing_docs)]

pub mod compare;
pub mod gif;
pub mod io;
pub mod plot;

pub use compare::{FlipResult, compare_files, flip_srgb8, mean_flip_hdr};
pub use gif::AnimatedGif;
pub use io::{ImageError, LoadedImage, check_output_path, read_image, write_image};
