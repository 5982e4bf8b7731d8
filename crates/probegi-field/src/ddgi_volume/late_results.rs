//! Results of update batches held until they are due: the queue the usage
//! scheme's counts (`usage_states`, `probe_usage_lag_updates`) and the ray
//! budget's probe changes (`probe_budget`, `ray_budget_change_lag_updates`)
//! share. A batch is queued with what the volume knows of it then (`K`) and
//! its result (`T`), or without the result while a device still holds it; a
//! batch is due once `lag` batches were queued after it, and one whose result
//! never came is dropped then.

use std::collections::VecDeque;

/// The batches waiting for their results' use, oldest first.
#[derive(Clone, Debug)]
pub(super) struct LateResults<K, T> {
    pending: VecDeque<(u64, K, Option<T>)>,
    /// One past the last batch number queued.
    next_batch: u64,
}

impl<K, T> Default for LateResults<K, T> {
    fn default() -> Self {
        Self { pending: VecDeque::new(), next_batch: 0 }
    }
}

impl<K, T> LateResults<K, T> {
    /// Queues the set's update batch `batch` (numbers only grow).
    pub(super) fn push(&mut self, batch: u64, known: K, result: Option<T>) {
        self.pending.push_back((batch, known, result));
        self.next_batch = batch + 1;
    }

    /// Batch `batch`'s result, where it is queued and waits for it.
    pub(super) fn fill(&mut self, batch: u64, result: T) {
        if let Some((_, _, waiting @ None)) = self.pending.iter_mut().find(|(b, _, _)| *b == batch) {
            *waiting = Some(result);
        }
    }

    /// What was known of batch `batch` when queued, where it waits for its result.
    pub(super) fn waiting(&self, batch: u64) -> Option<&K> {
        self.pending.iter().find(|(b, _, r)| *b == batch && r.is_none()).map(|(_, k, _)| k)
    }

    /// Takes the batches now `lag` old, oldest first, with their results
    /// (those whose result never came are dropped).
    pub(super) fn take_due(&mut self, lag: u32) -> Vec<(u64, K, T)> {
        let due = self.pending.len().saturating_sub(lag as usize);
        self.pending.drain(..due).filter_map(|(b, k, r)| r.map(|r| (b, k, r))).collect()
    }

    /// One past the last batch number queued.
    pub(super) fn next_batch(&self) -> u64 {
        self.next_batch
    }

    /// Drops every batch waiting.
    pub(super) fn clear(&mut self) {
        self.pending.clear();
    }
}
