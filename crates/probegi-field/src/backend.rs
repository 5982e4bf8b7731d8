//! The traits a backend implements to run the field's update on its device,
//! split by responsibility (RTXGI's per-API peers of one volume base):
//!
//! - [`ProbeBatchTracer`]: trace a probe ray batch (and optionally shade it, pose
//!   the scene, render the camera frame) while the host keeps the atlases;
//! - [`DeviceField`]: the passes of a device that keeps the field resident:
//!   trace with the hits kept there, the relocation and classification rounds,
//!   shade + blend + border into its own atlases, and the copy back.
//!
//! A tracer that can keep the field says so through
//! [`ProbeBatchTracer::device_field`]. Every method that may decline returns
//! `None` ("go the host way"); a failure is a [`BackendError`].

use glam::Vec3;
use probegi_core::camera::CameraRays;
use probegi_core::ddgi_volume_blend::DdgiFieldSetView;
use probegi_scene::{RayHit, Scene};

use crate::ddgi_volume::DdgiVolume;
use crate::device_plans::{
    DeviceInitChain, DeviceInitResult, DeviceUsageCounts, DeviceUsageRequest, DeviceVolumeBlend,
};
use crate::seam::{ProbeRayBatch, SeamError};

/// Why a backend could not do what the field asked of it.
#[derive(Clone, Debug, PartialEq, Eq)]
pub enum BackendError {
    /// The backend cannot run this at all (e.g. it holds no field, or does not
    /// shade this scene).
    Unsupported(String),
    /// The device failed or refused an input (out of memory, a lost device, a
    /// buffer over the adapter's limits, results of the wrong size).
    Device(String),
    /// The backend's results do not fit the seam's exchange (e.g. hits of the
    /// wrong count).
    Seam(SeamError),
}

impl From<SeamError> for BackendError {
    fn from(e: SeamError) -> Self {
        BackendError::Seam(e)
    }
}

impl std::fmt::Display for BackendError {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        match self {
            BackendError::Unsupported(what) => write!(f, "not supported by this backend: {what}"),
            BackendError::Device(what) => f.write_str(what),
            BackendError::Seam(e) => write!(f, "{e}"),
        }
    }
}

impl std::error::Error for BackendError {}

/// Trace (and optionally shade) work a render hands to another device: every
/// probe ray batch's trace, its shade and the camera frame. The CLI's
/// `--backend wgpu` plugs `probegi_wgpu::wgpu_field_backend::WgpuProbeTracer`
/// in here. The hits must be what `RayTracer::closest_hit` returns for the ray
/// `Ray::segment(origin, direction, max_distance)` (both faces).
pub trait ProbeBatchTracer: Sync {
    /// Closest hits of every ray of `batch`, in batch order, into `hits` (resized).
    /// `static_only`: an initialisation round, which must see static geometry only.
    fn closest_hits(
        &self,
        batch: &ProbeRayBatch,
        static_only: bool,
        hits: &mut Vec<Option<RayHit>>,
    ) -> Result<(), BackendError>;

    /// Shades the update batch this tracer traced last (the shade pass of
    /// `probegi_cpu::probe_shade` on another device) into `radiance` (one per
    /// batch ray), or returns `None` to leave the shading to the CPU. `field` is
    /// the set as queries read it, `volumes` the set's volumes (for their shading settings).
    fn shade_batch(
        &self,
        _batch: &ProbeRayBatch,
        _field: &DdgiFieldSetView<'_>,
        _volumes: &[DdgiVolume],
        _seed: u64,
        _frame: u32,
        _radiance: &mut Vec<Vec3>,
    ) -> Option<Result<(), BackendError>> {
        None
    }

    /// The scene as it is at frame `frame` (an animated scene, posed by
    /// `Scene::set_frame_from`), before the frame's update: a device that keeps
    /// its own copy of what changes (the lights, the moving objects' triangles
    /// and their placement in the top level) updates it here.
    fn pose_scene(&self, _scene: &Scene, _frame: f32) -> Result<(), BackendError> {
        Ok(())
    }

    /// Renders the frame's camera image on the other device (the G-buffer and
    /// camera passes of `probegi_frame::frame_loop` under DDGI) into `out`
    /// ([`CameraFrameOut`]), returning (pixels on a surface with a
    /// diffuse albedo, those of them the field left unlit), or `None` to leave
    /// the camera to the CPU. With `field_on_device` the device's own atlases are
    /// the current ones (`field`'s are stale; its per-probe data is current).
    /// `area_samples` and `sky_samples` are the CPU's camera `DirectSettings`
    /// (the sky's are used under a sky map only).
    /// With `probe_requests` (the screen scheme), the device also fills it
    /// with the request bitset of the probes its pixels' queries read
    /// (`DdgiFieldSet::probe_request_layout` over `field`'s members; the
    /// caller sizes it).
    #[allow(clippy::too_many_arguments)]
    fn camera_frame(
        &self,
        _camera: &CameraRays,
        _field: &DdgiFieldSetView<'_>,
        _field_on_device: bool,
        _area_samples: u32,
        _sky_samples: u32,
        _second_order: bool,
        _frame: u32,
        _seed: u64,
        _out: CameraFrameOut<'_>,
        _probe_requests: Option<&mut Vec<u32>>,
    ) -> Option<Result<(usize, usize), BackendError>> {
        None
    }

    /// The field-resident passes, when this tracer can keep the field on its device.
    fn device_field(&self) -> Option<&dyn DeviceField> {
        None
    }

    /// Wall milliseconds the host has spent blocked waiting for this tracer's
    /// device so far (`None`: it keeps no count); a benchmark's frame time
    /// less the difference is the host's share of the frame.
    fn device_wait_ms(&self) -> Option<f64> {
        None
    }

    /// The camera frame kept on the device, start to finish
    /// ([`crate::device_frame`]), when this tracer renders it there; the
    /// frame loop then reads no pixels back but those it is asked for.
    fn device_frame(&self) -> Option<&dyn crate::device_frame::DeviceFrame> {
        None
    }
}

/// Where a camera frame writes, per pixel, row-major
/// ([`ProbeBatchTracer::camera_frame`]).
pub struct CameraFrameOut<'a> {
    /// The direct term: emission, direct light, glossy reflections.
    pub direct: &'a mut [Vec3],
    /// The field's irradiance at the pixel's surface, over π: the field term
    /// before its diffuse albedo.
    pub irradiance_over_pi: &'a mut [Vec3],
    /// The diffuse albedo that weighs `irradiance_over_pi` (zero where the pixel
    /// sees no surface); a still camera accumulates it, so that it is antialiased.
    pub albedo: &'a mut [Vec3],
    /// Where the pixel's primary ray met the scene, metres, world space: where
    /// a moving camera's temporal filter finds the pixel in the last frame.
    pub position_m: &'a mut [Vec3],
    /// The geometric normal there, facing the camera; zero where the ray met
    /// nothing (the sky).
    pub normal: &'a mut [Vec3],
}

/// The passes of a device that keeps an update's hits and the field's atlases
/// where it computes them (seed 003 §4.3–4.5 on the device), so that neither
/// the rays' results nor the atlases cross to the host. Each `None` leaves that
/// step to the host way ([`ProbeBatchTracer::closest_hits`]): a batch too large
/// for the device, a pass the adapter cannot bind.
pub trait DeviceField: Sync {
    /// Traces the update batch and keeps its hits on the device, for
    /// [`Self::shade_and_blend`]. With `usage`
    /// ([`DdgiFieldSet::device_usage_request`](crate::DdgiFieldSet::device_usage_request)),
    /// counts seed 003's usage (usage, relevant, backfaces;
    /// `probegi_core::probe_classification::probe_usage`) of every entry of
    /// `batch.probes` with its volume's cage diagonal, and returns the counts
    /// of the set's earlier batches now `usage.lag_updates` old, oldest
    /// first, without waiting for the device unless it has not finished them;
    /// otherwise an empty vector.
    fn trace_resident(
        &self,
        batch: &ProbeRayBatch,
        usage: Option<&DeviceUsageRequest>,
    ) -> Option<Result<Vec<DeviceUsageCounts>, BackendError>>;

    /// Runs every initialisation round of `plan` (per volume, `None`: none
    /// pending) chained on the device, with one submission and no result
    /// read back between rounds: per volume of the plan, its offsets and
    /// states.
    fn initialise(
        &self,
        plan: &[Option<DeviceInitChain<'_>>],
    ) -> Option<Result<Vec<Option<DeviceInitResult>>, BackendError>>;

    /// Shades the batch [`Self::trace_resident`] traced and blends and borders
    /// it by `plan` into the atlases the device holds. `field` is the set as
    /// queries read it (grids, relocation offsets, usable probes); with
    /// `upload_atlases` its atlases are current on the host and replace the
    /// device's first. Returns wall milliseconds by pass (`shade`, `blend`: blend
    /// and border), the host having waited for each, and the probes' change
    /// where the plan asks for it.
    #[allow(clippy::too_many_arguments)]
    fn shade_and_blend(
        &self,
        batch: &ProbeRayBatch,
        field: &DdgiFieldSetView<'_>,
        upload_atlases: bool,
        plan: &[DeviceVolumeBlend<'_>],
        volumes: &[DdgiVolume],
        seed: u64,
        frame: u32,
    ) -> Result<crate::device_plans::DeviceBlendOutput, BackendError>;

    /// Whether [`Self::trace_resident`] makes an update batch's rays on the
    /// device from its `generated` records, so that the set can plan update
    /// batches without per-ray arrays
    /// ([`DdgiFieldSet::set_update_rays_on_device`](crate::DdgiFieldSet::set_update_rays_on_device)).
    fn generates_update_rays(&self) -> bool {
        false
    }

    /// Whether [`Self::shade_and_blend`] also runs the shadowing field's update
    /// (`DeviceVolumeBlend::shadow`: shadow rays from the previous update
    /// batch's hits, which the device keeps, and the occlusion blend), and
    /// [`Self::download_field`] copies the occlusion maps back
    /// ([`DdgiFieldSet::set_shadow_on_device`](crate::DdgiFieldSet::set_shadow_on_device)).
    fn blends_shadow_field(&self) -> bool {
        false
    }

    /// Copies the atlases of volume `index` as the device holds them into `volume`'s own.
    fn download_field(&self, index: usize, volume: &mut DdgiVolume) -> Result<(), BackendError>;
}

/// Shareable handle of a [`ProbeBatchTracer`] for render settings.
#[derive(Clone)]
pub struct ProbeTracerHandle(pub std::sync::Arc<dyn ProbeBatchTracer>);

impl std::fmt::Debug for ProbeTracerHandle {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.write_str("ProbeTracerHandle")
    }
}
