//! A DDGI volume on the CPU: the probe grid, its two atlases, and the per-frame
//! field update of seed 000 §3 / seed 003 §4.2–4.5 as four passes plus the border
//! refresh, each in its own module:
//! `probe_ray_gen` → `probe_trace` → `probe_shade` → blend (`probegi_core::probe_blend`)
//! → border (`probegi_core::probe_border`).
//!
//! A probe's first update replaces its (empty) history, i.e. blends with
//! hysteresis 0; every later update uses `probe_hysteresis`. Buffers are sized
//! once, so a frame allocates only the per-frame blend-weight tables.

use std::collections::BTreeMap;
use std::time::Instant;

use glam::{UVec3, Vec2, Vec3};
use probegi_core::ddgi_query::DdgiFieldView;
use probegi_core::ddgi_settings::DdgiVolumeSettings;
use probegi_core::probe_atlas::ProbeAtlas;
use probegi_core::probe_blend::{blend_distance_tile, blend_irradiance_tile};
use probegi_core::probe_border::update_tile_border;
use probegi_core::probe_grid::ProbeGrid;
use probegi_scene::{RayTracer, Scene};
use rayon::prelude::*;

use crate::direct::DirectLighting;
use crate::probe_ray_gen::generate_probe_rays;
use crate::probe_shade::{ProbeShadeInputs, shade_probe_rays};
use crate::probe_trace::{Surfel, trace_probe_rays};

pub struct DdgiVolume {
    pub grid: ProbeGrid,
    pub settings: DdgiVolumeSettings,
    /// Encoded mean radiance per texel (see `probe_blend`).
    pub irradiance: ProbeAtlas<Vec3>,
    /// (mean distance, mean squared distance) per texel.
    pub distance: ProbeAtlas<Vec2>,
    pub probe_positions: Vec<Vec3>,
    pub frames_updated: u32,
    surfels: Vec<Surfel>,
    ray_radiance: Vec<Vec3>,
    ray_distance: Vec<f32>,
}

/// Bytes a volume with these settings holds (atlases and per-ray buffers).
pub fn ddgi_volume_bytes(settings: &DdgiVolumeSettings) -> u64 {
    let probes = settings.probe_count();
    let rays = probes * settings.probe_rays_per_probe as u64;
    let tile = |n: u32| ((n + 2) * (n + 2)) as u64;
    rays * (std::mem::size_of::<Surfel>() + std::mem::size_of::<Vec3>() + 4) as u64
        + probes * (tile(settings.probe_irradiance_texels) * 12 + tile(settings.probe_distance_texels) * 8 + 12)
}

impl DdgiVolume {
    /// A volume over `scene_bounds` (used when the settings give no origin/spacing).
    pub fn new(settings: DdgiVolumeSettings, scene_bounds: (Vec3, Vec3)) -> Self {
        let counts: UVec3 = settings.probe_counts;
        let fitted = ProbeGrid::fit_to_bounds(scene_bounds.0, scene_bounds.1, counts);
        let grid = ProbeGrid {
            origin_m: settings.probe_origin_m.unwrap_or(fitted.origin_m),
            probe_counts: counts,
            spacing_m: settings.probe_spacing_m.unwrap_or(fitted.spacing_m),
        };
        let probes = grid.probe_count();
        let rays = probes * settings.probe_rays_per_probe as usize;
        let probe_positions = (0..probes).map(|i| grid.probe_position(grid.probe_coords(i))).collect();
        Self {
            irradiance: ProbeAtlas::new(probes, settings.probe_irradiance_texels),
            distance: ProbeAtlas::new(probes, settings.probe_distance_texels),
            grid,
            settings,
            probe_positions,
            frames_updated: 0,
            surfels: vec![Surfel::default(); rays],
            ray_radiance: vec![Vec3::ZERO; rays],
            ray_distance: vec![0.0; rays],
        }
    }

    pub fn view(&self) -> DdgiFieldView<'_> {
        DdgiFieldView {
            grid: &self.grid,
            settings: &self.settings,
            irradiance: &self.irradiance,
            distance: &self.distance,
        }
    }

    pub fn rays_per_frame(&self) -> u64 {
        self.surfels.len() as u64
    }

    /// The distance limit of the blend: RTXGI's 1.5 × the cell diagonal, or the
    /// trace limit if shorter.
    pub fn distance_clamp_m(&self) -> f32 {
        (1.5 * self.grid.spacing_m.length()).min(self.settings.probe_max_ray_distance_m)
    }

    /// One field update. Adds per-pass milliseconds to `pass_ms` and returns the
    /// rays traced (probe rays plus shading shadow rays).
    pub fn update(
        &mut self,
        scene: &Scene,
        tracer: &dyn RayTracer,
        direct: &DirectLighting<'_>,
        seed: u64,
        frame: u32,
        pass_ms: &mut BTreeMap<&'static str, f64>,
    ) -> u64 {
        let mut time =
            |name: &'static str, t: Instant| *pass_ms.entry(name).or_default() += t.elapsed().as_secs_f64() * 1e3;

        let t = Instant::now();
        let rays = generate_probe_rays(&self.settings, seed, frame);
        time("ray_gen", t);

        let t = Instant::now();
        let mut traced = trace_probe_rays(
            scene,
            tracer,
            &self.probe_positions,
            &rays.dirs,
            self.settings.probe_max_ray_distance_m,
            &mut self.surfels,
        );
        time("trace", t);

        let t = Instant::now();
        let inputs = ProbeShadeInputs {
            scene,
            direct,
            field: DdgiFieldView {
                grid: &self.grid,
                settings: &self.settings,
                irradiance: &self.irradiance,
                distance: &self.distance,
            },
            dirs: &rays.dirs,
            surfels: &self.surfels,
            seed,
            frame,
        };
        traced += shade_probe_rays(&inputs, &mut self.ray_radiance, &mut self.ray_distance);
        time("shade", t);

        let t = Instant::now();
        let hysteresis = if self.frames_updated == 0 { 0.0 } else { self.settings.probe_hysteresis };
        let n = rays.dirs.len();
        let (irr_n, dist_n) = (self.irradiance.interior, self.distance.interior);
        let gamma = self.settings.probe_irradiance_gamma;
        let clamp = self.distance_clamp_m();
        let irr_len = self.irradiance.tile_len();
        let dist_len = self.distance.tile_len();
        self.irradiance.texels.par_chunks_mut(irr_len).zip(self.ray_radiance.par_chunks(n)).for_each(
            |(tile, radiance)| {
                blend_irradiance_tile(tile, irr_n, &rays.irradiance_weights, radiance, hysteresis, gamma);
            },
        );
        self.distance.texels.par_chunks_mut(dist_len).zip(self.ray_distance.par_chunks(n)).for_each(
            |(tile, distance)| {
                blend_distance_tile(tile, dist_n, &rays.distance_weights, distance, hysteresis, clamp);
            },
        );
        time("blend", t);

        let t = Instant::now();
        self.irradiance.texels.par_chunks_mut(irr_len).for_each(|tile| update_tile_border(tile, irr_n));
        self.distance.texels.par_chunks_mut(dist_len).for_each(|tile| update_tile_border(tile, dist_n));
        time("border", t);

        self.frames_updated += 1;
        #[cfg(debug_assertions)]
        self.validate();
        traced
    }

    /// Atlas invariants: every texel finite and non-negative, every border equal to
    /// its source texel.
    pub fn validate(&self) {
        assert!(self.irradiance.texels.iter().all(|t| t.is_finite() && t.min_element() >= 0.0), "irradiance atlas");
        assert!(self.distance.texels.iter().all(|t| t.is_finite() && t.min_element() >= 0.0), "distance atlas");
        for p in 0..self.grid.probe_count() {
            check_borders(self.irradiance.tile(p), self.irradiance.interior);
            check_borders(self.distance.tile(p), self.distance.interior);
        }
    }
}

fn check_borders<T: PartialEq + Copy + std::fmt::Debug>(tile: &[T], interior: u32) {
    let s = (interior + 2) as usize;
    for ((dx, dy), (sx, sy)) in probegi_core::probe_border::border_sources(interior) {
        assert_eq!(tile[dy as usize * s + dx as usize], tile[sy as usize * s + sx as usize], "border texel");
    }
}
