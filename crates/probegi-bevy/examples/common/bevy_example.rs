//! What the Bevy examples share: their arguments, the app in a window (with a
//! fly camera) or headless (a number of frames rendered into a PNG, read back
//! from Bevy's device), and the camera.

use std::path::PathBuf;
use std::sync::{Arc, Mutex};

use bevy::app::PluginsState;
use bevy::camera::{Exposure, RenderTarget};
use bevy::core_pipeline::tonemapping::Tonemapping;
use bevy::prelude::*;
use bevy::render::gpu_readback::{Readback, ReadbackComplete};
use bevy::render::render_resource::{TextureFormat, TextureUsages};
use probegi_bevy::ProbegiVolume;

/// The examples' arguments.
pub struct Args {
    /// Frames to render headless before the picture is taken.
    pub frames: u32,
    /// Where the headless picture goes; `None`: a window (with the `window`
    /// feature), else `<example>.png`. A `.exr` is the frame's exposed
    /// radiance (radiance × the camera's exposure, as Bevy draws light):
    /// an HDR camera without tone mapping.
    pub out: Option<PathBuf>,
    /// No DDGI volume: Bevy's own lighting, to compare with.
    pub no_field: bool,
    /// Draw the probes (`ProbegiProbeView`; P toggles it in a window).
    pub probes: bool,
    /// The headless picture's size (its width a multiple of 64: read-back
    /// rows are whole 256-byte blocks), and the window's.
    pub size: UVec2,
    /// In a window (the `window` feature): after `frames` frames, the
    /// window's picture written here as a PNG, and the app ends.
    pub screenshot: Option<PathBuf>,
    /// Headless: each frame's wall time, reported as JSON on stdout after
    /// the picture (the GPU timing of `scripts/bevy-gpu-timing.sh`).
    pub bench: bool,
}

impl Args {
    /// `--frames N`, `--out PATH`, `--no-field`, `--probes`, `--size WxH`,
    /// `--screenshot PATH`, `--bench`.
    pub fn parse(mut args: impl Iterator<Item = String>) -> Result<Self, String> {
        let size = UVec2::new(640, 480);
        let mut out =
            Self { frames: 60, out: None, no_field: false, probes: false, size, screenshot: None, bench: false };
        while let Some(a) = args.next() {
            let mut value = || args.next().ok_or_else(|| format!("{a} needs a value"));
            match a.as_str() {
                "--frames" => {
                    let v = value()?;
                    out.frames = v.parse().ok().filter(|n| *n > 0).ok_or(format!("--frames {v}: not a count"))?;
                }
                "--out" => out.out = Some(PathBuf::from(value()?)),
                "--screenshot" => out.screenshot = Some(PathBuf::from(value()?)),
                "--no-field" => out.no_field = true,
                "--bench" => out.bench = true,
                "--probes" => out.probes = true,
                "--size" => {
                    let v = value()?;
                    let parsed =
                        v.split_once('x').and_then(|(w, h)| Some(UVec2::new(w.parse().ok()?, h.parse().ok()?)));
                    out.size = parsed
                        .filter(|s| s.x > 0 && s.y > 0 && s.x % 64 == 0 && s.x <= 4096 && s.y <= 4096)
                        .ok_or(format!("--size {v}: WxH, W a multiple of 64, both at most 4096"))?;
                }
                other => {
                    return Err(format!(
                        "unknown argument {other:?} (--frames N, --out PATH, --no-field, --probes, --size WxH, \
                         --screenshot PATH, --bench)"
                    ));
                }
            }
        }
        match (&out.screenshot, &out.out) {
            (Some(_), Some(_)) => Err("--screenshot is the window's picture, --out the headless one: not both".into()),
            (_, _) if out.bench && (!out.headless() || out.frames < 2) => {
                Err("--bench times a headless run (--out PATH) of at least 2 frames".into())
            }
            (Some(_), None) if !cfg!(feature = "window") => {
                Err("--screenshot needs a window: build the example with --features window".into())
            }
            _ => Ok(out),
        }
    }

    /// Whether the example runs headless.
    pub fn headless(&self) -> bool {
        self.out.is_some() || !cfg!(feature = "window")
    }

    /// Whether the headless picture is radiance (`--out *.exr`).
    pub fn radiance(&self) -> bool {
        self.out.as_ref().and_then(|p| p.extension()).is_some_and(|e| e.eq_ignore_ascii_case("exr"))
    }
}

/// The headless picture's target image, and whether it holds radiance
/// (`Rgba16Float` drawn by an HDR camera without tone mapping) or sRGB RGBA8.
#[derive(Resource, Clone)]
pub struct Target(pub Handle<Image>, pub bool);

/// Bevy's default plugins: with a window, or (headless) without one and with
/// the [`Target`] image made.
pub fn add_default_plugins(app: &mut App, args: &Args) {
    let plugins = DefaultPlugins.build();
    #[cfg(feature = "window")]
    let plugins = if args.headless() {
        plugins.disable::<bevy::winit::WinitPlugin>().set(WindowPlugin {
            primary_window: None,
            exit_condition: bevy::window::ExitCondition::DontExit,
            ..default()
        })
    } else {
        let resolution = (args.size.x, args.size.y).into();
        plugins.set(WindowPlugin {
            primary_window: Some(Window { title: "probegi-bevy".into(), resolution, ..default() }),
            ..default()
        })
    };
    app.add_plugins(plugins);
    app.insert_resource(probegi_bevy::ProbegiProbeView { enabled: args.probes, ..default() });
    if args.headless() {
        let format = if args.radiance() { TextureFormat::Rgba16Float } else { TextureFormat::Rgba8UnormSrgb };
        let mut target = Image::new_target_texture(args.size.x, args.size.y, format, None);
        target.texture_descriptor.usage |= TextureUsages::COPY_SRC;
        let handle = app.world_mut().resource_mut::<Assets<Image>>().add(target);
        app.insert_resource(Target(handle, args.radiance()));
    } else {
        #[cfg(feature = "window")]
        app.add_systems(Update, (fly_camera, toggle_probes));
        #[cfg(feature = "window")]
        if let Some(path) = args.screenshot.clone() {
            let frames = args.frames;
            app.add_systems(Update, move |mut commands: Commands, mut seen: Local<u32>| {
                *seen += 1;
                if *seen == frames {
                    commands
                        .spawn(bevy::render::view::screenshot::Screenshot::primary_window())
                        .observe(window_picture_to(path.clone()));
                }
            });
        }
    }
}

/// Writes the window's picture to `path` as a PNG and ends the app
/// (`AppExit::Success`, or an error with the reason on stderr).
#[cfg(feature = "window")]
fn window_picture_to(
    path: PathBuf,
) -> impl FnMut(On<bevy::render::view::screenshot::ScreenshotCaptured>, MessageWriter<AppExit>) {
    move |shot, mut exit| {
        let written = window_rgb(&shot.image).and_then(|(w, h, rgb)| {
            probegi_image::io::write_png(&path, w, h, rgb).map_err(|e| format!("{}: {e}", path.display()))
        });
        match written {
            Ok(()) => {
                eprintln!("wrote {} (the window after its frames)", path.display());
                exit.write(AppExit::Success);
            }
            Err(e) => {
                eprintln!("error: the window's picture: {e}");
                exit.write(AppExit::error());
            }
        }
    }
}

/// A window picture's size and sRGB RGB8 pixels: the swap chain's RGBA8 or
/// BGRA8, either encoding (the bytes are display values either way).
#[cfg(feature = "window")]
fn window_rgb(image: &Image) -> Result<(u32, u32, Vec<u8>), String> {
    let (w, h) = (image.width(), image.height());
    let data = image.data.as_deref().ok_or("the picture has no pixels on the host")?;
    let bgra = match image.texture_descriptor.format {
        TextureFormat::Rgba8UnormSrgb | TextureFormat::Rgba8Unorm => false,
        TextureFormat::Bgra8UnormSrgb | TextureFormat::Bgra8Unorm => true,
        other => return Err(format!("the window's format {other:?} is not RGBA8 or BGRA8")),
    };
    if data.len() != (w * h * 4) as usize {
        return Err(format!("{} bytes for {w}×{h} pixels", data.len()));
    }
    let rgb = data.chunks_exact(4).flat_map(|p| if bgra { [p[2], p[1], p[0]] } else { [p[0], p[1], p[2]] }).collect();
    Ok((w, h, rgb))
}

/// The camera at `at`: into the [`Target`] headless, else a fly camera.
/// ACES tone mapping (it needs no lookup table), none for a radiance target.
pub fn spawn_camera(commands: &mut Commands, at: Transform, exposure: Exposure, target: Option<&Target>) -> Entity {
    let mut camera = commands.spawn((Camera3d::default(), Tonemapping::AcesFitted, exposure, at));
    match target {
        // Shadow levels of detail from this camera (it renders to no window).
        Some(t) => camera.insert((RenderTarget::Image(t.0.clone().into()), bevy::camera::ShadowLodOrigin)),
        None => camera.insert(FlyCamera),
    };
    if target.is_some_and(|t| t.1) {
        camera.insert((bevy::camera::Hdr, Tonemapping::None));
    }
    camera.id()
}

/// Despawns every volume (`--no-field`): the materials draw Bevy's lighting.
pub fn remove_volumes(mut commands: Commands, volumes: Query<Entity, With<ProbegiVolume>>) {
    for v in &volumes {
        commands.entity(v).despawn();
    }
}

/// Runs the app: headless, `args.frames` frames and the last one written as a
/// PNG, its sRGB RGBA8 pixels returned; else in its window until it closes.
pub fn run(mut app: App, args: &Args) -> Result<Option<Vec<u8>>, String> {
    if !args.headless() {
        app.run();
        return Ok(None);
    }
    while app.plugins_state() == PluginsState::Adding {
        bevy::tasks::tick_global_task_pools_on_main_thread();
    }
    app.finish();
    app.cleanup();
    let mut frame_ms = Vec::with_capacity(args.frames as usize);
    for _ in 1..args.frames {
        let t = std::time::Instant::now();
        app.update();
        frame_ms.push(t.elapsed().as_secs_f64() * 1e3);
    }
    let target = app.world().resource::<Target>().0.clone();
    let rgba = last_frame(&mut app, &target)?;
    let out = args.out.clone().unwrap_or_else(|| PathBuf::from(format!("{}.png", example_name())));
    if args.radiance() {
        write_radiance(&out, args.size, &rgba)?;
    } else {
        let rgb: Vec<u8> = rgba.chunks_exact(4).flat_map(|p| [p[0], p[1], p[2]]).collect();
        if rgb.len() != (args.size.x * args.size.y * 3) as usize {
            return Err(format!("read back {} bytes for {}×{} pixels", rgba.len(), args.size.x, args.size.y));
        }
        probegi_image::io::write_png(&out, args.size.x, args.size.y, rgb).map_err(|e| e.to_string())?;
    }
    if let Some(e) = app
        .sub_app(bevy::render::RenderApp)
        .world()
        .resource::<probegi_bevy::field_on_bevy_device::ProbegiRenderField>()
        .error
        .clone()
    {
        return Err(format!("the field: {e}"));
    }
    eprintln!("wrote {} ({} frames)", out.display(), args.frames);
    if args.bench {
        println!("{}", bench_json(args, &frame_ms));
    }
    Ok(Some(rgba))
}

/// `--bench`'s report: the frames' wall milliseconds (`App::update`: with
/// Bevy's pipelined rendering, a frame's main-world systems while the last
/// one renders) after the first quarter (pipeline compiles, the field's
/// start-up), as mean, median and 95th percentile.
fn bench_json(args: &Args, frame_ms: &[f64]) -> String {
    let mut timed = frame_ms[frame_ms.len() / 4..].to_vec();
    timed.sort_by(f64::total_cmp);
    let at = |q: f64| timed.get(((timed.len() as f64 - 1.0) * q).round() as usize).copied().unwrap_or(f64::NAN);
    let mean = timed.iter().sum::<f64>() / timed.len().max(1) as f64;
    format!(
        "{{\"example\": \"{}\", \"field\": {}, \"size\": [{}, {}], \"frames_timed\": {}, \
         \"frame_ms\": {{\"mean\": {mean:.3}, \"median\": {:.3}, \"p95\": {:.3}}}}}",
        example_name(),
        !args.no_field,
        args.size.x,
        args.size.y,
        timed.len(),
        at(0.5),
        at(0.95)
    )
}

/// Writes an HDR camera's `Rgba16Float` frame `texels` to the EXR `out`:
/// exposed radiance, radiance × the camera's exposure as Bevy draws light:
/// values in display range, as an HDR-FLIP comparison and a contact sheet
/// read them, which compare with `probegi reference` of the same view lit ×
/// that exposure (`scenes/sponza-bevy-example.toml`).
fn write_radiance(out: &std::path::Path, size: UVec2, texels: &[u8]) -> Result<(), String> {
    if texels.len() != (size.x * size.y * 8) as usize {
        return Err(format!("read back {} bytes for {}×{} half-float pixels", texels.len(), size.x, size.y));
    }
    let half = |b: &[u8]| probegi_bevy::environment_sky::half_to_f32(u16::from_le_bytes([b[0], b[1]]));
    let pixels = texels
        .chunks_exact(8)
        .map(|p| {
            let c = glam::Vec3::new(half(&p[0..2]), half(&p[2..4]), half(&p[4..6]));
            if c.is_finite() { c.max(glam::Vec3::ZERO) } else { glam::Vec3::ZERO }
        })
        .collect();
    let image = probegi_core::image::Image { width: size.x, height: size.y, pixels };
    probegi_image::io::write_image(out, &image).map_err(|e| e.to_string())
}

/// The running example's name (its binary's), for the default picture.
fn example_name() -> String {
    std::env::args()
        .next()
        .and_then(|a| std::path::Path::new(&a).file_stem().map(|s| s.to_string_lossy().into_owned()))
        .unwrap_or_else(|| "bevy_example".into())
}

/// Renders one more frame and reads `target` back (sRGB RGBA8 rows).
fn last_frame(app: &mut App, target: &Handle<Image>) -> Result<Vec<u8>, String> {
    let pixels: Arc<Mutex<Option<Vec<u8>>>> = Arc::default();
    let sink = pixels.clone();
    let reader = app
        .world_mut()
        .spawn(Readback::texture(target.clone()))
        .observe(move |done: On<ReadbackComplete>| {
            if let Ok(mut p) = sink.lock() {
                *p = Some(done.data.clone());
            }
        })
        .id();
    app.update();
    app.world_mut().entity_mut(reader).remove::<Readback>();
    for _ in 0..10 {
        if let Some(p) = pixels.lock().map_err(|_| "the read-back panicked")?.take() {
            return Ok(p);
        }
        app.update();
    }
    Err("the frame was not read back in 10 frames".into())
}

/// The window's camera: WASD to move, Q/E down and up, the right mouse
/// button held to look.
#[derive(Component)]
pub struct FlyCamera;

/// P shows or hides the probes.
#[cfg(feature = "window")]
fn toggle_probes(keys: Res<ButtonInput<KeyCode>>, mut view: ResMut<probegi_bevy::ProbegiProbeView>) {
    if keys.just_pressed(KeyCode::KeyP) {
        view.enabled = !view.enabled;
    }
}

#[cfg(feature = "window")]
fn fly_camera(
    time: Res<Time>,
    keys: Res<ButtonInput<KeyCode>>,
    buttons: Res<ButtonInput<MouseButton>>,
    motion: Res<bevy::input::mouse::AccumulatedMouseMotion>,
    mut cameras: Query<&mut Transform, With<FlyCamera>>,
) {
    const SPEED_M_PER_S: f32 = 2.0;
    const RADIANS_PER_PIXEL: f32 = 0.003;
    for mut t in &mut cameras {
        if buttons.pressed(MouseButton::Right) {
            let (yaw, pitch, _) = t.rotation.to_euler(EulerRot::YXZ);
            let yaw = yaw - motion.delta.x * RADIANS_PER_PIXEL;
            let pitch = (pitch - motion.delta.y * RADIANS_PER_PIXEL).clamp(-1.5, 1.5);
            t.rotation = Quat::from_euler(EulerRot::YXZ, yaw, pitch, 0.0);
        }
        let mut step = Vec3::ZERO;
        for (key, dir) in [
            (KeyCode::KeyW, *t.forward()),
            (KeyCode::KeyS, -*t.forward()),
            (KeyCode::KeyD, *t.right()),
            (KeyCode::KeyA, -*t.right()),
            (KeyCode::KeyE, Vec3::Y),
            (KeyCode::KeyQ, -Vec3::Y),
        ] {
            if keys.pressed(key) {
                step += dir;
            }
        }
        t.translation += step.normalize_or_zero() * SPEED_M_PER_S * time.delta_secs();
    }
}
