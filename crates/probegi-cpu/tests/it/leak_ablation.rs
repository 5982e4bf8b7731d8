//! Seed 000 Fig. 7: a closed room lit only through its door. Turning on the
//! leak-reduction weights one by one (none → backface → Chebyshev → bias) must
//! bring the interior closer to the path-traced reference.

use glam::{UVec3, Vec3};
use probegi_core::camera::CameraRays;
use probegi_core::ddgi_settings::{DdgiVolumeSettings, ProbeBiasMode};
use probegi_core::image::Image;
use probegi_cpu::{PathTracer, PathTracerSettings};
use probegi_frame::frame_loop::{GiMethod, RenderSettings, render_frames};
use probegi_image::mean_flip_hdr;
use probegi_scene::{BvhSettings, BvhTracer, Scene};

/// Room interior [0,4] × [0,3] × [0,4] with 0.2 m walls, a 1.2 m × 2.2 m door in
/// the +z wall, open ground outside and a low sun shining in through the door
/// (`scenes/builtin/door-room.toml`).
fn door_room() -> Scene {
    probegi_scene::load_scene("builtin:door-room").expect("built in")
}

fn flip(a: &Image, b: &Image) -> f32 {
    mean_flip_hdr(a, b).expect("same size")
}

#[test]
fn leak_weights_bring_the_interior_monotonically_closer_to_the_reference() {
    let scene = door_room();
    assert!(scene.validate().is_ok());
    let bvh = BvhTracer::build(&scene.mesh, BvhSettings::default());
    let size = 48;
    let camera = CameraRays::new(&scene.camera.expect("camera"), size, size);
    let reference = PathTracer::new(&scene, &bvh, PathTracerSettings { pt_spp: 256, seed: 5, ..Default::default() })
        .render(&camera, size, size, &|| {})
        .0;

    // Probes 0.5 m inside and 0.4 m outside each wall, so outside probes can leak in.
    let base = DdgiVolumeSettings {
        probe_counts: UVec3::new(6, 3, 6),
        probe_origin_m: Some(Vec3::new(-0.5, 0.5, -0.5)),
        probe_spacing_m: Some(Vec3::new(1.0, 1.0, 1.0)),
        probe_rays_per_probe: 128,
        probe_hysteresis: 0.8,
        probe_backface_weight: false,
        probe_chebyshev_weight: false,
        probe_bias_mode: ProbeBiasMode::None,
        ..Default::default()
    };
    let steps = [
        ("none", base.clone()),
        ("backface", DdgiVolumeSettings { probe_backface_weight: true, ..base.clone() }),
        ("chebyshev", DdgiVolumeSettings { probe_backface_weight: true, probe_chebyshev_weight: true, ..base.clone() }),
        (
            "bias",
            DdgiVolumeSettings {
                probe_backface_weight: true,
                probe_chebyshev_weight: true,
                probe_bias_mode: ProbeBiasMode::SelfShadow,
                ..base.clone()
            },
        ),
    ];
    let mut flips = Vec::new();
    for (name, settings) in steps {
        let rs = RenderSettings {
            width: size,
            height: size,
            frames: 60,
            seed: 3,
            gi: GiMethod::Ddgi(Box::new(settings)),
            ..Default::default()
        };
        let img = render_frames(&scene, &bvh, &camera, &rs, |_, _| {}).image;
        let f = flip(&reference, &img);
        eprintln!("door room, weights up to {name}: FLIP {f:.4}, mean {} (reference {})", img.mean(), reference.mean());
        flips.push(f);
    }
    for w in flips.windows(2) {
        assert!(w[1] <= w[0] + 0.002, "FLIP must not grow as weights are added: {flips:?}");
    }
    assert!(flips[3] < 0.8 * flips[0], "all weights together must clearly reduce leaks: {flips:?}");
}
