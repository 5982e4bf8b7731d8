//! Row-parallel image loops. Work is split by rows and every pixel's random
//! numbers come from its own index, so results are bit-identical for any
//! thread count.

use rayon::prelude::*;

/// Calls `shade_row(y, row)` for every row of a `width`-wide buffer in parallel,
/// then `on_row_done` (for progress bars). Returns the sum of what the rows return
/// (ray counts).
pub fn for_each_row<T, F, P>(buffer: &mut [T], width: usize, shade_row: F, on_row_done: P) -> u64
where
    T: Send,
    F: Fn(usize, &mut [T]) -> u64 + Sync,
    P: Fn() + Sync,
{
    buffer
        .par_chunks_mut(width.max(1))
        .enumerate()
        .map(|(y, row)| {
            let n = shade_row(y, row);
            on_row_done();
            n
        })
        .sum()
}
