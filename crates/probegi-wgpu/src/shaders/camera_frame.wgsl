// The camera pass on the GPU (probegi_cpu::gbuffer::trace_gbuffer + frame_loop::camera_pass::
// shade_camera under DDGI): per pixel a primary ray through `bvh.wgsl` (pixel
// centre on frame 0, jittered inside the pixel after), then
//   direct   = emission + direct light (scene.wgsl; the emitters' specular lobe left
//              to the glossy ray on glossy pixels) + one GGX-sampled glossy ray whose
//              hit gets emission + direct light + diffuse albedo/π × the field (and,
//              with second-order glossy, its specular reflection of the field);
//   irradiance = ddgi_irradiance / π (ddgi_query.wgsl, group 2), which the host
//              weighs by the diffuse albedo (accumulated over a still camera's frames).
// Pixels that see nothing get the sky. `camera_direct` holds three texels per pixel:
// the direct term at 3i, the diffuse albedo that weighs `irradiance` at 3i + 1,
// and the hit point at 3i + 2 (w: 1 for a hit, 0 for none); the w of the first
// two hold the octahedral coordinates (ddgi_oct_encode) of the geometric normal
// facing the camera. Point and normal are the temporal filter's surface.
// The CPU accumulates both over a still camera's frames.
// `camera_irradiance[i].w` flags surfaces with a diffuse albedo (1) and those of them unlit (2),
// plus 4 where the direct term was non-finite (written as 0).
// With flag 4 (the screen scheme's requests) every surface pixel also sets, in
// `camera_requests`, the bits of the probes its query reads
// (probegi_core::ddgi_volume_blend::field_set_cage_probes; bit = the member's
// first probe in ddgi_probes + the storage slot, DdgiFieldSet::probe_request_layout).
// Must match `probegi_wgpu::camera_frame::CameraParams` (#[repr(C)], 96 bytes).

struct CameraParams {
    origin: vec4<f32>,   // xyz; w = tan(fov_y / 2)
    forward: vec4<f32>,  // xyz; w = aspect
    right: vec4<f32>,    // xyz; w = width (pixels)
    up: vec4<f32>,       // xyz; w = height (pixels)
    info: vec4<u32>,     // frame, seed, area samples, flags (1: second-order glossy, 2: shadowing field,
                         // 4: probe requests)
    sky: vec4<f32>,      // the constant sky's radiance; w: sky-map samples per pixel (u32 bits)
};

@group(0) @binding(0) var<uniform> camera: CameraParams;
@group(0) @binding(1) var<storage, read_write> camera_direct: array<vec4<f32>>;
@group(0) @binding(2) var<storage, read_write> camera_irradiance: array<vec4<f32>>;
@group(0) @binding(3) var<storage, read_write> camera_requests: array<atomic<u32>>;

// probegi_core::ddgi_volume_blend::field_set_cage_probes: sets the request bit
// of the eight cage corners of the biased point in every member that weighs it.
fn camera_request_probes(position: vec3<f32>, normal: vec3<f32>, view_dir: vec3<f32>) {
    let n = ddgi_set.header.x;
    var wsum = 0.0;
    for (var f = 0u; f < n; f++) {
        let w = ddgi_member_weight(f, position, wsum);
        if (!(w > 0.0)) {
            continue;
        }
        wsum += w;
        let v = ddgi_set.volumes[f];
        let cage = ddgi_cage(v, position + ddgi_surface_bias(v, normal, view_dir));
        for (var i = 0u; i < 8u; i++) {
            let o = vec3<i32>(i32(i & 1u), i32((i >> 1u) & 1u), i32((i >> 2u) & 1u));
            let bit = v.extra.x + ddgi_probe_index(v, vec3<u32>(min(cage.base + o, cage.max_c)));
            atomicOr(&camera_requests[bit / 32u], 1u << (bit % 32u));
        }
    }
}

fn camera_finite(v: vec3<f32>) -> bool {
    return all(abs(v) <= vec3<f32>(SCENE_F32_MAX));
}

@compute @workgroup_size(8, 8)
fn shade_camera(@builtin(global_invocation_id) gid: vec3<u32>) {
    let width = u32(camera.right.w);
    let height = u32(camera.up.w);
    if (gid.x >= width || gid.y >= height) {
        return;
    }
    let i = gid.y * width + gid.x;
    var rng = rng_hash(camera.info.y ^ rng_hash(camera.info.x ^ rng_hash(i)));
    var jitter = vec2<f32>(0.5);
    if (camera.info.x != 0u) {
        jitter = vec2<f32>(rng_next(&rng), rng_next(&rng));
    }
    // CameraRays::ray_dir_world
    let ndc_x = 2.0 * (f32(gid.x) + jitter.x) / camera.right.w - 1.0;
    let ndc_y = 1.0 - 2.0 * (f32(gid.y) + jitter.y) / camera.up.w;
    let dir = normalize(camera.forward.xyz + camera.right.xyz * (ndc_x * camera.origin.w * camera.forward.w)
        + camera.up.xyz * (ndc_y * camera.origin.w));
    let hit = bvh_trace(bvh_make_ray(camera.origin.xyz, dir, 0.0, SCENE_F32_MAX), false);
    if (hit.leaf == BVH_NO_HIT) {
        camera_direct[3u * i] = vec4<f32>(camera_sky(dir), 0.0);
        camera_direct[3u * i + 1u] = vec4<f32>(0.0);
        camera_direct[3u * i + 2u] = vec4<f32>(0.0);
        camera_irradiance[i] = vec4<f32>(0.0);
        return;
    }
    let sp = scene_surface_point(bvh_triangle_id(hit.leaf), hit.instance, hit.bary, hit.backface);
    let to_viewer = -dir;
    let bsdf = scene_bsdf(sp);
    let glossy = max(max(bsdf.specular_f0.x, bsdf.specular_f0.y), bsdf.specular_f0.z) > 0.0;
    let area = camera.info.z;
    var l = shadow_lit_direct(sp, to_viewer, area, !glossy, (camera.info.w & 2u) != 0u, &rng);
    l += scene_sky_direct(sp, bitcast<u32>(camera.sky.w), &rng);
    if (sp.front_face) {
        l += scene_emission(sp.material, sp.uv, sp.uv1);
    }
    if (glossy) {
        let fr = frame_from_normal(scene_facing_normal(sp));
        var wo = frame_to_local(fr, to_viewer);
        wo.z = max(wo.z, 1e-4);
        wo = normalize(wo);
        let u = vec2<f32>(rng_next(&rng), rng_next(&rng));
        var weight = vec3<f32>(0.0);
        let s = bsdf_sample_specular(bsdf, wo, u, &weight);
        if (s.w > 0.0) {
            let wi = frame_to_world(fr, s.xyz);
            if (scene_lambert_cos(sp, wi) > 0.0) {
                let g = bvh_trace(bvh_make_ray(scene_spawn_origin(sp, wi), wi, 0.0, SCENE_F32_MAX), false);
                var lr = camera_sky(wi);
                if (g.leaf != BVH_NO_HIT) {
                    // frame_loop::camera_pass::shade_glossy_hit
                    let sh = scene_surface_point(bvh_triangle_id(g.leaf), g.instance, g.bary, g.backface);
                    let bh = scene_bsdf(sh);
                    let nh = scene_facing_normal(sh);
                    lr = scene_direct(sh, -wi, area, true, &rng)
                        + bsdf_diffuse_albedo(bh) / SCENE_PI * ddgi_irradiance(sh.position, nh, -wi);
                    if (sh.front_face) {
                        lr += scene_emission(sh.material, sh.uv, sh.uv1);
                    }
                    if ((camera.info.w & 1u) != 0u && max(max(bh.specular_f0.x, bh.specular_f0.y), bh.specular_f0.z) > 0.0) {
                        // probegi_cpu::glossy::second_order_specular
                        let mirror = wi - nh * (2.0 * dot(wi, nh));
                        let e_mirror = ddgi_irradiance(sh.position, mirror, -wi);
                        lr += bsdf_specular_albedo(bh.specular_f0, max(dot(-wi, nh), 0.0), bh.alpha) * e_mirror / SCENE_PI;
                    }
                }
                l += weight * lr;
            }
        }
    }
    let oct = ddgi_oct_encode(scene_facing_geometric_normal(sp));
    camera_direct[3u * i] = vec4<f32>(select(vec3<f32>(0.0), l, camera_finite(l)), oct.x);
    let e = ddgi_irradiance(sp.position, scene_facing_normal(sp), to_viewer);
    if ((camera.info.w & 4u) != 0u) {
        camera_request_probes(sp.position, scene_facing_normal(sp), to_viewer);
    }
    // w: 1 for a surface with a diffuse albedo, 2 when the field gave it nothing
    // (the `frame_unlit_fraction` statistic: a black wall shows up here).
    let albedo = bsdf_diffuse_albedo(bsdf);
    var flag = 0.0;
    if (max(max(albedo.x, albedo.y), albedo.z) > 0.0) {
        flag = select(1.0, 2.0, !(max(max(e.x, e.y), e.z) > 0.0));
    }
    // + 4: the direct term came out NaN or infinite and was written as 0.
    flag += select(4.0, 0.0, camera_finite(l));
    camera_direct[3u * i + 1u] = vec4<f32>(albedo, oct.y);
    camera_direct[3u * i + 2u] = vec4<f32>(sp.position, 1.0);
    camera_irradiance[i] = vec4<f32>(e / SCENE_PI, flag);
}

// The sky a camera ray or a glossy reflection that leaves the scene sees: the
// sky map's (scene.wgsl's scene_sky), else the frame's constant sky (which the
// host may change between frames without posing the scene).
fn camera_sky(dir: vec3<f32>) -> vec3<f32> {
    if (bitcast<u32>(scene_lights[0].z) != SCENE_NONE) {
        return scene_sky(dir);
    }
    return camera.sky.xyz;
}
