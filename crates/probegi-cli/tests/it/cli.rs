//! The command-line contract: outputs, JSON keys, and clear non-zero exits on bad input.

use crate::common;

use std::path::PathBuf;
use std::process::{Command, Output};

fn probegi(args: &[&str]) -> Output {
    Command::new(env!("CARGO_BIN_EXE_probegi")).args(args).output().expect("spawn probegi")
}

fn tmp(name: &str) -> PathBuf {
    common::scratch("probegi-cli", name)
}

fn stderr(o: &Output) -> String {
    String::from_utf8_lossy(&o.stderr).into_owned()
}

fn fails_with(args: &[&str], needle: &str) {
    let o = probegi(args);
    assert!(!o.status.success(), "{args:?} should fail");
    let e = stderr(&o);
    assert!(e.contains(needle), "{args:?}: stderr does not mention `{needle}`:\n{e}");
    assert!(!e.contains("panicked"), "{args:?} panicked:\n{e}");
}

#[test]
fn render_writes_png_exr_and_stats_json() {
    let png = tmp("r.png");
    let exr = tmp("r.exr");
    let stats = tmp("stats.json");
    let s = |p: &PathBuf| p.to_string_lossy().into_owned();
    let o = probegi(&[
        "render",
        "--width",
        "32",
        "--height",
        "24",
        "--frames",
        "2",
        "--out",
        &s(&png),
        "--stats",
        &s(&stats),
    ]);
    assert!(o.status.success(), "{}", stderr(&o));
    assert!(stderr(&o).contains("wrote"));
    let json: serde_json::Value = serde_json::from_str(&std::fs::read_to_string(&stats).expect("stats")).expect("json");
    assert_eq!(json["frames"], 2);
    assert!(json["rays_traced"].as_u64().expect("rays") >= 2 * 32 * 24);
    assert!(json["pass_ms"]["gbuffer"].as_f64().is_some() && json["pass_ms"]["camera"].as_f64().is_some());
    let o = probegi(&["render", "--width", "32", "--height", "24", "--out", &s(&exr)]);
    assert!(o.status.success(), "{}", stderr(&o));

    // compare: PNG against EXR of the same frames is close; it prints the contract line.
    let sheet = tmp("sheet.png");
    let o = probegi(&["compare", &s(&exr), &s(&png), "--out", &s(&sheet)]);
    assert!(o.status.success(), "{}", stderr(&o));
    let out = String::from_utf8_lossy(&o.stdout);
    let line = out.lines().find(|l| l.starts_with("mean_flip: ")).expect("mean_flip line");
    let v: f32 = line["mean_flip: ".len()..].trim().parse().expect("number");
    assert!((0.0..0.2).contains(&v), "{v}");
    assert!(sheet.exists());
}

#[test]
fn ddgi_render_reports_field_stats_and_dumps_atlases() {
    let out = tmp("ddgi.exr");
    let stats = tmp("ddgi.json");
    let atlases = tmp("atlases");
    let s = |p: &PathBuf| p.to_string_lossy().into_owned();
    let o = probegi(&[
        "render",
        "--gi",
        "ddgi",
        "--probes",
        "3,3,3",
        "--rays-per-probe",
        "32",
        "--set",
        "hysteresis=0.5",
        "--frames",
        "3",
        "--width",
        "16",
        "--height",
        "16",
        "--show-probes",
        "--out",
        &s(&out),
        "--stats",
        &s(&stats),
        "--dump-atlases",
        &s(&atlases),
    ]);
    assert!(o.status.success(), "{}", stderr(&o));
    let json: serde_json::Value = serde_json::from_str(&std::fs::read_to_string(&stats).expect("stats")).expect("json");
    assert_eq!(json["probes"], 27);
    let active = json["active_probes"].as_u64().expect("active_probes");
    assert!(active > 0 && active <= 27);
    assert_eq!(json["rays_per_frame"].as_u64(), Some(active * 32), "rays traced by the active probes");
    for pass in ["ray_gen", "trace", "shade", "blend", "border", "camera"] {
        assert!(json["pass_ms"][pass].as_f64().is_some(), "pass_ms.{pass} missing");
    }
    assert!(json["field_update_ms"].as_f64().expect("field_update_ms") > 0.0);
    assert!(json["field_update_mrays_per_s"].as_f64().expect("mrays") > 0.0);
    let states = json["probe_states"].as_object().expect("probe_states");
    assert_eq!(states.values().filter_map(|v| v.as_u64()).sum::<u64>(), 27, "{states:?}");
    for f in ["irradiance.exr", "irradiance.png", "distance.exr", "distance.png"] {
        assert!(atlases.join(f).exists(), "{f} not written");
    }
    // 3×3×3 probes with 8×8 irradiance tiles: rows of 3 tiles.
    let irr = probegi_image::read_image(&atlases.join("irradiance.exr")).expect("atlas");
    assert_eq!(irr.size(), (3 * 8, 9 * 8));
}

#[test]
fn bad_volume_settings_name_the_field() {
    let o = tmp("never-ddgi.png").to_string_lossy().into_owned();
    fails_with(&["render", "--gi", "ddgi", "--set", "hysterisis=0.9", "--out", &o], "probe_hysteresis");
    fails_with(&["render", "--gi", "ddgi", "--set", "hysteresis=2", "--out", &o], "probe_hysteresis");
    fails_with(&["render", "--gi", "ddgi", "--rays-per-probe", "0", "--out", &o], "probe_rays_per_probe");
    fails_with(&["render", "--gi", "ddgi", "--probes", "0,4,4", "--out", &o], "at least 1");
    fails_with(&["render", "--gi", "ddgi", "--set", "probe_spacing_m=[1,-1,1]", "--out", &o], "probe_spacing_m");
    fails_with(&["render", "--gi", "ddgi", "--probes", "1000,1000,1000", "--out", &o], "memory");
    fails_with(&["render", "--show-probes", "--out", &o], "--gi ddgi");
    fails_with(&["render", "--gi", "ddgi", "--set", "probe_states=weird", "--out", &o], "all-active");
    fails_with(&["render", "--gi", "ddgi", "--set", "relocation=maybe", "--out", &o], "probe_relocation");
}

#[test]
fn reference_is_deterministic_for_a_seed() {
    let a = tmp("a.exr");
    let b = tmp("b.exr");
    let s = |p: &PathBuf| p.to_string_lossy().into_owned();
    for p in [&a, &b] {
        let o = probegi(&["reference", "--width", "16", "--height", "16", "--spp", "4", "--seed", "3", "--out", &s(p)]);
        assert!(o.status.success(), "{}", stderr(&o));
    }
    assert_eq!(std::fs::read(&a).expect("a"), std::fs::read(&b).expect("b"));
    let o = probegi(&["compare", &s(&a), &s(&b)]);
    let stdout = String::from_utf8_lossy(&o.stdout);
    assert!(stdout.contains("mean_flip: 0.000000"), "{stdout}");
    assert!(stdout.contains("mean_ratio: 1.000000 1.000000 1.000000"), "{stdout}");
}

#[test]
fn bad_input_exits_non_zero_with_a_clear_message() {
    let out = tmp("never.png");
    let o = out.to_string_lossy().into_owned();
    fails_with(&["render", "--scene", "/no/such/scene.obj", "--out", &o], "/no/such/scene.obj");
    fails_with(&["render", "--scene", "builtin:nope", "--out", &o], "cornell-box");
    fails_with(&["render", "--width", "0", "--out", &o], "--width");
    fails_with(&["render", "--width", "65536", "--height", "65536", "--out", &o], "memory");
    fails_with(&["render", "--frames", "0", "--out", &o], "--frames");
    fails_with(&["render", "--fov-y", "0", "--out", &o], "fov");
    fails_with(&["render", "--camera-pos", "1,2", "--out", &o], "X,Y,Z");
    fails_with(&["render", "--sky", "nan,0,0", "--out", &o], "not finite");
    fails_with(&["render", "--out", "image.bmp"], "image.bmp");
    fails_with(&["reference", "--spp", "0", "--out", &o], "--spp");
    fails_with(&["reference", "--max-depth", "0", "--out", &o], "--max-depth");
    fails_with(&["compare", "/no/ref.exr", "/no/test.exr"], "/no/ref.exr");
    fails_with(&["bench", "--probes", "0,1,1"], "at least 1");
    assert!(!out.exists(), "no image may be left behind by a failed run");

    // A malformed OBJ names file and line.
    let bad = tmp("bad.obj");
    std::fs::write(&bad, "v 0 0 0\nv 1 0 0\nv 0 1 nan\nf 1 2 3\n").expect("write");
    fails_with(&["render", "--scene", &bad.to_string_lossy(), "--out", &o], "bad.obj:3:");

    // Mismatched sizes in compare.
    let (a, b) = (tmp("s1.png"), tmp("s2.png"));
    for (p, w) in [(&a, "8"), (&b, "9")] {
        let r = probegi(&["render", "--width", w, "--height", "8", "--out", &p.to_string_lossy()]);
        assert!(r.status.success());
    }
    fails_with(&["compare", &a.to_string_lossy(), &b.to_string_lossy()], "sizes differ");
}

#[test]
fn bench_prints_json_with_throughput() {
    let o = probegi(&["bench", "--probes", "4,4,4", "--rays-per-probe", "64", "--repeat", "1"]);
    assert!(o.status.success(), "{}", stderr(&o));
    let json: serde_json::Value = serde_json::from_slice(&o.stdout).expect("bench prints JSON");
    assert_eq!(json["rays"], 4 * 4 * 4 * 64);
    assert!(json["closest_hit_mrays_per_s"].as_f64().expect("closest") > 0.0);
    assert!(json["any_hit_mrays_per_s"].as_f64().expect("any") > 0.0);
    assert!(json["bvh_build_ms"].as_f64().expect("build") >= 0.0);
    assert!(json["peak_rss_mib"].as_f64().expect("peak rss") > 0.0);
}

/// `--dump-rays` writes what `scripts/embree-compare.py` reads: every triangle and
/// ray as raw f32, probegi's closest hits agreeing with the report, and the report.
#[test]
fn bench_dumps_its_rays_and_triangles_for_another_tracer() {
    let dir = tmp("dump-rays");
    let d = dir.to_string_lossy();
    let o = probegi(&["bench", "--probes", "3,3,3", "--rays-per-probe", "16", "--repeat", "1", "--dump-rays", &d]);
    assert!(o.status.success(), "{}", stderr(&o));
    let json: serde_json::Value = serde_json::from_slice(&o.stdout).expect("bench prints JSON");
    let floats = |name: &str| -> Vec<f32> {
        let bytes = std::fs::read(dir.join(name)).expect(name);
        bytes.chunks_exact(4).map(|b| f32::from_le_bytes([b[0], b[1], b[2], b[3]])).collect()
    };
    let (tris, rays, t) = (floats("triangles.f32"), floats("rays.f32"), floats("closest_t.f32"));
    assert_eq!(tris.len() as u64, 9 * json["triangles"].as_u64().expect("triangles"));
    assert_eq!(rays.len(), 6 * 27 * 16);
    assert_eq!(t.len(), 27 * 16);
    let hits = t.iter().filter(|t| t.is_finite()).count() as f64 / t.len() as f64;
    assert_eq!(hits, json["closest_hit_fraction"].as_f64().expect("fraction"));
    assert!(t.iter().all(|t| *t > 0.0), "hit distances are positive, misses +∞");
    let meta: serde_json::Value =
        serde_json::from_slice(&std::fs::read(dir.join("meta.json")).expect("meta")).expect("meta is JSON");
    assert_eq!(meta["rays"], json["rays"]);
    // Another tracer could not reproduce instances or alpha tests from the dump.
    fails_with(&["bench", "--scene", "builtin:forest", "--probes", "2,2,2", "--dump-rays", &d], "without instances");
    fails_with(&["bench", "--gi", "ddgi", "--dump-rays", &d], "takes no --gi");
}

/// The DDGI sweep's bare rate traces exactly the rays of the field update's batch:
/// both rates divide by the same ray count (it once divided the bare trace of every
/// probe by the field's traced probes only).
#[test]
fn ddgi_bench_holds_field_and_bare_rates_to_the_same_rays() {
    let o = probegi(&["bench", "--gi", "ddgi", "--grids", "6,6,6", "--rays", "32", "--frames", "1"]);
    assert!(o.status.success(), "{}", stderr(&o));
    let json: serde_json::Value = serde_json::from_slice(&o.stdout).expect("bench prints JSON");
    let row = &json["sweep"][0];
    let rays = row["rays_per_frame"].as_u64().expect("rays_per_frame");
    assert_eq!(row["bare_rays"].as_u64(), Some(rays), "{row}");
    // The Cornell box's 6³ grid puts its outer probes inside the walls: fewer
    // traced than stored, which is where the two counts used to part.
    let probes = row["probe_count"].as_u64().expect("probe_count");
    assert!(rays < probes * 32, "every probe traced: {row}");
    assert!(row["bare_closest_hit_mrays_per_s"].as_f64().expect("bare") > 0.0);
    assert!(row["field_update_mrays_per_s"].as_f64().expect("field") > 0.0);
}

#[test]
fn sh_render_reports_probes_and_rejects_bad_settings_by_name() {
    let stats = tmp("sh.json");
    let out = tmp("sh.png");
    let o = probegi(&[
        "render",
        "--gi",
        "sh",
        "--width",
        "24",
        "--height",
        "24",
        "--frames",
        "3",
        "--probes",
        "4,4,4",
        "--set",
        "hysteresis=0.2",
        "--out",
        &out.to_string_lossy(),
        "--stats",
        &stats.to_string_lossy(),
    ]);
    assert!(o.status.success(), "{}", stderr(&o));
    let json: serde_json::Value = serde_json::from_str(&std::fs::read_to_string(&stats).expect("stats")).expect("json");
    assert_eq!(json["probes"], 2 * 64, "two cascades of 4×4×4");
    assert!(json["pass_ms"]["sh_update"].as_f64().is_some() && json["field_update_ms"].as_f64().is_some());
    fails_with(&["render", "--gi", "sh", "--set", "hysteresis=0"], "sh_hysteresis");
    fails_with(&["render", "--gi", "sh", "--set", "bogus=1"], "unknown setting `bogus`");
    fails_with(&["render", "--gi", "sh", "--rays-per-probe", "8"], "SH probes trace no rays");
    fails_with(&["render", "--gi", "sh", "--show-probes"], "need --gi ddgi");
    let toml = tmp("bad-sh.toml");
    std::fs::write(&toml, "[[meshes]]\npath = \"builtin:cornell-box\"\n[sh]\nsh_cascade_count = 0\n").expect("write");
    fails_with(&["render", "--gi", "sh", "--scene", &toml.to_string_lossy()], "sh.sh_cascade_count");
}

#[test]
fn sequence_writes_every_frame_and_reference_renders_any_frame() {
    let scene = PathBuf::from(env!("CARGO_MANIFEST_DIR")).join("../../scenes/cornell-moving-light.toml");
    let dir = tmp("seq");
    let o = probegi(&[
        "render",
        "--scene",
        &scene.to_string_lossy(),
        "--width",
        "16",
        "--height",
        "16",
        "--frames",
        "4",
        "--sequence",
        &dir.to_string_lossy(),
        "--sequence-exr",
        "--out",
        &tmp("seq-last.png").to_string_lossy(),
    ]);
    assert!(o.status.success(), "{}", stderr(&o));
    for f in 0..4 {
        for ext in ["png", "exr"] {
            assert!(dir.join(format!("frame-{f:04}.{ext}")).is_file(), "frame {f} {ext}");
        }
    }
    // The light sweeps from the red wall to the green: frames 0 and 30 differ.
    let r = |frame: &str, name: &str| {
        let out = tmp(name);
        let o = probegi(&[
            "reference",
            "--scene",
            &scene.to_string_lossy(),
            "--width",
            "8",
            "--height",
            "8",
            "--spp",
            "4",
            "--frame",
            frame,
            "--out",
            &out.to_string_lossy(),
        ]);
        assert!(o.status.success(), "{}", stderr(&o));
        std::fs::read(out).expect("reference written")
    };
    assert_ne!(r("0", "f0.exr"), r("30", "f30.exr"));
    fails_with(&["reference", "--frame", "nan", "--out", "x.exr"], "--frame");
}

#[test]
fn lag_writes_the_plot_the_curves_and_the_numbers() {
    // A dot in the name (as `lag-0.97.png`): every output keeps the whole stem.
    let out = tmp("lag").join("lag-0.5.png");
    let o = probegi(&[
        "lag",
        "--out",
        &out.to_string_lossy(),
        "--size",
        "12",
        "--hysteresis",
        "0.5,0.9",
        "--frames-before",
        "4",
        "--frames-after",
        "6",
        "--rays-per-probe",
        "16",
        "--target-frames",
        "12",
    ]);
    assert!(o.status.success(), "{}", stderr(&o));
    assert!(out.is_file() && out.with_file_name("lag-0.5-curves.png").is_file());
    let csv = std::fs::read_to_string(out.with_file_name("lag-0.5.csv")).expect("csv");
    // Header + 2 steps × 2 hysteresis × heuristics on/off.
    assert_eq!(csv.lines().count(), 1 + 8, "{csv}");
    assert!(csv.lines().nth(1).is_some_and(|l| l.starts_with("light on,0.5,true,")), "{csv}");
    fails_with(&["lag", "--hysteresis", "1.5"], "--hysteresis");
}

#[test]
fn gif_preview_and_builtin_seed_scenes() {
    let gif = tmp("preview.gif");
    let o = probegi(&[
        "render",
        "--scene",
        "builtin:color-bleed",
        "--gi",
        "ddgi",
        "--width",
        "16",
        "--height",
        "12",
        "--frames",
        "5",
        "--gif",
        &gif.to_string_lossy(),
        "--out",
        &tmp("color-bleed.png").to_string_lossy(),
    ]);
    assert!(o.status.success(), "{}", stderr(&o));
    let bytes = std::fs::read(&gif).expect("gif written");
    assert!(bytes.starts_with(b"GIF89a"));
    // Five frames: five image descriptors (0x2C after a graphic control extension).
    assert_eq!(bytes.windows(2).filter(|w| w == &[0x00, 0x2C]).count(), 5);
    // Sponza with a moving sun needs the shared folder and says so.
    let o = Command::new(env!("CARGO_BIN_EXE_probegi"))
        .args(["render", "--scene", "builtin:sponza-sun", "--out", &tmp("s.png").to_string_lossy()])
        .env("PROBEGI_SHARED_DIR", "/nonexistent/shared")
        .output()
        .expect("runs");
    assert!(!o.status.success());
    assert!(stderr(&o).contains("PROBEGI_SHARED_DIR"), "{}", stderr(&o));
}

#[test]
fn cascades_volumes_and_a_keyframed_camera_from_the_command_line() {
    let s = |p: &PathBuf| p.to_string_lossy().into_owned();
    // --cascades N: N tracking windows in one batch, split reported per volume.
    let stats = tmp("cascades.json");
    let o = probegi(&[
        "render",
        "--gi",
        "ddgi",
        "--cascades",
        "2",
        "--probes",
        "3,3,3",
        "--set",
        "probe_spacing_m=0.5",
        "--rays-per-probe",
        "16",
        "--width",
        "16",
        "--height",
        "16",
        "--frames",
        "2",
        "--out",
        &s(&tmp("c.exr")),
        "--stats",
        &s(&stats),
    ]);
    assert!(o.status.success(), "{}", stderr(&o));
    let json: serde_json::Value = serde_json::from_str(&std::fs::read_to_string(&stats).expect("stats")).expect("json");
    assert_eq!(json["volumes"], 2);
    assert_eq!(json["probes"], 54);
    // Camera-centred cascades update by the screen scheme unless told otherwise.
    let states = json["probe_states"].as_object().expect("states");
    assert!(states.keys().all(|k| k == "requested" || k == "idle"), "{states:?}");
    let split: Vec<u64> =
        json["batch_rays_per_volume"].as_array().expect("split").iter().map(|v| v.as_u64().expect("n")).collect();
    assert_eq!(split.iter().sum::<u64>(), json["batch_rays"].as_u64().expect("batch"));
    fails_with(&["render", "--cascades", "2", "--out", &s(&tmp("x.png"))], "--gi ddgi");
    fails_with(&["render", "--gi", "ddgi", "--cascades", "0", "--out", &s(&tmp("x.png"))], "--cascades 0");
    fails_with(
        &["render", "--gi", "ddgi", "--set", "probe_spacing_m=-1", "--out", &s(&tmp("x.png"))],
        "probe_spacing_m",
    );

    // [[volumes]] in a scene file, and a camera that moves between keyframes.
    let scene = tmp("world.toml");
    std::fs::write(
        &scene,
        r#"
[[meshes]]
path = "builtin:cornell-box"
[camera]
position = [0.0, 1.0, 3.0]
target = [0.0, 1.0, 0.0]
fov_y_deg = 50.0
keyframes = [{ frame = 0 }, { frame = 2, position = [0.5, 1.2, 2.5] }]
[[volumes]]
probe_counts = [3, 3, 3]
[[volumes]]
probe_counts = [4, 4, 4]
probe_spacing_m = [0.3, 0.3, 0.3]
volume_tracks_camera = true
"#,
    )
    .expect("write scene");
    let seq = tmp("seq");
    let o = probegi(&[
        "render",
        "--scene",
        &s(&scene),
        "--gi",
        "ddgi",
        "--rays-per-probe",
        "16",
        "--width",
        "16",
        "--height",
        "16",
        "--frames",
        "3",
        "--sequence",
        &s(&seq),
        "--out",
        &s(&tmp("v.exr")),
        "--stats",
        &s(&stats),
    ]);
    assert!(o.status.success(), "{}", stderr(&o));
    let json: serde_json::Value = serde_json::from_str(&std::fs::read_to_string(&stats).expect("stats")).expect("json");
    assert_eq!(json["volumes"], 2);
    let a = std::fs::read(seq.join("frame-0000.png")).expect("frame 0");
    let b = std::fs::read(seq.join("frame-0002.png")).expect("frame 2");
    assert_ne!(a, b, "the camera moved");
    // Both [volume] and [[volumes]] is an error naming the file.
    let both = "[[meshes]]\npath = \"builtin:cornell-box\"\n[volume]\nprobe_counts = [2, 2, 2]\n[[volumes]]\nprobe_counts = [2, 2, 2]\n";
    std::fs::write(&scene, both).expect("write");
    fails_with(&["render", "--scene", &s(&scene), "--out", &s(&tmp("x.png"))], "[[volumes]]");
}

#[test]
fn gpu_render_keeps_the_field_on_the_device_and_draws_probes_on_the_cpu_camera() {
    // Where the suite requires the GPU tests (scripts/test.sh found a Vulkan driver).
    if std::env::var_os("PROBEGI_REQUIRE_GPU").is_none() {
        eprintln!("skipped: PROBEGI_REQUIRE_GPU is not set");
        return;
    }
    let s = |p: &PathBuf| p.to_string_lossy().into_owned();
    for show_probes in [false, true] {
        let (png, stats, atlases) = (tmp("gpu.png"), tmp("gpu.json"), tmp("gpu-atlases"));
        let mut args = vec!["render", "--gi", "ddgi", "--backend", "wgpu", "--frames", "3", "--width", "32"];
        args.extend(["--height", "24", "--probes", "4,4,4", "--rays-per-probe", "32"]);
        let (png_s, stats_s, atlases_s) = (s(&png), s(&stats), s(&atlases));
        args.extend(["--out", &png_s, "--stats", &stats_s, "--dump-atlases", &atlases_s]);
        if show_probes {
            args.push("--show-probes");
        }
        let o = probegi(&args);
        assert!(o.status.success(), "{}", stderr(&o));
        let json: serde_json::Value =
            serde_json::from_str(&std::fs::read_to_string(&stats).expect("stats")).expect("json");
        assert_eq!(json["backend"], "wgpu");
        assert_eq!(json["probe_shade_on"], "gpu");
        assert_eq!(json["camera_on"], if show_probes { "cpu" } else { "gpu" });
        // Where the device has timestamp queries (lavapipe does), the device's own
        // shade time sits inside the host's wait around that pass.
        if let Some(gpu) = json["pass_ms"]["gpu_shade"].as_f64() {
            let wall = json["pass_ms"]["shade"].as_f64().expect("shade wall time");
            assert!(gpu > 0.0 && gpu <= wall * 1.05 + 0.5, "gpu_shade {gpu} ms against a {wall} ms wait");
            assert!(json["pass_ms"]["gpu_blend"].as_f64().is_some_and(|b| b > 0.0), "{json}");
        }
        // The atlases were read back from the device for the dump.
        assert!(atlases.join("irradiance.exr").exists());
    }
    // A moving object and instanced meshes go through the device's top level.
    let moving = PathBuf::from(env!("CARGO_MANIFEST_DIR")).join("../../scenes/moving-box.toml");
    for scene in [s(&moving), "builtin:forest".to_string()] {
        let (png, stats) = (tmp("gpu-tlas.png"), tmp("gpu-tlas.json"));
        let (png_s, stats_s) = (s(&png), s(&stats));
        let o = probegi(&[
            "render",
            "--scene",
            &scene,
            "--gi",
            "ddgi",
            "--backend",
            "wgpu",
            "--frames",
            "3",
            "--width",
            "32",
            "--height",
            "24",
            "--probes",
            "4,4,4",
            "--rays-per-probe",
            "32",
            "--out",
            &png_s,
            "--stats",
            &stats_s,
        ]);
        assert!(o.status.success(), "{scene}: {}", stderr(&o));
        let json: serde_json::Value =
            serde_json::from_str(&std::fs::read_to_string(&stats).expect("stats")).expect("json");
        assert_eq!(json["camera_on"], "gpu", "{scene}");
    }
}

#[test]
fn gpu_bench_runs_the_pipelined_update_as_one_submission_without_a_wait() {
    if std::env::var_os("PROBEGI_REQUIRE_GPU").is_none() {
        eprintln!("skipped: PROBEGI_REQUIRE_GPU is not set");
        return;
    }
    for states in ["jcgt", "all-active"] {
        let set = format!("probe_states={states}");
        let o = probegi(&[
            "bench",
            "--gi",
            "ddgi",
            "--backend",
            "wgpu",
            "--grids",
            "4,4,4",
            "--rays",
            "32",
            "--frames",
            "1",
            "--repeat",
            "1",
            "--set",
            &set,
        ]);
        assert!(o.status.success(), "{}", stderr(&o));
        let json: serde_json::Value = serde_json::from_slice(&o.stdout).expect("bench json");
        let piped = &json["sweep"][0]["pipelined"];
        // At least 4 updates back to back whatever --frames says; each one submission, none waited for.
        assert_eq!(piped["updates"], 4, "{piped}");
        assert_eq!(piped["submissions"].as_f64(), Some(1.0), "{piped}");
        assert_eq!(piped["blocking_waits"].as_f64(), Some(0.0), "{piped}");
        let (host, field_set) =
            (piped["host_ms"].as_f64().expect("host"), piped["field_set_ms"].as_f64().expect("set"));
        assert!(field_set > 0.0 && field_set <= host, "{piped}");
        // The calling thread's CPU time, where the platform says (Linux does).
        if cfg!(target_os = "linux") {
            assert!(piped["host_cpu_ms"].as_f64().is_some_and(|ms| ms > 0.0), "{piped}");
        }
        // A still field: past the warm-up's and the timed update's first
        // blends (a history begins, Newly Vigilant probes settle), every
        // pipelined update keeps the plan before it.
        assert_eq!(piped["plans_kept"].as_f64(), Some(1.0), "{piped}");
        assert!(piped["mrays_per_s"].as_f64().is_some_and(|r| r > 0.0), "{piped}");
    }
}

#[test]
fn ray_budget_inputs_are_checked_before_rendering() {
    for (set, key) in [
        ("ray_budget=-5", "ray_budget"),
        ("ray_budget_max_interval_frames=0", "ray_budget_max_interval_frames"),
        ("ray_budget_hysteresis_per_frame=maybe", "ray_budget_hysteresis_per_frame"),
        ("ray_budget_change_lag_updates=9", "ray_budget_change_lag_updates"),
        ("probe_usage_lag_updates=9", "probe_usage_lag_updates"),
        ("probe_usage_lag_updates=-1", "probe_usage_lag_updates"),
    ] {
        fails_with(&["render", "--gi", "ddgi", "--set", set], key);
    }
    fails_with(&["lag", "--set", "ray_budget_max_interval_frames=0"], "ray_budget_max_interval_frames");
}

#[test]
fn shadow_field_inputs_are_checked_before_rendering() {
    // `--ao` needs a shadowing field to draw; the field's settings are validated by name.
    fails_with(&["render", "--gi", "ddgi", "--ao", &tmp("ao.png").to_string_lossy()], "shadow_field=true");
    fails_with(&["render", "--ao", &tmp("ao2.png").to_string_lossy()], "--gi ddgi");
    for (set, key) in [
        ("shadow_field_sharpness=0", "shadow_field_sharpness"),
        ("shadow_field_texels=0", "shadow_field_texels"),
        ("shadow_field_surfel_reach_rel=-1", "shadow_field_surfel_reach_rel"),
        ("shadow_field_max_lights=0", "shadow_field_max_lights"),
    ] {
        fails_with(&["render", "--gi", "ddgi", "--set", "shadow_field=true", "--set", set], key);
    }
    // A reference's visibility image: exact shadow rays, values in [0, 1].
    let (out, ao) = (tmp("ref-ao.exr"), tmp("ref-ao-vis.exr"));
    let o = probegi(&[
        "reference",
        "--scene",
        "builtin:shadow-box",
        "--spp",
        "1",
        "--width",
        "32",
        "--height",
        "24",
        "--out",
        &out.to_string_lossy(),
        "--ao",
        &ao.to_string_lossy(),
    ]);
    assert!(o.status.success(), "{}", stderr(&o));
    let probegi_image::LoadedImage::Hdr(img) = probegi_image::read_image(&ao).expect("read the visibility image")
    else {
        panic!("an .exr reads as HDR");
    };
    let v: Vec<f32> = img.pixels.iter().map(|p| p.x).collect();
    assert!(v.iter().all(|x| (0.0..=1.0).contains(x)), "visibility outside [0, 1]");
    assert!(v.contains(&1.0) && v.contains(&0.0), "the box shows both lit and shadowed pixels");
}

#[test]
fn view_runs_scripted_without_a_window_and_names_bad_input() {
    // No window system: the message says so and names the scripted way.
    let o = Command::new(env!("CARGO_BIN_EXE_probegi"))
        .args(["view", "--scene", "builtin:cornell-box"])
        .env_remove("DISPLAY")
        .env_remove("WAYLAND_DISPLAY")
        .output()
        .expect("runs");
    assert!(!o.status.success() && stderr(&o).contains("no window system"), "{}", stderr(&o));
    assert!(stderr(&o).contains("--headless"), "{}", stderr(&o));
    fails_with(&["view", "--headless"], "--exit-after-frames");
    let script = tmp("bad-script.txt");
    std::fs::write(&script, "0 key w down\n3 key z down\n").expect("write");
    let s = script.to_string_lossy().into_owned();
    fails_with(
        &["view", "--headless", "--exit-after-frames", "2", "--input-script", &s],
        "bad-script.txt:2: unknown key",
    );
    fails_with(&["view", "--headless", "--exit-after-frames", "2", "--fly-speed=-1"], "--fly-speed");
    fails_with(&["view", "--headless", "--exit-after-frames", "2", "--view", "indirect"], "--view");
    let keys = tmp("viewer-keys.txt");
    std::fs::write(&keys, "0 key w down\n5 key f5 down\n").expect("write");
    fails_with(
        &["view", "--headless", "--exit-after-frames", "2", "--input-script", &keys.to_string_lossy()],
        "viewer-keys.txt: the viewer key Reference at frame 5 acts in the window only",
    );
    let help = probegi(&["view", "--help"]);
    let help = String::from_utf8_lossy(&help.stdout);
    for key in ["W A S D", "F5", "F12", "Space", "Ctrl+R"] {
        assert!(help.contains(key), "`view --help` lists {key}: {help}");
    }
    // A scripted CPU run: the camera flies, the screenshot is a lit frame.
    let good = tmp("fly.txt");
    std::fs::write(&good, "# forward for 10 frames\n0 key w down\n10 key w up\n").expect("write");
    let shot = tmp("view.exr");
    let o = probegi(&[
        "view",
        "--headless",
        "--backend",
        "cpu",
        "--input-script",
        &good.to_string_lossy(),
        "--exit-after-frames",
        "12",
        "--fly-speed",
        "0.6",
        "--width",
        "32",
        "--height",
        "24",
        "--rays-per-probe",
        "32",
        "--screenshot",
        &shot.to_string_lossy(),
        "--bench",
    ]);
    assert!(o.status.success(), "{}", stderr(&o));
    let report: serde_json::Value = serde_json::from_slice(&o.stdout).expect("--bench prints JSON");
    assert_eq!(report["frames"], 12);
    let (median, p95, max) = (&report["frame_ms"]["median"], &report["frame_ms"]["p95"], &report["frame_ms"]["max"]);
    let ms = |v: &serde_json::Value| v.as_f64().expect("a number");
    assert!(0.0 < ms(median) && ms(median) <= ms(p95) && ms(p95) <= ms(max), "{report}");
    assert!(report["field_update_ms"].as_f64().is_some_and(|v| v > 0.0), "{report}");
    // 10 frames of 1/60 s at 0.6 m/s: 0.1 m along the view from the Cornell camera's z.
    assert!(stderr(&o).contains("view: 12 frames of builtin:cornell-box"), "{}", stderr(&o));
    let probegi_image::LoadedImage::Hdr(image) = probegi_image::read_image(&shot).expect("screenshot") else {
        panic!("an EXR screenshot reads back as HDR");
    };
    assert!(image.mean().max_element() > 0.01 && image.first_invalid_pixel().is_none());
}

#[test]
fn sky_maps_light_the_render_and_bad_ones_are_refused_naming_the_file_and_the_place() {
    use glam::Vec3;
    let s = |p: &PathBuf| p.to_string_lossy().into_owned();
    // Written with the exr crate itself: probegi's writer refuses what these test.
    let write = |name: &str, w: u32, h: u32, f: &(dyn Fn(u32, u32) -> Vec3 + Sync)| {
        let p = tmp(name);
        exr::prelude::write_rgb_file(&p, w as usize, h as usize, |x, y| {
            let c = f(x as u32, y as u32);
            (c.x, c.y, c.z)
        })
        .expect("write map");
        s(&p)
    };
    let out = s(&tmp("sky.exr"));
    let render = |extra: &[&str]| {
        let mut args = vec!["render", "--frames", "1", "--width", "8", "--height", "8", "--out", &out];
        args.extend_from_slice(extra);
        args.iter().map(|a| a.to_string()).collect::<Vec<_>>()
    };
    let fails = |extra: &[&str], needle: &str| {
        let args = render(extra);
        fails_with(&args.iter().map(String::as_str).collect::<Vec<_>>(), needle);
    };
    // A camera looking straight up sees only the map: its middle row is 3 (× intensity 2).
    let good = write("good.exr", 16, 8, &|_, _| Vec3::splat(3.0));
    let up = ["--camera-pos", "0,100,0", "--camera-target", "0,101,0", "--camera-up", "0,0,1"];
    let mut args = render(&up);
    args.extend(["--sky-map", &good, "--sky-intensity", "2"].map(String::from));
    let o = probegi(&args.iter().map(String::as_str).collect::<Vec<_>>());
    assert!(o.status.success(), "{}", stderr(&o));
    let img = match probegi_image::read_image(&tmp("sky.exr")).expect("render") {
        probegi_image::LoadedImage::Hdr(img) => img,
        probegi_image::LoadedImage::Srgb8 { .. } => panic!("an EXR"),
    };
    assert!((img.mean() - Vec3::splat(6.0)).abs().max_element() < 1e-4, "sky pixels {}", img.mean());

    fails(&["--sky-map", "/nonexistent/dir/sky.exr"], "/nonexistent/dir/sky.exr");
    let square = write("square.exr", 8, 8, &|_, _| Vec3::ONE);
    fails(&["--sky-map", &square], "twice as wide as high; this one is 8×8");
    let nan = write("nan.exr", 8, 4, &|x, y| if (x, y) == (5, 2) { Vec3::new(1.0, f32::NAN, 1.0) } else { Vec3::ONE });
    fails(&["--sky-map", &nan], "texel (5, 2)");
    let negative = write("negative.exr", 8, 4, &|x, y| if (x, y) == (1, 3) { Vec3::splat(-1.0) } else { Vec3::ONE });
    fails(&["--sky-map", &negative], "texel (1, 3)");
    let hdr = tmp("broken.hdr");
    std::fs::write(&hdr, b"#?RADIANCE\nFORMAT=32-bit_rle_rgbe\n\n-Y 4 +Z 8\n\x01\x02").expect("write");
    fails(&["--sky-map", &s(&hdr)], "broken.hdr");
    fails(&["--sky-intensity", "2"], "need a sky map");
    fails(&["--sky-map", &good, "--sky-intensity", "-1"], "--sky-intensity -1");
    fails(&["--sky-map", &good, "--sky", "1,1,1"], "cannot be used with");

    // A scene file's [sky_map], relative to the file, and not beside sky_radiance.
    let dir = tmp("sky-scene");
    std::fs::create_dir_all(&dir).expect("dir");
    std::fs::copy(tmp("good.exr"), dir.join("map.exr")).expect("copy");
    let floor = "[[objects]]\npolygon_m = [[-1.0, 0.0, -1.0], [-1.0, 0.0, 1.0], [1.0, 0.0, 1.0], [1.0, 0.0, -1.0]]\n";
    let toml = dir.join("s.toml");
    std::fs::write(&toml, format!("{floor}[sky_map]\npath = \"map.exr\"\nintensity = 0.5\nrotation_deg = 10.0\n"))
        .expect("write");
    let mut args = render(&up);
    args.extend(["--scene".to_string(), s(&toml)]);
    let o = probegi(&args.iter().map(String::as_str).collect::<Vec<_>>());
    assert!(o.status.success(), "{}", stderr(&o));
    std::fs::write(&toml, format!("sky_radiance = [1.0, 1.0, 1.0]\n{floor}[sky_map]\npath = \"map.exr\"\n"))
        .expect("write");
    fails(&["--scene", &s(&toml)], "not both");
    std::fs::write(&toml, format!("{floor}[sky_map]\npath = \"gone.exr\"\n")).expect("write");
    fails(&["--scene", &s(&toml)], "gone.exr");
}

#[test]
fn screen_space_gi_that_sees_no_directly_lit_pixel_says_why_it_is_black() {
    // Looking up at the Cornell box's ceiling beside the light (which faces
    // away): every visible surface is lit only indirectly, which screen-space
    // GI cannot gather from the screen (seed 001 §7.3). DDGI lights the same view.
    let out = tmp("sh-ceiling.png").to_string_lossy().into_owned();
    let view = ["--camera-pos=-0.6,1.5,-0.6", "--camera-target=-0.6,1.99,-0.6", "--fov-y", "30"];
    let mut args = vec!["render", "--frames", "2", "--width", "16", "--height", "16", "--out", &out];
    args.extend(view);
    let mut sh = args.clone();
    sh.extend(["--gi", "sh"]);
    fails_with(&sh, "no pixel of this view is lit directly");
    args.extend(["--gi", "ddgi", "--probes", "4,4,4", "--rays-per-probe", "64"]);
    let o = probegi(&args);
    assert!(o.status.success(), "{}", stderr(&o));
}

#[test]
fn cascades_without_probe_counts_are_three_16_by_8_by_16_grids() {
    // `--cascades N` alone: each cascade 16×8×16 (DEFAULT_CASCADE_PROBE_COUNTS),
    // not the single volume's 8×8×8.
    let stats = tmp("cascades-default.json");
    let (out, stats_s) = (tmp("cd.exr").to_string_lossy().into_owned(), stats.to_string_lossy().into_owned());
    let o = probegi(&[
        "render",
        "--gi",
        "ddgi",
        "--cascades",
        "3",
        "--rays-per-probe",
        "16",
        "--width",
        "8",
        "--height",
        "8",
        "--frames",
        "1",
        "--out",
        &out,
        "--stats",
        &stats_s,
    ]);
    assert!(o.status.success(), "{}", stderr(&o));
    let json: serde_json::Value = serde_json::from_str(&std::fs::read_to_string(&stats).expect("stats")).expect("json");
    assert_eq!(json["volumes"], 3);
    assert_eq!(json["probes"], 3 * 16 * 8 * 16);
}
