//! The WGSL query (`ddgi_query.wgsl`, the file engines include) against the CPU's
//! (`probegi_core::ddgi_volume_blend::field_set_irradiance`) on fields the CPU
//! backend converged: the Cornell box with probe states and relocation, three
//! camera-centred cascades whose windows have scrolled (circular buffers), two
//! hand-placed volumes under density blending, and a field whose cages hold no
//! usable probe (the fallback table). 20 000 random surface points each (half on
//! the walls, half anywhere, random normals). The GPU evaluates the same
//! operations in the same order; sqrt, length and normalize may round differently
//! in the last bit, so the bound is 1e-4 relative to the field's largest value.

mod common;

use probegi_cpu::field_update::FieldSetUpdate;
use std::collections::BTreeMap;

use glam::{UVec3, Vec3};
use probegi_core::ddgi_query::nearest_usable_probes;
use probegi_core::ddgi_settings::{DdgiFieldSetSettings, DdgiVolumeSettings};
use probegi_core::ddgi_volume_blend::{DdgiFieldSetView, SetMember, VolumeBlending, field_set_irradiance};
use probegi_core::rng::Pcg32;
use probegi_core::sampling::sample_uniform_sphere;
use probegi_cpu::{DirectLighting, DirectSettings};
use probegi_field::ddgi_field_set::DdgiFieldSet;
use probegi_scene::{BvhSettings, BvhTracer, Ray, RayTracer, Scene};
use probegi_wgpu::GpuContext;
use probegi_wgpu::ddgi_query::{GpuDdgiField, GpuFieldQuery, QueryPoint};

fn points(scene: &Scene, tracer: &BvhTracer, n: usize) -> Vec<QueryPoint> {
    let (lo, hi) = scene.bounds().expect("geometry");
    let mut rng = Pcg32::new(3, 9);
    (0..n)
        .map(|k| {
            let p = lo + (hi - lo) * Vec3::new(rng.next_f32(), rng.next_f32(), rng.next_f32());
            let d = sample_uniform_sphere(rng.next_vec2());
            let view = sample_uniform_sphere(rng.next_vec2());
            match tracer.closest_hit(&Ray::new(p, d)) {
                // Surface points with their facing normal, viewed from the ray's origin.
                Some(h) if k % 2 == 0 => {
                    let sp = scene.surface_point(&h);
                    QueryPoint::new(sp.position, sp.facing_normal(), -d)
                }
                _ => QueryPoint::new(p, d, view),
            }
        })
        .collect()
}

fn compare(ctx: &GpuContext, view: &DdgiFieldSetView<'_>, pts: &[QueryPoint]) -> f32 {
    let field = GpuDdgiField::upload(ctx, view).expect("upload");
    let gpu = GpuFieldQuery::new(ctx).query(ctx, &field, pts).expect("query");
    let cpu: Vec<Vec3> = pts
        .iter()
        .map(|q| {
            let v = |a: [f32; 4]| Vec3::new(a[0], a[1], a[2]);
            field_set_irradiance(view, v(q.position), v(q.normal), v(q.view_dir))
        })
        .collect();
    let scale = cpu.iter().fold(0f32, |m, e| m.max(e.max_element())).max(1e-6);
    let worst = cpu.iter().zip(&gpu).map(|(c, g)| (*c - *g).abs().max_element()).fold(0f32, f32::max) / scale;
    let lit = cpu.iter().filter(|e| e.max_element() > 0.0).count();
    eprintln!("{} points ({lit} lit), largest {scale:.3} W/m², worst difference {worst:.2e} of it", pts.len());
    assert!(lit > pts.len() / 2, "too few lit points to test: {lit}");
    assert!(gpu.iter().all(|e| e.is_finite()));
    worst
}

fn converged(
    scene: &Scene,
    tracer: &BvhTracer,
    settings: &DdgiFieldSetSettings,
    camera: Option<Vec3>,
    frames: u32,
) -> DdgiFieldSet {
    let direct = DirectLighting::new(scene, tracer, DirectSettings::default());
    let mut set = DdgiFieldSet::new(settings, scene.bounds().expect("geometry"), camera);
    let mut ms = BTreeMap::new();
    for f in 0..frames {
        if let Some(c) = camera {
            // Walk the camera across the box so the windows scroll.
            set.set_tracking_target(c + Vec3::new(0.08 * f as f32, 0.0, -0.05 * f as f32));
        }
        set.update(scene, tracer, &direct, 11, f, &mut ms);
    }
    set
}

fn small(counts: UVec3, rays: u32) -> DdgiVolumeSettings {
    DdgiVolumeSettings { probe_counts: counts, probe_rays_per_probe: rays, ..Default::default() }
}

#[test]
fn single_volume_with_probe_states_and_relocation() {
    let Some(ctx) = common::context() else { return };
    let scene = probegi_scene::builtin::cornell_box();
    let tracer = BvhTracer::for_scene(&scene, BvhSettings::default());
    let set = converged(&scene, &tracer, &DdgiFieldSetSettings::single(small(UVec3::splat(6), 96)), None, 12);
    let v = &set.volumes()[0];
    assert!(v.probe_offsets.iter().any(|o| *o != Vec3::ZERO), "relocation moved some probes");
    assert!((0..v.grid.probe_count()).any(|p| !v.probe_usable(p)), "some probes are not usable");
    assert!(compare(&ctx, &set.view(), &points(&scene, &tracer, 20_000)) < 1e-4);
}

#[test]
fn scrolled_cascades_and_density_blended_volumes() {
    let Some(ctx) = common::context() else { return };
    let scene = probegi_scene::builtin::cornell_box();
    let tracer = BvhTracer::for_scene(&scene, BvhSettings::default());
    let pts = points(&scene, &tracer, 20_000);
    let cascades = DdgiFieldSetSettings::cascades(3, &small(UVec3::splat(5), 64), Vec3::splat(0.15), 2.0);
    let camera = scene.camera.expect("camera").position;
    let set = converged(&scene, &tracer, &cascades, Some(camera), 10);
    assert!(set.volumes().iter().any(|v| v.grid.probe_scroll_offsets != UVec3::ZERO), "a window scrolled");
    assert!(compare(&ctx, &set.view(), &pts) < 1e-4, "cascades");

    let (lo, hi) = scene.bounds().expect("geometry");
    let mid = (lo + hi) * 0.5;
    let dense = DdgiVolumeSettings {
        volume_bounds_m: Some([lo, Vec3::new(mid.x, hi.y, hi.z)]),
        ..small(UVec3::new(4, 6, 6), 64)
    };
    let density =
        DdgiFieldSetSettings { volumes: vec![small(UVec3::splat(4), 64), dense], blending: VolumeBlending::Density };
    let set = converged(&scene, &tracer, &density, None, 10);
    assert!(compare(&ctx, &set.view(), &pts) < 1e-4, "density");
}

#[test]
fn cages_without_usable_probes_read_the_fallback_probes() {
    let Some(ctx) = common::context() else { return };
    let scene = probegi_scene::builtin::cornell_box();
    let tracer = BvhTracer::for_scene(&scene, BvhSettings::default());
    let set = converged(&scene, &tracer, &DdgiFieldSetSettings::single(small(UVec3::splat(6), 96)), None, 6);
    let v = &set.volumes()[0];
    // Only every 29th probe usable: most cages are empty and take stand-ins.
    let usable: Vec<bool> = (0..v.grid.probe_count()).map(|p| p % 29 == 5).collect();
    let fallback = nearest_usable_probes(&v.grid, &usable);
    let mut field = v.view();
    field.probe_usable = &usable;
    field.probe_fallback = &fallback;
    let view = DdgiFieldSetView {
        members: vec![SetMember { field, volume: 0, tracks_camera: false, occlusion: None }],
        blending: VolumeBlending::Density,
        camera_m: None,
    };
    assert!(compare(&ctx, &view, &points(&scene, &tracer, 20_000)) < 1e-4);
}
