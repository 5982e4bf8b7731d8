//! Scrolling: a tracking window's whole-cell move over the circular buffer of
//! probe storage slots (seed 004's camera-following volume). Probes that scroll
//! in are reset: their history is cleared, queries skip them until their first
//! blend (under the screen scheme, until their first blend or seed), and they
//! wait for initialisation like new probes.

use glam::{IVec3, Vec2, Vec3};
use probegi_core::ddgi_query::nearest_usable_probes;
use probegi_core::probe_classification::ProbeState;

use super::DdgiVolume;

impl DdgiVolume {
    /// Moves a tracking window so that `target_m` (held inside
    /// `volume_tracking_bounds_m` where set) stays within a cell of its
    /// centre (seed 004 §7.3). Only the grid origin and the circular buffer's phase
    /// change; the probes of the planes that enter are reset (atlas tiles cleared,
    /// offset 0, no history, so they blend with hysteresis 0 and are not read
    /// before that) and queued for initialisation. Returns the probes reset.
    pub(crate) fn scroll_to(&mut self, target_m: Vec3) -> usize {
        if !self.settings.volume_tracks_camera || !target_m.is_finite() {
            return 0;
        }
        let target_m = match self.settings.volume_tracking_bounds_m {
            Some(b) => self.grid.tracking_target_within(target_m, b),
            None => target_m,
        };
        let cells = self.grid.tracking_scroll_cells(target_m);
        if cells == IVec3::ZERO {
            return 0;
        }
        self.grid.scroll(cells);
        self.scroll_leading = IVec3::select(cells.cmpne(IVec3::ZERO), cells.signum(), self.scroll_leading);
        let mut reset = 0;
        for p in 0..self.grid.probe_count() {
            let coords = self.grid.probe_coords(p);
            if self.grid.scrolled_in(cells, coords) {
                self.reset_probe(p);
                reset += 1;
            }
            self.probe_positions[p] = self.grid.probe_position(coords) + self.probe_offsets[p];
        }
        self.probes_scrolled_in += reset as u64;
        self.refresh_usable();
        // The slots changed places on the grid: the nearest usable probe of each is
        // another one now, whether or not the usable set changed.
        self.probe_fallback = nearest_usable_probes(&self.grid, &self.probe_usable);
        self.renew_probe_rows_id();
        reset
    }

    /// Whether storage slot `p` lies in the edge buffer: within
    /// `volume_edge_buffer_planes` planes of a face the window last scrolled
    /// toward (`DdgiVolumeSettings::volume_edge_buffer_planes`).
    pub(crate) fn in_edge_buffer(&self, p: usize) -> bool {
        let planes = self.settings.volume_edge_buffer_planes;
        if planes == 0 || !self.settings.volume_tracks_camera {
            return false;
        }
        let (c, n) = (self.grid.probe_coords(p), self.grid.probe_counts);
        (0..3).any(|a| match self.scroll_leading[a] {
            1 => c[a] + planes >= n[a],
            -1 => c[a] < planes,
            _ => false,
        })
    }

    /// Clears again the tiles of the probes reset since the last blend (after the
    /// atlases were copied back from a device that had not cleared them yet).
    pub(crate) fn clear_reset_tiles(&mut self) {
        for &p in &self.probes_reset_since_blend {
            if (p as usize) < self.grid.probe_count() {
                self.irradiance.tile_mut(p as usize).fill(Vec3::ZERO);
                self.distance.tile_mut(p as usize).fill(Vec2::ZERO);
                if let Some(shadow) = self.shadow.as_mut() {
                    shadow.occlusion.tile_mut(p as usize).fill(1.0);
                }
            }
        }
    }

    /// Forgets everything probe `p` knew: it is a new probe at its grid point.
    fn reset_probe(&mut self, p: usize) {
        self.settle_steady_counts();
        self.irradiance.tile_mut(p).fill(Vec3::ZERO);
        self.distance.tile_mut(p).fill(Vec2::ZERO);
        self.probe_offsets[p] = Vec3::ZERO;
        self.renew_probe_rows_id();
        self.probe_states[p] = ProbeState::Active;
        self.probe_hysteresis[p] = self.settings.probe_hysteresis;
        self.probe_has_history[p] = false;
        self.probe_alive_frames[p] = 0;
        self.restart_usage(p);
        self.probe_pending_init[p] = true;
        self.probe_init_hits_current[p] = false;
        self.mark_changed(p);
        self.probe_untraced_frames[p] = 0;
        self.probe_occlusion_change[p] = 0.0;
        self.probe_unblended_frames[p] = 0;
        self.probe_trace_run[p] = 0;
        self.probe_seeded[p] = false;
        self.probe_request_countdown[p] = 0;
        self.probe_blends[p] = 0;
        self.probe_requested[p] = false;
        self.probes_reset_since_blend.push(p as u32);
        if let Some(shadow) = self.shadow.as_mut() {
            shadow.reset_probe(p);
        }
    }
}
