//! Bevy's PBR lit by the field, on a headless Bevy app with its renderer (on
//! lavapipe in CI): a floor of two halves seen from above, the left with
//! `StandardMaterial`, the right with `ProbegiMaterial` (the same base), a
//! strong `AmbientLight`, no other light, the sky the only source the field
//! sees. The frame is rendered into a linear `Rgba16Float` image (no tone
//! mapping, no dithering) and read back.
//!
//! - With no volume, the right half is Bevy's own image: each pixel equals
//!   its mirror image on the left.
//! - With a volume, the right half is the field's Lambertian term alone,
//!   `exposure × diffuse_colour / π × E`, with `E` from probegi's CPU query
//!   over the atlases the frame read (read back after that frame's update):
//!   Bevy's ambient light is not added (it is more than twice the field's
//!   term here, so counting it would miss by far more than the bound). The left
//!   half keeps Bevy's ambient.
//!
//! Error analysis for the bound: the image stores half floats (relative
//! rounding ≤ 2⁻¹¹ ≈ 4.9·10⁻⁴); the shader's query and the CPU's read the
//! same atlas texels and differ by f32 rounding (~10⁻⁶ relative, the GPU
//! suite's query equivalence); the fragment's interpolated position and the
//! test's ray–plane intersection differ by ~10⁻⁶ m, over which the field is
//! flat. So 10⁻³ of the value (twice the half-float step).

use std::sync::{Arc, Mutex};

use bevy::camera::{Exposure, RenderTarget};
use bevy::core_pipeline::tonemapping::{DebandDither, Tonemapping};
use bevy::prelude::*;
use bevy::render::RenderApp;
use bevy::render::gpu_readback::{Readback, ReadbackComplete};
use bevy::render::render_resource::{TextureFormat, TextureUsages};
use bevy::render::view::Msaa;
use probegi_bevy::field_lighting::ProbegiQueryBindings;
use probegi_bevy::field_on_bevy_device::ProbegiRenderField;
use probegi_bevy::{ProbegiLit, ProbegiMaterial, ProbegiPlugin, ProbegiSky, ProbegiVolume};
use probegi_core::ddgi_settings::DdgiVolumeSettings;

use probegi_bevy::environment_sky::half_to_f32;

use crate::field_on_bevy_device::render_app_with;

const W: u32 = 64;
const H: u32 = 48;
const ALBEDO: f32 = 0.7;
const CAMERA_HEIGHT_M: f32 = 4.0;

/// The floor's two halves (left `StandardMaterial`, right `ProbegiMaterial`)
/// and the camera looking straight down at them; returns the target image.
fn spawn_floor_and_camera(app: &mut App) -> Handle<Image> {
    let world = app.world_mut();
    let half = world.resource_mut::<Assets<Mesh>>().add(Plane3d::new(Vec3::Y, Vec2::new(2.5, 5.0)));
    let base = StandardMaterial {
        base_color: Color::linear_rgb(ALBEDO, ALBEDO, ALBEDO),
        perceptual_roughness: 1.0,
        metallic: 0.0,
        ..default()
    };
    let plain = world.resource_mut::<Assets<StandardMaterial>>().add(base.clone());
    let lit = world.resource_mut::<Assets<ProbegiMaterial>>().add(ProbegiMaterial { base, extension: ProbegiLit });
    world.spawn((Mesh3d(half.clone()), MeshMaterial3d(plain), Transform::from_xyz(-2.5, 0.0, 0.0)));
    world.spawn((Mesh3d(half), MeshMaterial3d(lit), Transform::from_xyz(2.5, 0.0, 0.0)));
    let mut target = Image::new_target_texture(W, H, TextureFormat::Rgba16Float, None);
    // Read back: the copy reads the texture.
    target.texture_descriptor.usage |= TextureUsages::COPY_SRC;
    let image = world.resource_mut::<Assets<Image>>().add(target);
    world.spawn((
        Camera3d::default(),
        RenderTarget::Image(image.clone().into()),
        Tonemapping::None,
        DebandDither::Disabled,
        Msaa::Off,
        Exposure { ev100: 0.0 },
        AmbientLight { brightness: 10.0, ..default() },
        Transform::from_xyz(0.0, CAMERA_HEIGHT_M, 0.0).looking_at(Vec3::ZERO, Vec3::NEG_Z),
    ));
    image
}

/// Renders one frame and returns its pixels (RGB, row-major), after the
/// frames the read-back takes; `after_frame` runs right after the frame
/// rendered (before those).
fn render_frame(app: &mut App, image: &Handle<Image>, after_frame: impl FnOnce(&mut App)) -> Vec<[f32; 3]> {
    let pixels: Arc<Mutex<Option<Vec<u8>>>> = Arc::default();
    let sink = pixels.clone();
    // `ReadbackOnce` is taken off at the start of the next frame, so spawned
    // between frames it would be gone before this one: the `Readback` is
    // removed by hand after the frame instead.
    let reader = app
        .world_mut()
        .spawn(Readback::texture(image.clone()))
        .observe(move |done: On<ReadbackComplete>| {
            *sink.lock().expect("lock") = Some(done.data.clone());
        })
        .id();
    app.update();
    app.world_mut().entity_mut(reader).remove::<Readback>();
    after_frame(app);
    for _ in 0..10 {
        if pixels.lock().expect("lock").is_some() {
            break;
        }
        app.update();
    }
    let bytes = pixels.lock().expect("lock").take().expect("the frame was read back");
    assert_eq!(bytes.len(), (W * H * 8) as usize, "64 pixels × 8 bytes a row need no padding");
    bytes
        .chunks_exact(8)
        .map(|p| {
            let c = |i: usize| half_to_f32(u16::from_le_bytes([p[2 * i], p[2 * i + 1]]));
            [c(0), c(1), c(2)]
        })
        .collect()
}

/// Where pixel (x, y)'s centre meets the floor, and the unit direction from
/// there to the camera.
fn floor_point(app: &mut App, x: u32, y: u32) -> (Vec3, Vec3) {
    let mut q = app.world_mut().query::<(&Camera, &GlobalTransform)>();
    let (camera, transform) = q.single(app.world()).expect("one camera");
    let ray = camera.viewport_to_world(transform, Vec2::new(x as f32 + 0.5, y as f32 + 0.5)).expect("a ray");
    let t = -ray.origin.y / ray.direction.y;
    let point = ray.origin + ray.direction * t;
    (point, (transform.translation() - point).normalize())
}

fn close(a: f32, b: f32) -> bool {
    (a - b).abs() <= 1e-3 * a.abs().max(b.abs()) + 1e-6
}

/// Pixel (x, y) of a read-back frame.
fn pixel(px: &[[f32; 3]], x: u32, y: u32) -> [f32; 3] {
    px[(y * W + x) as usize]
}

/// Without a field: Bevy's lighting on both halves, mirror for mirror.
fn check_mirror_image(before: &[[f32; 3]]) {
    let mut checked = 0;
    for y in (0..H).step_by(7) {
        for x in 0..W / 2 {
            let (left, right) = (pixel(before, x, y), pixel(before, W - 1 - x, y));
            assert!(left[0] > 0.05, "Bevy's ambient lights the floor: {left:?} at ({x}, {y})");
            assert!((0..3).all(|c| close(left[c], right[c])), "({x}, {y}): {left:?} against {right:?}");
            checked += 1;
        }
    }
    assert!(checked >= 7 * 32);
}

/// The field's Lambertian term (exposure × albedo/π × the CPU query) at
/// each sample pixel's floor point, over the atlases the frame just rendered
/// read (read back before the next update changes them).
fn field_terms(app: &mut App, samples: &[(u32, u32)]) -> Vec<[f32; 3]> {
    let exposure = Exposure { ev100: 0.0 }.exposure();
    let points: Vec<(Vec3, Vec3)> = samples.iter().map(|&(x, y)| floor_point(app, x, y)).collect();
    let render_world = app.sub_app_mut(RenderApp).world_mut();
    let mut rf = render_world.resource_mut::<ProbegiRenderField>();
    assert!(rf.error.is_none(), "{:?}", rf.error);
    let field = rf.field.as_mut().expect("a field on Bevy's device");
    field.set.sync_host_atlases(Some(&field.tracer)).expect("read the atlases back");
    let g = |v: Vec3| glam::Vec3::from_array(v.to_array());
    points
        .into_iter()
        .map(|(p, v)| field.set.irradiance(g(p), glam::Vec3::Y, g(v)) * exposure * ALBEDO / std::f32::consts::PI)
        .map(|e| e.to_array())
        .collect()
}

/// With the volume moved to x < 0 only (its probes 1.25 m apart in x, the
/// last at x = −0.625): half a spacing beyond its box (x > 0.625) the field
/// covers nothing, and the right half is Bevy's own image (`before`) again.
fn check_bevys_image_outside(app: &mut App, image: &Handle<Image>, volume: Entity, before: &[[f32; 3]]) {
    *app.world_mut().get_mut::<Transform>(volume).expect("transform") =
        Transform::from_xyz(-2.5, 1.5, 0.0).with_scale(Vec3::new(5.0, 3.0, 10.0));
    for _ in 0..4 {
        app.update();
    }
    let outside = render_frame(app, image, |_| {});
    let mut compared = 0;
    for y in (0..H).step_by(5) {
        for x in W / 2..W {
            if floor_point(app, x, y).0.x > 0.7 {
                let (got, bevy) = (pixel(&outside, x, y), pixel(before, x, y));
                assert!((0..3).all(|c| close(got[c], bevy[c])), "({x}, {y}) outside the field: {got:?}, Bevy {bevy:?}");
                compared += 1;
            }
        }
    }
    assert!(compared >= 10, "{compared} pixels beyond the field's reach");
}

#[test]
fn the_field_replaces_bevys_indirect_diffuse_and_without_a_field_bevys_image_stays() {
    let Some(mut app) = render_app_with(ProbegiPlugin { sky: ProbegiSky::Radiance(Vec3::ONE), seed: 5 }) else {
        return;
    };
    let image = spawn_floor_and_camera(&mut app);
    for _ in 0..3 {
        app.update();
    }
    let before = render_frame(&mut app, &image, |_| {});
    check_mirror_image(&before);

    // A volume over the floor: the right half takes the field's light.
    let settings = DdgiVolumeSettings { probe_counts: [4, 3, 4].into(), ..default() };
    let volume = app
        .world_mut()
        .spawn((ProbegiVolume { settings }, Transform::from_xyz(0.0, 1.5, 0.0).with_scale(Vec3::new(10.0, 3.0, 10.0))))
        .id();
    for _ in 0..6 {
        app.update();
    }
    let samples: Vec<(u32, u32)> =
        (0..H).step_by(5).flat_map(|y| (W / 2 + 1..W).step_by(3).map(move |x| (x, y))).collect();
    let mut expected = vec![];
    let after = render_frame(&mut app, &image, |app| expected = field_terms(app, &samples));
    let bindings = app.sub_app(RenderApp).world().resource::<ProbegiQueryBindings>();
    assert!(bindings.binds_field(), "the materials bind the running field");
    assert!(bindings.rebinds >= 1, "the empty set's buffers were swapped for the field's");
    assert_eq!(expected.len(), samples.len());
    for (&(x, y), want) in samples.iter().zip(&expected) {
        let got = pixel(&after, x, y);
        assert!(want[0] > 0.05, "the field lights the floor: {want:?} at ({x}, {y})");
        assert!((0..3).all(|c| close(got[c], want[c])), "({x}, {y}): drawn {got:?}, the field's term {want:?}");
        // Bevy's ambient would have been far brighter: the test can tell.
        let ambient = pixel(&before, x, y);
        assert!(ambient[0] > 2.0 * want[0], "({x}, {y}): ambient {ambient:?} against the field's {want:?}");
        let (left, left_before) = (pixel(&after, W - 1 - x, y), pixel(&before, W - 1 - x, y));
        assert!(close(left[0], left_before[0]), "({x}, {y}): the plain half keeps Bevy's ambient");
    }
    eprintln!(
        "{} pixels: the field's term {:?} …; Bevy's ambient {:?}",
        samples.len(),
        expected[0],
        pixel(&before, samples[0].0, samples[0].1)
    );
    check_bevys_image_outside(&mut app, &image, volume, &before);
}
