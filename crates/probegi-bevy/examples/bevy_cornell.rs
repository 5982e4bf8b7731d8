//! A Cornell box of Bevy primitives lit by probegi's field: `ProbegiMaterial`
//! on every wall and box, a DDGI volume over the room, a point light, and a
//! cube that moves every frame (a moving object: the field keeps running).
//!
//! In a window (the `window` feature: Bevy's winit and X11), with a fly
//! camera (WASD to move, Q/E down and up, the right mouse button held to look):
//!
//! ```sh
//! cd crates/probegi-bevy
//! cargo +nightly run --ignore-rust-version --features window --example bevy_cornell
//! ```
//!
//! Headless (no window needed; what the tests run), `FRAMES` frames into a PNG;
//! `--no-field` draws Bevy's own image (no volume: `ProbegiMaterial` falls
//! back to Bevy's lighting) to compare:
//!
//! ```sh
//! cargo +nightly run --ignore-rust-version --example bevy_cornell -- --frames 60 --out cornell.png
//! ```

use bevy::prelude::*;
use probegi_bevy::{ProbegiDynamic, ProbegiLit, ProbegiMaterial, ProbegiPlugin, ProbegiVolume};
use probegi_core::ddgi_settings::DdgiVolumeSettings;

#[path = "common/bevy_example.rs"]
pub mod bevy_example;

fn main() -> Result<(), String> {
    let args = bevy_example::Args::parse(std::env::args().skip(1))?;
    run(&args).map(|_| ())
}

/// The example as `args` asks: headless into a PNG (its pixels returned), or
/// in a window.
pub fn run(args: &bevy_example::Args) -> Result<Option<Vec<u8>>, String> {
    let mut app = App::new();
    bevy_example::add_default_plugins(&mut app, args);
    app.add_plugins(ProbegiPlugin::default()).add_systems(Startup, (setup, camera)).add_systems(Update, move_the_cube);
    if args.no_field {
        app.add_systems(Update, bevy_example::remove_volumes);
    }
    bevy_example::run(app, args)
}

// README: bevy-plugin begin
/// The room: walls and boxes with `ProbegiMaterial` (Bevy's `StandardMaterial`,
/// its diffuse indirect light from the field), a volume, a light, a moving cube.
fn setup(mut commands: Commands, mut meshes: ResMut<Assets<Mesh>>, mut materials: ResMut<Assets<ProbegiMaterial>>) {
    // A DDGI volume over the room: the papers' settings, 8×8×8 probes.
    let settings = DdgiVolumeSettings { probe_counts: [8, 8, 8].into(), ..default() };
    commands.spawn((ProbegiVolume { settings }, Transform::from_xyz(0.0, 1.0, 0.0).with_scale(Vec3::splat(2.0))));
    let mut lit = |r, g, b| {
        let base = StandardMaterial { base_color: Color::srgb(r, g, b), perceptual_roughness: 0.9, ..default() };
        materials.add(ProbegiMaterial { base, extension: ProbegiLit })
    };
    let (white, red, green) = (lit(0.73, 0.73, 0.73), lit(0.63, 0.065, 0.05), lit(0.14, 0.45, 0.09));
    let mut solid = |size: Vec3, at: Vec3, turn: f32, material: &Handle<ProbegiMaterial>| {
        let mesh = meshes.add(Cuboid::from_size(size));
        let place = Transform::from_translation(at).with_rotation(Quat::from_rotation_y(turn));
        commands.spawn((Mesh3d(mesh), MeshMaterial3d(material.clone()), place)).id()
    };
    solid(Vec3::new(2.0, 0.02, 2.0), Vec3::new(0.0, -0.01, 0.0), 0.0, &white); // floor
    solid(Vec3::new(2.0, 0.02, 2.0), Vec3::new(0.0, 2.01, 0.0), 0.0, &white); // ceiling
    solid(Vec3::new(2.0, 2.0, 0.02), Vec3::new(0.0, 1.0, -1.01), 0.0, &white); // back
    solid(Vec3::new(0.02, 2.0, 2.0), Vec3::new(-1.01, 1.0, 0.0), 0.0, &red); // left
    solid(Vec3::new(0.02, 2.0, 2.0), Vec3::new(1.01, 1.0, 0.0), 0.0, &green); // right
    solid(Vec3::new(0.6, 1.2, 0.6), Vec3::new(-0.35, 0.6, -0.3), 0.3, &white); // tall box
    solid(Vec3::new(0.6, 0.6, 0.6), Vec3::new(0.35, 0.3, 0.3), -0.3, &white); // short box
    // A mesh that moves every frame: ProbegiDynamic makes it a moving object
    // from the start, so its moves never restart the field.
    let cube = solid(Vec3::splat(0.25), Vec3::new(0.0, 0.125, 0.7), 0.0, &white);
    commands.entity(cube).insert((ProbegiDynamic, MovingCube));
    // 20 000 lm under the ceiling (Bevy's units; the field converts them).
    let lamp = PointLight { intensity: 20_000.0, range: 10.0, shadow_maps_enabled: true, ..default() };
    commands.spawn((lamp, Transform::from_xyz(0.0, 1.9, 0.0)));
}
// README: bevy-plugin end

/// The cube that slides across the front of the room.
#[derive(Component)]
struct MovingCube;

/// Slides the cube by the frame count (the same path whatever the frame rate).
fn move_the_cube(frames: Res<bevy::diagnostic::FrameCount>, mut cubes: Query<&mut Transform, With<MovingCube>>) {
    for mut t in &mut cubes {
        t.translation.x = 0.6 * (frames.0 as f32 * 0.05).sin();
    }
}

/// The camera in front of the open side of the room, exposed for a room.
fn camera(mut commands: Commands, target: Option<Res<bevy_example::Target>>) {
    let at = Transform::from_xyz(0.0, 1.0, 3.9).looking_at(Vec3::new(0.0, 1.0, 0.0), Vec3::Y);
    bevy_example::spawn_camera(&mut commands, at, bevy::camera::Exposure::INDOOR, target.as_deref());
}
