// Trace pass: one thread per ray through `bvh.wgsl`. Must match
// `probegi_wgpu::bvh_trace::{TraceParams, GpuRay, GpuRayHit}` (#[repr(C)], 160, 32 and 24 bytes).
//
// Thread order (probegi_wgpu::bvh_trace::TraceSegment): a batch of probe rays is
// stored probe-major (a probe's rays together, as the blend reads them), which
// puts a probe's whole sphere of directions in one workgroup: the lanes of a
// SIMD group then walk unrelated parts of the BVH. Within a segment of P probes
// × R rays, thread j traces ray r = j / P of probe p = j % P instead, so
// neighbouring lanes trace the same Fibonacci direction from neighbouring
// probes: nearly parallel rays from nearby origins, which visit the same nodes
// (the coherence that Ylitie et al. 2017 §4 and Aila & Laine 2009 find decides
// SIMT traversal cost). Only the order of the threads changes; each ray's hit,
// and where it is written, are the same.

struct TraceParams {
    ray_count: u32,
    // Workgroups per dispatch row: ray = (wid.y * groups_x + wid.x) * 64 + lid.
    groups_x: u32,
    // 1: any hit (shadow rays), 0: closest hit.
    any_hit: u32,
    // BVH_INSTANCE_* flags of instances left out (BVH_INSTANCE_MOVING: static geometry only).
    skip: u32,
    // Segments in `segments` (0: threads trace rays in batch order).
    segment_count: u32,
    _pad0: u32,
    _pad1: u32,
    _pad2: u32,
    // Per segment: (first ray, probes, rays per probe, 0).
    segments: array<vec4<u32>, TRACE_MAX_SEGMENTS>,
};

struct GpuRay {
    origin: vec3<f32>,
    t_min: f32,
    dir: vec3<f32>,
    t_max: f32,
};

struct GpuRayHit {
    // Hit distance; the ray's t_max for a miss.
    t: f32,
    // Scene triangle, bit 31 set on a back face; 0xffffffff for a miss.
    triangle: u32,
    bary: vec2<f32>,
    // `Scene::instances` index, 0xffffffff for the scene's own mesh (and a miss).
    instance: u32,
    _pad: u32,
};

@group(0) @binding(0) var<uniform> trace_params: TraceParams;
@group(0) @binding(1) var<storage, read> rays: array<GpuRay>;
@group(0) @binding(2) var<storage, read_write> hits: array<GpuRayHit>;

// The batch ray that thread j traces (see the thread order above).
fn trace_ray_of_thread(j: u32) -> u32 {
    for (var s = 0u; s < min(trace_params.segment_count, TRACE_MAX_SEGMENTS); s++) {
        let seg = trace_params.segments[s];
        let local = j - seg.x;
        if (j >= seg.x && seg.y > 0u && local / seg.y < seg.z) {
            return seg.x + (local % seg.y) * seg.z + local / seg.y;
        }
    }
    return j;
}

@compute @workgroup_size(64)
fn trace_rays(@builtin(workgroup_id) wid: vec3<u32>, @builtin(local_invocation_index) lid: u32) {
    let j = (wid.y * trace_params.groups_x + wid.x) * 64u + lid;
    if (j >= trace_params.ray_count) {
        return;
    }
    let i = trace_ray_of_thread(j);
    let r = rays[i];
    let ray = bvh_make_ray(r.origin, r.dir, r.t_min, r.t_max);
    let h = bvh_trace_skipping(ray, trace_params.any_hit != 0u, trace_params.skip);
    if (h.leaf == BVH_NO_HIT) {
        hits[i] = GpuRayHit(r.t_max, BVH_NO_HIT, vec2<f32>(0.0), BVH_NO_HIT, 0u);
        return;
    }
    var triangle = bvh_triangle_id(h.leaf);
    if (h.backface) {
        triangle |= 0x80000000u;
    }
    hits[i] = GpuRayHit(h.t, triangle, h.bary, h.instance, 0u);
}
