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

/// The content hash of a mesh: geometry, attributes, materials and their textures.
pub fn mesh_hash(mesh: &Mesh) -> ContentHash {
    let mut h = blake3::Hasher::new();
    h.update(b"relief-mesh-v1");
    let floats = |h: &mut blake3::Hasher, values: &mut dyn Iterator<Item = f32>| {
        for v in values {
            h.update(&v.to_le_bytes());
        }
    };
    h.update(&(mesh.positions.len() as u64).to_le_bytes());
    floats(&mut h, &mut mesh.positions.iter().flat_map(|p| p.to_array()));
    h.update(&[mesh.normals.is_some() as u8]);
    if let Some(normals) = &mesh.normals {
        floats(&mut h, &mut normals.iter().flat_map(|p| p.to_array()));
    }
    h.update(&[mesh.texcoords.is_some() as u8]);
    if let Some(uvs) = &mesh.texcoords {
        floats(&mut h, &mut uvs.iter().flat_map(|p| p.to_array()));
    }
    h.update(&(mesh.triangles.len() as u64).to_le_bytes());
    for t in &mesh.triangles {
        for i in t {
            h.update(&i.to_le_bytes());
        }
    }
    h.update(&[mesh.triangle_materials.is_some() as u8]);
    if let Some(ids) = &mesh.triangle_materials {
        for i in ids {
            h.update(&i.to_le_bytes());
        }
    }
    h.update(&(mesh.materials.len() as u64).to_le_bytes());
    for m in &mesh.materials {
        floats(&mut h, &mut m.diffuse.to_array().into_iter());
        match &m.diffuse_texture {
            None => {
                h.update(&[0]);
            }
            Some(t) => {
                h.update(&[1]);
                h.update(&t.width.to_le_bytes());
                h.update(&t.height.to_le_bytes());
                floats(&mut h, &mut t.texels.iter().flat_map(|p| p.to_array()));
            }
        }
    }
    ContentHash(*h.finalize().as_bytes())
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::generators::Generator;

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
}
