//! Scene-change detection for the field (seed 004 §4.3 and Listing 5), done the
//! way an application would report changes, so every driver of a field set gets
//! it: call [`SceneChangeDetector::observe`] once per frame with the scene as it
//! is that frame, before the field update.
//!
//! - A punctual light switching on or off (intensity crossing zero) is a large
//!   light change for every volume.
//! - A sky map that turns or dims between frames (a moving sun, seed 004's
//!   time of day) is a small light change for every volume, renewed each frame
//!   it moves; a jump (more than [`SKY_JUMP_DEG`] of rotation, or an intensity
//!   that halves, doubles or crosses zero, in one frame) is a large one.
//! - Sleeping probes inside moving objects' boxes, grown by a cell, wake (jcgt).
//! - An object whose centre jumps by more than a volume's smallest spacing in one
//!   frame, within that volume grown by a cell, is a large object change for that
//!   volume (an occluder put in place).

use glam::{UVec3, Vec3};
use probegi_scene::Scene;

use probegi_field::ddgi_field_set::DdgiFieldSet;
use probegi_field::ddgi_volume::SceneEvent;

/// What one observation changed.
#[derive(Clone, Debug, Default, PartialEq)]
pub struct SceneChanges {
    /// A punctual light switched on or off since the last observation.
    pub light_toggled: bool,
    /// The sky map turned or dimmed since the last observation: `Some(true)`
    /// for a jump (a large light change), `Some(false)` for a gradual change.
    pub sky_changed: Option<bool>,
    /// Volumes told of a large object change.
    pub object_jumps: Vec<usize>,
    /// Sleeping probes woken around moving objects.
    pub probes_woken: usize,
}

/// Remembers the previous frame's lights and moving-object boxes.
#[derive(Clone, Debug, Default)]
pub struct SceneChangeDetector {
    lights_on: Option<Vec<bool>>,
    object_bounds: Vec<(Vec3, Vec3)>,
    /// The sky map's (intensity, rotation_deg) last observed.
    sky: Option<(f32, f32)>,
}

/// A sky map turning by more than this in one frame is a large light change
/// (seed 004 §4.3's abrupt time-of-day change); less is a small one.
pub const SKY_JUMP_DEG: f32 = 10.0;

impl SceneChangeDetector {
    /// A detector that has observed no frame yet.
    pub fn new() -> Self {
        Self::default()
    }

    /// Takes `scene`'s lights as the last observed frame's without reporting
    /// anything (a scene that starts to be observed mid-render: a viewer's
    /// first light switch is then a change).
    pub fn remember_lights(&mut self, scene: &Scene) {
        if self.lights_on.is_none() {
            self.lights_on = Some(scene.lights.iter().map(|l| l.intensity > 0.0).collect());
        }
    }

    /// The sky map's change since the last observation, told to `set` (see the module docs).
    fn observe_sky(&mut self, scene: &Scene, set: &mut DdgiFieldSet) -> Option<bool> {
        let now = scene.sky_map.as_ref().map(|m| (m.intensity, m.rotation_deg));
        let prev = std::mem::replace(&mut self.sky, now);
        let ((i0, r0), (i1, r1)) = (prev?, now?);
        if i0 == i1 && r0 == r1 {
            return None;
        }
        let crossed = (i0 > 0.0) != (i1 > 0.0);
        let jump = crossed || (r1 - r0).abs() > SKY_JUMP_DEG || i1 > 2.0 * i0 || i0 > 2.0 * i1;
        set.notify_scene_event(if jump { SceneEvent::LargeLightChange } else { SceneEvent::SmallLightChange });
        Some(jump)
    }

    /// Compares `scene` (this frame) with the last observed frame and reports the
    /// changes to `set`.
    pub fn observe(&mut self, scene: &Scene, set: &mut DdgiFieldSet) -> SceneChanges {
        let mut changes = SceneChanges::default();
        let on: Vec<bool> = scene.lights.iter().map(|l| l.intensity > 0.0).collect();
        if let Some(prev) = &self.lights_on
            && prev.len() == on.len()
            && prev.iter().zip(&on).any(|(a, b)| a != b)
        {
            changes.light_toggled = true;
            set.notify_scene_event(SceneEvent::LargeLightChange);
        }
        self.lights_on = Some(on);
        changes.sky_changed = self.observe_sky(scene, set);
        if scene.has_moving_geometry() {
            let bounds = scene.moving_object_bounds();
            changes.probes_woken = set.wake_probes_near(&bounds);
            if self.object_bounds.len() == bounds.len() {
                // Found through the shared view and notified one by one:
                // `volumes_mut` would draw new identities of every volume's
                // rows (a kept plan and the query's kept rows would go).
                for (i, v) in set.volumes().iter().enumerate() {
                    let g = &v.grid;
                    let (lo, hi) = (g.probe_position(UVec3::ZERO), g.probe_position(g.probe_counts - 1));
                    let near =
                        |b: &(Vec3, Vec3)| b.0.cmple(hi + g.spacing_m).all() && b.1.cmpge(lo - g.spacing_m).all();
                    let centre = |b: &(Vec3, Vec3)| (b.0 + b.1) * 0.5;
                    let jumped = self
                        .object_bounds
                        .iter()
                        .zip(&bounds)
                        .any(|(a, b)| (near(a) || near(b)) && centre(a).distance(centre(b)) > g.min_spacing_m());
                    if jumped {
                        changes.object_jumps.push(i);
                    }
                }
                for &i in &changes.object_jumps {
                    set.notify_volume_scene_event(i, SceneEvent::LargeObjectChange);
                }
            }
            self.object_bounds = bounds;
        }
        changes
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use probegi_core::ddgi_settings::DdgiVolumeSettings;
    use probegi_field::ddgi_volume::DdgiVolume;

    #[test]
    fn a_turning_sky_map_is_a_small_light_change_and_a_jump_a_large_one() {
        let map = probegi_scene::EnvironmentMap::from_texels(std::path::Path::new("sky"), 4, 2, vec![Vec3::ONE; 8])
            .expect("map");
        let mut scene = probegi_scene::builtin::cornell_box();
        scene.sky_map = Some(probegi_scene::SkyMap::new(std::sync::Arc::new(map)));
        let settings = DdgiVolumeSettings { probe_counts: UVec3::splat(2), ..Default::default() };
        let mut set = DdgiFieldSet::single(DdgiVolume::new(settings, (Vec3::ZERO, Vec3::ONE)));
        let mut detector = SceneChangeDetector::new();
        let mut at = |scene: &Scene, set: &mut DdgiFieldSet| {
            let c = detector.observe(scene, set);
            (c.sky_changed, set.volumes()[0].irradiance_hysteresis_scale())
        };
        // The first observation only remembers the sky; a still sky changes nothing.
        assert_eq!(at(&scene, &mut set), (None, 1.0));
        assert_eq!(at(&scene, &mut set), (None, 1.0));
        let turn = |scene: &mut Scene, deg: f32| scene.sky_map.as_mut().expect("map").rotation_deg = deg;
        turn(&mut scene, 2.0);
        let (changed, small) = at(&scene, &mut set);
        assert_eq!(changed, Some(false));
        assert!(small < 1.0, "a turning sky lowers the hysteresis: {small}");
        turn(&mut scene, 2.0 + SKY_JUMP_DEG + 1.0);
        let (changed, large) = at(&scene, &mut set);
        assert_eq!(changed, Some(true));
        assert!(large < small, "a jump lowers it further: {large} after {small}");
        // Dimming to half is a jump too.
        scene.sky_map.as_mut().expect("map").intensity = 0.4;
        assert_eq!(at(&scene, &mut set).0, Some(true));
    }

    /// Moving geometry, jumps included, leaves the rows' identity of every
    /// volume as it was (`DdgiFieldView::probe_rows_id`): a still field keeps
    /// its plan and the query keeps its rows while an object moves.
    #[test]
    fn moving_geometry_keeps_the_rows_identity() {
        let path = concat!(env!("CARGO_MANIFEST_DIR"), "/../../scenes/moving-box.toml");
        let base = probegi_scene::load_scene(path).expect("moving box");
        assert!(base.has_moving_geometry());
        let mut scene = base.clone();
        let settings = DdgiVolumeSettings { probe_counts: UVec3::splat(4), ..Default::default() };
        let mut set = DdgiFieldSet::single(DdgiVolume::new(settings, base.bounds().expect("bounds")));
        let id = |set: &DdgiFieldSet| set.view().members[0].field.probe_rows_id;
        let first = id(&set);
        let mut detector = SceneChangeDetector::new();
        let mut moved = 0;
        for f in 0..60 {
            scene.set_frame_from(&base, f as f32 * 4.0);
            let before = scene.moving_object_bounds();
            let changes = detector.observe(&scene, &mut set);
            moved += changes.object_jumps.len() + (before != base.moving_object_bounds()) as usize;
        }
        assert!(moved > 0, "the object moved");
        assert!(first.is_some() && id(&set) == first, "{first:?} → {:?}", id(&set));
    }
}
