//! Rigid object animation over frame numbers (dynamic-scenes issue; seed 000 §4.1
//! moves a spotlight, seed 003 moves occluders, seed 004 §4.3 wakes probes around
//! dynamic objects).
//!
//! An object is a contiguous range of the scene mesh's triangles and vertices.
//! Its authored geometry is its *rest* pose; at frame `f` every vertex is
//! `world_from_rest(f) · p_rest`, where
//!
//! ```text
//! world_from_rest(f) = placement · motion(f) · T(pivot) · T(t(f)) · R(r(f)) · S(s(f)) · T(−pivot) · placement⁻¹
//! ```
//!
//! - `t, r, s` come from keyframes, each channel interpolated linearly (rotation by
//!   slerp) between the keys that set it and held before the first and after the
//!   last, as light keyframes are;
//! - `motion(f)` is an optional closed-form path: a constant velocity, an orbit
//!   about an axis, or a spin about the pivot;
//! - key times count frames, or seconds (glTF) converted with the scene's
//!   `frames_per_second`;
//! - `pivot` defaults to the centre of the rest bounds, so rotation and scale act
//!   about the object itself;
//! - `placement` is the transform a scene file applied when it placed a file that
//!   carries its own animation (glTF), so that the animation moves with it.
//!
//! Scales must be positive: a mirroring animation would flip triangle windings
//! mid-sequence.

use glam::{Affine3A, Mat4, Quat, Vec3};

/// A key whose frame number orders it.
pub(crate) trait Keyed {
    fn frame(&self) -> f32;
}

/// Linear interpolation of one channel over the keys that set it; holds before
/// the first and after the last. `None` when no key sets the channel.
pub(crate) fn channel<K: Keyed, T: Copy>(
    keys: &[K],
    frame: f32,
    get: impl Fn(&K) -> Option<T>,
    lerp: impl Fn(T, T, f32) -> T,
) -> Option<T> {
    let mut prev: Option<(f32, T)> = None;
    for k in keys {
        let Some(v) = get(k) else { continue };
        if k.frame() >= frame {
            return Some(match prev {
                Some((f0, v0)) if k.frame() > f0 => lerp(v0, v, (frame - f0) / (k.frame() - f0)),
                _ => v,
            });
        }
        prev = Some((k.frame(), v));
    }
    prev.map(|p| p.1)
}

/// Why a key sequence is unusable: frames must be finite and increasing (a step
/// change is two keys one frame apart).
pub(crate) fn validate_key_frames<K: Keyed>(keys: &[K]) -> Result<(), String> {
    for (i, k) in keys.iter().enumerate() {
        if !k.frame().is_finite() || (i > 0 && k.frame() <= keys[i - 1].frame()) {
            return Err(format!("keyframe {i}: frame {} must be finite and after the previous key's", k.frame()));
        }
    }
    Ok(())
}

/// One key of an object's animation; any channel may be absent.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct TransformKeyframe {
    /// When this key applies, in the units of the animation's [`KeyClock`].
    pub frame: f32,
    /// Offset from the rest pose, metres.
    pub translation: Option<Vec3>,
    /// Rotation about the pivot.
    pub rotation: Option<Quat>,
    /// Scale about the pivot; every component positive.
    pub scale: Option<Vec3>,
}

impl Keyed for TransformKeyframe {
    fn frame(&self) -> f32 {
        self.frame
    }
}

/// Closed-form motion paths; in a scene file, `motion = { kind = "orbit", ... }`
/// with these field names.
#[derive(Clone, Copy, Debug, PartialEq, serde::Deserialize)]
#[serde(tag = "kind", rename_all = "snake_case", deny_unknown_fields)]
pub enum MotionPath {
    /// Constant velocity from the rest pose at frame 0.
    Translate {
        /// Displacement per frame, metres.
        velocity_m_per_frame: Vec3,
    },
    /// The whole object revolves about the axis through `centre_m`, one turn per
    /// `period_frames` (it keeps facing the centre, like a moon).
    Orbit {
        /// A point on the axis, metres.
        centre_m: Vec3,
        /// The axis direction (any non-zero length).
        axis: Vec3,
        /// Frames per full turn.
        period_frames: f32,
    },
    /// The object spins about its pivot, one turn per `period_frames`.
    Rotate {
        /// The spin axis direction through the pivot (any non-zero length).
        axis: Vec3,
        /// Frames per full turn.
        period_frames: f32,
    },
}

impl MotionPath {
    fn transform(&self, frame: f32, pivot: Vec3) -> Affine3A {
        let turn =
            |axis: Vec3, period: f32| Quat::from_axis_angle(axis.normalize(), std::f32::consts::TAU * frame / period);
        match *self {
            MotionPath::Translate { velocity_m_per_frame } => Affine3A::from_translation(velocity_m_per_frame * frame),
            MotionPath::Orbit { centre_m, axis, period_frames } => {
                Affine3A::from_rotation_translation(turn(axis, period_frames), centre_m)
                    * Affine3A::from_translation(-centre_m)
            }
            MotionPath::Rotate { axis, period_frames } => {
                Affine3A::from_rotation_translation(turn(axis, period_frames), pivot)
                    * Affine3A::from_translation(-pivot)
            }
        }
    }

    fn validate(&self) -> Result<(), String> {
        let (vectors, period) = match *self {
            MotionPath::Translate { velocity_m_per_frame } => (vec![velocity_m_per_frame], None),
            MotionPath::Orbit { centre_m, axis, period_frames } => (vec![centre_m, axis], Some((axis, period_frames))),
            MotionPath::Rotate { axis, period_frames } => (vec![axis], Some((axis, period_frames))),
        };
        if vectors.iter().any(|v| !v.is_finite()) {
            return Err("motion vectors must be finite".into());
        }
        if let Some((axis, period)) = period {
            if axis.length_squared() < 1e-12 {
                return Err("motion axis must be non-zero".into());
            }
            if !(period.is_finite() && period > 0.0) {
                return Err(format!("motion period_frames must be positive, got {period}"));
            }
        }
        Ok(())
    }
}

/// What a keyframe's `frame` counts.
#[derive(Clone, Copy, Debug, Default, PartialEq)]
pub enum KeyClock {
    /// Frame numbers (scene files).
    #[default]
    Frames,
    /// Seconds (glTF), played at `frames_per_second` (the scene's clock).
    Seconds {
        /// Frames per second of animation time.
        frames_per_second: f32,
    },
}

/// How an object moves; `Default` is still.
#[derive(Clone, Debug, Default, PartialEq)]
pub struct ObjectAnimation {
    /// Keyed offsets from the rest pose, in increasing `frame` order; empty when not keyed.
    pub keyframes: Vec<TransformKeyframe>,
    /// What the keys' `frame` counts.
    pub clock: KeyClock,
    /// A closed-form path, applied on top of the keyed pose.
    pub motion: Option<MotionPath>,
}

impl ObjectAnimation {
    /// Whether there is neither a key nor a motion path.
    pub fn is_still(&self) -> bool {
        self.keyframes.is_empty() && self.motion.is_none()
    }
}

/// A rigid object: a contiguous range of the scene mesh and its animation.
#[derive(Clone, Debug, PartialEq)]
pub struct SceneObject {
    /// For messages: the name the file gave it.
    pub name: String,
    /// First index into `Scene::mesh.triangles`.
    pub first_triangle: u32,
    /// Triangles in the range.
    pub triangle_count: u32,
    /// First index into the mesh's per-vertex arrays.
    pub first_vertex: u32,
    /// Vertices in the range.
    pub vertex_count: u32,
    /// Rotation and scale centre in rest space, metres.
    pub pivot_m: Vec3,
    /// How the object moves over frames.
    pub animation: ObjectAnimation,
    /// The transform a scene file placed this object's source with (see module docs).
    pub placement: Mat4,
}

impl SceneObject {
    /// The object's range of `Scene::mesh.triangles`.
    pub fn triangles(&self) -> std::ops::Range<usize> {
        self.first_triangle as usize..(self.first_triangle + self.triangle_count) as usize
    }

    /// The object's range of the mesh's per-vertex arrays.
    pub fn vertices(&self) -> std::ops::Range<usize> {
        self.first_vertex as usize..(self.first_vertex + self.vertex_count) as usize
    }

    /// Whether the object moves at all.
    pub fn is_animated(&self) -> bool {
        !self.animation.is_still()
    }

    /// The object's transform at `frame`, from its rest pose to world space.
    pub fn world_from_rest(&self, frame: f32) -> Affine3A {
        let a = &self.animation;
        if a.is_still() {
            return Affine3A::IDENTITY;
        }
        let k = &a.keyframes;
        let key_time = match a.clock {
            KeyClock::Frames => frame,
            KeyClock::Seconds { frames_per_second } => frame / frames_per_second,
        };
        let t = channel(k, key_time, |k| k.translation, |a, b, t| a.lerp(b, t)).unwrap_or(Vec3::ZERO);
        let r = channel(k, key_time, |k| k.rotation, |a, b, t| a.slerp(b, t)).unwrap_or(Quat::IDENTITY);
        let s = channel(k, key_time, |k| k.scale, |a, b, t| a.lerp(b, t)).unwrap_or(Vec3::ONE);
        let keyed = Affine3A::from_translation(self.pivot_m + t)
            * Affine3A::from_scale_rotation_translation(s, r, Vec3::ZERO)
            * Affine3A::from_translation(-self.pivot_m);
        let motion = a.motion.map(|m| m.transform(frame, self.pivot_m)).unwrap_or(Affine3A::IDENTITY);
        let local = motion * keyed;
        if self.placement == Mat4::IDENTITY {
            return local;
        }
        let placement = Affine3A::from_mat4(self.placement);
        placement * local * placement.inverse()
    }

    /// The frames that bound this object's poses up to `last_frame`: frame 0,
    /// `last_frame`, every key (translation and scale are linear between keys,
    /// a rotation keeps lengths) and the midpoints between them.
    fn bounding_frames(&self, last_frame: f32) -> Vec<f32> {
        let per_key = match self.animation.clock {
            KeyClock::Frames => 1.0,
            KeyClock::Seconds { frames_per_second } => frames_per_second,
        };
        let mut frames: Vec<f32> = [0.0, last_frame.max(0.0)]
            .into_iter()
            .chain(self.animation.keyframes.iter().map(|k| k.frame * per_key))
            .filter(|f| f.is_finite())
            .collect();
        frames.sort_by(f32::total_cmp);
        let mids: Vec<f32> = frames.windows(2).map(|w| w[0] * 0.5 + w[1] * 0.5).collect();
        frames.extend(mids);
        frames.sort_by(f32::total_cmp);
        frames.dedup();
        frames
    }

    /// The first frame up to `last_frame` (and at any key) at which this
    /// object's geometry, whose rest pose lies in the box `rest_bounds`,
    /// may reach beyond ±`bound_m` on an axis, with that reach; `None` when
    /// every pose stays inside. Conservative: the rest box's bounding sphere
    /// goes through each bounding frame's transform, its radius scaled by the
    /// transform's Frobenius norm; an orbit adds its centre's distance.
    pub fn posed_reach_beyond(&self, rest_bounds: (Vec3, Vec3), last_frame: f32, bound_m: f32) -> Option<(f32, f32)> {
        if !self.is_animated() {
            return None;
        }
        let (centre, radius) = ((rest_bounds.0 + rest_bounds.1) * 0.5, (rest_bounds.1 - rest_bounds.0).length() * 0.5);
        self.bounding_frames(last_frame).into_iter().find_map(|f| {
            let m = self.world_from_rest(f);
            let c = m.transform_point3(centre);
            let linear = m.matrix3;
            let norm =
                (linear.x_axis.length_squared() + linear.y_axis.length_squared() + linear.z_axis.length_squared())
                    .sqrt();
            let mut reach = c.abs().max_element() + radius * norm;
            if let Some(MotionPath::Orbit { centre_m, .. }) = self.animation.motion {
                reach = reach.max(centre_m.abs().max_element() + (c - centre_m).length() + radius * norm);
            }
            let inside = reach <= bound_m; // false for NaN too
            (!inside).then_some((f, reach))
        })
    }

    /// Why this object is unusable, if it is.
    pub fn validate(&self) -> Result<(), String> {
        let a = &self.animation;
        validate_key_frames(&a.keyframes)?;
        for (i, k) in a.keyframes.iter().enumerate() {
            if k.translation.is_some_and(|t| !t.is_finite()) || k.rotation.is_some_and(|r| !r.is_finite()) {
                return Err(format!("keyframe {i}: translation and rotation must be finite"));
            }
            if k.scale.is_some_and(|s| !s.is_finite() || s.min_element() <= 0.0) {
                return Err(format!("keyframe {i}: scale must be finite and positive on every axis"));
            }
        }
        if let Some(m) = &a.motion {
            m.validate()?;
        }
        if let KeyClock::Seconds { frames_per_second } = a.clock
            && !(frames_per_second.is_finite() && frames_per_second > 0.0)
        {
            return Err(format!("frames_per_second must be positive, got {frames_per_second}"));
        }
        if !self.pivot_m.is_finite() || !self.placement.is_finite() {
            return Err("pivot and placement must be finite".into());
        }
        Ok(())
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn object(animation: ObjectAnimation) -> SceneObject {
        SceneObject {
            name: "o".into(),
            first_triangle: 0,
            triangle_count: 0,
            first_vertex: 0,
            vertex_count: 0,
            pivot_m: Vec3::new(1.0, 0.0, 0.0),
            animation,
            placement: Mat4::IDENTITY,
        }
    }

    #[test]
    fn keyframed_translation_interpolates_and_holds() {
        let key = |frame, x| TransformKeyframe {
            frame,
            translation: Some(Vec3::new(x, 0.0, 0.0)),
            rotation: None,
            scale: None,
        };
        let o = object(ObjectAnimation { keyframes: vec![key(10.0, 0.0), key(20.0, 2.0)], ..Default::default() });
        let at = |f: f32| o.world_from_rest(f).transform_point3(Vec3::ZERO).x;
        assert_eq!(at(0.0), 0.0);
        assert!((at(15.0) - 1.0).abs() < 1e-6);
        assert!((at(40.0) - 2.0).abs() < 1e-6);
    }

    #[test]
    fn rotation_turns_about_the_pivot_and_orbit_about_its_centre() {
        let quarter = Quat::from_rotation_y(std::f32::consts::FRAC_PI_2);
        let o = object(ObjectAnimation {
            keyframes: vec![TransformKeyframe { frame: 0.0, translation: None, rotation: Some(quarter), scale: None }],
            ..Default::default()
        });
        // The pivot stays; a point 1 m along +x from it goes to −z.
        assert!(
            (o.world_from_rest(3.0).transform_point3(Vec3::new(1.0, 0.0, 0.0)) - Vec3::new(1.0, 0.0, 0.0)).length()
                < 1e-6
        );
        let p = o.world_from_rest(3.0).transform_point3(Vec3::new(2.0, 0.0, 0.0));
        assert!((p - Vec3::new(1.0, 0.0, -1.0)).length() < 1e-5, "{p}");

        let orbit = object(ObjectAnimation {
            motion: Some(MotionPath::Orbit { centre_m: Vec3::ZERO, axis: Vec3::Y, period_frames: 8.0 }),
            ..Default::default()
        });
        let p = orbit.world_from_rest(2.0).transform_point3(Vec3::new(1.0, 0.0, 0.0));
        assert!((p - Vec3::new(0.0, 0.0, -1.0)).length() < 1e-5, "{p}");
        assert!((orbit.world_from_rest(8.0).transform_point3(Vec3::X) - Vec3::X).length() < 1e-5);
    }

    #[test]
    fn posed_reach_is_bounded_at_keys_motion_ends_and_orbits() {
        let rest = (Vec3::ZERO, Vec3::ONE);
        let key = |frame, t: Option<Vec3>, s: Option<Vec3>| TransformKeyframe {
            frame,
            translation: t,
            rotation: None,
            scale: s,
        };
        let far = object(ObjectAnimation {
            keyframes: vec![key(0.0, Some(Vec3::ZERO), None), key(10.0, Some(Vec3::new(1e30, 0.0, 0.0)), None)],
            ..Default::default()
        });
        assert_eq!(far.posed_reach_beyond(rest, 0.0, 1e15).map(|r| r.0), Some(5.0), "between keys");
        let huge =
            object(ObjectAnimation { keyframes: vec![key(3.0, None, Some(Vec3::splat(1e30)))], ..Default::default() });
        assert!(huge.posed_reach_beyond(rest, 0.0, 1e15).is_some());
        let fast = object(ObjectAnimation {
            motion: Some(MotionPath::Translate { velocity_m_per_frame: Vec3::new(0.0, 1e30, 0.0) }),
            ..Default::default()
        });
        assert_eq!(fast.posed_reach_beyond(rest, 0.0, 1e15), None, "frame 0 is at rest");
        assert_eq!(fast.posed_reach_beyond(rest, 4.0, 1e15).map(|r| r.0), Some(2.0));
        let orbit = object(ObjectAnimation {
            motion: Some(MotionPath::Orbit { centre_m: Vec3::splat(1e30), axis: Vec3::Y, period_frames: 8.0 }),
            ..Default::default()
        });
        assert!(orbit.posed_reach_beyond(rest, 0.0, 1e15).is_some());
        let fine = object(ObjectAnimation {
            keyframes: vec![key(0.0, Some(Vec3::splat(5.0)), Some(Vec3::splat(2.0)))],
            motion: Some(MotionPath::Orbit { centre_m: Vec3::splat(3.0), axis: Vec3::Y, period_frames: 8.0 }),
            ..Default::default()
        });
        assert_eq!(fine.posed_reach_beyond(rest, 1000.0, 1e15), None);
    }

    #[test]
    fn bad_animation_is_rejected() {
        let key =
            TransformKeyframe { frame: 0.0, translation: None, rotation: None, scale: Some(Vec3::new(1.0, -1.0, 1.0)) };
        let o = object(ObjectAnimation { keyframes: vec![key], ..Default::default() });
        assert!(o.validate().expect_err("invalid").contains("scale"));
        let o = object(ObjectAnimation {
            motion: Some(MotionPath::Rotate { axis: Vec3::ZERO, period_frames: 10.0 }),
            ..Default::default()
        });
        assert!(o.validate().expect_err("invalid").contains("axis"));
        let keys = vec![
            TransformKeyframe { frame: 5.0, translation: None, rotation: None, scale: None },
            TransformKeyframe { frame: 2.0, translation: None, rotation: None, scale: None },
        ];
        assert!(
            object(ObjectAnimation { keyframes: keys, ..Default::default() })
                .validate()
                .expect_err("invalid")
                .contains("after the previous")
        );
    }

    #[test]
    fn a_scene_poses_its_own_objects_keys_from_the_rest_pose() {
        use crate::Scene;
        let mut rest = Scene::default();
        rest.mesh.positions = vec![Vec3::ZERO, Vec3::X, Vec3::Y, Vec3::new(5.0, 5.0, 5.0)];
        rest.mesh.normals = vec![Vec3::Z; 4];
        rest.mesh.triangles = vec![[0, 1, 2]];
        let still = SceneObject { first_vertex: 0, vertex_count: 3, triangle_count: 1, ..object(Default::default()) };
        rest.objects = vec![still];
        let mut posed = rest.clone();
        // The engine's key for this frame: a quarter turn about z, then 2 m up.
        let key = TransformKeyframe {
            frame: 0.0,
            translation: Some(Vec3::new(0.0, 0.0, 2.0)),
            rotation: Some(Quat::from_rotation_z(std::f32::consts::FRAC_PI_2)),
            scale: None,
        };
        posed.objects[0].animation = ObjectAnimation { keyframes: vec![key], ..Default::default() };
        posed.objects[0].pivot_m = Vec3::ZERO;
        posed.pose_objects_from(&rest, 7.0);
        let want = [Vec3::new(0.0, 0.0, 2.0), Vec3::new(0.0, 1.0, 2.0), Vec3::new(-1.0, 0.0, 2.0)];
        for (p, w) in posed.mesh.positions.iter().zip(want) {
            assert!(p.abs_diff_eq(w, 1e-6), "{p} against {w}");
        }
        assert_eq!(posed.mesh.positions[3], Vec3::new(5.0, 5.0, 5.0), "a vertex outside the object stays");
        assert!(posed.mesh.normals[0].abs_diff_eq(Vec3::Z, 1e-6));
        // Posed again with the same key, from the rest pose: not compounded.
        posed.pose_objects_from(&rest, 8.0);
        assert!(posed.mesh.positions[1].abs_diff_eq(want[1], 1e-6));
    }
}
