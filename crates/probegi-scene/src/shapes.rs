//! Mesh-building helpers for hand-made geometry (built-in scenes, scene-file
//! objects, tests): planar polygons, outward boxes and inward rooms.

use glam::Vec3;

use crate::mesh::Mesh;

/// Adds a planar polygon (fan-triangulated, winding as given) with flat normals.
pub fn add_polygon(mesh: &mut Mesh, corners: &[Vec3], material: u32) {
    let base = mesh.positions.len() as u32;
    let n = (corners[1] - corners[0]).cross(corners[2] - corners[0]).normalize_or_zero();
    for &c in corners {
        mesh.positions.push(c);
        mesh.normals.push(n);
        mesh.uvs.push(glam::Vec2::ZERO);
    }
    for k in 1..corners.len() as u32 - 1 {
        mesh.triangles.push([base, base + k, base + k + 1]);
        mesh.triangle_materials.push(material);
    }
}

/// Adds an axis-aligned box `[lo, hi]` whose faces point outward (a solid object).
pub fn add_box(mesh: &mut Mesh, lo: Vec3, hi: Vec3, material: u32) {
    let c = |x: bool, y: bool, z: bool| {
        Vec3::new(if x { hi.x } else { lo.x }, if y { hi.y } else { lo.y }, if z { hi.z } else { lo.z })
    };
    let faces = [
        [c(false, false, false), c(true, false, false), c(true, false, true), c(false, false, true)], // -y
        [c(false, true, false), c(false, true, true), c(true, true, true), c(true, true, false)],     // +y
        [c(false, false, false), c(false, true, false), c(true, true, false), c(true, false, false)], // -z
        [c(false, false, true), c(true, false, true), c(true, true, true), c(false, true, true)],     // +z
        [c(false, false, false), c(false, false, true), c(false, true, true), c(false, true, false)], // -x
        [c(true, false, false), c(true, true, false), c(true, true, true), c(true, false, true)],     // +x
    ];
    for f in &faces {
        add_polygon(mesh, f, material);
    }
}

/// Adds an axis-aligned box `[lo, hi]` whose faces point inward (a room seen
/// from inside; probes outside it see back faces).
pub fn add_room(mesh: &mut Mesh, lo: Vec3, hi: Vec3, material: u32) {
    let (t0, v0) = (mesh.triangles.len(), mesh.positions.len());
    add_box(mesh, lo, hi, material);
    mesh.triangles[t0..].iter_mut().for_each(|t| t.swap(1, 2));
    mesh.normals[v0..].iter_mut().for_each(|n| *n = -*n);
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn box_faces_point_outward() {
        let mut m = Mesh::default();
        add_box(&mut m, Vec3::ZERO, Vec3::ONE, 0);
        assert_eq!(m.triangle_count(), 12);
        for t in 0..12 {
            let [a, b, c] = m.vertices(t);
            assert!(m.face_normal_scaled(t).dot((a + b + c) / 3.0 - Vec3::splat(0.5)) > 0.0, "triangle {t}");
        }
    }
}
