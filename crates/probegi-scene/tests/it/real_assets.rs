//! Assets as their files describe them (real-assets issue): OBJ normals by
//! smoothing group, flat glTF normals without NORMAL, alpha cutouts inside
//! traversal, bump maps that tilt the normal by the expected angle, and
//! MikkTSpace tangents against the tangents a file stores.

use std::path::{Path, PathBuf};

use glam::{Vec2, Vec3, Vec4};
use probegi_scene::{BvhSettings, BvhTracer, Ray, RayTracer, Scene, load_scene};

fn dir(name: &str) -> PathBuf {
    let d = std::env::temp_dir().join(format!("probegi-assets-{}-{name}", std::process::id()));
    std::fs::create_dir_all(&d).expect("mkdir");
    d
}

/// A unit cube's 8 corners and 6 quads (counter-clockwise from outside), OBJ indices.
const CUBE_V: &str = "v 0 0 0\nv 1 0 0\nv 1 1 0\nv 0 1 0\nv 0 0 1\nv 1 0 1\nv 1 1 1\nv 0 1 1\n";
const CUBE_F: [&str; 6] = ["f 1 4 3 2", "f 5 6 7 8", "f 1 5 8 4", "f 2 3 7 6", "f 4 8 7 3", "f 1 2 6 5"];

/// The shading normal at the centre of each face hit straight on from outside.
fn face_centre_normals(scene: &Scene) -> Vec<(Vec3, Vec3)> {
    let bvh = BvhTracer::for_scene(scene, BvhSettings::default());
    let c = Vec3::splat(0.5);
    // Slightly off-centre so the ray does not land on the quad's diagonal.
    let axes = [Vec3::X, Vec3::NEG_X, Vec3::Y, Vec3::NEG_Y, Vec3::Z, Vec3::NEG_Z];
    axes.iter()
        .map(|&a| {
            let off = Vec3::new(0.13, 0.21, 0.17) * (Vec3::ONE - a.abs());
            // `-a` has negative zeros (e.g. (-1, -0, -0)): they must not make rays miss.
            let ray = Ray::new(c + a * 3.0 + off, -a);
            let hit = bvh.closest_hit(&ray).unwrap_or_else(|| {
                panic!("cube face {a} missed by {ray:?} ({} triangles)", scene.mesh.triangle_count())
            });
            (a, scene.surface_point(&hit).shading_normal)
        })
        .collect()
}

#[test]
fn obj_faces_without_a_smoothing_group_are_flat_and_a_group_is_smooth() {
    let d = dir("groups");
    let write = |name: &str, body: &str| {
        let p = d.join(name);
        std::fs::write(&p, format!("{CUBE_V}{body}")).expect("write");
        load_scene(&p.to_string_lossy()).expect("loads")
    };
    let flat = write("flat.obj", &CUBE_F.join("\n"));
    let off = write("off.obj", &format!("s 1\ns off\n{}", CUBE_F.join("\n")));
    let smooth = write("smooth.obj", &format!("s 1\n{}", CUBE_F.join("\n")));
    // Top (+Y, face 5) in its own group: smooth but alone, so flat; the rest share group 2.
    let mixed = write("mixed.obj", &format!("s 2\n{}\ns 3\n{}\ns 2\n{}", CUBE_F[..4].join("\n"), CUBE_F[4], CUBE_F[5]));
    for s in [&flat, &off] {
        for (axis, n) in face_centre_normals(s) {
            assert!(n.dot(axis) > 0.9999, "{}: face {axis} shades with {n}", s.name);
        }
    }
    // A smoothed cube: the corners' normals are the diagonals, so face centres lean
    // inward from the face normal, yet not past it.
    for (axis, n) in face_centre_normals(&smooth) {
        let d = n.dot(axis);
        assert!(d < 0.98 && d > 0.5, "smoothing group: face {axis} normal {n} ({d})");
    }
    for (axis, n) in face_centre_normals(&mixed) {
        let d = n.dot(axis);
        if axis == Vec3::Y {
            assert!(d > 0.9999, "the top face is alone in group 3: {n}");
        } else if axis == Vec3::NEG_Y || axis.y == 0.0 {
            assert!(d < 0.999, "face {axis} shares group 2 with its neighbours: {n}");
        }
    }
    std::fs::remove_dir_all(&d).ok();
}

#[test]
fn obj_vn_is_used_as_given() {
    let d = dir("vn");
    let p = d.join("q.obj");
    // A flat quad whose file normals lean 45° toward +X.
    std::fs::write(&p, "v 0 0 0\nv 1 0 0\nv 1 0 -1\nv 0 0 -1\nvn 1 1 0\nf 1//1 2//1 3//1 4//1\n").expect("write");
    let s = load_scene(&p.to_string_lossy()).expect("loads");
    let bvh = BvhTracer::for_scene(&s, BvhSettings::default());
    let hit = bvh.closest_hit(&Ray::new(Vec3::new(0.4, 1.0, -0.3), Vec3::NEG_Y)).expect("hit");
    let n = s.surface_point(&hit).shading_normal;
    assert!((n - Vec3::new(1.0, 1.0, 0.0).normalize()).length() < 1e-5, "{n}");
    std::fs::remove_dir_all(&d).ok();
}

/// Writes a glTF with one triangle-list primitive and its buffer; `attributes`
/// are (name, accessor type, components, data) in order.
fn write_gltf(
    d: &Path,
    name: &str,
    attrs: &[(&str, &str, Vec<f32>)],
    indices: &[u32],
    material: &str,
    extra: &str,
) -> PathBuf {
    let mut bin: Vec<u8> = vec![];
    let mut views = vec![];
    let mut accessors = vec![];
    let mut attr_json = vec![];
    let count = attrs[0].2.len() / 3;
    for (k, (attr, ty, data)) in attrs.iter().enumerate() {
        let offset = bin.len();
        data.iter().for_each(|v| bin.extend_from_slice(&v.to_le_bytes()));
        views.push(format!(r#"{{"buffer":0,"byteOffset":{offset},"byteLength":{}}}"#, data.len() * 4));
        let extra_minmax = if *attr == "POSITION" {
            let (mut lo, mut hi) = ([f32::MAX; 3], [f32::MIN; 3]);
            for p in data.chunks_exact(3) {
                for i in 0..3 {
                    lo[i] = lo[i].min(p[i]);
                    hi[i] = hi[i].max(p[i]);
                }
            }
            format!(r#","min":{lo:?},"max":{hi:?}"#)
        } else {
            String::new()
        };
        accessors
            .push(format!(r#"{{"bufferView":{k},"componentType":5126,"count":{count},"type":"{ty}"{extra_minmax}}}"#));
        attr_json.push(format!(r#""{attr}":{k}"#));
    }
    let offset = bin.len();
    indices.iter().for_each(|i| bin.extend_from_slice(&i.to_le_bytes()));
    views.push(format!(r#"{{"buffer":0,"byteOffset":{offset},"byteLength":{}}}"#, indices.len() * 4));
    accessors.push(format!(
        r#"{{"bufferView":{},"componentType":5125,"count":{},"type":"SCALAR"}}"#,
        attrs.len(),
        indices.len()
    ));
    std::fs::write(d.join(format!("{name}.bin")), &bin).expect("bin");
    let json = format!(
        r#"{{"asset":{{"version":"2.0"}},"scene":0,"scenes":[{{"nodes":[0]}}],"nodes":[{{"mesh":0}}],
"meshes":[{{"primitives":[{{"attributes":{{{}}},"indices":{},"material":0}}]}}],
"materials":[{material}],{extra}
"buffers":[{{"uri":"{name}.bin","byteLength":{}}}],"bufferViews":[{}],"accessors":[{}]}}"#,
        attr_json.join(","),
        attrs.len(),
        bin.len(),
        views.join(","),
        accessors.join(",")
    );
    let p = d.join(format!("{name}.gltf"));
    std::fs::write(&p, json).expect("gltf");
    p
}

#[test]
fn gltf_without_normal_is_flat_and_ignores_its_tangents() {
    let d = dir("gltf-flat");
    // The cube's 8 shared corners, 12 triangles, with a TANGENT that must be ignored.
    let corners: Vec<f32> =
        (0..8).flat_map(|i| [(i & 1) as f32, ((i >> 1) & 1) as f32, ((i >> 2) & 1) as f32]).collect();
    let tangents: Vec<f32> = (0..8).flat_map(|_| [0.0, 1.0, 0.0, 1.0]).collect();
    // Corner index = x + 2y + 4z; quads counter-clockwise from outside.
    let quads = [[0, 2, 3, 1], [4, 5, 7, 6], [0, 4, 6, 2], [1, 3, 7, 5], [2, 6, 7, 3], [0, 1, 5, 4]];
    let indices: Vec<u32> = quads.iter().flat_map(|q| [q[0], q[1], q[2], q[0], q[2], q[3]]).collect();
    let p = write_gltf(&d, "cube", &[("POSITION", "VEC3", corners), ("TANGENT", "VEC4", tangents)], &indices, "{}", "");
    let s = load_scene(&p.to_string_lossy()).expect("loads");
    assert!(s.mesh.tangents.is_empty(), "TANGENT without NORMAL must be ignored");
    for (axis, n) in face_centre_normals(&s) {
        assert!(n.dot(axis) > 0.9999, "face {axis} shades with {n}");
    }
    std::fs::remove_dir_all(&d).ok();
}

/// Positions, normals, UVs, tangents and indices.
type SphereArrays = (Vec<f32>, Vec<f32>, Vec<f32>, Vec<f32>, Vec<u32>);

/// A UV sphere (longitude → u, latitude → v) with analytic normals and
/// tangents (∂p/∂u), outward counter-clockwise triangles.
fn uv_sphere(n_lon: usize, n_lat: usize) -> SphereArrays {
    let (mut p, mut n, mut uv, mut t, mut idx) = (vec![], vec![], vec![], vec![], vec![]);
    for j in 0..=n_lat {
        for i in 0..=n_lon {
            let (u, v) = (i as f32 / n_lon as f32, j as f32 / n_lat as f32);
            let (phi, theta) = (u * std::f32::consts::TAU, v * std::f32::consts::PI);
            let q = Vec3::new(theta.sin() * phi.cos(), theta.cos(), theta.sin() * phi.sin());
            p.extend(q.to_array());
            n.extend(q.to_array());
            uv.extend([u, v]);
            let tangent = Vec3::new(-phi.sin(), 0.0, phi.cos());
            let bitangent = Vec3::new(theta.cos() * phi.cos(), -theta.sin(), theta.cos() * phi.sin());
            let w = if q.cross(tangent).dot(bitangent) < 0.0 { -1.0 } else { 1.0 };
            t.extend([tangent.x, tangent.y, tangent.z, w]);
        }
    }
    let at = |i: usize, j: usize| (j * (n_lon + 1) + i) as u32;
    for j in 0..n_lat {
        for i in 0..n_lon {
            let (a, b, c, d) = (at(i, j), at(i + 1, j), at(i + 1, j + 1), at(i, j + 1));
            // ∂p/∂u × ∂p/∂v points outward, so (a, b, c) and (a, c, d) wind counter-clockwise.
            idx.extend([a, b, c, a, c, d]);
        }
    }
    (p, n, uv, t, idx)
}

#[test]
fn mikktspace_tangents_match_the_tangents_the_file_stores() {
    let d = dir("mikk");
    let img = image::RgbImage::from_pixel(2, 2, image::Rgb([128, 128, 255]));
    img.save(d.join("flat-normal.png")).expect("png");
    let material = r#"{"normalTexture":{"index":0,"scale":1.0}}"#;
    let extra = r#""textures":[{"source":0}],"images":[{"uri":"flat-normal.png"}],"#;
    let (p, n, uv, t, idx) = uv_sphere(32, 16);
    let attrs = |with_t: bool| {
        let mut a =
            vec![("POSITION", "VEC3", p.clone()), ("NORMAL", "VEC3", n.clone()), ("TEXCOORD_0", "VEC2", uv.clone())];
        if with_t {
            a.push(("TANGENT", "VEC4", t.clone()));
        }
        a
    };
    let stored =
        load_scene(&write_gltf(&d, "stored", &attrs(true), &idx, material, extra).to_string_lossy()).expect("stored");
    let mikk =
        load_scene(&write_gltf(&d, "mikk", &attrs(false), &idx, material, extra).to_string_lossy()).expect("mikk");
    assert_eq!(stored.mesh.tangents.len(), stored.mesh.positions.len());
    assert!(
        mikk.mesh.tangents.len() == mikk.mesh.positions.len()
            && mikk.mesh.positions.len() >= stored.mesh.positions.len()
    );
    let key = |p: Vec3, uv: Vec2| (p.to_array().map(f32::to_bits), uv.to_array().map(f32::to_bits));
    let file: std::collections::HashMap<_, Vec4> = (0..stored.mesh.positions.len())
        .map(|v| (key(stored.mesh.positions[v], stored.mesh.uvs[v]), stored.mesh.tangents[v]))
        .collect();
    let (mut worst, mut worst_mid, mut sum, mut count) = (0.0f32, 0.0f32, 0.0f32, 0);
    for v in 0..mikk.mesh.positions.len() {
        // Skip the poles, where ∂p/∂u vanishes and any tangent is as good as another.
        if mikk.mesh.positions[v].y.abs() > 0.95 {
            continue;
        }
        let ours = mikk.mesh.tangents[v];
        let theirs = file[&key(mikk.mesh.positions[v], mikk.mesh.uvs[v])];
        let angle = ours.truncate().dot(theirs.truncate()).clamp(-1.0, 1.0).acos().to_degrees();
        assert_eq!(ours.w, theirs.w, "bitangent sign at vertex {v}");
        worst = worst.max(angle);
        // At the UV seam each side sees its faces only, so its tangent is the chord
        // half a segment away (360° / 32 / 2 = 5.6°); elsewhere faces on both sides average out.
        let seam = mikk.mesh.uvs[v].x == 0.0 || mikk.mesh.uvs[v].x == 1.0;
        if mikk.mesh.positions[v].y.abs() < 0.75 && !seam {
            worst_mid = worst_mid.max(angle);
        }
        sum += angle;
        count += 1;
    }
    let mean = sum / count as f32;
    eprintln!(
        "MikkTSpace vs stored tangents over {count} vertices: mean {mean:.3}°, worst {worst:.3}° (|y| < 0.75 off the seam: {worst_mid:.3}°)"
    );
    // The rings next to the poles, whose triangles are degenerate, differ most.
    assert!(
        count > 400 && mean < 0.5 && worst < 6.0 && worst_mid < 1.0,
        "mean {mean}°, worst {worst}°, mid {worst_mid}°"
    );
    // A flat normal map leaves the shading normal alone on both.
    let bvh = BvhTracer::for_scene(&mikk, BvhSettings::default());
    let hit = bvh.closest_hit(&Ray::new(Vec3::new(0.3, 0.2, 3.0), Vec3::NEG_Z)).expect("sphere");
    let sp = mikk.surface_point(&hit);
    assert!(sp.shading_normal.dot(sp.position.normalize()) > 0.999, "{}", sp.shading_normal);
    std::fs::remove_dir_all(&d).ok();
}

/// A 2 m × 2 m plane in y = 0, u along +x over [0, 1], with the material's MTL lines.
fn mtl_plane(d: &Path, name: &str, mtl: &str) -> Scene {
    let obj = format!(
        "mtllib {name}.mtl\nv -1 0 1\nv 1 0 1\nv 1 0 -1\nv -1 0 -1\nvt 0 0\nvt 1 0\nvt 1 1\nvt 0 1\nusemtl m\nf 1/1 2/2 3/3 4/4\n"
    );
    std::fs::write(d.join(format!("{name}.obj")), obj).expect("obj");
    std::fs::write(d.join(format!("{name}.mtl")), format!("newmtl m\nKd 0.5 0.5 0.5\n{mtl}\n")).expect("mtl");
    load_scene(&d.join(format!("{name}.obj")).to_string_lossy()).expect("loads")
}

fn normal_at(scene: &Scene, x: f32, z: f32) -> Option<Vec3> {
    let bvh = BvhTracer::for_scene(scene, BvhSettings::default());
    bvh.closest_hit(&Ray::new(Vec3::new(x, 1.0, z), Vec3::NEG_Y)).map(|h| scene.surface_point(&h).shading_normal)
}

#[test]
fn a_height_ramp_tilts_the_shading_normal_by_the_expected_angle() {
    let d = dir("bump");
    // Grey ramp along u: texel i holds i, so height rises 1/255 per texel.
    let img = image::GrayImage::from_fn(256, 4, |x, _| image::Luma([x as u8]));
    img.save(d.join("ramp.png")).expect("png");
    for bm in [1.0f32, 20.0] {
        let s = mtl_plane(&d, &format!("bm{}", (bm * 100.0) as u32), &format!("bump -bm {bm} ramp.png"));
        assert_eq!(s.materials[0].bump_multiplier, bm);
        let n = normal_at(&s, 0.1, 0.2).expect("hit");
        // 1/255 of height per texel; white stands 0.02 × 256 texels high: the slope
        // in texel space, whatever the plane's size (2 m) or UV density.
        let slope = bm * (0.02 * 256.0) / 255.0;
        let expected = slope.atan();
        let tilt = n.dot(Vec3::Y).clamp(-1.0, 1.0).acos();
        assert!((tilt - expected).abs() < 1e-3, "bm {bm}: tilt {}° vs {}°", tilt.to_degrees(), expected.to_degrees());
        assert!(n.x < 0.0 && n.z.abs() < 1e-4, "the normal leans away from rising height: {n}");
        let mut off = s.clone();
        probegi_scene::scene_file::apply_scene_setting(&mut off, "normal_maps=false").expect("setting");
        assert!(normal_at(&off, 0.1, 0.2).expect("hit").dot(Vec3::Y) > 0.99999);
    }
    std::fs::remove_dir_all(&d).ok();
}

#[test]
fn cut_out_texels_let_closest_hit_and_shadow_rays_through_inside_traversal() {
    let d = dir("cutout");
    // Alpha 0 on the left texel column, 255 on the right: u < 0.5 is cut out (away from the wrap seam).
    let img = image::RgbaImage::from_fn(2, 1, |x, _| image::Rgba([90, 160, 60, if x == 0 { 0 } else { 255 }]));
    img.save(d.join("leaf.png")).expect("png");
    let floor = "v -1 -1 1\nv 1 -1 1\nv 1 -1 -1\nv -1 -1 -1\n";
    let obj = format!(
        "mtllib c.mtl\nv -1 0 1\nv 1 0 1\nv 1 0 -1\nv -1 0 -1\nvt 0 0\nvt 1 0\nvt 1 1\nvt 0 1\nusemtl leaf\nf 1/1 2/2 3/3 4/4\n{floor}usemtl ground\nf 5 6 7 8\n"
    );
    std::fs::write(d.join("c.obj"), obj).expect("obj");
    for (mtl, rule) in [
        ("newmtl leaf\nmap_Kd leaf.png\nnewmtl ground\n", "map_Kd alpha"),
        ("newmtl leaf\nmap_d leaf.png\nnewmtl ground\n", "map_d"),
    ] {
        std::fs::write(d.join("c.mtl"), mtl).expect("mtl");
        let s = load_scene(&d.join("c.obj").to_string_lossy()).expect("loads");
        let bvh = BvhTracer::for_scene(&s, BvhSettings::default());
        assert_eq!(bvh.cutout_triangle_count(), 2, "{rule}");
        for x in [-0.9f32, -0.6, -0.35] {
            let u = (x + 1.0) / 2.0;
            let ray = Ray::new(Vec3::new(x, 1.0, 0.3), Vec3::NEG_Y);
            let hit = bvh.closest_hit(&ray).expect("the floor");
            assert!((hit.t - 2.0).abs() < 1e-4, "{rule}: u {u}: the ray should pass the cutout (t {})", hit.t);
            assert!(!bvh.occluded(&Ray::segment(ray.origin, ray.dir, 1.5)), "{rule}: shadow ray at u {u}");
            // From below too: both sides are cut out.
            assert!(!bvh.occluded(&Ray::segment(Vec3::new(x, -0.5, 0.3), Vec3::Y, 1.5)));
        }
        for x in [0.35f32, 0.6, 0.9] {
            let ray = Ray::new(Vec3::new(x, 1.0, 0.3), Vec3::NEG_Y);
            assert!((bvh.closest_hit(&ray).expect("leaf").t - 1.0).abs() < 1e-4, "{rule}: opaque half at x {x}");
            assert!(bvh.occluded(&Ray::segment(ray.origin, ray.dir, 1.5)));
        }
        let opaque = BvhTracer::build(&s.mesh, BvhSettings::default());
        assert!(
            (opaque.closest_hit(&Ray::new(Vec3::new(-0.6, 1.0, 0.3), Vec3::NEG_Y)).expect("leaf").t - 1.0).abs() < 1e-4
        );
    }
    // `d` below the cutoff removes a material without a texture; glTF BLEND is a cutout at 0.5.
    std::fs::write(d.join("c.mtl"), "newmtl leaf\nd 0.3\nnewmtl ground\n").expect("mtl");
    let s = load_scene(&d.join("c.obj").to_string_lossy()).expect("loads");
    let bvh = BvhTracer::for_scene(&s, BvhSettings::default());
    assert!((bvh.closest_hit(&Ray::new(Vec3::new(0.6, 1.0, 0.3), Vec3::NEG_Y)).expect("floor").t - 2.0).abs() < 1e-4);
    std::fs::remove_dir_all(&d).ok();
}

#[test]
fn scene_files_override_normals_and_place_instances() {
    let d = dir("toml");
    std::fs::write(d.join("cube.obj"), format!("{CUBE_V}{}", CUBE_F.join("\n"))).expect("obj");
    let toml = "[[meshes]]\npath = \"cube.obj\"\nnormals = \"smooth\"\n\n\
                [[instances]]\npath = \"cube.obj\"\ntransforms = [{ translation = [5.0, 0.0, 0.0] }, { translation = [8.0, 0.0, 0.0], scale = [2.0, 2.0, 2.0] }]\n\n\
                [[instances]]\npath = \"cube.obj\"\ngrid = { count = [3, 2], spacing_m = [3.0, 3.0], origin_m = [0.0, 0.0, 10.0] }\n";
    std::fs::write(d.join("s.toml"), toml).expect("toml");
    let s = load_scene(&d.join("s.toml").to_string_lossy()).expect("loads");
    assert_eq!(s.mesh.triangle_count(), 12, "instances are not copied into the mesh");
    assert_eq!((s.prototypes.len(), s.instances.len(), s.instanced_triangle_count()), (2, 8, 12 * 8));
    assert_eq!(s.materials.len(), 3, "one set of materials per entry, not per copy");
    let (lo, hi) = s.bounds().expect("bounds");
    assert_eq!((lo, hi), (Vec3::ZERO, Vec3::new(10.0, 2.0, 14.0)));
    for (axis, n) in face_centre_normals(&s) {
        assert!(n.dot(axis) < 0.98, "normals = \"smooth\" on the first cube: {n}");
    }
    let bad = "[[meshes]]\npath = \"cube.obj\"\nnormals = \"soft\"\n";
    std::fs::write(d.join("bad.toml"), bad).expect("toml");
    let e = load_scene(&d.join("bad.toml").to_string_lossy()).expect_err("unknown rule").to_string();
    assert!(e.contains("bad.toml") && e.contains("soft"), "{e}");
    std::fs::write(d.join("none.toml"), "[[instances]]\npath = \"cube.obj\"\n").expect("toml");
    let e = load_scene(&d.join("none.toml").to_string_lossy()).expect_err("no copies").to_string();
    assert!(e.contains("instances[0]") && e.contains("transforms"), "{e}");
    std::fs::remove_dir_all(&d).ok();
}

fn shared_scene(rel: &str) -> PathBuf {
    PathBuf::from(env!("CARGO_MANIFEST_DIR")).join("../../../shared/scenes").join(rel)
}

#[test]
fn instanced_pines_trace_and_shade_like_copies_merged_into_the_mesh() {
    let pine = shared_scene("scrub-pine/scrubPine.obj");
    let d = dir("instances");
    let toml = format!(
        "[[instances]]\npath = \"{}\"\nscale = [0.01, 0.01, 0.01]\n\
         grid = {{ count = [3, 3], spacing_m = [4.0, 4.0], origin_m = [-4.0, 0.0, -4.0], jitter_m = 1.0, random_yaw = true, scale_range = [0.7, 1.3], seed = 3 }}\n",
        pine.display()
    );
    std::fs::write(d.join("f.toml"), toml).expect("toml");
    let instanced = load_scene(&d.join("f.toml").to_string_lossy()).expect("loads");
    assert_eq!(instanced.instances.len(), 9);
    // The same copies, merged into one mesh by hand.
    let mut merged = instanced.clone();
    (merged.prototypes, merged.instances) = (vec![], vec![]);
    for inst in &instanced.instances {
        let mut copy = instanced.prototypes[inst.prototype as usize].mesh.clone();
        copy.transform(glam::Mat4::from(inst.world_from_local));
        merged.mesh.append(&copy, 0);
    }
    merged.validate().expect("valid");
    assert_eq!(instanced.bounds(), merged.bounds());
    let (a, b) = (
        BvhTracer::for_scene(&instanced, BvhSettings::default()),
        BvhTracer::for_scene(&merged, BvhSettings::default()),
    );
    assert_eq!(a.triangle_count() * 9, b.triangle_count(), "one pine stored, nine drawn");
    assert!(a.cutout_triangle_count() > 0 && a.cutout_triangle_count() * 9 == b.cutout_triangle_count());
    let mut rng = probegi_core::rng::Pcg32::new(5, 2);
    let (mut hits, mut cut_hits, mut mismatches, mut edge_cases) = (0, 0, 0, 0);
    for _ in 0..20_000 {
        let o = Vec3::new(rng.next_f32() * 12.0 - 6.0, rng.next_f32() * 10.0, rng.next_f32() * 12.0 - 6.0);
        let dir = probegi_core::sampling::sample_uniform_sphere(rng.next_vec2());
        let ray = Ray::segment(o, dir, 20.0);
        let (ha, hb) = (a.closest_hit(&ray), b.closest_hit(&ray));
        // Local-space and world-space barycentrics differ in the last bits, so a
        // point on a cutout's edge (coverage within 1e-3 of the cutoff) may go
        // either way: count, do not fail.
        edge_cases += (ha.is_some() != hb.is_some()) as u32 + (a.occluded(&ray) != b.occluded(&ray)) as u32;
        let (Some(ha), Some(hb)) = (ha, hb) else { continue };
        hits += 1;
        if (ha.t - hb.t).abs() > 1e-3 * ha.t.max(1.0) {
            edge_cases += 1;
            continue;
        }
        let (pa, pb) = (instanced.surface_point(&ha), merged.surface_point(&hb));
        assert!(ha.instance < 9 && hb.instance == u32::MAX);
        assert!((pa.position - pb.position).length() < 1e-3, "{} vs {}", pa.position, pb.position);
        // The pine's two levels of detail share coincident bark triangles, so the two
        // BVHs may pick different ones at the same distance: count those, do not fail.
        let same = pa.material == pb.material
            && pa.front_face == pb.front_face
            && pa.shading_normal.dot(pb.shading_normal) > 0.999
            && pa.geometric_normal.dot(pb.geometric_normal) > 0.999
            && (pa.uv - pb.uv).length() < 1e-4;
        mismatches += !same as u32;
        cut_hits += instanced.materials[pa.material as usize].has_cutout() as u32;
    }
    assert!(hits > 2000 && cut_hits > 500, "{hits} hits, {cut_hits} on needles");
    assert!(mismatches * 100 <= hits, "{mismatches} of {hits} hits shade differently");
    assert!(edge_cases <= 20, "{edge_cases} of 20000 rays disagree on hit or occlusion");
    std::fs::remove_dir_all(&d).ok();
}

#[test]
fn mirrored_or_emissive_instances_are_errors() {
    let d = dir("bad-instances");
    std::fs::write(d.join("cube.obj"), format!("mtllib c.mtl\nusemtl lamp\n{CUBE_V}{}", CUBE_F.join("\n")))
        .expect("obj");
    std::fs::write(d.join("c.mtl"), "newmtl lamp\nKe 1 1 1\n").expect("mtl");
    std::fs::write(d.join("plain.obj"), format!("{CUBE_V}{}", CUBE_F.join("\n"))).expect("obj");
    let cases = [
        ("[[instances]]\npath = \"cube.obj\"\ntransforms = [{}]\n", "emits"),
        ("[[instances]]\npath = \"plain.obj\"\ntransforms = [{ scale = [-1.0, 1.0, 1.0] }]\n", "mirrored"),
    ];
    for (k, (toml, why)) in cases.iter().enumerate() {
        let p = d.join(format!("bad{k}.toml"));
        std::fs::write(&p, toml).expect("toml");
        let e = load_scene(&p.to_string_lossy()).expect_err(why).to_string();
        assert!(e.contains(&format!("bad{k}.toml")) && e.contains(why), "{e}");
    }
    std::fs::remove_dir_all(&d).ok();
}
