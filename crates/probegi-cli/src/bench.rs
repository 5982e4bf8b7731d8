//! `probegi bench`: BVH build time and closest-hit / any-hit throughput on
//! probe-like rays — uniformly random directions from the points of a probe grid
//! spread over the scene bounds, the workload of DDGI's trace pass. Any-hit rays
//! are the same rays limited to one grid cell (a typical visibility query).

use std::time::Instant;

use anyhow::{Context, Result, bail};
use glam::Vec3;
use probegi_core::rng::{Pcg32, hash_combine};
use probegi_core::sampling::sample_uniform_sphere;
use probegi_scene::{BvhSettings, BvhTracer, Ray, RayTracer, load_scene};
use rayon::prelude::*;
use serde_json::json;

use crate::args::BenchArgs;

pub fn run(args: &BenchArgs) -> Result<serde_json::Value> {
    let ray_count = args.probes.iter().map(|&n| n as u64).product::<u64>() * args.rays_per_probe as u64;
    if args.rays_per_probe == 0 || args.repeat == 0 {
        bail!("--rays-per-probe and --repeat must be at least 1");
    }
    crate::check_memory(ray_count * std::mem::size_of::<Ray>() as u64, "bench rays")?;
    if !(args.aabb_pad_rel.is_finite() && args.aabb_pad_rel >= 0.0 && args.aabb_pad_rel < 0.1) {
        bail!("--aabb-pad-rel {} must be in [0, 0.1)", args.aabb_pad_rel);
    }
    let t = Instant::now();
    let scene = load_scene(&args.scene).with_context(|| format!("loading scene {}", args.scene))?;
    let load_ms = t.elapsed().as_secs_f64() * 1e3;
    let (lo, hi) = scene.bounds().context("scene has no geometry")?;

    let mut build_ms = f64::INFINITY;
    let mut bvh = None;
    for _ in 0..args.repeat.min(3) {
        let b = BvhTracer::build(&scene.mesh, BvhSettings { bvh_aabb_pad_rel: args.aabb_pad_rel });
        build_ms = build_ms.min(b.build_time.as_secs_f64() * 1e3);
        bvh = Some(b);
    }
    let bvh = bvh.context("no BVH built")?;

    let [nx, ny, nz] = args.probes;
    let cell = (hi - lo) / Vec3::new(nx as f32, ny as f32, nz as f32);
    let rays: Vec<Ray> = (0..nx * ny * nz)
        .into_par_iter()
        .flat_map_iter(|p| {
            let (ix, iy, iz) = (p % nx, (p / nx) % ny, p / (nx * ny));
            let origin = lo + cell * (Vec3::new(ix as f32, iy as f32, iz as f32) + 0.5);
            let mut rng = Pcg32::new(hash_combine(&[args.seed, p as u64]), p as u64);
            (0..args.rays_per_probe).map(move |_| Ray::new(origin, sample_uniform_sphere(rng.next_vec2())))
        })
        .collect();
    let any_hit_len = cell.min_element();

    let time_best = |f: &(dyn Fn() -> u64 + Sync)| {
        let mut best = f64::INFINITY;
        let mut hits = 0;
        for _ in 0..args.repeat {
            let t = Instant::now();
            hits = f();
            best = best.min(t.elapsed().as_secs_f64());
        }
        (best, hits)
    };
    let (closest_s, closest_hits) =
        time_best(&|| rays.par_iter().filter(|r| bvh.closest_hit(r).is_some()).count() as u64);
    let (any_s, any_hits) =
        time_best(&|| rays.par_iter().filter(|r| bvh.occluded(&Ray { t_max: any_hit_len, ..**r })).count() as u64);
    let n = rays.len() as f64;
    Ok(json!({
        "scene": args.scene,
        "triangles": scene.mesh.triangle_count(),
        "threads": rayon::current_num_threads(),
        "load_ms": load_ms,
        "bvh_build_ms": build_ms,
        "bvh_aabb_pad_rel": args.aabb_pad_rel,
        "probes": args.probes,
        "rays_per_probe": args.rays_per_probe,
        "rays": rays.len(),
        "closest_hit_mrays_per_s": n / closest_s / 1e6,
        "closest_hit_fraction": closest_hits as f64 / n,
        "any_hit_max_distance_m": any_hit_len,
        "any_hit_mrays_per_s": n / any_s / 1e6,
        "any_hit_fraction": any_hits as f64 / n,
    }))
}
