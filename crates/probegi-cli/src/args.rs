//! Command-line arguments: the contract scripts rely on (foundation issue, "CLI").

use std::path::PathBuf;

use clap::{Args, Parser, Subcommand, ValueEnum};
use glam::Vec3;

#[derive(Parser, Debug)]
#[command(
    name = "probegi",
    version,
    about = "Probe-based dynamic diffuse global illumination, with a path-traced reference and FLIP comparison.",
    long_about = None,
    after_help = format!(
        "Without a subcommand, renders the built-in Cornell box with DDGI (64 frames) to out/cornell-box.png.\n\
         PNG output is tone-mapped with {}; EXR output is linear radiance.",
        probegi_core::color::TONEMAP_NAME
    )
)]
pub struct Cli {
    #[command(subcommand)]
    pub command: Option<Command>,
}

#[derive(Subcommand, Debug)]
pub enum Command {
    /// Render frames with direct light and, with `--gi ddgi` or `--gi sh`, diffuse GI.
    Render(RenderArgs),
    /// Path-trace the unbiased reference image.
    Reference(ReferenceArgs),
    /// FLIP between a reference and a test image; prints `mean_flip: <value>`.
    Compare(CompareArgs),
    /// Ray-casting throughput on probe-like rays; with `--gi ddgi` the field-update
    /// sweep; with `--gi sh` SH probe update against DDGI at the same probe count.
    /// Prints JSON on stdout.
    Bench(BenchArgs),
    /// Convergence lag after a step change (a light switched on; an occluder put
    /// into the doorway) in the door room, against hysteresis with the fast-
    /// convergence heuristics on and off: a PNG plot, a curves PNG and a CSV.
    Lag(LagArgs),
    /// The field live in a window with a fly camera, panels (GI, field
    /// settings, views, lights, scene clock, reference, stats) and the
    /// path-traced reference one key away; `--headless` runs a script
    /// without a window.
    #[command(after_help = probegi_view::viewer_panels::keys_help())]
    View(ViewArgs),
}

#[derive(Args, Debug, Clone)]
pub struct ViewArgs {
    #[command(flatten)]
    pub scene: SceneArgs,
    /// Global illumination method.
    #[arg(long, value_enum, default_value_t = GiArg::Ddgi)]
    pub gi: GiArg,
    #[command(flatten)]
    pub volume: VolumeArgs,
    /// Area-light shadow samples per pixel per frame (stratified).
    #[arg(long, default_value_t = 16)]
    pub area_samples: u32,
    /// `wgpu` (the default here: the field and the camera frame on the GPU) or `cpu`.
    #[arg(long, value_enum, default_value_t = crate::gpu_backend::Backend::Wgpu)]
    pub backend: crate::gpu_backend::Backend,
    /// Run without a window: the input script drives the camera.
    #[arg(long)]
    pub headless: bool,
    /// Timed key and mouse events (format: `probegi_view::input_script`, docs/CLI.md).
    #[arg(long)]
    pub input_script: Option<PathBuf>,
    /// Frames to run before exiting.
    #[arg(long)]
    pub exit_after_frames: Option<u32>,
    /// Write the last frame here: .png (tone-mapped) or .exr (linear radiance).
    #[arg(long)]
    pub screenshot: Option<PathBuf>,
    /// The fly camera's starting speed in metres per second (default: a tenth
    /// of the scene's bounding-box diagonal).
    #[arg(long)]
    pub fly_speed: Option<f32>,
    /// Print frame-time percentiles as JSON on stdout: with --headless the
    /// frames' mean and percentiles after the warm-up, the host's share of
    /// them (less the time blocked on the device), the field update's and the
    /// camera frame's, and the device's per-pass times where it has
    /// timestamps; in a scripted window run the UI's frame interval beside the
    /// frame worker's frame time.
    #[arg(long)]
    pub bench: bool,
    /// Write every frame into this folder as frame-NNNN.png (tone-mapped).
    #[arg(long)]
    pub sequence: Option<PathBuf>,
    /// The view the window starts with: full, direct, indirect, albedo,
    /// normals, probes, irradiance-atlas, distance-atlas, light-visibility.
    #[arg(long)]
    pub view: Option<String>,
    /// Samples per pixel of the reference an input script's `f5` asks for
    /// (the window's panel sets its own).
    #[arg(long, default_value_t = 64)]
    pub reference_spp: u32,
}

#[derive(Args, Debug)]
pub struct LagArgs {
    /// The plot of frames-to-converge against hysteresis; the per-frame FLIP curves
    /// go beside it as NAME-curves.png (light on) and NAME-occluder-curves.png, and the numbers as NAME.csv.
    #[arg(long, default_value = "out/convergence-lag.png")]
    pub out: std::path::PathBuf,
    /// Image size (square) of the compared frames.
    #[arg(long, default_value_t = 48)]
    pub size: u32,
    /// Hysteresis values to try (comma-separated).
    #[arg(long, value_delimiter = ',', default_value = "0.8,0.9,0.95,0.97,0.99")]
    pub hysteresis: Vec<f32>,
    /// Frames before the step (the field converges to the old state).
    #[arg(long, default_value_t = 100)]
    pub frames_before: u32,
    /// Frames after the step that are compared.
    #[arg(long, default_value_t = 300)]
    pub frames_after: u32,
    /// Converged means: FLIP against the new state's converged image stays below
    /// this. The default sits above the noise floor of 64 rays per probe at 48²
    /// (FLIP 0.05–0.06 between two converged runs of the same state).
    #[arg(long, default_value_t = 0.1)]
    pub flip_threshold: f32,
    /// Probe rays per probe per frame.
    #[arg(long, default_value_t = 64)]
    pub rays_per_probe: u32,
    /// Frames the after-step state is held to make the converged target image.
    #[arg(long, default_value_t = 400)]
    pub target_frames: u32,
    /// Volume settings for the stepped runs (not the target), KEY=VALUE as
    /// `render --set` takes them, e.g. `ray_budget=3456`.
    #[arg(long = "set", value_name = "KEY=VALUE")]
    pub set: Vec<String>,
    #[arg(long, default_value_t = 0)]
    pub seed: u64,
}

/// A comma-separated `X,Y,Z` triple of finite numbers.
pub fn parse_vec3(s: &str) -> Result<Vec3, String> {
    let parts: Vec<&str> = s.split(',').map(str::trim).collect();
    if parts.len() != 3 {
        return Err(format!("expected X,Y,Z (three comma-separated numbers), got `{s}`"));
    }
    let mut v = [0.0f32; 3];
    for (o, p) in v.iter_mut().zip(&parts) {
        *o = p.parse().map_err(|_| format!("`{p}` is not a number"))?;
        if !o.is_finite() {
            return Err(format!("`{p}` is not finite"));
        }
    }
    Ok(Vec3::from(v))
}

/// A comma-separated `NX,NY,NZ` triple of positive integers.
pub fn parse_uvec3(s: &str) -> Result<[u32; 3], String> {
    let parts: Vec<&str> = s.split(',').map(str::trim).collect();
    if parts.len() != 3 {
        return Err(format!("expected NX,NY,NZ (three comma-separated integers), got `{s}`"));
    }
    let mut v = [0u32; 3];
    for (o, p) in v.iter_mut().zip(&parts) {
        *o = p.parse().map_err(|_| format!("`{p}` is not a positive integer"))?;
        if *o == 0 {
            return Err("probe counts must be at least 1".into());
        }
    }
    Ok(v)
}

#[derive(Args, Debug, Clone)]
pub struct SceneArgs {
    /// Scene: a .obj, .gltf, .glb or .toml path, or `builtin:NAME` (cornell-box, furnace-box,
    /// color-bleed, door-room, flood-room, sponza-sun).
    #[arg(long, default_value = "builtin:cornell-box")]
    pub scene: String,
    /// Image width in pixels.
    #[arg(long, default_value_t = 512)]
    pub width: u32,
    /// Image height in pixels.
    #[arg(long, default_value_t = 512)]
    pub height: u32,
    /// Camera position X,Y,Z in metres (default: the scene's camera).
    #[arg(long, value_parser = parse_vec3, allow_hyphen_values = true)]
    pub camera_pos: Option<Vec3>,
    /// Camera target X,Y,Z in metres.
    #[arg(long, value_parser = parse_vec3, allow_hyphen_values = true)]
    pub camera_target: Option<Vec3>,
    /// Camera up hint X,Y,Z (default: the scene's, else +Y). A view along the
    /// hint falls back to the world axis least aligned with it (looking down a
    /// y-up world the image's up is −Z).
    #[arg(long, value_parser = parse_vec3, allow_hyphen_values = true)]
    pub camera_up: Option<Vec3>,
    /// Vertical field of view in degrees.
    #[arg(long)]
    pub fov_y: Option<f32>,
    /// Constant sky radiance R,G,B for rays that leave the scene (default: the scene's, else black).
    #[arg(long, value_parser = parse_vec3, allow_hyphen_values = true, conflicts_with = "sky_map")]
    pub sky: Option<Vec3>,
    /// An equirectangular HDR sky (.exr or Radiance .hdr) lighting the scene
    /// instead of a constant one; Mitsuba's `envmap` convention (docs/SCENES.md).
    #[arg(long)]
    pub sky_map: Option<std::path::PathBuf>,
    /// Radiance scale of the sky map (default: the scene's, else 1).
    #[arg(long, allow_hyphen_values = true)]
    pub sky_intensity: Option<f32>,
    /// Rotation of the sky map about the up axis in degrees (+90: its centre
    /// turns from +Z to +X; default: the scene's, else 0).
    #[arg(long, allow_hyphen_values = true)]
    pub sky_rotation_deg: Option<f32>,
    /// Random seed; the same seed gives the same image on any number of threads.
    #[arg(long, default_value_t = 0)]
    pub seed: u64,
}

#[derive(ValueEnum, Clone, Copy, Debug, PartialEq, Eq)]
pub enum GiArg {
    /// Direct light only.
    None,
    /// Dynamic diffuse global illumination: one probe volume over the scene, the
    /// scene file's `[[volumes]]`, or with --cascades camera-centred cascades.
    Ddgi,
    /// Screen-space GI with progressive spherical-harmonics probes (seed 001):
    /// camera-centred cascades updated from the lit frame, no probe rays.
    Sh,
}

/// DDGI volume options shared by `render` and `bench`.
#[derive(Args, Debug, Clone, Default)]
pub struct VolumeArgs {
    /// Probe grid NX,NY,NZ fitted to the scene bounds (overrides the scene file's
    /// `[volume]`; refused with `[[volumes]]`); with --cascades, every cascade's counts.
    #[arg(long, value_parser = parse_uvec3)]
    pub probes: Option<[u32; 3]>,
    /// Camera-centred DDGI cascades (seed 003 §6.2): N nested tracking windows, each
    /// --cascade-ratio times the spacing of the one inside it, each of --probes
    /// counts (else the scene file's `[volume]`'s, else 16×8×16). The innermost spacing
    /// is `--set probe_spacing_m=S` (a scalar or X,Y,Z), else fitted so that the
    /// coarsest cascade is the scene's fitted grid (probes at cell centres). Every
    /// window stays half a cell inside the scene bounds where it is smaller than
    /// them (`volume_tracking_bounds_m`), so the coarsest covers the scene from
    /// any camera. Without it, one volume as before
    /// (or the scene file's `[[volumes]]`).
    #[arg(long)]
    pub cascades: Option<u32>,
    /// Spacing ratio between neighbouring cascades.
    #[arg(long, default_value_t = probegi_core::ddgi_settings::DEFAULT_CASCADE_SPACING_RATIO)]
    pub cascade_ratio: f32,
    /// Rays per probe per frame.
    #[arg(long)]
    pub rays_per_probe: Option<u32>,
    /// Override any volume setting by its TOML name, e.g. `--set hysteresis=0.9`
    /// (repeatable). Under `--gi sh` the keys are the `[sh]` settings, e.g. `--set sh_occlusion=true`.
    /// Scene settings apply under every `--gi`: `normal_maps=false`, `alpha_cutouts=false`.
    #[arg(long = "set", value_name = "KEY=VALUE")]
    pub set: Vec<String>,
}

#[derive(Args, Debug)]
pub struct RenderArgs {
    #[command(flatten)]
    pub scene: SceneArgs,
    /// Global illumination method.
    #[arg(long, value_enum, default_value_t = GiArg::None)]
    pub gi: GiArg,
    /// Frames to run; a static scene's direct light (and diffuse albedo) accumulates
    /// over them, the DDGI field updates once per frame and the final indirect light
    /// is the last frame's irradiance × the accumulated albedo.
    #[arg(long, default_value_t = 1)]
    pub frames: u32,
    #[command(flatten)]
    pub volume: VolumeArgs,
    /// Write the DDGI irradiance and distance atlases as images into this folder.
    #[arg(long)]
    pub dump_atlases: Option<PathBuf>,
    /// Draw each DDGI probe as a small sphere shaded by its irradiance.
    #[arg(long)]
    pub show_probes: bool,
    /// Write the shadowing field's light-visibility image (seed 003 ch. 5; needs
    /// `--set shadow_field=true`): per pixel the fraction of the punctual
    /// lights' direct light the field lets through, 0..1 (.exr or .png).
    #[arg(long)]
    pub ao: Option<PathBuf>,
    /// Area-light shadow samples per pixel per frame (stratified).
    #[arg(long, default_value_t = 16)]
    pub area_samples: u32,
    /// A moving camera's temporal filter: each pixel averages at most this many
    /// frames, reprojected from the last frame's view where they saw the same
    /// surface; 0 or 1 turns it off (every moving frame its own sample).
    #[arg(long, default_value_t = probegi_frame::frame_loop::TemporalSettings::default().temporal_history_frames)]
    pub temporal_frames: u32,
    /// The temporal filter clamps the direct term's history to the new frame's
    /// 3×3 neighbourhood mean ± this many standard deviations; 0: no clamp.
    #[arg(long, default_value_t = probegi_frame::frame_loop::TemporalSettings::default().temporal_clip_sigma)]
    pub temporal_clip_sigma: f32,
    /// Output image: .png (tone-mapped sRGB) or .exr (linear radiance).
    #[arg(long, default_value = "out/render.png")]
    pub out: PathBuf,
    /// Write per-pass timings and ray counts as JSON.
    #[arg(long)]
    pub stats: Option<PathBuf>,
    /// Write every frame into this folder as frame-NNNN.png (what the frame would
    /// show if it were the last: accumulated direct light + that frame's irradiance × the accumulated albedo).
    #[arg(long)]
    pub sequence: Option<PathBuf>,
    /// With --sequence, also write frame-NNNN.exr (linear radiance).
    #[arg(long, requires = "sequence")]
    pub sequence_exr: bool,
    /// Write an animated, looping GIF preview of every frame (tone-mapped).
    #[arg(long)]
    pub gif: Option<PathBuf>,
    /// Playback rate of the --gif preview.
    #[arg(long, default_value_t = 25.0, requires = "gif")]
    pub gif_fps: f32,
    /// Accept frames that come out all black although the scene has light
    /// sources and the camera sees diffuse surfaces (by default such a render is an
    /// error: it is almost always a bug, e.g. a degenerate camera).
    #[arg(long)]
    pub allow_black_frames: bool,
    /// `cpu`, or `wgpu`: the DDGI field's update (ray generation, trace, shade,
    /// blend, border, relocation, classification) and the camera frame run as
    /// WGSL compute shaders on a GPU (or Mesa's lavapipe), the atlases kept
    /// there; moving objects and instanced meshes through the CPU's top-level
    /// BVH, placed on the device each frame. With --show-probes the camera
    /// frame is the CPU's, and the atlases come back every frame for it.
    #[arg(long, value_enum, default_value_t = crate::gpu_backend::Backend::Cpu)]
    pub backend: crate::gpu_backend::Backend,
}

#[derive(Args, Debug)]
pub struct ReferenceArgs {
    #[command(flatten)]
    pub scene: SceneArgs,
    /// Samples per pixel.
    #[arg(long, default_value_t = 256)]
    pub spp: u32,
    /// Maximum path length in surface interactions (Russian roulette ends most paths sooner).
    #[arg(long, default_value_t = 64)]
    pub max_depth: u32,
    /// Render the scene as it is at this frame of its animation (light, object and camera keyframes).
    #[arg(long, default_value_t = 0.0)]
    pub frame: f32,
    /// Output image: .exr (linear radiance, recommended) or .png (tone-mapped).
    #[arg(long)]
    pub out: PathBuf,
    /// Scene settings, e.g. `--set normal_maps=false`, `--set alpha_cutouts=false`.
    #[arg(long = "set", value_name = "KEY=VALUE")]
    pub set: Vec<String>,
    /// Also write the punctual lights' exact light-visibility image (one shadow
    /// ray per light per pixel), to compare with `render --ao` (.exr or .png).
    #[arg(long)]
    pub ao: Option<PathBuf>,
}

#[derive(Args, Debug)]
pub struct CompareArgs {
    /// Reference image (.exr or .png).
    pub reference: PathBuf,
    /// Test image (.exr or .png).
    pub test: PathBuf,
    /// Write a contact sheet: reference | test | FLIP error (magma).
    #[arg(long)]
    pub out: Option<PathBuf>,
}

#[derive(Args, Debug)]
pub struct BenchArgs {
    /// Scene: a path or `builtin:NAME`.
    #[arg(long, default_value = "builtin:cornell-box")]
    pub scene: String,
    /// Probe grid NX,NY,NZ spread over the scene bounds; rays start at the probes.
    #[arg(long, value_parser = parse_uvec3, default_value = "16,8,16")]
    pub probes: [u32; 3],
    /// Rays per probe, uniformly distributed directions.
    #[arg(long, default_value_t = 256)]
    pub rays_per_probe: u32,
    /// Timed repetitions; the best is reported.
    #[arg(long, default_value_t = 5)]
    pub repeat: u32,
    /// Primitive AABB padding relative to the scene extent (0 = off, to measure it).
    #[arg(long, default_value_t = 1e-5)]
    pub aabb_pad_rel: f32,
    /// Random seed for ray directions.
    #[arg(long, default_value_t = 0)]
    pub seed: u64,
    /// Add this many orbiting boxes and report the instancing costs: static build,
    /// per-frame pose + TLAS rebuild, a full rebuild for comparison, and throughput.
    #[arg(long, default_value_t = 0)]
    pub moving_objects: u32,
    /// `ddgi`: sweep rays per probe (32–256) × probe grids and time the field update;
    /// `sh`: per grid, the SH probe update (without and with occlusion) against the
    /// DDGI field update at the same probe count (`--rays`, default 256) on the scene's camera.
    #[arg(long, value_enum, default_value_t = GiArg::None)]
    pub gi: GiArg,
    /// DDGI sweep: `wgpu` runs the field update on the GPU (through the seam,
    /// the atlases kept there) and times the GPU passes alone (ray generation,
    /// trace, shade, blend, border) with timestamp queries; `cpu` runs everything
    /// on the CPU.
    #[arg(long, value_enum, default_value_t = crate::gpu_backend::Backend::Cpu)]
    pub backend: crate::gpu_backend::Backend,
    /// DDGI sweep: frames timed per configuration (after one warm-up frame).
    #[arg(long, default_value_t = 2)]
    pub frames: u32,
    /// DDGI sweep: grids to run, e.g. `--grids 16,8,16 --grids 32,16,32`.
    #[arg(long, value_parser = parse_uvec3)]
    pub grids: Vec<[u32; 3]>,
    /// DDGI sweep: rays per probe to run (default 32, 64, 128, 256).
    #[arg(long)]
    pub rays: Vec<u32>,
    /// DDGI sweep: override a volume setting for every configuration (repeatable),
    /// e.g. `--set probe_states=all-active`. Scene settings apply to every bench:
    /// `--set alpha_cutouts=false`, `--set normal_maps=false`.
    #[arg(long = "set", value_name = "KEY=VALUE")]
    pub set: Vec<String>,
    /// Ray bench (`--gi none`): also write the scene's triangles, the bench rays and
    /// probegi's closest-hit distances to this folder as raw little-endian f32
    /// (`triangles.f32`, `rays.f32`, `closest_t.f32`) with `meta.json`, for
    /// `scripts/embree-compare.py` to trace the same rays with Embree.
    #[arg(long, value_name = "DIR")]
    pub dump_rays: Option<PathBuf>,
}
