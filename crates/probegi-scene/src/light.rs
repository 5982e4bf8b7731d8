//! Punctual lights with glTF KHR_lights_punctual semantics and units (see
//! `probegi_core::punctual` for the attenuation maths). Field names are the TOML
//! scene-file keys.

use glam::Vec3;
use serde::{Deserialize, Serialize};

use crate::animation::channel;

/// The kind of a punctual light (glTF KHR_lights_punctual `type`).
#[derive(Clone, Copy, Debug, PartialEq, Eq, Serialize, Deserialize)]
#[serde(rename_all = "snake_case")]
pub enum LightKind {
    /// Emits in every direction from `position`.
    Point,
    /// Emits from `position` along `direction`, within the cone angles.
    Spot,
    /// Parallel light along `direction` from infinitely far away (a sun).
    Directional,
}

/// A point, spot or directional light, a `[[lights]]` entry of a scene file.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct PunctualLight {
    /// Point, spot or directional.
    pub kind: LightKind,
    /// World position, metres (point and spot).
    #[serde(default)]
    pub position: Vec3,
    /// Direction the light travels, world space (spot and directional). glTF's
    /// default is the node's −Z axis.
    #[serde(default = "default_direction")]
    pub direction: Vec3,
    /// Linear RGB colour.
    #[serde(default = "default_color")]
    pub color: Vec3,
    /// Point/spot: radiant intensity (glTF candela) in W·sr⁻¹. Directional:
    /// irradiance at normal incidence (glTF lux) in W·m⁻².
    pub intensity: f32,
    /// Optional cutoff distance with the glTF window function; absent = infinite.
    #[serde(default)]
    pub range: Option<f32>,
    /// Spot inner cone angle, radians (glTF default 0).
    #[serde(default)]
    pub inner_cone_angle: f32,
    /// Spot outer cone angle, radians (glTF default π/4).
    #[serde(default = "default_outer_cone")]
    pub outer_cone_angle: f32,
    /// Animation over frame numbers (dynamic-scenes issue): each key sets any of
    /// position, direction and intensity; each channel interpolates linearly
    /// between the keys that set it and holds before the first and after the last.
    /// Intensity 0 switches the light off.
    #[serde(default, skip_serializing_if = "Vec::is_empty")]
    pub keyframes: Vec<LightKeyframe>,
}

/// One key of a light's animation.
#[derive(Clone, Copy, Debug, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct LightKeyframe {
    /// Frame number (fractional frames allowed); keys must be in increasing order.
    pub frame: f32,
    /// World position from this key on, metres.
    #[serde(default)]
    pub position: Option<Vec3>,
    /// Direction the light travels from this key on.
    #[serde(default)]
    pub direction: Option<Vec3>,
    /// Intensity from this key on (0: off), in the units of `PunctualLight::intensity`.
    #[serde(default)]
    pub intensity: Option<f32>,
}

impl crate::animation::Keyed for LightKeyframe {
    fn frame(&self) -> f32 {
        self.frame
    }
}

fn default_direction() -> Vec3 {
    Vec3::NEG_Z
}
fn default_color() -> Vec3 {
    Vec3::ONE
}
fn default_outer_cone() -> f32 {
    std::f32::consts::FRAC_PI_4
}

impl PunctualLight {
    /// This light at `frame` with its keyframes applied (itself if it has none).
    pub fn at_frame(&self, frame: f32) -> PunctualLight {
        let mut l = self.clone();
        let k = &self.keyframes;
        if let Some(p) = channel(k, frame, |k| k.position, |a, b, t| a.lerp(b, t)) {
            l.position = p;
        }
        if let Some(d) = channel(k, frame, |k| k.direction, |a, b, t| a.lerp(b, t).normalize_or(b)) {
            l.direction = d;
        }
        if let Some(i) = channel(k, frame, |k| k.intensity, |a, b, t| a + (b - a) * t) {
            l.intensity = i;
        }
        l
    }

    /// A still point light at `position` with colour `color` and radiant intensity `intensity` (W·sr⁻¹).
    pub fn point(position: Vec3, color: Vec3, intensity: f32) -> Self {
        Self {
            kind: LightKind::Point,
            position,
            direction: default_direction(),
            color,
            intensity,
            range: None,
            inner_cone_angle: 0.0,
            outer_cone_angle: default_outer_cone(),
            keyframes: Vec::new(),
        }
    }

    /// Why this light is unusable, if it is (checked on load).
    ///
    /// Intensities above [`MAX_LIGHT_INTENSITY`] are refused.
    pub fn validate(&self) -> Result<(), String> {
        if !(self.position.is_finite() && self.direction.is_finite() && self.color.is_finite()) {
            return Err("light position, direction and color must be finite".into());
        }
        if !(self.intensity.is_finite() && self.intensity >= 0.0) {
            return Err(format!("light intensity {} must be finite and >= 0", self.intensity));
        }
        if self.color.min_element() < 0.0 {
            return Err("light color must be non-negative".into());
        }
        // Beyond this, intensity × colour ÷ a small squared distance overflows f32.
        let peak = self.intensity * self.color.max_element();
        if peak > MAX_LIGHT_INTENSITY
            || self
                .keyframes
                .iter()
                .any(|k| k.intensity.is_some_and(|i| i * self.color.max_element() > MAX_LIGHT_INTENSITY))
        {
            return Err(format!(
                "light intensity × colour {peak:e} is absurd (above {MAX_LIGHT_INTENSITY:e} W/sr or W/m²)"
            ));
        }
        if self.kind != LightKind::Point && self.direction.length_squared() < 1e-12 {
            return Err("light direction must be non-zero".into());
        }
        if let Some(r) = self.range
            && !(r.is_finite() && r > 0.0)
        {
            return Err(format!("light range {r} must be finite and > 0"));
        }
        if self.kind == LightKind::Spot
            && !(0.0 <= self.inner_cone_angle
                && self.inner_cone_angle < self.outer_cone_angle
                && self.outer_cone_angle <= std::f32::consts::FRAC_PI_2)
        {
            return Err(format!(
                "spot cone angles must satisfy 0 <= inner ({}) < outer ({}) <= π/2",
                self.inner_cone_angle, self.outer_cone_angle
            ));
        }
        crate::animation::validate_key_frames(&self.keyframes)?;
        for (i, k) in self.keyframes.iter().enumerate() {
            if k.position.is_some_and(|p| !p.is_finite()) || k.direction.is_some_and(|d| !d.is_finite()) {
                return Err(format!("keyframe {i}: position and direction must be finite"));
            }
            if k.direction.is_some_and(|d| d.length_squared() < 1e-12) {
                return Err(format!("keyframe {i}: direction must be non-zero"));
            }
            if k.intensity.is_some_and(|v| !(v.is_finite() && v >= 0.0)) {
                return Err(format!("keyframe {i}: intensity must be finite and >= 0"));
            }
        }
        Ok(())
    }
}

/// The largest intensity × colour a punctual light may have (W/sr, or W/m² for
/// directional lights); above it, intensity over a small squared distance and
/// the products along a path approach the f32 range.
pub const MAX_LIGHT_INTENSITY: f32 = 1e20;

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn keyframes_interpolate_per_channel_and_hold_at_the_ends() {
        let mut l = PunctualLight::point(Vec3::ZERO, Vec3::ONE, 10.0);
        l.keyframes = vec![
            LightKeyframe { frame: 0.0, position: Some(Vec3::ZERO), direction: None, intensity: None },
            LightKeyframe {
                frame: 10.0,
                position: Some(Vec3::new(2.0, 0.0, 0.0)),
                direction: None,
                intensity: Some(10.0),
            },
            LightKeyframe { frame: 20.0, position: None, direction: None, intensity: Some(0.0) },
        ];
        assert!(l.validate().is_ok());
        assert_eq!(l.at_frame(5.0).position, Vec3::new(1.0, 0.0, 0.0));
        assert_eq!(l.at_frame(-3.0).position, Vec3::ZERO);
        assert_eq!(l.at_frame(30.0).position, Vec3::new(2.0, 0.0, 0.0));
        assert_eq!(l.at_frame(5.0).intensity, 10.0, "held before its first key");
        assert_eq!(l.at_frame(15.0).intensity, 5.0);
        assert_eq!(l.at_frame(25.0).intensity, 0.0, "switched off");
        l.keyframes[2].frame = 5.0;
        assert!(l.validate().is_err_and(|e| e.contains("keyframe 2")));
    }
}
