//! The device every pass runs on: one the caller provides, or a headless one on
//! the first adapter wgpu finds (lavapipe's software Vulkan included).

use std::fmt;
use wgpu::util::DeviceExt;

use crate::shader_registry::{BIND_GROUPS, PassShader, compose};

/// Why no device could be used.
#[derive(Debug)]
pub enum GpuError {
    /// No adapter: no GPU driver and no software Vulkan (Mesa's lavapipe).
    NoAdapter(String),
    /// The adapter refused a device.
    Device(String),
    /// A buffer could not be read back.
    Readback(String),
    /// Inputs that do not fit the pass (sizes, counts).
    Input(String),
}

impl fmt::Display for GpuError {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        match self {
            GpuError::NoAdapter(e) => write!(
                f,
                "no GPU adapter ({e}); install a Vulkan driver, or Mesa's software one \
                 (Debian/Ubuntu: apt-get install mesa-vulkan-drivers)"
            ),
            GpuError::Device(e) => write!(f, "the GPU adapter refused a device: {e}"),
            GpuError::Readback(e) => write!(f, "reading a GPU buffer back failed: {e}"),
            GpuError::Input(e) => write!(f, "{e}"),
        }
    }
}

impl std::error::Error for GpuError {}

/// A device, its queue and what the adapter says about itself.
pub struct GpuContext {
    /// The device every pass runs on.
    pub device: wgpu::Device,
    /// Its queue.
    pub queue: wgpu::Queue,
    /// The adapter's name and driver, e.g. "llvmpipe (LLVM 15.0.6)".
    pub adapter_name: String,
    /// Whether the device records GPU timestamps (`Features::TIMESTAMP_QUERY`).
    pub timestamps: bool,
    /// Bytes this crate's passes moved across the bus, host to device and back
    /// (what `bench --backend wgpu` reports per frame).
    transfers: TransferCounts,
    /// While deferring ([`GpuContext::defer_submissions`]): the command buffers
    /// recorded since the last [`GpuContext::flush`], in order.
    pending: std::sync::Mutex<Option<Vec<wgpu::CommandBuffer>>>,
    /// While deferring: the encoder [`GpuContext::record`] records into, after
    /// every buffer of `pending` (finished and appended by the next
    /// [`GpuContext::submit`] or [`GpuContext::flush`]). A frame's passes then
    /// share one command buffer: each encoder finished costs the host as much
    /// as recording a pass.
    open_encoder: std::sync::Mutex<Option<wgpu::CommandEncoder>>,
    /// The last submission made to the queue.
    last_submission: std::sync::Mutex<Option<wgpu::SubmissionIndex>>,
    /// [`GpuContext::buffer_rewritten`]'s and [`GpuContext::scratch_buffer`]'s
    /// buffers, per (label, key).
    frame_buffers: std::sync::Mutex<std::collections::HashMap<(&'static str, u64), FrameBuffer>>,
    /// [`GpuContext::bind_group_kept`]'s bind groups, per (label, key): the
    /// last few made, with the layout and buffers each binds.
    bind_groups: std::sync::Mutex<std::collections::HashMap<(&'static str, u64), Vec<KeptBindGroup>>>,
    /// While deferring: the bytes of this submission's buffer writes
    /// ([`UploadArena`]).
    uploads: std::sync::Mutex<UploadArena>,
}

/// The bytes a deferred submission's buffer writes carry, staged on the host
/// in a few device buffers (chunks) that are filled with one
/// `Queue::write_buffer` each when the submission goes to the queue; each
/// write is a copy from its chunk, recorded in order among the passes. On
/// lavapipe every `Queue::write_buffer` costs the host a staging buffer of
/// its own (about 20 µs), as did a deferred write's own staging buffer: a
/// frame's parameter blocks (ray generation's rotation, the trace's, the
/// shade's frame, the blend's ray directions) now share one. A chunk the
/// previous submission copied from is refilled only by the next submission's
/// queue write, which the queue orders after that submission.
#[derive(Default)]
struct UploadArena {
    /// The chunks, with the bytes staged in each since the last submission.
    chunks: Vec<(wgpu::Buffer, Vec<u8>)>,
    /// The chunk the next write goes to first.
    current: usize,
}

/// Bytes of a new [`UploadArena`] chunk (more for a larger write).
const UPLOAD_CHUNK_BYTES: u64 = 64 << 10;
/// The largest write staged in the arena; a larger one (a scene's upload while
/// deferring) gets a staging buffer of its own, not a chunk kept for good.
const UPLOAD_LARGEST_BYTES: u64 = 4 << 20;
/// Chunk bytes the arena keeps between submissions; chunks beyond are let go.
const UPLOAD_KEPT_BYTES: u64 = 8 << 20;

/// A buffer a pass keeps from frame to frame and rewrites in place
/// ([`GpuContext::buffer_rewritten`], [`GpuContext::scratch_buffer`]).
struct FrameBuffer {
    buffer: wgpu::Buffer,
    usage: wgpu::BufferUsages,
    /// The contents last written (empty for a scratch buffer).
    contents: Vec<u8>,
    /// The queue submissions made when it was last handed out: a pass recorded
    /// since then, not yet submitted, may still read what it holds.
    handed_out_at: u64,
    /// The identity of the contents, where they were written from one
    /// ([`GpuContext::buffer_identified`]).
    id: Option<Vec<u64>>,
    /// How many hand-outs in a row asked for less than half its size
    /// ([`FrameBuffer::serves`]).
    oversized_uses: u32,
}

/// How many hand-outs in a row a kept buffer serves needs of less than half
/// its size before it is let go ([`FrameBuffer::serves`]). A need that comes
/// back within them keeps the buffer: the usage scheme's blend entries grow
/// by 2.6× every `probe_sleeping_update_interval` (10) updates, when its
/// Usage Sleeping probes join the blend, and shrink the update after; with
/// the bare window of [`holds`] each swing made a buffer and a bind group.
const KEPT_OVERSIZED_USES: u32 = 64;

impl FrameBuffer {
    fn new(buffer: wgpu::Buffer, usage: wgpu::BufferUsages, contents: Vec<u8>, handed_out_at: u64) -> Self {
        Self { buffer, usage, contents, handed_out_at, id: None, oversized_uses: 0 }
    }

    /// Whether this buffer serves a need of `need` bytes of `usage`: it holds
    /// them, and has not been more than twice as large as the needs ([`holds`])
    /// for over [`KEPT_OVERSIZED_USES`] hand-outs in a row (counted here).
    fn serves(&mut self, need: u64, usage: wgpu::BufferUsages) -> bool {
        if self.usage != usage || self.buffer.size() < need {
            return false;
        }
        self.oversized_uses = if holds(self.buffer.size(), need) { 0 } else { self.oversized_uses + 1 };
        self.oversized_uses <= KEPT_OVERSIZED_USES
    }
}

/// A bind group [`GpuContext::bind_group_kept`] made, with what it binds.
struct KeptBindGroup {
    layout: wgpu::BindGroupLayout,
    buffers: Vec<wgpu::Buffer>,
    bind_group: wgpu::BindGroup,
}

/// How many bind groups [`GpuContext::bind_group_kept`] keeps per (label, key):
/// a pass that binds the ray batch sees the two batches it alternates between
/// (`WgpuProbeTracer::spare_batch`). No more: a kept bind group keeps the
/// buffers it binds alive, and these two are the batches the tracer holds anyway.
const KEPT_BIND_GROUPS: usize = 2;

/// Bytes uploaded (buffers made from host data, queue writes) and read back,
/// counted where every pass moves them: [`GpuContext::buffer_with`],
/// [`GpuContext::write_buffer`] and [`GpuContext::read_buffer`]; and the
/// submissions ([`GpuContext::submit`]) and blocking waits
/// ([`GpuContext::wait`], every blocking read-back) with the time spent in them.
#[derive(Debug, Default)]
struct TransferCounts {
    up: std::sync::atomic::AtomicU64,
    down: std::sync::atomic::AtomicU64,
    submissions: std::sync::atomic::AtomicU64,
    waits: std::sync::atomic::AtomicU64,
    wait_ns: std::sync::atomic::AtomicU64,
    kept: std::sync::atomic::AtomicU64,
    ray_batches: std::sync::atomic::AtomicU64,
    buffers: std::sync::atomic::AtomicU64,
    bind_groups: std::sync::atomic::AtomicU64,
}

/// What a [`GpuContext`] has done so far (differences between two readings
/// give a frame's): counts, not timings, so a test may hold them, except
/// `wait_ms`, the host's wall time blocked in waits and inside submissions (a
/// benchmark's host share is the rest).
#[derive(Clone, Copy, Debug, Default, PartialEq)]
pub struct GpuCounters {
    /// Command submissions to the queue.
    pub submissions: u64,
    /// Times the host blocked until the device finished (waits and blocking read-backs).
    pub blocking_waits: u64,
    /// Bytes uploaded (buffers made from host data, queue writes).
    pub bytes_up: u64,
    /// Bytes read back to the host.
    pub bytes_down: u64,
    /// Bytes a pass would have uploaded but the device already held
    /// ([`GpuContext::buffer_rewritten`]: its inputs repeated the last frame's).
    pub bytes_kept: u64,
    /// Wall milliseconds the host spent blocked in those waits and inside submissions.
    pub wait_ms: f64,
    /// Ray batches allocated (a batch's rays, hits and parameter buffers:
    /// 48 bytes a ray), uploaded or left for a pass to write.
    pub ray_batches_made: u64,
    /// Buffers made (every buffer this crate makes goes through
    /// [`GpuContext::create_buffer`] or a helper built on it; the staging
    /// memory wgpu's own `Queue::write_buffer` takes is not counted).
    pub buffers_made: u64,
    /// Bind groups made ([`GpuContext::create_bind_group`]).
    pub bind_groups_made: u64,
}

impl std::ops::Sub for GpuCounters {
    type Output = GpuCounters;
    fn sub(self, o: GpuCounters) -> GpuCounters {
        GpuCounters {
            submissions: self.submissions - o.submissions,
            blocking_waits: self.blocking_waits - o.blocking_waits,
            bytes_up: self.bytes_up - o.bytes_up,
            bytes_down: self.bytes_down - o.bytes_down,
            bytes_kept: self.bytes_kept - o.bytes_kept,
            wait_ms: self.wait_ms - o.wait_ms,
            ray_batches_made: self.ray_batches_made - o.ray_batches_made,
            buffers_made: self.buffers_made - o.buffers_made,
            bind_groups_made: self.bind_groups_made - o.bind_groups_made,
        }
    }
}

/// One compute pass of [`GpuContext::run_passes`]: the pipeline, its bind groups
/// from group 0 on (`None`: unused), and the workgroups in x and y.
pub(crate) type PassStep<'a> = (&'a wgpu::ComputePipeline, Vec<Option<&'a wgpu::BindGroup>>, (u32, u32));

/// The workgroups of one step of [`GpuContext::run_dispatches`].
pub(crate) enum Dispatch<'a> {
    /// Workgroups in x and y.
    Groups(u32, u32),
    /// Workgroups (x, y, z as three `u32`) that an earlier step wrote into
    /// `args` at byte `offset`: copied into `via` (`INDIRECT | COPY_DST`, bound
    /// to no pass: a buffer a pass binds cannot also hold its indirect
    /// arguments) just before the pass, then dispatched from it.
    Indirect { args: &'a wgpu::Buffer, offset: u64, via: &'a wgpu::Buffer },
}

impl GpuContext {
    /// A headless device on the compiled backends (Vulkan, Metal, DX12).
    pub fn headless() -> Result<Self, GpuError> {
        let instance = wgpu::Instance::new(wgpu::InstanceDescriptor::new_without_display_handle_from_env());
        let adapter = pollster::block_on(instance.request_adapter(&wgpu::RequestAdapterOptions {
            power_preference: wgpu::PowerPreference::HighPerformance,
            ..Default::default()
        }))
        .map_err(|e| GpuError::NoAdapter(e.to_string()))?;
        let info = adapter.get_info();
        // Timestamps for `bench --backend wgpu`'s per-pass times, where the adapter has them.
        let required_features = adapter.features() & wgpu::Features::TIMESTAMP_QUERY;
        let (device, queue) = pollster::block_on(adapter.request_device(&wgpu::DeviceDescriptor {
            label: Some("probegi"),
            required_features,
            // The blend binds six storage buffers; ask for what the adapter has.
            required_limits: adapter.limits(),
            ..Default::default()
        }))
        .map_err(|e| GpuError::Device(e.to_string()))?;
        Ok(Self {
            device,
            queue,
            adapter_name: format!("{} ({:?}, {})", info.name, info.backend, info.driver),
            timestamps: !required_features.is_empty(),
            transfers: TransferCounts::default(),
            pending: Default::default(),
            open_encoder: Default::default(),
            last_submission: Default::default(),
            frame_buffers: Default::default(),
            bind_groups: Default::default(),
            uploads: Default::default(),
        })
    }

    /// For test suites: a headless device, or `Ok(None)` (with a line saying why)
    /// when there is no adapter, unless the environment sets `PROBEGI_REQUIRE_GPU`
    /// (`scripts/test.sh` does once lavapipe is installed): then a missing adapter
    /// is the error.
    pub fn headless_unless_absent() -> Result<Option<Self>, GpuError> {
        match Self::headless() {
            Ok(c) => {
                eprintln!("adapter: {}", c.adapter_name);
                Ok(Some(c))
            }
            Err(e) if std::env::var_os("PROBEGI_REQUIRE_GPU").is_none() => {
                eprintln!("skipping the GPU test: {e}");
                Ok(None)
            }
            Err(e) => Err(e),
        }
    }

    /// A device and queue the caller owns (an engine's).
    pub fn from_device(device: wgpu::Device, queue: wgpu::Queue, adapter_name: impl Into<String>) -> Self {
        let timestamps = device.features().contains(wgpu::Features::TIMESTAMP_QUERY);
        Self {
            device,
            queue,
            adapter_name: adapter_name.into(),
            timestamps,
            transfers: TransferCounts::default(),
            pending: Default::default(),
            open_encoder: Default::default(),
            last_submission: Default::default(),
            frame_buffers: Default::default(),
            bind_groups: Default::default(),
            uploads: Default::default(),
        }
    }

    /// An error, not wgpu's panic, when a storage buffer of `bytes` exceeds what
    /// the device allows (its largest buffer or storage binding).
    pub(crate) fn check_buffer(&self, bytes: u64, what: &str) -> Result<(), GpuError> {
        let l = self.device.limits();
        let max = l.max_buffer_size.min(l.max_storage_buffer_binding_size);
        if bytes > max {
            return Err(GpuError::Input(format!(
                "{what} needs a {} MiB buffer; this device binds at most {} MiB",
                bytes >> 20,
                max >> 20
            )));
        }
        Ok(())
    }

    /// An error when a pipeline binding `n` storage buffers per stage (and
    /// [`BIND_GROUPS`] bind groups) exceeds the device's limits (WebGPU's
    /// defaults are 8 and 4; `headless` asks for what the adapter has).
    pub(crate) fn check_pipeline(&self, storage_buffers: u32, what: &str) -> Result<(), GpuError> {
        let l = self.device.limits();
        if storage_buffers > l.max_storage_buffers_per_shader_stage || l.max_bind_groups < BIND_GROUPS {
            return Err(GpuError::Device(format!(
                "{what} binds {storage_buffers} storage buffers in {BIND_GROUPS} groups; this device allows {} and {} \
                 (create it with the adapter's limits)",
                l.max_storage_buffers_per_shader_stage, l.max_bind_groups
            )));
        }
        Ok(())
    }

    /// A pass's own group ([`crate::shader_registry::PASS_GROUP`]): its uniform
    /// block at binding 0, then one storage buffer per entry of `read_only`
    /// (whether the pass only reads it) from binding 1 on.
    pub(crate) fn pass_layout(&self, label: &str, read_only: &[bool]) -> wgpu::BindGroupLayout {
        let mut entries = vec![uniform_entry(0)];
        entries.extend(read_only.iter().enumerate().map(|(i, r)| storage_entry(i as u32 + 1, *r)));
        self.device.create_bind_group_layout(&wgpu::BindGroupLayoutDescriptor { label: Some(label), entries: &entries })
    }

    /// Compute pipelines for `entries` of `shader` (composed by
    /// [`crate::shader_registry`]) over `layouts` (one per bind group; `None`
    /// for a group the module does not use).
    pub(crate) fn compute_pipelines<const N: usize>(
        &self,
        shader: &PassShader,
        layouts: &[Option<&wgpu::BindGroupLayout>],
        entries: [&str; N],
    ) -> [wgpu::ComputePipeline; N] {
        let label = shader.label;
        let module = self.device.create_shader_module(wgpu::ShaderModuleDescriptor {
            label: Some(label),
            source: wgpu::ShaderSource::Wgsl(compose(shader).into()),
        });
        let layout = self.device.create_pipeline_layout(&wgpu::PipelineLayoutDescriptor {
            label: Some(label),
            bind_group_layouts: layouts,
            immediate_size: 0,
        });
        entries.map(|entry| {
            self.device.create_compute_pipeline(&wgpu::ComputePipelineDescriptor {
                label: Some(entry),
                layout: Some(&layout),
                module: &module,
                entry_point: Some(entry),
                compilation_options: Default::default(),
                cache: None,
            })
        })
    }

    /// Bytes the passes have uploaded and read back so far: (host to device,
    /// device to host). Differences between two calls give a frame's traffic.
    pub fn bytes_transferred(&self) -> (u64, u64) {
        use std::sync::atomic::Ordering::Relaxed;
        (self.transfers.up.load(Relaxed), self.transfers.down.load(Relaxed))
    }

    /// Submissions, blocking waits and bytes moved so far ([`GpuCounters`]).
    pub fn counters(&self) -> GpuCounters {
        use std::sync::atomic::Ordering::Relaxed;
        let t = &self.transfers;
        GpuCounters {
            submissions: t.submissions.load(Relaxed),
            blocking_waits: t.waits.load(Relaxed),
            bytes_up: t.up.load(Relaxed),
            bytes_down: t.down.load(Relaxed),
            bytes_kept: t.kept.load(Relaxed),
            wait_ms: t.wait_ns.load(Relaxed) as f64 * 1e-6,
            ray_batches_made: t.ray_batches.load(Relaxed),
            buffers_made: t.buffers.load(Relaxed),
            bind_groups_made: t.bind_groups.load(Relaxed),
        }
    }

    /// With `on`, the passes' command buffers and buffer writes are recorded in
    /// order and go to the queue together at the next [`Self::flush`] (one
    /// submission: a frame's field update and camera frame), or before any
    /// blocking read-back or wait; off flushes what is pending and submits
    /// each at once again. Buffer writes are then copies recorded in the same
    /// order, not `Queue::write_buffer` (which lands before the whole submission).
    pub fn defer_submissions(&self, on: bool) {
        if !on {
            self.flush();
        }
        let mut pending = self.pending.lock().unwrap_or_else(|e| e.into_inner());
        match (on, pending.is_some()) {
            (true, false) => *pending = Some(Vec::new()),
            (false, true) => *pending = None,
            _ => {}
        }
    }

    /// Whether submissions are being deferred ([`Self::defer_submissions`]).
    pub(crate) fn deferring(&self) -> bool {
        self.pending.lock().unwrap_or_else(|e| e.into_inner()).is_some()
    }

    /// Submits one command buffer, or records it while deferring (counted when
    /// it reaches the queue). The time the driver holds the host inside a
    /// submission (a queue still busy with earlier work: lavapipe runs the work
    /// on the host's own cores) counts as waiting for the device.
    pub fn submit(&self, commands: wgpu::CommandBuffer) {
        let open = self.open_encoder.lock().unwrap_or_else(|e| e.into_inner()).take();
        let mut pending = self.pending.lock().unwrap_or_else(|e| e.into_inner());
        if let Some(list) = pending.as_mut() {
            // What `record` recorded before this buffer goes before it.
            list.extend(open.map(wgpu::CommandEncoder::finish));
            list.push(commands);
            return;
        }
        drop(pending);
        self.queue_submit(open.map(wgpu::CommandEncoder::finish).into_iter().chain([commands]).collect());
    }

    /// Runs `f` on a command encoder: while deferring, the one the deferred
    /// commands end with (made when none is open), so that a frame's passes
    /// finish as one command buffer at the next flush; otherwise a new one,
    /// submitted when `f` returns. `f` records into the encoder only: it must
    /// not submit, flush or write buffers through this context, nor call what
    /// writes through it (`buffer_rewritten`, `buffer_identified`,
    /// `GpuRayBatch::configure`): what it submitted would run before what it
    /// recorded, and a write's copy after it.
    pub fn record<T>(&self, f: impl FnOnce(&mut wgpu::CommandEncoder) -> T) -> T {
        if !self.deferring() {
            let mut encoder = self.device.create_command_encoder(&Default::default());
            let out = f(&mut encoder);
            self.submit(encoder.finish());
            return out;
        }
        let open = self.open_encoder.lock().unwrap_or_else(|e| e.into_inner()).take();
        let mut encoder = open.unwrap_or_else(|| self.device.create_command_encoder(&Default::default()));
        let out = f(&mut encoder);
        let mut open = self.open_encoder.lock().unwrap_or_else(|e| e.into_inner());
        debug_assert!(open.is_none(), "GpuContext::record called inside a record");
        if let Some(inner) = open.take() {
            // `f` recorded through this context (a misuse): keep both, this
            // encoder's commands first, rather than drop the other's.
            drop(open);
            self.submit(encoder.finish());
            self.submit(inner.finish());
            return out;
        }
        *open = Some(encoder);
        out
    }

    /// Submits what deferring recorded, as one submission, and returns the
    /// last submission made (this one, or an earlier one when nothing was pending).
    pub fn flush(&self) -> Option<wgpu::SubmissionIndex> {
        let open = self.open_encoder.lock().unwrap_or_else(|e| e.into_inner()).take();
        let mut pending = self.pending.lock().unwrap_or_else(|e| e.into_inner());
        match (pending.as_mut(), open) {
            (Some(list), Some(open)) => list.push(open.finish()),
            // Deferring ended while an encoder was open: it goes alone.
            (None, Some(open)) => {
                drop(pending);
                return Some(self.queue_submit(vec![open.finish()]));
            }
            _ => {}
        }
        let list = pending.as_mut().map(std::mem::take);
        drop(pending);
        match list {
            Some(list) if !list.is_empty() => Some(self.queue_submit(list)),
            _ => self.last_submission.lock().unwrap_or_else(|e| e.into_inner()).clone(),
        }
    }

    fn queue_submit(&self, commands: Vec<wgpu::CommandBuffer>) -> wgpu::SubmissionIndex {
        use std::sync::atomic::Ordering::Relaxed;
        self.upload_staged();
        let t = std::time::Instant::now();
        self.transfers.submissions.fetch_add(1, Relaxed);
        let index = self.queue.submit(commands);
        self.transfers.wait_ns.fetch_add(t.elapsed().as_nanos() as u64, Relaxed);
        *self.last_submission.lock().unwrap_or_else(|e| e.into_inner()) = Some(index.clone());
        index
    }

    /// Blocks until submission `index` has run (a blocking wait, counted and
    /// timed), not the ones after it.
    pub fn wait_for(&self, index: wgpu::SubmissionIndex) -> Result<(), GpuError> {
        use std::sync::atomic::Ordering::Relaxed;
        let t = std::time::Instant::now();
        let r = self.device.poll(wgpu::PollType::Wait { submission_index: Some(index), timeout: None });
        self.transfers.waits.fetch_add(1, Relaxed);
        self.transfers.wait_ns.fetch_add(t.elapsed().as_nanos() as u64, Relaxed);
        r.map(|_| ()).map_err(|e| GpuError::Device(e.to_string()))
    }

    /// Blocks until every submitted command has run (counted, and timed).
    fn blocking_poll(&self) -> Result<(), String> {
        use std::sync::atomic::Ordering::Relaxed;
        let t = std::time::Instant::now();
        let r = self.device.poll(wgpu::PollType::wait_indefinitely()).map(|_| ()).map_err(|e| e.to_string());
        self.transfers.waits.fetch_add(1, Relaxed);
        self.transfers.wait_ns.fetch_add(t.elapsed().as_nanos() as u64, Relaxed);
        r
    }

    /// Counts `bytes` as read back (a caller that maps a staging buffer itself).
    pub(crate) fn count_read_back(&self, bytes: u64) {
        self.transfers.down.fetch_add(bytes, std::sync::atomic::Ordering::Relaxed);
    }

    /// Counts a ray batch allocated ([`GpuCounters::ray_batches_made`]).
    pub(crate) fn count_ray_batch(&self) {
        self.transfers.ray_batches.fetch_add(1, std::sync::atomic::Ordering::Relaxed);
    }

    /// Counts `bytes` as kept: a pass found them already on the device and
    /// uploaded nothing ([`GpuCounters::bytes_kept`]).
    pub(crate) fn count_kept(&self, bytes: u64) {
        self.transfers.kept.fetch_add(bytes, std::sync::atomic::Ordering::Relaxed);
    }

    /// A buffer holding `contents` (counted as uploaded).
    pub(crate) fn buffer_with(&self, label: &str, contents: &[u8], usage: wgpu::BufferUsages) -> wgpu::Buffer {
        self.transfers.up.fetch_add(contents.len() as u64, std::sync::atomic::Ordering::Relaxed);
        self.transfers.buffers.fetch_add(1, std::sync::atomic::Ordering::Relaxed);
        self.device.create_buffer_init(&wgpu::util::BufferInitDescriptor { label: Some(label), contents, usage })
    }

    /// Writes `data` into `buffer` at `offset` (counted as uploaded): through
    /// the queue, or, while deferring, as a copy recorded after the passes
    /// before it, from the [`UploadArena`] (or, for a write larger than
    /// [`UPLOAD_LARGEST_BYTES`], from a staging buffer of its own).
    pub(crate) fn write_buffer(&self, buffer: &wgpu::Buffer, offset: u64, data: &[u8]) {
        self.transfers.up.fetch_add(data.len() as u64, std::sync::atomic::Ordering::Relaxed);
        if !self.deferring() || data.is_empty() {
            self.queue.write_buffer(buffer, offset, data);
            return;
        }
        let len = data.len() as u64;
        if let Some((chunk, at)) = self.stage(data) {
            self.record(|e| e.copy_buffer_to_buffer(&chunk, at, buffer, offset, len));
            return;
        }
        self.transfers.buffers.fetch_add(1, std::sync::atomic::Ordering::Relaxed);
        let staging = self.device.create_buffer_init(&wgpu::util::BufferInitDescriptor {
            label: Some("deferred write"),
            contents: data,
            usage: wgpu::BufferUsages::COPY_SRC,
        });
        self.record(|e| e.copy_buffer_to_buffer(&staging, 0, buffer, offset, len));
    }

    /// Stages `data` in the [`UploadArena`]: the chunk and the byte offset it
    /// will sit at once [`Self::upload_staged`] writes the chunk. `None` for a
    /// write the arena does not take (larger than [`UPLOAD_LARGEST_BYTES`],
    /// or of a length a copy cannot have).
    fn stage(&self, data: &[u8]) -> Option<(wgpu::Buffer, u64)> {
        let len = data.len() as u64;
        if len > UPLOAD_LARGEST_BYTES || !len.is_multiple_of(wgpu::COPY_BUFFER_ALIGNMENT) {
            return None;
        }
        let mut arena = self.uploads.lock().unwrap_or_else(|e| e.into_inner());
        // Any chunk with room (each copy has its own offset, so the order of
        // the chunks is free): the current one first, then the others.
        let room = |(b, bytes): &(wgpu::Buffer, Vec<u8>)| b.size() - bytes.len() as u64 >= len;
        let current = arena.chunks.get(arena.current).filter(|c| room(c)).map(|_| arena.current);
        let index = match current.or_else(|| arena.chunks.iter().position(room)) {
            Some(i) => i,
            None => {
                let size = UPLOAD_CHUNK_BYTES.max(len.next_power_of_two());
                let buffer = self.create_buffer(&wgpu::BufferDescriptor {
                    label: Some("upload arena"),
                    size,
                    usage: wgpu::BufferUsages::COPY_SRC | wgpu::BufferUsages::COPY_DST,
                    mapped_at_creation: false,
                });
                arena.chunks.push((buffer, Vec::with_capacity(size as usize)));
                arena.chunks.len() - 1
            }
        };
        arena.current = index;
        let (buffer, bytes) = &mut arena.chunks[index];
        let at = bytes.len() as u64;
        bytes.extend_from_slice(data);
        Some((buffer.clone(), at))
    }

    /// Writes what [`Self::stage`] staged since the last submission into its
    /// chunks, one `Queue::write_buffer` a chunk, which lands before the
    /// submission made next (the one holding the copies from them), and
    /// lets go of chunks beyond [`UPLOAD_KEPT_BYTES`].
    fn upload_staged(&self) {
        let mut arena = self.uploads.lock().unwrap_or_else(|e| e.into_inner());
        for (buffer, bytes) in arena.chunks.iter_mut().filter(|(_, b)| !b.is_empty()) {
            self.queue.write_buffer(buffer, 0, bytes);
            bytes.clear();
        }
        arena.current = 0;
        let mut kept = 0;
        arena.chunks.retain(|(b, _)| {
            kept += b.size();
            kept <= UPLOAD_KEPT_BYTES
        });
    }

    /// A buffer (counted in [`GpuCounters::buffers_made`]).
    pub fn create_buffer(&self, desc: &wgpu::BufferDescriptor<'_>) -> wgpu::Buffer {
        self.transfers.buffers.fetch_add(1, std::sync::atomic::Ordering::Relaxed);
        self.device.create_buffer(desc)
    }

    /// A bind group (counted in [`GpuCounters::bind_groups_made`]).
    pub fn create_bind_group(&self, desc: &wgpu::BindGroupDescriptor<'_>) -> wgpu::BindGroup {
        self.transfers.bind_groups.fetch_add(1, std::sync::atomic::Ordering::Relaxed);
        self.device.create_bind_group(desc)
    }

    /// The last submission made to the queue, if any.
    pub(crate) fn last_submission(&self) -> Option<wgpu::SubmissionIndex> {
        self.last_submission.lock().unwrap_or_else(|e| e.into_inner()).clone()
    }

    /// Queue submissions made so far (what [`FrameBuffer::handed_out_at`] compares).
    pub(crate) fn queue_submissions(&self) -> u64 {
        self.transfers.submissions.load(std::sync::atomic::Ordering::Relaxed)
    }

    /// A buffer of `usage` (plus `COPY_DST`) holding `contents`, for a pass's
    /// inputs that change from frame to frame (its uniform block, the frame's
    /// ray directions): kept per `(label, key)` and rewritten in place. Nothing
    /// is uploaded while the contents repeat (counted as kept), else one
    /// [`Self::write_buffer`]: while deferring, a copy from the
    /// [`UploadArena`] recorded before the passes recorded after this call;
    /// otherwise a `Queue::write_buffer`, which lands before the next
    /// submission and after the ones before it. Where a pass recorded since
    /// the last submission, or about to be recorded, may still read the old
    /// contents (the buffer was handed out since the last submission),
    /// writing in place would change what that pass reads: a new buffer
    /// replaces it instead. So a pass keyed per volume that runs once a
    /// frame makes no buffer, where it made one a frame before. Contents that
    /// change length (the screen scheme's probe records) keep a buffer that
    /// holds them and at most twice as many bytes, or more for a while
    /// ([`FrameBuffer::serves`]; a new one leaves a quarter more room): the
    /// passes read such inputs by the counts their uniform blocks give, never
    /// by the buffer's length.
    pub(crate) fn buffer_rewritten(
        &self,
        label: &'static str,
        key: u64,
        contents: &[u8],
        usage: wgpu::BufferUsages,
    ) -> wgpu::Buffer {
        let usage = usage | wgpu::BufferUsages::COPY_DST;
        let size = contents.len().max(16) as u64;
        let now = self.queue_submissions();
        let mut kept = self.frame_buffers.lock().unwrap_or_else(|e| e.into_inner());
        let before = kept.get(&(label, key)).map(|k| k.buffer.size());
        if let Some(k) = kept.get_mut(&(label, key))
            && k.serves(size, usage)
        {
            if k.contents == contents {
                self.count_kept(contents.len() as u64);
                k.handed_out_at = now;
                return k.buffer.clone();
            }
            if k.handed_out_at != now {
                self.write_buffer(&k.buffer, 0, contents);
                k.id = None;
                k.contents.clear();
                k.contents.extend_from_slice(contents);
                k.handed_out_at = now;
                return k.buffer.clone();
            }
        }
        // Room to grow where the length changed (a uniform block's never does).
        let size = if before.is_some_and(|b| b != size) { (size + size / 4).next_multiple_of(16) } else { size };
        let mut padded = contents.to_vec();
        padded.resize(size as usize, 0);
        let buffer = self.buffer_with(label, &padded, usage);
        kept.insert((label, key), FrameBuffer::new(buffer.clone(), usage, contents.to_vec(), now));
        buffer
    }

    /// [`Self::buffer_rewritten`] for contents with an identity `id` (a
    /// field's kept plan: `probegi_field::device_plans::DeviceVolumeBlend::probe_blend_id`,
    /// `GeneratedProbeRays::plan_id`; equal ids, equal contents): where the
    /// buffer kept under `(label, key)` was last written from `id`, it holds
    /// them already, and `contents` is not called (the host packs and
    /// compares nothing); else `buffer_rewritten` of `contents()`, whose
    /// error (contents it would not write) is returned, no identity kept.
    /// An identity is a list (one plan id per volume, for a batch's records).
    pub(crate) fn buffer_identified(
        &self,
        label: &'static str,
        key: u64,
        id: Option<&[u64]>,
        contents: impl FnOnce() -> Result<Vec<u8>, GpuError>,
        usage: wgpu::BufferUsages,
    ) -> Result<wgpu::Buffer, GpuError> {
        let with_dst = usage | wgpu::BufferUsages::COPY_DST;
        if let Some(id) = id {
            let mut kept = self.frame_buffers.lock().unwrap_or_else(|e| e.into_inner());
            // Kept by its identity while it would serve its contents' length
            // (so a buffer that shrank under a lasting id is let go in time).
            if let Some(k) = kept.get_mut(&(label, key))
                && k.id.as_deref() == Some(id)
                && k.serves(k.contents.len().max(16) as u64, with_dst)
            {
                self.count_kept(k.contents.len() as u64);
                k.handed_out_at = self.queue_submissions();
                return Ok(k.buffer.clone());
            }
        }
        let buffer = self.buffer_rewritten(label, key, &contents()?, usage);
        let mut kept = self.frame_buffers.lock().unwrap_or_else(|e| e.into_inner());
        if let Some(k) = kept.get_mut(&(label, key)) {
            k.id = id.map(<[u64]>::to_vec);
        }
        Ok(buffer)
    }

    /// A storage buffer of at least `bytes` for a pass to write and a later
    /// pass of the same frame to read (the shade pass's radiance, the blend's
    /// weight tables), kept per `(label, key)` while it holds `bytes` and at
    /// most twice as many, or more for a while ([`FrameBuffer::serves`]). Its
    /// contents are whatever a pass last wrote: it is for data a pass writes before it is read, read by counts
    /// and indices the passes are given, and the caller reads it before the
    /// next call with the same key records its writer (queue order does the rest).
    pub(crate) fn scratch_buffer(
        &self,
        label: &'static str,
        key: u64,
        bytes: u64,
        usage: wgpu::BufferUsages,
    ) -> wgpu::Buffer {
        let bytes = bytes.max(16);
        let mut kept = self.frame_buffers.lock().unwrap_or_else(|e| e.into_inner());
        if let Some(k) = kept.get_mut(&(label, key))
            && k.serves(bytes, usage)
        {
            return k.buffer.clone();
        }
        let buffer = self.create_buffer(&wgpu::BufferDescriptor {
            label: Some(label),
            size: bytes,
            usage,
            mapped_at_creation: false,
        });
        kept.insert((label, key), FrameBuffer::new(buffer.clone(), usage, Vec::new(), 0));
        buffer
    }

    /// A bind group of `buffers` (whole, at bindings 0, 1, …) over `layout`:
    /// one made earlier for the same `(label, key)`, layout and buffers when
    /// there is one among the last [`KEPT_BIND_GROUPS`], else a new one. With
    /// [`Self::buffer_rewritten`] and [`Self::scratch_buffer`] a still field's
    /// passes bind the same buffers every frame and make no bind group.
    pub(crate) fn bind_group_kept(
        &self,
        label: &'static str,
        key: u64,
        layout: &wgpu::BindGroupLayout,
        buffers: &[&wgpu::Buffer],
    ) -> wgpu::BindGroup {
        let mut kept = self.bind_groups.lock().unwrap_or_else(|e| e.into_inner());
        let list = kept.entry((label, key)).or_default();
        let same = |k: &KeptBindGroup| &k.layout == layout && k.buffers.iter().eq(buffers.iter().copied());
        if let Some(i) = list.iter().position(same) {
            let k = list.remove(i);
            let bind_group = k.bind_group.clone();
            list.push(k);
            return bind_group;
        }
        let entries: Vec<wgpu::BindGroupEntry<'_>> = buffers
            .iter()
            .enumerate()
            .map(|(i, b)| wgpu::BindGroupEntry { binding: i as u32, resource: b.as_entire_binding() })
            .collect();
        let bind_group =
            self.create_bind_group(&wgpu::BindGroupDescriptor { label: Some(label), layout, entries: &entries });
        if list.len() == KEPT_BIND_GROUPS {
            list.remove(0);
        }
        let buffers = buffers.iter().map(|b| (*b).clone()).collect();
        list.push(KeptBindGroup { layout: layout.clone(), buffers, bind_group: bind_group.clone() });
        bind_group
    }

    /// A storage buffer of `bytes` a pass writes and the host reads back.
    pub(crate) fn output_buffer(&self, label: &str, bytes: u64) -> wgpu::Buffer {
        self.create_buffer(&wgpu::BufferDescriptor {
            label: Some(label),
            size: bytes.max(16),
            usage: wgpu::BufferUsages::STORAGE | wgpu::BufferUsages::COPY_SRC,
            mapped_at_creation: false,
        })
    }

    /// Submits `steps` ([`PassStep`]: pipeline, bind groups from group 0 on with `None` for an
    /// unused one, workgroups x and y), one compute pass each so every step sees
    /// what the steps before it wrote.
    pub(crate) fn run_passes(&self, label: &str, steps: &[PassStep<'_>]) {
        let steps: Vec<_> = steps.iter().map(|(p, g, (x, y))| (*p, g.clone(), Dispatch::Groups(*x, *y))).collect();
        self.run_dispatches(label, &steps);
    }

    /// [`Self::run_passes`] where a step may take its workgroups from a buffer
    /// an earlier step wrote ([`Dispatch::Indirect`]).
    pub(crate) fn run_dispatches(
        &self,
        label: &str,
        steps: &[(&wgpu::ComputePipeline, Vec<Option<&wgpu::BindGroup>>, Dispatch<'_>)],
    ) {
        let mut encoder = self.device.create_command_encoder(&Default::default());
        for (pipeline, groups, dispatch) in steps {
            if let Dispatch::Indirect { args, offset, via } = dispatch {
                encoder.copy_buffer_to_buffer(args, *offset, via, 0, 12);
            }
            let mut pass =
                encoder.begin_compute_pass(&wgpu::ComputePassDescriptor { label: Some(label), timestamp_writes: None });
            pass.set_pipeline(pipeline);
            for (i, g) in groups.iter().enumerate() {
                if let Some(g) = g {
                    pass.set_bind_group(i as u32, *g, &[]);
                }
            }
            match dispatch {
                Dispatch::Groups(x, y) => pass.dispatch_workgroups(*x, *y, 1),
                Dispatch::Indirect { via, .. } => pass.dispatch_workgroups_indirect(via, 0),
            }
        }
        self.submit(encoder.finish());
    }

    /// Waits until every submitted command has run (a blocking wait, counted;
    /// what deferring recorded is submitted first).
    pub fn wait(&self) -> Result<(), GpuError> {
        self.flush();
        self.blocking_poll().map_err(GpuError::Device)
    }

    /// Copies a `COPY_SRC` buffer into a staging buffer and reads it back.
    pub fn read_back(&self, buffer: &wgpu::Buffer) -> Result<Vec<u8>, GpuError> {
        let staging = self.create_buffer(&wgpu::BufferDescriptor {
            label: Some("readback"),
            size: buffer.size(),
            usage: wgpu::BufferUsages::MAP_READ | wgpu::BufferUsages::COPY_DST,
            mapped_at_creation: false,
        });
        let mut encoder = self.device.create_command_encoder(&Default::default());
        encoder.copy_buffer_to_buffer(buffer, 0, &staging, 0, buffer.size());
        self.submit(encoder.finish());
        self.read_buffer(&staging)
    }

    /// Reads `bytes` of a `COPY_SRC` buffer back from byte `offset` on.
    pub(crate) fn read_back_range(&self, buffer: &wgpu::Buffer, offset: u64, bytes: u64) -> Result<Vec<u8>, GpuError> {
        let staging = self.create_buffer(&wgpu::BufferDescriptor {
            label: Some("readback"),
            size: bytes.max(4),
            usage: wgpu::BufferUsages::MAP_READ | wgpu::BufferUsages::COPY_DST,
            mapped_at_creation: false,
        });
        let mut encoder = self.device.create_command_encoder(&Default::default());
        encoder.copy_buffer_to_buffer(buffer, offset, &staging, 0, bytes);
        self.submit(encoder.finish());
        let mut out = self.read_buffer(&staging)?;
        out.truncate(bytes as usize);
        Ok(out)
    }

    /// Reads `buffers` back whole with one copy, in the same submission as
    /// whatever deferring recorded, and one wait.
    pub(crate) fn read_back_all(&self, buffers: &[&wgpu::Buffer]) -> Result<Vec<Vec<u8>>, GpuError> {
        let mut encoder = self.device.create_command_encoder(&Default::default());
        let staging: Vec<wgpu::Buffer> = buffers
            .iter()
            .map(|b| {
                let s = self.create_buffer(&wgpu::BufferDescriptor {
                    label: Some("readback"),
                    size: b.size(),
                    usage: wgpu::BufferUsages::MAP_READ | wgpu::BufferUsages::COPY_DST,
                    mapped_at_creation: false,
                });
                encoder.copy_buffer_to_buffer(b, 0, &s, 0, b.size());
                s
            })
            .collect();
        self.submit(encoder.finish());
        self.flush();
        let (tx, rx) = std::sync::mpsc::channel();
        for s in &staging {
            let tx = tx.clone();
            s.slice(..).map_async(wgpu::MapMode::Read, move |r| {
                let _ = tx.send(r);
            });
        }
        self.blocking_poll().map_err(GpuError::Readback)?;
        for _ in &staging {
            rx.recv().map_err(|e| GpuError::Readback(e.to_string()))?.map_err(|e| GpuError::Readback(e.to_string()))?;
        }
        staging
            .iter()
            .map(|s| {
                let bytes = s.slice(..).get_mapped_range().map_err(|e| GpuError::Readback(e.to_string()))?.to_vec();
                s.unmap();
                self.count_read_back(bytes.len() as u64);
                Ok(bytes)
            })
            .collect()
    }

    /// Copies `buffer` (a `MAP_READ | COPY_DST` staging buffer already filled) into a vector.
    pub(crate) fn read_buffer(&self, buffer: &wgpu::Buffer) -> Result<Vec<u8>, GpuError> {
        // The copy into `buffer` may be among the recorded commands: they go first.
        self.flush();
        let slice = buffer.slice(..);
        let (tx, rx) = std::sync::mpsc::channel();
        slice.map_async(wgpu::MapMode::Read, move |r| {
            let _ = tx.send(r);
        });
        self.blocking_poll().map_err(GpuError::Readback)?;
        rx.recv().map_err(|e| GpuError::Readback(e.to_string()))?.map_err(|e| GpuError::Readback(e.to_string()))?;
        let bytes = slice.get_mapped_range().map_err(|e| GpuError::Readback(e.to_string()))?.to_vec();
        buffer.unmap();
        self.transfers.down.fetch_add(bytes.len() as u64, std::sync::atomic::Ordering::Relaxed);
        Ok(bytes)
    }
}

/// Whether a kept buffer of `size` bytes fits `need`: it holds them, and not
/// more than twice as many (a much larger one is let go after a while,
/// [`FrameBuffer::serves`]).
fn holds(size: u64, need: u64) -> bool {
    size >= need && size / 2 <= need
}

/// A compute-visible storage-buffer layout entry at `binding`.
pub(crate) fn storage_entry(binding: u32, read_only: bool) -> wgpu::BindGroupLayoutEntry {
    wgpu::BindGroupLayoutEntry {
        binding,
        visibility: wgpu::ShaderStages::COMPUTE,
        ty: wgpu::BindingType::Buffer {
            ty: wgpu::BufferBindingType::Storage { read_only },
            has_dynamic_offset: false,
            min_binding_size: None,
        },
        count: None,
    }
}

/// A bind group of `buffers` at bindings 0, 1, … (a layout of storage buffers).
pub(crate) fn buffers_bind_group(
    ctx: &GpuContext,
    label: &str,
    layout: &wgpu::BindGroupLayout,
    buffers: &[wgpu::Buffer],
) -> wgpu::BindGroup {
    let entries: Vec<wgpu::BindGroupEntry<'_>> = buffers
        .iter()
        .enumerate()
        .map(|(i, b)| wgpu::BindGroupEntry { binding: i as u32, resource: b.as_entire_binding() })
        .collect();
    ctx.create_bind_group(&wgpu::BindGroupDescriptor { label: Some(label), layout, entries: &entries })
}

/// A compute-visible uniform-buffer layout entry at `binding`.
pub(crate) fn uniform_entry(binding: u32) -> wgpu::BindGroupLayoutEntry {
    wgpu::BindGroupLayoutEntry {
        binding,
        visibility: wgpu::ShaderStages::COMPUTE,
        ty: wgpu::BindingType::Buffer {
            ty: wgpu::BufferBindingType::Uniform,
            has_dynamic_offset: false,
            min_binding_size: None,
        },
        count: None,
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn read(ctx: &GpuContext, b: &wgpu::Buffer, bytes: u64) -> Vec<u8> {
        ctx.read_back_range(b, 0, bytes).expect("read back")
    }

    /// While deferring, `record`'s commands share one open encoder, and a
    /// buffer submitted after a record runs after it: copies into one buffer,
    /// recorded and submitted in turn, land in program order, in one
    /// submission.
    #[test]
    fn recorded_and_submitted_commands_run_in_program_order_in_one_submission() {
        let Some(ctx) = GpuContext::headless_unless_absent().expect("device") else { return };
        let usage = wgpu::BufferUsages::COPY_SRC | wgpu::BufferUsages::COPY_DST;
        let sources: Vec<wgpu::Buffer> = (1..=3u8).map(|k| ctx.buffer_with("test source", &[k; 16], usage)).collect();
        let target = ctx.buffer_with("test target", &[0; 16], usage);
        let copy = |e: &mut wgpu::CommandEncoder, k: usize| e.copy_buffer_to_buffer(&sources[k], 0, &target, 0, 16);
        // (recorded?, source) in program order: the last copy must win.
        let sequences: [&[(bool, usize)]; 3] =
            [&[(true, 0), (false, 1)], &[(false, 0), (true, 1)], &[(true, 2), (false, 0), (true, 1), (false, 2)]];
        for ops in sequences {
            ctx.defer_submissions(true);
            let before = ctx.counters();
            for &(recorded, k) in ops {
                if recorded {
                    ctx.record(|e| copy(e, k));
                } else {
                    let mut submitted = ctx.device.create_command_encoder(&Default::default());
                    copy(&mut submitted, k);
                    ctx.submit(submitted.finish());
                }
            }
            ctx.defer_submissions(false);
            assert_eq!((ctx.counters() - before).submissions, 1);
            let last = ops.last().expect("an op").1 as u8 + 1;
            assert_eq!(read(&ctx, &target, 16), [last; 16], "copies {ops:?}");
        }
        // Not deferring: recorded and submitted at once.
        let before = ctx.counters();
        ctx.record(|e| copy(e, 0));
        assert_eq!((ctx.counters() - before).submissions, 1);
        assert_eq!(read(&ctx, &target, 16), [1; 16]);
    }

    /// While deferring, buffer writes are copies from the upload arena, recorded
    /// in program order among the passes: a buffer written, copied, written
    /// again and copied gives each copy its own contents, in one submission.
    /// The arena's chunks are made on the first frame (one of 64 KiB, one for
    /// a write larger than that) and refilled on the next, where the copies
    /// read that frame's bytes; a write larger than the arena takes gets a
    /// staging buffer of its own.
    #[test]
    fn deferred_writes_share_the_upload_arena_and_land_in_program_order() {
        let Some(ctx) = GpuContext::headless_unless_absent().expect("device") else { return };
        let usage = wgpu::BufferUsages::COPY_SRC | wgpu::BufferUsages::COPY_DST;
        let target = ctx.buffer_with("test target", &[0; 16], usage);
        let snaps: Vec<wgpu::Buffer> = (0..2).map(|_| ctx.buffer_with("test snapshot", &[0; 16], usage)).collect();
        let big_bytes = 100 << 10;
        let big = ctx.buffer_with("test big", &vec![0; big_bytes], usage);
        let snapshot = |k: usize| ctx.record(|e| e.copy_buffer_to_buffer(&target, 0, &snaps[k], 0, 16));
        for frame in 1..=2u8 {
            ctx.defer_submissions(true);
            let before = ctx.counters();
            ctx.write_buffer(&target, 0, &[frame; 16]);
            snapshot(0);
            ctx.write_buffer(&target, 0, &[frame + 10; 16]);
            snapshot(1);
            ctx.write_buffer(&big, 0, &vec![frame; big_bytes]);
            ctx.write_buffer(&target, 8, &[frame + 20; 8]);
            ctx.defer_submissions(false);
            let d = ctx.counters() - before;
            assert_eq!((d.submissions, d.bytes_up), (1, 16 + 16 + big_bytes as u64 + 8));
            assert_eq!(d.buffers_made, if frame == 1 { 2 } else { 0 }, "frame {frame}");
            assert_eq!(read(&ctx, &snaps[0], 16), [frame; 16]);
            assert_eq!(read(&ctx, &snaps[1], 16), [frame + 10; 16]);
            assert_eq!(read(&ctx, &target, 16), [[frame + 10; 8], [frame + 20; 8]].concat());
            assert_eq!(read(&ctx, &big, big_bytes as u64), vec![frame; big_bytes]);
        }
        let huge_bytes = UPLOAD_LARGEST_BYTES as usize + 16;
        let huge = ctx.buffer_with("test huge", &vec![0; huge_bytes], usage);
        ctx.defer_submissions(true);
        let before = ctx.counters();
        ctx.write_buffer(&target, 0, &[7; 16]);
        snapshot(0);
        ctx.write_buffer(&huge, 0, &vec![9; huge_bytes]);
        ctx.record(|e| e.copy_buffer_to_buffer(&huge, 0, &target, 0, 16));
        snapshot(1);
        ctx.defer_submissions(false);
        let d = ctx.counters() - before;
        assert_eq!((d.submissions, d.buffers_made), (1, 1), "the huge write's own staging buffer");
        assert_eq!(read(&ctx, &snaps[0], 16), [7; 16]);
        assert_eq!(read(&ctx, &snaps[1], 16), [9; 16]);
        assert_eq!(read(&ctx, &huge, huge_bytes as u64), vec![9; huge_bytes]);
    }

    /// A need that swings between a size and 2.6 times it (the usage scheme's
    /// blend entries, whose Usage Sleeping probes join every tenth update)
    /// keeps the buffer it grew into, where the bare twice-its-bytes window
    /// made one at every swing; a need under half the buffer's size for more
    /// than `KEPT_OVERSIZED_USES` hand-outs in a row lets it go.
    #[test]
    fn a_kept_buffer_rides_out_a_swing_in_its_size_and_lets_go_of_a_lasting_shrink() {
        let Some(ctx) = GpuContext::headless_unless_absent().expect("device") else { return };
        let usage = wgpu::BufferUsages::STORAGE | wgpu::BufferUsages::COPY_SRC;
        let (small, large) = (vec![1u8; 1000], vec![2u8; 2600]);
        ctx.defer_submissions(true);
        let hand_out = |contents: &[u8]| {
            let b = ctx.buffer_rewritten("test swing", 3, contents, usage);
            ctx.submit(ctx.device.create_command_encoder(&Default::default()).finish());
            ctx.flush();
            b
        };
        hand_out(&small);
        let grown = hand_out(&large);
        // Written in place: through the upload arena, whose first chunk this makes.
        assert_eq!(hand_out(&small), grown);
        let before = ctx.counters().buffers_made;
        for update in 0..40 {
            let contents = if update % 10 == 0 { &large } else { &small };
            assert_eq!(hand_out(contents), grown, "update {update}");
        }
        assert_eq!(ctx.counters().buffers_made - before, 0, "a swing made buffers");
        assert_eq!(read(&ctx, &grown, 1000), small);
        hand_out(&large);
        for _ in 0..KEPT_OVERSIZED_USES {
            assert_eq!(hand_out(&small), grown);
        }
        let shrunk = hand_out(&small);
        ctx.defer_submissions(false);
        assert_ne!(shrunk, grown, "kept past KEPT_OVERSIZED_USES hand-outs under half its size");
        assert!(shrunk.size() < grown.size() / 2);
        assert_eq!(read(&ctx, &shrunk, 1000), small);
    }

    /// `buffer_rewritten` writes in place only where no pass recorded since the
    /// last submission may read the old contents; else the old buffer keeps
    /// them and a new one takes the new. What each buffer holds is read back.
    #[test]
    fn a_rewritten_buffer_handed_out_since_the_last_submission_is_replaced_not_overwritten() {
        let Some(ctx) = GpuContext::headless_unless_absent().expect("device") else { return };
        let usage = wgpu::BufferUsages::STORAGE | wgpu::BufferUsages::COPY_SRC;
        let (a, b, c) = ([1u8; 32], [2u8; 32], [3u8; 32]);
        ctx.defer_submissions(true);
        let first = ctx.buffer_rewritten("test input", 7, &a, usage);
        // Same contents: the same buffer, nothing uploaded.
        let before = ctx.counters();
        assert_eq!(ctx.buffer_rewritten("test input", 7, &a, usage), first);
        assert_eq!((ctx.counters() - before).bytes_kept, 32);
        assert_eq!((ctx.counters() - before).buffers_made, 0);
        // New contents before any submission: `first` may be read by a pass
        // recorded meanwhile, so it keeps `a` and a new buffer holds `b`.
        let second = ctx.buffer_rewritten("test input", 7, &b, usage);
        assert_ne!(second, first);
        // Flushing nothing is no submission: still replaced, not overwritten.
        ctx.flush();
        assert_ne!(ctx.buffer_rewritten("test input", 7, &a, usage), second);
        let second = ctx.buffer_rewritten("test input", 7, &b, usage);
        ctx.submit(ctx.device.create_command_encoder(&Default::default()).finish());
        ctx.flush();
        // After a submission: rewritten in place, the bytes staged in the
        // upload arena (whose first chunk this write makes).
        let before = ctx.counters();
        let third = ctx.buffer_rewritten("test input", 7, &c, usage);
        assert_eq!(third, second);
        assert_eq!((ctx.counters() - before).buffers_made, 1);
        assert_eq!((ctx.counters() - before).bytes_up, 32);
        ctx.submit(ctx.device.create_command_encoder(&Default::default()).finish());
        ctx.flush();
        // The next frame's rewrite makes no buffer at all.
        let before = ctx.counters();
        assert_eq!(ctx.buffer_rewritten("test input", 7, &b, usage), second);
        assert_eq!((ctx.counters() - before).buffers_made, 0);
        ctx.submit(ctx.device.create_command_encoder(&Default::default()).finish());
        ctx.flush();
        let third = ctx.buffer_rewritten("test input", 7, &c, usage);
        ctx.defer_submissions(false);
        assert_eq!(read(&ctx, &first, 32), a);
        assert_eq!(read(&ctx, &third, 32), c);
        // Another key is another buffer.
        assert_ne!(ctx.buffer_rewritten("test input", 8, &c, usage), third);
    }

    /// `bind_group_kept` hands out the bind group made for the same layout and
    /// buffers, and keeps the last two: a pass alternating between two ray
    /// batches makes none after the first two frames.
    #[test]
    fn kept_bind_groups_follow_the_buffers_they_bind() {
        let Some(ctx) = GpuContext::headless_unless_absent().expect("device") else { return };
        let layout = ctx.pass_layout("test", &[true]);
        let uniform = ctx.buffer_with("u", &[0; 16], wgpu::BufferUsages::UNIFORM);
        let storage = |n| ctx.buffer_with("s", &[n; 16], wgpu::BufferUsages::STORAGE);
        let (s1, s2, s3) = (storage(1), storage(2), storage(3));
        let made = |f: &dyn Fn()| {
            let before = ctx.counters().bind_groups_made;
            f();
            ctx.counters().bind_groups_made - before
        };
        let group = |s: &wgpu::Buffer| ctx.bind_group_kept("test", 0, &layout, &[&uniform, s]);
        assert_eq!(made(&|| drop(group(&s1))), 1);
        assert_eq!(made(&|| drop(group(&s2))), 1);
        assert_eq!(made(&|| drop((group(&s1), group(&s2), group(&s1)))), 0, "two alternating: kept");
        assert_eq!(group(&s1), group(&s1));
        assert_ne!(group(&s1), group(&s2));
        // A third pushes out the least recently used (s1's, s2's used since).
        assert_eq!(made(&|| drop(group(&s3))), 1);
        assert_eq!(made(&|| drop(group(&s2))), 0);
        assert_eq!(made(&|| drop(group(&s1))), 1);
    }
}
