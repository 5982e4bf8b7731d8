//! From the command line to the settings a render runs with: the `--set`
//! assignments split into scene keys and probe keys, the GI method with its
//! DDGI volumes (`--cascades`, the scene file's `[[volumes]]` or `[volume]`) or
//! SH probes, the keyframed camera path, and the `RenderSettings` of the frame
//! loop. Each layer applies in order over the one before: the papers'
//! defaults, the scene file, the options, then each `--set`.

use std::sync::Arc;

use anyhow::{Context, Result, bail};
use probegi_core::camera::CameraRays;
use probegi_core::ddgi_settings::{DdgiFieldSetSettings, DdgiVolumeSettings, ProbeStatesMode};
use probegi_core::sh_settings::ShProbeSettings;
use probegi_cpu::DirectSettings;
use probegi_cpu::probe_trace::ddgi_volume_bytes;
use probegi_field::{ProbeBatchTracer, ProbeTracerHandle};
use probegi_frame::frame_loop::{GiMethod, RenderSettings, TemporalSettings};
use probegi_scene::Scene;

use crate::args::{GiArg, RenderArgs, SceneArgs, VolumeArgs};
use crate::gpu_backend::WgpuProbeTracer;
use crate::memory::check_memory;

/// Host bytes per image pixel that a render or a view holds: the G-buffer
/// texel and the frame buffers (about 160), and the camera image's sums with
/// a moving camera's reprojection (`frame_loop::accumulation`: about 160
/// kept, 140 while it runs).
pub const IMAGE_BYTES_PER_PIXEL: u64 = 460;

/// The frame loop's settings of `render`: the image, frames and seed of the
/// arguments, the GI method `gi`, the camera path, and `gpu` (`--backend wgpu`)
/// as the probe tracer.
pub fn render_settings(
    args: &RenderArgs,
    scene: &Scene,
    gi: GiMethod,
    gpu: Option<Arc<WgpuProbeTracer>>,
) -> RenderSettings {
    let camera_path = camera_path(scene, &args.scene, args.frames);
    RenderSettings {
        width: args.scene.width,
        height: args.scene.height,
        frames: args.frames,
        seed: args.scene.seed,
        gi,
        direct: DirectSettings { direct_area_samples: args.area_samples, ..Default::default() },
        show_probes: args.show_probes,
        camera_path,
        probe_tracer: gpu.map(|g| ProbeTracerHandle(g as Arc<dyn ProbeBatchTracer>)),
        temporal: TemporalSettings {
            temporal_history_frames: args.temporal_frames,
            temporal_clip_sigma: args.temporal_clip_sigma,
        },
        // `render` takes each frame's statistics as it ends (the viewer sets its own lag).
        device_readback_lag_frames: 0,
    }
}

/// The GI method of `render --gi`, after checking that the probe options
/// (`--probes`, `--rays-per-probe`, probe `--set` keys, `--cascades`,
/// `--dump-atlases`, `--show-probes`) fit it.
pub fn gi_method(scene: &Scene, args: &RenderArgs) -> Result<GiMethod> {
    let v = &args.volume;
    if args.gi == GiArg::None
        && (v.probes.is_some() || v.rays_per_probe.is_some() || probe_settings(&v.set).next().is_some())
    {
        bail!("--probes, --rays-per-probe and --set configure probes: they need --gi ddgi or --gi sh");
    }
    if args.gi != GiArg::Ddgi && v.cascades.is_some() {
        bail!("--cascades configures DDGI volumes: it needs --gi ddgi");
    }
    let gi = match args.gi {
        GiArg::None => GiMethod::None,
        GiArg::Ddgi => ddgi_method(scene, &args.volume)?,
        GiArg::Sh => GiMethod::Sh(Box::new(sh_settings(scene, &args.volume)?)),
    };
    if !matches!(gi, GiMethod::Ddgi(_) | GiMethod::DdgiSet(_)) && (args.dump_atlases.is_some() || args.show_probes) {
        bail!("--dump-atlases and --show-probes need --gi ddgi");
    }
    let shadow_field = match &gi {
        GiMethod::Ddgi(s) => s.shadow_field,
        GiMethod::DdgiSet(set) => set.volumes.iter().any(|v| v.shadow_field),
        _ => false,
    };
    if args.ao.is_some() && !shadow_field {
        bail!("--ao writes the shadowing field's visibility: it needs --gi ddgi --set shadow_field=true");
    }
    Ok(gi)
}

/// The scene-level `--set` keys (`normal_maps`, `alpha_cutouts`) among `set`.
pub fn apply_scene_settings(scene: &mut Scene, set: &[String]) -> Result<()> {
    for a in set.iter().filter(|a| probegi_scene::scene_file::is_scene_setting(a)) {
        probegi_scene::scene_file::apply_scene_setting(scene, a)
            .map_err(anyhow::Error::msg)
            .with_context(|| format!("--set {a}"))?;
    }
    Ok(())
}

/// The `--set` assignments that configure probes (not the scene).
pub fn probe_settings(set: &[String]) -> impl Iterator<Item = &String> {
    set.iter().filter(|a| !probegi_scene::scene_file::is_scene_setting(a))
}

/// The DDGI of `render --gi ddgi`: `--cascades`, else the scene file's
/// `[[volumes]]`, else one volume (the file's `[volume]` or the defaults).
pub fn ddgi_method(scene: &Scene, args: &VolumeArgs) -> Result<GiMethod> {
    if let Some(n) = args.cascades {
        if n == 0 || n > 16 {
            bail!("--cascades {n}: must be in 1..=16");
        }
        let r = args.cascade_ratio;
        if !(1.0..=16.0).contains(&r) {
            bail!("--cascade-ratio {r}: must be in [1, 16]");
        }
        // Camera-centred cascades update the probes the camera's pixels read
        // (the screen scheme, Timberdoodle PGI's request countdowns) unless a
        // scene file names states other than jcgt or `--set` names any: it renders what
        // all-active probes render at a quarter of their rays, where seed
        // 003's jcgt states cost 0.016, and its cost follows the view, not
        // the world (docs/RESULTS.md, "Denser is better").
        // Each cascade's counts: --probes, else the file's [volume], else 16×8×16.
        let mut file = scene.volume.clone().unwrap_or_else(|| DdgiVolumeSettings {
            probe_counts: probegi_core::ddgi_settings::DEFAULT_CASCADE_PROBE_COUNTS,
            ..Default::default()
        });
        if file.probe_states == ProbeStatesMode::Jcgt {
            file.probe_states = ProbeStatesMode::Screen;
        }
        let base = apply_volume_args(file, args)?;
        let bounds = scene.bounds().unwrap_or((glam::Vec3::splat(-1.0), glam::Vec3::ONE));
        // Every window stays inside the scene bounds (where it is smaller than
        // them), so no cascade spends probes outside the scene; the coarsest
        // is the fitted grid of the bounds, half a cell off the outermost
        // walls. (A window that followed the camera freely needed twice the
        // bounds to cover Sponza from one end of the atrium, and left its far
        // arches to 4.6 m probes: HDR-FLIP 0.120 at 300 frames. Probes on the
        // bounds' faces instead: 0.104; at the cell centres 0.089.
        // docs/RESULTS.md, "Denser is better".)
        let set = DdgiFieldSetSettings::cascades_over_bounds(n, &base, bounds, r);
        set.validate().map_err(|(i, f, why)| anyhow::anyhow!("cascade {i}: volume setting {f}: {why}"))?;
        check_memory(set.volumes.iter().map(ddgi_volume_bytes).sum(), "the DDGI cascades")?;
        return Ok(GiMethod::DdgiSet(Box::new(set)));
    }
    if !scene.volumes.is_empty() {
        if args.probes.is_some() {
            bail!(
                "--probes would refit every one of the scene's [[volumes]] to the scene bounds; change their \
                 probe_counts in the file, or use --cascades"
            );
        }
        let mut volumes = Vec::new();
        for v in &scene.volumes {
            volumes.push(apply_volume_args(v.clone(), args)?);
        }
        let set = DdgiFieldSetSettings { volumes, blending: probegi_core::ddgi_volume_blend::VolumeBlending::Density };
        check_memory(set.volumes.iter().map(ddgi_volume_bytes).sum(), "the DDGI volumes")?;
        return Ok(GiMethod::DdgiSet(Box::new(set)));
    }
    Ok(GiMethod::Ddgi(Box::new(volume_settings(scene, args)?)))
}

/// The camera of every frame when the scene's camera is keyframed and no
/// `--camera-*` option fixes it; empty otherwise.
fn camera_path(scene: &Scene, args: &SceneArgs, frames: u32) -> Vec<CameraRays> {
    let fixed = args.camera_pos.is_some() || args.camera_target.is_some() || args.fov_y.is_some();
    if fixed || !scene.has_camera_animation() {
        return Vec::new();
    }
    scene.camera_path(frames).iter().map(|c| CameraRays::new(c, args.width, args.height)).collect()
}

/// `--probes`, `--rays-per-probe` and each `--set`, in order, over `s`.
fn apply_volume_args(mut s: DdgiVolumeSettings, args: &VolumeArgs) -> Result<DdgiVolumeSettings> {
    if let Some(p) = args.probes {
        s.probe_counts = glam::UVec3::from(p);
        s.probe_origin_m = None;
        s.probe_spacing_m = None;
    }
    if let Some(r) = args.rays_per_probe {
        s.probe_rays_per_probe = r;
    }
    for a in probe_settings(&args.set) {
        s = probegi_scene::scene_file::apply_volume_override(&s, a)
            .map_err(anyhow::Error::msg)
            .with_context(|| format!("--set {a}"))?;
    }
    s.validate().map_err(|(field, why)| anyhow::anyhow!("volume setting {field}: {why}"))?;
    check_memory(ddgi_volume_bytes(&s), "the DDGI volume")?;
    Ok(s)
}

/// Volume settings: the papers' defaults, then the scene file's `[volume]`, then
/// `--probes`, `--rays-per-probe` and each `--set` in order.
pub fn volume_settings(scene: &Scene, args: &VolumeArgs) -> Result<DdgiVolumeSettings> {
    apply_volume_args(scene.volume.clone().unwrap_or_default(), args)
}

/// SH probe settings: the paper's defaults, then the scene file's `[sh]`, then each
/// `--set`. `--probes` sets the probe counts of every cascade.
pub fn sh_settings(scene: &Scene, args: &VolumeArgs) -> Result<ShProbeSettings> {
    let mut s = scene.sh_probes.clone().unwrap_or_default();
    if let Some(p) = args.probes {
        s.sh_cascade_probe_counts = glam::UVec3::from(p);
    }
    if args.rays_per_probe.is_some() {
        bail!("--rays-per-probe is a DDGI setting; SH probes trace no rays (see --set sh_screen_samples)");
    }
    for a in probe_settings(&args.set) {
        s = probegi_scene::scene_file::apply_sh_override(&s, a)
            .map_err(anyhow::Error::msg)
            .with_context(|| format!("--set {a}"))?;
    }
    s.validate().map_err(|(field, why)| anyhow::anyhow!("SH setting {field}: {why}"))?;
    Ok(s)
}
