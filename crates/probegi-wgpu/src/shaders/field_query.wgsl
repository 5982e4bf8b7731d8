// Batch query of the DDGI field (`ddgi_query.wgsl`, its group 2 by `shader_registry`):
// one thread per point. Must match `probegi_wgpu::ddgi_query::{FieldQueryParams, QueryPoint}`.

struct FieldQueryParams {
    point_count: u32,
    groups_x: u32,
    _pad0: u32,
    _pad1: u32,
};

struct QueryPoint {
    position: vec4<f32>,  // xyz
    normal: vec4<f32>,    // xyz, unit
    view_dir: vec4<f32>,  // xyz, unit, surface → viewer
};

@group(0) @binding(0) var<uniform> query_params: FieldQueryParams;
@group(0) @binding(1) var<storage, read> query_points: array<QueryPoint>;
@group(0) @binding(2) var<storage, read_write> query_irradiance: array<vec4<f32>>;

@compute @workgroup_size(64)
fn query_field(@builtin(workgroup_id) wid: vec3<u32>, @builtin(local_invocation_index) lid: u32) {
    let i = (wid.y * query_params.groups_x + wid.x) * 64u + lid;
    if (i >= query_params.point_count) {
        return;
    }
    let q = query_points[i];
    query_irradiance[i] = vec4<f32>(ddgi_irradiance(q.position.xyz, q.normal.xyz, q.view_dir.xyz), 0.0);
}
