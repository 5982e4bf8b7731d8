//! Scene-file `[[objects]]` (boxes, polygons, files; keyframes and motion paths)
//! and the seeds' built-in scenes, which are the same files compiled in.

use std::path::PathBuf;

use glam::Vec3;
use probegi_scene::{BvhSettings, BvhTracer, Ray, RayTracer, load_scene};

fn repo(rel: &str) -> String {
    PathBuf::from(env!("CARGO_MANIFEST_DIR")).join("../..").join(rel).to_string_lossy().into_owned()
}

fn write(name: &str, text: &str) -> String {
    let d = std::env::temp_dir().join(format!("probegi-objects-{}", std::process::id()));
    std::fs::create_dir_all(&d).expect("mkdir");
    let p = d.join(name);
    std::fs::write(&p, text).expect("write");
    p.to_string_lossy().into_owned()
}

#[test]
fn each_builtin_seed_scene_is_its_scene_file() {
    for name in ["color-bleed", "door-room", "flood-room", "sponza-sun"] {
        let built_in = load_scene(&format!("builtin:{name}")).unwrap_or_else(|e| panic!("{name}: {e}"));
        let file = load_scene(&repo(&format!("scenes/builtin/{name}.toml"))).unwrap_or_else(|e| panic!("{name}: {e}"));
        assert_eq!(built_in.mesh.positions, file.mesh.positions, "{name}");
        assert_eq!(built_in.mesh.triangles, file.mesh.triangles, "{name}");
        assert_eq!(built_in.lights, file.lights, "{name}");
        assert_eq!(built_in.objects, file.objects, "{name}");
        assert!(built_in.camera.is_some() && built_in.volume.is_some(), "{name}");
        assert_eq!(built_in.name, format!("builtin:{name}"));
    }
    // The colour-bleeding box: 2×2×2 probes and a spotlight that translates.
    let s = load_scene("builtin:color-bleed").expect("loads");
    assert_eq!(s.volume.as_ref().expect("volume").probe_counts, glam::UVec3::splat(2));
    assert!(s.is_animated() && !s.has_moving_geometry());
    let (a, b) = (s.lights[0].at_frame(0.0).position, s.lights[0].at_frame(60.0).position);
    assert!((b - a).length() > 2.0);
    // Sponza with a moving sun reads the shared model.
    let sponza = load_scene("builtin:sponza-sun").expect("shared Sponza");
    assert!(sponza.mesh.triangle_count() > 60_000);
    let (d0, d1) = (sponza.lights[0].at_frame(0.0).direction, sponza.lights[0].at_frame(120.0).direction);
    assert!(d0.normalize().dot(d1.normalize()) < 0.7, "the sun moves");
}

#[test]
fn keyframed_box_moves_and_rays_follow_it() {
    let path = write(
        "moving.toml",
        r#"
[[objects]]
name = "floor"
polygon_m = [[-4.0, 0.0, -4.0], [-4.0, 0.0, 4.0], [4.0, 0.0, 4.0], [4.0, 0.0, -4.0]]

[[objects]]
name = "slider"
box_min_m = [-2.5, 0.0, -0.5]
box_max_m = [-1.5, 1.0, 0.5]
albedo = [0.2, 0.4, 0.9]
keyframes = [{ frame = 0, translation = [0.0, 0.0, 0.0] }, { frame = 20, translation = [4.0, 0.0, 0.0], rotation_deg = [0.0, 45.0, 0.0] }]

[[objects]]
name = "spinner"
box_min_m = [-0.2, 0.0, 1.0]
box_max_m = [0.2, 2.0, 3.0]
motion = { kind = "rotate", axis = [0.0, 1.0, 0.0], period_frames = 40 }
"#,
    );
    let base = load_scene(&path).expect("loads");
    assert_eq!(base.objects.len(), 3);
    assert_eq!(base.objects[1].name, "slider");
    assert_eq!(
        base.materials[base.mesh.triangle_materials[base.objects[1].triangles().start] as usize].base_color_factor,
        Vec3::new(0.2, 0.4, 0.9)
    );
    assert!(base.has_moving_geometry());
    let tracer = BvhTracer::for_scene(&base, BvhSettings::default());
    assert_eq!(tracer.instanced_object_count(), 2, "only moving objects are instanced");
    let mut posed = base.clone();
    posed.set_frame_from(&base, 10.0);
    let bounds = posed.moving_object_bounds();
    let centre = (bounds[0].0 + bounds[0].1) * 0.5;
    assert!((centre - Vec3::new(0.0, 0.5, 0.0)).length() < 1e-4, "halfway: {centre}");
    // Straight down on the slider's new place: its top at y = 1.
    let down = Ray::new(Vec3::new(0.0, 5.0, 0.0), Vec3::NEG_Y);
    let framed = tracer.at_frame(&posed, 10.0).expect("moving");
    assert!((framed.closest_hit(&down).expect("hit").t - 4.0).abs() < 1e-4);
    // Where it started, the floor.
    let start = Ray::new(Vec3::new(-2.0, 5.0, 0.0), Vec3::NEG_Y);
    assert!((framed.closest_hit(&start).expect("hit").t - 5.0).abs() < 1e-4);
    // A quarter turn of the spinner (frame 10 of 40) about its own centre turns
    // its long axis from z to x.
    let (lo, hi) = posed.moving_object_bounds()[1];
    assert!((hi - lo - Vec3::new(2.0, 2.0, 0.4)).abs().max_element() < 1e-4, "{lo} {hi}");
}

#[test]
fn object_errors_name_the_file_and_the_entry() {
    let cases = [
        ("[[objects]]\nbox_min_m = [1.0, 0.0, 0.0]\nbox_max_m = [0.0, 1.0, 1.0]\n", "objects[0]: box_min_m"),
        (
            "[[objects]]\nbox_min_m = [0.0, 0.0, 0.0]\nbox_max_m = [1.0, 1.0, 1.0]\npolygon_m = [[0.0,0.0,0.0],[1.0,0.0,0.0],[0.0,1.0,0.0]]\n",
            "exactly one",
        ),
        ("[[objects]]\npolygon_m = [[0.0,0.0,0.0],[1.0,0.0,0.0]]\n", "at least 3"),
        ("[[objects]]\npolygon_m = [[0.0,0.0,0.0],[1.0,0.0,0.0],[0.0,1.0,0.0]]\nbox_inward = true\n", "box_inward"),
        (
            "[[objects]]\nbox_min_m = [0.0, 0.0, 0.0]\nbox_max_m = [1.0, 1.0, 1.0]\nkeyframes = [{ frame = 0, scale = [1.0, -1.0, 1.0] }]\n",
            "scale",
        ),
        (
            "[[objects]]\nbox_min_m = [0.0, 0.0, 0.0]\nbox_max_m = [1.0, 1.0, 1.0]\nkeyframes = [{ frame = 5 }, { frame = 5 }]\n",
            "after the previous",
        ),
        (
            "[[objects]]\nbox_min_m = [0.0, 0.0, 0.0]\nbox_max_m = [1.0, 1.0, 1.0]\nmotion = { kind = \"wobble\" }\n",
            "wobble",
        ),
        (
            "[[objects]]\nbox_min_m = [0.0, 0.0, 0.0]\nbox_max_m = [1.0, 1.0, 1.0]\nmotion = { kind = \"orbit\", centre_m = [0.0,0.0,0.0], axis = [0.0,1.0,0.0], period_frames = 0 }\n",
            "period_frames",
        ),
        ("[[objects]]\npath = \"missing.obj\"\n", "missing.obj"),
        ("[[meshes]]\npath = \"shared:scenes/nowhere/none.obj\"\n", "none.obj"),
    ];
    for (i, (text, needle)) in cases.iter().enumerate() {
        let path = write(&format!("bad-object-{i}.toml"), text);
        let e = load_scene(&path).err().unwrap_or_else(|| panic!("case {i} loaded")).to_string();
        assert!(e.contains(needle), "case {i}: {e}");
        assert!(
            e.contains(&format!("bad-object-{i}.toml")) || *needle == "missing.obj" || *needle == "none.obj",
            "case {i}: {e}"
        );
    }
}

/// A unit quad on node 0 with a translation channel (0,2,0) → (2,2,0) and a
/// rotation channel 0° → 90° about +Y over one second, as a .gltf with a data URI.
fn animated_gltf() -> String {
    let mut b: Vec<u8> = Vec::new();
    let f32s = |v: &[f32], b: &mut Vec<u8>| v.iter().for_each(|x| b.extend_from_slice(&x.to_le_bytes()));
    f32s(&[0.0, 0.0, 0.0, 1.0, 0.0, 0.0, 1.0, 1.0, 0.0, 0.0, 1.0, 0.0], &mut b);
    for i in [0u16, 1, 2, 0, 2, 3] {
        b.extend_from_slice(&i.to_le_bytes());
    }
    let h = std::f32::consts::FRAC_1_SQRT_2;
    f32s(&[0.0, 1.0], &mut b);
    f32s(&[0.0, 2.0, 0.0, 2.0, 2.0, 0.0], &mut b);
    f32s(&[0.0, 0.0, 0.0, 1.0, 0.0, h, 0.0, h], &mut b);
    const T: &[u8; 64] = b"ABCDEFGHIJKLMNOPQRSTUVWXYZabcdefghijklmnopqrstuvwxyz0123456789+/";
    let mut b64 = String::new();
    for chunk in b.chunks(3) {
        let n = chunk.iter().enumerate().fold(0u32, |acc, (i, &x)| acc | (x as u32) << (16 - 8 * i));
        for i in 0..4 {
            b64.push(if i <= chunk.len() { T[((n >> (18 - 6 * i)) & 63) as usize] as char } else { '=' });
        }
    }
    let json = format!(
        r#"{{
  "asset": {{"version": "2.0"}},
  "scene": 0,
  "scenes": [{{"nodes": [0]}}],
  "nodes": [{{"mesh": 0, "name": "door", "translation": [0, 2, 0]}}],
  "meshes": [{{"primitives": [{{"attributes": {{"POSITION": 0}}, "indices": 1}}]}}],
  "animations": [{{
    "samplers": [{{"input": 2, "output": 3}}, {{"input": 2, "output": 4}}],
    "channels": [{{"sampler": 0, "target": {{"node": 0, "path": "translation"}}}},
                 {{"sampler": 1, "target": {{"node": 0, "path": "rotation"}}}}]
  }}],
  "buffers": [{{"uri": "data:application/octet-stream;base64,{b64}", "byteLength": {}}}],
  "bufferViews": [
    {{"buffer": 0, "byteOffset": 0, "byteLength": 48}},
    {{"buffer": 0, "byteOffset": 48, "byteLength": 12}},
    {{"buffer": 0, "byteOffset": 60, "byteLength": 8}},
    {{"buffer": 0, "byteOffset": 68, "byteLength": 24}},
    {{"buffer": 0, "byteOffset": 92, "byteLength": 32}}
  ],
  "accessors": [
    {{"bufferView": 0, "componentType": 5126, "count": 4, "type": "VEC3", "min": [0, 0, 0], "max": [1, 1, 0]}},
    {{"bufferView": 1, "componentType": 5123, "count": 6, "type": "SCALAR"}},
    {{"bufferView": 2, "componentType": 5126, "count": 2, "type": "SCALAR", "min": [0], "max": [1]}},
    {{"bufferView": 3, "componentType": 5126, "count": 2, "type": "VEC3"}},
    {{"bufferView": 4, "componentType": 5126, "count": 2, "type": "VEC4"}}
  ]
}}"#,
        b.len()
    );
    write("anim.gltf", &json)
}

#[test]
fn gltf_animation_channels_move_the_node_on_the_scene_clock() {
    let gltf = animated_gltf();
    let base = load_scene(&gltf).expect("loads");
    assert_eq!(base.objects.len(), 1);
    assert_eq!(base.objects[0].name, "door");
    assert!(base.has_moving_geometry());
    // Rest pose: the node's own translation.
    assert!((base.mesh.positions[1] - Vec3::new(1.0, 2.0, 0.0)).length() < 1e-6);
    let at = |scene: &probegi_scene::Scene, frame: f32| {
        let mut posed = scene.clone();
        posed.set_frame_from(scene, frame);
        posed.mesh.positions.clone()
    };
    // 30 frames per second: frame 15 is 0.5 s, halfway: (1, 2, 0) and 45° about +Y.
    let h = std::f32::consts::FRAC_1_SQRT_2;
    let expected = Vec3::new(1.0 + h, 2.0, -h);
    let p = at(&base, 15.0);
    assert!((p[1] - expected).length() < 1e-3, "{}", p[1]);
    assert!((at(&base, 30.0)[1] - Vec3::new(2.0, 2.0, -1.0)).length() < 1e-4, "end pose");
    assert!((at(&base, 90.0)[1] - Vec3::new(2.0, 2.0, -1.0)).length() < 1e-4, "held after the last key");

    // Placed by a scene file with its own clock: 10 frames per second, moved +5 z.
    let toml = write(
        "anim.toml",
        &format!(
            "frames_per_second = 10.0\n[[meshes]]\npath = \"{}\"\ntranslation = [0.0, 0.0, 5.0]\n",
            gltf.replace('\\', "/")
        ),
    );
    let placed = load_scene(&toml).expect("loads");
    let p = at(&placed, 5.0);
    assert!((p[1] - (expected + Vec3::new(0.0, 0.0, 5.0))).length() < 1e-3, "{}", p[1]);
}

/// `Scene::facing_geometric_normal` (the classification's plane normal, from
/// the triangle's corners alone) is the surface point's facing geometric
/// normal bit for bit, on instanced geometry and on back faces alike.
#[test]
fn the_plane_normal_of_a_hit_is_its_surface_points_facing_geometric_normal() {
    let scene = load_scene("builtin:forest").expect("builtin forest");
    let tracer = BvhTracer::for_scene(&scene, BvhSettings::default());
    let (lo, hi) = scene.bounds().expect("bounds");
    let centre = (lo + hi) * 0.5 + Vec3::new(0.0, -0.3, 0.0) * (hi - lo);
    let (mut instanced, mut back, mut hits) = (0, 0, 0);
    for k in 0..4096 {
        let z = 1.0 - 2.0 * (k as f32 + 0.5) / 4096.0;
        let phi = k as f32 * 2.399_963;
        let dir = Vec3::new((1.0 - z * z).sqrt() * phi.cos(), z, (1.0 - z * z).sqrt() * phi.sin());
        let Some(hit) = tracer.closest_hit(&Ray::new(centre, dir)) else { continue };
        let plane = scene.facing_geometric_normal(&hit);
        let expected = scene.surface_point(&hit).facing_geometric_normal();
        assert_eq!(plane, expected, "ray {k}: hit {hit:?}");
        assert!((plane.length() - 1.0).abs() < 1e-5, "ray {k}: {plane}");
        assert!(plane.dot(dir) <= 0.0, "ray {k}: the plane normal faces the ray's origin");
        hits += 1;
        instanced += (hit.instance != u32::MAX) as usize;
        back += hit.backface as usize;
    }
    assert!(hits > 1000 && instanced > 50 && back > 0, "{hits} hits, {instanced} instanced, {back} back faces");
}
