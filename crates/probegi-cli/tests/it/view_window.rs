//! `probegi view` in a real window: under Xvfb (`xvfb-run`, which
//! `scripts/test.sh` installs like lavapipe), a scripted flight through the
//! Cornell box opens the window, flies, exits 0, and leaves a screenshot
//! that matches the headless run of the same script, and a capture of the
//! window that is neither black nor the clear colour. Without `xvfb-run` the
//! test skips with a warning, unless `PROBEGI_REQUIRE_DISPLAY=1`.

use crate::common;

use std::path::{Path, PathBuf};
use std::process::{Command, Output};

fn tmp(name: &str) -> PathBuf {
    common::scratch("probegi-view-window", name)
}

fn script() -> String {
    Path::new(env!("CARGO_MANIFEST_DIR")).join("../../scenes/cornell-flight.script").to_string_lossy().into_owned()
}

/// The flight's arguments (a small field so 120 frames stay quick on lavapipe).
fn flight_args(shot: &Path) -> Vec<String> {
    [
        "view",
        "--scene",
        "builtin:cornell-box",
        "--input-script",
        &script(),
        "--exit-after-frames",
        "120",
        "--width",
        "64",
        "--height",
        "64",
        "--probes",
        "4,4,4",
        "--rays-per-probe",
        "64",
        "--fly-speed",
        "0.5",
        "--screenshot",
        &shot.to_string_lossy(),
    ]
    .iter()
    .map(|s| s.to_string())
    .collect()
}

fn stderr(o: &Output) -> String {
    String::from_utf8_lossy(&o.stderr).into_owned()
}

fn has_vulkan() -> bool {
    ["/usr/share/vulkan/icd.d", "/etc/vulkan/icd.d"]
        .iter()
        .any(|d| std::fs::read_dir(d).is_ok_and(|mut e| e.next().is_some()))
}

#[test]
fn a_window_flies_the_script_and_matches_the_headless_run() {
    let xvfb = Command::new("xvfb-run").arg("--help").output().is_ok();
    if !xvfb || !has_vulkan() {
        assert!(
            std::env::var("PROBEGI_REQUIRE_DISPLAY").is_err(),
            "PROBEGI_REQUIRE_DISPLAY is set but xvfb-run or a Vulkan driver is missing"
        );
        eprintln!("warning: SKIP: no xvfb-run or no Vulkan driver (apt-get install xvfb mesa-vulkan-drivers)");
        return;
    }
    let (headless_shot, window_shot) = (tmp("headless.exr"), tmp("window.exr"));
    let mut headless = flight_args(&headless_shot);
    headless.insert(1, "--headless".into());
    let o = Command::new(env!("CARGO_BIN_EXE_probegi")).args(&headless).output().expect("runs");
    assert!(o.status.success(), "headless: {}", stderr(&o));
    let o = Command::new("xvfb-run")
        .args(["-a", "-s", "-screen 0 1280x800x24", env!("CARGO_BIN_EXE_probegi")])
        .args(flight_args(&window_shot))
        .env_remove("WAYLAND_DISPLAY")
        .output()
        .expect("runs");
    assert!(o.status.success(), "window: {}", stderr(&o));
    let read = |p: &Path| match probegi_image::read_image(p).expect("screenshot") {
        probegi_image::LoadedImage::Hdr(i) => i,
        _ => panic!("an EXR screenshot reads back as HDR"),
    };
    let (a, b) = (read(&headless_shot), read(&window_shot));
    assert!(a.mean().max_element() > 0.01, "the headless frame is lit");
    let flip = probegi_image::mean_flip_hdr(&a, &b).expect("same size");
    assert!(flip < 1e-3, "the window's frame is the headless run's: FLIP {flip}");
    // The window itself: a capture of what was on screen.
    let capture = window_shot.with_file_name("window-window.png");
    let probegi_image::LoadedImage::Srgb8 { width, height, rgb } =
        probegi_image::read_image(&capture).expect("capture")
    else {
        panic!("the capture is a PNG");
    };
    assert!(width >= 640 && height >= 400, "a real window: {width}×{height}");
    let px: Vec<[u8; 3]> = rgb.chunks(3).map(|c| [c[0], c[1], c[2]]).collect();
    let dark = px.iter().filter(|p| p.iter().all(|&c| c < 8)).count() as f64 / px.len() as f64;
    let mut colours: Vec<[u8; 3]> = px.clone();
    colours.sort_unstable();
    colours.dedup();
    // The clear colour would be one flat colour everywhere; the frame and
    // the panels give hundreds.
    assert!(dark < 0.5, "the window is mostly black ({:.0} %)", dark * 100.0);
    assert!(colours.len() > 200, "the window shows {} colours: nothing drawn", colours.len());
    let lit = px.iter().filter(|p| p[0] > 60 && u16::from(p[0]) > u16::from(p[2]) + 20).count();
    assert!(lit > 1000, "the Cornell box's red wall is on screen ({lit} red pixels)");
    assert_shows_the_frame(&b, width as usize, &px);
    let _ = std::fs::remove_dir_all(headless_shot.parent().expect("dir"));
}

/// The window shows the frame as `render` tone-maps it, whichever way it
/// reaches the window (a texture on the shared device, or RGBA8 from the
/// host): inside the live frame's rectangle (a 200-pixel square well inside
/// it: the frame is drawn at the panel's top left, scaled to about 670
/// pixels), almost every pixel is one of the frame's own tone-mapped colours
/// (nearest filtering adds none), within the device tone map's ±1 code. A
/// frame decoded from sRGB once too often, or not tone-mapped, fails: its
/// colours are others.
fn assert_shows_the_frame(frame: &probegi_core::image::Image, width: usize, px: &[[u8; 3]]) {
    let colours: std::collections::HashSet<[u8; 3]> =
        frame.pixels.iter().map(|p| probegi_core::color::tonemap_rgb8(*p)).collect();
    let near = |c: [u8; 3]| {
        (0..27).any(|k| {
            let d = [k % 3, (k / 3) % 3, k / 9].map(|d| d as i16 - 1);
            let q = [0, 1, 2].map(|i| (c[i] as i16 + d[i]).clamp(0, 255) as u8);
            colours.contains(&q)
        })
    };
    let inside: Vec<[u8; 3]> = (100..300).flat_map(|y| (100..300).map(move |x| px[y * width + x])).collect();
    let shown = inside.iter().filter(|c| near(**c)).count() as f64 / inside.len() as f64;
    assert!(shown > 0.9, "only {:.0} % of the live frame's pixels are the frame's colours", shown * 100.0);
}
