//! Content hashes: the name under which machines agree on a mesh.
//!
//! The hash covers every value that affects a rendering, serialised in a fixed
//! little-endian layout, so it is the same across runs, processes and machines.

use std::fmt;

use crate::mesh::Mesh;

/// A BLAKE3 digest, shown as 64 hex digits.
#[derive(Clone, Copy, PartialEq, Eq, Hash, PartialOrd, Ord)]
pub struct ContentHash(pub [u8; 32]);

impl fmt::Display for ContentHash {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        for byte in self.0 {
            write!(f, "{byte:02x}")?;
        }
        Ok(())
    }
}

impl fmt::Debug for ContentHash {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        write!(f, "ContentHash({self})")
    }
}

impl ContentHash {
    /// Parses 64 hex digits.
    pub fn from_hex(text: &str) -> Option<Self> {
        if text.len() != 64 || !text.is_ascii() {
            return None;
        }
        let mut out = [0u8; 32];
        for (i, byte) in out.iter_mut().enumerate() {
            *byte = u8::from_str_radix(&text[2 * i..2 * i + 2], 16).ok()?;
        }
        Some(ContentHash(out))
    }
}

/// Feeds little-endian values to the hasher through a buffer: one `update` per 64 KiB,
/// not per value.
fn update_le<const N: usize>(h: &mut blake3::Hasher, values: impl Iterator<Item = [u8; N]>) {
    let mut buffer = Vec::with_capacity(1 << 16);
    for v in values {
        buffer.extend_from_slice(&v);
        if buffer.len() + N > buffer.capacity() {
            h.update(&buffer);
            buffer.clear();
        }
    }
    h.update(&buffer);
}

fn floats(h: &mut blake3::Hasher, values: impl Iterator<Item = f32>) {
    update_le(h, values.map(f32::to_le_bytes));
}

/// The content hash of a mesh: geometry, attributes, materials and their textures.
pub fn mesh_hash(mesh: &Mesh) -> ContentHash {
    let mut h = blake3::Hasher::new();
    h.update(b"relief-mesh-v1");
    h.update(&(mesh.positions.len() as u64).to_le_bytes());
    floats(&mut h, mesh.positions.iter().flat_map(|p| p.to_array()));
    h.update(&[mesh.normals.is_some() as u8]);
    if let Some(normals) = &mesh.normals {
        floats(&mut h, normals.iter().flat_map(|p| p.to_array()));
    }
    h.update(&[mesh.texcoords.is_some() as u8]);
    if let Some(uvs) = &mesh.texcoords {
        floats(&mut h, uvs.iter().flat_map(|p| p.to_array()));
    }
    h.update(&(mesh.triangles.len() as u64).to_le_bytes());
    update_le(&mut h, mesh.triangles.iter().flatten().map(|i| i.to_le_bytes()));
    h.update(&[mesh.triangle_materials.is_some() as u8]);
    if let Some(ids) = &mesh.triangle_materials {
        update_le(&mut h, ids.iter().map(|i| i.to_le_bytes()));
    }
    h.update(&(mesh.materials.len() as u64).to_le_bytes());
    for m in &mesh.materials {
        floats(&mut h, m.diffuse.to_array().into_iter());
        match &m.diffuse_texture {
            None => {
                h.update(&[0]);
            }
            Some(t) => {
                h.update(&[1]);
                h.update(&t.width.to_le_bytes());
                h.update(&t.height.to_le_bytes());
                floats(&mut h, t.texels.iter().flat_map(|p| p.to_array()));
            }
        }
    }
    ContentHash(*h.finalize().as_bytes())
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::generators::Generator;
    use glam::Vec3;

    #[test]
    fn hash_is_stable_and_sensitive() {
        let a = Generator::Sphere { subdivisions: 2 }.build();
        let b = Generator::Sphere { subdivisions: 2 }.build();
        assert_eq!(mesh_hash(&a), mesh_hash(&b));
        let mut c = b.clone();
        c.positions[3].x += 1e-6;
        assert_ne!(mesh_hash(&a), mesh_hash(&c));
        let hex = mesh_hash(&a).to_string();
        assert_eq!(ContentHash::from_hex(&hex), Some(mesh_hash(&a)));
    }

    /// The serialised layout is part of the protocol: machines compare these hashes.
    /// This mesh is written out exactly (no transcendental functions), so its hash must
    /// never change unless the layout's version tag does.
    #[test]
    fn golden_hash() {
        let mesh = Mesh {
            positions: vec![Vec3::ZERO, Vec3::X, Vec3::new(0.0, 0.5, -2.25)],
            normals: Some(vec![Vec3::Z; 3]),
            triangles: vec![[0, 1, 2]],
            materials: vec![crate::mesh::Material::default()],
            ..Default::default()
        };
        assert_eq!(
            mesh_hash(&mesh).to_string(),
            "a87f77cda915d9d8a00bd57aa797dee6d7a4af2fbf931aa30ad8ea36b39748d9"
        );
    }
}
