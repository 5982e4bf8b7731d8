//! Every glTF 2.0 file (.gltf and .glb) of Debian's `assimp-testmodels`
//! package (`/usr/share/assimp/models/glTF2`): files written to break
//! importers (SchemaFailures, wrongTypes, IndexOutOfRange, MissingBin,
//! RecursiveNodes, …) and valid ones (Khronos samples, the glTF Asset
//! Generator's primitive modes). Each load runs on its own thread under a time
//! bound. A broken file must give an error whose message names the file (never
//! a panic, never a hang); a valid file must load into a finite scene that a
//! BVH traces, or give an explicit unsupported-feature error. `scripts/test.sh`
//! installs the package; without it the test prints a warning and passes.

use std::path::{Path, PathBuf};
use std::sync::mpsc;
use std::time::Duration;

use glam::Vec3;
use probegi_scene::{BvhSettings, BvhTracer, Ray, RayTracer, Scene, SceneError, load_scene};

/// Where the package puts its glTF 2.0 models (Debian 12's layout first).
const ROOTS: [&str; 2] = ["/usr/share/assimp/models/glTF2", "/usr/share/assimp-testmodels/models/glTF2"];

/// No file of the corpus takes more than a fraction of a second; a load past
/// this is a hang.
const LOAD_TIME_BOUND: Duration = Duration::from_secs(60);

/// Files that are malformed (by their folder's name and content): they must be
/// refused, with the file named.
const BROKEN: [&str; 15] = [
    "BoxWithInfinites-glTF-Binary/BoxWithInfinites.glb",
    "IncorrectVertexArrays/Cube.gltf",
    "IndexOutOfRange/AllIndicesOutOfRange.gltf",
    "IndexOutOfRange/IndexOutOfRange.gltf",
    "MissingBin/BoxTextured.gltf",
    "RecursiveNodes/RecursiveNodes.gltf",
    "SchemaFailures/sceneWrongType.gltf",
    "TestNoRootNode/NoScene.gltf",
    "TestNoRootNode/SceneWithoutNodes.gltf",
    "wrongTypes/badArray.gltf",
    "wrongTypes/badExtension.gltf",
    "wrongTypes/badNumber.gltf",
    "wrongTypes/badObject.gltf",
    "wrongTypes/badString.gltf",
    "wrongTypes/badUint.gltf",
];

/// Valid files probegi cannot draw, and the words its error must contain.
const UNSUPPORTED: [(&str, &str); 10] = [
    ("draco/2CylinderEngine.gltf", "requires extension KHR_draco_mesh_compression"),
    ("BoxTextured-glTF-techniqueWebGL/BoxTextured.gltf", "requires extension KHR_technique_webgl"),
    // Points, lines, line loops and line strips (with and without indices): no surface.
    ("glTF-Asset-Generator/Mesh_PrimitiveMode/Mesh_PrimitiveMode_00.gltf", "no triangle primitives"),
    ("glTF-Asset-Generator/Mesh_PrimitiveMode/Mesh_PrimitiveMode_01.gltf", "no triangle primitives"),
    ("glTF-Asset-Generator/Mesh_PrimitiveMode/Mesh_PrimitiveMode_02.gltf", "no triangle primitives"),
    ("glTF-Asset-Generator/Mesh_PrimitiveMode/Mesh_PrimitiveMode_03.gltf", "no triangle primitives"),
    ("glTF-Asset-Generator/Mesh_PrimitiveMode/Mesh_PrimitiveMode_07.gltf", "no triangle primitives"),
    ("glTF-Asset-Generator/Mesh_PrimitiveMode/Mesh_PrimitiveMode_08.gltf", "no triangle primitives"),
    ("glTF-Asset-Generator/Mesh_PrimitiveMode/Mesh_PrimitiveMode_09.gltf", "no triangle primitives"),
    ("glTF-Asset-Generator/Mesh_PrimitiveMode/Mesh_PrimitiveMode_10.gltf", "no triangle primitives"),
];

fn corpus_root() -> Option<PathBuf> {
    ROOTS.iter().map(PathBuf::from).find(|p| p.is_dir())
}

/// Every .gltf and .glb under `dir`, sorted.
fn gltf_files(dir: &Path) -> Vec<PathBuf> {
    let mut out = vec![];
    let mut stack = vec![dir.to_path_buf()];
    while let Some(d) = stack.pop() {
        for entry in std::fs::read_dir(&d).into_iter().flatten().flatten() {
            let p = entry.path();
            let ext = p.extension().map(|e| e.to_string_lossy().to_lowercase());
            if p.is_dir() {
                stack.push(p);
            } else if matches!(ext.as_deref(), Some("gltf" | "glb")) {
                out.push(p);
            }
        }
    }
    out.sort();
    out
}

/// What a load came to.
enum Outcome {
    Loaded(Box<Scene>),
    Failed(SceneError),
    Panicked,
    Hung,
}

/// Loads `path` on its own thread, waiting at most [`LOAD_TIME_BOUND`].
fn load_bounded(path: &Path) -> Outcome {
    let (tx, rx) = mpsc::channel();
    let spec = path.to_string_lossy().into_owned();
    std::thread::spawn(move || {
        let _ = tx.send(load_scene(&spec));
    });
    match rx.recv_timeout(LOAD_TIME_BOUND) {
        Ok(Ok(scene)) => Outcome::Loaded(Box::new(scene)),
        Ok(Err(e)) => Outcome::Failed(e),
        // The sender went away without sending: the loader panicked.
        Err(mpsc::RecvTimeoutError::Disconnected) => Outcome::Panicked,
        Err(mpsc::RecvTimeoutError::Timeout) => Outcome::Hung,
    }
}

/// A loaded scene is finite and traceable: bounds, materials and lights are
/// finite, and rays aimed at its centre from outside hit it with finite
/// surface points and BSDFs.
fn check_traceable(name: &str, scene: &Scene) {
    let (lo, hi) = scene.bounds().unwrap_or_else(|| panic!("{name}: no bounds"));
    assert!(lo.is_finite() && hi.is_finite(), "{name}: bounds {lo} {hi}");
    let tracer = BvhTracer::for_scene(scene, BvhSettings::default());
    let (centre, radius) = ((lo + hi) * 0.5, ((hi - lo).length() * 0.5).max(1e-3));
    let mut hits = 0;
    for k in 0..64 {
        let z = 1.0 - 2.0 * (k as f32 + 0.5) / 64.0;
        let phi = k as f32 * 2.399_963;
        let dir = Vec3::new((1.0 - z * z).sqrt() * phi.cos(), z, (1.0 - z * z).sqrt() * phi.sin());
        let Some(hit) = tracer.closest_hit(&Ray::new(centre + dir * radius * 3.0, -dir)) else { continue };
        hits += 1;
        let sp = scene.surface_point(&hit);
        let bsdf = scene.bsdf(&sp);
        assert!(sp.position.is_finite() && sp.shading_normal.is_finite(), "{name}: surface point {sp:?}");
        assert!(bsdf.diffuse.is_finite() && bsdf.specular_f0.is_finite() && bsdf.alpha.is_finite(), "{name}");
        assert!(scene.emitted(&sp).is_finite(), "{name}: emission");
    }
    assert!(hits > 0, "{name}: no ray aimed at its centre hits it");
}

#[test]
fn every_gltf2_file_of_assimp_testmodels_loads_or_is_refused_with_its_name() {
    let Some(root) = corpus_root() else {
        eprintln!(
            "warning: assimp-testmodels is not installed (no {}): SKIPPING the glTF corpus test \
             (apt-get install -y assimp-testmodels)",
            ROOTS.join(" or ")
        );
        return;
    };
    let files = gltf_files(&root);
    assert!(files.len() >= 40, "{} holds only {} glTF files", root.display(), files.len());
    let (mut loaded, mut refused) = (0, 0);
    for path in &files {
        let rel = path.strip_prefix(&root).unwrap_or(path).to_string_lossy().replace('\\', "/");
        let unsupported = UNSUPPORTED.iter().find(|(f, _)| *f == rel).map(|(_, why)| *why);
        match load_bounded(path) {
            Outcome::Hung => panic!("{rel}: still loading after {LOAD_TIME_BOUND:?}"),
            Outcome::Panicked => panic!("{rel}: the loader panicked"),
            Outcome::Failed(e) => {
                let message = e.to_string();
                eprintln!("{rel}: refused: {message}");
                assert!(message.contains(&path.display().to_string()), "{rel}: the error does not name it: {message}");
                let why = unsupported.unwrap_or("");
                assert!(
                    BROKEN.contains(&rel.as_str()) || (!why.is_empty() && message.contains(why)),
                    "{rel}: a valid file was refused: {message}"
                );
                refused += 1;
            }
            Outcome::Loaded(scene) => {
                assert!(!BROKEN.contains(&rel.as_str()), "{rel}: a malformed file loaded");
                assert!(unsupported.is_none(), "{rel}: expected `{}`, it loaded", unsupported.unwrap_or(""));
                eprintln!("{rel}: {} triangles, {} warnings", scene.mesh.triangle_count(), scene.warnings.len());
                check_traceable(&rel, &scene);
                loaded += 1;
            }
        }
    }
    eprintln!("{} files: {loaded} loaded, {refused} refused", files.len());
    assert_eq!(refused, BROKEN.len() + UNSUPPORTED.len(), "every listed file was met");
}

fn load_corpus(rel: &str) -> Option<Scene> {
    let path = corpus_root()?.join(rel);
    match load_bounded(&path) {
        Outcome::Loaded(s) => Some(*s),
        Outcome::Failed(e) => panic!("{rel}: {e}"),
        _ => panic!("{rel}: panicked or hung"),
    }
}

/// The total area and the mean face normal of a scene's triangles.
fn area_and_normal(s: &Scene) -> (f32, Vec3) {
    let m = &s.mesh;
    let n: Vec3 = (0..m.triangle_count()).map(|t| m.face_normal_scaled(t)).sum();
    ((0..m.triangle_count()).map(|t| m.area(t)).sum(), n.normalize_or_zero())
}

#[test]
fn strips_and_fans_of_the_asset_generator_cover_the_triangle_list_quad_with_its_winding() {
    let dir = "glTF-Asset-Generator/Mesh_PrimitiveMode";
    let Some(list) = load_corpus(&format!("{dir}/Mesh_PrimitiveMode_06.gltf")) else {
        eprintln!("warning: assimp-testmodels is not installed: SKIPPING (apt-get install -y assimp-testmodels)");
        return;
    };
    let (area, normal) = area_and_normal(&list);
    assert!(area > 0.0 && normal.length() > 0.99, "the triangle list quad: {area} {normal}");
    // 04 strip, 05 fan (no indices); 11 strip, 12 fan (indexed).
    for k in ["04", "05", "11", "12"] {
        let s = load_corpus(&format!("{dir}/Mesh_PrimitiveMode_{k}.gltf")).expect("installed");
        let (a, n) = area_and_normal(&s);
        eprintln!(
            "mode file {k}: {} triangles, area {a} (list {area}), normal {n} (list {normal})",
            s.mesh.triangle_count()
        );
        assert_eq!(s.mesh.triangle_count(), 2, "{k}");
        assert!((a - area).abs() < 1e-5 * area, "{k}: area {a} vs {area}");
        assert!(n.dot(normal) > 0.999, "{k}: faces {n}, the list faces {normal}");
        // Both triangles face the same way (a strip alternates its corner order).
        assert!((0..2).all(|t| s.mesh.face_normal_scaled(t).normalize().dot(normal) > 0.999), "{k}");
    }
    // Points and lines: the warning names the mesh.
    let e =
        load_scene(&corpus_root().expect("installed").join(dir).join("Mesh_PrimitiveMode_01.gltf").to_string_lossy());
    assert!(e.is_err_and(|e| e.to_string().contains("no triangle primitives")));
}

#[test]
fn unfollowed_extensions_are_named_in_warnings_and_required_ones_in_errors() {
    let Some(clearcoat) = load_corpus("ClearCoat-glTF/ClearCoatTest.gltf") else {
        eprintln!("warning: assimp-testmodels is not installed: SKIPPING (apt-get install -y assimp-testmodels)");
        return;
    };
    let has = |s: &Scene, w: &str| s.warnings.iter().any(|x| x.contains(w));
    assert!(has(&clearcoat, "KHR_materials_clearcoat"), "{:?}", clearcoat.warnings);
    let sg = load_corpus("BoxTextured-glTF-pbrSpecularGlossiness/BoxTextured.gltf").expect("installed");
    assert!(has(&sg, "KHR_materials_pbrSpecularGlossiness"), "{:?}", sg.warnings);
    // KHR_texture_transform is followed: no warning, and the transform is read.
    let tt = load_corpus("textureTransform/TextureTransformTest.gltf").expect("installed");
    assert!(!has(&tt, "KHR_texture_transform"), "{:?}", tt.warnings);
    assert_eq!(tt.materials.iter().filter(|m| !m.base_color_uv.is_untransformed()).count(), 6);
    let root = corpus_root().expect("installed");
    let draco = root.join("draco/2CylinderEngine.gltf");
    let e = load_scene(&draco.to_string_lossy()).expect_err("draco is required");
    let message = e.to_string();
    assert!(
        message.contains("KHR_draco_mesh_compression") && message.contains(&draco.display().to_string()),
        "{message}"
    );
}
