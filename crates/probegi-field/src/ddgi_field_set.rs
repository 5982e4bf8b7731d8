//! A set of DDGI volumes and the seam an engine drives it through.
//!
//! The split is RTXGI's integration model: the application owns the acceleration
//! structure and the hit shading; the set owns the probes. One frame's update is a
//! short exchange, the same for one volume or many:
//!
//! ```text
//! set.set_tracking_target(camera)        // tracking windows scroll (seed 004 §7.3)
//! let mut step = set.begin_update(seed, frame);
//! loop {
//!     match step {
//!         UpdateStep::TraceRays => {      // set.ray_batch(): origins, directions, max distances
//!             hits = trace(set.ray_batch());          // signed distance + facing normal per ray
//!             step = set.submit_hits(&hits)?;
//!         }
//!         UpdateStep::ShadeRays => {      // rays with ray_batch().needs_radiance[i]
//!             radiance = shade(set.ray_batch(), &hits, |p, n, v| set.irradiance(p, n, v));
//!             step = set.submit_radiance(&radiance)?;
//!         }
//!         UpdateStep::Done => break,
//!     }
//! }
//! ```
//!
//! A steady frame is one `TraceRays` and one `ShadeRays`: **one ray batch** holds
//! every volume's and every cascade's probe rays (seed 003 §3.3 and §6.2.1, seed
//! 004 Fig. 11), laid out probe by probe. Initialisation (relocation and
//! classification, seed 004 Listings 4–5) adds distance-only `TraceRays` rounds
//! before it, against static geometry only (`ray_batch().static_geometry_only`),
//! on the first frame and when a tracking window scrolls planes in. The set then
//! blends, borders and classifies every volume.
//!
//! The caller's hits are signed distances (front face `t`, back face `−t`, miss
//! `+∞`) and, in the rounds that read it ([`DdgiFieldSet::hit_normals_needed`]:
//! classification), the facing unit normal at the hit. The set applies the backface rule
//! itself (zero radiance, distance −0.2·t), so a caller shades only front hits and
//! misses (misses: the sky or environment). Shading a front hit is direct light
//! plus albedo/π × [`DdgiFieldSet::irradiance`] at the hit, the previous frame's
//! field (so bounces accumulate; seed 000 §3).
//!
//! *Deviation:* seed 003 §6.2.1 updates each cascade "with no knowledge about other
//! cascades". Here a probe ray's hit reads the whole set, so a hit outside a small
//! window reads the coarser volume around it rather than the window's clamped
//! edge probes. (For one volume that is its own field, except that a hit farther
//! than a cell outside its probe box reads zero, as a camera pixel there does.)
//!
//! Tracking targets given while an exchange is under way are applied at the next
//! `begin_update`, so a batch never refers to probes that moved under it.
//!
//! **A device that keeps the field.** A caller whose hits, shading and atlases live
//! on another device (a GPU) reads back only what the set's bookkeeping needs,
//! which [`DdgiFieldSet::hits_needed_on_host`] names per batch: for the
//! initialisation rounds, run back to back there, each probe's offset and
//! (inside, kept) once they all ran ([`DdgiFieldSet::device_init_plan`] →
//! [`DdgiFieldSet::submit_device_init`]), for an update batch the usage
//! counts under the usage scheme or nothing ([`DdgiFieldSet::submit_device_hits`]);
//! then it blends there by [`DdgiFieldSet::device_blend_plan`] and reports with
//! [`DdgiFieldSet::submit_device_blend`]. The volumes' own atlases are then stale
//! ([`DdgiFieldSet::field_on_device`]) until the device's are copied back
//! ([`DdgiFieldSet::accept_host_atlases`]); a host blend refuses to run until then.
//!
//! `probegi_frame::field_update` is the convenience that plays both caller roles
//! with probegi's own scene, tracer and shading, on either path.

use std::collections::BTreeMap;

use glam::Vec3;
use probegi_core::ddgi_settings::DdgiFieldSetSettings;
use probegi_core::ddgi_volume_blend::{DdgiFieldSetView, SetMember, VolumeBlending, field_set_irradiance};
use probegi_core::probe_classification::ProbeUsageCounts;

use crate::backend::{BackendError, ProbeBatchTracer};
use crate::ddgi_volume::{DdgiVolume, SceneEvent, VolumeFrame};
use crate::device_plans::{DeviceInitChain, DeviceInitResult, DeviceVolumeBlend};
pub use crate::seam::{
    BatchProbe, GeneratedProbeRays, HostHits, ProbeRayBatch, ProbeRayBatchKind, ProbeRayHit, SeamError, UpdateStep,
};

/// Any number of DDGI volumes, sampled together (see
/// `probegi_core::ddgi_volume_blend`), updated through one ray batch per frame.
#[derive(Clone, Debug)]
pub struct DdgiFieldSet {
    /// Private so that the per-volume scratch and sampling order stay in step;
    /// see [`Self::volumes`] and [`Self::volumes_mut`].
    volumes: Vec<DdgiVolume>,
    /// How overlapping volumes are weighted at a shading point (multiple volumes, cascades).
    pub blending: VolumeBlending,
    /// Volume indices in sampling order: densest (or finest) first.
    order: Vec<usize>,
    /// The point tracking windows follow (the camera), for camera-aware blending.
    tracking_target_m: Option<Vec3>,
    /// A target given during an exchange, applied at the next `begin_update`.
    pending_target_m: Option<Vec3>,
    /// Probes scrolled in by targets applied at `begin_update`.
    pub last_scrolled_in: usize,
    batch: ProbeRayBatch,
    hits: Vec<ProbeRayHit>,
    /// The hits' signed distances, and the blend's per-ray inputs (backface rule applied).
    distances: Vec<f32>,
    blend_radiance: Vec<Vec3>,
    blend_distance: Vec<f32>,
    frames: Vec<VolumeFrame>,
    expected: UpdateStep,
    init_round: usize,
    seed: u64,
    frame: u32,
    /// Milliseconds of the set's own work in the last update, by pass.
    pub last_pass_ms: BTreeMap<&'static str, f64>,
    /// Rays in the last update batch.
    pub last_batch_rays: u64,
    /// Rays in the last update batch, per volume (in volume order).
    pub last_batch_rays_per_volume: Vec<u64>,
    /// Initialisation rays in the last update.
    pub last_init_rays: u64,
    /// True while another device holds the current atlases (it blended the last
    /// update there) and the volumes' own atlases are stale.
    field_on_device: bool,
    /// Update batches leave their per-ray arrays empty: a device makes the rays
    /// from the batch's `generated` records ([`Self::set_update_rays_on_device`]).
    update_rays_on_device: bool,
    /// The punctual lights the shadowing field serves ([`Self::set_shadow_lights`]).
    shadow_lights: Vec<probegi_scene::PunctualLight>,
    /// A device casts and blends the shadowing field's rays ([`Self::set_shadow_on_device`]).
    shadow_on_device: bool,
    /// A still field's update keeps the last plan ([`Self::set_steady_plans`]).
    steady_plans: bool,
    /// The current update kept the last one's plan (`ddgi_volume::steady_frames`).
    plan_kept: bool,
    /// The current update kept the last one's trace plan alone (the usage
    /// scheme, `ddgi_volume::steady_frames`).
    trace_kept: bool,
    /// The usage scheme's lagged counts (`ddgi_volume::usage_states`): the
    /// set's identity for a device, the next update batch's number, and per
    /// batch whose counts are still on the device its (volume, probe) entries.
    usage_set_id: SetId,
    update_batches: u64,
    usage_on_device: std::collections::VecDeque<(u64, Vec<[u32; 2]>)>,
}

/// A set's identity for a device that keeps usage counts of several sets
/// ([`crate::DeviceUsageRequest::set_id`]): a clone draws its own, so two
/// sets never take each other's counts.
struct SetId(u64);

impl Clone for SetId {
    fn clone(&self) -> Self {
        Self(crate::device_plans::next_plan_id())
    }
}

impl std::fmt::Debug for SetId {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.write_str("SetId")
    }
}

impl DdgiFieldSet {
    /// A set from its settings; volumes without an origin, spacing or
    /// `volume_bounds_m` are fitted to `scene_bounds`; tracking volumes start
    /// centred on `camera_m` when given.
    pub fn new(settings: &DdgiFieldSetSettings, scene_bounds: (Vec3, Vec3), camera_m: Option<Vec3>) -> Self {
        let volumes = settings.volumes.iter().map(|v| DdgiVolume::placed(v.clone(), scene_bounds, camera_m)).collect();
        Self::from_volumes(volumes, settings.blending, camera_m)
    }

    /// A set of volumes made elsewhere.
    pub fn from_volumes(mut volumes: Vec<DdgiVolume>, blending: VolumeBlending, camera_m: Option<Vec3>) -> Self {
        for (i, v) in volumes.iter_mut().enumerate() {
            v.stream = i as u64;
            // Made elsewhere: their public fields may have changed since.
            v.renew_probe_rows_id();
        }
        let mut order: Vec<usize> = (0..volumes.len()).collect();
        // Densest (smallest cell) first; a stable sort keeps the given order on ties.
        let cell = |v: &DdgiVolume| v.grid.spacing_m.element_product();
        order.sort_by(|&a, &b| cell(&volumes[a]).total_cmp(&cell(&volumes[b])));
        let n = volumes.len();
        // Batch numbers only grow, whatever sets these volumes served before.
        let update_batches = volumes.iter().map(|v| v.usage_batches().max(v.change_batches())).max().unwrap_or(0);
        Self {
            volumes,
            blending,
            order,
            tracking_target_m: camera_m,
            pending_target_m: None,
            last_scrolled_in: 0,
            batch: ProbeRayBatch::default(),
            hits: Vec::new(),
            distances: Vec::new(),
            blend_radiance: Vec::new(),
            blend_distance: Vec::new(),
            frames: vec![VolumeFrame::default(); n],
            expected: UpdateStep::Done,
            init_round: 0,
            seed: 0,
            frame: 0,
            last_pass_ms: BTreeMap::new(),
            last_batch_rays: 0,
            last_batch_rays_per_volume: vec![0; n],
            last_init_rays: 0,
            field_on_device: false,
            update_rays_on_device: false,
            shadow_lights: Vec::new(),
            shadow_on_device: false,
            steady_plans: true,
            plan_kept: false,
            trace_kept: false,
            usage_set_id: SetId(crate::device_plans::next_plan_id()),
            update_batches,
            usage_on_device: std::collections::VecDeque::new(),
        }
    }

    /// A set of one volume.
    pub fn single(volume: DdgiVolume) -> Self {
        Self::from_volumes(vec![volume], VolumeBlending::Density, None)
    }

    /// The volumes, in the order they were given.
    pub fn volumes(&self) -> &[DdgiVolume] {
        &self.volumes
    }

    /// The volumes, to change their settings between updates. Changing a volume
    /// during an exchange (between `begin_update` and `Done`) takes effect from
    /// the next update: the current batch keeps the counts it was planned with.
    /// Every volume's rows draw a new identity (`DdgiFieldView::probe_rows_id`):
    /// the next update plans in full and the query's rows are written again,
    /// so a caller that changes nothing reads [`Self::volumes`] instead.
    pub fn volumes_mut(&mut self) -> &mut [DdgiVolume] {
        // Their public fields may change: the rows' identities go (and with
        // them a kept plan, `ddgi_volume::steady_frames`).
        self.volumes.iter_mut().for_each(DdgiVolume::renew_probe_rows_id);
        &mut self.volumes
    }

    /// The volumes, taken out of the set, their rows under new identities
    /// (their public fields may change from here).
    pub fn into_volumes(mut self) -> Vec<DdgiVolume> {
        self.volumes.iter_mut().for_each(DdgiVolume::renew_probe_rows_id);
        self.volumes
    }

    /// The query's view of the set. While [`Self::field_on_device`] its atlases
    /// are stale (the per-probe data is current): copy the device's back first
    /// ([`Self::accept_host_atlases`], `sync_host_atlases`).
    pub fn view(&self) -> DdgiFieldSetView<'_> {
        DdgiFieldSetView {
            members: self
                .order
                .iter()
                .map(|&i| {
                    let v = &self.volumes[i];
                    SetMember {
                        field: v.view_with_rows_id(),
                        volume: i,
                        tracks_camera: v.settings.volume_tracks_camera,
                        occlusion: v.shadow.as_ref().map(|s| &s.occlusion),
                    }
                })
                .collect(),
            blending: self.blending,
            camera_m: self.tracking_target_m,
        }
    }

    /// Irradiance (W·m⁻²) at `position` on a surface with unit `normal` seen along
    /// `view_dir` (toward the viewer), over every volume. Zero where no volume reaches.
    /// For many queries, build [`Self::view`] once and call `field_set_irradiance`.
    pub fn irradiance(&self, position: Vec3, normal: Vec3, view_dir: Vec3) -> Vec3 {
        field_set_irradiance(&self.view(), position, normal, view_dir)
    }

    /// Moves every tracking window toward `target_m` (whole cells; seed 004 §7.3)
    /// and remembers it for camera-aware blending. Returns the probes scrolled in.
    /// During an exchange the move waits for the next `begin_update` (and 0 is returned).
    pub fn set_tracking_target(&mut self, target_m: Vec3) -> usize {
        if !target_m.is_finite() {
            return 0;
        }
        if self.expected != UpdateStep::Done {
            self.pending_target_m = Some(target_m);
            return 0;
        }
        self.tracking_target_m = Some(target_m);
        let scrolled = self.volumes.iter_mut().map(|v| v.scroll_to(target_m)).sum();
        if scrolled > 0 {
            self.seed_new_probes();
        }
        scrolled
    }

    /// Plans the seeds of every volume with `probe_seeding` for its probes reset
    /// since its last blend, and applies them to the host atlases when those
    /// are current (else a device mixes them before its next blend, and
    /// [`Self::accept_host_atlases`] repeats them on the copy).
    fn seed_new_probes(&mut self) {
        for i in 0..self.volumes.len() {
            if !self.volumes[i].settings.probe_seeding {
                continue;
            }
            let reset = self.volumes[i].probes_reset_since_blend().to_vec();
            let seeds = crate::probe_seeding::plan_seeds(&self.volumes, &self.order, i, &reset);
            if self.field_on_device {
                seeds.iter().for_each(|s| self.volumes[i].mark_seeded(s.probe as usize));
            } else {
                crate::probe_seeding::apply_seeds(&mut self.volumes, i, &seeds);
            }
            self.volumes[i].pending_seeds = seeds;
        }
    }

    /// Whether a volume runs the screen scheme (`ProbeStatesMode::Screen`):
    /// the camera frame should then report the probes it read, with
    /// [`Self::request_probes_at`] or [`Self::submit_probe_requests`].
    pub fn wants_probe_requests(&self) -> bool {
        self.volumes.iter().any(|v| v.settings.probe_states == probegi_core::ddgi_settings::ProbeStatesMode::Screen)
    }

    /// The layout of a request bitset ([`Self::submit_probe_requests`]): per
    /// member in sampling order (the set view's), its first bit; the last
    /// entry is the total. A device's query numbers probes the same way
    /// (member by member, storage slots within).
    pub fn probe_request_layout(&self) -> Vec<usize> {
        let mut first = vec![0];
        for &i in &self.order {
            first.push(first.last().copied().unwrap_or(0) + self.volumes[i].grid.probe_count());
        }
        first
    }

    /// The screen scheme's requests from the camera frame, as a bitset over
    /// [`Self::probe_request_layout`] (bit `b` of word `b / 32`): each set
    /// bit requests that probe for the next update. Volumes under other
    /// schemes ignore theirs. An error when the length is not
    /// `⌈total / 32⌉` words.
    pub fn submit_probe_requests(&mut self, words: &[u32]) -> Result<(), SeamError> {
        let layout = self.probe_request_layout();
        let total = layout.last().copied().unwrap_or(0);
        if words.len() != total.div_ceil(32) {
            return Err(SeamError::WrongLength {
                what: "probe request words",
                expected: total.div_ceil(32),
                got: words.len(),
            });
        }
        for (m, &i) in self.order.iter().enumerate() {
            for p in 0..self.volumes[i].grid.probe_count() {
                let b = layout[m] + p;
                if words[b / 32] >> (b % 32) & 1 != 0 {
                    self.volumes[i].request_probe(p);
                }
            }
        }
        Ok(())
    }

    /// The request bitset ([`Self::submit_probe_requests`]) of camera
    /// pixels at `points` (surface position, unit facing normal, unit
    /// direction toward the camera): the probes their queries read
    /// (`probegi_core::ddgi_volume_blend::field_set_cage_probes`).
    pub fn probe_requests_at(&self, points: &[(Vec3, Vec3, Vec3)]) -> Vec<u32> {
        use rayon::prelude::*;
        let layout = self.probe_request_layout();
        let words = layout.last().copied().unwrap_or(0).div_ceil(32);
        let view = self.view();
        points
            .par_chunks(1024)
            .map(|chunk| {
                let mut w = vec![0u32; words];
                for &(p, n, v) in chunk {
                    probegi_core::ddgi_volume_blend::field_set_cage_probes(&view, p, n, v, |m, slot| {
                        let b = layout[m] + slot;
                        w[b / 32] |= 1 << (b % 32);
                    });
                }
                w
            })
            .reduce(
                || vec![0u32; words],
                |mut a, b| {
                    a.iter_mut().zip(b).for_each(|(x, y)| *x |= y);
                    a
                },
            )
    }

    /// [`Self::probe_requests_at`] then [`Self::submit_probe_requests`]: the
    /// screen scheme's requests of camera pixels at `points`.
    pub fn request_probes_at(&mut self, points: &[(Vec3, Vec3, Vec3)]) {
        let words = self.probe_requests_at(points);
        // The words are this set's own layout, so the length holds.
        let _ = self.submit_probe_requests(&words);
    }

    /// The point tracking windows follow now (the camera), if one was given.
    pub fn tracking_target(&self) -> Option<Vec3> {
        self.tracking_target_m
    }

    /// Reports a scene change to every volume (seed 004 §4.3).
    pub fn notify_scene_event(&mut self, event: SceneEvent) {
        self.volumes.iter_mut().for_each(|v| v.notify_scene_event(event));
    }

    /// Reports a scene change to volume `volume` alone (an object that jumped
    /// near it); nothing for a volume the set does not have. Unlike a change
    /// through [`Self::volumes_mut`], the volume's rows keep their identity.
    pub fn notify_volume_scene_event(&mut self, volume: usize, event: SceneEvent) {
        if let Some(v) = self.volumes.get_mut(volume) {
            v.notify_scene_event(event);
        }
    }

    /// Wakes Sleeping probes around moving objects in every volume; returns the
    /// count. Under a ray budget the probes around them also count as changed
    /// (`DdgiVolume::mark_changed_near`).
    pub fn wake_probes_near(&mut self, dynamic_aabbs: &[(Vec3, Vec3)]) -> usize {
        if self.ray_budget() > 0 {
            self.volumes.iter_mut().for_each(|v| {
                v.mark_changed_near(dynamic_aabbs);
            });
        }
        self.volumes.iter_mut().map(|v| v.wake_probes_near(dynamic_aabbs)).sum()
    }

    /// The current batch (valid after `begin_update` / `submit_hits` ask for a trace or shade).
    pub fn ray_batch(&self) -> &ProbeRayBatch {
        &self.batch
    }

    /// Total probes over every volume.
    pub fn probe_count(&self) -> usize {
        self.volumes.iter().map(|v| v.grid.probe_count()).sum()
    }

    /// Probe rays of the last update (every volume's tracing probes).
    pub fn rays_per_frame(&self) -> u64 {
        self.volumes.iter().map(|v| v.rays_per_frame()).sum()
    }

    /// With `on_device`, update batches and initialisation rounds from the next
    /// [`Self::begin_update`] on carry their rays per probe only (origins and the `generated` records,
    /// O(probes) on the host), for a device that makes the rays where it traces
    /// them. A caller that then traces or shades on the host after all calls
    /// [`Self::fill_ray_arrays`] first.
    pub fn set_update_rays_on_device(&mut self, on_device: bool) {
        self.update_rays_on_device = on_device;
    }

    /// With `keep` (the default), an update whose every volume is as it was
    /// when the last update was planned keeps that plan, its batch and its
    /// blend plan, with the frame's ray rotation (`ddgi_volume::steady_frames`:
    /// the host then visits no probe to plan or classify it; the kept batch
    /// keeps its `probe_needs_radiance`). Only where a device makes the rays
    /// ([`Self::set_update_rays_on_device`]), with no host shadow rays, and
    /// after an update that was finished. Without, every update is planned in
    /// full; both give the same batches, blend plans and volumes (but for the
    /// plans' identities, `GeneratedProbeRays::plan_id`,
    /// `DeviceVolumeBlend::probe_blend_id` and
    /// `ProbeRayBatch::probe_needs_radiance_id`). The same switch keeps the
    /// usage scheme's trace plan alone ([`Self::update_kept_trace_plan`]).
    pub fn set_steady_plans(&mut self, keep: bool) {
        self.steady_plans = keep;
    }

    /// Whether the current (or last) update kept the plan before it.
    pub fn update_kept_plan(&self) -> bool {
        self.plan_kept
    }

    /// Whether the current (or last) update kept the trace plan alone of the
    /// update before it: the batch's probes, first rays and records'
    /// identities, under the usage scheme (`ddgi_volume::steady_frames`);
    /// the classification, the blend plan and the bookkeeping ran in full.
    pub fn update_kept_trace_plan(&self) -> bool {
        self.trace_kept
    }

    /// Fills the current batch's per-ray arrays where it was planned without
    /// them ([`Self::set_update_rays_on_device`]); the rays equal the host
    /// plan's bit for bit.
    pub fn fill_ray_arrays(&mut self) {
        self.batch.fill_ray_arrays();
    }

    /// Starts frame `frame`'s update: the first batch to trace.
    pub fn begin_update(&mut self, seed: u64, frame: u32) -> UpdateStep {
        self.seed = seed;
        self.frame = frame;
        self.init_round = 0;
        self.plan_kept = false;
        self.trace_kept = false;
        if self.expected != UpdateStep::Done {
            // The last update was left unfinished: its plan's blend never
            // ran, so no later frame may keep that plan.
            self.frames.iter_mut().for_each(DdgiVolume::forget_plan_snapshot);
        }
        self.expected = UpdateStep::Done;
        self.last_scrolled_in = match self.pending_target_m.take() {
            Some(t) => self.set_tracking_target(t),
            None => 0,
        };
        self.last_pass_ms.clear();
        self.last_init_rays = 0;
        self.volumes.iter_mut().for_each(|v| v.forget_init_hits());
        let t = std::time::Instant::now();
        let step = self.plan_init_or_update();
        self.time("ray_gen", t);
        step
    }

    fn time(&mut self, pass: &'static str, t: std::time::Instant) {
        *self.last_pass_ms.entry(pass).or_default() += t.elapsed().as_secs_f64() * 1e3;
    }

    /// Plans the next initialisation round of the volumes still initialising, or
    /// (once none is) the update batch.
    fn plan_init_or_update(&mut self) -> UpdateStep {
        loop {
            let pending: Vec<usize> = (0..self.volumes.len()).filter(|&i| self.volumes[i].needs_init()).collect();
            if pending.is_empty() {
                break;
            }
            for &i in &pending {
                DdgiVolume::forget_plan_snapshot(&mut self.frames[i]);
                self.volumes[i].settle_steady_counts();
            }
            // A device that makes the update rays makes these too (no per-ray
            // arrays; a host trace fills them first).
            self.batch.clear(ProbeRayBatchKind::Initialization, !self.update_rays_on_device);
            self.frames.iter_mut().for_each(|f| f.init_reuses_hits = false);
            for &i in &pending {
                let has_round = self.volumes[i].plan_init_round(
                    &mut self.frames[i],
                    self.init_round,
                    self.seed,
                    i as u32,
                    &mut self.batch,
                );
                if !has_round {
                    self.volumes[i].finish_init();
                }
            }
            if !self.batch.is_empty() {
                self.expected = UpdateStep::TraceRays;
                return UpdateStep::TraceRays;
            }
            // No probe traces in this round (every pending probe has settled):
            // on to the next, after a classification that reads kept hits alone.
            for &i in &pending {
                if self.frames[i].init_reuses_hits {
                    self.volumes[i].accept_init_round(&self.frames[i], self.init_round, &[], &[], None);
                }
            }
            self.init_round += 1;
        }
        if self.keep_steady_plan() || self.keep_trace_plan() {
            self.expected = UpdateStep::TraceRays;
            return UpdateStep::TraceRays;
        }
        // A full plan: the counters the kept frames owe first, and the screen
        // scheme's idle phases (the budget reads them).
        for v in &mut self.volumes {
            v.settle_steady_counts();
            v.keep_idle_phases();
        }
        // Shadow rays are made on the host: a batch with them keeps per-ray arrays.
        let per_ray = !self.update_rays_on_device || self.has_host_shadow_rays();
        self.batch.clear(ProbeRayBatchKind::Update, per_ray);
        self.volumes.iter_mut().for_each(|v| v.tick_screen_requests());
        self.apply_ray_budget();
        for i in 0..self.volumes.len() {
            self.volumes[i].plan_update(&mut self.frames[i], self.seed, self.frame, i as u32, &mut self.batch);
        }
        // Then every volume's shadow rays, after all the probes' primary rays
        // (none where a device casts them from the hits it kept).
        let lights: &[probegi_scene::PunctualLight] = if self.shadow_on_device { &[] } else { &self.shadow_lights };
        for i in 0..self.volumes.len() {
            self.volumes[i].plan_shadow_rays(&mut self.frames[i], lights, &mut self.batch);
        }
        // (Kept whether or not the set keeps steady plans: the volumes stay
        // the same either way.)
        for (v, f) in self.volumes.iter().zip(&mut self.frames) {
            match !per_ray {
                true => v.keep_plan_snapshot(f),
                false => DdgiVolume::forget_plan_snapshot(f),
            }
        }
        self.last_batch_rays = self.batch.len() as u64;
        self.last_batch_rays_per_volume = self.batch.rays_per_volume(self.volumes.len());
        self.expected = UpdateStep::TraceRays;
        UpdateStep::TraceRays
    }

    /// Keeps the last update's plan for this frame where every volume is
    /// as it was when that plan was made (`ddgi_volume::steady_frames`): the
    /// batch's probes and first rays stay, its rays take the frame's rotation,
    /// and each volume counts its probes' untraced frames. Returns whether it
    /// did.
    fn keep_steady_plan(&mut self) -> bool {
        let kept = self.batch_may_be_kept() && self.volumes.iter().zip(&self.frames).all(|(v, f)| v.plan_is_steady(f));
        self.plan_kept = kept;
        if !kept {
            return false;
        }
        for (i, (v, f)) in self.volumes.iter_mut().zip(&mut self.frames).enumerate() {
            self.batch.generated[i].rotation = v.plan_steady_update(f, self.seed, self.frame);
        }
        self.batch.renew_rays();
        true
    }

    /// What a kept plan or kept trace asks of the set and of the last batch:
    /// steady plans on, rays made on the device, no host shadow rays, no
    /// ray budget, and an update batch planned without per-ray arrays with
    /// one generated entry per volume, in order.
    fn batch_may_be_kept(&self) -> bool {
        self.steady_plans
            && self.update_rays_on_device
            && !self.has_host_shadow_rays()
            && self.ray_budget() == 0
            && self.batch.kind == ProbeRayBatchKind::Update
            && !self.batch.planned_with_ray_arrays()
            && self.batch.generated.iter().map(|g| g.volume as usize).eq(0..self.volumes.len())
    }

    /// Keeps the last update's trace plan alone where every volume's trace
    /// would repeat it (the usage scheme, `ddgi_volume::steady_frames`): the
    /// batch's probes, first rays and records' identities stay, its rays take
    /// the frame's rotation, and each volume plans the rest of the frame
    /// (counters, which probes' states want a blend). Returns whether it did.
    fn keep_trace_plan(&mut self) -> bool {
        let kept =
            self.batch_may_be_kept() && self.volumes.iter().zip(&self.frames).all(|(v, f)| v.trace_plan_is_steady(f));
        self.trace_kept = kept;
        if !kept {
            return false;
        }
        // No budget: which probes trace is the states' alone.
        self.apply_ray_budget();
        for (i, (v, f)) in self.volumes.iter_mut().zip(&mut self.frames).enumerate() {
            self.batch.generated[i].rotation = v.plan_kept_trace_update(f, self.seed, self.frame);
        }
        self.batch.renew_rays();
        true
    }

    /// The set's ray budget: the largest `ray_budget` of its volumes (0: none).
    pub fn ray_budget(&self) -> u64 {
        self.volumes.iter().map(|v| v.settings.ray_budget).max().unwrap_or(0)
    }

    /// Under a ray budget (`crate::ray_budget`), which probes of every volume
    /// trace this frame; without one, every volume traces as its states say.
    fn apply_ray_budget(&mut self) {
        let budget = self.ray_budget();
        for f in &mut self.frames {
            f.budget_traces = None;
            f.measure_change = budget > 0;
        }
        if budget == 0 {
            return;
        }
        let mut candidates = Vec::new();
        for (i, v) in self.volumes.iter().enumerate() {
            v.budget_candidates(i as u32, self.frame, &mut candidates);
        }
        let chosen = crate::ray_budget::select_budget_probes(&candidates, budget);
        for (f, v) in self.frames.iter_mut().zip(&self.volumes) {
            f.budget_traces = Some(vec![false; v.grid.probe_count()]);
        }
        for (c, _) in candidates.iter().zip(&chosen).filter(|(_, k)| **k) {
            if let Some(t) = self.frames[c.volume as usize].budget_traces.as_mut() {
                t[c.probe as usize] = true;
            }
        }
    }

    /// `probe_needs_radiance` of the update batch: the probes that blend this
    /// frame (after the hits classified them).
    /// A kept trace plan's batch keeps the flags' identity where they repeat.
    fn mark_probes_needing_radiance(&mut self) {
        let frames = &self.frames;
        let flags = self.batch.probes.iter().map(|bp| frames[bp.volume as usize].active[bp.probe as usize]);
        let same = self.trace_kept && self.batch.probe_needs_radiance.iter().copied().eq(flags.clone());
        if !same {
            self.batch.probe_needs_radiance.clear();
            self.batch.probe_needs_radiance.extend(flags);
            self.batch.renew_radiance_id();
        }
    }

    fn expect(&self, step: UpdateStep, called: &'static str) -> Result<(), SeamError> {
        if self.expected == step { Ok(()) } else { Err(SeamError::OutOfOrder { expected: self.expected, called }) }
    }

    /// Takes the batch's hits (one per ray, in batch order). After an
    /// initialisation round the next batch is traced again; after the update batch
    /// the rays in `ray_batch().needs_radiance` must be shaded. Non-finite
    /// distances other than `+∞`, and NaN normals, count as misses.
    pub fn submit_hits(&mut self, hits: &[ProbeRayHit]) -> Result<UpdateStep, SeamError> {
        self.submit_hits_inner(hits, None)
    }

    /// As [`Self::submit_hits`], where the caller can give a hit's facing
    /// normal on request (`normal_of(batch ray)`) instead of with every hit: a
    /// relocation round's hits then need none (as [`Self::hit_normals_needed`]
    /// says), and the set asks for the normals of the front hits it keeps for
    /// the classification round (those of the probes the round left in place),
    /// which then need not trace again. Plain `submit_hits` keeps none.
    pub fn submit_init_hits(
        &mut self,
        hits: &[ProbeRayHit],
        normal_of: &crate::ddgi_volume::HitNormals<'_>,
    ) -> Result<UpdateStep, SeamError> {
        self.submit_hits_inner(hits, Some(normal_of))
    }

    fn submit_hits_inner(
        &mut self,
        hits: &[ProbeRayHit],
        normal_of: Option<&crate::ddgi_volume::HitNormals<'_>>,
    ) -> Result<UpdateStep, SeamError> {
        self.expect(UpdateStep::TraceRays, "submit_hits")?;
        if hits.len() != self.batch.len() {
            return Err(SeamError::WrongLength { what: "hits", expected: self.batch.len(), got: hits.len() });
        }
        self.hits.clear();
        self.hits.extend(hits.iter().map(|h| {
            if h.distance_m.is_nan() || h.distance_m == f32::NEG_INFINITY || !h.normal.is_finite() {
                ProbeRayHit::MISS
            } else {
                *h
            }
        }));
        self.distances.clear();
        self.distances.extend(self.hits.iter().map(|h| h.distance_m));
        let t = std::time::Instant::now();
        match self.batch.kind {
            ProbeRayBatchKind::Initialization => {
                self.last_init_rays += self.batch.len() as u64;
                for i in 0..self.volumes.len() {
                    if self.volumes[i].needs_init() {
                        self.volumes[i].accept_init_round(
                            &self.frames[i],
                            self.init_round,
                            &self.hits,
                            &self.distances,
                            normal_of,
                        );
                    }
                }
                self.init_round += 1;
                let step = self.plan_init_or_update();
                self.time("probe_init", t);
                Ok(step)
            }
            ProbeRayBatchKind::Update => {
                self.batch.needs_radiance = vec![false; self.batch.len()];
                let batch = self.update_batches;
                self.update_batches += 1;
                for i in 0..self.volumes.len() {
                    let (frames, volumes) = (&mut self.frames, &mut self.volumes);
                    volumes[i].accept_update_hits(
                        &mut frames[i],
                        self.frame,
                        batch,
                        &self.hits,
                        &mut self.batch.needs_radiance,
                    );
                    volumes[i].accept_shadow_hits(&mut frames[i], self.frame, &self.batch, &self.hits);
                }
                self.mark_probes_needing_radiance();
                self.time("classify", t);
                self.expected = UpdateStep::ShadeRays;
                Ok(UpdateStep::ShadeRays)
            }
        }
    }

    /// Takes the shaded radiance (one per batch ray; only the rays with
    /// `needs_radiance` are read) and blends, borders and classifies every volume.
    pub fn submit_radiance(&mut self, radiance: &[Vec3]) -> Result<UpdateStep, SeamError> {
        self.expect(UpdateStep::ShadeRays, "submit_radiance")?;
        if self.field_on_device {
            return Err(SeamError::FieldOnDevice);
        }
        if radiance.len() != self.batch.len() {
            return Err(SeamError::WrongLength { what: "radiance", expected: self.batch.len(), got: radiance.len() });
        }
        let mut pass_ms = std::mem::take(&mut self.last_pass_ms);
        crate::ddgi_volume::blend_inputs(
            &self.batch,
            &self.hits,
            radiance,
            &mut self.blend_radiance,
            &mut self.blend_distance,
        );
        for i in 0..self.volumes.len() {
            let batch = self.current_batch();
            self.volumes[i].blend_results(
                &self.frames[i],
                batch,
                &self.blend_radiance,
                &self.blend_distance,
                &mut pass_ms,
            );
        }
        self.last_pass_ms = pass_ms;
        self.expected = UpdateStep::Done;
        Ok(UpdateStep::Done)
    }

    /// What of the current batch's hits the set needs on the host. A device that
    /// keeps the hits and the atlases (`ProbeBatchTracer::trace_on_device`) traces
    /// the update batch there, counts usage there when asked, and goes on with
    /// [`Self::submit_device_hits`]; initialisation rounds need every hit.
    pub fn hits_needed_on_host(&self) -> HostHits {
        if self.batch.kind == ProbeRayBatchKind::Initialization {
            let round = self.init_round;
            let pending = || self.volumes.iter().filter(|v| v.needs_init());
            if pending().all(|v| v.init_round_is_relocation(round)) { HostHits::Relocation } else { HostHits::All }
        } else if self.has_host_shadow_rays() {
            // The shadow field's shadow rays and surfels are read on the host.
            HostHits::All
        } else if self
            .volumes
            .iter()
            .any(|v| v.settings.probe_states == probegi_core::ddgi_settings::ProbeStatesMode::Usage)
        {
            HostHits::ProbeUsage
        } else {
            HostHits::None
        }
    }

    /// Whether the current batch's round reads [`ProbeRayHit::normal`]: an
    /// initialisation round that classifies (seed 004 Listing 5 reads the hit
    /// points' facing plane normals). Relocation rounds and update batches read
    /// distances only, so a caller may submit any finite normal there (zero)
    /// and skip building the surface point of every hit.
    pub fn hit_normals_needed(&self) -> bool {
        match self.batch.kind {
            ProbeRayBatchKind::Initialization => self.hits_needed_on_host() != HostHits::Relocation,
            // The shadow field keeps front hits as surfels, with their normals.
            ProbeRayBatchKind::Update => self.has_host_shadow_rays(),
        }
    }

    /// Whether a volume of the set keeps a shadowing field (`shadow_field`).
    pub fn has_shadow_field(&self) -> bool {
        self.volumes.iter().any(|v| v.shadow.is_some())
    }

    /// Whether the host plans and reads the shadowing field's rays (a volume
    /// keeps a field, and no device casts them).
    fn has_host_shadow_rays(&self) -> bool {
        self.has_shadow_field() && !self.shadow_on_device
    }

    /// With `on_device`, from the next update on a device that keeps the update
    /// batches' hits casts the shadowing field's shadow rays from them and
    /// blends the occlusion maps it holds (`DeviceVolumeBlend::shadow`); the
    /// host plans none.
    pub fn set_shadow_on_device(&mut self, on_device: bool) {
        self.shadow_on_device = on_device;
    }

    /// The punctual lights the shadowing field's probes serve from the next
    /// update on (the scene's, as posed for that frame; each volume picks its
    /// brightest `shadow_field_max_lights`).
    pub fn set_shadow_lights(&mut self, lights: &[probegi_scene::PunctualLight]) {
        self.shadow_lights.clear();
        self.shadow_lights.extend_from_slice(lights);
    }

    /// The shadowing field's cage at `position` on a surface with unit `normal`
    /// (`probegi_core::shadow_field::ShadowCage`: weighed once, then read per
    /// light), from the densest volume with a shadow field whose probe box, or
    /// the cell around it, holds the point; `None` where no such volume covers
    /// it (the caller traces shadow rays there).
    pub fn shadow_cage(
        &self,
        position: Vec3,
        normal: Vec3,
        view_dir: Vec3,
    ) -> Option<probegi_core::shadow_field::ShadowCage<'_>> {
        // `field_set_shadow_cage`'s rule over `view()`, without building the view.
        self.order.iter().map(|&i| &self.volumes[i]).find_map(|v| {
            let occlusion = &v.shadow.as_ref()?.occlusion;
            probegi_core::ddgi_volume_blend::member_shadow_cage(&v.view(), occlusion, position, normal, view_dir)
        })
    }

    /// The light visibility in `[0, 1]` toward unit `dir_to_light` from
    /// [`Self::shadow_cage`]; `None` where it has none.
    pub fn shadow_visibility(&self, position: Vec3, normal: Vec3, view_dir: Vec3, dir_to_light: Vec3) -> Option<f32> {
        self.shadow_cage(position, normal, view_dir).map(|c| c.visibility(dir_to_light))
    }

    /// Every initialisation round of this frame as one chain per volume still
    /// initialising (`None` for the others), for a device that keeps the field
    /// and runs them back to back ([`DeviceInitChain`]: the host path's rounds,
    /// skips and kept hits); then [`Self::submit_device_init`]. An error
    /// unless the set waits for its first initialisation round's hits.
    pub fn device_init_plan(&self) -> Result<Vec<Option<DeviceInitChain<'_>>>, SeamError> {
        self.expect(UpdateStep::TraceRays, "device_init_plan")?;
        if self.batch.kind != ProbeRayBatchKind::Initialization || self.init_round != 0 {
            return Err(SeamError::OutOfOrder { expected: UpdateStep::TraceRays, called: "device_init_plan" });
        }
        Ok(self.volumes.iter().map(|v| v.needs_init().then(|| v.device_init_chain(self.seed))).collect())
    }

    /// In place of [`Self::submit_hits`] for every initialisation round, run
    /// on another device from [`Self::device_init_plan`]: per volume of the
    /// plan, its result. Ends the initialisation and plans the update batch.
    pub fn submit_device_init(&mut self, results: &[Option<DeviceInitResult>]) -> Result<UpdateStep, SeamError> {
        self.expect(UpdateStep::TraceRays, "submit_device_init")?;
        if self.batch.kind != ProbeRayBatchKind::Initialization || self.init_round != 0 {
            return Err(SeamError::OutOfOrder { expected: UpdateStep::TraceRays, called: "submit_device_init" });
        }
        if results.len() != self.volumes.len() {
            return Err(SeamError::WrongLength {
                what: "init results",
                expected: self.volumes.len(),
                got: results.len(),
            });
        }
        for (v, r) in self.volumes.iter().zip(results) {
            let probes = v.grid.probe_count();
            let Some(r) = r.as_ref().filter(|_| v.needs_init()) else { continue };
            if r.classification.is_some() != v.init_classifies() {
                return Err(SeamError::WrongLength {
                    what: "init classifications",
                    expected: v.init_classifies() as usize,
                    got: r.classification.is_some() as usize,
                });
            }
            let states = r.classification.as_ref().map_or(probes, |c| c.len());
            if r.offsets_m.len() != probes || states != probes {
                let got = if r.offsets_m.len() != probes { r.offsets_m.len() } else { states };
                return Err(SeamError::WrongLength { what: "init results", expected: probes, got });
            }
        }
        let t = std::time::Instant::now();
        for (v, r) in self.volumes.iter_mut().zip(results) {
            if let (true, Some(r)) = (v.needs_init(), r) {
                self.last_init_rays += r.rays_traced;
                v.accept_device_init(r);
            }
        }
        let step = self.plan_init_or_update();
        self.time("probe_init", t);
        Ok(step)
    }

    /// What a device that keeps the update batch's hits must count there for
    /// the usage scheme ([`HostHits::ProbeUsage`]; `None` otherwise): each
    /// volume's cage diagonal, this batch's number, and how many batches late
    /// the counts may come back (the smallest `probe_usage_lag_updates` of the
    /// volumes under the usage scheme).
    pub fn device_usage_request(&self) -> Option<crate::DeviceUsageRequest> {
        if self.hits_needed_on_host() != HostHits::ProbeUsage {
            return None;
        }
        let usage = probegi_core::ddgi_settings::ProbeStatesMode::Usage;
        let lag = self.volumes.iter().filter(|v| v.settings.probe_states == usage);
        Some(crate::DeviceUsageRequest {
            cage_diagonals_m: self.volumes.iter().map(|v| v.grid.spacing_m.length()).collect(),
            set_id: self.usage_set_id.0,
            batch: self.update_batches,
            lag_updates: lag.map(|v| v.settings.probe_usage_lag_updates).min().unwrap_or(0),
        })
    }

    /// In place of [`Self::submit_hits`] for an update batch whose hits stayed on
    /// another device. Under the usage scheme ([`Self::device_usage_request`])
    /// the device keeps this batch's counts for now, and `usage_counts` holds
    /// those of earlier batches that it read back (empty otherwise); a batch
    /// whose counts never come classifies nothing. Each probe that updates is
    /// then marked in `probe_needs_radiance` (`needs_radiance` stays empty:
    /// O(probes), not O(rays), on the host); the device applies the backface
    /// rule itself.
    pub fn submit_device_hits(&mut self, usage_counts: &[crate::DeviceUsageCounts]) -> Result<UpdateStep, SeamError> {
        self.expect(UpdateStep::TraceRays, "submit_device_hits")?;
        if self.batch.kind != ProbeRayBatchKind::Update {
            return Err(SeamError::OutOfOrder { expected: UpdateStep::TraceRays, called: "submit_device_hits" });
        }
        let t = std::time::Instant::now();
        let batch = self.update_batches;
        if self.hits_needed_on_host() == HostHits::ProbeUsage {
            // This batch's entries first: with no lag its own counts are here.
            let entries = self.batch.probes.iter().map(|bp| [bp.volume, bp.probe]).collect();
            self.usage_on_device.push_back((batch, entries));
        }
        let earlier = match self.earlier_device_usage(usage_counts) {
            Ok(earlier) => earlier,
            Err(e) => {
                // As if never called: the batch's entries go again.
                self.usage_on_device.retain(|(b, _)| *b != batch);
                return Err(e);
            }
        };
        self.update_batches += 1;
        self.hits.clear();
        self.distances.clear();
        self.batch.needs_radiance.clear();
        for ((v, f), earlier) in self.volumes.iter_mut().zip(&mut self.frames).zip(earlier) {
            v.accept_device_hits(f, self.frame, batch, earlier);
        }
        if !self.plan_kept {
            // A kept plan's batch kept them.
            self.mark_probes_needing_radiance();
        }
        self.time("classify", t);
        self.expected = UpdateStep::ShadeRays;
        Ok(UpdateStep::ShadeRays)
    }

    /// Per volume, the usage counts of earlier batches a device read back,
    /// by batch number, each spread over the volume's probes; the batches
    /// before one that came back and never came themselves are forgotten,
    /// and so are counts of earlier batches the set no longer waits for.
    /// Checked before anything is taken: an error leaves the queue as it was.
    #[allow(clippy::type_complexity)]
    fn earlier_device_usage(
        &mut self,
        usage_counts: &[crate::DeviceUsageCounts],
    ) -> Result<Vec<Vec<(u64, Vec<Option<ProbeUsageCounts>>)>>, SeamError> {
        let current = self.update_batches;
        for c in usage_counts {
            match self.usage_on_device.iter().find(|(b, _)| *b == c.batch) {
                Some((_, entries)) if entries.len() != c.counts.len() => {
                    let (expected, got) = (entries.len(), c.counts.len());
                    return Err(SeamError::WrongLength { what: "usage counts", expected, got });
                }
                Some(_) => {}
                // An earlier batch the set no longer waits for (its update
                // failed after the count): dropped, as the device cannot know.
                None if c.batch < current => {}
                None => return Err(SeamError::UnknownBatch { batch: c.batch }),
            }
        }
        let mut per_volume = vec![Vec::new(); self.volumes.len()];
        for c in usage_counts {
            let Some(at) = self.usage_on_device.iter().position(|(b, _)| *b == c.batch) else { continue };
            // The batches before it whose counts never came are forgotten.
            self.usage_on_device.drain(..at);
            let Some((_, entries)) = self.usage_on_device.pop_front() else { break };
            let mut spread: Vec<Vec<Option<ProbeUsageCounts>>> =
                self.volumes.iter().map(|v| vec![None; v.grid.probe_count()]).collect();
            for (&[volume, probe], &counts) in entries.iter().zip(&c.counts) {
                if let Some(slot) = spread.get_mut(volume as usize).and_then(|s| s.get_mut(probe as usize)) {
                    *slot = Some(counts);
                }
            }
            for (v, spread) in per_volume.iter_mut().zip(spread) {
                v.push((c.batch, spread));
            }
        }
        Ok(per_volume)
    }

    /// In place of [`Self::submit_radiance`] when another device shades the
    /// update batch and blends it into atlases it holds: per volume, what to
    /// blend ([`DeviceVolumeBlend`]). Call [`Self::submit_device_blend`] once the
    /// device has run it.
    pub fn device_blend_plan(&self) -> Result<Vec<DeviceVolumeBlend<'_>>, SeamError> {
        self.expect(UpdateStep::ShadeRays, "device_blend_plan")?;
        let plan = self.volumes.iter().zip(&self.frames).map(|(v, f)| {
            let change_key = crate::DeviceChangeKey {
                set_id: self.usage_set_id.0,
                batch: self.current_batch(),
                lag_updates: v.settings.ray_budget_change_lag_updates,
            };
            DeviceVolumeBlend { change_key, ..v.device_blend(f, &self.shadow_lights) }
        });
        Ok(plan.collect())
    }

    /// The number of the update batch in hand (the last one whose hits came).
    fn current_batch(&self) -> u64 {
        self.update_batches.saturating_sub(1)
    }

    /// The set's bookkeeping after a device ran [`Self::device_blend_plan`]
    /// (hysteresis ramps, Newly * states, usable probes). The volumes' own
    /// atlases are stale from here until [`Self::accept_host_atlases`].
    /// `probe_change`: the changes the device measured after earlier blends
    /// and read back since ([`crate::DeviceBlendOutput::probe_change`]), one
    /// entry per volume and batch the set waits for; anything else is
    /// refused before the set changes.
    pub fn submit_device_blend(&mut self, probe_change: &[crate::DeviceProbeChanges]) -> Result<UpdateStep, SeamError> {
        self.expect(UpdateStep::ShadeRays, "submit_device_blend")?;
        let batch = self.current_batch();
        for c in probe_change {
            let (v, f) = (self.volumes.get(c.volume as usize), self.frames.get(c.volume as usize));
            let wanted = match (v, f) {
                // This batch's own (no lag): every probe it blends now.
                (Some(_), Some(f)) if c.batch == batch && f.measure_change => {
                    Some((0..f.first_ray.len()).filter(|&p| f.blends(p)).count())
                }
                // An earlier batch the volume no longer waits for (its update
                // failed, or went the host way): dropped, as the device
                // cannot know.
                (Some(v), _) if c.batch < batch => v.changes_awaited(c.batch).or(Some(c.changes.len())),
                _ => None,
            };
            match wanted {
                None => return Err(SeamError::UnknownBatch { batch: c.batch }),
                Some(n) if n != c.changes.len() => {
                    return Err(SeamError::WrongLength { what: "probe changes", expected: n, got: c.changes.len() });
                }
                Some(_) => {}
            }
        }
        for i in 0..self.volumes.len() {
            if self.plan_kept {
                self.volumes[i].accept_steady_blend(&self.frames[i]);
                continue;
            }
            let earlier: Vec<(u64, &[f32])> = probe_change
                .iter()
                .filter(|c| c.volume as usize == i)
                .map(|c| (c.batch, c.changes.as_slice()))
                .collect();
            self.volumes[i].accept_device_blend(&self.frames[i], &self.shadow_lights, batch, &earlier);
            self.volumes[i].record_shadow_batch(&self.frames[i], self.frame);
        }
        self.field_on_device = true;
        self.expected = UpdateStep::Done;
        Ok(UpdateStep::Done)
    }

    /// Whether another device holds the current atlases (the volumes' own are stale).
    pub fn field_on_device(&self) -> bool {
        self.field_on_device
    }

    /// The device's atlases, copied into the volumes by `copy` (given each volume
    /// in order), make the volumes' own atlases current again.
    pub fn accept_host_atlases<E>(
        &mut self,
        mut copy: impl FnMut(usize, &mut DdgiVolume) -> Result<(), E>,
    ) -> Result<(), E> {
        for (i, v) in self.volumes.iter_mut().enumerate() {
            copy(i, v)?;
            // Tiles the host cleared since the device last blended (a scroll) stay clear.
            v.clear_reset_tiles();
        }
        // ... or seeded, from the sources as the device will see them.
        for i in 0..self.volumes.len() {
            let seeds = std::mem::take(&mut self.volumes[i].pending_seeds);
            crate::probe_seeding::apply_seeds(&mut self.volumes, i, &seeds);
            self.volumes[i].pending_seeds = seeds;
        }
        self.field_on_device = false;
        Ok(())
    }

    /// Makes the volumes' own atlases current: when a device holds the field
    /// ([`Self::field_on_device`]), copies its atlases back through `batch_tracer`.
    pub fn sync_host_atlases(&mut self, batch_tracer: Option<&dyn ProbeBatchTracer>) -> Result<(), BackendError> {
        if !self.field_on_device() {
            return Ok(());
        }
        let device = batch_tracer.and_then(|t| t.device_field()).ok_or_else(|| {
            BackendError::Unsupported("the field's atlases are on a device this caller does not reach".into())
        })?;
        self.accept_host_atlases(|i, v| device.download_field(i, v))
    }

    /// The hits of the current batch, as submitted (sanitised).
    pub fn batch_hits(&self) -> &[ProbeRayHit] {
        &self.hits
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use probegi_core::ddgi_settings::DdgiVolumeSettings;
    use probegi_core::probe_classification::{ProbeState, probe_usage};

    /// A set of two volumes (every probe active) past initialisation (every init ray a miss), its
    /// frame-3 update batch planned with or without per-ray arrays.
    fn update_batch(on_device: bool) -> DdgiFieldSet {
        let volume = |n: u32, rays: u32| {
            let s = DdgiVolumeSettings {
                probe_counts: glam::UVec3::new(n, 2, 3),
                probe_rays_per_probe: rays,
                probe_states: probegi_core::ddgi_settings::ProbeStatesMode::AllActive,
                ..Default::default()
            };
            DdgiVolume::new(s, (Vec3::ZERO, Vec3::splat(4.0)))
        };
        let mut set = DdgiFieldSet::from_volumes(vec![volume(3, 32), volume(2, 48)], VolumeBlending::default(), None);
        set.set_update_rays_on_device(on_device);
        let mut step = set.begin_update(5, 3);
        while set.ray_batch().kind == ProbeRayBatchKind::Initialization {
            let misses = vec![ProbeRayHit::MISS; set.ray_batch().len()];
            step = set.submit_hits(&misses).expect("init round");
        }
        assert_eq!(step, UpdateStep::TraceRays);
        set
    }

    #[test]
    fn a_batch_planned_per_probe_expands_to_the_per_ray_plan() {
        let (host, device) = (update_batch(false), update_batch(true));
        let (a, b) = (host.ray_batch(), device.ray_batch());
        assert!(a.has_ray_arrays() && !b.has_ray_arrays());
        assert!(b.origins_m.is_empty() && b.directions.is_empty() && b.max_distances_m.is_empty());
        assert_eq!((a.len(), &a.probes, &a.probe_origins_m), (b.len(), &b.probes, &b.probe_origins_m));
        assert!(!a.is_empty());
        let expanded = b.expanded();
        assert_eq!(expanded.origins_m, a.origins_m);
        assert_eq!(expanded.directions, a.directions);
        assert_eq!(expanded.max_distances_m, a.max_distances_m);
    }

    /// Plans frames 0..=`frames` of a one-volume set under `states`, the
    /// device keeping the hits and the atlases (every ray a miss), and
    /// returns the last frame's blend plan as (per-probe frame counts, probes
    /// that blend).
    fn device_plan_after(states: probegi_core::ddgi_settings::ProbeStatesMode, frames: u32) -> (Vec<u32>, usize) {
        let s = DdgiVolumeSettings {
            probe_counts: glam::UVec3::new(4, 2, 3),
            probe_rays_per_probe: 16,
            probe_states: states,
            probe_relocation: false,
            ..Default::default()
        };
        let mut set = DdgiFieldSet::single(DdgiVolume::new(s, (Vec3::ZERO, Vec3::splat(4.0))));
        set.set_update_rays_on_device(true);
        let mut last = (Vec::new(), 0);
        for frame in 0..=frames {
            set.begin_update(5, frame);
            while set.ray_batch().kind == ProbeRayBatchKind::Initialization {
                let misses = vec![ProbeRayHit::MISS; set.ray_batch().len()];
                set.submit_hits(&misses).expect("init round");
            }
            assert_eq!(set.submit_device_hits(&[]), Ok(UpdateStep::ShadeRays));
            let plan = set.device_blend_plan().expect("plan");
            last = (plan[0].probe_blend_frames.to_vec(), plan[0].probe_blend.iter().flatten().count());
            drop(plan);
            assert_eq!(set.submit_device_blend(&[]), Ok(UpdateStep::Done));
        }
        last
    }

    #[test]
    fn a_still_fields_device_plan_carries_frame_counts_only_where_a_blend_stands_for_several() {
        use probegi_core::ddgi_settings::ProbeStatesMode;
        // Every probe blends every frame: no per-probe counts (1 for all).
        let (frames, blending) = device_plan_after(ProbeStatesMode::AllActive, 3);
        assert!(frames.is_empty(), "{frames:?}");
        assert_eq!(blending, 24);
        // The screen scheme's idle probes blend once an interval (8): each
        // blend then stands for the frames since its last, per probe.
        let (frames, blending) = device_plan_after(ProbeStatesMode::Screen, 9);
        assert_eq!(frames.len(), 24);
        assert!(blending > 0 && blending < 24, "{blending} of 24 idle probes blend in one frame");
        assert!(frames.iter().any(|&k| k > 1), "{frames:?}");
    }

    #[test]
    fn device_hits_mark_probes_not_rays() {
        let mut set = update_batch(true);
        // The first batch's usage counts (if any) stay on the device for now.
        assert_eq!(set.submit_device_hits(&[]), Ok(UpdateStep::ShadeRays));
        let batch = set.ray_batch();
        assert!(batch.needs_radiance.is_empty());
        assert_eq!(batch.probe_needs_radiance.len(), batch.probes.len());
        // Host hits mark both, and agree per probe.
        let mut host = update_batch(false);
        let misses = vec![ProbeRayHit::MISS; host.ray_batch().len()];
        host.submit_hits(&misses).expect("hits");
        let hb = host.ray_batch();
        for (k, p) in hb.probes.iter().enumerate() {
            let rays = &hb.needs_radiance[p.first_ray as usize..(p.first_ray + p.ray_count) as usize];
            assert!(rays.iter().all(|&r| r == hb.probe_needs_radiance[k]));
        }
        assert!(hb.probe_needs_radiance.iter().any(|&n| n));
    }

    /// A one-volume set of 4×2×3 probes, 16 rays, no relocation, with
    /// `settings`' other fields; the device keeps the hits with `on_device`.
    fn small_set(settings: DdgiVolumeSettings, on_device: bool) -> DdgiFieldSet {
        let s = DdgiVolumeSettings {
            probe_counts: glam::UVec3::new(4, 2, 3),
            probe_rays_per_probe: 16,
            probe_relocation: false,
            ..settings
        };
        let mut set = DdgiFieldSet::single(DdgiVolume::new(s, (Vec3::ZERO, Vec3::splat(4.0))));
        set.set_update_rays_on_device(on_device);
        set
    }

    /// A [`small_set`] under the usage scheme whose classification reads the
    /// counts `lag` batches back.
    fn usage_set(lag: u32, on_device: bool) -> DdgiFieldSet {
        let usage = probegi_core::ddgi_settings::ProbeStatesMode::Usage;
        small_set(
            DdgiVolumeSettings { probe_states: usage, probe_usage_lag_updates: lag, ..Default::default() },
            on_device,
        )
    }

    /// Starts frame `frame` and runs its initialisation rounds (every ray a miss).
    fn begin_usage_frame(set: &mut DdgiFieldSet, frame: u32) {
        set.begin_update(5, frame);
        while set.ray_batch().kind == ProbeRayBatchKind::Initialization {
            let misses = vec![ProbeRayHit::MISS; set.ray_batch().len()];
            set.submit_hits(&misses).expect("init round");
        }
    }

    /// Frame `frame`'s hit of every ray: misses before frame 3, then back
    /// faces 0.1 m away (every probe buried: DEAD by seed 003 §6.1.1).
    fn usage_hit(frame: u32) -> ProbeRayHit {
        match frame {
            0..3 => ProbeRayHit::MISS,
            _ => ProbeRayHit { distance_m: -0.1, normal: Vec3::Y },
        }
    }

    #[test]
    fn usage_states_follow_the_counts_of_the_batch_lag_updates_back() {
        // Probes start Alive; the hits bury them from frame 3 on. With the
        // counts read `lag` batches late, they die `lag` frames later, all at
        // once, on the host path (which holds its own counts as long).
        for lag in [0, 1, 2] {
            let mut set = usage_set(lag, false);
            let mut dead = Vec::new();
            for frame in 0..8 {
                host_frame(&mut set, frame, usage_hit(frame), Vec3::ZERO);
                dead.push(set.volumes()[0].state_counts().get("dead").copied().unwrap_or(0));
            }
            let probes = set.probe_count();
            let want: Vec<usize> = (0..8).map(|f| if f >= 3 + lag as usize { probes } else { 0 }).collect();
            assert_eq!(dead, want, "lag {lag}: dead probes by frame");
        }
    }

    #[test]
    fn device_usage_counts_given_late_classify_as_the_host_path() {
        // The device path with the counts a device would read back (each
        // batch's, `lag` batches later) gives the host path's states every
        // frame; counts for a batch the set does not wait for, or of another
        // length, are refused and leave the step as it was.
        let lag = 2;
        let (mut host, mut device) = (usage_set(lag, false), usage_set(lag, true));
        let mut traced: Vec<(u64, Vec<probegi_core::probe_classification::ProbeUsageCounts>)> = Vec::new();
        for frame in 0..8 {
            host_frame(&mut host, frame, usage_hit(frame), Vec3::ZERO);

            begin_usage_frame(&mut device, frame);
            let request = device.device_usage_request().expect("the usage scheme counts on the device");
            assert_eq!(request.lag_updates, lag);
            let diagonal = request.cage_diagonals_m[0];
            let counts = device
                .ray_batch()
                .probes
                .iter()
                .map(|_| probe_usage((0..16).map(|_| usage_hit(frame).distance_m), diagonal))
                .collect();
            traced.push((request.batch, counts));
            let mut due: Vec<crate::DeviceUsageCounts> = traced
                .iter()
                .filter(|(b, _)| b + lag as u64 == request.batch)
                .map(|(batch, counts)| crate::DeviceUsageCounts { batch: *batch, counts: counts.clone() })
                .collect();
            // A batch already taken, counted again by a device whose update
            // failed: dropped (were it taken, every probe would come alive).
            let alive = crate::DeviceUsageCounts {
                batch: 0,
                counts: vec![(5, 5, 0); due.first().map_or(0, |d| d.counts.len())],
            };
            let stale =
                request.batch.checked_sub(lag as u64 + 1).map(|batch| crate::DeviceUsageCounts { batch, ..alive });
            if let Some(first) = due.first() {
                let short = crate::DeviceUsageCounts { batch: first.batch, counts: first.counts[1..].to_vec() };
                assert!(matches!(device.submit_device_hits(&[short]), Err(SeamError::WrongLength { .. })));
                let later = crate::DeviceUsageCounts { batch: request.batch + 1, counts: first.counts.clone() };
                let unknown = device.submit_device_hits(&[later]);
                assert_eq!(unknown, Err(SeamError::UnknownBatch { batch: request.batch + 1 }));
            }
            due.extend(stale);
            assert_eq!(device.submit_device_hits(&due), Ok(UpdateStep::ShadeRays), "frame {frame}");
            assert_eq!(device.submit_device_blend(&[]), Ok(UpdateStep::Done));
            let (h, d) = (&host.volumes()[0], &device.volumes()[0]);
            assert_eq!(h.probe_states, d.probe_states, "frame {frame}");
        }
        assert!(host.volumes()[0].probe_states.iter().all(|&s| s == ProbeState::Dead));
    }

    #[test]
    fn counts_traced_before_a_scroll_do_not_classify_the_probes_scrolled_in() {
        // Lag 2, every ray buried from the start: the probes that stay die at
        // frame 2, from batch 0's counts. The plane scrolled in after frame 1
        // drops batches 0 and 1 (traced where its storage slots stood before)
        // and dies at frame 4, from batch 2, its first traced where it is now.
        let s = DdgiVolumeSettings { volume_tracks_camera: true, ..usage_set(2, false).volumes()[0].settings.clone() };
        let mut set = DdgiFieldSet::single(DdgiVolume::new(s, (Vec3::ZERO, Vec3::splat(4.0))));
        let buried = ProbeRayHit { distance_m: -0.1, normal: Vec3::Y };
        let mut scrolled: Vec<u32> = Vec::new();
        for frame in 0..6 {
            host_frame(&mut set, frame, buried, Vec3::ZERO);
            if frame == 1 {
                let grid = set.volumes()[0].grid;
                assert!(set.set_tracking_target(grid.centre_m() + 2.0 * grid.spacing_m * Vec3::X) > 0);
                scrolled = set.volumes()[0].probes_reset_since_blend().to_vec();
            }
            let v = &set.volumes()[0];
            for (p, state) in v.probe_states.iter().enumerate() {
                let dies_at = if scrolled.contains(&(p as u32)) { 4 } else { 2 };
                assert_eq!(*state == ProbeState::Dead, frame >= dies_at, "probe {p}, frame {frame}: {state:?}");
            }
        }
        assert!(!scrolled.is_empty() && scrolled.len() < set.probe_count());
    }

    /// A [`small_set`] under a ray budget that covers every probe (so every
    /// probe traces and blends each frame, and its change is measured), the
    /// changes recorded `lag` batches late.
    fn budget_set(lag: u32, on_device: bool) -> DdgiFieldSet {
        let s = DdgiVolumeSettings {
            probe_states: probegi_core::ddgi_settings::ProbeStatesMode::AllActive,
            ray_budget: 24 * 16,
            ray_budget_change_lag_updates: lag,
            ..Default::default()
        };
        small_set(s, on_device)
    }

    /// A whole host update of frame `frame`: every ray `hit`, every shaded ray `radiance`.
    fn host_frame(set: &mut DdgiFieldSet, frame: u32, hit: ProbeRayHit, radiance: Vec3) {
        begin_usage_frame(set, frame);
        assert_eq!(set.submit_hits(&vec![hit; set.ray_batch().len()]), Ok(UpdateStep::ShadeRays));
        assert_eq!(set.submit_radiance(&vec![radiance; set.ray_batch().len()]), Ok(UpdateStep::Done));
    }

    #[test]
    fn a_blends_changes_reach_the_budget_lag_updates_later_and_a_mark_outlives_older_ones() {
        // Every ray a miss shaded 1: the first blend replaces an empty history
        // (change 1), the ones after blend the same light again (change 0).
        // The budget reads the second blend's change `lag` updates later. A
        // probe marked changed after frame 4 (a moving object nearby) keeps
        // its mark against the blends before the mark, whose changes arrive
        // after it, and takes frame 5's, its first blend since, at 5 + lag.
        for lag in [0u32, 1, 2] {
            let mut set = budget_set(lag, false);
            let mut seen = Vec::new();
            for frame in 0..10 {
                host_frame(&mut set, frame, ProbeRayHit::MISS, Vec3::ONE);
                if frame == 4 {
                    let at = set.volumes()[0].probe_positions[0];
                    assert!(set.volumes_mut()[0].mark_changed_near(&[(at, at)]) > 0);
                }
                let v = &set.volumes()[0];
                seen.push((v.probe_change(0), v.probe_change(23)));
            }
            let lag = lag as usize;
            for (frame, (marked, still)) in seen.iter().enumerate() {
                let still_want = if frame > lag { 0.0 } else { 1.0 };
                assert_eq!(*still, still_want, "lag {lag}, frame {frame}: a still probe's change");
                let marked_want = if (1 + lag..4).contains(&frame) || frame >= 5 + lag { 0.0 } else { 1.0 };
                assert_eq!(*marked, marked_want, "lag {lag}, frame {frame}: the marked probe's change");
            }
        }
    }

    #[test]
    fn device_changes_given_late_reach_the_budget_as_the_host_blends_do() {
        // A device's changes for batch n, handed over with batch n + lag's
        // blend, are recorded then; changes for a batch the set does not
        // wait for, or of another length, are refused before anything moves.
        let lag = 2u64;
        let mut set = budget_set(lag as u32, true);
        let probes = set.probe_count();
        for frame in 0..8u32 {
            begin_usage_frame(&mut set, frame);
            set.submit_device_hits(&[]).expect("hits stay on the device");
            let key = set.device_blend_plan().expect("plan")[0].change_key;
            assert_eq!(key.lag_updates as u64, lag);
            let change = |batch: u64, n: usize| crate::DeviceProbeChanges { volume: 0, batch, changes: vec![0.25; n] };
            let mut due: Vec<_> = key.batch.checked_sub(lag).map(|b| change(b, probes)).into_iter().collect();
            if let Some(d) = due.first() {
                let short = crate::DeviceProbeChanges { changes: vec![0.25; probes - 1], ..d.clone() };
                assert!(matches!(set.submit_device_blend(&[short]), Err(SeamError::WrongLength { .. })));
                let unknown = set.submit_device_blend(&[change(key.batch + 1, probes)]);
                assert_eq!(unknown, Err(SeamError::UnknownBatch { batch: key.batch + 1 }));
            }
            // A blend already recorded, measured again by a device whose
            // update failed: dropped (were it taken, the change would read 0.9).
            let stale = key
                .batch
                .checked_sub(lag + 1)
                .map(|b| crate::DeviceProbeChanges { changes: vec![0.9; probes], ..change(b, probes) });
            due.extend(stale);
            assert_eq!(set.submit_device_blend(&due), Ok(UpdateStep::Done), "frame {frame}");
            let want = if frame as u64 >= lag { 0.25 } else { 1.0 };
            assert_eq!(set.volumes()[0].probe_change(5), want, "frame {frame}");
        }
    }

    #[test]
    fn a_volume_moved_into_a_new_set_keeps_its_batch_numbers_growing() {
        // A mark made in the new set counts against the batches before it;
        // the new set numbers its batches past the volume's, so its own
        // blends' changes still reach the budget `lag` updates later.
        let frame = |set: &mut DdgiFieldSet, f: u32| host_frame(set, f, ProbeRayHit::MISS, Vec3::ONE);
        let mut set = budget_set(2, false);
        (0..5).for_each(|f| frame(&mut set, f));
        let mut set = DdgiFieldSet::from_volumes(set.into_volumes(), VolumeBlending::default(), None);
        let every = (Vec3::splat(-10.0), Vec3::splat(10.0));
        assert_eq!(set.volumes_mut()[0].mark_changed_near(&[every]), set.probe_count());
        (5..8).for_each(|f| frame(&mut set, f));
        // Frame 5's blend (the first after the mark, change 0) is recorded at frame 7.
        assert_eq!(set.volumes()[0].probe_change(0), 0.0);
    }
}
