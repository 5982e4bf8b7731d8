// Ray generation (probegi_cpu::probe_ray_gen::probe_ray_directions; seed 003
// §4.2 eq. 4.1–4.3, seed 004 §2.3): ray i of probe p starts at the probe and runs
// along spherical Fibonacci direction i of n (probegi_core::fibonacci::
// spherical_fibonacci), rotated by the frame's random rotation (a unit
// quaternion the CPU draws from (seed, frame), as it does for its own rays).
// frac(i/Φ) is computed in 0.32 fixed point (2654435769 = 2³²/Φ), exact where
// the CPU uses f64. Must match `probegi_wgpu::probe_ray_gen::RayGenParams`
// (#[repr(C)], 32 bytes) and the trace pass's `GpuRay`.

struct RayGenParams {
    rotation: vec4<f32>,  // quaternion (x, y, z, w)
    rays_per_probe: u32,
    probe_count: u32,
    groups_x: u32,
    first_ray: u32,       // where these probes' rays start in the batch
};

struct GenRay {
    origin: vec3<f32>,
    t_min: f32,
    dir: vec3<f32>,
    t_max: f32,
};

@group(0) @binding(0) var<uniform> ray_gen: RayGenParams;
// Per probe: origin xyz (m), w = max ray distance (m).
@group(0) @binding(1) var<storage, read> ray_gen_probes: array<vec4<f32>>;
@group(0) @binding(2) var<storage, read_write> ray_gen_rays: array<GenRay>;

const RAY_GEN_TWO_PI: f32 = 6.28318530717959;

// probegi_core::fibonacci::spherical_fibonacci
fn spherical_fibonacci(i: u32, n: u32) -> vec3<f32> {
    let frac = f32(i * 2654435769u) * (1.0 / 4294967296.0);
    let phi = RAY_GEN_TWO_PI * frac;
    let z = 1.0 - (2.0 * f32(i) + 1.0) / f32(n);
    let r = sqrt(max(1.0 - z * z, 0.0));
    return vec3<f32>(cos(phi) * r, sin(phi) * r, z);
}

// glam's Quat * Vec3.
fn quat_rotate(q: vec4<f32>, v: vec3<f32>) -> vec3<f32> {
    let t = 2.0 * cross(q.xyz, v);
    return v + q.w * t + cross(q.xyz, t);
}

@compute @workgroup_size(64)
fn generate_probe_rays(@builtin(workgroup_id) wid: vec3<u32>, @builtin(local_invocation_index) lid: u32) {
    let k = (wid.y * ray_gen.groups_x + wid.x) * 64u + lid;
    let n = ray_gen.rays_per_probe;
    if (k >= n * ray_gen.probe_count) {
        return;
    }
    let probe = ray_gen_probes[k / n];
    let dir = normalize(quat_rotate(ray_gen.rotation, spherical_fibonacci(k % n, n)));
    ray_gen_rays[ray_gen.first_ray + k] = GenRay(probe.xyz, 0.0, dir, probe.w);
}
