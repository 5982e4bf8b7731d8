// The camera frame after the camera pass, on the device (probegi_wgpu::device_frame;
// the CPU's reference is probegi_cpu::frame_loop::accumulation and frame_loop's
// statistics). Three entry points, one compute pass each, recorded after
// `shade_camera` into the frame's one submission:
//   frame_resolve  Accumulation::add_frame: this frame's surface point per pixel
//                  (frame_points), then the history kept (still camera), cleared
//                  (changed scene) or reprojected (moved camera: history_at with
//                  Catmull-Rom or bilinear taps over the same surface, TapSum::history,
//                  the cap and clamp_to_neighbourhood), then the frame added;
//   frame_compose  Accumulation::pixels / means: direct + albedo × irradiance/π,
//                  tone-mapped (probegi_core::color::tonemap_rgb8) into RGBA8,
//                  and per-workgroup sums of the image and of its field term,
//                  and counts of surfaces, unlit surfaces and non-finite pixels;
//   frame_stats    the workgroups' sums reduced to the frame's means.
// The history holds running means (not sums, as the CPU's f64 does: a mean in f32
// keeps its precision however many frames it has seen), four texels a pixel:
//   4p: direct mean, w = frames in it;  4p + 1: albedo mean, w = the normal's oct.x;
//   4p + 2: irradiance/π at the last diffuse sample, w = oct.y;
//   4p + 3: the surface point at the pixel's centre ray, w = 1 (0: the sky).
// Must match `probegi_wgpu::device_frame::FrameParams` (#[repr(C)], 176 bytes) and
// `FrameStatsBlock` (48 bytes).

struct FrameCamera {
    origin: vec4<f32>,   // xyz; w = tan(fov_y / 2)
    forward: vec4<f32>,  // xyz; w = aspect
    right: vec4<f32>,    // xyz; w = width (pixels)
    up: vec4<f32>,       // xyz; w = height (pixels)
};

struct FrameParams {
    now_cam: FrameCamera,   // this frame's camera
    last_cam: FrameCamera,  // the last frame's (mode 2)
    info: vec4<u32>,     // mode (0 accumulate, 1 restart, 2 reproject, 3 no history: a new size), history frames − 1,
                         // layer for RGBA8 (0 full, 1 direct, 2 indirect), workgroups of frame_compose
    clip: vec4<f32>,     // x: temporal_clip_sigma
    pitch: vec4<u32>,    // x: frame_rgba8's row pitch, pixels (rows of 256-byte multiples)
};

struct FrameStats {
    mean: vec4<f32>,
    indirect_mean: vec4<f32>,
    surfaces: atomic<u32>,
    unlit: atomic<u32>,
    nonfinite: atomic<u32>,
    pad: u32,
};

@group(0) @binding(0) var<uniform> frame: FrameParams;
@group(0) @binding(1) var<storage, read> camera_direct: array<vec4<f32>>;
@group(0) @binding(2) var<storage, read> camera_irradiance: array<vec4<f32>>;
@group(0) @binding(3) var<storage, read> history_prev: array<vec4<f32>>;
@group(0) @binding(4) var<storage, read_write> history_next: array<vec4<f32>>;
@group(0) @binding(5) var<storage, read_write> frame_partials: array<vec4<f32>>;
@group(0) @binding(6) var<storage, read_write> frame_stats_out: FrameStats;
@group(0) @binding(7) var<storage, read_write> frame_rgba8: array<u32>;

const FRAME_F32_MAX: f32 = 3.40282347e38;
// accumulation::MIN_TAP_WEIGHT
const FRAME_MIN_TAP_WEIGHT: f32 = 1e-4;
// accumulation::SAME_SURFACE_PLANE_DEPTH_FRACTION
const FRAME_SAME_SURFACE_PLANE_DEPTH_FRACTION: f32 = 0.05;

fn frame_finite3(v: vec3<f32>) -> bool {
    return all(abs(v) <= vec3<f32>(FRAME_F32_MAX));
}

// CameraRays::ray_dir_world
fn frame_ray_dir(c: FrameCamera, x: f32, y: f32) -> vec3<f32> {
    let ndc_x = 2.0 * x / c.right.w - 1.0;
    let ndc_y = 1.0 - 2.0 * y / c.up.w;
    return normalize(c.forward.xyz + c.right.xyz * (ndc_x * c.origin.w * c.forward.w) + c.up.xyz * (ndc_y * c.origin.w));
}

// CameraRays::project_world: the continuous pixel position; z = 1 where the point is in front.
fn frame_project(c: FrameCamera, point: vec3<f32>) -> vec3<f32> {
    let d = point - c.origin.xyz;
    let z = dot(d, c.forward.xyz);
    if (!(z > 0.0)) {
        return vec3<f32>(0.0);
    }
    let ndc_x = dot(d, c.right.xyz) / (z * c.origin.w * c.forward.w);
    let ndc_y = dot(d, c.up.xyz) / (z * c.origin.w);
    return vec3<f32>((ndc_x + 1.0) * 0.5 * c.right.w, (1.0 - ndc_y) * 0.5 * c.up.w, 1.0);
}

fn frame_sign_not_zero(v: vec2<f32>) -> vec2<f32> {
    return select(vec2<f32>(-1.0), vec2<f32>(1.0), v >= vec2<f32>(0.0));
}

// probegi_core::octahedral::oct_decode
fn frame_oct_decode(uv: vec2<f32>) -> vec3<f32> {
    var d = vec3<f32>(uv.x, uv.y, 1.0 - abs(uv.x) - abs(uv.y));
    if (d.z < 0.0) {
        let xy = (vec2<f32>(1.0) - abs(d.yx)) * frame_sign_not_zero(d.xy);
        d = vec3<f32>(xy, d.z);
    }
    return normalize(d);
}

// accumulation::Surface: what a pixel saw (has = 0: the sky).
struct FrameSurface {
    point: vec3<f32>,
    normal: vec3<f32>,
    has: bool,
};

// Accumulation::frame_points for pixel (x, y): where its centre ray meets the
// tangent plane of its sample's surface.
fn frame_point_now(x: u32, y: u32, p: u32) -> FrameSurface {
    let c2 = camera_direct[3u * p + 2u];
    var s = FrameSurface(vec3<f32>(0.0), vec3<f32>(0.0), false);
    if (!(c2.w > 0.5) || !frame_finite3(c2.xyz)) {
        return s;
    }
    let normal = frame_oct_decode(vec2<f32>(camera_direct[3u * p].w, camera_direct[3u * p + 1u].w));
    let o = frame.now_cam.origin.xyz;
    let dir = frame_ray_dir(frame.now_cam, f32(x) + 0.5, f32(y) + 0.5);
    let along = dot(c2.xyz - o, normal);
    let facing = dot(dir, normal);
    let t = along / facing;
    let sample_t = distance(c2.xyz, o);
    var point = c2.xyz;
    if (abs(facing) > 1e-3 && t > 0.5 * sample_t && t < 2.0 * sample_t) {
        point = o + dir * t;
    }
    s.point = point;
    s.normal = normal;
    s.has = true;
    return s;
}

// The surface pixel q saw in the last frame (history_prev).
fn frame_point_then(q: u32) -> FrameSurface {
    let h3 = history_prev[4u * q + 3u];
    let oct = vec2<f32>(history_prev[4u * q + 1u].w, history_prev[4u * q + 2u].w);
    return FrameSurface(h3.xyz, frame_oct_decode(oct), h3.w > 0.5);
}

// Surface::continues: `then` lies within 5 % of its depth in `from` of `now`'s
// tangent plane, on the same side.
fn frame_continues(now: FrameSurface, then: FrameSurface) -> bool {
    let depth_m = dot(now.point - frame.last_cam.origin.xyz, frame.last_cam.forward.xyz);
    let off_plane_m = abs(dot(then.point - now.point, now.normal));
    return off_plane_m <= FRAME_SAME_SURFACE_PLANE_DEPTH_FRACTION * depth_m && dot(then.normal, now.normal) >= 0.0;
}

// history_at's `passing`: tap (qx, qy) lies in the image, has a history and saw
// the same surface (or the sky, for a sky pixel).
fn frame_tap_passes(qx: i32, qy: i32, now: FrameSurface) -> bool {
    let w = i32(frame.now_cam.right.w);
    let h = i32(frame.now_cam.up.w);
    if (qx < 0 || qy < 0 || qx >= w || qy >= h) {
        return false;
    }
    let q = u32(qy * w + qx);
    if (!(history_prev[4u * q].w > 0.0)) {
        return false;
    }
    let then = frame_point_then(q);
    if (now.has && then.has) {
        return frame_continues(now, then);
    }
    return !now.has && !then.has;
}

// A pixel's means (LastMeans / PixelHistory in mean form).
struct FrameMeans {
    direct: vec3<f32>,
    albedo: vec3<f32>,
    irradiance: vec3<f32>,
    count: f32,
};

// TapSum
struct FrameTaps {
    sum: FrameMeans,
    lo: FrameMeans,
    hi: FrameMeans,
    weight: f32,
};

fn frame_means_of(q: u32) -> FrameMeans {
    let h0 = history_prev[4u * q];
    return FrameMeans(h0.xyz, history_prev[4u * q + 1u].xyz, history_prev[4u * q + 2u].xyz, h0.w);
}

fn frame_taps_add(t: ptr<function, FrameTaps>, qx: i32, qy: i32, k: f32) {
    let m = frame_means_of(u32(qy * i32(frame.now_cam.right.w) + qx));
    (*t).sum.direct += m.direct * k;
    (*t).sum.albedo += m.albedo * k;
    (*t).sum.irradiance += m.irradiance * k;
    (*t).sum.count += m.count * k;
    (*t).lo.direct = min((*t).lo.direct, m.direct);
    (*t).hi.direct = max((*t).hi.direct, m.direct);
    (*t).lo.albedo = min((*t).lo.albedo, m.albedo);
    (*t).hi.albedo = max((*t).hi.albedo, m.albedo);
    (*t).lo.irradiance = min((*t).lo.irradiance, m.irradiance);
    (*t).hi.irradiance = max((*t).hi.irradiance, m.irradiance);
    (*t).lo.count = min((*t).lo.count, m.count);
    (*t).hi.count = max((*t).hi.count, m.count);
    (*t).weight += k;
}

// TapSum::history: the taps' means over their weight, held inside their range;
// a history whose taps carry less than the whole weight counts that much less.
fn frame_taps_history(t: FrameTaps) -> FrameMeans {
    var m = FrameMeans(vec3<f32>(0.0), vec3<f32>(0.0), vec3<f32>(0.0), 0.0);
    if (t.weight < FRAME_MIN_TAP_WEIGHT) {
        return m;
    }
    let w = t.weight;
    m.count = clamp(t.sum.count / w, t.lo.count, t.hi.count) * min(w, 1.0);
    m.direct = clamp(t.sum.direct / w, t.lo.direct, t.hi.direct);
    m.albedo = clamp(t.sum.albedo / w, t.lo.albedo, t.hi.albedo);
    m.irradiance = clamp(t.sum.irradiance / w, t.lo.irradiance, t.hi.irradiance);
    return m;
}

// accumulation::catmull_rom
fn frame_catmull_rom(t: f32) -> vec4<f32> {
    return vec4<f32>(
        t * (-0.5 + t * (1.0 - 0.5 * t)),
        1.0 + t * t * (-2.5 + 1.5 * t),
        t * (0.5 + t * (2.0 - 1.5 * t)),
        t * t * (-0.5 + 0.5 * t),
    );
}

// Accumulation::history_at: the last frame's means around where pixel (x, y)'s
// point (or, for the sky, its direction) projects in `from`.
fn frame_history_at(x: u32, y: u32, now: FrameSurface) -> FrameMeans {
    var seen = now.point;
    if (!now.has) {
        seen = frame.last_cam.origin.xyz + frame_ray_dir(frame.now_cam, f32(x) + 0.5, f32(y) + 0.5);
    }
    let at = frame_project(frame.last_cam, seen);
    let big = FRAME_F32_MAX;
    var taps = FrameTaps(
        FrameMeans(vec3<f32>(0.0), vec3<f32>(0.0), vec3<f32>(0.0), 0.0),
        FrameMeans(vec3<f32>(big), vec3<f32>(big), vec3<f32>(big), big),
        FrameMeans(vec3<f32>(-big), vec3<f32>(-big), vec3<f32>(-big), -big),
        0.0,
    );
    if (!(at.z > 0.5) || !frame_finite3(at)) {
        return frame_taps_history(taps);
    }
    let f = at.xy - vec2<f32>(0.5);
    let fl = floor(f);
    // Far outside the image no tap passes; the clamp keeps the conversion defined.
    let base = vec2<i32>(clamp(fl, vec2<f32>(-4.0), vec2<f32>(frame.now_cam.right.w + 4.0, frame.now_cam.up.w + 4.0)));
    let a = f - fl;
    let centre = frame_tap_passes(base.x, base.y, now) && frame_tap_passes(base.x + 1, base.y, now)
        && frame_tap_passes(base.x, base.y + 1, now) && frame_tap_passes(base.x + 1, base.y + 1, now);
    if (centre) {
        let cx = frame_catmull_rom(a.x);
        let cy = frame_catmull_rom(a.y);
        for (var k = 0; k < 16; k++) {
            let q = base + vec2<i32>(k % 4 - 1, k / 4 - 1);
            if (frame_tap_passes(q.x, q.y, now)) {
                frame_taps_add(&taps, q.x, q.y, cx[k % 4] * cy[k / 4]);
            }
        }
    } else {
        let bilinear = vec4<f32>((1.0 - a.x) * (1.0 - a.y), a.x * (1.0 - a.y), (1.0 - a.x) * a.y, a.x * a.y);
        for (var k = 0; k < 4; k++) {
            let q = base + vec2<i32>(k % 2, k / 2);
            if (frame_tap_passes(q.x, q.y, now)) {
                frame_taps_add(&taps, q.x, q.y, bilinear[k]);
            }
        }
    }
    return frame_taps_history(taps);
}

// accumulation::clamp_to_neighbourhood: `mean` clamped, per channel, to this
// frame's direct term around (x, y) (3 × 3): its mean ± sigma standard deviations.
fn frame_clamp_direct(x: u32, y: u32, mean: vec3<f32>, sigma: f32) -> vec3<f32> {
    let w = i32(frame.now_cam.right.w);
    let h = i32(frame.now_cam.up.w);
    var m1 = vec3<f32>(0.0);
    var m2 = vec3<f32>(0.0);
    var n = 0.0;
    for (var dy = -1; dy <= 1; dy++) {
        for (var dx = -1; dx <= 1; dx++) {
            let qx = i32(x) + dx;
            let qy = i32(y) + dy;
            if (qx >= 0 && qy >= 0 && qx < w && qy < h) {
                let v = camera_direct[3u * u32(qy * w + qx)].xyz;
                m1 += v;
                m2 += v * v;
                n += 1.0;
            }
        }
    }
    let mu = m1 / n;
    let spread = sqrt(max(m2 / n - mu * mu, vec3<f32>(0.0))) * sigma;
    return clamp(mean, mu - spread, mu + spread);
}

@compute @workgroup_size(8, 8)
fn frame_resolve(@builtin(global_invocation_id) gid: vec3<u32>) {
    let width = u32(frame.now_cam.right.w);
    let height = u32(frame.now_cam.up.w);
    if (gid.x >= width || gid.y >= height) {
        return;
    }
    let p = gid.y * width + gid.x;
    let now = frame_point_now(gid.x, gid.y, p);
    var hist = FrameMeans(vec3<f32>(0.0), vec3<f32>(0.0), vec3<f32>(0.0), 0.0);
    let mode = frame.info.x;
    if (mode == 0u) {
        hist = frame_means_of(p);
    } else if (mode == 1u) {
        // Accumulation::add_frame's restart clears the sums, not the last irradiance.
        hist.irradiance = history_prev[4u * p + 2u].xyz;
    } else if (mode == 2u) {
        hist = frame_history_at(gid.x, gid.y, now);
        let frames_max = f32(frame.info.y);
        hist.count = min(hist.count, frames_max);
        if (frame.clip.x > 0.0 && hist.count > 0.0) {
            hist.direct = frame_clamp_direct(gid.x, gid.y, hist.direct, frame.clip.x);
        }
    }
    let c0 = camera_direct[3u * p];
    let c1 = camera_direct[3u * p + 1u];
    let n1 = hist.count + 1.0;
    let direct = (hist.direct * hist.count + c0.xyz) / n1;
    let albedo = (hist.albedo * hist.count + c1.xyz) / n1;
    var irradiance = hist.irradiance;
    if (max(max(c1.x, c1.y), c1.z) > 0.0) {
        irradiance = camera_irradiance[p].xyz;
    }
    // The packed normal travels as the camera wrote it (zero for the sky).
    var oct = vec2<f32>(0.0);
    if (now.has) {
        oct = vec2<f32>(c0.w, c1.w);
    }
    history_next[4u * p] = vec4<f32>(direct, n1);
    history_next[4u * p + 1u] = vec4<f32>(albedo, oct.x);
    history_next[4u * p + 2u] = vec4<f32>(irradiance, oct.y);
    history_next[4u * p + 3u] = vec4<f32>(now.point, select(0.0, 1.0, now.has));
}

// probegi_core::color::tonemap's ACES fit and the sRGB OETF, then quantize.
fn frame_aces(x: f32) -> f32 {
    var v = 0.0;
    if (abs(x) <= FRAME_F32_MAX) {
        v = max(x, 0.0);
    }
    return clamp((v * (2.51 * v + 0.03)) / (v * (2.43 * v + 0.59) + 0.14), 0.0, 1.0);
}

fn frame_linear_to_srgb(l: f32) -> f32 {
    let c = clamp(l, 0.0, 1.0);
    if (c <= 0.0031308) {
        return c * 12.92;
    }
    return 1.055 * pow(c, 1.0 / 2.4) - 0.055;
}

fn frame_quantize(x: f32) -> u32 {
    return u32(clamp(x, 0.0, 1.0) * 255.0 + 0.5);
}

fn frame_rgba8_of(c: vec3<f32>) -> u32 {
    let r = frame_quantize(frame_linear_to_srgb(frame_aces(c.x)));
    let g = frame_quantize(frame_linear_to_srgb(frame_aces(c.y)));
    let b = frame_quantize(frame_linear_to_srgb(frame_aces(c.z)));
    return r | (g << 8u) | (b << 16u) | (255u << 24u);
}

var<workgroup> compose_image: array<vec3<f32>, 64>;
var<workgroup> compose_field: array<vec3<f32>, 64>;
var<workgroup> compose_counts: array<atomic<u32>, 3>;

@compute @workgroup_size(8, 8)
fn frame_compose(
    @builtin(global_invocation_id) gid: vec3<u32>,
    @builtin(local_invocation_index) lid: u32,
    @builtin(workgroup_id) wid: vec3<u32>,
    @builtin(num_workgroups) groups: vec3<u32>,
) {
    let width = u32(frame.now_cam.right.w);
    let height = u32(frame.now_cam.up.w);
    if (lid < 3u) {
        atomicStore(&compose_counts[lid], 0u);
    }
    workgroupBarrier();
    var image = vec3<f32>(0.0);
    var field = vec3<f32>(0.0);
    if (gid.x < width && gid.y < height) {
        let p = gid.y * width + gid.x;
        let direct = history_next[4u * p].xyz;
        field = history_next[4u * p + 1u].xyz * history_next[4u * p + 2u].xyz;
        image = direct + field;
        var shown = image;
        if (frame.info.z == 1u) {
            shown = direct;
        } else if (frame.info.z == 2u) {
            shown = field;
        }
        frame_rgba8[gid.y * frame.pitch.x + gid.x] = frame_rgba8_of(shown);
        // camera_frame.wgsl's flags: 1 a diffuse surface, 2 one the field left unlit, + 4 non-finite direct.
        let flags = u32(camera_irradiance[p].w + 0.5);
        if ((flags & 3u) != 0u) {
            atomicAdd(&compose_counts[0], 1u);
        }
        if ((flags & 3u) == 2u) {
            atomicAdd(&compose_counts[1], 1u);
        }
        if ((flags & 4u) != 0u) {
            atomicAdd(&compose_counts[2], 1u);
        }
    }
    compose_image[lid] = image;
    compose_field[lid] = field;
    workgroupBarrier();
    for (var s = 32u; s > 0u; s = s >> 1u) {
        if (lid < s) {
            compose_image[lid] += compose_image[lid + s];
            compose_field[lid] += compose_field[lid + s];
        }
        workgroupBarrier();
    }
    if (lid == 0u) {
        let g = wid.y * groups.x + wid.x;
        frame_partials[2u * g] = vec4<f32>(compose_image[0], 0.0);
        frame_partials[2u * g + 1u] = vec4<f32>(compose_field[0], 0.0);
        atomicAdd(&frame_stats_out.surfaces, atomicLoad(&compose_counts[0]));
        atomicAdd(&frame_stats_out.unlit, atomicLoad(&compose_counts[1]));
        atomicAdd(&frame_stats_out.nonfinite, atomicLoad(&compose_counts[2]));
    }
}

var<workgroup> stats_image: array<vec3<f32>, 256>;
var<workgroup> stats_field: array<vec3<f32>, 256>;

@compute @workgroup_size(256)
fn frame_stats(@builtin(local_invocation_index) lid: u32) {
    var image = vec3<f32>(0.0);
    var field = vec3<f32>(0.0);
    for (var g = lid; g < frame.info.w; g += 256u) {
        image += frame_partials[2u * g].xyz;
        field += frame_partials[2u * g + 1u].xyz;
    }
    stats_image[lid] = image;
    stats_field[lid] = field;
    workgroupBarrier();
    for (var s = 128u; s > 0u; s = s >> 1u) {
        if (lid < s) {
            stats_image[lid] += stats_image[lid + s];
            stats_field[lid] += stats_field[lid + s];
        }
        workgroupBarrier();
    }
    if (lid == 0u) {
        let pixels = max(frame.now_cam.right.w * frame.now_cam.up.w, 1.0);
        frame_stats_out.mean = vec4<f32>(stats_image[0] / pixels, 0.0);
        frame_stats_out.indirect_mean = vec4<f32>(stats_field[0] / pixels, 0.0);
    }
}
