//! What `render` and `reference` write: every output path checked before a
//! render starts, the `--sequence` frames (PNG, `--sequence-exr` EXR) and the
//! `--gif` written as frames finish and removed again if the render fails, the
//! final image (EXR or PNG by extension), the `--dump-atlases` pictures and the
//! `--stats` JSON.

use std::path::{Path, PathBuf};

use anyhow::{Context, Result, bail};
use probegi_core::image::Image;
use probegi_field::ddgi_field_set::DdgiFieldSet;
use probegi_frame::frame_loop::RenderStats;
use probegi_scene::{BvhTracer, Scene};

use crate::args::RenderArgs;
use crate::atlas_dump;
use crate::gpu_backend::WgpuProbeTracer;

/// Every output of a render checked before it starts, so that a long render
/// does not fail at its end (`probegi_image::check_output_path`).
pub fn check_render_outputs(args: &RenderArgs) -> Result<()> {
    probegi_image::check_output_path(&args.out, true)?;
    if let Some(p) = &args.stats {
        probegi_image::check_output_path(p, false)?;
    }
    if let Some(p) = &args.gif {
        probegi_image::check_output_path(p, false)?;
    }
    if let Some(p) = &args.ao {
        probegi_image::check_output_path(p, true)?;
    }
    for dir in [&args.sequence, &args.dump_atlases].into_iter().flatten() {
        if dir.exists() && !dir.is_dir() {
            bail!("{}: exists and is not a directory", dir.display());
        }
        probegi_image::check_output_path(&dir.join("frame-0000.png"), true)?;
    }
    Ok(())
}

/// The per-frame outputs of a render, `--sequence` and `--gif`, written as each
/// frame finishes. The first error stops them; `finish` then removes what this
/// run wrote, so that no partial sequence looks complete.
pub struct FrameOutputs<'a> {
    args: &'a RenderArgs,
    gif: Option<probegi_image::AnimatedGif>,
    sequence_error: Option<probegi_image::ImageError>,
    sequence_written: Vec<PathBuf>,
}

impl<'a> FrameOutputs<'a> {
    /// Creates the `--sequence` directory and starts the `--gif`.
    pub fn create(args: &'a RenderArgs) -> Result<Self> {
        if let Some(dir) = &args.sequence {
            std::fs::create_dir_all(dir).with_context(|| format!("creating {}", dir.display()))?;
        }
        let gif = match &args.gif {
            Some(path) => Some(probegi_image::AnimatedGif::create(path, args.gif_fps)?),
            None => None,
        };
        Ok(Self { args, gif, sequence_error: None, sequence_written: Vec::new() })
    }

    /// Writes frame `f`; `image` is only called when there is something to write.
    pub fn push(&mut self, f: u32, image: &dyn Fn() -> Image) {
        if self.sequence_error.is_some() || (self.args.sequence.is_none() && self.gif.is_none()) {
            return;
        }
        let img = image();
        if let Some(dir) = &self.args.sequence {
            let mut names = vec![format!("frame-{f:04}.png")];
            if self.args.sequence_exr {
                names.push(format!("frame-{f:04}.exr"));
            }
            for path in names.into_iter().map(|n| dir.join(n)) {
                match probegi_image::write_image(&path, &img) {
                    Ok(()) => self.sequence_written.push(path),
                    Err(e) => {
                        self.sequence_error = Some(e);
                        break;
                    }
                }
            }
        }
        if let (Some(g), None) = (self.gif.as_mut(), &self.sequence_error) {
            self.sequence_error = g.push(&img).err();
        }
    }

    /// After the last frame: the first write error, else the render's failure
    /// (`render_failure`), removes this run's frames and fails; otherwise the
    /// GIF is completed.
    pub fn finish(self, stats: &RenderStats, allow_black_frames: bool, screen_space_gi: bool) -> Result<()> {
        let failure = match self.sequence_error {
            Some(e) => Some(anyhow::Error::new(e).context(
                "writing the --sequence / --gif frames (this run's frames were removed); a non-finite pixel \
                 usually comes from a material, texture or light with huge or non-finite values",
            )),
            None => render_failure(stats, allow_black_frames, screen_space_gi),
        };
        if let Some(e) = failure {
            // No partial sequence that looks complete: this run's frames go too, and
            // the unfinished GIF's temporary file goes when `gif` drops.
            for path in &self.sequence_written {
                std::fs::remove_file(path).ok();
            }
            return Err(e);
        }
        if let Some(g) = self.gif {
            g.finish()?;
        }
        Ok(())
    }
}

/// Why a finished render must not be written: the frame loop stopped early,
/// or frames came out all black though the scene has light sources and the
/// camera sees surfaces with a diffuse albedo (`RenderStats::black_frames`).
/// Under screen-space GI (`--gi sh`) such a frame is the method's known
/// limit, not a bug: it gathers indirect light only from pixels the frame
/// lights directly (seed 001 §7.3), and a black frame has none (a camera
/// looking up at the Cornell box's ceiling, whose light faces away).
fn render_failure(stats: &RenderStats, allow_black_frames: bool, screen_space_gi: bool) -> Option<anyhow::Error> {
    if let Some(e) = &stats.error {
        return Some(anyhow::anyhow!("render stopped: {e}; nothing was written"));
    }
    if stats.black_frames.is_empty() || allow_black_frames {
        return None;
    }
    let frames = if stats.black_frames.len() == 1 { "" } else { "s" };
    if screen_space_gi {
        return Some(anyhow::anyhow!(
            "frame{frames} {:?} came out all black: no pixel of this view is lit directly, and --gi sh gathers \
             indirect light only from directly lit pixels on the screen (seed 001 §7.3: off-screen surfaces do \
             not contribute), so every surface it sees, lit only indirectly, stays black; nothing was written. \
             --gi ddgi traces the whole scene; a view that sees a directly lit surface works with --gi sh; \
             --allow-black-frames accepts such frames",
            stats.black_frames
        ));
    }
    Some(anyhow::anyhow!(
        "frame{} {:?} came out all black although the scene has light sources and the camera sees diffuse \
         surfaces: this is almost always a bug (please report it with the scene); nothing was written. \
         --allow-black-frames accepts such frames (a view where every light is hidden)",
        if stats.black_frames.len() == 1 { "" } else { "s" },
        stats.black_frames
    ))
}

/// Writes a rendered image; a non-finite pixel (which `write_image` refuses, naming
/// it) gets a hint at its usual causes.
pub fn write_radiance(path: &Path, image: &Image) -> Result<()> {
    probegi_image::write_image(path, image).map_err(|e| {
        let hint = matches!(e, probegi_image::ImageError::NonFinite { .. }).then_some(
            "; check the scene's materials (Kd, Ke, emissive factors), textures and light intensities for huge or \
             non-finite values",
        );
        anyhow::anyhow!("{e}{}", hint.unwrap_or(""))
    })
}

/// `--dump-atlases DIR`: the atlases of every volume of `set`.
pub fn dump_set_atlases(dir: &Path, set: &DdgiFieldSet) -> Result<()> {
    for (i, volume) in set.volumes().iter().enumerate() {
        // One volume: its atlases in DIR as before; several: DIR/volume-I each.
        let d = if set.volumes().len() == 1 { dir.to_path_buf() } else { dir.join(format!("volume-{i}")) };
        atlas_dump::dump_atlases(&d, volume)?;
    }
    eprintln!("wrote atlases to {}", dir.display());
    Ok(())
}

/// What a finished render's `--stats` reports from.
pub struct RenderRun<'a> {
    pub args: &'a RenderArgs,
    pub scene: &'a Scene,
    pub bvh: &'a BvhTracer,
    pub gpu: Option<&'a WgpuProbeTracer>,
    pub image: &'a Image,
    pub stats: &'a RenderStats,
}

/// Writes the `--stats` JSON of a render to `path`.
pub fn write_render_stats(path: &Path, run: &RenderRun<'_>) -> Result<()> {
    write_text(path, &serde_json::to_string_pretty(&render_stats_json(run)?)?)
}

/// The `--stats` JSON of a render.
fn render_stats_json(run: &RenderRun<'_>) -> Result<serde_json::Value> {
    Ok(serde_json::json!({
        "backend": format!("{:?}", run.args.backend).to_lowercase(),
        "adapter": run.gpu.map(|g| g.adapter_name().to_string()),
        "probe_shade_on": run.gpu.map(|g| if g.shades() { "gpu" } else { "cpu" }),
        // --show-probes draws on the CPU's G-buffer, so its camera frame is the CPU's.
        "camera_on": if run.gpu.is_some_and(|g| g.renders_camera()) && !run.args.show_probes { "gpu" } else { "cpu" },
        "frames": run.stats.frames,
        "pass_ms": run.stats.pass_ms,
        "rays_traced": run.stats.rays_traced,
        "width": run.image.width,
        "height": run.image.height,
        "triangles": run.scene.drawn_triangle_count(),
        "stored_triangles": run.scene.stored_triangle_count(),
        "instances": run.scene.instances.len(),
        "bvh_build_ms": run.bvh.build_time.as_secs_f64() * 1e3,
        "probes": run.stats.probes,
        "rays_per_frame": run.stats.rays_per_frame,
        "probe_rays_traced": run.stats.probe_rays_traced,
        "field_update_ms": run.stats.field_update_ms,
        "field_update_mrays_per_s": run.stats.field_update_mrays_per_s,
        "probe_states": run.stats.probe_states,
        "active_probes": run.stats.active_probes,
        "volumes": run.stats.volumes,
        "batch_rays": run.stats.batch_rays,
        "batch_rays_per_volume": run.stats.batch_rays_per_volume,
        "probes_scrolled_in": run.stats.probes_scrolled_in,
        "probes_woken": run.stats.probes_woken,
        "frame_means": run.stats.frame_means.iter().map(|m| [m.x, m.y, m.z]).collect::<Vec<_>>(),
        "frame_indirect_means": run.stats.frame_indirect_means.iter().map(|m| [m.x, m.y, m.z]).collect::<Vec<_>>(),
        "frame_unlit_fraction": run.stats.frame_unlit_fraction,
        // Rays answered without a full BVH walk (probegi_scene::bvh_walk): the
        // ray rule's misses and walks cut short, per backend.
        "trace_guards_cpu": run.bvh.trace_guard_counts(),
        "nonfinite_pixels": run.stats.nonfinite_pixels,
        "trace_guards_gpu": run.gpu.map(|g| g.bvh.trace_guard_counts(&g.ctx)).transpose()?,
    }))
}

fn write_text(path: &Path, text: &str) -> Result<()> {
    if let Some(dir) = path.parent().filter(|d| !d.as_os_str().is_empty()) {
        std::fs::create_dir_all(dir).with_context(|| format!("creating {}", dir.display()))?;
    }
    std::fs::write(path, text).with_context(|| format!("writing {}", path.display()))
}
