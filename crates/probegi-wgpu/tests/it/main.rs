//! probegi-wgpu's integration tests, one binary (each former test file a
//! module): one link instead of one per file. Run one file's tests with
//! `cargo test -p probegi-wgpu --test it MODULE::`.

mod common;

mod blend_equivalence;
mod camera_equivalence;
mod device_frame;
mod field_equivalence;
mod field_on_the_device;
mod fuzz_seam_rays;
mod query_equivalence;
mod ray_budget_equivalence;
mod ray_gen_equivalence;
mod screen_requests_equivalence;
mod scroll_on_the_gpu;
mod shade_flags;
mod shadow_field_equivalence;
mod trace_equivalence;
mod wgpu_embed_example;
