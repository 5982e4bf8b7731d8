//! A bounded fuzzer over camera paths and ray batches, on the stable
//! toolchain with a seeded PCG. Camera paths: random keyframes whose
//! positions, targets and up hints are drawn from a palette that includes
//! looking straight up and down, an up hint along the view, coincident eye
//! and target, zero, huge and non-finite values. Every path the validation
//! accepts must give a finite orthonormal view basis and finite unit rays on
//! every frame; every path it refuses must say why. Ray batches: random rays
//! whose components come from a palette of NaN, ±∞, ±0, denormals and values
//! near `f32::MAX`, traced closest and any hit through the static BVH and the
//! two-level BVH of `scenes/moving-box.toml`. Each batch must return within
//! a bound (a hang fails the test instead of stalling the suite).
//! `PROBEGI_FUZZ_CAMERA_SECONDS` (default 5 in all; `scripts/long-checks.sh`: 5 minutes) and `PROBEGI_FUZZ_SEED`.

use std::path::PathBuf;
use std::sync::mpsc;
use std::time::{Duration, Instant};

use glam::Vec3;
use probegi_core::camera::{Camera, CameraRays};
use probegi_core::rng::Pcg32;
use probegi_scene::{BvhSettings, BvhTracer, CameraKeyframe, Ray, RayTracer, Scene, load_scene};

fn budget_s() -> f64 {
    std::env::var("PROBEGI_FUZZ_CAMERA_SECONDS").ok().and_then(|v| v.parse().ok()).unwrap_or(5.0)
}

fn seed() -> u64 {
    std::env::var("PROBEGI_FUZZ_SEED").ok().and_then(|v| v.parse().ok()).unwrap_or(1)
}

fn pick<T: Copy>(rng: &mut Pcg32, palette: &[T]) -> T {
    palette[(rng.next_u32() as usize) % palette.len()]
}

/// A component from the hostile palette, or a plain random number.
fn component(rng: &mut Pcg32) -> f32 {
    let palette = [
        f32::NAN,
        f32::INFINITY,
        f32::NEG_INFINITY,
        0.0,
        -0.0,
        1e-40,
        -1e-45,
        f32::MIN_POSITIVE,
        1e38,
        -3e38,
        f32::MAX,
        1e-30,
    ];
    if rng.next_f32() < 0.4 { pick(rng, &palette) } else { rng.next_f32() * 4.0 - 2.0 }
}

fn hostile_vec(rng: &mut Pcg32) -> Vec3 {
    Vec3::new(component(rng), component(rng), component(rng))
}

/// A point of a camera path: mostly ordinary, often on the vertical through
/// the eye, sometimes the eye itself or hostile.
fn path_point(rng: &mut Pcg32, eye: Vec3) -> Vec3 {
    match rng.next_u32() % 6 {
        0 => eye + Vec3::Y * (rng.next_f32() + 0.1),
        1 => eye - Vec3::Y * (rng.next_f32() + 0.1),
        2 => eye,
        3 if rng.next_f32() < 0.3 => hostile_vec(rng),
        _ => Vec3::new(rng.next_f32(), rng.next_f32(), rng.next_f32()) * 4.0 - 2.0,
    }
}

fn random_path(rng: &mut Pcg32) -> Vec<CameraKeyframe> {
    let eye = Vec3::new(0.1, 1.0, 0.2);
    let keys = 1 + rng.next_u32() % 5;
    let mut frame = 0.0;
    (0..keys)
        .map(|_| {
            frame += pick(rng, &[0.5, 1.0, 3.0, 10.0, 0.0]);
            let position = if rng.next_f32() < 0.7 { eye } else { path_point(rng, eye) };
            let target = path_point(rng, position);
            let up = pick(rng, &[Vec3::Y, Vec3::Y, Vec3::X, -Vec3::Y, Vec3::ZERO, target - position]);
            let fov_y_deg = pick(rng, &[60.0, 1.0, 178.0, 0.0, f32::NAN]);
            CameraKeyframe { frame, camera: Camera { position, target, up, fov_y_deg } }
        })
        .collect()
}

fn orthonormal(rays: &CameraRays) -> bool {
    let ([f, r, u], _) = rays.basis();
    let unit = |v: Vec3| (v.length() - 1.0).abs() < 1e-4;
    unit(f) && unit(r) && unit(u) && f.dot(r).abs() < 1e-4 && f.dot(u).abs() < 1e-4 && r.dot(u).abs() < 1e-4
}

/// Every frame of an accepted path has a finite orthonormal basis and finite
/// unit rays, and `camera_at` agrees with `camera_path`.
fn check_path(scene: &Scene, frames: u32) -> Result<(), String> {
    let path = scene.camera_path(frames);
    for (f, c) in path.iter().enumerate() {
        let rays = CameraRays::new(c, 8, 6);
        if !orthonormal(&rays) {
            return Err(format!("frame {f}: basis {:?} of {c:?}", rays.basis()));
        }
        for (x, y) in [(0.0, 0.0), (4.0, 3.0), (8.0, 6.0)] {
            let d = rays.ray_dir_world(x, y);
            if !d.is_finite() || (d.length() - 1.0).abs() > 1e-4 {
                return Err(format!("frame {f}: ray {d} through ({x}, {y})"));
            }
        }
    }
    for f in [0, frames / 2, frames - 1] {
        if scene.camera_at(f as f32) != path.get(f as usize).copied() {
            return Err(format!("camera_at({f}) differs from camera_path"));
        }
    }
    Ok(())
}

#[test]
fn random_camera_paths_are_refused_or_render_finite_rays_on_every_frame() {
    let mut rng = Pcg32::new(seed(), 0xca3e);
    let base = probegi_scene::builtin::cornell_box();
    let start = Instant::now();
    let (mut accepted, mut refused, mut vertical) = (0, 0, 0);
    // A fixed number of paths, more while the time budget lasts.
    while accepted + refused < 2000 || start.elapsed().as_secs_f64() < budget_s() * 0.5 {
        let keys = random_path(&mut rng);
        let mut scene = base.clone();
        scene.camera = Some(keys[0].camera);
        scene.camera_keyframes = keys.clone();
        match scene.validate() {
            Err(e) => {
                assert!(!e.is_empty());
                refused += 1;
            }
            Ok(()) => {
                accepted += 1;
                vertical +=
                    keys.iter().any(|k| (k.camera.target - k.camera.position).normalize().y.abs() > 0.9999) as usize;
                if let Err(e) = check_path(&scene, 40) {
                    panic!("path {keys:?}: {e}");
                }
            }
        }
    }
    eprintln!("{accepted} camera paths accepted ({vertical} through the vertical), {refused} refused");
    assert!(accepted > 50 && refused > 50 && vertical > 10, "{accepted} / {refused} / {vertical}");
}

fn random_rays(rng: &mut Pcg32, inside: Vec3, n: usize) -> Vec<Ray> {
    (0..n)
        .map(|_| {
            let origin = if rng.next_f32() < 0.5 { inside } else { hostile_vec(rng) };
            let dir = hostile_vec(rng);
            let (t_min, t_max) = match rng.next_u32() % 4 {
                0 => (component(rng), component(rng)),
                1 => (0.0, component(rng).abs()),
                _ => (0.0, f32::INFINITY),
            };
            Ray { origin, dir, t_min, t_max }
        })
        .collect()
}

/// Traces `rays` (closest and any hit) on a worker and returns how many rays
/// the rule refuses hit anything; fails the test if the worker takes longer
/// than `secs` (a hang) or panics.
fn trace_within(tracer: std::sync::Arc<BvhTracer>, posed: Option<Scene>, rays: Vec<Ray>, secs: u64) -> usize {
    let (tx, rx) = mpsc::channel();
    let first = rays[..8.min(rays.len())].to_vec();
    std::thread::spawn(move || {
        let frame = posed.as_ref().and_then(|s| tracer.at_frame(s, 7.5));
        let t: &dyn RayTracer = frame.as_deref().unwrap_or(&*tracer);
        let mut refused_hits = 0;
        for r in &rays {
            let hit = t.closest_hit(r).is_some() | t.occluded(r);
            refused_hits += (hit && !probegi_scene::bvh_walk::ray_is_traced(r)) as usize;
        }
        let _ = tx.send(refused_hits);
    });
    match rx.recv_timeout(Duration::from_secs(secs)) {
        Ok(hits) => hits,
        Err(mpsc::RecvTimeoutError::Timeout) => panic!("a batch of hostile rays did not finish; first rays: {first:?}"),
        Err(mpsc::RecvTimeoutError::Disconnected) => panic!("tracing a hostile batch panicked; first rays: {first:?}"),
    }
}

#[test]
fn random_hostile_ray_batches_finish_on_both_bvh_levels() {
    let moving = PathBuf::from(env!("CARGO_MANIFEST_DIR")).join("../../scenes/moving-box.toml");
    let moving = load_scene(&moving.to_string_lossy()).expect("moving box");
    let mut posed = moving.clone();
    posed.set_frame_from(&moving, 7.5);
    let scenes = [(probegi_scene::builtin::cornell_box(), None), (moving, Some(posed))];
    let mut rng = Pcg32::new(seed(), 0x5a7);
    let start = Instant::now();
    let mut batches = 0;
    while start.elapsed().as_secs_f64() < budget_s() * 0.5 || batches < 8 {
        let (scene, posed) = &scenes[batches % 2];
        let tracer = std::sync::Arc::new(BvhTracer::for_scene(scene, BvhSettings::default()));
        let (lo, hi) = scene.bounds().expect("geometry");
        let rays = random_rays(&mut rng, (lo + hi) * 0.5, 4096);
        let refused_hits = trace_within(tracer.clone(), posed.clone(), rays.clone(), 60);
        assert_eq!(refused_hits, 0, "rays the rule refuses must miss");
        let refused = rays.iter().filter(|r| !probegi_scene::bvh_walk::ray_is_traced(r)).count() as u64;
        let counts = tracer.trace_guard_counts();
        assert_eq!(counts.rays_refused, 2 * refused, "each refused ray counted per query");
        assert_eq!(counts.walks_cut_short, 0);
        batches += 1;
    }
    eprintln!("{batches} batches of 4096 hostile rays");
}
