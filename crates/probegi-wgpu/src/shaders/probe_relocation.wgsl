// The initialisation rounds chained on the device (probegi_field::ddgi_volume's
// init_rounds, every round in one submission): per volume, `init_chain_rays`
// writes each probe's rays for the round from where it is now, the trace pass
// traces them (a probe out of the round has t_max −1: no hit, nothing read),
// `init_chain_relocate` runs one iteration of seed 004 §5's position optimizer
// (Listing 4: probegi_core::probe_relocation::probe_ray_stats over the probe's
// rays, then relocation_step; RTXGI `ProbeRelocationCS`) per probe in the
// round, and a probe it leaves in place leaves the rounds, its rays and hits
// kept for the classification (they are the classification's: the same
// directions from where it stays). After the last relocation round
// `init_chain_keep` keeps the hits of the probes traced again from where the
// last round moved them. Must match `probegi_wgpu::probe_relocation::ChainParams`
// and the trace pass's `GpuRay` (32 bytes) / `GpuRayHit` (24).

struct ChainParams {
    spacing_m: vec3<f32>,
    offset_limit_rel: f32,
    probe_count: u32,
    rays_per_probe: u32,
    groups_x: u32,          // per-probe passes: workgroups along x
    ray_groups_x: u32,      // init_chain_rays: workgroups along x
    min_frontface_rel: f32,
    keep: u32,              // 1: keep settled probes' rays and hits (a classification follows)
    _pad0: u32,
    _pad1: u32,
};

struct RelocationRay {
    origin: vec3<f32>,
    t_min: f32,
    dir: vec3<f32>,
    t_max: f32,
};

struct RelocationHit {
    t: f32,
    triangle: u32,
    bary: vec2<f32>,
    instance: u32,
    _pad: u32,
};

@group(0) @binding(0) var<uniform> chain_params: ChainParams;
// The round's batch: probe p's rays at p × rays_per_probe.
@group(0) @binding(1) var<storage, read_write> relocation_rays: array<RelocationRay>;
@group(0) @binding(2) var<storage, read> relocation_hits: array<RelocationHit>;
// The fixed unit directions every round traces (xyz).
@group(0) @binding(3) var<storage, read> chain_dirs: array<vec4<f32>>;
// Per probe: its grid point (xyz, m).
@group(0) @binding(4) var<storage, read> chain_grid_points: array<vec4<f32>>;
// Per probe: its offset from the grid point (xyz, m), w = rounds it traced.
@group(0) @binding(5) var<storage, read_write> chain_offsets: array<vec4<f32>>;
// Per probe: where it is (xyz, m), w = its rays' t_max in the next round (−1: out of the rounds).
@group(0) @binding(6) var<storage, read_write> chain_probes: array<vec4<f32>>;
// The kept rays and hits, probe p's at p × rays_per_probe.
@group(0) @binding(7) var<storage, read_write> kept_rays: array<RelocationRay>;
@group(0) @binding(8) var<storage, read_write> kept_hits: array<RelocationHit>;

const RELOCATION_NO_HIT: u32 = 0xffffffffu;

fn relocation_within(o: vec3<f32>, limit: vec3<f32>) -> bool {
    return all(abs(o) < limit);
}

fn chain_probe_index(wid: vec3<u32>, lid: u32) -> u32 {
    return (wid.y * chain_params.groups_x + wid.x) * 64u + lid;
}

@compute @workgroup_size(64)
fn init_chain_rays(@builtin(workgroup_id) wid: vec3<u32>, @builtin(local_invocation_index) lid: u32) {
    let k = (wid.y * chain_params.ray_groups_x + wid.x) * 64u + lid;
    let n = chain_params.rays_per_probe;
    if (k >= chain_params.probe_count * n) {
        return;
    }
    let probe = chain_probes[k / n];
    relocation_rays[k] = RelocationRay(probe.xyz, 0.0, chain_dirs[k % n].xyz, probe.w);
}

// Probe p's rays and hits of this round into the kept ones.
fn chain_keep_probe(p: u32) {
    let n = chain_params.rays_per_probe;
    for (var i = p * n; i < (p + 1u) * n; i++) {
        kept_rays[i] = relocation_rays[i];
        kept_hits[i] = relocation_hits[i];
    }
}

@compute @workgroup_size(64)
fn init_chain_keep(@builtin(workgroup_id) wid: vec3<u32>, @builtin(local_invocation_index) lid: u32) {
    let p = chain_probe_index(wid, lid);
    if (p >= chain_params.probe_count || chain_probes[p].w < 0.0) {
        return;
    }
    chain_offsets[p].w += 1.0;
    chain_keep_probe(p);
}

@compute @workgroup_size(64)
fn init_chain_relocate(@builtin(workgroup_id) wid: vec3<u32>, @builtin(local_invocation_index) lid: u32) {
    let p = chain_probe_index(wid, lid);
    if (p >= chain_params.probe_count) {
        return;
    }
    let probe = chain_probes[p];
    if (probe.w < 0.0) {
        return;
    }
    let offset = chain_offsets[p].xyz;
    let next = relocation_step(p * chain_params.rays_per_probe, chain_params.rays_per_probe, offset);
    // Left in place: the next rounds would trace the same rays from the same point.
    let settled = all(next == offset);
    chain_offsets[p] = vec4<f32>(next, chain_offsets[p].w + 1.0);
    chain_probes[p] = vec4<f32>(chain_grid_points[p].xyz + next, select(probe.w, -1.0, settled));
    if (settled && chain_params.keep != 0u) {
        chain_keep_probe(p);
    }
}

// probegi_core::probe_relocation::{probe_ray_stats, relocation_step} over the
// probe's `ray_count` rays from `first_ray`: its next offset.
fn relocation_step(first_ray: u32, ray_count: u32, offset: vec3<f32>) -> vec3<f32> {
    // probegi_core::probe_relocation::probe_ray_stats (strict comparisons: the
    // first of equal distances wins, as on the CPU).
    var backfaces = 0u;
    var has_back = false;
    var back_dir = vec3<f32>(0.0);
    var back_d = 0.0;
    var has_front = false;
    var close_dir = vec3<f32>(0.0);
    var close_d = 0.0;
    var far_dir = vec3<f32>(0.0);
    var far_d = 0.0;
    for (var i = first_ray; i < first_ray + ray_count; i++) {
        let h = relocation_hits[i];
        if (h.triangle == RELOCATION_NO_HIT) {
            continue; // a miss: +∞, neither face
        }
        let dir = relocation_rays[i].dir;
        // The CPU's signed distance is −t for a backface; −0 (t = 0) counts as a front face.
        if ((h.triangle & 0x80000000u) != 0u && h.t > 0.0) {
            backfaces += 1u;
            if (!has_back || h.t < back_d) {
                has_back = true;
                back_dir = dir;
                back_d = h.t;
            }
        } else {
            if (!has_front || h.t < close_d) {
                close_dir = dir;
                close_d = h.t;
            }
            if (!has_front || h.t > far_d) {
                far_dir = dir;
                far_d = h.t;
            }
            has_front = true;
        }
    }
    let backface_fraction = f32(backfaces) / f32(max(ray_count, 1u));
    // probegi_core::probe_relocation::relocation_step
    let spacing_m = chain_params.spacing_m;
    let limit = spacing_m * chain_params.offset_limit_rel;
    let min_spacing = min(min(spacing_m.x, spacing_m.y), spacing_m.z);
    var full = offset;
    if (backface_fraction > INSIDE_GEOMETRY_BACKFACE_FRACTION) {
        if (has_back) {
            let v = back_dir * back_d;
            for (var i = 1u; i <= 100u; i++) {
                full = offset + v * (2.0 - f32(i) * 0.01);
                if (relocation_within(full, limit)) {
                    break;
                }
            }
        }
    } else if (has_front && close_d < chain_params.min_frontface_rel * min_spacing && dot(close_dir, far_dir) <= 0.5) {
        full = offset + far_dir * min(far_d, FRONTFACE_STEP_LIMIT_REL * min_spacing);
    }
    if (!relocation_within(full, limit)) {
        full = offset;
    }
    return full;
}
