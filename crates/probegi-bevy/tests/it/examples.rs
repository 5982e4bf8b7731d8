//! The Bevy examples, run headless as part of the suite (on lavapipe in CI):
//! `examples/bevy_cornell.rs` renders its room with the field and without
//! (`--no-field`: no volume, so `ProbegiMaterial` draws Bevy's lighting).
//! The field must put the walls' colours on the floor beside them, which
//! Bevy's ambient light cannot: the floor by the red wall redder, and by the
//! green wall greener, than in Bevy's own image.

#[path = "../../examples/bevy_cornell.rs"]
#[allow(dead_code)]
mod bevy_cornell;

use bevy::math::UVec2;

/// Mean sRGB colour of the pixels in the box of fractions `x` × `y` of the image.
fn mean(rgba: &[u8], size: UVec2, x: [f32; 2], y: [f32; 2]) -> [f32; 3] {
    let (mut sum, mut n) = ([0.0f32; 3], 0.0);
    let px = |f: f32, n: u32| (f * n as f32) as u32;
    for row in px(y[0], size.y)..px(y[1], size.y) {
        for col in px(x[0], size.x)..px(x[1], size.x) {
            let p = &rgba[((row * size.x + col) * 4) as usize..][..3];
            (0..3).for_each(|c| sum[c] += p[c] as f32);
            n += 1.0;
        }
    }
    sum.map(|s| s / n)
}

#[test]
fn the_cornell_example_bleeds_the_walls_colours_where_bevys_ambient_cannot() {
    if probegi_wgpu::GpuContext::headless_unless_absent().expect("PROBEGI_REQUIRE_GPU is set").is_none() {
        return;
    }
    let dir = std::env::temp_dir().join(format!("probegi-bevy-examples-{}", std::process::id()));
    let run = |no_field: bool| {
        let out = dir.join(if no_field { "cornell-bevy.png" } else { "cornell-field.png" });
        let args = bevy_cornell::bevy_example::Args {
            frames: 40,
            out: Some(out.clone()),
            no_field,
            probes: false,
            size: UVec2::new(320, 240),
            screenshot: None,
            bench: false,
        };
        let rgba = bevy_cornell::run(&args).expect("the example ran").expect("headless pixels");
        assert!(std::fs::metadata(&out).map(|m| m.len() > 1000).unwrap_or(false), "a PNG was written");
        rgba
    };
    let (field, bevy) = (run(false), run(true));
    let size = UVec2::new(320, 240);
    // The floor's strips by the red (left) and green (right) walls.
    let (y, left, right) = ([0.85, 0.89], [0.23, 0.3], [0.7, 0.77]);
    let red = |rgba: &[u8]| {
        let m = mean(rgba, size, left, y);
        m[0] / m[1]
    };
    let green = |rgba: &[u8]| {
        let m = mean(rgba, size, right, y);
        m[1] / m[0]
    };
    let back = mean(&field, size, [0.4, 0.6], [0.3, 0.4]);
    assert!(back.iter().all(|c| *c > 60.0), "the back wall is lit: {back:?}");
    eprintln!(
        "red floor r/g: field {:.3}, Bevy {:.3}; green floor g/r: field {:.3}, Bevy {:.3}",
        red(&field),
        red(&bevy),
        green(&field),
        green(&bevy)
    );
    assert!(red(&field) > red(&bevy) + 0.02, "the red wall's light on the floor");
    assert!(green(&field) > green(&bevy) + 0.02, "the green wall's light on the floor");
    let _ = std::fs::remove_dir_all(&dir);
}

/// The Cornell example in a real window (the `window` feature, under Xvfb):
/// after 20 frames its `--screenshot` must show the room, neither black nor
/// the clear colour. Without `xvfb-run` or a Vulkan driver the test skips
/// with a warning, unless `PROBEGI_REQUIRE_DISPLAY=1`.
#[cfg(feature = "window")]
#[test]
fn the_cornell_example_draws_the_room_in_a_window() {
    use std::process::Command;
    let xvfb = Command::new("xvfb-run").arg("--help").output().is_ok();
    let gpu = probegi_wgpu::GpuContext::headless_unless_absent().ok().flatten().is_some();
    if !xvfb || !gpu {
        assert!(
            std::env::var("PROBEGI_REQUIRE_DISPLAY").is_err(),
            "PROBEGI_REQUIRE_DISPLAY is set but xvfb-run or a Vulkan driver is missing"
        );
        eprintln!("warning: SKIP: no xvfb-run or no Vulkan driver (apt-get install xvfb mesa-vulkan-drivers)");
        return;
    }
    // `cargo test` builds the examples beside the test binaries' deps folder.
    let exe = std::env::current_exe().expect("test binary");
    let example = exe.parent().and_then(|d| d.parent()).expect("target dir").join("examples/bevy_cornell");
    let dir = std::env::temp_dir().join(format!("probegi-bevy-window-{}", std::process::id()));
    std::fs::create_dir_all(&dir).expect("temp dir");
    let shot = dir.join("window.png");
    let o = Command::new("xvfb-run")
        .args(["-a", "-s", "-screen 0 1024x768x24"])
        .arg(&example)
        .args(["--frames", "20", "--size", "320x240", "--screenshot"])
        .arg(&shot)
        .env_remove("WAYLAND_DISPLAY")
        .output()
        .expect("xvfb-run runs");
    assert!(o.status.success(), "{}: {}", example.display(), String::from_utf8_lossy(&o.stderr));
    let probegi_image::LoadedImage::Srgb8 { width, height, rgb } =
        probegi_image::read_image(&shot).expect("the screenshot")
    else {
        panic!("the screenshot is a PNG");
    };
    assert_eq!((width, height), (320, 240), "the window's size");
    let px: Vec<[u8; 3]> = rgb.chunks(3).map(|c| [c[0], c[1], c[2]]).collect();
    let share = |f: &dyn Fn(&[u8; 3]) -> bool| px.iter().filter(|p| f(p)).count() as f64 / px.len() as f64;
    // Bevy's default clear colour, sRGB (43, 44, 47), where nothing is drawn.
    let clear = share(&|p| p.iter().zip([43u8, 44, 47]).all(|(a, b)| a.abs_diff(b) <= 2));
    let dark = share(&|p| p.iter().all(|&c| c < 8));
    assert!(clear < 0.5, "the window is mostly the clear colour ({:.0} %)", clear * 100.0);
    assert!(dark < 0.5, "the window is mostly black ({:.0} %)", dark * 100.0);
    // The room: its red (left) and green (right) walls face the camera.
    let red = share(&|p| p[0] > 60 && u16::from(p[0]) > u16::from(p[1]) + 30);
    let green = share(&|p| p[1] > 60 && u16::from(p[1]) > u16::from(p[0]) + 30);
    assert!(red > 0.02 && green > 0.02, "the red and green walls: {red:.3}, {green:.3} of the pixels");
    let _ = std::fs::remove_dir_all(&dir);
}
