// Seed 004 Listing 5's classification round of the jcgt probe states on the GPU,
// over one volume's probes of a traced initialisation batch (probegi_cpu::ddgi's
// classify_jcgt_pending, with probegi_core::probe_classification::{probe_watches,
// uncovered_point_probe} and probegi_core::probe_relocation::is_inside_geometry):
// - `classify_first`, one thread per probe: inside geometry (more than 25 %
//   backfaces) and whether a front-face hit lies in the box the probe watches;
// - the covering pass, probegi_core::probe_classification::cover_proposals:
//   `classify_propose`, one thread per ray of the round, lists what each
//   front-face point the first pass left uncovered would keep (and takes an
//   atomic minimum of its ray per probe); `classify_args` sizes the indirect
//   dispatches over that list; then `classify_clear` + `classify_round` per
//   Jacobi round (the greedy pass's recursion in ray order, every listed point
//   at once), `classify_mark` (the rounds' probes kept) and `classify_fixup` (a
//   point still uncovered keeps its proposal). Order-free, so the CPU's result
//   bit for bit.
// Included after bvh.wgsl and scene.wgsl (groups 1 and 3) for the hits' facing
// plane normals. Must match `probegi_wgpu::probe_classification::ClassifyParams`
// and the trace pass's `GpuRay` / `GpuRayHit`.

struct ClassifyParams {
    origin_m: vec3<f32>,
    probe_count: u32,
    spacing_m: vec3<f32>,
    rays_per_probe: u32,
    probe_counts: vec3<u32>,
    groups_x: u32,
    scroll_offsets: vec3<u32>,
    cover_round: u32,          // classify_clear / classify_round: the Jacobi round (parity: keeper array)
    reach_rel: f32,
    bias_m: f32,
    cover_rounds: u32,         // classify_mark: rounds run (parity: the last keeper array)
    ray_threads: u32,          // per-ray passes: probe_count × rays_per_probe
    ray_groups_x: u32,         // per-ray passes: workgroups along x
    _pad0: u32,
    _pad1: u32,
    _pad2: u32,
};

struct ClassifyRay {
    origin: vec3<f32>,
    t_min: f32,
    dir: vec3<f32>,
    t_max: f32,
};

struct ClassifyHit {
    t: f32,
    triangle: u32,
    bary: vec2<f32>,
    instance: u32,
    _pad: u32,
};

@group(0) @binding(0) var<uniform> classify_params: ClassifyParams;
@group(0) @binding(1) var<storage, read> classify_rays: array<ClassifyRay>;
@group(0) @binding(2) var<storage, read> classify_hits: array<ClassifyHit>;
// Per probe: first ray in the batch (all ones: none), pending, its state traces, 0.
@group(0) @binding(3) var<storage, read> classify_probes: array<vec4<u32>>;
// Per probe: position with its relocation offset (m).
@group(0) @binding(4) var<storage, read> classify_positions: array<vec4<f32>>;
// Per probe: inside geometry, kept (first pass, then the rounds' keepers),
// eligible, kept by the fix-up.
@group(0) @binding(5) var<storage, read_write> classify_out: array<vec4<u32>>;
// The proposals: [0..3) the indirect workgroups over them (x, y, 1), [3] their
// count, then per proposal its ray and the probe it would keep.
@group(0) @binding(6) var<storage, read_write> classify_list: array<atomic<u32>>;
// Two arrays of probe_count: per probe, the first ray that keeps it (Jacobi ping-pong).
@group(0) @binding(7) var<storage, read_write> classify_keepers: array<atomic<u32>>;

const CLASSIFY_NONE: u32 = 0xffffffffu;

// probegi_core::probe_grid::ProbeGrid::probe_coords
fn classify_probe_coords(index: u32) -> vec3<u32> {
    let c = classify_params.probe_counts;
    let s = vec3<u32>(index % c.x, (index / c.x) % c.y, index / (c.x * c.y));
    let o = classify_params.scroll_offsets;
    return select(s + c - o, s - o, s >= o);
}

// probegi_core::probe_grid::ProbeGrid::probe_index
fn classify_probe_index(coords: vec3<u32>) -> u32 {
    let c = classify_params.probe_counts;
    let s0 = coords + classify_params.scroll_offsets;
    let s = select(s0, s0 - c, s0 >= c);
    return s.x + c.x * (s.y + c.y * s.z);
}

// probegi_core::probe_grid::ProbeGrid::probe_position
fn classify_grid_point(coords: vec3<u32>) -> vec3<f32> {
    return classify_params.origin_m + classify_params.spacing_m * vec3<f32>(coords);
}

// The ray's front-face hit point (the ray's origin + direction × t) and the
// triangle's facing plane normal (Scene::facing_geometric_normal, which
// probegi_cpu::probe_trace's HitNormal::Plane gives the host rounds), or false.
struct FrontHit {
    ok: bool,
    point: vec3<f32>,
    normal: vec3<f32>,
};

fn classify_front_hit(r: u32) -> FrontHit {
    var out: FrontHit;
    let h = classify_hits[r];
    out.ok = h.triangle != CLASSIFY_NONE && (h.triangle & 0x80000000u) == 0u && h.t > 0.0;
    if (!out.ok) { return out; }
    let ray = classify_rays[r];
    out.point = ray.origin + ray.dir * h.t;
    out.normal = scene_facing_geometric_normal(scene_surface_point(h.triangle, h.instance, h.bary, false));
    return out;
}

// probegi_core::probe_classification::probe_watches
fn classify_watches(coords: vec3<u32>, offset_m: vec3<f32>) -> bool {
    let last = max(classify_params.probe_counts, vec3<u32>(1u)) - vec3<u32>(1u);
    for (var axis = 0u; axis < 3u; axis++) {
        let o = offset_m[axis];
        let outward = (coords[axis] == 0u && o < 0.0) || (coords[axis] == last[axis] && o > 0.0);
        if (!(outward || abs(o) <= classify_params.reach_rel * classify_params.spacing_m[axis] + classify_params.bias_m)) {
            return false;
        }
    }
    return true;
}

@compute @workgroup_size(64)
fn classify_first(@builtin(workgroup_id) wid: vec3<u32>, @builtin(local_invocation_index) lid: u32) {
    let p = (wid.y * classify_params.groups_x + wid.x) * 64u + lid;
    if (p >= classify_params.probe_count) {
        return;
    }
    atomicStore(&classify_keepers[p], CLASSIFY_NONE);
    atomicStore(&classify_keepers[classify_params.probe_count + p], CLASSIFY_NONE);
    if (p == 0u) {
        atomicStore(&classify_list[3], 0u);
    }
    let probe = classify_probes[p];
    let pending = probe.y != 0u;
    if (!pending || probe.x == CLASSIFY_NONE) {
        // Not pending: keeps its state, counts as covering when it traces.
        classify_out[p] = vec4<u32>(0u, select(0u, probe.z, !pending), u32(pending), 0u);
        return;
    }
    let n = classify_params.rays_per_probe;
    let coords = classify_probe_coords(p);
    let grid_point = classify_grid_point(coords);
    var backfaces = 0u;
    var watches = false;
    for (var r = probe.x; r < probe.x + n; r++) {
        let h = classify_hits[r];
        if (h.triangle != CLASSIFY_NONE && (h.triangle & 0x80000000u) != 0u && h.t > 0.0) {
            backfaces += 1u;
        }
        if (!watches) {
            let f = classify_front_hit(r);
            watches = f.ok && classify_watches(coords, f.point - grid_point);
        }
    }
    // probegi_core::probe_relocation::is_inside_geometry
    let inside = f32(backfaces) / f32(max(n, 1u)) > INSIDE_GEOMETRY_BACKFACE_FRACTION;
    classify_out[p] = vec4<u32>(u32(inside), u32(!inside && watches), u32(!inside), 0u);
}

// probegi_core::probe_grid::ProbeGrid::cage of `point`: its base corner, the
// fractions within the cell, and the largest coordinates.
struct ClassifyCage {
    base: vec3<u32>,
    alpha: vec3<f32>,
    max_c: vec3<u32>,
};

fn classify_cage(point: vec3<f32>) -> ClassifyCage {
    var c: ClassifyCage;
    let max_c = vec3<f32>(max(vec3<i32>(classify_params.probe_counts) - vec3<i32>(1), vec3<i32>(0)));
    let rel = (point - classify_params.origin_m) / classify_params.spacing_m;
    c.base = vec3<u32>(clamp(floor(rel), vec3<f32>(0.0), max_c));
    let base_pos = classify_params.origin_m + classify_params.spacing_m * vec3<f32>(c.base);
    c.alpha = clamp((point - base_pos) / classify_params.spacing_m, vec3<f32>(0.0), vec3<f32>(1.0));
    c.max_c = vec3<u32>(max_c);
    return c;
}

// Corner i of the cage (x in bit 0, y in bit 1, z in bit 2), as a probe index.
fn classify_cage_probe(c: ClassifyCage, i: u32) -> u32 {
    let o = vec3<u32>(i & 1u, (i >> 1u) & 1u, (i >> 2u) & 1u);
    return classify_probe_index(min(c.base + o, c.max_c));
}

// Whether probe p lies strictly in front of the surface at `point` with `normal`.
fn classify_in_front(p: u32, point: vec3<f32>, normal: vec3<f32>) -> bool {
    return dot(classify_positions[p].xyz - point, normal) > 0.0;
}

// probegi_core::probe_classification::uncovered_point_probe, over the first
// pass's kept flags in classify_out.
fn classify_uncovered(point: vec3<f32>, normal: vec3<f32>) -> u32 {
    let c = classify_cage(point);
    var best = CLASSIFY_NONE;
    var best_w = 0.0;
    for (var i = 0u; i < 8u; i++) {
        let p = classify_cage_probe(c, i);
        if (!classify_in_front(p, point, normal)) {
            continue;
        }
        if (classify_out[p].y != 0u) {
            return CLASSIFY_NONE;
        }
        let fo = vec3<f32>(vec3<u32>(i & 1u, (i >> 1u) & 1u, (i >> 2u) & 1u));
        let t = (vec3<f32>(1.0) - c.alpha) * (vec3<f32>(1.0) - fo) + c.alpha * fo;
        let w = t.x * t.y * t.z;
        if (classify_out[p].z != 0u && (best == CLASSIFY_NONE || w > best_w)) {
            best = p;
            best_w = w;
        }
    }
    return best;
}

// The batch ray of per-ray thread `t` (probe t / rays, its ray t % rays), or
// none where the probe is not pending or did not trace.
fn classify_thread_ray(wid: vec3<u32>, lid: u32) -> u32 {
    let t = (wid.y * classify_params.ray_groups_x + wid.x) * 64u + lid;
    if (t >= classify_params.ray_threads) {
        return CLASSIFY_NONE;
    }
    let n = max(classify_params.rays_per_probe, 1u);
    let probe = classify_probes[t / n];
    if (probe.y == 0u || probe.x == CLASSIFY_NONE) {
        return CLASSIFY_NONE;
    }
    return probe.x + t % n;
}

@compute @workgroup_size(64)
fn classify_propose(@builtin(workgroup_id) wid: vec3<u32>, @builtin(local_invocation_index) lid: u32) {
    let r = classify_thread_ray(wid, lid);
    if (r == CLASSIFY_NONE) {
        return;
    }
    var q = CLASSIFY_NONE;
    let f = classify_front_hit(r);
    if (f.ok) {
        q = classify_uncovered(f.point, f.normal);
    }
    if (q != CLASSIFY_NONE) {
        let i = atomicAdd(&classify_list[3], 1u);
        atomicStore(&classify_list[4u + 2u * i], r);
        atomicStore(&classify_list[5u + 2u * i], q);
        atomicMin(&classify_keepers[q], r);
    }
}

// The workgroups of 64 over the listed proposals, in x (at most 65 535) and y.
@compute @workgroup_size(1)
fn classify_args() {
    let groups = (atomicLoad(&classify_list[3]) + 63u) / 64u;
    let x = clamp(groups, 1u, 65535u);
    atomicStore(&classify_list[0], x);
    atomicStore(&classify_list[1], (groups + x - 1u) / x);
    atomicStore(&classify_list[2], 1u);
}

// The proposal of an indirect thread: (ray, probe), or none past the list.
fn classify_listed(wid: vec3<u32>, lid: u32) -> vec2<u32> {
    let i = (wid.y * atomicLoad(&classify_list[0]) + wid.x) * 64u + lid;
    if (i >= atomicLoad(&classify_list[3])) {
        return vec2<u32>(CLASSIFY_NONE);
    }
    return vec2<u32>(atomicLoad(&classify_list[4u + 2u * i]), atomicLoad(&classify_list[5u + 2u * i]));
}

// Whether a front-side cage probe of ray r's point has a keeper before r in
// keeper array `array_index` (classify_mark's kept flags when it is none).
fn classify_covered(r: u32, array_index: u32) -> bool {
    let f = classify_front_hit(r);
    let c = classify_cage(f.point);
    for (var i = 0u; i < 8u; i++) {
        let p = classify_cage_probe(c, i);
        if (!classify_in_front(p, f.point, f.normal)) {
            continue;
        }
        if (array_index == CLASSIFY_NONE) {
            if (classify_out[p].y != 0u) {
                return true;
            }
        } else if (atomicLoad(&classify_keepers[array_index * classify_params.probe_count + p]) < r) {
            return true;
        }
    }
    return false;
}

// Clears the keeper array round `cover_round` writes.
@compute @workgroup_size(64)
fn classify_clear(@builtin(workgroup_id) wid: vec3<u32>, @builtin(local_invocation_index) lid: u32) {
    let p = (wid.y * classify_params.groups_x + wid.x) * 64u + lid;
    if (p < classify_params.probe_count) {
        let to = (classify_params.cover_round + 1u) & 1u;
        atomicStore(&classify_keepers[to * classify_params.probe_count + p], CLASSIFY_NONE);
    }
}

// One Jacobi round: a point keeps its proposal unless an earlier keeper of the
// last round kept one of its front-side probes.
@compute @workgroup_size(64)
fn classify_round(@builtin(workgroup_id) wid: vec3<u32>, @builtin(local_invocation_index) lid: u32) {
    let listed = classify_listed(wid, lid);
    let r = listed.x;
    let q = listed.y;
    if (r == CLASSIFY_NONE) {
        return;
    }
    let last = classify_params.cover_round & 1u;
    if (!classify_covered(r, last)) {
        atomicMin(&classify_keepers[(last ^ 1u) * classify_params.probe_count + q], r);
    }
}

// The rounds' keepers join the first pass's kept probes.
@compute @workgroup_size(64)
fn classify_mark(@builtin(workgroup_id) wid: vec3<u32>, @builtin(local_invocation_index) lid: u32) {
    let p = (wid.y * classify_params.groups_x + wid.x) * 64u + lid;
    if (p < classify_params.probe_count) {
        let last = classify_params.cover_rounds & 1u;
        if (atomicLoad(&classify_keepers[last * classify_params.probe_count + p]) != CLASSIFY_NONE) {
            classify_out[p].y = 1u;
        }
    }
}

// A point the rounds left uncovered (rounds cut short) keeps its proposal.
@compute @workgroup_size(64)
fn classify_fixup(@builtin(workgroup_id) wid: vec3<u32>, @builtin(local_invocation_index) lid: u32) {
    let listed = classify_listed(wid, lid);
    let r = listed.x;
    let q = listed.y;
    if (r != CLASSIFY_NONE && !classify_covered(r, CLASSIFY_NONE)) {
        classify_out[q].w = 1u;
    }
}
