//! Embedding probegi's DDGI in an engine: this program owns its triangles, its
//! ray caster and its shading, and drives a DDGI field set through the seam
//! (`probegi_field::ddgi_field_set`). It uses no probegi scene types.
//!
//! The world is a white furnace: a closed 4 m cube whose inside faces all emit
//! Le = 1 W·m⁻²·sr⁻¹ and reflect ρ = 0.5. Every bounce must accumulate, so the
//! radiance converges to L = Le / (1 − ρ) = 2 and the irradiance anywhere on a
//! face to E = π·L ≈ 6.283 W·m⁻². The program prints the field's irradiance at the
//! middle of the floor and exits with an error if it is more than 3 % off.
//!
//! Run: `cargo run -p probegi-cpu --example embed_ddgi`. CI runs it as the test
//! `probegi-cpu/tests/it/embed_example.rs`, which includes this file.

use glam::{UVec3, Vec3};
use probegi_core::ddgi_settings::{DdgiFieldSetSettings, DdgiVolumeSettings};
use probegi_core::ddgi_volume_blend::field_set_irradiance;
use probegi_field::{DdgiFieldSet, ProbeRayBatch, ProbeRayHit, SeamError, UpdateStep};

/// The application's own geometry: triangles with their inward (front) normal.
struct Triangle {
    v: [Vec3; 3],
    normal: Vec3,
}

/// A cube's twelve triangles, wound so that their normals face inward.
fn cube(lo: Vec3, hi: Vec3) -> Vec<Triangle> {
    let c = |x: usize, y: usize, z: usize| Vec3::new([lo.x, hi.x][x], [lo.y, hi.y][y], [lo.z, hi.z][z]);
    let quads = [
        [c(0, 0, 0), c(1, 0, 0), c(1, 0, 1), c(0, 0, 1)], // floor
        [c(0, 1, 0), c(0, 1, 1), c(1, 1, 1), c(1, 1, 0)], // ceiling
        [c(0, 0, 0), c(0, 0, 1), c(0, 1, 1), c(0, 1, 0)], // x = lo
        [c(1, 0, 0), c(1, 1, 0), c(1, 1, 1), c(1, 0, 1)], // x = hi
        [c(0, 0, 0), c(0, 1, 0), c(1, 1, 0), c(1, 0, 0)], // z = lo
        [c(0, 0, 1), c(1, 0, 1), c(1, 1, 1), c(0, 1, 1)], // z = hi
    ];
    let centre = (lo + hi) * 0.5;
    let mut tris = Vec::new();
    for q in quads {
        for v in [[q[0], q[1], q[2]], [q[0], q[2], q[3]]] {
            let mut normal = (v[1] - v[0]).cross(v[2] - v[0]).normalize();
            // Face the inside whatever the winding above.
            if normal.dot(centre - v[0]) < 0.0 {
                normal = -normal;
            }
            tris.push(Triangle { v, normal });
        }
    }
    tris
}

/// The application's ray caster: brute-force Möller–Trumbore over every triangle.
/// Returns (distance, triangle) of the closest hit within `max_t`.
fn closest_hit(tris: &[Triangle], origin: Vec3, dir: Vec3, max_t: f32) -> Option<(f32, &Triangle)> {
    let mut best: Option<(f32, &Triangle)> = None;
    for t in tris {
        let (e1, e2) = (t.v[1] - t.v[0], t.v[2] - t.v[0]);
        let p = dir.cross(e2);
        let det = e1.dot(p);
        if det.abs() < 1e-12 {
            continue;
        }
        let s = origin - t.v[0];
        let u = s.dot(p) / det;
        let q = s.cross(e1);
        let v = dir.dot(q) / det;
        let d = e2.dot(q) / det;
        if u < 0.0 || v < 0.0 || u + v > 1.0 || d <= 1e-6 || d > max_t {
            continue;
        }
        if best.is_none_or(|(b, _)| d < b) {
            best = Some((d, t));
        }
    }
    best
}

const EMISSION: f32 = 1.0;
const ALBEDO: f32 = 0.5;

/// The application traces the set's batch with its own ray caster: one
/// `ProbeRayHit` per ray (a miss, or a front or back face at `t` with the normal
/// that faces the ray's origin).
fn trace(world: &[Triangle], batch: &ProbeRayBatch) -> Vec<ProbeRayHit> {
    (0..batch.len())
        .map(|i| {
            let (o, d) = (batch.origins_m[i], batch.directions[i]);
            match closest_hit(world, o, d, batch.max_distances_m[i]) {
                None => ProbeRayHit::MISS,
                Some((t, tri)) if tri.normal.dot(d) < 0.0 => ProbeRayHit::front(t, tri.normal),
                Some((t, tri)) => ProbeRayHit::back(t, -tri.normal),
            }
        })
        .collect()
}

/// The application shades the hits: emission plus the diffuse bounce of the
/// field's previous irradiance. Only front hits and misses need radiance; the set
/// zeroes backfaces.
fn shade(set: &DdgiFieldSet, hits: &[ProbeRayHit]) -> Vec<Vec3> {
    let (batch, view) = (set.ray_batch(), set.view());
    let radiance = hits.iter().enumerate().map(|(i, h)| {
        if !batch.needs_radiance[i] || !h.distance_m.is_finite() {
            return Vec3::ZERO; // no sky: the box is closed
        }
        let dir = batch.directions[i];
        let p = batch.origins_m[i] + dir * h.distance_m;
        let e = field_set_irradiance(&view, p, h.normal, -dir);
        Vec3::splat(EMISSION) + ALBEDO * std::f32::consts::FRAC_1_PI * e
    });
    radiance.collect()
}

/// The furnace: the field's irradiance at the middle of the floor after 80
/// frames, and the probe rays the application traced.
fn furnace_irradiance() -> Result<(Vec3, u64), SeamError> {
    let (lo, hi) = (Vec3::ZERO, Vec3::splat(4.0));
    let world = cube(lo, hi);
    // README: cpu-field begin
    // One volume of 4³ probes fitted to the box, 64 rays each; a short hysteresis
    // so that 80 frames converge; everything else is the papers' defaults.
    let volume = DdgiVolumeSettings {
        probe_counts: UVec3::splat(4),
        probe_rays_per_probe: 64,
        probe_hysteresis: 0.8,
        ..Default::default()
    };
    let mut set = DdgiFieldSet::new(&DdgiFieldSetSettings::single(volume), (lo, hi), None);
    let (mut hits, mut rays_traced) = (Vec::new(), 0u64);
    for frame in 0..80 {
        let mut step = set.begin_update(7, frame);
        while step != UpdateStep::Done {
            step = match step {
                UpdateStep::TraceRays => {
                    hits = trace(&world, set.ray_batch()); // your ray caster
                    rays_traced += hits.len() as u64;
                    set.submit_hits(&hits)?
                }
                UpdateStep::ShadeRays => set.submit_radiance(&shade(&set, &hits))?, // your shading
                UpdateStep::Done => UpdateStep::Done,
            };
        }
    }
    let e = set.irradiance(Vec3::new(2.0, 0.0, 2.0), Vec3::Y, Vec3::Y); // at the middle of the floor
    // README: cpu-field end
    Ok((e, rays_traced))
}

pub fn main() -> Result<(), Box<dyn std::error::Error>> {
    let (e, rays_traced) = furnace_irradiance()?;
    let want = std::f32::consts::PI * EMISSION / (1.0 - ALBEDO);
    println!(
        "irradiance at the middle of the floor: {:.4} {:.4} {:.4} W/m² (analytic {want:.4}), \
         {rays_traced} probe rays traced by the application",
        e.x, e.y, e.z
    );
    let err = (e.x - want).abs() / want;
    if err > 0.03 {
        return Err(format!("off by {:.1} %, more than 3 %", err * 100.0).into());
    }
    Ok(())
}
