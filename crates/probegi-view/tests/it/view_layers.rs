//! The viewer's light-visibility view on `builtin:shadow-box` (a spot light
//! and a block): without a shadowing field it is the exact shadow-ray
//! visibility (`probegi_cpu::light_visibility` with no field, as `render --ao`
//! without one); with `shadow_field` it is the field's, which after a few
//! frames agrees with the exact one on most pixels but is not it.

use probegi_core::camera::CameraRays;
use probegi_core::ddgi_settings::DdgiVolumeSettings;
use probegi_cpu::light_visibility::light_visibility_image;
use probegi_frame::frame_loop::{GiMethod, RenderSettings};
use probegi_scene::{BvhSettings, BvhTracer, load_scene};
use probegi_view::view_layers::{ViewMode, view_image};
use probegi_view::view_session::ViewSession;

#[test]
fn the_light_visibility_view_shows_the_shadowing_fields_or_exact_shadows() {
    let scene = load_scene("builtin:shadow-box").expect("built-in scene");
    let bvh = BvhTracer::for_scene(&scene, BvhSettings::default());
    let camera = scene.default_camera();
    let (w, h) = (32, 24);
    let exact = light_visibility_image(&scene, &bvh, &CameraRays::new(&camera, w, h), w, h, None);
    let lit = exact.pixels.iter().filter(|p| p.x > 0.5).count();
    let dark = exact.pixels.iter().filter(|p| p.x < 0.1).count();
    assert!(lit > 20 && dark > 20, "the box has lit and shadowed pixels: {lit} lit, {dark} dark");
    let mut images = Vec::new();
    for shadow_field in [false, true] {
        let volume = DdgiVolumeSettings {
            probe_counts: glam::UVec3::new(8, 3, 8),
            probe_rays_per_probe: 64,
            shadow_field,
            ..Default::default()
        };
        let settings =
            RenderSettings { width: w, height: h, gi: GiMethod::Ddgi(Box::new(volume)), ..Default::default() };
        let mut session = ViewSession::new(&scene, &bvh, &camera, &settings, 1.0, vec![]);
        let mut full = session.frame(1.0 / 60.0).expect("frame");
        for _ in 0..4 {
            full = session.frame(1.0 / 60.0).expect("frame");
        }
        let view = view_image(ViewMode::LightVisibility, &full, &mut session, &bvh, 0).expect("view");
        assert_eq!((view.width, view.height), (w, h));
        assert!(view.pixels.iter().all(|p| p.x == p.y && p.y == p.z && (0.0..=1.0).contains(&p.x)), "grey, in [0, 1]");
        images.push(view);
    }
    let worst = images[0].pixels.iter().zip(&exact.pixels).map(|(a, b)| (a.x - b.x).abs()).fold(0.0, f32::max);
    assert!(worst < 1e-4, "no shadowing field: the exact visibility (differs by {worst})");
    let differ = images[1].pixels.iter().zip(&exact.pixels).filter(|(a, b)| (a.x - b.x).abs() > 1e-3).count();
    let agree = images[1].pixels.iter().zip(&exact.pixels).filter(|(a, b)| (a.x - b.x).abs() < 0.25).count();
    eprintln!("shadowing field vs exact: {differ} of {} pixels differ, {agree} within 0.25", w * h);
    assert!(differ > 0, "with a shadowing field the view reads the field");
    assert!(agree * 10 >= 7 * (w * h) as usize, "the field's visibility follows the exact one: {agree} within 0.25");
}
