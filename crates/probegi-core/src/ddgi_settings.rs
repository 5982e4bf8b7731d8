//! Per-volume DDGI settings: a plain struct whose `Default` holds the papers' and
//! RTXGI's published values (RTXGI `DDGIVolumeDesc`). Field names are the TOML
//! keys of a scene file's `[volume]` table and of `--set KEY=VALUE`.

use glam::{UVec3, Vec3};
use serde::{Deserialize, Serialize};

pub use crate::probe_classification::ProbeStatesMode;

/// How the query offsets the visibility test point away from the surface.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Serialize, Deserialize)]
#[serde(rename_all = "snake_case")]
pub enum ProbeBiasMode {
    /// Seed 004 eq. 2: (0.2·n + 0.8·ω_o) · 0.75 · min spacing · `probe_self_shadow_bias`.
    SelfShadow,
    /// Seed 003 eq. 4.11: (0.8·n + 0.3·v) · `probe_normal_bias`.
    Normal,
    /// No bias (for the leak ablation of seed 000 Fig. 7).
    None,
}

/// One DDGI volume: its probe grid, rays, atlas tiles, blending, bias,
/// relocation, classification and probe states. Each field's doc gives the
/// source of its default.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields, default)]
pub struct DdgiVolumeSettings {
    /// Probes per axis; any count ≥ 1 (seed 003 §4.1 allows non-powers of two).
    pub probe_counts: UVec3,
    /// World position of probe (0,0,0); absent = fit the grid to the scene bounds.
    pub probe_origin_m: Option<Vec3>,
    /// Spacing per axis in metres; absent = fit the grid to the scene bounds
    /// (or to `volume_bounds_m`). `--set probe_spacing_m=S` takes a scalar for all axes.
    pub probe_spacing_m: Option<Vec3>,
    /// The box `[lo, hi]` the grid is fitted to when no origin or spacing is given;
    /// absent = the scene bounds. A `[[volumes]]` entry places a volume this way.
    pub volume_bounds_m: Option<[Vec3; 2]>,
    /// A tracking window (seed 004 §7.3): the volume starts centred on the camera
    /// and moves with it in whole-cell steps over a circular buffer; planes that
    /// scroll in are reset and re-initialised. Blended camera-aware (§7.4).
    pub volume_tracks_camera: bool,
    /// A tracking window keeps its probe box at least half a cell inside these
    /// bounds `[lo, hi]` (m), on a lattice of cell centres from `lo`, on every
    /// axis where it fits, and centred on them where it does not: it follows
    /// the camera only as far as probes there still cover the scene, instead of
    /// spending them outside it (a camera at one end of Sponza's atrium left
    /// half of each cascade outside the building), and, where it fits, puts no
    /// plane on the bounds' faces, the outermost walls
    /// (`ProbeGrid::tracking_target_within`). `None` (the default): it follows
    /// the camera freely. `--cascades` sets it to the scene bounds.
    pub volume_tracking_bounds_m: Option<[Vec3; 2]>,
    /// Rays traced per probe per frame (RTXGI default 256; seed 000 Table 2 sweeps 32–256).
    pub probe_rays_per_probe: u32,
    /// Interior irradiance texels per side (seed 004 Table 2: 8×8 with the 1-texel border).
    pub probe_irradiance_texels: u32,
    /// Interior distance texels per side (seed 004 Table 2: 16×16 with the border).
    pub probe_distance_texels: u32,
    /// Temporal hysteresis α of eq. 4.12/4.15–4.16 (RTXGI 0.97).
    pub probe_hysteresis: f32,
    /// Power-cosine exponent k_s of the distance weight, seed 003 eq. 4.14 (RTXGI 50).
    pub probe_distance_exponent: f32,
    /// Perceptual irradiance encoding exponent, seed 004 §4.2 Listings 1–2 (5).
    pub probe_irradiance_gamma: f32,
    /// Which bias the query applies before the visibility test.
    pub probe_bias_mode: ProbeBiasMode,
    /// `TunableShadowBias` of seed 004 eq. 2 (default 0.3).
    pub probe_self_shadow_bias: f32,
    /// k_n of seed 003 eq. 4.11, metres; in [0, 1] per the thesis (we use 0.25).
    pub probe_normal_bias_m: f32,
    /// Energy conservation factor on sampled irradiance (seed 003 §4.4, in 0–1).
    /// 1 = none, as RTXGI; lower it only for scenes whose bounces diverge.
    pub probe_energy_conservation: f32,
    /// Probe rays longer than this count as misses (RTXGI `probeMaxRayDistance`).
    pub probe_max_ray_distance_m: f32,
    /// Weights below this are crushed by w²/c² (seed 003 eq. 4.10; RTXGI 0.2).
    pub probe_crush_threshold: f32,
    /// Wrap-shading backface weight ((cos+1)/2)² + 0.2 (seed 003 eq. 4.4 with a = 1, RTXGI's +0.2).
    pub probe_backface_weight: bool,
    /// Chebyshev visibility weight (seed 003 eq. 4.5–4.9), cubed with a 0.05 floor as RTXGI.
    pub probe_chebyshev_weight: bool,
    /// Crush of small weights (seed 003 eq. 4.10).
    pub probe_crush_weight: bool,
    /// Trilinear weight between the 8 cage probes.
    pub probe_trilinear_weight: bool,
    /// Fast-convergence heuristics (seed 004 §4.3, Listing 3): per-texel thresholds
    /// and per-probe scene-event hysteresis reductions.
    pub probe_fast_convergence: bool,
    /// Per-texel change (encoded irradiance, max component) above which hysteresis drops by 0.15.
    pub probe_significant_change_threshold: f32,
    /// Per-texel change above which hysteresis drops to 0 (a new distribution).
    pub probe_new_distribution_threshold: f32,
    /// Timberdoodle PGI's firefly clamp (`../shared/PEERS.md`): a texel's new
    /// irradiance estimate is limited to this many times its history
    /// (`probegi_core::probe_blend::firefly_clamp`; PGI 32). 0 (the default):
    /// off, as the papers blend; measured in docs/RESULTS.md.
    pub probe_firefly_clamp_ratio: f32,
    /// Timberdoodle PGI's adaptive per-texel hysteresis: each irradiance texel
    /// keeps a state that rises 0.1 a blend and falls by its relative change,
    /// and blends with at most that (`probegi_core::probe_blend::adaptive_texel_hysteresis`).
    /// Off by default; measured in docs/RESULTS.md.
    pub probe_adaptive_hysteresis: bool,
    /// The relative change (in the γ-encoded space) an adaptive-hysteresis
    /// state tolerates before it falls: noise below it lets the state climb
    /// (0: PGI's rule, every change counts). Measured in docs/RESULTS.md.
    pub probe_adaptive_hysteresis_tolerance: f32,
    /// Timberdoodle PGI's short-range AO on hit radiance (`../shared/PEERS.md`),
    /// against light stuck in corners: at each front probe-ray hit one
    /// cosine-distributed any-hit ray of this many times the volume's smallest
    /// spacing leaves the surface, and the field's term of the hit's radiance
    /// (diffuse albedo/π × the field's irradiance there) counts only when it
    /// escapes. The blend averages the binary samples over a texel's rays and
    /// frames. PEERS names the idea, not PGI's estimator; this is ours. 0 (the
    /// default): off; measured in docs/RESULTS.md.
    pub probe_hit_ao_radius_rel: f32,
    /// With `probe_hit_ao_radius_rel`: an AO ray that hits a front face within
    /// its length carries that occluder's radiance (shaded as a probe-ray hit
    /// is: its direct light by shadow rays, emission, and diffuse albedo/π ×
    /// the field's irradiance there) instead of zero, so the field's term is
    /// the one-bounce near-field estimate π · mean(escaped ? E_field(x)/π :
    /// L_occluder): exact in a furnace, where the plain AO darkens. Not in the
    /// papers: seed 000 §6 names DDGI's over-illumination and ambient
    /// occlusion as its remedy; this form of it is ours. Off by default (the
    /// papers have no such term); measured in docs/RESULTS.md.
    pub probe_hit_ao_near_field: bool,
    /// Probe position optimizer at initialisation (seed 004 §5, Listing 4).
    pub probe_relocation: bool,
    /// Optimizer iterations (seed 004: five).
    pub probe_relocation_iterations: u32,
    /// Rays per probe in each initialisation round (relocation and
    /// classification, seed 004 Listing 5's distance-only traces). Seed 004
    /// names no count; RTXGI runs both on 32 "fixed" rays a probe
    /// (`RTXGI_DDGI_NUM_FIXED_RAYS`), and so does this default, so that start-up
    /// costs about one update, not six full traces of every probe. Each round
    /// still turns the set by its own random rotation (unlike RTXGI's fixed
    /// directions: our rounds run once, so five rotations see more directions).
    pub probe_init_rays_per_probe: u32,
    /// Largest offset per axis as a fraction of the spacing (RTXGI 0.45; < 0.5 keeps grid indexing).
    pub probe_relocation_offset_limit_rel: f32,
    /// A front face closer than this × the minimum spacing pushes the probe away.
    pub probe_relocation_min_frontface_rel: f32,
    /// Probe states: `all-active`, `jcgt` (seed 004 §6), `usage` (seed 003 §6.1)
    /// or `screen` (Timberdoodle PGI's screen-driven countdowns; see
    /// `probegi_core::probe_classification`).
    pub probe_states: ProbeStatesMode,
    /// jcgt classification, first pass: a probe stays Vigilant when a front-face hit
    /// lies within this fraction of the spacing of its grid point on every axis
    /// (0.5 = its Voronoi cell, 1 = RTXGI's rule); a covering pass then keeps a
    /// front-side probe for every seen surface point (see `probe_classification`).
    /// Deviation from seed 004 Listing 5 (minimum spacing); 0.5 measured on Sponza.
    pub probe_classification_reach_rel: f32,
    /// Usage scheme: SLEEPING probes update every this many frames (seed 003: 10).
    pub probe_sleeping_update_interval: u32,
    /// Usage scheme: frames a probe stays ALIVE before it may fall asleep (seed 003
    /// §6.1 keeps ALIVE probes "for some minimum of frames" without a number; we use
    /// the sleeping interval, so a probe at the rim r is never stale longer than it).
    pub probe_alive_min_frames: u32,
    /// Usage scheme: update batches between a batch's trace and the
    /// classification its usage counts feed (0: the same batch, as seed 003
    /// §6.1 has it). Deliberate deviation, default 2: a device that keeps the
    /// hits counts usage there and the host reads the counts back this many
    /// batches late, never waiting on the device inside an update; the CPU
    /// backend lags alike, so both give the same states. A probe's state then
    /// follows what it saw two updates ago, well inside the sleeping interval.
    pub probe_usage_lag_updates: u32,
    /// Screen scheme: frames a probe stays Requested after a camera pixel last
    /// read its cage (PGI's direct countdown: 63).
    pub probe_screen_request_frames: u32,
    /// Screen scheme: Idle probes trace and blend every this many frames,
    /// interleaved (PGI updates 1/8 of its active probes a frame: 8).
    pub probe_screen_idle_interval_frames: u32,
    /// Second-order glossy from probes (seed 004 §4.4): the hit of a camera glossy ray
    /// adds its own specular reflection from the probes' irradiance.
    pub glossy_second_order: bool,
    /// Area-light next-event samples per probe-ray hit in the shade pass (stratified,
    /// rounded up to a square count).
    pub probe_area_light_samples: u32,
    /// Under a sky map: next-event samples of the map per probe-ray hit in the
    /// shade pass (drawn from its luminance density, stratified, rounded up to
    /// a square count). A map's light reaches surfaces this way, not through
    /// probe rays that miss (`Scene::sky_on_probe_miss`). 1, as
    /// `probe_area_light_samples`: a probe's rays and frames average it.
    pub probe_sky_light_samples: u32,
    /// Under a sky map: probe rays that miss read the map's radiance (as
    /// RTXGI's miss shader reads its sky), and hits take no next-event samples
    /// of it (`probe_sky_light_samples` unused). The field then carries the
    /// map's light, direct and bounced, for a renderer that does not sample
    /// the map at its pixels (an engine's: the Bevy plugin's). Off: probegi's
    /// own renderers sample the map at hits and pixels (`Scene::sky_on_probe_miss`
    /// says why), and a camera under this mode takes no sky samples either.
    pub probe_sky_map_on_miss: bool,
    /// The shadowing field (seed 003 ch. 5, `probegi_core::shadow_field`): the
    /// volume's probes also keep occlusion maps, fed by one shadow ray per light
    /// from each of the last frame's front-face hits, and cameras read punctual
    /// lights' visibility from them instead of tracing a shadow ray per pixel.
    /// Off by default: the seeds' DDGI has no such field.
    pub shadow_field: bool,
    /// Occlusion map interior texels per side (seed 003 Fig. 5.1, 7.10: 16×16).
    pub shadow_field_texels: u32,
    /// The power the sampled visibility is raised to (seed 003 Fig. 7.10 shows 1, 2
    /// and 3); 1 keeps it as blended.
    pub shadow_field_sharpness: f32,
    /// The lights a probe serves: the brightest this many punctual lights at the
    /// volume's centre (the seed's scenes have one or two; it names no limit).
    pub shadow_field_max_lights: u32,
    /// Probe-ray hits, too, read punctual lights' visibility from the shadowing
    /// field (the previous frame's) instead of tracing shadow rays: cheaper,
    /// softer bounce light. Off by default: the seed uses the field for the
    /// final image only.
    pub shadow_field_probe_shading: bool,
    /// Front-face surfels farther from their probe than this many cage
    /// diagonals cast no shadow ray (an extension, `probegi_field`'s
    /// `shadow_rays` docs); 0 keeps every surfel, as the seed does. 0.5–1
    /// measured best on the shadow box.
    pub shadow_field_surfel_reach_rel: f32,
    /// Probe rays per frame for the whole field set (seed 003 §8.2 and seed 000
    /// §5.2 leave it as future work; `probegi_field::ray_budget`): the tracing
    /// probes of every volume share them, whole probe updates at a time, those
    /// whose irradiance or visibility changed most first. 0 (the default)
    /// traces every tracing probe every frame, as the seeds do. A set uses the
    /// largest value among its volumes (`--set` gives every volume the same).
    pub ray_budget: u64,
    /// The budget's floor: a tracing probe traces at least once every this
    /// many frames, however little it changed (and the floor wins over the
    /// budget). Seed 000 §5.2 asks for "a set minimum" without a number; 8
    /// measured on the moving box and Sponza (docs/RESULTS.md).
    pub ray_budget_max_interval_frames: u32,
    /// Under a budget, a probe that last blended k frames ago blends with
    /// hysteresis α^k (capped at the floor's interval), as if it had blended
    /// this frame's estimate on each frame it skipped: the field then responds
    /// in as many frames as without a budget, at the cost of noise where
    /// probes wait. Measured in docs/RESULTS.md: off, a budget of half the rays
    /// doubles the lag of a change that reaches every probe.
    pub ray_budget_hysteresis_per_frame: bool,
    /// Ray budget: update batches between a blend and the moment its probes'
    /// changes (`probegi_core::probe_change`) enter the budget's priorities
    /// (0: the next plan reads them, as seed 003 §8.2 has it). Deliberate
    /// deviation, default 2: a device measures the changes after its blend
    /// and the host reads them back this many batches late, never waiting on
    /// the device inside an update; the CPU backend lags alike, so both
    /// choose the same probes.
    pub ray_budget_change_lag_updates: u32,
    /// Edge buffers (seed 003 §6.2.1's "buffering probes with low hysteresis",
    /// seed 004 §7.3's leapfrogging planes): in a tracking window, the this many
    /// planes nearest the face it last scrolled toward, on each axis it has
    /// scrolled along, blend with at most `volume_edge_buffer_hysteresis`, so
    /// the field in front of a moving camera converges first. 0 (the default)
    /// is off: a window that never scrolls is unchanged either way.
    /// *Deviation:* the seed buffers every edge and never samples it; we lower
    /// only the leading planes, which camera-aware blending (seed 004 §7.4)
    /// already reads at a falling weight.
    pub volume_edge_buffer_planes: u32,
    /// The edge buffers' hysteresis cap (the seed says "low" without a number;
    /// measured in docs/RESULTS.md).
    pub volume_edge_buffer_hysteresis: f32,
    /// A probe's first blends after it (re)starts average its samples
    /// equally: blend n (from 0) uses at most hysteresis 1 − 1/(n + 1), until
    /// that reaches `probe_hysteresis` (33 blends at 0.97), so a new probe's
    /// field is as old as the probe instead of keeping its first, darkest
    /// frames at α^n (a running mean, then the papers' exponential one; PGI
    /// ramps its per-texel hysteresis up by 0.1 per update instead). A seeded
    /// probe counts its seed as its first blend. Off by default; measured in
    /// docs/RESULTS.md.
    pub probe_hysteresis_ramp: bool,
    /// The volume's first blends average its frames equally: blend n of the
    /// volume (from 0, `DdgiVolume::frames_updated`) uses at most hysteresis
    /// 1 − 1/(n + 1), until that reaches `probe_hysteresis` (33 blends at
    /// 0.97). With α from a probe's second blend on, the field's bounces build
    /// up at (1 − α)(1 − λ) a frame (λ the scene's bounce gain): an e-fold
    /// every 70 frames on Sponza, where the 6 144-probe grid was 10 % dark at
    /// frame 100. The start-up ramp runs those bounces at full speed while the
    /// whole field is young. Unlike `probe_hysteresis_ramp` it ends with the
    /// start-up: probes woken or scrolled in later blend as the papers do
    /// (hysteresis 0, then α), so a dynamic object's passage is forgotten at
    /// α. A deliberate deviation from seed 004's update; measured in
    /// docs/RESULTS.md ("Convergence over the view set").
    pub probe_hysteresis_startup_ramp: bool,
    /// Seed the probes a tracking window scrolls in from the next coarser
    /// cascade (or sparser volume) instead of starting them from nothing
    /// (Timberdoodle PGI, `../shared/PEERS.md`; `probegi_field::probe_seeding`):
    /// their first own blend then weighs the seed with their hysteresis.
    /// Off by default; measured in docs/RESULTS.md.
    pub probe_seeding: bool,
}

impl Default for DdgiVolumeSettings {
    fn default() -> Self {
        Self {
            probe_counts: UVec3::splat(8),
            probe_origin_m: None,
            probe_spacing_m: None,
            volume_bounds_m: None,
            volume_tracks_camera: false,
            volume_tracking_bounds_m: None,
            probe_rays_per_probe: 256,
            probe_irradiance_texels: 6,
            probe_distance_texels: 14,
            probe_hysteresis: 0.97,
            probe_distance_exponent: 50.0,
            probe_irradiance_gamma: 5.0,
            probe_bias_mode: ProbeBiasMode::SelfShadow,
            probe_self_shadow_bias: 0.3,
            probe_normal_bias_m: 0.25,
            probe_energy_conservation: 1.0,
            probe_max_ray_distance_m: 1.0e4,
            probe_crush_threshold: 0.2,
            probe_backface_weight: true,
            probe_chebyshev_weight: true,
            probe_crush_weight: true,
            probe_trilinear_weight: true,
            probe_fast_convergence: true,
            probe_significant_change_threshold: 0.25,
            probe_new_distribution_threshold: 0.8,
            probe_firefly_clamp_ratio: 0.0,
            probe_adaptive_hysteresis: false,
            probe_adaptive_hysteresis_tolerance: 0.0,
            probe_hit_ao_radius_rel: 0.0,
            probe_hit_ao_near_field: false,
            probe_relocation: true,
            probe_relocation_iterations: 5,
            probe_init_rays_per_probe: 32,
            probe_relocation_offset_limit_rel: 0.45,
            probe_relocation_min_frontface_rel: 0.5,
            probe_states: ProbeStatesMode::Jcgt,
            probe_classification_reach_rel: 0.5,
            probe_sleeping_update_interval: 10,
            probe_alive_min_frames: 10,
            probe_usage_lag_updates: 2,
            probe_screen_request_frames: 63,
            probe_screen_idle_interval_frames: 8,
            glossy_second_order: true,
            probe_area_light_samples: 1,
            probe_sky_light_samples: 1,
            probe_sky_map_on_miss: false,
            shadow_field: false,
            shadow_field_texels: 16,
            shadow_field_sharpness: 1.0,
            shadow_field_max_lights: 8,
            shadow_field_probe_shading: false,
            shadow_field_surfel_reach_rel: 0.0,
            ray_budget: 0,
            ray_budget_max_interval_frames: 8,
            ray_budget_hysteresis_per_frame: true,
            ray_budget_change_lag_updates: 2,
            volume_edge_buffer_planes: 0,
            volume_edge_buffer_hysteresis: 0.8,
            probe_seeding: false,
            probe_hysteresis_ramp: false,
            probe_hysteresis_startup_ramp: true,
        }
    }
}

impl DdgiVolumeSettings {
    /// The first setting that makes no sense, as `(field, reason)`.
    pub fn validate(&self) -> Result<(), (&'static str, String)> {
        self.validate_grid_and_atlas()?;
        self.validate_update_parameters()
    }

    /// `validate`'s first checks: the probe grid (counts, spacing, origin,
    /// bounds), the rays per probe and the atlas tile sizes.
    fn validate_grid_and_atlas(&self) -> Result<(), (&'static str, String)> {
        let c = self.probe_counts;
        if c.min_element() == 0 {
            return Err(("probe_counts", format!("{c} has a zero count; every axis needs at least 1 probe")));
        }
        if c.max_element() > 1024 {
            return Err(("probe_counts", format!("{c}: at most 1024 probes per axis")));
        }
        if let Some(s) = self.probe_spacing_m
            && !(s.is_finite() && s.min_element() > 0.0)
        {
            return Err(("probe_spacing_m", format!("{s} must be finite and positive on every axis")));
        }
        if let Some(o) = self.probe_origin_m
            && !o.is_finite()
        {
            return Err(("probe_origin_m", format!("{o} must be finite")));
        }
        if let Some([lo, hi]) = self.volume_bounds_m
            && !(lo.is_finite() && hi.is_finite() && hi.cmpgt(lo).all())
        {
            return Err(("volume_bounds_m", format!("[{lo}, {hi}] must be finite with hi > lo on every axis")));
        }
        if let Some([lo, hi]) = self.volume_tracking_bounds_m
            && !(lo.is_finite() && hi.is_finite() && hi.cmpge(lo).all())
        {
            return Err((
                "volume_tracking_bounds_m",
                format!("[{lo}, {hi}] must be finite with hi ≥ lo on every axis"),
            ));
        }
        if let Some(s) = self.probe_spacing_m
            && !(self.probe_origin_m.unwrap_or(Vec3::ZERO) + s * self.probe_counts.as_vec3()).is_finite()
        {
            return Err(("probe_spacing_m", format!("{s} × the probe counts overflows")));
        }
        if self.probe_rays_per_probe == 0 || self.probe_rays_per_probe > 65_536 {
            return Err(("probe_rays_per_probe", format!("{} must be in 1..=65536", self.probe_rays_per_probe)));
        }
        for (name, v) in [
            ("probe_irradiance_texels", self.probe_irradiance_texels),
            ("probe_distance_texels", self.probe_distance_texels),
            ("shadow_field_texels", self.shadow_field_texels),
        ] {
            if v == 0 || v > 64 {
                return Err((name, format!("{v} must be in 1..=64")));
            }
        }
        Ok(())
    }

    /// `validate`'s remaining checks: the blend, bias, relocation,
    /// classification, probe-state and area-light parameters.
    fn validate_update_parameters(&self) -> Result<(), (&'static str, String)> {
        let unit = |name: &'static str, v: f32| {
            if (0.0..=1.0).contains(&v) { Ok(()) } else { Err((name, format!("{v} must be in [0, 1]"))) }
        };
        unit("probe_hysteresis", self.probe_hysteresis)?;
        unit("probe_adaptive_hysteresis_tolerance", self.probe_adaptive_hysteresis_tolerance)?;
        unit("probe_energy_conservation", self.probe_energy_conservation)?;
        unit("probe_crush_threshold", self.probe_crush_threshold)?;
        unit("probe_classification_reach_rel", self.probe_classification_reach_rel)?;
        unit("volume_edge_buffer_hysteresis", self.volume_edge_buffer_hysteresis)?;
        let positive = |name: &'static str, v: f32| {
            if v.is_finite() && v > 0.0 { Ok(()) } else { Err((name, format!("{v} must be finite and > 0"))) }
        };
        positive("probe_distance_exponent", self.probe_distance_exponent)?;
        positive("probe_irradiance_gamma", self.probe_irradiance_gamma)?;
        positive("shadow_field_sharpness", self.shadow_field_sharpness)?;
        if !(self.shadow_field_surfel_reach_rel.is_finite() && self.shadow_field_surfel_reach_rel >= 0.0) {
            return Err((
                "shadow_field_surfel_reach_rel",
                format!("{} must be finite and ≥ 0", self.shadow_field_surfel_reach_rel),
            ));
        }
        if self.shadow_field && self.shadow_field_max_lights == 0 {
            return Err(("shadow_field_max_lights", "0: a shadow field must serve at least one light".into()));
        }
        positive("probe_max_ray_distance_m", self.probe_max_ray_distance_m)?;
        let non_negative = |name: &'static str, v: f32| {
            if v.is_finite() && v >= 0.0 { Ok(()) } else { Err((name, format!("{v} must be finite and >= 0"))) }
        };
        non_negative("probe_self_shadow_bias", self.probe_self_shadow_bias)?;
        non_negative("probe_hit_ao_radius_rel", self.probe_hit_ao_radius_rel)?;
        non_negative("probe_normal_bias_m", self.probe_normal_bias_m)?;
        if !(0.0..0.5).contains(&self.probe_relocation_offset_limit_rel) {
            return Err((
                "probe_relocation_offset_limit_rel",
                format!("{} must be in [0, 0.5) so grid indexing holds", self.probe_relocation_offset_limit_rel),
            ));
        }
        non_negative("probe_relocation_min_frontface_rel", self.probe_relocation_min_frontface_rel)?;
        non_negative("probe_significant_change_threshold", self.probe_significant_change_threshold)?;
        non_negative("probe_new_distribution_threshold", self.probe_new_distribution_threshold)?;
        let r = self.probe_firefly_clamp_ratio;
        if !(r.is_finite() && (r == 0.0 || r >= 1.0)) {
            return Err(("probe_firefly_clamp_ratio", format!("{r} must be 0 (off) or a finite ratio ≥ 1")));
        }
        if self.probe_relocation_iterations > 100 {
            return Err((
                "probe_relocation_iterations",
                format!("{} must be at most 100", self.probe_relocation_iterations),
            ));
        }
        if !(1..=65_536).contains(&self.probe_init_rays_per_probe) {
            return Err((
                "probe_init_rays_per_probe",
                format!("{} must be in 1..=65536", self.probe_init_rays_per_probe),
            ));
        }
        if self.ray_budget_max_interval_frames == 0 || self.ray_budget_max_interval_frames > 1000 {
            return Err((
                "ray_budget_max_interval_frames",
                format!("{} must be in 1..=1000", self.ray_budget_max_interval_frames),
            ));
        }
        if self.ray_budget_change_lag_updates > 8 {
            let lag = self.ray_budget_change_lag_updates;
            return Err(("ray_budget_change_lag_updates", format!("{lag} must be at most 8")));
        }
        if self.probe_usage_lag_updates > 8 {
            return Err(("probe_usage_lag_updates", format!("{} must be at most 8", self.probe_usage_lag_updates)));
        }
        if self.probe_screen_request_frames == 0 || self.probe_screen_request_frames > 10_000 {
            return Err((
                "probe_screen_request_frames",
                format!("{} must be in 1..=10000", self.probe_screen_request_frames),
            ));
        }
        if self.probe_screen_idle_interval_frames == 0 || self.probe_screen_idle_interval_frames > 1000 {
            return Err((
                "probe_screen_idle_interval_frames",
                format!("{} must be in 1..=1000", self.probe_screen_idle_interval_frames),
            ));
        }
        if self.probe_sleeping_update_interval == 0 {
            return Err(("probe_sleeping_update_interval", "must be at least 1".into()));
        }
        if self.probe_area_light_samples > 1024 {
            return Err((
                "probe_area_light_samples",
                format!("{} must be at most 1024", self.probe_area_light_samples),
            ));
        }
        if self.probe_sky_light_samples > 1024 {
            return Err(("probe_sky_light_samples", format!("{} must be at most 1024", self.probe_sky_light_samples)));
        }
        Ok(())
    }

    /// Probes in the grid: the product of `probe_counts`.
    pub fn probe_count(&self) -> u64 {
        self.probe_counts.as_u64vec3().element_product()
    }
}

/// How a set of volumes is sampled (the weights are `ddgi_volume_blend`'s).
#[derive(Clone, Copy, Debug, PartialEq, Eq, Serialize, Deserialize, Default)]
#[serde(rename_all = "kebab-case")]
pub enum VolumeBlending {
    /// Seed 004 §7.4: densest first, one-cell falloff, camera-aware for tracking volumes.
    #[default]
    Density,
    /// Seed 003 §6.2 Algorithms 1–2: nested cascades, finest first.
    Cascades,
}

/// A set of DDGI volumes (`probegi_field::ddgi_field_set::DdgiFieldSet`): the volumes
/// in any order (the set samples them densest or finest first) and how they blend.
#[derive(Clone, Debug, PartialEq, Default)]
pub struct DdgiFieldSetSettings {
    /// Each volume's settings, in any order.
    pub volumes: Vec<DdgiVolumeSettings>,
    /// How the set samples and blends its volumes.
    pub blending: VolumeBlending,
}

/// Spacing ratio between neighbouring cascades, `--cascades`' default.
/// *Deviation:* seed 003 §6.2 halves the probe density per cascade (2). With
/// the coarsest cascade the scene's fitted grid, 1.5 makes the finer cascades
/// coarser and wider. On Sponza (3 × 16×8×16, 300 frames) it scores HDR-FLIP
/// 0.089 against 0.095 at 2, below the best fitted grid of the same probe
/// count (0.093); docs/RESULTS.md, "Probe planes off the outer walls". In the
/// 4×4 world of Sponza copies, ratio 2's middle cascades still light a gallery
/// from outside: 0.170 there against 0.134 at 1.5.
pub const DEFAULT_CASCADE_SPACING_RATIO: f32 = 1.5;

/// Probes of each cascade when `--cascades N` gets neither `--probes` nor a
/// scene file's `[volume]`: 16×8×16, the counts every cascade measurement in
/// docs/RESULTS.md used (three of them on Sponza: HDR-FLIP 0.126 at 300
/// frames against 0.128 for the fitted 32×16×12 of the same 6 144 probes, and
/// 0.157 against 0.194 at 100 frames). Before, a cascade took the single
/// volume's default 8×8×8, and `--cascades 3` gave 1 536 probes scoring 0.180.
pub const DEFAULT_CASCADE_PROBE_COUNTS: glam::UVec3 = glam::UVec3::new(16, 8, 16);

impl DdgiFieldSetSettings {
    /// One volume: today's single grid.
    pub fn single(volume: DdgiVolumeSettings) -> Self {
        Self { volumes: vec![volume], blending: Default::default() }
    }

    /// Seed 003 §6.2: `count` camera-centred cascades with `base`'s settings (its
    /// probe counts in every cascade), the innermost `innermost_spacing_m` apart and
    /// each next one `ratio` × farther apart. Every cascade is a tracking window.
    pub fn cascades(count: u32, base: &DdgiVolumeSettings, innermost_spacing_m: Vec3, ratio: f32) -> Self {
        let volumes = (0..count)
            .map(|i| DdgiVolumeSettings {
                probe_origin_m: None,
                probe_spacing_m: Some(innermost_spacing_m * ratio.powi(i as i32)),
                volume_bounds_m: None,
                volume_tracks_camera: true,
                ..base.clone()
            })
            .collect();
        Self { volumes, blending: VolumeBlending::Cascades }
    }

    /// [`Self::cascades`] over a scene of `bounds` (`probegi render
    /// --cascades`): every window held inside the bounds (unless `base`
    /// names its own tracking bounds), and, unless `base` fixes a spacing,
    /// the coarsest cascade the fitted grid of the bounds (probes at the
    /// centres of `probe_counts` equal cells, as `ProbeGrid::fit_to_bounds`
    /// places them), which covers the whole scene from any camera.
    pub fn cascades_over_bounds(count: u32, base: &DdgiVolumeSettings, (lo, hi): (Vec3, Vec3), ratio: f32) -> Self {
        let mut base = base.clone();
        base.volume_tracking_bounds_m.get_or_insert([lo, hi]);
        let spacing = base.probe_spacing_m.unwrap_or_else(|| {
            let cells = base.probe_counts.as_vec3().max(Vec3::ONE);
            ((hi - lo) / cells / ratio.powi(count as i32 - 1)).max(Vec3::splat(1e-3))
        });
        Self::cascades(count, &base, spacing, ratio)
    }

    /// The first volume setting that makes no sense, as `(volume index, field, reason)`.
    pub fn validate(&self) -> Result<(), (usize, &'static str, String)> {
        if self.volumes.is_empty() {
            return Err((0, "volumes", "a set needs at least one volume".into()));
        }
        if self.volumes.len() > 64 {
            return Err((64, "volumes", format!("{} volumes: at most 64", self.volumes.len())));
        }
        for (i, v) in self.volumes.iter().enumerate() {
            v.validate().map_err(|(f, why)| (i, f, why))?;
        }
        // Where the field carries a sky map the camera samples none of it, so
        // every member must carry it or none.
        let on_miss = self.volumes[0].probe_sky_map_on_miss;
        if let Some(i) = self.volumes.iter().position(|v| v.probe_sky_map_on_miss != on_miss) {
            let why = format!("{} here but {on_miss} on volume 0: every volume or none", !on_miss);
            return Err((i, "probe_sky_map_on_miss", why));
        }
        Ok(())
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn a_set_carries_a_sky_map_on_every_volume_or_none() {
        let on = DdgiVolumeSettings { probe_sky_map_on_miss: true, ..Default::default() };
        let mixed =
            DdgiFieldSetSettings { volumes: vec![on.clone(), DdgiVolumeSettings::default()], ..Default::default() };
        assert_eq!(mixed.validate().map_err(|e| (e.0, e.1)), Err((1, "probe_sky_map_on_miss")));
        let all = DdgiFieldSetSettings { volumes: vec![on.clone(), on], ..Default::default() };
        assert!(all.validate().is_ok());
    }

    #[test]
    fn defaults_are_the_papers_values_and_valid() {
        let s = DdgiVolumeSettings::default();
        assert_eq!(s.probe_rays_per_probe, 256);
        assert_eq!((s.probe_irradiance_texels + 2, s.probe_distance_texels + 2), (8, 16));
        assert_eq!(s.probe_hysteresis, 0.97);
        assert_eq!(s.probe_distance_exponent, 50.0);
        assert_eq!(s.probe_irradiance_gamma, 5.0);
        assert_eq!(s.probe_self_shadow_bias, 0.3);
        assert_eq!(s.probe_crush_threshold, 0.2);
        assert_eq!((s.probe_relocation_iterations, s.probe_init_rays_per_probe), (5, 32));
        assert!(s.validate().is_ok());
    }

    #[test]
    fn nonsense_is_rejected_by_field_name() {
        let bad = |f: fn(&mut DdgiVolumeSettings)| {
            let mut s = DdgiVolumeSettings::default();
            f(&mut s);
            s.validate().expect_err("invalid").0
        };
        assert_eq!(bad(|s| s.probe_counts = UVec3::new(0, 4, 4)), "probe_counts");
        assert_eq!(bad(|s| s.probe_rays_per_probe = 0), "probe_rays_per_probe");
        assert_eq!(bad(|s| s.probe_init_rays_per_probe = 0), "probe_init_rays_per_probe");
        assert_eq!(bad(|s| s.probe_spacing_m = Some(Vec3::new(1.0, -1.0, 1.0))), "probe_spacing_m");
        assert_eq!(bad(|s| s.probe_hysteresis = 1.5), "probe_hysteresis");
        assert_eq!(bad(|s| s.probe_hysteresis = -0.1), "probe_hysteresis");
        assert_eq!(bad(|s| s.probe_firefly_clamp_ratio = 0.5), "probe_firefly_clamp_ratio");
        assert_eq!(bad(|s| s.probe_firefly_clamp_ratio = f32::NAN), "probe_firefly_clamp_ratio");
        assert_eq!(bad(|s| s.probe_distance_exponent = f32::NAN), "probe_distance_exponent");
    }

    #[test]
    fn cascades_over_bounds_make_the_coarsest_the_fitted_grid_held_inside() {
        let bounds = (Vec3::new(-8.0, 0.0, -4.0), Vec3::new(8.0, 8.0, 4.0));
        let base = DdgiVolumeSettings { probe_counts: glam::UVec3::new(16, 8, 16), ..Default::default() };
        let set = DdgiFieldSetSettings::cascades_over_bounds(3, &base, bounds, 2.0);
        let spacing = |i: usize| set.volumes[i].probe_spacing_m.expect("spacing");
        // 16 × 8 × 8 m in 16 × 8 × 16 cells: 1 × 1 × 0.5 m at the coarsest, halved twice inward.
        assert!(spacing(2).abs_diff_eq(Vec3::new(1.0, 1.0, 0.5), 1e-6));
        assert!(spacing(0).abs_diff_eq(Vec3::new(0.25, 0.25, 0.125), 1e-6));
        assert!(set.volumes.iter().all(|v| v.volume_tracking_bounds_m == Some([bounds.0, bounds.1])));
        assert_eq!(set.blending, VolumeBlending::Cascades);
        // A base that names its spacing and tracking bounds keeps them.
        let own = DdgiVolumeSettings {
            probe_spacing_m: Some(Vec3::splat(0.5)),
            volume_tracking_bounds_m: Some([Vec3::ZERO, Vec3::ONE]),
            ..base
        };
        let set = DdgiFieldSetSettings::cascades_over_bounds(2, &own, bounds, 2.0);
        assert_eq!(set.volumes[1].probe_spacing_m, Some(Vec3::splat(1.0)));
        assert_eq!(set.volumes[0].volume_tracking_bounds_m, Some([Vec3::ZERO, Vec3::ONE]));
    }
}
