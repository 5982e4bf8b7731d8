//! What the GPU tests share: the device (or a clear skip), the field-keeping
//! tracer `--backend wgpu` uses, a small DDGI render on either backend, the
//! shared scenes, and how far a device's ray-triangle answer may stray from the
//! CPU's (`trace_error`).

#![allow(dead_code)]

pub mod trace_error;

use std::sync::Arc;

use probegi_core::camera::CameraRays;
use probegi_core::ddgi_settings::DdgiVolumeSettings;
use probegi_core::image::Image;
use probegi_field::{ProbeBatchTracer, ProbeTracerHandle};
use probegi_frame::frame_loop::{GiMethod, RenderSettings, render_frames};
use probegi_scene::{BvhSettings, BvhTracer, Scene};
use probegi_wgpu::GpuContext;
use probegi_wgpu::wgpu_field_backend::WgpuProbeTracer;

/// A headless device, or `None` when there is none and `PROBEGI_REQUIRE_GPU` is
/// not set (see `GpuContext::headless_unless_absent`).
pub fn context() -> Option<GpuContext> {
    GpuContext::headless_unless_absent().expect("PROBEGI_REQUIRE_GPU is set")
}

/// The shared data folder (the one holding `scenes/`): `$PROBEGI_SHARED_DIR` when
/// set (`probegi_scene::file_lookup::SHARED_DIR_ENV`, the binary's convention),
/// else `shared/` beside the checkout this test was built in. The variable lets
/// a test binary run away from its checkout (`scripts/gpu-tests.sh run`).
pub fn shared_dir() -> std::path::PathBuf {
    match std::env::var_os(probegi_scene::file_lookup::SHARED_DIR_ENV) {
        Some(dir) => std::path::PathBuf::from(dir),
        None => std::path::PathBuf::from(env!("CARGO_MANIFEST_DIR")).join("../../../shared"),
    }
}

/// A file of this repository, `rel` from its root (`scenes/moving-box.toml`): the
/// checkout the test was built in, or else the first ancestor of the working
/// directory that has it (a test binary run from another copy's root, as
/// `scripts/gpu-tests.sh run` does on a machine without the toolchain).
pub fn repo_file(rel: &str) -> String {
    let built = std::path::PathBuf::from(env!("CARGO_MANIFEST_DIR")).join("../..").join(rel);
    let here = std::env::current_dir().ok();
    let found = std::iter::once(built)
        .chain(here.iter().flat_map(|d| d.ancestors().map(|a| a.join(rel))))
        .find(|p| p.is_file())
        .unwrap_or_else(|| panic!("{rel} is neither in the checkout the test was built in nor above {here:?}"));
    found.to_string_lossy().into_owned()
}

/// A file under the shared folder's `scenes/` (see [`shared_dir`]).
pub fn shared(path: &str) -> String {
    shared_dir().join("scenes").join(path).to_string_lossy().into_owned()
}

/// `scene` on the device as `--backend wgpu` has it: the field kept there and
/// the camera frame rendered there; `None` without a device (see [`context`]).
pub fn resident_tracer(scene: &Scene) -> Option<WgpuProbeTracer> {
    let bvh = BvhTracer::for_scene(scene, BvhSettings::default());
    let t = WgpuProbeTracer::new(context()?, scene, &bvh, true).expect("upload").keeping_field(true);
    assert!(t.renders_camera(), "{:?}", t.shading_note);
    Some(t)
}

/// `frames` frames of DDGI with `s` at 64×48 from the scene's camera at
/// `seed`, on the CPU or (with `gpu`) the device; the last frame.
pub fn render_ddgi(
    scene: &Scene,
    frames: u32,
    seed: u64,
    s: DdgiVolumeSettings,
    gpu: Option<Arc<WgpuProbeTracer>>,
) -> Image {
    let cpu = BvhTracer::for_scene(scene, BvhSettings::default());
    let camera = CameraRays::new(&scene.camera.expect("camera"), 64, 48);
    let rs = RenderSettings {
        width: 64,
        height: 48,
        frames,
        seed,
        gi: GiMethod::Ddgi(Box::new(s)),
        probe_tracer: gpu.map(|g| ProbeTracerHandle(g as Arc<dyn ProbeBatchTracer>)),
        ..Default::default()
    };
    let out = render_frames(scene, &cpu, &camera, &rs, |_, _| {});
    assert!(out.stats.error.is_none(), "{:?}", out.stats.error);
    out.image
}
