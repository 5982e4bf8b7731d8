//! What the viewer's panels set: the GI method, the field's settings, the
//! lights and the sky, the view, the scene clock. Plain data, so the panels
//! (UI thread) and the frame worker (its own thread) exchange it by value.
//!
//! Two kinds of field setting:
//! - **live** ([`FieldControls::apply_live`]): hysteresis, fast convergence,
//!   second-order glossy and the ray budget change the running field's
//!   `DdgiVolumeSettings` between two frames;
//! - **rebuild** ([`ViewerControls::needs_rebuild`]): the GI method, rays per
//!   probe, the probe-state scheme, relocation, the shadowing field and the
//!   cascade count size the field's buffers, so the worker builds the field
//!   anew with them (as RTXGI's harness recreates a volume whose probe
//!   counts change); the field then converges from black again.
//!
//! Lights and sky reach the scene through `FrameStepper::set_scene_edit`,
//! which the field sees as a keyframed light's change: its scene-change
//! detector and fast-convergence heuristics react as in `probegi lag`.

use probegi_core::ddgi_settings::DdgiVolumeSettings;
use probegi_core::probe_classification::ProbeStatesMode;
use probegi_field::ddgi_field_set::DdgiFieldSet;
use probegi_scene::{LightKind, Scene};
use serde::{Deserialize, Serialize};

use crate::view_layers::ViewMode;

/// The GI method of the panel.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq, Serialize, Deserialize)]
#[serde(rename_all = "kebab-case")]
pub enum GiChoice {
    /// Direct light only.
    None,
    /// The DDGI field.
    #[default]
    Ddgi,
    /// Screen-space GI with SH probes (seed 001; the CPU backend).
    Sh,
}

/// The field settings the panel exposes (volume 0's; applied to every volume).
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct FieldControls {
    /// `probe_hysteresis` (live).
    pub hysteresis: f32,
    /// `probe_fast_convergence` (live).
    pub fast_convergence: bool,
    /// `glossy_second_order` (live).
    pub glossy_second_order: bool,
    /// `ray_budget`, rays per frame, 0 = off (live).
    pub ray_budget: u64,
    /// `probe_rays_per_probe` (rebuild).
    pub rays_per_probe: u32,
    /// `probe_states` (rebuild).
    pub probe_states: ProbeStatesMode,
    /// `probe_relocation` (rebuild).
    pub relocation: bool,
    /// `shadow_field` (rebuild).
    pub shadow_field: bool,
}

impl FieldControls {
    /// The controls as `settings` holds them.
    pub fn from_settings(s: &DdgiVolumeSettings) -> Self {
        Self {
            hysteresis: s.probe_hysteresis,
            fast_convergence: s.probe_fast_convergence,
            glossy_second_order: s.glossy_second_order,
            ray_budget: s.ray_budget,
            rays_per_probe: s.probe_rays_per_probe,
            probe_states: s.probe_states,
            relocation: s.probe_relocation,
            shadow_field: s.shadow_field,
        }
    }

    /// Writes the live settings into every volume of `set`.
    pub fn apply_live(&self, set: &mut DdgiFieldSet) {
        for v in set.volumes_mut() {
            v.settings.probe_hysteresis = self.hysteresis.clamp(0.0, 1.0);
            v.settings.probe_fast_convergence = self.fast_convergence;
            v.settings.glossy_second_order = self.glossy_second_order;
            v.settings.ray_budget = self.ray_budget;
        }
    }

    /// The settings that differ from `base` (what the command line built) as
    /// `--set KEY=VALUE` overrides, for the field built anew; every setting
    /// without a base. A scene's `[[volumes]]` keep their own values for the
    /// settings the panel did not touch.
    pub fn set_overrides_from(&self, base: Option<&FieldControls>) -> Vec<String> {
        let all = self.set_overrides();
        match base {
            Some(b) => all.into_iter().zip(b.set_overrides()).filter(|(a, b)| a != b).map(|(a, _)| a).collect(),
            None => all,
        }
    }

    /// Every panel setting as a `--set KEY=VALUE` override.
    pub fn set_overrides(&self) -> Vec<String> {
        let states = match self.probe_states {
            ProbeStatesMode::AllActive => "all-active",
            ProbeStatesMode::Jcgt => "jcgt",
            ProbeStatesMode::Usage => "usage",
            ProbeStatesMode::Screen => "screen",
        };
        vec![
            format!("probe_hysteresis={}", self.hysteresis),
            format!("probe_fast_convergence={}", self.fast_convergence),
            format!("glossy_second_order={}", self.glossy_second_order),
            format!("ray_budget={}", self.ray_budget),
            format!("probe_rays_per_probe={}", self.rays_per_probe),
            format!("probe_states={states}"),
            format!("probe_relocation={}", self.relocation),
            format!("shadow_field={}", self.shadow_field),
        ]
    }
}

/// One punctual light's switch.
#[derive(Clone, Debug, PartialEq)]
pub struct LightControl {
    /// Its name in the panel (kind and index).
    pub name: String,
    /// On or off.
    pub enabled: bool,
    /// Its intensity over the scene's.
    pub intensity_scale: f32,
}

/// Everything the panels set (see the module docs).
#[derive(Clone, Debug, PartialEq)]
pub struct ViewerControls {
    /// The GI method.
    pub gi: GiChoice,
    /// The field's settings (`None`: the method has no DDGI field).
    pub field: Option<FieldControls>,
    /// Camera-centred cascades (`--cascades`); 0: the scene's volumes (rebuild).
    pub cascades: u32,
    /// The scene's punctual lights.
    pub lights: Vec<LightControl>,
    /// Sky radiance over the scene's.
    pub sky_scale: f32,
    /// What the frame shows.
    pub view: ViewMode,
    /// The volume whose atlases the atlas views show.
    pub atlas_volume: usize,
    /// The scene clock is paused.
    pub paused: bool,
    /// The field's settings as the command line built them (the first
    /// session's), against which a rebuild's overrides are taken.
    pub field_at_start: Option<FieldControls>,
}

impl ViewerControls {
    /// The controls of a freshly built session: `scene`'s lights at their
    /// intensity, and the field's settings as built.
    pub fn new(gi: GiChoice, cascades: u32, scene: &Scene, field: Option<&DdgiFieldSet>) -> Self {
        let lights = scene
            .lights
            .iter()
            .enumerate()
            .map(|(i, l)| {
                let kind = match l.kind {
                    LightKind::Point => "point",
                    LightKind::Spot => "spot",
                    LightKind::Directional => "sun",
                };
                LightControl { name: format!("{kind} {i}"), enabled: true, intensity_scale: 1.0 }
            })
            .collect();
        Self {
            gi,
            field: field.and_then(|f| f.volumes().first()).map(|v| FieldControls::from_settings(&v.settings)),
            cascades,
            lights,
            sky_scale: 1.0,
            view: ViewMode::Full,
            atlas_volume: 0,
            paused: false,
            field_at_start: None,
        }
    }

    /// Whether going from `self` to `next` builds the field anew.
    pub fn needs_rebuild(&self, next: &ViewerControls) -> bool {
        let structural =
            |f: &Option<FieldControls>| f.map(|f| (f.rays_per_probe, f.probe_states, f.relocation, f.shadow_field));
        self.gi != next.gi || self.cascades != next.cascades || structural(&self.field) != structural(&next.field)
    }

    /// Whether the lights or the sky differ from the scene's.
    pub fn edits_scene(&self) -> bool {
        self.sky_scale != 1.0 || self.lights.iter().any(|l| !l.enabled || l.intensity_scale != 1.0)
    }

    /// The scene edit for `FrameStepper::set_scene_edit`: each light's
    /// intensity and the sky set from the base scene's by these switches.
    pub fn scene_edit(&self) -> probegi_frame::frame_loop::SceneEdit<'static> {
        let scales: Vec<f32> =
            self.lights.iter().map(|l| if l.enabled { l.intensity_scale.max(0.0) } else { 0.0 }).collect();
        let sky = self.sky_scale.max(0.0);
        Box::new(move |base: &Scene, posed: &mut Scene| {
            for (l, s) in posed.lights.iter_mut().zip(&scales) {
                l.intensity *= s;
            }
            posed.sky_radiance = base.sky_radiance * sky;
            // The posed map (its keyframes applied this frame) scaled alike.
            if let Some(posed_map) = posed.sky_map.as_mut() {
                posed_map.intensity *= sky;
            }
        })
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn overrides_are_only_what_the_panel_changed() {
        let base = FieldControls::from_settings(&DdgiVolumeSettings::default());
        let mut f = base;
        assert!(f.set_overrides_from(Some(&base)).is_empty());
        f.rays_per_probe = 64;
        f.probe_states = ProbeStatesMode::AllActive;
        assert_eq!(
            f.set_overrides_from(Some(&base)),
            vec!["probe_rays_per_probe=64".to_string(), "probe_states=all-active".to_string()]
        );
        assert_eq!(f.set_overrides_from(None).len(), 8);
    }
}
