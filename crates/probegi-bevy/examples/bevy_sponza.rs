//! The shared Dabrovic Sponza (`../shared/scenes/dabrovic-sponza`, CC BY-NC,
//! © 2002 Marko Dabrovic; its SOURCE.md) brought into Bevy by probegi's own
//! OBJ loader, lit by the sun and a sky, with camera-centred cascades
//! (`ProbegiCascades`, as `probegi render --cascades 3`). Every material is a
//! `ProbegiMaterial`: Bevy's PBR with its diffuse indirect light from the
//! field.
//!
//! ```sh
//! cd crates/probegi-bevy
//! cargo +nightly run --ignore-rust-version --features window --example bevy_sponza
//! cargo +nightly run --ignore-rust-version --example bevy_sponza -- --frames 40 --out sponza.png [--no-field]
//! ```
//!
//! `--scene PATH` reads another OBJ or glTF file. What the conversion keeps:
//! positions, normals, the first UV set, base colour (factor and texture,
//! sampled repeating), the coverage cut-out, emission, roughness and
//! metalness; not the bump and normal maps.

use std::path::PathBuf;

use bevy::asset::RenderAssetUsages;
use bevy::image::{ImageAddressMode, ImageFilterMode, ImageSampler, ImageSamplerDescriptor};
use bevy::mesh::{Indices, PrimitiveTopology};
use bevy::prelude::*;
use bevy::render::render_resource::{Extent3d, TextureDimension, TextureFormat};
use probegi_bevy::{ProbegiCascades, ProbegiLit, ProbegiMaterial, ProbegiPlugin};
use probegi_scene::Scene;
use probegi_scene::material::SpecularModel;

#[path = "common/bevy_example.rs"]
pub mod bevy_example;

/// The sky's luminance, cd·m⁻² (a clear sky's blue, about 1 500 nits).
const SKY_NITS: Vec3 = Vec3::new(1250.0, 1500.0, 2080.0);

/// The camera's exposure: a sunny day's EV100.
const EXPOSURE: bevy::camera::Exposure = bevy::camera::Exposure { ev100: 13.0 };

fn main() -> Result<(), String> {
    let mut rest = vec![];
    let mut scene = PathBuf::from(env!("CARGO_MANIFEST_DIR")).join("../../../shared/scenes/dabrovic-sponza/sponza.obj");
    let mut args = std::env::args().skip(1);
    while let Some(a) = args.next() {
        match a.as_str() {
            "--scene" => scene = PathBuf::from(args.next().ok_or("--scene needs a path")?),
            _ => rest.push(a),
        }
    }
    let args = bevy_example::Args::parse(rest.into_iter())?;
    let loaded = probegi_scene::load_scene(&scene.to_string_lossy()).map_err(|e| e.to_string())?;
    let mut app = App::new();
    bevy_example::add_default_plugins(&mut app, &args);
    // The clear colour is the field's sky (`ProbegiSky::ClearColor`, the
    // default): the colour this camera's exposure draws a sky of SKY_NITS as.
    let clear = SKY_NITS * EXPOSURE.exposure();
    app.add_plugins(ProbegiPlugin::default())
        .insert_resource(ClearColor(Color::linear_rgb(clear.x, clear.y, clear.z)))
        .insert_resource(Loaded(loaded, args.no_field))
        .add_systems(Startup, setup);
    bevy_example::run(app, &args).map(|_| ())
}

/// The scene probegi's loader read, and whether to leave the field out
/// (`--no-field`: no cascades, Bevy's own lighting).
#[derive(Resource)]
struct Loaded(Scene, bool);

/// The model as Bevy meshes, the sun, and the camera with its cascades.
fn setup(
    mut commands: Commands,
    loaded: Res<Loaded>,
    mut meshes: ResMut<Assets<Mesh>>,
    mut materials: ResMut<Assets<ProbegiMaterial>>,
    mut images: ResMut<Assets<Image>>,
    target: Option<Res<bevy_example::Target>>,
) {
    let scene = &loaded.0;
    let textures: Vec<Handle<Image>> = scene.textures.iter().map(|t| images.add(bevy_image(t))).collect();
    for (m, material) in scene.materials.iter().enumerate() {
        let Some(mesh) = material_mesh(scene, m as u32) else { continue };
        let base = standard_material(material, &textures);
        let handle = materials.add(ProbegiMaterial { base, extension: ProbegiLit });
        commands.spawn((Mesh3d(meshes.add(mesh)), MeshMaterial3d(handle), Name::new(material.name.clone())));
    }
    // The sun: direct sunlight, from the east and high.
    let sun = DirectionalLight { illuminance: 100_000.0, shadow_maps_enabled: true, ..default() };
    commands.spawn((sun, Transform::default().looking_to(Vec3::new(0.6, -1.0, 0.15), Vec3::Y)));
    // The camera at the atrium's west end, carrying the field's cascades.
    let at = Transform::from_xyz(-12.0, 2.5, -1.0).looking_at(Vec3::new(4.0, 4.5, 0.5), Vec3::Y);
    let camera = bevy_example::spawn_camera(&mut commands, at, EXPOSURE, target.as_deref());
    if !loaded.1 {
        commands.entity(camera).insert(ProbegiCascades::default());
    }
}

/// Material `m`'s triangles as one Bevy mesh, `None` where it has none.
fn material_mesh(scene: &Scene, m: u32) -> Option<Mesh> {
    let mesh = &scene.mesh;
    let mut remap = std::collections::HashMap::new();
    let (mut positions, mut normals, mut uvs, mut indices) = (vec![], vec![], vec![], vec![]);
    for (t, _) in mesh.triangles.iter().zip(&mesh.triangle_materials).filter(|(_, tm)| **tm == m) {
        for &v in t {
            let i = *remap.entry(v).or_insert_with(|| {
                positions.push(mesh.positions[v as usize].to_array());
                normals.push(mesh.normals[v as usize].to_array());
                uvs.push(mesh.uvs.get(v as usize).map_or([0.0; 2], |uv| uv.to_array()));
                positions.len() as u32 - 1
            });
            indices.push(i);
        }
    }
    if indices.is_empty() {
        return None;
    }
    let mut out = Mesh::new(PrimitiveTopology::TriangleList, RenderAssetUsages::default());
    out.insert_attribute(Mesh::ATTRIBUTE_POSITION, positions);
    out.insert_attribute(Mesh::ATTRIBUTE_NORMAL, normals);
    out.insert_attribute(Mesh::ATTRIBUTE_UV_0, uvs);
    out.insert_indices(Indices::U32(indices));
    Some(out)
}

/// probegi's material as Bevy's (linear factors, textures by index).
fn standard_material(m: &probegi_scene::Material, textures: &[Handle<Image>]) -> StandardMaterial {
    let texture = |i: Option<usize>| i.and_then(|i| textures.get(i).cloned());
    let e = m.emissive_factor * m.emissive_strength;
    // An MTL material's F0 is its Ks: Bevy's F0 = 0.16 × (reflectance ×
    // tint)², so reflectance² = max(Ks) / 0.16 and tint² = Ks / max(Ks).
    let (reflectance, specular_tint) = match m.specular_model {
        SpecularModel::Mtl | SpecularModel::None => {
            let ks = if m.specular_model == SpecularModel::Mtl { m.specular_color } else { glam::Vec3::ZERO };
            let k = ks.max_element();
            let tint = if k > 0.0 { (ks / k).to_array().map(f32::sqrt) } else { [1.0; 3] };
            ((k / 0.16).sqrt(), Color::linear_rgb(tint[0], tint[1], tint[2]))
        }
        SpecularModel::MetallicRoughness => (0.5, Color::WHITE),
    };
    StandardMaterial {
        base_color: Color::linear_rgb(m.base_color_factor.x, m.base_color_factor.y, m.base_color_factor.z),
        base_color_texture: texture(m.base_color_texture),
        emissive: LinearRgba::rgb(e.x, e.y, e.z),
        emissive_texture: texture(m.emissive_texture),
        perceptual_roughness: m.roughness,
        metallic: m.metallic,
        reflectance,
        specular_tint,
        alpha_mode: match m.alpha_mode {
            probegi_scene::material::AlphaMode::Opaque => AlphaMode::Opaque,
            probegi_scene::material::AlphaMode::Mask { cutoff } => AlphaMode::Mask(cutoff),
        },
        ..default()
    }
}

/// probegi's texture (sRGB RGB8 and an optional alpha plane) as a Bevy image,
/// sampled repeating and linearly, as OBJ's texture coordinates expect.
fn bevy_image(t: &probegi_scene::texture::Texture) -> Image {
    let alpha = |i: usize| t.alpha.as_ref().map_or(255, |a| a[i]);
    let data: Vec<u8> = t.texels.iter().enumerate().flat_map(|(i, p)| [p[0], p[1], p[2], alpha(i)]).collect();
    let size = Extent3d { width: t.width, height: t.height, depth_or_array_layers: 1 };
    let mut image =
        Image::new(size, TextureDimension::D2, data, TextureFormat::Rgba8UnormSrgb, RenderAssetUsages::default());
    image.sampler = ImageSampler::Descriptor(ImageSamplerDescriptor {
        address_mode_u: ImageAddressMode::Repeat,
        address_mode_v: ImageAddressMode::Repeat,
        mag_filter: ImageFilterMode::Linear,
        min_filter: ImageFilterMode::Linear,
        ..default()
    });
    image
}
