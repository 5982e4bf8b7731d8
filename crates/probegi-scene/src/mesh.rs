//! Indexed triangle meshes. All scene geometry ends up in one [`Mesh`] so that the
//! tracer's triangle index is the mesh's triangle index.
//!
//! Winding: the front face is the side a counter-clockwise winding faces
//! (`(v1 - v0) × (v2 - v0)`); only the front face of an emissive triangle emits.

use std::collections::HashMap;

use glam::{Mat4, Vec2, Vec3, Vec4};

use crate::material::VertexAttributes;

/// An indexed triangle mesh with per-vertex attributes and a material id per triangle.
#[derive(Clone, Debug, Default)]
pub struct Mesh {
    /// Vertex positions, metres.
    pub positions: Vec<Vec3>,
    /// Unit shading normals, one per vertex.
    pub normals: Vec<Vec3>,
    /// Texture coordinates, one per vertex (`v = 0` at the top of the image).
    pub uvs: Vec<Vec2>,
    /// The second texture coordinate set (glTF `TEXCOORD_1`). Vertices past
    /// its end (meshes without a second set) read `uvs` instead.
    pub uvs1: Vec<Vec2>,
    /// Linear vertex colours (glTF `COLOR_0`'s RGB). Vertices past its end are white.
    pub colors: Vec<Vec3>,
    /// Vertex indices, counter-clockwise seen from the front face.
    pub triangles: Vec<[u32; 3]>,
    /// Index into `Scene::materials`, one per triangle.
    pub triangle_materials: Vec<u32>,
    /// Tangent-space frames for normal maps: unit tangent in xyz, bitangent
    /// sign in w (glTF `TANGENT`: bitangent = w · normal × tangent). Empty, or
    /// one per vertex; a zero tangent means none.
    pub tangents: Vec<Vec4>,
}

/// A position (its coordinates' bits) within a smoothing group.
type PositionInGroup = ([u32; 3], u32);

/// How the shading normals of a triangle's corners are derived by
/// [`Mesh::derive_normals`].
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum NormalSource {
    /// The face (geometric) normal at every corner.
    Flat,
    /// Angle-weighted normals (Thürmer & Wüthrich 1998) of the faces with the
    /// same group that share the corner's position and turn from this face by
    /// at most the crease angle.
    Smooth(u32),
}

impl Mesh {
    /// Number of triangles.
    pub fn triangle_count(&self) -> usize {
        self.triangles.len()
    }

    /// The positions of triangle `tri`'s corners, in winding order.
    pub fn vertices(&self, tri: usize) -> [Vec3; 3] {
        let [a, b, c] = self.triangles[tri];
        [self.positions[a as usize], self.positions[b as usize], self.positions[c as usize]]
    }

    /// Unnormalised counter-clockwise normal; its length is twice the area.
    pub fn face_normal_scaled(&self, tri: usize) -> Vec3 {
        let [a, b, c] = self.vertices(tri);
        (b - a).cross(c - a)
    }

    /// Area of triangle `tri`, square metres.
    pub fn area(&self, tri: usize) -> f32 {
        0.5 * self.face_normal_scaled(tri).length()
    }

    /// Vertex `v`'s second texture coordinate set (its first where it has none).
    pub fn uv1(&self, v: usize) -> Vec2 {
        self.uvs1.get(v).or(self.uvs.get(v)).copied().unwrap_or(Vec2::ZERO)
    }

    /// Vertex `v`'s colour (white where it has none).
    pub fn color(&self, v: usize) -> Vec3 {
        self.colors.get(v).copied().unwrap_or(Vec3::ONE)
    }

    /// The material inputs of vertex `v`.
    pub fn vertex_attributes(&self, v: usize) -> VertexAttributes {
        VertexAttributes { uv: [self.uvs.get(v).copied().unwrap_or(Vec2::ZERO), self.uv1(v)], color: self.color(v) }
    }

    /// The material inputs at barycentric weights `bary` (of corners 0, 1, 2)
    /// inside triangle `tri`.
    pub fn attributes_at(&self, tri: usize, bary: Vec3) -> VertexAttributes {
        let [a, b, c] = self.triangles[tri].map(|v| self.vertex_attributes(v as usize));
        interpolate_attributes([a, b, c], bary)
    }

    /// Appends `other`, shifting its material ids by `material_offset`.
    pub fn append(&mut self, other: &Mesh, material_offset: u32) {
        let base = self.positions.len() as u32;
        self.positions.extend_from_slice(&other.positions);
        self.normals.extend_from_slice(&other.normals);
        self.uvs.extend_from_slice(&other.uvs);
        if !(self.uvs1.is_empty() && other.uvs1.is_empty()) {
            // Fill this mesh's vertices without a second set with their first, then append.
            let from = self.uvs1.len().min(base as usize);
            self.uvs1.truncate(from);
            self.uvs1.extend_from_slice(&self.uvs[from..base as usize]);
            self.uvs1.extend((0..other.positions.len()).map(|v| other.uv1(v)));
        }
        if !(self.colors.is_empty() && other.colors.is_empty()) {
            self.colors.resize(base as usize, Vec3::ONE);
            self.colors.extend((0..other.positions.len()).map(|v| other.color(v)));
        }
        self.triangles.extend(other.triangles.iter().map(|t| [t[0] + base, t[1] + base, t[2] + base]));
        self.triangle_materials.extend(other.triangle_materials.iter().map(|m| m + material_offset));
        if !self.tangents.is_empty() || !other.tangents.is_empty() {
            self.tangents.resize(base as usize, Vec4::ZERO);
            if other.tangents.is_empty() {
                self.tangents.resize(self.positions.len(), Vec4::ZERO);
            } else {
                self.tangents.extend_from_slice(&other.tangents);
            }
        }
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
        let mirror = if world_from_local.determinant() < 0.0 { -1.0 } else { 1.0 };
        for t in &mut self.tangents {
            *t = transformed_tangent(world_from_local, *t, mirror);
        }
        if mirror < 0.0 {
            for t in &mut self.triangles {
                t.swap(1, 2);
            }
        }
    }

    /// Re-derives the shading normals of the corners whose vertex is flagged in
    /// `needs_normal` (all corners when it is empty), triangle `t` by
    /// `sources[t]`; other corners keep theirs. Vertices split where corners
    /// that shared them now differ. Smoothing joins corners by position (equal
    /// coordinates), so UV seams do not crease. `crease_angle_deg` ≥ 180 joins
    /// every face of a group. Tangents of re-derived corners are dropped (glTF
    /// §3.7.2.1: tangents are ignored when normals are computed). Returns the
    /// old vertex of each new vertex.
    pub fn derive_normals(
        &mut self,
        sources: &[NormalSource],
        needs_normal: &[bool],
        crease_angle_deg: f32,
    ) -> Vec<u32> {
        let face: Vec<Vec3> =
            (0..self.triangle_count()).map(|t| self.face_normal_scaled(t).normalize_or_zero()).collect();
        let corner_angle = |t: usize, k: usize| {
            let p = self.vertices(t);
            let e1 = (p[(k + 1) % 3] - p[k]).normalize_or_zero();
            let e2 = (p[(k + 2) % 3] - p[k]).normalize_or_zero();
            e1.dot(e2).clamp(-1.0, 1.0).acos()
        };
        let key = |v: u32, group: u32| {
            let p = self.positions[v as usize];
            ([p.x.to_bits(), p.y.to_bits(), p.z.to_bits()], group)
        };
        // Faces around each (position, group), for the smoothed corners.
        let mut around: HashMap<PositionInGroup, Vec<(u32, f32)>> = HashMap::new();
        for (t, tri) in self.triangles.iter().enumerate() {
            if let NormalSource::Smooth(g) = sources[t] {
                if face[t] == Vec3::ZERO {
                    continue;
                }
                for (k, &v) in tri.iter().enumerate() {
                    around.entry(key(v, g)).or_default().push((t as u32, corner_angle(t, k)));
                }
            }
        }
        let crease_cos = if crease_angle_deg >= 180.0 { -2.0 } else { crease_angle_deg.to_radians().cos() };
        let needs = |v: u32| needs_normal.is_empty() || needs_normal[v as usize];
        let mut corners = Vec::with_capacity(self.triangles.len() * 3);
        for (t, tri) in self.triangles.iter().enumerate() {
            for &v in tri {
                if !needs(v) {
                    corners.push((v, self.normals[v as usize], self.tangents.get(v as usize).copied()));
                    continue;
                }
                let n = match sources[t] {
                    NormalSource::Flat => face[t],
                    NormalSource::Smooth(g) => around
                        .get(&key(v, g))
                        .map(|fs| {
                            fs.iter()
                                .filter(|&&(f, _)| face[f as usize].dot(face[t]) >= crease_cos)
                                .map(|&(f, angle)| face[f as usize] * angle)
                                .sum::<Vec3>()
                                .normalize_or_zero()
                        })
                        .unwrap_or(Vec3::ZERO),
                };
                let n = if n != Vec3::ZERO {
                    n
                } else if face[t] != Vec3::ZERO {
                    face[t]
                } else {
                    Vec3::Y
                };
                corners.push((v, n, None));
            }
        }
        self.reindex(&corners)
    }

    /// MikkTSpace tangents (the `mikktspace` crate; what glTF asks for when a
    /// normal-mapped primitive has no `TANGENT`) for every corner; vertices split
    /// where corners that shared them get different tangents. Returns the old
    /// vertex of each new vertex, or `None` when the algorithm gave up (then
    /// nothing changed).
    pub fn generate_tangents(&mut self) -> Option<Vec<u32>> {
        struct Corners<'a> {
            mesh: &'a Mesh,
            out: Vec<Vec4>,
        }
        impl mikktspace::Geometry for Corners<'_> {
            fn num_faces(&self) -> usize {
                self.mesh.triangles.len()
            }
            fn num_vertices_of_face(&self, _face: usize) -> usize {
                3
            }
            fn position(&self, face: usize, vert: usize) -> [f32; 3] {
                self.mesh.positions[self.mesh.triangles[face][vert] as usize].to_array()
            }
            fn normal(&self, face: usize, vert: usize) -> [f32; 3] {
                self.mesh.normals[self.mesh.triangles[face][vert] as usize].to_array()
            }
            fn tex_coord(&self, face: usize, vert: usize) -> [f32; 2] {
                self.mesh.uvs[self.mesh.triangles[face][vert] as usize].to_array()
            }
            fn set_tangent_encoded(&mut self, tangent: [f32; 4], face: usize, vert: usize) {
                self.out[face * 3 + vert] = Vec4::from_array(tangent);
            }
        }
        let mut c = Corners { mesh: self, out: vec![Vec4::ZERO; self.triangles.len() * 3] };
        if !mikktspace::generate_tangents(&mut c) {
            return None;
        }
        let out = c.out;
        let corners: Vec<(u32, Vec3, Option<Vec4>)> = self
            .triangles
            .iter()
            .enumerate()
            .flat_map(|(t, tri)| (0..3).map(move |k| (t, k, tri[k])))
            .map(|(t, k, v)| {
                let tan = out[t * 3 + k];
                let tan = if tan.is_finite() { tan } else { Vec4::ZERO };
                (v, self.normals[v as usize], Some(tan))
            })
            .collect();
        Some(self.reindex(&corners))
    }

    /// Rebuilds the vertex arrays from per-corner `(old vertex, normal,
    /// tangent)` (three per triangle, in order), sharing a new vertex between
    /// corners with the same old vertex, normal and tangent. New vertices are
    /// numbered in order of first use. Returns the old vertex of each new one.
    fn reindex(&mut self, corners: &[(u32, Vec3, Option<Vec4>)]) -> Vec<u32> {
        let with_tangents = !self.tangents.is_empty() || corners.iter().any(|c| c.2.is_some_and(|t| t != Vec4::ZERO));
        let mut ids: HashMap<(u32, [u32; 3], [u32; 4]), u32> = HashMap::new();
        let (mut positions, mut normals, mut uvs, mut tangents, mut old) = (vec![], vec![], vec![], vec![], vec![]);
        let (mut uvs1, mut colors) = (vec![], vec![]);
        let (with_uvs1, with_colors) = (!self.uvs1.is_empty(), !self.colors.is_empty());
        for (c, tri) in corners.chunks_exact(3).zip(self.triangles.iter_mut()) {
            for (k, &(v, n, tan)) in c.iter().enumerate() {
                let tan = tan.unwrap_or(Vec4::ZERO);
                let id = *ids
                    .entry((v, n.to_array().map(f32::to_bits), tan.to_array().map(f32::to_bits)))
                    .or_insert_with(|| {
                        positions.push(self.positions[v as usize]);
                        uvs.push(self.uvs[v as usize]);
                        let vi = v as usize;
                        if with_uvs1 {
                            uvs1.push(*self.uvs1.get(vi).unwrap_or(&self.uvs[vi]));
                        }
                        if with_colors {
                            colors.push(self.colors.get(vi).copied().unwrap_or(Vec3::ONE));
                        }
                        normals.push(n);
                        tangents.push(tan);
                        old.push(v);
                        (positions.len() - 1) as u32
                    });
                tri[k] = id;
            }
        }
        self.positions = positions;
        self.normals = normals;
        self.uvs = uvs;
        self.uvs1 = uvs1;
        self.colors = colors;
        self.tangents = if with_tangents { tangents } else { vec![] };
        old
    }

    /// Axis-aligned bounds `(min, max)`; `None` for an empty mesh.
    pub fn bounds(&self) -> Option<(Vec3, Vec3)> {
        let first = *self.positions.first()?;
        Some(self.positions.iter().fold((first, first), |(lo, hi), &p| (lo.min(p), hi.max(p))))
    }
}

/// Barycentric blend of three vertices' material inputs.
pub fn interpolate_attributes(v: [VertexAttributes; 3], bary: Vec3) -> VertexAttributes {
    let mix2 = |k: usize| v[0].uv[k] * bary.x + v[1].uv[k] * bary.y + v[2].uv[k] * bary.z;
    VertexAttributes { uv: [mix2(0), mix2(1)], color: v[0].color * bary.x + v[1].color * bary.y + v[2].color * bary.z }
}

/// A tangent under an affine transform: the linear part moves it, and a
/// mirroring transform flips the bitangent sign.
pub(crate) fn transformed_tangent(world_from_local: Mat4, t: Vec4, mirror: f32) -> Vec4 {
    if t == Vec4::ZERO {
        return t;
    }
    let v = world_from_local.transform_vector3(t.truncate()).normalize_or_zero();
    v.extend(if v == Vec3::ZERO { 0.0 } else { t.w * mirror })
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn smoothed_normals_of_a_flat_quad_are_its_face_normal() {
        let mut m = Mesh {
            positions: vec![Vec3::ZERO, Vec3::X, Vec3::new(1.0, 0.0, -1.0), Vec3::NEG_Z],
            uvs: vec![Vec2::ZERO; 4],
            triangles: vec![[0, 1, 2], [0, 2, 3]],
            triangle_materials: vec![0, 0],
            ..Default::default()
        };
        m.derive_normals(&[NormalSource::Smooth(1); 2], &[], 180.0);
        assert_eq!(m.positions.len(), 4, "one smoothing group shares its vertices");
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
            ..Default::default()
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
        m.derive_normals(&[NormalSource::Smooth(1)], &[], 180.0);
        assert!(m.normals.iter().all(|n| n.is_finite() && (n.length() - 1.0).abs() < 1e-6));
    }

    /// A unit cube's 8 shared corners, outward-facing, 12 triangles.
    fn shared_corner_cube() -> Mesh {
        let mut m = Mesh::default();
        crate::shapes::add_box(&mut m, Vec3::ZERO, Vec3::ONE, 0);
        // Weld the box's per-face corners into 8 shared vertices, as an OBJ without vn has them.
        let mut ids: HashMap<[u32; 3], u32> = HashMap::new();
        let mut positions = vec![];
        let remap: Vec<u32> = m
            .positions
            .iter()
            .map(|p| {
                *ids.entry(p.to_array().map(f32::to_bits)).or_insert_with(|| {
                    positions.push(*p);
                    (positions.len() - 1) as u32
                })
            })
            .collect();
        let triangles = m.triangles.iter().map(|t| t.map(|v| remap[v as usize])).collect();
        let n = positions.len();
        Mesh {
            positions,
            normals: vec![Vec3::ZERO; n],
            uvs: vec![Vec2::ZERO; n],
            triangles,
            triangle_materials: m.triangle_materials,
            ..Default::default()
        }
    }

    #[test]
    fn flat_cube_faces_keep_their_face_normal_and_a_crease_splits_smoothing() {
        let base = shared_corner_cube();
        assert_eq!(base.positions.len(), 8);
        let tris = base.triangle_count();
        for (source, crease, vertices) in
            [(NormalSource::Flat, 180.0, 24), (NormalSource::Smooth(1), 60.0, 24), (NormalSource::Smooth(1), 180.0, 8)]
        {
            let mut m = base.clone();
            m.derive_normals(&vec![source; tris], &[], crease);
            assert_eq!(m.positions.len(), vertices, "{source:?} crease {crease}");
            for t in 0..tris {
                let face = m.face_normal_scaled(t).normalize();
                for &v in &m.triangles[t] {
                    let d = m.normals[v as usize].dot(face);
                    if vertices == 24 {
                        assert!(d > 0.9999, "{source:?}: a corner tilts off its face ({d})");
                    } else {
                        // Fully smoothed: every corner normal is the cube diagonal, 54.7° off each face.
                        assert!((d - 1.0 / 3f32.sqrt()).abs() < 1e-4, "{d}");
                    }
                }
            }
        }
        // Two groups on one cube: the top in group 2, the rest in group 1; no normal crosses groups.
        let mut m = base.clone();
        let sources: Vec<NormalSource> = (0..tris)
            .map(|t| if base.face_normal_scaled(t).y > 0.5 { NormalSource::Smooth(2) } else { NormalSource::Smooth(1) })
            .collect();
        m.derive_normals(&sources, &[], 180.0);
        for t in (0..tris).filter(|&t| matches!(sources[t], NormalSource::Smooth(2))) {
            assert!(m.triangles[t].iter().all(|&v| (m.normals[v as usize] - Vec3::Y).length() < 1e-5));
        }
    }

    #[test]
    fn second_uv_sets_and_colours_survive_appends_and_vertex_splits() {
        let tri = |uv1: Vec<Vec2>, colors: Vec<Vec3>| Mesh {
            positions: vec![Vec3::ZERO, Vec3::X, Vec3::Y],
            normals: vec![Vec3::Z; 3],
            uvs: vec![Vec2::new(0.1, 0.0), Vec2::new(0.2, 0.0), Vec2::new(0.3, 0.0)],
            uvs1: uv1,
            colors,
            triangles: vec![[0, 1, 2]],
            triangle_materials: vec![0],
            ..Default::default()
        };
        let mut m = tri(vec![], vec![]);
        m.append(&tri(vec![Vec2::splat(0.5); 3], vec![Vec3::new(1.0, 0.0, 0.0); 3]), 0);
        m.append(&tri(vec![], vec![]), 0);
        assert_eq!((m.uvs1.len(), m.colors.len()), (9, 9));
        assert_eq!((m.uv1(1), m.color(1)), (Vec2::new(0.2, 0.0), Vec3::ONE), "no second set: the first");
        assert_eq!((m.uv1(4), m.color(4)), (Vec2::splat(0.5), Vec3::X));
        assert_eq!((m.uv1(8), m.color(8)), (Vec2::new(0.3, 0.0), Vec3::ONE));
        let centre = m.attributes_at(1, Vec3::splat(1.0 / 3.0));
        assert!((centre.uv[1] - Vec2::splat(0.5)).length() < 1e-6 && (centre.color - Vec3::X).length() < 1e-6);
        // Flat normals on a mesh of shared corners split vertices; the attributes follow them.
        m.triangles[1] = [0, 4, 5];
        m.derive_normals(&[NormalSource::Flat; 3], &[], 180.0);
        assert_eq!((m.uvs1.len(), m.colors.len()), (m.positions.len(), m.positions.len()));
        let v = m.triangles[1][1] as usize;
        assert_eq!((m.uv1(v), m.color(v)), (Vec2::splat(0.5), Vec3::X));
    }

    #[test]
    fn mikktspace_tangents_follow_u_on_a_plane_and_flip_sign_when_v_is_mirrored() {
        for (v_sign, w) in [(1.0f32, 1.0f32), (-1.0, -1.0)] {
            let mut m = Mesh {
                positions: vec![Vec3::ZERO, Vec3::X, Vec3::new(1.0, 0.0, -1.0), Vec3::NEG_Z],
                normals: vec![Vec3::Y; 4],
                uvs: vec![Vec2::ZERO, Vec2::new(1.0, 0.0), Vec2::new(1.0, v_sign), Vec2::new(0.0, v_sign)],
                triangles: vec![[0, 1, 2], [0, 2, 3]],
                triangle_materials: vec![0, 0],
                ..Default::default()
            };
            m.generate_tangents().expect("mikktspace");
            assert_eq!(m.tangents.len(), m.positions.len());
            for t in &m.tangents {
                assert!((t.truncate() - Vec3::X).length() < 1e-5 && t.w == w, "{t} for v sign {v_sign}");
            }
        }
    }
}
