// The probes' change in a blend, the ray budget's signal (probegi_core::probe_change;
// probegi_field::ray_budget):
//   snapshot_tiles: before the blend, one thread per listed probe copies its
//     interior irradiance texels (and occlusion texels) into `snapshot`;
//   measure_change: after the blend and the shadowing field's, one thread per
//     listed probe compares them with the atlases: the mean SMAPE of the encoded
//     irradiance as YCoCg vectors and the mean absolute occlusion change, summed
//     in the CPU's row-major texel order; the probe's change is the larger.
// Must match `probegi_wgpu::probe_change::ChangeParams` (#[repr(C)], 32 bytes) and
// the tile-major atlas layout of probegi_core::probe_atlas.

struct ChangeParams {
    entry_count: u32,
    groups_x: u32,
    irradiance_interior: u32,
    irradiance_first: u32,
    // 0: the volume keeps no occlusion maps.
    occlusion_interior: u32,
    occlusion_first: u32,
    _pad0: u32,
    _pad1: u32,
};

@group(0) @binding(0) var<uniform> change_params: ChangeParams;
// The probes (storage slots) that blend this frame, in increasing order.
@group(0) @binding(1) var<storage, read> change_probes: array<u32>;
@group(0) @binding(2) var<storage, read> irradiance: array<vec4<f32>>;
// The distance buffer: the occlusion maps are its x after the distance atlases.
@group(0) @binding(3) var<storage, read> distance: array<vec2<f32>>;
// Per listed probe: 3·n² irradiance floats, then m² occlusion floats.
@group(0) @binding(4) var<storage, read_write> snapshot: array<f32>;
@group(0) @binding(5) var<storage, read_write> probe_change: array<f32>;

fn change_entry(wid: vec3<u32>, lid: u32) -> u32 {
    return (wid.y * change_params.groups_x + wid.x) * 64u + lid;
}

fn change_stride() -> u32 {
    let n = change_params.irradiance_interior;
    let m = change_params.occlusion_interior;
    return 3u * n * n + m * m;
}

// Texel (i, j) of `probe`'s interior in a buffer whose tiles start at `first`.
fn change_texel(first: u32, interior: u32, probe: u32, i: u32, j: u32) -> u32 {
    let side = interior + 2u;
    return first + probe * side * side + (j + 1u) * side + i + 1u;
}

@compute @workgroup_size(64)
fn snapshot_tiles(@builtin(workgroup_id) wid: vec3<u32>, @builtin(local_invocation_index) lid: u32) {
    let e = change_entry(wid, lid);
    if (e >= change_params.entry_count) { return; }
    let probe = change_probes[e];
    let n = change_params.irradiance_interior;
    let m = change_params.occlusion_interior;
    let base = e * change_stride();
    for (var t = 0u; t < n * n; t++) {
        let v = irradiance[change_texel(change_params.irradiance_first, n, probe, t % n, t / n)].xyz;
        snapshot[base + 3u * t] = v.x;
        snapshot[base + 3u * t + 1u] = v.y;
        snapshot[base + 3u * t + 2u] = v.z;
    }
    for (var t = 0u; t < m * m; t++) {
        snapshot[base + 3u * n * n + t] = distance[change_texel(change_params.occlusion_first, m, probe, t % m, t / m)].x;
    }
}

// probegi_core::probe_change::ycocg
fn change_ycocg(c: vec3<f32>) -> vec3<f32> {
    return vec3<f32>(0.25 * c.x + 0.5 * c.y + 0.25 * c.z, 0.5 * c.x - 0.5 * c.z, -0.25 * c.x + 0.5 * c.y - 0.25 * c.z);
}

// probegi_core::probe_change::texel_change
fn change_of_texel(before: vec3<f32>, after: vec3<f32>) -> f32 {
    let a = change_ycocg(before);
    let b = change_ycocg(after);
    let s = abs(a) + abs(b);
    let den = s.x + s.y + s.z;
    if (!(den > 0.0)) { return 0.0; }
    let d = abs(a - b);
    return min((d.x + d.y + d.z) / den, 1.0);
}

@compute @workgroup_size(64)
fn measure_change(@builtin(workgroup_id) wid: vec3<u32>, @builtin(local_invocation_index) lid: u32) {
    let e = change_entry(wid, lid);
    if (e >= change_params.entry_count) { return; }
    let probe = change_probes[e];
    let n = change_params.irradiance_interior;
    let m = change_params.occlusion_interior;
    let base = e * change_stride();
    var irr = 0.0;
    for (var t = 0u; t < n * n; t++) {
        let old = vec3<f32>(snapshot[base + 3u * t], snapshot[base + 3u * t + 1u], snapshot[base + 3u * t + 2u]);
        let now = irradiance[change_texel(change_params.irradiance_first, n, probe, t % n, t / n)].xyz;
        irr += change_of_texel(old, now);
    }
    irr = irr / f32(max(n * n, 1u));
    var occ = 0.0;
    for (var t = 0u; t < m * m; t++) {
        let now = distance[change_texel(change_params.occlusion_first, m, probe, t % m, t / m)].x;
        occ += abs(now - snapshot[base + 3u * n * n + t]);
    }
    occ = occ / f32(max(m * m, 1u));
    // probegi_core::probe_change::probe_change: not a number counts as a full change.
    var c = 1.0;
    if (abs(irr) <= 3.4028235e38 && abs(occ) <= 3.4028235e38) {
        c = clamp(max(irr, occ), 0.0, 1.0);
    }
    probe_change[e] = c;
}
