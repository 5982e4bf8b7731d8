//! Animated GIF previews (`probegi render --gif`): each frame tone-mapped like the
//! PNG output (ACES + sRGB), quantised to a 256-colour palette per frame, looping.
//! Written to a temporary file and renamed on [`AnimatedGif::finish`], so an
//! interrupted render never leaves a truncated preview under the real name.

use std::fs::File;
use std::io::BufWriter;
use std::path::{Path, PathBuf};

use image::codecs::gif::{GifEncoder, Repeat};
use image::{Delay, Frame, RgbaImage};
use probegi_core::image::Image;

use probegi_core::color::tonemap_rgb8;

use crate::io::{ImageError, check_extension, check_finite, io_err, temp_path};

/// A looping GIF preview being written, one frame at a time.
pub struct AnimatedGif {
    path: PathBuf,
    tmp: PathBuf,
    /// `None` once finished.
    encoder: Option<GifEncoder<BufWriter<File>>>,
    delay: Delay,
    frames: u32,
}

impl AnimatedGif {
    /// Starts a looping GIF at `frames_per_second` (GIF stores delays in 10 ms units).
    pub fn create(path: &Path, frames_per_second: f32) -> Result<Self, ImageError> {
        check_extension(path, "gif")?;
        if !(frames_per_second.is_finite() && frames_per_second > 0.0) {
            return Err(io_err(path, format!("frames per second must be positive, got {frames_per_second}")));
        }
        if let Some(dir) = path.parent().filter(|d| !d.as_os_str().is_empty()) {
            std::fs::create_dir_all(dir).map_err(|e| io_err(path, e))?;
        }
        let tmp = temp_path(path);
        let file = File::create(&tmp).map_err(|e| io_err(path, e))?;
        // Speed 10: NeuQuant's default trade-off between palette quality and time.
        let mut encoder = GifEncoder::new_with_speed(BufWriter::new(file), 10);
        encoder.set_repeat(Repeat::Infinite).map_err(|e| io_err(path, e))?;
        let delay_ms = (1000.0 / frames_per_second).round().max(10.0) as u32;
        Ok(Self {
            path: path.to_path_buf(),
            tmp,
            encoder: Some(encoder),
            delay: Delay::from_numer_denom_ms(delay_ms, 1),
            frames: 0,
        })
    }

    /// Appends a frame; a frame with a non-finite or negative pixel is refused.
    pub fn push(&mut self, img: &Image) -> Result<(), ImageError> {
        check_finite(&self.path, img)?;
        let rgba: Vec<u8> = img
            .pixels
            .iter()
            .flat_map(|p| {
                let [r, g, b] = tonemap_rgb8(*p);
                [r, g, b, 255]
            })
            .collect();
        let buf =
            RgbaImage::from_raw(img.width, img.height, rgba).ok_or_else(|| io_err(&self.path, "bad frame size"))?;
        let encoder = self.encoder.as_mut().ok_or_else(|| io_err(&self.path, "already finished"))?;
        encoder.encode_frame(Frame::from_parts(buf, 0, 0, self.delay)).map_err(|e| io_err(&self.path, e))?;
        self.frames += 1;
        Ok(())
    }

    /// Closes the file and moves it to its real name.
    pub fn finish(mut self) -> Result<u32, ImageError> {
        // Dropping the encoder writes the trailer and flushes the file.
        drop(self.encoder.take());
        crate::io::commit(&self.tmp, &self.path, Ok(()))?;
        Ok(self.frames)
    }
}

impl Drop for AnimatedGif {
    fn drop(&mut self) {
        // Unfinished (an error elsewhere): leave no partial file behind.
        if self.encoder.take().is_some() {
            std::fs::remove_file(&self.tmp).ok();
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use glam::Vec3;

    #[test]
    fn frames_round_trip_through_a_gif_decoder() {
        let dir = std::env::temp_dir().join(format!("probegi-gif-{}", std::process::id()));
        let path = dir.join("t.gif");
        let mut gif = AnimatedGif::create(&path, 25.0).expect("create");
        for k in 0..3 {
            let mut img = Image::new(8, 4);
            img.pixels.iter_mut().for_each(|p| *p = Vec3::splat(k as f32 * 0.5));
            gif.push(&img).expect("push");
        }
        assert_eq!(gif.finish().expect("finish"), 3);
        use image::AnimationDecoder;
        let file = std::io::BufReader::new(File::open(&path).expect("open"));
        let frames =
            image::codecs::gif::GifDecoder::new(file).expect("decode").into_frames().collect_frames().expect("frames");
        assert_eq!(frames.len(), 3);
        assert_eq!(frames[0].delay().numer_denom_ms(), (40, 1));
        // Brighter radiance, brighter pixels.
        let lum = |f: &Frame| f.buffer().get_pixel(3, 2)[1];
        assert!(lum(&frames[0]) < lum(&frames[1]) && lum(&frames[1]) < lum(&frames[2]));
        std::fs::remove_dir_all(&dir).ok();
    }

    #[test]
    fn a_frame_with_inf_is_refused_and_an_unfinished_gif_leaves_nothing() {
        let dir = std::env::temp_dir().join(format!("probegi-gif-inf-{}", std::process::id()));
        let path = dir.join("t.gif");
        {
            let mut gif = AnimatedGif::create(&path, 25.0).expect("create");
            gif.push(&Image::new(4, 4)).expect("a finite frame");
            let mut bad = Image::new(4, 4);
            bad.pixels[5] = Vec3::new(f32::INFINITY, 0.0, 0.0);
            let e = gif.push(&bad).expect_err("Inf").to_string();
            assert!(e.contains("(1, 1)") && e.contains("t.gif"), "{e}");
        }
        let left: Vec<_> = std::fs::read_dir(&dir).map(|d| d.flatten().collect()).unwrap_or_default();
        assert!(left.is_empty(), "{left:?}");
        assert!(AnimatedGif::create(&dir.join("x.png"), 25.0).is_err(), "GIF data under .png");
        std::fs::remove_dir_all(&dir).ok();
    }

    #[test]
    fn bad_rate_names_the_file() {
        let e = AnimatedGif::create(Path::new("x/y.gif"), 0.0).err().expect("error").to_string();
        assert!(e.contains("y.gif"), "{e}");
    }
}
