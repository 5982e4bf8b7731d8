// Shade pass of the probe rays (probegi_cpu::probe_shade::shade_probe_rays; seed 000
// §3, seed 003 §4.4, seed 004 §4.1, §4.4): one thread per batch ray, over the
// trace pass's hits. Misses take the constant sky (none of a sky map's, which the hits sample); back faces give zero (the set's rule
// turns their distance into −0.2·t); front faces get direct light (scene.wgsl)
// plus diffuse albedo/π × the set's previous irradiance (ddgi_query.wgsl at group
// 2), plus with second-order glossy the hit's specular reflection of the field.
// No emission (see probe_shade.rs on the CPU: emitters are sampled as area lights).
// Must match `probegi_wgpu::probe_shade::ShadeParams` (#[repr(C)], 32 bytes),
// `ShadeProbe` (16 bytes) and the trace pass's `GpuRay` / `GpuRayHit`.

struct ShadeParams {
    ray_count: u32,
    groups_x: u32,
    seed: u32,
    frame: u32,
    probe_count: u32,
    _pad0: u32,
    _pad1: u32,
    _pad2: u32,
};

// One probe's rays and how to shade them: per probe, not per ray, so the host
// uploads O(probes) a frame.
struct ShadeProbe {
    first_ray: u32,
    ray_count: u32,
    info: u32,
    hit_ao_radius_m: f32, // probe_hit_ao's ray length; 0: off
};

struct ShadeRay {
    origin: vec3<f32>,
    t_min: f32,
    dir: vec3<f32>,
    t_max: f32,
};

struct ShadeHit {
    t: f32,
    triangle: u32,
    bary: vec2<f32>,
    instance: u32,
    _pad: u32,
};

@group(0) @binding(0) var<uniform> shade_params: ShadeParams;
@group(0) @binding(1) var<storage, read> shade_rays: array<ShadeRay>;
@group(0) @binding(2) var<storage, read> shade_hits: array<ShadeHit>;
// Per probe, sorted by first_ray: its rays and its `info`: bit 31 the set wants
// their radiance, bit 30 second-order glossy, bit 29 punctual lights through the
// shadowing field (shadow_lighting.wgsl), bits 16..27 sky-map samples, bits 0..15 area samples.
// Output per ray: xyz radiance, w the blend's signed distance (probe_blend.wgsl's ray_results).
@group(0) @binding(3) var<storage, read> shade_probes: array<ShadeProbe>;
@group(0) @binding(4) var<storage, read_write> shade_radiance: array<vec4<f32>>;
// Per probe record k, bit k % 32 of word k / 32: the set wants its rays'
// radiance (ORed into `info`'s bit 31). Apart from the records, which stay
// while a kept plan's flags move (probe_shade.rs, `ShadeProbes`).
@group(0) @binding(5) var<storage, read> shade_probe_radiance: array<u32>;

// The shading record of ray i: its probe's (a binary search over the probes'
// first rays), all 0 for a ray no probe holds.
fn ray_shade_probe(i: u32) -> ShadeProbe {
    var lo = 0u;
    var hi = shade_params.probe_count;
    // The last probe whose first ray is at or before i lies in [lo, hi).
    while (hi - lo > 1u) {
        let mid = (lo + hi) / 2u;
        if (shade_probes[mid].first_ray <= i) {
            lo = mid;
        } else {
            hi = mid;
        }
    }
    let none = ShadeProbe(0u, 0u, 0u, 0.0);
    if (shade_params.probe_count == 0u) {
        return none;
    }
    var p = shade_probes[lo];
    if (i < p.first_ray || i - p.first_ray >= p.ray_count) {
        return none;
    }
    if (((shade_probe_radiance[lo / 32u] >> (lo % 32u)) & 1u) != 0u) {
        p.info = p.info | 0x80000000u;
    }
    return p;
}

// probegi_cpu::probe_shade::hit_ao: 1 when one cosine-distributed ray around the
// facing normal leaves the hit unoccluded for radius_m, else 0 (two draws after
// the direct light's).
fn probe_hit_ao(sp: SurfacePoint, radius_m: f32, rng: ptr<function, u32>) -> f32 {
    let hit = bvh_trace(probe_hit_ao_ray(sp, radius_m, rng), true);
    return select(0.0, 1.0, hit.leaf == BVH_NO_HIT);
}

// probegi_cpu::probe_shade::hit_ao_ray: the hit AO's cosine-distributed ray
// around the facing normal (two draws), radius_m long.
fn probe_hit_ao_ray(sp: SurfacePoint, radius_m: f32, rng: ptr<function, u32>) -> BvhRay {
    let u = vec2<f32>(rng_next(rng), rng_next(rng));
    let wi = frame_to_world(frame_from_normal(scene_facing_normal(sp)), sample_cosine_hemisphere(u));
    return bvh_make_ray(scene_spawn_origin(sp, wi), wi, 0.0, radius_m * (1.0 - 1e-4));
}

// probegi_cpu::probe_shade::hit_ao_irradiance with near_field: the field's
// irradiance `field_e` when the AO ray escapes; π × the occluder's radiance
// toward the hit (its direct light, emission and field term, as this pass
// shades a hit) when it hits a front face within radius_m; zero on a back face.
fn probe_hit_ao_near_field(sp: SurfacePoint, field_e: vec3<f32>, radius_m: f32, info: u32, rng: ptr<function, u32>) -> vec3<f32> {
    let ray = probe_hit_ao_ray(sp, radius_m, rng);
    let hit = bvh_trace(ray, false);
    if (hit.leaf == BVH_NO_HIT) {
        return field_e;
    }
    if (hit.backface) {
        return vec3<f32>(0.0);
    }
    let q = scene_surface_point(bvh_triangle_id(hit.leaf), hit.instance, hit.bary, false);
    let wo = -ray.dir;
    // Shadow rays for the occluder's lights, as the CPU's twin (not the shadowing field).
    var l = shadow_lit_direct(q, wo, info & 0xffffu, true, false, rng);
    l += scene_sky_direct(q, (info >> 16u) & SHADE_SKY_SAMPLES_MAX, rng);
    let e_q = ddgi_irradiance(q.position, scene_facing_normal(q), wo);
    l += bsdf_diffuse_albedo(scene_bsdf(q)) / SCENE_PI * e_q;
    return SCENE_PI * l;
}

@compute @workgroup_size(64)
fn shade_probe_rays(@builtin(workgroup_id) wid: vec3<u32>, @builtin(local_invocation_index) lid: u32) {
    let i = (wid.y * shade_params.groups_x + wid.x) * 64u + lid;
    if (i >= shade_params.ray_count) {
        return;
    }
    let probe = ray_shade_probe(i);
    let info = probe.info;
    let h = shade_hits[i];
    let r = shade_rays[i];
    let back = (h.triangle & 0x80000000u) != 0u && h.triangle != BVH_NO_HIT;
    // w: the blend's signed distance (probegi_cpu::ddgi::blend_inputs: a backface
    // −0.2·t, seed 004 §4.1; a miss the ray's max distance).
    var d = h.t;
    if (h.triangle == BVH_NO_HIT) {
        d = r.t_max;
    } else if (back) {
        d = -BACKFACE_DISTANCE_SCALE * h.t;
    }
    if ((info & 0x80000000u) == 0u || back) {
        shade_radiance[i] = vec4<f32>(0.0, 0.0, 0.0, d);
        return;
    }
    if (h.triangle == BVH_NO_HIT) {
        var sky = scene_sky_on_probe_miss(r.dir);
        if ((info & SHADE_SKY_MAP_ON_MISS) != 0u) {
            sky = scene_sky(r.dir);
        }
        shade_radiance[i] = vec4<f32>(sky, d);
        return;
    }
    let sp = scene_surface_point(h.triangle, h.instance, h.bary, false);
    var rng = rng_hash(shade_params.seed ^ rng_hash(shade_params.frame ^ rng_hash(i)));
    let to_viewer = -r.dir;
    let n = scene_facing_normal(sp);
    var l = shadow_lit_direct(sp, to_viewer, info & 0xffffu, true, (info & 0x20000000u) != 0u, &rng);
    l += scene_sky_direct(sp, (info >> 16u) & SHADE_SKY_SAMPLES_MAX, &rng);
    var e = ddgi_irradiance(sp.position, n, to_viewer);
    if (probe.hit_ao_radius_m > 0.0) {
        if ((info & SHADE_HIT_AO_NEAR_FIELD) != 0u) {
            e = probe_hit_ao_near_field(sp, e, probe.hit_ao_radius_m, info, &rng);
        } else {
            e *= probe_hit_ao(sp, probe.hit_ao_radius_m, &rng);
        }
    }
    let bsdf = scene_bsdf(sp);
    l += bsdf_diffuse_albedo(bsdf) / SCENE_PI * e;
    if ((info & 0x40000000u) != 0u && max(max(bsdf.specular_f0.x, bsdf.specular_f0.y), bsdf.specular_f0.z) > 0.0) {
        // probegi_cpu::glossy::second_order_specular
        let mirror = r.dir - n * (2.0 * dot(r.dir, n));
        let e_mirror = ddgi_irradiance(sp.position, mirror, to_viewer);
        l += bsdf_specular_albedo(bsdf.specular_f0, max(dot(to_viewer, n), 0.0), bsdf.alpha) * e_mirror / SCENE_PI;
    }
    if (all(abs(l) <= vec3<f32>(SCENE_F32_MAX))) {
        shade_radiance[i] = vec4<f32>(l, d);
    } else {
        shade_radiance[i] = vec4<f32>(vec3<f32>(bitcast<f32>(0x7fc00000u)), d);
    }
}
