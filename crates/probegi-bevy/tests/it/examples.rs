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
