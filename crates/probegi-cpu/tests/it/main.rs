//! probegi-cpu's integration tests, one binary (each former test file a
//! module): one link instead of one per file. Run one file's tests with
//! `cargo test -p probegi-cpu --test it MODULE::`.

mod common;

mod analytic;
mod cutouts;
mod ddgi;
mod dynamic;
mod embed_example;
mod glossy;
mod leak_ablation;
mod moving_objects;
mod probe_states_real_scenes;
mod production;
mod ray_budget;
mod reference_image;
mod sh_probes;
mod shadow_field;
mod soak;
mod temporal_filter;
mod world_scale;
