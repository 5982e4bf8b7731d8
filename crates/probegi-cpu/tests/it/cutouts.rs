//! Alpha cutouts in every ray (real-assets issue): a wall that is cut out
//! everywhere must be invisible to camera rays, shadow rays, probe rays (the
//! trace, state classification and relocation), the path-traced reference and
//! the SH screen samples and their occlusion rays. The renders with the wall
//! must equal the renders without it; with the wall opaque they must not.

use glam::Vec3;
use probegi_core::camera::CameraRays;
use probegi_core::ddgi_settings::{DdgiVolumeSettings, ProbeStatesMode};
use probegi_core::image::Image;
use probegi_core::sh_settings::ShProbeSettings;
use probegi_cpu::path_tracer::{PathTracer, PathTracerSettings};
use probegi_frame::frame_loop::{GiMethod, RenderSettings, render_frames};
use probegi_scene::builtin::{add_polygon, cornell_box};
use probegi_scene::material::{AlphaMode, Material};
use probegi_scene::texture::Texture;
use probegi_scene::{BvhSettings, BvhTracer, Scene};

const SIZE: u32 = 40;

/// The Cornell box with a wall across it between the camera and the boxes,
/// cut out everywhere (`opaque = false`) or not at all.
fn with_wall(opaque: bool) -> Scene {
    let mut s = cornell_box();
    let tex = Texture::from_rgb8(2, 2, vec![[200; 3]; 4], "clear".into()).and_then(|t| t.with_alpha(vec![0; 4]));
    s.textures.push(tex.expect("texture"));
    let mut m = Material::diffuse("cut wall", Vec3::splat(0.8));
    m.base_color_texture = Some(s.textures.len() - 1);
    m.alpha_mode = if opaque { AlphaMode::Opaque } else { AlphaMode::Mask { cutoff: 0.5 } };
    m.alpha_texture = m.base_color_texture;
    s.materials.push(m);
    let mat = (s.materials.len() - 1) as u32;
    let z = 0.6;
    let corners = [Vec3::new(-0.9, 0.05, z), Vec3::new(0.9, 0.05, z), Vec3::new(0.9, 1.9, z), Vec3::new(-0.9, 1.9, z)];
    add_polygon(&mut s.mesh, &corners, mat);
    s.validate().expect("valid");
    s
}

fn frames(scene: &Scene, gi: GiMethod, n: u32) -> Image {
    let bvh = BvhTracer::for_scene(scene, BvhSettings::default());
    let rays = CameraRays::new(&scene.default_camera(), SIZE, SIZE);
    let settings = RenderSettings { width: SIZE, height: SIZE, frames: n, seed: 5, gi, ..Default::default() };
    render_frames(scene, &bvh, &rays, &settings, |_, _| {}).image
}

fn reference(scene: &Scene) -> Image {
    let bvh = BvhTracer::for_scene(scene, BvhSettings::default());
    let rays = CameraRays::new(&scene.default_camera(), SIZE, SIZE);
    let pt = PathTracer::new(scene, &bvh, PathTracerSettings { pt_spp: 8, seed: 3, ..Default::default() });
    pt.render(&rays, SIZE, SIZE, &|| {}).0
}

/// The share of pixels that differ by more than 1e-4 of the image's mean.
/// (A different BVH over the same triangles may still send a ray that grazes a
/// shared edge or a node's box to the other side, so a stray pixel may differ.)
fn differing_share(a: &Image, b: &Image) -> f32 {
    let mean = a.pixels.iter().map(|p| p.element_sum()).sum::<f32>() / (3.0 * a.pixels.len() as f32);
    let differ = a.pixels.iter().zip(&b.pixels).filter(|(p, q)| (**p - **q).abs().max_element() > 1e-4 * mean);
    differ.count() as f32 / a.pixels.len() as f32
}

#[test]
fn a_fully_cut_out_wall_is_invisible_to_every_kind_of_ray() {
    let (bare, cut, solid) = (cornell_box(), with_wall(false), with_wall(true));
    let ddgi = |states| {
        GiMethod::Ddgi(Box::new(DdgiVolumeSettings {
            probe_counts: glam::UVec3::splat(4),
            probe_rays_per_probe: 64,
            probe_states: states,
            ..Default::default()
        }))
    };
    let sh = || GiMethod::Sh(Box::new(ShProbeSettings { sh_occlusion: true, ..Default::default() }));
    type Renderer<'a> = (&'a str, Box<dyn Fn(&Scene) -> Image + 'a>);
    let renderers: Vec<Renderer> = vec![
        ("reference (camera, bounce and shadow rays)", Box::new(reference)),
        ("direct only (G-buffer and shadow rays)", Box::new(|s: &Scene| frames(s, GiMethod::None, 2))),
        (
            "DDGI, usage states (probe trace, classification)",
            Box::new(|s: &Scene| frames(s, ddgi(ProbeStatesMode::Usage), 6)),
        ),
        ("DDGI, jcgt states (init trace, relocation)", Box::new(|s: &Scene| frames(s, ddgi(ProbeStatesMode::Jcgt), 6))),
        ("SH probes with occlusion (screen samples, shadow rays)", Box::new(|s: &Scene| frames(s, sh(), 6))),
    ];
    for (what, render) in &renderers {
        let (b, c, o) = (render(&bare), render(&cut), render(&solid));
        let (through, blocked) = (differing_share(&b, &c), differing_share(&b, &o));
        eprintln!(
            "{what}: a cut-out wall changes {:.2} % of the pixels, an opaque one {:.0} %",
            through * 100.0,
            blocked * 100.0
        );
        assert!(through <= 0.002, "{what}: the cut-out wall is visible ({through})");
        assert!(blocked > 0.5, "{what}: the opaque wall should change the image ({blocked})");
    }
}
