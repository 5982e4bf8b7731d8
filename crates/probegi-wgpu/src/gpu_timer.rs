//! GPU time per compute pass from timestamp queries (`Features::TIMESTAMP_QUERY`),
//! for `probegi bench --backend wgpu`. Without the feature every time is `None`
//! and callers fall back to wall-clock time around a submit.

use crate::gpu_context::{GpuContext, GpuError};

/// Begin/end timestamps for `passes` compute passes.
pub struct GpuTimer {
    passes: u32,
    queries: Option<(wgpu::QuerySet, wgpu::Buffer)>,
    period_ns: f64,
}

impl GpuTimer {
    /// Timestamps for `passes` passes (none where the device has no timestamp queries).
    pub fn new(ctx: &GpuContext, passes: u32) -> Self {
        let queries = (ctx.timestamps && passes > 0).then(|| {
            let set = ctx.device.create_query_set(&wgpu::QuerySetDescriptor {
                label: Some("pass timestamps"),
                ty: wgpu::QueryType::Timestamp,
                count: passes * 2,
            });
            let resolve = ctx.create_buffer(&wgpu::BufferDescriptor {
                label: Some("timestamp resolve"),
                size: passes as u64 * 16,
                usage: wgpu::BufferUsages::QUERY_RESOLVE | wgpu::BufferUsages::COPY_SRC,
                mapped_at_creation: false,
            });
            (set, resolve)
        });
        Self { passes, queries, period_ns: ctx.queue.get_timestamp_period() as f64 }
    }

    /// The timestamp writes of pass `i`, or `None` without timestamps.
    pub fn writes(&self, i: u32) -> Option<wgpu::ComputePassTimestampWrites<'_>> {
        let (set, _) = self.queries.as_ref()?;
        (i < self.passes).then_some(wgpu::ComputePassTimestampWrites {
            query_set: set,
            beginning_of_pass_write_index: Some(2 * i),
            end_of_pass_write_index: Some(2 * i + 1),
        })
    }

    /// Records the resolve of every timestamp (after the passes, before submit).
    pub fn resolve(&self, encoder: &mut wgpu::CommandEncoder) {
        if let Some((set, buffer)) = &self.queries {
            encoder.resolve_query_set(set, 0..self.passes * 2, buffer, 0);
        }
    }

    /// Milliseconds per pass of the last submitted resolve; `None` without timestamps.
    pub fn read_ms(&self, ctx: &GpuContext) -> Result<Option<Vec<f64>>, GpuError> {
        let Some((_, buffer)) = &self.queries else { return Ok(None) };
        let bytes = ctx.read_back(buffer)?;
        let ticks: &[u64] = bytemuck::cast_slice(&bytes);
        Ok(Some(ticks.chunks(2).map(|t| t[1].saturating_sub(t[0]) as f64 * self.period_ns * 1e-6).collect()))
    }
}
