//! G-buffer pass: one primary ray per pixel into the scene, keeping the surface
//! each pixel sees. Later passes (direct light, GI queries) shade from it.

use glam::Vec3;
use probegi_core::camera::CameraRays;
use probegi_core::rng::{Pcg32, hash_combine};
use probegi_scene::{Ray, RayTracer, Scene, SurfacePoint};

/// What one pixel sees.
#[derive(Clone, Copy, Debug)]
pub struct GBufferTexel {
    /// The visible surface; `None` when the primary ray left the scene.
    pub surface: Option<SurfacePoint>,
    /// Unit direction from the surface toward the camera.
    pub view_dir_world: Vec3,
}

/// One frame's primary-ray hits: what each pixel sees.
#[derive(Clone, Debug)]
pub struct GBuffer {
    /// Width in pixels.
    pub width: u32,
    /// Height in pixels.
    pub height: u32,
    /// One texel per pixel, row-major (`y * width + x`).
    pub texels: Vec<GBufferTexel>,
}

/// Traces the primary rays of frame `frame_index`. Frame 0 samples pixel
/// centres; later frames jitter uniformly inside the pixel (box filter), so
/// accumulating frames antialiases. Returns the buffer and the ray count.
pub fn trace_gbuffer(
    scene: &Scene,
    tracer: &dyn RayTracer,
    camera: &CameraRays,
    width: u32,
    height: u32,
    frame_index: u32,
    seed: u64,
) -> (GBuffer, u64) {
    let empty = GBufferTexel { surface: None, view_dir_world: Vec3::Z };
    let mut texels = vec![empty; width as usize * height as usize];
    let w = width as usize;
    let rays = crate::parallel::for_each_row(
        &mut texels,
        w,
        |y, row| {
            for (x, t) in row.iter_mut().enumerate() {
                let jitter = if frame_index == 0 {
                    glam::Vec2::splat(0.5)
                } else {
                    let pixel = (y * w + x) as u64;
                    Pcg32::new(hash_combine(&[seed, pixel, frame_index as u64, 0x6b]), pixel).next_vec2()
                };
                let dir = camera.ray_dir_world(x as f32 + jitter.x, y as f32 + jitter.y);
                let ray = Ray::new(camera.origin_world, dir);
                *t = GBufferTexel {
                    surface: tracer.closest_hit(&ray).map(|h| scene.surface_point(&h)),
                    view_dir_world: -dir,
                };
            }
            row.len() as u64
        },
        || {},
    );
    (GBuffer { width, height, texels }, rays)
}
