//! The DDGI field on Bevy's own device: in the render world, on its
//! `RenderDevice` and `RenderQueue`, through `probegi-wgpu` on a caller-owned
//! device (`GpuContext::from_device`). No second device is made.
//!
//! Each frame the main world's [`ProbegiScene`] is extracted (an `Arc` of the
//! scene, no copy) and, in `RenderSystems::PrepareResources`, the field set is
//! updated on the device (`FieldSetUpdate::update_on_device`: the trace,
//! shade, blend and borders run as compute passes, the atlases stay on the
//! device and no CPU lighting is built). When the scene or the volumes change
//! (a new [`ProbegiScene::generation`]) the BVH, the device's scene and the
//! field are made again, as `probegi render` makes them for a scene: the
//! field starts over (seed 004's initialisation rounds, then the start-up
//! ramp).
//!
//! An update's passes go to Bevy's queue as one submission. The field's
//! first frame runs the initialisation rounds, which read their results back
//! (waits, once); later frames submit without waiting while the probe states
//! stay put (jcgt, the default).

use std::collections::BTreeMap;
use std::sync::Arc;

use bevy::prelude::*;
use bevy::render::extract_resource::{ExtractResource, ExtractResourcePlugin};
use bevy::render::renderer::{RenderAdapterInfo, RenderDevice, RenderQueue};
use bevy::render::{Render, RenderApp, RenderSystems};
use probegi_core::ddgi_settings::{DdgiFieldSetSettings, DdgiVolumeSettings};
use probegi_field::DdgiFieldSet;
use probegi_frame::field_update::FieldSetUpdate;
use probegi_scene::{BvhSettings, BvhTracer, Scene};
use probegi_wgpu::GpuContext;
use probegi_wgpu::wgpu_field_backend::WgpuProbeTracer;

use crate::ProbegiScene;

/// What the render world takes from [`ProbegiScene`] each frame.
#[derive(Resource, Clone)]
pub struct ExtractedProbegiScene {
    scene: Arc<Scene>,
    volumes: Vec<DdgiVolumeSettings>,
    generation: u64,
    seed: u64,
}

impl ExtractResource<RenderApp> for ExtractedProbegiScene {
    type Source = ProbegiScene;

    fn extract_resource(source: &ProbegiScene) -> Self {
        Self {
            scene: source.scene.clone(),
            volumes: source.volumes.clone(),
            generation: source.generation,
            seed: source.seed,
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
    /// The scene the field was made for.
    pub scene: Arc<Scene>,
    bvh: BvhTracer,
    generation: u64,
    seed: u64,
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

/// Makes the field again when the extracted scene changed, then updates it.
fn update_field(
    extracted: Option<Res<ExtractedProbegiScene>>,
    device: Res<RenderDevice>,
    queue: Res<RenderQueue>,
    adapter: Res<RenderAdapterInfo>,
    mut out: ResMut<ProbegiRenderField>,
) {
    let Some(x) = extracted else { return };
    let stale = out.field.as_ref().is_none_or(|f| f.generation != x.generation);
    if stale {
        out.field = None;
        if x.volumes.is_empty() || x.scene.mesh.triangles.is_empty() {
            return;
        }
        let ctx = GpuContext::from_device(device.wgpu_device().clone(), (**queue).clone(), adapter.name.clone());
        match make_field(ctx, &x) {
            Ok(f) => out.field = Some(f),
            Err(e) => return report(&mut out, e),
        }
    }
    let Some(f) = out.field.as_mut() else { return };
    let mut pass_ms = BTreeMap::new();
    // The update's passes go to Bevy's queue together: one submission.
    f.tracer.ctx.defer_submissions(true);
    let result = f.set.update_on_device(&f.scene, &f.bvh, &f.tracer, f.seed, f.frame, &mut pass_ms);
    f.tracer.ctx.defer_submissions(false);
    match result {
        Ok(_) => {
            f.frame += 1;
            out.error = None;
        }
        Err(e) => report(&mut out, format!("the field update failed: {e}")),
    }
}

fn report(out: &mut ProbegiRenderField, e: String) {
    if out.error.as_deref() != Some(e.as_str()) {
        error!("probegi-bevy: {e}");
    }
    out.error = Some(e);
}

/// The BVH, the scene on the device and a fresh field set for `x`.
fn make_field(ctx: GpuContext, x: &ExtractedProbegiScene) -> Result<ProbegiField, String> {
    let scene = x.scene.clone();
    let bvh = BvhTracer::for_scene(&scene, BvhSettings::default());
    let tracer = WgpuProbeTracer::with_camera(ctx, &scene, &bvh, true, false)
        .map_err(|e| format!("the scene does not fit Bevy's device: {e}"))?
        .keeping_field(true)
        .generating_rays(true);
    let bounds = scene.bounds().ok_or("the scene has no geometry")?;
    let settings = DdgiFieldSetSettings { volumes: x.volumes.clone(), ..Default::default() };
    settings.validate().map_err(|(v, key, why)| format!("volume {v}: {key}: {why}"))?;
    let set = DdgiFieldSet::new(&settings, bounds, None);
    Ok(ProbegiField { set, tracer, scene, bvh, generation: x.generation, seed: x.seed, frame: 0 })
}
