//! probegi-view: the field live through a fly camera (issue "`probegi
//! view`…"), in a window or without one.
//! - [`fly_camera`]: WASD/QE and mouse look, a speed on the scroll wheel,
//!   reset to the scene's camera;
//! - [`input_script`]: timed key and mouse events from a small text format,
//!   so a run is reproducible without a person;
//! - [`view_session`]: one viewer frame (input, fly camera, then
//!   `probegi_frame::frame_loop::FrameStepper`, on either backend), with a scene
//!   clock that pauses and steps;
//! - [`scripted_run`]: the headless run (`probegi view --headless`);
//! - [`view_layers`]: the debug views (direct, indirect, albedo, normals,
//!   probes, atlases);
//! - [`viewer_controls`]: what the panels set, live or by rebuilding the field;
//! - [`viewer_worker`]: the frame worker thread (sessions, the path-traced
//!   reference with FLIP, screenshots, reload, adaptive CPU frame size);
//! - [`viewer_panels`]: the egui panels; [`viewer_prefs`]: settings that
//!   persist; [`viewer_window`]: winit + egui-wgpu.
//!
//! The UI crates (winit, egui, egui-winit, egui-wgpu) come into this crate
//! only, so the library crates never compile them.

#![warn(missing_docs)]

pub mod fly_camera;
pub mod input_script;
pub mod scripted_run;
pub mod view_layers;
pub mod view_session;
pub mod viewer_controls;
pub mod viewer_panels;
pub mod viewer_prefs;
pub mod viewer_window;
pub mod viewer_worker;
