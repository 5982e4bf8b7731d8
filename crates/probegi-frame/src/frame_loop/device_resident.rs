//! The frame loop's side of a camera frame kept on the device
//! (`probegi_field::DeviceFrame`, issue 44): the loop hands the device each
//! frame's camera and what happens to its history (the same
//! [`History`](super::accumulation) decision the CPU path takes), and takes
//! back the frames' statistics as they arrive, one or more frames late
//! (`RenderSettings::device_readback_lag_frames`): the means `--sequence`
//! and `--stats` report, the unlit fraction, the black-frame guard, the
//! non-finite count and the screen scheme's probe requests. No pixel comes
//! back unless a caller asks for the image.

use std::cell::RefCell;
use std::ops::ControlFlow::{self, Break, Continue};
use std::time::Instant;

use probegi_core::image::Image;
use probegi_field::device_frame::{DeviceFrame, DeviceFrameInput, DeviceFrameReadout, FrameHistory, FrameLayer};

use super::accumulation::History;
use super::{Frame, FrameLoop};

impl FrameLoop<'_> {
    /// The frame's camera image kept on the device by `df`; `on_frame_done`
    /// composes it only when called (a read-back). `Break` when the device failed.
    pub(super) fn camera_image_kept_on_device(
        &mut self,
        df: &dyn DeviceFrame,
        frame: &Frame<'_>,
        on_frame_done: &mut impl FnMut(u32, &dyn Fn() -> Image),
    ) -> ControlFlow<()> {
        let (f, settings) = (frame.index, &self.settings);
        let Some(set) = self.field.as_ref() else { return Break(()) };
        let t = Instant::now();
        // The device keeps its frame across steppers (a tracer outlives a
        // render): this loop's first frame there starts the sums, as a new
        // `Accumulation` does on the host.
        let history = match self.history(frame) {
            _ if !self.device_image => FrameHistory::Restart,
            History::Accumulate => FrameHistory::Accumulate,
            History::Restart => FrameHistory::Restart,
            History::Reproject { from, settings } => FrameHistory::Reproject {
                from,
                history_frames: settings.temporal_history_frames,
                clip_sigma: settings.temporal_clip_sigma,
            },
        };
        let request_words = if set.wants_probe_requests() {
            set.probe_request_layout().last().copied().unwrap_or(0).div_ceil(32) as u32
        } else {
            0
        };
        let view = set.view();
        let input = DeviceFrameInput {
            camera: frame.camera,
            history,
            field: &view,
            field_on_device: set.field_on_device(),
            area_samples: self.camera_direct.direct_area_samples,
            sky_samples: self.camera_direct.direct_sky_samples,
            second_order: set.volumes().iter().any(|v| v.settings.glossy_second_order),
            frame: f,
            seed: settings.seed,
            request_words,
            readback_lag_frames: settings.device_readback_lag_frames,
        };
        let rendered = df.render_frame(&input);
        drop(view);
        let readouts = match rendered {
            Ok(r) => r,
            Err(e) => {
                self.stats.error = Some(format!("frame {f}: camera frame on the device: {e}"));
                return Break(());
            }
        };
        // Primary rays; the device's shadow and glossy rays are not counted.
        self.stats.rays_traced += settings.width as u64 * settings.height as u64;
        self.device_image = true;
        self.device_pending.push_back((f, frame.scene.has_light_sources()));
        self.take_readouts(readouts);
        *self.pass_totals.entry("camera").or_default() += t.elapsed().as_secs_f64() * 1e3;
        let failed = RefCell::new(None);
        let compose = || {
            let (width, height) = (self.settings.width, self.settings.height);
            let pixels = df.read_layer(FrameLayer::Full).unwrap_or_else(|e| {
                *failed.borrow_mut() = Some(e.to_string());
                Vec::new()
            });
            Image { width, height, pixels }
        };
        on_frame_done(f, &compose);
        if let Some(e) = failed.into_inner() {
            self.stats.error = Some(format!("frame {f}: reading the frame back: {e}"));
            return Break(());
        }
        Continue(())
    }

    /// Books the statistics of frames whose readouts came back, in frame order.
    pub(super) fn take_readouts(&mut self, readouts: Vec<DeviceFrameReadout>) {
        for r in readouts {
            let lights = loop {
                match self.device_pending.pop_front() {
                    Some((f, lights)) if f == r.frame => break lights,
                    Some(_) => continue,
                    None => break false,
                }
            };
            let stats = &mut self.stats;
            stats.frame_means.push(r.mean);
            stats.frame_indirect_means.push(r.indirect_mean);
            stats.frame_unlit_fraction.push(r.unlit as f32 / r.surfaces.max(1) as f32);
            stats.nonfinite_pixels += r.nonfinite;
            for (name, ms) in probegi_field::DEVICE_FRAME_PASSES.iter().zip(&r.gpu_pass_ms) {
                *self.pass_totals.entry(name).or_default() += ms;
            }
            if r.surfaces > 0 && r.mean == glam::Vec3::ZERO && lights {
                stats.black_frames.push(r.frame);
            }
            if let (false, Some(set)) = (r.requests.is_empty(), self.field.as_mut()) {
                // A layout that changed since the frame (a rebuilt set) drops them.
                let _ = set.submit_probe_requests(&r.requests);
            }
        }
    }

    /// After the last frame: the readouts still in flight.
    pub(super) fn drain_device_readouts(&mut self) {
        let Some(df) = self.device_frame_handle() else { return };
        match df.0.device_frame().map(|d| d.drain_readouts()) {
            Some(Ok(r)) => self.take_readouts(r),
            Some(Err(e)) => {
                self.stats.error.get_or_insert(format!("reading the frames' statistics back: {e}"));
            }
            None => {}
        }
    }

    /// The tracer that keeps the frame on its device, when the last frame was kept there.
    fn device_frame_handle(&self) -> Option<probegi_field::ProbeTracerHandle> {
        self.settings.probe_tracer.clone().filter(|_| self.device_image)
    }

    /// The last frame's `layer` from the device, when it holds the frame.
    pub(super) fn device_layer(&self, layer: FrameLayer) -> Option<Result<Image, String>> {
        let h = self.device_frame_handle()?;
        let df = h.0.device_frame()?;
        let (width, height) = (self.settings.width, self.settings.height);
        Some(
            df.read_layer(layer)
                .map(|pixels| Image { width, height, pixels })
                .map_err(|e| format!("reading the frame back: {e}")),
        )
    }
}
