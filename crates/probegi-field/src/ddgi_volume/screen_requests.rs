//! The screen scheme's states (`ProbeStatesMode::Screen`; Timberdoodle PGI's
//! request countdowns, `probegi_core::probe_classification` module docs):
//! the camera frame's requests arrive between updates
//! ([`DdgiVolume::request_probe`]); each update first turns them into
//! countdowns and states ([`DdgiVolume::tick_screen_requests`]), then traces
//! the Requested probes, the probes without content and the Idle probes in
//! their interleaved phase ([`DdgiVolume::traces_in_frame`]). With
//! `probe_seeding`, a probe a tracking window scrolls in has content from its
//! seed: queries read it at once, and unless requested it waits for its
//! phase, as PGI's seeded probes wait for their interleaved update.

use probegi_core::ddgi_settings::ProbeStatesMode;
use probegi_core::probe_classification::{ProbeState, screen_idle_phase};

use super::{DdgiVolume, VolumeFrame};

impl DdgiVolume {
    /// Marks storage slot `p` as read by a camera pixel since the last update
    /// (screen scheme; not recorded under the others nor for a slot out of
    /// range).
    pub fn request_probe(&mut self, p: usize) {
        if self.settings.probe_states != ProbeStatesMode::Screen {
            return;
        }
        if let Some(r) = self.probe_requested.get_mut(p) {
            *r = true;
        }
    }

    /// Frames probe `p` stays Requested (0: Idle).
    pub fn probe_request_countdown(&self, p: usize) -> u32 {
        self.probe_request_countdown.get(p).copied().unwrap_or(0)
    }

    /// Screen scheme, at the start of an update: a probe requested since the
    /// last update restarts its countdown at `probe_screen_request_frames`,
    /// the others count one frame down; a probe with frames left is
    /// Requested, else Idle. Probes not yet initialised keep their state.
    pub(crate) fn tick_screen_requests(&mut self) {
        if self.settings.probe_states != ProbeStatesMode::Screen {
            return;
        }
        let frames = self.settings.probe_screen_request_frames;
        // The per-probe arrays in step (no index checks), so the loop has no
        // branch a probe but the pending one.
        let probes = self.probe_request_countdown.iter_mut().zip(&mut self.probe_requested);
        let probes = probes.zip(self.probe_states.iter_mut().zip(&self.probe_pending_init));
        for ((countdown, requested), (state, &pending)) in probes {
            *countdown = if std::mem::take(requested) { frames } else { countdown.saturating_sub(1) };
            if !pending {
                *state = if *countdown > 0 { ProbeState::Requested } else { ProbeState::Idle };
            }
        }
    }

    /// Whether probe `p`'s state traces in frame `frame`: under the screen
    /// scheme a Requested probe or one without content (neither blended nor
    /// seeded) always, an Idle one in
    /// its phase of `probe_screen_idle_interval_frames`
    /// (`probegi_core::probe_classification::screen_idle_phase`) and, with a
    /// shadowing field, the frame after; under the other schemes, as the
    /// state says. `phases`: every probe's phase where the caller holds them
    /// ([`Self::idle_phases`]), else each is computed here.
    pub(crate) fn traces_in_frame(&self, p: usize, frame: u32, phases: Option<&[u32]>) -> bool {
        let state = self.probe_states[p];
        if state != ProbeState::Idle || !self.probe_has_content(p) {
            return state.traces();
        }
        let interval = self.settings.probe_screen_idle_interval_frames.max(1);
        let phase = phases.map_or_else(|| screen_idle_phase(self.world_cell(p), interval), |ph| ph[p]);
        let now = frame % interval;
        // A shadowing field blends a probe's occlusion maps from the surfels of
        // its trace the frame before (`shadow_rays`): with one, an Idle probe
        // traces two frames in a row, in its phase and the next.
        now == phase || (self.shadow.is_some() && now == (phase + 1) % interval)
    }

    /// Every probe's [`Self::traces_in_frame`] in probe order, appended to
    /// `tracing`, and where `chosen` (a ray budget's choice) is given, only
    /// the probes it chose. With `phases` (every probe's), the frame's place
    /// in the idle interval is worked out once instead of a remainder a
    /// probe, and the per-probe arrays are read in step.
    pub(crate) fn extend_tracing(
        &self,
        tracing: &mut Vec<bool>,
        frame: u32,
        phases: Option<&[u32]>,
        chosen: Option<&[bool]>,
    ) {
        let probes = self.grid.probe_count();
        let Some(phases) = phases.filter(|ph| ph.len() == probes) else {
            tracing.extend((0..probes).map(|p| self.traces_in_frame(p, frame, None) && chosen.is_none_or(|c| c[p])));
            return;
        };
        let interval = self.settings.probe_screen_idle_interval_frames.max(1);
        let now = frame % interval;
        // The phase whose next frame is this one (`traces_in_frame`'s second
        // frame with a shadowing field).
        let before = (now + interval - 1) % interval;
        let shadow = self.shadow.is_some();
        let probes_in_step = self.probe_states.iter().zip(self.probes_have_content()).zip(phases);
        tracing.extend(probes_in_step.enumerate().map(|(p, ((&state, content), &phase))| {
            // `traces_in_frame`, with the arrays read in step.
            let traces = match state == ProbeState::Idle && content {
                true => phase == now || (shadow && phase == before),
                false => state.traces(),
            };
            traces && chosen.is_none_or(|c| c[p])
        }));
    }

    /// Screen scheme: every probe's idle phase (`screen_idle_phase` of its
    /// world cell), where [`Self::keep_idle_phases`] computed them for the
    /// volume's grid and interval as they are now; `None` otherwise.
    pub(crate) fn idle_phases(&self) -> Option<&[u32]> {
        let key = (self.grid, self.settings.probe_screen_idle_interval_frames.max(1));
        (self.idle_phases.0 == Some(key)).then_some(self.idle_phases.1.as_slice())
    }

    /// Screen scheme: computes every probe's idle phase where the grid or the
    /// interval changed since they were last computed (a window that scrolls
    /// moves the grid), so a frame's plan looks each up instead of deriving
    /// it from the probe's coordinates (three divisions and a remainder a probe).
    pub(crate) fn keep_idle_phases(&mut self) {
        if self.settings.probe_states != ProbeStatesMode::Screen || self.idle_phases().is_some() {
            return;
        }
        let interval = self.settings.probe_screen_idle_interval_frames.max(1);
        let phases = (0..self.grid.probe_count()).map(|p| screen_idle_phase(self.world_cell(p), interval)).collect();
        self.idle_phases = (Some((self.grid, interval)), phases);
    }

    /// Probe `p`'s lattice point in whole cells from the world origin: a
    /// probe keeps it while a tracking window scrolls around it.
    pub(super) fn world_cell(&self, p: usize) -> glam::IVec3 {
        let g = &self.grid;
        // floor(x + ½), not round(): a tie never flips with the origin's sign.
        (g.origin_m / g.spacing_m + 0.5).floor().as_ivec3() + g.probe_coords(p).as_ivec3()
    }

    /// Screen scheme: per probe, the frames its blend this frame would stand
    /// for, the frames since it last traced, capped at the idle interval
    /// (under a ray budget, which may hold an Idle probe back past its phase,
    /// at the larger of that and `ray_budget_max_interval_frames`); read
    /// before the trace counts reset. The scheme's own α^k does not depend on
    /// `ray_budget_hysteresis_per_frame`.
    pub(super) fn screen_blend_frames(&self, frame: &mut VolumeFrame) {
        frame.screen_blend_frames.clear();
        if self.settings.probe_states != ProbeStatesMode::Screen {
            return;
        }
        let mut cap = self.settings.probe_screen_idle_interval_frames.max(1);
        if frame.budget_traces.is_some() {
            cap = cap.max(self.settings.ray_budget_max_interval_frames);
        }
        frame.screen_blend_frames.extend(self.probe_untraced_frames.iter().map(|n| n.saturating_add(1).min(cap)));
    }
}
