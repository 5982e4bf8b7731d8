// The shadowing field's passes on the device (seed 003 ch. 5; probegi_field's
// `ddgi_volume::shadow_rays` and probegi_core::shadow_field::blend_shadow_tile on the CPU):
//   generate_shadow_rays: one thread per slot (a probe's previous-frame ray × a
//     served light): a front-face hit casts a shadow ray toward the light from its
//     surfel (position + normal × 1e-4·(1 + max|p|)); a miss or back face is a free
//     sample (visible, the direction from the probe to the light) with an empty
//     ray; a surfel facing away from the light adds nothing (empty ray);
//   blend_shadow_maps: one workgroup per probe: each occlusion texel ω blends
//     Σ max(0, ω·l)·V / Σ max(0, ω·l) over the probe's slots with its hysteresis
//     (eq. 5.2–5.3), V = 1 when the (any-hit) shadow ray found nothing;
//   border_shadow_maps: the tiles' guard borders (probegi_core::probe_border).
// The occlusion maps live in the field's distance buffer (x of each vec2; y the
// texel's change in its last blend, for the ray budget), after the distance
// atlases (probegi_wgpu::ddgi_query::GpuDdgiVolume::shadow).
// Must match `probegi_wgpu::shadow_field::{ShadowParams, ShadowProbe}` (#[repr(C)],
// 32 bytes each) and the trace pass's `GpuRay` / `GpuRayHit`.

struct ShadowParams {
    entry_count: u32,
    light_count: u32,
    slot_count: u32,
    groups_x: u32,
    // Occlusion interior texels per side; the volume's first occlusion texel.
    interior: u32,
    occlusion_first: u32,
    // Front-face surfels farther than this from their probe cast no ray (0: all).
    surfel_reach_m: f32,
    _pad0: u32,
};

// One probe that blends this frame with rays from the previous frame.
struct ShadowProbe {
    prev_first_ray: u32,
    ray_count: u32,
    // Its storage slot in the volume (its occlusion tile).
    probe: u32,
    first_slot: u32,
    // Blend hysteresis (0 replaces the tile).
    hysteresis: f32,
    _pad0: u32,
    _pad1: u32,
    _pad2: u32,
};

struct ShadowRay {
    origin: vec3<f32>,
    t_min: f32,
    dir: vec3<f32>,
    t_max: f32,
};

struct ShadowHit {
    t: f32,
    triangle: u32,
    bary: vec2<f32>,
    instance: u32,
    _pad: u32,
};

@group(0) @binding(0) var<uniform> shadow_params: ShadowParams;
@group(0) @binding(1) var<storage, read> prev_rays: array<ShadowRay>;
@group(0) @binding(2) var<storage, read> prev_hits: array<ShadowHit>;
@group(0) @binding(3) var<storage, read> shadow_probes: array<ShadowProbe>;
// The served lights (xyz: position, or direction of travel when w's bits are 0),
// then the occlusion texels' unit directions (oct_decode of their centres).
@group(0) @binding(4) var<storage, read> shadow_lights: array<vec4<f32>>;
@group(0) @binding(5) var<storage, read_write> shadow_rays: array<ShadowRay>;
// Per slot: xyz the unit direction to the light, w's bits 0 none, 1 traced, 2 free.
@group(0) @binding(6) var<storage, read_write> shadow_slots: array<vec4<f32>>;
@group(0) @binding(7) var<storage, read> shadow_hits: array<ShadowHit>;
@group(0) @binding(8) var<storage, read_write> occlusion: array<vec2<f32>>;

const SHADOW_NONE: u32 = 0u;
const SHADOW_TRACED: u32 = 1u;
const SHADOW_FREE: u32 = 2u;

// The entry whose slots hold slot `j` (binary search over first slots).
fn shadow_entry_of(j: u32) -> u32 {
    var lo = 0u;
    var hi = shadow_params.entry_count;
    while (hi - lo > 1u) {
        let mid = (lo + hi) / 2u;
        if (shadow_probes[mid].first_slot <= j) { lo = mid; } else { hi = mid; }
    }
    return lo;
}

// Unit direction and distance from `origin` to light `k` (distance SCENE_F32_MAX
// for a directional light; w < 0 when there is none).
fn shadow_toward(k: u32, origin: vec3<f32>) -> vec4<f32> {
    let l = shadow_lights[k];
    if (bitcast<u32>(l.w) == 0u) {
        let d = l.xyz;
        let len = length(d);
        if (!(len > 0.0)) { return vec4<f32>(0.0, 0.0, 0.0, -1.0); }
        return vec4<f32>(-d / len, SCENE_F32_MAX);
    }
    let to = l.xyz - origin;
    let d = length(to);
    if (!(d > 0.0 && d <= SCENE_F32_MAX)) { return vec4<f32>(0.0, 0.0, 0.0, -1.0); }
    return vec4<f32>(to / d, d);
}

@compute @workgroup_size(64)
fn generate_shadow_rays(@builtin(workgroup_id) wid: vec3<u32>, @builtin(local_invocation_index) lid: u32) {
    let j = (wid.y * shadow_params.groups_x + wid.x) * 64u + lid;
    if (j >= shadow_params.slot_count || shadow_params.entry_count == 0u) {
        return;
    }
    let e = shadow_probes[shadow_entry_of(j)];
    let local = j - e.first_slot;
    let lights = shadow_params.light_count;
    let r = e.prev_first_ray + local / lights;
    let k = local % lights;
    let ray = prev_rays[r];
    let h = prev_hits[r];
    var out = ShadowRay(ray.origin, 0.0, vec3<f32>(0.0, 1.0, 0.0), 0.0);
    var slot = vec4<f32>(0.0, 0.0, 0.0, bitcast<f32>(SHADOW_NONE));
    let front = h.triangle != BVH_NO_HIT && (h.triangle & 0x80000000u) == 0u;
    if (!front) {
        let to = shadow_toward(k, ray.origin);
        if (to.w >= 0.0) {
            slot = vec4<f32>(to.xyz, bitcast<f32>(SHADOW_FREE));
        }
    } else if (shadow_params.surfel_reach_m <= 0.0 || h.t <= shadow_params.surfel_reach_m) {
        let sp = scene_surface_point(h.triangle, h.instance, h.bary, false);
        let n = scene_facing_normal(sp);
        let pos = ray.origin + ray.dir * h.t;
        let to = shadow_toward(k, pos);
        if (to.w >= 0.0 && dot(n, to.xyz) > 0.0) {
            let a = abs(pos);
            let eps = 1e-4 * (1.0 + max(max(a.x, a.y), a.z));
            var t_max = SCENE_F32_MAX;
            if (to.w < SCENE_F32_MAX) {
                t_max = to.w * (1.0 - 1e-4);
            }
            out = ShadowRay(pos + n * eps, 0.0, to.xyz, t_max);
            slot = vec4<f32>(to.xyz, bitcast<f32>(SHADOW_TRACED));
        }
    }
    shadow_rays[j] = out;
    shadow_slots[j] = slot;
}

// The entry (probe) workgroup `wid` blends or borders.
fn shadow_entry_index(wid: vec3<u32>) -> u32 {
    return wid.y * shadow_params.groups_x + wid.x;
}

// The first texel of entry `e`'s occlusion tile in `occlusion`.
fn shadow_tile_base(e: ShadowProbe) -> u32 {
    let side = shadow_params.interior + 2u;
    return shadow_params.occlusion_first + e.probe * side * side;
}

@compute @workgroup_size(64)
fn blend_shadow_maps(@builtin(workgroup_id) wid: vec3<u32>, @builtin(local_invocation_index) lid: u32) {
    let ei = shadow_entry_index(wid);
    if (ei >= shadow_params.entry_count) {
        return;
    }
    let e = shadow_probes[ei];
    let n = shadow_params.interior;
    let side = n + 2u;
    let slots = e.ray_count * shadow_params.light_count;
    let base = shadow_tile_base(e);
    for (var t = lid; t < n * n; t += 64u) {
        let omega = shadow_lights[shadow_params.light_count + t].xyz;
        var sum = 0.0;
        var wsum = 0.0;
        for (var s = 0u; s < slots; s++) {
            let slot = shadow_slots[e.first_slot + s];
            let kind = bitcast<u32>(slot.w);
            if (kind == SHADOW_NONE) {
                continue;
            }
            var visible = 1.0;
            if (kind == SHADOW_TRACED && shadow_hits[e.first_slot + s].triangle != BVH_NO_HIT) {
                visible = 0.0;
            }
            let w = max(dot(omega, slot.xyz), 0.0);
            sum += w * visible;
            wsum += w;
        }
        let i = t % n;
        let jj = t / n;
        let dst = base + (jj + 1u) * side + (i + 1u);
        if (!(wsum > 0.0)) {
            occlusion[dst].y = 0.0;
            continue;
        }
        let old = occlusion[dst].x;
        // y: the texel's change (probegi_core::shadow_field::blend_shadow_tile's).
        let change = abs(sum / wsum - old);
        let blended = (sum / wsum) * (1.0 - e.hysteresis) + old * e.hysteresis;
        if (blended >= -SCENE_F32_MAX && blended <= SCENE_F32_MAX) {
            occlusion[dst] = vec2<f32>(clamp(blended, 0.0, 1.0), change);
        } else {
            occlusion[dst].y = change;
        }
    }
}

@compute @workgroup_size(64)
fn border_shadow_maps(@builtin(workgroup_id) wid: vec3<u32>, @builtin(local_invocation_index) lid: u32) {
    let ei = shadow_entry_index(wid);
    if (ei >= shadow_params.entry_count) {
        return;
    }
    let e = shadow_probes[ei];
    let n = shadow_params.interior;
    let side = n + 2u;
    let base = shadow_tile_base(e);
    for (var t = lid; t < side * side; t += 64u) {
        let x = t % side;
        let y = t / side;
        if (is_border(x, y, n)) {
            let src = border_source(x, y, n);
            occlusion[base + y * side + x] = occlusion[base + src.y * side + src.x];
        }
    }
}
