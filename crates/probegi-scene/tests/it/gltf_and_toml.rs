//! glTF 2.0 (.gltf with a data-URI buffer, and .glb) and TOML scene files.

use std::path::PathBuf;

use glam::Vec3;
use probegi_scene::{LightKind, load_scene};

fn tmp_dir(name: &str) -> PathBuf {
    let d = std::env::temp_dir().join(format!("probegi-scene-{}-{name}", std::process::id()));
    std::fs::create_dir_all(&d).expect("mkdir");
    d
}

/// Binary buffer: a unit quad in the XY plane (4 positions, 6 u16 indices).
fn quad_buffer() -> Vec<u8> {
    let mut b = Vec::new();
    for p in [[0.0f32, 0.0, 0.0], [1.0, 0.0, 0.0], [1.0, 1.0, 0.0], [0.0, 1.0, 0.0]] {
        for c in p {
            b.extend_from_slice(&c.to_le_bytes());
        }
    }
    for i in [0u16, 1, 2, 0, 2, 3] {
        b.extend_from_slice(&i.to_le_bytes());
    }
    b
}

fn gltf_json(buffer_uri: Option<String>, byte_length: usize) -> String {
    let uri = buffer_uri.map(|u| format!(r#""uri": "{u}","#)).unwrap_or_default();
    format!(
        r#"{{
  "asset": {{"version": "2.0"}},
  "extensionsUsed": ["KHR_lights_punctual", "KHR_materials_emissive_strength"],
  "extensions": {{"KHR_lights_punctual": {{"lights": [
    {{"type": "spot", "color": [1, 0.5, 0.25], "intensity": 40, "range": 10,
      "spot": {{"innerConeAngle": 0.2, "outerConeAngle": 0.6}}}}
  ]}}}},
  "scene": 0,
  "scenes": [{{"nodes": [0, 1]}}],
  "nodes": [
    {{"mesh": 0, "translation": [0, 2, 0], "scale": [2, 2, 2]}},
    {{"extensions": {{"KHR_lights_punctual": {{"light": 0}}}}, "translation": [0, 5, 0],
      "rotation": [-0.7071068, 0, 0, 0.7071068]}}
  ],
  "meshes": [{{"primitives": [{{"attributes": {{"POSITION": 0}}, "indices": 1, "material": 0}}]}}],
  "materials": [{{"name": "glow",
    "pbrMetallicRoughness": {{"baseColorFactor": [0.2, 0.4, 0.6, 1], "metallicFactor": 0, "roughnessFactor": 0.3}},
    "emissiveFactor": [1, 1, 1],
    "extensions": {{"KHR_materials_emissive_strength": {{"emissiveStrength": 7}}}}}}],
  "buffers": [{{{uri} "byteLength": {byte_length}}}],
  "bufferViews": [
    {{"buffer": 0, "byteOffset": 0, "byteLength": 48}},
    {{"buffer": 0, "byteOffset": 48, "byteLength": 12}}
  ],
  "accessors": [
    {{"bufferView": 0, "componentType": 5126, "count": 4, "type": "VEC3", "min": [0, 0, 0], "max": [1, 1, 0]}},
    {{"bufferView": 1, "componentType": 5123, "count": 6, "type": "SCALAR"}}
  ]
}}"#
    )
}

fn base64(data: &[u8]) -> String {
    const T: &[u8; 64] = b"ABCDEFGHIJKLMNOPQRSTUVWXYZabcdefghijklmnopqrstuvwxyz0123456789+/";
    let mut s = String::new();
    for chunk in data.chunks(3) {
        let n = chunk.iter().enumerate().fold(0u32, |acc, (i, &b)| acc | (b as u32) << (16 - 8 * i));
        for i in 0..4 {
            if i <= chunk.len() {
                s.push(T[((n >> (18 - 6 * i)) & 63) as usize] as char);
            } else {
                s.push('=');
            }
        }
    }
    s
}

fn check_loaded(path: &std::path::Path) {
    let s = load_scene(&path.to_string_lossy()).expect("loads");
    assert_eq!(s.mesh.triangle_count(), 2);
    // Node transform: scale 2 then translate +2 in y.
    let (lo, hi) = s.bounds().expect("bounds");
    assert!((lo - Vec3::new(0.0, 2.0, 0.0)).length() < 1e-6 && (hi - Vec3::new(2.0, 4.0, 0.0)).length() < 1e-6);
    // Generated normals face +Z (CCW), and stay unit length after the scale.
    assert!(s.mesh.normals.iter().all(|n| (*n - Vec3::Z).length() < 1e-5));
    let m = &s.materials[0];
    assert_eq!(m.base_color_factor, Vec3::new(0.2, 0.4, 0.6));
    assert_eq!(m.emissive_strength, 7.0);
    assert_eq!(m.roughness, 0.3);
    assert_eq!(s.lights.len(), 1);
    let l = &s.lights[0];
    assert_eq!(l.kind, LightKind::Spot);
    assert_eq!((l.intensity, l.range, l.inner_cone_angle, l.outer_cone_angle), (40.0, Some(10.0), 0.2, 0.6));
    assert!((l.position - Vec3::new(0.0, 5.0, 0.0)).length() < 1e-6);
    // −90° about X turns the node's −Z into −Y: the spot points down.
    assert!((l.direction - Vec3::NEG_Y).length() < 1e-5, "{}", l.direction);
}

#[test]
fn gltf_with_data_uri_buffer() {
    let buf = quad_buffer();
    let dir = tmp_dir("gltf");
    let path = dir.join("quad.gltf");
    let json = gltf_json(Some(format!("data:application/octet-stream;base64,{}", base64(&buf))), buf.len());
    std::fs::write(&path, json).expect("write");
    check_loaded(&path);
    std::fs::remove_dir_all(dir).ok();
}

#[test]
fn glb_binary_container() {
    let buf = quad_buffer();
    let mut json = gltf_json(None, buf.len()).into_bytes();
    while !json.len().is_multiple_of(4) {
        json.push(b' ');
    }
    let mut bin = buf.clone();
    while !bin.len().is_multiple_of(4) {
        bin.push(0);
    }
    let total = 12 + 8 + json.len() + 8 + bin.len();
    let mut glb = Vec::new();
    glb.extend_from_slice(b"glTF");
    glb.extend_from_slice(&2u32.to_le_bytes());
    glb.extend_from_slice(&(total as u32).to_le_bytes());
    glb.extend_from_slice(&(json.len() as u32).to_le_bytes());
    glb.extend_from_slice(b"JSON");
    glb.extend_from_slice(&json);
    glb.extend_from_slice(&(bin.len() as u32).to_le_bytes());
    glb.extend_from_slice(b"BIN\0");
    glb.extend_from_slice(&bin);
    let dir = tmp_dir("glb");
    let path = dir.join("quad.glb");
    std::fs::write(&path, glb).expect("write");
    check_loaded(&path);
    std::fs::remove_dir_all(dir).ok();
}

#[test]
fn gltf_base_color_texture_is_srgb_decoded_and_multiplied_by_the_factor() {
    // A 1×1 PNG of sRGB 128 grey as a data URI; base colour factor 0.5.
    let mut png = Vec::new();
    image::RgbImage::from_pixel(1, 1, image::Rgb([128, 128, 128]))
        .write_to(&mut std::io::Cursor::new(&mut png), image::ImageFormat::Png)
        .expect("encode png");
    let buf = quad_buffer();
    let json = gltf_json(Some(format!("data:application/octet-stream;base64,{}", base64(&buf))), buf.len())
        .replace(
            r#""baseColorFactor": [0.2, 0.4, 0.6, 1]"#,
            r#""baseColorFactor": [0.5, 0.5, 0.5, 1], "baseColorTexture": {"index": 0}"#,
        )
        .replace(
            r#""buffers":"#,
            &format!(
                r#""textures": [{{"source": 0}}], "images": [{{"uri": "data:image/png;base64,{}"}}], "buffers":"#,
                base64(&png)
            ),
        );
    let dir = tmp_dir("gltftex");
    let path = dir.join("tex.gltf");
    std::fs::write(&path, json).expect("write");
    let s = load_scene(&path.to_string_lossy()).expect("loads");
    assert_eq!(s.textures.len(), 1);
    let c = s.materials[0]
        .base_color(&s.textures, &probegi_scene::material::VertexAttributes::at_uv(glam::Vec2::new(0.3, 0.7)));
    // sRGB 128 decodes to 0.2158; times the 0.5 factor.
    assert!((c.x - 0.5 * 0.215_860_5).abs() < 1e-5, "{c}");
    std::fs::remove_dir_all(dir).ok();
}

#[test]
fn malformed_gltf_is_an_error_naming_the_file() {
    let dir = tmp_dir("badgltf");
    let path = dir.join("broken.gltf");
    std::fs::write(&path, "{ \"asset\": { \"version\": \"2.0\" }, ").expect("write");
    let e = load_scene(&path.to_string_lossy()).expect_err("malformed").to_string();
    assert!(e.contains("broken.gltf"), "{e}");
    // Index past the vertex count.
    let buf = quad_buffer();
    let bad = gltf_json(Some(format!("data:application/octet-stream;base64,{}", base64(&buf))), buf.len())
        .replace(r#""count": 4, "type": "VEC3""#, r#""count": 2, "type": "VEC3""#)
        .replace(r#""max": [1, 1, 0]"#, r#""max": [1, 0, 0]"#);
    std::fs::write(&path, bad).expect("write");
    let e = load_scene(&path.to_string_lossy()).expect_err("index out of range").to_string();
    assert!(e.contains("broken.gltf") && e.contains("out of range"), "{e}");
    std::fs::remove_dir_all(dir).ok();
}

#[test]
fn toml_scene_file_merges_meshes_lights_sky_and_camera() {
    let dir = tmp_dir("toml");
    let path = dir.join("scene.toml");
    std::fs::write(
        &path,
        r#"
sky_radiance = [0.1, 0.2, 0.3]

[[meshes]]
path = "builtin:cornell-box"

[[meshes]]
path = "builtin:cornell-box"
translation = [5.0, 0.0, 0.0]
rotation_deg = [0.0, 180.0, 0.0]

[[lights]]
kind = "point"
position = [0.0, 1.5, 0.0]
intensity = 3.0

[[lights]]
kind = "directional"
direction = [0.0, -1.0, 0.0]
color = [1.0, 0.9, 0.8]
intensity = 2.0

[camera]
position = [2.5, 1.0, 8.0]
target = [2.5, 1.0, 0.0]
fov_y_deg = 50.0
"#,
    )
    .expect("write");
    let s = load_scene(&path.to_string_lossy()).expect("loads");
    assert_eq!(s.mesh.triangle_count(), 72);
    assert_eq!(s.materials.len(), 16);
    assert_eq!(s.lights.len(), 2);
    assert_eq!(s.sky_radiance, Vec3::new(0.1, 0.2, 0.3));
    assert_eq!(s.camera.expect("camera").fov_y_deg, 50.0);
    let (lo, hi) = s.bounds().expect("bounds");
    assert!(hi.x > 5.9 && lo.x < -0.9, "{lo} {hi}");
    std::fs::remove_dir_all(dir).ok();
}

#[test]
fn toml_errors_name_the_file_and_the_field() {
    let dir = tmp_dir("badtoml");
    let path = dir.join("bad.toml");
    let cases = [
        ("[[meshes]]\npath = \"builtin:cornell-box\"\nscael = [1.0, 1.0, 1.0]\n", "scael"),
        ("[[meshes]]\npath = \"builtin:cornell-box\"\n[[lights]]\nkind = \"laser\"\nintensity = 1.0\n", "laser"),
        ("[[meshes]]\npath = \"builtin:cornell-box\"\n[[lights]]\nkind = \"point\"\nintensity = -1.0\n", "intensity"),
        ("[[meshes]]\npath = \"missing.obj\"\n", "missing.obj"),
        ("[[meshes]\n", "bad.toml"),
        ("sky_radiance = [0.0, 0.0]\n[[meshes]]\npath = \"builtin:cornell-box\"\n", "sky_radiance"),
        ("[[meshes]]\npath = \"builtin:cornell-box\"\nscale = [0.0, 1.0, 1.0]\n", "meshes[0]"),
    ];
    for (text, needle) in cases {
        std::fs::write(&path, text).expect("write");
        let e = load_scene(&path.to_string_lossy()).expect_err(needle).to_string();
        assert!(e.contains(needle), "error for `{needle}` was: {e}");
        assert!(e.contains("bad.toml") || needle == "missing.obj", "{e}");
    }
    std::fs::remove_dir_all(dir).ok();
}

#[test]
fn unknown_builtin_lists_the_available_ones() {
    let e = load_scene("builtin:nope").expect_err("unknown").to_string();
    assert!(e.contains("cornell-box"), "{e}");
    let e = load_scene("scene.fbx").expect_err("format").to_string();
    assert!(e.contains("scene.fbx"), "{e}");
}

#[test]
fn volume_settings_from_toml_and_set_overrides() {
    use probegi_scene::scene_file::apply_volume_override;
    let dir = tmp_dir("volume");
    let path = dir.join("v.toml");
    std::fs::write(
        &path,
        "[[meshes]]\npath = \"builtin:cornell-box\"\n[volume]\nprobe_counts = [4, 3, 5]\nprobe_hysteresis = 0.9\n",
    )
    .expect("write");
    let s = load_scene(&path.to_string_lossy()).expect("loads");
    let v = s.volume.expect("volume");
    assert_eq!(v.probe_counts, glam::UVec3::new(4, 3, 5));
    assert_eq!(v.probe_hysteresis, 0.9);
    assert_eq!(v.probe_rays_per_probe, 256, "unset fields keep the papers' defaults");

    let v2 = apply_volume_override(&v, "hysteresis=0.5").expect("alias without prefix");
    assert_eq!(v2.probe_hysteresis, 0.5);
    let v3 = apply_volume_override(&v2, "probe_bias_mode=normal").expect("enum as bare word");
    assert_eq!(v3.probe_bias_mode, probegi_core::ddgi_settings::ProbeBiasMode::Normal);
    let v4 = apply_volume_override(&v3, "probe_spacing_m=[0.5, 0.5, 0.5]").expect("optional vector");
    assert_eq!(v4.probe_spacing_m, Some(Vec3::splat(0.5)));
    let v5 = apply_volume_override(&v3, "probe_spacing_m=0.25").expect("a scalar for every axis");
    assert_eq!(v5.probe_spacing_m, Some(Vec3::splat(0.25)));
    let v6 = apply_volume_override(&v3, "probe_origin_m=1,2,3").expect("X,Y,Z without brackets");
    assert_eq!(v6.probe_origin_m, Some(Vec3::new(1.0, 2.0, 3.0)));
    let v7 = apply_volume_override(&v3, "probe_max_ray_distance_m=50").expect("scalars stay scalars");
    assert_eq!(v7.probe_max_ray_distance_m, 50.0);
    let e = apply_volume_override(&v, "hysterisis=0.5").expect_err("typo");
    assert!(e.contains("hysterisis") && e.contains("probe_hysteresis"), "{e}");
    let e = apply_volume_override(&v, "hysteresis=1.5").expect_err("range");
    assert!(e.contains("probe_hysteresis"), "{e}");
    let e = apply_volume_override(&v, "rays_per_probe=lots").expect_err("type");
    assert!(e.contains("probe_rays_per_probe"), "{e}");

    std::fs::write(&path, "[[meshes]]\npath = \"builtin:cornell-box\"\n[volume]\nprobe_counts = [0, 3, 5]\n")
        .expect("write");
    let e = load_scene(&path.to_string_lossy()).expect_err("zero probes").to_string();
    assert!(e.contains("volume.probe_counts") && e.contains("v.toml"), "{e}");
    std::fs::remove_dir_all(dir).ok();
}

#[test]
fn a_missing_gltf_image_and_out_of_spec_factors_warn_and_load() {
    let buf = quad_buffer();
    let json = gltf_json(Some(format!("data:application/octet-stream;base64,{}", base64(&buf))), buf.len())
        .replace(
            r#""baseColorFactor": [0.2, 0.4, 0.6, 1]"#,
            r#""baseColorFactor": [0.2, 0.4, 0.6, 1], "baseColorTexture": {"index": 0}"#,
        )
        .replace(r#""roughnessFactor": 0.3"#, r#""roughnessFactor": 7.0"#)
        .replace(r#""buffers":"#, r#""textures": [{"source": 0}], "images": [{"uri": "gone%20away.png"}], "buffers":"#);
    let dir = tmp_dir("gltf-noimage");
    let path = dir.join("noimage.gltf");
    std::fs::write(&path, &json).expect("write");
    let s = load_scene(&path.to_string_lossy()).expect("a missing image is recoverable");
    assert!(s.warnings.iter().any(|w| w.contains("gone away.png")), "{:?}", s.warnings);
    assert!(s.warnings.iter().any(|w| w.contains("roughnessFactor 7")), "{:?}", s.warnings);
    assert_eq!((s.materials[0].base_color_texture, s.materials[0].roughness), (None, 1.0));
    // A negative alpha cutoff has no sensible reading: an error naming the material.
    let bad = json.replace(r#""name": "glow","#, r#""name": "glow", "alphaMode": "MASK", "alphaCutoff": -1,"#);
    assert_ne!(bad, json);
    std::fs::write(&path, bad).expect("write");
    let e = load_scene(&path.to_string_lossy()).expect_err("negative cutoff").to_string();
    assert!(e.contains("noimage.gltf") && e.contains("alphaCutoff"), "{e}");
    // An absurd diffuse colour would overflow radiance: an error naming the material.
    std::fs::write(dir.join("hot.mtl"), "newmtl blinding\nKd 1e30 1 1\n").expect("write");
    std::fs::write(dir.join("hot.obj"), "mtllib hot.mtl\nusemtl blinding\nv 0 0 0\nv 1 0 0\nv 0 1 0\nf 1 2 3\n")
        .expect("write");
    let e = load_scene(&dir.join("hot.obj").to_string_lossy()).expect_err("absurd Kd").to_string();
    assert!(e.contains("hot.obj") && e.contains("blinding") && e.contains("absurd"), "{e}");
    std::fs::remove_dir_all(dir).ok();
}

/// One triangle (corners at the origin, +x and +y) as a glTF with `nodes`
/// and `extras` given by the caller.
fn triangle_gltf(nodes: &str, extra: &str) -> String {
    format!(
        r#"{{"asset": {{"version": "2.0"}}, "nodes": [{nodes}], {extra}
"meshes": [{{"primitives": [{{"attributes": {{"POSITION": 0}}}}]}}],
"buffers": [{{"uri": "data:application/octet-stream;base64,AAAAAAAAAAAAAAAAAACAPwAAAAAAAAAAAAAAAAAAgD8AAAAA", "byteLength": 36}}],
"bufferViews": [{{"buffer": 0, "byteOffset": 0, "byteLength": 36}}],
"accessors": [{{"bufferView": 0, "componentType": 5126, "count": 3, "type": "VEC3", "min": [0, 0, 0], "max": [1, 1, 0]}}]}}"#
    )
}

#[test]
fn a_gltf_without_scenes_draws_each_node_once_under_its_parent() {
    let dir = tmp_dir("no-scenes");
    let path = dir.join("tree.gltf");
    let nodes = r#"{"children": [1], "translation": [1.5, 0, 0]}, {"mesh": 0}"#;
    std::fs::write(&path, triangle_gltf(nodes, "")).expect("write");
    let s = load_scene(&path.to_string_lossy()).expect("loads");
    assert_eq!(s.mesh.triangle_count(), 1, "the child is drawn under its parent only");
    let (lo, _) = s.bounds().expect("geometry");
    assert!((lo.x - 1.5).abs() < 1e-6, "{lo}");
}

#[test]
fn a_placed_gltf_brings_its_lights_and_camera_along() {
    let dir = tmp_dir("placed-lights");
    let gltf = triangle_gltf(
        r#"{"mesh": 0}, {"translation": [0.3, 0.3, 1], "extensions": {"KHR_lights_punctual": {"light": 0}}},
           {"translation": [0.3, 0.3, 4], "camera": 0}"#,
        r#""scene": 0, "scenes": [{"nodes": [0, 1, 2]}], "extensionsUsed": ["KHR_lights_punctual"],
"extensions": {"KHR_lights_punctual": {"lights": [{"type": "point", "intensity": 5}]}},
"cameras": [{"type": "perspective", "perspective": {"yfov": 0.8, "znear": 0.01}}],"#,
    );
    std::fs::write(dir.join("lit.gltf"), gltf).expect("write");
    let toml = "[[meshes]]\npath = \"lit.gltf\"\ntranslation = [3.0, 0.0, 0.0]\nrotation_deg = [0.0, 90.0, 0.0]\n";
    std::fs::write(dir.join("placed.toml"), toml).expect("write");
    let s = load_scene(&dir.join("placed.toml").to_string_lossy()).expect("loads");
    let light = s.lights.first().expect("the file's light");
    // (0.3, 0.3, 1) turned 90° about y is (1, 0.3, −0.3), then moved 3 m along x.
    assert!((light.position - Vec3::new(4.0, 0.3, -0.3)).length() < 1e-5, "{}", light.position);
    let camera = s.camera.expect("the file's camera");
    assert!((camera.position - Vec3::new(7.0, 0.3, -0.3)).length() < 1e-4, "{}", camera.position);
    let to_target = (camera.target - camera.position).normalize();
    assert!((to_target - Vec3::NEG_X).length() < 1e-4, "the camera still faces the triangle: {to_target}");
}
