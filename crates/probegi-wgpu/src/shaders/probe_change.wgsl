// Each blended probe's change, the ray budget's signal (probegi_core::probe_change;
// probegi_field::ray_budget): one thread per listed probe averages the changes the
// blends left in its tiles (irradiance w, from probe_blend.wgsl; occlusion y, from
// shadow_field.wgsl, as of the tile's last occlusion blend), summed in the CPU's
// row-major texel order, and keeps the larger (probegi_core::probe_change::probe_change).
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
// The probes (storage slots) that blended this frame, in increasing order.
@group(0) @binding(1) var<storage, read> change_probes: array<u32>;
@group(0) @binding(2) var<storage, read> irradiance: array<vec4<f32>>;
// The distance buffer: the occlusion maps are after the distance atlases.
@group(0) @binding(3) var<storage, read> distance: array<vec2<f32>>;
@group(0) @binding(4) var<storage, read_write> probe_change: array<f32>;

// Texel (i, j) of `probe`'s interior in a buffer whose tiles start at `first`.
fn change_texel(first: u32, interior: u32, probe: u32, i: u32, j: u32) -> u32 {
    let side = interior + 2u;
    return first + probe * side * side + (j + 1u) * side + i + 1u;
}

@compute @workgroup_size(64)
fn measure_change(@builtin(workgroup_id) wid: vec3<u32>, @builtin(local_invocation_index) lid: u32) {
    let e = (wid.y * change_params.groups_x + wid.x) * 64u + lid;
    if (e >= change_params.entry_count) { return; }
    let probe = change_probes[e];
    let n = change_params.irradiance_interior;
    let m = change_params.occlusion_interior;
    var irr = 0.0;
    for (var t = 0u; t < n * n; t++) {
        irr += irradiance[change_texel(change_params.irradiance_first, n, probe, t % n, t / n)].w;
    }
    irr = irr / f32(max(n * n, 1u));
    var occ = 0.0;
    for (var t = 0u; t < m * m; t++) {
        occ += distance[change_texel(change_params.occlusion_first, m, probe, t % m, t / m)].y;
    }
    occ = occ / f32(max(m * m, 1u));
    // probegi_core::probe_change::probe_change: not a number counts as a full change.
    var c = 1.0;
    if (abs(irr) <= 3.4028235e38 && abs(occ) <= 3.4028235e38) {
        c = clamp(max(irr, occ), 0.0, 1.0);
    }
    probe_change[e] = c;
}
