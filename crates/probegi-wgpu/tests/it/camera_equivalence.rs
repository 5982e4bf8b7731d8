//! `render --backend wgpu`'s whole frame on the GPU (probe trace, probe shade and
//! the camera pass) against the CPU renderer: HDR-FLIP of the images on the
//! built-in Cornell box, the door room, McGuire's glossy Cornell box (GGX
//! specular, glossy camera rays, second-order glossy) and the shared Sponza
//! (textures and bump maps), the instanced forest (36 copies of the shared pine
//! through the top level, alpha-cut needles) and `scenes/moving-box.toml`,
//! its box made to glow (the top level placed, the box's triangles and the
//! emitters' distribution rewritten on the device each frame); and, exactly, a point-lit plane under a normal
//! map and under a bump map (nothing random: punctual light, frame 0). Random
//! numbers differ between the backends, so the images differ by Monte Carlo
//! noise. Each FLIP is printed beside the CPU's own FLIP between two seeds; it
//! must stay under 0.02 where that noise floor is lower, and under the noise
//! floor (plus 0.005) where it is not, and the image means must agree within 2 %.
//! The GPU keeps the field on the device (`keeping_field`), as `--backend wgpu` does.

use crate::common;

use common::shared;

use std::sync::Arc;

use glam::UVec3;
use probegi_core::camera::CameraRays;
use probegi_core::ddgi_settings::DdgiVolumeSettings;
use probegi_core::image::Image;
use probegi_cpu::DirectSettings;
use probegi_field::{ProbeBatchTracer, ProbeTracerHandle};
use probegi_frame::frame_loop::{GiMethod, RenderSettings, render_frames};
use probegi_scene::{BvhSettings, BvhTracer, Scene, load_scene};
use probegi_wgpu::GpuContext;
use probegi_wgpu::wgpu_field_backend::WgpuProbeTracer;

/// Area-light samples per pixel per frame: above the default 16, so that the
/// seed noise of the comparison stays small.
const AREA_SAMPLES: u32 = 64;

fn render(
    scene: &Scene,
    size: u32,
    frames: u32,
    seed: u64,
    s: &DdgiVolumeSettings,
    path: &[CameraRays],
    gpu: Option<Arc<WgpuProbeTracer>>,
) -> Image {
    let cpu = BvhTracer::for_scene(scene, BvhSettings::default());
    let camera = CameraRays::new(&scene.camera.expect("camera"), size, size);
    let rs = RenderSettings {
        width: size,
        height: size,
        frames,
        seed,
        gi: GiMethod::Ddgi(Box::new(s.clone())),
        direct: DirectSettings { direct_area_samples: AREA_SAMPLES, ..Default::default() },
        probe_tracer: gpu.map(|g| ProbeTracerHandle(g as Arc<dyn ProbeBatchTracer>)),
        camera_path: path.to_vec(),
        ..Default::default()
    };
    let out = render_frames(scene, &cpu, &camera, &rs, |_, _| {});
    assert!(out.stats.error.is_none(), "{:?}", out.stats.error);
    // The black-wall statistic is recorded for every frame on both backends.
    assert_eq!(out.stats.frame_unlit_fraction.len(), frames as usize);
    let unlit = out.stats.frame_unlit_fraction.last().copied().unwrap_or(1.0);
    assert!(unlit < 0.01, "{:.3} of the surface pixels are unlit", unlit);
    out.image
}

fn check(name: &str, scene: Scene, s: DdgiVolumeSettings, size: u32, frames: u32) {
    check_path(name, scene, s, size, frames, &[]);
}

/// [`check`] with the camera following `path` (empty: the scene's camera).
fn check_path(name: &str, scene: Scene, s: DdgiVolumeSettings, size: u32, frames: u32, path: &[CameraRays]) {
    let Some(ctx) = GpuContext::headless_unless_absent().expect("PROBEGI_REQUIRE_GPU is set") else { return };
    let gpu = WgpuProbeTracer::new(ctx, &scene, &BvhTracer::for_scene(&scene, BvhSettings::default()), true)
        .expect("upload")
        .keeping_field(true);
    assert!(gpu.renders_camera(), "{name}: {:?}", gpu.shading_note);
    let a = render(&scene, size, frames, 3, &s, path, None);
    let b = render(&scene, size, frames, 4, &s, path, None);
    let g = render(&scene, size, frames, 3, &s, path, Some(Arc::new(gpu)));
    let flip = |x: &Image, y: &Image| probegi_image::mean_flip_hdr(x, y).expect("same size");
    let (noise, f) = (flip(&a, &b), flip(&a, &g));
    eprintln!(
        "{name}: HDR-FLIP CPU vs GPU frame {f:.4}; CPU seed 3 vs 4 {noise:.4}; means CPU {} GPU {}",
        a.mean(),
        g.mean()
    );
    assert!(g.first_invalid_pixel().is_none(), "{name}");
    // The bound where the CPU's own seed noise is below it; the noise
    // floor (plus 0.005) where it is not (subpixel jitter at edges and texture
    // detail, and another seed's probe-ray rotations, dominate it).
    assert!(f < noise.max(0.02) + 0.005, "{name}: FLIP {f} above the seed noise {noise}");
    let (ma, mg) = (a.mean(), g.mean());
    assert!((ma - mg).abs().max_element() < 0.02 * ma.max_element(), "{name}: means {ma} vs {mg}");
}

fn small(counts: UVec3) -> DdgiVolumeSettings {
    DdgiVolumeSettings { probe_counts: counts, probe_rays_per_probe: 128, ..Default::default() }
}

#[test]
fn cornell_box_frame_on_the_gpu() {
    check("cornell box", probegi_scene::builtin::cornell_box(), small(UVec3::splat(6)), 64, 48);
}

#[test]
fn door_room_frame_on_the_gpu() {
    let s = DdgiVolumeSettings {
        probe_origin_m: Some(glam::Vec3::new(-0.5, 0.5, -0.5)),
        probe_spacing_m: Some(glam::Vec3::ONE),
        ..small(UVec3::new(6, 3, 6))
    };
    check("door room", load_scene("builtin:door-room").expect("built in"), s, 64, 48);
}

#[test]
fn glossy_cornell_box_frame_on_the_gpu() {
    let mut scene = load_scene(&shared("cornell-box/CornellBox-Glossy.obj")).expect("shared glossy Cornell box");
    // Its light has no Ke (the loader makes it grey): CornellBox-Original's, as the CPU tests do.
    let light = scene.materials.iter_mut().find(|m| m.name == "light").expect("light material");
    light.emissive_factor = glam::Vec3::new(17.0, 12.0, 4.0);
    scene.camera = Some(probegi_core::camera::Camera::default());
    assert!(scene.materials.iter().any(|m| m.specular_color.max_element() > 0.5), "glossy");
    check("glossy cornell box", scene, small(UVec3::splat(6)), 64, 48);
}

#[test]
fn textured_sponza_frame_on_the_gpu() {
    // A camera frame of 66k textured triangles on a software rasteriser's compute
    // path: 24 frames at 64×64 keep it to seconds.
    let mut scene = load_scene(&shared("dabrovic-sponza/sponza.obj")).expect("shared Sponza");
    assert!(scene.materials.iter().any(|m| m.base_color_texture.is_some()), "Sponza is textured");
    assert!(scene.materials.iter().any(|m| m.bump_texture.is_some()), "and bump-mapped");
    scene.camera = Some(probegi_core::camera::Camera {
        position: glam::Vec3::new(-12.0, 2.0, 0.0),
        target: glam::Vec3::new(10.0, 4.0, 0.0),
        up: glam::Vec3::Y,
        fov_y_deg: 60.0,
    });
    scene.sky_radiance = glam::Vec3::splat(3.0);
    check("sponza (textures, bump maps)", scene, small(UVec3::new(12, 6, 6)), 64, 24);
}

/// A camera dollying through Sponza: the moving camera's temporal filter
/// reprojects both backends' frames alike (the device returns its hit
/// points and normals; the host filters).
#[test]
fn moving_camera_through_sponza_on_the_gpu() {
    let mut scene = load_scene(&shared("dabrovic-sponza/sponza.obj")).expect("shared Sponza");
    scene.sky_radiance = glam::Vec3::splat(3.0);
    let (start, target) = (glam::Vec3::new(-12.0, 2.0, 0.0), glam::Vec3::new(10.0, 4.0, 0.0));
    scene.camera = Some(probegi_core::camera::Camera { position: start, target, up: glam::Vec3::Y, fov_y_deg: 60.0 });
    let path: Vec<CameraRays> = (0..24)
        .map(|f| {
            let at = start + glam::Vec3::new(0.08, 0.02, 0.01) * f as f32;
            let camera = probegi_core::camera::Camera { position: at, ..scene.camera.expect("camera") };
            CameraRays::new(&camera, 64, 64)
        })
        .collect();
    check_path("sponza, moving camera", scene, small(UVec3::new(12, 6, 6)), 64, 24, &path);
}

#[test]
fn instanced_forest_frame_on_the_gpu() {
    let scene = load_scene("builtin:forest").expect("built-in forest (shared pine)");
    assert!(!scene.instances.is_empty(), "instanced");
    let s = DdgiVolumeSettings { probe_counts: UVec3::new(8, 4, 8), probe_rays_per_probe: 128, ..Default::default() };
    check("instanced forest", scene, s, 64, 24);
}

#[test]
fn moving_box_frame_on_the_gpu() {
    let path = common::repo_file("scenes/moving-box.toml");
    let mut scene = load_scene(&path).expect("moving box");
    // Its box glows, so the emitters' distribution follows its growing area too.
    let mut glow = probegi_scene::Material::diffuse("glow", glam::Vec3::splat(0.5));
    glow.emissive_factor = glam::Vec3::new(2.0, 1.5, 1.0);
    scene.materials.push(glow);
    let glow = (scene.materials.len() - 1) as u32;
    let mover = scene.objects.iter().find(|o| o.name == "blue box").expect("blue box").triangles();
    mover.for_each(|t| scene.mesh.triangle_materials[t] = glow);
    scene.validate().expect("valid");
    let mut s = scene.volume.clone().expect("volume");
    s.probe_rays_per_probe = 128;
    check("moving glowing box", scene, s, 64, 32);
}

/// A 4 m plane (two triangles with UVs tiling a 64² map four times, tangent
/// along +x), lit by a point light, seen from above, DDGI over it.
fn mapped_plane(normal_map: bool) -> Scene {
    use probegi_scene::{Material, PunctualLight};
    let mut scene =
        Scene { materials: vec![Material::diffuse("mapped", glam::Vec3::splat(0.7))], ..Default::default() };
    let m = &mut scene.mesh;
    for (p, uv) in
        [((-2.0, -2.0), (0.0, 0.0)), ((2.0, -2.0), (4.0, 0.0)), ((2.0, 2.0), (4.0, 4.0)), ((-2.0, 2.0), (0.0, 4.0))]
    {
        m.positions.push(glam::Vec3::new(p.0, 0.0, p.1));
        m.normals.push(glam::Vec3::Y);
        m.uvs.push(glam::Vec2::new(uv.0, uv.1));
        m.tangents.push(glam::Vec4::new(1.0, 0.0, 0.0, 1.0));
    }
    m.triangles = vec![[0, 3, 2], [0, 2, 1]];
    m.triangle_materials = vec![0, 0];
    // Concentric ripples: as a normal map (tangent-space normals) or a height map.
    let n = 64u32;
    let texels = (0..n * n)
        .map(|i| {
            let (x, y) = ((i % n) as f32 / n as f32 - 0.5, (i / n) as f32 / n as f32 - 0.5);
            let r = (x * x + y * y).sqrt() * 25.0;
            if normal_map {
                let (dx, dy) = (0.6 * r.cos() * x, 0.6 * r.cos() * y);
                let v = glam::Vec3::new(dx, dy, 1.0).normalize() * 0.5 + glam::Vec3::splat(0.5);
                [(v.x * 255.0) as u8, (v.y * 255.0) as u8, (v.z * 255.0) as u8]
            } else {
                let h = ((r.sin() * 0.5 + 0.5) * 255.0) as u8;
                [h, h, h]
            }
        })
        .collect();
    scene.textures.push(probegi_scene::texture::Texture::from_rgb8(n, n, texels, "ripples".into()).expect("texture"));
    if normal_map {
        scene.materials[0].normal_texture = Some(0);
    } else {
        scene.materials[0].bump_texture = Some(0);
        scene.materials[0].bump_multiplier = 3.0;
    }
    scene.lights.push(PunctualLight::point(glam::Vec3::new(0.5, 1.5, 0.3), glam::Vec3::ONE, 4.0));
    scene.camera = Some(probegi_core::camera::Camera {
        position: glam::Vec3::new(0.0, 3.5, 2.5),
        target: glam::Vec3::ZERO,
        up: glam::Vec3::Y,
        fov_y_deg: 50.0,
    });
    scene
}

#[test]
fn normal_and_bump_mapped_planes_shade_the_same_on_both_backends() {
    for normal_map in [true, false] {
        let scene = mapped_plane(normal_map);
        let name = if normal_map { "normal-mapped plane" } else { "bump-mapped plane" };
        let Some(ctx) = GpuContext::headless_unless_absent().expect("PROBEGI_REQUIRE_GPU is set") else { return };
        let gpu = WgpuProbeTracer::new(ctx, &scene, &BvhTracer::for_scene(&scene, BvhSettings::default()), true)
            .expect("upload")
            .keeping_field(true);
        let s = small(UVec3::new(4, 2, 4));
        let a = render(&scene, 64, 1, 3, &s, &[], None);
        let g = render(&scene, 64, 1, 3, &s, &[], Some(Arc::new(gpu)));
        // Without the map the plane is smooth: the map must show.
        let mut plain = scene.clone();
        plain.materials[0].normal_texture = None;
        plain.materials[0].bump_texture = None;
        let smooth = render(&plain, 64, 1, 3, &s, &[], None);
        let flip = |x: &Image, y: &Image| probegi_image::mean_flip_hdr(x, y).expect("same size");
        let (f, shows) = (flip(&a, &g), flip(&a, &smooth));
        eprintln!("{name}: HDR-FLIP CPU vs GPU {f:.5}; CPU with vs without the map {shows:.4}");
        assert!(shows > 0.03, "{name}: the map changes little ({shows})");
        assert!(f < 0.01, "{name}: FLIP {f}");
    }
}

/// A 4 m plane under a point light with glTF 2.0 §3.9 material inputs: a
/// metallic-roughness texture (roughness ramp in G, a metalness checker in B,
/// mirrored in u and clamped in v, KHR_texture_transform-scaled), a base-colour
/// texture read through TEXCOORD_1 with a rotated and offset transform, clamped
/// in u, mirrored in v and filtered nearest, an emissive texture on set 0, and
/// vertex colours (COLOR_0). With `textured` false: the same plane with its
/// factors alone.
fn gltf_material_plane(textured: bool) -> Scene {
    use probegi_scene::material::{SpecularModel, UvMapping};
    use probegi_scene::texture::{Filter, Sampler, Texture, Wrap};
    use probegi_scene::{Material, PunctualLight};
    let mut m = Material {
        roughness: 0.9,
        metallic: 1.0,
        specular_model: SpecularModel::MetallicRoughness,
        emissive_factor: glam::Vec3::splat(0.05),
        ..Material::diffuse("glTF", glam::Vec3::new(0.9, 0.8, 0.7))
    };
    let mut scene = Scene::default();
    let mesh = &mut scene.mesh;
    let corners =
        [((-2.0, -2.0), (0.0, 0.0)), ((2.0, -2.0), (3.0, 0.0)), ((2.0, 2.0), (3.0, 3.0)), ((-2.0, 2.0), (0.0, 3.0))];
    let colors = [
        glam::Vec3::new(1.0, 0.4, 0.4),
        glam::Vec3::new(0.4, 1.0, 0.4),
        glam::Vec3::ONE,
        glam::Vec3::new(0.4, 0.4, 1.0),
    ];
    for (k, (p, uv)) in corners.into_iter().enumerate() {
        mesh.positions.push(glam::Vec3::new(p.0, 0.0, p.1));
        mesh.normals.push(glam::Vec3::Y);
        mesh.uvs.push(glam::Vec2::new(uv.0, uv.1));
        if textured {
            mesh.uvs1.push(glam::Vec2::new(uv.1 * 0.5 - 0.4, uv.0 * 0.6 - 0.3));
            mesh.colors.push(colors[k]);
        }
    }
    mesh.triangles = vec![[0, 3, 2], [0, 2, 1]];
    mesh.triangle_materials = vec![0, 0];
    if textured {
        let n = 16u32;
        let ramp = (0..n * n).map(|i| {
            let (x, y) = (i % n, i / n);
            [(x * 16) as u8, (40 + y * 13) as u8, if (x / 4 + y / 4) % 2 == 0 { 250 } else { 10 }]
        });
        let rgb = (0..n * n).map(|i| [(i % n * 15) as u8, 200 - (i / n * 12) as u8, ((i * 7) % 256) as u8]);
        let texture = |texels: Vec<[u8; 3]>, sampler| {
            Texture::from_rgb8(n, n, texels, "plane".into()).expect("texture").with_sampler(sampler)
        };
        let mirror_clamp = Sampler { wrap_u: Wrap::MirroredRepeat, wrap_v: Wrap::ClampToEdge, filter: Filter::Linear };
        let clamp_mirror_nearest =
            Sampler { wrap_u: Wrap::ClampToEdge, wrap_v: Wrap::MirroredRepeat, filter: Filter::Nearest };
        scene.textures = vec![texture(ramp.collect(), mirror_clamp), texture(rgb.collect(), clamp_mirror_nearest)];
        m.metallic_roughness_texture = Some(0);
        m.metallic_roughness_uv =
            UvMapping::texture_transform(0, glam::Vec2::new(0.1, -0.2), 0.0, glam::Vec2::splat(0.8));
        m.base_color_texture = Some(1);
        m.base_color_uv = UvMapping::texture_transform(1, glam::Vec2::new(0.3, 0.1), 0.4, glam::Vec2::new(1.2, 0.9));
        m.emissive_texture = Some(1);
    }
    scene.materials.push(m);
    scene.lights.push(PunctualLight::point(glam::Vec3::new(0.5, 1.5, 0.3), glam::Vec3::ONE, 4.0));
    scene.camera = Some(probegi_core::camera::Camera {
        position: glam::Vec3::new(0.0, 3.5, 2.5),
        target: glam::Vec3::ZERO,
        up: glam::Vec3::Y,
        fov_y_deg: 50.0,
    });
    scene.validate().expect("valid");
    scene
}

#[test]
fn gltf_material_inputs_shade_the_same_on_both_backends() {
    let scene = gltf_material_plane(true);
    let Some(ctx) = GpuContext::headless_unless_absent().expect("PROBEGI_REQUIRE_GPU is set") else { return };
    let gpu = WgpuProbeTracer::new(ctx, &scene, &BvhTracer::for_scene(&scene, BvhSettings::default()), true)
        .expect("upload")
        .keeping_field(true);
    assert!(gpu.renders_camera() && gpu.shades(), "{:?}", gpu.shading_note);
    let s = small(UVec3::new(4, 2, 4));
    let a = render(&scene, 64, 1, 3, &s, &[], None);
    let g = render(&scene, 64, 1, 3, &s, &[], Some(Arc::new(gpu)));
    // The textures, their samplers and transforms, the second set and the
    // vertex colours must show: the factors alone render differently.
    let plain = render(&gltf_material_plane(false), 64, 1, 3, &s, &[], None);
    let flip = |x: &Image, y: &Image| probegi_image::mean_flip_hdr(x, y).expect("same size");
    let (f, shows) = (flip(&a, &g), flip(&a, &plain));
    eprintln!("glTF material plane: HDR-FLIP CPU vs GPU {f:.5}; CPU with vs without its inputs {shows:.4}");
    assert!(shows > 0.05, "the material inputs change little ({shows})");
    assert!(f < 0.01, "FLIP {f}");
    let (ma, mg) = (a.mean(), g.mean());
    assert!((ma - mg).abs().max_element() < 0.01 * ma.max_element(), "means {ma} vs {mg}");
}

#[test]
fn a_keyframed_light_moves_and_switches_off_on_the_gpu_as_on_the_cpu() {
    // scenes/cornell-moving-light.toml: a point light sweeps red → green over
    // frames 0–30 and switches off at 61. The GPU poses it every frame
    // (`GpuScene::pose_lights`). Each frame's field term (the indirect image's
    // mean) follows the light on both backends; single frames' full means are
    // dominated by the jittered ceiling emitter's edge pixels, so those are
    // compared over ten-frame windows.
    let path = common::repo_file("scenes/cornell-moving-light.toml");
    let scene = load_scene(&path).expect("scene");
    assert!(scene.is_animated());
    let Some(ctx) = GpuContext::headless_unless_absent().expect("PROBEGI_REQUIRE_GPU is set") else { return };
    let gpu = WgpuProbeTracer::new(ctx, &scene, &BvhTracer::for_scene(&scene, BvhSettings::default()), true)
        .expect("upload")
        .keeping_field(true);
    assert!(gpu.renders_camera(), "{:?}", gpu.shading_note);
    let run = |g: Option<Arc<WgpuProbeTracer>>| {
        let cpu = BvhTracer::for_scene(&scene, BvhSettings::default());
        let camera = CameraRays::new(&scene.camera.expect("camera"), 32, 32);
        let rs = RenderSettings {
            width: 32,
            height: 32,
            frames: 72,
            seed: 3,
            gi: GiMethod::Ddgi(Box::new(small(UVec3::splat(4)))),
            probe_tracer: g.map(|g| ProbeTracerHandle(g as Arc<dyn ProbeBatchTracer>)),
            ..Default::default()
        };
        let out = render_frames(&scene, &cpu, &camera, &rs, |_, _| {});
        assert!(out.stats.error.is_none(), "{:?}", out.stats.error);
        (out.stats.frame_means, out.stats.frame_indirect_means)
    };
    let ((c, ci), (g, gi)) = (run(None), run(Some(Arc::new(gpu))));
    for f in [0usize, 15, 30, 45, 60, 62, 71] {
        let (a, b) = (ci[f], gi[f]);
        eprintln!("frame {f}: indirect mean CPU {a} GPU {b}");
        assert!((a - b).abs().max_element() < 0.05 * a.max_element(), "frame {f}: {a} vs {b}");
    }
    let window = |m: &[glam::Vec3], from: usize| m[from..from + 10].iter().copied().sum::<glam::Vec3>() / 10.0;
    for from in [0usize, 25, 50, 62] {
        let (a, b) = (window(&c, from), window(&g, from));
        eprintln!("frames {from}–{}: image mean CPU {a} GPU {b}", from + 9);
        assert!((a - b).abs().max_element() < 0.06 * a.max_element(), "frames {from}+: {a} vs {b}");
    }
    // The field follows the light: redder while it is near the red wall, and
    // darker once it is off (both backends agree on that above).
    assert!(gi[0].x / gi[0].y > gi[45].x / gi[45].y, "the light moved toward the green wall: {} {}", gi[0], gi[45]);
    assert!(gi[71].length() < 0.9 * gi[60].length(), "the light switched off: {} {}", gi[60], gi[71]);
}

/// A 64 × 32 sky map: a sky of 0.3–1.2 brighter toward the zenith and bluer
/// toward +x (the map's quarter), with a 2 × 2-texel warm sun of 400 at 43°
/// from the zenith.
fn test_sky_map(intensity: f32, rotation_deg: f32) -> probegi_scene::SkyMap {
    let texel = |x: u32, y: u32| {
        if (40..42).contains(&x) && (7..9).contains(&y) {
            return glam::Vec3::new(400.0, 300.0, 200.0);
        }
        let up = 1.0 - y as f32 / 31.0;
        let toward_x = ((x as f32 + 0.5) / 64.0 * std::f32::consts::TAU).sin().max(0.0);
        glam::Vec3::new(0.3 + 0.6 * up, 0.3 + 0.7 * up, 0.3 + 0.9 * up + 0.5 * toward_x)
    };
    let texels = (0..32u32).flat_map(|y| (0..64u32).map(move |x| (x, y))).map(|(x, y)| texel(x, y)).collect();
    let map =
        probegi_scene::EnvironmentMap::from_texels(std::path::Path::new("test-sky"), 64, 32, texels).expect("map");
    probegi_scene::SkyMap { intensity, rotation_deg, ..probegi_scene::SkyMap::new(Arc::new(map)) }
}

/// A scene of one grey (0.5) floor at y = 0, `half_m` to each side, facing up,
/// and no light.
fn floor_scene(half_m: f32) -> Scene {
    let mut scene = probegi_scene::builtin::cornell_box();
    scene.mesh = Default::default();
    scene.lights.clear();
    scene.materials = vec![probegi_scene::Material::diffuse("floor", glam::Vec3::splat(0.5))];
    let corners = [(-1.0, 1.0), (1.0, 1.0), (1.0, -1.0), (-1.0, -1.0)];
    let polygon = corners.map(|(x, z)| glam::Vec3::new(x * half_m, 0.0, z * half_m));
    probegi_scene::builtin::add_polygon(&mut scene.mesh, &polygon, 0);
    scene
}

/// A floor and two boxes under `test_sky_map` turned 30°, the camera seeing
/// both sky and ground; probes on a grid that misses the boxes.
fn sky_map_scene() -> (Scene, DdgiVolumeSettings) {
    // Inside the probe grid's span: beyond it the cage's visibility test
    // would leave far ground unlit (a known limit of the field, not of the map).
    let mut scene = floor_scene(4.0);
    for (lo, hi) in [
        (glam::Vec3::new(-0.5, 0.0, 2.0), glam::Vec3::new(0.5, 2.0, 3.0)),
        (glam::Vec3::new(2.0, 0.0, -0.5), glam::Vec3::new(3.0, 1.0, 0.5)),
    ] {
        probegi_scene::shapes::add_box(&mut scene.mesh, lo, hi, 0);
    }
    scene.sky_map = Some(test_sky_map(1.0, 30.0));
    scene.camera = Some(probegi_core::camera::Camera {
        position: glam::Vec3::new(0.0, 1.5, -4.0),
        target: glam::Vec3::new(0.5, 1.2, 2.0),
        up: glam::Vec3::Y,
        fov_y_deg: 70.0,
    });
    let settings = DdgiVolumeSettings {
        // No probe inside or on a box.
        probe_origin_m: Some(glam::Vec3::new(-4.25, 0.4, -4.25)),
        probe_spacing_m: Some(glam::Vec3::splat(2.0)),
        ..small(UVec3::new(5, 3, 5))
    };
    (scene, settings)
}

#[test]
fn a_sky_map_lights_the_field_and_fills_the_sky_pixels_on_the_gpu_as_on_the_cpu() {
    // Probe-ray misses, the camera's sky pixels and its glossy misses read the
    // map on both backends.
    let (scene, settings) = sky_map_scene();
    check("sky map", scene, settings, 64, 32);
}

#[test]
fn a_sky_map_the_misses_read_lights_the_field_on_the_gpu_as_on_the_cpu() {
    // `probe_sky_map_on_miss` (the Bevy plugin's): the probes' misses read the
    // map, the hits and the camera sample none of it.
    let (scene, settings) = sky_map_scene();
    check("sky map on miss", scene, DdgiVolumeSettings { probe_sky_map_on_miss: true, ..settings }, 64, 32);
}

#[test]
fn a_turning_sky_map_turns_on_the_gpu_as_on_the_cpu() {
    // The map's keyframes turn it 180° over 12 frames (a moving sun): the device
    // poses it each frame (`GpuScene::pose_lights`), and each frame's mean
    // follows the CPU's while the sky pixels change under the camera.
    let (mut scene, settings) = sky_map_scene();
    let sky = scene.sky_map.as_mut().expect("map");
    sky.keyframes = vec![
        probegi_scene::environment_map::SkyMapKeyframe { frame: 0.0, intensity: None, rotation_deg: Some(30.0) },
        probegi_scene::environment_map::SkyMapKeyframe { frame: 12.0, intensity: None, rotation_deg: Some(210.0) },
    ];
    assert!(scene.is_animated());
    let Some(ctx) = GpuContext::headless_unless_absent().expect("PROBEGI_REQUIRE_GPU is set") else { return };
    let gpu = WgpuProbeTracer::new(ctx, &scene, &BvhTracer::for_scene(&scene, BvhSettings::default()), true)
        .expect("upload")
        .keeping_field(true);
    let run = |g: Option<Arc<WgpuProbeTracer>>, seed: u64| {
        let cpu = BvhTracer::for_scene(&scene, BvhSettings::default());
        let camera = CameraRays::new(&scene.camera.expect("camera"), 32, 16);
        let rs = RenderSettings {
            width: 32,
            height: 16,
            frames: 13,
            seed,
            gi: GiMethod::Ddgi(Box::new(settings.clone())),
            probe_tracer: g.map(|g| ProbeTracerHandle(g as Arc<dyn ProbeBatchTracer>)),
            ..Default::default()
        };
        let out = render_frames(&scene, &cpu, &camera, &rs, |_, _| {});
        assert!(out.stats.error.is_none(), "{:?}", out.stats.error);
        out.stats.frame_means
    };
    let (c, g) = (run(None, 3), run(Some(Arc::new(gpu)), 3));
    // Both backends trace the same probe rays for a seed (the device makes the
    // host's directions); their sky-map samples and the camera's pixel jitter
    // differ (the device hashes where the CPU runs PCG streams). A 32 × 16
    // frame averages 8 of those samples a pixel: the means stray by up to
    // 1.8 % on lavapipe (frame 8). 3 %, then.
    for f in [0usize, 4, 8, 12] {
        eprintln!("frame {f}: mean CPU {} GPU {}", c[f], g[f]);
        assert!((c[f] - g[f]).abs().max_element() < 0.03 * c[f].max_element(), "frame {f}: {} vs {}", c[f], g[f]);
    }
    assert!((c[0] - c[12]).abs().max_element() > 0.05 * c[0].max_element(), "the sky turned: {} {}", c[0], c[12]);
}

#[test]
fn a_uniform_sky_map_lights_the_open_floor_to_rho_l_on_the_gpu() {
    // The sky's furnace on the device (probegi-cpu's ddgi.rs has the CPU's):
    // ρ/π · π L = 0.5 · 2 = 1 on the floor.
    let mut scene = floor_scene(50.0);
    let map =
        probegi_scene::EnvironmentMap::from_texels(std::path::Path::new("white"), 16, 8, vec![glam::Vec3::ONE; 128])
            .expect("map");
    scene.sky_map =
        Some(probegi_scene::SkyMap { intensity: 2.0, rotation_deg: 25.0, ..probegi_scene::SkyMap::new(Arc::new(map)) });
    scene.camera = Some(probegi_core::camera::Camera {
        position: glam::Vec3::new(0.3, 2.0, 0.2),
        target: glam::Vec3::new(0.3, 0.0, 0.2),
        up: glam::Vec3::Z,
        fov_y_deg: 40.0,
    });
    let settings = DdgiVolumeSettings {
        probe_origin_m: Some(glam::Vec3::new(-2.0, 0.5, -2.0)),
        probe_spacing_m: Some(glam::Vec3::ONE),
        ..small(UVec3::new(5, 3, 5))
    };
    let Some(ctx) = GpuContext::headless_unless_absent().expect("PROBEGI_REQUIRE_GPU is set") else { return };
    let gpu = WgpuProbeTracer::new(ctx, &scene, &BvhTracer::for_scene(&scene, BvhSettings::default()), true)
        .expect("upload")
        .keeping_field(true);
    assert!(gpu.renders_camera(), "{:?}", gpu.shading_note);
    let g = render(&scene, 16, 8, 3, &settings, &[], Some(Arc::new(gpu)));
    let mean = g.mean();
    assert!((mean - glam::Vec3::ONE).abs().max_element() < 0.01, "floor under a white sky map on the GPU: {mean}");
}
