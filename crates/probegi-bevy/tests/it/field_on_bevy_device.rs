//! The field on Bevy's own device: a headless Bevy app with its renderer (on
//! lavapipe in CI) updates the DDGI field in its render world; after the same
//! frames with the same seed, its atlases equal those of probegi's own GPU
//! backend run on a device of its own over the scene the plugin extracted.
//! Both run the same passes on the same kind of adapter, so the bound is the
//! GPU suite's for device-resident fields (1e-5 of the largest texel,
//! `probegi-wgpu/tests/it/field_on_the_device.rs`).

use std::collections::BTreeMap;

use bevy::app::PluginsState;
use bevy::prelude::*;
use bevy::render::RenderApp;
use probegi_bevy::field_on_bevy_device::ProbegiRenderField;
use probegi_bevy::{ProbegiCascades, ProbegiDynamic, ProbegiPlugin, ProbegiScene, ProbegiSky, ProbegiVolume};
use probegi_core::ddgi_settings::{DdgiFieldSetSettings, DdgiVolumeSettings};
use probegi_field::{DdgiFieldSet, ProbeBatchTracer};
use probegi_frame::field_update::FieldSetUpdate;
use probegi_scene::{BvhSettings, BvhTracer};
use probegi_wgpu::GpuContext;
use probegi_wgpu::wgpu_field_backend::WgpuProbeTracer;

const FRAMES: u32 = 6;
const SEED: u64 = 11;

/// A closed box of coloured walls around a lamp, and a 6×5×6 volume over it.
fn spawn_room(app: &mut App) {
    let world = app.world_mut();
    let mut meshes = world.resource_mut::<Assets<Mesh>>();
    let (wall, floor) = (meshes.add(Cuboid::new(0.2, 4.0, 6.0)), meshes.add(Cuboid::new(6.0, 0.2, 6.0)));
    let mut materials = world.resource_mut::<Assets<StandardMaterial>>();
    let mut colour = |r, g, b| materials.add(StandardMaterial { base_color: Color::srgb(r, g, b), ..default() });
    let (red, green, white) = (colour(0.8, 0.1, 0.1), colour(0.1, 0.8, 0.1), colour(0.8, 0.8, 0.8));
    let mut spawn = |mesh: &Handle<Mesh>, m: &Handle<StandardMaterial>, t: Transform| {
        world.spawn((Mesh3d(mesh.clone()), MeshMaterial3d(m.clone()), t));
    };
    spawn(&wall, &red, Transform::from_xyz(-3.0, 2.0, 0.0));
    spawn(&wall, &green, Transform::from_xyz(3.0, 2.0, 0.0));
    spawn(&floor, &white, Transform::from_xyz(0.0, 0.0, 0.0));
    spawn(&floor, &white, Transform::from_xyz(0.0, 4.0, 0.0));
    let back = Transform::from_xyz(0.0, 2.0, -3.0).with_rotation(Quat::from_rotation_y(std::f32::consts::FRAC_PI_2));
    spawn(&wall, &white, back);
    world.spawn((PointLight { intensity: 20_000.0, range: 20.0, ..default() }, Transform::from_xyz(0.0, 3.0, 0.0)));
    let settings = DdgiVolumeSettings { probe_counts: UVec3::new(6, 5, 6).to_array().into(), ..default() };
    world.spawn((ProbegiVolume { settings }, Transform::from_xyz(0.0, 2.0, 0.0).with_scale(Vec3::new(5.6, 3.6, 5.6))));
}

/// A Bevy app with its renderer, headless; `None` without a GPU adapter
/// (unless PROBEGI_REQUIRE_GPU is set, which makes that a failure).
fn render_app() -> Option<App> {
    render_app_with(ProbegiPlugin { sky: ProbegiSky::Radiance(Vec3::splat(0.2)), seed: SEED })
}

/// [`render_app`] with `plugin`.
pub(crate) fn render_app_with(plugin: ProbegiPlugin) -> Option<App> {
    GpuContext::headless_unless_absent().expect("PROBEGI_REQUIRE_GPU is set")?;
    let mut app = App::new();
    // Bevy's log only where asked for (it is global: one test at a time).
    let plugins = DefaultPlugins.build();
    let plugins = if std::env::var_os("PROBEGI_BEVY_LOG").is_some() {
        plugins
    } else {
        plugins.disable::<bevy::log::LogPlugin>()
    };
    // Built with the examples' `window` feature: still no window here (the
    // test threads are not the main thread an event loop needs).
    #[cfg(feature = "window")]
    let plugins = plugins.disable::<bevy::winit::WinitPlugin>().set(bevy::window::WindowPlugin {
        primary_window: None,
        exit_condition: bevy::window::ExitCondition::DontExit,
        ..default()
    });
    app.add_plugins(plugins).add_plugins(plugin);
    while app.plugins_state() == PluginsState::Adding {
        bevy::tasks::tick_global_task_pools_on_main_thread();
    }
    app.finish();
    app.cleanup();
    Some(app)
}

#[test]
fn the_field_on_bevys_device_equals_probegis_own() {
    let Some(mut app) = render_app() else { return };
    spawn_room(&mut app);
    for _ in 0..FRAMES {
        app.update();
    }
    let ps = app.world().resource::<ProbegiScene>();
    let scene = probegi_scene::Scene { lights: ps.lights.clone(), ..(*ps.scene).clone() };
    let volumes = ps.volumes.clone();
    assert_eq!(scene.mesh.triangles.len(), 5 * 12);
    // Past the start-up (whose initialisation rounds read back once), a Bevy
    // frame's field update never waits for the device.
    let counters = |app: &App| {
        let rf = app.sub_app(RenderApp).world().resource::<ProbegiRenderField>();
        assert!(rf.error.is_none(), "{:?}", rf.error);
        let field = rf.field.as_ref().expect("a field on Bevy's device");
        (field.tracer.ctx.counters(), field.frame)
    };
    let (before, frames_before) = counters(&app);
    assert!(frames_before >= FRAMES - 1, "the field runs from the first frames: {frames_before} updates");
    for _ in 0..3 {
        app.update();
    }
    let d = counters(&app).0 - before;
    assert_eq!(d.blocking_waits, 0, "the field waited for Bevy's device {} times in 3 frames", d.blocking_waits);
    assert_eq!(d.submissions, 3, "one submission a frame");
    let render_world = app.sub_app_mut(RenderApp).world_mut();
    let mut rf = render_world.resource_mut::<ProbegiRenderField>();
    let field = rf.field.as_mut().expect("a field on Bevy's device");
    let frames = field.frame;
    assert_eq!(frames, frames_before + 3, "one update a Bevy frame");
    field.set.sync_host_atlases(Some(&field.tracer)).expect("read the atlases back");
    let bevy_volume = &field.set.volumes()[0];

    // probegi's own GPU backend on its own device, the same scene and frames.
    let set = own_field(&scene, &volumes, None, frames);
    let own_volume = &set.volumes()[0];

    let (worst, largest) = irradiance_difference(bevy_volume, own_volume);
    eprintln!(
        "{frames} frames: irradiance differs by at most {worst} of {largest}; {} submissions in 3 frames",
        d.submissions
    );
    assert!(worst <= 1e-5 * largest, "irradiance differs by {worst} of {largest}");
}

/// (the largest irradiance difference, the largest texel) between two
/// volumes whose probe states must be equal; the field must hold light.
fn irradiance_difference(a: &probegi_field::DdgiVolume, b: &probegi_field::DdgiVolume) -> (f32, f32) {
    assert_eq!(a.probe_states, b.probe_states);
    let flat =
        |v: &probegi_field::DdgiVolume| v.irradiance.texels.iter().flat_map(|t| t.to_array()).collect::<Vec<_>>();
    let (a, b) = (flat(a), flat(b));
    let largest = b.iter().fold(0.0f32, |m, x| m.max(x.abs()));
    assert!(largest > 0.0, "the field holds light");
    (a.iter().zip(&b).map(|(x, y)| (x - y).abs()).fold(0.0f32, f32::max), largest)
}

/// The render world's field: (updates since it was made, its volume's hysteresis).
fn field_state(app: &App) -> (u32, f32) {
    let rf = app.sub_app(RenderApp).world().resource::<ProbegiRenderField>();
    assert!(rf.error.is_none(), "{:?}", rf.error);
    let f = rf.field.as_ref().expect("a field");
    (f.frame, f.set.volumes()[0].settings.probe_hysteresis)
}

#[test]
fn lights_and_live_settings_change_the_running_field_and_the_rest_makes_it_again() {
    let Some(mut app) = render_app() else { return };
    spawn_room(&mut app);
    for _ in 0..3 {
        app.update();
    }
    let (start, hysteresis) = field_state(&app);
    assert!(start >= 2 && hysteresis == 0.97, "{start} updates, hysteresis {hysteresis}");
    // The lamp moves: posed on the device, the field keeps its history.
    let mut lamp = app.world_mut().query_filtered::<&mut Transform, With<PointLight>>();
    for mut t in lamp.iter_mut(app.world_mut()) {
        t.translation.x = 1.5;
    }
    app.update();
    assert_eq!(field_state(&app).0, start + 1, "a moved light does not restart the field");
    let rf = app.sub_app(RenderApp).world().resource::<ProbegiRenderField>();
    assert_eq!(rf.field.as_ref().expect("field").scene.lights[0].position.x, 1.5);
    // A live setting: written into the running field.
    let mut volume = app.world_mut().query::<&mut ProbegiVolume>();
    for mut v in volume.iter_mut(app.world_mut()) {
        v.settings.probe_hysteresis = 0.9;
    }
    app.update();
    assert_eq!(field_state(&app), (start + 2, 0.9), "the hysteresis changes the running field");
    // A setting that sizes the field: made again.
    for mut v in volume.iter_mut(app.world_mut()) {
        v.settings.probe_counts = glam::UVec3::new(4, 4, 4);
    }
    app.update();
    assert_eq!(field_state(&app), (1, 0.9), "new probe counts make the field again");
    let rf = app.sub_app(RenderApp).world().resource::<ProbegiRenderField>();
    assert_eq!(rf.field.as_ref().expect("field").set.probe_count(), 64);
}

#[test]
fn cascades_follow_their_entity_without_starting_over() {
    let Some(mut app) = render_app() else { return };
    spawn_room(&mut app);
    let settings = DdgiVolumeSettings { probe_counts: glam::UVec3::new(4, 4, 4), ..default() };
    let eye = app
        .world_mut()
        .spawn((ProbegiCascades { count: 2, settings, ..default() }, Transform::from_xyz(-1.5, 2.0, 0.0)))
        .id();
    for _ in 0..3 {
        app.update();
    }
    let window = |app: &App| {
        let rf = app.sub_app(RenderApp).world().resource::<ProbegiRenderField>();
        assert!(rf.error.is_none(), "{:?}", rf.error);
        let f = rf.field.as_ref().expect("a field");
        assert_eq!(f.set.volumes().len(), 2, "the cascades, not the room's ProbegiVolume");
        (f.frame, f.set.volumes()[0].grid.origin_m)
    };
    let (start, before) = window(&app);
    assert!(start >= 2, "{start} updates");
    app.world_mut().entity_mut(eye).get_mut::<Transform>().expect("transform").translation.x = 1.5;
    app.update();
    let (frame, after) = window(&app);
    assert_eq!(frame, start + 1, "a moved camera scrolls the cascades; the field keeps running");
    assert!(after.x > before.x + 1.0, "the innermost window moved with its entity: {before} -> {after}");
}

#[test]
fn a_moving_mesh_is_placed_on_the_device_and_the_field_keeps_running() {
    let Some(mut app) = render_app() else { return };
    spawn_room(&mut app);
    let world = app.world_mut();
    let cube = world.resource_mut::<Assets<Mesh>>().add(Cuboid::new(0.6, 0.6, 0.6));
    let white = world.resource_mut::<Assets<StandardMaterial>>().add(StandardMaterial::default());
    let ball =
        world.spawn((Mesh3d(cube), MeshMaterial3d(white), Transform::from_xyz(-1.0, 0.5, 0.0), ProbegiDynamic)).id();
    for _ in 0..3 {
        app.update();
    }
    let placed = |app: &App| {
        let rf = app.sub_app(RenderApp).world().resource::<ProbegiRenderField>();
        assert!(rf.error.is_none(), "{:?}", rf.error);
        let f = rf.field.as_ref().expect("a field");
        let (lo, hi) = f.scene.moving_object_bounds()[0];
        (f.frame, (lo + hi) * 0.5)
    };
    let (start, centre) = placed(&app);
    assert!(centre.abs_diff_eq(glam::Vec3::new(-1.0, 0.5, 0.0), 1e-5), "{centre}");
    for step in 1..=3 {
        app.world_mut().get_mut::<Transform>(ball).expect("transform").translation.x += 0.5;
        app.update();
        let (frame, centre) = placed(&app);
        assert_eq!(frame, start + step, "a moving mesh does not restart the field");
        let want = glam::Vec3::new(-1.0 + 0.5 * step as f32, 0.5, 0.0);
        assert!(centre.abs_diff_eq(want, 1e-5), "step {step}: placed at {centre}, the entity at {want}");
    }
    let s = app.world().resource::<ProbegiScene>();
    assert_eq!(s.geometry_generation, 1, "the geometry was built once");

    // probegi's own GPU backend, the box placed by the same keys before the
    // same updates: the Bevy field must trace the box where it is, as this one.
    let render_world = app.sub_app_mut(RenderApp).world_mut();
    let mut rf = render_world.resource_mut::<ProbegiRenderField>();
    let field = rf.field.as_mut().expect("a field on Bevy's device");
    field.set.sync_host_atlases(Some(&field.tracer)).expect("read the atlases back");
    let ps = app.world().resource::<ProbegiScene>();
    let rest = probegi_scene::Scene { lights: ps.lights.clone(), ..(*ps.scene).clone() };
    let own = own_field(&rest, &ps.volumes, Some(start), start + 3);
    let rf = app.sub_app(RenderApp).world().resource::<ProbegiRenderField>();
    let bevy_volume = &rf.field.as_ref().expect("field").set.volumes()[0];
    let own_volume = &own.volumes()[0];
    let (worst, largest) = irradiance_difference(bevy_volume, own_volume);
    assert!(worst <= 1e-5 * largest, "irradiance differs by {worst} of {largest}");
}

/// probegi's own GPU backend on a device of its own over `rest` with
/// `volumes` for `frames` updates, the scene change detector told each frame
/// as the plugin tells it; with `first_move`, its one moving object 0.5 m
/// further along x before each update from then on (three moves at most), as
/// the moving-mesh test moves its entity.
fn own_field(
    rest: &probegi_scene::Scene,
    volumes: &[DdgiVolumeSettings],
    first_move: Option<u32>,
    frames: u32,
) -> DdgiFieldSet {
    let mut scene = rest.clone();
    let bvh = BvhTracer::for_scene(&scene, BvhSettings::default());
    let ctx = GpuContext::headless().expect("a GPU adapter");
    let own = WgpuProbeTracer::with_camera(ctx, &scene, &bvh, true, false)
        .expect("upload")
        .keeping_field(true)
        .generating_rays(true);
    let settings = DdgiFieldSetSettings { volumes: volumes.to_vec(), ..Default::default() };
    let mut set = DdgiFieldSet::new(&settings, scene.bounds().expect("geometry"), None);
    let mut detector = probegi_frame::scene_events::SceneChangeDetector::new();
    detector.remember_lights(&scene);
    let mut placed = 0;
    for f in 0..frames {
        let moves = first_move.map_or(0, |m| (f + 1).saturating_sub(m).min(3));
        if moves != placed {
            let pose = glam::Mat4::from_translation(glam::Vec3::new(0.5 * moves as f32, 0.0, 0.0));
            scene.objects[0].animation.keyframes = vec![probegi_bevy::scene_extract::moving_key(pose).expect("a key")];
            scene.pose_objects_from(rest, 0.0);
            own.pose_scene(&scene, f as f32).expect("pose");
            placed = moves;
        }
        detector.observe(&scene, &mut set);
        set.update_on_device(&scene, &bvh, &own, SEED, f, &mut BTreeMap::new()).expect("update");
    }
    set.sync_host_atlases(Some(&own)).expect("read the atlases back");
    set
}

/// The sky furnace's scene: a grey 40 m floor, a camera 2 m above it with
/// `cubemap` as its skybox (brightness 2, turned 0.4 rad about +y), and a
/// 4×3×4 volume over the floor; then `frames` frames.
pub(crate) fn sky_furnace_frames(app: &mut App, cubemap: Image, frames: u32) {
    let world = app.world_mut();
    let floor = world.resource_mut::<Assets<Mesh>>().add(Plane3d::new(Vec3::Y, Vec2::splat(20.0)));
    let grey = world.resource_mut::<Assets<StandardMaterial>>().add(StandardMaterial::default());
    world.spawn((Mesh3d(floor), MeshMaterial3d(grey)));
    let image = world.resource_mut::<Assets<Image>>().add(cubemap);
    let skybox = bevy::light::Skybox { image: Some(image), brightness: 2.0, rotation: Quat::from_rotation_y(0.4) };
    world.spawn((Camera3d::default(), skybox, Transform::from_xyz(0.0, 2.0, 0.0)));
    let settings = DdgiVolumeSettings { probe_counts: glam::UVec3::new(4, 3, 4), ..default() };
    // Probe rows at y = −0.25 (under the floor: switched off), 1.25 and 2.75.
    let around = Transform::from_xyz(0.0, 1.25, 0.0).with_scale(Vec3::new(4.0, 3.0, 4.0));
    world.spawn((ProbegiVolume { settings }, around));
    for _ in 0..frames {
        app.update();
    }
}

#[test]
fn a_uniform_skybox_lights_an_open_floor_through_the_field_to_pi_l() {
    // The sky's furnace on Bevy's device: a skybox of radiance 1 × brightness
    // 2 over a 40 m floor. The probes' misses read the map
    // (`probe_sky_map_on_miss`), so each probe's irradiance toward +y is π L
    // whatever its rays: the floor's E is 2π once the blend has converged
    // (the CPU backend's furnace is within 1 % by frame 40), up to the
    // irradiance encoding's rounding.
    let Some(mut app) = render_app_with(ProbegiPlugin { sky: ProbegiSky::Radiance(Vec3::ZERO), seed: SEED }) else {
        return;
    };
    sky_furnace_frames(&mut app, crate::extract::cubemap([[1.0; 3]; 6], 4), 40);
    let render_world = app.sub_app_mut(RenderApp).world_mut();
    let mut rf = render_world.resource_mut::<ProbegiRenderField>();
    assert!(rf.error.is_none(), "{:?}", rf.error);
    let field = rf.field.as_mut().expect("a field on Bevy's device");
    assert!(field.scene.sky_map.is_some(), "the skybox is the field's sky");
    field.set.sync_host_atlases(Some(&field.tracer)).expect("read the atlases back");
    let want = 2.0 * std::f32::consts::PI;
    for p in [glam::Vec3::ZERO, glam::Vec3::new(1.0, 0.0, -0.7)] {
        let e = field.set.irradiance(p, glam::Vec3::Y, glam::Vec3::Y);
        assert!((e - glam::Vec3::splat(want)).abs().max_element() < 0.01 * want, "E at {p}: {e}, want {want}");
    }
}

#[test]
fn a_hidden_mesh_leaves_the_fields_scene_and_comes_back_when_shown() {
    // Bevy's visibility (propagated by its VisibilityPlugin, in DefaultPlugins).
    let Some(mut app) = render_app() else { return };
    spawn_room(&mut app);
    app.update();
    let triangles = |app: &App| app.world().resource::<ProbegiScene>().scene.mesh.triangles.len();
    assert_eq!(triangles(&app), 5 * 12);
    let mut walls = app.world_mut().query_filtered::<Entity, With<Mesh3d>>();
    let wall = walls.iter(app.world()).next().expect("a wall");
    *app.world_mut().get_mut::<Visibility>(wall).expect("visibility") = Visibility::Hidden;
    app.update();
    assert_eq!(triangles(&app), 4 * 12, "a hidden mesh is not traced");
    *app.world_mut().get_mut::<Visibility>(wall).expect("visibility") = Visibility::Inherited;
    app.update();
    assert_eq!(triangles(&app), 5 * 12, "shown again");
}

#[test]
fn the_probe_view_draws_every_probe_where_it_is_and_the_field_never_sees_it() {
    use probegi_bevy::ProbegiProbeView;
    use probegi_bevy::probe_debug::ProbeMarker;
    let Some(mut app) = render_app() else { return };
    spawn_room(&mut app);
    for _ in 0..3 {
        app.update();
    }
    let generation = app.world().resource::<ProbegiScene>().geometry_generation;
    app.world_mut().resource_mut::<ProbegiProbeView>().enabled = true;
    for _ in 0..3 {
        app.update();
    }
    let mut markers = app.world_mut().query_filtered::<&Transform, With<ProbeMarker>>();
    let mut placed: Vec<[f32; 3]> = markers.iter(app.world()).map(|t| t.translation.to_array()).collect();
    let rf = app.sub_app(RenderApp).world().resource::<ProbegiRenderField>();
    let volume = &rf.field.as_ref().expect("a field").set.volumes()[0];
    let mut probes: Vec<[f32; 3]> = volume.probe_positions.iter().map(|p| p.to_array()).collect();
    assert_eq!(placed.len(), 6 * 5 * 6, "a sphere a probe");
    let order = |a: &[f32; 3], b: &[f32; 3]| a.partial_cmp(b).expect("finite");
    placed.sort_by(order);
    probes.sort_by(order);
    assert_eq!(placed, probes, "each sphere where relocation put its probe");
    let s = app.world().resource::<ProbegiScene>();
    assert_eq!((s.geometry_generation, s.scene.mesh.triangles.len()), (generation, 5 * 12), "not traced");
    // Off: the spheres go, and the field's geometry stays.
    app.world_mut().resource_mut::<ProbegiProbeView>().enabled = false;
    app.update();
    app.update();
    assert_eq!(app.world_mut().query_filtered::<(), With<ProbeMarker>>().iter(app.world()).count(), 0);
    assert_eq!(app.world().resource::<ProbegiScene>().geometry_generation, generation);
}
