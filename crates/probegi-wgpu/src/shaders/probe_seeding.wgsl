// Seeding new probes (probegi_field::probe_seeding, the host's twin): each seed
// fills one scrolled-in probe's irradiance and distance tiles, borders included,
// with the weighted mix of up to eight source tiles of another volume of the
// resident field (texel for texel: the volumes share tile sizes). Irradiance is
// mixed as decoded mean radiance (e^gamma) and re-encoded (e^(1/gamma)), w left
// 0; distance moments are mixed as they are. Sources are usable probes and
// targets reset ones, so no thread reads a texel another writes.
// Must match `probegi_wgpu::probe_seeding::SeedEntry` (#[repr(C)], 128 bytes)
// and `SeedParams` (16 bytes).

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
    // x: the irradiance gamma.
    encoding: vec4<f32>,
};

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
    if (t < e.dest.z) {
        var sum = vec3<f32>(0.0);
        for (var i = 0u; i < 8u; i++) {
            let w = e.weights[i / 4u][i % 4u];
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
            let w = e.weights[i / 4u][i % 4u];
            if (w > 0.0) {
                sum += w * distance[e.source_distance[i / 4u][i % 4u] + t];
            }
        }
        distance[e.dest.y + t] = sum;
    }
}
