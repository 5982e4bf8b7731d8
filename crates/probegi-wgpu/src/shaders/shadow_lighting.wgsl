// Punctual lights lit through the shadowing field (seed 003 §5.2), for passes that
// include ddgi_query.wgsl and scene.wgsl (the camera frame; the probe shade under
// `shadow_field_probe_shading`): scene_direct_punctual with each light's
// visibility read from the point's shadow cage (probegi_cpu::shading::
// punctual_direct_with under `shadow_field`), shadow rays where no volume has one.
fn shadow_lit_punctual(sp: SurfacePoint, to_viewer: vec3<f32>) -> vec3<f32> {
    let s = scene_shading(sp, to_viewer);
    // The point's shadow cage, weighed once for all its lights.
    let cage = ddgi_shadow_cage(sp.position, scene_facing_normal(sp), to_viewer);
    if (cage.member == DDGI_NO_PROBE) {
        return scene_direct_punctual(sp, s);
    }
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
        let v = ddgi_shadow_cage_visibility(cage, inc.xyz);
        if (v > 0.0) {
            l += bsdf_eval(s.bsdf, s.wo, frame_to_local(s.fr, inc.xyz)) * e * (cos * v);
        }
    }
    return l;
}

// scene_direct, with the punctual lights through the shadowing field when
// `through_field` (the emitters' samples stay ray-traced either way).
fn shadow_lit_direct(sp: SurfacePoint, to_viewer: vec3<f32>, area_samples: u32, specular_area: bool,
                     through_field: bool, rng: ptr<function, u32>) -> vec3<f32> {
    if (!through_field) {
        return scene_direct(sp, to_viewer, area_samples, specular_area, rng);
    }
    return shadow_lit_punctual(sp, to_viewer) + scene_direct_area(sp, to_viewer, area_samples, specular_area, rng);
}
