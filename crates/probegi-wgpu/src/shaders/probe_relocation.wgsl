// The probe-position optimizer (seed 004 §5, Listing 4), one thread per probe of an
// initialisation batch: probegi_core::probe_relocation::probe_ray_stats over the
// probe's rays (directions from the trace's rays, signed distances from its hits),
// then relocation_step. Must match `probegi_wgpu::probe_relocation::RelocationParams`,
// `probegi_field::device_plans::DeviceRelocationProbe` (uploaded as the field plans it,
// 40 bytes: its vectors are three f32 each, hence `array<f32, 3>` here) and the trace
// pass's `GpuRay` (32 bytes) / `GpuRayHit` (24).

struct RelocationParams {
    probe_count: u32,
    groups_x: u32,
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

struct RelocationProbe {
    offset_m: array<f32, 3>,
    first_ray: u32,
    spacing_m: array<f32, 3>,
    ray_count: u32,
    offset_limit_rel: f32,
    min_frontface_rel: f32,
};

@group(0) @binding(0) var<uniform> relocation_params: RelocationParams;
@group(0) @binding(1) var<storage, read> relocation_rays: array<RelocationRay>;
@group(0) @binding(2) var<storage, read> relocation_hits: array<RelocationHit>;
@group(0) @binding(3) var<storage, read> relocation_probes: array<RelocationProbe>;
// Per probe: the new offset from its grid point (m).
@group(0) @binding(4) var<storage, read_write> relocation_offsets: array<vec4<f32>>;

const RELOCATION_NO_HIT: u32 = 0xffffffffu;

fn relocation_vec3(v: array<f32, 3>) -> vec3<f32> {
    return vec3<f32>(v[0], v[1], v[2]);
}

fn relocation_within(o: vec3<f32>, limit: vec3<f32>) -> bool {
    return all(abs(o) < limit);
}

@compute @workgroup_size(64)
fn relocate_probes(@builtin(workgroup_id) wid: vec3<u32>, @builtin(local_invocation_index) lid: u32) {
    let p = (wid.y * relocation_params.groups_x + wid.x) * 64u + lid;
    if (p >= relocation_params.probe_count) {
        return;
    }
    let probe = relocation_probes[p];
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
    for (var i = probe.first_ray; i < probe.first_ray + probe.ray_count; i++) {
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
    let backface_fraction = f32(backfaces) / f32(max(probe.ray_count, 1u));
    // probegi_core::probe_relocation::relocation_step
    let offset = relocation_vec3(probe.offset_m);
    let spacing_m = relocation_vec3(probe.spacing_m);
    let limit = spacing_m * probe.offset_limit_rel;
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
    } else if (has_front && close_d < probe.min_frontface_rel * min_spacing && dot(close_dir, far_dir) <= 0.5) {
        full = offset + far_dir * min(far_d, FRONTFACE_STEP_LIMIT_REL * min_spacing);
    }
    if (!relocation_within(full, limit)) {
        full = offset;
    }
    relocation_offsets[p] = vec4<f32>(full, 0.0);
}
