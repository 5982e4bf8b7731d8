// A scene's surfaces, materials and lights on the GPU, mirroring the CPU's:
//   probegi_scene::Scene::surface_point          (interpolated shading normal on the geometric side),
//   probegi_scene::SurfacePoint::{facing_normal, facing_geometric_normal, spawn_origin},
//   probegi_scene::material::Material::{bsdf, base_color, roughness_metallic, emission}, probegi_scene::material::UvMapping::apply,
//   probegi_scene::texture::{Footprint::sampled, axis_texels, Texture::sample},
//   probegi_core::bsdf::SurfaceBsdf::eval        (Lambert × (1 − max F0) + GGX, height-correlated Smith, Schlick),
//   probegi_cpu::shading::{lambert_cos, shadow_ray_to, shadow_ray_along, punctual_direct},
//   probegi_cpu::light_sampling::{AreaLights::sample, punctual_incident}, probegi_core::punctual,
//   probegi_cpu::direct::DirectLighting::reflected (punctual exactly, area lights by stratified NEE).
// Random numbers differ from the CPU's (a PCG hash per ray instead of a PCG32
// stream per probe), so area-light estimates agree in distribution, not bit for bit.
// Buffers (group 3, written by `probegi_wgpu::gpu_scene::GpuScene`):
//   scene_triangles: 15 × vec4 per scene triangle: p0 (w: material bits), p1, p2, n0, n1, n2, (uv0, uv1),
//                    (uv2, set-1 uv0), t0, t1, t2 (tangent xyz, bitangent sign w; zero when none),
//                    (set-1 uv1, set-1 uv2), colour0, colour1, colour2 (linear rgb, 1): the
//                    scene mesh's (moving objects as posed at the frame), then each prototype's
//                    (`Scene::prototypes`) in its local space; then per `Scene::instances` entry
//                    7 × vec4: world-from-local columns (xyz; w of the first: its prototype's first
//                    triangle bits), its translation, normal-from-local columns (xyz)
//   scene_materials: 13 × vec4 per material: (base colour factor, base texture bits | none),
//                    (specular colour, α of the roughness factor), (model: 0 none, 1 MTL, 2 metallic-roughness;
//                    metallic, roughness, metallic-roughness texture bits | none),
//                    (emission = factor × strength, emissive texture bits | none),
//                    (normal texture bits | none, normal scale, bump texture bits | none, bump multiplier),
//                    then the UvMappings of the base-colour, emissive, normal (and bump) and
//                    metallic-roughness textures, 2 × vec4 each: (row 0, set bits), (row 1, 0)
//   scene_textures:  words 0..255 the sRGB8 → linear table (f32 bits), 256 texture count, 257 the
//                    GGX albedo table's side N, 258 its first word, 259 the first vec4 of the instance
//                    records in scene_triangles, then per texture (width,
//                    height, first texel word, sampler: wrap u (0 repeat, 1 mirrored, 2 clamp) | wrap v << 2
//                    | nearest << 4), the (A, B) table (N × N × 2 f32 bits,
//                    probegi_core::bsdf::specular_albedo_table), then RGB8 texels one per word,
//                    then the sky map's texels (`Scene::sky_map`), f32 bits r, g, b each, row-major
//                    from the top row, then its sampling CDFs (EnvironmentMap::sampling_cdfs, f32
//                    bits): the rows' H + 1 running sums, then each row's W + 1
//   scene_lights:    vec4 header (punctual count, emitter count bits, the sky map's first word in
//                    scene_textures bits (NONE: no map), its width bits), vec4 sky: the constant
//                    sky's radiance, or with a map (intensity, sin, cos of minus its rotation, 0),
//                    per punctual light 4 × vec4: (kind, range or −1, inner, outer), position, direction, colour × intensity;
//                    per emitter vec4: (triangle bits, CDF, selection pdf / area, 0)

@group(3) @binding(0) var<storage, read> scene_triangles: array<vec4<f32>>;
@group(3) @binding(1) var<storage, read> scene_materials: array<vec4<f32>>;
@group(3) @binding(2) var<storage, read> scene_textures: array<u32>;
@group(3) @binding(3) var<storage, read> scene_lights: array<vec4<f32>>;

const SCENE_PI: f32 = 3.14159265358979;
const SCENE_TAU: f32 = 6.28318530717959;
const SCENE_NONE: u32 = 0xffffffffu;
const SCENE_F32_MAX: f32 = 3.4028235e38;
// probegi_core::bsdf::MIN_ALPHA
const SCENE_MIN_ALPHA: f32 = 1e-3;
const SCENE_TRIANGLE_VEC4S: u32 = 15u;
const SCENE_MATERIAL_VEC4S: u32 = 13u;
// The material's texture slots (UvMapping order in scene_materials).
const SCENE_SLOT_BASE: u32 = 0u;
const SCENE_SLOT_EMISSIVE: u32 = 1u;
const SCENE_SLOT_NORMAL: u32 = 2u;
const SCENE_SLOT_METALLIC_ROUGHNESS: u32 = 3u;
// probegi_scene::material::BUMP_WHITE_HEIGHT_REL
const SCENE_BUMP_WHITE_HEIGHT_REL: f32 = 0.02;

struct SurfacePoint {
    position: vec3<f32>,
    geometric_normal: vec3<f32>,
    shading_normal: vec3<f32>,
    uv: vec2<f32>,
    // Texture coordinate set 1 and the linear vertex colour.
    uv1: vec2<f32>,
    color: vec3<f32>,
    material: u32,
    front_face: bool,
};

// probegi_scene::material::UvMapping::apply for texture slot `slot` of
// `material`: its set's coordinates (`uv0` or `uv1`), transformed unless the
// mapping is the identity.
fn scene_map_uv(material: u32, slot: u32, uv0: vec2<f32>, uv1: vec2<f32>) -> vec2<f32> {
    let m = material * SCENE_MATERIAL_VEC4S + 5u + 2u * slot;
    let r0 = scene_materials[m];
    let r1 = scene_materials[m + 1u];
    let uv = select(uv0, uv1, bitcast<u32>(r0.w) >= 1u);
    if (all(r0.xyz == vec3<f32>(1.0, 0.0, 0.0)) && all(r1.xyz == vec3<f32>(0.0, 1.0, 0.0))) {
        return uv;
    }
    return vec2<f32>(r0.x * uv.x + r0.y * uv.y + r0.z, r1.x * uv.x + r1.y * uv.y + r1.z);
}

fn scene_normalize_or_zero(v: vec3<f32>) -> vec3<f32> {
    let l = length(v);
    if (l > 0.0 && l < SCENE_F32_MAX) {
        return v / l;
    }
    return vec3<f32>(0.0);
}

// probegi_scene::scene `Corners`: a hit triangle's corners in world space, an
// instanced copy's placed by its transform (`Corners::placed`).
struct SceneCorners {
    p0: vec3<f32>,
    p1: vec3<f32>,
    p2: vec3<f32>,
    n0: vec3<f32>,
    n1: vec3<f32>,
    n2: vec3<f32>,
    uv0: vec2<f32>,
    uv1: vec2<f32>,
    uv2: vec2<f32>,
    // Texture coordinate set 1 and the colour of each corner.
    set1_0: vec2<f32>,
    set1_1: vec2<f32>,
    set1_2: vec2<f32>,
    color0: vec3<f32>,
    color1: vec3<f32>,
    color2: vec3<f32>,
    t0: vec4<f32>,
    t1: vec4<f32>,
    t2: vec4<f32>,
    material: u32,
};

fn scene_corners(triangle: u32, instance: u32) -> SceneCorners {
    var tri = triangle;
    var inst = 0u;
    if (instance != SCENE_NONE) {
        inst = scene_textures[259] + instance * 7u;
        tri += bitcast<u32>(scene_triangles[inst].w);
    }
    let t = tri * SCENE_TRIANGLE_VEC4S;
    let p0 = scene_triangles[t];
    let uv01 = scene_triangles[t + 6u];
    let uv2 = scene_triangles[t + 7u];
    let set1 = scene_triangles[t + 11u];
    var c = SceneCorners(p0.xyz, scene_triangles[t + 1u].xyz, scene_triangles[t + 2u].xyz,
        scene_triangles[t + 3u].xyz, scene_triangles[t + 4u].xyz, scene_triangles[t + 5u].xyz,
        uv01.xy, uv01.zw, uv2.xy, uv2.zw, set1.xy, set1.zw,
        scene_triangles[t + 12u].xyz, scene_triangles[t + 13u].xyz, scene_triangles[t + 14u].xyz,
        scene_triangles[t + 8u], scene_triangles[t + 9u], scene_triangles[t + 10u], bitcast<u32>(p0.w));
    if (instance != SCENE_NONE) {
        let m = mat3x3<f32>(scene_triangles[inst].xyz, scene_triangles[inst + 1u].xyz, scene_triangles[inst + 2u].xyz);
        let tr = scene_triangles[inst + 3u].xyz;
        let nm = mat3x3<f32>(scene_triangles[inst + 4u].xyz, scene_triangles[inst + 5u].xyz, scene_triangles[inst + 6u].xyz);
        c.p0 = m * c.p0 + tr;
        c.p1 = m * c.p1 + tr;
        c.p2 = m * c.p2 + tr;
        c.n0 = nm * c.n0;
        c.n1 = nm * c.n1;
        c.n2 = nm * c.n2;
        c.t0 = vec4<f32>(scene_normalize_or_zero(m * c.t0.xyz), c.t0.w);
        c.t1 = vec4<f32>(scene_normalize_or_zero(m * c.t1.xyz), c.t1.w);
        c.t2 = vec4<f32>(scene_normalize_or_zero(m * c.t2.xyz), c.t2.w);
    }
    return c;
}

// probegi_scene::Scene::surface_point: the interpolated shading normal on the
// geometric side, perturbed by the material's normal or bump map. `instance`:
// the hit's `RayHit::instance` (SCENE_NONE for the scene's own mesh).
fn scene_surface_point(triangle: u32, instance: u32, bary_in: vec2<f32>, backface: bool) -> SurfacePoint {
    let c = scene_corners(triangle, instance);
    let bary = vec3<f32>(1.0 - bary_in.x - bary_in.y, bary_in.x, bary_in.y);
    let position = c.p0 * bary.x + c.p1 * bary.y + c.p2 * bary.z;
    let ng = scene_normalize_or_zero(cross(c.p1 - c.p0, c.p2 - c.p0));
    var ns = scene_normalize_or_zero(c.n0 * bary.x + c.n1 * bary.y + c.n2 * bary.z);
    if (all(ns == vec3<f32>(0.0))) {
        ns = ng;
    } else if (dot(ns, ng) < 0.0) {
        ns = -ns;
    }
    // probegi_scene::mesh::interpolate_attributes
    let uv = c.uv0 * bary.x + c.uv1 * bary.y + c.uv2 * bary.z;
    let uv1 = c.set1_0 * bary.x + c.set1_1 * bary.y + c.set1_2 * bary.z;
    let color = c.color0 * bary.x + c.color1 * bary.y + c.color2 * bary.z;
    let perturbed = scene_perturbed_normal(c, bary, ns, uv, uv1);
    // A perturbed normal below the surface would shade light from inside it.
    if (dot(perturbed, ng) > 1e-3) {
        ns = perturbed;
    }
    return SurfacePoint(position, ng, ns, uv, uv1, color, c.material, !backface);
}

fn scene_normalize_or(v: vec3<f32>, fallback: vec3<f32>) -> vec3<f32> {
    let n = scene_normalize_or_zero(v);
    return select(n, fallback, all(n == vec3<f32>(0.0)));
}

// Scene::perturbed_normal: `n` tilted by the normal map (tangent space, glTF's
// bitangent = sign · n × tangent) or by the bump map's slopes along ∂p/∂u, ∂p/∂v;
// both read the coordinates of the material's normal slot.
fn scene_perturbed_normal(c: SceneCorners, bary: vec3<f32>, n: vec3<f32>, uv0: vec2<f32>, uv1: vec2<f32>) -> vec3<f32> {
    let maps = scene_materials[c.material * SCENE_MATERIAL_VEC4S + 4u];
    let uv = scene_map_uv(c.material, SCENE_SLOT_NORMAL, uv0, uv1);
    let normal_tex = bitcast<u32>(maps.x);
    if (normal_tex != SCENE_NONE) {
        let t0 = c.t0;
        let tan0 = t0.xyz * bary.x + c.t1.xyz * bary.y + c.t2.xyz * bary.z;
        let tan = scene_normalize_or_zero(tan0 - n * dot(n, tan0));
        if (all(tan == vec3<f32>(0.0))) {
            return n;
        }
        let bitangent = cross(n, tan) * select(1.0, -1.0, t0.w < 0.0);
        let s = scene_texture_raw(normal_tex, uv) * 2.0 - vec3<f32>(1.0);
        let local = vec3<f32>(s.x * maps.y, s.y * maps.y, s.z);
        return scene_normalize_or(tan * local.x + bitangent * local.y + n * local.z, n);
    }
    let bump_tex = bitcast<u32>(maps.z);
    if (bump_tex != SCENE_NONE) {
        // uv_derivatives over the corners' mapped coordinates
        let cuv0 = scene_map_uv(c.material, SCENE_SLOT_NORMAL, c.uv0, c.set1_0);
        let cuv1 = scene_map_uv(c.material, SCENE_SLOT_NORMAL, c.uv1, c.set1_1);
        let cuv2 = scene_map_uv(c.material, SCENE_SLOT_NORMAL, c.uv2, c.set1_2);
        let duv02 = cuv0 - cuv2;
        let duv12 = cuv1 - cuv2;
        let dp02 = c.p0 - c.p2;
        let dp12 = c.p1 - c.p2;
        let det = duv02.x * duv12.y - duv02.y * duv12.x;
        if (abs(det) < 1e-12) {
            return n;
        }
        let inv = 1.0 / det;
        let dpdu = (dp02 * duv12.y - dp12 * duv02.y) * inv;
        let dpdv = (dp12 * duv02.x - dp02 * duv12.x) * inv;
        if (!(all(abs(dpdu) <= vec3<f32>(SCENE_F32_MAX)) && all(abs(dpdv) <= vec3<f32>(SCENE_F32_MAX)))) {
            return n;
        }
        let h = 260u + bump_tex * 4u;
        let size = vec2<f32>(f32(scene_textures[h]), f32(scene_textures[h + 1u]));
        let grad = scene_height_gradient(bump_tex, uv);
        let white_texels = SCENE_BUMP_WHITE_HEIGHT_REL * max(size.x, size.y);
        let slope = grad / size * white_texels * maps.w;
        let along_u = scene_normalize_or_zero(dpdu - n * dot(n, dpdu));
        let along_v = scene_normalize_or_zero(dpdv - n * dot(n, dpdv));
        return scene_normalize_or(n - along_u * slope.x - along_v * slope.y, n);
    }
    return n;
}

fn scene_facing_normal(sp: SurfacePoint) -> vec3<f32> {
    return select(-sp.shading_normal, sp.shading_normal, sp.front_face);
}

fn scene_facing_geometric_normal(sp: SurfacePoint) -> vec3<f32> {
    return select(-sp.geometric_normal, sp.geometric_normal, sp.front_face);
}

// SurfacePoint::spawn_origin.
fn scene_spawn_origin(sp: SurfacePoint, dir: vec3<f32>) -> vec3<f32> {
    let n = select(-sp.geometric_normal, sp.geometric_normal, dot(dir, sp.geometric_normal) >= 0.0);
    let p = abs(sp.position);
    let eps = 1e-4 * (1.0 + max(max(p.x, p.y), p.z));
    return sp.position + n * eps;
}

// probegi_cpu::shading::lambert_cos: the cosine on the viewer's side, or ≤ 0 when
// `wi` points into the surface by either normal.
fn scene_lambert_cos(sp: SurfacePoint, wi: vec3<f32>) -> f32 {
    let cos = dot(wi, scene_facing_normal(sp));
    if (cos > 0.0 && dot(wi, scene_facing_geometric_normal(sp)) > 0.0) {
        return cos;
    }
    return 0.0;
}

// probegi_scene::texture::Footprint::sampled over texture `tex` through its
// sampler: the four texels' words in scene_textures and the bilinear fractions;
// the default sampler (repeat, linear) is Footprint::at, bvh.wgsl's `wrap_footprint`.
struct TexFootprint {
    words: vec4<u32>,
    f: vec2<f32>,
};

fn scene_footprint(tex: u32, uv: vec2<f32>) -> TexFootprint {
    let h = 260u + tex * 4u;
    let width = scene_textures[h];
    let height = scene_textures[h + 1u];
    let sampler = scene_textures[h + 3u];
    let first = vec4<u32>(scene_textures[h + 2u]);
    if (sampler == 0u) {
        let fp = wrap_footprint(width, height, uv);
        return TexFootprint(fp.texel + first, fp.f);
    }
    if (!all(abs(uv) <= vec2<f32>(SCENE_F32_MAX))) {
        return TexFootprint(first, vec2<f32>(0.0));
    }
    let nearest = (sampler & 16u) != 0u;
    let cols = tex_axis(uv.x, width, sampler & 3u, nearest);
    let rows = tex_axis(uv.y, height, (sampler >> 2u) & 3u, nearest);
    let r = rows.i * width;
    return TexFootprint(vec4<u32>(r.x + cols.i.x, r.x + cols.i.y, r.y + cols.i.x, r.y + cols.i.y) + first,
        vec2<f32>(cols.f, rows.f));
}

// probegi_scene::texture::axis_texels: the two texel indices along an axis of
// `size` texels (the same one twice when `nearest`) and the fraction between.
struct AxisTexels {
    i: vec2<u32>,
    f: f32,
};

fn tex_address(i: i32, n: i32, wrap: u32) -> u32 {
    if (wrap == 0u) {
        return u32(((i % n) + n) % n);
    }
    if (wrap == 1u) {
        let m = ((i % (2 * n)) + 2 * n) % (2 * n);
        return u32(select(m, 2 * n - 1 - m, m >= n));
    }
    return u32(clamp(i, 0, n - 1));
}

fn tex_axis(c_in: f32, size: u32, wrap: u32, nearest: bool) -> AxisTexels {
    // One period of the wrap mode first (rem_euclid(1), rem_euclid(2), clamp to [−1, 2]).
    var c = clamp(c_in, -1.0, 2.0);
    if (wrap == 0u) {
        c = c_in - floor(c_in);
    } else if (wrap == 1u) {
        c = c_in - 2.0 * floor(c_in * 0.5);
    }
    let n = i32(size);
    if (nearest) {
        let i = tex_address(i32(floor(c * f32(size))), n, wrap);
        return AxisTexels(vec2<u32>(i, i), 0.0);
    }
    let x = c * f32(size) - 0.5;
    let x0 = floor(x);
    return AxisTexels(vec2<u32>(tex_address(i32(x0), n, wrap), tex_address(i32(x0) + 1, n, wrap)), x - x0);
}

fn tex_blend(v: array<vec3<f32>, 4>, f: vec2<f32>) -> vec3<f32> {
    return (v[0] * (1.0 - f.x) + v[1] * f.x) * (1.0 - f.y) + (v[2] * (1.0 - f.x) + v[3] * f.x) * f.y;
}

// Texture::sample: sRGB8 texels decoded by the table, then filtered.
fn scene_texture(tex: u32, uv: vec2<f32>) -> vec3<f32> {
    let fp = scene_footprint(tex, uv);
    var v: array<vec3<f32>, 4>;
    for (var k = 0u; k < 4u; k++) {
        let t = scene_textures[fp.words[k]];
        v[k] = vec3<f32>(
            bitcast<f32>(scene_textures[t & 0xffu]),
            bitcast<f32>(scene_textures[(t >> 8u) & 0xffu]),
            bitcast<f32>(scene_textures[(t >> 16u) & 0xffu]),
        );
    }
    return tex_blend(v, fp.f);
}

fn tex_unorm(t: u32) -> vec3<f32> {
    return vec3<f32>(f32(t & 0xffu), f32((t >> 8u) & 0xffu), f32((t >> 16u) & 0xffu)) * (1.0 / 255.0);
}

// Texture::sample_raw: the stored values as unorm (normal, height, metallic-roughness maps).
fn scene_texture_raw(tex: u32, uv: vec2<f32>) -> vec3<f32> {
    let fp = scene_footprint(tex, uv);
    var v: array<vec3<f32>, 4>;
    for (var k = 0u; k < 4u; k++) {
        v[k] = tex_unorm(scene_textures[fp.words[k]]);
    }
    return tex_blend(v, fp.f);
}

// Texture::sample_height_gradient's gradient: of the Rec. 709 grey level, per unit of u and v.
fn scene_height_gradient(tex: u32, uv: vec2<f32>) -> vec2<f32> {
    let fp = scene_footprint(tex, uv);
    let grey = vec3<f32>(0.2126, 0.7152, 0.0722);
    let h00 = dot(tex_unorm(scene_textures[fp.words.x]), grey);
    let h10 = dot(tex_unorm(scene_textures[fp.words.y]), grey);
    let h01 = dot(tex_unorm(scene_textures[fp.words.z]), grey);
    let h11 = dot(tex_unorm(scene_textures[fp.words.w]), grey);
    let d_dx = (1.0 - fp.f.y) * (h10 - h00) + fp.f.y * (h11 - h01);
    let d_dy = (1.0 - fp.f.x) * (h01 - h00) + fp.f.x * (h11 - h10);
    let h = 260u + tex * 4u;
    return vec2<f32>(d_dx * f32(scene_textures[h]), d_dy * f32(scene_textures[h + 1u]));
}

struct Bsdf {
    diffuse: vec3<f32>,
    specular_f0: vec3<f32>,
    alpha: f32,
};

// Material::bsdf at the surface point: base colour = factor × vertex colour ×
// texture; roughness and metalness × the metallic-roughness texture's G and B.
fn scene_bsdf(sp: SurfacePoint) -> Bsdf {
    let m = sp.material * SCENE_MATERIAL_VEC4S;
    let a = scene_materials[m];
    let s = scene_materials[m + 1u];
    let model = scene_materials[m + 2u];
    var base = a.xyz * sp.color;
    let tex = bitcast<u32>(a.w);
    if (tex != SCENE_NONE) {
        base = base * scene_texture(tex, scene_map_uv(sp.material, SCENE_SLOT_BASE, sp.uv, sp.uv1));
    }
    let kind = bitcast<u32>(model.x);
    if (kind == 0u) {
        return Bsdf(base, vec3<f32>(0.0), 1.0);
    }
    if (kind == 1u) {
        return Bsdf(base, s.xyz, s.w);
    }
    var metallic = model.y;
    var alpha = s.w;
    let mr_tex = bitcast<u32>(model.w);
    if (mr_tex != SCENE_NONE) {
        let texel = scene_texture_raw(mr_tex, scene_map_uv(sp.material, SCENE_SLOT_METALLIC_ROUGHNESS, sp.uv, sp.uv1));
        let roughness = model.z * texel.y;
        metallic = model.y * texel.z;
        alpha = clamp(roughness * roughness, SCENE_MIN_ALPHA, 1.0);
    }
    return Bsdf(base * (1.0 - metallic), mix(vec3<f32>(0.04), base, metallic), alpha);
}

// Material::emission at a point with coordinate sets `uv0`, `uv1` (front face
// only, as Scene::emitted).
fn scene_emission(material: u32, uv0: vec2<f32>, uv1: vec2<f32>) -> vec3<f32> {
    let e = scene_materials[material * SCENE_MATERIAL_VEC4S + 3u];
    let tex = bitcast<u32>(e.w);
    if (all(e.xyz == vec3<f32>(0.0)) || tex == SCENE_NONE) {
        return e.xyz;
    }
    return e.xyz * scene_texture(tex, scene_map_uv(material, SCENE_SLOT_EMISSIVE, uv0, uv1));
}

fn bsdf_diffuse_albedo(b: Bsdf) -> vec3<f32> {
    return b.diffuse * (1.0 - min(max(max(b.specular_f0.x, b.specular_f0.y), b.specular_f0.z), 1.0));
}

// SurfaceBsdf::eval in the local frame (+z = facing normal).
fn bsdf_eval(b: Bsdf, wo: vec3<f32>, wi: vec3<f32>) -> vec3<f32> {
    if (wi.z <= 0.0) {
        return vec3<f32>(0.0);
    }
    var f = bsdf_diffuse_albedo(b) / SCENE_PI;
    if (max(max(b.specular_f0.x, b.specular_f0.y), b.specular_f0.z) > 0.0 && wo.z > 0.0) {
        let h = scene_normalize_or_zero(wo + wi);
        if (any(h != vec3<f32>(0.0))) {
            let a = max(b.alpha, SCENE_MIN_ALPHA);
            let a2 = a * a;
            let c2 = h.z * h.z;
            let dd = c2 * (a2 - 1.0) + 1.0;
            let d = a2 / (SCENE_PI * dd * dd);
            let lo = wi.z * sqrt(a2 + (1.0 - a2) * wo.z * wo.z);
            let li = wo.z * sqrt(a2 + (1.0 - a2) * wi.z * wi.z);
            let g2 = 2.0 * wo.z * wi.z / (lo + li);
            let m = pow(1.0 - clamp(dot(wi, h), 0.0, 1.0), 5.0);
            let fresnel = b.specular_f0 + (vec3<f32>(1.0) - b.specular_f0) * m;
            f += fresnel * (d * g2 / (4.0 * wo.z * wi.z));
        }
    }
    return f;
}

// probegi_core::bsdf::specular_directional_albedo: F0·A + B, bilinear in the table.
fn bsdf_specular_albedo(f0: vec3<f32>, cos_o: f32, alpha: f32) -> vec3<f32> {
    let n = scene_textures[257u];
    let first = scene_textures[258u];
    let x = clamp(cos_o, 0.0, 1.0) * f32(n - 1u);
    let y = clamp(alpha, 0.0, 1.0) * f32(n - 1u);
    let x0 = min(u32(x), n - 2u);
    let y0 = min(u32(y), n - 2u);
    let fx = x - f32(x0);
    let fy = y - f32(y0);
    let at = array<u32, 4>(y0 * n + x0, y0 * n + x0 + 1u, (y0 + 1u) * n + x0, (y0 + 1u) * n + x0 + 1u);
    var v: array<vec2<f32>, 4>;
    for (var k = 0u; k < 4u; k++) {
        v[k] = vec2<f32>(bitcast<f32>(scene_textures[first + 2u * at[k]]), bitcast<f32>(scene_textures[first + 2u * at[k] + 1u]));
    }
    let a0 = v[0] + (v[1] - v[0]) * fx;
    let a1 = v[2] + (v[3] - v[2]) * fx;
    let ab = a0 + (a1 - a0) * fy;
    return f0 * ab.x + vec3<f32>(ab.y);
}

// SurfaceBsdf::sample_specular (GGX VNDF, Heitz 2018): (wi local, weight = F·G2/G1)
// in `weight`, or w = 0 when there is no sample.
fn bsdf_sample_specular(b: Bsdf, wo: vec3<f32>, u: vec2<f32>, weight: ptr<function, vec3<f32>>) -> vec4<f32> {
    if (!(max(max(b.specular_f0.x, b.specular_f0.y), b.specular_f0.z) > 0.0) || wo.z <= 0.0) {
        return vec4<f32>(0.0);
    }
    let a = max(b.alpha, SCENE_MIN_ALPHA);
    let vh = normalize(vec3<f32>(a * wo.x, a * wo.y, wo.z));
    let lensq = vh.x * vh.x + vh.y * vh.y;
    var t1 = vec3<f32>(1.0, 0.0, 0.0);
    if (lensq > 0.0) {
        t1 = vec3<f32>(-vh.y, vh.x, 0.0) / sqrt(lensq);
    }
    let t2 = cross(vh, t1);
    let r = sqrt(u.x);
    let phi = 2.0 * SCENE_PI * u.y;
    let p1 = r * cos(phi);
    let s = 0.5 * (1.0 + vh.z);
    let p2 = (1.0 - s) * sqrt(max(1.0 - p1 * p1, 0.0)) + s * r * sin(phi);
    let nh = t1 * p1 + t2 * p2 + vh * sqrt(max(1.0 - p1 * p1 - p2 * p2, 0.0));
    let h = normalize(vec3<f32>(a * nh.x, a * nh.y, max(nh.z, 1e-6)));
    let wi = h * (2.0 * dot(wo, h)) - wo;
    if (wi.z <= 0.0) {
        return vec4<f32>(0.0);
    }
    let a2 = a * a;
    let lo = wi.z * sqrt(a2 + (1.0 - a2) * wo.z * wo.z);
    let li = wo.z * sqrt(a2 + (1.0 - a2) * wi.z * wi.z);
    let g2 = 2.0 * wo.z * wi.z / (lo + li);
    let g1 = 2.0 * wo.z / (wo.z + sqrt(a2 + (1.0 - a2) * wo.z * wo.z));
    let m = pow(1.0 - clamp(dot(wi, h), 0.0, 1.0), 5.0);
    *weight = (b.specular_f0 + (vec3<f32>(1.0) - b.specular_f0) * m) * (g2 / g1);
    return vec4<f32>(wi, 1.0);
}

// probegi_core::sampling::sample_cosine_hemisphere: cosine-weighted around +z.
fn sample_cosine_hemisphere(u: vec2<f32>) -> vec3<f32> {
    let r = sqrt(u.x);
    let phi = 2.0 * SCENE_PI * u.y;
    return vec3<f32>(r * cos(phi), r * sin(phi), sqrt(max(1.0 - u.x, 0.0)));
}

fn frame_to_world(f: Frame, v: vec3<f32>) -> vec3<f32> {
    return f.t * v.x + f.b * v.y + f.n * v.z;
}

// An orthonormal frame around unit n (Duff et al. 2017).
struct Frame {
    t: vec3<f32>,
    b: vec3<f32>,
    n: vec3<f32>,
};

fn frame_from_normal(n: vec3<f32>) -> Frame {
    let s = select(-1.0, 1.0, n.z >= 0.0);
    let a = -1.0 / (s + n.z);
    let b = n.x * n.y * a;
    return Frame(vec3<f32>(1.0 + s * n.x * n.x * a, s * b, -s * n.x), vec3<f32>(b, s + n.y * n.y * a, -n.y), n);
}

fn frame_to_local(f: Frame, v: vec3<f32>) -> vec3<f32> {
    return vec3<f32>(dot(v, f.t), dot(v, f.b), dot(v, f.n));
}

// A PCG hash stream (Jarzynski & Olano 2020), one per ray.
fn rng_hash(v: u32) -> u32 {
    let state = v * 747796405u + 2891336453u;
    let word = ((state >> ((state >> 28u) + 4u)) ^ state) * 277803737u;
    return (word >> 22u) ^ word;
}

fn rng_next(state: ptr<function, u32>) -> f32 {
    *state = rng_hash(*state);
    return f32(*state >> 8u) * (1.0 / 16777216.0);
}

// probegi_cpu::light_sampling::punctual_incident → (wi, distance), irradiance in `e`.
fn scene_punctual(k: u32, point: vec3<f32>, e: ptr<function, vec3<f32>>) -> vec4<f32> {
    let base = 2u + k * 4u;
    let h = scene_lights[base];
    let power = scene_lights[base + 3u].xyz;
    let kind = bitcast<u32>(h.x);
    if (kind == 2u) {
        *e = power;
        return vec4<f32>(-normalize(scene_lights[base + 2u].xyz), SCENE_F32_MAX);
    }
    let to = scene_lights[base + 1u].xyz - point;
    let d2 = dot(to, to);
    if (d2 <= 0.0) {
        *e = vec3<f32>(0.0);
        return vec4<f32>(0.0);
    }
    let d = sqrt(d2);
    let wi = to / d;
    var window = 1.0;
    if (h.y > 0.0) {
        let q = d / h.y;
        let c = clamp(1.0 - q * q * q * q, 0.0, 1.0);
        window = c * c;
    }
    var irr = power * window / d2;
    if (kind == 1u) {
        let cos_angle = dot(normalize(scene_lights[base + 2u].xyz), -wi);
        let cos_outer = cos(h.w);
        let scale = 1.0 / max(cos(h.z) - cos_outer, 1e-3);
        let t = clamp(cos_angle * scale - cos_outer * scale, 0.0, 1.0);
        irr *= t * t;
    }
    *e = irr;
    return vec4<f32>(wi, d);
}

// A surface point's shading frame, the direction to the viewer in it (lifted
// off the horizon) and its BSDF: what every light sample at the point reads.
struct SceneShading {
    fr: Frame,
    wo: vec3<f32>,
    bsdf: Bsdf,
};

fn scene_shading(sp: SurfacePoint, to_viewer: vec3<f32>) -> SceneShading {
    let fr = frame_from_normal(scene_facing_normal(sp));
    var wo = frame_to_local(fr, to_viewer);
    wo.z = max(wo.z, 1e-4);
    return SceneShading(fr, normalize(wo), scene_bsdf(sp));
}

// Direct light reflected toward `to_viewer` (DirectLighting::reflected with the sky
// left out): punctual lights exactly, `area_samples` stratified NEE samples of the
// emitters (full BSDF, or the diffuse lobe alone when `specular_area` is false
// because the caller gathers emitters' highlights with reflected rays), every
// sample with a shadow ray through `bvh.wgsl`. No emission.
fn scene_direct(sp: SurfacePoint, to_viewer: vec3<f32>, area_samples: u32, specular_area: bool,
                rng: ptr<function, u32>) -> vec3<f32> {
    let s = scene_shading(sp, to_viewer);
    return scene_direct_punctual(sp, s) + scene_direct_area_in(sp, s, area_samples, specular_area, rng);
}

// scene_direct's emitters alone (a caller that lights the punctual lights itself:
// shadow_lighting.wgsl under a shadowing field).
fn scene_direct_area(sp: SurfacePoint, to_viewer: vec3<f32>, area_samples: u32, specular_area: bool,
                     rng: ptr<function, u32>) -> vec3<f32> {
    return scene_direct_area_in(sp, scene_shading(sp, to_viewer), area_samples, specular_area, rng);
}

fn scene_direct_area_in(sp: SurfacePoint, s: SceneShading, area_samples: u32, specular_area: bool,
                        rng: ptr<function, u32>) -> vec3<f32> {
    let header = scene_lights[0];
    let punctual = bitcast<u32>(header.x);
    let emitters = bitcast<u32>(header.y);
    var l = vec3<f32>(0.0);
    if (emitters > 0u && area_samples > 0u) {
        let k = u32(ceil(sqrt(f32(area_samples))));
        let n = k * k;
        let first = 2u + punctual * 4u;
        var sum = vec3<f32>(0.0);
        for (var i = 0u; i < n; i++) {
            let u = vec2<f32>((f32(i % k) + rng_next(rng)) / f32(k), (f32(i / k) + rng_next(rng)) / f32(k));
            let u_select = rng_next(rng);
            var c = vec3<f32>(0.0);
            if (scene_emitter_sample(sp, s.fr, s.wo, s.bsdf, specular_area, u, u_select, first, emitters, &c)) {
                sum += c;
            }
        }
        l += sum / f32(n);
    }
    return l;
}

// A punctual light's visibility from `sp` by one shadow ray toward `inc`
// (scene_punctual's direction and distance): 1 or 0.
fn scene_punctual_shadow_ray(sp: SurfacePoint, inc: vec4<f32>) -> f32 {
    var t_max = SCENE_F32_MAX;
    if (inc.w < SCENE_F32_MAX) {
        t_max = inc.w * (1.0 - 1e-4);
    }
    let shadow = bvh_trace(bvh_make_ray(scene_spawn_origin(sp, inc.xyz), inc.xyz, 0.0, t_max), true);
    return select(0.0, 1.0, shadow.leaf == BVH_NO_HIT);
}

// scene_direct's punctual lights (punctual_direct), each with a shadow ray.
fn scene_direct_punctual(sp: SurfacePoint, s: SceneShading) -> vec3<f32> {
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
        if (scene_punctual_shadow_ray(sp, inc) > 0.0) {
            l += bsdf_eval(s.bsdf, s.wo, frame_to_local(s.fr, inc.xyz)) * e * cos;
        }
    }
    return l;
}

// One of scene_direct's area-light samples (AreaLights::sample with `u` on the
// triangle, `u_select` choosing the emitter among the `emitters` from light
// vec4 `first`): false when it adds nothing, else its estimate in `out`.
fn scene_emitter_sample(sp: SurfacePoint, fr: Frame, wo: vec3<f32>, bsdf: Bsdf, specular_area: bool, u: vec2<f32>,
                        u_select: f32, first: u32, emitters: u32, out: ptr<function, vec3<f32>>) -> bool {
    // Distribution1d::sample_discrete: the first CDF entry above u.
    var lo = 0u;
    var hi = emitters;
    while (lo < hi) {
        let mid = (lo + hi) / 2u;
        if (scene_lights[first + mid].y <= u_select) { lo = mid + 1u; } else { hi = mid; }
    }
    let em = scene_lights[first + min(lo, emitters - 1u)];
    let tri = bitcast<u32>(em.x) * SCENE_TRIANGLE_VEC4S;
    let su = sqrt(u.x);
    let b0 = 1.0 - su;
    let b1 = u.y * su;
    let b = vec3<f32>(b0, b1, 1.0 - b0 - b1);
    let p0 = scene_triangles[tri].xyz;
    let p1 = scene_triangles[tri + 1u].xyz;
    let p2 = scene_triangles[tri + 2u].xyz;
    let point = p0 * b.x + p1 * b.y + p2 * b.z;
    let to = point - sp.position;
    let dist2 = dot(to, to);
    if (dist2 <= 0.0) {
        return false;
    }
    let wi = to / sqrt(dist2);
    let nl = scene_normalize_or_zero(cross(p1 - p0, p2 - p0));
    let cos_light = -dot(wi, nl);
    if (cos_light <= 0.0) {
        return false;
    }
    // Mesh::attributes_at
    let uv01 = scene_triangles[tri + 6u];
    let uv2 = scene_triangles[tri + 7u];
    let set1 = scene_triangles[tri + 11u];
    let uv = uv01.xy * b.x + uv01.zw * b.y + uv2.xy * b.z;
    let uv1 = uv2.zw * b.x + set1.xy * b.y + set1.zw * b.z;
    let radiance = scene_emission(bitcast<u32>(scene_triangles[tri].w), uv, uv1);
    let pdf = em.z * dist2 / cos_light;
    let cos = scene_lambert_cos(sp, wi);
    if (cos <= 0.0 || all(radiance == vec3<f32>(0.0)) || pdf <= 0.0) {
        return false;
    }
    // probegi_cpu::shading::shadow_ray_to
    let origin = scene_spawn_origin(sp, point - sp.position);
    let to_point = point - origin;
    let d = length(to_point);
    let shadow = bvh_trace(bvh_make_ray(origin, to_point / d, 0.0, d * (1.0 - 1e-4)), true);
    if (shadow.leaf == BVH_NO_HIT) {
        let wl = frame_to_local(fr, wi);
        var f = bsdf_diffuse_albedo(bsdf) / SCENE_PI;
        if (specular_area) {
            f = bsdf_eval(bsdf, wo, wl);
        } else if (wl.z <= 0.0) {
            f = vec3<f32>(0.0);
        }
        *out = f * radiance * (cos / pdf);
        return true;
    }
    return false;
}

// probegi_scene::Scene::sky_toward: the radiance seen looking along unit `dir`
// from inside the scene: the sky map's (probegi_scene::environment_map: Mitsuba's
// envmap convention, bilinear between texel centres, wrapping in u, clamped in v)
// or the constant sky's.
fn scene_sky(dir: vec3<f32>) -> vec3<f32> {
    let header = scene_lights[0];
    let sky = scene_lights[1];
    let first = bitcast<u32>(header.z);
    if (first == SCENE_NONE) {
        return sky.xyz;
    }
    let w = bitcast<u32>(header.w);
    let h = w / 2u;
    // SkyMap::to_map, then environment_map::direction_to_uv.
    let l = vec3<f32>(sky.z * dir.x + sky.y * dir.z, dir.y, -sky.y * dir.x + sky.z * dir.z);
    var u = atan2(l.x, -l.z) / SCENE_TAU;
    if (u < 0.0) {
        u += 1.0;
    }
    let v = acos(clamp(l.y, -1.0, 1.0)) / SCENE_PI;
    // EnvironmentMap::lookup_uv
    let x = u * f32(w) - 0.5;
    let y = v * f32(h) - 0.5;
    let x0 = floor(x);
    let y0 = floor(y);
    let fx = x - x0;
    let fy = y - y0;
    let i0 = u32((i32(x0) % i32(w) + i32(w)) % i32(w));
    let i1 = (i0 + 1u) % w;
    let j0 = u32(clamp(i32(y0), 0, i32(h) - 1));
    let j1 = u32(clamp(i32(y0) + 1, 0, i32(h) - 1));
    let top = scene_sky_texel(first, w, i0, j0) * (1.0 - fx) + scene_sky_texel(first, w, i1, j0) * fx;
    let bottom = scene_sky_texel(first, w, i0, j1) * (1.0 - fx) + scene_sky_texel(first, w, i1, j1) * fx;
    return (top * (1.0 - fy) + bottom * fy) * sky.x;
}

fn scene_sky_texel(first: u32, w: u32, i: u32, j: u32) -> vec3<f32> {
    let k = first + 3u * (j * w + i);
    return vec3<f32>(bitcast<f32>(scene_textures[k]), bitcast<f32>(scene_textures[k + 1u]),
                     bitcast<f32>(scene_textures[k + 2u]));
}

fn scene_sky_cdf(k: u32) -> f32 {
    return bitcast<f32>(scene_textures[k]);
}

// environment_map::pick: the interval of the running sum at `base` (n + 1
// entries from 0) that holds x, never one of zero weight; (index, where in it).
fn scene_sky_pick(base: u32, n: u32, x: f32) -> vec2<f32> {
    // The last k in [0, n) with cdf[k] <= x.
    var lo = 0u;
    var hi = n;
    while (hi - lo > 1u) {
        let mid = (lo + hi) / 2u;
        if (scene_sky_cdf(base + mid) <= x) { lo = mid; } else { hi = mid; }
    }
    // Interval k holds x unless x reached the total (u rounded to 1): then the
    // last interval of non-zero weight.
    var k = lo;
    while (k > 0u && scene_sky_cdf(base + k + 1u) <= scene_sky_cdf(base + k)) {
        k -= 1u;
    }
    let c0 = scene_sky_cdf(base + k);
    let width = scene_sky_cdf(base + k + 1u) - c0;
    return vec2<f32>(f32(k), clamp((x - c0) / max(width, 1e-30), 0.0, 1.0 - 1e-7));
}

// probegi_scene::environment_map::SkyMap::sample: a world direction drawn from
// the sky map's density (xyz) and its density per steradian (w; 0: none).
fn scene_sky_sample(u: vec2<f32>) -> vec4<f32> {
    let header = scene_lights[0];
    let sky = scene_lights[1];
    let first = bitcast<u32>(header.z);
    if (first == SCENE_NONE || !(sky.x > 0.0)) {
        return vec4<f32>(0.0);
    }
    let w = bitcast<u32>(header.w);
    let h = w / 2u;
    let marginal = first + 3u * w * h;
    let total = scene_sky_cdf(marginal + h);
    if (!(total > 0.0)) {
        return vec4<f32>(0.0);
    }
    let row_pick = scene_sky_pick(marginal, h, u.y * total);
    let j = u32(row_pick.x);
    let row = marginal + h + 1u + j * (w + 1u);
    let col_pick = scene_sky_pick(row, w, u.x * scene_sky_cdf(row + w));
    let i = u32(col_pick.x);
    let uv = vec2<f32>((f32(i) + col_pick.y) / f32(w), (f32(j) + row_pick.y) / f32(h));
    let pdf_uv = (scene_sky_cdf(row + i + 1u) - scene_sky_cdf(row + i)) / total * f32(w * h);
    let sin_theta = sin(uv.y * SCENE_PI);
    if (!(sin_theta > 0.0) || !(pdf_uv > 0.0)) {
        return vec4<f32>(0.0);
    }
    // environment_map::uv_to_direction, then SkyMap::to_world (sky.y, sky.z:
    // the sine and cosine of minus the rotation).
    let phi = uv.x * SCENE_TAU;
    let l = vec3<f32>(sin_theta * sin(phi), cos(uv.y * SCENE_PI), -sin_theta * cos(phi));
    let wi = vec3<f32>(sky.z * l.x - sky.y * l.z, l.y, sky.y * l.x + sky.z * l.z);
    return vec4<f32>(wi, pdf_uv / (2.0 * SCENE_PI * SCENE_PI * sin_theta));
}

// probegi_cpu::direct::DirectLighting::sky_map_direct: the sky map's light
// reflected by the diffuse lobe, `samples` draws of its density (stratified,
// rounded up to a square), each with a shadow ray; 0 without a map (before
// any material lookup).
fn scene_sky_direct(sp: SurfacePoint, samples: u32, rng: ptr<function, u32>) -> vec3<f32> {
    if (bitcast<u32>(scene_lights[0].z) == SCENE_NONE || samples == 0u) {
        return vec3<f32>(0.0);
    }
    let fr = frame_from_normal(scene_facing_normal(sp));
    let f_diffuse = bsdf_diffuse_albedo(scene_bsdf(sp)) / SCENE_PI;
    let k = u32(ceil(sqrt(f32(samples))));
    let n = k * k;
    var sum = vec3<f32>(0.0);
    for (var i = 0u; i < n; i++) {
        let u = vec2<f32>((f32(i % k) + rng_next(rng)) / f32(k), (f32(i / k) + rng_next(rng)) / f32(k));
        let d = scene_sky_sample(u);
        if (!(d.w > 0.0)) {
            continue;
        }
        let wi = d.xyz;
        let cos = scene_lambert_cos(sp, wi);
        if (cos <= 0.0) {
            continue;
        }
        let shadow = bvh_trace(bvh_make_ray(scene_spawn_origin(sp, wi), wi, 0.0, SCENE_F32_MAX), true);
        if (shadow.leaf != BVH_NO_HIT) {
            continue;
        }
        if (frame_to_local(fr, wi).z <= 0.0) {
            continue;
        }
        sum += f_diffuse * scene_sky(wi) * (cos / d.w);
    }
    return sum / f32(n);
}

// probegi_scene::Scene::sky_on_probe_miss: the constant sky, nothing under a
// map (whose light reaches surfaces by scene_sky_direct).
fn scene_sky_on_probe_miss(dir: vec3<f32>) -> vec3<f32> {
    if (bitcast<u32>(scene_lights[0].z) != SCENE_NONE) {
        return vec3<f32>(0.0);
    }
    return scene_lights[1].xyz;
}
