//! A debug view of the probes, as RTXGI's probe visualisation colours them
//! by state: with [`ProbegiProbeView::enabled`], a small unlit sphere at every
//! probe of the running field, where relocation put it, coloured by its
//! state (seed 004's six under jcgt, seed 003's three under usage, the screen
//! scheme's two):
//! - green: tracing and blending every frame (Active, Vigilant, Alive, Requested);
//! - yellow: just classified or woken (NewlyVigilant, NewlyAwake);
//! - cyan: woken by a moving object (Awake);
//! - blue: asleep or idle (Sleeping, UsageSleeping, Idle);
//! - red: off, inside geometry (Off, Dead).
//!
//! The render world publishes the probes' positions and states after each
//! update (the host's copies: no read-back, no wait); the main world places
//! the spheres ([`ProbeMarker`]) a frame later. The spheres are not part of
//! the field's scene and cast no shadows.

use std::sync::{Arc, Mutex};

use bevy::light::NotShadowCaster;
use bevy::prelude::*;
use bevy::render::extract_resource::{ExtractResource, ExtractResourcePlugin};
use bevy::render::{Render, RenderApp, RenderSystems};
use probegi_core::probe_classification::ProbeState;

use crate::field_on_bevy_device::ProbegiRenderField;

/// Whether the probes are drawn, and how large.
#[derive(Resource, Clone, Debug, PartialEq)]
pub struct ProbegiProbeView {
    /// Draw a sphere at every probe.
    pub enabled: bool,
    /// The spheres' radius, metres.
    pub radius_m: f32,
}

impl Default for ProbegiProbeView {
    fn default() -> Self {
        Self { enabled: false, radius_m: 0.05 }
    }
}

impl ExtractResource<RenderApp> for ProbegiProbeView {
    type Source = Self;

    fn extract_resource(source: &Self) -> Self {
        source.clone()
    }
}

/// A probe's sphere (never traced by the field).
#[derive(Component, Clone, Copy, Debug)]
pub struct ProbeMarker;

/// The probes as the render world last published them: position and state.
#[derive(Resource, Clone, Default)]
struct ProbeSnapshot(Arc<Mutex<Vec<(Vec3, ProbeState)>>>);

/// The spheres' mesh and one unlit material per colour.
struct MarkerAssets {
    mesh: Handle<Mesh>,
    colours: [Handle<StandardMaterial>; 5],
}

/// The colour index of a state (module docs).
fn colour(state: ProbeState) -> usize {
    match state {
        ProbeState::Active | ProbeState::Vigilant | ProbeState::Alive | ProbeState::Requested => 0,
        ProbeState::NewlyVigilant | ProbeState::NewlyAwake => 1,
        ProbeState::Awake => 2,
        ProbeState::Sleeping | ProbeState::UsageSleeping | ProbeState::Idle => 3,
        ProbeState::Off | ProbeState::Dead => 4,
    }
}

/// The view's resource and systems in both worlds.
pub(crate) fn build(app: &mut App) {
    let snapshot = ProbeSnapshot::default();
    app.init_resource::<ProbegiProbeView>().insert_resource(snapshot.clone()).add_systems(Update, place_markers);
    if app.get_sub_app(RenderApp).is_none() {
        return;
    }
    app.add_plugins(ExtractResourcePlugin::<ProbegiProbeView>::default());
    let Some(render_app) = app.get_sub_app_mut(RenderApp) else { return };
    render_app.insert_resource(snapshot).add_systems(
        Render,
        publish_probes.in_set(RenderSystems::PrepareResources).after(crate::field_on_bevy_device::update_field),
    );
}

/// The running field's probes, where the view is on.
fn publish_probes(view: Option<Res<ProbegiProbeView>>, field: Res<ProbegiRenderField>, snapshot: Res<ProbeSnapshot>) {
    if !view.is_some_and(|v| v.enabled) {
        return;
    }
    let probes = field
        .field
        .iter()
        .flat_map(|f| f.set.volumes())
        .flat_map(|v| v.probe_positions.iter().zip(&v.probe_states))
        .map(|(p, s)| (Vec3::from_array(p.to_array()), *s))
        .collect();
    if let Ok(mut held) = snapshot.0.lock() {
        *held = probes;
    }
}

/// One sphere a probe, placed and coloured; none with the view off.
fn place_markers(
    mut commands: Commands,
    view: Res<ProbegiProbeView>,
    snapshot: Res<ProbeSnapshot>,
    mut markers: Query<(Entity, &mut Transform, &mut MeshMaterial3d<StandardMaterial>), With<ProbeMarker>>,
    mut assets: Local<Option<MarkerAssets>>,
    mut meshes: ResMut<Assets<Mesh>>,
    mut materials: ResMut<Assets<StandardMaterial>>,
) {
    let probes = match (view.enabled, snapshot.0.lock()) {
        (true, Ok(held)) => held.clone(),
        _ => Vec::new(),
    };
    let assets = assets.get_or_insert_with(|| {
        let unlit = |c: Color| StandardMaterial { base_color: c, unlit: true, ..default() };
        let colours = [
            Color::srgb(0.1, 0.9, 0.2),
            Color::srgb(0.95, 0.85, 0.1),
            Color::srgb(0.1, 0.9, 0.9),
            Color::srgb(0.2, 0.35, 1.0),
            Color::srgb(0.95, 0.1, 0.1),
        ];
        MarkerAssets { mesh: meshes.add(Sphere::new(1.0)), colours: colours.map(|c| materials.add(unlit(c))) }
    });
    let mut existing = markers.iter_mut();
    for (position, state) in &probes {
        let at = Transform::from_translation(*position).with_scale(Vec3::splat(view.radius_m));
        let material = assets.colours[colour(*state)].clone();
        match existing.next() {
            Some((_, mut t, mut m)) => {
                t.set_if_neq(at);
                if m.0 != material {
                    m.0 = material;
                }
            }
            None => {
                commands.spawn((
                    ProbeMarker,
                    Mesh3d(assets.mesh.clone()),
                    MeshMaterial3d(material),
                    at,
                    NotShadowCaster,
                ));
            }
        }
    }
    for (extra, ..) in existing {
        commands.entity(extra).despawn();
    }
}
