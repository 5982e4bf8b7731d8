//! The shadowing field (seed 003 ch. 5) on the CPU: analytic cases (an open
//! floor under a sun sees it, a sealed room does not), and the shadow box of
//! Fig. 7.10, where the field's visibility must follow the exact shadows.

use std::collections::BTreeMap;

use glam::{UVec3, Vec3};
use probegi_core::ddgi_settings::DdgiVolumeSettings;
use probegi_cpu::{DirectLighting, DirectSettings};
use probegi_field::ddgi_field_set::DdgiFieldSet;
use probegi_field::ddgi_volume::DdgiVolume;
use probegi_frame::field_update::FieldSetUpdate;
use probegi_scene::{BvhSettings, BvhTracer, Ray, RayTracer, Scene, load_scene};

/// `scene` (a TOML scene file's text) loaded from a temporary file.
fn scene_from(name: &str, text: &str) -> Scene {
    let dir = std::env::temp_dir().join(format!("probegi-shadow-field-{}", std::process::id()));
    std::fs::create_dir_all(&dir).expect("temp dir");
    let path = dir.join(format!("{name}.toml"));
    std::fs::write(&path, text).expect("write scene");
    load_scene(path.to_str().expect("utf-8 path")).expect("scene loads")
}

/// A set of one volume with a shadow field over `lo..hi`, updated `frames` times.
fn updated_field(scene: &Scene, counts: UVec3, lo: Vec3, hi: Vec3, frames: u32) -> DdgiFieldSet {
    let settings = DdgiVolumeSettings {
        probe_counts: counts,
        probe_rays_per_probe: 64,
        volume_bounds_m: Some([lo, hi]),
        shadow_field: true,
        ..Default::default()
    };
    let bvh = BvhTracer::for_scene(scene, BvhSettings::default());
    let direct = DirectLighting::new(scene, &bvh, DirectSettings::default());
    let mut set = DdgiFieldSet::single(DdgiVolume::new(settings, (lo, hi)));
    let mut ms = BTreeMap::new();
    for f in 0..frames {
        set.update_traced_by(scene, &bvh, None, &direct, 7, f, &mut ms).expect("update");
    }
    assert!(ms.contains_key("shadow_blend"), "the shadow maps blended: {ms:?}");
    let occlusion = &set.volumes()[0].shadow.as_ref().expect("shadow field").occlusion;
    assert!(occlusion.texels.iter().all(|v| v.is_finite() && (0.0..=1.0).contains(v)));
    set
}

const SUN: &str = r#"
[[lights]]
kind = "directional"
direction = [0.2, -1.0, 0.1]
intensity = 5.0
"#;

#[test]
fn an_open_floor_under_the_sun_sees_it_and_a_sealed_room_does_not() {
    let open = scene_from(
        "open",
        &format!("[[objects]]\nname = \"floor\"\nbox_min_m = [-4.0, -0.2, -4.0]\nbox_max_m = [4.0, 0.0, 4.0]\n{SUN}"),
    );
    let (lo, hi) = (Vec3::new(-3.0, 0.3, -3.0), Vec3::new(3.0, 2.3, 3.0));
    let set = updated_field(&open, UVec3::new(4, 2, 4), lo, hi, 4);
    eprintln!("open: states {:?}", set.volumes()[0].state_counts());
    let sun = -Vec3::new(0.2, -1.0, 0.1).normalize();
    for p in [Vec3::new(0.0, 0.0, 0.0), Vec3::new(1.3, 0.0, -2.1), Vec3::new(-2.5, 0.0, 0.7)] {
        let v = set.shadow_visibility(p, Vec3::Y, Vec3::Y, sun).expect("inside the volume");
        assert!(v > 0.95, "open floor at {p}: visibility {v}");
    }
    // The same floor inside a sealed room (walls and a roof 0.2 m thick).
    let room = "[[objects]]\nname = \"room\"\nbox_min_m = [-4.0, -0.2, -4.0]\nbox_max_m = [4.0, 0.0, 4.0]\n\
        [[objects]]\nname = \"roof\"\nbox_min_m = [-4.0, 3.0, -4.0]\nbox_max_m = [4.0, 3.2, 4.0]\n\
        [[objects]]\nname = \"w\"\nbox_min_m = [-4.2, -0.2, -4.2]\nbox_max_m = [-4.0, 3.2, 4.2]\n\
        [[objects]]\nname = \"e\"\nbox_min_m = [4.0, -0.2, -4.2]\nbox_max_m = [4.2, 3.2, 4.2]\n\
        [[objects]]\nname = \"n\"\nbox_min_m = [-4.0, -0.2, -4.2]\nbox_max_m = [4.0, 3.2, -4.0]\n\
        [[objects]]\nname = \"s\"\nbox_min_m = [-4.0, -0.2, 4.0]\nbox_max_m = [4.0, 3.2, 4.2]\n";
    let sealed = scene_from("sealed", &format!("{room}{SUN}"));
    let set = updated_field(&sealed, UVec3::new(4, 2, 4), lo, hi, 4);
    for p in [Vec3::new(0.0, 0.0, 0.0), Vec3::new(1.3, 0.0, -2.1), Vec3::new(-2.5, 0.0, 0.7)] {
        let v = set.shadow_visibility(p, Vec3::Y, Vec3::Y, sun).expect("inside the volume");
        assert!(v < 0.05, "sealed floor at {p}: visibility {v}");
    }
}

#[test]
fn the_shadow_box_field_follows_the_exact_shadows() {
    // Seed 003 Fig. 7.10's box (builtin:shadow-box) at 16×4×16 probes.
    let scene = load_scene("builtin:shadow-box").expect("builtin");
    let (lo, hi) = scene.bounds().expect("bounds");
    let set = updated_field(&scene, UVec3::new(16, 4, 16), lo, hi, 6);
    let bvh = BvhTracer::for_scene(&scene, BvhSettings::default());
    // Floor points on a grid: exact visibility of the first spotlight, and the field's.
    let light = &scene.lights[0];
    let (mut lit, mut shadowed) = (vec![], vec![]);
    for i in 0..40 {
        for j in 0..40 {
            let p = Vec3::new(0.1 + i as f32 * 0.2, 0.0, 0.1 + j as f32 * 0.2);
            let to = light.position - p;
            let inside_occluder = (3.4..=4.6).contains(&p.x) && (3.4..=4.6).contains(&p.z);
            if inside_occluder {
                continue;
            }
            let (d, wi) = (to.length(), to.normalize());
            let exact = !bvh.occluded(&Ray::segment(p + Vec3::Y * 1e-3, wi, d * 0.999));
            let v = set.shadow_visibility(p, Vec3::Y, Vec3::Y, wi).expect("inside the volume");
            if exact { lit.push(v) } else { shadowed.push(v) }
        }
    }
    let mean = |v: &[f32]| v.iter().sum::<f32>() / v.len().max(1) as f32;
    let (l, s) = (mean(&lit), mean(&shadowed));
    eprintln!("field visibility: {} lit points mean {l:.3}, {} shadowed points mean {s:.3}", lit.len(), shadowed.len());
    assert!(lit.len() > 100 && shadowed.len() > 50, "{} lit, {} shadowed", lit.len(), shadowed.len());
    assert!(l > 0.8, "lit floor reads {l}");
    assert!(l - s > 0.15, "the field does not separate shadow ({s}) from light ({l})");
}
