// Trace pass: one thread per ray through `bvh.wgsl`. Must match
// `probegi_wgpu::bvh_trace::{TraceParams, GpuRay, GpuRayHit}` (#[repr(C)], 16, 32 and 24 bytes).

struct TraceParams {
    ray_count: u32,
    // Workgroups per dispatch row: ray = (wid.y * groups_x + wid.x) * 64 + lid.
    groups_x: u32,
    // 1: any hit (shadow rays), 0: closest hit.
    any_hit: u32,
    // BVH_INSTANCE_* flags of instances left out (BVH_INSTANCE_MOVING: static geometry only).
    skip: u32,
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

@compute @workgroup_size(64)
fn trace_rays(@builtin(workgroup_id) wid: vec3<u32>, @builtin(local_invocation_index) lid: u32) {
    let i = (wid.y * trace_params.groups_x + wid.x) * 64u + lid;
    if (i >= trace_params.ray_count) {
        return;
    }
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
