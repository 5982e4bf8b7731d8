//! Results the host reads some update batches after the pass that made them
//! (the usage scheme's counts, `probe_usage`; the ray budget's probe changes,
//! `probe_change`), so that an update never waits on the device for them
//! (issue "The field update at the seeds' GPU rates…", goal 2).
//!
//! Each result is copied into a staging buffer behind its pass, in the
//! batch's own submission while the context defers; the buffer's map starts
//! once that submission is made. A result is due `lag` batches after its
//! own: it is then read, waited for only if the device has not finished it
//! (lag 0: always read in the batch that made it). Results are kept per
//! (set, batch, part), so several field sets may share a device.

use std::collections::VecDeque;
use std::sync::Arc;
use std::sync::atomic::{AtomicBool, Ordering};

use crate::gpu_context::{GpuContext, GpuError};

/// Results kept waiting at most: beyond it, other sets' oldest are let go (a
/// set that stopped updating leaves its last results behind); the asking
/// set's own are bounded by its lag.
const SLOTS_KEPT: usize = 256;

/// Which result: the field set's identity, the update batch that made it,
/// and its part of the batch (a volume, or 0 where the batch has one).
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub(crate) struct LateKey {
    pub(crate) set_id: u64,
    pub(crate) batch: u64,
    pub(crate) part: u32,
}

/// One result on its way back.
struct Slot {
    key: LateKey,
    /// The staging buffer the result is copied into and its bytes (`None`: an
    /// empty result).
    buffer: Option<wgpu::Buffer>,
    /// `GpuContext::queue_submissions` once the copy was recorded (deferred):
    /// a larger count since means a flush has submitted it.
    recorded_at: u64,
    /// A submission at or after the copy's, once made; its map has started then.
    submission: Option<wgpu::SubmissionIndex>,
    mapped: Arc<AtomicBool>,
}

/// The results on their way back, in the order recorded, and staging
/// buffers free for reuse.
#[derive(Default)]
pub(crate) struct LateReadback {
    free: Vec<wgpu::Buffer>,
    slots: VecDeque<Slot>,
}

impl LateReadback {
    /// Records the copy of `source`'s first `bytes` (none for an empty
    /// result) as `key`'s result; a result already kept under `key` (its
    /// update failed after the pass and the set asks again under the same
    /// batch) is replaced.
    pub(crate) fn push(&mut self, ctx: &GpuContext, key: LateKey, source: Option<(&wgpu::Buffer, u64)>) {
        let buffer = source.map(|(source, bytes)| {
            let staging = self.staging(ctx, bytes);
            ctx.record(|encoder| encoder.copy_buffer_to_buffer(source, 0, &staging, 0, bytes));
            staging
        });
        let mut slot = Slot {
            key,
            buffer,
            recorded_at: ctx.queue_submissions(),
            submission: None,
            mapped: Arc::new(AtomicBool::new(false)),
        };
        if !ctx.deferring() {
            // The copy went with its own submission, the last one.
            slot.start_map(ctx.last_submission());
        }
        if let Some(i) = self.slots.iter().position(|s| s.key == key)
            && let Some(stale) = self.slots.remove(i)
        {
            self.release(stale);
        }
        self.slots.push_back(slot);
    }

    /// The results of set `set_id` from batches up to `last_batch`, oldest
    /// first, each as `decode` makes it of its bytes (empty for an empty
    /// result), read where they are mapped (no copy first), with their keys; starts
    /// the maps of every result submitted since the last call. Other sets'
    /// results beyond [`SLOTS_KEPT`] are let go, oldest first. On an error
    /// the results already read are lost: the set takes nothing from them.
    pub(crate) fn take_due<T>(
        &mut self,
        ctx: &GpuContext,
        set_id: u64,
        last_batch: u64,
        decode: impl Fn(&[u8]) -> T,
    ) -> Result<Vec<(LateKey, T)>, GpuError> {
        let submitted = ctx.queue_submissions();
        for slot in self.slots.iter_mut().filter(|s| s.submission.is_none() && submitted > s.recorded_at) {
            slot.start_map(ctx.last_submission());
        }
        let due = |s: &Slot| s.key.set_id == set_id && s.key.batch <= last_batch;
        let mut out = Vec::new();
        while let Some(i) = self.slots.iter().position(due) {
            let Some(slot) = self.slots.remove(i) else { break };
            let key = slot.key;
            out.push((key, self.read(ctx, slot, &decode)?));
        }
        while self.slots.len() > SLOTS_KEPT {
            let Some(i) = self.slots.iter().position(|s| s.key.set_id != set_id) else { break };
            if let Some(slot) = self.slots.remove(i) {
                self.release(slot);
            }
        }
        Ok(out)
    }

    /// A staging buffer of `bytes`, reused when a free one has the size.
    fn staging(&mut self, ctx: &GpuContext, bytes: u64) -> wgpu::Buffer {
        if let Some(i) = self.free.iter().position(|b| b.size() == bytes) {
            return self.free.swap_remove(i);
        }
        ctx.create_buffer(&wgpu::BufferDescriptor {
            label: Some("late readback"),
            size: bytes,
            usage: wgpu::BufferUsages::MAP_READ | wgpu::BufferUsages::COPY_DST,
            mapped_at_creation: false,
        })
    }

    /// A due result's bytes, `decode`d: submitted first if its copy is still
    /// deferred, waited for if the device has not finished it.
    fn read<T>(&mut self, ctx: &GpuContext, mut slot: Slot, decode: impl Fn(&[u8]) -> T) -> Result<T, GpuError> {
        if slot.buffer.is_none() {
            return Ok(decode(&[]));
        }
        if slot.submission.is_none() {
            slot.start_map(ctx.flush());
        }
        if !slot.mapped.load(Ordering::Acquire) {
            let _ = ctx.device.poll(wgpu::PollType::Poll);
        }
        if !slot.mapped.load(Ordering::Acquire) {
            let submission =
                slot.submission.clone().ok_or_else(|| GpuError::Readback("a result unsubmitted".into()))?;
            ctx.wait_for(submission)?;
        }
        let bytes = match (&slot.buffer, slot.mapped.load(Ordering::Acquire)) {
            (Some(buffer), true) => {
                let view = buffer.slice(..).get_mapped_range().map_err(|e| GpuError::Readback(e.to_string()))?;
                ctx.count_read_back(view.len() as u64);
                Ok(decode(&view))
            }
            _ => Err(GpuError::Readback("a late result could not be mapped".into())),
        };
        self.release(slot);
        bytes
    }

    /// Keeps a slot's staging buffer for reuse where its map has completed
    /// (unmapped first); one whose copy or map is still pending is dropped.
    fn release(&mut self, slot: Slot) {
        let Some(buffer) = slot.buffer else { return };
        if slot.mapped.load(Ordering::Acquire) {
            buffer.unmap();
            if self.free.len() < 8 {
                self.free.push(buffer);
            }
        }
    }
}

impl Slot {
    /// Records the submission that holds the copy (or a later one) and starts the map.
    fn start_map(&mut self, submission: Option<wgpu::SubmissionIndex>) {
        let (Some(buffer), Some(submission)) = (&self.buffer, submission) else { return };
        let flag = self.mapped.clone();
        buffer.slice(..).map_async(wgpu::MapMode::Read, move |r| flag.store(r.is_ok(), Ordering::Release));
        self.submission = Some(submission);
    }
}
