//! probegi-view's integration tests, one binary (each former test file a
//! module): one link instead of one per file. Run one file's tests with
//! `cargo test -p probegi-view --test it MODULE::`.

mod offscreen_equivalence;
mod panels;
mod view_layers;
mod worker;
