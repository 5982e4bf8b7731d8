// Punctual lights lit through the shadowing field (seed 003 §5.2), for passes that
// include ddgi_query.wgsl and scene.wgsl (the camera frame; the probe shade under
// `shadow_field_probe_shading`).
// scene_direct_punctual with each light's visibility from the shadowing field
// (probegi_cpu::shading::punctual_direct_with under `shadow_field`), a shadow ray
// where the field has none.
fn shadow_lit_punctual(sp: SurfacePoint, to_viewer: vec3<f32>) -> vec3<f32> {
    let fr = frame_from_normal(scene_facing_normal(sp));
    var wo = frame_to_local(fr, to_viewer);
    wo.z = max(wo.z, 1e-4);
    wo = normalize(wo);
    let bsdf = scene_bsdf(sp);
    let n = scene_facing_normal(sp);
    // The point's shadow cage, weighed once for all its lights.
    let cage = ddgi_shadow_cage(sp.position, n, to_viewer);
    var l = vec3<f32>(0.0);
    for (var k = 0u; k < bitcast<u32>(scene_lights[0].x); k++) {
        var e = vec3<f32>(0.0);
        let inc = scene_punctual(k, sp.position, &e);
        if (!(max(max(e.x, e.y), e.z) > 0.0)) {
            continue;
        }
        let cos = scene_lambert_cos(sp, inc.xyz);
        if (cos <= 0.0) {
            continue;
        }
        var v = -1.0;
        if (cage.member != DDGI_NO_PROBE) {
            v = ddgi_shadow_cage_visibility(cage, inc.xyz);
        } else {
            var t_max = SCENE_F32_MAX;
            if (inc.w < SCENE_F32_MAX) {
                t_max = inc.w * (1.0 - 1e-4);
            }
            let shadow = bvh_trace(bvh_make_ray(scene_spawn_origin(sp, inc.xyz), inc.xyz, 0.0, t_max), true);
            v = select(0.0, 1.0, shadow.leaf == BVH_NO_HIT);
        }
        if (v > 0.0) {
            l += bsdf_eval(bsdf, wo, frame_to_local(fr, inc.xyz)) * e * (cos * v);
        }
    }
    return l;
}

