//! Triangle meshes with per-vertex attributes and per-triangle materials.

use std::sync::Arc;

use glam::{Affine3A, Mat3, Vec2, Vec3};
use rayon::prelude::*;

use crate::bounds::Aabb;

/// An RGB image used as a material's diffuse texture, stored as linear `[0, 1]` floats.
#[derive(Debug, Clone, PartialEq)]
pub struct TextureImage {
    pub width: u32,
    pub height: u32,
    pub texels: Vec<Vec3>,
}

/// The largest material texture edge read, texels: a texture is held as three 4-byte
/// floats a texel, so 4096² is 200 MB; a larger (or a forged) image is refused before
/// it is decoded.
pub const MAX_TEXTURE_EDGE: u32 = 4096;

impl TextureImage {
    /// The PNG or JPEG image in `bytes`, refused (with the decoder's reason) past
    /// [`MAX_TEXTURE_EDGE`] a side or when it cannot be read.
    pub fn decode(bytes: &[u8]) -> std::result::Result<TextureImage, String> {
        let mut limits = image::Limits::default();
        limits.max_image_width = Some(MAX_TEXTURE_EDGE);
        limits.max_image_height = Some(MAX_TEXTURE_EDGE);
        // (The decoder's own buffers: at most the RGBA bytes of the largest image.)
        limits.max_alloc = Some(4 * u64::from(MAX_TEXTURE_EDGE).pow(2));
        let mut reader = image::ImageReader::new(std::io::Cursor::new(bytes))
            .with_guessed_format()
            .map_err(|e| e.to_string())?;
        reader.limits(limits);
        let image = reader.decode().map_err(|e| e.to_string())?;
        Ok(TextureImage::from_rgb8(&image.to_rgb8()))
    }

    /// An 8-bit RGB image's texels, each channel over 255.
    fn from_rgb8(image: &image::RgbImage) -> TextureImage {
        TextureImage {
            width: image.width(),
            height: image.height(),
            texels: image
                .pixels()
                .map(|p| Vec3::new(p[0] as f32, p[1] as f32, p[2] as f32) / 255.0)
                .collect(),
        }
    }

    /// Bilinear lookup with wrap-around addressing; `uv = (0, 0)` is the bottom-left
    /// corner, as in OBJ.
    pub fn sample(&self, uv: Vec2) -> Vec3 {
        if self.texels.is_empty() || !uv.is_finite() {
            return Vec3::ONE;
        }
        let (w, h) = (self.width as f32, self.height as f32);
        let x = uv.x.rem_euclid(1.0) * w - 0.5;
        let y = (1.0 - uv.y.rem_euclid(1.0)) * h - 0.5;
        let (x0, y0) = (x.floor(), y.floor());
        let (fx, fy) = (x - x0, y - y0);
        let wrap = |v: f32, n: u32| (v as i64).rem_euclid(n as i64) as usize;
        let (xa, xb) = (wrap(x0, self.width), wrap(x0 + 1.0, self.width));
        let (ya, yb) = (wrap(y0, self.height), wrap(y0 + 1.0, self.height));
        let at = |x: usize, y: usize| self.texels[y * self.width as usize + x];
        let top = at(xa, ya).lerp(at(xb, ya), fx);
        let bottom = at(xa, yb).lerp(at(xb, yb), fx);
        top.lerp(bottom, fy)
    }
}

/// A surface's diffuse reflectance: a colour, optionally modulated by a texture.
#[derive(Debug, Clone, PartialEq)]
pub struct Material {
    pub name: String,
    /// Linear RGB albedo in `[0, 1]`.
    pub diffuse: Vec3,
    pub diffuse_texture: Option<Arc<TextureImage>>,
}

impl Default for Material {
    fn default() -> Self {
        Material {
            name: "default".into(),
            diffuse: Vec3::splat(0.8),
            diffuse_texture: None,
        }
    }
}

/// Most triangles a mesh may have (the ray tracer packs triangle indices in 27 bits).
pub const MAX_TRIANGLES: usize = (1 << 27) - 1;

/// An indexed triangle mesh.
///
/// Attribute arrays are indexed like `positions`. A zero vertex normal means "none":
/// shading then falls back to the triangle's geometric normal.
#[derive(Debug, Clone, Default)]
pub struct Mesh {
    pub positions: Vec<Vec3>,
    pub normals: Option<Vec<Vec3>>,
    pub texcoords: Option<Vec<Vec2>>,
    pub triangles: Vec<[u32; 3]>,
    /// Index into `materials` per triangle; `None` means material 0 for all.
    pub triangle_materials: Option<Vec<u16>>,
    /// At least one material.
    pub materials: Vec<Material>,
}

/// An open mesh is taken for leaves or sheets, and its textures asked in perspective
/// (the client's `projection_for`), when more than this share of its edges bound one triangle
/// only. The tree's rim is 67 % of its edges; the rock's (its seams unwelded) 0.5 %,
/// the scanned bunny's (a few holes) 0.2 %: orthographic, they came 0.7–1.2 dB and
/// 0.6 dB nearer geometry's median in the demo than in perspective, and their worst
/// frames 2.5–3 dB and 5 dB nearer. A sheet of N × N cells has a rim of about 4/(3N)
/// of its edges: one cut finer than about 27 × 27 cells counts as a solid here.
pub const SHEET_RIM_SHARE: f32 = 0.05;

/// How a mesh's edges are shared ([`Mesh::edge_census`]).
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct EdgeCensus {
    /// Every edge shared by exactly two triangles.
    pub closed: bool,
    /// The share of edges that bound one triangle only: the rim of an open surface.
    /// About 4/(3N) for a sheet of N × N cells, 0.67 for the default scene's tree (its
    /// leaves), near 0 for a solid with a few holes.
    pub rim_share: f32,
}

impl EdgeCensus {
    /// Whether the mesh is taken for leaves or sheets: more than [`SHEET_RIM_SHARE`] of
    /// its edges bound one triangle only. (Then its faces' winding says nothing of which
    /// way they look: it is drawn from both sides.)
    pub fn is_sheets(&self) -> bool {
        self.rim_share > SHEET_RIM_SHARE
    }
}

/// What makes a mesh unusable; vertices and triangles are counted from 1.
#[derive(Debug, Clone, PartialEq, Eq, thiserror::Error)]
pub enum MeshError {
    #[error("the mesh has no triangles")]
    NoTriangles,
    #[error("the mesh has {0} triangles; at most {MAX_TRIANGLES} are supported")]
    TooManyTriangles(usize),
    #[error("the mesh has no material")]
    NoMaterial,
    #[error("vertex {vertex} has a non-finite position")]
    NonFinitePosition { vertex: usize },
    #[error("normal count differs from vertex count")]
    NormalCount,
    #[error("texture-coordinate count differs from vertex count")]
    TexcoordCount,
    #[error("triangle {triangle} refers to a vertex that does not exist")]
    MissingVertex { triangle: usize },
    #[error("material-id count differs from triangle count")]
    MaterialIdCount,
    #[error("a triangle refers to a material that does not exist")]
    MissingMaterial,
    #[error("the mesh would have {0} materials; at most {max} are supported", max = u16::MAX)]
    TooManyMaterials(usize),
    #[error("the mesh would have {0} vertices; at most {max} are supported", max = u32::MAX)]
    TooManyVertices(usize),
}

impl Mesh {
    pub fn triangle_count(&self) -> usize {
        self.triangles.len()
    }

    /// Normals as a file gave them, made unit — a non-finite or zero one means "none
    /// here" (zero): shading falls back to the face normal. Every loader calls this.
    pub(crate) fn settle_normals(&mut self) {
        for n in self.normals.iter_mut().flatten() {
            *n = if n.is_finite() {
                n.normalize_or_zero()
            } else {
                Vec3::ZERO
            };
        }
    }

    /// Checks index ranges, attribute lengths and finiteness; the error says what is wrong.
    pub fn validate(&self) -> Result<(), MeshError> {
        if self.triangles.is_empty() {
            return Err(MeshError::NoTriangles);
        }
        if self.triangles.len() > MAX_TRIANGLES {
            return Err(MeshError::TooManyTriangles(self.triangles.len()));
        }
        if self.materials.is_empty() {
            return Err(MeshError::NoMaterial);
        }
        let n = self.positions.len();
        if let Some(i) = self.positions.iter().position(|p| !p.is_finite()) {
            return Err(MeshError::NonFinitePosition { vertex: i + 1 });
        }
        if let Some(normals) = &self.normals
            && normals.len() != n
        {
            return Err(MeshError::NormalCount);
        }
        if let Some(uv) = &self.texcoords
            && uv.len() != n
        {
            return Err(MeshError::TexcoordCount);
        }
        if let Some(t) = self
            .triangles
            .iter()
            .position(|t| t.iter().any(|&i| i as usize >= n))
        {
            return Err(MeshError::MissingVertex { triangle: t + 1 });
        }
        if let Some(ids) = &self.triangle_materials {
            if ids.len() != self.triangles.len() {
                return Err(MeshError::MaterialIdCount);
            }
            if ids.iter().any(|&m| m as usize >= self.materials.len()) {
                return Err(MeshError::MissingMaterial);
            }
        }
        Ok(())
    }

    /// Whether the mesh is closed: every edge is shared by exactly two triangles, so it
    /// bounds a solid and no back face of it can show from outside (see
    /// [`Mesh::edge_census`]).
    pub fn is_closed(&self) -> bool {
        self.edge_census().closed
    }

    /// How the mesh's edges are shared between its triangles. Vertices within a
    /// millionth of the mesh's size of one another count as one (a generator's faces
    /// may each keep their own copy of a seam, a rounding apart); a mesh whose seams do
    /// not meet counts as open, the safe answer.
    pub fn edge_census(&self) -> EdgeCensus {
        let bounds = self.bounds();
        let cell = (bounds.extent().length() * 1e-6).max(f32::MIN_POSITIVE);
        let key = |p: Vec3| ((p - bounds.min) / cell).round().to_array().map(|c| c as i64);
        let mut canonical: std::collections::HashMap<[i64; 3], u32> =
            std::collections::HashMap::with_capacity(self.positions.len());
        let ids: Vec<u32> = self
            .positions
            .iter()
            .enumerate()
            .map(|(k, &p)| *canonical.entry(key(p)).or_insert(k as u32))
            .collect();
        let mut edges: Vec<u64> = self
            .triangles
            .iter()
            .map(|t| t.map(|v| ids.get(v as usize).copied().unwrap_or(v)))
            .flat_map(|[a, b, c]| [(a, b), (b, c), (c, a)])
            .map(|(p, q)| (u64::from(p.min(q)) << 32) | u64::from(p.max(q)))
            .collect();
        edges.par_sort_unstable();
        let (mut distinct, mut rim, mut paired) = (0usize, 0usize, 0usize);
        for shared in edges.chunk_by(|x, y| x == y) {
            distinct += 1;
            rim += usize::from(shared.len() == 1);
            paired += usize::from(shared.len() == 2);
        }
        EdgeCensus {
            closed: distinct > 0 && paired == distinct,
            rim_share: if distinct == 0 {
                0.0
            } else {
                rim as f32 / distinct as f32
            },
        }
    }

    /// A box, `size` along each axis, its centre at `centre`: 12 triangles wound
    /// anticlockwise seen from outside (normals outwards), one default material.
    pub fn cuboid(size: Vec3, centre: Vec3) -> Mesh {
        let h = size * 0.5;
        let corner = |i: u32| {
            centre
                + Vec3::new(
                    if i & 1 == 0 { -h.x } else { h.x },
                    if i & 2 == 0 { -h.y } else { h.y },
                    if i & 4 == 0 { -h.z } else { h.z },
                )
        };
        let quads = [
            [0, 4, 6, 2],
            [1, 3, 7, 5],
            [0, 1, 5, 4],
            [2, 6, 7, 3],
            [0, 2, 3, 1],
            [4, 5, 7, 6],
        ];
        Mesh {
            positions: (0..8).map(corner).collect(),
            triangles: quads
                .iter()
                .flat_map(|&[a, b, c, d]| [[a, b, c], [a, c, d]])
                .collect(),
            materials: vec![Material::default()],
            ..Default::default()
        }
    }

    /// Bounds of the vertices that triangles use.
    pub fn bounds(&self) -> Aabb {
        let mut b = Aabb::EMPTY;
        for t in &self.triangles {
            for &i in t {
                b.grow(self.positions[i as usize]);
            }
        }
        b
    }

    /// The three corner positions of triangle `tri`.
    #[inline]
    pub fn corners(&self, tri: usize) -> [Vec3; 3] {
        let [a, b, c] = self.triangles[tri];
        [
            self.positions[a as usize],
            self.positions[b as usize],
            self.positions[c as usize],
        ]
    }

    /// Unit geometric normal by the winding `(b - a) × (c - a)`; zero for a degenerate
    /// triangle.
    pub fn face_normal(&self, tri: usize) -> Vec3 {
        let [a, b, c] = self.corners(tri);
        (b - a).cross(c - a).normalize_or_zero()
    }

    /// The shading normal at barycentric `(u, v)` (weights `1-u-v, u, v` of the corners):
    /// interpolated vertex normals when the mesh has them, else the face normal.
    pub fn shading_normal(&self, tri: usize, u: f32, v: f32) -> Vec3 {
        let Some(normals) = &self.normals else {
            return self.face_normal(tri);
        };
        let [a, b, c] = self.triangles[tri];
        let n = normals[a as usize] * (1.0 - u - v) + normals[b as usize] * u + normals[c as usize] * v;
        self.unit_or_face(n, tri)
    }

    /// `n` made unit length, or triangle `tri`'s face normal where `n` has none (vertex
    /// normals that cancel).
    fn unit_or_face(&self, n: Vec3, tri: usize) -> Vec3 {
        let n = n.normalize_or_zero();
        if n == Vec3::ZERO { self.face_normal(tri) } else { n }
    }

    /// The normal [`Mesh::shading_normal`] gives everywhere on triangle `tri`, when it
    /// is one: no vertex normals, or three equal ones.
    pub fn uniform_normal(&self, tri: usize) -> Option<Vec3> {
        let Some(normals) = &self.normals else {
            return Some(self.face_normal(tri));
        };
        let [a, b, c] = self.triangles[tri].map(|k| normals[k as usize]);
        (a == b && b == c).then(|| self.unit_or_face(a, tri))
    }

    /// The albedo [`Mesh::albedo`] gives everywhere on triangle `tri`, when it is one
    /// (no texture).
    pub fn uniform_albedo(&self, tri: usize) -> Option<Vec3> {
        self.diffuse_map(tri)
            .is_none()
            .then(|| self.material(tri).diffuse)
    }

    /// The texture triangle `tri`'s albedo is read from, with the mesh's texture
    /// coordinates, when it has both.
    fn diffuse_map(&self, tri: usize) -> Option<(&TextureImage, &[Vec2])> {
        let texture = self.material(tri).diffuse_texture.as_deref()?;
        Some((texture, self.texcoords.as_deref()?))
    }

    /// The material of triangle `tri`.
    #[inline]
    pub fn material(&self, tri: usize) -> &Material {
        let id = self.triangle_materials.as_ref().map_or(0, |m| m[tri] as usize);
        &self.materials[id]
    }

    /// Linear albedo at barycentric `(u, v)` of triangle `tri`.
    pub fn albedo(&self, tri: usize, u: f32, v: f32) -> Vec3 {
        let diffuse = self.material(tri).diffuse;
        let Some((texture, uvs)) = self.diffuse_map(tri) else {
            return diffuse;
        };
        let [a, b, c] = self.triangles[tri];
        let uv = uvs[a as usize] * (1.0 - u - v) + uvs[b as usize] * u + uvs[c as usize] * v;
        diffuse * texture.sample(uv)
    }

    /// A copy placed in the world by `transform`; normals go through the inverse
    /// transpose and are renormalised, and a mirror (a negative determinant) reverses
    /// each triangle's corners, so that faces keep facing out.
    pub fn transformed(&self, transform: Affine3A) -> Mesh {
        let normal_matrix: Mat3 = Mat3::from(transform.matrix3).inverse().transpose();
        let triangles = if transform.matrix3.determinant() < 0.0 {
            self.triangles.iter().map(|&[a, b, c]| [a, c, b]).collect()
        } else {
            self.triangles.clone()
        };
        Mesh {
            triangles,
            positions: self
                .positions
                .iter()
                .map(|&p| transform.transform_point3(p))
                .collect(),
            normals: self.normals.as_ref().map(|ns| {
                ns.iter()
                    .map(|&n| (normal_matrix * n).normalize_or_zero())
                    .collect()
            }),
            texcoords: self.texcoords.clone(),
            triangle_materials: self.triangle_materials.clone(),
            materials: self.materials.clone(),
        }
    }

    /// Appends `other`, offsetting its indices and material ids; an error (and nothing
    /// appended) when the two hold more materials than a `u16` id names or more
    /// vertices than a `u32` index does.
    pub fn append(&mut self, other: Mesh) -> Result<(), MeshError> {
        let materials = self.materials.len() + other.materials.len();
        if materials > usize::from(u16::MAX) {
            return Err(MeshError::TooManyMaterials(materials));
        }
        let vertices = self.positions.len() + other.positions.len();
        if vertices > u32::MAX as usize {
            return Err(MeshError::TooManyVertices(vertices));
        }
        let vertex_offset = self.positions.len() as u32;
        let material_offset = self.materials.len() as u16;
        let (own_vertices, other_vertices) = (self.positions.len(), other.positions.len());
        let own_triangles = self.triangles.len();
        merge_attribute(
            &mut self.normals,
            other.normals,
            own_vertices,
            other_vertices,
            Vec3::ZERO,
        );
        merge_attribute(
            &mut self.texcoords,
            other.texcoords,
            own_vertices,
            other_vertices,
            Vec2::ZERO,
        );
        let own_ids = self
            .triangle_materials
            .take()
            .unwrap_or_else(|| vec![0; own_triangles]);
        let other_ids = other
            .triangle_materials
            .unwrap_or_else(|| vec![0; other.triangles.len()]);
        self.triangle_materials = Some(
            own_ids
                .into_iter()
                .chain(other_ids.into_iter().map(|m| m + material_offset))
                .collect(),
        );
        self.positions.extend(other.positions);
        self.triangles
            .extend(other.triangles.into_iter().map(|t| t.map(|i| i + vertex_offset)));
        self.materials.extend(other.materials);
        Ok(())
    }

    /// Heap bytes held by the mesh (excluding material textures).
    pub fn heap_bytes(&self) -> usize {
        self.positions.len() * size_of::<Vec3>()
            + self.normals.as_ref().map_or(0, |n| n.len() * size_of::<Vec3>())
            + self.texcoords.as_ref().map_or(0, |t| t.len() * size_of::<Vec2>())
            + self.triangles.len() * size_of::<[u32; 3]>()
            + self
                .triangle_materials
                .as_ref()
                .map_or(0, |m| m.len() * size_of::<u16>())
    }
}

/// Concatenates an optional per-vertex attribute, filling the side that lacks it.
pub(crate) fn merge_attribute<T: Copy>(
    own: &mut Option<Vec<T>>,
    other: Option<Vec<T>>,
    own_len: usize,
    other_len: usize,
    fill: T,
) {
    match (own.as_mut(), other) {
        (None, None) => {}
        (Some(values), None) => values.extend(std::iter::repeat_n(fill, other_len)),
        (None, Some(values)) => {
            let mut merged = vec![fill; own_len];
            merged.extend(values);
            *own = Some(merged);
        }
        (Some(values), Some(more)) => values.extend(more),
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn triangle(z: f32, normals: bool) -> Mesh {
        Mesh {
            positions: vec![
                Vec3::new(0.0, 0.0, z),
                Vec3::new(1.0, 0.0, z),
                Vec3::new(0.0, 1.0, z),
            ],
            normals: normals.then(|| vec![Vec3::Z; 3]),
            triangles: vec![[0, 1, 2]],
            materials: vec![Material::default()],
            ..Default::default()
        }
    }

    #[test]
    fn append_offsets_indices_and_fills_missing_normals() {
        let mut m = triangle(0.0, false);
        m.append(triangle(1.0, true)).unwrap();
        assert_eq!(m.triangles[1], [3, 4, 5]);
        assert_eq!(m.normals.as_ref().unwrap()[0], Vec3::ZERO);
        assert_eq!(m.triangle_materials.as_deref(), Some(&[0u16, 1][..]));
        assert!(m.validate().is_ok());
        // A zero vertex normal falls back to the face normal.
        assert_eq!(m.shading_normal(0, 0.3, 0.3), Vec3::Z);
        // More materials than a u16 id names: refused, nothing appended.
        let mut many = triangle(2.0, false);
        many.materials = vec![Material::default(); usize::from(u16::MAX)];
        let (triangles, materials) = (m.triangles.len(), m.materials.len());
        assert_eq!(
            m.append(many),
            Err(MeshError::TooManyMaterials(usize::from(u16::MAX) + 2))
        );
        assert_eq!((m.triangles.len(), m.materials.len()), (triangles, materials));
    }

    #[test]
    fn validate_names_the_problem() {
        let mut m = triangle(0.0, false);
        m.positions[1].x = f32::NAN;
        assert!(m.validate().unwrap_err().to_string().contains("vertex 2"));
        let mut m = triangle(0.0, false);
        m.triangles[0][2] = 7;
        assert!(m.validate().unwrap_err().to_string().contains("triangle 1"));
    }

    #[test]
    fn degenerate_triangle_has_zero_face_normal() {
        let mut m = triangle(0.0, false);
        m.positions[2] = m.positions[1];
        assert_eq!(m.face_normal(0), Vec3::ZERO);
    }
}
