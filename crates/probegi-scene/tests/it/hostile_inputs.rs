//! Hostile and careless inputs (issue: never a panic): each gets an error that names
//! the file and what to fix, never a crash.

use std::path::PathBuf;

use probegi_scene::load_scene;

fn tmp_dir(name: &str) -> PathBuf {
    let d = std::env::temp_dir().join(format!("probegi-hostile-{}-{name}", std::process::id()));
    std::fs::create_dir_all(&d).expect("mkdir");
    d
}

#[test]
fn scene_files_that_include_each_other_are_an_error_not_a_stack_overflow() {
    let d = tmp_dir("cycle");
    std::fs::write(d.join("self.toml"), "[[meshes]]\npath = \"self.toml\"\n").expect("write");
    let e = load_scene(&d.join("self.toml").to_string_lossy()).expect_err("cycle").to_string();
    assert!(e.contains("cycle") && e.contains("self.toml"), "{e}");
    std::fs::write(d.join("a.toml"), "[[meshes]]\npath = \"b.toml\"\n").expect("write");
    std::fs::write(d.join("b.toml"), "[[meshes]]\npath = \"a.toml\"\n").expect("write");
    let e = load_scene(&d.join("a.toml").to_string_lossy()).expect_err("cycle").to_string();
    assert!(e.contains("a.toml → ") && e.contains("b.toml"), "{e}");
    // A file included twice side by side (no cycle) still loads.
    std::fs::write(d.join("tri.obj"), "v 0 0 0\nv 1 0 0\nv 0 1 0\nf 1 2 3\n").expect("write");
    std::fs::write(d.join("twice.toml"), "[[meshes]]\npath = \"tri.obj\"\n[[meshes]]\npath = \"tri.obj\"\n")
        .expect("write");
    assert_eq!(load_scene(&d.join("twice.toml").to_string_lossy()).expect("no cycle").mesh.triangles.len(), 2);
    std::fs::remove_dir_all(&d).ok();
}

#[test]
fn absurd_extents_and_energy_gain_are_reported() {
    let d = tmp_dir("extent");
    std::fs::write(d.join("far.obj"), "v 0 0 0\nv 1e20 0 0\nv 0 1 0\nf 1 2 3\n").expect("write");
    let e = load_scene(&d.join("far.obj").to_string_lossy()).expect_err("absurd extent").to_string();
    assert!(e.contains("far.obj") && e.contains("beyond"), "{e}");
    std::fs::write(d.join("hot.mtl"), "newmtl hot\nKd 1.5 0.5 0.5\n").expect("write");
    std::fs::write(d.join("hot.obj"), "mtllib hot.mtl\nusemtl hot\nv 0 0 0\nv 1 0 0\nv 0 1 0\nf 1 2 3\n")
        .expect("write");
    let s = load_scene(&d.join("hot.obj").to_string_lossy()).expect("Kd above 1 loads");
    assert!(s.warnings.iter().any(|w| w.contains("hot") && w.contains("energy gain")), "{:?}", s.warnings);
    std::fs::remove_dir_all(&d).ok();
}

/// A glTF animation that translates its mesh by 1e30 m: the posed geometry,
/// bounded like loaded geometry, is an error naming the object and the frame
/// at load, not a panic in the BVH builder when the frame is posed.
#[test]
fn a_gltf_animation_that_translates_beyond_the_bound_is_an_error() {
    let dir = tmp_dir("far-gltf");
    let path = dir.join("far.gltf");
    let gltf = r#"{"asset": {"version": "2.0"}, "scene": 0, "scenes": [{"nodes": [0]}],
"nodes": [{"mesh": 0, "name": "runaway"}],
"meshes": [{"primitives": [{"attributes": {"POSITION": 0}}]}],
"animations": [{"channels": [{"sampler": 0, "target": {"node": 0, "path": "translation"}}],
  "samplers": [{"input": 1, "output": 2, "interpolation": "LINEAR"}]}],
"buffers": [{"uri": "data:application/octet-stream;base64,AAAAAAAAAAAAAAAAAACAPwAAAAAAAAAAAAAAAAAAgD8AAAAAAAAAAAAAgD8AAAAAAAAAAAAAAADK8klxAAAAAAAAAAA=", "byteLength": 68}],
"bufferViews": [{"buffer": 0, "byteOffset": 0, "byteLength": 36}, {"buffer": 0, "byteOffset": 36, "byteLength": 8},
  {"buffer": 0, "byteOffset": 44, "byteLength": 24}],
"accessors": [{"bufferView": 0, "componentType": 5126, "count": 3, "type": "VEC3", "min": [0, 0, 0], "max": [1, 1, 0]},
  {"bufferView": 1, "componentType": 5126, "count": 2, "type": "SCALAR", "min": [0], "max": [1]},
  {"bufferView": 2, "componentType": 5126, "count": 2, "type": "VEC3"}]}"#;
    std::fs::write(&path, gltf).expect("write");
    let e = load_scene(&path.to_string_lossy()).expect_err("beyond the bound");
    let e = e.to_string();
    assert!(e.contains("far.gltf") && e.contains("runaway") && e.contains("frame") && e.contains("beyond"), "{e}");
    // The same file moving by 1 m loads.
    std::fs::write(
        &path,
        gltf.replace(
            "AAAAAAAAAAAAAAAAAACAPwAAAAAAAAAAAAAAAAAAgD8AAAAAAAAAAAAAgD8AAAAAAAAAAAAAAADK8klxAAAAAAAAAAA=",
            "AAAAAAAAAAAAAAAAAACAPwAAAAAAAAAAAAAAAAAAgD8AAAAAAAAAAAAAgD8AAAAAAAAAAAAAAAAAAIA/AAAAAAAAAAA=",
        ),
    )
    .expect("write");
    load_scene(&path.to_string_lossy()).expect("a 1 m move loads");
}
