//! How far a device's ray-triangle answer may stray from the CPU's, per ray.
//!
//! Both sides run obvhs `RtTriangle::intersect` (`bvh.wgsl` `bvh_intersect_leaf`)
//! on the same stored bits (v0, e1, e2, ng = e1 × e2, the ray):
//!   c = v0 − o,  D = ng·d,  r = d × c,
//!   u = (r·e2)/D,  v = (r·e1)/D,  t = (ng·c)/D.
//! WGSL lets a driver fuse multiply-adds and divide approximately (the Vulkan
//! precision table: x/y within 2.5 ulp, 1/x likewise); every other operation
//! here is correctly rounded. With u = 2⁻²⁴ the unit roundoff and first-order
//! error terms (γₙ ≈ n·u), each side's answer is within the following of the
//! exact one, so the two sides differ by at most twice that:
//! - c = v0 − o: one rounding, |δc| ≤ u|c|; ng·c: a 3-term dot, γ₃ Σ|ngᵢcᵢ| ≤ 3u|ng||c|.
//!   Relative error of N = ng·c: 4u·|c|/dist, dist = |n̂·c| the origin's distance
//!   to the plane (the dot's condition number; large for far or grazing origins).
//! - D = ng·d: 3u·|ng||d|/|D| = 3u/cos θ, θ between the ray and the normal
//!   (grazing rays are ill-conditioned).
//! - t = N·(1/D): the reciprocal 2.5 ulp = 5u, the product u; 6u.
//!   So |δt|/t ≤ u·(4|c|/dist + 3/cos θ + 6).
//! - The barycentrics: r = d × c, each component a difference of two products
//!   (2u|d||c|), then a 3-term dot with e2 (3u|r||e2|): an absolute error of
//!   5u|d||c||e2|/|D| = 5u|c|/(h·cos θ) with h = |ng|/|e2| the triangle's altitude
//!   over e2 (the smallest altitude bounds all three); D's and the division's
//!   relative error (3u/cos θ + 6u) on a weight ≤ 1.
//!   So |δu|, |δv| ≤ u·(5|c|/(h_min·cos θ) + 3/cos θ + 6); w = 1 − u − v carries
//!   both first terms, hence their factor 2 below.
//! - A ray into a placed copy (an instance, a moving object) is first moved into
//!   its space, `local_from_world`: origin M·o + m (3 products and 3 sums a
//!   component, |δo_local| ≤ 4u(‖M‖|o| + |m|)), direction M·d (3u‖M‖|d|). Mapped
//!   back to the world that is |δo| ≤ 4u·κ(|o| + |b|) and |δd| ≤ 3u·κ|d|, with
//!   b the copy's translation and κ = ‖A‖‖A⁻¹‖ the condition of its linear part A
//!   (Frobenius norms, which bound the spectral ones). An origin moved by δo moves
//!   the plane distance by |δo|, t by |δo|/cos θ; a direction turned by δd moves t
//!   by t|δd|/(|d| cos θ) and the hit point in the plane by t|δd|/cos θ. The
//!   intersection itself runs in the copy's space, whose angles and distance
//!   ratios differ from the world's by at most κ: the terms above take a factor κ.

use glam::{Affine3A, DVec2, DVec3};
use probegi_scene::{Ray, RayHit, Scene};

/// The f32 unit roundoff, 2⁻²⁴.
pub const UNIT_ROUNDOFF: f64 = f32::EPSILON as f64 * 0.5;

/// How far the device's answer for one ray-triangle hit may be from the CPU's:
/// the sum of both sides' bounds from the module docs.
#[derive(Clone, Copy, Debug)]
pub struct HitTolerance {
    /// Hit distance, absolute (metres).
    pub dt: f64,
    /// Each barycentric weight (u, v and 1 − u − v), absolute.
    pub bary: f64,
    /// |cos θ| between the ray and the triangle's normal (how far a moved origin
    /// moves t: |δo|/cos θ).
    pub cos: f64,
}

/// A triangle in world space and, when the tracers reach it through a placed
/// copy, the copy's world-from-local transform.
#[derive(Clone, Copy, Debug)]
pub struct WorldTriangle {
    /// Corners, world space (placed in f64, so that the placing adds no error).
    pub p: [DVec3; 3],
    /// World from local of an instance or moving object; `None` for the static mesh.
    pub placed: Option<Affine3A>,
}

/// The world triangle `hit` names in `scene` posed at `frame` (its moving
/// objects where `Scene::set_frame_from` put them).
pub fn world_triangle(scene: &Scene, frame: f32, hit: &RayHit) -> WorldTriangle {
    let tri = hit.triangle as usize;
    match scene.instances.get(hit.instance as usize) {
        Some(inst) => {
            let mesh = &scene.prototypes[inst.prototype as usize].mesh;
            let p = mesh.triangles[tri].map(|v| place(&inst.world_from_local, mesh.positions[v as usize].as_dvec3()));
            WorldTriangle { p, placed: Some(inst.world_from_local) }
        }
        None => {
            let p = scene.mesh.triangles[tri].map(|v| scene.mesh.positions[v as usize].as_dvec3());
            let moving = scene.objects.iter().find(|o| o.triangles().contains(&tri) && !o.animation.is_still());
            WorldTriangle { p, placed: moving.map(|o| o.world_from_rest(frame)) }
        }
    }
}

/// `a` applied to `p` in f64.
fn place(a: &Affine3A, p: DVec3) -> DVec3 {
    a.matrix3.x_axis.as_dvec3() * p.x
        + a.matrix3.y_axis.as_dvec3() * p.y
        + a.matrix3.z_axis.as_dvec3() * p.z
        + a.translation.as_dvec3()
}

/// κ = ‖A‖_F ‖A⁻¹‖_F of the linear part (≥ the spectral condition number).
fn condition(a: &Affine3A) -> f64 {
    let m =
        glam::DMat3::from_cols(a.matrix3.x_axis.as_dvec3(), a.matrix3.y_axis.as_dvec3(), a.matrix3.z_axis.as_dvec3());
    let frobenius =
        |m: &glam::DMat3| (m.x_axis.length_squared() + m.y_axis.length_squared() + m.z_axis.length_squared()).sqrt();
    frobenius(&m) * frobenius(&m.inverse())
}

/// The tolerance for `ray` meeting `tri` at distance `t` (module docs).
/// Infinite for a ray in the triangle's plane.
pub fn hit_tolerance(ray: &Ray, t: f32, tri: &WorldTriangle) -> HitTolerance {
    let u = UNIT_ROUNDOFF;
    let [p0, p1, p2] = tri.p;
    let (o, d, t) = (ray.origin.as_dvec3(), ray.dir.as_dvec3(), t as f64);
    let (e1, e2) = (p1 - p0, p2 - p0);
    let ng = e1.cross(e2);
    let area2 = ng.length();
    let n = ng / area2;
    let cos = n.dot(d).abs() / d.length();
    let c = p0 - o;
    let dist = n.dot(c).abs();
    let h_min = area2 / e1.length().max(e2.length()).max((e2 - e1).length());
    let (kappa, moved, turned) = match &tri.placed {
        // The ray's move into the copy's space (module docs), as world-space δo and |δd|/|d|.
        Some(a) => {
            let k = condition(a);
            let b = a.translation.as_dvec3().length();
            (k, 4.0 * u * k * (o.length() + b), 3.0 * u * k)
        }
        None => (1.0, 0.0, 0.0),
    };
    let rel_t = kappa * u * (4.0 * c.length() / dist + 3.0 / cos + 6.0) + moved / dist + turned / cos;
    let in_plane = kappa * u * 5.0 * c.length() + moved + turned * t * d.length();
    let bary = 2.0 * in_plane / (h_min * cos) + kappa * u * (3.0 / cos + 6.0);
    // Both sides: the device's and the CPU's answers each within the bound of the exact one.
    HitTolerance { dt: 2.0 * rel_t * t, bary: 2.0 * bary, cos }
}

/// Whether `hit` lies within its tolerance of its triangle's edges, where a
/// rounding may move it off the triangle (onto a neighbour, or off the mesh).
pub fn near_an_edge(hit: &RayHit, tol: &HitTolerance) -> bool {
    let b = hit.barycentric.as_dvec2();
    b.x.min(b.y).min(1.0 - b.x - b.y) <= tol.bary
}

/// Whether `hit` is a true meeting of the ray with `tri` (the one it names):
/// the ray meets the triangle's plane within the hit's distance tolerance of
/// its t, at a point whose barycentrics are the hit's within their tolerance,
/// none of them below −tolerance. Computed in f64 (exact to far below the
/// tolerances), so a hit reported on the wrong triangle, or at a wrong
/// distance, fails even where its t happens to tie with the right one's.
pub fn is_genuine(ray: &Ray, hit: &RayHit, tri: &WorldTriangle, tol: &HitTolerance) -> bool {
    let [p0, p1, p2] = tri.p;
    let (o, d) = (ray.origin.as_dvec3(), ray.dir.as_dvec3());
    let (e1, e2) = (p1 - p0, p2 - p0);
    let ng = e1.cross(e2);
    let det = ng.dot(d);
    if det == 0.0 {
        return false;
    }
    let t = ng.dot(p0 - o) / det;
    let q = o + d * t - p0;
    // Barycentrics of q in the plane: solve q = u·e1 + v·e2 by the normal equations.
    let (a11, a12, a22) = (e1.dot(e1), e1.dot(e2), e2.dot(e2));
    let (b1, b2) = (q.dot(e1), q.dot(e2));
    let den = a11 * a22 - a12 * a12;
    let bary = DVec2::new((b1 * a22 - b2 * a12) / den, (b2 * a11 - b1 * a12) / den);
    let w = 1.0 - bary.x - bary.y;
    (t - hit.t as f64).abs() <= tol.dt
        && (bary - hit.barycentric.as_dvec2()).abs().max_element() <= tol.bary
        && bary.x.min(bary.y).min(w) >= -tol.bary
}

/// Whether the hit's triangle is cut out by an alpha mask: its coverage test
/// (bilinear coverage at the hit's uv against the cutoff) is one more boundary
/// a rounding of the barycentrics may cross, whose distance these bounds do
/// not measure.
pub fn cut_out(scene: &Scene, hit: &RayHit) -> bool {
    let mesh = match scene.instances.get(hit.instance as usize) {
        Some(inst) => &scene.prototypes[inst.prototype as usize].mesh,
        None => &scene.mesh,
    };
    let material = scene.material(mesh.triangle_materials[hit.triangle as usize]);
    material.alpha_mode != probegi_scene::material::AlphaMode::Opaque
}
