//! The WGSL query (`ddgi_query.wgsl`, the file engines include) against the CPU's
//! (`probegi_core::ddgi_volume_blend::field_set_irradiance`) on fields the CPU
//! backend converged: the Cornell box with probe states and relocation, three
//! camera-centred cascades whose windows have scrolled (circular buffers), two
//! hand-placed volumes under density blending, and a field whose cages hold no
//! usable probe (the fallback table). 20 000 random surface points each (half on
//! the walls, half anywhere, random normals).
//!
//! The GPU evaluates the same operations in the same order, but a driver may
//! fuse multiply-adds and approximate division, square roots and normalize
//! (see [`SMOOTH_ERROR_REL`]). Each point is held to a bound in two parts: the
//! rounding of the query's arithmetic where it is well conditioned (relative to
//! the field's largest possible value), and the query's own sensitivity to the
//! inputs it is ill-conditioned in, measured on the CPU by moving those inputs
//! by the device's backward error ([`Sensitivity`]): the distance moments (the
//! Chebyshev variance m₂ − m₁² cancels) and the position (a cage, a fallback
//! probe or a member's weight switches at a cell boundary; a point within that
//! error of the boundary may land on either side). A wrong texel, weight, cage
//! or probe away from such a boundary still fails.

use crate::common;

use probegi_frame::field_update::FieldSetUpdate;
use std::collections::BTreeMap;

use glam::Vec2;
use glam::{UVec3, Vec3};
use probegi_core::ddgi_query::{DdgiFieldView, nearest_usable_probes};
use probegi_core::ddgi_settings::{DdgiFieldSetSettings, DdgiVolumeSettings};
use probegi_core::ddgi_volume_blend::{DdgiFieldSetView, SetMember, VolumeBlending, field_set_irradiance};
use probegi_core::probe_atlas::ProbeAtlas;
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

/// The f32 unit roundoff, 2⁻²⁴.
const U: f32 = f32::EPSILON / 2.0;

/// The query's rounding where it is well conditioned, relative to the field's
/// largest possible value, per side (device and CPU), first order in u:
/// - a bilinear texel sample, 4 products and 3 sums of non-negative terms with
///   weights that take 3u each: 7u;
/// - the half decode e²·√e (γ = 5): 2.5 × 7u, 2u for the products, and the
///   square root, which WGSL inherits from 1/inverseSqrt (2 + 2.5 ulp, 9u): 29u
///   (every field here has the default γ = 5; another γ takes `pow`, inherited
///   from exp2(y·log2 x), which this count does not cover: `compare` refuses it);
/// - the backface weight ((n̂·n + 1)/2)² + 0.2 with n̂ = normalize(probe − x)
///   (inherited from x/length(x): 3u + 9u + 5u = 17u a component): the dot is off
///   by 20u, the square by 23u absolute, over the 0.2 floor: 116u;
/// - the Chebyshev weight's last steps (w = var/(var + d²), cubed): 7u, tripled,
///   23u (its ill-conditioned inputs are [`Sensitivity`]'s);
/// - the trilinear factors and the products of the factors: 11u + 3u;
/// - the crush w³/c² triples all that and adds 9u: 3 × 153u + 9u = 468u;
/// - the weighted mean h = Σwᵢeᵢ/Σwᵢ: a weight's relative error ρ moves h by at
///   most ρ·max eᵢ, the texels' by 29u·max eᵢ, the sums and the division 20u: 517u
///   of the largest corner value max e;
/// - E = h²·π·c: twice that against π·c·(max e)², the field's largest value, and
///   3u; the members' blend adds 18u: 2 × 517u + 21u = 1055u.
///
/// Both sides round, so the bound is twice that: 2110u ≈ 1.26e-4.
const SMOOTH_ERROR_REL: f32 = 2.0 * 1055.0 * U;

/// The device's backward error in the distance moments (m₁, m₂) a corner's
/// Chebyshev weight reads, relative: the bilinear sample (7u), the distance it
/// is compared with (length: 12u, the same as moving m₁ by it), and m₁²'s product
/// (u, fused or not): 20u for m₁; 7u + u = 8u for m₂.
const MOMENT_BACKWARD_REL: [f32; 2] = [20.0 * U, 8.0 * U];

/// The device's backward error in the query position, relative to R, the
/// largest coordinate in play (the point's, the volumes' corners'): the surface
/// bias (6 operations on a vector below a spacing, 6u), the biased point (u),
/// (biased − origin)/spacing (2u + 5u), the cage's base position (2u) and the
/// cell fraction (2u + 5u), each at most R in size: 23u, taken as 32u.
const POSITION_BACKWARD_REL: f32 = 32.0 * U;

/// The field's largest possible value: over members, π·c·(max e)² for the
/// brightest texel (what `SMOOTH_ERROR_REL` is relative to).
fn largest_value(view: &DdgiFieldSetView<'_>) -> f32 {
    view.members
        .iter()
        .map(|m| {
            let s = m.field.settings;
            let x = m.field.irradiance.texels.iter().fold(0f32, |a, t| a.max(t.max_element()));
            let e =
                probegi_core::irradiance_encoding::decode_irradiance_half(Vec3::splat(x), s.probe_irradiance_gamma).x;
            std::f32::consts::PI * s.probe_energy_conservation * e * e
        })
        .fold(1e-6, f32::max)
}

/// `view` with every member's distance atlas replaced by `atlases`'.
fn with_distances<'b>(view: &DdgiFieldSetView<'b>, atlases: &'b [ProbeAtlas<Vec2>]) -> DdgiFieldSetView<'b> {
    DdgiFieldSetView {
        members: view
            .members
            .iter()
            .zip(atlases)
            .map(|(m, d)| SetMember { field: DdgiFieldView { distance: d, ..m.field }, ..*m })
            .collect(),
        blending: view.blending,
        camera_m: view.camera_m,
    }
}

/// The CPU query's own spread under the device's backward errors: the largest
/// change (over channels) when m₁, m₂ (each uniformly and tile by tile) or
/// one position coordinate moves by its backward error either way, summed over
/// those seven groups. The device's
/// answer differs from the CPU's by at most twice it (each side within it of
/// the exact one on the unrounded inputs) beyond the smooth rounding.
struct Sensitivity<'a> {
    /// The view with m₁ moved up and down, uniformly then tile by tile, then m₂
    /// likewise: pairs of opposite moves.
    moved_moments: [DdgiFieldSetView<'a>; 8],
    /// R: the largest corner coordinate of any member's grid.
    reach: f32,
}

impl Sensitivity<'_> {
    fn spread(&self, view: &DdgiFieldSetView<'_>, q: &QueryPoint, at: Vec3) -> f32 {
        let v = |a: [f32; 4]| Vec3::new(a[0], a[1], a[2]);
        let (p, n, d) = (v(q.position), v(q.normal), v(q.view_dir));
        let change = |e: Vec3| (e - at).abs().max_element();
        let moments: f32 = self
            .moved_moments
            .chunks(2)
            .map(|pair| pair.iter().map(|w| change(field_set_irradiance(w, p, n, d))).fold(0.0, f32::max))
            .sum();
        let beta = POSITION_BACKWARD_REL * self.reach.max(p.abs().max_element());
        let position: f32 = (0..3)
            .map(|axis| {
                [-beta, beta]
                    .iter()
                    .map(|b| change(field_set_irradiance(view, p + Vec3::AXES[axis] * *b, n, d)))
                    .fold(0.0, f32::max)
            })
            .sum();
        moments + position
    }
}

/// The CPU's answer at `pts` against the GPU's, each within its bound (module
/// docs); panics on a point outside it. The number of points beyond the smooth
/// bound must not exceed the number the CPU's own spread marks as ill-conditioned.
fn compare(ctx: &GpuContext, view: &DdgiFieldSetView<'_>, pts: &[QueryPoint]) {
    let field = GpuDdgiField::upload(ctx, view).expect("upload");
    let gpu = GpuFieldQuery::new(ctx).query(ctx, &field, pts).expect("query");
    let v = |a: [f32; 4]| Vec3::new(a[0], a[1], a[2]);
    let cpu: Vec<Vec3> =
        pts.iter().map(|q| field_set_irradiance(view, v(q.position), v(q.normal), v(q.view_dir))).collect();
    let lit = cpu.iter().filter(|e| e.max_element() > 0.0).count();
    assert!(lit > pts.len() / 2, "too few lit points to test: {lit}");
    assert!(gpu.iter().all(|e| e.is_finite()));

    assert!(
        view.members.iter().all(|m| m.field.settings.probe_irradiance_gamma == 5.0),
        "SMOOTH_ERROR_REL counts the γ = 5 decode only"
    );
    let scale = largest_value(view);
    let smooth = SMOOTH_ERROR_REL * scale;
    // m₁ then m₂, each moved by its backward error: all tiles one way, then each
    // tile a pseudo-random way (so that corners whose changes would cancel under
    // a uniform move are also tried), both signs of each.
    let moved: Vec<Vec<ProbeAtlas<Vec2>>> = [(0, false), (0, true), (1, false), (1, true)]
        .iter()
        .flat_map(|&(k, mixed)| [1.0, -1.0].map(|sign| (k, mixed, sign)))
        .map(|(k, mixed, sign)| {
            view.members
                .iter()
                .map(|m| {
                    let d = m.field.distance;
                    let tile = d.tile_len();
                    let texels = d
                        .texels
                        .iter()
                        .enumerate()
                        .map(|(i, t)| {
                            let flip = mixed && Pcg32::new(i as u64 / tile as u64, 5).next_u32() & 1 == 1;
                            let f = 1.0 + if flip { -sign } else { sign } * MOMENT_BACKWARD_REL[k];
                            if k == 0 { Vec2::new(t.x * f, t.y) } else { Vec2::new(t.x, t.y * f) }
                        })
                        .collect();
                    ProbeAtlas { texels, ..d.clone() }
                })
                .collect()
        })
        .collect();
    let reach = view
        .members
        .iter()
        .map(|m| {
            let g = m.field.grid;
            let far = g.origin_m + g.spacing_m * (g.probe_counts.as_vec3() - Vec3::ONE);
            g.origin_m.abs().max(far.abs()).max_element()
        })
        .fold(0.0, f32::max);
    let sensitivity = Sensitivity { moved_moments: std::array::from_fn(|i| with_distances(view, &moved[i])), reach };
    let (mut beyond_smooth, mut ill_conditioned, mut worst_share) = (0, 0, 0f32);
    for ((q, c), g) in pts.iter().zip(&cpu).zip(&gpu) {
        let diff = (*c - *g).abs().max_element();
        let spread = sensitivity.spread(view, q, *c);
        let bound = smooth + 2.0 * spread;
        ill_conditioned += usize::from(2.0 * spread > smooth);
        beyond_smooth += usize::from(diff > smooth);
        worst_share = worst_share.max(diff / bound);
        assert!(
            diff <= bound,
            "at {:?} (normal {:?}): GPU {g}, CPU {c}: {diff:e} > {smooth:e} + 2·{spread:e} (the CPU's own spread)",
            q.position,
            q.normal
        );
    }
    eprintln!(
        "{} points ({lit} lit), largest possible {scale:.3} W/m²: {beyond_smooth} beyond the smooth bound {:.2e} of it, \
         {ill_conditioned} ill-conditioned; worst difference {worst_share:.3} of its bound",
        pts.len(),
        SMOOTH_ERROR_REL
    );
    assert!(
        beyond_smooth <= ill_conditioned,
        "{beyond_smooth} points beyond the smooth bound, only {ill_conditioned} ill-conditioned ones"
    );
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
    compare(&ctx, &set.view(), &points(&scene, &tracer, 20_000));
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
    compare(&ctx, &set.view(), &pts);

    let (lo, hi) = scene.bounds().expect("geometry");
    let mid = (lo + hi) * 0.5;
    let dense = DdgiVolumeSettings {
        volume_bounds_m: Some([lo, Vec3::new(mid.x, hi.y, hi.z)]),
        ..small(UVec3::new(4, 6, 6), 64)
    };
    let density =
        DdgiFieldSetSettings { volumes: vec![small(UVec3::splat(4), 64), dense], blending: VolumeBlending::Density };
    let set = converged(&scene, &tracer, &density, None, 10);
    compare(&ctx, &set.view(), &pts);
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
    compare(&ctx, &view, &points(&scene, &tracer, 20_000));
}
