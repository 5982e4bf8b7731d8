//! The TOML scene file: references mesh files (OBJ, glTF, `builtin:NAME`, or
//! `shared:PATH` for the shared scene folder), adds objects built from boxes and
//! polygons or files (still or animated), punctual lights, sky, camera, the GI
//! volume and SH settings. Field names are those of the structs; unknown keys are
//! errors, so a typo never silently does nothing.
//!
//! ```toml
//! sky_radiance = [0.0, 0.0, 0.0]                  # constant sky, or instead:
//! # [sky_map]                                     # an equirectangular HDR sky (docs/SCENES.md)
//! # path = "sunset.exr"                           # .exr or Radiance .hdr, relative to this file
//! # intensity = 1.0                               # radiance scale
//! # rotation_deg = 0.0                            # about +y; +90° turns the map's centre from +z to +x
//! # keyframes = [{ frame = 0, rotation_deg = 0.0 }, { frame = 120, rotation_deg = 90.0, intensity = 2.0 }]
//! frames_per_second = 30.0                        # animation clock (glTF seconds)
//!
//! [[meshes]]
//! path = "../shared/scenes/sibenik/sibenik.obj"   # relative to this file
//! translation = [0.0, 0.0, 0.0]                   # metres
//! rotation_deg = [0.0, 90.0, 0.0]                 # Euler X, Y, Z, degrees
//! scale = [1.0, 1.0, 1.0]
//! normals = "file"                                # file (default) | flat | smooth
//! crease_angle_deg = 180.0                        # "smooth": faces further apart keep their edge
//!
//! [[instances]]                 # copies of one file, placed by a list or a grid of transforms
//! path = "shared:scenes/scrub-pine/scrubPine.obj"
//! scale = [0.01, 0.01, 0.01]    # translation / rotation_deg / scale: each copy's own placement first
//! transforms = [{ translation = [0.0, 0.0, 0.0], rotation_deg = [0.0, 30.0, 0.0] }]
//! # or: grid = { count = [10, 10], spacing_m = [4.0, 4.0], origin_m = [-18.0, 0.0, -18.0],
//! #              jitter_m = 1.0, random_yaw = true, scale_range = [0.8, 1.2], seed = 1 }
//!
//! [[objects]]                   # one rigid object: a box, a polygon or a file
//! name = "occluder"
//! box_min_m = [1.0, 0.0, 1.0]   # faces outward; `box_inward = true` for a room
//! box_max_m = [2.0, 1.0, 2.0]
//! albedo = [0.8, 0.8, 0.8]      # diffuse; `emission` makes it an area light
//! keyframes = [{ frame = 0, translation = [0.0, 0.0, 0.0] }, { frame = 60, translation = [3.0, 0.0, 0.0], rotation_deg = [0.0, 90.0, 0.0] }]
//! motion = { kind = "orbit", centre_m = [0.0, 0.0, 0.0], axis = [0.0, 1.0, 0.0], period_frames = 120 }
//! # or: polygon_m = [[x, y, z], ...] (one planar polygon, counter-clockwise = front)
//! # or: path = "part.obj" with translation / rotation_deg / scale as for meshes
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
//! up = [0.0, 1.0, 0.0]          # optional, default +Y
//! fov_y_deg = 60.0
//! # Optional animation: keys in strictly increasing frame order (frames ≥ 0).
//! # A key may omit any field but `frame`: it holds the previous key's value (the
//! # first key's come from the table above, which may then leave them out).
//! # Between keys position, target, up and fov_y_deg interpolate linearly; the
//! # camera holds before the first key and after the last.
//! keyframes = [
//!     { frame = 0, position = [-10.0, 2.0, 0.0] },
//!     { frame = 60, position = [0.0, 2.0, -10.0], fov_y_deg = 45.0 },
//!     { frame = 90.5, target = [0.0, 1.0, 0.0], up = [0.0, 1.0, 0.1] },
//! ]
//!
//! [volume]                      # DDGI: DdgiVolumeSettings field names
//! probe_counts = [16, 8, 16]
//!
//! # Or several volumes (seed 004 §7.4), each with every [volume] key: placed by
//! # origin and spacing, or fitted to volume_bounds_m; a tracking window follows
//! # the camera. A file with [[volumes]] may not also have [volume].
//! [[volumes]]
//! probe_counts = [8, 4, 8]
//! volume_bounds_m = [[-20.0, 0.0, -10.0], [20.0, 15.0, 10.0]]
//! [[volumes]]
//! probe_counts = [8, 8, 8]
//! probe_spacing_m = [0.5, 0.5, 0.5]
//! volume_tracks_camera = true
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
use toml::Spanned;

use crate::animation::{KeyClock, MotionPath, ObjectAnimation, SceneObject, TransformKeyframe};
use crate::error::{Result, SceneError};
use crate::light::PunctualLight;
use crate::scene::{CameraKeyframe, Scene};

/// `[sky_map]`: an equirectangular HDR image lighting the scene
/// ([`crate::environment_map`]).
#[derive(Debug, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct SkyMapEntry {
    /// `.exr` or Radiance `.hdr`, relative to the scene file (or `shared:PATH`).
    pub path: String,
    /// Radiance scale of every texel.
    #[serde(default = "unit_intensity")]
    pub intensity: f32,
    /// Rotation about the up axis, degrees (+90°: the map's centre turns from +z to +x).
    #[serde(default)]
    pub rotation_deg: f32,
    /// Keys of `intensity` and `rotation_deg` over frames (a moving sun).
    #[serde(default)]
    pub keyframes: Vec<crate::environment_map::SkyMapKeyframe>,
}

fn unit_intensity() -> f32 {
    1.0
}

/// A whole scene file, as parsed (the module doc shows every table).
#[derive(Debug, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct SceneFile {
    /// Files merged into the scene, each placed once.
    #[serde(default)]
    pub meshes: Vec<MeshRef>,
    /// Copies of one file each.
    #[serde(default)]
    pub instances: Vec<InstanceEntry>,
    /// Punctual lights, in world space.
    #[serde(default)]
    pub lights: Vec<PunctualLight>,
    /// Constant radiance of rays that leave the scene; black when absent.
    #[serde(default)]
    pub sky_radiance: Option<Vec3>,
    /// `[sky_map]`: an environment map instead (not with `sky_radiance`).
    #[serde(default)]
    pub sky_map: Option<SkyMapEntry>,
    /// `[camera]`, with its span for error lines.
    #[serde(default)]
    pub camera: Option<Spanned<CameraEntry>>,
    /// The DDGI volume (`probegi_core::ddgi_settings::DdgiVolumeSettings` field names).
    #[serde(default)]
    pub volume: Option<DdgiVolumeSettings>,
    /// Several DDGI volumes, blended by density (the same field names each).
    #[serde(default)]
    pub volumes: Vec<DdgiVolumeSettings>,
    /// The SH probes of `--gi sh` (`probegi_core::sh_settings::ShProbeSettings` field names).
    #[serde(default)]
    pub sh: Option<ShProbeSettings>,
    /// Rigid objects, still or animated, each a box, a polygon or a file.
    #[serde(default)]
    pub objects: Vec<ObjectEntry>,
    /// The animation clock for animations authored in seconds (glTF).
    #[serde(default)]
    pub frames_per_second: Option<f32>,
}

/// The `[camera]` table: a [`Camera`]'s fields, optionally animated by
/// `keyframes`. Without keyframes, position, target and fov_y_deg are required;
/// with them, these are only the first key's fallbacks.
#[derive(Debug, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct CameraEntry {
    /// Eye position, metres.
    #[serde(default)]
    pub position: Option<Vec3>,
    /// The point looked at, metres.
    #[serde(default)]
    pub target: Option<Vec3>,
    /// Default +Y.
    #[serde(default)]
    pub up: Option<Vec3>,
    /// Vertical field of view, degrees.
    #[serde(default)]
    pub fov_y_deg: Option<f32>,
    /// The camera's animation, keys in strictly increasing frame order.
    #[serde(default)]
    pub keyframes: Vec<Spanned<CameraKeyEntry>>,
}

/// A key of `[camera].keyframes`; an omitted field holds the previous key's
/// value (the first key's: the table's).
#[derive(Debug, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct CameraKeyEntry {
    /// Frame number, ≥ 0 (fractional frames allowed).
    pub frame: f32,
    /// Eye position from this key on, metres.
    #[serde(default)]
    pub position: Option<Vec3>,
    /// The point looked at from this key on, metres.
    #[serde(default)]
    pub target: Option<Vec3>,
    /// Up direction from this key on.
    #[serde(default)]
    pub up: Option<Vec3>,
    /// Vertical field of view from this key on, degrees.
    #[serde(default)]
    pub fov_y_deg: Option<f32>,
}

/// Why a `[camera]` table cannot be used: the byte offset it concerns and the message.
type CameraError = (usize, String);

impl CameraEntry {
    /// The camera (the first key's, when animated) and the resolved keys; the
    /// table starts at byte `at` of the file.
    fn resolve(&self, at: usize) -> std::result::Result<(Camera, Vec<CameraKeyframe>), CameraError> {
        let up = self.up.unwrap_or(Vec3::Y);
        if self.keyframes.is_empty() {
            let missing = |field: &str| (at, format!("camera: missing field `{field}`"));
            let camera = Camera {
                position: self.position.ok_or_else(|| missing("position"))?,
                target: self.target.ok_or_else(|| missing("target"))?,
                up,
                fov_y_deg: self.fov_y_deg.ok_or_else(|| missing("fov_y_deg"))?,
            };
            camera.validate().map_err(|e| (at, format!("camera: {e}")))?;
            return Ok((camera, Vec::new()));
        }
        let (mut position, mut target, mut up, mut fov_y_deg) = (self.position, self.target, up, self.fov_y_deg);
        let mut keys = Vec::with_capacity(self.keyframes.len());
        for (i, key) in self.keyframes.iter().enumerate() {
            let k = key.get_ref();
            position = k.position.or(position);
            target = k.target.or(target);
            up = k.up.unwrap_or(up);
            fov_y_deg = k.fov_y_deg.or(fov_y_deg);
            let missing = |field: &str| {
                let why =
                    format!("camera.keyframes[{i}]: no `{field}`: give it in this key, an earlier one or [camera]");
                (key.span().start, why)
            };
            let camera = Camera {
                position: position.ok_or_else(|| missing("position"))?,
                target: target.ok_or_else(|| missing("target"))?,
                up,
                fov_y_deg: fov_y_deg.ok_or_else(|| missing("fov_y_deg"))?,
            };
            keys.push(CameraKeyframe { frame: k.frame, camera });
        }
        if let Some((i, why)) = crate::scene::camera_keyframe_error(&keys) {
            return Err((self.keyframes[i].span().start, format!("camera.keyframes[{i}]: {why}")));
        }
        Ok((keys[0].camera, keys))
    }
}

/// The 1-based line of byte `offset` in `text`.
fn line_of(text: &str, offset: usize) -> usize {
    text.as_bytes()[..offset.min(text.len())].iter().filter(|&&b| b == b'\n').count() + 1
}

/// One `[[objects]]` entry: exactly one of a box, a polygon or a file.
#[derive(Debug, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct ObjectEntry {
    /// For messages; default `object`.
    #[serde(default)]
    pub name: Option<String>,
    /// A box's lowest corner, metres (with `box_max_m`).
    #[serde(default)]
    pub box_min_m: Option<Vec3>,
    /// A box's highest corner, metres (with `box_min_m`).
    #[serde(default)]
    pub box_max_m: Option<Vec3>,
    /// The box's faces point inward (a closed room seen from inside).
    #[serde(default)]
    pub box_inward: bool,
    /// One planar polygon's corners, metres, counter-clockwise seen from the front.
    #[serde(default)]
    pub polygon_m: Option<Vec<Vec3>>,
    /// A mesh file (as in `[[meshes]]`), placed by translation / rotation_deg / scale.
    #[serde(default)]
    pub path: Option<String>,
    /// A file's placement: translation, metres.
    #[serde(default)]
    pub translation: Vec3,
    /// A file's placement: intrinsic Euler angles X, Y, Z in degrees.
    #[serde(default)]
    pub rotation_deg: Vec3,
    /// A file's placement: scale per axis.
    #[serde(default = "one")]
    pub scale: Vec3,
    /// Diffuse albedo of a box or polygon (default 0.8 grey).
    #[serde(default)]
    pub albedo: Option<Vec3>,
    /// Emitted radiance of a box or polygon, W·sr⁻¹·m⁻² (front faces).
    #[serde(default)]
    pub emission: Option<Vec3>,
    /// Rotation and scale centre; default the centre of the object's bounds.
    #[serde(default)]
    pub pivot_m: Option<Vec3>,
    /// Keyed offsets from the authored pose, in increasing frame order.
    #[serde(default)]
    pub keyframes: Vec<ObjectKeyframe>,
    /// A closed-form motion path on top of the keys.
    #[serde(default)]
    pub motion: Option<MotionPath>,
}

/// A key of `[[objects]].keyframes`: offsets from the authored pose.
#[derive(Debug, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct ObjectKeyframe {
    /// Frame number (fractional frames allowed); keys in increasing order.
    pub frame: f32,
    /// Offset from the authored position, metres.
    #[serde(default)]
    pub translation: Option<Vec3>,
    /// Intrinsic Euler angles X, Y, Z in degrees, about the pivot.
    #[serde(default)]
    pub rotation_deg: Option<Vec3>,
    /// Scale about the pivot, per axis.
    #[serde(default)]
    pub scale: Option<Vec3>,
}

/// One `[[meshes]]` entry: a file merged into the scene, placed by scale,
/// rotation, then translation.
#[derive(Debug, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct MeshRef {
    /// OBJ, glTF/GLB, or `builtin:NAME`; relative paths are relative to the TOML file.
    pub path: String,
    /// Translation, metres.
    #[serde(default)]
    pub translation: Vec3,
    /// Intrinsic Euler angles X, Y, Z in degrees.
    #[serde(default)]
    pub rotation_deg: Vec3,
    /// Scale per axis.
    #[serde(default = "one")]
    pub scale: Vec3,
    /// Shading normals: as the file says, or overridden.
    #[serde(default)]
    pub normals: NormalsRule,
    /// For `normals = "smooth"`: faces turned further apart than this keep a
    /// hard edge; 180 smooths across every face sharing a position.
    #[serde(default = "no_crease")]
    pub crease_angle_deg: f32,
}

fn one() -> Vec3 {
    Vec3::ONE
}

fn no_crease() -> f32 {
    180.0
}

/// A mesh entry's shading normals.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq, Deserialize)]
#[serde(rename_all = "lowercase")]
pub enum NormalsRule {
    /// The format's rule (OBJ: `vn`, smoothing groups, else flat; glTF: `NORMAL`, else flat).
    #[default]
    File,
    /// Face normals everywhere.
    Flat,
    /// Angle-weighted normals across shared positions, within the crease angle.
    Smooth,
}

impl NormalsRule {
    fn apply(self, scene: &mut Scene, crease_angle_deg: f32) -> std::result::Result<(), String> {
        if !(crease_angle_deg.is_finite() && crease_angle_deg >= 0.0) {
            return Err(format!("crease_angle_deg must be a non-negative angle, got {crease_angle_deg}"));
        }
        match self {
            NormalsRule::File => {}
            NormalsRule::Flat => scene.derive_normals(crate::mesh::NormalSource::Flat, 180.0),
            NormalsRule::Smooth => scene.derive_normals(crate::mesh::NormalSource::Smooth(1), crease_angle_deg),
        }
        Ok(())
    }
}

/// `[[instances]]`: one file, copied. Each copy is placed by the entry's own
/// translation / rotation_deg / scale, then by its transform from `transforms`
/// or `grid`.
#[derive(Debug, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct InstanceEntry {
    /// The file copied, named as in `[[meshes]]`; it may not be animated or have instances itself.
    pub path: String,
    /// Every copy's own placement first: translation, metres.
    #[serde(default)]
    pub translation: Vec3,
    /// Every copy's own placement first: intrinsic Euler angles X, Y, Z in degrees.
    #[serde(default)]
    pub rotation_deg: Vec3,
    /// Every copy's own placement first: scale per axis.
    #[serde(default = "one")]
    pub scale: Vec3,
    /// Shading normals, as for `[[meshes]]`.
    #[serde(default)]
    pub normals: NormalsRule,
    /// For `normals = "smooth"`, as for `[[meshes]]`.
    #[serde(default = "no_crease")]
    pub crease_angle_deg: f32,
    /// One copy per transform.
    #[serde(default)]
    pub transforms: Vec<InstanceTransform>,
    /// Copies on a jittered grid, after those of `transforms`.
    pub grid: Option<InstanceGrid>,
}

/// One entry of `[[instances]].transforms`: a copy's placement, applied after the
/// entry's own.
#[derive(Debug, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct InstanceTransform {
    /// Translation, metres.
    #[serde(default)]
    pub translation: Vec3,
    /// Intrinsic Euler angles X, Y, Z in degrees.
    #[serde(default)]
    pub rotation_deg: Vec3,
    /// Scale per axis.
    #[serde(default = "one")]
    pub scale: Vec3,
}

/// Copies on a jittered grid in the XZ plane.
#[derive(Debug, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct InstanceGrid {
    /// Copies along X and Z.
    pub count: [u32; 2],
    /// Distance between neighbours along X and Z, metres.
    pub spacing_m: [f32; 2],
    /// Where copy (0, 0) stands before jitter.
    #[serde(default)]
    pub origin_m: Vec3,
    /// Each copy moves by up to this much along X and Z (uniform).
    #[serde(default)]
    pub jitter_m: f32,
    /// A uniform random turn about +Y per copy.
    #[serde(default)]
    pub random_yaw: bool,
    /// Uniform scale per copy, drawn from this range.
    #[serde(default = "unit_range")]
    pub scale_range: [f32; 2],
    /// Seed of the jitter, yaw and scale draws; the same seed gives the same copies.
    #[serde(default = "seed_one")]
    pub seed: u64,
}

fn unit_range() -> [f32; 2] {
    [1.0, 1.0]
}

fn seed_one() -> u64 {
    1
}

/// The most copies one scene file may make.
pub const MAX_INSTANCES: usize = 1 << 20;

impl InstanceEntry {
    /// World-from-file transform of every copy.
    fn placements(&self) -> std::result::Result<Vec<Mat4>, String> {
        let own = placement_matrix(self.translation, self.rotation_deg, self.scale);
        let mut out: Vec<Mat4> =
            self.transforms.iter().map(|t| placement_matrix(t.translation, t.rotation_deg, t.scale) * own).collect();
        if let Some(g) = &self.grid {
            let n = g.count[0] as usize * g.count[1] as usize;
            if n + out.len() > MAX_INSTANCES {
                return Err(format!("grid of {} × {} copies is more than {MAX_INSTANCES}", g.count[0], g.count[1]));
            }
            let finite = g.spacing_m.iter().chain(&g.scale_range).all(|v| v.is_finite()) && g.jitter_m.is_finite();
            if !finite || g.scale_range[0] <= 0.0 || g.scale_range[1] < g.scale_range[0] || g.jitter_m < 0.0 {
                return Err("grid needs finite spacing, jitter_m ≥ 0 and 0 < scale_range[0] ≤ scale_range[1]".into());
            }
            let mut rng = probegi_core::rng::Pcg32::new(g.seed, 0x1257);
            for j in 0..g.count[1] {
                for i in 0..g.count[0] {
                    let (jx, jz) = (rng.next_f32() * 2.0 - 1.0, rng.next_f32() * 2.0 - 1.0);
                    let yaw = if g.random_yaw { rng.next_f32() * std::f32::consts::TAU } else { 0.0 };
                    let k = g.scale_range[0] + (g.scale_range[1] - g.scale_range[0]) * rng.next_f32();
                    let at = g.origin_m
                        + Vec3::new(
                            i as f32 * g.spacing_m[0] + jx * g.jitter_m,
                            0.0,
                            j as f32 * g.spacing_m[1] + jz * g.jitter_m,
                        );
                    out.push(
                        Mat4::from_scale_rotation_translation(Vec3::splat(k), Quat::from_rotation_y(yaw), at) * own,
                    );
                }
            }
        }
        if out.is_empty() {
            return Err("give `transforms` or `grid`".into());
        }
        if out.len() > MAX_INSTANCES {
            return Err(format!("{} copies is more than {MAX_INSTANCES}", out.len()));
        }
        out.into_iter().map(placement).collect()
    }
}

impl MeshRef {
    /// The entry's placement: scale, then rotation, then translation.
    pub fn world_from_local(&self) -> Mat4 {
        placement_matrix(self.translation, self.rotation_deg, self.scale)
    }
}

/// Scene files may name other scene files in `[[meshes]]`; this many deep at most.
pub const MAX_SCENE_FILE_DEPTH: usize = 16;

thread_local! {
    /// The scene files being loaded on this thread, outermost first (cycle detection).
    static INCLUDE_STACK: std::cell::RefCell<Vec<PathBuf>> = const { std::cell::RefCell::new(Vec::new()) };
}

/// Pops the include stack however the load ends.
struct IncludeGuard;

impl Drop for IncludeGuard {
    fn drop(&mut self) {
        INCLUDE_STACK.with(|s| s.borrow_mut().pop());
    }
}

/// Loads a TOML scene file and everything it names; a file that names itself,
/// directly or not, or nests deeper than [`MAX_SCENE_FILE_DEPTH`] is an error.
pub fn load_scene_file(path: &Path) -> Result<Scene> {
    let text =
        std::fs::read_to_string(path).map_err(|source| SceneError::Io { path: path.to_path_buf(), cause: source })?;
    let key = std::fs::canonicalize(path).unwrap_or_else(|_| path.to_path_buf());
    let chain = INCLUDE_STACK.with(|s| {
        let s = s.borrow();
        (s.contains(&key) || s.len() >= MAX_SCENE_FILE_DEPTH).then(|| {
            s.iter().chain(std::iter::once(&key)).map(|p| p.display().to_string()).collect::<Vec<_>>().join(" → ")
        })
    });
    if let Some(chain) = chain {
        return Err(SceneError::Invalid {
            path: path.to_path_buf(),
            message: format!(
                "scene files include each other in a cycle or more than {MAX_SCENE_FILE_DEPTH} deep: {chain}"
            ),
        });
    }
    INCLUDE_STACK.with(|s| s.borrow_mut().push(key));
    let _guard = IncludeGuard;
    let base_dir = path.parent().unwrap_or(Path::new(".")).to_path_buf();
    parse_scene_file(&text, path, &base_dir)
}

/// Parses scene-file text; `name` is what errors call it, `base_dir` what relative
/// paths are relative to.
///
/// A placed file's punctual lights and camera move with its geometry (a glTF's
/// KHR_lights_punctual lights and camera are part of what it places).
pub fn parse_scene_file(text: &str, name: &Path, base_dir: &Path) -> Result<Scene> {
    let path = name;
    let toml_err = |message: String| SceneError::Toml { path: path.to_path_buf(), message };
    let file: SceneFile = toml::from_str(text).map_err(|e| toml_err(e.to_string()))?;
    let mut scene = Scene { name: path.display().to_string(), ..Default::default() };
    if file.meshes.is_empty() && file.objects.is_empty() && file.instances.is_empty() {
        return Err(toml_err("no [[meshes]], [[instances]] or [[objects]] entries".into()));
    }
    place_meshes(&mut scene, &file.meshes, path, base_dir)?;
    place_instances(&mut scene, &file.instances, path, base_dir)?;
    for (i, o) in file.objects.iter().enumerate() {
        let sub = object_scene(o, base_dir).map_err(|e| match e {
            ObjectError::Message(m) => toml_err(format!("objects[{i}]: {m}")),
            ObjectError::Scene(e) => e,
        })?;
        merge_into(&mut scene, sub);
    }
    if let Some(fps) = file.frames_per_second {
        scene.set_frames_per_second(fps);
    }
    scene.lights.extend(file.lights);
    if let Some(sky) = file.sky_radiance {
        scene.sky_radiance = sky;
    }
    if let Some(entry) = &file.sky_map {
        if file.sky_radiance.is_some() {
            return Err(toml_err("give sky_radiance or [sky_map], not both".into()));
        }
        let map_path = resolve_file(&entry.path, base_dir)?;
        let map = crate::environment_map::EnvironmentMap::load(&map_path)?;
        let sky = crate::environment_map::SkyMap {
            map: std::sync::Arc::new(map),
            intensity: entry.intensity,
            rotation_deg: entry.rotation_deg,
            keyframes: entry.keyframes.clone(),
        };
        sky.validate().map_err(|e| toml_err(format!("[sky_map]: {e}")))?;
        scene.sky_map = Some(sky);
    }
    if let Some(entry) = &file.camera {
        let (camera, keys) = entry.get_ref().resolve(entry.span().start).map_err(|(at, message)| {
            SceneError::Parse { path: path.to_path_buf(), line: line_of(text, at), message }
        })?;
        scene.camera = Some(camera);
        scene.camera_keyframes = keys;
    }
    if file.volume.is_some() && !file.volumes.is_empty() {
        return Err(toml_err("both [volume] and [[volumes]]: use [[volumes]] entries only".into()));
    }
    if let Some(v) = file.volume {
        v.validate().map_err(|(field, why)| toml_err(format!("volume.{field}: {why}")))?;
        scene.volume = Some(v);
    }
    if file.volumes.len() > 64 {
        return Err(toml_err(format!("{} [[volumes]]: at most 64", file.volumes.len())));
    }
    for (i, v) in file.volumes.iter().enumerate() {
        v.validate().map_err(|(field, why)| toml_err(format!("volumes[{i}].{field}: {why}")))?;
    }
    if !file.volumes.is_empty() {
        scene.volumes = file.volumes;
    }
    if let Some(v) = file.sh {
        v.validate().map_err(|(field, why)| toml_err(format!("sh.{field}: {why}")))?;
        scene.sh_probes = Some(v);
    }
    scene.validate().map_err(toml_err)?;
    Ok(scene)
}

/// Merges each `[[meshes]]` entry's file into `scene`, placed by its transform.
fn place_meshes(scene: &mut Scene, meshes: &[MeshRef], path: &Path, base_dir: &Path) -> Result<()> {
    let toml_err = |message: String| SceneError::Toml { path: path.to_path_buf(), message };
    for (i, m) in meshes.iter().enumerate() {
        let xf = placement(m.world_from_local()).map_err(|e| toml_err(format!("meshes[{i}]: {e}")))?;
        let mut sub = load_sub_scene(&m.path, base_dir)?;
        m.normals.apply(&mut sub, m.crease_angle_deg).map_err(|e| toml_err(format!("meshes[{i}]: {e}")))?;
        sub.mesh.transform(xf);
        place_lights_and_camera(&mut sub, xf);
        for inst in &mut sub.instances {
            *inst = crate::scene::MeshInstance::new(inst.prototype, xf * Mat4::from(inst.world_from_local))
                .map_err(|e| toml_err(format!("meshes[{i}]: {e}")))?;
        }
        for o in &mut sub.objects {
            o.placement = xf * o.placement;
        }
        scene.warnings.append(&mut sub.warnings);
        merge_into(scene, sub);
    }
    Ok(())
}

/// Adds each `[[instances]]` entry's file to `scene` as one prototype drawn at
/// each of its placements.
fn place_instances(scene: &mut Scene, instances: &[InstanceEntry], path: &Path, base_dir: &Path) -> Result<()> {
    let toml_err = |message: String| SceneError::Toml { path: path.to_path_buf(), message };
    for (i, entry) in instances.iter().enumerate() {
        let err = |e: String| toml_err(format!("instances[{i}]: {e}"));
        let placements = entry.placements().map_err(err)?;
        let mut sub = load_sub_scene(&entry.path, base_dir)?;
        if sub.has_moving_geometry() {
            return Err(err(format!("{} is animated; instances are still copies", entry.path)));
        }
        if !sub.lights.is_empty() {
            sub.warnings.push(format!("instances[{i}]: the lights of {} are not copied", entry.path));
            sub.lights.clear();
        }
        if !sub.instances.is_empty() {
            return Err(err(format!(
                "{} has [[instances]] itself; instances of instances are not supported",
                entry.path
            )));
        }
        entry.normals.apply(&mut sub, entry.crease_angle_deg).map_err(err)?;
        sub.objects.clear();
        let mut mesh = std::mem::take(&mut sub.mesh);
        let material_offset = scene.materials.len() as u32;
        mesh.triangle_materials.iter_mut().for_each(|m| *m += material_offset);
        scene.warnings.append(&mut sub.warnings);
        merge_into(scene, sub);
        // One prototype, drawn once per placement: the tracer shares its BVH.
        scene.add_instanced_mesh(&entry.path, mesh, &placements).map_err(err)?;
    }
    Ok(())
}

/// Intrinsic Euler angles X, Y, Z in degrees, as scene files write rotations.
fn quat_from_euler_deg(r: Vec3) -> Quat {
    Quat::from_euler(EulerRot::XYZ, r.x.to_radians(), r.y.to_radians(), r.z.to_radians())
}

/// Scale, then rotation (Euler degrees), then translation.
fn placement_matrix(translation: Vec3, rotation_deg: Vec3, scale: Vec3) -> Mat4 {
    Mat4::from_scale_rotation_translation(scale, quat_from_euler_deg(rotation_deg), translation)
}

fn placement(xf: Mat4) -> std::result::Result<Mat4, String> {
    if !xf.is_finite() || xf.determinant().abs() < 1e-12 {
        return Err("transform is degenerate or not finite".into());
    }
    Ok(xf)
}

/// Loads a file named in a scene file: `builtin:NAME`, `shared:PATH` (the shared
/// scene folder, see [`crate::file_lookup::shared_dir`]) or a path relative to `base_dir`.
fn load_sub_scene(spec: &str, base_dir: &Path) -> Result<Scene> {
    if spec.starts_with("builtin:") {
        return crate::load::load_scene(spec);
    }
    crate::load::load_scene(&resolve_file(spec, base_dir)?.to_string_lossy())
}

/// A file named in a scene file: `shared:PATH` or a path relative to `base_dir`.
fn resolve_file(spec: &str, base_dir: &Path) -> Result<PathBuf> {
    Ok(match spec.strip_prefix("shared:") {
        Some(rel) => crate::file_lookup::shared_dir()
            .map(|d| d.join(rel))
            .map_err(|message| SceneError::Invalid { path: PathBuf::from(spec), message })?,
        None => base_dir.join(spec),
    })
}

enum ObjectError {
    Message(String),
    Scene(SceneError),
}

impl From<String> for ObjectError {
    fn from(m: String) -> Self {
        ObjectError::Message(m)
    }
}

/// The scene holding one `[[objects]]` entry as a single object.
fn object_scene(o: &ObjectEntry, base_dir: &Path) -> std::result::Result<Scene, ObjectError> {
    let name = o.name.clone().unwrap_or_else(|| "object".into());
    let shapes = [o.box_min_m.is_some() || o.box_max_m.is_some(), o.polygon_m.is_some(), o.path.is_some()];
    if shapes.iter().filter(|&&b| b).count() != 1 {
        return Err("give exactly one of box_min_m + box_max_m, polygon_m or path".to_string().into());
    }
    if o.box_inward && !shapes[0] {
        return Err("box_inward applies to a box (box_min_m + box_max_m)".to_string().into());
    }
    let mut sub =
        if let Some(spec) = &o.path { file_object_scene(o, spec, base_dir)? } else { shape_object_scene(o, &name)? };
    let animation = ObjectAnimation {
        keyframes: o
            .keyframes
            .iter()
            .map(|k| TransformKeyframe {
                frame: k.frame,
                translation: k.translation,
                rotation: k.rotation_deg.map(quat_from_euler_deg),
                scale: k.scale,
            })
            .collect(),
        clock: KeyClock::Frames,
        motion: o.motion,
    };
    let bounds = sub.mesh.bounds().ok_or_else(|| "the object has no geometry".to_string())?;
    let object = SceneObject {
        name,
        first_triangle: 0,
        triangle_count: sub.mesh.triangle_count() as u32,
        first_vertex: 0,
        vertex_count: sub.mesh.positions.len() as u32,
        pivot_m: o.pivot_m.unwrap_or((bounds.0 + bounds.1) * 0.5),
        animation,
        placement: Mat4::IDENTITY,
    };
    object.validate()?;
    sub.objects = vec![object];
    Ok(sub)
}

/// The geometry of an `[[objects]]` entry that names a file: the file, placed.
fn file_object_scene(o: &ObjectEntry, spec: &str, base_dir: &Path) -> std::result::Result<Scene, ObjectError> {
    if o.albedo.is_some() || o.emission.is_some() {
        return Err("albedo and emission apply to boxes and polygons; a file brings its materials".to_string().into());
    }
    let mut sub = load_sub_scene(spec, base_dir).map_err(ObjectError::Scene)?;
    if !sub.instances.is_empty() {
        return Err(format!("{spec} has [[instances]]; place it with [[meshes]] instead").into());
    }
    if sub.has_moving_geometry() {
        return Err(format!("{spec} is animated itself; place it with [[meshes]] instead").into());
    }
    let xf = placement(placement_matrix(o.translation, o.rotation_deg, o.scale))?;
    sub.mesh.transform(xf);
    place_lights_and_camera(&mut sub, xf);
    sub.objects.clear();
    Ok(sub)
}

/// The geometry of an `[[objects]]` entry that gives a box or a polygon in
/// place, with its one material.
fn shape_object_scene(o: &ObjectEntry, name: &str) -> std::result::Result<Scene, ObjectError> {
    let albedo = o.albedo.unwrap_or(Vec3::splat(0.8));
    let material = match o.emission {
        Some(e) => crate::material::Material::emissive(name, albedo, e),
        None => crate::material::Material::diffuse(name, albedo),
    };
    let mut mesh = crate::mesh::Mesh::default();
    if let Some(poly) = &o.polygon_m {
        if poly.len() < 3 || poly.iter().any(|p| !p.is_finite()) {
            return Err("polygon_m needs at least 3 finite corners".to_string().into());
        }
        crate::shapes::add_polygon(&mut mesh, poly, 0);
    } else {
        let (Some(lo), Some(hi)) = (o.box_min_m, o.box_max_m) else {
            return Err("a box needs both box_min_m and box_max_m".to_string().into());
        };
        if !(lo.is_finite() && hi.is_finite() && lo.cmplt(hi).all()) {
            return Err(format!("box_min_m {lo} must be below box_max_m {hi} on every axis").into());
        }
        if o.box_inward {
            crate::shapes::add_room(&mut mesh, lo, hi, 0);
        } else {
            crate::shapes::add_box(&mut mesh, lo, hi, 0);
        }
    }
    if o.translation != Vec3::ZERO || o.rotation_deg != Vec3::ZERO || o.scale != Vec3::ONE {
        return Err("translation / rotation_deg / scale place files; give a box or polygon in place"
            .to_string()
            .into());
    }
    Ok(Scene { materials: vec![material], mesh, ..Default::default() })
}

/// Appends `sub`'s geometry, materials, textures and lights; keeps the first
/// camera (with its animation).
fn merge_into(scene: &mut Scene, sub: Scene) {
    let mat_offset = scene.materials.len() as u32;
    let tex_offset = scene.textures.len();
    let (tri_offset, vertex_offset) = (scene.mesh.triangle_count() as u32, scene.mesh.positions.len() as u32);
    scene.objects.extend(sub.objects.into_iter().map(|mut o| {
        o.first_triangle += tri_offset;
        o.first_vertex += vertex_offset;
        o
    }));
    scene.mesh.append(&sub.mesh, mat_offset);
    let prototype_offset = scene.prototypes.len() as u32;
    scene.prototypes.extend(sub.prototypes.into_iter().map(|mut p| {
        p.mesh.triangle_materials.iter_mut().for_each(|m| *m += mat_offset);
        p
    }));
    scene.instances.extend(sub.instances.into_iter().map(|mut i| {
        i.prototype += prototype_offset;
        i
    }));
    scene.materials.extend(sub.materials.into_iter().map(|mut m| {
        m.offset_textures(tex_offset);
        m
    }));
    scene.textures.extend(sub.textures);
    scene.lights.extend(sub.lights);
    scene.sky_radiance = scene.sky_radiance.max(sub.sky_radiance);
    if scene.sky_map.is_none() {
        scene.sky_map = sub.sky_map;
    }
    if scene.camera.is_none() {
        scene.camera = sub.camera;
        scene.camera_keyframes = sub.camera_keyframes;
    }
    if scene.volume.is_none() && scene.volumes.is_empty() {
        scene.volume = sub.volume;
        scene.volumes = sub.volumes;
    }
    if scene.sh_probes.is_none() {
        scene.sh_probes = sub.sh_probes;
    }
}

/// `--set` keys that change the scene itself, for every renderer (the
/// reference included): `normal_maps=false` drops normal and bump maps,
/// `alpha_cutouts=false` makes every material opaque.
pub const SCENE_SETTING_KEYS: [&str; 2] = ["normal_maps", "alpha_cutouts"];

/// Whether `KEY=VALUE` names a scene setting ([`SCENE_SETTING_KEYS`]).
pub fn is_scene_setting(assignment: &str) -> bool {
    let key = assignment.split_once('=').map_or(assignment, |(k, _)| k).trim();
    SCENE_SETTING_KEYS.contains(&key)
}

/// Applies a scene setting `KEY=true|false` to `scene`.
pub fn apply_scene_setting(scene: &mut Scene, assignment: &str) -> std::result::Result<(), String> {
    let (key, value) = assignment.split_once('=').ok_or_else(|| format!("`{assignment}` is not KEY=VALUE"))?;
    let on = match value.trim() {
        "true" => true,
        "false" => false,
        v => return Err(format!("{key} takes true or false, not `{v}`")),
    };
    match key.trim() {
        "normal_maps" if !on => {
            scene.materials.iter_mut().for_each(|m| (m.normal_texture, m.bump_texture) = (None, None))
        }
        "alpha_cutouts" if !on => {
            scene.materials.iter_mut().for_each(|m| m.alpha_mode = crate::material::AlphaMode::Opaque)
        }
        "normal_maps" | "alpha_cutouts" => {}
        k => return Err(format!("`{k}` is not a scene setting (those are {})", SCENE_SETTING_KEYS.join(", "))),
    }
    Ok(())
}

/// Every key `--set` and a `[volume]` table accept.
pub fn volume_setting_keys() -> Vec<String> {
    let all = DdgiVolumeSettings {
        probe_origin_m: Some(Vec3::ZERO),
        probe_spacing_m: Some(Vec3::ONE),
        volume_tracking_bounds_m: Some([Vec3::ZERO, Vec3::ONE]),
        ..Default::default()
    };
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
    let mut parsed: toml::Value = match toml::from_str::<toml::Table>(&format!("v = {value}")) {
        Ok(mut t) => t.remove("v").unwrap_or(toml::Value::String(value.to_string())),
        Err(_) => toml::Value::String(value.to_string()),
    };
    // A scalar for a per-axis metre setting means the same on every axis
    // (`probe_spacing_m=0.5`); `X,Y,Z` without brackets is accepted too.
    if matches!(canonical.as_str(), "probe_spacing_m" | "probe_origin_m") {
        if matches!(parsed, toml::Value::Float(_) | toml::Value::Integer(_)) {
            parsed = toml::Value::Array(vec![parsed.clone(), parsed.clone(), parsed]);
        } else if matches!(parsed, toml::Value::String(_))
            && let Ok(mut t) = toml::from_str::<toml::Table>(&format!("v = [{value}]"))
            && let Some(v @ toml::Value::Array(_)) = t.remove("v")
            && value.contains(',')
        {
            parsed = v;
        }
    }
    let mut table = toml::Table::try_from(settings).map_err(|e| e.to_string())?;
    table.insert(canonical.clone(), parsed);
    table.try_into().map_err(|e: toml::de::Error| format!("{canonical} = {value}: {}", e.message()))
}

/// Moves a placed file's punctual lights (positions, directions, and their
/// keyframes') and its camera (and camera keyframes) by `xf`, as its geometry
/// moves; directions stay unit length.
fn place_lights_and_camera(sub: &mut Scene, xf: Mat4) {
    let point = |p: Vec3| xf.transform_point3(p);
    let dir = |d: Vec3| xf.transform_vector3(d).try_normalize().unwrap_or(d);
    for l in &mut sub.lights {
        l.position = point(l.position);
        l.direction = dir(l.direction);
        for k in &mut l.keyframes {
            k.position = k.position.map(point);
            k.direction = k.direction.map(dir);
        }
    }
    let place = |c: &mut Camera| {
        (c.position, c.target, c.up) = (point(c.position), point(c.target), dir(c.up));
    };
    if let Some(c) = sub.camera.as_mut() {
        place(c);
    }
    sub.camera_keyframes.iter_mut().for_each(|k| place(&mut k.camera));
}
