// A cubemap texture as the scene's equirectangular sky map (sky_from_cubemap::GpuSkyFromCubemap):
// each map texel reads the cube's first level, nearest texel, along `to_cube` times its
// centre's direction, and writes its radiance where scene.wgsl's `scene_sky` reads it
// (three f32 words a texel, row-major from the top row, at `first_word` of scene_textures).
// The host's twin: probegi_bevy::environment_sky::equirect_from_cubemap.

// Must match `SkyFromCubemapParams` in sky_from_cubemap.rs.
struct SkyFromCubemapParams {
    // The rows of the linear map from a world direction to the cube's lookup direction.
    to_cube_x: vec4<f32>,
    to_cube_y: vec4<f32>,
    to_cube_z: vec4<f32>,
    first_word: u32,
    width: u32,
    face_width: u32,
    _pad: u32,
}

@group(0) @binding(0) var<uniform> sky_params: SkyFromCubemapParams;
@group(0) @binding(1) var sky_cube: texture_2d_array<f32>;
@group(0) @binding(2) var<storage, read_write> sky_words: array<u32>;

const SKY_PI: f32 = 3.14159265358979;

// probegi_scene::environment_map::uv_to_direction: Mitsuba's envmap convention.
fn sky_uv_to_direction(uv: vec2<f32>) -> vec3<f32> {
    let phi = uv.x * 2.0 * SKY_PI;
    let theta = uv.y * SKY_PI;
    return vec3<f32>(sin(theta) * sin(phi), cos(theta), -sin(theta) * cos(phi));
}

// probegi_bevy::environment_sky::cube_face: the face (+X, −X, +Y, −Y, +Z, −Z) of
// direction `s`'s major axis and its (u, v) in [0, 1]², Vulkan's and WebGPU's table.
fn sky_cube_face(s: vec3<f32>) -> vec3<f32> {
    let a = abs(s);
    var face = 0.0;
    var sc = 0.0;
    var tc = 0.0;
    var ma = 1.0;
    if (a.x >= a.y && a.x >= a.z) {
        ma = a.x;
        if (s.x > 0.0) { face = 0.0; sc = -s.z; tc = -s.y; } else { face = 1.0; sc = s.z; tc = -s.y; }
    } else if (a.y >= a.z) {
        ma = a.y;
        if (s.y > 0.0) { face = 2.0; sc = s.x; tc = s.z; } else { face = 3.0; sc = s.x; tc = -s.z; }
    } else {
        ma = a.z;
        if (s.z > 0.0) { face = 4.0; sc = s.x; tc = -s.y; } else { face = 5.0; sc = -s.x; tc = -s.y; }
    }
    return vec3<f32>(face, (sc / ma + 1.0) * 0.5, (tc / ma + 1.0) * 0.5);
}

@compute @workgroup_size(8, 8)
fn sky_from_cubemap(@builtin(global_invocation_id) id: vec3<u32>) {
    let w = sky_params.width;
    let h = w / 2u;
    if (id.x >= w || id.y >= h) {
        return;
    }
    let uv = vec2<f32>((f32(id.x) + 0.5) / f32(w), (f32(id.y) + 0.5) / f32(h));
    let d = sky_uv_to_direction(uv);
    let s = vec3<f32>(dot(sky_params.to_cube_x.xyz, d), dot(sky_params.to_cube_y.xyz, d),
                      dot(sky_params.to_cube_z.xyz, d));
    let f = sky_cube_face(s);
    let n = sky_params.face_width;
    let x = min(u32(f.y * f32(n)), n - 1u);
    let y = min(u32(f.z * f32(n)), n - 1u);
    let c = textureLoad(sky_cube, vec2<u32>(x, y), u32(f.x), 0).rgb;
    // Radiance is finite and non-negative: a negative or non-finite texel reads as
    // black (the host's map refuses such a cube instead).
    let r = select(vec3<f32>(0.0), max(c, vec3<f32>(0.0)), all(c == c) && all(abs(c) < vec3<f32>(3.0e38)));
    let k = sky_params.first_word + 3u * (id.y * w + id.x);
    sky_words[k] = bitcast<u32>(r.x);
    sky_words[k + 1u] = bitcast<u32>(r.y);
    sky_words[k + 2u] = bitcast<u32>(r.z);
}
