// Blend and border passes of a DDGI volume (seed 003 §4.5, seed 004 §2.3, §4.2–4.3).
// Must match `probegi_wgpu::probe_blend::BlendParams` (#[repr(C)], 64 bytes) and the
// tile-major atlas layout of `probegi_core::probe_atlas` (tile side = interior + 2,
// row-major inside a tile, interior texel (i, j) at tile texel (i + 1, j + 1)).

struct BlendParams {
    probe_count: u32,
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
    probes_per_row: u32,       // dispatch: probe = wid.y + wid.z * probes_per_row
    _pad0: u32,
    _pad1: u32,
    _pad2: u32,
};

@group(0) @binding(0) var<uniform> params: BlendParams;
@group(0) @binding(1) var<storage, read> ray_dirs: array<vec4<f32>>;       // rays_per_probe
@group(0) @binding(2) var<storage, read> ray_radiance: array<vec4<f32>>;   // probes × rays
@group(0) @binding(3) var<storage, read> ray_distance: array<f32>;         // probes × rays, signed
@group(0) @binding(4) var<storage, read> probe_hysteresis: array<f32>;     // < 0: not updated
@group(0) @binding(5) var<storage, read_write> irradiance: array<vec4<f32>>;
@group(0) @binding(6) var<storage, read_write> distance: array<vec2<f32>>;

// probegi_core::probe_blend::BLEND_WEIGHT_EPSILON
const BLEND_WEIGHT_EPSILON: f32 = 1e-6;

fn sign_not_zero(v: vec2<f32>) -> vec2<f32> {
    return select(vec2<f32>(-1.0), vec2<f32>(1.0), v >= vec2<f32>(0.0));
}

// probegi_core::octahedral::oct_decode
fn oct_decode(uv: vec2<f32>) -> vec3<f32> {
    var d = vec3<f32>(uv.x, uv.y, 1.0 - abs(uv.x) - abs(uv.y));
    if (d.z < 0.0) {
        let xy = (vec2<f32>(1.0) - vec2<f32>(abs(d.y), abs(d.x))) * sign_not_zero(d.xy);
        d = vec3<f32>(xy, d.z);
    }
    return normalize(d);
}

// probegi_core::octahedral::texel_center_uv
fn texel_center_uv(i: u32, j: u32, n: u32) -> vec2<f32> {
    return vec2<f32>((f32(i) + 0.5) / f32(n), (f32(j) + 0.5) / f32(n)) * 2.0 - vec2<f32>(1.0);
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

fn probe_of(wid: vec3<u32>) -> u32 {
    return wid.y + wid.z * params.probes_per_row;
}

// One blend thread's texel: its probe, interior texel (i, j) and direction, and
// the probe's hysteresis; `valid` is false past the grid or for a probe that does
// not update this frame (hysteresis < 0).
struct TexelJob {
    valid: bool,
    probe: u32,
    n: u32,
    i: u32,
    j: u32,
    hysteresis: f32,
    dir: vec3<f32>,
};

fn interior_job(gid: vec3<u32>, wid: vec3<u32>, n: u32) -> TexelJob {
    var job: TexelJob;
    job.probe = probe_of(wid);
    job.n = n;
    job.valid = job.probe < params.probe_count && gid.x < n * n;
    if (!job.valid) { return job; }
    job.hysteresis = probe_hysteresis[job.probe];
    job.valid = job.hysteresis >= 0.0;
    job.i = gid.x % n;
    job.j = gid.x / n;
    job.dir = oct_decode(texel_center_uv(job.i, job.j, n));
    return job;
}

// probegi_core::probe_blend::blend_irradiance_tile, one thread per interior texel.
@compute @workgroup_size(64)
fn blend_irradiance(@builtin(global_invocation_id) gid: vec3<u32>, @builtin(workgroup_id) wid: vec3<u32>) {
    let job = interior_job(gid, wid, params.irradiance_interior);
    if (!job.valid) { return; }
    let probe = job.probe;
    let n = job.n;
    let h0 = job.hysteresis;
    let texel_dir = job.dir;
    var sum = vec3<f32>(0.0);
    var wsum = 0.0;
    let first = probe * params.rays_per_probe;
    for (var r = 0u; r < params.rays_per_probe; r++) {
        let c = dot(texel_dir, ray_dirs[r].xyz);
        if (c <= 0.0 || c < BLEND_WEIGHT_EPSILON) { continue; }
        let l = ray_radiance[first + r].xyz;
        if (is_finite3(l)) {
            sum += l * c;
            wsum += c;
        }
    }
    if (wsum <= 0.0) { return; }
    let encoded = encode_irradiance(sum / wsum, params.gamma);
    let idx = probe * (n + 2u) * (n + 2u) + interior_texel_index(n, job.i, job.j);
    let old = irradiance[idx].xyz;
    var h = h0 * params.irradiance_scale;
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
    let blended = encoded * (1.0 - h) + old * h;
    if (is_finite3(blended)) {
        irradiance[idx] = vec4<f32>(blended, 0.0);
    }
}

// probegi_core::probe_blend::blend_distance_tile, one thread per interior texel.
@compute @workgroup_size(64)
fn blend_distance(@builtin(global_invocation_id) gid: vec3<u32>, @builtin(workgroup_id) wid: vec3<u32>) {
    let job = interior_job(gid, wid, params.distance_interior);
    if (!job.valid) { return; }
    let probe = job.probe;
    let n = job.n;
    let h0 = job.hysteresis;
    let texel_dir = job.dir;
    var sum = vec2<f32>(0.0);
    var wsum = 0.0;
    let first = probe * params.rays_per_probe;
    for (var r = 0u; r < params.rays_per_probe; r++) {
        let c = dot(texel_dir, ray_dirs[r].xyz);
        if (c <= 0.0) { continue; }
        let w = pow(c, params.distance_exponent);
        if (w < BLEND_WEIGHT_EPSILON) { continue; }
        let d = min(abs(ray_distance[first + r]), params.distance_clamp_m);
        if (d != d) { continue; }
        sum += vec2<f32>(d, d * d) * w;
        wsum += w;
    }
    if (wsum <= 0.0) { return; }
    let idx = probe * (n + 2u) * (n + 2u) + interior_texel_index(n, job.i, job.j);
    let h = h0 * params.visibility_scale;
    let blended = (sum / wsum) * (1.0 - h) + distance[idx] * h;
    if (all(abs(blended) <= vec2<f32>(3.4028235e38))) {
        distance[idx] = blended;
    }
}

// probegi_core::probe_border::update_tile_border: border texel (x, y) of a tile
// with `n` interior texels copies its mirrored interior source.
fn border_source(x: u32, y: u32, n: u32) -> vec2<u32> {
    let last = n + 1u;
    if ((x == 0u || x == last) && (y == 0u || y == last)) {
        // Corners take the diagonally opposite interior corner.
        return vec2<u32>(select(1u, n, x == 0u), select(1u, n, y == 0u));
    }
    if (y == 0u) { return vec2<u32>(n + 1u - x, 1u); }
    if (y == last) { return vec2<u32>(n + 1u - x, n); }
    if (x == 0u) { return vec2<u32>(1u, n + 1u - y); }
    return vec2<u32>(n, n + 1u - y);
}

fn is_border(x: u32, y: u32, n: u32) -> bool {
    return x == 0u || y == 0u || x == n + 1u || y == n + 1u;
}

@compute @workgroup_size(64)
fn border_irradiance(@builtin(global_invocation_id) gid: vec3<u32>, @builtin(workgroup_id) wid: vec3<u32>) {
    let probe = probe_of(wid);
    let n = params.irradiance_interior;
    let s = n + 2u;
    if (probe >= params.probe_count || gid.x >= s * s || probe_hysteresis[probe] < 0.0) { return; }
    let x = gid.x % s;
    let y = gid.x / s;
    if (!is_border(x, y, n)) { return; }
    let src = border_source(x, y, n);
    let base = probe * s * s;
    irradiance[base + y * s + x] = irradiance[base + src.y * s + src.x];
}

@compute @workgroup_size(64)
fn border_distance(@builtin(global_invocation_id) gid: vec3<u32>, @builtin(workgroup_id) wid: vec3<u32>) {
    let probe = probe_of(wid);
    let n = params.distance_interior;
    let s = n + 2u;
    if (probe >= params.probe_count || gid.x >= s * s || probe_hysteresis[probe] < 0.0) { return; }
    let x = gid.x % s;
    let y = gid.x / s;
    if (!is_border(x, y, n)) { return; }
    let src = border_source(x, y, n);
    let base = probe * s * s;
    distance[base + y * s + x] = distance[base + src.y * s + src.x];
}
