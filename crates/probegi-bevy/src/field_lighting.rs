//! Bevy's PBR lit by the DDGI field: [`ProbegiMaterial`], Bevy's
//! `StandardMaterial` extended by [`ProbegiLit`], whose fragment shader
//! (`field_lighting.wesl`) runs Bevy's own lighting with its diffuse
//! indirect light off and adds the field's: the Lambertian term of seed 000
//! eq. 4, `diffuse_color / π × E(x, n)`, with `E` from probegi's WGSL query
//! (`probegi_wgpu::ddgi_query::query_wgsl_at`, the 8-probe cage of seed 000
//! §3 with the production weights of seed 004), scaled by the camera's
//! exposure as Bevy scales its lights and by the material's diffuse
//! occlusion (its occlusion texture, SSAO).
//!
//! What it replaces: Bevy's `AmbientLight`, the diffuse part of an
//! `EnvironmentMapLight` and Bevy's irradiance volumes, on the meshes that
//! use [`ProbegiMaterial`] (Bevy scales all three by `diffuse_occlusion`,
//! which the shader zeroes for Bevy's part; the ambient light's small
//! specular term goes with it). Everything else is Bevy's: direct lights and
//! their shadows, the environment map's specular, emissive, fog, tone
//! mapping. Where the field has no volume yet (or no field runs), and outside
//! every volume, Bevy's own lighting is drawn unchanged; across a volume's
//! edge the two fade into each other (`probegi_field_coverage`). Not handled: lightmaps (Bevy adds them
//! without that scale, so a lightmapped mesh would count its indirect light
//! twice), the deferred renderer (its lighting pass is Bevy's) and
//! order-independent transparency.
//!
//! The field's four buffers sit in the material's bind group at
//! [`FIELD_BINDING`]…+3 (Bevy keeps 0–99 for the material). The render
//! world binds the running field's buffers, or an empty set's while there is
//! none ([`ProbegiQueryBindings`]); when the field is made again (new
//! buffers), every [`ProbegiMaterial`] is prepared again the next frame.
//! The extension is not bindless, so the combined material is not either.

use bevy::asset::uuid_handle;
use bevy::ecs::system::SystemParamItem;
use bevy::ecs::system::lifetimeless::SRes;
use bevy::pbr::{ExtendedMaterial, MaterialExtension, MeshMaterial3d};
use bevy::prelude::*;
use bevy::render::erased_render_asset::{AssetExtractionSystems, ExtractedAssets};
use bevy::render::render_resource::{
    AsBindGroup, AsBindGroupError, BindGroupBuilder, BindGroupLayout, BindGroupLayoutEntry, UnpreparedBindingResource,
};
use bevy::render::renderer::{RenderAdapterInfo, RenderDevice, RenderQueue};
use bevy::render::{Extract, ExtractSchedule, Render, RenderApp, RenderSystems};
use bevy::shader::{Shader, ShaderRef};
use probegi_core::ddgi_volume_blend::{DdgiFieldSetView, VolumeBlending};
use probegi_wgpu::GpuContext;
use probegi_wgpu::ddgi_query::{GpuDdgiField, query_wgsl_at};
use probegi_wgpu::wgpu;

use crate::field_on_bevy_device::ProbegiRenderField;

/// `StandardMaterial` lit by the field: use it where a mesh would use
/// `StandardMaterial` (`ProbegiMaterial { base, extension: ProbegiLit }`).
/// The field reads its base as it reads a `StandardMaterial`.
pub type ProbegiMaterial = ExtendedMaterial<StandardMaterial, ProbegiLit>;

/// The first of the field's four bindings in the material's bind group.
pub const FIELD_BINDING: u32 = 100;

/// Bevy's material bind group (`bevy_pbr::MATERIAL_BIND_GROUP_INDEX`), where
/// the query's bindings go.
const MATERIAL_GROUP: u32 = 3;

/// The fragment shader, made at start-up from `field_lighting.wesl` and
/// probegi's query library.
pub const FIELD_LIGHTING_SHADER: Handle<Shader> = uuid_handle!("27fbfce3-df1d-4b2a-9f74-1b820436b562");

/// The extension that lights a `StandardMaterial` by the field. It holds no
/// data: what it binds is the field, the same for every material.
#[derive(Asset, TypePath, Clone, Copy, Debug, Default, PartialEq)]
pub struct ProbegiLit;

impl MaterialExtension for ProbegiLit {
    fn fragment_shader() -> ShaderRef {
        FIELD_LIGHTING_SHADER.into()
    }
}

impl AsBindGroup for ProbegiLit {
    type Data = ();
    type Param = Option<SRes<ProbegiQueryBindings>>;

    fn label() -> &'static str {
        "probegi_lit"
    }

    fn bind_group_data(&self) -> Self::Data {}

    fn build_bind_group(
        &self,
        _layout: &BindGroupLayout,
        _render_device: &RenderDevice,
        bindings: &mut SystemParamItem<'_, '_, Self::Param>,
        _force_no_bindless: bool,
        output: &mut BindGroupBuilder,
    ) -> Result<(), AsBindGroupError> {
        // Before the render world's first frame has bound a field: next frame.
        let Some(bindings) = bindings.as_ref() else { return Err(AsBindGroupError::RetryNextUpdate) };
        for (b, buffer) in (FIELD_BINDING..).zip(&bindings.buffers) {
            output.push((b, UnpreparedBindingResource::Buffer(buffer.clone())));
        }
        Ok(())
    }

    fn bind_group_layout_entries(_: &RenderDevice, _force_no_bindless: bool) -> Vec<BindGroupLayoutEntry> {
        GpuDdgiField::layout_entries(FIELD_BINDING)
    }
}

/// The field buffers [`ProbegiMaterial`]s bind, in the render world.
#[derive(Resource)]
pub struct ProbegiQueryBindings {
    /// What the bind groups take (set, irradiance, distance, probes).
    buffers: [bevy::render::render_resource::Buffer; 4],
    /// The running field's buffers they are, or `None`: the empty set's.
    field: Option<[wgpu::Buffer; 4]>,
    /// An empty set's buffers (no member: Bevy's own lighting).
    empty: [wgpu::Buffer; 4],
    /// Bound to other buffers this frame: the materials are prepared again.
    rebound: bool,
    /// Times the buffers changed.
    pub rebinds: u64,
}

impl ProbegiQueryBindings {
    /// Whether the materials read the running field (else the empty set).
    pub fn binds_field(&self) -> bool {
        self.field.is_some()
    }
}

/// The shader from its template and probegi's query library.
pub fn field_lighting_source() -> String {
    let template = include_str!("field_lighting.wesl");
    let library = query_wgsl_at(MATERIAL_GROUP, FIELD_BINDING);
    template.replacen("// @probegi-query-library", &library, 1)
}

/// Adds the material, its shader and the render world's binding systems.
pub(crate) fn build(app: &mut App) {
    if app.get_sub_app(RenderApp).is_none() {
        // No renderer: the material is an asset the scene reads, no more.
        app.init_asset::<ProbegiMaterial>();
        return;
    }
    let shader = Shader::from_wesl(field_lighting_source(), "embedded://probegi_bevy/field_lighting.wesl");
    if let Some(mut shaders) = app.world_mut().get_resource_mut::<Assets<Shader>>()
        && let Err(e) = shaders.insert(&FIELD_LIGHTING_SHADER, shader)
    {
        error!("probegi-bevy: the field lighting shader: {e}");
    }
    app.add_plugins(MaterialPlugin::<ProbegiMaterial>::default());
    let Some(render_app) = app.get_sub_app_mut(RenderApp) else { return };
    render_app
        .add_systems(
            Render,
            bind_field.in_set(RenderSystems::PrepareResources).after(crate::field_on_bevy_device::update_field),
        )
        .add_systems(ExtractSchedule, prepare_materials_again.after(AssetExtractionSystems));
}

/// Binds the running field's buffers, or the empty set's while none runs;
/// marks a change for [`prepare_materials_again`].
fn bind_field(
    field: Res<ProbegiRenderField>,
    device: Res<RenderDevice>,
    queue: Res<RenderQueue>,
    adapter: Res<RenderAdapterInfo>,
    bindings: Option<ResMut<ProbegiQueryBindings>>,
    mut commands: Commands,
) {
    let running = field.field.as_ref().and_then(|f| f.tracer.resident_query_buffers());
    let Some(mut bindings) = bindings else {
        let ctx = GpuContext::from_device(device.wgpu_device().clone(), (**queue).clone(), adapter.name.clone());
        let set = DdgiFieldSetView { members: vec![], blending: VolumeBlending::Density, camera_m: None };
        let empty = match GpuDdgiField::upload(&ctx, &set) {
            Ok(f) => f.query_buffers(),
            Err(e) => return error!("probegi-bevy: the empty field's buffers: {e}"),
        };
        let buffers = running.clone().unwrap_or_else(|| empty.clone()).map(Into::into);
        commands.insert_resource(ProbegiQueryBindings { buffers, field: running, empty, rebound: true, rebinds: 0 });
        return;
    };
    if bindings.field != running {
        bindings.buffers = running.clone().unwrap_or_else(|| bindings.empty.clone()).map(Into::into);
        bindings.field = running;
        bindings.rebound = true;
        bindings.rebinds += 1;
    }
}

/// After the field's buffers changed, every [`ProbegiMaterial`] is extracted
/// again (from the main world, as Bevy extracts a changed asset), so its
/// bind group is made again with the new buffers this frame.
fn prepare_materials_again(
    bindings: Option<ResMut<ProbegiQueryBindings>>,
    materials: Extract<Res<Assets<ProbegiMaterial>>>,
    mut extracted: ResMut<ExtractedAssets<MeshMaterial3d<ProbegiMaterial>>>,
) {
    let Some(mut bindings) = bindings else { return };
    if !std::mem::take(&mut bindings.rebound) {
        return;
    }
    for (id, material) in materials.iter() {
        if extracted.added.insert(id) {
            extracted.extracted.push((id, material.clone()));
        }
    }
}
