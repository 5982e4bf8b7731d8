//! The viewer's debug views of a frame (RTXGI's test harness shows the same
//! set): the full frame, its direct and indirect terms, the surfaces' diffuse
//! albedo and shading normals, the probes drawn as spheres shaded by their
//! irradiance, a volume's irradiance and distance atlases, and the punctual
//! lights' visibility (the shadowing field's, seed 003 ch. 5, or exact).
//!
//! Full, direct and indirect are the stepper's own terms, from whichever
//! backend rendered them. Albedo, normals and the probe spheres are drawn on a
//! G-buffer traced on the CPU at the frame's size (primary rays only), and the
//! atlases are read on the host (a device-resident field is read back first).

use probegi_core::camera::CameraRays;
use probegi_core::image::Image;
use probegi_cpu::gbuffer::trace_gbuffer;
use probegi_cpu::light_visibility::light_visibility_image;
use probegi_cpu::shading::ShadingContext;
use probegi_field::atlas_view::{distance_grey_image, irradiance_image};
use probegi_scene::RayTracer;

use crate::view_session::ViewSession;

/// What the viewer shows.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq, serde::Serialize, serde::Deserialize)]
#[serde(rename_all = "kebab-case")]
pub enum ViewMode {
    /// The frame as `probegi render` composes it.
    #[default]
    Full,
    /// The direct term.
    Direct,
    /// The indirect term (the field's, or the SH probes').
    Indirect,
    /// Diffuse albedo of the surface each pixel sees.
    Albedo,
    /// Shading normals, mapped from [−1, 1] to [0, 1].
    Normals,
    /// The full frame with the probes drawn as spheres shaded by their irradiance.
    Probes,
    /// A volume's irradiance atlas (decoded radiance).
    IrradianceAtlas,
    /// A volume's distance atlas (mean distance over the clamp, grey).
    DistanceAtlas,
    /// The punctual lights' visibility at each pixel's surface: the shadowing
    /// field's (seed 003 ch. 5) where the field keeps one, else exact shadow
    /// rays (`probegi_cpu::light_visibility`, as `render --ao` writes it).
    LightVisibility,
}

impl ViewMode {
    /// Every view, in the panel's order.
    pub const ALL: [ViewMode; 9] = [
        ViewMode::Full,
        ViewMode::Direct,
        ViewMode::Indirect,
        ViewMode::Albedo,
        ViewMode::Normals,
        ViewMode::Probes,
        ViewMode::IrradianceAtlas,
        ViewMode::DistanceAtlas,
        ViewMode::LightVisibility,
    ];

    /// The view's name in the panel.
    pub fn label(self) -> &'static str {
        match self {
            ViewMode::Full => "full",
            ViewMode::Direct => "direct",
            ViewMode::Indirect => "indirect",
            ViewMode::Albedo => "albedo",
            ViewMode::Normals => "normals",
            ViewMode::Probes => "probes",
            ViewMode::IrradianceAtlas => "irradiance atlas",
            ViewMode::DistanceAtlas => "distance atlas",
            ViewMode::LightVisibility => "light visibility",
        }
    }

    /// The view after this one (`V`), skipping those that need a field when
    /// there is none.
    pub fn next(self, has_field: bool) -> ViewMode {
        let i = ViewMode::ALL.iter().position(|m| *m == self).unwrap_or(0);
        (1..=ViewMode::ALL.len())
            .map(|k| ViewMode::ALL[(i + k) % ViewMode::ALL.len()])
            .find(|m| has_field || !m.needs_field())
            .unwrap_or(ViewMode::Full)
    }

    /// The view named `name` (its label, spaces or dashes).
    pub fn from_name(name: &str) -> Option<ViewMode> {
        let n = name.replace('-', " ");
        ViewMode::ALL.into_iter().find(|m| m.label() == n)
    }

    /// Whether the view reads the DDGI field (absent without `--gi ddgi`).
    pub fn needs_field(self) -> bool {
        matches!(self, ViewMode::Probes | ViewMode::IrradianceAtlas | ViewMode::DistanceAtlas)
    }
}

/// The HDR image of `mode` for the frame `full` that `session` just
/// rendered; `tracer` traces the loaded scene (moving objects are placed at
/// the frame's clock). Views that need a field show the full frame without one.
pub fn view_image(
    mode: ViewMode,
    full: &Image,
    session: &mut ViewSession<'_>,
    tracer: &dyn RayTracer,
    volume: usize,
) -> Result<Image, String> {
    match mode {
        ViewMode::Full => return Ok(full.clone()),
        ViewMode::Direct => return Ok(session.stepper().layers()?.direct),
        ViewMode::Indirect => return Ok(session.stepper().layers()?.indirect),
        _ => {}
    }
    let has_field = session.stepper_mut().sync_field_to_host()?.is_some();
    let st = session.stepper();
    // The scene as the frame saw it: posed at its clock, lights switched.
    let scene = st.frame_scene();
    let at_frame = tracer.at_frame(scene, session.last_scene_frame() as f32);
    let tracer: &dyn RayTracer = at_frame.as_deref().unwrap_or(tracer);
    let camera = CameraRays::new(&session.last_camera(), full.width, full.height);
    let gbuffer_image = |pixel: &dyn Fn(&probegi_scene::SurfacePoint, glam::Vec3) -> glam::Vec3| {
        let (g, _) = trace_gbuffer(scene, tracer, &camera, full.width, full.height, 0, 0);
        let pixels =
            g.texels.iter().map(|t| t.surface.as_ref().map_or(glam::Vec3::ZERO, |sp| pixel(sp, t.view_dir_world)));
        Image { width: full.width, height: full.height, pixels: pixels.collect() }
    };
    let set = st.field().filter(|_| has_field);
    match (mode, set) {
        (ViewMode::Albedo, _) => Ok(gbuffer_image(&|sp, v| ShadingContext::new(scene, sp, -v).bsdf.diffuse_albedo())),
        (ViewMode::Normals, _) => Ok(gbuffer_image(&|sp, _| sp.shading_normal * 0.5 + 0.5)),
        (ViewMode::LightVisibility, set) => {
            let field = set.filter(|s| s.has_shadow_field());
            Ok(light_visibility_image(scene, tracer, &camera, full.width, full.height, field))
        }
        (_, None) => Ok(full.clone()),
        (ViewMode::IrradianceAtlas, Some(set)) => {
            Ok(irradiance_image(&set.volumes()[volume.min(set.volumes().len() - 1)]))
        }
        (ViewMode::DistanceAtlas, Some(set)) => {
            Ok(distance_grey_image(&set.volumes()[volume.min(set.volumes().len() - 1)]))
        }
        (_, Some(set)) => {
            let (g, _) = trace_gbuffer(scene, tracer, &camera, full.width, full.height, 0, 0);
            let mut pixels = full.pixels.clone();
            for v in set.volumes() {
                probegi_cpu::probe_vis::draw_probes(v, &camera, &g, &mut pixels);
            }
            Ok(Image { width: full.width, height: full.height, pixels })
        }
    }
}

/// `image` tone-mapped (the CLI's fixed operator) as RGBA8.
pub fn to_rgba8(image: &Image) -> Vec<u8> {
    image
        .pixels
        .iter()
        .flat_map(|p| {
            let [r, g, b] = probegi_core::color::tonemap_rgb8(*p);
            [r, g, b, 255]
        })
        .collect()
}
