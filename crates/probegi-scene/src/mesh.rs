//! Indexed triangle meshes. All scene geometry ends up in one [`Mesh`] so that the
//! tracer's triangle index is the mesh's triangle index.
//!
//! Winding: the front face is the side a counter-clockwise winding faces
//! (`(v1 - v0) × (v2 - v0)`); only the front face of an emissive triangle emits.

use glam::{Mat4, Vec2, Vec3};

#[derive(Clone, Debug, Default)]
pub struct Mesh {
    pub positions: Vec<Vec3>,
    /// Unit shading normals, one per vertex.
    pub normals: Vec<Vec3>,
    /// Texture coordinates, one per vertex (`v = 0` at the top of the image).
    pub uvs: Vec<Vec2>,
    pub triangles: Vec<[u32; 3]>,
    /// Index into `Scene::materials`, one per triangle.
    pub triangle_materials: Vec<u32>,
}

impl Mesh {
    pub fn triangle_count(&self) -> usize {
        self.triangles.len()
    }

    pub fn vertices(&self, tri: usize) -> [Vec3; 3] {
        let [a, b, c] = self.triangles[tri];
        [self.positions[a as usize], self.positions[b as usize], self.positions[c as usize]]
    }

    /// Unnormalised counter-clockwise normal; its length is twice the area.
    pub fn face_normal_scaled(&self, tri: usize) -> Vec3 {
        let [a, b, c] = self.vertices(tri);
        (b - a).cross(c - a)
    }

    pub fn area(&self, tri: usize) -> f32 {
        0.5 * self.face_normal_scaled(tri).length()
    }

    /// Appends `other`, shifting its material ids by `material_offset`.
    pub fn append(&mut self, other: &Mesh, material_offset: u32) {
        let base = self.positions.len() as u32;
        self.positions.extend_from_slice(&other.positions);
        self.normals.extend_from_slice(&other.normals);
        self.uvs.extend_from_slice(&other.uvs);
        self.triangles.extend(other.triangles.iter().map(|t| [t[0] + base, t[1] + base, t[2] + base]));
        self.triangle_materials.extend(other.triangle_materials.iter().map(|m| m + material_offset));
    }

    /// Applies an affine transform; normals use the inverse transpose. A mirroring
    /// transform flips the winding so that front faces stay front faces.
    pub fn transform(&mut self, world_from_local: Mat4) {
        let normal_matrix = glam::Mat3::from_mat4(world_from_local).inverse().transpose();
        for p in &mut self.positions {
            *p = world_from_local.transform_point3(*p);
        }
        for n in &mut self.normals {
            *n = (normal_matrix * *n).normalize_or_zero();
        }
        if world_from_local.determinant() < 0.0 {
            for t in &mut self.triangles {
                t.swap(1, 2);
            }
        }
    }

    /// Angle-weighted vertex normals (Thürmer & Wüthrich 1998) from the faces that
    /// share each vertex, for vertices flagged in `needs_normal` — what Mitsuba
    /// does for meshes without normals. Degenerate faces contribute nothing; a vertex
    /// with no usable face gets +Y so that no NaN escapes.
    pub fn generate_normals(&mut self, needs_normal: &[bool]) {
        let mut acc = vec![Vec3::ZERO; self.positions.len()];
        for t in &self.triangles {
            let p = [self.positions[t[0] as usize], self.positions[t[1] as usize], self.positions[t[2] as usize]];
            let n = (p[1] - p[0]).cross(p[2] - p[0]).normalize_or_zero();
            if n == Vec3::ZERO {
                continue;
            }
            for k in 0..3 {
                let v = t[k] as usize;
                if !needs_normal[v] {
                    continue;
                }
                let e1 = (p[(k + 1) % 3] - p[k]).normalize_or_zero();
                let e2 = (p[(k + 2) % 3] - p[k]).normalize_or_zero();
                let angle = e1.dot(e2).clamp(-1.0, 1.0).acos();
                acc[v] += n * angle;
            }
        }
        self.normals.resize(self.positions.len(), Vec3::Y);
        for (v, a) in acc.into_iter().enumerate() {
            if needs_normal[v] {
                let n = a.normalize_or_zero();
                self.normals[v] = if n == Vec3::ZERO { Vec3::Y } else { n };
            }
        }
    }

    /// Axis-aligned bounds `(min, max)`; `None` for an empty mesh.
    pub fn bounds(&self) -> Option<(Vec3, Vec3)> {
        let first = *self.positions.first()?;
        Some(self.positions.iter().fold((first, first), |(lo, hi), &p| (lo.min(p), hi.max(p))))
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn generated_normals_of_a_flat_quad_are_its_face_normal() {
        let mut m = Mesh {
            positions: vec![Vec3::ZERO, Vec3::X, Vec3::new(1.0, 0.0, -1.0), Vec3::NEG_Z],
            uvs: vec![Vec2::ZERO; 4],
            triangles: vec![[0, 1, 2], [0, 2, 3]],
            triangle_materials: vec![0, 0],
            ..Default::default()
        };
        m.generate_normals(&[true; 4]);
        for n in &m.normals {
            assert!((*n - Vec3::Y).length() < 1e-6, "{n}");
        }
    }

    #[test]
    fn mirroring_transform_keeps_front_faces() {
        let mut m = Mesh {
            positions: vec![Vec3::ZERO, Vec3::X, Vec3::Y],
            normals: vec![Vec3::Z; 3],
            uvs: vec![Vec2::ZERO; 3],
            triangles: vec![[0, 1, 2]],
            triangle_materials: vec![0],
        };
        m.transform(Mat4::from_scale(Vec3::new(1.0, 1.0, -1.0)));
        // The face normal followed the shading normal to -Z.
        assert!(m.face_normal_scaled(0).normalize().dot(m.normals[0]) > 0.99);
        assert!((m.normals[0] - Vec3::NEG_Z).length() < 1e-6);
    }

    #[test]
    fn degenerate_faces_do_not_produce_nan_normals() {
        let mut m = Mesh {
            positions: vec![Vec3::ZERO, Vec3::ZERO, Vec3::ZERO],
            uvs: vec![Vec2::ZERO; 3],
            triangles: vec![[0, 1, 2]],
            triangle_materials: vec![0],
            ..Default::default()
        };
        m.generate_normals(&[true; 3]);
        assert!(m.normals.iter().all(|n| n.is_finite() && (n.length() - 1.0).abs() < 1e-6));
    }
}
