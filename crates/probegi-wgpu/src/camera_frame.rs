//! The camera frame on the GPU (`shaders/camera_frame.wgsl`): primary rays
//! through the same BVH, surfaces, textures and the BSDF as the probe shade,
//! direct light with shadow rays, one GGX-sampled glossy ray per glossy pixel,
//! and the field query for indirect diffuse, mirroring the CPU's G-buffer and
//! camera passes under DDGI (`probegi_cpu::gbuffer`, `probegi_frame::frame_loop`).
//! The CPU reads back the frame's direct and indirect terms (it accumulates the
//! direct one over frames, as on the CPU).
//!
//! *Deviation:* per-pixel random numbers come from a PCG hash, not the CPU's
//! PCG32 streams, so area-light and glossy estimates (and the subpixel jitter
//! after frame 0) agree with the CPU's in distribution, not bit for bit.

use bytemuck::{Pod, Zeroable};
use glam::Vec3;
use probegi_core::camera::CameraRays;

use crate::bvh_trace::{GpuBvh, bvh_bind_group_layout};
use crate::ddgi_query::GpuDdgiField;
use crate::gpu_context::{GpuContext, GpuError};
use crate::gpu_scene::{GpuScene, scene_bind_group_layout};
use crate::shader_registry::{
    BVH_GROUP, BVH_STORAGE_BUFFERS, CAMERA_FRAME, FIELD_GROUP, FIELD_STORAGE_BUFFERS, PASS_GROUP, SCENE_GROUP,
    SCENE_STORAGE_BUFFERS,
};

/// The camera pass's uniform block; must match `CameraParams` in `camera_frame.wgsl`.
#[repr(C)]
#[derive(Clone, Copy, Debug, Default, Pod, Zeroable)]
pub(crate) struct CameraParams {
    /// xyz: the eye (m); w: tan(fov_y / 2).
    pub(crate) origin: [f32; 4],
    /// xyz: the view direction; w: the aspect ratio.
    pub(crate) forward: [f32; 4],
    /// xyz: the right axis; w: the width (pixels).
    pub(crate) right: [f32; 4],
    /// xyz: the up axis; w: the height (pixels).
    pub(crate) up: [f32; 4],
    /// Frame, seed, area-light samples, flags (1: second-order glossy, 2:
    /// shadowing field, 4: probe requests).
    pub(crate) info: [u32; 4],
    /// xyz: the sky's radiance.
    pub(crate) sky: [f32; 4],
}
const _: () = assert!(std::mem::size_of::<CameraParams>() == 96);

/// One frame's camera settings.
#[derive(Clone, Copy, Debug)]
pub struct CameraFrame<'a> {
    /// The camera's rays (its basis and resolution).
    pub camera: &'a CameraRays,
    /// The image's width in pixels (the camera's).
    pub width: u32,
    /// The image's height in pixels (the camera's).
    pub height: u32,
    /// The frame number (subpixel jitter after frame 0, random streams).
    pub frame: u32,
    /// The render's seed.
    pub seed: u32,
    /// Area-light samples per pixel (stratified).
    pub area_samples: u32,
    /// Sky-map samples per pixel (stratified; a constant sky takes none).
    pub sky_samples: u32,
    /// Second-order glossy on glossy rays' hits.
    pub second_order: bool,
    /// Radiance of the sky for rays that miss.
    pub sky_radiance: Vec3,
    /// The screen scheme's requests: the words of the request bitset
    /// (`DdgiFieldSet::probe_request_layout`) to fill, 0 for none.
    pub request_words: u32,
}

/// One camera frame read back.
#[derive(Clone, Debug, Default)]
pub struct CameraImage {
    /// Direct light per pixel, row-major.
    pub direct: Vec<Vec3>,
    /// The field's irradiance/π per pixel, row-major.
    pub irradiance_over_pi: Vec<Vec3>,
    /// The diffuse albedo that weighs it per pixel, row-major.
    pub albedo: Vec<Vec3>,
    /// The primary ray's hit point per pixel, metres, row-major.
    pub position_m: Vec<Vec3>,
    /// The geometric normal facing the camera per pixel (zero: no hit), row-major.
    pub normal: Vec<Vec3>,
    /// Pixels on a surface with a diffuse albedo.
    pub surfaces: usize,
    /// Those of them that got no light from the field.
    pub unlit: usize,
    /// The probes the frame's queries read, as the request bitset
    /// (`CameraFrame::request_words` words; empty without requests).
    pub requests: Vec<u32>,
}

/// The camera pass's pipeline (`camera_frame.wgsl` with the BVH, the field and
/// the scene in their groups, `shader_registry`).
pub struct GpuCameraPass {
    layout: wgpu::BindGroupLayout,
    pipeline: wgpu::ComputePipeline,
}

impl GpuCameraPass {
    /// Storage buffers the pass binds per stage: its own 3, the BVH's, the
    /// field's and the scene's.
    pub const STORAGE_BUFFERS: u32 = 3 + BVH_STORAGE_BUFFERS + FIELD_STORAGE_BUFFERS + SCENE_STORAGE_BUFFERS;

    /// The pipeline on `ctx`; an error where the device binds too few storage buffers.
    pub fn new(ctx: &GpuContext) -> Result<Self, GpuError> {
        ctx.check_pipeline(Self::STORAGE_BUFFERS, "the camera pass")?;
        let layout = ctx.pass_layout("camera frame", &[false, false, false]);
        let bvh = bvh_bind_group_layout(&ctx.device);
        let field = GpuDdgiField::bind_group_layout(&ctx.device);
        let scene = scene_bind_group_layout(&ctx.device);
        let [pipeline] = ctx.compute_pipelines(
            &CAMERA_FRAME,
            &[Some(&layout), Some(&bvh), Some(&field), Some(&scene)],
            ["shade_camera"],
        );
        Ok(Self { layout, pipeline })
    }

    /// The uniform block of frame `f` (an error where the rays' size is not the frame's).
    pub(crate) fn params(f: &CameraFrame<'_>, shadow_field: bool) -> Result<CameraParams, GpuError> {
        let (_, [_, _, w, h]) = f.camera.basis();
        if w as u32 != f.width || h as u32 != f.height {
            return Err(GpuError::Input(format!("camera rays for {w}×{h}, frame of {}×{}", f.width, f.height)));
        }
        let [origin, forward, right, up] = camera_texels(f.camera);
        Ok(CameraParams {
            origin,
            forward,
            right,
            up,
            info: [
                f.frame,
                f.seed,
                f.area_samples,
                f.second_order as u32 | (shadow_field as u32) << 1 | ((f.request_words > 0) as u32) << 2,
            ],
            sky: f.sky_radiance.extend(f32::from_bits(f.sky_samples)).into(),
        })
    }

    /// Records the pass of frame `f` into `encoder`, writing `targets`
    /// (its uniform block already written to `targets.params`).
    pub(crate) fn record(
        &self,
        ctx: &GpuContext,
        encoder: &mut wgpu::CommandEncoder,
        (bvh, field, scene): (&GpuBvh, &GpuDdgiField, &GpuScene),
        f: &CameraFrame<'_>,
        targets: &CameraTargets<'_>,
        timestamps: Option<wgpu::ComputePassTimestampWrites<'_>>,
    ) {
        let buffers = [targets.params, targets.direct, targets.irradiance, targets.requests];
        // The device frame binds the same images every frame: one bind group,
        // kept. The host path's images are new each call: so is its group.
        let bind_group = if targets.kept {
            ctx.bind_group_kept("camera frame", 0, &self.layout, &buffers)
        } else {
            let buffers: Vec<wgpu::Buffer> = buffers.into_iter().cloned().collect();
            crate::gpu_context::buffers_bind_group(ctx, "camera frame", &self.layout, &buffers)
        };
        let mut pass = encoder.begin_compute_pass(&wgpu::ComputePassDescriptor {
            label: Some("camera frame"),
            timestamp_writes: timestamps,
        });
        pass.set_pipeline(&self.pipeline);
        pass.set_bind_group(PASS_GROUP, &bind_group, &[]);
        pass.set_bind_group(BVH_GROUP, bvh.bind_group(), &[]);
        pass.set_bind_group(FIELD_GROUP, field.bind_group(), &[]);
        pass.set_bind_group(SCENE_GROUP, scene.bind_group(), &[]);
        pass.dispatch_workgroups(f.width.div_ceil(8), f.height.div_ceil(8), 1);
    }

    /// The frame's direct and indirect terms, row-major, and (surface pixels with
    /// a diffuse albedo, those of them the field left unlit), read back: the
    /// host path (`ProbeBatchTracer::camera_frame`) and the equivalence tests.
    /// The device-resident frame (`device_frame`) records the same pass instead.
    pub fn render(
        &self,
        ctx: &GpuContext,
        bvh: &GpuBvh,
        field: &GpuDdgiField,
        scene: &GpuScene,
        f: &CameraFrame<'_>,
    ) -> Result<CameraImage, GpuError> {
        let n = f.width as u64 * f.height as u64;
        if n == 0 {
            return Ok(CameraImage::default());
        }
        let params = Self::params(f, field.shadow_field)?;
        let device = &ctx.device;
        let params = ctx.buffer_with("camera params", bytemuck::bytes_of(&params), wgpu::BufferUsages::UNIFORM);
        let image = |label, texels_per_pixel: u64| -> Result<wgpu::Buffer, GpuError> {
            let size = n * 16 * texels_per_pixel;
            ctx.check_buffer(size, label)?;
            Ok(ctx.create_buffer(&wgpu::BufferDescriptor {
                label: Some(label),
                size,
                usage: wgpu::BufferUsages::STORAGE | wgpu::BufferUsages::COPY_SRC,
                mapped_at_creation: false,
            }))
        };
        // `camera_direct` holds three texels per pixel: the direct term, the
        // albedo, the hit point (their w: the normal's octahedral coordinates, a hit).
        let (direct, irradiance) = (image("camera direct, albedo and normal", 3)?, image("camera irradiance", 1)?);
        // Zeroed at creation; at least one word so the binding is never empty.
        let requests = ctx.create_buffer(&wgpu::BufferDescriptor {
            label: Some("camera probe requests"),
            size: 4 * f.request_words.max(1) as u64,
            usage: wgpu::BufferUsages::STORAGE | wgpu::BufferUsages::COPY_SRC,
            mapped_at_creation: false,
        });
        let targets = CameraTargets {
            params: &params,
            direct: &direct,
            irradiance: &irradiance,
            requests: &requests,
            kept: false,
        };
        let mut encoder = device.create_command_encoder(&Default::default());
        self.record(ctx, &mut encoder, (bvh, field, scene), f, &targets, None);
        ctx.submit(encoder.finish());
        let read = |b: &wgpu::Buffer| -> Result<Vec<[f32; 4]>, GpuError> {
            let bytes = ctx.read_back(b)?;
            Ok(bytemuck::cast_slice::<u8, [f32; 4]>(&bytes).to_vec())
        };
        let (d, i) = (read(&direct)?, read(&irradiance)?);
        let requests = if f.request_words > 0 {
            bytemuck::cast_slice::<u8, u32>(&ctx.read_back(&requests)?).to_vec()
        } else {
            Vec::new()
        };
        let v3 = |t: &[f32; 4]| Vec3::new(t[0], t[1], t[2]);
        let flags = |t: &[f32; 4]| (t[3] + 0.5) as u32 & 3;
        Ok(CameraImage {
            direct: d.iter().step_by(3).map(v3).collect(),
            albedo: d.iter().skip(1).step_by(3).map(v3).collect(),
            position_m: d.iter().skip(2).step_by(3).map(v3).collect(),
            normal: d.chunks_exact(3).map(camera_normal).collect(),
            irradiance_over_pi: i.iter().map(v3).collect(),
            surfaces: i.iter().filter(|t| flags(t) != 0).count(),
            unlit: i.iter().filter(|t| flags(t) == 2).count(),
            requests,
        })
    }
}

/// A camera as the shaders read it (`CameraParams`'s and `device_frame.wgsl`'s
/// `FrameCamera`'s first four texels): the eye with tan(fov_y / 2), then the
/// forward, right and up axes with the aspect, the width and the height.
pub(crate) fn camera_texels(c: &CameraRays) -> [[f32; 4]; 4] {
    let ([forward, right, up], [tan, aspect, w, h]) = c.basis();
    let o = c.origin_world;
    [[o.x, o.y, o.z, tan], forward.extend(aspect).into(), right.extend(w).into(), up.extend(h).into()]
}

/// Where the camera pass writes: its uniform block, `camera_direct` (three
/// texels a pixel), `camera_irradiance` (one) and the request bitset.
pub(crate) struct CameraTargets<'a> {
    pub(crate) params: &'a wgpu::Buffer,
    pub(crate) direct: &'a wgpu::Buffer,
    pub(crate) irradiance: &'a wgpu::Buffer,
    pub(crate) requests: &'a wgpu::Buffer,
    /// Images kept from frame to frame (the device frame's): their bind group is too.
    pub(crate) kept: bool,
}

/// A pixel's normal from its three `camera_direct` texels: the octahedral
/// coordinates in the first two's w, zero where the third's w flags no hit.
fn camera_normal(texels: &[[f32; 4]]) -> Vec3 {
    if texels[2][3] > 0.5 {
        probegi_core::octahedral::oct_decode(glam::Vec2::new(texels[0][3], texels[1][3]))
    } else {
        Vec3::ZERO
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use probegi_core::octahedral::oct_encode;

    /// `camera_frame.wgsl` packs a pixel's normal as `ddgi_oct_encode` (which
    /// mirrors `oct_encode`) into the w of its first two texels and flags a
    /// hit in the third's; the host's decode gives the normal back, and zero
    /// for a miss.
    #[test]
    fn the_packed_normal_decodes() {
        for n in [Vec3::Y, -Vec3::Z, Vec3::new(0.3, -0.8, 0.52).normalize(), Vec3::new(-0.6, 0.1, -0.79).normalize()] {
            let uv = oct_encode(n);
            let texels = [[0.0, 0.0, 0.0, uv.x], [0.0, 0.0, 0.0, uv.y], [1.0, 2.0, 3.0, 1.0]];
            let got = camera_normal(&texels);
            assert!(got.dot(n) > 1.0 - 1e-5, "{n} → {got}");
        }
        let miss = [[0.0, 0.0, 0.0, 0.0], [0.0, 0.0, 0.0, 0.0], [0.0, 0.0, 0.0, 0.0]];
        assert_eq!(camera_normal(&miss), Vec3::ZERO);
    }
}
