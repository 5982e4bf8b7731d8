//! The per-frame loop of `probegi render`: passes in order, per-pass timings, ray
//! counts, and accumulation of a static scene's direct term over frames.

use std::collections::BTreeMap;
use std::time::Instant;

use glam::Vec3;
use probegi_core::camera::CameraRays;
use probegi_core::image::Image;
use probegi_scene::{RayTracer, Scene};

use crate::direct::{DirectLighting, DirectSettings};
use crate::gbuffer::trace_gbuffer;

/// Which global illumination runs on top of direct light.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum GiMethod {
    /// Direct light only.
    None,
}

#[derive(Clone, Debug)]
pub struct RenderSettings {
    pub width: u32,
    pub height: u32,
    pub frames: u32,
    pub seed: u64,
    pub gi: GiMethod,
    pub direct: DirectSettings,
}

/// Measurements of a render; serialised by the CLI's `--stats`.
#[derive(Clone, Debug, Default)]
pub struct RenderStats {
    pub frames: u32,
    /// Mean wall-clock milliseconds per frame, by pass name.
    pub pass_ms: BTreeMap<&'static str, f64>,
    pub rays_traced: u64,
}

/// Renders `settings.frames` frames and returns the final image. With `GiMethod::None`
/// on a static scene the final image is the running mean of all frames.
pub fn render_frames(
    scene: &Scene,
    tracer: &dyn RayTracer,
    camera: &CameraRays,
    settings: &RenderSettings,
    mut on_frame_done: impl FnMut(u32),
) -> (Image, RenderStats) {
    let direct = DirectLighting::new(scene, tracer, settings.direct);
    let n = settings.width as usize * settings.height as usize;
    let mut frame = vec![Vec3::ZERO; n];
    let mut accum = vec![glam::DVec3::ZERO; n];
    let mut stats = RenderStats::default();
    let mut pass_totals: BTreeMap<&'static str, f64> = BTreeMap::new();
    let frames = settings.frames.max(1);
    for f in 0..frames {
        let t = Instant::now();
        let (gbuffer, rays) = trace_gbuffer(scene, tracer, camera, settings.width, settings.height, f, settings.seed);
        *pass_totals.entry("gbuffer").or_default() += t.elapsed().as_secs_f64() * 1e3;
        stats.rays_traced += rays;

        let t = Instant::now();
        stats.rays_traced += direct.shade_gbuffer(&gbuffer, f, settings.seed, &mut frame);
        *pass_totals.entry("direct").or_default() += t.elapsed().as_secs_f64() * 1e3;

        let t = Instant::now();
        for (a, p) in accum.iter_mut().zip(&frame) {
            *a += p.as_dvec3();
        }
        *pass_totals.entry("accumulate").or_default() += t.elapsed().as_secs_f64() * 1e3;
        on_frame_done(f);
    }
    stats.frames = frames;
    stats.pass_ms = pass_totals.into_iter().map(|(k, v)| (k, v / frames as f64)).collect();
    let pixels = accum.into_iter().map(|a| (a / frames as f64).as_vec3()).collect();
    let image = Image { width: settings.width, height: settings.height, pixels };
    (image, stats)
}
