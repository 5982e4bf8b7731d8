//! Never hang, never silently wrong: cameras that look straight up or down,
//! on every path (fixed, keyframed, `reference --frame`, the GPU camera);
//! keyframe paths validated at load; moving geometry bounded before a render;
//! outputs checked before a render and nothing left behind when one fails.

use crate::common;

use std::path::{Path, PathBuf};
use std::process::{Command, Output};

fn probegi(args: &[&str]) -> Output {
    Command::new(env!("CARGO_BIN_EXE_probegi")).args(args).output().expect("spawn probegi")
}

fn tmp(name: &str) -> PathBuf {
    common::scratch("probegi-nsw", name)
}

fn s(p: &Path) -> String {
    p.to_string_lossy().into_owned()
}

fn stderr(o: &Output) -> String {
    String::from_utf8_lossy(&o.stderr).into_owned()
}

fn fails_with(args: &[&str], needle: &str) -> String {
    let o = probegi(args);
    let e = stderr(&o);
    assert!(!o.status.success(), "{args:?} should fail:\n{e}");
    assert!(e.contains(needle), "{args:?}: stderr does not mention `{needle}`:\n{e}");
    assert!(!e.contains("panicked"), "{args:?} panicked:\n{e}");
    e
}

fn gpu_required() -> bool {
    std::env::var_os("PROBEGI_REQUIRE_GPU").is_some()
}

/// The per-frame image means a render's `--stats` reports.
fn frame_means(stats: &Path) -> Vec<f64> {
    let json: serde_json::Value = serde_json::from_str(&std::fs::read_to_string(stats).expect("stats")).expect("json");
    assert_eq!(json["nonfinite_pixels"], 0, "no pixel came out NaN");
    let means = json["frame_means"].as_array().expect("frame_means");
    means.iter().map(|m| m.as_array().expect("rgb").iter().map(|c| c.as_f64().expect("f64")).sum::<f64>()).collect()
}

/// Inside the Cornell box, turning in place from looking along +x, straight up
/// at frame 4, to looking along −x at frame 8 (up hint +y throughout).
const TURN_THROUGH_THE_ZENITH: &str = r#"
[[meshes]]
path = "builtin:cornell-box"
[camera]
position = [0.0, 1.0, 0.0]
fov_y_deg = 60.0
keyframes = [
  { frame = 0, target = [1.0, 1.0, 0.0] },
  { frame = 4, target = [0.0, 2.0, 0.0] },
  { frame = 8, target = [-1.0, 1.0, 0.0] },
]
"#;

#[test]
fn a_camera_path_through_the_zenith_is_lit_on_every_frame_and_backend() {
    let scene = tmp("zenith.toml");
    std::fs::write(&scene, TURN_THROUGH_THE_ZENITH).expect("scene");
    let mut runs: Vec<Vec<&str>> = vec![vec!["--gi", "ddgi"], vec!["--gi", "sh"], vec!["--gi", "none"]];
    if gpu_required() {
        runs.push(vec!["--gi", "ddgi", "--backend", "wgpu"]);
    }
    for extra in runs {
        let stats = tmp("zenith.json");
        let mut args = vec!["render", "--scene", &s(&scene)].into_iter().map(String::from).collect::<Vec<_>>();
        args.extend(["--frames", "9", "--width", "16", "--height", "16", "--probes", "4,4,4"].map(String::from));
        if extra.contains(&"ddgi") {
            args.extend(["--rays-per-probe", "32"].map(String::from));
        }
        if extra.contains(&"none") {
            args.retain(|a| a != "--probes" && a != "4,4,4");
        }
        args.extend(extra.iter().map(|a| a.to_string()));
        args.extend(["--out", &s(&tmp("zenith.exr")), "--stats", &s(&stats)].map(String::from));
        let o = probegi(&args.iter().map(String::as_str).collect::<Vec<_>>());
        assert!(o.status.success(), "{extra:?}: {}", stderr(&o));
        let means = frame_means(&stats);
        assert_eq!(means.len(), 9, "{extra:?}");
        assert!(means.iter().all(|&m| m.is_finite() && m > 1e-3), "{extra:?}: a dark frame in {means:?}");
    }
    // The reference at the straight-up frame sees the lit ceiling and the light.
    let exr = tmp("zenith-ref.exr");
    let o = probegi(&[
        "reference",
        "--scene",
        &s(&scene),
        "--frame",
        "4",
        "--spp",
        "4",
        "--width",
        "16",
        "--height",
        "16",
        "--out",
        &s(&exr),
    ]);
    assert!(o.status.success(), "{}", stderr(&o));
    let probegi_image::LoadedImage::Hdr(img) = probegi_image::read_image(&exr).expect("reference") else {
        panic!("an .exr reads as HDR")
    };
    let mean: f32 = img.pixels.iter().map(|p| p.x + p.y + p.z).sum::<f32>() / img.pixels.len() as f32;
    assert!(mean > 0.05, "the straight-up reference frame is dark: {mean}");
}

#[test]
fn fixed_cameras_looking_straight_down_and_up_render() {
    let mut backends = vec!["cpu"];
    if gpu_required() {
        backends.push("wgpu");
    }
    for backend in backends {
        for (pos, target) in [("0,1.9,0", "0,0,0"), ("0,0.2,0", "0,2,0")] {
            let stats = tmp("down.json");
            let o = probegi(&[
                "render",
                "--gi",
                "ddgi",
                "--backend",
                backend,
                "--camera-pos",
                pos,
                "--camera-target",
                target,
                "--probes",
                "4,4,4",
                "--rays-per-probe",
                "32",
                "--frames",
                "2",
                "--width",
                "16",
                "--height",
                "16",
                "--out",
                &s(&tmp("down.png")),
                "--stats",
                &s(&stats),
            ]);
            assert!(o.status.success(), "{backend} {pos} → {target}: {}", stderr(&o));
            assert!(frame_means(&stats).iter().all(|&m| m > 1e-3), "{backend} {pos} → {target}: dark");
        }
    }
}

#[test]
fn keyframes_whose_eye_reaches_the_target_are_refused_at_load() {
    let scene = tmp("coincident.toml");
    let out = s(&tmp("x.png"));
    // The eye passes through the target between keys 0 and 1 (frame 2).
    std::fs::write(
        &scene,
        "[[meshes]]\npath = \"builtin:cornell-box\"\n[camera]\nfov_y_deg = 50.0\ntarget = [0.0, 1.0, 0.0]\n\
         keyframes = [{ frame = 0, position = [0.0, 1.0, 2.0] }, { frame = 4, position = [0.0, 1.0, -2.0] }]\n",
    )
    .expect("scene");
    let e = fails_with(&["render", "--scene", &s(&scene), "--out", &out], "camera.keyframes[1]");
    assert!(e.contains("reaches its target") && e.contains("frame 2"), "{e}");
    // A key whose target is its position names the key.
    std::fs::write(
        &scene,
        "[[meshes]]\npath = \"builtin:cornell-box\"\n[camera]\nfov_y_deg = 50.0\ntarget = [0.0, 1.0, 0.0]\n\
         keyframes = [{ frame = 0, position = [0.0, 1.0, 2.0] }, { frame = 4, position = [0.0, 1.0, 0.0] }]\n",
    )
    .expect("scene");
    fails_with(&["render", "--scene", &s(&scene), "--out", &out], "camera.keyframes[1]");
    fails_with(
        &["render", "--camera-pos", "0,1,2", "--camera-target", "0,1,2", "--out", &out],
        "camera target equals camera position",
    );
}

#[test]
fn posed_geometry_beyond_the_coordinate_bound_is_an_error_naming_object_and_frame() {
    let scene = tmp("far.toml");
    let out = s(&tmp("far.png"));
    let with_object = |animation: &str| {
        format!(
            "[[meshes]]\npath = \"builtin:cornell-box\"\n[[objects]]\nname = \"crate\"\n\
             box_min_m = [0.0, 0.0, 0.0]\nbox_max_m = [0.2, 0.2, 0.2]\nalbedo = [0.5, 0.5, 0.5]\n{animation}\n"
        )
    };
    for (animation, needle) in [
        ("keyframes = [{ frame = 0, scale = [1.0, 1.0, 1.0] }, { frame = 2, scale = [1e30, 1e30, 1e30] }]", "frame 1"),
        (
            "keyframes = [{ frame = 0, translation = [0.0, 0.0, 0.0] }, { frame = 2, translation = [1e30, 0.0, 0.0] }]",
            "frame 1",
        ),
        ("motion = { kind = \"translate\", velocity_m_per_frame = [1e30, 0.0, 0.0] }", "frame 1"),
    ] {
        std::fs::write(&scene, with_object(animation)).expect("scene");
        let args = ["render", "--scene", &s(&scene), "--frames", "3", "--width", "8", "--height", "8", "--out", &out];
        let e = fails_with(&args, "object `crate`");
        assert!(e.contains(needle) && e.contains("beyond"), "{animation}: {e}");
    }
}

#[test]
fn outputs_are_checked_before_rendering_and_failures_leave_nothing() {
    let dir = tmp("outputs");
    std::fs::create_dir_all(dir.join("taken.png")).expect("dir");
    let before: Vec<_> = std::fs::read_dir(&dir).expect("ls").collect();
    // Checked before rendering: no frame is rendered (no progress, no "wrote").
    let args = ["render", "--gi", "ddgi", "--frames", "2000", "--out", &s(&dir.join("taken.png"))];
    let e = fails_with(&args, "is a directory");
    assert!(!e.contains("render [") && !e.contains("wrote"), "{e}");
    let file = dir.join("plain-file");
    std::fs::write(&file, b"x").expect("file");
    fails_with(&["render", "--out", &s(&file.join("o.png"))], "not a directory");
    fails_with(&["render", "--sequence", &s(&file), "--out", &s(&dir.join("o.png"))], "not a directory");
    fails_with(&["reference", "--out", &s(&dir.join("taken.png"))], "is a directory");
    let after: Vec<String> =
        std::fs::read_dir(&dir).expect("ls").map(|e| e.expect("entry").file_name().to_string_lossy().into()).collect();
    assert_eq!(after.len(), before.len() + 1, "{after:?}");
    assert!(after.iter().all(|n| !n.contains("partial")), "{after:?}");
}

#[test]
fn an_all_black_frame_of_a_lit_scene_is_an_error_unless_allowed() {
    // A point light shut inside a closed box seen from outside under a black
    // sky: every pixel is black although the scene has a light and the camera
    // sees a surface, the pattern of the degenerate-camera bugs this check is for.
    let scene = tmp("shut.toml");
    std::fs::write(
        &scene,
        "[[objects]]\nbox_min_m = [-1.0, -1.0, -1.0]\nbox_max_m = [1.0, 1.0, 1.0]\nalbedo = [0.8, 0.8, 0.8]\n\
         [[lights]]\nkind = \"point\"\nposition = [0.0, 0.0, 0.0]\nintensity = 10.0\n\
         [camera]\nposition = [0.0, 0.0, 5.0]\ntarget = [0.0, 0.0, 0.0]\nfov_y_deg = 40.0\n",
    )
    .expect("scene");
    let seq = tmp("shut-seq");
    let out = tmp("shut.png");
    let args = ["render", "--scene", &s(&scene), "--frames", "2", "--width", "8", "--height", "8"];
    let mut failing: Vec<&str> = args.to_vec();
    let gif = tmp("shut.gif");
    let (seq_s, out_s, gif_s) = (s(&seq), s(&out), s(&gif));
    failing.extend(["--sequence", &seq_s, "--out", &out_s, "--gif", &gif_s]);
    let e = fails_with(&failing, "all black");
    assert!(e.contains("[0, 1]"), "{e}");
    assert!(!out.exists() && !gif.exists(), "nothing written");
    let partial = std::fs::read_dir(gif.parent().expect("dir"))
        .expect("ls")
        .filter(|e| e.as_ref().is_ok_and(|e| e.file_name().to_string_lossy().contains("shut.partial")))
        .count();
    assert_eq!(partial, 0, "no temporary file left");
    assert_eq!(std::fs::read_dir(&seq).map(|d| d.count()).unwrap_or(0), 0, "no sequence frames left");
    failing.push("--allow-black-frames");
    let o = probegi(&failing);
    assert!(o.status.success(), "{}", stderr(&o));
}

#[test]
fn looking_straight_up_in_sponza_shows_the_sky_through_the_open_roof() {
    // `scenes/sponza-world-zenith.toml`'s turn on one copy of the shared Sponza,
    // 9 frames: straight up at frame 4, under a sky no surface can match.
    let scene = tmp("sponza-zenith.toml");
    std::fs::write(
        &scene,
        "sky_radiance = [0.25, 0.5, 1.0]\n[[meshes]]\npath = \"shared:scenes/dabrovic-sponza/sponza.obj\"\n\
         [camera]\nposition = [0.0, 4.0, 0.0]\nfov_y_deg = 65.0\nkeyframes = [{ frame = 0, target = [10.0, 4.0, 0.0] }, \
         { frame = 4, target = [0.0, 14.0, 0.0] }, { frame = 8, target = [-10.0, 4.0, 0.0] }]\n",
    )
    .expect("scene");
    let seq = tmp("sponza-zenith-seq");
    let args = ["render", "--scene", &s(&scene), "--frames", "9", "--width", "24", "--height", "24"];
    let mut args: Vec<&str> = args.to_vec();
    let (seq_s, out_s) = (s(&seq), s(&tmp("sponza-zenith.exr")));
    args.extend(["--sequence", &seq_s, "--sequence-exr", "--out", &out_s]);
    let o = probegi(&args);
    assert!(o.status.success(), "{}", stderr(&o));
    let sky_fraction = |f: u32| {
        let path = seq.join(format!("frame-{f:04}.exr"));
        let probegi_image::LoadedImage::Hdr(img) = probegi_image::read_image(&path).expect("frame") else {
            panic!("an .exr reads as HDR")
        };
        let sky = |p: &glam::Vec3| (*p - glam::Vec3::new(0.25, 0.5, 1.0)).abs().max_element() < 1e-6;
        img.pixels.iter().filter(|p| sky(p)).count() as f32 / img.pixels.len() as f32
    };
    let up = sky_fraction(4);
    assert!(up > 0.2 && up < 1.0, "looking up, the open roof shows the sky in {up} of the pixels");
    assert!(sky_fraction(0) < up && sky_fraction(8) < up, "the horizontal views see the walls");
}
