//! glTF 2.0 loader (.gltf with external or embedded buffers, and .glb).
//! Section numbers are the glTF 2.0 specification's (Khronos, 2.0.1).
//!
//! What it reads:
//! - the default scene's node hierarchy with transforms (§3.5), the first
//!   perspective camera (§3.10), KHR_lights_punctual;
//! - triangle primitives (§3.7.2.1): modes TRIANGLES, TRIANGLE_STRIP and
//!   TRIANGLE_FAN, strips and fans turned into triangle lists with the
//!   section's winding; `POSITION`, `NORMAL` (flat normals without it, and then
//!   `TANGENT` is ignored), `TANGENT` (MikkTSpace without it, for normal maps),
//!   `TEXCOORD_0`, `TEXCOORD_1` and `COLOR_0` (VEC3 or VEC4; float, normalized
//!   unsigned byte or short; clamped to [0, 1]). POINTS, LINES, LINE_LOOP and
//!   LINE_STRIP primitives are skipped with a warning naming the mesh;
//! - metallic-roughness materials (§3.9.2): `baseColorFactor` × `COLOR_0` ×
//!   `baseColorTexture` (sRGB), `metallicFactor` and `roughnessFactor` × the
//!   blue and green channels of `metallicRoughnessTexture` (linear),
//!   `normalTexture` with its `scale`, `emissiveFactor` × `emissiveTexture`
//!   (sRGB) × KHR_materials_emissive_strength, `alphaMode` and `alphaCutoff`
//!   (§3.9.4; BLEND as MASK at 0.5, see `material.rs`). Every texture
//!   reference reads its `texCoord` set (0 or 1; a higher set is a warning and
//!   the texture is ignored) through KHR_texture_transform (offset, rotation,
//!   scale, texCoord override; see `UvMapping`) and its texture's sampler
//!   (§3.8.4: wrapS/wrapT per axis, magFilter; no mipmaps, see `texture.rs`);
//! - animations (below).
//!
//! Not read: `occlusionTexture` (the renderers trace occlusion themselves; §3.9.3
//! applies it to ambient light only), skins and morph targets (the rest pose is
//! drawn), orthographic cameras, `doubleSided` (every surface is two-sided).
//!
//! Extensions (§3.12): KHR_lights_punctual, KHR_materials_emissive_strength and
//! KHR_texture_transform are followed. A file whose `extensionsRequired` names any
//! other is refused with an error naming the extension; any other extension in
//! `extensionsUsed` (KHR_materials_transmission, clearcoat, sheen, volume, ior,
//! specular, iridescence, anisotropy, dispersion, pbrSpecularGlossiness, unlit,
//! variants, KHR_draco_mesh_compression, EXT_meshopt_compression,
//! KHR_mesh_quantization, KHR_texture_basisu, …) loads with a warning naming it:
//! the scene renders as if it were absent.
//!
//! Animations: translation, rotation and scale channels of every animation play
//! together on the scene clock (`Scene::frames_per_second`, key times in seconds).
//! Each mesh node under an animated node becomes a rigid [`SceneObject`] whose
//! world transform is baked, relative to its rest pose, at the union of the key
//! times of its ancestor chain (plus 3 samples between consecutive keys) and
//! interpolated between them (lerp, slerp); with one animated node and linear
//! channels this is exact at keys and close between. STEP channels hold,
//! CUBICSPLINE channels use their key values linearly (a warning says so); morph
//! weights, and animated lights and cameras, are not followed (warnings).
//!
//! Hostile files: every accessor is checked (component type, type, stride and
//! byte range inside its buffer) before the library reads it, sparse accessors are
//! refused, a GLB whose header claims more bytes than the file holds is refused
//! before anything is allocated, and the node hierarchy is walked with a cycle
//! check and a depth limit ([`MAX_NODE_DEPTH`]).
//!
//! Units: light intensities are used as the spec's photometric numbers without a
//! lm→W conversion (candela → W·sr⁻¹, lux → W·m⁻²), which is what a renderer
//! working in relative radiance expects (see `probegi_core::punctual`).

use std::collections::HashMap;
use std::path::Path;

use glam::{Mat4, Quat, Vec2, Vec3, Vec4};
use probegi_core::camera::Camera;

use crate::animation::{KeyClock, ObjectAnimation, SceneObject, TransformKeyframe};
use crate::error::{Result, SceneError};
use crate::light::{LightKind, PunctualLight};
use crate::material::{Material, UvMapping};
use crate::mesh::{Mesh, NormalSource};
use crate::scene::Scene;
use crate::texture::{Filter, Sampler, Texture, Wrap};

struct Loader<'a> {
    path: &'a Path,
    buffers: Vec<gltf::buffer::Data>,
    /// `None` where the image could not be read (a warning says which).
    images: Vec<Option<gltf::image::Data>>,
    scene: Scene,
    material_ids: HashMap<Option<usize>, u32>,
    /// Scene textures by (image, sampler) index.
    texture_ids: HashMap<(usize, Option<usize>), Option<usize>>,
    /// Animation channels by node index.
    channels: HashMap<usize, NodeChannels>,
    /// Point and line primitives left out, for the error when nothing else is drawn.
    skipped_primitives: Vec<String>,
}

/// A node's animated local TRS channels, `(time s, value)` sorted by time.
#[derive(Default)]
struct NodeChannels {
    translation: Vec<(f32, Vec3)>,
    rotation: Vec<(f32, Quat)>,
    scale: Vec<(f32, Vec3)>,
}

/// Piecewise-linear sample of a channel, held beyond its ends.
fn sample<T: Copy>(keys: &[(f32, T)], t: f32, lerp: impl Fn(T, T, f32) -> T) -> Option<T> {
    let first = keys.first()?;
    if t <= first.0 {
        return Some(first.1);
    }
    for w in keys.windows(2) {
        let ((t0, a), (t1, b)) = (w[0], w[1]);
        if t <= t1 {
            return Some(if t1 > t0 { lerp(a, b, (t - t0) / (t1 - t0)) } else { b });
        }
    }
    keys.last().map(|k| k.1)
}

impl NodeChannels {
    fn times(&self) -> impl Iterator<Item = f32> + '_ {
        let t = self.translation.iter().map(|k| k.0);
        t.chain(self.rotation.iter().map(|k| k.0)).chain(self.scale.iter().map(|k| k.0))
    }

    /// The node's local matrix at `t`, channels overriding its static TRS.
    fn local(&self, node: &gltf::Node, t: f32) -> Mat4 {
        let (tr, rot, sc) = node.transform().decomposed();
        let tr = sample(&self.translation, t, |a, b, u| a.lerp(b, u)).unwrap_or(Vec3::from(tr));
        let rot = sample(&self.rotation, t, |a, b, u| a.slerp(b, u)).unwrap_or(Quat::from_array(rot));
        let sc = sample(&self.scale, t, |a, b, u| a.lerp(b, u)).unwrap_or(Vec3::from(sc));
        Mat4::from_scale_rotation_translation(sc, rot.normalize(), tr)
    }
}

/// Node hierarchies deeper than this are refused (a recursion bound).
pub const MAX_NODE_DEPTH: usize = 256;

/// The glTF extensions the loader follows (see the module docs).
pub const FOLLOWED_EXTENSIONS: [&str; 3] =
    ["KHR_lights_punctual", "KHR_materials_emissive_strength", "KHR_texture_transform"];

/// A file that requires an extension the loader does not follow is refused
/// (glTF 2.0 §3.12: `extensionsRequired` lists what is needed "to load and/or
/// render" it), before the library validates it (which would say only
/// "Unsupported extension"). The document is parsed without validation here; a
/// document that does not parse is left to the library's own error.
fn check_required_extensions(path: &Path) -> Result<()> {
    let Ok(file) = std::fs::File::open(path) else {
        return Ok(()); // the library's own error follows
    };
    let Ok(doc) = gltf::Gltf::from_reader_without_validation(std::io::BufReader::new(file)) else {
        return Ok(());
    };
    match doc.extensions_required().find(|e| !FOLLOWED_EXTENSIONS.contains(e)) {
        Some(ext) => Err(SceneError::Gltf {
            path: path.to_path_buf(),
            message: format!("the file requires extension {ext}, which probegi does not implement"),
        }),
        None => Ok(()),
    }
}

/// One warning per extension in `extensionsUsed` that the loader does not
/// follow: nothing it adds is silently dropped.
fn unfollowed_extension_warnings(path: &Path, doc: &gltf::Document) -> Vec<String> {
    doc.extensions_used()
        .filter(|e| !FOLLOWED_EXTENSIONS.contains(e))
        .map(|e| {
            format!(
                "{}: extension {e} is used but probegi does not implement it; the scene renders without it",
                path.display()
            )
        })
        .collect()
}

/// A GLB's header and chunk lengths against the file's size, before the library
/// allocates what they claim.
fn check_glb_header(path: &Path) -> Result<()> {
    use std::io::Read;
    let err = |message: String| SceneError::Gltf { path: path.to_path_buf(), message };
    let size =
        std::fs::metadata(path).map_err(|source| SceneError::Io { path: path.to_path_buf(), cause: source })?.len();
    let mut head = [0u8; 20];
    let mut f =
        std::fs::File::open(path).map_err(|source| SceneError::Io { path: path.to_path_buf(), cause: source })?;
    let n = f.read(&mut head).map_err(|source| SceneError::Io { path: path.to_path_buf(), cause: source })?;
    if n < 4 || &head[..4] != b"glTF" {
        return Ok(()); // JSON glTF, or the library's own error.
    }
    if n < 20 {
        return Err(err(format!("GLB header truncated ({size} bytes)")));
    }
    let u32_at = |i: usize| u32::from_le_bytes([head[i], head[i + 1], head[i + 2], head[i + 3]]) as u64;
    let (length, chunk) = (u32_at(8), u32_at(12));
    if length > size {
        return Err(err(format!("GLB header says {length} bytes, the file has {size}")));
    }
    if chunk + 20 > length {
        return Err(err(format!("GLB JSON chunk of {chunk} bytes does not fit the {length}-byte file")));
    }
    Ok(())
}

/// `%XX` escapes of a URI reference decoded (glTF URIs are percent-encoded).
fn decode_uri(uri: &str) -> String {
    let bytes = uri.as_bytes();
    let mut out = Vec::with_capacity(bytes.len());
    let mut i = 0;
    while i < bytes.len() {
        let hex = |b: u8| (b as char).to_digit(16);
        if bytes[i] == b'%'
            && i + 2 < bytes.len()
            && let (Some(h), Some(l)) = (hex(bytes[i + 1]), hex(bytes[i + 2]))
        {
            out.push((h * 16 + l) as u8);
            i += 3;
        } else {
            out.push(bytes[i]);
            i += 1;
        }
    }
    String::from_utf8_lossy(&out).into_owned()
}

/// Every external buffer and image file the document names exists, so a missing
/// one is reported by its own name (the library's error does not name it).
fn check_external_files(path: &Path) -> Result<()> {
    let Ok(doc) = gltf::Gltf::open(path) else {
        return Ok(()); // the library's own error follows
    };
    let dir = path.parent().unwrap_or(Path::new("."));
    let buffers = doc.buffers().filter_map(|b| match b.source() {
        gltf::buffer::Source::Uri(uri) => Some(("buffer", b.index(), uri.to_string())),
        gltf::buffer::Source::Bin => None,
    });
    // Images are checked as they load: a missing one is a warning (as for OBJ).
    for (what, i, uri) in buffers {
        if uri.starts_with("data:") {
            continue;
        }
        let file = dir.join(decode_uri(&uri));
        if !file.exists() {
            return Err(SceneError::Gltf {
                path: path.to_path_buf(),
                message: format!("{what} {i}: file {} not found", file.display()),
            });
        }
    }
    Ok(())
}

/// Checks an accessor before the library reads it: not sparse, a buffer view, one
/// of the `allowed` (component type, type) pairs, a stride no smaller than an
/// element, and every element's bytes inside the view and the view inside its
/// buffer.
fn check_accessor(
    path: &Path,
    buffers: &[gltf::buffer::Data],
    accessor: &gltf::Accessor,
    allowed: &[(gltf::accessor::DataType, gltf::accessor::Dimensions)],
    what: &str,
) -> Result<()> {
    let err = |m: String| SceneError::Gltf {
        path: path.to_path_buf(),
        message: format!("{what}: accessor {}: {m}", accessor.index()),
    };
    if accessor.sparse().is_some() {
        return Err(err("sparse accessors are not supported".into()));
    }
    let (dt, dims) = (accessor.data_type(), accessor.dimensions());
    if !allowed.contains(&(dt, dims)) {
        return Err(err(format!("{dt:?} {dims:?} is not allowed here (expected one of {allowed:?})")));
    }
    let view = accessor.view().ok_or_else(|| err("no bufferView".into()))?;
    let elem = (dt.size() * dims.multiplicity()) as u64;
    let stride = view.stride().map_or(elem, |s| s as u64);
    if stride < elem {
        return Err(err(format!("byteStride {stride} is smaller than an element ({elem} bytes)")));
    }
    let buffer_len = buffers.get(view.buffer().index()).map_or(0, |b| b.0.len() as u64);
    let (view_start, view_len) = (view.offset() as u64, view.length() as u64);
    if view_start + view_len > buffer_len {
        return Err(err(format!(
            "bufferView {} ends at byte {} of a {buffer_len}-byte buffer",
            view.index(),
            view_start + view_len
        )));
    }
    let count = accessor.count() as u64;
    let end = accessor.offset() as u64 + if count == 0 { 0 } else { stride * (count - 1) + elem };
    if end > view_len {
        return Err(err(format!("{count} elements need {end} bytes, bufferView {} has {view_len}", view.index())));
    }
    Ok(())
}

/// Every index the loader follows, against the array it points into: the library
/// trusts them and panics on one out of range.
fn check_json_indices(path: &Path, root: &gltf::json::Root) -> Result<()> {
    let err = |m: String| SceneError::Gltf { path: path.to_path_buf(), message: m };
    let within = |what: String, i: usize, n: usize| {
        if i < n { Ok(()) } else { Err(err(format!("{what} = {i} is out of range ({n} defined)"))) }
    };
    let (accessors, views, nodes) = (root.accessors.len(), root.buffer_views.len(), root.nodes.len());
    for (i, a) in root.accessors.iter().enumerate() {
        if let Some(v) = &a.buffer_view {
            within(format!("accessors[{i}].bufferView"), v.value(), views)?;
        }
        if let Some(sp) = &a.sparse {
            within(format!("accessors[{i}].sparse.indices.bufferView"), sp.indices.buffer_view.value(), views)?;
            within(format!("accessors[{i}].sparse.values.bufferView"), sp.values.buffer_view.value(), views)?;
        }
    }
    for (i, v) in root.buffer_views.iter().enumerate() {
        within(format!("bufferViews[{i}].buffer"), v.buffer.value(), root.buffers.len())?;
    }
    for (m, mesh) in root.meshes.iter().enumerate() {
        for (k, prim) in mesh.primitives.iter().enumerate() {
            for a in prim.attributes.values() {
                within(format!("meshes[{m}].primitives[{k}].attributes"), a.value(), accessors)?;
            }
            if let Some(a) = &prim.indices {
                within(format!("meshes[{m}].primitives[{k}].indices"), a.value(), accessors)?;
            }
            if let Some(mat) = &prim.material {
                within(format!("meshes[{m}].primitives[{k}].material"), mat.value(), root.materials.len())?;
            }
        }
    }
    for (i, n) in root.nodes.iter().enumerate() {
        for c in n.children.iter().flatten() {
            within(format!("nodes[{i}].children"), c.value(), nodes)?;
        }
        if let Some(m) = &n.mesh {
            within(format!("nodes[{i}].mesh"), m.value(), root.meshes.len())?;
        }
        if let Some(c) = &n.camera {
            within(format!("nodes[{i}].camera"), c.value(), root.cameras.len())?;
        }
    }
    for (i, sc) in root.scenes.iter().enumerate() {
        for n in &sc.nodes {
            within(format!("scenes[{i}].nodes"), n.value(), nodes)?;
        }
    }
    for (i, anim) in root.animations.iter().enumerate() {
        for (k, ch) in anim.channels.iter().enumerate() {
            within(format!("animations[{i}].channels[{k}].sampler"), ch.sampler.value(), anim.samplers.len())?;
            within(format!("animations[{i}].channels[{k}].target.node"), ch.target.node.value(), nodes)?;
        }
        for (k, sm) in anim.samplers.iter().enumerate() {
            within(format!("animations[{i}].samplers[{k}].input"), sm.input.value(), accessors)?;
            within(format!("animations[{i}].samplers[{k}].output"), sm.output.value(), accessors)?;
        }
    }
    Ok(())
}

thread_local! {
    /// Set while this thread runs the glTF library under [`guarded`].
    static IN_GLTF_GUARD: std::cell::Cell<bool> = const { std::cell::Cell::new(false) };
}

/// Runs `f` (the glTF library and our reads through it) so that a panic inside it
/// becomes an error naming the file. gltf-json 1.4 panics on some malformed
/// documents during its own validation (an invalid enum value it then unwraps, a
/// POSITION accessor index out of range); those are caught here, and the panic
/// hook stays quiet for them (installed once, it defers to the previous hook for
/// every other panic).
fn guarded<T>(path: &Path, f: impl FnOnce() -> Result<T>) -> Result<T> {
    static QUIET_HOOK: std::sync::Once = std::sync::Once::new();
    QUIET_HOOK.call_once(|| {
        let previous = std::panic::take_hook();
        std::panic::set_hook(Box::new(move |info| {
            if !IN_GLTF_GUARD.with(|g| g.get()) {
                previous(info);
            }
        }));
    });
    IN_GLTF_GUARD.with(|g| g.set(true));
    let result = std::panic::catch_unwind(std::panic::AssertUnwindSafe(f));
    IN_GLTF_GUARD.with(|g| g.set(false));
    result.unwrap_or_else(|panic| {
        let why = panic
            .downcast_ref::<&str>()
            .map(|s| s.to_string())
            .or_else(|| panic.downcast_ref::<String>().cloned())
            .unwrap_or_else(|| "unknown".into());
        Err(SceneError::Gltf { path: path.to_path_buf(), message: format!("malformed document ({why})") })
    })
}

/// Loads a glTF or GLB file (its buffers, textures, lights, camera and animations) as a scene.
pub fn load_gltf(path: &Path) -> Result<Scene> {
    guarded(path, || load_gltf_unguarded(path))
}

fn load_gltf_unguarded(path: &Path) -> Result<Scene> {
    if !path.exists() {
        return Err(SceneError::Io {
            path: path.to_path_buf(),
            cause: std::io::Error::new(std::io::ErrorKind::NotFound, "file not found"),
        });
    }
    check_glb_header(path)?;
    check_required_extensions(path)?;
    check_external_files(path)?;
    let gltf_err = |e: gltf::Error| SceneError::Gltf { path: path.to_path_buf(), message: e.to_string() };
    let gltf::Gltf { document: doc, blob } = gltf::Gltf::open(path).map_err(gltf_err)?;
    let base = path.parent();
    let buffers = gltf::import_buffers(&doc, base, blob).map_err(gltf_err)?;
    let mut warnings = unfollowed_extension_warnings(path, &doc);
    let images: Vec<Option<gltf::image::Data>> = doc
        .images()
        .map(|im| {
            let name = match im.source() {
                gltf::image::Source::Uri { uri, .. } if !uri.starts_with("data:") => {
                    format!("`{}`", base.unwrap_or(Path::new(".")).join(decode_uri(uri)).display())
                }
                _ => "(embedded)".to_string(),
            };
            gltf::image::Data::from_source(im.source(), base, &buffers)
                .map_err(|e| {
                    warnings.push(format!(
                        "{}: image {} {name} could not be read ({e}); textures using it are ignored",
                        path.display(),
                        im.index()
                    ))
                })
                .ok()
        })
        .collect();
    check_json_indices(path, doc.as_json())?;
    let mut loader = Loader {
        path,
        buffers,
        images,
        scene: Scene { name: path.display().to_string(), warnings, ..Default::default() },
        material_ids: HashMap::new(),
        texture_ids: HashMap::new(),
        channels: HashMap::new(),
        skipped_primitives: Vec::new(),
    };
    loader.read_animations(&doc)?;
    let roots: Vec<gltf::Node> = match doc.default_scene().or_else(|| doc.scenes().next()) {
        Some(s) => s.nodes().collect(),
        // No scene: every node that is nobody's child is a root (glTF 2.0 §3.5.2
        // leaves the choice to the loader; a child must not be drawn twice).
        None => {
            let children: std::collections::HashSet<usize> =
                doc.nodes().flat_map(|n| n.children().map(|c| c.index()).collect::<Vec<_>>()).collect();
            doc.nodes().filter(|n| !children.contains(&n.index())).collect()
        }
    };
    for node in roots {
        loader.visit(&node, Mat4::IDENTITY, &[], &mut Vec::new())?;
    }
    if loader.scene.mesh.triangles.is_empty() {
        let skipped = &loader.skipped_primitives;
        let message = if skipped.is_empty() {
            "no triangle primitives".to_string()
        } else {
            format!("no triangle primitives (points and lines are not drawn: {})", skipped.join(", "))
        };
        return Err(SceneError::Invalid { path: path.to_path_buf(), message });
    }
    Ok(loader.scene)
}

impl Loader<'_> {
    fn err(&self, message: String) -> SceneError {
        SceneError::Gltf { path: self.path.to_path_buf(), message }
    }

    /// Reads every animation's TRS channels into `self.channels`.
    fn read_animations(&mut self, doc: &gltf::Document) -> Result<()> {
        for anim in doc.animations() {
            for ch in anim.channels() {
                self.read_channel(&anim, &ch)?;
            }
        }
        Ok(())
    }

    /// Reads one animation channel's key times and values into `self.channels`.
    fn read_channel(&mut self, anim: &gltf::Animation<'_>, ch: &gltf::animation::Channel<'_>) -> Result<()> {
        use gltf::animation::util::ReadOutputs;
        use gltf::animation::{Interpolation, Property};
        let node = ch.target().node().index();
        let what = format!("animation {} channel {}", anim.index(), ch.index());
        self.check_channel_accessors(ch, &what)?;
        let buffers = &self.buffers;
        let reader = ch.reader(|b| buffers.get(b.index()).map(|d| &d.0[..]));
        let times: Vec<f32> =
            reader.read_inputs().ok_or_else(|| self.err(format!("{what}: no input times")))?.collect();
        if times.iter().any(|t| !t.is_finite()) || times.windows(2).any(|w| w[1] < w[0]) {
            return Err(self.err(format!("{what}: key times must be finite and increasing")));
        }
        let interpolation = ch.sampler().interpolation();
        if interpolation == Interpolation::CubicSpline {
            self.scene.warnings.push(format!(
                "{}: {what}: CUBICSPLINE interpolated linearly between its key values",
                self.path.display()
            ));
        }
        // CUBICSPLINE outputs are (in-tangent, value, out-tangent) triples.
        let pick = |k: usize| if interpolation == Interpolation::CubicSpline { 3 * k + 1 } else { k };
        let outputs = reader.read_outputs().ok_or_else(|| self.err(format!("{what}: no outputs")))?;
        let keys_of = |values: Vec<[f32; 4]>| -> Option<Vec<(f32, [f32; 4])>> {
            let mut keys = Vec::new();
            for (k, &t) in times.iter().enumerate() {
                let v = *values.get(pick(k))?;
                if interpolation == Interpolation::Step
                    && let Some(&(_, prev)) = keys.last()
                {
                    // Hold the previous value up to just before this key.
                    keys.push(((t - 1e-4).max(0.0), prev));
                }
                keys.push((t, v));
            }
            Some(keys)
        };
        let path = self.path;
        let short = || SceneError::Gltf {
            path: path.to_path_buf(),
            message: format!("{what}: fewer output values than key times"),
        };
        let entry = self.channels.entry(node).or_default();
        match (ch.target().property(), outputs) {
            (Property::Translation, ReadOutputs::Translations(it)) => {
                let keys = keys_of(it.map(|v| [v[0], v[1], v[2], 0.0]).collect()).ok_or_else(short)?;
                entry.translation = keys.into_iter().map(|(t, v)| (t, Vec3::new(v[0], v[1], v[2]))).collect();
            }
            (Property::Rotation, ReadOutputs::Rotations(it)) => {
                let keys = keys_of(it.into_f32().collect()).ok_or_else(short)?;
                entry.rotation = keys.into_iter().map(|(t, v)| (t, Quat::from_array(v).normalize())).collect();
            }
            (Property::Scale, ReadOutputs::Scales(it)) => {
                let keys = keys_of(it.map(|v| [v[0], v[1], v[2], 0.0]).collect()).ok_or_else(short)?;
                entry.scale = keys.into_iter().map(|(t, v)| (t, Vec3::new(v[0], v[1], v[2]))).collect();
            }
            _ => self.scene.warnings.push(format!("{}: {what}: morph-target weights are not animated", path.display())),
        }
        Ok(())
    }

    /// Checks a channel's input (times) and output (values) accessors against
    /// the types its target property allows.
    fn check_channel_accessors(&self, ch: &gltf::animation::Channel<'_>, what: &str) -> Result<()> {
        use gltf::accessor::{DataType as T, Dimensions as D};
        use gltf::animation::Property;
        let sampler = ch.sampler();
        check_accessor(self.path, &self.buffers, &sampler.input(), &[(T::F32, D::Scalar)], what)?;
        let out: &[(T, D)] = match ch.target().property() {
            Property::Rotation => {
                &[(T::F32, D::Vec4), (T::I8, D::Vec4), (T::U8, D::Vec4), (T::I16, D::Vec4), (T::U16, D::Vec4)]
            }
            Property::MorphTargetWeights => {
                &[(T::F32, D::Scalar), (T::I8, D::Scalar), (T::U8, D::Scalar), (T::I16, D::Scalar), (T::U16, D::Scalar)]
            }
            _ => &[(T::F32, D::Vec3)],
        };
        check_accessor(self.path, &self.buffers, &sampler.output(), out, what)?;
        Ok(())
    }

    /// Visits `node` under `parent` (its world matrix at rest); `chain` lists the
    /// animated ancestors' nodes, root first.
    /// `path` holds the node indices from the root to `node`'s parent (cycle check).
    fn visit<'n>(
        &mut self,
        node: &gltf::Node<'n>,
        parent: Mat4,
        chain: &[gltf::Node<'n>],
        path: &mut Vec<usize>,
    ) -> Result<()> {
        if path.contains(&node.index()) {
            return Err(self.err(format!("node {} is its own ancestor (a cycle in the node hierarchy)", node.index())));
        }
        if path.len() >= MAX_NODE_DEPTH {
            return Err(
                self.err(format!("node hierarchy deeper than {MAX_NODE_DEPTH} levels at node {}", node.index()))
            );
        }
        let world = parent * Mat4::from_cols_array_2d(&node.transform().matrix());
        if !world.is_finite() {
            return Err(self.err(format!("node {} has a non-finite transform", node.index())));
        }
        let mut chain = chain.to_vec();
        chain.push(node.clone());
        let animated = chain.iter().any(|n| self.channels.contains_key(&n.index()));
        if let Some(mesh) = node.mesh() {
            let (t0, v0) = (self.scene.mesh.triangle_count() as u32, self.scene.mesh.positions.len() as u32);
            for prim in mesh.primitives() {
                self.add_primitive(&mesh, &prim, world)?;
            }
            if animated {
                self.add_animated_object(node, &chain, world, t0, v0)?;
            }
        }
        if animated && (node.light().is_some() || node.camera().is_some()) {
            self.scene.warnings.push(format!(
                "{}: node {}: animated lights and cameras stay at their rest pose",
                self.path.display(),
                node.index()
            ));
        }
        if let Some(light) = node.light() {
            let position = world.transform_point3(Vec3::ZERO);
            let direction = world.transform_vector3(Vec3::NEG_Z).normalize_or_zero();
            let (kind, inner, outer) = match light.kind() {
                gltf::khr_lights_punctual::Kind::Directional => (LightKind::Directional, 0.0, 0.0),
                gltf::khr_lights_punctual::Kind::Point => (LightKind::Point, 0.0, 0.0),
                gltf::khr_lights_punctual::Kind::Spot { inner_cone_angle, outer_cone_angle } => {
                    (LightKind::Spot, inner_cone_angle, outer_cone_angle)
                }
            };
            let l = PunctualLight {
                kind,
                position,
                direction,
                color: Vec3::from(light.color()),
                intensity: light.intensity(),
                range: light.range(),
                inner_cone_angle: inner,
                outer_cone_angle: if kind == LightKind::Spot { outer } else { std::f32::consts::FRAC_PI_4 },
                keyframes: Vec::new(),
            };
            l.validate().map_err(|e| self.err(format!("light {}: {e}", light.index())))?;
            self.scene.lights.push(l);
        }
        if let (Some(cam), None) = (node.camera(), self.scene.camera)
            && let gltf::camera::Projection::Perspective(p) = cam.projection()
        {
            let position = world.transform_point3(Vec3::ZERO);
            self.scene.camera = Some(Camera {
                position,
                target: position + world.transform_vector3(Vec3::NEG_Z).normalize_or_zero(),
                up: world.transform_vector3(Vec3::Y).normalize_or_zero(),
                fov_y_deg: p.yfov().to_degrees(),
            });
        }
        path.push(node.index());
        for child in node.children() {
            self.visit(&child, world, &chain, path)?;
        }
        path.pop();
        Ok(())
    }

    /// The mesh node's triangles from `t0` / vertices from `v0` as a rigid object
    /// following its animated ancestor chain (see the module docs).
    fn add_animated_object(
        &mut self,
        node: &gltf::Node,
        chain: &[gltf::Node],
        rest_world: Mat4,
        t0: u32,
        v0: u32,
    ) -> Result<()> {
        let mut times: Vec<f32> =
            chain.iter().filter_map(|n| self.channels.get(&n.index())).flat_map(|c| c.times()).collect();
        times.sort_by(f32::total_cmp);
        times.dedup();
        let mut samples = vec![];
        for (k, &t) in times.iter().enumerate() {
            samples.push(t);
            if let Some(&next) = times.get(k + 1) {
                samples.extend((1..4).map(|i| t + (next - t) * i as f32 / 4.0));
            }
        }
        let rest_inverse = rest_world.inverse();
        let empty = NodeChannels::default();
        let mut keyframes = vec![];
        for &t in &samples {
            let world = chain
                .iter()
                .fold(Mat4::IDENTITY, |m, n| m * self.channels.get(&n.index()).unwrap_or(&empty).local(n, t));
            let (scale, rotation, translation) = (world * rest_inverse).to_scale_rotation_translation();
            if !(scale.is_finite() && rotation.is_finite() && translation.is_finite()) || scale.min_element() <= 0.0 {
                return Err(
                    self.err(format!("node {}: animated transform at {t} s is degenerate or mirrored", node.index()))
                );
            }
            keyframes.push(TransformKeyframe {
                frame: t,
                translation: Some(translation),
                rotation: Some(rotation),
                scale: Some(scale),
            });
        }
        let mesh = &self.scene.mesh;
        self.scene.objects.push(SceneObject {
            name: node.name().map_or_else(|| format!("node {}", node.index()), str::to_string),
            first_triangle: t0,
            triangle_count: mesh.triangle_count() as u32 - t0,
            first_vertex: v0,
            vertex_count: mesh.positions.len() as u32 - v0,
            pivot_m: Vec3::ZERO,
            animation: ObjectAnimation {
                keyframes,
                clock: KeyClock::Seconds { frames_per_second: self.scene.frames_per_second },
                motion: None,
            },
            placement: Mat4::IDENTITY,
        });
        Ok(())
    }

    fn add_primitive(&mut self, mesh: &gltf::Mesh, prim: &gltf::Primitive, world: Mat4) -> Result<()> {
        use gltf::mesh::Mode;
        let what = format!("mesh {} (`{}`) primitive {}", mesh.index(), mesh.name().unwrap_or(""), prim.index());
        if !matches!(prim.mode(), Mode::Triangles | Mode::TriangleStrip | Mode::TriangleFan) {
            self.skipped_primitives.push(format!("{what} ({:?})", prim.mode()));
            self.scene.warnings.push(format!(
                "{}: {what}: mode {:?} skipped (points and lines have no surface to shade)",
                self.path.display(),
                prim.mode()
            ));
            return Ok(());
        }
        self.check_primitive(prim, &what)?;
        let material = self.material(prim.material())?;
        let Some(mut local) = self.read_primitive(prim, &what, material)? else {
            return Ok(());
        };
        let needs: Vec<bool> = local.normals.iter().map(|v| !(v.is_finite() && v.length_squared() > 0.0)).collect();
        if needs.iter().any(|&b| b) {
            local.derive_normals(&vec![NormalSource::Flat; local.triangle_count()], &needs, 180.0);
        }
        for v in &mut local.normals {
            *v = v.normalize_or(Vec3::Y);
        }
        let m = &self.scene.materials[material as usize];
        let (normal_mapped, normal_uv) = (m.normal_texture.is_some(), m.normal_uv);
        if normal_mapped && local.tangents.iter().all(|t| *t == Vec4::ZERO) && !tangents_for(&mut local, normal_uv) {
            self.scene.warnings.push(format!(
                "{}: {what}: MikkTSpace could not build tangents; its normal map is ignored",
                self.path.display()
            ));
        }
        local.transform(world);
        self.scene.mesh.append(&local, 0);
        Ok(())
    }

    /// Every accessor of a triangle primitive that the loader reads, checked
    /// before the library reads it (glTF 2.0 §3.7.2.1's types per attribute).
    fn check_primitive(&self, prim: &gltf::Primitive, what: &str) -> Result<()> {
        use gltf::accessor::{DataType as T, Dimensions as D};
        use gltf::mesh::Semantic;
        let check = |a: &gltf::Accessor, allowed: &[(T, D)], name: &str| {
            check_accessor(self.path, &self.buffers, a, allowed, &format!("{what}: {name}"))
        };
        let pos = prim.get(&Semantic::Positions).ok_or_else(|| self.err(format!("{what}: no POSITION attribute")))?;
        check(&pos, &[(T::F32, D::Vec3)], "POSITION")?;
        if let Some(a) = prim.get(&Semantic::Normals) {
            check(&a, &[(T::F32, D::Vec3)], "NORMAL")?;
        }
        if let Some(a) = prim.get(&Semantic::Tangents) {
            check(&a, &[(T::F32, D::Vec4)], "TANGENT")?;
        }
        for set in 0..2 {
            if let Some(a) = prim.get(&Semantic::TexCoords(set)) {
                check(&a, &[(T::F32, D::Vec2), (T::U8, D::Vec2), (T::U16, D::Vec2)], &format!("TEXCOORD_{set}"))?;
            }
        }
        if let Some(a) = prim.get(&Semantic::Colors(0)) {
            let colors = [T::F32, T::U8, T::U16].into_iter().flat_map(|t| [(t, D::Vec3), (t, D::Vec4)]);
            check(&a, &colors.collect::<Vec<_>>(), "COLOR_0")?;
        }
        if let Some(a) = prim.indices() {
            check(&a, &[(T::U8, D::Scalar), (T::U16, D::Scalar), (T::U32, D::Scalar)], "indices")?;
        }
        Ok(())
    }

    /// The primitive's vertices and triangles in its local space, every
    /// triangle with `material` (`None` when it has no triangles).
    fn read_primitive(&mut self, prim: &gltf::Primitive, what: &str, material: u32) -> Result<Option<Mesh>> {
        let buffers = &self.buffers;
        let reader = prim.reader(|b| buffers.get(b.index()).map(|d| &d.0[..]));
        let positions: Vec<Vec3> = reader
            .read_positions()
            .ok_or_else(|| self.err(format!("{what}: no POSITION attribute")))?
            .map(Vec3::from)
            .collect();
        if let Some(i) = positions.iter().position(|p| !p.is_finite()) {
            return Err(self.err(format!("{what}: vertex {i} has a non-finite position")));
        }
        let n = positions.len();
        let normals: Option<Vec<Vec3>> = reader.read_normals().map(|it| it.map(Vec3::from).collect());
        let read_uvs = |set| reader.read_tex_coords(set).map(|tc| tc.into_f32().map(Vec2::from).collect::<Vec<_>>());
        let (uvs, uvs1) = (read_uvs(0).unwrap_or_else(|| vec![Vec2::ZERO; n]), read_uvs(1).unwrap_or_default());
        let colors: Vec<Vec4> =
            reader.read_colors(0).map(|c| c.into_rgba_f32().map(Vec4::from).collect()).unwrap_or_default();
        let indices: Vec<u32> = match reader.read_indices() {
            Some(ix) => ix.into_u32().collect(),
            None => (0..n as u32).collect(),
        };
        if let Some(&bad) = indices.iter().find(|&&i| i as usize >= n) {
            return Err(self.err(format!("{what}: index {bad} out of range ({n} vertices)")));
        }
        let triangles = triangles_of(prim.mode(), &indices)
            .ok_or_else(|| self.err(format!("{what}: index count {} is not a multiple of 3", indices.len())))?;
        let counts_differ = uvs.len() != n
            || normals.as_ref().is_some_and(|v| v.len() != n)
            || !(uvs1.is_empty() || uvs1.len() == n)
            || !(colors.is_empty() || colors.len() == n);
        if counts_differ {
            return Err(self.err(format!("{what}: attribute counts differ from POSITION ({n})")));
        }
        // glTF §3.7.2.1: without NORMAL, flat normals, and TANGENT is ignored.
        let tangents: Vec<Vec4> = match (&normals, reader.read_tangents()) {
            (Some(_), Some(t)) => t.map(Vec4::from).map(|t| if t.is_finite() { t } else { Vec4::ZERO }).collect(),
            _ => vec![],
        };
        if !tangents.is_empty() && tangents.len() != n {
            return Err(self.err(format!("{what}: attribute counts differ from POSITION ({n})")));
        }
        let colors = self.vertex_colors(colors, material, what);
        self.warn_missing_second_set(material, uvs1.is_empty(), what);
        if triangles.is_empty() {
            return Ok(None);
        }
        Ok(Some(Mesh {
            positions,
            normals: normals.unwrap_or_else(|| vec![Vec3::ZERO; n]),
            uvs,
            uvs1,
            colors,
            triangle_materials: vec![material; triangles.len()],
            triangles,
            tangents,
        }))
    }

    /// `COLOR_0`'s RGB, clamped to [0, 1] as glTF 2.0 §3.7.2.1 requires (with a
    /// warning where it was not); its alpha is not a coverage (a warning says
    /// so where it is below 1 on a cut-out material).
    fn vertex_colors(&mut self, colors: Vec<Vec4>, material: u32, what: &str) -> Vec<Vec3> {
        let file = self.path.display();
        if colors.iter().any(|c| !(c.cmpge(Vec4::ZERO).all() && c.cmple(Vec4::ONE).all())) {
            self.scene.warnings.push(format!("{file}: {what}: COLOR_0 outside [0, 1] (or not finite) is clamped"));
        }
        let m = &self.scene.materials[material as usize];
        if m.alpha_mode != crate::material::AlphaMode::Opaque && colors.iter().any(|c| c.w < 1.0) {
            self.scene
                .warnings
                .push(format!("{file}: {what}: COLOR_0's alpha is not used for alpha cutouts (material `{}`)", m.name));
        }
        let unit = |v: f32| if v.is_nan() { 0.0 } else { v.clamp(0.0, 1.0) };
        colors.into_iter().map(|c| Vec3::new(unit(c.x), unit(c.y), unit(c.z))).collect()
    }

    /// A warning when the material's textures read `TEXCOORD_1` and the
    /// primitive has none (they read `TEXCOORD_0` instead).
    fn warn_missing_second_set(&mut self, material: u32, missing: bool, what: &str) {
        let m = &self.scene.materials[material as usize];
        let slots = [
            (m.base_color_texture, m.base_color_uv),
            (m.emissive_texture, m.emissive_uv),
            (m.normal_texture, m.normal_uv),
            (m.metallic_roughness_texture, m.metallic_roughness_uv),
        ];
        if missing && slots.iter().any(|(t, uv)| t.is_some() && uv.set == 1) {
            self.scene.warnings.push(format!(
                "{}: {what}: material `{}` reads TEXCOORD_1, which the primitive lacks; TEXCOORD_0 is used",
                self.path.display(),
                m.name
            ));
        }
    }

    fn material(&mut self, mat: gltf::Material) -> Result<u32> {
        let key = mat.index();
        if let Some(&id) = self.material_ids.get(&key) {
            return Ok(id);
        }
        let m = self.build_material(&mat)?;
        self.warn_cutout_sampling(&m);
        self.scene.materials.push(m);
        let id = (self.scene.materials.len() - 1) as u32;
        self.material_ids.insert(key, id);
        Ok(id)
    }

    /// glTF 2.0 §3.9: the metallic-roughness parameters and their textures
    /// (each with its coordinate set and KHR_texture_transform), normal and
    /// emissive textures, alpha mode; out-of-range factors clamped with a warning.
    fn build_material(&mut self, mat: &gltf::Material) -> Result<Material> {
        use crate::material::{AlphaMode, DEFAULT_ALPHA_CUTOFF};
        let name = mat.name().unwrap_or("gltf-default").to_string();
        let pbr = mat.pbr_metallic_roughness();
        let (base_color_texture, base_color_uv) =
            self.texture_slot(pbr.base_color_texture().as_ref().map(TextureRef::of_info), &name)?;
        let (metallic_roughness_texture, metallic_roughness_uv) =
            self.texture_slot(pbr.metallic_roughness_texture().as_ref().map(TextureRef::of_info), &name)?;
        let (emissive_texture, emissive_uv) =
            self.texture_slot(mat.emissive_texture().as_ref().map(TextureRef::of_info), &name)?;
        let normal = mat.normal_texture();
        let normal_ref = normal
            .as_ref()
            .map(TextureRef::of_normal)
            .transpose()
            .map_err(|e| self.err(format!("material `{name}`: normalTexture: KHR_texture_transform: {e}")))?;
        let (normal_texture, normal_uv) = self.texture_slot(normal_ref, &name)?;
        let normal_scale = normal.map_or(1.0, |n| n.scale());
        let alpha_mode = match mat.alpha_mode() {
            gltf::material::AlphaMode::Opaque => AlphaMode::Opaque,
            gltf::material::AlphaMode::Mask => {
                AlphaMode::Mask { cutoff: mat.alpha_cutoff().unwrap_or(DEFAULT_ALPHA_CUTOFF) }
            }
            gltf::material::AlphaMode::Blend => AlphaMode::Mask { cutoff: DEFAULT_ALPHA_CUTOFF },
        };
        if let AlphaMode::Mask { cutoff } = alpha_mode
            && (cutoff.is_nan() || cutoff < 0.0)
        {
            return Err(self.err(format!("material `{name}`: alphaCutoff {cutoff} must be ≥ 0")));
        }
        if !normal_scale.is_finite() {
            return Err(self.err(format!("material `{name}`: normalTexture.scale {normal_scale} is not finite")));
        }
        let bc = pbr.base_color_factor();
        let (roughness, metallic, alpha) = self.unit_factors(
            &name,
            [pbr.roughness_factor(), pbr.metallic_factor(), bc[3]],
            ["roughnessFactor", "metallicFactor", "baseColorFactor alpha"],
        );
        Ok(Material {
            base_color_factor: Vec3::new(bc[0], bc[1], bc[2]),
            base_color_texture,
            base_color_uv,
            emissive_factor: Vec3::from(mat.emissive_factor()),
            emissive_texture,
            emissive_uv,
            emissive_strength: mat.emissive_strength().unwrap_or(1.0),
            roughness,
            metallic,
            metallic_roughness_texture,
            metallic_roughness_uv,
            specular_model: crate::material::SpecularModel::MetallicRoughness,
            alpha_mode,
            alpha_factor: alpha,
            alpha_texture: base_color_texture.filter(|&t| self.scene.textures[t].alpha.is_some()),
            normal_texture,
            normal_uv,
            normal_scale,
            ..Material::default_grey(&name)
        })
    }

    /// Factors glTF 2.0 §5.22 keeps in [0, 1] (roughness, metallic, alpha),
    /// clamped with a warning when outside (NaN becomes 0).
    fn unit_factors(&mut self, material: &str, values: [f32; 3], names: [&str; 3]) -> (f32, f32, f32) {
        let mut unit = |v: f32, what: &str| {
            if (0.0..=1.0).contains(&v) {
                return v;
            }
            let clamped = if v.is_nan() { 0.0 } else { v.clamp(0.0, 1.0) };
            self.scene.warnings.push(format!(
                "{}: material `{material}`: {what} {v} is outside [0, 1]; using {clamped}",
                self.path.display()
            ));
            clamped
        };
        (unit(values[0], names[0]), unit(values[1], names[1]), unit(values[2], names[2]))
    }

    /// Alpha cutouts are tested inside traversal with `TEXCOORD_0`, repeat
    /// addressing, bilinear filtering and no transform (`bvh/cutouts.rs`): a warning
    /// where a cut-out material's base-colour texture asks for more.
    fn warn_cutout_sampling(&mut self, m: &Material) {
        let Some(t) = m.alpha_texture.filter(|_| m.has_cutout()) else { return };
        let plain_sampler = self.scene.textures[t].sampler == crate::texture::Sampler::default();
        if !plain_sampler || m.base_color_uv != UvMapping::IDENTITY {
            self.scene.warnings.push(format!(
                "{}: material `{}`: its alpha cutout is tested with TEXCOORD_0, repeat addressing, bilinear \
                 filtering and no texture transform, unlike its base colour",
                self.path.display(),
                m.name
            ));
        }
    }

    /// A texture reference as the material stores it: the texture (`None` when
    /// it cannot be used; a warning says why) and its coordinates. glTF 2.0
    /// §3.9.2 `texCoord`, overridden by KHR_texture_transform's when given.
    fn texture_slot(&mut self, r: Option<TextureRef>, material: &str) -> Result<(Option<usize>, UvMapping)> {
        let Some(r) = r else { return Ok((None, UvMapping::IDENTITY)) };
        let set = r.transform.and_then(|t| t.tex_coord).unwrap_or(r.tex_coord);
        if set > 1 {
            self.scene.warnings.push(format!(
                "{}: material `{material}`: texture {} uses TEXCOORD_{set}; probegi reads sets 0 and 1, texture ignored",
                self.path.display(),
                r.texture.index()
            ));
            return Ok((None, UvMapping::IDENTITY));
        }
        let mapping = match r.transform {
            Some(t) => {
                if !(t.offset.is_finite() && t.rotation.is_finite() && t.scale.is_finite()) {
                    return Err(self.err(format!(
                        "material `{material}`: texture {}: KHR_texture_transform has a non-finite value",
                        r.texture.index()
                    )));
                }
                UvMapping::texture_transform(set, t.offset, t.rotation, t.scale)
            }
            None => UvMapping { set, ..UvMapping::IDENTITY },
        };
        Ok((self.texture(r.texture)?, mapping))
    }

    /// The scene texture of a glTF texture (its image read through its
    /// sampler, glTF 2.0 §3.8), shared by every reference to the same image and
    /// sampler; `None` when its image could not be read.
    fn texture(&mut self, tex: gltf::Texture) -> Result<Option<usize>> {
        let img_index = tex.source().index();
        let key = (img_index, tex.sampler().index());
        if let Some(&id) = self.texture_ids.get(&key) {
            return Ok(id);
        }
        let Some(data) = self.images.get(img_index).ok_or_else(|| self.err(format!("image {img_index} missing")))?
        else {
            self.texture_ids.insert(key, None);
            return Ok(None);
        };
        use gltf::image::Format;
        let channels = match data.format {
            Format::R8 => 1,
            Format::R8G8 => 2,
            Format::R8G8B8 => 3,
            Format::R8G8B8A8 => 4,
            other => {
                self.scene.warnings.push(format!(
                    "{}: image {img_index} has unsupported format {other:?}; texture ignored",
                    self.path.display()
                ));
                self.texture_ids.insert(key, None);
                return Ok(None);
            }
        };
        let texels: Vec<[u8; 3]> = data
            .pixels
            .chunks_exact(channels)
            .map(|p| match channels {
                1 | 2 => [p[0]; 3],
                _ => [p[0], p[1], p[2]],
            })
            .collect();
        let mismatch = || self.err(format!("image {img_index}: pixel data does not match its size"));
        let mut t =
            Texture::from_rgb8(data.width, data.height, texels, format!("{} image {img_index}", self.path.display()))
                .ok_or_else(mismatch)?;
        if channels == 2 || channels == 4 {
            let alpha = data.pixels.chunks_exact(channels).map(|p| p[channels - 1]).collect();
            t = t.with_alpha(alpha).ok_or_else(mismatch)?;
        }
        self.scene.textures.push(t.with_sampler(sampler_of(&tex.sampler())));
        let id = Some(self.scene.textures.len() - 1);
        self.texture_ids.insert(key, id);
        Ok(id)
    }
}

/// A material's reference to a texture, from a `textureInfo` or a
/// `normalTextureInfo`.
struct TextureRef<'a> {
    texture: gltf::Texture<'a>,
    tex_coord: u32,
    transform: Option<TextureTransform>,
}

/// KHR_texture_transform's values.
#[derive(Clone, Copy)]
struct TextureTransform {
    offset: Vec2,
    rotation: f32,
    scale: Vec2,
    tex_coord: Option<u32>,
}

impl<'a> TextureRef<'a> {
    fn of_info(info: &gltf::texture::Info<'a>) -> Self {
        let transform = info.texture_transform().map(|t| TextureTransform {
            offset: Vec2::from(t.offset()),
            rotation: t.rotation(),
            scale: Vec2::from(t.scale()),
            tex_coord: t.tex_coord(),
        });
        Self { texture: info.texture(), tex_coord: info.tex_coord(), transform }
    }

    /// The library does not parse KHR_texture_transform on normal textures;
    /// it is read here from the extension's JSON (malformed JSON is an error,
    /// as the library makes it on other texture references).
    fn of_normal(info: &gltf::material::NormalTexture<'a>) -> std::result::Result<Self, String> {
        use gltf::json::extensions::texture::TextureTransform as Json;
        let transform = match info.extension_value("KHR_texture_transform") {
            Some(v) => {
                let t = gltf::json::deserialize::from_value::<Json>(v.clone()).map_err(|e| e.to_string())?;
                Some(TextureTransform {
                    offset: Vec2::from(t.offset.0),
                    rotation: t.rotation.0,
                    scale: Vec2::from(t.scale.0),
                    tex_coord: t.tex_coord,
                })
            }
            None => None,
        };
        Ok(Self { texture: info.texture(), tex_coord: info.tex_coord(), transform })
    }
}

/// MikkTSpace tangents over the coordinates the normal map reads (§3.7.2.1:
/// "the texture coordinates associated with the normal texture", its set and
/// KHR_texture_transform), the mesh's own coordinates kept; false when the
/// algorithm gave up.
fn tangents_for(mesh: &mut Mesh, normal_uv: UvMapping) -> bool {
    if normal_uv == UvMapping::IDENTITY {
        return mesh.generate_tangents().is_some();
    }
    let uvs = mesh.uvs.clone();
    mesh.uvs = (0..uvs.len()).map(|v| normal_uv.apply(&mesh.vertex_attributes(v))).collect();
    let Some(old) = mesh.generate_tangents() else {
        mesh.uvs = uvs;
        return false;
    };
    mesh.uvs = old.iter().map(|&v| uvs[v as usize]).collect();
    true
}

/// glTF 2.0 §3.8.4: wrap modes as given; the filter is `magFilter` (every
/// lookup is treated as magnification, see `texture.rs`), else the §3.8.4.2
/// no-mipmap fallback of `minFilter`, else linear.
fn sampler_of(s: &gltf::texture::Sampler) -> Sampler {
    use gltf::texture::{MagFilter, MinFilter, WrappingMode};
    let wrap = |w| match w {
        WrappingMode::Repeat => Wrap::Repeat,
        WrappingMode::MirroredRepeat => Wrap::MirroredRepeat,
        WrappingMode::ClampToEdge => Wrap::ClampToEdge,
    };
    let filter = match (s.mag_filter(), s.min_filter()) {
        (Some(MagFilter::Nearest), _) => Filter::Nearest,
        (Some(MagFilter::Linear), _) => Filter::Linear,
        (None, Some(MinFilter::Nearest | MinFilter::NearestMipmapNearest | MinFilter::NearestMipmapLinear)) => {
            Filter::Nearest
        }
        (None, _) => Filter::Linear,
    };
    Sampler { wrap_u: wrap(s.wrap_s()), wrap_v: wrap(s.wrap_t()), filter }
}

/// The triangles a primitive's indices describe (glTF 2.0 §3.7.2.1,
/// topology types): lists as they are, `None` when their count is not a
/// multiple of 3; strips `p_i = {v_i, v_(i+1+i%2), v_(i+2−i%2)}` (every other
/// triangle flipped, so all keep the first one's winding); fans `p_i =
/// {v_(i+1), v_(i+2), v_0}`. A strip's or fan's triangles that use a vertex
/// twice (degenerate joins, which the section advises against) are dropped.
fn triangles_of(mode: gltf::mesh::Mode, v: &[u32]) -> Option<Vec<[u32; 3]>> {
    use gltf::mesh::Mode;
    let corners: Vec<[u32; 3]> = match mode {
        Mode::Triangles if v.len().is_multiple_of(3) => {
            return Some(v.chunks_exact(3).map(|t| [t[0], t[1], t[2]]).collect());
        }
        Mode::Triangles => return None,
        Mode::TriangleStrip => {
            (0..v.len().saturating_sub(2)).map(|i| [v[i], v[i + 1 + i % 2], v[i + 2 - i % 2]]).collect()
        }
        Mode::TriangleFan => (0..v.len().saturating_sub(2)).map(|i| [v[i + 1], v[i + 2], v[0]]).collect(),
        _ => Vec::new(),
    };
    Some(corners.into_iter().filter(|[a, b, c]| a != b && b != c && a != c).collect())
}
