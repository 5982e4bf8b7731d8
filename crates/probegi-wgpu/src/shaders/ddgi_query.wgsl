// The DDGI query in WGSL: irradiance at a world position and normal from a set of
// DDGI volumes, for any shader to include (an engine's fragment or compute shader,
// probegi's own passes). It mirrors, function by function:
//   probegi_core::ddgi_query::irradiance         (seed 003 §4.4 eq. 4.4–4.10, seed 004 §2.2 eq. 2, §4.1–4.2),
//   probegi_core::ddgi_query::surface_bias       (seed 004 eq. 2 / seed 003 eq. 4.11),
//   probegi_core::ddgi_query::{chebyshev_weight, backface_weight},
//   probegi_core::ddgi_volume_blend::{volume_blend_weight, cascade_field_weight, member_weight,
//                                      field_set_irradiance}
//                                                 (seed 004 §7.4, seed 003 §6.2 Algorithms 1–2),
//   probegi_core::probe_grid::{ProbeGrid::probe_index, ProbeGrid::cage} (circular tracking windows),
//   probegi_core::probe_atlas::BilinearFootprint, probegi_core::octahedral::oct_encode,
//   probegi_core::irradiance_encoding::{decode_irradiance_half, finish_half_decode} (seed 004 Listing 2),
//   probegi_core::shadow_field::shadow_visibility and DdgiFieldSet::shadow_visibility (seed 003 §5.2).
//
// Its weight floors (BACKFACE_WEIGHT_FLOOR, CHEBYSHEV_WEIGHT_FLOOR, MIN_PROBE_WEIGHT,
// TRILINEAR_WEIGHT_FLOOR) are the constants prelude's, generated from probegi_core::ddgi_query.
// Bind-group layout (group DDGI_GROUP: `probegi_wgpu::shader_registry` fills it with 2 in
// probegi's passes, `probegi_wgpu::ddgi_query::query_wgsl` with an engine's), all read-only storage buffers written by `probegi_wgpu::ddgi_query::GpuDdgiField`:
//   @binding(0) ddgi_set:        DdgiSet (header, camera, one DdgiVolume per member in sampling order)
//   @binding(1) ddgi_irradiance_atlas: array<vec4<f32>>, every member's irradiance atlas, tile-major
//                                (probegi_core::probe_atlas layout), xyz = γ-encoded mean radiance
//   @binding(2) ddgi_distance_atlas:   array<vec2<f32>>, every member's (mean, mean²) distance atlas,
//                                then every shadowing-field member's occlusion maps (x = visibility)
//   @binding(3) ddgi_probes:     array<vec4<f32>>, per probe: relocation offset xyz (m), w = bits:
//                                31 = usable by queries, 0..30 = nearest usable probe (0x7fffffff: none)
// Entry: `ddgi_irradiance(position, normal, view_dir) -> vec3<f32>` in W/m²; shade with albedo/π.
// Entry: `ddgi_shadow_visibility(position, normal, view_dir, dir_to_light) -> f32`, a punctual
// light's visibility in [0, 1] from the shadowing field, or −1 where no member has one.

struct DdgiVolume {
    origin_m: vec4<f32>,       // xyz probe (0,0,0) before scrolling; w = min spacing (m)
    spacing_m: vec4<f32>,      // xyz; w = irradiance γ
    probe_counts: vec4<u32>,   // xyz; w = weight flags: 1 backface, 2 Chebyshev, 4 crush, 8 trilinear
    scroll_offsets: vec4<u32>, // xyz circular-buffer phase; w = bias mode: 0 none, 1 self-shadow, 2 normal
    texels: vec4<u32>,         // irradiance interior, distance interior, first irradiance texel, first distance texel
    params: vec4<f32>,         // self-shadow bias, normal bias (m), crush threshold, energy conservation
    extra: vec4<u32>,          // first probe in ddgi_probes, tracks the camera, 0, 0
    shadow: vec4<u32>,         // first occlusion texel in ddgi_distance_atlas, occlusion interior (0: none),
                               // sharpness (f32 bits), 0
};

struct DdgiSet {
    header: vec4<u32>,         // member count, blending (0 density, 1 cascades), has camera, 0
    camera_m: vec4<f32>,
    volumes: array<DdgiVolume>,
};

@group(DDGI_GROUP) @binding(0) var<storage, read> ddgi_set: DdgiSet;
@group(DDGI_GROUP) @binding(1) var<storage, read> ddgi_irradiance_atlas: array<vec4<f32>>;
@group(DDGI_GROUP) @binding(2) var<storage, read> ddgi_distance_atlas: array<vec2<f32>>;
@group(DDGI_GROUP) @binding(3) var<storage, read> ddgi_probes: array<vec4<f32>>;

const DDGI_PI: f32 = 3.14159265358979;
const DDGI_NO_PROBE: u32 = 0x7fffffffu;

fn ddgi_sign_not_zero(v: vec2<f32>) -> vec2<f32> {
    return select(vec2<f32>(-1.0), vec2<f32>(1.0), v >= vec2<f32>(0.0));
}

// probegi_core::octahedral::oct_encode (L1-normalised; any length).
fn ddgi_oct_encode(dir: vec3<f32>) -> vec2<f32> {
    let l1 = abs(dir.x) + abs(dir.y) + abs(dir.z);
    if (!(l1 > 0.0)) {
        return vec2<f32>(0.0);
    }
    let uv = dir.xy / l1;
    if (dir.z < 0.0) {
        return (vec2<f32>(1.0) - abs(uv.yx)) * ddgi_sign_not_zero(uv);
    }
    return uv;
}

// probegi_core::probe_grid::ProbeGrid::probe_index (storage slot of grid coordinates).
fn ddgi_probe_index(v: DdgiVolume, coords: vec3<u32>) -> u32 {
    let c = v.probe_counts.xyz;
    var s = coords + v.scroll_offsets.xyz;
    s = select(s, s - c, s >= c);
    return s.x + c.x * (s.y + c.y * s.z);
}

// probegi_core::probe_grid::ProbeGrid::probe_coords (inverse of ddgi_probe_index).
fn ddgi_probe_coords(v: DdgiVolume, index: u32) -> vec3<u32> {
    let c = v.probe_counts.xyz;
    let s = vec3<u32>(index % c.x, (index / c.x) % c.y, index / (c.x * c.y));
    let o = v.scroll_offsets.xyz;
    return select(s + c - o, s - o, s >= o);
}

// probegi_core::probe_atlas::BilinearFootprint: the four tile texels and weights at uv.
struct DdgiFootprint {
    i00: u32,
    side: u32,
    w: vec4<f32>,
};

fn ddgi_footprint(interior: u32, uv: vec2<f32>) -> DdgiFootprint {
    let side = interior + 2u;
    let n = f32(interior);
    let c = (clamp(uv, vec2<f32>(-1.0), vec2<f32>(1.0)) * 0.5 + vec2<f32>(0.5)) * n + vec2<f32>(0.5);
    let x0 = min(u32(c.x), side - 2u);
    let y0 = min(u32(c.y), side - 2u);
    let fx = clamp(c.x - f32(x0), 0.0, 1.0);
    let fy = clamp(c.y - f32(y0), 0.0, 1.0);
    return DdgiFootprint(y0 * side + x0, side, vec4<f32>((1.0 - fx) * (1.0 - fy), fx * (1.0 - fy), (1.0 - fx) * fy, fx * fy));
}

fn ddgi_sample_irradiance(f: DdgiFootprint, tile_base: u32) -> vec3<f32> {
    let b = tile_base + f.i00;
    return ddgi_irradiance_atlas[b].xyz * f.w.x + ddgi_irradiance_atlas[b + 1u].xyz * f.w.y
        + ddgi_irradiance_atlas[b + f.side].xyz * f.w.z + ddgi_irradiance_atlas[b + f.side + 1u].xyz * f.w.w;
}

fn ddgi_sample_distance(f: DdgiFootprint, tile_base: u32) -> vec2<f32> {
    let b = tile_base + f.i00;
    return ddgi_distance_atlas[b] * f.w.x + ddgi_distance_atlas[b + 1u] * f.w.y
        + ddgi_distance_atlas[b + f.side] * f.w.z + ddgi_distance_atlas[b + f.side + 1u] * f.w.w;
}

// probegi_core::ddgi_query::surface_bias.
fn ddgi_surface_bias(v: DdgiVolume, normal: vec3<f32>, view_dir: vec3<f32>) -> vec3<f32> {
    switch v.scroll_offsets.w {
        case 1u: { return (normal * 0.2 + view_dir * 0.8) * (0.75 * v.origin_m.w) * v.params.x; }
        case 2u: { return (normal * 0.8 + view_dir * 0.3) * v.params.y; }
        default: { return vec3<f32>(0.0); }
    }
}

// probegi_core::ddgi_query::chebyshev_weight (eq. 4.5–4.9, cubed).
fn ddgi_chebyshev_weight(moments: vec2<f32>, distance: f32) -> f32 {
    let mean = moments.x;
    if (distance <= mean) {
        return 1.0;
    }
    let variance = abs(moments.x * moments.x - moments.y);
    let d = distance - mean;
    let w = variance / (variance + d * d);
    return max(w * w * w, 0.0);
}

// probegi_core::ddgi_query::backface_weight (eq. 4.4 with RTXGI's 0.2 floor).
fn ddgi_backface_weight(dir_to_probe: vec3<f32>, normal: vec3<f32>) -> f32 {
    let wrap = (dot(dir_to_probe, normal) + 1.0) * 0.5;
    return wrap * wrap + BACKFACE_WEIGHT_FLOOR;
}

// probegi_core::irradiance_encoding::decode_irradiance_half (γ = 5: e²·√e exactly).
fn ddgi_decode_half(e: vec3<f32>, gamma: f32) -> vec3<f32> {
    let half = 0.5 * gamma;
    if (half == 2.5) {
        return e * e * sqrt(e);
    }
    return pow(e, vec3<f32>(half));
}

fn ddgi_normalize_or_zero(v: vec3<f32>) -> vec3<f32> {
    let l = length(v);
    if (l > 0.0 && l < 3.4028235e38) {
        return v / l;
    }
    return vec3<f32>(0.0);
}

// One cage corner's weight and half-decoded irradiance; `probe` may be the
// corner's fallback, at grid coordinates `coords`, weighted like the corner.
fn ddgi_weigh(v: DdgiVolume, position: vec3<f32>, normal: vec3<f32>, biased: vec3<f32>, alpha: vec3<f32>,
              corner: u32, probe: u32, coords: vec3<u32>, normal_texels: DdgiFootprint) -> vec4<f32> {
    let probe_pos = v.origin_m.xyz + v.spacing_m.xyz * vec3<f32>(coords) + ddgi_probes[v.extra.x + probe].xyz;
    let flags = v.probe_counts.w;
    var weight = 1.0;
    if ((flags & 1u) != 0u) {
        weight *= ddgi_backface_weight(ddgi_normalize_or_zero(probe_pos - position), normal);
    }
    if ((flags & 2u) != 0u) {
        let to_probe = probe_pos - biased;
        let dist = length(to_probe);
        let side = v.texels.y + 2u;
        let f = ddgi_footprint(v.texels.y, ddgi_oct_encode(-to_probe));
        let moments = ddgi_sample_distance(f, v.texels.w + probe * side * side);
        weight *= max(ddgi_chebyshev_weight(moments, dist), CHEBYSHEV_WEIGHT_FLOOR);
    }
    weight = max(weight, MIN_PROBE_WEIGHT);
    let c = v.params.z;
    if ((flags & 4u) != 0u && weight < c) {
        weight *= weight * weight / (c * c);
    }
    if ((flags & 8u) != 0u) {
        let o = vec3<f32>(f32(corner & 1u), f32((corner >> 1u) & 1u), f32((corner >> 2u) & 1u));
        let t = max((vec3<f32>(1.0) - alpha) * (vec3<f32>(1.0) - o) + alpha * o, vec3<f32>(TRILINEAR_WEIGHT_FLOOR));
        weight *= t.x * t.y * t.z;
    }
    let side = v.texels.x + 2u;
    let e = max(ddgi_sample_irradiance(normal_texels, v.texels.z + probe * side * side), vec3<f32>(0.0));
    return vec4<f32>(ddgi_decode_half(e, v.spacing_m.w), weight);
}

// ProbeGrid::cage: the base probe's grid coordinates (clamped into the grid),
// the largest coordinates, and the point's position across the cell.
struct DdgiCage {
    base: vec3<i32>,
    max_c: vec3<i32>,
    alpha: vec3<f32>,
};

fn ddgi_cage(v: DdgiVolume, biased: vec3<f32>) -> DdgiCage {
    let counts = vec3<i32>(v.probe_counts.xyz);
    let max_c = max(counts - vec3<i32>(1), vec3<i32>(0));
    let rel = (biased - v.origin_m.xyz) / v.spacing_m.xyz;
    let base = clamp(vec3<i32>(floor(rel)), vec3<i32>(0), max_c);
    let base_pos = v.origin_m.xyz + v.spacing_m.xyz * vec3<f32>(base);
    let alpha = clamp((biased - base_pos) / v.spacing_m.xyz, vec3<f32>(0.0), vec3<f32>(1.0));
    return DdgiCage(base, max_c, alpha);
}

// probegi_core::ddgi_query::irradiance for member `m`.
fn ddgi_volume_irradiance(m: u32, position: vec3<f32>, normal: vec3<f32>, view_dir: vec3<f32>) -> vec3<f32> {
    let v = ddgi_set.volumes[m];
    let biased = position + ddgi_surface_bias(v, normal, view_dir);
    let cage = ddgi_cage(v, biased);
    let base = cage.base;
    let max_c = cage.max_c;
    let alpha = cage.alpha;
    let normal_texels = ddgi_footprint(v.texels.x, ddgi_oct_encode(normal));

    var sum = vec3<f32>(0.0);
    var wsum = 0.0;
    for (var i = 0u; i < 8u; i++) {
        let o = vec3<i32>(i32(i & 1u), i32((i >> 1u) & 1u), i32((i >> 2u) & 1u));
        let coords = vec3<u32>(min(base + o, max_c));
        let probe = ddgi_probe_index(v, coords);
        let bits = bitcast<u32>(ddgi_probes[v.extra.x + probe].w);
        if ((bits & 0x80000000u) == 0u) {
            continue; // not usable by queries
        }
        let r = ddgi_weigh(v, position, normal, biased, alpha, i, probe, coords, normal_texels);
        sum += r.xyz * r.w;
        wsum += r.w;
    }
    if (!(wsum > 0.0 && wsum < 3.4028235e38)) {
        // No usable probe in the cage: each corner's nearest usable probe stands in.
        for (var i = 0u; i < 8u; i++) {
            let o = vec3<i32>(i32(i & 1u), i32((i >> 1u) & 1u), i32((i >> 2u) & 1u));
            let corner = ddgi_probe_index(v, vec3<u32>(min(base + o, max_c)));
            let q = bitcast<u32>(ddgi_probes[v.extra.x + corner].w) & DDGI_NO_PROBE;
            if (q != DDGI_NO_PROBE) {
                let r = ddgi_weigh(v, position, normal, biased, alpha, i, q, ddgi_probe_coords(v, q), normal_texels);
                sum += r.xyz * r.w;
                wsum += r.w;
            }
        }
    }
    if (!(wsum > 0.0 && wsum < 3.4028235e38)) {
        return vec3<f32>(0.0);
    }
    let h = sum / wsum;
    let e = h * h * DDGI_PI * v.params.w;
    if (all(abs(e) <= vec3<f32>(3.4028235e38))) {
        return e;
    }
    return vec3<f32>(0.0);
}

// probegi_core::ddgi_volume_blend::volume_blend_weight.
fn ddgi_volume_blend_weight(v: DdgiVolume, point: vec3<f32>, camera_aware: bool) -> f32 {
    let spacing = v.spacing_m.xyz;
    var half = spacing * (vec3<f32>(v.probe_counts.xyz) - vec3<f32>(1.0)) * 0.5;
    var centre = v.origin_m.xyz + half;
    if (camera_aware) {
        centre = ddgi_set.camera_m.xyz;
        half = max(half - spacing, vec3<f32>(0.0));
    }
    let outside = max(abs(point - centre) - half, vec3<f32>(0.0)) / spacing;
    let w = clamp(vec3<f32>(1.0) - outside, vec3<f32>(0.0), vec3<f32>(1.0));
    return w.x * w.y * w.z;
}

// probegi_core::ddgi_volume_blend::cascade_field_weight (Algorithm 1, far edge R − 2).
fn ddgi_cascade_field_weight(v: DdgiVolume, point: vec3<f32>) -> f32 {
    let a = (point - v.origin_m.xyz) / v.spacing_m.xyz;
    let r = vec3<f32>(v.probe_counts.xyz) - vec3<f32>(1.0);
    let w = clamp(min(a, r - a), vec3<f32>(0.0), vec3<f32>(1.0));
    return w.x * w.y * w.z;
}

// probegi_core::ddgi_volume_blend::member_weight: member `f`'s share at
// `position` by the set's scheme, given the weight `wsum` the members before it
// took (0 once they took it all).
fn ddgi_member_weight(f: u32, position: vec3<f32>, wsum: f32) -> f32 {
    let n = ddgi_set.header.x;
    if (wsum >= 1.0) {
        return 0.0;
    }
    let v = ddgi_set.volumes[f];
    var w = 0.0;
    if (ddgi_set.header.y == 0u) {
        let camera_aware = v.extra.y != 0u && f + 1u < n && ddgi_set.header.z != 0u;
        w = ddgi_volume_blend_weight(v, position, camera_aware);
    } else if (f + 1u < n || wsum > 0.9) {
        w = ddgi_cascade_field_weight(v, position);
    } else {
        w = 1.0;
    }
    if (!(w > 0.0)) {
        return 0.0;
    }
    return w * clamp(1.0 - wsum, 0.0, 1.0);
}

// probegi_core::ddgi_volume_blend::field_set_irradiance: irradiance (W/m²) at a
// surface point with unit `normal`; `view_dir` points from the surface to the viewer.
fn ddgi_irradiance(position: vec3<f32>, normal: vec3<f32>, view_dir: vec3<f32>) -> vec3<f32> {
    let n = ddgi_set.header.x;
    var sum = vec3<f32>(0.0);
    var wsum = 0.0;
    var only = vec3<f32>(0.0);
    var contributors = 0u;
    for (var f = 0u; f < n; f++) {
        if (wsum >= 1.0) {
            break;
        }
        let w = ddgi_member_weight(f, position, wsum);
        if (!(w > 0.0)) {
            continue;
        }
        let e = ddgi_volume_irradiance(f, position, normal, view_dir);
        sum += e * w;
        wsum += w;
        contributors += 1u;
        only = e;
    }
    if (contributors == 0u) {
        return vec3<f32>(0.0);
    }
    if (contributors == 1u) {
        return only;
    }
    return sum / wsum;
}

// probegi_core::shadow_field::ShadowCage: a point's cage in a shadowing-field
// member, weighed once (the cosine weight, the wrap weight where no probe faces
// the point, Chebyshev visibility, trilinear), then read per light.
struct DdgiShadowCage {
    // The member (ddgi_set.volumes index); DDGI_NO_PROBE: no cage.
    member: u32,
    probes: array<u32, 8>,
    // Normalised weights (0 for a corner without a probe).
    weights: array<f32, 8>,
};

// The cage of `position` in member `m`; member DDGI_NO_PROBE when no probe of
// the cage nor a fallback is usable.
fn ddgi_volume_shadow_cage(m: u32, position: vec3<f32>, normal: vec3<f32>, view_dir: vec3<f32>) -> DdgiShadowCage {
    let v = ddgi_set.volumes[m];
    var cage: DdgiShadowCage;
    cage.member = DDGI_NO_PROBE;
    let biased = position + ddgi_surface_bias(v, normal, view_dir);
    let grid_cage = ddgi_cage(v, biased);
    let base = grid_cage.base;
    let max_c = grid_cage.max_c;
    let alpha = grid_cage.alpha;
    let dist_side = v.texels.y + 2u;
    var cos_w: array<f32, 8>;
    var wrap_w: array<f32, 8>;
    var cos_wsum = 0.0;
    var wrap_wsum = 0.0;
    for (var i = 0u; i < 8u; i++) {
        cage.probes[i] = DDGI_NO_PROBE;
        cos_w[i] = 0.0;
        wrap_w[i] = 0.0;
        let o = vec3<i32>(i32(i & 1u), i32((i >> 1u) & 1u), i32((i >> 2u) & 1u));
        var coords = vec3<u32>(min(base + o, max_c));
        var probe = ddgi_probe_index(v, coords);
        let bits = bitcast<u32>(ddgi_probes[v.extra.x + probe].w);
        if ((bits & 0x80000000u) == 0u) {
            let q = bits & DDGI_NO_PROBE;
            if (q == DDGI_NO_PROBE) {
                continue;
            }
            probe = q;
            coords = ddgi_probe_coords(v, q);
        }
        let probe_pos = v.origin_m.xyz + v.spacing_m.xyz * vec3<f32>(coords) + ddgi_probes[v.extra.x + probe].xyz;
        let to_probe = probe_pos - biased;
        let f = ddgi_footprint(v.texels.y, ddgi_oct_encode(-to_probe));
        let moments = ddgi_sample_distance(f, v.texels.w + probe * dist_side * dist_side);
        let corner_f = vec3<f32>(o);
        let t = max((vec3<f32>(1.0) - alpha) * (vec3<f32>(1.0) - corner_f) + alpha * corner_f, vec3<f32>(TRILINEAR_WEIGHT_FLOOR));
        let w = max(ddgi_chebyshev_weight(moments, length(to_probe)), CHEBYSHEV_WEIGHT_FLOOR) * (t.x * t.y * t.z);
        let dir = ddgi_normalize_or_zero(probe_pos - position);
        cage.probes[i] = probe;
        cos_w[i] = max(dot(dir, normal), 0.0) * w;
        wrap_w[i] = ddgi_backface_weight(dir, normal) * w;
        cos_wsum += cos_w[i];
        wrap_wsum += wrap_w[i];
    }
    var use_cos = cos_wsum > 0.0;
    var wsum = select(wrap_wsum, cos_wsum, use_cos);
    if (!(wsum > 0.0 && wsum <= 3.4028235e38)) {
        return cage;
    }
    for (var i = 0u; i < 8u; i++) {
        cage.weights[i] = select(wrap_w[i], cos_w[i], use_cos) / wsum;
    }
    cage.member = m;
    return cage;
}

// ShadowCage::visibility: the light's visibility in [0, 1] toward `dir_to_light`, sharpened.
fn ddgi_shadow_cage_visibility(cage: DdgiShadowCage, dir_to_light: vec3<f32>) -> f32 {
    let v = ddgi_set.volumes[cage.member];
    let occ_side = v.shadow.y + 2u;
    let f = ddgi_footprint(v.shadow.y, ddgi_oct_encode(dir_to_light));
    var r = 0.0;
    for (var i = 0u; i < 8u; i++) {
        if (cage.probes[i] != DDGI_NO_PROBE && cage.weights[i] > 0.0) {
            let occ = ddgi_sample_distance(f, v.shadow.x + cage.probes[i] * occ_side * occ_side).x;
            r += cage.weights[i] * clamp(occ, 0.0, 1.0);
        }
    }
    if (!(r >= 0.0 && r <= 3.4028235e38)) {
        return 1.0;
    }
    return pow(clamp(r, 0.0, 1.0), max(bitcast<f32>(v.shadow.z), 0.0));
}

// DdgiFieldSet::shadow_cage: the cage in the first member in sampling order
// with a shadowing field that weighs the point (its probe box and one cell
// around it) and has a usable probe; member DDGI_NO_PROBE where none does.
fn ddgi_shadow_cage(position: vec3<f32>, normal: vec3<f32>, view_dir: vec3<f32>) -> DdgiShadowCage {
    var none: DdgiShadowCage;
    none.member = DDGI_NO_PROBE;
    let n = ddgi_set.header.x;
    for (var m = 0u; m < n; m++) {
        let v = ddgi_set.volumes[m];
        if (v.shadow.y == 0u || ddgi_volume_blend_weight(v, position, false) <= 0.0) {
            continue;
        }
        let cage = ddgi_volume_shadow_cage(m, position, normal, view_dir);
        if (cage.member != DDGI_NO_PROBE) {
            return cage;
        }
    }
    return none;
}

// A punctual light's visibility in [0, 1] from the shadowing field, −1 where no
// member has one at the point (one light; a point lit by several weighs its
// cage once with ddgi_shadow_cage).
fn ddgi_shadow_visibility(position: vec3<f32>, normal: vec3<f32>, view_dir: vec3<f32>,
                          dir_to_light: vec3<f32>) -> f32 {
    let cage = ddgi_shadow_cage(position, normal, view_dir);
    if (cage.member == DDGI_NO_PROBE) {
        return -1.0;
    }
    return ddgi_shadow_cage_visibility(cage, dir_to_light);
}
