//! Punctual lights with glTF KHR_lights_punctual semantics and units (see
//! `probegi_core::punctual` for the attenuation maths). Field names are the TOML
//! scene-file keys.

use glam::Vec3;
use serde::{Deserialize, Serialize};

#[derive(Clone, Copy, Debug, PartialEq, Eq, Serialize, Deserialize)]
#[serde(rename_all = "snake_case")]
pub enum LightKind {
    Point,
    Spot,
    Directional,
}

#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct PunctualLight {
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
        }
    }

    /// Why this light is unusable, if it is (checked on load).
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
        Ok(())
    }
}
