// Seeding new probes (probegi_field::probe_seeding, the host's twin): each seed
// fills one scrolled-in probe's irradiance and distance tiles, borders included,
// with the weighted mix of up to eight source tiles of another volume of the
// resident field (texel for texel: the volumes share tile sizes). Each source's
// trilinear weight is multiplied by its Chebyshev visibility of the seeded
// position (ddgi_query.wgsl's ddgi_chebyshev_weight, from the nearest interior
// distance texel toward it: probegi_field::probe_seeding::seed_weights); where no
// source sees it the trilinear weights apply. Irradiance is
// mixed as decoded mean radiance (e^gamma) and re-encoded (e^(1/gamma)), w left
// 0; distance moments are mixed as they are. Sources are usable probes and
// targets reset ones, so no thread reads a texel another writes.
// Must match `probegi_wgpu::probe_seeding::SeedEntry` (#[repr(C)], 272 bytes)
// and `SeedParams` (16 bytes). Composed after ddgi_query.wgsl, whose helpers it
// calls (none of its bindings).

struct SeedParams {
    seed_count: u32,
    groups_x: u32,
    _pad0: u32,
    _pad1: u32,
};

struct SeedEntry {
    // First irradiance texel, first distance texel, irradiance and distance tile lengths.
    dest: vec4<u32>,
    // The eight sources' first irradiance texels, then their first distance texels.
    source_irradiance: array<vec4<u32>, 2>,
    source_distance: array<vec4<u32>, 2>,
    // The eight weights (0: unused), summing to 1.
    weights: array<vec4<f32>, 2>,
    // x: the irradiance gamma; y: the distance tiles' interior texels per side.
    encoding: vec4<f32>,
    // The seeded probe's position (xyz), metres.
    position: vec4<f32>,
    // The sources' positions (xyz), metres.
    source_positions: array<vec4<f32>, 8>,
};

// probegi_field::probe_seeding::nearest_texel: the bordered-tile index of the
// interior texel of an n × n map that holds direction `dir`.
fn seed_nearest_texel(dir: vec3<f32>, n: u32) -> u32 {
    let uv = ddgi_oct_encode(dir) * 0.5 + vec2<f32>(0.5);
    let top = f32(n) - 1.0;
    let x = u32(clamp(floor(uv.x * f32(n)), 0.0, top));
    let y = u32(clamp(floor(uv.y * f32(n)), 0.0, top));
    return (y + 1u) * (n + 2u) + x + 1u;
}

// probegi_field::probe_seeding::seed_weights.
fn seed_weights(e: SeedEntry) -> array<f32, 8> {
    var w: array<f32, 8>;
    var sum = 0.0;
    let n = u32(e.encoding.y);
    for (var i = 0u; i < 8u; i++) {
        let t = e.weights[i / 4u][i % 4u];
        w[i] = 0.0;
        if (t <= 0.0) { continue; }
        let to = e.position.xyz - e.source_positions[i].xyz;
        let d = length(to);
        var visible = 1.0;
        if (d > 1e-4) {
            let moments = distance[e.source_distance[i / 4u][i % 4u] + seed_nearest_texel(to / d, n)];
            visible = ddgi_chebyshev_weight(moments, d);
        }
        w[i] = t * visible;
        sum += w[i];
    }
    for (var i = 0u; i < 8u; i++) {
        if (sum < SEED_VISIBLE_WEIGHT_MIN) {
            w[i] = e.weights[i / 4u][i % 4u];
        } else {
            w[i] = w[i] / sum;
        }
    }
    return w;
}

@group(0) @binding(0) var<uniform> seed_params: SeedParams;
@group(0) @binding(1) var<storage, read> seeds: array<SeedEntry>;
@group(0) @binding(2) var<storage, read_write> irradiance: array<vec4<f32>>;
@group(0) @binding(3) var<storage, read_write> distance: array<vec2<f32>>;

// One thread per texel of one seed's tiles: x over texels, y over seeds.
@compute @workgroup_size(64)
fn seed_tiles(@builtin(workgroup_id) wid: vec3<u32>, @builtin(local_invocation_index) lid: u32) {
    let s = wid.y;
    if (s >= seed_params.seed_count) { return; }
    let t = wid.x * 64u + lid;
    let e = seeds[s];
    let gamma = e.encoding.x;
    let weights = seed_weights(e);
    if (t < e.dest.z) {
        var sum = vec3<f32>(0.0);
        for (var i = 0u; i < 8u; i++) {
            let w = weights[i];
            if (w > 0.0) {
                let v = max(irradiance[e.source_irradiance[i / 4u][i % 4u] + t].xyz, vec3<f32>(0.0));
                sum += w * pow(v, vec3<f32>(gamma));
            }
        }
        irradiance[e.dest.x + t] = vec4<f32>(pow(max(sum, vec3<f32>(0.0)), vec3<f32>(1.0 / gamma)), 0.0);
    }
    if (t < e.dest.w) {
        var sum = vec2<f32>(0.0);
        for (var i = 0u; i < 8u; i++) {
            let w = weights[i];
            if (w > 0.0) {
                sum += w * distance[e.source_distance[i / 4u][i % 4u] + t];
            }
        }
        distance[e.dest.y + t] = sum;
    }
}
