// Seed 004 Listing 5's classification round of the jcgt probe states on the GPU,
// over one volume's probes of a traced initialisation batch (probegi_cpu::ddgi's
// classify_jcgt_pending, with probegi_core::probe_classification::{probe_watches,
// uncovered_point_probe} and probegi_core::probe_relocation::is_inside_geometry):
// - `classify_first`, one thread per probe: inside geometry (more than 25 %
//   backfaces) and whether a front-face hit lies in the box the probe watches;
// - `classify_cover`, one thread for the whole volume: the covering pass, in probe
//   and ray order as on the CPU (sequential, so deterministic and greedy), keeps a
//   front-side cage probe for every surface point a pending probe saw. It runs as
//   a sequence of dispatches over chunks of probes (one long invocation is cut
//   short on some drivers: lavapipe stopped a 131 072-ray loop after ~20 000).
// Included after bvh.wgsl and scene.wgsl (groups 1 and 3) for the hits' facing
// shading normals. Must match `probegi_wgpu::probe_classification::ClassifyParams`
// and the trace pass's `GpuRay` / `GpuRayHit`.

struct ClassifyParams {
    origin_m: vec3<f32>,
    probe_count: u32,
    spacing_m: vec3<f32>,
    rays_per_probe: u32,
    probe_counts: vec3<u32>,
    groups_x: u32,
    scroll_offsets: vec3<u32>,
    cover_first: u32,          // classify_cover: the first probe of this dispatch's chunk
    reach_rel: f32,
    bias_m: f32,
    cover_count: u32,          // classify_cover: probes in the chunk
    _pad0: f32,
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
// Per probe: inside geometry, kept (watches / chosen to cover), eligible, 0.
@group(0) @binding(5) var<storage, read_write> classify_out: array<vec4<u32>>;

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

// The ray's front-face hit point and facing shading normal (probegi_cpu::ddgi's
// front_hits: the ray's origin + direction × t), or false.
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
    out.normal = scene_facing_normal(scene_surface_point(h.triangle, h.instance, h.bary, false));
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

// probegi_core::probe_classification::uncovered_point_probe, over the kept flags in classify_out.
fn classify_uncovered(point: vec3<f32>, normal: vec3<f32>) -> u32 {
    // probegi_core::probe_grid::ProbeGrid::cage
    let max_c = vec3<f32>(max(vec3<i32>(classify_params.probe_counts) - vec3<i32>(1), vec3<i32>(0)));
    let rel = (point - classify_params.origin_m) / classify_params.spacing_m;
    let base = vec3<u32>(clamp(floor(rel), vec3<f32>(0.0), max_c));
    let base_pos = classify_params.origin_m + classify_params.spacing_m * vec3<f32>(base);
    let alpha = clamp((point - base_pos) / classify_params.spacing_m, vec3<f32>(0.0), vec3<f32>(1.0));
    var best = CLASSIFY_NONE;
    var best_w = 0.0;
    for (var i = 0u; i < 8u; i++) {
        let o = vec3<u32>(i & 1u, (i >> 1u) & 1u, (i >> 2u) & 1u);
        let corner = min(base + o, vec3<u32>(max_c));
        let p = classify_probe_index(corner);
        if (dot(classify_positions[p].xyz - point, normal) <= 0.0) {
            continue;
        }
        if (classify_out[p].y != 0u) {
            return CLASSIFY_NONE;
        }
        let fo = vec3<f32>(o);
        let t = (vec3<f32>(1.0) - alpha) * (vec3<f32>(1.0) - fo) + alpha * fo;
        let w = t.x * t.y * t.z;
        if (classify_out[p].z != 0u && (best == CLASSIFY_NONE || w > best_w)) {
            best = p;
            best_w = w;
        }
    }
    return best;
}

@compute @workgroup_size(1)
fn classify_cover() {
    let n = classify_params.rays_per_probe;
    let end = min(classify_params.cover_first + classify_params.cover_count, classify_params.probe_count);
    for (var p = classify_params.cover_first; p < end; p++) {
        let probe = classify_probes[p];
        if (probe.y == 0u || probe.x == CLASSIFY_NONE) {
            continue;
        }
        for (var r = probe.x; r < probe.x + n; r++) {
            let f = classify_front_hit(r);
            if (!f.ok) { continue; }
            let q = classify_uncovered(f.point, f.normal);
            if (q != CLASSIFY_NONE) {
                classify_out[q].y = 1u;
            }
        }
    }
}

