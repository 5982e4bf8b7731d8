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
