//! The TOML scene file: references mesh files (OBJ, glTF, or `builtin:NAME`),
//! adds punctual lights, sky and camera. Later issues add the GI volume and
//! animation tables. Field names are those of the structs; unknown keys are
//! errors, so a typo never silently does nothing.
//!
//! ```toml
//! sky_radiance = [0.0, 0.0, 0.0]
//!
//! [[meshes]]
//! path = "../shared/scenes/sibenik/sibenik.obj"   # relative to this file
//! translation = [0.0, 0.0, 0.0]                   # metres
//! rotation_deg = [0.0, 90.0, 0.0]                 # Euler X, Y, Z, degrees
//! scale = [1.0, 1.0, 1.0]
//!
//! [[lights]]
//! kind = "spot"                 # point | spot | directional
//! position = [0.0, 10.0, 0.0]
//! direction = [0.0, -1.0, 0.0]
//! color = [1.0, 0.9, 0.8]
//! intensity = 200.0             # W/sr (point, spot) or W/m² (directional)
//! outer_cone_angle = 0.6
//! keyframes = [{ frame = 0, position = [0.0, 10.0, 0.0] }, { frame = 30, intensity = 0.0 }]
//!
//! [camera]
//! position = [-10.0, 2.0, 0.0]
//! target = [0.0, 2.0, 0.0]
//! fov_y_deg = 60.0
//!
//! [volume]                      # DDGI: DdgiVolumeSettings field names
//! probe_counts = [16, 8, 16]
//!
//! [sh]                          # --gi sh: ShProbeSettings field names
//! sh_occlusion = true
//! ```

use std::path::{Path, PathBuf};

use glam::{EulerRot, Mat4, Quat, Vec3};
use probegi_core::camera::Camera;
use probegi_core::ddgi_settings::DdgiVolumeSettings;
use probegi_core::sh_settings::ShProbeSettings;
use serde::Deserialize;

use crate::error::{Result, SceneError};
use crate::light::PunctualLight;
use crate::scene::Scene;

#[derive(Debug, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct SceneFile {
    #[serde(default)]
    pub meshes: Vec<MeshRef>,
    #[serde(default)]
    pub lights: Vec<PunctualLight>,
    #[serde(default)]
    pub sky_radiance: Option<Vec3>,
    #[serde(default)]
    pub camera: Option<Camera>,
    /// The DDGI volume (`probegi_core::ddgi_settings::DdgiVolumeSettings` field names).
    #[serde(default)]
    pub volume: Option<DdgiVolumeSettings>,
    /// The SH probes of `--gi sh` (`probegi_core::sh_settings::ShProbeSettings` field names).
    #[serde(default)]
    pub sh: Option<ShProbeSettings>,
}

#[derive(Debug, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct MeshRef {
    /// OBJ, glTF/GLB, or `builtin:NAME`; relative paths are relative to the TOML file.
    pub path: String,
    #[serde(default)]
    pub translation: Vec3,
    /// Intrinsic Euler angles X, Y, Z in degrees.
    #[serde(default)]
    pub rotation_deg: Vec3,
    #[serde(default = "one")]
    pub scale: Vec3,
}

fn one() -> Vec3 {
    Vec3::ONE
}

impl MeshRef {
    pub fn world_from_local(&self) -> Mat4 {
        let r = self.rotation_deg;
        Mat4::from_scale_rotation_translation(
            self.scale,
            Quat::from_euler(EulerRot::XYZ, r.x.to_radians(), r.y.to_radians(), r.z.to_radians()),
            self.translation,
        )
    }
}

pub fn load_scene_file(path: &Path) -> Result<Scene> {
    let text = std::fs::read_to_string(path).map_err(|source| SceneError::Io { path: path.to_path_buf(), source })?;
    let file: SceneFile =
        toml::from_str(&text).map_err(|e| SceneError::Toml { path: path.to_path_buf(), message: e.to_string() })?;
    let base_dir = path.parent().unwrap_or(Path::new(".")).to_path_buf();
    let mut scene = Scene { name: path.display().to_string(), ..Default::default() };
    if file.meshes.is_empty() {
        return Err(SceneError::Toml { path: path.to_path_buf(), message: "no [[meshes]] entries".into() });
    }
    for (i, m) in file.meshes.iter().enumerate() {
        let xf = m.world_from_local();
        if !xf.is_finite() || xf.determinant().abs() < 1e-12 {
            return Err(SceneError::Toml {
                path: path.to_path_buf(),
                message: format!("meshes[{i}]: transform is degenerate or not finite"),
            });
        }
        let sub_path: PathBuf =
            if m.path.starts_with("builtin:") { PathBuf::from(&m.path) } else { base_dir.join(&m.path) };
        let mut sub = crate::load::load_scene(&sub_path.to_string_lossy())?;
        sub.mesh.transform(xf);
        scene.warnings.append(&mut sub.warnings);
        merge_into(&mut scene, sub);
    }
    scene.lights.extend(file.lights);
    if let Some(sky) = file.sky_radiance {
        scene.sky_radiance = sky;
    }
    if file.camera.is_some() {
        scene.camera = file.camera;
    }
    if let Some(v) = file.volume {
        v.validate().map_err(|(field, why)| SceneError::Toml {
            path: path.to_path_buf(),
            message: format!("volume.{field}: {why}"),
        })?;
        scene.volume = Some(v);
    }
    if let Some(v) = file.sh {
        v.validate().map_err(|(field, why)| SceneError::Toml {
            path: path.to_path_buf(),
            message: format!("sh.{field}: {why}"),
        })?;
        scene.sh_probes = Some(v);
    }
    scene.validate().map_err(|message| SceneError::Toml { path: path.to_path_buf(), message })?;
    Ok(scene)
}

/// Appends `sub`'s geometry, materials, textures and lights; keeps the first camera.
fn merge_into(scene: &mut Scene, sub: Scene) {
    let mat_offset = scene.materials.len() as u32;
    let tex_offset = scene.textures.len();
    scene.mesh.append(&sub.mesh, mat_offset);
    scene.materials.extend(sub.materials.into_iter().map(|mut m| {
        m.base_color_texture = m.base_color_texture.map(|t| t + tex_offset);
        m.emissive_texture = m.emissive_texture.map(|t| t + tex_offset);
        m
    }));
    scene.textures.extend(sub.textures);
    scene.lights.extend(sub.lights);
    scene.sky_radiance = scene.sky_radiance.max(sub.sky_radiance);
    if scene.camera.is_none() {
        scene.camera = sub.camera;
    }
    if scene.volume.is_none() {
        scene.volume = sub.volume;
    }
    if scene.sh_probes.is_none() {
        scene.sh_probes = sub.sh_probes;
    }
}

/// Every key `--set` and a `[volume]` table accept.
pub fn volume_setting_keys() -> Vec<String> {
    let all =
        DdgiVolumeSettings { probe_origin_m: Some(Vec3::ZERO), probe_spacing_m: Some(Vec3::ONE), ..Default::default() };
    setting_keys(&all)
}

/// Every key `--set` (under `--gi sh`) and an `[sh]` table accept.
pub fn sh_setting_keys() -> Vec<String> {
    setting_keys(&ShProbeSettings { sh_cascade_spacing_m: Some(1.0), ..Default::default() })
}

fn setting_keys<T: serde::Serialize>(all: &T) -> Vec<String> {
    match toml::Table::try_from(all) {
        Ok(t) => t.keys().cloned().collect(),
        Err(_) => Vec::new(),
    }
}

/// Applies `--set KEY=VALUE` to volume settings. `KEY` is a `[volume]` field name,
/// with or without its `probe_` prefix (`hysteresis` = `probe_hysteresis`);
/// `VALUE` is a TOML value (`0.9`, `true`, `[4, 4, 4]`) or a bare word for enums
/// (`normal`). Errors name the key and list the valid ones.
pub fn apply_volume_override(
    settings: &DdgiVolumeSettings,
    assignment: &str,
) -> std::result::Result<DdgiVolumeSettings, String> {
    let updated: DdgiVolumeSettings = apply_override(settings, assignment, "probe_", &volume_setting_keys())?;
    updated.validate().map_err(|(field, why)| format!("{field}: {why}"))?;
    Ok(updated)
}

/// Applies `--set KEY=VALUE` to SH probe settings; `KEY` is an `[sh]` field name,
/// with or without its `sh_` prefix.
pub fn apply_sh_override(settings: &ShProbeSettings, assignment: &str) -> std::result::Result<ShProbeSettings, String> {
    let updated: ShProbeSettings = apply_override(settings, assignment, "sh_", &sh_setting_keys())?;
    updated.validate().map_err(|(field, why)| format!("{field}: {why}"))?;
    Ok(updated)
}

fn apply_override<T: serde::Serialize + serde::de::DeserializeOwned>(
    settings: &T,
    assignment: &str,
    prefix: &str,
    keys: &[String],
) -> std::result::Result<T, String> {
    let (key, value) = assignment
        .split_once('=')
        .map(|(k, v)| (k.trim(), v.trim()))
        .ok_or_else(|| format!("`{assignment}` is not KEY=VALUE"))?;
    let canonical = if keys.iter().any(|k| k == key) {
        key.to_string()
    } else if keys.iter().any(|k| *k == format!("{prefix}{key}")) {
        format!("{prefix}{key}")
    } else {
        return Err(format!("unknown setting `{key}`; valid keys: {}", keys.join(", ")));
    };
    let parsed: toml::Value = match toml::from_str::<toml::Table>(&format!("v = {value}")) {
        Ok(mut t) => t.remove("v").unwrap_or(toml::Value::String(value.to_string())),
        Err(_) => toml::Value::String(value.to_string()),
    };
    let mut table = toml::Table::try_from(settings).map_err(|e| e.to_string())?;
    table.insert(canonical.clone(), parsed);
    table.try_into().map_err(|e: toml::de::Error| format!("{canonical} = {value}: {}", e.message()))
}
