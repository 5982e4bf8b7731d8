//! The camera image's running sums between frames, and the temporal filter
//! that carries them across a moving camera's frames.
//!
//! A still camera's direct term and diffuse albedo accumulate over its jittered
//! frames (a box-filtered mean: antialiased). Its field term is the field's
//! irradiance/π at the pixel's last diffuse sample, weighed by the accumulated
//! albedo rather than by one sample of it (demodulation, as real-time denoisers
//! do: the albedo is antialiased, the irradiance stays current). One jittered
//! texture sample per pixel otherwise leaves texel-sized speckle in the
//! indirect light: on Sponza's walls 1.4 % of the reference-lit pixels
//! rendered under a quarter of it, 0.8 % demodulated.
//!
//! A moving camera reprojects the sums instead of starting them again
//! (temporal antialiasing: Karis, "High-quality temporal supersampling",
//! SIGGRAPH 2014 course; Salvi, "An excursion in temporal supersampling",
//! GDC 2016). Each pixel's surface point, where its centre ray meets the
//! tangent plane of its jittered sample's surface, is projected into the
//! last frame's camera. The last frame's means are read from the taps that
//! saw the same surface, and held inside those taps' range. A pixel that
//! sees the sky reads the taps that saw the sky. The history then weighs at
//! most [`TemporalSettings::temporal_history_frames`] − 1 frames against the
//! new one. The direct term's history is clamped to the new frame's 3 × 3
//! neighbourhood, which bounds the ghost of view-dependent glossy light; the
//! albedo is view-independent and is not. The field term stays the current
//! frame's irradiance, so the filter delays no change of the field. An
//! animated scene (moving objects, edited lights) still starts the sums
//! again: it has no motion vectors.
//!
//! Deliberate deviations from those sources, each measured on the 4×4
//! flythrough (docs/RESULTS.md, "A moving camera's temporal filter"):
//! - The surface test is the distance to the point's tangent plane (5 % of
//!   its depth) and the same side, not SVGF's (Schied et al. 2017) depth
//!   gradient and normal thresholds: a floor seen edge-on passes because its
//!   points lie on the plane, and matching normals cost more in aliasing on
//!   faceted columns than they saved.
//! - The history is a box mean capped at a few frames (as SVGF's
//!   α = max(1/n, α_min)), not Karis's fixed exponential weight.
//! - Catmull-Rom taps where the central 2 × 2 pass, else bilinear: bilinear's
//!   blur compounds frame after frame.
//! - The clamp is per RGB channel, mean ± σ·`temporal_clip_sigma`, not
//!   Salvi's variance clipping in YCoCg.

use glam::{DVec3, Vec3};
use probegi_core::camera::CameraRays;
use rayon::prelude::*;

/// The temporal filter of a moving camera (see the module docs): a render-loop
/// choice, not a paper's. `Default` holds the values measured on the 4×4
/// Sponza flythrough (docs/RESULTS.md).
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct TemporalSettings {
    /// The most frames a moving camera's pixel averages, the new one included
    /// (default 4: each resampling of the history blurs it a little; on the
    /// 4×4 flythrough 4 beat 8 and 16 and tied with 2, which lost on a
    /// dolly); 0 or 1 turns the filter off: each moving frame is then its
    /// own sample.
    pub temporal_history_frames: u32,
    /// The direct term's history is clamped to the new frame's 3 × 3
    /// neighbourhood mean ± this many standard deviations, per channel
    /// (default 1.25, Salvi 2016's range); 0 leaves it unclamped, which on the
    /// flythrough let sunlit surfaces ghost across the frame.
    pub temporal_clip_sigma: f32,
}

impl Default for TemporalSettings {
    fn default() -> Self {
        Self { temporal_history_frames: 4, temporal_clip_sigma: 1.25 }
    }
}

/// What a frame does to the sums before it adds to them.
pub(super) enum History {
    /// A still camera in a still scene: the frame adds to the sums.
    Accumulate,
    /// The scene changed: the sums start again from this frame.
    Restart,
    /// The camera moved from `from`: the sums are reprojected first.
    Reproject { from: CameraRays, settings: TemporalSettings },
}

/// A pixel's means in the last frame, as the reprojection reads them.
#[derive(Clone, Copy)]
struct LastMeans {
    direct: Vec3,
    albedo: Vec3,
    irradiance: Vec3,
    count: f32,
}

/// The weighed sum of a pixel's history taps, and the range of their values.
struct TapSum {
    sum: LastMeans,
    lo: LastMeans,
    hi: LastMeans,
    weight: f32,
}

impl Default for TapSum {
    fn default() -> Self {
        let at =
            |v: f32| LastMeans { direct: Vec3::splat(v), albedo: Vec3::splat(v), irradiance: Vec3::splat(v), count: v };
        Self { sum: at(0.0), lo: at(f32::INFINITY), hi: at(f32::NEG_INFINITY), weight: 0.0 }
    }
}

impl TapSum {
    fn add(&mut self, tap: &LastMeans, k: f32) {
        let s = &mut self.sum;
        (s.direct, s.albedo, s.irradiance, s.count) = (
            s.direct + tap.direct * k,
            s.albedo + tap.albedo * k,
            s.irradiance + tap.irradiance * k,
            s.count + tap.count * k,
        );
        (self.lo.direct, self.hi.direct) = (self.lo.direct.min(tap.direct), self.hi.direct.max(tap.direct));
        (self.lo.albedo, self.hi.albedo) = (self.lo.albedo.min(tap.albedo), self.hi.albedo.max(tap.albedo));
        (self.lo.irradiance, self.hi.irradiance) =
            (self.lo.irradiance.min(tap.irradiance), self.hi.irradiance.max(tap.irradiance));
        (self.lo.count, self.hi.count) = (self.lo.count.min(tap.count), self.hi.count.max(tap.count));
        self.weight += k;
    }

    /// The taps' means renormalised over their weight and held inside the
    /// taps' range (Catmull-Rom's negative lobes overshoot at an edge, and the
    /// albedo is not clamped to the new frame). A history whose taps carry
    /// less than the whole weight (bilinear taps past a silhouette) counts
    /// that much less; none where no weight is left.
    fn history(&self) -> PixelHistory {
        if self.weight < MIN_TAP_WEIGHT {
            return PixelHistory::default();
        }
        let (s, lo, hi, w) = (&self.sum, &self.lo, &self.hi, self.weight);
        let n = ((s.count / w).clamp(lo.count, hi.count) * w.min(1.0)) as f64;
        PixelHistory {
            direct_sum: (s.direct / w).clamp(lo.direct, hi.direct).as_dvec3() * n,
            albedo_sum: (s.albedo / w).clamp(lo.albedo, hi.albedo).as_dvec3() * n,
            count: n,
            irradiance: (s.irradiance / w).clamp(lo.irradiance, hi.irradiance),
        }
    }
}

/// Below this total tap weight a history is empty.
const MIN_TAP_WEIGHT: f32 = 1e-4;

/// A pixel's sums as the reprojection carries them over.
#[derive(Clone, Copy, Default)]
struct PixelHistory {
    direct_sum: DVec3,
    albedo_sum: DVec3,
    count: f64,
    irradiance: Vec3,
}

/// The render's running sums between frames (see the module docs).
#[derive(Clone)]
pub(super) struct Accumulation {
    width: usize,
    direct_sum: Vec<DVec3>,
    albedo_sum: Vec<DVec3>,
    /// Frames in each pixel's sums (fractional after a reprojection).
    count: Vec<f64>,
    /// This frame's direct term per pixel.
    pub(super) frame_direct: Vec<Vec3>,
    /// This frame's irradiance/π from the field per pixel.
    pub(super) frame_irradiance: Vec<Vec3>,
    /// This frame's diffuse albedo per pixel (zero off surfaces).
    pub(super) frame_albedo: Vec<Vec3>,
    /// This frame's primary-ray hit point per pixel, metres.
    pub(super) frame_position_m: Vec<Vec3>,
    /// This frame's geometric normal per pixel, facing the camera (zero where
    /// the ray met nothing).
    pub(super) frame_normal: Vec<Vec3>,
    /// Irradiance/π at the last sample of each pixel that had a diffuse albedo.
    irradiance: Vec<Vec3>,
    /// The surface point each pixel saw in the last frame (`None`: the sky).
    points: Vec<Option<Surface>>,
}

impl Accumulation {
    pub(super) fn new(width: u32, height: u32) -> Self {
        let pixels = width as usize * height as usize;
        Self {
            width: width.max(1) as usize,
            direct_sum: vec![DVec3::ZERO; pixels],
            albedo_sum: vec![DVec3::ZERO; pixels],
            count: vec![0.0; pixels],
            frame_direct: vec![Vec3::ZERO; pixels],
            frame_irradiance: vec![Vec3::ZERO; pixels],
            frame_albedo: vec![Vec3::ZERO; pixels],
            frame_position_m: vec![Vec3::ZERO; pixels],
            frame_normal: vec![Vec3::ZERO; pixels],
            irradiance: vec![Vec3::ZERO; pixels],
            points: vec![None; pixels],
        }
    }

    /// Pixels in the image.
    pub(super) fn len(&self) -> usize {
        self.direct_sum.len()
    }

    /// Adds the frame seen through `camera` (its direct term and albedo, and its
    /// irradiance where it saw a diffuse surface), after `history` has kept,
    /// cleared or reprojected the sums.
    pub(super) fn add_frame(&mut self, camera: &CameraRays, history: History) {
        let points = self.frame_points(camera);
        match history {
            History::Accumulate => {}
            History::Reproject { from, settings } if settings.temporal_history_frames > 1 => {
                self.reproject(&from, camera, &points, settings)
            }
            History::Restart | History::Reproject { .. } => {
                self.direct_sum.iter_mut().for_each(|a| *a = DVec3::ZERO);
                self.albedo_sum.iter_mut().for_each(|a| *a = DVec3::ZERO);
                self.count.iter_mut().for_each(|n| *n = 0.0);
            }
        }
        for p in 0..self.len() {
            self.direct_sum[p] += self.frame_direct[p].as_dvec3();
            self.albedo_sum[p] += self.frame_albedo[p].as_dvec3();
            self.count[p] += 1.0;
            if self.frame_albedo[p].max_element() > 0.0 {
                self.irradiance[p] = self.frame_irradiance[p];
            }
        }
        self.points = points;
    }

    /// What each pixel saw this frame through `camera`: where its centre ray
    /// meets the tangent plane of its sample's surface (the pixel's own point,
    /// whatever its jitter; the sample's point where that ray runs along the
    /// plane), and the normal; `None` where the sample met nothing.
    fn frame_points(&self, camera: &CameraRays) -> Vec<Option<Surface>> {
        let w = self.width;
        let (positions, normals) = (&self.frame_position_m, &self.frame_normal);
        (0..positions.len())
            .into_par_iter()
            .map(|p| {
                let (sample, normal) = (positions[p], normals[p]);
                if normal == Vec3::ZERO || !sample.is_finite() {
                    return None;
                }
                let dir = camera.ray_dir_world((p % w) as f32 + 0.5, (p / w) as f32 + 0.5);
                let (along, facing) = ((sample - camera.origin_world).dot(normal), dir.dot(normal));
                let t = along / facing;
                let sample_t = sample.distance(camera.origin_world);
                // A centre ray nearly along the plane, or far off the sample's
                // distance, keeps the sample's own point.
                let point_world = if facing.abs() > 1e-3 && t > 0.5 * sample_t && t < 2.0 * sample_t {
                    camera.origin_world + dir * t
                } else {
                    sample
                };
                Some(Surface { point_world, normal })
            })
            .collect()
    }

    /// Replaces the sums by those of the last frame reprojected to `to`'s
    /// pixels (`points`: what they see now), each capped to
    /// `temporal_history_frames` − 1 frames and its direct term clamped.
    fn reproject(&mut self, from: &CameraRays, to: &CameraRays, points: &[Option<Surface>], s: TemporalSettings) {
        let frames_max = (s.temporal_history_frames - 1) as f64;
        let w = self.width;
        let last: Vec<LastMeans> = (0..self.len())
            .into_par_iter()
            .map(|q| {
                let n = self.count[q];
                let mean = |sum: DVec3| if n > 0.0 { (sum / n).as_vec3() } else { Vec3::ZERO };
                LastMeans {
                    direct: mean(self.direct_sum[q]),
                    albedo: mean(self.albedo_sum[q]),
                    irradiance: self.irradiance[q],
                    count: n as f32,
                }
            })
            .collect();
        let history: Vec<PixelHistory> = (0..self.len())
            .into_par_iter()
            .map(|p| {
                let mut h = self.history_at(p, from, to, points, &last);
                if h.count > frames_max {
                    let k = frames_max / h.count;
                    (h.direct_sum, h.albedo_sum, h.count) = (h.direct_sum * k, h.albedo_sum * k, frames_max);
                }
                if s.temporal_clip_sigma > 0.0 && h.count > 0.0 {
                    let sigma = s.temporal_clip_sigma;
                    h.direct_sum =
                        clamp_to_neighbourhood(&self.frame_direct, w, p, h.direct_sum / h.count, sigma) * h.count;
                }
                h
            })
            .collect();
        self.direct_sum.par_iter_mut().zip(&history).for_each(|(a, h)| *a = h.direct_sum);
        self.albedo_sum.par_iter_mut().zip(&history).for_each(|(a, h)| *a = h.albedo_sum);
        self.count.par_iter_mut().zip(&history).for_each(|(a, h)| *a = h.count);
        self.irradiance.par_iter_mut().zip(&history).for_each(|(a, h)| *a = h.irradiance);
    }

    /// Pixel `p`'s history: the last frame's means around where its point (or,
    /// for the sky, its direction) projects in `from`, read from the taps that
    /// saw the same surface; empty when none did. Catmull-Rom over the 4 × 4
    /// taps that pass where the central 2 × 2 all do (sharper than bilinear,
    /// whose blur compounds frame after frame), else bilinear over those of
    /// the 2 × 2 that pass.
    fn history_at(
        &self,
        p: usize,
        from: &CameraRays,
        to: &CameraRays,
        points: &[Option<Surface>],
        last: &[LastMeans],
    ) -> PixelHistory {
        let (w, h) = (self.width, self.len() / self.width);
        let (x, y) = (p % w, p / w);
        let seen = match points[p] {
            Some(surface) => surface.point_world,
            None => from.origin_world + to.ray_dir_world(x as f32 + 0.5, y as f32 + 0.5),
        };
        let Some(at) = from.project_world(seen) else {
            return PixelHistory::default();
        };
        let same_surface = |q: usize| {
            self.count[q] > 0.0
                && match (points[p], self.points[q]) {
                    (Some(now), Some(then)) => now.continues(&then, from),
                    (None, None) => true,
                    _ => false,
                }
        };
        let (fx, fy) = (at.x - 0.5, at.y - 0.5);
        let (x0, y0) = (fx.floor() as i64, fy.floor() as i64);
        let (ax, ay) = (fx - fx.floor(), fy - fy.floor());
        let tap = |dx: i64, dy: i64| {
            let (qx, qy) = (x0 + dx, y0 + dy);
            (qx >= 0 && qy >= 0 && qx < w as i64 && qy < h as i64).then(|| qy as usize * w + qx as usize)
        };
        let (cx, cy) = (catmull_rom(ax), catmull_rom(ay));
        let passing = |dx: i64, dy: i64| tap(dx, dy).filter(|&q| same_surface(q));
        let centre = [(0, 0), (1, 0), (0, 1), (1, 1)];
        let mut sum = TapSum::default();
        if centre.iter().all(|&(dx, dy)| passing(dx, dy).is_some()) {
            for k in 0..16i64 {
                if let Some(q) = passing(k % 4 - 1, k / 4 - 1) {
                    sum.add(&last[q], cx[(k % 4) as usize] * cy[(k / 4) as usize]);
                }
            }
        } else {
            let bilinear = [(1.0 - ax) * (1.0 - ay), ax * (1.0 - ay), (1.0 - ax) * ay, ax * ay];
            for (&(dx, dy), k) in centre.iter().zip(bilinear) {
                if let Some(q) = passing(dx, dy) {
                    sum.add(&last[q], k);
                }
            }
        }
        sum.history()
    }

    /// Pixel `p`'s mean direct term over the frames in its sums.
    pub(super) fn direct(&self, p: usize) -> Vec3 {
        (self.direct_sum[p] / self.count[p].max(1.0)).as_vec3()
    }

    /// Pixel `p`'s field term: the mean diffuse albedo × the irradiance/π of
    /// its last diffuse sample.
    pub(super) fn indirect(&self, p: usize) -> Vec3 {
        (self.albedo_sum[p] / self.count[p].max(1.0)).as_vec3() * self.irradiance[p]
    }

    /// The composed image: mean direct term plus the antialiased field term.
    pub(super) fn pixels(&self) -> Vec<Vec3> {
        (0..self.len()).map(|p| self.direct(p) + self.indirect(p)).collect()
    }

    /// The field term as the image shows it ([`Self::indirect`]).
    pub(super) fn indirect_image(&self) -> Vec<Vec3> {
        (0..self.len()).map(|p| self.indirect(p)).collect()
    }

    /// Means of the composed image and of its field term, without composing it.
    pub(super) fn means(&self) -> (Vec3, Vec3) {
        let (mut all, mut field) = (DVec3::ZERO, DVec3::ZERO);
        for p in 0..self.len() {
            let indirect = self.indirect(p).as_dvec3();
            all += self.direct(p).as_dvec3() + indirect;
            field += indirect;
        }
        let n = self.len().max(1) as f64;
        ((all / n).as_vec3(), (field / n).as_vec3())
    }
}

/// `mean` clamped, per channel, to `frame` (a `width`-wide image) around
/// pixel `p` (3 × 3): its mean ± `sigma` standard deviations.
fn clamp_to_neighbourhood(frame: &[Vec3], width: usize, p: usize, mean: DVec3, sigma: f32) -> DVec3 {
    let (w, h) = (width as i64, (frame.len() / width) as i64);
    let (x, y) = ((p % width) as i64, (p / width) as i64);
    let (mut m1, mut m2, mut n) = (DVec3::ZERO, DVec3::ZERO, 0.0);
    for (qx, qy) in (-1..=1).flat_map(|dy| (-1..=1).map(move |dx| (x + dx, y + dy))) {
        if qx >= 0 && qy >= 0 && qx < w && qy < h {
            let v = frame[(qy * w + qx) as usize].as_dvec3();
            (m1, m2, n) = (m1 + v, m2 + v * v, n + 1.0);
        }
    }
    let mu = m1 / n;
    let spread = (m2 / n - mu * mu).max(DVec3::ZERO).sqrt() * sigma as f64;
    mean.clamp(mu - spread, mu + spread)
}

/// Catmull-Rom weights of the taps at −1, 0, 1 and 2 for a point `t` ∈ [0, 1)
/// past tap 0 (they sum to 1).
fn catmull_rom(t: f32) -> [f32; 4] {
    [
        t * (-0.5 + t * (1.0 - 0.5 * t)),
        1.0 + t * t * (-2.5 + 1.5 * t),
        t * (0.5 + t * (2.0 - 1.5 * t)),
        t * t * (-0.5 + 0.5 * t),
    ]
}

/// How far from a point's tangent plane, as a fraction of its depth, a point
/// of the last frame may lie and count as the same surface ([`Surface::continues`]).
const SAME_SURFACE_PLANE_DEPTH_FRACTION: f32 = 0.05;

/// What a pixel saw: the surface point at its centre ray and the geometric
/// normal there, facing the camera.
#[derive(Clone, Copy, Debug)]
struct Surface {
    point_world: Vec3,
    normal: Vec3,
}

impl Surface {
    /// Whether `then`, seen from `from` in the last frame, lies on the same
    /// surface as this point: within 5 % of its depth in `from` of this
    /// point's tangent plane (so that a floor seen edge-on still passes and a
    /// silhouette does not), on the same side (so that the far face of a thin
    /// wall does not). Measured on the 4×4 flythrough (docs/RESULTS.md): a
    /// tighter plane or normals within 37° or 60° of each other cost more in
    /// aliasing than they saved in ghosts.
    fn continues(&self, then: &Surface, from: &CameraRays) -> bool {
        let depth_m = (self.point_world - from.origin_world).dot(from.forward_world());
        let off_plane_m = (then.point_world - self.point_world).dot(self.normal).abs();
        off_plane_m <= SAME_SURFACE_PLANE_DEPTH_FRACTION * depth_m && then.normal.dot(self.normal) >= 0.0
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use probegi_core::camera::Camera;

    /// A still camera's field term: the last frame's irradiance weighed by the
    /// albedo accumulated over its frames, per channel; a restart forgets it.
    #[test]
    fn the_field_term_takes_the_accumulated_albedo() {
        let camera = CameraRays::new(&Camera::default(), 2, 1);
        let mut acc = Accumulation::new(2, 1);
        let e_over_pi = Vec3::new(2.0, 3.0, 4.0);
        for albedo in [Vec3::new(0.2, 0.1, 0.0), Vec3::new(0.6, 0.3, 0.5)] {
            acc.frame_albedo = vec![albedo, Vec3::ZERO];
            acc.frame_irradiance = vec![e_over_pi, Vec3::ZERO];
            acc.frame_direct = vec![Vec3::ONE, Vec3::splat(0.5)];
            acc.add_frame(&camera, History::Accumulate);
        }
        // Mean albedo (0.4, 0.2, 0.25).
        let want = Vec3::new(0.4, 0.2, 0.25) * e_over_pi;
        assert!((acc.indirect(0) - want).abs().max_element() < 1e-6, "{} vs {want}", acc.indirect(0));
        assert_eq!(acc.indirect(1), Vec3::ZERO, "no surface, no field term");
        assert!((acc.pixels()[0] - (Vec3::ONE + want)).abs().max_element() < 1e-6);
        // A last sample off the surface (the sky past a silhouette) dilutes the
        // albedo and keeps the surface's irradiance.
        acc.frame_albedo = vec![Vec3::ZERO; 2];
        acc.frame_irradiance = vec![Vec3::ZERO; 2];
        acc.add_frame(&camera, History::Accumulate);
        let want = Vec3::new(0.8, 0.4, 0.5) / 3.0 * e_over_pi;
        assert!((acc.indirect(0) - want).abs().max_element() < 1e-6, "{} vs {want}", acc.indirect(0));
        // A changed scene restarts the means: the frame's own sample again.
        acc.frame_albedo = vec![Vec3::splat(0.8), Vec3::ZERO];
        acc.frame_irradiance = vec![e_over_pi * 2.0, Vec3::ZERO];
        acc.add_frame(&camera, History::Restart);
        assert!((acc.indirect(0) - Vec3::splat(0.8) * e_over_pi * 2.0).abs().max_element() < 1e-6);
    }

    const W: u32 = 8;
    /// The wall at z = −4 m: 1 m per pixel through a 90° camera 8 pixels wide.
    const WALL_Z_M: f32 = -4.0;

    /// An 8 × 8 camera at `x` metres on the x axis, looking down −z, 90° wide.
    fn camera_at(x: f32) -> CameraRays {
        let camera =
            Camera { position: Vec3::new(x, 0.0, 0.0), target: Vec3::new(x, 0.0, -1.0), up: Vec3::Y, fov_y_deg: 90.0 };
        CameraRays::new(&camera, W, W)
    }

    /// One frame through `camera` of the wall, whose direct term is `direct(world
    /// x)` at each pixel centre; `near` pixels see an occluder 1 m away instead.
    fn wall_frame(acc: &mut Accumulation, camera: &CameraRays, direct: impl Fn(f32) -> f32, near: &[usize]) {
        for p in 0..acc.len() {
            let (x, y) = ((p % W as usize) as f32 + 0.5, (p / W as usize) as f32 + 0.5);
            let dir = camera.ray_dir_world(x, y);
            let z_m = if near.contains(&p) { -1.0 } else { WALL_Z_M };
            acc.frame_position_m[p] = camera.origin_world + dir * (z_m / dir.z);
            acc.frame_normal[p] = Vec3::Z;
            acc.frame_direct[p] = Vec3::splat(direct((camera.origin_world + dir * (WALL_Z_M / dir.z)).x));
            acc.frame_albedo[p] = Vec3::splat(0.5);
            acc.frame_irradiance[p] = Vec3::ONE;
        }
    }

    fn unclamped(frames: u32) -> TemporalSettings {
        TemporalSettings { temporal_history_frames: frames, temporal_clip_sigma: 0.0 }
    }

    /// A camera moved by one pixel's footprint: each pixel's history is the
    /// last frame's value of the same wall point, one pixel over; the column
    /// that enters the view and a disoccluded pixel start from their own sample.
    #[test]
    fn a_moved_camera_reads_the_same_surface_point_from_the_last_frame() {
        let mut acc = Accumulation::new(W, W);
        let (a, b) = (camera_at(0.0), camera_at(1.0));
        // Pixel (5, 3) of the first frame sees an occluder, not the wall.
        let occluded = 3 * W as usize + 5;
        wall_frame(&mut acc, &a, |x| 10.0 + x, &[occluded]);
        acc.add_frame(&a, History::Accumulate);
        wall_frame(&mut acc, &b, |x| 11.0 + x, &[]);
        acc.add_frame(&b, History::Reproject { from: a, settings: unclamped(16) });
        for p in 0..acc.len() {
            let (x, y) = ((p % W as usize) as f32 + 0.5, (p / W as usize) as f32 + 0.5);
            let world_x = x + 1.0 - 4.0;
            let (got, new) = (acc.direct(p).x, 11.0 + world_x);
            // The last column saw nothing of this wall; (4, 3) saw the occluder's pixel.
            let want = if p % W as usize == W as usize - 1 || p == occluded - 1 { new } else { new - 0.5 };
            assert!((got - want).abs() < 1e-3, "pixel ({x}, {y}): {got} vs {want}");
            assert!((acc.indirect(p) - Vec3::splat(0.5)).abs().max_element() < 1e-5);
        }
    }

    /// The history never weighs more than `temporal_history_frames` − 1 frames,
    /// and the clamp pulls a stale history into the new frame's neighbourhood.
    #[test]
    fn the_history_is_capped_and_clamped() {
        let mut acc = Accumulation::new(W, W);
        let mut from = camera_at(0.0);
        wall_frame(&mut acc, &from, |_| 1.0, &[]);
        acc.add_frame(&from, History::Accumulate);
        // Twenty frames of a slow pan: the wall's value 1 throughout.
        for k in 1..=20 {
            let to = camera_at(k as f32 * 0.01);
            wall_frame(&mut acc, &to, |_| 1.0, &[]);
            acc.add_frame(&to, History::Reproject { from, settings: unclamped(4) });
            from = to;
        }
        let centre = 4 * W as usize + 4;
        assert!(acc.count[centre] <= 4.0 + 1e-9 && acc.count[centre] > 3.9, "{}", acc.count[centre]);
        // The wall turns to 3: unclamped, a quarter of it shows; clamped, all.
        let to = camera_at(0.22);
        wall_frame(&mut acc, &to, |_| 3.0, &[]);
        let mut clamped = acc.clone();
        acc.add_frame(&to, History::Reproject { from, settings: unclamped(4) });
        assert!((acc.direct(centre).x - 1.5).abs() < 1e-3, "{}", acc.direct(centre).x);
        let settings = TemporalSettings { temporal_history_frames: 4, temporal_clip_sigma: 1.0 };
        clamped.add_frame(&to, History::Reproject { from, settings });
        assert!((clamped.direct(centre).x - 3.0).abs() < 1e-4, "{}", clamped.direct(centre).x);
    }

    /// A pixel that sees the sky keeps the sky's history, and never a
    /// surface's: past a silhouette the history starts again.
    #[test]
    fn the_sky_reads_only_the_sky() {
        let mut acc = Accumulation::new(W, W);
        let (a, b) = (camera_at(0.0), camera_at(1.0));
        wall_frame(&mut acc, &a, |_| 1.0, &[]);
        // The left half of the first frame sees the sky (value 5).
        for p in (0..acc.len()).filter(|p| p % W as usize <= 3) {
            (acc.frame_normal[p], acc.frame_direct[p], acc.frame_albedo[p]) =
                (Vec3::ZERO, Vec3::splat(5.0), Vec3::ZERO);
        }
        acc.add_frame(&a, History::Accumulate);
        wall_frame(&mut acc, &b, |_| 1.0, &[]);
        for p in 0..acc.len() {
            (acc.frame_normal[p], acc.frame_direct[p], acc.frame_albedo[p]) =
                (Vec3::ZERO, Vec3::splat(7.0), Vec3::ZERO);
        }
        acc.add_frame(&b, History::Reproject { from: a, settings: unclamped(16) });
        for y in 0..W as usize {
            // Column x of b looks along column x of a (the sky is at infinity):
            // the sky's history on the left, none where a saw the wall.
            for x in 0..W as usize {
                let want = if x <= 3 { 6.0 } else { 7.0 };
                let got = acc.direct(y * W as usize + x).x;
                assert!((got - want).abs() < 1e-3, "({x}, {y}): {got} vs {want}");
            }
        }
    }

    /// The surface test: points of one floor pass however far apart along it
    /// (seen edge-on), a point 30 cm above it at 4 m does not, nor the far
    /// face of a thin slab.
    #[test]
    fn the_same_surface_is_its_tangent_plane_on_its_side() {
        let from = camera_at(0.0);
        let floor = |x: f32, z: f32| Surface { point_world: Vec3::new(x, -1.0, z), normal: Vec3::Y };
        let now = floor(0.0, -4.0);
        assert!(now.continues(&floor(0.3, -7.0), &from), "the same floor, 3 m further along");
        let above = Surface { point_world: Vec3::new(0.0, -0.7, -4.0), ..now };
        assert!(!now.continues(&above, &from), "30 cm above it");
        let underside = Surface { point_world: Vec3::new(0.0, -1.05, -4.0), normal: -Vec3::Y };
        assert!(!now.continues(&underside, &from), "the slab's underside");
    }

    /// Catmull-Rom's weights sum to one, pass a sample through unchanged, and
    /// reproduce a linear ramp exactly.
    #[test]
    fn catmull_rom_interpolates_a_ramp_exactly() {
        assert_eq!(catmull_rom(0.0), [0.0, 1.0, 0.0, 0.0]);
        for t in [0.1f32, 0.3, 0.5, 0.77, 0.99] {
            let w = catmull_rom(t);
            assert!((w.iter().sum::<f32>() - 1.0).abs() < 1e-6, "{t}: {w:?}");
            let ramp: f32 = w.iter().enumerate().map(|(i, k)| k * (i as f32 - 1.0)).sum();
            assert!((ramp - t).abs() < 1e-6, "{t}: {ramp}");
        }
    }

    /// A camera moved by 0.3 of a pixel's footprint over a wall whose direct
    /// term is a ramp: the history is the ramp at the pixel's point in the
    /// last frame, exactly, where all 4 × 4 taps lie in the image.
    #[test]
    fn a_fractional_move_reads_the_ramp_between_pixels() {
        let mut acc = Accumulation::new(W, W);
        let (a, b) = (camera_at(0.0), camera_at(0.3));
        wall_frame(&mut acc, &a, |x| 10.0 + x, &[]);
        acc.add_frame(&a, History::Accumulate);
        wall_frame(&mut acc, &b, |x| 11.0 + x, &[]);
        acc.add_frame(&b, History::Reproject { from: a, settings: unclamped(16) });
        for (x, y) in (1..=5).flat_map(|x| (0..W as usize - 1).map(move |y| (x, y))) {
            let world_x = x as f32 + 0.5 + 0.3 - 4.0;
            let got = acc.direct(y * W as usize + x).x;
            assert!((got - (10.5 + world_x)).abs() < 1e-3, "({x}, {y}): {got} vs {}", 10.5 + world_x);
        }
    }

    /// A jittered sample stands for its pixel's centre: the point the filter
    /// reprojects is where the centre ray meets the sample's tangent plane.
    #[test]
    fn a_jittered_sample_moves_to_the_centre_ray() {
        let camera = camera_at(0.0);
        let mut acc = Accumulation::new(W, W);
        let p = 2 * W as usize + 3;
        let jittered = camera.ray_dir_world(3.9, 2.1);
        acc.frame_position_m[p] = camera.origin_world + jittered * (WALL_Z_M / jittered.z);
        acc.frame_normal[p] = Vec3::Z;
        let point = acc.frame_points(&camera)[p].expect("a surface").point_world;
        let centre = camera.ray_dir_world(3.5, 2.5);
        assert!((point - camera.origin_world).normalize().dot(centre) > 1.0 - 1e-6, "{point}");
        assert!((point.z - WALL_Z_M).abs() < 1e-4, "on the wall: {point}");
        assert!(acc.frame_points(&camera)[0].is_none(), "no normal: the sky");
    }
}
