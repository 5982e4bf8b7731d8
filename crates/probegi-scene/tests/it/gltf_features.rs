//! glTF 2.0 features the loader reads, on small files written here: triangle
//! strips and fans (§3.7.2.1 topology), points and lines skipped by name,
//! `TEXCOORD_1` and `COLOR_0` (§3.7.2.1 attributes), the metallic-roughness
//! texture read linear (§3.9.2), samplers (§3.8.4), KHR_texture_transform on
//! every kind of texture reference, and extensions (§3.12): required ones
//! probegi does not follow are errors, used ones warnings, both naming them.

use std::path::{Path, PathBuf};

use glam::{Vec2, Vec3};
use probegi_scene::material::VertexAttributes;
use probegi_scene::texture::{Filter, Wrap};
use probegi_scene::{Scene, load_scene};

fn tmp_dir(name: &str) -> PathBuf {
    let d = std::env::temp_dir().join(format!("probegi-gltf-features-{}-{name}", std::process::id()));
    std::fs::create_dir_all(&d).expect("mkdir");
    d
}

/// A glTF document's binary buffer, buffer views and accessors, built up
/// attribute by attribute.
#[derive(Default)]
struct Buffers {
    bin: Vec<u8>,
    views: Vec<String>,
    accessors: Vec<String>,
}

impl Buffers {
    /// Appends `bytes` as a view and an accessor of `count` elements; returns
    /// the accessor's index.
    fn accessor(&mut self, bytes: &[u8], component_type: u32, count: usize, ty: &str, extra: &str) -> usize {
        while !self.bin.len().is_multiple_of(4) {
            self.bin.push(0);
        }
        let view = self.views.len();
        self.views.push(format!(r#"{{"buffer": 0, "byteOffset": {}, "byteLength": {}}}"#, self.bin.len(), bytes.len()));
        self.bin.extend_from_slice(bytes);
        self.accessors.push(format!(
            r#"{{"bufferView": {view}, "componentType": {component_type}, "count": {count}, "type": "{ty}"{extra}}}"#
        ));
        self.accessors.len() - 1
    }

    fn floats(&mut self, values: &[f32], width: usize, ty: &str) -> usize {
        let bytes: Vec<u8> = values.iter().flat_map(|v| v.to_le_bytes()).collect();
        let extra = if ty == "VEC3" && width == 3 {
            // POSITION needs its bounds.
            let axis = |k: usize| values.iter().skip(k).step_by(3).copied();
            let lo: Vec<f32> = (0..3).map(|k| axis(k).fold(f32::INFINITY, f32::min)).collect();
            let hi: Vec<f32> = (0..3).map(|k| axis(k).fold(f32::NEG_INFINITY, f32::max)).collect();
            format!(r#", "min": {lo:?}, "max": {hi:?}"#)
        } else {
            String::new()
        };
        self.accessor(&bytes, 5126, values.len() / width, ty, &extra)
    }

    fn indices(&mut self, values: &[u16]) -> usize {
        let bytes: Vec<u8> = values.iter().flat_map(|v| v.to_le_bytes()).collect();
        self.accessor(&bytes, 5123, values.len(), "SCALAR", "")
    }

    /// Writes `name.bin` and `name.gltf` (the JSON `body` plus buffers, views
    /// and accessors) into `dir`.
    fn write(&self, dir: &Path, name: &str, body: &str) -> PathBuf {
        std::fs::write(dir.join(format!("{name}.bin")), &self.bin).expect("write bin");
        let json = format!(
            r#"{{"asset": {{"version": "2.0"}}, {body},
              "buffers": [{{"uri": "{name}.bin", "byteLength": {}}}],
              "bufferViews": [{}], "accessors": [{}]}}"#,
            self.bin.len(),
            self.views.join(", "),
            self.accessors.join(", ")
        );
        let path = dir.join(format!("{name}.gltf"));
        std::fs::write(&path, json).expect("write gltf");
        path
    }
}

fn load(path: &Path) -> Scene {
    load_scene(&path.to_string_lossy()).unwrap_or_else(|e| panic!("{e}"))
}

fn face_z(s: &Scene, t: usize) -> f32 {
    s.mesh.face_normal_scaled(t).normalize().z
}

#[test]
fn strips_and_fans_become_triangles_with_one_winding_and_lines_are_skipped_by_name() {
    let dir = tmp_dir("modes");
    let mut b = Buffers::default();
    // A zigzag of 8 vertices, (k, 0) and (k, 1), joined by a degenerate pair.
    let zigzag: Vec<f32> = (0..8).flat_map(|i| [(i / 2) as f32, (i % 2) as f32, 0.0]).collect();
    let strip_pos = b.floats(&zigzag, 3, "VEC3");
    let strip_idx = b.indices(&[0, 1, 2, 3, 3, 4, 4, 5, 6, 7]);
    // A fan around the origin, counter-clockwise seen from +z.
    let fan: Vec<f32> =
        [[0.0, 0.0], [1.0, 0.0], [0.0, 1.0], [-1.0, 0.0], [0.0, -1.0]].iter().flat_map(|p| [p[0], p[1], 2.0]).collect();
    let fan_pos = b.floats(&fan, 3, "VEC3");
    let body = format!(
        r#""scene": 0, "scenes": [{{"nodes": [0, 1, 2]}}],
        "nodes": [{{"mesh": 0}}, {{"mesh": 1}}, {{"mesh": 2}}],
        "meshes": [
          {{"name": "zigzag", "primitives": [{{"attributes": {{"POSITION": {strip_pos}}}, "indices": {strip_idx}, "mode": 5}}]}},
          {{"name": "fan", "primitives": [{{"attributes": {{"POSITION": {fan_pos}}}, "mode": 6}}]}},
          {{"name": "wire", "primitives": [{{"attributes": {{"POSITION": {fan_pos}}}, "mode": 3}}]}}
        ]"#
    );
    let s = load(&b.write(&dir, "modes", &body));
    // Strip: 8 triangles, 4 of them degenerate (the join); every other one's
    // corners swapped, so all face −z like the first (0, 0), (0, 1), (1, 0).
    assert_eq!(s.mesh.triangle_count(), 4 + 3, "4 strip and 3 fan triangles");
    for t in 0..4 {
        assert!((face_z(&s, t) + 1.0).abs() < 1e-6, "strip triangle {t} faces {}", face_z(&s, t));
        assert!((s.mesh.area(t) - 0.5).abs() < 1e-6);
    }
    // Fan: p_i = {v_(i+1), v_(i+2), v_0}, counter-clockwise like its outline.
    for t in 4..7 {
        assert!((face_z(&s, t) - 1.0).abs() < 1e-6, "fan triangle {t} faces {}", face_z(&s, t));
    }
    assert!(s.warnings.iter().any(|w| w.contains("`wire`") && w.contains("LineStrip")), "{:?}", s.warnings);
    // A file of lines only: an error naming the file and what was skipped.
    let body = format!(
        r#""scene": 0, "scenes": [{{"nodes": [0]}}], "nodes": [{{"mesh": 0}}],
        "meshes": [{{"name": "wire", "primitives": [{{"attributes": {{"POSITION": {fan_pos}}}, "mode": 1}}]}}]"#
    );
    let path = b.write(&dir, "lines", &body);
    let e = load_scene(&path.to_string_lossy()).expect_err("nothing to draw").to_string();
    assert!(e.contains("lines.gltf") && e.contains("`wire`") && e.contains("no triangle primitives"), "{e}");
    std::fs::remove_dir_all(&dir).ok();
}

/// A unit quad with two coordinate sets and `COLOR_0` as normalized unsigned
/// bytes; its material's textures as `material` gives them, over images 0 (a
/// 2×2 metallic-roughness map) and 1 (a 4×1 colour ramp).
fn quad_file(dir: &Path, name: &str, material: &str, samplers: &str, with_uv1: bool) -> PathBuf {
    let mut b = Buffers::default();
    let pos = b.floats(&[0.0, 0.0, 0.0, 1.0, 0.0, 0.0, 1.0, 1.0, 0.0, 0.0, 1.0, 0.0], 3, "VEC3");
    let uv0 = b.floats(&[0.0, 0.0, 1.0, 0.0, 1.0, 1.0, 0.0, 1.0], 2, "VEC2");
    let uv1 = b.floats(&[0.5, 0.5, 2.5, 0.5, 2.5, 1.5, 0.5, 1.5], 2, "VEC2");
    let colors = [255u8, 0, 0, 255, 0, 255, 0, 255, 0, 0, 255, 255, 255, 255, 255, 128];
    let color = b.accessor(&colors, 5121, 4, "VEC4", r#", "normalized": true"#);
    let idx = b.indices(&[0, 1, 2, 0, 2, 3]);
    let uv1_attr = if with_uv1 { format!(r#", "TEXCOORD_1": {uv1}"#) } else { String::new() };
    let mr = image::RgbImage::from_fn(2, 2, |x, y| image::Rgb([255, if x == 0 { 128 } else { 255 }, (y * 200) as u8]));
    mr.save(dir.join("mr.png")).expect("png");
    let ramp = image::RgbImage::from_fn(4, 1, |x, _| image::Rgb([(x * 80) as u8, 50, 200]));
    ramp.save(dir.join("ramp.png")).expect("png");
    let body = format!(
        r#""extensionsUsed": ["KHR_texture_transform"],
        "scene": 0, "scenes": [{{"nodes": [0]}}], "nodes": [{{"mesh": 0}}],
        "meshes": [{{"name": "quad", "primitives": [{{"attributes": {{"POSITION": {pos}, "TEXCOORD_0": {uv0},
          "COLOR_0": {color}{uv1_attr}}}, "indices": {idx}, "material": 0}}]}}],
        "materials": [{material}],
        "images": [{{"uri": "mr.png"}}, {{"uri": "ramp.png"}}],
        "samplers": [{samplers}],
        "textures": [{{"source": 0, "sampler": 0}}, {{"source": 1, "sampler": 1}}]"#
    );
    b.write(dir, name, &body)
}

#[test]
fn metallic_roughness_samplers_second_sets_vertex_colours_and_transforms_are_read() {
    let dir = tmp_dir("material");
    let material = r#"{"name": "m", "pbrMetallicRoughness": {
        "roughnessFactor": 0.5, "metallicFactor": 1.0,
        "metallicRoughnessTexture": {"index": 0,
          "extensions": {"KHR_texture_transform": {"offset": [0.5, 0.0]}}},
        "baseColorTexture": {"index": 1, "texCoord": 1}},
      "normalTexture": {"index": 0, "scale": 0.7,
        "extensions": {"KHR_texture_transform": {"scale": [2.0, 3.0], "texCoord": 1}}},
      "emissiveFactor": [1, 1, 1], "emissiveTexture": {"index": 1, "texCoord": 2}}"#;
    // Image 0 repeats and filters linearly; image 1 clamps u, mirrors v, nearest.
    let samplers = r#"{}, {"magFilter": 9728, "minFilter": 9987, "wrapS": 33071, "wrapT": 33648}"#;
    let s = load(&quad_file(&dir, "material", material, samplers, true));
    let m = &s.materials[0];
    // The metallic-roughness map, read linear: G 128 at column 0 → 128/255 ×
    // 0.5 (sRGB decoding would give 0.216 × 0.5); B 0 at row 0, 200 at row 1.
    // Its transform's offset of 0.5 in u moves column 0's centre (0.25) to u = −0.25.
    let at = |u: f32, v: f32| VertexAttributes::at_uv(Vec2::new(u, v));
    let (r, metal) = m.roughness_metallic(&s.textures, &at(-0.25, 0.25));
    assert!((r - 0.5 * 128.0 / 255.0).abs() < 1e-6 && metal.abs() < 1e-6, "roughness {r}, metalness {metal}");
    let (r, metal) = m.roughness_metallic(&s.textures, &at(0.25, 0.75));
    assert!((r - 0.5).abs() < 1e-6 && (metal - 200.0 / 255.0).abs() < 1e-6, "roughness {r}, metalness {metal}");
    // The base colour reads TEXCOORD_1 through its sampler: clamp in u, nearest.
    let ramp = &s.textures[m.base_color_texture.expect("base colour texture")];
    assert_eq!(
        (ramp.sampler.wrap_u, ramp.sampler.wrap_v, ramp.sampler.filter),
        (Wrap::ClampToEdge, Wrap::MirroredRepeat, Filter::Nearest)
    );
    assert_eq!(m.base_color_uv.set, 1);
    let lut = probegi_core::color::srgb8_to_linear_table();
    let two_sets = VertexAttributes { uv: [Vec2::ZERO, Vec2::new(2.5, 0.5)], color: Vec3::new(1.0, 0.5, 1.0) };
    let c = m.base_color(&s.textures, &two_sets);
    // u = 2.5 clamps to the last texel (red 240), exactly (nearest); COLOR_0 multiplies it.
    let want = Vec3::new(lut[240], lut[50] * 0.5, lut[200]);
    assert!((c - want).abs().max_element() < 1e-6, "{c} vs {want}");
    // Nearest: u = 0.3 of the 4-texel ramp is texel 1 (red 80) with no blend.
    let c = m.base_color(&s.textures, &VertexAttributes { uv: [Vec2::ZERO, Vec2::new(0.3, 0.5)], color: Vec3::ONE });
    assert!((c.x - lut[80]).abs() < 1e-6, "{c}");
    // The normal map's transform is read from its extension's JSON, texCoord override included.
    assert_eq!((m.normal_uv.set, m.normal_uv.rows[0].x, m.normal_uv.rows[1].y, m.normal_scale), (1, 2.0, 3.0, 0.7));
    // TEXCOORD_2 is not read: the emissive texture is dropped, with a warning.
    assert!(m.emissive_texture.is_none());
    assert!(s.warnings.iter().any(|w| w.contains("TEXCOORD_2")), "{:?}", s.warnings);
    // COLOR_0 (normalized unsigned bytes) and TEXCOORD_1 per vertex.
    assert_eq!(s.mesh.colors[..3], [Vec3::X, Vec3::Y, Vec3::Z]);
    assert_eq!(s.mesh.uvs1[1], Vec2::new(2.5, 0.5));
    // A malformed transform on a normal texture is an error, as on the others.
    let bad = material.replace(r#""scale": [2.0, 3.0], "texCoord": 1"#, r#""scale": "large""#);
    let path = quad_file(&dir, "bad-transform", &bad, samplers, true);
    let e = load_scene(&path.to_string_lossy()).expect_err("malformed").to_string();
    assert!(e.contains("bad-transform.gltf") && e.contains("normalTexture"), "{e}");
    // MikkTSpace tangents follow the normal map's coordinates: turned a quarter
    // turn by its transform, u' runs along the quad's v, which is +y.
    let turned = r#"{"name": "n", "normalTexture": {"index": 0,
        "extensions": {"KHR_texture_transform": {"rotation": 1.5707964}}}}"#;
    let s = load(&quad_file(&dir, "turned", turned, samplers, true));
    assert!(!s.mesh.tangents.is_empty() && s.mesh.tangents.iter().all(|t| t.y.abs() > 0.999), "{:?}", s.mesh.tangents);
    assert_eq!(s.mesh.uvs[2], Vec2::ONE, "the mesh keeps its own coordinates");
    // Without TEXCOORD_1 on the primitive: a warning, and set 0 is read.
    let s = load(&quad_file(&dir, "no-uv1", material, samplers, false));
    assert!(s.warnings.iter().any(|w| w.contains("TEXCOORD_1")), "{:?}", s.warnings);
    assert_eq!(s.mesh.uv1(2), s.mesh.uvs[2]);
    std::fs::remove_dir_all(&dir).ok();
}

#[test]
fn required_extensions_probegi_does_not_follow_are_errors_and_used_ones_warnings() {
    let dir = tmp_dir("extensions");
    let material = r#"{"name": "m", "pbrMetallicRoughness": {"baseColorTexture": {"index": 1}}}"#;
    let base = quad_file(&dir, "base", material, "{}, {}", true);
    let json = std::fs::read_to_string(&base).expect("read");
    let with = |name: &str, extensions: &str| {
        let path = dir.join(format!("{name}.gltf"));
        let patched = json.replacen(r#""extensionsUsed": ["KHR_texture_transform"],"#, extensions, 1);
        assert_ne!(patched, json);
        std::fs::write(&path, patched).expect("write");
        path
    };
    let path = with(
        "volume",
        r#""extensionsUsed": ["KHR_materials_volume"], "extensionsRequired": ["KHR_materials_volume"],"#,
    );
    let e = load_scene(&path.to_string_lossy()).expect_err("required and not followed").to_string();
    assert!(e.contains("KHR_materials_volume") && e.contains("volume.gltf"), "{e}");
    let path = with("used", r#""extensionsUsed": ["KHR_materials_sheen", "EXT_meshopt_compression"],"#);
    let s = load(&path);
    for ext in ["KHR_materials_sheen", "EXT_meshopt_compression"] {
        assert!(s.warnings.iter().any(|w| w.contains(ext) && w.contains("used.gltf")), "{ext}: {:?}", s.warnings);
    }
    // The extensions probegi follows may be required, silently.
    let followed = r#""extensionsUsed": ["KHR_texture_transform", "KHR_lights_punctual"],
        "extensionsRequired": ["KHR_texture_transform"],"#;
    let s = load(&with("followed", followed));
    assert!(s.warnings.is_empty(), "{:?}", s.warnings);
    std::fs::remove_dir_all(&dir).ok();
}

#[test]
fn float_colours_outside_the_unit_range_are_clamped_with_a_warning() {
    let dir = tmp_dir("colours");
    let mut b = Buffers::default();
    let pos = b.floats(&[0.0, 0.0, 0.0, 1.0, 0.0, 0.0, 0.0, 1.0, 0.0], 3, "VEC3");
    let color = b.floats(&[2.0, 0.5, -1.0, 0.25, 0.5, 0.75, 1.0, 1.0, 1.0], 3, "VEC3");
    let shorts: Vec<u8> = [65535u16, 0, 32768, 0, 65535, 0, 0, 0, 65535].iter().flat_map(|v| v.to_le_bytes()).collect();
    let color16 = b.accessor(&shorts, 5123, 3, "VEC3", r#", "normalized": true"#);
    let body = format!(
        r#""scene": 0, "scenes": [{{"nodes": [0, 1]}}], "nodes": [{{"mesh": 0}}, {{"mesh": 1}}],
        "meshes": [{{"primitives": [{{"attributes": {{"POSITION": {pos}, "COLOR_0": {color}}}}}]}},
                   {{"primitives": [{{"attributes": {{"POSITION": {pos}, "COLOR_0": {color16}}}}}]}}]"#
    );
    let s = load(&b.write(&dir, "colours", &body));
    assert_eq!(s.mesh.colors[0], Vec3::new(1.0, 0.5, 0.0));
    assert_eq!(s.mesh.colors[1], Vec3::new(0.25, 0.5, 0.75));
    assert!((s.mesh.colors[3] - Vec3::new(1.0, 0.0, 32768.0 / 65535.0)).abs().max_element() < 1e-6);
    assert!(s.warnings.iter().any(|w| w.contains("COLOR_0") && w.contains("clamped")), "{:?}", s.warnings);
    // The default material's base colour (white, metalness 1) is multiplied by
    // the vertex colour, and so is its specular colour.
    let sp = s.surface_point(&probegi_scene::RayHit {
        t: 1.0,
        triangle: 0,
        barycentric: Vec2::ZERO,
        backface: false,
        instance: u32::MAX,
    });
    assert_eq!(s.materials[0].base_color(&s.textures, &sp.attributes()), Vec3::new(1.0, 0.5, 0.0));
    assert_eq!(s.bsdf(&sp).specular_f0, Vec3::new(1.0, 0.5, 0.0));
    std::fs::remove_dir_all(&dir).ok();
}
