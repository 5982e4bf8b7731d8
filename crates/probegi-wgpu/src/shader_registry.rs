//! The one owner of the crate's WGSL: which files each pass is built from, in
//! which order, the constants prelude they all start with, and the bind-group
//! convention they share. Every pipeline is made from a [`PassShader`] through
//! `GpuContext::compute_pipelines`; nothing else reads `src/shaders/`.
//!
//! **Composition** is plain concatenation (WGSL declarations may come in any
//! order, so the order only keeps a reader's view: helpers before the pass):
//!
//! | pass                    | files after the prelude                                         |
//! |-------------------------|-----------------------------------------------------------------|
//! | [`TRACE_RAYS`]          | `bvh.wgsl`, `trace_rays.wgsl`                                   |
//! | [`PROBE_RAY_GEN`]       | `probe_ray_gen.wgsl`                                            |
//! | [`PROBE_SHADE`]         | `bvh.wgsl`, `ddgi_query.wgsl`, `scene.wgsl`, `shadow_lighting.wgsl`, `probe_shade.wgsl` |
//! | [`PROBE_BLEND`]         | `probe_border.wgsl`, `probe_blend.wgsl`                         |
//! | [`PROBE_CHANGE`]        | `probe_change.wgsl`                                             |
//! | [`PROBE_SEEDING`]       | `ddgi_query.wgsl`, `probe_seeding.wgsl`                         |
//! | [`PROBE_RELOCATION`]    | `probe_relocation.wgsl`                                         |
//! | [`PROBE_CLASSIFICATION`]| `bvh.wgsl`, `scene.wgsl`, `probe_classification.wgsl`           |
//! | [`PROBE_USAGE`]         | `probe_usage.wgsl`                                              |
//! | [`CAMERA_FRAME`]        | `bvh.wgsl`, `ddgi_query.wgsl`, `scene.wgsl`, `shadow_lighting.wgsl`, `camera_frame.wgsl` |
//! | [`SHADOW_FIELD`]        | `bvh.wgsl`, `scene.wgsl`, `probe_border.wgsl`, `shadow_field.wgsl` |
//! | [`FIELD_QUERY`]         | `ddgi_query.wgsl`, `field_query.wgsl`                           |
//! | [`DEVICE_FRAME`]        | `device_frame.wgsl`                                             |
//! | [`SKY_FROM_CUBEMAP`]    | `sky_from_cubemap.wgsl`                                         |
//!
//! The one substitution: `ddgi_query.wgsl` names its group `DDGI_GROUP`, which
//! [`compose`] fills with [`FIELD_GROUP`] and `ddgi_query::query_wgsl` with
//! the group an engine chooses.
//!
//! **The prelude** ([`constants_prelude`]) is generated from the Rust `const`s
//! the shaders share with the CPU (the query's weight floors, the relocation's
//! backface fraction and step, the blend's backface distance rule, the BVH's
//! instance flags), each printed so that it parses back to the same bits; so a
//! constant cannot drift between the two languages (the unit tests parse every
//! composed pass with naga and compare).
//!
//! **Bind groups**, the same numbers in every pass that binds them:
//! - [`PASS_GROUP`] (0): the pass's own uniform block and buffers;
//! - [`BVH_GROUP`] (1): `bvh.wgsl`'s [`BVH_STORAGE_BUFFERS`] buffers (`GpuBvh`);
//! - [`FIELD_GROUP`] (2): `ddgi_query.wgsl`'s [`FIELD_STORAGE_BUFFERS`] (`GpuDdgiField`);
//! - [`SCENE_GROUP`] (3): `scene.wgsl`'s [`SCENE_STORAGE_BUFFERS`] (`GpuScene`).

use probegi_core::{ddgi_query, probe_blend, probe_relocation};

/// One WGSL file of `src/shaders/`.
#[derive(Clone, Copy, Debug)]
pub(crate) struct WgslFile {
    pub(crate) name: &'static str,
    pub(crate) source: &'static str,
}

macro_rules! wgsl_file {
    ($name:literal) => {
        WgslFile { name: $name, source: include_str!(concat!("shaders/", $name)) }
    };
}

/// The CWBVH traversal (group [`BVH_GROUP`]).
const BVH: WgslFile = wgsl_file!("bvh.wgsl");
/// The field query (group [`FIELD_GROUP`], through the `DDGI_GROUP` placeholder).
const DDGI_QUERY: WgslFile = wgsl_file!("ddgi_query.wgsl");
/// Surfaces, materials and lights (group [`SCENE_GROUP`]).
const SCENE: WgslFile = wgsl_file!("scene.wgsl");
/// Punctual lights through the shadowing field (after the query and the scene).
const SHADOW_LIGHTING: WgslFile = wgsl_file!("shadow_lighting.wgsl");
/// Tile guard borders (no bindings).
const PROBE_BORDER: WgslFile = wgsl_file!("probe_border.wgsl");

/// A pass's shader module: its label and its files in order, after the prelude.
#[derive(Debug)]
pub(crate) struct PassShader {
    pub(crate) label: &'static str,
    pub(crate) files: &'static [WgslFile],
}

/// `bvh_trace::GpuRayTrace`.
pub(crate) const TRACE_RAYS: PassShader =
    PassShader { label: "trace_rays.wgsl", files: &[BVH, wgsl_file!("trace_rays.wgsl")] };
/// `probe_ray_gen::GpuProbeRayGen`.
pub(crate) const PROBE_RAY_GEN: PassShader =
    PassShader { label: "probe_ray_gen.wgsl", files: &[wgsl_file!("probe_ray_gen.wgsl")] };
/// `probe_shade::GpuProbeShade`.
pub(crate) const PROBE_SHADE: PassShader = PassShader {
    label: "probe_shade.wgsl",
    files: &[BVH, DDGI_QUERY, SCENE, SHADOW_LIGHTING, wgsl_file!("probe_shade.wgsl")],
};
/// `probe_blend::GpuProbeBlend`.
pub(crate) const PROBE_BLEND: PassShader =
    PassShader { label: "probe_blend.wgsl", files: &[PROBE_BORDER, wgsl_file!("probe_blend.wgsl")] };
/// `probe_change::GpuProbeChange`.
pub(crate) const PROBE_CHANGE: PassShader =
    PassShader { label: "probe_change.wgsl", files: &[wgsl_file!("probe_change.wgsl")] };
/// `probe_seeding::GpuProbeSeeding`.
pub(crate) const PROBE_SEEDING: PassShader =
    PassShader { label: "probe_seeding.wgsl", files: &[DDGI_QUERY, wgsl_file!("probe_seeding.wgsl")] };
/// `probe_relocation::GpuProbeRelocation`.
pub(crate) const PROBE_RELOCATION: PassShader =
    PassShader { label: "probe_relocation.wgsl", files: &[wgsl_file!("probe_relocation.wgsl")] };
/// `probe_classification::GpuProbeClassification`.
pub(crate) const PROBE_CLASSIFICATION: PassShader =
    PassShader { label: "probe_classification.wgsl", files: &[BVH, SCENE, wgsl_file!("probe_classification.wgsl")] };
/// `probe_usage::GpuProbeUsage`.
pub(crate) const PROBE_USAGE: PassShader =
    PassShader { label: "probe_usage.wgsl", files: &[wgsl_file!("probe_usage.wgsl")] };
/// `camera_frame::GpuCameraPass`.
pub(crate) const CAMERA_FRAME: PassShader = PassShader {
    label: "camera_frame.wgsl",
    files: &[BVH, DDGI_QUERY, SCENE, SHADOW_LIGHTING, wgsl_file!("camera_frame.wgsl")],
};
/// `shadow_field::GpuShadowField`.
pub(crate) const SHADOW_FIELD: PassShader =
    PassShader { label: "shadow_field.wgsl", files: &[BVH, SCENE, PROBE_BORDER, wgsl_file!("shadow_field.wgsl")] };
/// `device_frame::GpuFrame`.
pub(crate) const DEVICE_FRAME: PassShader =
    PassShader { label: "device_frame.wgsl", files: &[wgsl_file!("device_frame.wgsl")] };
/// `sky_from_cubemap::GpuSkyFromCubemap`.
pub(crate) const SKY_FROM_CUBEMAP: PassShader =
    PassShader { label: "sky_from_cubemap.wgsl", files: &[wgsl_file!("sky_from_cubemap.wgsl")] };
/// `ddgi_query::GpuFieldQuery`.
pub(crate) const FIELD_QUERY: PassShader =
    PassShader { label: "field_query.wgsl", files: &[DDGI_QUERY, wgsl_file!("field_query.wgsl")] };

/// Every pass of the crate (the unit tests compile each).
#[cfg(test)]
pub(crate) const PASSES: [&PassShader; 14] = [
    &DEVICE_FRAME,
    &SKY_FROM_CUBEMAP,
    &SHADOW_FIELD,
    &PROBE_CHANGE,
    &PROBE_SEEDING,
    &TRACE_RAYS,
    &PROBE_RAY_GEN,
    &PROBE_SHADE,
    &PROBE_BLEND,
    &PROBE_RELOCATION,
    &PROBE_CLASSIFICATION,
    &PROBE_USAGE,
    &CAMERA_FRAME,
    &FIELD_QUERY,
];

/// The pass's own group: its uniform block at binding 0, then its buffers.
pub(crate) const PASS_GROUP: u32 = 0;
/// `bvh.wgsl`'s group.
pub(crate) const BVH_GROUP: u32 = 1;
/// `ddgi_query.wgsl`'s group in the crate's passes.
pub(crate) const FIELD_GROUP: u32 = 2;
/// `scene.wgsl`'s group.
pub(crate) const SCENE_GROUP: u32 = 3;
/// Groups a pass may bind (WebGPU's default limit is also 4).
pub(crate) const BIND_GROUPS: u32 = 4;

/// Storage buffers of the BVH's group: nodes, triangles, cutouts, instances
/// (read-only) and the guard counters (read-write).
pub(crate) const BVH_STORAGE_BUFFERS: u32 = 5;
/// Storage buffers of the field's group: set, irradiance, distance, probes.
pub(crate) const FIELD_STORAGE_BUFFERS: u32 = 4;
/// Storage buffers of the scene's group: triangles, materials, textures, lights.
pub(crate) const SCENE_STORAGE_BUFFERS: u32 = 4;

/// `bvh.wgsl`'s flag of an instance whose local-from-world is the identity.
pub(crate) const BVH_INSTANCE_IDENTITY: u32 = 1;
/// `bvh.wgsl`'s flag of a moving object's instance (left out of a static-only trace).
pub(crate) const BVH_INSTANCE_MOVING: u32 = 2;

/// The `f32` constants of the prelude: WGSL name (the Rust one) and value.
const F32_CONSTANTS: [(&str, f32); 11] = [
    ("BACKFACE_WEIGHT_FLOOR", ddgi_query::BACKFACE_WEIGHT_FLOOR),
    ("CHEBYSHEV_WEIGHT_FLOOR", ddgi_query::CHEBYSHEV_WEIGHT_FLOOR),
    ("MIN_PROBE_WEIGHT", ddgi_query::MIN_PROBE_WEIGHT),
    ("TRILINEAR_WEIGHT_FLOOR", ddgi_query::TRILINEAR_WEIGHT_FLOOR),
    ("INSIDE_GEOMETRY_BACKFACE_FRACTION", probe_relocation::INSIDE_GEOMETRY_BACKFACE_FRACTION),
    ("FRONTFACE_STEP_LIMIT_REL", probe_relocation::FRONTFACE_STEP_LIMIT_REL),
    ("BACKFACE_DISTANCE_SCALE", probe_blend::BACKFACE_DISTANCE_SCALE),
    ("ADAPTIVE_HYSTERESIS_RISE", probe_blend::ADAPTIVE_HYSTERESIS_RISE),
    ("ADAPTIVE_HYSTERESIS_FLOOR", probe_blend::ADAPTIVE_HYSTERESIS_FLOOR),
    ("BLEND_WEIGHT_EPSILON", probe_blend::BLEND_WEIGHT_EPSILON),
    ("SEED_VISIBLE_WEIGHT_MIN", probegi_field::probe_seeding::SEED_VISIBLE_WEIGHT_MIN),
];

/// The `u32` constants of the prelude.
const U32_CONSTANTS: [(&str, u32); 6] = [
    ("SHADE_SKY_MAP_ON_MISS", crate::probe_shade::SHADE_SKY_MAP_ON_MISS),
    ("SHADE_HIT_AO_NEAR_FIELD", crate::probe_shade::SHADE_HIT_AO_NEAR_FIELD),
    ("SHADE_SKY_SAMPLES_MAX", crate::probe_shade::SHADE_SKY_SAMPLES_MAX),
    ("BVH_INSTANCE_IDENTITY", BVH_INSTANCE_IDENTITY),
    ("BVH_INSTANCE_MOVING", BVH_INSTANCE_MOVING),
    ("TRACE_MAX_SEGMENTS", crate::bvh_trace::TRACE_MAX_SEGMENTS as u32),
];

/// The WGSL `const` declarations of the values the shaders share with Rust. An
/// `f32` is printed as Rust's shortest round-trip decimal with WGSL's `f`
/// suffix, which parses straight to the same `f32`.
pub(crate) fn constants_prelude() -> String {
    let mut out = String::from("// Generated by probegi_wgpu::shader_registry from the Rust constants.\n");
    for (name, v) in F32_CONSTANTS {
        out.push_str(&format!("const {name}: f32 = {v:?}f;\n"));
    }
    for (name, v) in U32_CONSTANTS {
        out.push_str(&format!("const {name}: u32 = {v}u;\n"));
    }
    out
}

/// One file's text (`name`, `source`), the query's group placeholder filled
/// with `field_group`.
fn file_text(name: &str, source: &str, field_group: u32) -> String {
    let text = source.replace("DDGI_GROUP", &field_group.to_string());
    format!("// ---- {name} ----\n{text}\n")
}

/// `pass`'s module source: the prelude, then its files in order.
pub(crate) fn compose(pass: &PassShader) -> String {
    let mut out = constants_prelude();
    for file in pass.files {
        out.push_str(&file_text(file.name, file.source, FIELD_GROUP));
    }
    out
}

/// The query library for an engine's shader: the prelude and `ddgi_query.wgsl`
/// with its bindings in `group`, numbered from `first_binding` (their order
/// kept: set, irradiance, distance, probes).
pub(crate) fn query_library(group: u32, first_binding: u32) -> String {
    let mut source = DDGI_QUERY.source.to_owned();
    for b in 0..FIELD_STORAGE_BUFFERS {
        // Each replacement drops the placeholder, so a later binding number
        // never matches an earlier one's result.
        source = source.replace(
            &format!("@group(DDGI_GROUP) @binding({b})"),
            &format!("@group({group}) @binding({})", first_binding + b),
        );
    }
    constants_prelude() + &file_text(DDGI_QUERY.name, &source, group)
}

#[cfg(test)]
mod tests {
    use super::*;
    use std::mem::size_of;
    use wgpu::naga;

    fn parse(pass: &PassShader) -> naga::Module {
        let module = naga::front::wgsl::parse_str(&compose(pass)).unwrap_or_else(|e| panic!("{}: {e}", pass.label));
        let mut validator =
            naga::valid::Validator::new(naga::valid::ValidationFlags::all(), naga::valid::Capabilities::all());
        validator.validate(&module).unwrap_or_else(|e| panic!("{}: {e:?}", pass.label));
        module
    }

    /// The size naga's layouter gives the struct `name` of `module`.
    fn struct_size(module: &naga::Module, name: &str) -> u32 {
        let mut layouter = naga::proc::Layouter::default();
        layouter.update(module.to_ctx()).expect("layout");
        let (handle, _) = module
            .types
            .iter()
            .find(|(_, t)| t.name.as_deref() == Some(name))
            .unwrap_or_else(|| panic!("no struct {name}"));
        layouter[handle].size
    }

    /// Every struct the host writes or reads, beside its Rust twin.
    #[test]
    fn wgsl_structs_match_their_rust_twins() {
        use crate::bvh_trace::{GpuRay, GpuRayHit, TraceParams};
        use crate::camera_frame::CameraParams;
        use crate::ddgi_query::{FieldQueryParams, GpuDdgiSetHeader, GpuDdgiVolume, QueryPoint};
        use crate::probe_blend::BlendParams;
        use crate::probe_classification::ClassifyParams;
        use crate::probe_ray_gen::RayGenParams;
        use crate::probe_relocation::ChainParams;
        use crate::probe_shade::{ShadeParams, ShadeProbe};
        use crate::probe_usage::UsageParams;
        use crate::shadow_field::{ShadowParams, ShadowProbe};
        use crate::sky_from_cubemap::SkyFromCubemapParams;
        use probegi_field::seam::BatchProbe;
        let (ray, hit) = (size_of::<GpuRay>(), size_of::<GpuRayHit>());
        let cases: [(&PassShader, &str, usize); 30] = [
            (&SKY_FROM_CUBEMAP, "SkyFromCubemapParams", size_of::<SkyFromCubemapParams>()),
            (&SHADOW_FIELD, "ShadowParams", size_of::<ShadowParams>()),
            (&SHADOW_FIELD, "ShadowProbe", size_of::<ShadowProbe>()),
            (&SHADOW_FIELD, "ShadowRay", ray),
            (&SHADOW_FIELD, "ShadowHit", hit),
            (&TRACE_RAYS, "TraceParams", size_of::<TraceParams>()),
            (&TRACE_RAYS, "GpuRay", ray),
            (&TRACE_RAYS, "GpuRayHit", hit),
            (&PROBE_RAY_GEN, "RayGenParams", size_of::<RayGenParams>()),
            (&PROBE_RAY_GEN, "GenRay", ray),
            (&PROBE_SHADE, "ShadeParams", size_of::<ShadeParams>()),
            (&PROBE_SHADE, "ShadeProbe", size_of::<ShadeProbe>()),
            (&PROBE_SHADE, "ShadeRay", ray),
            (&PROBE_SHADE, "ShadeHit", hit),
            (&PROBE_SHADE, "DdgiVolume", size_of::<GpuDdgiVolume>()),
            (&PROBE_BLEND, "BlendParams", size_of::<BlendParams>()),
            (&PROBE_RELOCATION, "ChainParams", size_of::<ChainParams>()),
            (&PROBE_RELOCATION, "RelocationRay", ray),
            (&PROBE_RELOCATION, "RelocationHit", hit),
            (&PROBE_CLASSIFICATION, "ClassifyParams", size_of::<ClassifyParams>()),
            (&PROBE_CLASSIFICATION, "ClassifyRay", ray),
            (&PROBE_CLASSIFICATION, "ClassifyHit", hit),
            (&PROBE_USAGE, "UsageParams", size_of::<UsageParams>()),
            (&PROBE_USAGE, "UsageHit", hit),
            (&PROBE_USAGE, "UsageProbe", size_of::<BatchProbe>()),
            (&CAMERA_FRAME, "CameraParams", size_of::<CameraParams>()),
            (&CAMERA_FRAME, "DdgiVolume", size_of::<GpuDdgiVolume>()),
            (&FIELD_QUERY, "FieldQueryParams", size_of::<FieldQueryParams>()),
            (&FIELD_QUERY, "QueryPoint", size_of::<QueryPoint>()),
            (&FIELD_QUERY, "DdgiVolume", size_of::<GpuDdgiVolume>()),
        ];
        for (pass, name, rust) in cases {
            let module = parse(pass);
            assert_eq!(struct_size(&module, name) as usize, rust, "{}: {name}", pass.label);
        }
        // `DdgiSet` is the header, then the runtime array of volumes.
        let module = parse(&FIELD_QUERY);
        let (_, set) = module.types.iter().find(|(_, t)| t.name.as_deref() == Some("DdgiSet")).expect("DdgiSet");
        let naga::TypeInner::Struct { members, .. } = &set.inner else { panic!("DdgiSet is not a struct") };
        let volumes = members.iter().find(|m| m.name.as_deref() == Some("volumes")).expect("volumes");
        assert_eq!(volumes.offset as usize, size_of::<GpuDdgiSetHeader>());
    }

    /// The prelude's constants evaluate, in every pass, to the Rust values' bits.
    #[test]
    fn prelude_constants_keep_their_bits() {
        for pass in PASSES {
            let module = parse(pass);
            let value = |name: &str| {
                let (_, c) = module.constants.iter().find(|(_, c)| c.name.as_deref() == Some(name)).expect(name);
                match module.global_expressions[c.init] {
                    naga::Expression::Literal(l) => l,
                    ref e => panic!("{name} is not a literal: {e:?}"),
                }
            };
            for (name, v) in F32_CONSTANTS {
                let naga::Literal::F32(got) = value(name) else { panic!("{}: {name} is not an f32", pass.label) };
                assert_eq!(got.to_bits(), v.to_bits(), "{}: {name}", pass.label);
            }
            for (name, v) in U32_CONSTANTS {
                assert_eq!(value(name), naga::Literal::U32(v), "{}: {name}", pass.label);
            }
        }
    }

    /// Every binding sits in the group of the file that declares it, and each
    /// shared group holds the storage buffers its constant counts.
    #[test]
    fn bind_groups_follow_the_convention() {
        for pass in PASSES {
            let module = parse(pass);
            let mut storage = [0u32; BIND_GROUPS as usize];
            for (_, g) in module.global_variables.iter() {
                let Some(binding) = &g.binding else { continue };
                let name = g.name.as_deref().unwrap_or("");
                let group = match name {
                    n if n.starts_with("bvh_") => BVH_GROUP,
                    n if n.starts_with("ddgi_") => FIELD_GROUP,
                    n if n.starts_with("scene_") => SCENE_GROUP,
                    _ => PASS_GROUP,
                };
                assert_eq!(binding.group, group, "{}: {name}", pass.label);
                if matches!(g.space, naga::AddressSpace::Storage { .. }) {
                    storage[group as usize] += 1;
                }
            }
            for (group, count) in [
                (BVH_GROUP, BVH_STORAGE_BUFFERS),
                (FIELD_GROUP, FIELD_STORAGE_BUFFERS),
                (SCENE_GROUP, SCENE_STORAGE_BUFFERS),
            ] {
                let used = storage[group as usize];
                assert!(used == 0 || used == count, "{}: group {group} binds {used} storage buffers", pass.label);
            }
        }
    }

    #[test]
    fn the_engine_query_library_binds_where_it_is_asked_to() {
        for (group, first) in [(0, 0), (3, 100), (1, 2)] {
            let source = query_library(group, first);
            let module = naga::front::wgsl::parse_str(&source).unwrap_or_else(|e| panic!("{group}/{first}: {e}"));
            let mut bound: Vec<(String, u32, u32)> = module
                .global_variables
                .iter()
                .filter_map(|(_, g)| Some((g.name.clone()?, g.binding.as_ref()?.group, g.binding.as_ref()?.binding)))
                .collect();
            bound.sort_by_key(|b| b.2);
            let names = ["ddgi_set", "ddgi_irradiance_atlas", "ddgi_distance_atlas", "ddgi_probes"];
            let want: Vec<(String, u32, u32)> =
                names.iter().zip(first..).map(|(n, b)| (n.to_string(), group, b)).collect();
            assert_eq!(bound, want, "group {group}, first binding {first}");
        }
    }
}
