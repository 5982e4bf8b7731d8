//! What a device that keeps the hits (and the field) needs to run the
//! relocation, classification and blend passes where the hits lie: each plan is
//! what the host pass would do, as data (`DdgiFieldSet::device_*_plan`).

use glam::Vec3;
use probegi_core::ddgi_settings::DdgiVolumeSettings;
use probegi_core::probe_classification::ClassificationProbe;
use probegi_core::probe_grid::ProbeGrid;

/// A new plan identity (`DeviceVolumeBlend::probe_blend_id`,
/// `GeneratedProbeRays::plan_id`): unique in the process, so two sets (or
/// two frames of one) never share one by chance.
pub(crate) fn next_plan_id() -> u64 {
    static NEXT: std::sync::atomic::AtomicU64 = std::sync::atomic::AtomicU64::new(1);
    NEXT.fetch_add(1, std::sync::atomic::Ordering::Relaxed)
}

/// One volume's share of an update blended on another device (see
/// `DdgiFieldSet::device_blend_plan`): what `blend_results` would do, as data.
#[derive(Clone, Debug)]
pub struct DeviceVolumeBlend<'a> {
    /// The volume's settings (atlas sizes, encoding, thresholds).
    pub settings: &'a DdgiVolumeSettings,
    /// The frame's unit ray directions (every probe's, in ray order): the
    /// device weighs them against each texel's direction itself
    /// (`max(0, ω·r)^k` as `probegi_core::probe_blend::BlendWeights` does).
    pub ray_dirs: &'a [Vec3],
    /// Per probe: its first ray in the batch and its blend hysteresis (before the
    /// start-up cap and the scene-event scales), or `None` when it does not
    /// blend this frame.
    pub probe_blend: std::borrow::Cow<'a, [Option<(u32, f32)>]>,
    /// An identity of `probe_blend` (`device_plans::next_plan_id`): plans with the
    /// same `Some` id have the same entries (a steady frame's kept plan,
    /// `ddgi_volume::steady_frames`), so a device may keep what it made of
    /// them; `None`: made for this frame alone.
    pub probe_blend_id: Option<u64>,
    /// The start-up ramp's cap on every probe's hysteresis this frame
    /// (`probe_hysteresis_startup_ramp`; 1: none). The device blends with the
    /// smaller of it and the probe's own, so `probe_blend`'s entries repeat
    /// from frame to frame while the ramp runs (a device may keep them).
    pub hysteresis_cap: f32,
    /// The scene-event reduction of the irradiance hysteresis (`probe_fast_convergence`; 1 otherwise).
    pub irradiance_scale: f32,
    /// The scene-event reduction of the distance (visibility) hysteresis.
    pub visibility_scale: f32,
    /// The distance limit of the blend ([`crate::ddgi_volume::DdgiVolume::distance_clamp_m`]).
    pub distance_clamp_m: f32,
    /// Probes whose tiles the host cleared since the last blend (scrolled in):
    /// the device clears its copies before blending.
    pub reset_probes: &'a [u32],
    /// Seeds for some of `reset_probes` (`crate::probe_seeding`), mixed from
    /// other volumes' tiles after the clear and before any blend of the frame.
    pub seeds: &'a [crate::probe_seeding::ProbeSeed],
    /// The shadowing field's share, for a volume that keeps one
    /// ([`DeviceShadowBlend`]; `None` otherwise).
    pub shadow: Option<DeviceShadowBlend>,
    /// A ray budget runs: after the blend (and the shadowing field's), the
    /// device measures each blended probe's change
    /// (`probegi_core::probe_change::probe_change` of its irradiance and
    /// occlusion tiles, before against after) and returns one per probe
    /// with `probe_blend` set, in increasing probe order
    /// ([`crate::DeviceBlendOutput::probe_change`]), read back
    /// `change_key.lag_updates` batches later.
    pub measure_change: bool,
    /// Under which set and batch the measured changes come back, and how
    /// late ([`DeviceChangeKey`]).
    pub change_key: DeviceChangeKey,
    /// Per probe, the frames its blend stands for (a ray budget's probe that
    /// waited, `ray_budget_hysteresis_per_frame`): each texel's hysteresis,
    /// after the scene-event scale and Listing 3, is raised to it
    /// (`probegi_core::probe_blend::hysteresis_over_frames`). Empty: 1 for all.
    pub probe_blend_frames: std::borrow::Cow<'a, [u32]>,
}

/// Where a blend's measured probe changes come back
/// (`DeviceVolumeBlend::change_key`): the set's identity (a device that
/// serves several sets keeps theirs apart), the update batch's number in the
/// set, and the batches they may wait on the device: the blend of batch `n`
/// returns the changes of every blend up to `n − lag_updates` not yet
/// returned (0: its own, waited for).
#[derive(Clone, Copy, Default, PartialEq, Eq)]
pub struct DeviceChangeKey {
    /// The set's identity (`device_plans::next_plan_id`).
    pub set_id: u64,
    /// The update batch's number in the set.
    pub batch: u64,
    /// `ray_budget_change_lag_updates`.
    pub lag_updates: u32,
}

/// An identity, not a value: `Debug` leaves `set_id` out, so two sets' equal
/// plans print alike.
impl std::fmt::Debug for DeviceChangeKey {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.debug_struct("DeviceChangeKey").field("batch", &self.batch).field("lag_updates", &self.lag_updates).finish()
    }
}

/// The changes a device measured after one volume's blend of an earlier
/// update batch ([`DeviceChangeKey`]).
#[derive(Clone, Debug, PartialEq)]
pub struct DeviceProbeChanges {
    /// The volume's index in the plan.
    pub volume: u32,
    /// The update batch's number in the set.
    pub batch: u64,
    /// One per probe the volume blended in that batch, in increasing probe order.
    pub changes: Vec<f32>,
}

/// What [`crate::DeviceField::shade_and_blend`] returns.
#[derive(Clone, Debug, Default)]
pub struct DeviceBlendOutput {
    /// Wall milliseconds by pass (`shade`, `blend`, ...), the host having waited for each.
    pub pass_ms: Vec<(&'static str, f64)>,
    /// The changes measured after earlier blends now due, where a plan asked
    /// for them (`DeviceVolumeBlend::measure_change`), by volume and batch.
    pub probe_change: Vec<DeviceProbeChanges>,
}

/// What a device that keeps an update batch's hits counts there for the
/// usage scheme (`DdgiFieldSet::device_usage_request`; seed 003 §6.1): per
/// probe of the batch, (usage, relevant, backfaces)
/// (`probegi_core::probe_classification::probe_usage`), read back
/// `lag_updates` batches later ([`DeviceUsageCounts`]).
#[derive(Clone, Debug, PartialEq)]
pub struct DeviceUsageRequest {
    /// Per volume of the set, its cage diagonal (m): a probe's counts use its volume's.
    pub cage_diagonals_m: Vec<f32>,
    /// The set's identity (`device_plans::next_plan_id`): a device that serves
    /// several sets keeps their counts apart.
    pub set_id: u64,
    /// The batch's number in the set; the counts come back under it.
    pub batch: u64,
    /// Batches a batch's counts may stay on the device: the call for batch `n`
    /// returns those of every batch up to `n − lag_updates` not yet returned
    /// (waiting for them only if the device has not finished them). 0: this
    /// batch's own, waited for.
    pub lag_updates: u32,
}

/// The usage counts of one earlier update batch, as a device read them back
/// ([`DeviceUsageRequest`]): one per entry of that batch's `probes`, in order.
#[derive(Clone, Debug, PartialEq)]
pub struct DeviceUsageCounts {
    /// The batch's number in its set ([`DeviceUsageRequest::batch`]).
    pub batch: u64,
    /// (usage, relevant, backfaces) per probe of the batch.
    pub counts: Vec<probegi_core::probe_classification::ProbeUsageCounts>,
}

/// One volume's shadowing-field update on another device (seed 003 §5.1, eq.
/// 5.2–5.3; `ddgi_volume::shadow_rays` on the host): shadow rays from the hits
/// of the previous frame's update batch, which the device kept, toward
/// `lights`, blended into the occlusion maps it holds.
#[derive(Clone, Debug)]
pub struct DeviceShadowBlend {
    /// The frame whose update batch the rays below refer to: a device whose
    /// kept batch is another frame's blends nothing this frame.
    pub prev_frame: u32,
    /// Front-face surfels farther than this (m) from their probe cast no
    /// shadow ray (`shadow_field_surfel_reach_rel`; 0: every surfel).
    pub surfel_reach_m: f32,
    /// The lights the volume serves (its brightest `shadow_field_max_lights`).
    pub lights: Vec<probegi_scene::PunctualLight>,
    /// Per probe that blends this frame and traced in the previous one: its
    /// storage slot, its first ray and ray count in that frame's batch, and its
    /// occlusion hysteresis (0 for a first blend).
    pub probes: Vec<(u32, u32, u32, f32)>,
}

/// One volume's initialisation rounds chained on another device
/// (`DdgiFieldSet::device_init_plan`; `ddgi_volume::init_rounds` on the host):
/// `relocation_rounds` iterations of seed 004 Listing 4 for the pending probes
/// (a probe whose iteration left it in place traces no more, its hits kept),
/// then, with `classification`, one trace of the probes that moved in the last
/// round and the classification over every pending probe's kept hits. Every
/// round traces `dirs` from each probe's position at that round; the device
/// runs them back to back, with no result crossing to the host between them.
#[derive(Clone, Debug)]
pub struct DeviceInitChain<'a> {
    /// The volume's settings (relocation limits, max ray distance).
    pub settings: &'a DdgiVolumeSettings,
    /// The volume's probe lattice.
    pub grid: &'a ProbeGrid,
    /// Per probe: waiting for initialisation (the rounds move and classify it).
    pub pending: &'a [bool],
    /// Per probe: its offset from its grid point now (m).
    pub offsets_m: &'a [Vec3],
    /// Relocation iterations to run (0: none).
    pub relocation_rounds: u32,
    /// The fixed unit directions every round traces (RTXGI's fixed rays).
    pub dirs: Vec<Vec3>,
    /// The classification after the relocation, with jcgt states: each pending
    /// probe's rays at `probe × dirs.len()` of the kept hits. Its probes'
    /// `position_m` are where they start: the device classifies at the
    /// positions its relocation rounds leave.
    pub classification: Option<DeviceClassification<'a>>,
}

/// What a device returns for one volume's [`DeviceInitChain`].
#[derive(Clone, Debug, Default)]
pub struct DeviceInitResult {
    /// Per probe: its offset after the relocation rounds (m).
    pub offsets_m: Vec<Vec3>,
    /// Per probe (inside geometry, kept), where the chain classified.
    pub classification: Option<Vec<(bool, bool)>>,
    /// Rays the chain traced with a length (settled probes' rounds skipped).
    pub rays_traced: u64,
}

/// One volume's classification round run on another device (the end of a
/// [`DeviceInitChain`]): the grid, the watch box
/// (`probe_classification_reach_rel`, the query's largest surface bias) and
/// every probe of the volume.
#[derive(Clone, Debug)]
pub struct DeviceClassification<'a> {
    /// The volume's probe lattice.
    pub grid: &'a ProbeGrid,
    /// Rays each probe cast in the round.
    pub rays_per_probe: u32,
    /// The watch box's half-size per axis, as a fraction of the spacing
    /// (`probe_classification_reach_rel`).
    pub reach_rel: f32,
    /// The query's largest surface bias (m), which grows the watch box.
    pub bias_m: f32,
    /// Every probe of the volume: its ray range, init and trace state, and position.
    pub probes: Vec<ClassificationProbe>,
}
