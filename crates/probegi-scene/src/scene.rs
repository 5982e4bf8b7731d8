//! The scene model: one merged triangle mesh, its materials and textures, punctual
//! lights, a constant sky or an environment map, and an optional camera. Emissive triangles are the area
//! lights. Scenes are y-up, in metres. Rigid [`SceneObject`]s are ranges of the
//! mesh that move over frames; [`Scene::set_frame_from`] poses them (and the
//! lights) for a frame, and a tracer built with `BvhTracer::for_scene` follows
//! them through its per-frame top-level structure.
//!
//! Instancing: a [`MeshPrototype`] is a mesh in its own local space, drawn by
//! any number of [`MeshInstance`]s (still copies placed by a transform). The
//! tracer keeps one BVH per prototype under its top-level structure, so a
//! forest of thousands of pines stores one pine. `Scene::mesh` holds the
//! world geometry only; hits on an instance carry its index and are moved to
//! world space by [`Scene::surface_point`]. Prototypes may not emit (area
//! lights are sampled from `Scene::mesh`) and placements may not mirror.

use glam::{Vec2, Vec3};
use probegi_core::camera::Camera;

use crate::animation::SceneObject;
use crate::light::PunctualLight;
use crate::material::{Material, VertexAttributes};
use crate::mesh::Mesh;
use crate::ray::RayHit;
use crate::texture::Texture;

/// A loaded scene: the world geometry and its materials, lights, sky, camera,
/// instances and the GI settings its file asked for (see the module doc).
#[derive(Clone, Debug)]
pub struct Scene {
    /// For messages: the path or built-in name it was loaded from.
    pub name: String,
    /// The world geometry, every loader's meshes merged (instances apart).
    pub mesh: Mesh,
    /// Indexed by the meshes' per-triangle material ids.
    pub materials: Vec<Material>,
    /// Indexed by the materials' texture references.
    pub textures: Vec<Texture>,
    /// Point, spot and directional lights (area lights are the emissive triangles).
    pub lights: Vec<PunctualLight>,
    /// Named mesh ranges, animated or not; ranges do not overlap.
    pub objects: Vec<SceneObject>,
    /// Meshes drawn by `instances`, each in its own local space.
    pub prototypes: Vec<MeshPrototype>,
    /// Still copies of prototypes.
    pub instances: Vec<MeshInstance>,
    /// Frames per second of the animation clock, for animations authored in
    /// seconds (glTF); frame `f` is at `f / frames_per_second` seconds.
    pub frames_per_second: f32,
    /// Constant radiance of rays that leave the scene, W·sr⁻¹·m⁻² per channel
    /// (unused where `sky_map` is set).
    pub sky_radiance: Vec3,
    /// An environment map in place of the constant sky (see
    /// [`crate::environment_map`]); [`Scene::sky_toward`] reads whichever is set.
    pub sky_map: Option<crate::environment_map::SkyMap>,
    /// The camera the file asked for, if any; when the camera is animated, the
    /// first key's camera.
    pub camera: Option<Camera>,
    /// The camera's animation over frames, in strictly increasing frame order;
    /// empty when the camera does not move. See [`Scene::camera_at`].
    pub camera_keyframes: Vec<CameraKeyframe>,
    /// The DDGI volume the file asked for, if any.
    pub volume: Option<probegi_core::ddgi_settings::DdgiVolumeSettings>,
    /// The DDGI volumes of a file's `[[volumes]]` (empty: one volume, `volume`).
    pub volumes: Vec<probegi_core::ddgi_settings::DdgiVolumeSettings>,
    /// SH probe settings from a scene file's `[sh]` table.
    pub sh_probes: Option<probegi_core::sh_settings::ShProbeSettings>,
    /// Things the loader recovered from (missing .mtl or texture, unknown material).
    pub warnings: Vec<String>,
}

/// One key of the camera's animation, fully resolved (a scene file's omitted
/// fields are already filled in from earlier keys).
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct CameraKeyframe {
    /// Frame number (fractional frames allowed), finite and ≥ 0.
    pub frame: f32,
    /// The camera at that frame.
    pub camera: Camera,
}

/// The first unusable key of a camera animation, by index, and why: frames must
/// be finite, non-negative and strictly increasing, and every key's camera must
/// pass [`Camera::validate`].
pub(crate) fn camera_keyframe_error(keys: &[CameraKeyframe]) -> Option<(usize, String)> {
    keys.iter().enumerate().find_map(|(i, k)| {
        if !(k.frame.is_finite() && k.frame >= 0.0) {
            return Some((i, format!("frame {} must be a finite number ≥ 0", k.frame)));
        }
        if i > 0 && k.frame <= keys[i - 1].frame {
            return Some((i, format!("frame {} must be after the previous key's ({})", k.frame, keys[i - 1].frame)));
        }
        if let Some(e) = k.camera.validate().err() {
            return Some((i, e));
        }
        (i > 0).then(|| eye_meets_target(&keys[i - 1], k)).flatten().map(|frame| {
            (
                i,
                format!(
                    "between this key and the previous one the camera's position reaches its target (frame {frame})"
                ),
            )
        })
    })
}

/// The frame between two keys at which the linearly interpolated eye reaches
/// the interpolated target, if it does: `target − position` is linear in the
/// blend, so its shortest length is found in closed form.
fn eye_meets_target(a: &CameraKeyframe, b: &CameraKeyframe) -> Option<f32> {
    // In f64: keys far apart would overflow the squared lengths in f32.
    let view = |c: &Camera| c.target.as_dvec3() - c.position.as_dvec3();
    let (da, db) = (view(&a.camera), view(&b.camera));
    let slope = db - da;
    let s2 = slope.length_squared();
    let t = if s2 > 0.0 { (-da.dot(slope) / s2).clamp(0.0, 1.0) } else { 0.0 };
    let closest = (da + slope * t).length_squared();
    (closest < 1e-12 || closest.is_nan()).then_some(a.frame + (b.frame - a.frame) * t as f32)
}

/// Most frames [`Scene::camera_at`] steps through to carry a path's image up
/// (beyond this many, it steps by more than one frame).
const MAX_CAMERA_WALK_STEPS: f32 = 1e6;

/// A mesh drawn by instances, in its local space; its triangles' material ids
/// index `Scene::materials`.
#[derive(Clone, Debug, Default)]
pub struct MeshPrototype {
    /// For messages: the file it came from.
    pub name: String,
    /// The geometry, in the prototype's local space.
    pub mesh: Mesh,
}

/// One still copy of a prototype.
#[derive(Clone, Copy, Debug)]
pub struct MeshInstance {
    /// Index into `Scene::prototypes`.
    pub prototype: u32,
    /// Places the prototype's local space in the world.
    pub world_from_local: glam::Affine3A,
    /// Inverse transpose of the linear part, for normals.
    pub normal_from_local: glam::Mat3A,
}

impl MeshInstance {
    /// A copy of `prototype` placed by `world_from_local`, which must be finite
    /// and must not mirror or collapse.
    pub fn new(prototype: u32, world_from_local: glam::Mat4) -> Result<Self, String> {
        let det = world_from_local.determinant();
        if !world_from_local.is_finite() || det.is_nan() || det <= 1e-18 {
            return Err(format!(
                "an instance transform must be finite and keep handedness (determinant {det}); mirrored instances are not supported"
            ));
        }
        let world_from_local = glam::Affine3A::from_mat4(world_from_local);
        Ok(Self { prototype, world_from_local, normal_from_local: world_from_local.matrix3.inverse().transpose() })
    }
}

/// The corners of a hit triangle in world space.
struct Corners {
    p: [Vec3; 3],
    n: [Vec3; 3],
    /// Both texture coordinate sets and the vertex colour of each corner.
    attributes: [VertexAttributes; 3],
    /// Tangent (xyz, world) and bitangent sign (w); zero when none.
    t: [glam::Vec4; 3],
}

impl Corners {
    fn of(mesh: &Mesh, tri: usize) -> Self {
        let v = mesh.triangles[tri].map(|i| i as usize);
        Self {
            p: v.map(|i| mesh.positions[i]),
            n: v.map(|i| mesh.normals[i]),
            attributes: v.map(|i| mesh.vertex_attributes(i)),
            t: v.map(|i| mesh.tangents.get(i).copied().unwrap_or(glam::Vec4::ZERO)),
        }
    }

    fn placed(mut self, inst: &MeshInstance) -> Self {
        self.p = self.p.map(|p| inst.world_from_local.transform_point3(p));
        self.n = self.n.map(|n| Vec3::from(inst.normal_from_local * glam::Vec3A::from(n)));
        self.t = self.t.map(|t| {
            let v = inst.world_from_local.transform_vector3(t.truncate()).normalize_or_zero();
            v.extend(t.w)
        });
        self
    }
}

/// Everything a shader needs about a ray-surface intersection.
#[derive(Clone, Copy, Debug)]
pub struct SurfacePoint {
    /// The hit point, world space.
    pub position: Vec3,
    /// Unit counter-clockwise (front-face) geometric normal.
    pub geometric_normal: Vec3,
    /// Unit shading normal, interpolated and flipped into the geometric normal's hemisphere.
    pub shading_normal: Vec3,
    /// Texture coordinate set 0.
    pub uv: Vec2,
    /// Texture coordinate set 1 (set 0 where the mesh has no second set).
    pub uv1: Vec2,
    /// Linear vertex colour (white where the mesh has none).
    pub vertex_color: Vec3,
    /// Index into `Scene::materials`.
    pub material: u32,
    /// Index of the triangle in `Scene::mesh`, or in its prototype's mesh when
    /// `instance` is set.
    pub triangle: u32,
    /// Index into `Scene::instances`, or `u32::MAX` for the scene's own mesh.
    pub instance: u32,
    /// The ray arrived on the front (counter-clockwise) side.
    pub front_face: bool,
}

impl SurfacePoint {
    /// What its material reads here: both coordinate sets and the vertex colour.
    pub fn attributes(&self) -> VertexAttributes {
        VertexAttributes { uv: [self.uv, self.uv1], color: self.vertex_color }
    }

    /// The shading normal turned toward the side the ray came from: the frame two-sided
    /// Lambertian shading uses.
    pub fn facing_normal(&self) -> Vec3 {
        if self.front_face { self.shading_normal } else { -self.shading_normal }
    }

    /// The geometric normal turned toward the side the ray came from.
    pub fn facing_geometric_normal(&self) -> Vec3 {
        if self.front_face { self.geometric_normal } else { -self.geometric_normal }
    }

    /// A point nudged off the surface toward `dir`, for spawning rays without
    /// self-intersection. The offset scales with the magnitude of the position
    /// (floating-point error grows with it).
    pub fn spawn_origin(&self, dir: Vec3) -> Vec3 {
        let n = if dir.dot(self.geometric_normal) >= 0.0 { self.geometric_normal } else { -self.geometric_normal };
        let eps = 1e-4 * (1.0 + self.position.abs().max_element());
        self.position + n * eps
    }
}

impl Default for Scene {
    fn default() -> Self {
        Self {
            name: String::new(),
            mesh: Mesh::default(),
            materials: Vec::new(),
            textures: Vec::new(),
            lights: Vec::new(),
            objects: Vec::new(),
            prototypes: Vec::new(),
            instances: Vec::new(),
            frames_per_second: 30.0,
            sky_radiance: Vec3::ZERO,
            sky_map: None,
            camera: None,
            camera_keyframes: Vec::new(),
            volume: None,
            volumes: Vec::new(),
            sh_probes: None,
            warnings: Vec::new(),
        }
    }
}

/// ∂p/∂u and ∂p/∂v of a triangle's linear UV mapping (pbrt's
/// `Triangle::Intersect`); `None` when its UVs are degenerate.
fn uv_derivatives(p: [Vec3; 3], uv: [Vec2; 3]) -> Option<(Vec3, Vec3)> {
    let (duv02, duv12) = (uv[0] - uv[2], uv[1] - uv[2]);
    let (dp02, dp12) = (p[0] - p[2], p[1] - p[2]);
    let det = duv02.x * duv12.y - duv02.y * duv12.x;
    if det.abs() < 1e-12 {
        return None;
    }
    let inv = 1.0 / det;
    let dpdu = (dp02 * duv12.y - dp12 * duv02.y) * inv;
    let dpdv = (dp12 * duv02.x - dp02 * duv12.x) * inv;
    (dpdu.is_finite() && dpdv.is_finite()).then_some((dpdu, dpdv))
}

/// The unit counter-clockwise normal of the triangle `p` (zero when degenerate).
fn plane_normal(p: [Vec3; 3]) -> Vec3 {
    (p[1] - p[0]).cross(p[2] - p[0]).normalize_or_zero()
}

/// Instanced vertices up to which [`Scene::bounds`] transforms every one.
pub const MAX_TIGHT_BOUND_VERTICES: usize = 50_000_000;

/// The largest diffuse colour factor a material may have (above 1 loads with a
/// warning: energy gain).
pub const MAX_ALBEDO: f32 = 1e3;

/// The largest emitted radiance a material may have, W·sr⁻¹·m⁻² per channel.
pub const MAX_EMISSION: f32 = 1e15;

/// The largest vertex coordinate a scene may have, metres.
pub const MAX_COORDINATE_M: f32 = 1e15;

impl Scene {
    /// The unit geometric normal at a hit, world space, turned toward the side
    /// the ray came from: [`SurfacePoint::facing_geometric_normal`] of
    /// [`Self::surface_point`], from the triangle's corners alone (no
    /// attributes, no normal map). Zero for a degenerate triangle.
    pub fn facing_geometric_normal(&self, hit: &RayHit) -> Vec3 {
        let tri = hit.triangle as usize;
        let p = match self.instances.get(hit.instance as usize) {
            Some(inst) => {
                let mesh = &self.prototypes[inst.prototype as usize].mesh;
                mesh.vertices(tri).map(|p| inst.world_from_local.transform_point3(p))
            }
            None => self.mesh.vertices(tri),
        };
        let n = plane_normal(p);
        if hit.backface { -n } else { n }
    }

    /// Reconstructs the surface at a hit reported by a tracer, in world space.
    pub fn surface_point(&self, hit: &RayHit) -> SurfacePoint {
        let tri = hit.triangle as usize;
        let (mesh, corners) = match self.instances.get(hit.instance as usize) {
            Some(inst) => {
                let mesh = &self.prototypes[inst.prototype as usize].mesh;
                (mesh, Corners::of(mesh, tri).placed(inst))
            }
            None => (&self.mesh, Corners::of(&self.mesh, tri)),
        };
        let b = hit.barycentric;
        let bary = Vec3::new(1.0 - b.x - b.y, b.x, b.y);
        let mix3 = |v: [Vec3; 3]| v[0] * bary.x + v[1] * bary.y + v[2] * bary.z;
        let p = corners.p;
        let position = mix3(p);
        let geometric_normal = plane_normal(p);
        let mut shading_normal = mix3(corners.n).normalize_or_zero();
        if shading_normal == Vec3::ZERO {
            shading_normal = geometric_normal;
        } else if shading_normal.dot(geometric_normal) < 0.0 {
            shading_normal = -shading_normal;
        }
        let attributes = crate::mesh::interpolate_attributes(corners.attributes, bary);
        let uv = attributes.uv[0];
        let material_id = mesh.triangle_materials[tri];
        let material = &self.materials[material_id as usize];
        if material.perturbs_normals() {
            let perturbed = self.perturbed_normal(material, &corners, bary, shading_normal, &attributes);
            // A perturbed normal below the surface would shade light from inside it.
            if perturbed.dot(geometric_normal) > 1e-3 {
                shading_normal = perturbed;
            }
        }
        SurfacePoint {
            position,
            geometric_normal,
            shading_normal,
            uv,
            uv1: attributes.uv[1],
            vertex_color: attributes.color,
            material: material_id,
            triangle: hit.triangle,
            instance: hit.instance,
            front_face: !hit.backface,
        }
    }

    /// The shading normal `n` at `at` perturbed by the material's normal map
    /// (tangent space: the interpolated tangent, made orthogonal to `n`, and
    /// bitangent = sign · n × tangent, glTF's convention) or height map (see
    /// [`crate::material::BUMP_WHITE_HEIGHT_REL`]: the map's slopes in texel
    /// space tilt `n` against the directions of ∂p/∂u and ∂p/∂v, which come
    /// from the triangle's UV mapping as in pbrt). Returns `n` where the frame
    /// is degenerate. Both maps read the coordinates of `material.normal_uv`.
    fn perturbed_normal(
        &self,
        material: &Material,
        corners: &Corners,
        bary: Vec3,
        n: Vec3,
        at: &VertexAttributes,
    ) -> Vec3 {
        let uv = material.normal_uv.apply(at);
        if let Some(t) = material.normal_texture.and_then(|t| self.textures.get(t)) {
            let tangents = corners.t;
            let tan =
                tangents[0].truncate() * bary.x + tangents[1].truncate() * bary.y + tangents[2].truncate() * bary.z;
            let tan = (tan - n * n.dot(tan)).normalize_or_zero();
            let sign = if tangents[0].w < 0.0 { -1.0 } else { 1.0 };
            if tan == Vec3::ZERO {
                return n;
            }
            let bitangent = n.cross(tan) * sign;
            let s = t.sample_raw(uv) * 2.0 - Vec3::ONE;
            let local = Vec3::new(s.x * material.normal_scale, s.y * material.normal_scale, s.z);
            return (tan * local.x + bitangent * local.y + n * local.z).normalize_or(n);
        }
        if let Some(t) = material.bump_texture.and_then(|t| self.textures.get(t)) {
            let corner_uv = corners.attributes.map(|a| material.normal_uv.apply(&a));
            let Some((dpdu, dpdv)) = uv_derivatives(corners.p, corner_uv) else {
                return n;
            };
            let (_, grad_uv) = t.sample_height_gradient(uv);
            // Height per texel, times the white height in texels: rise over run in texel space.
            let white_texels = crate::material::BUMP_WHITE_HEIGHT_REL * t.width.max(t.height) as f32;
            let texels = Vec2::new(t.width as f32, t.height as f32);
            let slope = grad_uv / texels * white_texels * material.bump_multiplier;
            let along_u = (dpdu - n * n.dot(dpdu)).normalize_or_zero();
            let along_v = (dpdv - n * n.dot(dpdv)).normalize_or_zero();
            // Rising height along a direction leans the normal away from it.
            return (n - along_u * slope.x - along_v * slope.y).normalize_or(n);
        }
        n
    }

    /// Material `id` (an index into `materials`).
    pub fn material(&self, id: u32) -> &Material {
        &self.materials[id as usize]
    }

    /// The BSDF at a surface point.
    pub fn bsdf(&self, sp: &SurfacePoint) -> probegi_core::bsdf::SurfaceBsdf {
        self.material(sp.material).bsdf(&self.textures, &sp.attributes())
    }

    /// The scene mesh's emitters for next-event estimation, and their selection
    /// weights: every triangle whose material emits, weighted by the luminance of
    /// its mean emission × its area (zero, negative or non-finite powers left
    /// out). The one owner of the rule both backends' area-light sampling uses.
    pub fn emitter_powers(&self) -> (Vec<u32>, Vec<f32>) {
        let mesh = &self.mesh;
        let (mut emitters, mut weights) = (Vec::new(), Vec::new());
        for t in 0..mesh.triangle_count() {
            let mat = self.material(mesh.triangle_materials[t]);
            if !mat.is_emissive() {
                continue;
            }
            let power = probegi_core::color::luminance(mat.mean_emission(&self.textures)) * mesh.area(t);
            if power > 0.0 && power.is_finite() {
                emitters.push(t as u32);
                weights.push(power);
            }
        }
        (emitters, weights)
    }

    /// Radiance emitted toward the viewer of `sp`: non-zero only on the front face.
    pub fn emitted(&self, sp: &SurfacePoint) -> Vec3 {
        if !sp.front_face {
            return Vec3::ZERO;
        }
        self.material(sp.material).emission(&self.textures, &sp.attributes())
    }

    /// Whether anything in the scene changes from frame to frame.
    pub fn is_animated(&self) -> bool {
        self.lights.iter().any(|l| !l.keyframes.is_empty())
            || self.sky_map.as_ref().is_some_and(|s| !s.keyframes.is_empty())
            || self.has_moving_geometry()
    }

    /// Re-derives shading normals of every triangle by `rule` (see
    /// [`Mesh::derive_normals`]), keeping the objects' vertex ranges.
    pub fn derive_normals(&mut self, source: crate::mesh::NormalSource, crease_angle_deg: f32) {
        let sources = vec![source; self.mesh.triangle_count()];
        self.mesh.derive_normals(&sources, &[], crease_angle_deg);
        // New vertices are numbered in triangle order and objects own contiguous
        // triangles and their vertices, so each object's vertices stay contiguous.
        for o in &mut self.objects {
            let used = o.triangles().flat_map(|t| self.mesh.triangles[t]);
            let (lo, hi) = used.fold((u32::MAX, 0), |(lo, hi), v| (lo.min(v), hi.max(v + 1)));
            (o.first_vertex, o.vertex_count) = if lo == u32::MAX { (0, 0) } else { (lo, hi - lo) };
        }
    }

    /// Appends geometry (`add_geometry` writes it into the mesh) as one object that
    /// moves by `animation`, pivoting about the centre of its bounds. Returns the
    /// object's index.
    pub fn add_object(
        &mut self,
        name: &str,
        add_geometry: impl FnOnce(&mut Mesh),
        animation: crate::animation::ObjectAnimation,
    ) -> usize {
        let (t0, v0) = (self.mesh.triangle_count(), self.mesh.positions.len());
        add_geometry(&mut self.mesh);
        let added = &self.mesh.positions[v0..];
        let pivot_m = match added.first() {
            Some(&p) => {
                let (lo, hi) = added.iter().fold((p, p), |(lo, hi), &q| (lo.min(q), hi.max(q)));
                (lo + hi) * 0.5
            }
            None => Vec3::ZERO,
        };
        self.objects.push(SceneObject {
            name: name.to_string(),
            first_triangle: t0 as u32,
            triangle_count: (self.mesh.triangle_count() - t0) as u32,
            first_vertex: v0 as u32,
            vertex_count: (self.mesh.positions.len() - v0) as u32,
            pivot_m,
            animation,
            placement: glam::Mat4::IDENTITY,
        });
        self.objects.len() - 1
    }

    /// Sets the animation clock; animations keyed in seconds play at it.
    pub fn set_frames_per_second(&mut self, fps: f32) {
        self.frames_per_second = fps;
        for o in &mut self.objects {
            if let crate::animation::KeyClock::Seconds { frames_per_second } = &mut o.animation.clock {
                *frames_per_second = fps;
            }
        }
    }

    /// Whether any object moves.
    pub fn has_moving_geometry(&self) -> bool {
        self.objects.iter().any(|o| o.is_animated())
    }

    /// Sets this scene's animated state to frame `frame` of `base` (same scene):
    /// lights from their keyframes, and the vertices and normals of every moving
    /// object from `base`'s rest pose.
    pub fn set_frame_from(&mut self, base: &Scene, frame: f32) {
        for (l, b) in self.lights.iter_mut().zip(&base.lights) {
            *l = b.at_frame(frame);
        }
        if let (Some(sky), Some(b)) = (self.sky_map.as_mut(), base.sky_map.as_ref()) {
            *sky = b.at_frame(frame);
        }
        for o in base.objects.iter().filter(|o| o.is_animated()) {
            self.pose_vertices(o.world_from_rest(frame), o.vertices(), base);
        }
    }

    /// Poses this scene's own moving objects at `frame` by their animations
    /// (which may differ from `rest`'s: an engine that sets each object's
    /// pose as its key), their vertices, normals and tangents from `rest`'s
    /// rest pose. `rest` must hold the same mesh.
    pub fn pose_objects_from(&mut self, rest: &Scene, frame: f32) {
        for i in 0..self.objects.len() {
            let o = &self.objects[i];
            if o.is_animated() {
                let (xf, vertices) = (o.world_from_rest(frame), o.vertices());
                self.pose_vertices(xf, vertices, rest);
            }
        }
    }

    /// The vertices, normals and tangents `vertices` placed by `xf` from
    /// `rest`'s (a range that either mesh lacks is left as it is).
    fn pose_vertices(&mut self, xf: glam::Affine3A, vertices: std::ops::Range<usize>, rest: &Scene) {
        let held = self.mesh.positions.len().min(rest.mesh.positions.len()).min(rest.mesh.normals.len());
        if vertices.end > held || vertices.end > self.mesh.normals.len() {
            return;
        }
        let normal_matrix = glam::Mat3::from(xf.matrix3).inverse().transpose();
        for v in vertices.clone() {
            self.mesh.positions[v] = xf.transform_point3(rest.mesh.positions[v]);
            self.mesh.normals[v] = (normal_matrix * rest.mesh.normals[v]).normalize_or(Vec3::Y);
        }
        if rest.mesh.tangents.len() >= vertices.end && self.mesh.tangents.len() >= vertices.end {
            let xf = glam::Mat4::from(xf);
            let mirror = if xf.determinant() < 0.0 { -1.0 } else { 1.0 };
            for v in vertices {
                self.mesh.tangents[v] = crate::mesh::transformed_tangent(xf, rest.mesh.tangents[v], mirror);
            }
        }
    }

    /// World bounds of every moving object as posed in this scene, for waking
    /// the probes around them (seed 004 §4.3).
    pub fn moving_object_bounds(&self) -> Vec<(Vec3, Vec3)> {
        self.objects
            .iter()
            .filter(|o| o.is_animated() && o.vertex_count > 0)
            .map(|o| {
                let p = &self.mesh.positions[o.vertices()];
                p.iter().fold((p[0], p[0]), |(lo, hi), &q| (lo.min(q), hi.max(q)))
            })
            .collect()
    }

    /// Axis-aligned bounds of the geometry, instances included: tight (each
    /// copy's vertices, transformed: the box the copies merged would have) up to
    /// [`MAX_TIGHT_BOUND_VERTICES`] instanced vertices, each copy's transformed
    /// prototype box beyond (conservative, and bounded in time).
    pub fn bounds(&self) -> Option<(Vec3, Vec3)> {
        let instanced_vertices: usize = self
            .instances
            .iter()
            .filter_map(|i| self.prototypes.get(i.prototype as usize))
            .map(|p| p.mesh.positions.len())
            .sum();
        let tight = instanced_vertices <= MAX_TIGHT_BOUND_VERTICES;
        let boxes: Vec<Option<(Vec3, Vec3)>> = self.prototypes.iter().map(|p| p.mesh.bounds()).collect();
        let placed = self.instances.iter().filter_map(|i| {
            if !tight {
                let (lo, hi) = boxes.get(i.prototype as usize).copied().flatten()?;
                return Some(crate::bounds::transformed_bounds(&i.world_from_local, lo, hi));
            }
            let m = &self.prototypes.get(i.prototype as usize)?.mesh;
            let mut points = m.positions.iter().map(|&p| i.world_from_local.transform_point3(p));
            let first = points.next()?;
            Some(points.fold((first, first), |(lo, hi), p| (lo.min(p), hi.max(p))))
        });
        self.mesh.bounds().into_iter().chain(placed).reduce(|(a, b), (c, d)| (a.min(c), b.max(d)))
    }

    /// Adds `mesh` (local space; material ids already index `materials`) as a
    /// prototype drawn at each of `placements`. Returns the prototype's index.
    pub fn add_instanced_mesh(&mut self, name: &str, mesh: Mesh, placements: &[glam::Mat4]) -> Result<u32, String> {
        let prototype = self.prototypes.len() as u32;
        let instances: Vec<MeshInstance> =
            placements.iter().map(|&m| MeshInstance::new(prototype, m)).collect::<Result<_, _>>()?;
        self.prototypes.push(MeshPrototype { name: name.to_string(), mesh });
        self.instances.extend(instances);
        Ok(prototype)
    }

    /// Triangles drawn: the scene's mesh and every instance's copy.
    pub fn drawn_triangle_count(&self) -> usize {
        self.mesh.triangle_count() + self.instanced_triangle_count()
    }

    /// Triangles stored: the scene's mesh and each prototype once.
    pub fn stored_triangle_count(&self) -> usize {
        self.mesh.triangle_count() + self.prototypes.iter().map(|p| p.mesh.triangle_count()).sum::<usize>()
    }

    /// Triangles drawn by instances (each copy counted).
    pub fn instanced_triangle_count(&self) -> usize {
        self.instances.iter().map(|i| self.prototypes[i.prototype as usize].mesh.triangle_count()).sum()
    }

    /// The camera to use: the file's, else one that frames the scene bounds from +Z.
    pub fn default_camera(&self) -> Camera {
        if let Some(c) = self.camera {
            return c;
        }
        match self.bounds() {
            Some((lo, hi)) => {
                let centre = (lo + hi) * 0.5;
                let half = (hi - lo) * 0.5;
                let fov_y_deg = 45.0f32;
                let dist = half.x.max(half.y) / (fov_y_deg.to_radians() * 0.5).tan() + half.z;
                Camera { position: centre + Vec3::Z * dist.max(1e-3) * 1.05, target: centre, up: Vec3::Y, fov_y_deg }
            }
            None => Camera::default(),
        }
    }

    /// An error naming the object and the frame if moving geometry can reach
    /// beyond ±[`MAX_COORDINATE_M`] at any key or at any frame up to
    /// `last_frame` (loaded geometry is held to the same bound; a posed box
    /// beyond it overflows the BVH builder). [`Scene::validate`] checks the
    /// keys; a renderer checks its last frame before it starts.
    pub fn check_posed_bounds(&self, last_frame: f32) -> Result<(), String> {
        for o in self.objects.iter().filter(|o| o.is_animated()) {
            let vertices = self.mesh.positions.get(o.vertices()).unwrap_or(&[]);
            let Some(rest) = vertices
                .iter()
                .fold(None, |b: Option<(Vec3, Vec3)>, &p| Some(b.map_or((p, p), |(lo, hi)| (lo.min(p), hi.max(p)))))
            else {
                continue;
            };
            if let Some((frame, reach)) = o.posed_reach_beyond(rest, last_frame, MAX_COORDINATE_M) {
                return Err(format!(
                    "object `{}`: at frame {frame} its animation moves its geometry to ±{reach:e} m, beyond \
                     ±{MAX_COORDINATE_M:e} m (check its keyframes' translation and scale, and its motion)",
                    o.name
                ));
            }
        }
        Ok(())
    }

    /// Whether anything in the scene gives light as it stands (at the frame it
    /// is set to): a punctual light of non-zero intensity and colour, a
    /// triangle with an emissive material, or a non-black sky.
    pub fn has_light_sources(&self) -> bool {
        let lit = |l: &crate::light::PunctualLight| l.intensity > 0.0 && l.color.max_element() > 0.0;
        let emits = |&m: &u32| self.materials.get(m as usize).is_some_and(|m| m.is_emissive());
        self.has_sky()
            || self.lights.iter().any(lit)
            || self.mesh.triangle_materials.iter().any(emits)
            || self.prototypes.iter().any(|p| p.mesh.triangle_materials.iter().any(emits))
    }

    /// The radiance a ray that leaves the scene along unit direction `dir`
    /// sees: the environment map's there, else the constant sky.
    pub fn sky_toward(&self, dir: Vec3) -> Vec3 {
        match &self.sky_map {
            Some(map) => map.radiance(dir),
            None => self.sky_radiance,
        }
    }

    /// The radiance a probe ray that leaves the scene along `dir` carries into
    /// the field: the constant sky's, but nothing under a sky map. A map's
    /// light reaches every surface by next-event estimation instead (camera
    /// pixels and probe-ray hits sample its density with shadow rays), so the
    /// field holds only what surfaces reflect: a sun or a bright patch of sky
    /// lights the surfaces it reaches sharply, where probes would blur it
    /// (Sponza under Blender's courtyard.exr: the field alone came out 35 %
    /// dark against the reference). The constant sky stays in the field:
    /// smooth light that the probes carry well, as the DDGI papers do.
    pub fn sky_on_probe_miss(&self, dir: Vec3) -> Vec3 {
        match &self.sky_map {
            Some(_) => Vec3::ZERO,
            None => self.sky_toward(dir),
        }
    }

    /// Whether rays that leave the scene see any light.
    pub fn has_sky(&self) -> bool {
        match &self.sky_map {
            Some(map) => !map.is_black(),
            None => self.sky_radiance.max_element() > 0.0,
        }
    }

    /// Whether the camera is animated: it has keyframes (then
    /// [`Scene::camera_at`] gives its camera for every frame).
    pub fn has_camera_animation(&self) -> bool {
        !self.camera_keyframes.is_empty()
    }

    /// The animated camera at `frame` (fractional frames allowed); `None` when
    /// the camera has no keyframes. Position, target, up hint and fov
    /// interpolate as [`Scene::camera_between_keys`] says; the camera's `up` is
    /// then its frame's image up on the path (`Camera::view_basis` carried from
    /// frame 0 through every whole frame before `frame`), so a path through the
    /// vertical turns continuously; from the first whole frame after the last
    /// key the camera holds. `camera_at(f)` equals `camera_path(n)[f]` for
    /// every whole frame `f < n` (for paths under a million frames long).
    pub fn camera_at(&self, frame: f32) -> Option<Camera> {
        let hold = self.camera_hold_frame()?;
        let end = if frame.is_nan() { 0.0 } else { frame.min(hold) };
        let step = (end / MAX_CAMERA_WALK_STEPS).max(1.0);
        let mut previous = None;
        let mut f = 0.0f32;
        while f < end {
            let c = self.camera_between_keys(f)?;
            previous = Some(c.view_basis(previous.as_ref()));
            f += step;
        }
        let c = self.camera_between_keys(end)?;
        Some(c.with_basis(&c.view_basis(previous.as_ref())))
    }

    /// The first whole frame at or after the last camera key, from which the
    /// path holds its camera.
    fn camera_hold_frame(&self) -> Option<f32> {
        Some(self.camera_keyframes.last()?.frame.max(0.0).ceil())
    }

    /// The cameras of frames `0..frames` of the keyframed path (see
    /// [`Scene::camera_at`]); empty when the camera has no keyframes.
    pub fn camera_path(&self, frames: u32) -> Vec<Camera> {
        let Some(hold) = self.camera_hold_frame() else { return Vec::new() };
        let mut previous = None;
        let mut path: Vec<Camera> = Vec::with_capacity(frames as usize);
        for f in 0..frames {
            if f as f32 > hold
                && let Some(&last) = path.last()
            {
                path.push(last);
                continue;
            }
            let Some(c) = self.camera_between_keys(f as f32) else { break };
            let basis = c.view_basis(previous.as_ref());
            path.push(c.with_basis(&basis));
            previous = Some(basis);
        }
        path
    }

    /// The keyframed camera at `frame` as the keys give it: between two keys,
    /// position, target, up hint and fov_y_deg interpolate linearly (the hint
    /// normalised afterwards, or the earlier key's where the blend vanishes);
    /// before the first key and after the last the camera holds, and at a key
    /// it is that key's camera exactly. Validation ([`Scene::validate`]) makes
    /// sure the eye never reaches the target in between.
    pub fn camera_between_keys(&self, frame: f32) -> Option<Camera> {
        let keys = &self.camera_keyframes;
        let first = keys.first()?;
        // Keys at or before `frame`; a NaN frame counts as before the first.
        let after = keys.partition_point(|k| k.frame <= frame);
        if after == 0 {
            return Some(first.camera);
        }
        let a = &keys[after - 1];
        let Some(b) = keys.get(after) else { return Some(a.camera) };
        let t = (frame - a.frame) / (b.frame - a.frame);
        if t <= 0.0 {
            return Some(a.camera);
        }
        let (ca, cb) = (a.camera, b.camera);
        Some(Camera {
            position: ca.position.lerp(cb.position, t),
            target: ca.target.lerp(cb.target, t),
            up: ca.up.lerp(cb.up, t).try_normalize().unwrap_or(ca.up),
            fov_y_deg: ca.fov_y_deg + (cb.fov_y_deg - ca.fov_y_deg) * t,
        })
    }

    /// Warnings about values that are valid but physically suspect: a diffuse
    /// colour above 1 reflects more energy than it receives.
    pub fn energy_warnings(&self) -> Vec<String> {
        self.materials
            .iter()
            .filter(|m| m.base_color_factor.max_element() > 1.0)
            .map(|m| {
                format!(
                    "material `{}`: diffuse colour {} is above 1, so it reflects more light than it receives \
                     (energy gain; bounces may not converge)",
                    m.name, m.base_color_factor
                )
            })
            .collect()
    }

    /// Invariants every loader must establish; returns the first broken one.
    pub fn validate(&self) -> Result<(), String> {
        self.validate_mesh()?;
        if !self.sky_radiance.is_finite() || self.sky_radiance.min_element() < 0.0 {
            return Err("sky_radiance must be finite and non-negative".into());
        }
        if let Some(map) = &self.sky_map {
            map.validate()?;
        }
        for (i, l) in self.lights.iter().enumerate() {
            l.validate().map_err(|e| format!("light {i}: {e}"))?;
        }
        self.validate_materials()?;
        if let Some(c) = &self.camera {
            c.validate()?;
        }
        if let Some((i, why)) = camera_keyframe_error(&self.camera_keyframes) {
            return Err(format!("camera.keyframes[{i}]: {why}"));
        }
        self.validate_objects()?;
        self.validate_prototypes()?;
        self.validate_instances()?;
        if !(self.frames_per_second.is_finite() && self.frames_per_second > 0.0) {
            return Err(format!("frames_per_second must be positive, got {}", self.frames_per_second));
        }
        Ok(())
    }

    /// The scene mesh's arrays, vertices, indices and material ids.
    fn validate_mesh(&self) -> Result<(), String> {
        let m = &self.mesh;
        if m.normals.len() != m.positions.len()
            || m.uvs.len() != m.positions.len()
            || m.uvs1.len() > m.positions.len()
            || m.colors.len() > m.positions.len()
            || !(m.tangents.is_empty() || m.tangents.len() == m.positions.len())
        {
            return Err("per-vertex arrays differ in length".into());
        }
        if m.triangle_materials.len() != m.triangles.len() {
            return Err("one material id per triangle required".into());
        }
        if let Some(i) = m.positions.iter().position(|p| !p.is_finite()) {
            return Err(format!("vertex {i} has a non-finite position"));
        }
        // Beyond this, products of coordinates overflow f32 in ray casting and BVH
        // builds (seen panicking in obvhs from about 1e19 m).
        if let Some(i) = m.positions.iter().position(|p| p.abs().max_element() > MAX_COORDINATE_M) {
            return Err(format!(
                "vertex {i} at {} lies beyond ±{MAX_COORDINATE_M:e} m: the scene's extent is absurd \
                 (wrong units or a corrupt file?)",
                m.positions[i]
            ));
        }
        for (i, t) in m.triangles.iter().enumerate() {
            if t.iter().any(|&v| v as usize >= m.positions.len()) {
                return Err(format!("triangle {i} indexes past the vertex array"));
            }
        }
        if let Some(i) = m.triangle_materials.iter().position(|&mat| mat as usize >= self.materials.len()) {
            return Err(format!("triangle {i} has an unknown material"));
        }
        Ok(())
    }

    /// Colours, emission, factors and cutoffs of every material.
    fn validate_materials(&self) -> Result<(), String> {
        for mat in &self.materials {
            let vals = [mat.base_color_factor, mat.emissive_factor * mat.emissive_strength];
            if vals.iter().any(|v| !v.is_finite() || v.min_element() < 0.0) {
                return Err(format!("material `{}` has a negative or non-finite colour", mat.name));
            }
            // Beyond these, products along a path overflow f32 to infinite radiance.
            if mat.base_color_factor.max_element() > MAX_ALBEDO {
                return Err(format!(
                    "material `{}`: diffuse colour {} is absurd (above {MAX_ALBEDO}); reflectances lie in [0, 1]",
                    mat.name, mat.base_color_factor
                ));
            }
            if vals[1].max_element() > MAX_EMISSION {
                return Err(format!(
                    "material `{}`: emission {} is absurd (above {MAX_EMISSION:e} W·sr⁻¹·m⁻²)",
                    mat.name, vals[1]
                ));
            }
            let factors = [mat.alpha_factor, mat.normal_scale, mat.bump_multiplier, mat.roughness, mat.metallic];
            if factors.iter().any(|f| !f.is_finite()) {
                return Err(format!(
                    "material `{}` has a non-finite alpha, normal, bump, roughness or metallic factor",
                    mat.name
                ));
            }
            if let crate::material::AlphaMode::Mask { cutoff } = mat.alpha_mode
                && !cutoff.is_finite()
            {
                return Err(format!("material `{}`: alpha cutoff {cutoff} is not finite", mat.name));
            }
        }
        Ok(())
    }

    /// Objects: inside the mesh, disjoint, closed over their vertex ranges, valid
    /// animations and bounds at frame 0; no loose triangle uses an object's vertices.
    fn validate_objects(&self) -> Result<(), String> {
        let m = &self.mesh;
        let mut claimed = vec![false; m.triangles.len()];
        for o in &self.objects {
            let name = &o.name;
            if o.triangles().end > m.triangles.len() || o.vertices().end > m.positions.len() {
                return Err(format!("object `{name}` reaches past the mesh"));
            }
            if o.triangles().any(|t| std::mem::replace(&mut claimed[t], true)) {
                return Err(format!("object `{name}` overlaps another object"));
            }
            let vs = o.vertices();
            if o.triangles().any(|t| m.triangles[t].iter().any(|&v| !vs.contains(&(v as usize)))) {
                return Err(format!("object `{name}` has triangles that use vertices outside its range"));
            }
            o.validate().map_err(|e| format!("object `{name}`: {e}"))?;
        }
        self.check_posed_bounds(0.0)?;
        let mut vertex_owner = vec![u32::MAX; m.positions.len()];
        for (i, o) in self.objects.iter().enumerate() {
            vertex_owner[o.vertices()].iter_mut().for_each(|v| *v = i as u32);
        }
        let loose = (0..m.triangles.len()).filter(|&t| !claimed[t]);
        if let Some(t) =
            loose.into_iter().find(|&t| m.triangles[t].iter().any(|&v| vertex_owner[v as usize] != u32::MAX))
        {
            return Err(format!("triangle {t} is in no object but uses an object's vertices"));
        }
        Ok(())
    }

    /// Prototype meshes: their arrays, vertices and indices, and known, non-emissive materials.
    fn validate_prototypes(&self) -> Result<(), String> {
        for (k, proto) in self.prototypes.iter().enumerate() {
            let pm = &proto.mesh;
            let name = &proto.name;
            if pm.normals.len() != pm.positions.len()
                || pm.uvs.len() != pm.positions.len()
                || pm.uvs1.len() > pm.positions.len()
                || pm.colors.len() > pm.positions.len()
                || pm.triangle_materials.len() != pm.triangles.len()
                || !(pm.tangents.is_empty() || pm.tangents.len() == pm.positions.len())
            {
                return Err(format!("prototype {k} (`{name}`): per-vertex or per-triangle arrays differ in length"));
            }
            if pm.positions.iter().any(|p| !p.is_finite() || p.abs().max_element() > MAX_COORDINATE_M) {
                return Err(format!("prototype {k} (`{name}`) has a non-finite or absurd vertex"));
            }
            if pm.triangles.iter().any(|t| t.iter().any(|&v| v as usize >= pm.positions.len())) {
                return Err(format!("prototype {k} (`{name}`) has a triangle past its vertex array"));
            }
            match pm
                .triangle_materials
                .iter()
                .find(|&&m| self.materials.get(m as usize).is_none_or(|m| m.is_emissive()))
            {
                Some(&m) if (m as usize) < self.materials.len() => {
                    return Err(format!(
                        "prototype {k} (`{name}`): material `{}` emits, and instanced meshes may not \
                         (area lights are sampled from the scene's own mesh)",
                        self.materials[m as usize].name
                    ));
                }
                Some(_) => return Err(format!("prototype {k} (`{name}`) has an unknown material")),
                None => {}
            }
        }
        Ok(())
    }

    /// Instances: an existing prototype, a finite transform, a sane extent.
    fn validate_instances(&self) -> Result<(), String> {
        if let Some(i) = self.instances.iter().position(|i| i.prototype as usize >= self.prototypes.len()) {
            return Err(format!("instance {i} names a missing prototype"));
        }
        if let Some(i) =
            self.instances.iter().position(|i| !(i.world_from_local.is_finite() && i.normal_from_local.is_finite()))
        {
            return Err(format!("instance {i} has a non-finite transform"));
        }
        // The placed copies obey the same extent limit as the scene's own vertices.
        if let Some(i) = self.instances.iter().position(|i| {
            let m = i.world_from_local;
            m.translation.abs().max_element() > MAX_COORDINATE_M
                || [m.matrix3.x_axis, m.matrix3.y_axis, m.matrix3.z_axis].iter().any(|c| c.abs().max_element() > 1e6)
        }) {
            return Err(format!(
                "instance {i} is placed beyond ±{MAX_COORDINATE_M:e} m or scaled by more than 1e6: \
                 the scene's extent is absurd (wrong units?)"
            ));
        }
        Ok(())
    }
}
