//! Wavefront OBJ loading (through `tobj`): positions, normals when present, texture
//! coordinates, and the materials' diffuse colour and diffuse texture.

use std::path::Path;
use std::sync::Arc;

use glam::{Vec2, Vec3};

use crate::error::{Error, Result};
use crate::mesh::{Material, Mesh, TextureImage};
use crate::reach::Reach;

/// Loads every group of an OBJ file into one mesh.
///
/// A missing or unreadable MTL file or texture is reported with `tracing::warn!` and
/// replaced by the default material; a malformed OBJ, or one with no triangles or with
/// non-finite coordinates, is an error naming the file. Every file opened (the OBJ, its
/// MTLs, their textures) must be within `reach`: one outside it is an error for the OBJ,
/// and a missing material or texture for the others.
pub fn load_obj(path: &Path, reach: Reach) -> Result<Mesh> {
    let obj_error = |message: String| Error::Obj {
        path: path.to_path_buf(),
        message,
    };
    // Reach first: outside it, whether the file exists is not the scene's business.
    let opened = reach.check(path)?;
    if !path.is_file() {
        return Err(Error::io(
            path,
            std::io::Error::new(std::io::ErrorKind::NotFound, "no such file"),
        ));
    }
    let options = tobj::LoadOptions {
        single_index: true,
        triangulate: true,
        ignore_points: true,
        ignore_lines: true,
    };
    let file = std::fs::File::open(opened).map_err(|e| Error::io(path, e))?;
    let base_dir = path.parent().unwrap_or(Path::new("."));
    // MTL files resolve against the OBJ's directory, as `tobj::load_obj` does.
    let load_mtl = |mtl: &Path| {
        let mtl = reach
            .check(&base_dir.join(mtl))
            .map_err(|_| tobj::LoadError::OpenFileFailed)?;
        tobj::load_mtl(mtl)
    };
    let (models, materials) = tobj::load_obj_buf(&mut std::io::BufReader::new(file), &options, load_mtl)
        .map_err(|e| obj_error(format!("malformed OBJ: {e}")))?;
    let mut materials: Vec<Material> = match materials {
        Ok(materials) => materials
            .iter()
            .map(|m| convert_material(m, base_dir, reach))
            .collect(),
        Err(e) => {
            tracing::warn!(
                "{}: materials not loaded ({e}); using the default material",
                path.display()
            );
            Vec::new()
        }
    };
    // Slot for faces without a material (or with an id past the MTL's list).
    let default_id = materials.len() as u16;
    materials.push(Material::default());

    let mut mesh = Mesh {
        materials,
        ..Default::default()
    };
    let mut any_normals = false;
    let mut any_texcoords = false;
    for model in &models {
        any_normals |= !model.mesh.normals.is_empty();
        any_texcoords |= !model.mesh.texcoords.is_empty();
    }
    let mut normals = Vec::new();
    let mut texcoords = Vec::new();
    let mut ids = Vec::new();
    for model in models {
        let m = model.mesh;
        let offset = mesh.positions.len() as u32;
        let count = m.positions.len() / 3;
        mesh.positions
            .extend(m.positions.chunks_exact(3).map(|c| Vec3::new(c[0], c[1], c[2])));
        if any_normals {
            if m.normals.len() == m.positions.len() {
                normals.extend(m.normals.chunks_exact(3).map(|c| Vec3::new(c[0], c[1], c[2])));
            } else {
                normals.extend(std::iter::repeat_n(Vec3::ZERO, count));
            }
        }
        if any_texcoords {
            if m.texcoords.len() / 2 == count {
                texcoords.extend(m.texcoords.chunks_exact(2).map(|c| Vec2::new(c[0], c[1])));
            } else {
                texcoords.extend(std::iter::repeat_n(Vec2::ZERO, count));
            }
        }
        let material = m
            .material_id
            .filter(|&id| id < default_id as usize)
            .map_or(default_id, |id| id as u16);
        for t in m.indices.chunks_exact(3) {
            mesh.triangles.push([t[0] + offset, t[1] + offset, t[2] + offset]);
            ids.push(material);
        }
    }
    mesh.normals = any_normals.then_some(normals);
    mesh.texcoords = any_texcoords.then_some(texcoords);
    mesh.triangle_materials = Some(ids);
    mesh.settle_normals();
    mesh.validate().map_err(|e| obj_error(e.to_string()))?;
    Ok(mesh)
}

fn convert_material(m: &tobj::Material, base_dir: &Path, reach: Reach) -> Material {
    let diffuse = m
        .diffuse
        .map(Vec3::from_array)
        .filter(|d| d.is_finite())
        .unwrap_or(Vec3::splat(0.8))
        .clamp(Vec3::ZERO, Vec3::ONE);
    let diffuse_texture = m.diffuse_texture.as_ref().and_then(|name| {
        let path = base_dir.join(name.replace('\\', "/"));
        match reach.check(&path).and_then(|path| load_texture(&path)) {
            Ok(t) => Some(Arc::new(t)),
            Err(e) => {
                tracing::warn!("material `{}`: texture not loaded: {e}", m.name);
                None
            }
        }
    });
    Material {
        name: m.name.clone(),
        diffuse,
        diffuse_texture,
    }
}

/// Loads an image file as a linear RGB texture ([`TextureImage::decode`]).
pub fn load_texture(path: &Path) -> Result<TextureImage> {
    let bytes = std::fs::read(path).map_err(|e| Error::io(path, e))?;
    TextureImage::decode(&bytes).map_err(|e| Error::Obj {
        path: path.to_path_buf(),
        message: format!("cannot read texture: {e}"),
    })
}

/// The triangles [`load_obj`] would make of `path` (each face of `n` corners gives
/// `n − 2`), read from its face lines without building anything; `path` must lie
/// within `reach`.
pub fn count_triangles(path: &Path, reach: Reach) -> Result<u64> {
    use std::io::BufRead;
    let opened = reach.check(path)?;
    let file = std::fs::File::open(opened).map_err(|e| Error::io(path, e))?;
    let mut reader = std::io::BufReader::new(file);
    let (mut line, mut triangles) = (Vec::new(), 0u64);
    loop {
        line.clear();
        if reader
            .read_until(b'\n', &mut line)
            .map_err(|e| Error::io(path, e))?
            == 0
        {
            return Ok(triangles);
        }
        let mut words = line.split(|b| b.is_ascii_whitespace()).filter(|w| !w.is_empty());
        if words.next() == Some(b"f".as_slice()) {
            triangles = triangles.saturating_add((words.count() as u64).saturating_sub(2));
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn write(dir: &Path, name: &str, text: &str) -> std::path::PathBuf {
        let path = dir.join(name);
        std::fs::write(&path, text).unwrap();
        path
    }

    fn temp_dir(tag: &str) -> crate::scratch::PrivateDir {
        crate::scratch::PrivateDir::new(&format!("relief-obj-{tag}")).unwrap()
    }

    #[test]
    fn loads_quads_materials_and_missing_normals() {
        let dir = temp_dir("quad");
        write(&dir, "m.mtl", "newmtl red\nKd 1 0 0\n");
        let path = write(
            &dir,
            "q.obj",
            "mtllib m.mtl\nv 0 0 0\nv 1 0 0\nv 1 1 0\nv 0 1 0\nusemtl red\nf 1 2 3 4\n",
        );
        let mesh = load_obj(&path, Reach::Anywhere).unwrap();
        assert_eq!(mesh.triangle_count(), 2);
        assert!(mesh.normals.is_none());
        assert_eq!(mesh.material(0).diffuse, Vec3::new(1.0, 0.0, 0.0));
        assert_eq!(mesh.shading_normal(0, 0.2, 0.2), Vec3::Z);
    }

    #[test]
    fn diffuse_texture_modulates_albedo() {
        let dir = temp_dir("texture");
        // 2×1 texture: red on the left, blue on the right.
        image::save_buffer(
            dir.join("t.png"),
            &[255, 0, 0, 0, 0, 255],
            2,
            1,
            image::ColorType::Rgb8,
        )
        .unwrap();
        write(&dir, "m.mtl", "newmtl tex\nKd 1 1 0.5\nmap_Kd t.png\n");
        let path = write(
            &dir,
            "t.obj",
            "mtllib m.mtl\nv 0 0 0\nv 1 0 0\nv 0 1 0\nvt 0.25 0.5\nvt 0.75 0.5\nvt 0.25 0.5\nusemtl tex\nf 1/1 2/2 3/3\n",
        );
        let mesh = load_obj(&path, Reach::Anywhere).unwrap();
        assert!(mesh.texcoords.is_some());
        // Texel centres: corner 0 samples pure red, corner 1 pure blue (times Kd).
        assert!(
            mesh.albedo(0, 0.0, 0.0)
                .abs_diff_eq(Vec3::new(1.0, 0.0, 0.0), 1e-3)
        );
        assert!(
            mesh.albedo(0, 1.0, 0.0)
                .abs_diff_eq(Vec3::new(0.0, 0.0, 0.5), 1e-3)
        );
    }

    #[test]
    fn errors_name_the_file_and_problem() {
        let dir = temp_dir("bad");
        let nan = write(&dir, "nan.obj", "v 0 0 0\nv nan 0 0\nv 0 1 0\nf 1 2 3\n");
        let err = load_obj(&nan, Reach::Anywhere).unwrap_err().to_string();
        assert!(err.contains("nan.obj") && err.contains("vertex 2"), "{err}");
        let empty = write(&dir, "empty.obj", "v 0 0 0\n");
        assert!(
            load_obj(&empty, Reach::Anywhere)
                .unwrap_err()
                .to_string()
                .contains("no triangles")
        );
        let bad = write(&dir, "bad.obj", "v 0 0 0\nv 1 0 0\nv 0 1 0\nf 1 2 9\n");
        assert!(
            load_obj(&bad, Reach::Anywhere)
                .unwrap_err()
                .to_string()
                .contains("bad.obj")
        );
        let missing = dir.join("missing.obj");
        assert!(
            load_obj(&missing, Reach::Anywhere)
                .unwrap_err()
                .to_string()
                .contains("missing.obj")
        );
    }
}
