// Blend and border passes of a DDGI volume (seed 003 §4.5, seed 004 §2.3, §4.2–4.3).
// Must match `probegi_wgpu::probe_blend::BlendParams` (#[repr(C)], 80 bytes) and the
// tile-major atlas layout of `probegi_core::probe_atlas` (tile side = interior + 2,
// row-major inside a tile, interior texel (i, j) at tile texel (i + 1, j + 1)).
// An irradiance texel's w holds its change in its last blend (the ray budget's
// signal, probegi_core::probe_change::texel_change; 0 where no ray weighs it),
// which probe_change.wgsl averages; queries read xyz only.

struct BlendParams {
    blend_count: u32,          // entries of probe_blend: the probes that blend this frame
    rays_per_probe: u32,
    irradiance_interior: u32,
    distance_interior: u32,
    gamma: f32,
    irradiance_scale: f32,     // scene-event reduction on irradiance hysteresis
    visibility_scale: f32,     // scene-event reduction on distance hysteresis
    use_thresholds: u32,
    significant: f32,          // Listing 3
    new_distribution: f32,     // Listing 3
    distance_exponent: f32,    // k_s of eq. 4.14
    distance_clamp_m: f32,
    probes_per_row: u32,       // dispatch: entry = wid.y + wid.z * probes_per_row
    irradiance_first: u32,     // the volume's first texel in the irradiance buffer
    distance_first: u32,       // the volume's first texel in the distance buffer
    weight_count: u32,         // u32s of blend_weights: texels × (1 + 2 × rays), texels = irradiance_interior² + distance_interior²
    firefly_clamp_ratio: f32,  // Timberdoodle PGI's firefly clamp; 0: off
    adaptive_hysteresis: u32,  // Timberdoodle PGI's adaptive per-texel hysteresis
    adaptive_tolerance: f32,   // the relative change its states tolerate
    hysteresis_cap: f32,       // the start-up ramp's cap on every probe's hysteresis
};

@group(0) @binding(0) var<uniform> params: BlendParams;
// The frame's sparse texel-to-ray weight tables, written by `blend_weights_table`
// from the frame's ray directions: per texel (the irradiance tile's, then the
// distance tile's; T in all) the entries of probegi_core::probe_blend::BlendWeights,
// max(0, ω·r)^k ≥ BLEND_WEIGHT_EPSILON in ray order. First the T entry counts,
// then from T the (ray, weight bits) pairs, entry e of texel t at pair e × T + t
// (neighbouring texel threads read neighbouring pairs).
@group(0) @binding(1) var<storage, read_write> blend_weights: array<u32>;
// Per batch ray: xyz radiance, w the signed blend distance (backfaces −0.2·t,
// misses the ray's max distance), as probe_shade.wgsl writes them.
@group(0) @binding(2) var<storage, read> ray_results: array<vec4<f32>>;
// Per probe that blends this frame, in probe order (params.blend_count entries):
// x its first ray in the batch, y the bits of its blend hysteresis, z the frames
// the blend stands for (a ray budget's; 1 otherwise), w the probe (its tile).
@group(0) @binding(3) var<storage, read> probe_blend: array<vec4<u32>>;
@group(0) @binding(4) var<storage, read_write> irradiance: array<vec4<f32>>;
@group(0) @binding(5) var<storage, read_write> distance: array<vec2<f32>>;
// One adaptive-hysteresis state per irradiance texel, indexed as `irradiance`
// (probegi_core::probe_blend::adaptive_texel_hysteresis; read and written only
// with params.adaptive_hysteresis).
@group(0) @binding(6) var<storage, read_write> texel_hysteresis: array<f32>;
// Every interior texel's unit direction (probegi_core::probe_blend::texel_directions):
// the irradiance tile's, then the distance tile's.
@group(0) @binding(7) var<storage, read> blend_texel_dirs: array<vec4<f32>>;
// The frame's unit ray directions, shared by every probe.
@group(0) @binding(8) var<storage, read> blend_ray_dirs: array<vec4<f32>>;

// One thread per texel: probegi_core::probe_blend::BlendWeights::new's entries
// for it, once a frame for every probe of the volume.
@compute @workgroup_size(64)
fn blend_weights_table(@builtin(global_invocation_id) gid: vec3<u32>, @builtin(num_workgroups) groups: vec3<u32>) {
    let t = gid.x + gid.y * groups.x * 64u;
    let ni2 = params.irradiance_interior * params.irradiance_interior;
    let texels = ni2 + params.distance_interior * params.distance_interior;
    if (t >= texels) { return; }
    let exponent = select(params.distance_exponent, 1.0, t < ni2);
    let d = blend_texel_dirs[t].xyz;
    var count = 0u;
    for (var r = 0u; r < params.rays_per_probe; r++) {
        let dir = blend_ray_dirs[r].xyz;
        // glam's Vec3::dot, in its order.
        let c = d.x * dir.x + d.y * dir.y + d.z * dir.z;
        if (c <= 0.0) { continue; }
        let w = select(pow(c, exponent), c, exponent == 1.0);
        if (w < BLEND_WEIGHT_EPSILON) { continue; }
        let k = texels + 2u * (count * texels + t);
        blend_weights[k] = r;
        blend_weights[k + 1u] = bitcast<u32>(w);
        count++;
    }
    blend_weights[t] = count;
}

// probegi_core::probe_atlas::interior_texel_index
fn interior_texel_index(interior: u32, i: u32, j: u32) -> u32 {
    return (j + 1u) * (interior + 2u) + i + 1u;
}

// probegi_core::irradiance_encoding::encode_irradiance
fn encode_irradiance(mean: vec3<f32>, gamma: f32) -> vec3<f32> {
    return pow(max(mean, vec3<f32>(0.0)), vec3<f32>(1.0 / gamma));
}

fn is_finite3(v: vec3<f32>) -> bool {
    // NaN fails every comparison; ±Inf exceeds the largest f32.
    return all(abs(v) <= vec3<f32>(3.4028235e38));
}

// The entry of probe_blend a workgroup serves.
fn entry_of(wid: vec3<u32>) -> u32 {
    return wid.y + wid.z * params.probes_per_row;
}

// Rays of a probe staged in workgroup memory by `blend_probe` (RTXGI's
// ProbeBlendingCS with RTXGI_DDGI_BLEND_SHARED_MEMORY): 16 bytes each, 8 KiB in
// all, half of WebGPU's guaranteed 16 KiB. A volume with more rays per probe
// reads them from ray_results (the branch is uniform: a volume's ray count).
const MAX_STAGED_RAYS: u32 = 512u;
var<workgroup> staged_rays: array<vec4<f32>, 512>;
var<workgroup> staged_probe: vec4<u32>;

// Ray r of the probe whose rays start at batch ray `first`: xyz radiance, w the
// signed blend distance.
fn probe_ray(first: u32, r: u32) -> vec4<f32> {
    if (params.rays_per_probe <= MAX_STAGED_RAYS) {
        return staged_rays[r];
    }
    return ray_results[first + r];
}

// One workgroup per blending probe (an entry of probe_blend): its rays staged once, then every interior texel of
// both atlases (irradiance first), 64 at a time. Each texel sums its weight
// table's entries in ray order, as the CPU sums its own table's.
@compute @workgroup_size(64)
fn blend_probe(@builtin(workgroup_id) wid: vec3<u32>, @builtin(local_invocation_index) lid: u32) {
    let entry = entry_of(wid);
    if (entry >= params.blend_count) { return; }
    if (lid == 0u) {
        staged_probe = probe_blend[entry];
    }
    // x its first ray, y its hysteresis bits, z its frames, w the probe.
    let pb = workgroupUniformLoad(&staged_probe);
    let probe = pb.w;
    let h0 = min(bitcast<f32>(pb.y), params.hysteresis_cap);
    if (params.rays_per_probe <= MAX_STAGED_RAYS) {
        for (var r = lid; r < params.rays_per_probe; r += 64u) {
            staged_rays[r] = ray_results[pb.x + r];
        }
    }
    workgroupBarrier();
    let ni2 = params.irradiance_interior * params.irradiance_interior;
    let total = ni2 + params.distance_interior * params.distance_interior;
    for (var t = lid; t < total; t += 64u) {
        if (t < ni2) {
            blend_irradiance_texel(probe, pb.x, h0, pb.z, t);
        } else {
            blend_distance_texel(probe, pb.x, h0, pb.z, t - ni2);
        }
    }
}

// probegi_core::probe_blend::blend_irradiance_tile for row-major interior texel
// `texel` of `probe` (rays from `first`, hysteresis h0 over `frames` frames).
fn blend_irradiance_texel(probe: u32, first: u32, h0: f32, frames: u32, texel: u32) {
    let n = params.irradiance_interior;
    var sum = vec3<f32>(0.0);
    var wsum = 0.0;
    let texels = n * n + params.distance_interior * params.distance_interior;
    for (var e = 0u; e < blend_weights[texel]; e++) {
        let k = texels + 2u * (e * texels + texel);
        let w = bitcast<f32>(blend_weights[k + 1u]);
        let l = probe_ray(first, blend_weights[k]).xyz;
        if (is_finite3(l)) {
            sum += l * w;
            wsum += w;
        }
    }
    let idx = params.irradiance_first + probe * (n + 2u) * (n + 2u) + interior_texel_index(n, texel % n, texel / n);
    if (wsum <= 0.0) {
        irradiance[idx].w = 0.0;
        return;
    }
    let old = irradiance[idx].xyz;
    let planned = h0 * params.irradiance_scale;
    var encoded = encode_irradiance(sum / wsum, params.gamma);
    if (planned > 0.0 && params.firefly_clamp_ratio > 0.0) {
        encoded = firefly_clamp(encoded, old);
    }
    var h = planned;
    if (params.use_thresholds != 0u) {
        // probegi_core::probe_blend::adjusted_hysteresis (seed 004 Listing 3)
        let e = encoded - old;
        let change = abs(max(max(e.x, e.y), e.z));
        if (change > params.new_distribution) {
            h = 0.0;
        } else if (change > params.significant) {
            h = max(h - 0.15, 0.0);
        }
    }
    if (params.adaptive_hysteresis != 0u) {
        let state = adaptive_texel_hysteresis(texel_hysteresis[idx], planned, old, encoded);
        texel_hysteresis[idx] = state;
        h = min(h, state);
    }
    h = hysteresis_over_frames(h, frames);
    let blended = encoded * (1.0 - h) + old * h;
    let change = texel_change(old, encoded);
    if (is_finite3(blended)) {
        irradiance[idx] = vec4<f32>(blended, change);
    } else {
        irradiance[idx].w = change;
    }
}

fn max3(v: vec3<f32>) -> f32 {
    return max(max(v.x, v.y), v.z);
}

// probegi_core::probe_blend::firefly_clamp: the estimate scaled so that its largest
// linear component is at most firefly_clamp_ratio × the history's (encoded values).
fn firefly_clamp(encoded: vec3<f32>, history: vec3<f32>) -> vec3<f32> {
    let old = max3(history);
    let new_max = max3(encoded);
    if (!(old > 0.0)) { return encoded; }
    let limit = old * pow(params.firefly_clamp_ratio, 1.0 / params.gamma);
    if (new_max > limit) { return encoded * (limit / new_max); }
    return encoded;
}

// probegi_core::probe_blend::adaptive_texel_hysteresis: + ADAPTIVE_HYSTERESIS_RISE a
// blend, − the relative change beyond the tolerance, within [0, 1]; 0 where the
// history restarts.
fn adaptive_texel_hysteresis(state: f32, planned: f32, history: vec3<f32>, encoded: vec3<f32>) -> f32 {
    if (!(planned > 0.0)) { return 0.0; }
    let relative = max3(abs(encoded - history)) / (max(max3(history), 0.0) + ADAPTIVE_HYSTERESIS_FLOOR);
    let next = state + ADAPTIVE_HYSTERESIS_RISE - max(relative - params.adaptive_tolerance, 0.0);
    if (!(abs(next) <= 3.4028235e38)) { return 0.0; }
    return clamp(next, 0.0, 1.0);
}

// probegi_core::probe_blend::hysteresis_over_frames: h^frames by repeated multiplication.
fn hysteresis_over_frames(h: f32, frames: u32) -> f32 {
    var hk = h;
    for (var i = 1u; i < frames; i++) {
        hk *= h;
    }
    return hk;
}

// probegi_core::probe_change::ycocg
fn ycocg(c: vec3<f32>) -> vec3<f32> {
    return vec3<f32>(0.25 * c.x + 0.5 * c.y + 0.25 * c.z, 0.5 * c.x - 0.5 * c.z, -0.25 * c.x + 0.5 * c.y - 0.25 * c.z);
}

// probegi_core::probe_change::texel_change: SMAPE of the YCoCg vectors, in [0, 1].
fn texel_change(history: vec3<f32>, estimate: vec3<f32>) -> f32 {
    let a = ycocg(history);
    let b = ycocg(estimate);
    let s = abs(a) + abs(b);
    let den = s.x + s.y + s.z;
    if (!(den > 0.0)) { return 0.0; }
    let d = abs(a - b);
    return min((d.x + d.y + d.z) / den, 1.0);
}

// probegi_core::probe_blend::blend_distance_tile for row-major interior texel
// `texel` of `probe` (see blend_irradiance_texel).
fn blend_distance_texel(probe: u32, first: u32, h0: f32, frames: u32, texel: u32) {
    let n = params.distance_interior;
    var sum = vec2<f32>(0.0);
    var wsum = 0.0;
    let ni2 = params.irradiance_interior * params.irradiance_interior;
    let texels = ni2 + n * n;
    let t = ni2 + texel;
    for (var e = 0u; e < blend_weights[t]; e++) {
        let k = texels + 2u * (e * texels + t);
        let w = bitcast<f32>(blend_weights[k + 1u]);
        let signed = probe_ray(first, blend_weights[k]).w;
        if (signed != signed) { continue; } // NaN before min, which may drop it
        let d = min(abs(signed), params.distance_clamp_m);
        sum += vec2<f32>(d, d * d) * w;
        wsum += w;
    }
    if (wsum <= 0.0) { return; }
    let idx = params.distance_first + probe * (n + 2u) * (n + 2u) + interior_texel_index(n, texel % n, texel / n);
    let h = hysteresis_over_frames(h0 * params.visibility_scale, frames);
    let blended = (sum / wsum) * (1.0 - h) + distance[idx] * h;
    if (all(abs(blended) <= vec2<f32>(3.4028235e38))) {
        distance[idx] = blended;
    }
}

@compute @workgroup_size(64)
fn border_irradiance(@builtin(global_invocation_id) gid: vec3<u32>, @builtin(workgroup_id) wid: vec3<u32>) {
    let entry = entry_of(wid);
    let n = params.irradiance_interior;
    let s = n + 2u;
    if (entry >= params.blend_count || gid.x >= s * s) { return; }
    let probe = probe_blend[entry].w;
    let x = gid.x % s;
    let y = gid.x / s;
    if (!is_border(x, y, n)) { return; }
    let src = border_source(x, y, n);
    let base = params.irradiance_first + probe * s * s;
    irradiance[base + y * s + x] = irradiance[base + src.y * s + src.x];
}

@compute @workgroup_size(64)
fn border_distance(@builtin(global_invocation_id) gid: vec3<u32>, @builtin(workgroup_id) wid: vec3<u32>) {
    let entry = entry_of(wid);
    let n = params.distance_interior;
    let s = n + 2u;
    if (entry >= params.blend_count || gid.x >= s * s) { return; }
    let probe = probe_blend[entry].w;
    let x = gid.x % s;
    let y = gid.x / s;
    if (!is_border(x, y, n)) { return; }
    let src = border_source(x, y, n);
    let base = params.distance_first + probe * s * s;
    distance[base + y * s + x] = distance[base + src.y * s + src.x];
}
