//! The camera frame kept on the device, start to finish (issue 44): the
//! camera pass (`camera_frame`), then `shaders/device_frame.wgsl`'s resolve
//! (accumulation, or a moved camera's temporal filter), compose (+ tone map to
//! RGBA8) and statistics passes, all recorded into one submission over images
//! allocated once per size. The host gets 48 bytes of statistics, the
//! screen scheme's request words and (where the device has timestamp
//! queries) 64 bytes of pass timestamps a frame, through a ring of staging buffers
//! mapped without waiting ([`FrameReadbackRing`]); pixels come back only when
//! asked ([`GpuFrame::read_layer`], [`GpuFrame::read_rgba8`]).
//!
//! Like kajiya's frame state, [`GpuFrame`] owns what lives across frames (the
//! camera images, the two history buffers it ping-pongs between, the
//! statistics and the ring); each frame's handles (bind groups, the encoder)
//! are made per frame.
//!
//! The CPU frame loop is the reference: each WGSL function names the Rust one
//! it mirrors (`probegi_frame::frame_loop::accumulation`).
//!
//! *Deviations:* the history holds running means in f32 where the CPU holds
//! f64 sums (the same arithmetic to rounding: a mean keeps f32's relative
//! precision however many frames it has seen); the frame's means are a tree
//! sum in f32 (relative error about log2(pixels) · 2⁻²⁴, against the CPU's f64).

use std::collections::VecDeque;
use std::sync::Arc;
use std::sync::atomic::{AtomicBool, Ordering};

use bytemuck::{Pod, Zeroable};
use glam::Vec3;
use probegi_core::camera::CameraRays;
use probegi_field::device_frame::{DEVICE_FRAME_PASSES, DeviceFrameReadout, FrameHistory, FrameLayer};

use crate::bvh_trace::GpuBvh;
use crate::camera_frame::{CameraFrame, CameraParams, CameraTargets, GpuCameraPass, camera_texels};
use crate::ddgi_query::GpuDdgiField;
use crate::gpu_context::{GpuContext, GpuError};
use crate::gpu_scene::GpuScene;
use crate::shader_registry::DEVICE_FRAME;

/// A camera in `device_frame.wgsl`'s `FrameCamera` layout.
#[repr(C)]
#[derive(Clone, Copy, Debug, Default, Pod, Zeroable)]
struct FrameCamera {
    origin: [f32; 4],
    forward: [f32; 4],
    right: [f32; 4],
    up: [f32; 4],
}

impl FrameCamera {
    fn of(c: &CameraRays) -> Self {
        let [origin, forward, right, up] = camera_texels(c);
        Self { origin, forward, right, up }
    }
}

/// The frame passes' uniform block; must match `FrameParams` in `device_frame.wgsl`.
#[repr(C)]
#[derive(Clone, Copy, Debug, Default, Pod, Zeroable)]
struct FrameParams {
    to: FrameCamera,
    from: FrameCamera,
    /// Mode (0 accumulate, 1 restart, 2 reproject, 3 no history), history frames − 1, the
    /// RGBA8 layer (0 full, 1 direct, 2 indirect), `frame_compose`'s workgroups.
    info: [u32; 4],
    /// x: the direct history's clip, standard deviations.
    clip: [f32; 4],
    /// x: the RGBA8 image's row pitch in pixels (rows padded to 256 bytes, as
    /// a copy into a texture wants them).
    layout: [u32; 4],
}
const _: () = assert!(std::mem::size_of::<FrameParams>() == 176);

/// The RGBA8 image's row pitch in pixels: `width` rounded up to 256 bytes.
fn rgba8_pitch(width: u32) -> u32 {
    width.div_ceil(64) * 64
}

/// `FrameStats` in `device_frame.wgsl`: the means, then the counts.
#[repr(C)]
#[derive(Clone, Copy, Debug, Default, Pod, Zeroable)]
struct FrameStatsBlock {
    mean: [f32; 4],
    indirect_mean: [f32; 4],
    /// Surfaces, unlit surfaces, non-finite pixels, unused.
    counts: [u32; 4],
}
const STATS_BYTES: u64 = std::mem::size_of::<FrameStatsBlock>() as u64;
/// Begin and end timestamps of the frame's passes (`DEVICE_FRAME_PASSES`), 8 bytes each.
const TIMESTAMP_BYTES: u64 = DEVICE_FRAME_PASSES.len() as u64 * 16;
const _: () = assert!(STATS_BYTES == 48);

/// Texels (16 bytes) a pixel of the history holds (see `device_frame.wgsl`).
const HISTORY_TEXELS: u64 = 4;

/// Device memory a `width` × `height` frame keeps (the camera images, two
/// histories, the RGBA8 image and the partial sums), for a caller's budget.
pub fn frame_bytes(width: u32, height: u32) -> u64 {
    let n = width as u64 * height as u64;
    let rgba8 = rgba8_pitch(width) as u64 * height as u64 * 4;
    n * 16 * (3 + 1 + 2 * HISTORY_TEXELS) + rgba8 + width.div_ceil(8) as u64 * height.div_ceil(8) as u64 * 32
}

/// The frame's images on the device, allocated once per size.
struct FrameImages {
    width: u32,
    height: u32,
    camera_params: wgpu::Buffer,
    frame_params: wgpu::Buffer,
    direct: wgpu::Buffer,
    irradiance: wgpu::Buffer,
    /// The two histories; `current` holds the last frame's.
    history: [wgpu::Buffer; 2],
    current: usize,
    /// Bind groups reading history `i` and writing `1 − i`.
    bind_groups: [wgpu::BindGroup; 2],
    stats: wgpu::Buffer,
    rgba8: wgpu::Buffer,
    /// The RGBA8 image as a texture on the device (sRGB-encoded), for a window
    /// on the same device ([`GpuFrame::present`]); made with the first.
    texture: Option<wgpu::Texture>,
    requests: wgpu::Buffer,
    request_words: u32,
    /// No frame has run at this size yet: the first one restarts the sums.
    fresh: bool,
}

/// One staging buffer of the ring: the frame it holds, and whether its map has
/// completed.
struct ReadbackSlot {
    buffer: wgpu::Buffer,
    /// The submission that fills it.
    submission: wgpu::SubmissionIndex,
    frame: u32,
    request_words: u32,
    /// Timestamps follow the requests; ms per tick (0: none).
    tick_ms: f64,
    mapped: Arc<AtomicBool>,
}

/// A small ring of staging buffers for the frames' statistics and requests,
/// read one or more frames late without waiting (a slot is waited for only
/// when every slot is still in flight, or when asked to drain).
#[derive(Default)]
pub struct FrameReadbackRing {
    free: Vec<wgpu::Buffer>,
    in_flight: VecDeque<ReadbackSlot>,
}

/// The most staging buffers [`FrameReadbackRing::take`] makes ahead for a
/// read-back lag (a larger lag, which nothing bounds, grows the ring as
/// frames need more).
const READBACK_RING_MAX: usize = 8;

impl FrameReadbackRing {
    /// A staging buffer for `words` request words, reused when one of the size
    /// is free. Where none is, the ring makes at once every buffer that a lag
    /// of `lag_frames` (up to [`READBACK_RING_MAX`]) can hold in flight
    /// ([`Self::collect`] keeps at most `lag_frames` and this frame takes one
    /// more) and lets go of free ones of other sizes: how many frames' maps are still pending depends on the
    /// device's timing, so a ring grown one buffer at a time would make one
    /// in whichever steady frame first found every buffer in flight.
    fn take(&mut self, ctx: &GpuContext, words: u32, lag_frames: usize) -> wgpu::Buffer {
        let size = STATS_BYTES + 4 * words as u64 + if ctx.timestamps { TIMESTAMP_BYTES } else { 0 };
        if let Some(i) = self.free.iter().position(|b| b.size() == size) {
            return self.free.swap_remove(i);
        }
        self.free.clear();
        let in_flight = self.in_flight.iter().filter(|s| s.buffer.size() == size).count();
        let make = || {
            ctx.create_buffer(&wgpu::BufferDescriptor {
                label: Some("frame readback"),
                size,
                usage: wgpu::BufferUsages::MAP_READ | wgpu::BufferUsages::COPY_DST,
                mapped_at_creation: false,
            })
        };
        self.free.extend((in_flight + 1..=lag_frames.min(READBACK_RING_MAX)).map(|_| make()));
        make()
    }

    /// Starts mapping `buffer` (filled by `submission`) for frame `frame`.
    fn push(
        &mut self,
        buffer: wgpu::Buffer,
        submission: wgpu::SubmissionIndex,
        frame: u32,
        request_words: u32,
        tick_ms: f64,
    ) {
        let mapped = Arc::new(AtomicBool::new(false));
        let flag = mapped.clone();
        buffer.slice(..).map_async(wgpu::MapMode::Read, move |r| flag.store(r.is_ok(), Ordering::Release));
        self.in_flight.push_back(ReadbackSlot { buffer, submission, frame, request_words, tick_ms, mapped });
    }

    /// The readouts whose maps have completed, oldest first (in frame order:
    /// a later one waits for the earlier), after a non-blocking poll; with
    /// `keep` slots at most left in flight (waiting for the oldest otherwise).
    fn collect(&mut self, ctx: &GpuContext, keep: usize) -> Result<Vec<DeviceFrameReadout>, GpuError> {
        let _ = ctx.device.poll(wgpu::PollType::Poll);
        let mut out = Vec::new();
        while let Some(slot) = self.in_flight.front() {
            if !slot.mapped.load(Ordering::Acquire) {
                if self.in_flight.len() <= keep {
                    break;
                }
                // The oldest frame only: the frames after it keep running.
                ctx.wait_for(slot.submission.clone())?;
                if !slot.mapped.load(Ordering::Acquire) {
                    return Err(GpuError::Readback("a frame's statistics could not be mapped".into()));
                }
            }
            let Some(slot) = self.in_flight.pop_front() else { break };
            let readout = read_slot(ctx, &slot);
            slot.buffer.unmap();
            self.free.push(slot.buffer);
            match readout {
                Ok(r) => out.push(r),
                // The frames before it are booked; this one's figures are lost.
                Err(e) if !out.is_empty() => {
                    eprintln!("warning: frame {}'s statistics could not be read: {e}", slot.frame);
                    break;
                }
                Err(e) => return Err(e),
            }
        }
        Ok(out)
    }
}

/// A mapped slot's statistics and requests.
fn read_slot(ctx: &GpuContext, slot: &ReadbackSlot) -> Result<DeviceFrameReadout, GpuError> {
    let view = slot.buffer.slice(..).get_mapped_range().map_err(|e| GpuError::Readback(e.to_string()))?;
    let bytes: &[u8] = &view;
    ctx.count_read_back(bytes.len() as u64);
    let stats: FrameStatsBlock = bytemuck::pod_read_unaligned(&bytes[..STATS_BYTES as usize]);
    let words_end = STATS_BYTES as usize + 4 * slot.request_words as usize;
    let words = &bytes[STATS_BYTES as usize..words_end];
    let requests = if slot.request_words > 0 { bytemuck::pod_collect_to_vec::<u8, u32>(words) } else { Vec::new() };
    let ticks: Vec<u64> =
        if slot.tick_ms > 0.0 { bytemuck::pod_collect_to_vec(&bytes[words_end..]) } else { Vec::new() };
    let gpu_pass_ms = ticks.chunks_exact(2).map(|t| t[1].saturating_sub(t[0]) as f64 * slot.tick_ms).collect();
    let v3 = |v: [f32; 4]| Vec3::new(v[0], v[1], v[2]);
    Ok(DeviceFrameReadout {
        frame: slot.frame,
        mean: v3(stats.mean),
        indirect_mean: v3(stats.indirect_mean),
        surfaces: stats.counts[0] as u64,
        unlit: stats.counts[1] as u64,
        nonfinite: stats.counts[2] as u64,
        requests,
        gpu_pass_ms,
    })
}

/// Records the copies of the frame's statistics, request words and (resolved)
/// timestamps into `staging`, in that order.
fn record_readback(
    encoder: &mut wgpu::CommandEncoder,
    images: &FrameImages,
    staging: &wgpu::Buffer,
    timestamps: Option<&(wgpu::QuerySet, wgpu::Buffer)>,
) {
    encoder.copy_buffer_to_buffer(&images.stats, 0, staging, 0, STATS_BYTES);
    let words_bytes = 4 * images.request_words as u64;
    if images.request_words > 0 {
        encoder.copy_buffer_to_buffer(&images.requests, 0, staging, STATS_BYTES, words_bytes);
    }
    if let Some((set, resolve)) = timestamps {
        encoder.resolve_query_set(set, 0..2 * DEVICE_FRAME_PASSES.len() as u32, resolve, 0);
        encoder.copy_buffer_to_buffer(resolve, 0, staging, STATS_BYTES + words_bytes, TIMESTAMP_BYTES);
    }
}

/// One frame for [`GpuFrame::render`]: the camera pass's settings and what
/// happens to the history.
pub struct GpuFrameInput<'a> {
    /// The camera pass's frame.
    pub camera: CameraFrame<'a>,
    /// Accumulate, restart or reproject.
    pub history: FrameHistory,
    /// Frames the statistics may come back late (0: wait for this frame's).
    pub readback_lag_frames: u32,
}

/// The device-resident frame (see the module docs).
pub struct GpuFrame {
    layout: wgpu::BindGroupLayout,
    pipelines: [wgpu::ComputePipeline; 3],
    images: Option<FrameImages>,
    ring: FrameReadbackRing,
    /// Timestamps of the frame's passes and their resolve buffer, where the
    /// device has timestamp queries; read late with the statistics.
    timestamps: Option<(wgpu::QuerySet, wgpu::Buffer)>,
}

impl GpuFrame {
    /// The frame passes' pipelines on `ctx` (images come with the first frame).
    pub fn new(ctx: &GpuContext) -> Self {
        let layout = ctx.pass_layout("device frame", &[true, true, true, false, false, false, false]);
        let pipelines =
            ctx.compute_pipelines(&DEVICE_FRAME, &[Some(&layout)], ["frame_resolve", "frame_compose", "frame_stats"]);
        let passes = DEVICE_FRAME_PASSES.len() as u32;
        let timestamps = ctx.timestamps.then(|| {
            let set = ctx.device.create_query_set(&wgpu::QuerySetDescriptor {
                label: Some("frame pass timestamps"),
                ty: wgpu::QueryType::Timestamp,
                count: 2 * passes,
            });
            let resolve = ctx.create_buffer(&wgpu::BufferDescriptor {
                label: Some("frame timestamp resolve"),
                size: TIMESTAMP_BYTES,
                usage: wgpu::BufferUsages::QUERY_RESOLVE | wgpu::BufferUsages::COPY_SRC,
                mapped_at_creation: false,
            });
            (set, resolve)
        });
        Self { layout, pipelines, images: None, ring: FrameReadbackRing::default(), timestamps }
    }

    /// The images for a `width` × `height` frame with `words` request words
    /// (over `layout`), made again when either changes.
    fn ensure_images<'i>(
        layout: &wgpu::BindGroupLayout,
        images: &'i mut Option<FrameImages>,
        ctx: &GpuContext,
        (width, height, words): (u32, u32, u32),
    ) -> Result<&'i mut FrameImages, GpuError> {
        let fits = images.as_ref().is_some_and(|i| (i.width, i.height, i.request_words) == (width, height, words));
        if !fits {
            *images = Some(Self::make_images(layout, ctx, width, height, words)?);
        }
        images.as_mut().ok_or_else(|| GpuError::Input("no frame images".into()))
    }

    fn make_images(
        layout: &wgpu::BindGroupLayout,
        ctx: &GpuContext,
        width: u32,
        height: u32,
        words: u32,
    ) -> Result<FrameImages, GpuError> {
        let n = width as u64 * height as u64;
        let storage = |label: &str, bytes: u64| -> Result<wgpu::Buffer, GpuError> {
            ctx.check_buffer(bytes, label)?;
            Ok(ctx.create_buffer(&wgpu::BufferDescriptor {
                label: Some(label),
                size: bytes.max(16),
                usage: wgpu::BufferUsages::STORAGE | wgpu::BufferUsages::COPY_SRC | wgpu::BufferUsages::COPY_DST,
                mapped_at_creation: false,
            }))
        };
        let uniform = |label: &str, bytes: u64| {
            ctx.create_buffer(&wgpu::BufferDescriptor {
                label: Some(label),
                size: bytes,
                usage: wgpu::BufferUsages::UNIFORM | wgpu::BufferUsages::COPY_DST,
                mapped_at_creation: false,
            })
        };
        let groups = width.div_ceil(8) as u64 * height.div_ceil(8) as u64;
        let direct = storage("camera direct, albedo and point", n * 48)?;
        let irradiance = storage("camera irradiance", n * 16)?;
        let history = [storage("frame history a", n * 16 * HISTORY_TEXELS)?, storage("frame history b", n * 64)?];
        let partials = storage("frame partial sums", groups * 32)?;
        let stats = storage("frame statistics", STATS_BYTES)?;
        let rgba8 = storage("frame rgba8", rgba8_pitch(width) as u64 * height as u64 * 4)?;
        let requests = storage("camera probe requests", 4 * words.max(1) as u64)?;
        let frame_params = uniform("frame params", std::mem::size_of::<FrameParams>() as u64);
        let group = |read: usize| {
            let b =
                [&frame_params, &direct, &irradiance, &history[read], &history[1 - read], &partials, &stats, &rgba8];
            let entries: Vec<wgpu::BindGroupEntry<'_>> = b
                .iter()
                .enumerate()
                .map(|(i, b)| wgpu::BindGroupEntry { binding: i as u32, resource: b.as_entire_binding() })
                .collect();
            ctx.create_bind_group(&wgpu::BindGroupDescriptor { label: Some("device frame"), layout, entries: &entries })
        };
        let bind_groups = [group(0), group(1)];
        Ok(FrameImages {
            width,
            height,
            camera_params: uniform("camera params", std::mem::size_of::<CameraParams>() as u64),
            frame_params,
            direct,
            irradiance,
            history,
            current: 0,
            bind_groups,
            stats,
            rgba8,
            texture: None,
            requests,
            request_words: words,
            fresh: true,
        })
    }

    /// Records and submits frame `input` (one submission: the camera pass, the
    /// resolve, compose and statistics passes, the copy of the statistics into
    /// the ring) and returns the readouts that came back meanwhile (with
    /// `readback_lag_frames` 0, this frame's, waited for).
    pub fn render(
        &mut self,
        ctx: &GpuContext,
        pass: &GpuCameraPass,
        resources: (&GpuBvh, &GpuDdgiField, &GpuScene),
        input: &GpuFrameInput<'_>,
    ) -> Result<Vec<DeviceFrameReadout>, GpuError> {
        let f = &input.camera;
        if f.width == 0 || f.height == 0 {
            return Err(GpuError::Input("a camera frame of no pixels".into()));
        }
        let camera_params = GpuCameraPass::params(f, resources.1.shadow_field)?;
        let Self { layout, pipelines: [resolve, compose, stats], images, ring, timestamps } = self;
        let writes = |i: u32| {
            timestamps.as_ref().map(|(set, _)| wgpu::ComputePassTimestampWrites {
                query_set: set,
                beginning_of_pass_write_index: Some(2 * i),
                end_of_pass_write_index: Some(2 * i + 1),
            })
        };
        let staging = ring.take(ctx, f.request_words, input.readback_lag_frames as usize);
        let images = Self::ensure_images(layout, images, ctx, (f.width, f.height, f.request_words))?;
        let (mode, frames_max, clip) = match (&input.history, images.fresh) {
            (_, true) => (3, 0, 0.0),
            (FrameHistory::Restart, _) => (1, 0, 0.0),
            (FrameHistory::Accumulate, _) => (0, 0, 0.0),
            (FrameHistory::Reproject { history_frames, .. }, _) if *history_frames <= 1 => (1, 0, 0.0),
            (FrameHistory::Reproject { history_frames, clip_sigma, .. }, _) => (2, history_frames - 1, *clip_sigma),
        };
        let from = match &input.history {
            FrameHistory::Reproject { from, .. } => FrameCamera::of(from),
            _ => FrameCamera::default(),
        };
        let (gx, gy) = (f.width.div_ceil(8), f.height.div_ceil(8));
        let params = FrameParams {
            to: FrameCamera::of(f.camera),
            from,
            info: [mode, frames_max, 0, gx * gy],
            clip: [clip.max(0.0), 0.0, 0.0, 0.0],
            layout: [rgba8_pitch(f.width), 0, 0, 0],
        };
        // The frame's own uniform blocks, written in order before its passes.
        ctx.write_buffer(&images.camera_params, 0, bytemuck::bytes_of(&camera_params));
        ctx.write_buffer(&images.frame_params, 0, bytemuck::bytes_of(&params));
        let mut encoder = ctx.device.create_command_encoder(&Default::default());
        encoder.clear_buffer(&images.stats, 0, None);
        if f.request_words > 0 {
            encoder.clear_buffer(&images.requests, 0, None);
        }
        let targets = CameraTargets {
            params: &images.camera_params,
            direct: &images.direct,
            irradiance: &images.irradiance,
            requests: &images.requests,
            kept: true,
        };
        pass.record(ctx, &mut encoder, resources, f, &targets, writes(0));
        let group = &images.bind_groups[images.current];
        for (k, (pipeline, (x, y))) in
            [(resolve, (gx, gy)), (compose, (gx, gy)), (stats, (1, 1))].into_iter().enumerate()
        {
            let mut p = encoder.begin_compute_pass(&wgpu::ComputePassDescriptor {
                label: None,
                timestamp_writes: writes(1 + k as u32),
            });
            p.set_pipeline(pipeline);
            p.set_bind_group(0, group, &[]);
            p.dispatch_workgroups(x, y, 1);
        }
        record_readback(&mut encoder, images, &staging, timestamps.as_ref());
        let tick_ms = if timestamps.is_some() { ctx.queue.get_timestamp_period() as f64 * 1e-6 } else { 0.0 };
        // The frame's one submission: with deferring, the field update's passes
        // recorded before it go with it.
        ctx.submit(encoder.finish());
        let submission = ctx.flush().ok_or_else(|| GpuError::Input("the frame was not submitted".into()))?;
        images.current = 1 - images.current;
        images.fresh = false;
        ring.push(staging, submission, f.frame, f.request_words, tick_ms);
        ring.collect(ctx, input.readback_lag_frames as usize)
    }

    /// Waits for every readout still in flight.
    pub fn drain(&mut self, ctx: &GpuContext) -> Result<Vec<DeviceFrameReadout>, GpuError> {
        self.ring.collect(ctx, 0)
    }

    /// The last frame's `layer`, linear, row-major (reads the history back: 64
    /// bytes a pixel, a blocking wait).
    pub fn read_layer(&self, ctx: &GpuContext, layer: FrameLayer) -> Result<Vec<Vec3>, GpuError> {
        let images = self.images.as_ref().filter(|i| !i.fresh).ok_or_else(|| GpuError::Input("no frame yet".into()))?;
        let bytes = ctx.read_back(&images.history[images.current])?;
        let texels: &[[f32; 4]] = bytemuck::cast_slice(&bytes);
        let v3 = |t: &[f32; 4]| Vec3::new(t[0], t[1], t[2]);
        Ok(texels
            .chunks_exact(HISTORY_TEXELS as usize)
            .map(|h| {
                let (direct, field) = (v3(&h[0]), v3(&h[1]) * v3(&h[2]));
                match layer {
                    FrameLayer::Full => direct + field,
                    FrameLayer::Direct => direct,
                    FrameLayer::Indirect => field,
                }
            })
            .collect())
    }

    /// Records a compose pass that tone-maps the last frame's `layer` into
    /// the RGBA8 image (the frame's own pass wrote the full frame there).
    fn record_compose(
        &self,
        ctx: &GpuContext,
        images: &FrameImages,
        layer: FrameLayer,
        encoder: &mut wgpu::CommandEncoder,
    ) {
        let layer_index = match layer {
            FrameLayer::Full => 0u32,
            FrameLayer::Direct => 1,
            FrameLayer::Indirect => 2,
        };
        // Field `info.z` of the uniform block: 2 cameras of 64 bytes, then mode and frames.
        ctx.write_buffer(&images.frame_params, 128 + 8, bytemuck::bytes_of(&layer_index));
        let (gx, gy) = (images.width.div_ceil(8), images.height.div_ceil(8));
        // The group that wrote the current history reads it as `history_next`.
        let mut p = encoder.begin_compute_pass(&Default::default());
        p.set_pipeline(&self.pipelines[1]);
        p.set_bind_group(0, &images.bind_groups[1 - images.current], &[]);
        p.dispatch_workgroups(gx, gy, 1);
    }

    /// The last frame's `layer` tone-mapped on the device, RGBA8 row-major (a
    /// compose pass for `layer`, then a blocking read-back of 4 bytes a pixel).
    pub fn read_rgba8(&self, ctx: &GpuContext, layer: FrameLayer) -> Result<Vec<u8>, GpuError> {
        let images = self.images.as_ref().filter(|i| !i.fresh).ok_or_else(|| GpuError::Input("no frame yet".into()))?;
        let mut encoder = ctx.device.create_command_encoder(&Default::default());
        self.record_compose(ctx, images, layer, &mut encoder);
        ctx.submit(encoder.finish());
        let padded = ctx.read_back(&images.rgba8)?;
        let (row, pitch) = (images.width as usize * 4, rgba8_pitch(images.width) as usize * 4);
        Ok(padded.chunks_exact(pitch).flat_map(|r| &r[..row]).copied().collect())
    }

    /// The last frame's `layer`, tone-mapped, in a texture on this device
    /// (`Rgba8Unorm` holding sRGB-encoded bytes, as egui-wgpu draws its own;
    /// the frame's size), for a window that shares the
    /// device: a compose pass for `layer` where it is not the full frame and
    /// a copy into the texture, submitted without waiting. No pixel reaches the host.
    pub fn present(&mut self, ctx: &GpuContext, layer: FrameLayer) -> Result<wgpu::Texture, GpuError> {
        let this = &*self;
        let images = this.images.as_ref().filter(|i| !i.fresh).ok_or_else(|| GpuError::Input("no frame yet".into()))?;
        let mut encoder = ctx.device.create_command_encoder(&Default::default());
        if layer != FrameLayer::Full {
            this.record_compose(ctx, images, layer, &mut encoder);
        }
        let size = wgpu::Extent3d { width: images.width, height: images.height, depth_or_array_layers: 1 };
        let texture = images.texture.clone().unwrap_or_else(|| {
            ctx.device.create_texture(&wgpu::TextureDescriptor {
                label: Some("frame"),
                size,
                mip_level_count: 1,
                sample_count: 1,
                dimension: wgpu::TextureDimension::D2,
                format: wgpu::TextureFormat::Rgba8Unorm,
                usage: wgpu::TextureUsages::TEXTURE_BINDING | wgpu::TextureUsages::COPY_DST,
                view_formats: &[],
            })
        });
        encoder.copy_buffer_to_texture(
            wgpu::TexelCopyBufferInfo {
                buffer: &images.rgba8,
                layout: wgpu::TexelCopyBufferLayout {
                    offset: 0,
                    bytes_per_row: Some(rgba8_pitch(images.width) * 4),
                    rows_per_image: None,
                },
            },
            texture.as_image_copy(),
            size,
        );
        ctx.submit(encoder.finish());
        ctx.flush();
        if let Some(images) = self.images.as_mut() {
            images.texture = Some(texture.clone());
        }
        Ok(texture)
    }

    /// Device memory the frame holds now.
    pub fn bytes(&self) -> u64 {
        self.images.as_ref().map_or(0, |i| frame_bytes(i.width, i.height))
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    /// A submission holding nothing, for a slot to wait on.
    fn submission(ctx: &GpuContext) -> wgpu::SubmissionIndex {
        ctx.submit(ctx.device.create_command_encoder(&Default::default()).finish());
        ctx.flush().expect("submitted")
    }

    /// With a read-back lag of 2 frames, the ring makes its three buffers with
    /// the first frame, and steady frames whose maps are all still pending
    /// (a device running behind: CI's lavapipe beside other tests) make none;
    /// a new request size makes the three of its size.
    #[test]
    fn the_ring_makes_every_buffer_a_lag_holds_in_flight_with_its_first_frame() {
        let Some(ctx) = GpuContext::headless_unless_absent().expect("device") else { return };
        let mut ring = FrameReadbackRing::default();
        let lag = 2;
        for words in [4, 8] {
            let before = ctx.counters().buffers_made;
            for frame in 0..=lag as u32 {
                let buffer = ring.take(&ctx, words, lag);
                let made = ctx.counters().buffers_made - before;
                assert_eq!(made, lag as u64 + 1, "{words} words, frame {frame}: buffers made so far");
                // Never collected: every slot stays in flight, as behind a slow device.
                ring.push(buffer, submission(&ctx), frame, words, 0.0);
            }
            let readouts = ring.collect(&ctx, 0).expect("drained");
            assert_eq!(readouts.len(), lag + 1);
            assert_eq!(ring.free.len(), lag + 1, "{words} words: the buffers back in the ring");
        }
    }
}
