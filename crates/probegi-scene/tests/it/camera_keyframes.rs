//! Camera animation: `[camera].keyframes` in TOML scene files and `Scene::camera_at`.

use std::path::PathBuf;

use glam::Vec3;
use probegi_core::camera::Camera;
use probegi_scene::{CameraKeyframe, Scene, load_scene};

fn tmp_dir(name: &str) -> PathBuf {
    let d = std::env::temp_dir().join(format!("probegi-keyframes-{}-{name}", std::process::id()));
    std::fs::create_dir_all(&d).expect("mkdir");
    d
}

fn close(a: Vec3, b: Vec3) -> bool {
    (a - b).length() < 1e-5
}

/// Loads `camera` (the text after a `[camera]` header) under a Cornell box.
fn load_camera(dir: &std::path::Path, file: &str, camera: &str) -> Result<Scene, String> {
    let path = dir.join(file);
    std::fs::write(&path, format!("[[meshes]]\npath = \"builtin:cornell-box\"\n\n[camera]\n{camera}")).expect("write");
    load_scene(&path.to_string_lossy()).map_err(|e| e.to_string())
}

const THREE_KEYS: &str = r#"target = [0.0, 1.0, 0.0]
fov_y_deg = 40.0
keyframes = [
    { frame = 0, position = [0.0, 1.0, 4.0] },
    { frame = 10, position = [2.0, 1.0, 4.0] },
    { frame = 30, position = [2.0, 3.0, 4.0], target = [1.0, 1.0, 0.0], fov_y_deg = 60.0, up = [1.0, 1.0, 0.0] },
]
"#;

#[test]
fn keys_hold_omitted_fields_and_interpolate_between_keys() {
    let dir = tmp_dir("camkeys");
    let s = load_camera(&dir, "anim.toml", THREE_KEYS).expect("loads");
    assert!(s.has_camera_animation());
    assert_eq!(s.camera_keyframes.len(), 3);
    let k = &s.camera_keyframes;
    // The first key takes target and fov from the table; the middle key holds them.
    let first =
        Camera { position: Vec3::new(0.0, 1.0, 4.0), target: Vec3::new(0.0, 1.0, 0.0), up: Vec3::Y, fov_y_deg: 40.0 };
    assert_eq!(k[0], CameraKeyframe { frame: 0.0, camera: first });
    assert_eq!(k[1].frame, 10.0);
    assert_eq!(k[1].camera, Camera { position: Vec3::new(2.0, 1.0, 4.0), ..first });
    assert_eq!(k[2].frame, 30.0);
    assert_eq!(
        k[2].camera,
        Camera {
            position: Vec3::new(2.0, 3.0, 4.0),
            target: Vec3::new(1.0, 1.0, 0.0),
            up: Vec3::new(1.0, 1.0, 0.0),
            fov_y_deg: 60.0
        }
    );
    assert_eq!(s.camera, Some(first), "scene.camera is the first key's camera");
    assert_eq!(s.default_camera(), first);

    // Before the first key: held.
    assert_eq!(s.camera_at(-5.0), Some(first));
    // Between keys 0 and 1.
    let c = s.camera_at(5.0).expect("animated");
    assert!(close(c.position, Vec3::new(1.0, 1.0, 4.0)), "{c:?}");
    assert!(close(c.target, Vec3::new(0.0, 1.0, 0.0)), "{c:?}");
    assert!(close(c.up, Vec3::Y), "{c:?}");
    assert!((c.fov_y_deg - 40.0).abs() < 1e-5, "{c:?}");
    // At a key: that key's camera exactly.
    assert_eq!(s.camera_at(0.0), Some(first));
    assert_eq!(s.camera_at(10.0), Some(k[1].camera));
    assert_eq!(s.camera_at(30.0), Some(k[2].camera));
    // Half way between keys 1 and 2: up is blended, then normalised.
    let c = s.camera_at(20.0).expect("animated");
    assert!(close(c.position, Vec3::new(2.0, 2.0, 4.0)), "{c:?}");
    assert!(close(c.target, Vec3::new(0.5, 1.0, 0.0)), "{c:?}");
    assert!(close(c.up, Vec3::new(0.5, 1.0, 0.0).normalize()), "{c:?}");
    assert!((c.up.length() - 1.0).abs() < 1e-6);
    assert!((c.fov_y_deg - 50.0).abs() < 1e-4, "{c:?}");
    // A quarter of the way.
    let c = s.camera_at(15.0).expect("animated");
    assert!(close(c.position, Vec3::new(2.0, 1.5, 4.0)), "{c:?}");
    assert!((c.fov_y_deg - 45.0).abs() < 1e-4, "{c:?}");
    // After the last key: held.
    assert_eq!(s.camera_at(100.0), Some(k[2].camera));
    assert_eq!(s.camera_at(f32::NAN), Some(first), "a NaN frame does not poison the camera");
    std::fs::remove_dir_all(dir).ok();
}

#[test]
fn a_still_camera_has_no_animation() {
    let dir = tmp_dir("camstill");
    let s = load_camera(&dir, "still.toml", "position = [0.0, 1.0, 4.0]\ntarget = [0.0, 1.0, 0.0]\nfov_y_deg = 40.0\n")
        .expect("loads");
    assert!(!s.has_camera_animation());
    assert!(s.camera_keyframes.is_empty());
    assert_eq!(s.camera_at(3.0), None);
    assert_eq!(s.camera.expect("camera").fov_y_deg, 40.0);
    assert!(!load_scene("builtin:cornell-box").expect("builtin").has_camera_animation());
    std::fs::remove_dir_all(dir).ok();
}

#[test]
fn fractional_frames_and_a_single_key() {
    let dir = tmp_dir("camone");
    let s = load_camera(
        &dir,
        "one.toml",
        "keyframes = [{ frame = 2.5, position = [0.0, 1.0, 4.0], target = [0.0, 1.0, 0.0], fov_y_deg = 30.0 }]\n",
    )
    .expect("loads");
    assert!(s.has_camera_animation());
    assert_eq!(s.camera_keyframes[0].frame, 2.5);
    assert_eq!(s.camera_at(0.0), s.camera);
    assert_eq!(s.camera_at(9.0), s.camera);
    std::fs::remove_dir_all(dir).ok();
}

#[test]
fn an_included_scene_file_brings_its_camera_animation_unless_overridden() {
    let dir = tmp_dir("caminclude");
    load_camera(&dir, "inner.toml", THREE_KEYS).expect("inner loads");
    let outer = dir.join("outer.toml");
    std::fs::write(&outer, "[[meshes]]\npath = \"inner.toml\"\n").expect("write");
    let s = load_scene(&outer.to_string_lossy()).expect("loads");
    assert_eq!(s.camera_keyframes.len(), 3);
    assert_eq!(s.camera, Some(s.camera_keyframes[0].camera));

    std::fs::write(
        &outer,
        "[[meshes]]\npath = \"inner.toml\"\n[camera]\nposition = [0.0, 1.0, 5.0]\ntarget = [0.0, 1.0, 0.0]\nfov_y_deg = 30.0\n",
    )
    .expect("write");
    let s = load_scene(&outer.to_string_lossy()).expect("loads");
    assert!(!s.has_camera_animation(), "the file's own still camera replaces the included animation");
    assert_eq!(s.camera.expect("camera").fov_y_deg, 30.0);
    std::fs::remove_dir_all(dir).ok();
}

#[test]
fn bad_keyframes_are_errors_naming_the_file_and_the_key() {
    let dir = tmp_dir("camerr");
    let cases = [
        // Out of order: key 2 is before key 1 (on line 8 of the file).
        (
            "keyframes = [\n{ frame = 0, position = [0.0, 1.0, 4.0], target = [0.0, 1.0, 0.0], fov_y_deg = 40.0 },\n\
             { frame = 20, position = [1.0, 1.0, 4.0] },\n{ frame = 10 },\n]\n",
            &["camera.keyframes[2]", "frame 10", "bad.toml:8:"][..],
        ),
        // Two keys on one frame.
        (
            "position = [0.0, 1.0, 4.0]\ntarget = [0.0, 1.0, 0.0]\nfov_y_deg = 40.0\n\
             keyframes = [{ frame = 3 }, { frame = 3 }]\n",
            &["camera.keyframes[1]", "after the previous key"],
        ),
        (
            "position = [0.0, 1.0, 4.0]\ntarget = [0.0, 1.0, 0.0]\nfov_y_deg = 40.0\nkeyframes = [{ frame = -1 }]\n",
            &["camera.keyframes[0]", "≥ 0"],
        ),
        (
            "position = [0.0, 1.0, 4.0]\ntarget = [0.0, 1.0, 0.0]\nfov_y_deg = 40.0\nkeyframes = [{ frame = inf }]\n",
            &["camera.keyframes[0]", "finite"],
        ),
        // Unknown field in a key: the place comes from the TOML parser.
        (
            "position = [0.0, 1.0, 4.0]\ntarget = [0.0, 1.0, 0.0]\nfov_y_deg = 40.0\n\
             keyframes = [{ frame = 0 }, { frame = 1, positon = [1.0, 1.0, 4.0] }]\n",
            &["positon", "line 8"],
        ),
        // Unknown field in the table.
        ("position = [0.0, 1.0, 4.0]\ntarget = [0.0, 1.0, 0.0]\nfov = 40.0\n", &["fov", "line 7"]),
        (
            "position = [0.0, 1.0, 4.0]\ntarget = [0.0, 1.0, 0.0]\nfov_y_deg = 40.0\nkeyframes = [{ position = [0.0, 1.0, 4.0] }]\n",
            &["frame"],
        ),
        // A field neither the key nor the table gives.
        (
            "fov_y_deg = 40.0\nkeyframes = [{ frame = 0, position = [0.0, 1.0, 4.0] }, { frame = 5, target = [0.0, 1.0, 0.0] }]\n",
            &["camera.keyframes[0]", "`target`"],
        ),
        (
            "position = [0.0, 1.0, 4.0]\ntarget = [0.0, 1.0, 0.0]\n",
            &["camera: missing field `fov_y_deg`", "bad.toml:4:"],
        ),
        // Each key's camera must be valid.
        (
            "target = [0.0, 1.0, 0.0]\nfov_y_deg = 40.0\n\
             keyframes = [{ frame = 0, position = [0.0, 1.0, 4.0] }, { frame = 5, position = [0.0, 1.0, 0.0] }]\n",
            &["camera.keyframes[1]", "target equals camera position"],
        ),
        (
            "position = [0.0, 1.0, 4.0]\ntarget = [0.0, 1.0, 0.0]\nfov_y_deg = 40.0\n\
             keyframes = [{ frame = 0 }, { frame = 5, position = [nan, 1.0, 4.0] }]\n",
            &["camera.keyframes[1]", "finite"],
        ),
        (
            "position = [0.0, 1.0, 4.0]\ntarget = [0.0, 1.0, 0.0]\nfov_y_deg = 40.0\n\
             keyframes = [{ frame = 0 }, { frame = 5, fov_y_deg = 180.0 }]\n",
            &["camera.keyframes[1]", "fov_y_deg"],
        ),
    ];
    // An up hint along the view is not an error: the basis falls back (camera.rs).
    let along = "position = [0.0, 1.0, 4.0]\ntarget = [0.0, 1.0, 0.0]\nfov_y_deg = 40.0\n\
                 keyframes = [{ frame = 0, up = [0.0, 0.0, 1.0] }]\n";
    assert!(load_camera(&dir, "along.toml", along).is_ok());
    for (camera, needles) in cases {
        let e = load_camera(&dir, "bad.toml", camera).expect_err(needles[0]);
        for needle in needles {
            assert!(e.contains(needle), "error for `{needle}` was: {e}");
        }
        assert!(e.contains("bad.toml"), "{e}");
    }
    std::fs::remove_dir_all(dir).ok();
}

#[test]
fn scene_validate_checks_programmatic_keyframes() {
    let mut s = load_scene("builtin:cornell-box").expect("builtin");
    let cam = Camera::default();
    s.camera_keyframes = vec![CameraKeyframe { frame: 0.0, camera: cam }, CameraKeyframe { frame: 4.0, camera: cam }];
    assert!(s.validate().is_ok());
    s.camera_keyframes[1].frame = 0.0;
    assert!(s.validate().is_err_and(|e| e.contains("camera.keyframes[1]")));
    s.camera_keyframes[1].frame = 4.0;
    s.camera_keyframes[0].camera.target = cam.position;
    assert!(s.validate().is_err_and(|e| e.contains("camera.keyframes[0]")));
    // Keys so far apart that their squared distance overflows f32, the eye
    // passing through the target half way: refused, not a NaN frame.
    let far = |z: f32| Camera { position: Vec3::new(0.0, 0.0, z), target: Vec3::ZERO, ..cam };
    s.camera_keyframes =
        vec![CameraKeyframe { frame: 0.0, camera: far(1e20) }, CameraKeyframe { frame: 2.0, camera: far(-1e20) }];
    assert!(s.validate().is_err_and(|e| e.contains("camera.keyframes[1]") && e.contains("frame 1")));
}

#[test]
fn a_degenerate_up_blend_keeps_the_earlier_keys_up() {
    let mut s = load_scene("builtin:cornell-box").expect("builtin");
    // Looking along −Z; up flips from +Y to −Y, so half way the blend vanishes.
    let a = Camera { up: Vec3::Y, ..Camera::default() };
    let b = Camera { up: Vec3::NEG_Y, ..Camera::default() };
    s.camera_keyframes = vec![CameraKeyframe { frame: 0.0, camera: a }, CameraKeyframe { frame: 2.0, camera: b }];
    assert_eq!(s.camera_at(1.0).expect("animated").up, Vec3::Y);
    assert_eq!(s.camera_at(0.5).expect("animated").up, Vec3::Y);
    assert_eq!(s.camera_at(1.5).expect("animated").up, Vec3::NEG_Y);
}
