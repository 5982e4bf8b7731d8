//! The glossy BSDF in the reference and seed 004 §4.4's second-order glossy from
//! probes, on McGuire's CornellBox-Glossy.

use std::path::PathBuf;

use probegi_core::camera::CameraRays;
use probegi_core::ddgi_settings::DdgiVolumeSettings;
use probegi_core::image::Image;
use probegi_cpu::{PathTracer, PathTracerSettings};
use probegi_frame::frame_loop::{GiMethod, RenderSettings, render_frames};
use probegi_image::mean_flip_hdr;
use probegi_scene::{BvhSettings, BvhTracer, Scene, load_scene};

/// CornellBox-Glossy as shipped uses a `light` material its MTL does not define (the
/// loader warns and makes it grey); we give it CornellBox-Original's Ke = 17 12 4.
fn glossy_box() -> Scene {
    let p = PathBuf::from(env!("CARGO_MANIFEST_DIR")).join("../../../shared/scenes/cornell-box/CornellBox-Glossy.obj");
    let mut s = load_scene(&p.to_string_lossy()).expect("CornellBox-Glossy from ../shared");
    assert!(s.warnings.iter().any(|w| w.contains("light")), "{:?}", s.warnings);
    let light = s.materials.iter_mut().find(|m| m.name == "light").expect("light material");
    light.emissive_factor = glam::Vec3::new(17.0, 12.0, 4.0);
    light.base_color_factor = glam::Vec3::splat(0.78);
    s.camera = Some(probegi_core::camera::Camera::default());
    s
}

fn flip(a: &Image, b: &Image) -> f32 {
    mean_flip_hdr(a, b).expect("same size")
}

#[test]
fn glossy_mis_and_bsdf_only_estimators_agree() {
    let scene = glossy_box();
    assert!(scene.materials.iter().any(|m| m.specular_color.max_element() > 0.5), "Ks kept");
    let bvh = BvhTracer::build(&scene.mesh, BvhSettings::default());
    let cam = CameraRays::new(&scene.camera.expect("camera"), 24, 24);
    let render = |nee: bool| {
        let s = PathTracerSettings { pt_spp: 512, seed: 21, pt_light_sampling: nee, ..Default::default() };
        PathTracer::new(&scene, &bvh, s).render(&cam, 24, 24, &|| {}).0.mean()
    };
    let (mis, bsdf_only) = (render(true), render(false));
    eprintln!("glossy box mean radiance: MIS {mis}, BSDF-only {bsdf_only}");
    for c in 0..3 {
        assert!((mis[c] - bsdf_only[c]).abs() / mis[c] < 0.03, "{mis} vs {bsdf_only}");
    }
}

#[test]
fn second_order_glossy_brings_the_glossy_box_closer_to_the_reference() {
    let scene = glossy_box();
    let bvh = BvhTracer::build(&scene.mesh, BvhSettings::default());
    let size = 48;
    let cam = CameraRays::new(&scene.camera.expect("camera"), size, size);
    let reference = PathTracer::new(&scene, &bvh, PathTracerSettings { pt_spp: 512, seed: 4, ..Default::default() })
        .render(&cam, size, size, &|| {})
        .0;
    let render = |gi: GiMethod| {
        let rs = RenderSettings { width: size, height: size, frames: 80, seed: 8, gi, ..Default::default() };
        render_frames(&scene, &bvh, &cam, &rs, |_, _| {}).image
    };
    let base = DdgiVolumeSettings { probe_rays_per_probe: 128, probe_hysteresis: 0.9, ..Default::default() };
    let with = render(GiMethod::Ddgi(Box::new(base.clone())));
    let without = render(GiMethod::Ddgi(Box::new(DdgiVolumeSettings { glossy_second_order: false, ..base })));
    let direct = render(GiMethod::None);
    let (fw, fo, fd) = (flip(&reference, &with), flip(&reference, &without), flip(&reference, &direct));
    eprintln!("CornellBox-Glossy 48×48 FLIP: second order {fw:.4}, without {fo:.4}, direct only {fd:.4}");
    assert!(fw <= fo + 0.002, "second-order glossy must not move away from the reference: {fw} vs {fo}");
    // Measured 0.075 with the GGX lobe's directional albedo; 0.086 with Schlick's F
    // alone, which ignores masking and over-reflects on rough lobes.
    assert!(fw < 0.08, "second-order glossy weighted by the GGX lobe: {fw}");
    assert!(fw < 0.6 * fd, "DDGI with glossy {fw} must be far closer than direct only {fd}");
    let (m, r) = (with.mean(), reference.mean());
    assert!((m.x - r.x).abs() / r.x < 0.05, "mean {m} vs reference {r}");
}
