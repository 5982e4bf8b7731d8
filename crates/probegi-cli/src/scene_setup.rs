//! The scene and camera that `render` and `reference` start from: the image
//! size checked against memory, the scene loaded with its scene-level `--set`
//! keys, `--sky` and the `--camera-*` options applied, and moving geometry
//! checked against the coordinate bound for every frame the command poses.

use anyhow::{Context, Result, bail};
use probegi_core::camera::Camera;
use probegi_scene::{Scene, load_scene};

use crate::args::SceneArgs;
use crate::memory::check_memory;
use crate::render_settings::apply_scene_settings;

/// Loads the scene and resolves the camera and sky the arguments ask for.
pub fn prepare(args: &SceneArgs, set: &[String], bytes_per_pixel: u64) -> Result<(Scene, Camera)> {
    if args.width == 0 || args.height == 0 {
        bail!("--width and --height must be at least 1 (got {}×{})", args.width, args.height);
    }
    if args.width > 65_536 || args.height > 65_536 {
        bail!("--width and --height must be at most 65536 (got {}×{})", args.width, args.height);
    }
    check_memory(args.width as u64 * args.height as u64 * bytes_per_pixel, "the image buffers")?;
    let mut scene = load_scene(&args.scene).with_context(|| format!("loading scene {}", args.scene))?;
    for w in &scene.warnings {
        eprintln!("warning: {w}");
    }
    apply_scene_settings(&mut scene, set)?;
    if let Some(sky) = args.sky {
        if sky.min_element() < 0.0 {
            bail!("--sky {sky} must be non-negative");
        }
        scene.sky_radiance = sky;
        scene.sky_map = None;
    }
    apply_sky_map(&mut scene, args)?;
    let mut camera = scene.default_camera();
    if let Some(p) = args.camera_pos {
        camera.position = p;
    }
    if let Some(t) = args.camera_target {
        camera.target = t;
    }
    if let Some(u) = args.camera_up {
        camera.up = u;
    }
    if let Some(f) = args.fov_y {
        camera.fov_y_deg = f;
    }
    camera.validate().map_err(anyhow::Error::msg).with_context(|| {
        format!(
            "invalid camera for scene {} (position {}, target {}, up {}); --camera-pos, --camera-target, \
             --camera-up and --fov-y set it",
            args.scene, camera.position, camera.target, camera.up
        )
    })?;
    Ok((scene, camera))
}

/// Moving geometry must stay inside the coordinate bound of loaded geometry
/// at every frame up to `last_frame` (`Scene::check_posed_bounds`).
pub fn check_posed_bounds(scene: &Scene, last_frame: f32) -> Result<()> {
    scene.check_posed_bounds(last_frame).map_err(|e| anyhow::anyhow!("scene {}: {e}", scene.name))
}

/// `--sky-map`, `--sky-intensity` and `--sky-rotation-deg`: a map from the
/// command line replaces the scene's sky; the other two adjust whichever map
/// the scene then has.
fn apply_sky_map(scene: &mut Scene, args: &SceneArgs) -> Result<()> {
    if let Some(path) = &args.sky_map {
        let map = probegi_scene::EnvironmentMap::load(path).map_err(|e| anyhow::anyhow!("--sky-map: {e}"))?;
        scene.sky_map = Some(probegi_scene::SkyMap::new(std::sync::Arc::new(map)));
    }
    let adjusts = args.sky_intensity.is_some() || args.sky_rotation_deg.is_some();
    let Some(map) = scene.sky_map.as_mut() else {
        if adjusts {
            bail!("--sky-intensity and --sky-rotation-deg need a sky map (--sky-map, or [sky_map] in the scene file)");
        }
        return Ok(());
    };
    if let Some(i) = args.sky_intensity {
        if !i.is_finite() || i < 0.0 {
            bail!("--sky-intensity {i} must be finite and non-negative");
        }
        map.intensity = i;
    }
    if let Some(r) = args.sky_rotation_deg {
        if !r.is_finite() {
            bail!("--sky-rotation-deg {r} must be finite");
        }
        map.rotation_deg = r;
    }
    Ok(())
}
