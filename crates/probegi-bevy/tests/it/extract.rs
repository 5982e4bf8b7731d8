//! The ECS as probegi sees it: a headless Bevy app (no renderer) with a few
//! meshes, materials, a texture, lights and a volume; after an update the
//! plugin's `ProbegiScene` must hold exactly those, in world space and in
//! probegi's units.

use std::f32::consts::PI;

use bevy::asset::{AssetPlugin, RenderAssetUsages};
use bevy::image::Image;
use bevy::mesh::{Indices, PrimitiveTopology};
use bevy::prelude::*;
use bevy::render::render_resource::{Extent3d, TextureDimension, TextureFormat};
use probegi_bevy::{
    ProbegiDynamic, ProbegiLit, ProbegiMaterial, ProbegiPlugin, ProbegiScene, ProbegiSky, ProbegiVolume,
};
use probegi_scene::LightKind;
use probegi_scene::material::AlphaMode as ProbegiAlpha;

fn app() -> App {
    let mut app = App::new();
    app.add_plugins((MinimalPlugins, AssetPlugin::default(), bevy::transform::TransformPlugin))
        .init_asset::<Mesh>()
        .init_asset::<Image>()
        .init_asset::<StandardMaterial>()
        .add_plugins(ProbegiPlugin { sky: ProbegiSky::Radiance(Vec3::new(0.5, 0.6, 0.7)), ..default() });
    app
}

fn scene(app: &App) -> &ProbegiScene {
    app.world().resource::<ProbegiScene>()
}

/// A red box (2 × 1 × 1 m, scaled ×2 in y), a textured, cut-out floor, a
/// 100 cd point light, a sun of 1 000 lx pointing down and a 10 m volume.
fn spawn_world(app: &mut App) {
    let world = app.world_mut();
    let cuboid = world.resource_mut::<Assets<Mesh>>().add(Cuboid::new(2.0, 1.0, 1.0));
    let floor = world.resource_mut::<Assets<Mesh>>().add(Plane3d::default().mesh().size(4.0, 4.0));
    let texels = [255u8, 128, 0, 100];
    let image = Image::new_fill(
        Extent3d { width: 2, height: 2, depth_or_array_layers: 1 },
        TextureDimension::D2,
        &texels,
        TextureFormat::Rgba8UnormSrgb,
        RenderAssetUsages::default(),
    );
    let image = world.resource_mut::<Assets<Image>>().add(image);
    let mut materials = world.resource_mut::<Assets<StandardMaterial>>();
    let red = materials.add(StandardMaterial {
        base_color: Color::srgb(1.0, 0.0, 0.0),
        emissive: LinearRgba::rgb(2.0, 3.0, 4.0),
        perceptual_roughness: 0.3,
        metallic: 0.25,
        ..default()
    });
    let textured = materials.add(StandardMaterial {
        base_color: Color::srgb(0.5, 0.5, 0.5),
        base_color_texture: Some(image),
        alpha_mode: AlphaMode::Mask(0.3),
        reflectance: 0.25,
        specular_tint: Color::linear_rgb(1.0, 0.5, 0.0),
        ..default()
    });
    world.spawn((
        Name::new("box"),
        Mesh3d(cuboid),
        MeshMaterial3d(red),
        Transform::from_xyz(1.0, 2.0, 3.0).with_scale(Vec3::new(1.0, 2.0, 1.0)),
    ));
    world.spawn((Name::new("floor"), Mesh3d(floor), MeshMaterial3d(textured), Transform::default()));
    world.spawn((
        PointLight { intensity: 4.0 * PI * 100.0, range: 12.0, ..default() },
        Transform::from_xyz(0.0, 5.0, 0.0),
    ));
    world.spawn((
        DirectionalLight { illuminance: 1000.0, ..default() },
        Transform::default().looking_to(Vec3::NEG_Y, Vec3::Z),
    ));
    world.spawn((ProbegiVolume::default(), Transform::from_xyz(0.0, 1.0, 0.0).with_scale(Vec3::splat(10.0))));
}

#[test]
fn meshes_materials_lights_and_volumes_come_from_the_ecs() {
    let mut app = app();
    spawn_world(&mut app);
    app.update();
    let s = scene(&app);
    assert!(s.error.is_none(), "{:?}", s.error);
    let sc = &s.scene;
    assert_eq!(sc.mesh.triangles.len(), 12 + 2, "a cuboid's 12 triangles and a plane's 2");
    assert_eq!(sc.mesh.triangle_materials.len(), 14);
    // The box in world space: centre (1, 2, 3), half extents (1, 0.5 × 2, 0.5).
    let boxed: Vec<glam::Vec3> = sc
        .mesh
        .triangles
        .iter()
        .zip(&sc.mesh.triangle_materials)
        .filter(|(_, m)| sc.materials[**m as usize].texture_free())
        .flat_map(|(t, _)| t.map(|i| sc.mesh.positions[i as usize]))
        .collect();
    let lo = boxed.iter().fold(glam::Vec3::INFINITY, |a, p| a.min(*p));
    let hi = boxed.iter().fold(glam::Vec3::NEG_INFINITY, |a, p| a.max(*p));
    assert!(
        lo.abs_diff_eq(glam::Vec3::new(0.0, 1.0, 2.5), 1e-5) && hi.abs_diff_eq(glam::Vec3::new(2.0, 3.0, 3.5), 1e-5)
    );
    // Materials: linear base colour, emission in nits, roughness, metalness, cut-outs.
    let red = sc.materials.iter().find(|m| m.base_color_texture.is_none()).expect("the box's material");
    assert_eq!(red.base_color_factor, glam::Vec3::new(1.0, 0.0, 0.0));
    // At Bevy's default exposure weight 0 the emissive is a display value:
    // the luminance Bevy's default camera (no camera here) would show so.
    let display = 1.0 / bevy::camera::Exposure::default().exposure();
    assert!(red.emissive_factor.abs_diff_eq(glam::Vec3::new(2.0, 3.0, 4.0) * display, 1e-2), "{}", red.emissive_factor);
    assert_eq!((red.roughness, red.metallic, red.alpha_mode), (0.3, 0.25, ProbegiAlpha::Opaque));
    let floor = sc.materials.iter().find(|m| m.base_color_texture.is_some()).expect("the floor's material");
    assert!((floor.base_color_factor.x - 0.214).abs() < 1e-3, "sRGB 0.5 is linear 0.214");
    assert_eq!(floor.alpha_mode, ProbegiAlpha::Mask { cutoff: 0.3 });
    // Bevy's specular lobe: a dielectric's F0 = 0.16 × (reflectance × tint)²,
    // probegi's MTL model; a metallic one the metallic-roughness model.
    use probegi_scene::material::SpecularModel;
    assert_eq!(floor.specular_model, SpecularModel::Mtl);
    assert!(floor.specular_color.abs_diff_eq(glam::Vec3::new(0.01, 0.0025, 0.0), 1e-7), "{}", floor.specular_color);
    assert_eq!(red.specular_model, SpecularModel::MetallicRoughness);
    let tex = &sc.textures[floor.base_color_texture.expect("texture")];
    assert_eq!((tex.width, tex.height, tex.texels[3]), (2, 2, [255, 128, 0]));
    assert_eq!(tex.alpha.as_deref(), Some(&[100u8; 4][..]));
    // Lights in probegi's (glTF's) units: 4π·100 lm is 100 cd; lux stays lux.
    assert!(sc.lights.is_empty(), "the lights are kept apart from the geometry");
    let point = s.lights.iter().find(|l| l.kind == LightKind::Point).expect("point light");
    assert!((point.intensity - 100.0).abs() < 1e-3 && point.range == Some(12.0));
    assert_eq!(point.position, glam::Vec3::new(0.0, 5.0, 0.0));
    let sun = s.lights.iter().find(|l| l.kind == LightKind::Directional).expect("sun");
    assert_eq!(sun.intensity, 1000.0);
    assert!(sun.direction.abs_diff_eq(glam::Vec3::NEG_Y, 1e-6), "the sun shines along its forward axis");
    assert_eq!(sc.sky_radiance, glam::Vec3::new(0.5, 0.6, 0.7));
    // The volume: the entity's unit cube.
    assert_eq!(s.volumes.len(), 1);
    let [lo, hi] = s.volumes[0].volume_bounds_m.expect("bounds");
    assert_eq!((lo, hi), (glam::Vec3::new(-5.0, -4.0, -5.0), glam::Vec3::new(5.0, 6.0, 5.0)));
}

trait TextureFree {
    fn texture_free(&self) -> bool;
}
impl TextureFree for probegi_scene::Material {
    fn texture_free(&self) -> bool {
        self.base_color_texture.is_none()
    }
}

#[test]
fn a_still_world_is_extracted_once_and_a_moved_entity_again() {
    let mut app = app();
    spawn_world(&mut app);
    app.update();
    let g = scene(&app).generation;
    app.update();
    app.update();
    assert_eq!(scene(&app).generation, g, "nothing changed: no rebuild");
    let mut q = app.world_mut().query::<(&Name, &mut Transform)>();
    for (name, mut t) in q.iter_mut(app.world_mut()) {
        if name.as_str() == "box" {
            t.translation.x += 10.0;
        }
    }
    app.update();
    assert_eq!(scene(&app).generation, g + 1);
    assert_eq!(scene(&app).geometry_generation, 2, "a mesh moved: the geometry is built again");
    let max_x = scene(&app).scene.mesh.positions.iter().map(|p| p.x).fold(f32::MIN, f32::max);
    assert!((max_x - 12.0).abs() < 1e-5, "the box moved with its entity: {max_x}");
    // A light that moves changes the lights only.
    let mut lights = app.world_mut().query_filtered::<&mut Transform, With<PointLight>>();
    for mut t in lights.iter_mut(app.world_mut()) {
        t.translation.y = 4.0;
    }
    app.update();
    let s = scene(&app);
    assert_eq!((s.generation, s.geometry_generation), (g + 2, 2), "the geometry stays");
    assert!(s.lights.iter().any(|l| l.kind == LightKind::Point && l.position.y == 4.0));
}

#[test]
fn a_mirroring_transform_keeps_front_faces_in_front() {
    let mut app = app();
    let cuboid = app.world_mut().resource_mut::<Assets<Mesh>>().add(Cuboid::new(1.0, 1.0, 1.0));
    app.world_mut().spawn((Mesh3d(cuboid), Transform::from_scale(Vec3::new(-1.0, 1.0, 1.0))));
    app.update();
    let m = &scene(&app).scene.mesh;
    for t in &m.triangles {
        let [a, b, c] = t.map(|i| m.positions[i as usize]);
        let winding = (b - a).cross(c - a);
        let shading = m.normals[t[0] as usize];
        assert!(winding.dot(shading) > 0.0, "winding {winding} against normal {shading}");
    }
}

#[test]
fn a_mesh_the_field_cannot_trace_is_an_error_that_names_its_entity() {
    let mut app = app();
    spawn_world(&mut app);
    app.update();
    let good = scene(&app).scene.mesh.triangles.len();
    let mut lines = Mesh::new(PrimitiveTopology::LineList, RenderAssetUsages::default());
    lines.insert_attribute(Mesh::ATTRIBUTE_POSITION, vec![[0.0f32, 0.0, 0.0], [1.0, 0.0, 0.0]]);
    lines.insert_indices(Indices::U32(vec![0, 1]));
    let lines = app.world_mut().resource_mut::<Assets<Mesh>>().add(lines);
    app.world_mut().spawn((Name::new("wire"), Mesh3d(lines)));
    app.update();
    let e = scene(&app).error.clone().expect("an error");
    assert_eq!(e.entity, "wire");
    assert!(e.to_string().contains("LineList"), "{e}");
    assert_eq!(scene(&app).scene.mesh.triangles.len(), good, "the last good scene stays");
}

#[test]
fn cascades_are_probegi_renders_and_held_to_its_ranges() {
    use probegi_bevy::ProbegiCascades;
    let bounds = (glam::Vec3::new(-8.0, 0.0, -4.0), glam::Vec3::new(8.0, 8.0, 4.0));
    let set = ProbegiCascades::default().volumes(bounds);
    assert_eq!(set.volumes.len(), 3);
    // The outermost is the bounds' fitted grid: 16×8×16 cells of 1 × 1 × 0.5 m.
    let outer = set.volumes[2].probe_spacing_m.expect("spacing");
    assert!(outer.abs_diff_eq(glam::Vec3::new(1.0, 1.0, 0.5), 1e-5), "{outer}");
    let inner = set.volumes[0].probe_spacing_m.expect("spacing");
    assert!((outer / inner).abs_diff_eq(glam::Vec3::splat(1.5 * 1.5), 1e-4), "ratio 1.5 twice");
    assert!(
        set.volumes.iter().all(|v| v.volume_tracks_camera && v.volume_tracking_bounds_m == Some([bounds.0, bounds.1]))
    );
    assert!(set.validate().is_ok());
    let held = |count, ratio| ProbegiCascades { count, ratio, ..Default::default() }.volumes(bounds);
    assert_eq!(held(0, 2.0).volumes.len(), 1);
    assert_eq!(held(40, 2.0).volumes.len(), 16);
    let nan = held(2, f32::NAN);
    let r = nan.volumes[1].probe_spacing_m.expect("s") / nan.volumes[0].probe_spacing_m.expect("s");
    assert!(r.abs_diff_eq(glam::Vec3::splat(1.5), 1e-5), "a NaN ratio takes the default: {r}");
}

#[test]
fn only_the_assets_mesh_entities_use_make_the_geometry_again() {
    let mut app = app();
    spawn_world(&mut app);
    app.update();
    app.update();
    let g = scene(&app).geometry_generation;
    // A material no entity draws, made and changed: nothing to rebuild.
    let unused = app.world_mut().resource_mut::<Assets<StandardMaterial>>().add(StandardMaterial::default());
    app.update();
    let _ = app.world_mut().resource_mut::<Assets<StandardMaterial>>().get_mut(&unused);
    app.update();
    assert_eq!(scene(&app).geometry_generation, g, "an unused material changes nothing");
    // The box's material, changed: rebuilt, with its new colour.
    let mut q = app.world_mut().query::<(&Name, &MeshMaterial3d<StandardMaterial>)>();
    let used = q.iter(app.world()).find(|(n, _)| n.as_str() == "box").map(|(_, m)| m.0.clone()).expect("box");
    if let Some(mut m) = app.world_mut().resource_mut::<Assets<StandardMaterial>>().get_mut(&used) {
        m.base_color = Color::srgb(0.0, 1.0, 0.0);
    }
    app.update();
    app.update();
    let s = scene(&app);
    assert_eq!(s.geometry_generation, g + 1, "the box's material changed");
    assert!(s.scene.materials.iter().any(|m| m.base_color_factor == glam::Vec3::new(0.0, 1.0, 0.0)));
}

#[test]
fn a_probegi_material_is_traced_as_its_base_and_its_changes_count() {
    let mut app = app();
    let world = app.world_mut();
    let cube = world.resource_mut::<Assets<Mesh>>().add(Cuboid::new(1.0, 1.0, 1.0));
    let base = StandardMaterial { base_color: Color::srgb(1.0, 0.0, 0.0), perceptual_roughness: 0.4, ..default() };
    let lit = world.resource_mut::<Assets<ProbegiMaterial>>().add(ProbegiMaterial { base, extension: ProbegiLit });
    world.spawn((Mesh3d(cube), MeshMaterial3d(lit.clone()), Transform::default()));
    app.update();
    let s = scene(&app);
    assert!(s.error.is_none(), "{:?}", s.error);
    assert_eq!(s.scene.mesh.triangles.len(), 12);
    assert_eq!(s.scene.materials.len(), 1, "the cube's material, not the default");
    let m = &s.scene.materials[0];
    assert_eq!((m.base_color_factor, m.roughness), (glam::Vec3::new(1.0, 0.0, 0.0), 0.4));
    let g = s.geometry_generation;
    // Its base changed: the geometry is made again with the new colour.
    if let Some(mut m) = app.world_mut().resource_mut::<Assets<ProbegiMaterial>>().get_mut(&lit) {
        m.base.base_color = Color::srgb(0.0, 0.0, 1.0);
    }
    app.update();
    let s = scene(&app);
    assert_eq!(s.geometry_generation, g + 1);
    assert_eq!(s.scene.materials[0].base_color_factor, glam::Vec3::new(0.0, 0.0, 1.0));
}

#[test]
fn moving_meshes_are_posed_without_making_the_geometry_again() {
    let mut app = app();
    spawn_world(&mut app);
    let world = app.world_mut();
    let cube = world.resource_mut::<Assets<Mesh>>().add(Cuboid::new(0.5, 0.5, 0.5));
    let white = world.resource_mut::<Assets<StandardMaterial>>().add(StandardMaterial::default());
    let start = Transform::from_xyz(0.0, 1.0, 0.0);
    let ball = world.spawn((Mesh3d(cube), MeshMaterial3d(white), start, ProbegiDynamic)).id();
    app.update();
    let s = scene(&app);
    assert_eq!(s.moving, vec![ball], "the ProbegiDynamic mesh is a moving object from the start");
    assert_eq!(s.scene.objects.len(), 1);
    assert_eq!(s.scene.objects[0].triangle_count, 12);
    assert_eq!(s.object_poses, vec![glam::Mat4::IDENTITY]);
    let g = s.geometry_generation;
    // It moves and turns: posed, the geometry kept.
    let to = Transform::from_xyz(2.0, 1.0, -1.0).with_rotation(Quat::from_rotation_y(0.5));
    *app.world_mut().get_mut::<Transform>(ball).expect("transform") = to;
    app.update();
    let s = scene(&app);
    assert_eq!(s.geometry_generation, g, "a moving object's move keeps the geometry");
    let m = |t: Transform| glam::Mat4::from_cols_array(&t.to_matrix().to_cols_array());
    let want = m(to) * m(start).inverse();
    assert!(s.object_poses[0].abs_diff_eq(want, 1e-5), "{} against {want}", s.object_poses[0]);
    // A still mesh that moves: the geometry made again once, with it as a
    // moving object; its later moves are poses.
    let mut q = app.world_mut().query::<(Entity, &Name)>();
    let boxed = q.iter(app.world()).find(|(_, n)| n.as_str() == "box").map(|(e, _)| e).expect("box");
    app.world_mut().get_mut::<Transform>(boxed).expect("transform").translation.x += 1.0;
    app.update();
    let s = scene(&app);
    assert_eq!((s.geometry_generation, s.moving.len()), (g + 1, 2), "made again once");
    app.world_mut().get_mut::<Transform>(boxed).expect("transform").translation.x += 1.0;
    app.update();
    let s = scene(&app);
    assert_eq!(s.geometry_generation, g + 1, "then posed");
    let i = s.moving.iter().position(|e| *e == boxed).expect("the box moves");
    assert!(s.object_poses[i].abs_diff_eq(glam::Mat4::from_translation(glam::Vec3::X), 1e-5));
}

/// A cubemap of `size`² faces, each one colour (+X, −X, +Y, −Y, +Z, −Z), RGBA32F.
pub(crate) fn cubemap(faces: [[f32; 3]; 6], size: u32) -> Image {
    let texel = |c: [f32; 3]| [c[0], c[1], c[2], 1.0].into_iter().flat_map(f32::to_le_bytes).collect::<Vec<u8>>();
    let data: Vec<u8> = faces.iter().flat_map(|c| (0..size * size).flat_map(move |_| texel(*c))).collect();
    cube_image(size, TextureFormat::Rgba32Float, data)
}

/// Six `size`² layers of `format` holding `data`, viewed as a cube (as a
/// skybox's image is).
pub(crate) fn cube_image(size: u32, format: TextureFormat, data: Vec<u8>) -> Image {
    let size = Extent3d { width: size, height: size, depth_or_array_layers: 6 };
    let mut image = Image::new(size, TextureDimension::D2, data, format, RenderAssetUsages::default());
    image.texture_view_descriptor = Some(bevy::render::render_resource::TextureViewDescriptor {
        dimension: Some(bevy::render::render_resource::TextureViewDimension::Cube),
        ..default()
    });
    image
}

#[test]
fn the_cameras_skybox_is_the_fields_sky_map_looked_up_as_bevy_looks_it_up() {
    let mut app = app();
    spawn_world(&mut app);
    let faces = [[1.0, 0.0, 0.0], [2.0, 0.0, 0.0], [0.0, 3.0, 0.0], [0.0, 4.0, 0.0], [0.0, 0.0, 5.0], [0.0, 0.0, 6.0]];
    let image = app.world_mut().resource_mut::<Assets<Image>>().add(cubemap(faces, 8));
    let skybox = bevy::light::Skybox { image: Some(image), brightness: 100.0, rotation: Quat::IDENTITY };
    let camera = app.world_mut().spawn((Camera::default(), skybox)).id();
    app.update();
    let s = scene(&app);
    assert!(s.error.is_none(), "{:?}", s.error);
    assert!(s.volumes.iter().all(|v| v.probe_sky_map_on_miss), "the field carries the map's light");
    let map = s.sky_map.as_ref().expect("a sky map");
    // Bevy reads a cubemap along (x, y, −z): world +z sees the −Z face.
    let want = |face: usize| glam::Vec3::from_array(faces[face]) * 100.0;
    for (d, face) in [(glam::Vec3::X, 0), (glam::Vec3::NEG_X, 1), (glam::Vec3::Y, 2), (glam::Vec3::NEG_Y, 3)]
        .into_iter()
        .chain([(glam::Vec3::Z, 5), (glam::Vec3::NEG_Z, 4)])
    {
        assert!(map.radiance(d).abs_diff_eq(want(face), 1e-3), "{d}: {} against face {face}", map.radiance(d));
    }
    let generation = s.sky_generation;
    // Brighter: the same map, its intensity.
    app.world_mut().get_mut::<bevy::light::Skybox>(camera).expect("skybox").brightness = 50.0;
    app.update();
    let s = scene(&app);
    assert_eq!((s.sky_generation, s.sky_map.as_ref().map(|m| m.intensity)), (generation, Some(50.0)));
    // Turned a quarter about +y: world +x now sees what +z saw... Bevy's
    // lookup turns the direction back, R⁻¹·(+x) = +z, which reads the −Z face.
    app.world_mut().get_mut::<bevy::light::Skybox>(camera).expect("skybox").rotation =
        Quat::from_rotation_y(std::f32::consts::FRAC_PI_2);
    app.update();
    let s = scene(&app);
    assert_eq!(s.sky_generation, generation + 1, "a turn makes the map again");
    let map = s.sky_map.as_ref().expect("a sky map");
    assert!(map.radiance(glam::Vec3::X).abs_diff_eq(want(5) * 0.5, 1e-3), "{}", map.radiance(glam::Vec3::X));
    // The cubemap's texels changed in place (a hot reload): the map is made again.
    let handle = app.world().get::<bevy::light::Skybox>(camera).and_then(|s| s.image.clone()).expect("image");
    if let Some(mut image) = app.world_mut().resource_mut::<Assets<Image>>().get_mut(&handle) {
        *image = cubemap([[7.0, 7.0, 7.0]; 6], 8);
    }
    app.update();
    let s = scene(&app);
    assert_eq!(s.sky_generation, generation + 2, "new texels make the map again");
    let map = s.sky_map.as_ref().expect("a sky map");
    assert!(map.radiance(glam::Vec3::Y).abs_diff_eq(glam::Vec3::splat(7.0 * 50.0), 1e-3));
    // No skybox: the constant sky again.
    app.world_mut().entity_mut(camera).remove::<bevy::light::Skybox>();
    app.update();
    assert!(scene(&app).sky_map.is_none());
}

#[test]
fn emissives_are_the_luminance_the_camera_shows() {
    // Bevy draws emissive × mix(1, exposure, w): luminance emissive × ((1 − w)/exposure + w).
    let mut app = app();
    let world = app.world_mut();
    let quad = world.resource_mut::<Assets<Mesh>>().add(Plane3d::default().mesh().size(1.0, 1.0));
    let mut materials = world.resource_mut::<Assets<StandardMaterial>>();
    let glow = |w: f32| StandardMaterial {
        emissive: LinearRgba::rgb(1.0, 2.0, 3.0),
        emissive_exposure_weight: w,
        ..default()
    };
    let (display, luminance) = (materials.add(glow(0.0)), materials.add(glow(1.0)));
    world.spawn((Mesh3d(quad.clone()), MeshMaterial3d(display), Transform::default()));
    world.spawn((Mesh3d(quad), MeshMaterial3d(luminance), Transform::from_xyz(2.0, 0.0, 0.0)));
    let camera = world.spawn((Camera3d::default(), bevy::camera::Exposure { ev100: 0.0 })).id();
    app.update();
    let emissive = |app: &App| {
        let mut e: Vec<glam::Vec3> = scene(app).scene.materials.iter().map(|m| m.emissive_factor).collect();
        e.sort_by(|a, b| a.x.total_cmp(&b.x));
        e
    };
    // EV100 0: exposure 1/1.2.
    let want = [glam::Vec3::new(1.0, 2.0, 3.0), glam::Vec3::new(1.2, 2.4, 3.6)];
    assert!(emissive(&app).iter().zip(want).all(|(a, b)| a.abs_diff_eq(b, 1e-5)), "{:?}", emissive(&app));
    // Two stops brighter exposure: the display value is a quarter of the light.
    let g = scene(&app).geometry_generation;
    app.world_mut().get_mut::<bevy::camera::Exposure>(camera).expect("exposure").ev100 = -2.0;
    app.update();
    assert_eq!(scene(&app).geometry_generation, g + 1, "a new exposure reads the emissives again");
    let want = [glam::Vec3::new(0.3, 0.6, 0.9), glam::Vec3::new(1.0, 2.0, 3.0)];
    assert!(emissive(&app).iter().zip(want).all(|(a, b)| a.abs_diff_eq(b, 1e-5)), "{:?}", emissive(&app));
}

#[test]
fn a_moving_mesh_the_geometry_does_not_hold_makes_nothing_again() {
    // A mesh whose asset has not arrived is not in the geometry: its moves
    // must not make the geometry again (its arrival will).
    let mut app = app();
    spawn_world(&mut app);
    app.update();
    let g = scene(&app).geometry_generation;
    let pending = app.world_mut().resource_mut::<Assets<Mesh>>().reserve_handle();
    let ghost = app.world_mut().spawn((Mesh3d(pending), Transform::default(), ProbegiDynamic)).id();
    app.update();
    for step in 0..3 {
        app.world_mut().get_mut::<Transform>(ghost).expect("transform").translation.x = step as f32;
        app.update();
    }
    assert!(scene(&app).geometry_generation <= g + 1, "at most its arrival's rebuild, not one a move");
}

#[test]
fn the_clear_colour_is_the_sky_its_camera_draws() {
    // Bevy writes the clear colour into the view target as it is, where light
    // arrives × exposure: the sky that draws it has luminance clear / exposure.
    let mut app = App::new();
    app.add_plugins((MinimalPlugins, AssetPlugin::default(), bevy::transform::TransformPlugin))
        .init_asset::<Mesh>()
        .init_asset::<Image>()
        .init_asset::<StandardMaterial>()
        .add_plugins(ProbegiPlugin::default())
        .insert_resource(ClearColor(Color::linear_rgb(0.1, 0.2, 0.3)));
    spawn_world(&mut app);
    // EV100 0: exposure 1/1.2.
    let camera = app.world_mut().spawn((Camera3d::default(), bevy::camera::Exposure { ev100: 0.0 })).id();
    app.update();
    let sky = |app: &App| glam::Vec3::from_array(scene(app).sky_radiance.to_array());
    assert!(sky(&app).abs_diff_eq(glam::Vec3::new(0.12, 0.24, 0.36), 1e-5), "{}", sky(&app));
    assert_eq!(scene(&app).scene.sky_radiance, sky(&app), "the geometry is built under it");
    let (generation, geometry) = (scene(&app).generation, scene(&app).geometry_generation);
    app.update();
    assert_eq!(scene(&app).generation, generation, "an unchanged clear colour changes nothing");
    // A new clear colour: the field's sky follows, the geometry stays.
    app.world_mut().resource_mut::<ClearColor>().0 = Color::linear_rgb(0.5, 0.5, 0.5);
    app.update();
    assert!(sky(&app).abs_diff_eq(glam::Vec3::splat(0.6), 1e-5), "{}", sky(&app));
    assert_eq!((scene(&app).generation, scene(&app).geometry_generation), (generation + 1, geometry));
    // The camera's own clear colour wins over the resource, through its exposure.
    let mut cam = app.world_mut().get_mut::<Camera>(camera).expect("camera");
    cam.clear_color = ClearColorConfig::Custom(Color::linear_rgb(1.0, 0.0, 0.25));
    app.world_mut().get_mut::<bevy::camera::Exposure>(camera).expect("exposure").ev100 = -2.0;
    app.update();
    assert!(sky(&app).abs_diff_eq(glam::Vec3::new(0.3, 0.0, 0.075), 1e-5), "{}", sky(&app));
    // A camera that clears to nothing draws no sky.
    app.world_mut().get_mut::<Camera>(camera).expect("camera").clear_color = ClearColorConfig::None;
    app.update();
    assert_eq!(sky(&app), glam::Vec3::ZERO);
    // A radiance the application states wins over the clear colour.
    app.world_mut().resource_mut::<ProbegiScene>().sky = ProbegiSky::Radiance(Vec3::new(4.0, 5.0, 6.0));
    app.update();
    assert_eq!(sky(&app), glam::Vec3::new(4.0, 5.0, 6.0));
}

#[test]
fn a_metallic_roughness_texture_is_read_as_bevy_reads_it() {
    // Bevy's channels: roughness in G, metalness in B, linear values.
    let mut app = app();
    let world = app.world_mut();
    let quad = world.resource_mut::<Assets<Mesh>>().add(Plane3d::default().mesh().size(1.0, 1.0));
    let size = Extent3d { width: 1, height: 1, depth_or_array_layers: 1 };
    let texels = [0u8, 128, 64, 255];
    let linear =
        Image::new_fill(size, TextureDimension::D2, &texels, TextureFormat::Rgba8Unorm, RenderAssetUsages::default());
    let mr = world.resource_mut::<Assets<Image>>().add(linear);
    let material = StandardMaterial {
        base_color_texture: Some(mr.clone()), // the same image as a colour too
        metallic: 1.0,
        perceptual_roughness: 1.0,
        metallic_roughness_texture: Some(mr),
        ..default()
    };
    let material = world.resource_mut::<Assets<StandardMaterial>>().add(material);
    world.spawn((Mesh3d(quad), MeshMaterial3d(material)));
    app.update();
    let s = scene(&app);
    assert!(s.error.is_none(), "{:?}", s.error);
    let sc = &s.scene;
    let m = sc.materials.iter().find(|m| m.metallic_roughness_texture.is_some()).expect("the textured material");
    assert_eq!(m.specular_model, probegi_scene::material::SpecularModel::MetallicRoughness);
    let at = probegi_scene::material::VertexAttributes { uv: [glam::Vec2::splat(0.5); 2], color: glam::Vec3::ONE };
    let (roughness, metallic) = m.roughness_metallic(&sc.textures, &at);
    assert!(
        (roughness - 128.0 / 255.0).abs() < 1e-6 && (metallic - 64.0 / 255.0).abs() < 1e-6,
        "{roughness} {metallic}"
    );
    // As a colour the same image is sRGB-encoded: another texture.
    let colour = &sc.textures[m.base_color_texture.expect("base colour")];
    let data = &sc.textures[m.metallic_roughness_texture.expect("data")];
    assert_eq!(data.texels[0], [0, 128, 64]);
    assert_ne!(colour.texels[0], data.texels[0], "the colour copy is sRGB-encoded");
}
