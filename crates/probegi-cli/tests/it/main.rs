//! probegi-cli's integration tests, one binary (each former test file a
//! module): one link instead of one per file. Run one file's tests with
//! `cargo test -p probegi-cli --test it MODULE::`.

mod common;

mod cli;
mod fuzz_args;
mod never_silently_wrong;
mod readme_blocks;
mod view_window;
