//! The field set's seam (`probegi_cpu::ddgi_field_set`) driven by the wgpu
//! backend: [`WgpuProbeTracer`] is a `ProbeBatchTracer` whose probe ray batches
//! are traced by `probegi_wgpu::bvh_trace` (the WGSL CWBVH traversal) and, where
//! the scene allows, shaded by `probegi_wgpu::probe_shade` with the set's
//! previous field uploaded for `ddgi_query.wgsl`. The set's own bookkeeping
//! (relocation, classification, states, blend, border) stays on the CPU.
//!
//! This crate exists so that neither backend depends on the other: `probegi-cpu`
//! knows nothing of wgpu, `probegi-wgpu` nothing of the CPU backend.

use std::sync::Mutex;

use glam::Vec3;
use probegi_core::camera::CameraRays;
use probegi_core::ddgi_volume_blend::DdgiFieldSetView;
use probegi_cpu::ddgi::DdgiVolume;
use probegi_cpu::ddgi_field_set::ProbeRayBatch;
use probegi_cpu::probe_trace::ProbeBatchTracer;
use probegi_scene::{BvhTracer, RayHit, Scene};
use probegi_wgpu::bvh_trace::{GpuBvh, GpuRay, GpuRayBatch, GpuRayTrace};
use probegi_wgpu::camera_frame::{CameraFrame, GpuCameraPass};
use probegi_wgpu::ddgi_query::GpuDdgiField;
use probegi_wgpu::gpu_scene::{GpuScene, unsupported_by_gpu_shading};
use probegi_wgpu::probe_shade::{GpuProbeShade, shade_info};
use probegi_wgpu::{GpuContext, GpuError};

/// A batch's rays as the GPU trace reads them.
pub fn batch_rays(batch: &ProbeRayBatch) -> Vec<GpuRay> {
    (0..batch.len())
        .map(|i| GpuRay::new(batch.origins_m[i], batch.directions[i], 0.0, batch.max_distances_m[i]))
        .collect()
}

/// The GPU behind the seam: trace always, shade where [`WgpuProbeTracer::shades`].
pub struct WgpuProbeTracer {
    pub ctx: GpuContext,
    pub trace: GpuRayTrace,
    pub bvh: GpuBvh,
    /// The shade pass and the scene on the device; `None` when the scene needs
    /// what the GPU shading lacks (see `shading_note`).
    shading: Option<(GpuProbeShade, GpuScene)>,
    /// The camera pass (with `shading`, unless asked to leave the camera to the CPU).
    camera: Option<GpuCameraPass>,
    sky_radiance: Vec3,
    /// Why the probe rays are shaded on the CPU, when they are.
    pub shading_note: Option<String>,
    /// The last traced batch, resident for the shade pass.
    last: Mutex<Option<GpuRayBatch>>,
}

impl WgpuProbeTracer {
    /// The scene's BVH (and, where supported, its shading data) on `ctx`.
    /// `gpu_shading` false keeps the shade and the camera on the CPU; `gpu_camera`
    /// false keeps only the camera there.
    pub fn new(ctx: GpuContext, scene: &Scene, bvh: &BvhTracer, gpu_shading: bool) -> Result<Self, GpuError> {
        Self::with_camera(ctx, scene, bvh, gpu_shading, gpu_shading)
    }

    pub fn with_camera(
        ctx: GpuContext,
        scene: &Scene,
        bvh: &BvhTracer,
        gpu_shading: bool,
        gpu_camera: bool,
    ) -> Result<Self, GpuError> {
        let export = bvh.export_static().map_err(GpuError::Input)?;
        let gpu_bvh = GpuBvh::upload(&ctx, &export)?;
        let trace = GpuRayTrace::new(&ctx);
        let note = if gpu_shading { unsupported_by_gpu_shading(scene) } else { Some("CPU shading asked for".into()) };
        let shading = match note {
            None => Some((GpuProbeShade::new(&ctx)?, GpuScene::upload(&ctx, scene)?)),
            Some(_) => None,
        };
        let camera = if shading.is_some() && gpu_camera { Some(GpuCameraPass::new(&ctx)?) } else { None };
        Ok(Self {
            ctx,
            trace,
            bvh: gpu_bvh,
            shading,
            camera,
            sky_radiance: scene.sky_radiance,
            shading_note: note,
            last: Mutex::new(None),
        })
    }

    /// Whether the camera frame is rendered on the GPU.
    pub fn renders_camera(&self) -> bool {
        self.camera.is_some()
    }

    /// Whether the probe rays are shaded on the GPU.
    pub fn shades(&self) -> bool {
        self.shading.is_some()
    }

    /// The shade pass and the scene on the device, when the GPU shades.
    pub fn shading(&self) -> Option<(&GpuProbeShade, &GpuScene)> {
        self.shading.as_ref().map(|(p, s)| (p, s))
    }

    pub fn adapter_name(&self) -> &str {
        &self.ctx.adapter_name
    }
}

impl ProbeBatchTracer for WgpuProbeTracer {
    fn closest_hits(
        &self,
        batch: &ProbeRayBatch,
        _static_only: bool,
        hits: &mut Vec<Option<RayHit>>,
    ) -> Result<(), String> {
        // The GPU BVH holds static geometry only (`export_static`), so every batch
        // already sees what an initialisation round must.
        let rays = batch_rays(batch);
        hits.clear();
        if rays.len() > GpuRayTrace::max_batch_rays(&self.ctx) {
            // Larger than one binding: trace in pieces, shade on the CPU.
            let gpu = self.trace.trace(&self.ctx, &self.bvh, &rays, false).map_err(|e| e.to_string())?;
            hits.extend(gpu.iter().map(|h| h.ray_hit()));
            *self.last.lock().map_err(|e| e.to_string())? = None;
            return Ok(());
        }
        let resident = self.trace.batch(&self.ctx, &rays, false).map_err(|e| e.to_string())?;
        let mut encoder = self.ctx.device.create_command_encoder(&Default::default());
        self.trace.record(&mut encoder, &self.bvh, &resident, None);
        self.ctx.queue.submit([encoder.finish()]);
        let gpu = self.trace.download(&self.ctx, &resident).map_err(|e| e.to_string())?;
        hits.extend(gpu.iter().map(|h| h.ray_hit()));
        *self.last.lock().map_err(|e| e.to_string())? = Some(resident);
        Ok(())
    }

    fn shade_batch(
        &self,
        batch: &ProbeRayBatch,
        field: &DdgiFieldSetView<'_>,
        volumes: &[DdgiVolume],
        seed: u64,
        frame: u32,
        radiance: &mut Vec<Vec3>,
    ) -> Option<Result<(), String>> {
        let (shade, scene) = self.shading.as_ref()?;
        let last = self.last.lock().ok()?;
        let resident = last.as_ref().filter(|b| b.ray_count as usize == batch.len())?;
        let run = || -> Result<Vec<Vec3>, GpuError> {
            let mut info = vec![0u32; batch.len()];
            for bp in &batch.probes {
                let s = &volumes[bp.volume as usize].settings;
                for i in bp.first_ray..bp.first_ray + bp.ray_count {
                    let i = i as usize;
                    info[i] = shade_info(batch.needs_radiance[i], s.glossy_second_order, s.probe_area_light_samples);
                }
            }
            let gpu_field = GpuDdgiField::upload(&self.ctx, field)?;
            let seed32 = (seed ^ (seed >> 32)) as u32;
            shade.shade(&self.ctx, &self.bvh, &gpu_field, scene, resident, &info, seed32, frame, None)
        };
        Some(run().map(|l| *radiance = l).map_err(|e| e.to_string()))
    }

    fn pose_scene(&self, scene: &Scene) -> Result<(), String> {
        match &self.shading {
            Some((_, gpu_scene)) => gpu_scene.pose_lights(&self.ctx, scene).map_err(|e| e.to_string()),
            None => Ok(()),
        }
    }

    fn camera_frame(
        &self,
        camera: &CameraRays,
        field: &DdgiFieldSetView<'_>,
        area_samples: u32,
        second_order: bool,
        frame: u32,
        seed: u64,
        direct: &mut [Vec3],
        indirect: &mut [Vec3],
    ) -> Option<Result<(usize, usize), String>> {
        let pass = self.camera.as_ref()?;
        let (_, scene) = self.shading.as_ref()?;
        let ([_, _, _], [_, _, w, h]) = camera.basis();
        let mut run = || -> Result<(usize, usize), GpuError> {
            let gpu_field = GpuDdgiField::upload(&self.ctx, field)?;
            let f = CameraFrame {
                camera,
                width: w as u32,
                height: h as u32,
                frame,
                seed: (seed ^ (seed >> 32)) as u32,
                area_samples,
                second_order,
                sky_radiance: self.sky_radiance,
            };
            let image = pass.render(&self.ctx, &self.bvh, &gpu_field, scene, &f)?;
            if image.direct.len() != direct.len() || image.indirect.len() != indirect.len() {
                return Err(GpuError::Input(format!(
                    "{} camera pixels for a {}-pixel frame",
                    image.direct.len(),
                    direct.len()
                )));
            }
            direct.copy_from_slice(&image.direct);
            indirect.copy_from_slice(&image.indirect);
            Ok((image.surfaces, image.unlit))
        };
        Some(run().map_err(|e| e.to_string()))
    }
}
