//! probegi's dynamic diffuse global illumination (DDGI, seed 000) for Bevy
//! 0.20, on any wgpu adapter: no ray-tracing hardware needed.
//!
//! This first version of the plugin builds the field from Bevy's world and
//! updates it on Bevy's own device:
//! - [`ProbegiPlugin`] keeps a probegi [`Scene`] from the ECS in the
//!   [`ProbegiScene`] resource ([`scene_extract`]: meshes, `StandardMaterial`s,
//!   textures, point, spot and directional lights, in Bevy's own units:
//!   [`light_units`]): the geometry rebuilt in a frame where a mesh, material
//!   or texture changed, the lights read again where a light did, with the
//!   DDGI volumes that [`ProbegiVolume`] entities place, or the camera-centred
//!   cascades of a [`ProbegiCascades`] entity. Extraction errors (a
//!   mesh Bevy no longer holds in the main world, a texture format the field
//!   cannot read) name the entity, are kept in [`ProbegiScene::error`] and are
//!   logged once each;
//! - with Bevy's renderer, the render world updates the field every frame on
//!   Bevy's `RenderDevice` and `RenderQueue` ([`field_on_bevy_device`]): one
//!   submission a frame, no wait after the start-up, the atlases kept there
//!   ([`field_on_bevy_device::ProbegiRenderField`]). Moving lights and a
//!   volume's live settings change the running field; other changes make it
//!   again.
//!
//! - [`ProbegiMaterial`] (`StandardMaterial` extended by [`ProbegiLit`]) is
//!   Bevy's PBR with its diffuse indirect light taken from the field
//!   ([`field_lighting`]);
//! - meshes that move are moving objects, posed on the device each frame
//!   ([`ProbegiDynamic`]);
//! - the camera's `Skybox` or `EnvironmentMapLight` is the field's sky
//!   ([`environment_sky`]), else its clear colour ([`ProbegiSky`]);
//! - [`ProbegiProbeView`] draws the probes coloured by state ([`probe_debug`]).
//!
//! Add the plugin after `DefaultPlugins` (its material needs Bevy's render
//! app). crates/probegi-bevy/README.md lists what is not built yet.

pub mod environment_sky;
pub mod field_lighting;
pub mod field_on_bevy_device;
pub mod light_units;
pub mod probe_debug;
pub mod scene_extract;

use std::collections::HashSet;
use std::sync::Arc;

use bevy::asset::{Asset, AssetEvent, AssetId, UntypedAssetId};
use bevy::prelude::*;
use probegi_core::ddgi_settings::{DdgiFieldSetSettings, DdgiVolumeSettings, VolumeBlending};
use probegi_scene::{LightKind, PunctualLight, Scene};

pub use field_lighting::{ProbegiLit, ProbegiMaterial};
pub use probe_debug::ProbegiProbeView;
pub use scene_extract::{ExtractError, MeshEntity, SceneBuilder};

/// probegi's DDGI for Bevy: add it to an `App` beside Bevy's PBR plugins.
#[derive(Default)]
pub struct ProbegiPlugin {
    /// The constant sky that rays leaving the scene read where the camera
    /// has no `Skybox` or `EnvironmentMapLight` ([`ProbegiScene::sky`]
    /// changes it as the field runs). By default the camera's clear colour.
    pub sky: ProbegiSky,
    /// The seed of the field's random streams (ray rotations, shading).
    pub seed: u64,
}

/// Where the field's constant sky comes from (a camera's `Skybox` or
/// `EnvironmentMapLight`, where it has one, is the sky instead: see
/// [`environment_sky`]).
#[derive(Clone, Copy, Debug, Default, PartialEq)]
pub enum ProbegiSky {
    /// The clear colour of the first active 3D camera (by `Camera::order`,
    /// then entity): its `ClearColorConfig::Custom`, else the `ClearColor`
    /// resource (Bevy's default where there is none), read as the luminance
    /// its exposure would draw so ([`light_units::clear_color_luminance`]);
    /// black for a camera that clears to nothing. Without a 3D camera, the
    /// `ClearColor` resource through Bevy's default exposure.
    #[default]
    ClearColor,
    /// This radiance, in Bevy's luminance units (cd·m⁻²), linear RGB.
    Radiance(Vec3),
}

impl Plugin for ProbegiPlugin {
    fn build(&self, app: &mut App) {
        app.insert_resource(ProbegiScene { sky: self.sky, seed: self.seed, ..default() }).add_systems(
            PostUpdate,
            extract_scene
                .after(bevy::transform::TransformSystems::Propagate)
                .after(bevy::camera::visibility::VisibilitySystems::VisibilityPropagate),
        );
        field_lighting::build(app);
        probe_debug::build(app);
    }

    /// The render world's part, once every plugin is in (`RenderPlugin`
    /// makes the render app; without it only the main-world scene is kept).
    fn finish(&self, app: &mut App) {
        field_on_bevy_device::build(app);
    }
}

/// A DDGI volume: probes over the entity's box, the unit cube centred on its
/// `GlobalTransform`'s translation and scaled by its scale (its rotation is
/// not used: probe grids are axis-aligned), with `settings` (the papers'
/// defaults unless changed; `probe_counts` sets the grid). Moving the entity,
/// or changing a setting that sizes the field, makes the field again; the
/// live settings ([`field_on_bevy_device::LIVE_SETTINGS`]) change it as it runs.
#[derive(Component, Clone, Debug, Default)]
#[require(Transform)]
pub struct ProbegiVolume {
    /// The volume's settings (`DdgiVolumeSettings::default()`: the papers').
    pub settings: DdgiVolumeSettings,
}

/// Camera-centred DDGI cascades (seed 003 §6.2): on the camera (or any entity
/// whose `GlobalTransform` the cascades should follow), `count` nested
/// tracking windows, each `settings.probe_counts` probes, the innermost
/// spaced so that the outermost is the scene bounds' fitted grid and each
/// next one `ratio` × coarser, every window held inside the scene bounds; as
/// `probegi render --cascades N` makes them. Moving the entity scrolls the
/// windows (the field keeps running). Where an entity has this, it is the
/// field, and [`ProbegiVolume`]s are not used. The cascades keep seed 004's
/// (jcgt) probe states: the screen scheme that `probegi render` gives
/// cascades needs its camera frame's probe requests, which a Bevy frame does
/// not make yet.
#[derive(Component, Clone, Debug)]
#[require(Transform)]
pub struct ProbegiCascades {
    /// Cascades (`probegi render --cascades`), held to 1 to 16.
    pub count: u32,
    /// Spacing ratio between neighbouring cascades (`--cascade-ratio`), held to 1 to 16.
    pub ratio: f32,
    /// Every cascade's settings (`probe_counts`: 16×8×16 by default).
    pub settings: DdgiVolumeSettings,
}

impl Default for ProbegiCascades {
    fn default() -> Self {
        Self {
            count: 3,
            ratio: probegi_core::ddgi_settings::DEFAULT_CASCADE_SPACING_RATIO,
            settings: DdgiVolumeSettings {
                probe_counts: probegi_core::ddgi_settings::DEFAULT_CASCADE_PROBE_COUNTS,
                ..default()
            },
        }
    }
}

impl ProbegiCascades {
    /// The cascades' volume settings over a scene of `bounds`, as `probegi
    /// render --cascades` makes them (`DdgiFieldSetSettings::cascades_over_bounds`).
    pub fn volumes(&self, bounds: (glam::Vec3, glam::Vec3)) -> DdgiFieldSetSettings {
        // `probegi render` refuses other values; a component is held to them.
        let n = self.count.clamp(1, 16);
        let ratio = if self.ratio.is_finite() {
            self.ratio.clamp(1.0, 16.0)
        } else {
            probegi_core::ddgi_settings::DEFAULT_CASCADE_SPACING_RATIO
        };
        DdgiFieldSetSettings::cascades_over_bounds(n, &self.settings, bounds, ratio)
    }
}

/// A mesh that moves: traced from its first frame as a moving object
/// (probegi's top level: its own BLAS, placed every frame by a TLAS
/// instance), so moving it never makes the geometry again. Without it, a
/// mesh that moves is made a moving object at its first move, which makes
/// the geometry (and the field) again once.
#[derive(Component, Clone, Copy, Debug, Default)]
pub struct ProbegiDynamic;

/// The probegi world the plugin keeps from the ECS.
#[derive(Resource, Default)]
pub struct ProbegiScene {
    /// The scene's geometry: world-space static triangles, materials and
    /// textures (its `lights` are empty: see [`Self::lights`]).
    pub scene: Arc<Scene>,
    /// The punctual lights, read again whenever a light changes.
    pub lights: Vec<PunctualLight>,
    /// The volumes' settings, each with `volume_bounds_m` from its entity's
    /// box, or the [`ProbegiCascades`]' windows.
    pub volumes: Vec<DdgiVolumeSettings>,
    /// How the volumes are sampled (cascades or the density rule).
    pub blending: VolumeBlending,
    /// Where the tracking windows (the cascades) are centred now: the
    /// [`ProbegiCascades`] entity's position.
    pub tracking_target: Option<glam::Vec3>,
    /// Updates so far: it changes when anything here changes.
    pub generation: u64,
    /// Geometry rebuilds so far: it changes when `scene` does.
    pub geometry_generation: u64,
    /// Why the last rebuild failed, if it did (the scene is then the last good one).
    pub error: Option<ExtractError>,
    /// Where the constant sky comes from ([`ProbegiPlugin::sky`]): change it
    /// here as the field runs.
    pub sky: ProbegiSky,
    /// The constant sky radiance the field reads now (cd·m⁻², linear RGB),
    /// from [`Self::sky`]; a change is posed on the device, as a light's is.
    pub sky_radiance: Vec3,
    /// The field's seed ([`ProbegiPlugin::seed`]).
    pub seed: u64,
    /// The moving objects' entities, in `scene.objects` order: the
    /// [`ProbegiDynamic`] meshes, and each mesh that moved after the geometry
    /// was built with it (made again once, with it as an object).
    pub moving: Vec<Entity>,
    /// Each moving object's transform from its rest pose (as `scene` holds
    /// it) to where its entity is now; posed on the device each frame
    /// without making the geometry again.
    pub object_poses: Vec<glam::Mat4>,
    /// The moving objects' transforms when the geometry was built.
    rest: Vec<glam::Mat4>,
    /// The mesh entities in the geometry.
    known: HashSet<Entity>,
    /// Meshes that moved after they were built still: moving from then on.
    promoted: HashSet<Entity>,
    /// The camera's sky as the field's ([`environment_sky`]): its `Skybox`,
    /// else its `EnvironmentMapLight`; `None`: the constant `sky_radiance`.
    pub sky_map: Option<probegi_scene::SkyMap>,
    /// Sky maps made so far: it changes when `sky_map` is made again (a new
    /// cubemap or rotation; a new brightness only sets its intensity).
    pub sky_generation: u64,
    /// The cubemap and rotation `sky_map` was made from.
    sky_key: Option<(AssetId<Image>, [f32; 4])>,
    /// Where `sky_map` is a placeholder the device fills
    /// ([`environment_sky::device_sky_placeholder`]): the cubemap the render
    /// world reads each frame and its rotation.
    pub sky_on_device: Option<(AssetId<Image>, Quat)>,
    /// The camera exposure the emissives were read through
    /// (`light_units::emissive_luminance`).
    camera_exposure: f32,
    /// Why the camera's sky could not be the field's, if it could not (the
    /// constant sky stands in).
    pub sky_error: Option<ExtractError>,
    /// Moving objects whose pose could not be a key (warned about once).
    unkeyed: HashSet<Entity>,
}

type MeshQuery<'w, 's> = Query<
    'w,
    's,
    (
        Entity,
        Option<&'static Name>,
        &'static Mesh3d,
        &'static GlobalTransform,
        Option<&'static MeshMaterial3d<StandardMaterial>>,
        Option<&'static MeshMaterial3d<ProbegiMaterial>>,
        Has<ProbegiDynamic>,
        Option<&'static InheritedVisibility>,
    ),
    Without<probe_debug::ProbeMarker>,
>;

/// A mesh entity's geometry or material changed.
/// (A moved mesh is sorted out apart: a moving object is posed, a still one
/// makes the geometry again and moves as an object from then on.)
type GeometryChanged = (
    With<Mesh3d>,
    Without<probe_debug::ProbeMarker>,
    Or<(
        Added<ProbegiDynamic>,
        Changed<InheritedVisibility>,
        Changed<Mesh3d>,
        Changed<MeshMaterial3d<StandardMaterial>>,
        Changed<MeshMaterial3d<ProbegiMaterial>>,
    )>,
);

/// A mesh entity (not a probe view's sphere) moved.
type MeshMoved = (With<Mesh3d>, Without<probe_debug::ProbeMarker>, Changed<GlobalTransform>);

/// A light or a volume changed (or moved).
type LightOrVolumeChanged = (
    Or<(With<PointLight>, With<SpotLight>, With<DirectionalLight>, With<ProbegiVolume>, With<ProbegiCascades>)>,
    Or<(
        Changed<GlobalTransform>,
        Changed<PointLight>,
        Changed<SpotLight>,
        Changed<DirectionalLight>,
        Changed<ProbegiVolume>,
        Changed<ProbegiCascades>,
    )>,
);

/// What changed since the last run: the geometry (meshes, materials,
/// textures), or only lights and volumes.
#[derive(bevy::ecs::system::SystemParam)]
struct SceneChanges<'w, 's> {
    geometry: Query<'w, 's, (), GeometryChanged>,
    moved: Query<'w, 's, Entity, MeshMoved>,
    lights_or_volumes: Query<'w, 's, (), LightOrVolumeChanged>,
    removed_meshes: RemovedComponents<'w, 's, Mesh3d>,
    removed_materials: RemovedComponents<'w, 's, MeshMaterial3d<StandardMaterial>>,
    removed_lit_materials: RemovedComponents<'w, 's, MeshMaterial3d<ProbegiMaterial>>,
    removed_lights: RemovedComponents<'w, 's, PointLight>,
    removed_spots: RemovedComponents<'w, 's, SpotLight>,
    removed_suns: RemovedComponents<'w, 's, DirectionalLight>,
    removed_volumes: RemovedComponents<'w, 's, ProbegiVolume>,
    removed_cascades: RemovedComponents<'w, 's, ProbegiCascades>,
    mesh_events: MessageReader<'w, 's, AssetEvent<Mesh>>,
    material_events: MessageReader<'w, 's, AssetEvent<StandardMaterial>>,
    lit_material_events: MessageReader<'w, 's, AssetEvent<ProbegiMaterial>>,
    image_events: MessageReader<'w, 's, AssetEvent<Image>>,
}

/// The asset an event is about, unless it only says the asset went unused.
fn event_asset<A: Asset>(e: &AssetEvent<A>) -> Option<AssetId<A>> {
    match *e {
        AssetEvent::Added { id }
        | AssetEvent::Modified { id }
        | AssetEvent::Removed { id }
        | AssetEvent::LoadedWithDependencies { id } => Some(id),
        AssetEvent::Unused { .. } => None,
    }
}

impl SceneChanges<'_, '_> {
    /// (the geometry changed, a light or volume changed, the images that
    /// changed). Every reader is drained, so each change counts once. Asset events count only for the
    /// meshes, materials and textures that mesh entities use: a UI texture
    /// or a material nobody draws does not make the field again.
    fn read(
        &mut self,
        meshes_q: &MeshQuery,
        assets: &MeshAssets,
        known: &HashSet<Entity>,
    ) -> (bool, bool, Vec<AssetId<Image>>) {
        let meshes: Vec<AssetId<Mesh>> = self.mesh_events.read().filter_map(event_asset).collect();
        let mut materials: Vec<UntypedAssetId> =
            self.material_events.read().filter_map(event_asset).map(Into::into).collect();
        materials.extend(self.lit_material_events.read().filter_map(event_asset).map(UntypedAssetId::from));
        let images: Vec<AssetId<Image>> = self.image_events.read().filter_map(event_asset).collect();
        let used = |(_, _, m, _, plain, lit, ..): MeshItem| {
            let material = standard_material(plain, lit, assets);
            let textures = material
                .map(|(_, m)| m)
                .into_iter()
                .flat_map(|m| [&m.base_color_texture, &m.emissive_texture].into_iter().flatten().map(|h| h.id()));
            meshes.contains(&m.0.id())
                || material.is_some_and(|(id, _)| materials.contains(&id))
                || textures.into_iter().any(|t| images.contains(&t))
        };
        let asset_changed =
            !(meshes.is_empty() && materials.is_empty() && images.is_empty()) && meshes_q.iter().any(used);
        // Only what the geometry holds (the probe view's spheres come and go).
        let removed_materials = self.removed_materials.read().filter(|e| known.contains(e)).count()
            + self.removed_lit_materials.read().filter(|e| known.contains(e)).count();
        let removed_meshes = self.removed_meshes.read().filter(|e| known.contains(e)).count();
        let geometry = [removed_meshes, removed_materials, asset_changed as usize];
        let others = [
            self.removed_lights.read().count(),
            self.removed_spots.read().count(),
            self.removed_suns.read().count(),
            self.removed_volumes.read().count(),
            self.removed_cascades.read().count(),
        ];
        (
            !self.geometry.is_empty() || geometry.iter().any(|n| *n > 0),
            !self.lights_or_volumes.is_empty() || others.iter().any(|n| *n > 0),
            images,
        )
    }
}

/// Lights of the three kinds Bevy has, with their transforms.
#[derive(bevy::ecs::system::SystemParam)]
struct Lights<'w, 's> {
    points: Query<'w, 's, (Entity, &'static GlobalTransform, &'static PointLight)>,
    spots: Query<'w, 's, (Entity, &'static GlobalTransform, &'static SpotLight)>,
    suns: Query<'w, 's, (Entity, &'static GlobalTransform, &'static DirectionalLight)>,
}

/// The mesh assets a rebuild reads.
#[derive(bevy::ecs::system::SystemParam)]
struct MeshAssets<'w> {
    meshes: Res<'w, Assets<Mesh>>,
    materials: Res<'w, Assets<StandardMaterial>>,
    lit_materials: Res<'w, Assets<ProbegiMaterial>>,
    images: Res<'w, Assets<Image>>,
}

type MeshItem<'a> = (
    Entity,
    Option<&'a Name>,
    &'a Mesh3d,
    &'a GlobalTransform,
    Option<&'a MeshMaterial3d<StandardMaterial>>,
    Option<&'a MeshMaterial3d<ProbegiMaterial>>,
    bool,
    Option<&'a InheritedVisibility>,
);

/// A mesh entity's `StandardMaterial` with its asset's id: its own, else
/// its [`ProbegiMaterial`]'s base (`None` while the asset is loading).
fn standard_material<'a>(
    plain: Option<&MeshMaterial3d<StandardMaterial>>,
    lit: Option<&MeshMaterial3d<ProbegiMaterial>>,
    assets: &'a MeshAssets,
) -> Option<(UntypedAssetId, &'a StandardMaterial)> {
    match (plain, lit) {
        (Some(h), _) => assets.materials.get(&h.0).map(|m| (h.0.id().untyped(), m)),
        (None, Some(h)) => assets.lit_materials.get(&h.0).map(|m| (h.0.id().untyped(), &m.base)),
        (None, None) => None,
    }
}

/// Keeps [`ProbegiScene`] up to date: the geometry rebuilt when it changed,
/// the moving objects' poses and the lights and volumes read again when
/// they did.
fn extract_scene(
    mut changes: SceneChanges,
    meshes_q: MeshQuery,
    lights: Lights,
    volumes: Volumes,
    assets: MeshAssets,
    mut skies: Skies,
    mut out: ResMut<ProbegiScene>,
) {
    let first = out.generation == 0;
    let (mut geometry, others, images_changed) = changes.read(&meshes_q, &assets, &out.known);
    let (sky_changed, sky_image_changed) = skies.changed(&images_changed);
    // Display-weighted emissives (and the clear colour) read through the camera's exposure.
    let exposure = skies.camera_exposure();
    let sky_radiance = match out.sky {
        ProbegiSky::Radiance(l) => l,
        ProbegiSky::ClearColor => skies.clear_color_radiance(),
    };
    // Written only when it changed: the resource stays unchanged in a still frame.
    let constant_sky_changed = sky_radiance != out.sky_radiance;
    if constant_sky_changed {
        out.sky_radiance = sky_radiance;
    }
    if exposure != out.camera_exposure && out.scene.materials.iter().any(|m| m.emissive_factor != glam::Vec3::ZERO) {
        geometry = true;
    }
    let mut moved = false;
    for e in changes.moved.iter() {
        if out.moving.contains(&e) {
            moved = true;
        } else if out.known.contains(&e) {
            // A still mesh that moved: a moving object from now on.
            geometry = true;
            out.promoted.insert(e);
        }
        // Otherwise the geometry does not hold it (new, hidden, or its mesh
        // still loading): its arrival, showing or loading makes it again.
    }
    if !(first || geometry || others || moved || sky_changed || constant_sky_changed) {
        return;
    }
    if moved && !(first || geometry) {
        match object_poses(&mut out, &meshes_q) {
            Some(poses) => out.object_poses = poses,
            None => geometry = true,
        }
    }
    if first || geometry {
        out.camera_exposure = exposure;
        rebuild_geometry(&meshes_q, &assets, &mut out);
    }
    if first || sky_changed {
        skies.update(&assets.images, sky_image_changed, &mut out);
    }
    out.lights = punctual_lights(&lights);
    let bounds = out.scene.bounds();
    (out.volumes, out.blending, out.tracking_target) = volumes.settings(bounds);
    out.generation += 1;
}

/// Builds the geometry again into `out` (the last good one stays on an error).
fn rebuild_geometry(meshes_q: &MeshQuery, assets: &MeshAssets, out: &mut ProbegiScene) {
    match build_geometry(meshes_q, assets, vec3(out.sky_radiance), out.camera_exposure, &out.promoted) {
        Ok(built) => {
            out.object_poses = vec![glam::Mat4::IDENTITY; built.moving.len()];
            out.scene = Arc::new(built.scene);
            (out.moving, out.rest, out.known) = (built.moving, built.rest, built.known);
            // Despawned (or no longer drawn) entities leave the moving set.
            let known = &out.known;
            out.promoted.retain(|e| known.contains(e));
            out.unkeyed.retain(|e| known.contains(e));
            out.geometry_generation += 1;
            out.error = None;
        }
        Err(e) => {
            if out.error.as_ref() != Some(&e) {
                error!("{e}");
            }
            out.error = Some(e);
        }
    }
}

/// Each moving object's transform from its rest pose to now; `None` where
/// one is gone or cannot be a key (`scene_extract::moving_key`).
fn object_poses(out: &mut ProbegiScene, meshes_q: &MeshQuery) -> Option<Vec<glam::Mat4>> {
    let mut poses = Vec::with_capacity(out.moving.len());
    for (e, rest) in out.moving.iter().zip(&out.rest) {
        let (_, _, _, t, ..) = meshes_q.get(*e).ok()?;
        let pose = world_from_local(t) * rest.inverse();
        if scene_extract::moving_key(pose).is_none() {
            if out.unkeyed.insert(*e) {
                warn!(
                    "probegi-bevy: {e} moved by more than a translation, rotation and positive scale from \
                     where the geometry was built (a changing non-uniform scale, a shear, a zero scale): \
                     the geometry, and the field, are made again each such frame"
                );
            }
            return None;
        }
        poses.push(pose);
    }
    Some(poses)
}

/// A `GlobalTransform` as probegi's matrix.
fn world_from_local(t: &GlobalTransform) -> glam::Mat4 {
    glam::Mat4::from_cols_array(&t.to_matrix().to_cols_array())
}

/// The geometry and what the moving objects were built from.
struct BuiltGeometry {
    scene: Scene,
    /// The moving objects' entities, in `scene.objects` order.
    moving: Vec<Entity>,
    /// Their transforms as built (their rest poses).
    rest: Vec<glam::Mat4>,
    /// Every mesh entity in it.
    known: HashSet<Entity>,
}

/// Every mesh entity's triangles and materials (no lights): the
/// [`ProbegiDynamic`] ones and those in `promoted` as moving objects.
fn build_geometry(
    meshes_q: &MeshQuery,
    assets: &MeshAssets,
    sky: glam::Vec3,
    camera_exposure: f32,
    promoted: &HashSet<Entity>,
) -> Result<BuiltGeometry, ExtractError> {
    let mut builder = SceneBuilder::new("bevy world", sky).with_camera_exposure(camera_exposure);
    let (mut moving, mut rest, mut known) = (vec![], vec![], HashSet::new());
    for (entity, name, mesh, transform, plain, lit, dynamic, visible) in meshes_q.iter() {
        if visible.is_some_and(|v| !v.get()) {
            continue; // hidden: Bevy does not draw it, the field does not see it
        }
        let name = name.map_or_else(|| format!("{entity}"), |n| n.as_str().to_owned());
        let Some(mesh) = assets.meshes.get(&mesh.0) else { continue }; // still loading
        let material = standard_material(plain, lit, assets);
        let world_from_local = world_from_local(transform);
        let entity_mesh = MeshEntity { name, mesh, world_from_local, material };
        if dynamic || promoted.contains(&entity) {
            builder.add_moving_mesh(&entity_mesh, &assets.images)?;
            moving.push(entity);
            rest.push(world_from_local);
        } else {
            builder.add_mesh(&entity_mesh, &assets.images)?;
        }
        known.insert(entity);
    }
    Ok(BuiltGeometry { scene: builder.finish(), moving, rest, known })
}

/// A camera and the sky components it may carry.
type CameraSky = (Entity, Option<&'static bevy::light::Skybox>, Option<&'static bevy::light::EnvironmentMapLight>);

/// A camera's sky component changed.
type SkyChanged = Or<(Changed<bevy::light::Skybox>, Changed<bevy::light::EnvironmentMapLight>)>;

/// The cameras whose sky the field takes ([`environment_sky`]).
#[derive(bevy::ecs::system::SystemParam)]
struct Skies<'w, 's> {
    cameras: Query<'w, 's, CameraSky, With<Camera>>,
    changed: Query<'w, 's, (), (With<Camera>, SkyChanged)>,
    exposures: Query<'w, 's, (Entity, &'static Camera, Option<&'static bevy::camera::Exposure>), With<Camera3d>>,
    clear_color: Option<Res<'w, ClearColor>>,
    removed_skyboxes: RemovedComponents<'w, 's, bevy::light::Skybox>,
    removed_maps: RemovedComponents<'w, 's, bevy::light::EnvironmentMapLight>,
}

/// Where the field's sky comes from: a camera, its cubemap, rotation and
/// brightness (cd·m⁻² per unit texel).
type SkySource = (Entity, Handle<Image>, Quat, f32);

impl Skies<'_, '_> {
    /// The exposure of the first active 3D camera (by `Camera::order`, then
    /// entity), Bevy's default without one: what display-weighted emissives
    /// are read through.
    fn camera_exposure(&self) -> f32 {
        self.first_camera().and_then(|(.., x)| x.copied()).unwrap_or_default().exposure()
    }

    /// The first active 3D camera by `Camera::order`, then entity.
    fn first_camera(&self) -> Option<(Entity, &Camera, Option<&bevy::camera::Exposure>)> {
        self.exposures.iter().filter(|(_, c, _)| c.is_active).min_by_key(|(e, c, _)| (c.order, *e))
    }

    /// [`ProbegiSky::ClearColor`]'s radiance: the first camera's clear
    /// colour through its exposure (`light_units::clear_color_luminance`).
    fn clear_color_radiance(&self) -> Vec3 {
        let resource = self.clear_color.as_deref().cloned().unwrap_or_default().0;
        let clear = match self.first_camera().map(|(_, c, _)| &c.clear_color) {
            Some(bevy::camera::ClearColorConfig::Custom(c)) => *c,
            Some(bevy::camera::ClearColorConfig::None) => return Vec3::ZERO,
            Some(bevy::camera::ClearColorConfig::Default) | None => resource,
        };
        let luminance = light_units::clear_color_luminance(linear_rgb(clear), self.camera_exposure());
        Vec3::from_array(luminance.to_array())
    }

    /// The first camera's (in entity order) `Skybox` with an image, else its
    /// `EnvironmentMapLight`.
    fn source(&self) -> Option<SkySource> {
        let mut cameras: Vec<_> = self.cameras.iter().collect();
        cameras.sort_by_key(|(e, ..)| *e);
        cameras.into_iter().find_map(|(e, skybox, map)| match (skybox.and_then(|s| s.image.clone()), map) {
            (Some(image), _) => skybox.map(|s| (e, image, s.rotation, s.brightness)),
            (None, Some(m)) => Some((e, m.specular_map.clone(), m.rotation, m.intensity)),
            (None, None) => None,
        })
    }

    /// (whether the sky may have changed: a camera's sky component or the
    /// sky's image; whether that image did), `images` those that changed.
    fn changed(&mut self, images: &[AssetId<Image>]) -> (bool, bool) {
        let removed = self.removed_skyboxes.read().count() + self.removed_maps.read().count();
        let image = self.source().is_some_and(|(_, h, ..)| images.contains(&h.id()));
        (!self.changed.is_empty() || removed > 0 || image, image)
    }

    /// The sky map made again where its cubemap (another, or its texels,
    /// `image_changed`) or rotation changed (an error names the camera, is
    /// logged once and kept in `sky_error`; the constant sky then stands in),
    /// else its intensity set.
    fn update(&self, images: &Assets<Image>, image_changed: bool, out: &mut ProbegiScene) {
        let source = self.source();
        let has_source = source.is_some();
        let key = source.as_ref().map(|(_, h, r, _)| (h.id(), r.to_array()));
        if key.is_some() && key == out.sky_key && !image_changed {
            if let (Some(map), Some((.., brightness))) = (out.sky_map.as_mut(), source) {
                map.intensity = brightness;
            }
            return;
        }
        out.sky_on_device = None;
        let made = source.and_then(|(e, handle, rotation, brightness)| {
            let image = images.get(&handle)?; // still loading: the constant sky meanwhile
            let name = format!("{e}'s sky");
            // A cubemap the host cannot read is made into the map on the device.
            let map = if environment_sky::host_reads(image) {
                environment_sky::equirect_from_cubemap(image, rotation, &name)
            } else {
                let placeholder = environment_sky::device_sky_placeholder(image, &name);
                if placeholder.is_ok() {
                    out.sky_on_device = Some((handle.id(), rotation));
                }
                placeholder
            };
            match map {
                Ok(map) => {
                    Some(probegi_scene::SkyMap { intensity: brightness, ..probegi_scene::SkyMap::new(Arc::new(map)) })
                }
                Err(what) => {
                    let e = ExtractError { entity: format!("{e}"), what };
                    if out.sky_error.as_ref() != Some(&e) {
                        error!("{e}");
                    }
                    out.sky_error = Some(e);
                    None
                }
            }
        });
        if made.is_some() || !has_source {
            out.sky_error = None;
        }
        out.sky_key = made.as_ref().and(key);
        if made.is_some() || out.sky_map.is_some() {
            out.sky_generation += 1;
        }
        out.sky_map = made;
    }
}

/// The entities that place the field's volumes.
#[derive(bevy::ecs::system::SystemParam)]
struct Volumes<'w, 's> {
    boxes: Query<'w, 's, (&'static GlobalTransform, &'static ProbegiVolume)>,
    cascades: Query<'w, 's, (&'static GlobalTransform, &'static ProbegiCascades)>,
}

impl Volumes<'_, '_> {
    /// The volumes' settings, their blending and the tracking target: the
    /// first [`ProbegiCascades`]' (once the scene has bounds), else every
    /// [`ProbegiVolume`]'s.
    fn settings(
        &self,
        bounds: Option<(glam::Vec3, glam::Vec3)>,
    ) -> (Vec<DdgiVolumeSettings>, VolumeBlending, Option<glam::Vec3>) {
        // Bevy samples no sky map at its pixels: the field carries the map's
        // light (`probe_sky_map_on_miss`; a constant sky it carries anyway).
        let on_miss = |v: DdgiVolumeSettings| DdgiVolumeSettings { probe_sky_map_on_miss: true, ..v };
        if let Some((t, c)) = self.cascades.iter().next() {
            let Some(bounds) = bounds else { return (Vec::new(), VolumeBlending::Cascades, None) };
            let set = c.volumes(bounds);
            return (set.volumes.into_iter().map(on_miss).collect(), set.blending, Some(vec3(t.translation())));
        }
        let boxes = self.boxes.iter().map(|(t, v)| on_miss(volume_settings(t, v))).collect();
        (boxes, VolumeBlending::Density, None)
    }
}

/// A volume's settings with its entity's box as `volume_bounds_m`.
fn volume_settings(transform: &GlobalTransform, volume: &ProbegiVolume) -> DdgiVolumeSettings {
    let (scale, _, centre) = transform.to_scale_rotation_translation();
    let (c, half) = (vec3(centre), vec3(scale.abs()) * 0.5);
    DdgiVolumeSettings { volume_bounds_m: Some([c - half, c + half]), ..volume.settings.clone() }
}

/// Bevy's vector as probegi's (Bevy 0.20 is on another glam).
fn vec3(v: bevy::math::Vec3) -> glam::Vec3 {
    glam::Vec3::from_array(v.to_array())
}

fn linear_rgb(c: Color) -> glam::Vec3 {
    let l = c.to_linear();
    glam::Vec3::new(l.red, l.green, l.blue)
}

/// The ECS's lights as probegi's (units: [`light_units`]), in entity order:
/// the order stays when an entity changes archetype, so the field's scene
/// change detector, which pairs lights by index, sees the same light.
fn punctual_lights(lights: &Lights) -> Vec<PunctualLight> {
    let light = |kind, t: &GlobalTransform, color: Color, intensity: f32| PunctualLight {
        kind,
        position: vec3(t.translation()),
        direction: vec3(t.forward().as_vec3()),
        color: linear_rgb(color),
        intensity,
        range: None,
        inner_cone_angle: 0.0,
        outer_cone_angle: std::f32::consts::FRAC_PI_4,
        keyframes: Vec::new(),
    };
    let points = lights.points.iter().map(|(e, t, p)| {
        let l = light(LightKind::Point, t, p.color, light_units::point_intensity_from_lumens(p.intensity));
        (e, PunctualLight { range: Some(p.range), ..l })
    });
    let spots = lights.spots.iter().map(|(e, t, s)| {
        let l = light(LightKind::Spot, t, s.color, light_units::spot_intensity_from_lumens(s.intensity));
        let (inner_cone_angle, outer_cone_angle) = light_units::spot_cone(s.inner_angle, s.outer_angle);
        (e, PunctualLight { range: Some(s.range), inner_cone_angle, outer_cone_angle, ..l })
    });
    let suns = lights.suns.iter().map(|(e, t, d)| {
        (e, light(LightKind::Directional, t, d.color, light_units::directional_irradiance_from_lux(d.illuminance)))
    });
    let mut all: Vec<(Entity, PunctualLight)> = points.chain(spots).chain(suns).collect();
    all.sort_by_key(|(e, _)| *e);
    all.into_iter().map(|(_, l)| l).collect()
}
