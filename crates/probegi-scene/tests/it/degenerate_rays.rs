//! Every ray gets a defined answer from the CPU tracer, in bounded time
//! (`probegi_scene::bvh_walk`): NaN, ±∞, zero, denormal and huge origins,
//! directions and ranges, closest and any hit, through the static BVH of the
//! shared Sponza and through the top level of `builtin:forest` (instanced
//! pines with alpha-cut leaves) and `scenes/moving-box.toml` (a moving object)
//! at a frame. Rays the rule refuses are misses and are counted; the others
//! hit or miss as they may, but never hang.

use crate::common;

use common::shared;

use std::path::PathBuf;
use std::sync::mpsc;
use std::time::Duration;

use glam::Vec3;
use probegi_scene::bvh_walk::hostile_rays;
use probegi_scene::{BvhSettings, BvhTracer, Ray, RayTracer, Scene, load_scene};

fn repo(rel: &str) -> String {
    PathBuf::from(env!("CARGO_MANIFEST_DIR")).join("../..").join(rel).to_string_lossy().into_owned()
}

/// Runs `f` on its own thread and fails the test if it takes longer than `secs`.
fn within<T: Send + 'static>(secs: u64, what: &str, f: impl FnOnce() -> T + Send + 'static) -> T {
    let (tx, rx) = mpsc::channel();
    std::thread::spawn(move || {
        let _ = tx.send(f());
    });
    rx.recv_timeout(Duration::from_secs(secs)).unwrap_or_else(|_| panic!("{what}: no answer within {secs} s (a hang)"))
}

/// Traces every ray (closest and any hit) through `tracer`; returns what the
/// refused rays gave and the tracer's guard counts.
fn trace_all(tracer: &dyn RayTracer, refused: &[Ray], traced: &[Ray]) -> (usize, usize) {
    let mut refused_hits = 0;
    for r in refused {
        refused_hits += tracer.closest_hit(r).is_some() as usize + tracer.occluded(r) as usize;
    }
    for r in traced {
        if let Some(h) = tracer.closest_hit(r) {
            assert!(h.t.is_finite() && h.t >= r.t_min && h.t <= r.t_max, "{r:?}: {h:?}");
        }
        tracer.occluded(r);
    }
    (refused_hits, refused.len())
}

fn check_scene(scene: Scene, frame: Option<f32>, name: &'static str) {
    within(120, name, move || {
        let tracer = BvhTracer::for_scene(&scene, BvhSettings::default());
        let (lo, hi) = scene.bounds().expect("geometry");
        let (refused, traced) = hostile_rays((lo + hi) * 0.5);
        let posed;
        let frame_tracer = match frame {
            Some(f) => {
                let mut s = scene.clone();
                s.set_frame_from(&scene, f);
                posed = s;
                tracer.at_frame(&posed, f)
            }
            None => None,
        };
        let t: &dyn RayTracer = frame_tracer.as_deref().unwrap_or(&tracer);
        let (hits, n) = trace_all(t, &refused, &traced);
        assert_eq!(hits, 0, "{name}: refused rays must miss");
        let counts = tracer.trace_guard_counts();
        assert_eq!(counts.rays_refused, 2 * n as u64, "{name}: each refused ray counted once per query");
        assert_eq!(counts.walks_cut_short, 0, "{name}");
        // The valid ray still hits after all that.
        assert!(t.closest_hit(&traced[0]).is_some() || t.occluded(&Ray::new((lo + hi) * 0.5, Vec3::NEG_Y)));
    });
}

#[test]
fn sponza_answers_every_degenerate_ray() {
    check_scene(load_scene(&shared("dabrovic-sponza/sponza.obj")).expect("sponza"), None, "sponza");
}

#[test]
fn the_two_level_trace_answers_every_degenerate_ray() {
    check_scene(load_scene("builtin:forest").expect("forest"), None, "instanced forest");
    check_scene(load_scene(&repo("scenes/moving-box.toml")).expect("moving box"), Some(7.5), "moving box");
}
