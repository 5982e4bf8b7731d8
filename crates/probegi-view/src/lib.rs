//! probegi-view: the field live, one frame at a time through a fly camera
//! (issue "`probegi view`…"). Built so far, without a window:
//! - [`fly_camera`]: WASD/QE and mouse look, a speed on the scroll wheel,
//!   reset to the scene's camera;
//! - [`input_script`]: timed key and mouse events from a small text format,
//!   so a run is reproducible without a person;
//! - [`scripted_run`]: the headless run (`probegi view --headless`): the
//!   script drives the fly camera frame by frame while the field keeps
//!   updating (`probegi_cpu::frame_loop::FrameStepper`, on either backend).
//!
//! Not built yet: the window (winit), the panels (egui), the reference one key
//! away. The UI crates will come into this crate only, so the library crates
//! never compile them.

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
