//! Scene-change detection for the field (seed 004 §4.3 and Listing 5), done the
//! way an application would report changes, so every driver of a field set gets
//! it: call [`SceneChangeDetector::observe`] once per frame with the scene as it
//! is that frame, before the field update.
//!
//! - A punctual light switching on or off (intensity crossing zero) is a large
//!   light change for every volume.
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
}

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
        if scene.has_moving_geometry() {
            let bounds = scene.moving_object_bounds();
            changes.probes_woken = set.wake_probes_near(&bounds);
            if self.object_bounds.len() == bounds.len() {
                for (i, v) in set.volumes_mut().iter_mut().enumerate() {
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
                        v.notify_scene_event(SceneEvent::LargeObjectChange);
                        changes.object_jumps.push(i);
                    }
                }
            }
            self.object_bounds = bounds;
        }
        changes
    }
}
