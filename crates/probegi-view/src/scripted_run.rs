//! The headless run (`probegi view --headless`): frame by frame the script's
//! events reach the fly camera (a keyframed camera plays until the input
//! first moves it), the camera moves, and the field updates and
//! the frame renders through `probegi_frame::frame_loop::FrameStepper`, the same
//! stepper `probegi render` drives, on the CPU or (with the settings' probe
//! tracer) on the GPU. The scene clock is the frame index; each frame is
//! `frame_dt_s` of fly time, fixed so a run is the same on every machine.

use probegi_core::camera::Camera;
use probegi_core::image::Image;
use probegi_frame::frame_loop::{RenderOutput, RenderSettings};
use probegi_scene::{RayTracer, Scene};

use crate::fly_camera::FlyCamera;
use crate::input_script::InputScript;
use crate::view_session::ViewSession;

/// What a scripted run does.
#[derive(Clone, Debug)]
pub struct ScriptedRun<'s> {
    /// The timed input.
    pub script: &'s InputScript,
    /// Frames to run (`--exit-after-frames`).
    pub frames: u32,
    /// Fly time per frame, seconds (1/60).
    pub frame_dt_s: f32,
    /// The fly camera's starting speed, metres per second.
    pub fly_speed_m_per_s: f32,
    /// A keyframed camera's path, one camera per frame (empty: none). The run
    /// plays it until the input first moves the camera, which then flies on
    /// from where the path was; R returns to the path.
    pub camera_path: Vec<Camera>,
}

/// What a scripted run leaves.
pub struct ScriptedOutput {
    /// The last frame's image.
    pub image: Image,
    /// The fly camera after the last frame.
    pub camera: FlyCamera,
    /// The render's statistics and field, as `probegi render` leaves them.
    pub render: RenderOutput,
    /// Wall milliseconds of each frame (input, field update, camera frame).
    pub frame_ms: Vec<f64>,
    /// Of each frame's, the milliseconds the host did not spend blocked on
    /// the device (`ProbeBatchTracer::device_wait_ms`; the whole frame on the CPU).
    pub host_ms: Vec<f64>,
}

/// Median, 95th percentile and largest of `ms` (nearest rank; zeros when empty).
pub fn frame_time_percentiles(ms: &[f64]) -> [f64; 3] {
    if ms.is_empty() {
        return [0.0; 3];
    }
    let mut v = ms.to_vec();
    v.sort_by(f64::total_cmp);
    let rank = |p: f64| v[((p * v.len() as f64).ceil() as usize).clamp(1, v.len()) - 1];
    [rank(0.5), rank(0.95), v[v.len() - 1]]
}

/// Runs `run` over `scene` with `settings` (size, seed, GI, probe tracer; its
/// `frames` and `camera_path` are not read), the fly camera starting at
/// `camera`; `on_frame` sees each frame's session, and reads its image only
/// if it needs it (`ViewSession::image`: a device that keeps the frame reads
/// nothing back otherwise). An error names the frame and the pass that failed.
pub fn run_scripted(
    scene: &Scene,
    tracer: &dyn RayTracer,
    camera: &Camera,
    settings: &RenderSettings,
    run: &ScriptedRun<'_>,
    mut on_frame: impl FnMut(u32, &ViewSession<'_>) -> Result<(), String>,
) -> Result<ScriptedOutput, String> {
    let mut session = ViewSession::new(scene, tracer, camera, settings, run.fly_speed_m_per_s, run.camera_path.clone());
    let mut events = run.script.events.iter().peekable();
    let frames = run.frames.max(1) as usize;
    let (mut frame_ms, mut host_ms) = (Vec::with_capacity(frames), Vec::with_capacity(frames));
    let waited_ms = || settings.probe_tracer.as_ref().and_then(|h| h.0.device_wait_ms()).unwrap_or(0.0);
    for f in 0..frames as u32 {
        let (t, waited) = (std::time::Instant::now(), waited_ms());
        while let Some((_, e)) = events.next_if(|(at, _)| *at <= f) {
            session.apply(*e);
        }
        session.advance(run.frame_dt_s)?;
        let ms = t.elapsed().as_secs_f64() * 1e3;
        frame_ms.push(ms);
        host_ms.push((ms - (waited_ms() - waited)).max(0.0));
        on_frame(f, &session)?;
    }
    let image = session.image()?;
    let (render, camera) = session.finish();
    Ok(ScriptedOutput { image, camera, render, frame_ms, host_ms })
}

#[cfg(test)]
mod tests {
    use super::frame_time_percentiles;

    #[test]
    fn percentiles_are_nearest_rank() {
        let ms: Vec<f64> = (1..=100).map(f64::from).collect();
        assert_eq!(frame_time_percentiles(&ms), [50.0, 95.0, 100.0]);
        assert_eq!(frame_time_percentiles(&[3.0]), [3.0, 3.0, 3.0]);
        assert_eq!(frame_time_percentiles(&[]), [0.0; 3]);
    }
}
