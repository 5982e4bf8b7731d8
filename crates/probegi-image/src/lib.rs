//! probegi-image: image files (EXR, PNG, animated GIF previews), FLIP comparison and
//! line plots.

pub mod compare;
pub mod gif;
pub mod io;
pub mod plot;

pub use compare::{FlipResult, compare_files, flip_srgb8, mean_flip_hdr};
pub use gif::AnimatedGif;
pub use io::{ImageError, LoadedImage, check_output_path, read_image, write_image};
