//! Scenes compiled into the binary, named on the command line as `builtin:NAME`.
//!
//! `color-bleed`, `door-room`, `flood-room`, `sponza-sun`, `forest`: the seeds' test scenes,
//! defined once as scene files in `scenes/builtin/` and compiled in.
//!
//! `cornell-box`: the geometry and materials of McGuire's CornellBox-Original.obj
//! (Cardenas & McGuire 2011, after the Cornell measurements; public domain):
//! the same vertices, windings and Kd/Ke values (area light Ke = 17 12 4), with
//! the default camera of the foundation issue. One deliberate difference: the
//! OBJ's two "Bottom Face" records reuse the vertices of an earlier side face
//! (an indexing slip in the file); here they are the real bottoms, which lie on
//! the floor and are never visible.

use glam::Vec3;
use probegi_core::camera::Camera;

use crate::error::{Result, SceneError};
use crate::material::Material;
use crate::mesh::Mesh;
use crate::scene::Scene;
pub use crate::shapes::{add_box, add_polygon, add_room};

/// Every name `builtin:NAME` accepts.
pub const BUILTIN_NAMES: &[&str] =
    &["cornell-box", "furnace-box", "color-bleed", "door-room", "flood-room", "sponza-sun", "forest", "shadow-box"];

/// The seeds' test scenes (dynamic-scenes issue), compiled in from the scene files
/// in `scenes/builtin/`, so `builtin:NAME` and the file are the same scene.
const SCENE_FILES: &[(&str, &str)] = &[
    ("color-bleed", include_str!("../../../scenes/builtin/color-bleed.toml")),
    ("door-room", include_str!("../../../scenes/builtin/door-room.toml")),
    ("flood-room", include_str!("../../../scenes/builtin/flood-room.toml")),
    ("sponza-sun", include_str!("../../../scenes/builtin/sponza-sun.toml")),
    ("forest", include_str!("../../../scenes/builtin/forest.toml")),
    ("shadow-box", include_str!("../../../scenes/builtin/shadow-box.toml")),
];

/// The built-in scene `name` (without the `builtin:` prefix); an error listing
/// [`BUILTIN_NAMES`] for an unknown one.
pub fn load_builtin(name: &str) -> Result<Scene> {
    match name {
        "cornell-box" => Ok(cornell_box()),
        "furnace-box" => Ok(furnace_box(0.5, 1.0)),
        _ => match SCENE_FILES.iter().find(|(n, _)| *n == name) {
            Some((_, text)) => {
                let label = std::path::PathBuf::from(format!("builtin:{name}"));
                let mut scene = crate::scene_file::parse_scene_file(text, &label, std::path::Path::new("."))?;
                scene.name = format!("builtin:{name}");
                Ok(scene)
            }
            None => Err(SceneError::UnknownBuiltin { name: name.to_string(), available: BUILTIN_NAMES.join(", ") }),
        },
    }
}

fn v(x: f32, y: f32, z: f32) -> Vec3 {
    Vec3::new(x, y, z)
}

/// `builtin:cornell-box`: CornellBox-Original (see the module doc) with the default camera.
pub fn cornell_box() -> Scene {
    let white = Vec3::new(0.725, 0.71, 0.68);
    let materials = vec![
        Material::diffuse("leftWall", Vec3::new(0.63, 0.065, 0.05)),
        Material::diffuse("rightWall", Vec3::new(0.14, 0.45, 0.091)),
        Material::diffuse("floor", white),
        Material::diffuse("ceiling", white),
        Material::diffuse("backWall", white),
        Material::diffuse("shortBox", white),
        Material::diffuse("tallBox", white),
        Material::emissive("light", Vec3::splat(0.78), Vec3::new(17.0, 12.0, 4.0)),
    ];
    let (left, right, floor, ceiling, back, short_box, tall_box, light) = (0, 1, 2, 3, 4, 5, 6, 7);
    let mut m = Mesh::default();
    add_polygon(&mut m, &[v(-1.01, 0.0, 0.99), v(1.0, 0.0, 0.99), v(1.0, 0.0, -1.04), v(-0.99, 0.0, -1.04)], floor);
    add_polygon(
        &mut m,
        &[v(-1.02, 1.99, 0.99), v(-1.02, 1.99, -1.04), v(1.0, 1.99, -1.04), v(1.0, 1.99, 0.99)],
        ceiling,
    );
    add_polygon(&mut m, &[v(-0.99, 0.0, -1.04), v(1.0, 0.0, -1.04), v(1.0, 1.99, -1.04), v(-1.02, 1.99, -1.04)], back);
    add_polygon(&mut m, &[v(1.0, 0.0, -1.04), v(1.0, 0.0, 0.99), v(1.0, 1.99, 0.99), v(1.0, 1.99, -1.04)], right);
    add_polygon(
        &mut m,
        &[v(-1.01, 0.0, 0.99), v(-0.99, 0.0, -1.04), v(-1.02, 1.99, -1.04), v(-1.02, 1.99, 0.99)],
        left,
    );
    // Short box: top, left, front, right, back, bottom.
    let sb = [
        [v(0.53, 0.6, 0.75), v(0.7, 0.6, 0.17), v(0.13, 0.6, 0.0), v(-0.05, 0.6, 0.57)],
        [v(-0.05, 0.0, 0.57), v(-0.05, 0.6, 0.57), v(0.13, 0.6, 0.0), v(0.13, 0.0, 0.0)],
        [v(0.53, 0.0, 0.75), v(0.53, 0.6, 0.75), v(-0.05, 0.6, 0.57), v(-0.05, 0.0, 0.57)],
        [v(0.7, 0.0, 0.17), v(0.7, 0.6, 0.17), v(0.53, 0.6, 0.75), v(0.53, 0.0, 0.75)],
        [v(0.13, 0.0, 0.0), v(0.13, 0.6, 0.0), v(0.7, 0.6, 0.17), v(0.7, 0.0, 0.17)],
        [v(0.53, 0.0, 0.75), v(0.7, 0.0, 0.17), v(0.13, 0.0, 0.0), v(-0.05, 0.0, 0.57)],
    ];
    for q in &sb {
        add_polygon(&mut m, q, short_box);
    }
    // Tall box: top, left, back, right, front, bottom.
    let tb = [
        [v(-0.53, 1.2, 0.09), v(0.04, 1.2, -0.09), v(-0.14, 1.2, -0.67), v(-0.71, 1.2, -0.49)],
        [v(-0.53, 0.0, 0.09), v(-0.53, 1.2, 0.09), v(-0.71, 1.2, -0.49), v(-0.71, 0.0, -0.49)],
        [v(-0.71, 0.0, -0.49), v(-0.71, 1.2, -0.49), v(-0.14, 1.2, -0.67), v(-0.14, 0.0, -0.67)],
        [v(-0.14, 0.0, -0.67), v(-0.14, 1.2, -0.67), v(0.04, 1.2, -0.09), v(0.04, 0.0, -0.09)],
        [v(0.04, 0.0, -0.09), v(0.04, 1.2, -0.09), v(-0.53, 1.2, 0.09), v(-0.53, 0.0, 0.09)],
        [v(-0.53, 0.0, 0.09), v(0.04, 0.0, -0.09), v(-0.14, 0.0, -0.67), v(-0.71, 0.0, -0.49)],
    ];
    for q in &tb {
        add_polygon(&mut m, q, tall_box);
    }
    add_polygon(
        &mut m,
        &[v(-0.24, 1.98, 0.16), v(-0.24, 1.98, -0.22), v(0.23, 1.98, -0.22), v(0.23, 1.98, 0.16)],
        light,
    );
    Scene {
        name: "builtin:cornell-box".into(),
        mesh: m,
        materials,
        camera: Some(Camera::default()),
        ..Default::default()
    }
}

/// A closed axis-aligned box of side 2 m centred at (0,1,0) whose every face has
/// diffuse albedo `albedo` and emits `emission` inward: the white furnace, where
/// radiance everywhere is `emission / (1 - albedo)`. The camera sits inside.
pub fn furnace_box(albedo: f32, emission: f32) -> Scene {
    let mut m = Mesh::default();
    let (lo, hi) = (v(-1.0, 0.0, -1.0), v(1.0, 2.0, 1.0));
    let c = |x: bool, y: bool, z: bool| {
        v(if x { hi.x } else { lo.x }, if y { hi.y } else { lo.y }, if z { hi.z } else { lo.z })
    };
    // Each face wound so that its counter-clockwise normal points into the box.
    let faces = [
        [c(false, false, false), c(false, false, true), c(true, false, true), c(true, false, false)], // floor, +y
        [c(false, true, false), c(true, true, false), c(true, true, true), c(false, true, true)],     // ceiling, -y
        [c(false, false, false), c(true, false, false), c(true, true, false), c(false, true, false)], // back, +z
        [c(false, false, true), c(false, true, true), c(true, true, true), c(true, false, true)],     // front, -z
        [c(false, false, false), c(false, true, false), c(false, true, true), c(false, false, true)], // left, +x
        [c(true, false, false), c(true, false, true), c(true, true, true), c(true, true, false)],     // right, -x
    ];
    for f in &faces {
        add_polygon(&mut m, f, 0);
    }
    Scene {
        name: "builtin:furnace-box".into(),
        mesh: m,
        materials: vec![Material::emissive("furnace", Vec3::splat(albedo), Vec3::splat(emission))],
        camera: Some(Camera { position: v(0.0, 1.0, 0.5), target: v(0.0, 1.0, -1.0), up: Vec3::Y, fov_y_deg: 90.0 }),
        ..Default::default()
    }
}

/// A tracking-window test world: a 60 m × 20 m ground plane (x from −10 to 50)
/// under a sky of radiance 1, roofed by a 0.2 m slab at y = 3 for x < 20 and
/// open beyond, so probes under the roof and in the open differ by the roof's
/// contrast (a stale probe that scrolled out from under the roof shows).
pub fn half_roofed_ground() -> Scene {
    let mut scene = Scene {
        materials: vec![Material::diffuse("ground", Vec3::splat(0.5))],
        sky_radiance: Vec3::splat(1.0),
        ..Default::default()
    };
    add_polygon(
        &mut scene.mesh,
        &[
            Vec3::new(-10.0, 0.0, -10.0),
            Vec3::new(-10.0, 0.0, 10.0),
            Vec3::new(50.0, 0.0, 10.0),
            Vec3::new(50.0, 0.0, -10.0),
        ],
        0,
    );
    add_box(&mut scene.mesh, Vec3::new(-10.0, 3.0, -10.0), Vec3::new(20.0, 3.2, 10.0), 0);
    scene
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn furnace_faces_point_inward() {
        let s = furnace_box(0.5, 1.0);
        for t in 0..s.mesh.triangle_count() {
            let [a, b, c] = s.mesh.vertices(t);
            let centroid = (a + b + c) / 3.0;
            let n = s.mesh.face_normal_scaled(t);
            assert!(n.dot(v(0.0, 1.0, 0.0) - centroid) > 0.0, "triangle {t} faces out");
        }
    }

    #[test]
    fn cornell_light_faces_down_and_walls_face_in() {
        let s = cornell_box();
        assert!(s.validate().is_ok());
        let light_tris: Vec<usize> =
            (0..s.mesh.triangle_count()).filter(|&t| s.mesh.triangle_materials[t] == 7).collect();
        assert_eq!(light_tris.len(), 2);
        for t in light_tris {
            assert!(s.mesh.face_normal_scaled(t).normalize().y < -0.99);
        }
        assert_eq!(s.mesh.triangle_count(), 36);
    }
}
