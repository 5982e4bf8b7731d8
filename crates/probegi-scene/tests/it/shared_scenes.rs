//! The loaders on the real scenes in ../shared/scenes (McGuire Computer Graphics
//! Archive). CI has them beside the repository; a missing folder is a failure,
//! not a skip.

use crate::common;

use common::shared;

use std::path::PathBuf;

use glam::Vec3;
use probegi_scene::{BvhSettings, BvhTracer, Ray, RayTracer, load_scene};

#[test]
fn cornell_box_original_obj_matches_the_builtin() {
    let obj = load_scene(&shared("cornell-box/CornellBox-Original.obj")).expect("loads");
    let builtin = load_scene("builtin:cornell-box").expect("loads");
    assert!(obj.warnings.is_empty(), "{:?}", obj.warnings);
    assert_eq!(obj.mesh.triangle_count(), 36);
    assert_eq!(obj.materials.len(), builtin.materials.len());
    for m in &builtin.materials {
        let o = obj.materials.iter().find(|o| o.name == m.name).expect("same material names");
        assert_eq!(o.base_color_factor, m.base_color_factor, "{}", m.name);
        assert_eq!(o.emissive_factor, m.emissive_factor, "{}", m.name);
    }
    assert_eq!(obj.bounds(), builtin.bounds());
    // Same total emitter area, same light orientation (front face down).
    let emitter_area = |s: &probegi_scene::Scene| -> f32 {
        (0..s.mesh.triangle_count())
            .filter(|&t| s.material(s.mesh.triangle_materials[t]).is_emissive())
            .map(|t| s.mesh.area(t))
            .sum()
    };
    assert!((emitter_area(&obj) - emitter_area(&builtin)).abs() < 1e-6);
    // The OBJ has no normals: generated ones are flat because no vertex is shared.
    for t in 0..obj.mesh.triangle_count() {
        let n = obj.mesh.face_normal_scaled(t).normalize();
        for &v in &obj.mesh.triangles[t] {
            assert!(obj.mesh.normals[v as usize].dot(n) > 0.9999);
        }
    }
}

#[test]
fn dabrovic_sponza_loads_with_every_texture_despite_case_mismatches() {
    let s = load_scene(&shared("dabrovic-sponza/sponza.obj")).expect("loads");
    // Counts from the archive's SOURCE.md.
    assert_eq!(s.mesh.triangle_count(), 66450);
    assert!(s.warnings.is_empty(), "{:?}", s.warnings);
    assert!(s.textures.len() >= 10, "{} textures", s.textures.len());
    let textured = s.materials.iter().filter(|m| m.base_color_texture.is_some()).count();
    assert!(textured >= 10, "{textured} textured materials");
    assert!(s.mesh.normals.iter().all(|n| n.is_finite() && (n.length() - 1.0).abs() < 1e-3));
    let (lo, hi) = s.bounds().expect("bounds");
    assert!((hi - lo).max_element() > 20.0, "Sponza is about 30 m long");
}

#[test]
fn sibenik_loads_and_rays_hit_inside() {
    let s = load_scene(&shared("sibenik/sibenik.obj")).expect("loads");
    assert_eq!(s.mesh.triangle_count(), 75284);
    assert!(s.warnings.is_empty(), "{:?}", s.warnings);
    let bvh = BvhTracer::build(&s.mesh, BvhSettings::default());
    // From the middle of the nave, rays along ±x/±z hit walls or columns.
    let (lo, hi) = s.bounds().expect("bounds");
    let c = (lo + hi) * 0.5;
    for d in [Vec3::X, Vec3::NEG_X, Vec3::Z, Vec3::NEG_Z, Vec3::NEG_Y] {
        let hit = bvh.closest_hit(&Ray::new(c, d)).expect("the cathedral is closed on this axis");
        let sp = s.surface_point(&hit);
        assert!((sp.position - (c + d * hit.t)).length() < 1e-3 * (1.0 + hit.t));
    }
}

#[test]
fn scrub_pine_loads() {
    let s = load_scene(&shared("scrub-pine/scrubPine.obj")).expect("loads");
    assert!(s.mesh.triangle_count() > 100);
    assert!(s.warnings.is_empty(), "{:?}", s.warnings);
    assert_eq!(s.textures.len(), 2, "bark and needle textures");
}

#[test]
fn bvh_agrees_with_brute_force_on_sponza() {
    let s = load_scene(&shared("dabrovic-sponza/sponza.obj")).expect("loads");
    let bvh = BvhTracer::build(&s.mesh, BvhSettings::default());
    let (lo, hi) = s.bounds().expect("bounds");
    let mut rng = probegi_core::rng::Pcg32::new(5, 5);
    for _ in 0..64 {
        let o = lo + (hi - lo) * Vec3::new(rng.next_f32(), rng.next_f32(), rng.next_f32());
        let d = probegi_core::sampling::sample_uniform_sphere(rng.next_vec2());
        let ray = Ray::new(o, d);
        let mut best = f32::INFINITY;
        for t in 0..s.mesh.triangle_count() {
            let [a, b, c] = s.mesh.vertices(t);
            // Möller–Trumbore.
            let (e1, e2) = (b - a, c - a);
            let p = d.cross(e2);
            let det = e1.dot(p);
            if det.abs() < 1e-12 {
                continue;
            }
            let inv = 1.0 / det;
            let tv = o - a;
            let u = tv.dot(p) * inv;
            let q = tv.cross(e1);
            let v = d.dot(q) * inv;
            let tt = e2.dot(q) * inv;
            if u >= 0.0 && v >= 0.0 && u + v <= 1.0 && tt > 0.0 {
                best = best.min(tt);
            }
        }
        let got = bvh.closest_hit(&ray).map_or(f32::INFINITY, |h| h.t);
        if best.is_finite() {
            assert!((got - best).abs() <= 1e-3 * best.max(1.0), "bvh {got} brute {best}");
        } else {
            assert!(got.is_infinite());
        }
        assert_eq!(bvh.occluded(&ray), best.is_finite());
    }
}

#[test]
fn the_repository_scene_files_load() {
    for f in ["sponza-sun.toml", "sibenik-lamp.toml"] {
        let p = PathBuf::from(env!("CARGO_MANIFEST_DIR")).join("../../scenes").join(f);
        let s = load_scene(&p.to_string_lossy()).unwrap_or_else(|e| panic!("{f}: {e}"));
        assert!(!s.lights.is_empty() && s.camera.is_some() && s.volume.is_some(), "{f}");
        assert!(s.mesh.triangle_count() > 60_000, "{f}");
    }
}
