//! Embedding probegi's DDGI in a wgpu engine. This program owns its device, its
//! triangles, its shading and its shader, and uses probegi for three things:
//! - the field set's seam (`probegi_field::ddgi_field_set`): probe placement,
//!   relocation, states, blending with hysteresis, border, classification;
//! - the GPU trace (`probegi_wgpu::bvh_trace`): the seam's probe rays, the
//!   shadow rays of its own shading and its camera's primary rays, through the
//!   WGSL CWBVH traversal over its own triangle soup;
//! - the WGSL query (`probegi_wgpu::ddgi_query::query_wgsl`), included in its own
//!   compute shader (`SHADE_WGSL` below), which lights every pixel with direct
//!   light + albedo/π × the field's irradiance, and reads the shadowing field's
//!   visibility of the light (`ddgi_shadow_visibility`, seed 003 ch. 5: the
//!   volume keeps one, fed by the shadow rays the seam puts in its batch).
//!
//! The world: a 4 × 3 × 4 m room with a red left wall, a green right wall, white
//! floor, ceiling and back wall, an open front, a white box, and a point light
//! under the ceiling. The program writes a PNG (tone-mapped) and checks what it
//! drew: every pixel's field term from the included WGSL query equals the CPU
//! query's at the same point within 1e-4 of the largest, and so does its light
//! visibility from the shadowing field (`DdgiFieldSet::shadow_visibility`); the
//! field reads the floor in the box's exact shadow as less visible than the lit
//! floor; no pixel is non-finite,
//! and the floor takes colour from the walls (redder near the red wall, greener
//! near the green one). It fails otherwise.
//!
//! Run: `cargo run -p probegi-wgpu --example wgpu_embed [out.png]` (needs a GPU
//! or Mesa's lavapipe). CI runs it as `probegi-wgpu/tests/it/wgpu_embed_example.rs`.

use glam::{UVec3, Vec3};
use probegi_core::ddgi_settings::{DdgiFieldSetSettings, DdgiVolumeSettings};
use probegi_field::ddgi_field_set::{DdgiFieldSet, ProbeRayHit, UpdateStep};
use probegi_wgpu::GpuContext;
use probegi_wgpu::bvh_trace::{GpuBvh, GpuRay, GpuRayHit, GpuRayTrace};
use probegi_wgpu::ddgi_query::{GpuDdgiField, query_wgsl};
use wgpu::util::DeviceExt;

type Error = Box<dyn std::error::Error>;

/// The application's triangles: corners (counter-clockwise seen from the front)
/// and diffuse albedo.
struct World {
    triangles: Vec<[Vec3; 3]>,
    albedo: Vec<Vec3>,
}

impl World {
    fn quad(&mut self, c: [Vec3; 4], albedo: Vec3) {
        self.triangles.push([c[0], c[1], c[2]]);
        self.triangles.push([c[0], c[2], c[3]]);
        self.albedo.extend([albedo, albedo]);
    }

    fn room() -> Self {
        let mut w = World { triangles: vec![], albedo: vec![] };
        let v = Vec3::new;
        let (white, red, green) = (Vec3::splat(0.75), v(0.75, 0.1, 0.1), v(0.1, 0.75, 0.1));
        // Inward-facing room, open toward +z.
        w.quad([v(0., 0., 0.), v(0., 0., 4.), v(4., 0., 4.), v(4., 0., 0.)], white); // floor
        w.quad([v(0., 3., 0.), v(4., 3., 0.), v(4., 3., 4.), v(0., 3., 4.)], white); // ceiling
        w.quad([v(0., 0., 0.), v(4., 0., 0.), v(4., 3., 0.), v(0., 3., 0.)], white); // back
        w.quad([v(0., 0., 0.), v(0., 3., 0.), v(0., 3., 4.), v(0., 0., 4.)], red); // left
        w.quad([v(4., 0., 0.), v(4., 0., 4.), v(4., 3., 4.), v(4., 3., 0.)], green); // right
        // An outward-facing box.
        let (lo, hi) = (v(1.5, 0.0, 1.2), v(2.5, 1.2, 2.2));
        let c = |x: usize, y: usize, z: usize| v([lo.x, hi.x][x], [lo.y, hi.y][y], [lo.z, hi.z][z]);
        for q in [
            [c(0, 1, 0), c(0, 1, 1), c(1, 1, 1), c(1, 1, 0)],
            [c(0, 0, 0), c(0, 0, 1), c(0, 1, 1), c(0, 1, 0)],
            [c(1, 0, 0), c(1, 1, 0), c(1, 1, 1), c(1, 0, 1)],
            [c(0, 0, 0), c(0, 1, 0), c(1, 1, 0), c(1, 0, 0)],
            [c(0, 0, 1), c(1, 0, 1), c(1, 1, 1), c(0, 1, 1)],
        ] {
            w.quad(q, white);
        }
        w
    }

    /// Unit counter-clockwise normal of triangle `t`.
    fn normal(&self, t: usize) -> Vec3 {
        let [a, b, c] = self.triangles[t];
        (b - a).cross(c - a).normalize()
    }
}

const LIGHT_POSITION: Vec3 = Vec3::new(2.0, 2.8, 2.0);
const LIGHT_INTENSITY: f32 = 12.0; // W/sr

/// A surface point the application shades.
struct Surface {
    position: Vec3,
    /// Facing the viewer.
    normal: Vec3,
    albedo: Vec3,
}

/// The application's direct light at surfaces (Lambertian, one point light),
/// with shadow rays through the library's any-hit trace.
fn direct_light(ctx: &GpuContext, trace: &GpuRayTrace, bvh: &GpuBvh, points: &[Surface]) -> Result<Vec<Vec3>, Error> {
    let rays: Vec<GpuRay> = points
        .iter()
        .map(|s| {
            let to = LIGHT_POSITION - s.position;
            GpuRay::new(s.position + s.normal * 1e-3, to.normalize(), 0.0, to.length() - 2e-3)
        })
        .collect();
    let blocked = trace.trace(ctx, bvh, &rays, true)?;
    Ok(points
        .iter()
        .zip(&blocked)
        .map(|(s, b)| {
            let to = LIGHT_POSITION - s.position;
            let cos = s.normal.dot(to.normalize());
            if b.is_hit() || cos <= 0.0 {
                Vec3::ZERO
            } else {
                s.albedo / std::f32::consts::PI * LIGHT_INTENSITY * cos / to.length_squared()
            }
        })
        .collect())
}

/// The surface a ray hit, with its normal turned toward the ray's origin.
fn surface(world: &World, ray: &GpuRay, hit: &GpuRayHit) -> Surface {
    let t = (hit.triangle & 0x7fff_ffff) as usize;
    let d = Vec3::from(ray.dir);
    let n = world.normal(t);
    Surface {
        position: Vec3::from(ray.origin) + d * hit.t,
        normal: if n.dot(d) > 0.0 { -n } else { n },
        albedo: world.albedo[t],
    }
}

/// One field update through the seam: the library traces, the application shades.
fn update_field(
    ctx: &GpuContext,
    trace: &GpuRayTrace,
    bvh: &GpuBvh,
    world: &World,
    set: &mut DdgiFieldSet,
    frame: u32,
) -> Result<(), Error> {
    // The shadowing field serves the application's light.
    set.set_shadow_lights(&[probegi_scene::PunctualLight::point(LIGHT_POSITION, Vec3::ONE, LIGHT_INTENSITY)]);
    let mut step = set.begin_update(7, frame);
    let mut rays: Vec<GpuRay> = vec![];
    let mut gpu_hits: Vec<GpuRayHit> = vec![];
    while step != UpdateStep::Done {
        let batch = set.ray_batch();
        step = match step {
            UpdateStep::TraceRays => {
                rays = (0..batch.len())
                    .map(|i| GpuRay::new(batch.origins_m[i], batch.directions[i], 0.0, batch.max_distances_m[i]))
                    .collect();
                gpu_hits = trace.trace(ctx, bvh, &rays, false)?;
                let hits: Vec<ProbeRayHit> = gpu_hits
                    .iter()
                    .map(|h| match h.ray_hit() {
                        None => ProbeRayHit::MISS,
                        Some(r) => {
                            let n = world.normal(r.triangle as usize);
                            if r.backface { ProbeRayHit::back(r.t, n) } else { ProbeRayHit::front(r.t, n) }
                        }
                    })
                    .collect();
                set.submit_hits(&hits)?
            }
            UpdateStep::ShadeRays => {
                // Front hits the set asks for: direct light + albedo/π × the field.
                let wanted: Vec<usize> = (0..batch.len())
                    .filter(|&i| {
                        batch.needs_radiance[i] && gpu_hits[i].is_hit() && gpu_hits[i].triangle & 0x8000_0000 == 0
                    })
                    .collect();
                let surfaces: Vec<Surface> = wanted.iter().map(|&i| surface(world, &rays[i], &gpu_hits[i])).collect();
                let direct = direct_light(ctx, trace, bvh, &surfaces)?;
                let mut radiance = vec![Vec3::ZERO; batch.len()]; // misses: a black sky
                for ((&i, s), l) in wanted.iter().zip(&surfaces).zip(direct) {
                    let e = set.irradiance(s.position, s.normal, -Vec3::from(rays[i].dir));
                    radiance[i] = l + s.albedo / std::f32::consts::PI * e;
                }
                set.submit_radiance(&radiance)?
            }
            UpdateStep::Done => UpdateStep::Done,
        };
    }
    Ok(())
}

/// The application's own shader: it includes probegi's WGSL query (group 1) and
/// lights each pixel with its direct light + albedo/π × `ddgi_irradiance`.
const SHADE_WGSL: &str = r#"
struct Pixel {
    position: vec4<f32>,  // w: 1 where the camera ray hit something
    normal: vec4<f32>,
    view_dir: vec4<f32>,
    albedo: vec4<f32>,
    direct: vec4<f32>,
};
@group(0) @binding(0) var<storage, read> pixels: array<Pixel>;
@group(0) @binding(1) var<storage, read_write> image: array<vec4<f32>>;

@compute @workgroup_size(64)
fn shade(@builtin(global_invocation_id) id: vec3<u32>) {
    let i = id.x;
    if (i >= arrayLength(&pixels)) {
        return;
    }
    let p = pixels[i];
    if (p.position.w == 0.0) {
        image[i] = vec4<f32>(0.0, 0.0, 0.0, 0.0);
        return;
    }
    let e = ddgi_irradiance(p.position.xyz, p.normal.xyz, p.view_dir.xyz);
    let indirect = p.albedo.xyz / 3.14159265 * e;
    // w: the light's visibility from the shadowing field (−1 where it has none).
    let to_light = normalize(vec3<f32>(2.0, 2.8, 2.0) - p.position.xyz);
    let v = ddgi_shadow_visibility(p.position.xyz, p.normal.xyz, p.view_dir.xyz, to_light);
    image[i] = vec4<f32>(p.direct.xyz + indirect, v);
}
"#;

#[repr(C)]
#[derive(Clone, Copy, bytemuck::Pod, bytemuck::Zeroable)]
struct Pixel {
    position: [f32; 4],
    normal: [f32; 4],
    view_dir: [f32; 4],
    albedo: [f32; 4],
    direct: [f32; 4],
}

pub fn main() -> Result<(), Error> {
    let out = std::env::args().nth(1).unwrap_or_else(|| "out/wgpu-embed.png".to_string());
    main_to(std::path::Path::new(&out))
}

pub fn main_to(out: &std::path::Path) -> Result<(), Error> {
    let ctx = application_device()?;
    println!("adapter: {}", ctx.adapter_name);
    // README: gpu-field begin
    // Its triangles, on the device as a CWBVH.
    let world = World::room();
    let bvh = GpuBvh::from_triangles(&ctx, &world.triangles)?;
    let trace = GpuRayTrace::new(&ctx);

    // A DDGI volume over the room, updated through the seam.
    let volume = DdgiVolumeSettings {
        probe_counts: UVec3::new(6, 5, 6),
        probe_rays_per_probe: 128,
        shadow_field: true,
        ..Default::default()
    };
    let bounds = (Vec3::ZERO, Vec3::new(4.0, 3.0, 4.0));
    let mut set = DdgiFieldSet::new(&DdgiFieldSetSettings::single(volume), bounds, None);
    for frame in 0..40 {
        update_field(&ctx, &trace, &bvh, &world, &mut set, frame)?;
    }

    // The camera: primary rays through the library's trace, direct light by the
    // application, the field term by its own shader with the included query.
    let (width, height) = (128u32, 96u32);
    let pixels = camera_pixels(&ctx, &trace, &bvh, &world, width, height)?;
    let field = GpuDdgiField::upload(&ctx, &set.view())?;
    let image = shade_on_gpu(&ctx, &field, &pixels)?;
    check_against_the_cpu(&set, &pixels, &image)?;
    // README: gpu-field end

    // Tone-map (exposure 1, Reinhard) and write.
    let mut img = probegi_core::image::Image::new(width, height);
    for (k, t) in image.iter().enumerate() {
        let c = Vec3::from_slice(&t[..3]);
        img.pixels[k] = c / (Vec3::ONE + c);
    }
    if let Some(dir) = out.parent() {
        std::fs::create_dir_all(dir)?;
    }
    probegi_image::write_image(out, &img)?;
    println!("wrote {}", out.display());
    Ok(())
}

/// The application's device (an engine's would already exist), wrapped for the library.
fn application_device() -> Result<GpuContext, Error> {
    let instance = wgpu::Instance::new(wgpu::InstanceDescriptor::new_without_display_handle_from_env());
    let adapter = pollster::block_on(instance.request_adapter(&wgpu::RequestAdapterOptions::default()))?;
    let (device, queue) = pollster::block_on(
        adapter.request_device(&wgpu::DeviceDescriptor { required_limits: adapter.limits(), ..Default::default() }),
    )?;
    Ok(GpuContext::from_device(device, queue, adapter.get_info().name))
}

/// The camera's `width × height` pixels: primary rays through the library's
/// trace, the surfaces they hit and the application's direct light there.
fn camera_pixels(
    ctx: &GpuContext,
    trace: &GpuRayTrace,
    bvh: &GpuBvh,
    world: &World,
    width: u32,
    height: u32,
) -> Result<Vec<Pixel>, Error> {
    let eye = Vec3::new(2.0, 1.6, 9.0);
    let forward = (Vec3::new(2.0, 1.2, 0.0) - eye).normalize();
    let right = forward.cross(Vec3::Y).normalize();
    let up = right.cross(forward);
    let tan = (25f32).to_radians().tan();
    let camera_rays: Vec<GpuRay> = (0..width * height)
        .map(|i| {
            let (x, y) = ((i % width) as f32 + 0.5, (i / width) as f32 + 0.5);
            let sx = (2.0 * x / width as f32 - 1.0) * tan * width as f32 / height as f32;
            let sy = (1.0 - 2.0 * y / height as f32) * tan;
            GpuRay::new(eye, (forward + right * sx + up * sy).normalize(), 0.0, f32::INFINITY)
        })
        .collect();
    let camera_hits = trace.trace(ctx, bvh, &camera_rays, false)?;
    let surfaces: Vec<Option<Surface>> =
        camera_rays.iter().zip(&camera_hits).map(|(r, h)| h.is_hit().then(|| surface(world, r, h))).collect();
    let lit: Vec<Surface> = surfaces
        .iter()
        .flatten()
        .map(|s| Surface { position: s.position, normal: s.normal, albedo: s.albedo })
        .collect();
    let mut direct = direct_light(ctx, trace, bvh, &lit)?.into_iter();
    Ok(surfaces
        .iter()
        .zip(&camera_rays)
        .map(|(s, r)| match s {
            None => bytemuck::Zeroable::zeroed(),
            Some(s) => {
                let v = -Vec3::from(r.dir);
                let d = direct.next().unwrap_or(Vec3::ZERO);
                Pixel {
                    position: s.position.extend(1.0).into(),
                    normal: s.normal.extend(0.0).into(),
                    view_dir: v.extend(0.0).into(),
                    albedo: s.albedo.extend(0.0).into(),
                    direct: d.extend(0.0).into(),
                }
            }
        })
        .collect())
}

/// What the application's shader drew, checked against the CPU query at the
/// same points, and the colour the walls bleed onto the floor.
fn check_against_the_cpu(set: &DdgiFieldSet, pixels: &[Pixel], image: &[[f32; 4]]) -> Result<(), Error> {
    let mut worst = 0f32;
    let mut worst_visibility = 0f32;
    // The field's visibility on floor points the exact shadow rays see lit and shadowed.
    let (mut lit_floor, mut shadowed_floor) = ((0f32, 0u32), (0f32, 0u32));
    let mut largest = 0f32;
    let (mut left, mut right_side) = (Vec3::ZERO, Vec3::ZERO);
    for (k, (p, texel)) in pixels.iter().zip(image).enumerate() {
        let c = &Vec3::from_slice(&texel[..3]);
        if !c.is_finite() {
            return Err(format!("pixel {k} is not finite: {c}").into());
        }
        if p.position[3] == 0.0 {
            continue;
        }
        let pos = Vec3::from_slice(&p.position[..3]);
        let n = Vec3::from_slice(&p.normal[..3]);
        let albedo = Vec3::from_slice(&p.albedo[..3]);
        let cpu = Vec3::from_slice(&p.direct[..3])
            + albedo / std::f32::consts::PI * set.irradiance(pos, n, Vec3::from_slice(&p.view_dir[..3]));
        worst = worst.max((cpu - *c).abs().max_element());
        largest = largest.max(cpu.max_element());
        let view = Vec3::from_slice(&p.view_dir[..3]);
        let v = set.shadow_visibility(pos, n, view, (LIGHT_POSITION - pos).normalize()).unwrap_or(-1.0);
        worst_visibility = worst_visibility.max((v - texel[3]).abs());
        if n.y > 0.9 && pos.y < 0.01 && v >= 0.0 {
            let exact_lit = Vec3::from_slice(&p.direct[..3]).max_element() > 0.0;
            let m = if exact_lit { &mut lit_floor } else { &mut shadowed_floor };
            *m = (m.0 + v, m.1 + 1);
        }
        // Floor points near each coloured wall: their indirect light.
        if n.y > 0.9 && pos.y < 0.01 && pos.z > 2.5 {
            let e = set.irradiance(pos, n, Vec3::Y);
            if pos.x < 0.8 {
                left += e;
            } else if pos.x > 3.2 {
                right_side += e;
            }
        }
    }
    let rel = worst / largest.max(1e-6);
    println!("GPU shader vs CPU query: worst {rel:.2e} of the largest pixel ({largest:.3})");
    println!("floor irradiance near the red wall {left}, near the green wall {right_side}");
    let (lit, shadowed) = (lit_floor.0 / lit_floor.1.max(1) as f32, shadowed_floor.0 / shadowed_floor.1.max(1) as f32);
    println!(
        "shadowing field: GPU vs CPU visibility worst {worst_visibility:.2e}; floor visibility where exact rays see \
         the light {lit:.3} ({} px), where they do not {shadowed:.3} ({} px)",
        lit_floor.1, shadowed_floor.1
    );
    if rel > 1e-4 {
        return Err(format!("the included WGSL query differs from the CPU's by {rel:e}").into());
    }
    if worst_visibility > 1e-4 {
        return Err(format!("the included shadow lookup differs from the CPU's by {worst_visibility:e}").into());
    }
    if shadowed_floor.1 == 0 || shadowed >= lit - 0.05 {
        return Err(format!("the shadowing field sees no shadow on the floor: {shadowed} against {lit}").into());
    }
    if !(left.x > 1.1 * left.y && right_side.y > 1.1 * right_side.x) {
        return Err(format!("no colour bleeding: {left} near red, {right_side} near green").into());
    }
    Ok(())
}

/// Runs `SHADE_WGSL` (with the included query at group 1) over `pixels`.
fn shade_on_gpu(ctx: &GpuContext, field: &GpuDdgiField, pixels: &[Pixel]) -> Result<Vec<[f32; 4]>, Error> {
    let device = &ctx.device;
    let (layout, pipeline) = shade_pipeline(device);
    let input = device.create_buffer_init(&wgpu::util::BufferInitDescriptor {
        label: Some("pixels"),
        contents: bytemuck::cast_slice(pixels),
        usage: wgpu::BufferUsages::STORAGE,
    });
    let size = pixels.len() as u64 * 16;
    let output = device.create_buffer(&wgpu::BufferDescriptor {
        label: Some("image"),
        size,
        usage: wgpu::BufferUsages::STORAGE | wgpu::BufferUsages::COPY_SRC,
        mapped_at_creation: false,
    });
    let staging = device.create_buffer(&wgpu::BufferDescriptor {
        label: Some("image readback"),
        size,
        usage: wgpu::BufferUsages::MAP_READ | wgpu::BufferUsages::COPY_DST,
        mapped_at_creation: false,
    });
    let bind_group = device.create_bind_group(&wgpu::BindGroupDescriptor {
        label: Some("pixels"),
        layout: &layout,
        entries: &[
            wgpu::BindGroupEntry { binding: 0, resource: input.as_entire_binding() },
            wgpu::BindGroupEntry { binding: 1, resource: output.as_entire_binding() },
        ],
    });
    let mut encoder = device.create_command_encoder(&Default::default());
    {
        let mut pass = encoder.begin_compute_pass(&Default::default());
        pass.set_pipeline(&pipeline);
        pass.set_bind_group(0, &bind_group, &[]);
        pass.set_bind_group(1, field.bind_group(), &[]);
        pass.dispatch_workgroups((pixels.len() as u32).div_ceil(64), 1, 1);
    }
    encoder.copy_buffer_to_buffer(&output, 0, &staging, 0, size);
    ctx.queue.submit([encoder.finish()]);
    let slice = staging.slice(..);
    let (tx, rx) = std::sync::mpsc::channel();
    slice.map_async(wgpu::MapMode::Read, move |r| {
        let _ = tx.send(r);
    });
    device.poll(wgpu::PollType::wait_indefinitely())?;
    rx.recv()??;
    let bytes = slice.get_mapped_range()?.to_vec();
    let texels: &[[f32; 4]] = bytemuck::cast_slice(&bytes);
    Ok(texels.to_vec())
}

/// `SHADE_WGSL` after the included query (its bindings in group 1): the
/// pixels' layout (group 0) and the pipeline.
fn shade_pipeline(device: &wgpu::Device) -> (wgpu::BindGroupLayout, wgpu::ComputePipeline) {
    let source = format!("{}\n{}", query_wgsl(1), SHADE_WGSL);
    let module = device.create_shader_module(wgpu::ShaderModuleDescriptor {
        label: Some("application shader"),
        source: wgpu::ShaderSource::Wgsl(source.into()),
    });
    let storage = |binding: u32, read_only: bool| wgpu::BindGroupLayoutEntry {
        binding,
        visibility: wgpu::ShaderStages::COMPUTE,
        ty: wgpu::BindingType::Buffer {
            ty: wgpu::BufferBindingType::Storage { read_only },
            has_dynamic_offset: false,
            min_binding_size: None,
        },
        count: None,
    };
    let layout = device.create_bind_group_layout(&wgpu::BindGroupLayoutDescriptor {
        label: Some("pixels"),
        entries: &[storage(0, true), storage(1, false)],
    });
    let field_layout = GpuDdgiField::bind_group_layout(device);
    let pipeline_layout = device.create_pipeline_layout(&wgpu::PipelineLayoutDescriptor {
        label: Some("application shader"),
        bind_group_layouts: &[Some(&layout), Some(&field_layout)],
        immediate_size: 0,
    });
    let pipeline = device.create_compute_pipeline(&wgpu::ComputePipelineDescriptor {
        label: Some("shade"),
        layout: Some(&pipeline_layout),
        module: &module,
        entry_point: Some("shade"),
        compilation_options: Default::default(),
        cache: None,
    });
    (layout, pipeline)
}
