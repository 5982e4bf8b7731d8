//! `--show-probes`: draws each probe as a small sphere in the camera image, shaded
//! by the probe's stored irradiance in the direction of the sphere's normal (the
//! mean radiance, i.e. what a white diffuse surface facing that way would reflect).
//! Probes that queries skip are drawn flat by state: Off and Dead dark red,
//! Sleeping (jcgt) blue; the usage scheme's SLEEPING probes, which queries read but
//! which update only every few frames, show their irradiance tinted blue.
//! Spheres are found by projecting each probe's bounding box to the screen and
//! intersecting the covered pixels' camera rays exactly.

use glam::{Vec2, Vec3};
use probegi_core::camera::CameraRays;
use probegi_core::octahedral::oct_encode;
use probegi_core::probe_classification::ProbeState;

use crate::gbuffer::GBuffer;
use probegi_core::irradiance_encoding::decode_irradiance;
use probegi_field::ddgi_volume::DdgiVolume;

/// Sphere radius as a fraction of the smallest probe spacing.
pub const PROBE_SPHERE_RADIUS_REL: f32 = 0.1;

/// Overwrites the pixels of `image` where a probe sphere is in front of the G-buffer surface.
pub fn draw_probes(volume: &DdgiVolume, camera: &CameraRays, gbuffer: &GBuffer, image: &mut [Vec3]) {
    let r = volume.grid.min_spacing_m() * PROBE_SPHERE_RADIUS_REL;
    let (w, h) = (gbuffer.width as i64, gbuffer.height as i64);
    let gamma = volume.settings.probe_irradiance_gamma;
    for (probe, &c) in volume.probe_positions.iter().enumerate() {
        let mut lo = Vec2::splat(f32::INFINITY);
        let mut hi = Vec2::splat(f32::NEG_INFINITY);
        for corner in 0..8 {
            let o = Vec3::new(
                if corner & 1 == 0 { -r } else { r },
                if corner & 2 == 0 { -r } else { r },
                if corner & 4 == 0 { -r } else { r },
            );
            match camera.project_world(c + o) {
                Some(p) => {
                    lo = lo.min(p);
                    hi = hi.max(p);
                }
                None => {
                    lo = Vec2::splat(f32::INFINITY);
                    break;
                }
            }
        }
        if !lo.is_finite() {
            continue;
        }
        let (x0, y0) = ((lo.x.floor() as i64).max(0), (lo.y.floor() as i64).max(0));
        let (x1, y1) = ((hi.x.ceil() as i64).min(w - 1), (hi.y.ceil() as i64).min(h - 1));
        for y in y0..=y1 {
            for x in x0..=x1 {
                let dir = camera.ray_dir_world(x as f32 + 0.5, y as f32 + 0.5);
                let oc = camera.origin_world - c;
                let b = oc.dot(dir);
                let disc = b * b - (oc.length_squared() - r * r);
                if disc < 0.0 {
                    continue;
                }
                let t = -b - disc.sqrt();
                if t <= 0.0 {
                    continue;
                }
                let idx = (y * w + x) as usize;
                let surface_t =
                    gbuffer.texels[idx].surface.map_or(f32::INFINITY, |s| (s.position - camera.origin_world).length());
                if t >= surface_t {
                    continue;
                }
                let n = (camera.origin_world + dir * t - c).normalize();
                image[idx] = match volume.probe_states[probe] {
                    ProbeState::Off | ProbeState::Dead => Vec3::new(0.3, 0.0, 0.0),
                    ProbeState::Sleeping => Vec3::new(0.05, 0.1, 0.5),
                    state => {
                        let e = volume.irradiance.sample_bilinear(probe, oct_encode(n));
                        let l = decode_irradiance(e, gamma);
                        if matches!(state, ProbeState::UsageSleeping | ProbeState::Idle) {
                            l * Vec3::new(0.3, 0.5, 1.0)
                        } else {
                            l
                        }
                    }
                };
            }
        }
    }
}
