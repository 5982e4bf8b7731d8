//! probegi-field's integration tests, one binary (each former test file a
//! module): one link instead of one per file. Run one file's tests with
//! `cargo test -p probegi-field --test it MODULE::`.

mod hysteresis_ramp;
mod init_rounds;
mod screen_requests;
mod steady_frames;
mod tracking_bounds;
