//! The DDGI field on Bevy's own device: in the render world, on its
//! `RenderDevice` and `RenderQueue`, through `probegi-wgpu` on a caller-owned
//! device (`GpuContext::from_device`). No second device is made.
//!
//! Each frame the main world's [`ProbegiScene`] is extracted (an `Arc` of the
//! geometry, no copy; the lights and the volumes' settings) and, in
//! `RenderSystems::PrepareResources`, the field set is updated on the device
//! (`FieldSetUpdate::update_on_device`: the trace, shade, blend and borders
//! run as compute passes, the atlases stay on the device and no CPU lighting
//! is built). What a change costs:
//! - the geometry (a mesh, a material, a texture, a mesh entity's transform),
//!   a volume's box or a setting that sizes the field, or the number of
//!   lights: the BVH, the device's scene and the field are made again, as
//!   `probegi render` makes them for a scene; the field starts over (seed
//!   004's initialisation rounds, then the start-up ramp);
//! - a light that moves, turns, dims or changes colour: posed on the device
//!   (`ProbeBatchTracer::pose_scene`), the field keeps running, and
//!   `probegi_frame`'s `SceneChangeDetector` reports what seed 004 §4.3
//!   calls a light change (a light switched on or off);
//! - the [`LIVE_SETTINGS`] of a volume: written into the running field.
//!
//! An update's passes go to Bevy's queue as one submission. The field's
//! first frame runs the initialisation rounds, which read their results back
//! (waits, once); later frames submit without waiting while the probe states
//! stay put (jcgt, the default).

use std::collections::BTreeMap;
use std::sync::Arc;

use bevy::prelude::*;
use bevy::render::extract_resource::{ExtractResource, ExtractResourcePlugin};
use bevy::render::render_asset::RenderAssets;
use bevy::render::renderer::{RenderAdapterInfo, RenderDevice, RenderQueue};
use bevy::render::texture::GpuImage;
use bevy::render::{Render, RenderApp, RenderSystems};
use probegi_core::ddgi_settings::{DdgiFieldSetSettings, DdgiVolumeSettings};
use probegi_field::DdgiFieldSet;
use probegi_field::ProbeBatchTracer;
use probegi_frame::field_update::FieldSetUpdate;
use probegi_frame::scene_events::SceneChangeDetector;
use probegi_scene::{BvhSettings, BvhTracer, Scene};
use probegi_wgpu::GpuContext;
use probegi_wgpu::sky_from_cubemap::GpuSkyFromCubemap;
use probegi_wgpu::wgpu_field_backend::WgpuProbeTracer;

use crate::ProbegiScene;

/// The volume settings a running field takes as they change: the blend's
/// and the shade's, read every frame (the viewer's live settings, and PGI's
/// blend safeguards, which the device allocates for when turned on). Any
/// other setting makes the field again.
pub const LIVE_SETTINGS: [&str; 7] = [
    "probe_hysteresis",
    "probe_fast_convergence",
    "glossy_second_order",
    "ray_budget",
    "probe_firefly_clamp_ratio",
    "probe_adaptive_hysteresis",
    "probe_adaptive_hysteresis_tolerance",
];

/// `to` with [`LIVE_SETTINGS`] from `from`.
fn with_live_settings(to: &DdgiVolumeSettings, from: &DdgiVolumeSettings) -> DdgiVolumeSettings {
    DdgiVolumeSettings {
        probe_hysteresis: from.probe_hysteresis,
        probe_fast_convergence: from.probe_fast_convergence,
        glossy_second_order: from.glossy_second_order,
        ray_budget: from.ray_budget,
        probe_firefly_clamp_ratio: from.probe_firefly_clamp_ratio,
        probe_adaptive_hysteresis: from.probe_adaptive_hysteresis,
        probe_adaptive_hysteresis_tolerance: from.probe_adaptive_hysteresis_tolerance,
        ..to.clone()
    }
}

/// What the render world takes from [`ProbegiScene`] each frame.
#[derive(Resource, Clone)]
pub struct ExtractedProbegiScene {
    geometry: Arc<Scene>,
    lights: Vec<probegi_scene::PunctualLight>,
    volumes: Vec<DdgiVolumeSettings>,
    blending: probegi_core::ddgi_settings::VolumeBlending,
    tracking_target: Option<glam::Vec3>,
    sky_radiance: glam::Vec3,
    geometry_generation: u64,
    seed: u64,
    object_poses: Vec<glam::Mat4>,
    sky_map: Option<probegi_scene::SkyMap>,
    sky_generation: u64,
    /// The cubemap whose texels the device writes into `sky_map` each frame,
    /// and its lookup (`ProbegiScene::sky_on_device`, `environment_sky::to_cube`).
    sky_on_device: Option<(AssetId<Image>, glam::Mat3)>,
}

impl ExtractResource<RenderApp> for ExtractedProbegiScene {
    type Source = ProbegiScene;

    fn extract_resource(source: &ProbegiScene) -> Self {
        Self {
            geometry: source.scene.clone(),
            lights: source.lights.clone(),
            volumes: source.volumes.clone(),
            blending: source.blending,
            tracking_target: source.tracking_target,
            sky_radiance: glam::Vec3::from_array(source.sky_radiance.to_array()),
            geometry_generation: source.geometry_generation,
            seed: source.seed,
            object_poses: source.object_poses.clone(),
            sky_map: source.sky_map.clone(),
            sky_generation: source.sky_generation,
            sky_on_device: source.sky_on_device.map(|(id, r)| (id, crate::environment_sky::to_cube(r))),
        }
    }
}

/// The field in the render world: the set, the tracer that keeps its atlases
/// on Bevy's device, and what they were made from.
pub struct ProbegiField {
    /// The field set (its atlases live on the device: `DdgiFieldSet::field_on_device`).
    pub set: DdgiFieldSet,
    /// The passes on Bevy's device, holding the field's atlases.
    pub tracer: WgpuProbeTracer,
    /// The scene as the field sees it: the geometry it was made for and
    /// this frame's lights.
    pub scene: Scene,
    /// The volumes' settings as extracted (the structure the field was made
    /// with, the live settings as last applied).
    pub volumes: Vec<DdgiVolumeSettings>,
    set_blending: probegi_core::ddgi_settings::VolumeBlending,
    bvh: BvhTracer,
    geometry_generation: u64,
    seed: u64,
    detector: SceneChangeDetector,
    /// The moving objects' poses as last placed (`ProbegiScene::object_poses`).
    object_poses: Vec<glam::Mat4>,
    /// The sky map it was made with (`ProbegiScene::sky_generation`).
    sky_generation: u64,
    /// The pass that writes the sky map from a cubemap on the device, where
    /// the host could not read it.
    sky_pass: Option<GpuSkyFromCubemap>,
    /// Updates run since the field was made.
    pub frame: u32,
}

/// The render world's field ([`ProbegiField`]), with the last error.
#[derive(Resource, Default)]
pub struct ProbegiRenderField {
    /// The field, once a scene with a volume was extracted.
    pub field: Option<ProbegiField>,
    /// Why the last update or rebuild failed, if it did.
    pub error: Option<String>,
    /// What the last failed rebuild was made from: not tried again until the
    /// extracted scene changes.
    failed: Option<(u64, Vec<DdgiVolumeSettings>, usize)>,
}

/// Adds the extraction and the update to the render app, where there is one
/// (an app without `RenderPlugin` keeps only the main-world scene).
pub(crate) fn build(app: &mut App) {
    if app.get_sub_app(RenderApp).is_none() {
        return;
    }
    app.add_plugins(ExtractResourcePlugin::<ExtractedProbegiScene>::default());
    let Some(render_app) = app.get_sub_app_mut(RenderApp) else { return };
    render_app
        .init_resource::<ProbegiRenderField>()
        .add_systems(Render, update_field.in_set(RenderSystems::PrepareResources));
}

/// Makes the field again when the extracted scene changed in structure,
/// takes its lights and live settings, then updates it.
pub(crate) fn update_field(
    extracted: Option<Res<ExtractedProbegiScene>>,
    device: Res<RenderDevice>,
    queue: Res<RenderQueue>,
    adapter: Res<RenderAdapterInfo>,
    gpu_images: Res<RenderAssets<GpuImage>>,
    mut out: ResMut<ProbegiRenderField>,
) {
    let Some(x) = extracted else { return };
    if out.field.as_ref().is_none_or(|f| needs_rebuild(f, &x)) {
        out.field = None;
        let key = (x.geometry_generation, x.volumes.clone(), x.lights.len());
        if x.volumes.is_empty() || x.geometry.mesh.triangles.is_empty() || out.failed.as_ref() == Some(&key) {
            return;
        }
        let ctx = GpuContext::from_device(device.wgpu_device().clone(), (**queue).clone(), adapter.name.clone());
        match make_field(ctx, &x) {
            Ok(f) => (out.field, out.failed) = (Some(f), None),
            Err(e) => {
                out.failed = Some(key);
                return report(&mut out, e);
            }
        }
    }
    let Some(f) = out.field.as_mut() else { return };
    if let Err(e) = take_changes(f, &x) {
        return report(&mut out, e);
    }
    let mut pass_ms = BTreeMap::new();
    // The update's passes go to Bevy's queue together: one submission.
    f.tracer.ctx.defer_submissions(true);
    let sky = write_sky_on_device(f, &x, &gpu_images);
    let result = f.set.update_on_device(&f.scene, &f.bvh, &f.tracer, f.seed, f.frame, &mut pass_ms);
    f.tracer.ctx.defer_submissions(false);
    if result.is_ok() {
        f.frame += 1;
    }
    match (result, sky) {
        (Ok(_), Ok(())) => out.error = None,
        (Err(e), _) => report(&mut out, format!("the field update failed: {e}")),
        (Ok(_), Err(e)) => report(&mut out, e),
    }
}

/// Records the pass that writes the sky map from the cubemap Bevy holds on
/// the device ([`ExtractedProbegiScene::sky_on_device`]), where there is one
/// and Bevy has prepared it (until then the map stays black).
fn write_sky_on_device(
    f: &ProbegiField,
    x: &ExtractedProbegiScene,
    gpu_images: &RenderAssets<GpuImage>,
) -> Result<(), String> {
    let (Some((id, to_cube)), Some(pass)) = (x.sky_on_device, f.sky_pass.as_ref()) else { return Ok(()) };
    let (Some(image), Some((_, scene))) = (gpu_images.get(id), f.tracer.shading()) else { return Ok(()) };
    let mut encoder = f.tracer.ctx.device.create_command_encoder(&Default::default());
    pass.record(&f.tracer.ctx, &mut encoder, &image.texture, to_cube, scene)
        .map_err(|e| format!("the sky cubemap on the device: {e}"))?;
    f.tracer.ctx.submit(encoder.finish());
    Ok(())
}

/// Whether `x` differs from what `f` was made with in more than its lights'
/// poses and the volumes' [`LIVE_SETTINGS`].
fn needs_rebuild(f: &ProbegiField, x: &ExtractedProbegiScene) -> bool {
    f.geometry_generation != x.geometry_generation
        || f.sky_generation != x.sky_generation
        || f.scene.lights.len() != x.lights.len()
        || f.volumes.len() != x.volumes.len()
        || f.set_blending != x.blending
        || f.volumes.iter().zip(&x.volumes).any(|(old, new)| with_live_settings(new, old) != *old)
}

/// This frame's lights, sky and moving objects (posed on the device, the
/// detector told) and live settings (validated as the field's are).
fn take_changes(f: &mut ProbegiField, x: &ExtractedProbegiScene) -> Result<(), String> {
    let objects_moved = f.object_poses != x.object_poses;
    let intensity = |m: &Option<probegi_scene::SkyMap>| m.as_ref().map(|m| m.intensity);
    let map_dimmed = intensity(&f.scene.sky_map) != intensity(&x.sky_map);
    if f.scene.lights != x.lights || f.scene.sky_radiance != x.sky_radiance || objects_moved || map_dimmed {
        let lights = std::mem::replace(&mut f.scene.lights, x.lights.clone());
        let sky = std::mem::replace(&mut f.scene.sky_radiance, x.sky_radiance);
        let map_intensity = intensity(&f.scene.sky_map);
        if let (Some(map), Some(i)) = (f.scene.sky_map.as_mut(), intensity(&x.sky_map)) {
            map.intensity = i;
        }
        if objects_moved {
            place_objects(&mut f.scene, x)?;
        }
        if let Err(e) = f.tracer.pose_scene(&f.scene, f.frame as f32) {
            // Kept as they were, so the next frame tries again.
            (f.scene.lights, f.scene.sky_radiance) = (lights, sky);
            if let (Some(map), Some(i)) = (f.scene.sky_map.as_mut(), map_intensity) {
                map.intensity = i;
            }
            return Err(format!("the lights and moving objects could not be posed: {e}"));
        }
        f.object_poses.clone_from(&x.object_poses);
    }
    if let Some(t) = x.tracking_target {
        // The cascades follow their entity (whole cells: seed 004 §7.3).
        f.set.set_tracking_target(t);
    }
    f.detector.observe(&f.scene, &mut f.set);
    if f.volumes != x.volumes {
        let live: Vec<DdgiVolumeSettings> =
            f.set.volumes().iter().zip(&x.volumes).map(|(v, new)| with_live_settings(&v.settings, new)).collect();
        let settings = DdgiFieldSetSettings { volumes: live, blending: f.set_blending };
        settings.validate().map_err(|(v, key, why)| format!("volume {v}: {key}: {why}"))?;
        for (v, s) in f.set.volumes_mut().iter_mut().zip(settings.volumes) {
            v.settings = s;
        }
        f.volumes = x.volumes.clone();
    }
    Ok(())
}

/// Sets each moving object's key to its pose and poses its vertices from the
/// rest geometry (the device's TLAS and vertices follow in `pose_scene`).
fn place_objects(scene: &mut Scene, x: &ExtractedProbegiScene) -> Result<(), String> {
    if scene.objects.len() != x.object_poses.len() {
        return Err(format!("{} moving objects, {} poses", scene.objects.len(), x.object_poses.len()));
    }
    for (o, pose) in scene.objects.iter_mut().zip(&x.object_poses) {
        let key = crate::scene_extract::moving_key(*pose).ok_or_else(|| format!("{}: a pose no key gives", o.name))?;
        o.animation.keyframes = vec![key];
    }
    scene.pose_objects_from(&x.geometry, 0.0);
    Ok(())
}

fn report(out: &mut ProbegiRenderField, e: String) {
    if out.error.as_deref() != Some(e.as_str()) {
        error!("probegi-bevy: {e}");
    }
    out.error = Some(e);
}

/// The BVH, the scene on the device and a fresh field set for `x`.
fn make_field(ctx: GpuContext, x: &ExtractedProbegiScene) -> Result<ProbegiField, String> {
    let settings = DdgiFieldSetSettings { volumes: x.volumes.clone(), blending: x.blending };
    settings.validate().map_err(|(v, key, why)| format!("volume {v}: {key}: {why}"))?;
    let scene = Scene {
        lights: x.lights.clone(),
        sky_radiance: x.sky_radiance,
        sky_map: x.sky_map.clone(),
        ..(*x.geometry).clone()
    };
    let bvh = BvhTracer::for_scene(&scene, BvhSettings::default());
    let tracer = WgpuProbeTracer::with_camera(ctx, &scene, &bvh, true, false)
        .map_err(|e| format!("the scene does not fit Bevy's device: {e}"))?
        .keeping_field(true)
        .generating_rays(true);
    let bounds = scene.bounds().ok_or("the scene has no geometry")?;
    let set = DdgiFieldSet::new(&settings, bounds, x.tracking_target);
    let mut detector = SceneChangeDetector::new();
    detector.remember_lights(&scene);
    let sky_pass = x.sky_on_device.map(|_| GpuSkyFromCubemap::new(&tracer.ctx));
    Ok(ProbegiField {
        set,
        tracer,
        scene,
        volumes: x.volumes.clone(),
        set_blending: x.blending,
        bvh,
        geometry_generation: x.geometry_generation,
        seed: x.seed,
        detector,
        object_poses: vec![glam::Mat4::IDENTITY; x.object_poses.len()],
        sky_generation: x.sky_generation,
        sky_pass,
        frame: 0,
    })
}
