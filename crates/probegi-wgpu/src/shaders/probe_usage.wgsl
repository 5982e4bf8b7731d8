// Seed 003 eq. 6.1–6.2 per probe of a batch (probegi_core::probe_classification::probe_usage):
// Usage(P) = Σ R(dᵢ) over the probe's rays, R = −1 for a backface, +1 for a front
// hit within the cage diagonal r, 0 otherwise; with the relevant and backface
// counts the usage scheme's states come from. One thread per batch probe.
// Must match `probegi_wgpu::probe_usage::UsageParams`, `probegi_field::seam::BatchProbe`
// (the batch's probes uploaded as they are) and the trace pass's `GpuRayHit` (24 bytes;
// triangle bit 31 = backface, all ones = miss).

struct UsageParams {
    probe_count: u32,
    groups_x: u32,
    // Entries of `usage_cage_diagonals_m` (the buffer, kept from batch to
    // batch, may hold more).
    diagonal_count: u32,
    _pad: u32,
};

struct UsageHit {
    t: f32,
    triangle: u32,
    bary: vec2<f32>,
    instance: u32,
    _pad: u32,
};

// probegi_field::seam::BatchProbe.
struct UsageProbe {
    volume: u32,
    probe: u32,
    first_ray: u32,
    ray_count: u32,
};

@group(0) @binding(0) var<uniform> usage_params: UsageParams;
@group(0) @binding(1) var<storage, read> usage_hits: array<UsageHit>;
// The batch's probes.
@group(0) @binding(2) var<storage, read> usage_probes: array<UsageProbe>;
// Per volume: its cage diagonal r (m); a volume past `diagonal_count` has r = 0.
@group(0) @binding(3) var<storage, read> usage_cage_diagonals_m: array<f32>;
// Per batch probe: usage, relevant samples, backfaces, 0.
@group(0) @binding(4) var<storage, read_write> usage_counts: array<vec4<i32>>;

const USAGE_NO_HIT: u32 = 0xffffffffu;

@compute @workgroup_size(64)
fn probe_usage(@builtin(workgroup_id) wid: vec3<u32>, @builtin(local_invocation_index) lid: u32) {
    let p = (wid.y * usage_params.groups_x + wid.x) * 64u + lid;
    if (p >= usage_params.probe_count) {
        return;
    }
    let probe = usage_probes[p];
    var r = 0.0;
    if (probe.volume < usage_params.diagonal_count) {
        r = usage_cage_diagonals_m[probe.volume];
    }
    var usage = 0i;
    var relevant = 0i;
    var backfaces = 0i;
    for (var i = probe.first_ray; i < probe.first_ray + probe.ray_count; i++) {
        let h = usage_hits[i];
        if (h.triangle == USAGE_NO_HIT) {
            continue;
        }
        // The CPU's signed distance is −t for a backface: −0 (t = 0) is no backface.
        if ((h.triangle & 0x80000000u) != 0u && h.t > 0.0) {
            usage -= 1;
            relevant += 1;
            backfaces += 1;
        } else if (h.t <= r) {
            usage += 1;
            relevant += 1;
        }
    }
    usage_counts[p] = vec4<i32>(usage, relevant, backfaces, 0);
}
