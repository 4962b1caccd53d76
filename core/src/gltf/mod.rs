//! glTF 2.0 loading (through `gltf`), `.gltf` and `.glb`: each mesh (its triangle
//! primitives merged, positions, normals, first texture coordinates), the default
//! scene's node hierarchy as placements of those meshes (a mesh many nodes use is one
//! mesh), and each material's base colour — factor and texture — as albedo.
//!
//! Nothing is read outside the caller's [`Reach`]: the crate's own importer (which
//! opens whatever a URI names) is not used; buffers and images come from the `.glb`'s
//! binary chunk, `data:` URIs, or files beside the model within reach; accessors are
//! read by `accessor.rs`, which checks every offset.

mod accessor;

use std::path::{Path, PathBuf};
use std::sync::Arc;

use base64::Engine;
use glam::{DAffine3, DMat3, DMat4, DQuat, DVec3, Vec2, Vec3};

use gltf::json::accessor::ComponentType;

use crate::error::{Error, Result};
use crate::mesh::{Material, Mesh, TextureImage, merge_attribute};
use crate::reach::Reach;

/// A glTF file's meshes, and where its default scene places them.
#[derive(Debug)]
pub struct GltfModel {
    /// Mesh `k` of the file (only those some node uses are built; the rest are `None`).
    pub meshes: Vec<Option<Mesh>>,
    pub placements: Vec<GltfPlacement>,
}

/// A node of the default scene that holds a mesh.
#[derive(Debug, Clone)]
pub struct GltfPlacement {
    /// The node's name, or `node<index>` when it has none.
    pub name: String,
    /// Index into [`GltfModel::meshes`].
    pub mesh: usize,
    /// The node's transform composed with its ancestors': model space to the file's
    /// world.
    pub transform: DAffine3,
}

/// What [`load_gltf`] would build from a file, read from its JSON before any buffer.
/// A primitive counts the triangles it holds, or a third of its vertices where those
/// are more (many primitives may share one large vertex accessor, each copying it).
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct GltfCensus {
    /// Triangles built for a scene of the file: the meshes its default scene uses,
    /// each once, and again for each placement that is no similarity (which gets a
    /// transformed copy).
    pub built_triangles: u64,
    /// … and over every placement: what [`load_gltf_merged`] builds.
    pub placed_triangles: u64,
    /// Nodes holding a mesh.
    pub placements: usize,
}

/// [`GltfCensus`] of `path`, within `reach`.
pub fn census(path: &Path, reach: Reach) -> Result<GltfCensus> {
    let gltf = open(path, reach)?;
    let mut triangles_of: Vec<Option<u64>> = vec![None; gltf.document.meshes().len()];
    let mut census = GltfCensus {
        built_triangles: 0,
        placed_triangles: 0,
        placements: 0,
    };
    for (node, transform) in scene_nodes(&gltf.document) {
        let Some(mesh) = node.mesh() else { continue };
        let known = triangles_of[mesh.index()];
        let triangles = known.unwrap_or_else(|| {
            let primitives = mesh
                .primitives()
                .filter(|p| p.mode() == gltf::mesh::Mode::Triangles);
            let corners = primitives.map(|p| {
                let indices = p.indices().map_or(0, |a| a.count());
                let vertices = p.get(&gltf::Semantic::Positions).map_or(0, |a| a.count());
                indices.max(vertices) as u64 / 3
            });
            corners.fold(0u64, u64::saturating_add)
        });
        triangles_of[mesh.index()] = Some(triangles);
        let copies = u64::from(known.is_none()) + u64::from(similarity(&transform).is_none());
        census.built_triangles = census
            .built_triangles
            .saturating_add(copies.saturating_mul(triangles));
        census.placed_triangles = census.placed_triangles.saturating_add(triangles);
        census.placements += 1;
    }
    Ok(census)
}

/// The files beside a glTF file that it names by URI (buffers and images, not `data:`
/// URIs), as paths relative to its directory: what a scene bundle must carry with it.
/// `bytes` are the file's, read from `path` (named in errors).
pub fn referenced_files(path: &Path, bytes: &[u8]) -> Result<Vec<String>> {
    let gltf = parse(path, bytes)?;
    let buffers = gltf.document.buffers().filter_map(|b| match b.source() {
        gltf::buffer::Source::Uri(uri) => Some(uri),
        gltf::buffer::Source::Bin => None,
    });
    // (From the JSON: `gltf`'s `Image::source` panics on an image with neither.)
    let images = gltf
        .document
        .as_json()
        .images
        .iter()
        .filter_map(|i| i.uri.as_deref());
    Ok(buffers
        .chain(images)
        .filter(|uri| !uri.starts_with("data:") && !uri.contains("://"))
        .map(percent_decoded)
        .collect())
}

/// The default scene of `path` as one mesh: each placement's mesh transformed by its
/// node's transform, all merged (what a scene file's object naming a glTF file is).
pub fn load_gltf_merged(path: &Path, reach: Reach) -> Result<Mesh> {
    let model = load_gltf(path, reach)?;
    let mut merged: Option<Mesh> = None;
    for placement in &model.placements {
        let Some(mesh) = &model.meshes[placement.mesh] else {
            continue;
        };
        let placed = mesh.transformed(glam::Affine3A::from_mat3_translation(
            placement.transform.matrix3.as_mat3(),
            placement.transform.translation.as_vec3(),
        ));
        match &mut merged {
            Some(all) => all.append(placed).map_err(|e| Error::Obj {
                path: path.to_path_buf(),
                message: format!("its placements merged: {e}"),
            })?,
            None => merged = Some(placed),
        }
    }
    merged.ok_or_else(|| Error::Obj {
        path: path.to_path_buf(),
        message: "its scene places no mesh".into(),
    })
}

/// Loads `path` (a `.gltf` or `.glb` within `reach`): its meshes and its default
/// scene's placements of them (the first scene when none is the default). Errors name
/// the file and the node, mesh, primitive or accessor at fault.
pub fn load_gltf(path: &Path, reach: Reach) -> Result<GltfModel> {
    let error = |message: String| Error::Obj {
        path: path.to_path_buf(),
        message,
    };
    let gltf = open(path, reach)?;
    let base = path.parent().unwrap_or(Path::new("."));
    let buffers = read_buffers(&gltf, base, reach).map_err(error)?;
    let mut materials = Materials::new(gltf.document.as_json(), &buffers, base, reach, path);
    let mut meshes: Vec<Option<Mesh>> = vec![None; gltf.document.meshes().len()];
    let mut placements = Vec::new();
    for (node, transform) in scene_nodes(&gltf.document) {
        let Some(mesh) = node.mesh() else { continue };
        let name = node
            .name()
            .map_or_else(|| format!("node{}", node.index()), str::to_string);
        let at = |message: String| error(format!("node {} (`{name}`): {message}", node.index()));
        if !transform.is_finite() {
            return Err(at("its transform (with its ancestors') is not finite".into()));
        }
        if meshes[mesh.index()].is_none() {
            meshes[mesh.index()] =
                Some(build_mesh(path, &mesh, gltf.document.as_json(), &buffers, &mut materials).map_err(at)?);
        }
        placements.push(GltfPlacement {
            name,
            mesh: mesh.index(),
            transform,
        });
    }
    if placements.is_empty() {
        return Err(error("its scene places no mesh".into()));
    }
    Ok(GltfModel { meshes, placements })
}

/// The file's buffers: the binary chunk (buffer 0 only, as glTF puts it), `data:` URIs,
/// or files beside it — each file read once, however many buffers name it.
fn read_buffers(gltf: &gltf::Gltf, base: &Path, reach: Reach) -> std::result::Result<Vec<Arc<[u8]>>, String> {
    let blob: Option<Arc<[u8]>> = gltf.blob.as_deref().map(Arc::from);
    let mut files: std::collections::HashMap<&str, Arc<[u8]>> = std::collections::HashMap::new();
    let mut buffers = Vec::new();
    for buffer in gltf.document.buffers() {
        let k = buffer.index();
        let data = match buffer.source() {
            gltf::buffer::Source::Bin if k == 0 => blob
                .clone()
                .ok_or("buffer 0 is the binary chunk, which the file lacks")?,
            gltf::buffer::Source::Bin => return Err(format!("buffer {k} has no uri")),
            gltf::buffer::Source::Uri(uri) => match files.get(uri) {
                Some(data) => data.clone(),
                None => {
                    let data: Arc<[u8]> = read_uri(uri, base, reach)
                        .map_err(|e| format!("buffer {k}: {e}"))?
                        .into();
                    files.insert(uri, data.clone());
                    data
                }
            },
        };
        if data.len() < buffer.length() {
            return Err(format!(
                "buffer {k}: {} bytes, where its byteLength says {}",
                data.len(),
                buffer.length()
            ));
        }
        buffers.push(data);
    }
    Ok(buffers)
}

/// Reads and validates the file's JSON (and a `.glb`'s binary chunk).
fn open(path: &Path, reach: Reach) -> Result<gltf::Gltf> {
    let opened = reach.check(path)?;
    let bytes = std::fs::read(opened).map_err(|e| Error::io(path, e))?;
    parse(path, &bytes)
}

/// Validates a glTF file's `bytes` (read from `path`, named in errors).
fn parse(path: &Path, bytes: &[u8]) -> Result<gltf::Gltf> {
    let error = |message: String| Error::Obj {
        path: path.to_path_buf(),
        message,
    };
    let malformed = |e: gltf::Error| error(format!("malformed glTF: {e}"));
    let gltf::Gltf { document, blob } =
        gltf::Gltf::from_slice_without_validation(bytes).map_err(malformed)?;
    let root = document.into_json();
    // gltf-json 1.4's validation looks up a primitive's POSITION accessor before it
    // checks that the index is in range (a panic on a bad one, found by fuzzing):
    // every attribute's accessor is checked here first.
    for (m, mesh) in root.meshes.iter().enumerate() {
        for (p, primitive) in mesh.primitives.iter().enumerate() {
            if let Some(index) = primitive
                .attributes
                .values()
                .find(|a| a.value() >= root.accessors.len())
            {
                return Err(error(format!(
                    "meshes[{m}].primitives[{p}].attributes: accessor {} is past the file's {}",
                    index.value(),
                    root.accessors.len()
                )));
            }
        }
    }
    let document = gltf::Document::from_json(root).map_err(malformed)?;
    Ok(gltf::Gltf { document, blob })
}

/// The default scene's nodes (the first scene's when none is the default), each with
/// its transform composed with its ancestors'. Depth first, parents before children; a
/// node reached twice (glTF forbids it, but a file may) is visited once.
fn scene_nodes(document: &gltf::Document) -> Vec<(gltf::Node<'_>, DAffine3)> {
    let Some(scene) = document.default_scene().or_else(|| document.scenes().next()) else {
        return Vec::new();
    };
    let mut seen = vec![false; document.nodes().len()];
    let mut out = Vec::new();
    let mut stack: Vec<(gltf::Node<'_>, DAffine3)> = scene.nodes().map(|n| (n, DAffine3::IDENTITY)).collect();
    stack.reverse();
    while let Some((node, parent)) = stack.pop() {
        if std::mem::replace(&mut seen[node.index()], true) {
            continue;
        }
        let own = DMat4::from_cols_array_2d(&node.transform().matrix().map(|c| c.map(f64::from)));
        let transform = parent * DAffine3::from_mat4(own);
        let children: Vec<_> = node.children().map(|c| (c, transform)).collect();
        stack.extend(children.into_iter().rev());
        out.push((node, transform));
    }
    out
}

/// A mesh's triangle primitives merged into one [`Mesh`]; the message names the
/// primitive or accessor at fault.
fn build_mesh(
    path: &Path,
    mesh: &gltf::Mesh<'_>,
    root: &gltf::json::Root,
    buffers: &[Arc<[u8]>],
    materials: &mut Materials<'_>,
) -> std::result::Result<Mesh, String> {
    let label = format!(
        "mesh {}{}",
        mesh.index(),
        mesh.name().map_or(String::new(), |n| format!(" (`{n}`)"))
    );
    let mut out = Mesh::default();
    // The materials this mesh's primitives use, numbered in the mesh (by the file's
    // index; `None`, the default material).
    let mut numbered: std::collections::HashMap<Option<usize>, u16> = std::collections::HashMap::new();
    let mut ids = Vec::new();
    for primitive in mesh.primitives() {
        let at = format!("{label}, primitive {}", primitive.index());
        if primitive.mode() != gltf::mesh::Mode::Triangles {
            tracing::warn!(
                "{}: {at}: {:?} primitives are not drawn, only triangles",
                path.display(),
                primitive.mode()
            );
            continue;
        }
        let floats = [ComponentType::F32];
        let accessor = |semantic: gltf::Semantic| primitive.get(&semantic).map(|a| a.index());
        let read =
            |index: usize, allowed: &[ComponentType]| accessor::floats::<3>(root, buffers, index, allowed);
        let positions: Vec<Vec3> = match accessor(gltf::Semantic::Positions) {
            Some(index) => read(index, &floats).map_err(|e| format!("{at}: {e}"))?,
            None => return Err(format!("{at}: no POSITION")),
        }
        .into_iter()
        .map(Vec3::from)
        .collect();
        let first = u32::try_from(out.positions.len())
            .ok()
            .filter(|first| {
                first.checked_add(positions.len() as u32).is_some() && positions.len() < u32::MAX as usize
            })
            .ok_or_else(|| format!("{at}: more than {} vertices in the mesh", u32::MAX))?;
        let n = positions.len();
        let prim_normals: Option<Vec<Vec3>> = (accessor(gltf::Semantic::Normals))
            .map(|index| read(index, &floats).map(|ns| ns.into_iter().map(Vec3::from).collect()))
            .transpose()
            .map_err(|e| format!("{at}: {e}"))?;
        let uv_types = [ComponentType::F32, ComponentType::U8, ComponentType::U16];
        let prim_uv: Option<Vec<Vec2>> = (accessor(gltf::Semantic::TexCoords(0)))
            .map(|index| {
                let uv = accessor::floats::<2>(root, buffers, index, &uv_types)?;
                // glTF's v runs down the image; the meshes' up (as in OBJ).
                Ok::<_, String>(uv.into_iter().map(|[u, v]| Vec2::new(u, 1.0 - v)).collect())
            })
            .transpose()
            .map_err(|e| format!("{at}: {e}"))?;
        for (what, len) in [
            ("NORMAL", prim_normals.as_ref().map(Vec::len)),
            ("TEXCOORD_0", prim_uv.as_ref().map(Vec::len)),
        ] {
            if let Some(len) = len
                && len != n
            {
                return Err(format!("{at}: {len} {what} values for {n} positions"));
            }
        }
        let corners: Vec<u32> = match primitive.indices() {
            Some(a) => accessor::indices(root, buffers, a.index()).map_err(|e| format!("{at}: {e}"))?,
            None => (0..n as u32).collect(),
        };
        if let Some(i) = corners.iter().position(|&i| i as usize >= n) {
            return Err(format!(
                "{at}: index {} (corner {i} of accessor {}) names a vertex past its {n}",
                corners[i],
                primitive.indices().map_or(0, |a| a.index())
            ));
        }
        let index = primitive.material().index();
        let material = match numbered.get(&index) {
            Some(&number) => number,
            None => {
                let number = u16::try_from(out.materials.len())
                    .map_err(|_| format!("{at}: more than {} materials in the mesh", u16::MAX))?;
                out.materials.push(materials.get(index));
                numbered.insert(index, number);
                number
            }
        };
        // Attributes some primitives lack: zero normals (taken as absent: faceted) and
        // zero coordinates.
        let had = out.positions.len();
        merge_attribute(&mut out.normals, prim_normals, had, n, Vec3::ZERO);
        merge_attribute(&mut out.texcoords, prim_uv, had, n, Vec2::ZERO);
        out.positions.extend(positions);
        for t in corners.chunks_exact(3) {
            out.triangles.push([first + t[0], first + t[1], first + t[2]]);
            ids.push(material);
        }
    }
    out.triangle_materials = Some(ids);
    out.settle_normals();
    out.validate().map_err(|e| format!("{label}: {e}"))?;
    Ok(out)
}

/// The file's materials, each made the first time a mesh uses one: the base colour as
/// albedo, the factor (linear RGB) times the base colour texture where it has one that
/// can be read (else a warning, and the factor). Each image is decoded once, however
/// many materials use it, within [`TextureImage::decode`]'s limits.
struct Materials<'a> {
    root: &'a gltf::json::Root,
    buffers: &'a [Arc<[u8]>],
    base: &'a Path,
    reach: Reach<'a>,
    path: &'a Path,
    made: Vec<Option<Material>>,
    images: std::collections::HashMap<usize, Option<Arc<TextureImage>>>,
}

impl<'a> Materials<'a> {
    fn new(
        root: &'a gltf::json::Root,
        buffers: &'a [Arc<[u8]>],
        base: &'a Path,
        reach: Reach<'a>,
        path: &'a Path,
    ) -> Self {
        Materials {
            root,
            buffers,
            base,
            reach,
            path,
            made: vec![None; root.materials.len()],
            images: std::collections::HashMap::new(),
        }
    }

    /// Material `index` of the file (the default material for `None`).
    fn get(&mut self, index: Option<usize>) -> Material {
        let Some(index) = index.filter(|&k| k < self.made.len()) else {
            return Material::default();
        };
        if let Some(made) = &self.made[index] {
            return made.clone();
        }
        let json = &self.root.materials[index];
        let pbr = &json.pbr_metallic_roughness;
        let [r, g, b, _] = pbr.base_color_factor.0;
        let name = json.name.clone().unwrap_or_else(|| format!("material{index}"));
        let diffuse_texture = (pbr.base_color_texture.as_ref())
            .and_then(|info| self.root.textures.get(info.index.value()))
            .and_then(|texture| self.image(texture.source.value(), &name));
        let material = Material {
            name,
            diffuse: Vec3::new(r, g, b).clamp(Vec3::ZERO, Vec3::ONE),
            diffuse_texture,
        };
        self.made[index] = Some(material.clone());
        material
    }

    /// Image `index`, decoded once; `None` (and a warning naming `material`) when it
    /// cannot be read.
    fn image(&mut self, index: usize, material: &str) -> Option<Arc<TextureImage>> {
        if let Some(image) = self.images.get(&index) {
            return image.clone();
        }
        let bytes = image_bytes(self.root, index, self.buffers, self.base, self.reach);
        let image = match bytes.and_then(|bytes| TextureImage::decode(&bytes)) {
            Ok(image) => Some(Arc::new(image)),
            Err(e) => {
                tracing::warn!(
                    "{}: material `{material}`'s base colour texture not read ({e}); its factor alone is used",
                    self.path.display()
                );
                None
            }
        };
        self.images.insert(index, image.clone());
        image
    }
}

/// The bytes of image `index`: its buffer view's, or its URI's. (Read from the JSON:
/// `gltf`'s `Image::source` panics on an image with a view but no MIME type, or with
/// neither a view nor a URI, which its validation lets through.)
fn image_bytes(
    root: &gltf::json::Root,
    index: usize,
    buffers: &[Arc<[u8]>],
    base: &Path,
    reach: Reach,
) -> std::result::Result<Vec<u8>, String> {
    let image = root.images.get(index).ok_or(format!("no image {index}"))?;
    match (&image.buffer_view, &image.uri) {
        (Some(view), _) => {
            let view =
                (root.buffer_views.get(view.value())).ok_or(format!("image {index}: no buffer view"))?;
            let start = view.byte_offset.map_or(0, |o| o.0);
            let range = usize::try_from(start)
                .ok()
                .zip(usize::try_from(start.saturating_add(view.byte_length.0)).ok());
            range
                .and_then(|(start, end)| buffers.get(view.buffer.value())?.get(start..end))
                .map(<[u8]>::to_vec)
                .ok_or_else(|| format!("image {index}'s buffer view lies past its buffer"))
        }
        (None, Some(uri)) => read_uri(uri, base, reach),
        (None, None) => Err(format!("image {index} has neither a buffer view nor a uri")),
    }
}

/// The bytes a URI names: a `data:` URI's base64 payload, or a file relative to
/// `base` within `reach`.
fn read_uri(uri: &str, base: &Path, reach: Reach) -> std::result::Result<Vec<u8>, String> {
    if let Some(data) = uri.strip_prefix("data:") {
        let (_, payload) = data
            .split_once(";base64,")
            .ok_or("a data: URI that is not base64")?;
        return base64::engine::general_purpose::STANDARD
            .decode(payload)
            .map_err(|e| format!("a data: URI's base64: {e}"));
    }
    if uri.contains("://") {
        return Err(format!(
            "`{uri}`: only data: URIs and files beside the model are read"
        ));
    }
    let file: PathBuf = base.join(percent_decoded(uri));
    let opened = reach.check(&file).map_err(|e| e.to_string())?;
    std::fs::read(opened).map_err(|e| format!("{}: {e}", file.display()))
}

/// A URI path with its `%XX` escapes decoded (glTF URIs are escaped: a space is `%20`).
fn percent_decoded(uri: &str) -> String {
    let bytes = uri.as_bytes();
    let mut out = Vec::with_capacity(bytes.len());
    let mut i = 0;
    while i < bytes.len() {
        let hex = |b: u8| (b as char).to_digit(16);
        if bytes[i] == b'%'
            && let (Some(hi), Some(lo)) = (
                bytes.get(i + 1).and_then(|&b| hex(b)),
                bytes.get(i + 2).and_then(|&b| hex(b)),
            )
        {
            out.push((hi * 16 + lo) as u8);
            i += 3;
        } else {
            out.push(bytes[i]);
            i += 1;
        }
    }
    String::from_utf8_lossy(&out).into_owned()
}

/// A placement's transform as a similarity — origin, rotation, uniform scale — when it
/// is one (within a part in 10⁶); `None` for a shear or an uneven scale, whose mesh is
/// then transformed into a mesh of its own.
pub fn similarity(transform: &DAffine3) -> Option<(DVec3, DQuat, f64)> {
    let m: DMat3 = transform.matrix3;
    let scales = DVec3::new(m.x_axis.length(), m.y_axis.length(), m.z_axis.length());
    let scale = scales.x;
    let even = (scales - DVec3::splat(scale)).abs().max_element() <= 1e-6 * scale;
    if !scale.is_finite() || scale <= 0.0 || !even || m.determinant() <= 0.0 {
        return None;
    }
    let turn = m * (1.0 / scale);
    let orthogonal = (turn.transpose() * turn - DMat3::IDENTITY)
        .to_cols_array()
        .iter()
        .all(|e| e.abs() <= 1e-6);
    orthogonal.then(|| (transform.translation, DQuat::from_mat3(&turn), scale))
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::scratch::PrivateDir;

    /// A unit quad (4 positions, 6 u16 indices) as one buffer's bytes.
    fn quad_bytes() -> Vec<u8> {
        let mut bytes = Vec::new();
        for p in [[0f32, 0., 0.], [1., 0., 0.], [1., 1., 0.], [0., 1., 0.]] {
            bytes.extend(p.iter().flat_map(|c| c.to_le_bytes()));
        }
        for i in [0u16, 1, 2, 0, 2, 3] {
            bytes.extend(i.to_le_bytes());
        }
        bytes
    }

    /// A glTF document of the quad mesh placed by three children of a moved and scaled
    /// parent: moved, turned 90° about y, and stretched along y (`children` and
    /// `indices` may be changed by a test). `uri` is the buffer's (none: a .glb's).
    fn document(uri: Option<&str>, indices_accessor: u32, stretch: &str) -> String {
        let uri = uri.map_or(String::new(), |u| format!(r#""uri": "{u}", "#));
        format!(
            r#"{{
  "asset": {{ "version": "2.0" }},
  "scene": 0,
  "scenes": [{{ "nodes": [0] }}],
  "nodes": [
    {{ "name": "parent", "translation": [10, 0, 0], "scale": [2, 2, 2], "children": [1, 2, 3] }},
    {{ "name": "moved", "mesh": 0, "translation": [1, 0, 0] }},
    {{ "name": "turned", "mesh": 0, "rotation": [0, 0.70710678, 0, 0.70710678] }},
    {{ "name": "stretched", "mesh": 0, "scale": {stretch} }}
  ],
  "meshes": [{{ "name": "quad", "primitives": [{{ "attributes": {{ "POSITION": 0 }}, "indices": {indices_accessor}, "material": 0 }}] }}],
  "materials": [{{ "name": "red", "pbrMetallicRoughness": {{ "baseColorFactor": [0.8, 0.1, 0.1, 1] }} }}],
  "accessors": [
    {{ "bufferView": 0, "componentType": 5126, "count": 4, "type": "VEC3", "min": [0, 0, 0], "max": [1, 1, 0] }},
    {{ "bufferView": 1, "componentType": 5123, "count": 6, "type": "SCALAR" }},
    {{ "bufferView": 1, "componentType": 5123, "count": 6, "type": "SCALAR", "byteOffset": 0 }}
  ],
  "bufferViews": [
    {{ "buffer": 0, "byteOffset": 0, "byteLength": 48 }},
    {{ "buffer": 0, "byteOffset": 48, "byteLength": 12 }}
  ],
  "buffers": [{{ {uri}"byteLength": 60 }}]
}}"#
        )
    }

    fn data_uri() -> String {
        format!(
            "data:application/octet-stream;base64,{}",
            base64::engine::general_purpose::STANDARD.encode(quad_bytes())
        )
    }

    /// A file `name` in a fresh scratch directory, and the directory (removed when
    /// dropped).
    fn scratch(name: &str) -> (PrivateDir, PathBuf) {
        let dir = PrivateDir::new("relief-gltf").expect("scratch dir");
        let path = dir.join(name);
        (dir, path)
    }

    /// A .glb: the JSON chunk (padded with spaces) and the binary chunk.
    fn glb(json: &str, bin: &[u8]) -> Vec<u8> {
        let mut json = json.as_bytes().to_vec();
        json.resize(json.len().div_ceil(4) * 4, b' ');
        let mut bin = bin.to_vec();
        bin.resize(bin.len().div_ceil(4) * 4, 0);
        let total = 12 + 8 + json.len() + 8 + bin.len();
        let mut out = Vec::new();
        out.extend(b"glTF");
        out.extend(2u32.to_le_bytes());
        out.extend((total as u32).to_le_bytes());
        out.extend((json.len() as u32).to_le_bytes());
        out.extend(b"JSON");
        out.extend(json);
        out.extend((bin.len() as u32).to_le_bytes());
        out.extend(b"BIN\0");
        out.extend(bin);
        out
    }

    /// Normals as the file gives them are made unit, and a non-finite or zero one is
    /// taken as none (zero: shading falls back to the face's), as from an OBJ file.
    #[test]
    fn normals_are_settled_as_from_an_obj_file() {
        let mut bytes = Vec::new();
        for p in [[0f32, 0., 0.], [1., 0., 0.], [1., 1., 0.], [0., 1., 0.]] {
            bytes.extend(p.iter().flat_map(|c| c.to_le_bytes()));
        }
        for n in [[0f32, 0., 2.], [f32::NAN, 0., 1.], [0., 0., 0.], [0., 0., 1.]] {
            bytes.extend(n.iter().flat_map(|c| c.to_le_bytes()));
        }
        for i in [0u16, 1, 2, 0, 2, 3] {
            bytes.extend(i.to_le_bytes());
        }
        let json = r#"{
  "asset": { "version": "2.0" },
  "scene": 0,
  "scenes": [{ "nodes": [0] }],
  "nodes": [{ "name": "quad", "mesh": 0 }],
  "meshes": [{ "primitives": [{ "attributes": { "POSITION": 0, "NORMAL": 1 }, "indices": 2 }] }],
  "accessors": [
    { "bufferView": 0, "componentType": 5126, "count": 4, "type": "VEC3", "min": [0, 0, 0], "max": [1, 1, 0] },
    { "bufferView": 1, "componentType": 5126, "count": 4, "type": "VEC3" },
    { "bufferView": 2, "componentType": 5123, "count": 6, "type": "SCALAR" }
  ],
  "bufferViews": [
    { "buffer": 0, "byteOffset": 0, "byteLength": 48 },
    { "buffer": 0, "byteOffset": 48, "byteLength": 48 },
    { "buffer": 0, "byteOffset": 96, "byteLength": 12 }
  ],
  "buffers": [{ "byteLength": 108 }]
}"#;
        let (_dir, path) = scratch("normals.glb");
        std::fs::write(&path, glb(json, &bytes)).expect("write");
        let model = load_gltf(&path, Reach::Anywhere).expect("load");
        let mesh = model.meshes[0].as_ref().expect("mesh built");
        let normals = mesh.normals.as_ref().expect("normals");
        assert_eq!(normals, &[Vec3::Z, Vec3::ZERO, Vec3::ZERO, Vec3::Z]);
        let merged = load_gltf_merged(&path, Reach::Anywhere).expect("merged");
        assert_eq!(merged.normals.as_ref(), Some(normals));
    }

    /// The quad's corner (1, 1, 0) in the world, through each placement, as composed by
    /// hand; the three placements of one mesh; the base colour as albedo. The same from
    /// a .gltf with a data: URI, one with the buffer in a file beside it, and a .glb.
    #[test]
    fn nodes_place_one_mesh_as_composed_by_hand() {
        let (_gltf_dir, gltf) = scratch("quad.gltf");
        std::fs::write(&gltf, document(Some(&data_uri()), 1, "[1, 2, 1]")).expect("write");
        let (_beside_dir, beside) = scratch("quad beside.gltf");
        std::fs::write(beside.with_file_name("quad data.bin"), quad_bytes()).expect("write");
        std::fs::write(&beside, document(Some("quad%20data.bin"), 1, "[1, 2, 1]")).expect("write");
        let (_binary_dir, binary) = scratch("quad.glb");
        std::fs::write(&binary, glb(&document(None, 1, "[1, 2, 1]"), &quad_bytes())).expect("write");
        for path in [gltf, beside, binary] {
            let counted = census(&path, Reach::Anywhere).expect("census");
            assert_eq!(
                (
                    counted.built_triangles,
                    counted.placed_triangles,
                    counted.placements
                ),
                (4, 6, 3), // (the stretched placement builds a copy)
                "{}",
                path.display()
            );
            let merged = load_gltf_merged(&path, Reach::Anywhere).expect("merged");
            assert_eq!(merged.triangle_count(), 6);
            let model = load_gltf(&path, Reach::Anywhere).expect("load");
            let names: Vec<&str> = model.placements.iter().map(|p| p.name.as_str()).collect();
            assert_eq!(names, ["moved", "turned", "stretched"]);
            assert!(model.placements.iter().all(|p| p.mesh == 0));
            let mesh = model.meshes[0].as_ref().expect("mesh built");
            assert_eq!(mesh.triangle_count(), 2);
            assert_eq!(mesh.materials[0].diffuse, Vec3::new(0.8, 0.1, 0.1));
            let corner = DVec3::new(1.0, 1.0, 0.0);
            let world: Vec<DVec3> = model
                .placements
                .iter()
                .map(|p| p.transform.transform_point3(corner))
                .collect();
            // parent: x ↦ (10, 0, 0) + 2x.
            let expected = [
                DVec3::new(10.0 + 2.0 * 2.0, 2.0, 0.0),
                DVec3::new(10.0, 2.0, -2.0),
                DVec3::new(12.0, 4.0, 0.0),
            ];
            for (w, e) in world.iter().zip(expected) {
                assert!(w.distance(e) < 1e-6, "{w} against {e}");
            }
            let kinds: Vec<bool> = model
                .placements
                .iter()
                .map(|p| similarity(&p.transform).is_some())
                .collect();
            assert_eq!(kinds, [true, true, false], "the stretch is no similarity");
            let (origin, _, scale) = similarity(&model.placements[1].transform).expect("turned");
            assert!(
                (scale - 2.0).abs() < 1e-6 && origin.distance(DVec3::new(10.0, 0.0, 0.0)) < 1e-9,
                "{scale} {origin}"
            );
            // As a scene: the similarities place one mesh, the stretch has its own.
            let scene = crate::scene::Scene::load(&path.to_string_lossy()).expect("scene");
            let objects = &scene.objects;
            assert_eq!(objects.iter().map(|o| o.name.as_str()).collect::<Vec<_>>(), names);
            assert!(objects[0].shares_mesh(&objects[1]) && !objects[0].shares_mesh(&objects[2]));
            for (object, e) in objects.iter().zip(expected) {
                let local = object.mesh.positions[2];
                assert!(
                    object.to_world(local).distance(e) < 1e-5,
                    "{}: {}",
                    object.name,
                    object.to_world(local)
                );
            }
        }
    }

    /// Faults name what is at fault: an accessor index past the list (the JSON path),
    /// vectors of floats given as indices, indices naming a vertex past the positions
    /// (the accessor), a transform that
    /// overflows (the node), a buffer shorter than it says, a URI that is not a file.
    #[test]
    fn bad_files_name_the_fault() {
        let cases: [(String, &str); 6] = [
            (document(Some(&data_uri()), 9, "[1, 2, 1]"), "indices"),
            (
                document(Some(&data_uri()), 0, "[1, 2, 1]"),
                "accessor 0: 1 components",
            ),
            (
                document(Some(&data_uri()), 1, "[1, 1e39, 1]"),
                "node 3 (`stretched`)",
            ),
            (
                document(Some("data:application/octet-stream;base64,AAAA"), 1, "[1, 2, 1]"),
                "buffer 0: 3 bytes",
            ),
            (
                document(Some("https://example.com/quad.bin"), 1, "[1, 2, 1]"),
                "only data: URIs",
            ),
            (document(Some("missing.bin"), 1, "[1, 2, 1]"), "buffer 0"),
        ];
        for (k, (text, named)) in cases.iter().enumerate() {
            let (_dir, path) = scratch(&format!("bad{k}.gltf"));
            std::fs::write(&path, text).expect("write");
            let message = load_gltf(&path, Reach::Anywhere)
                .expect_err("refused")
                .to_string();
            assert!(
                message.contains(named) && message.contains("bad"),
                "case {k}: {message}"
            );
        }
        // Indices past the quad's four vertices.
        let mut bytes = quad_bytes();
        bytes[48..50].copy_from_slice(&7u16.to_le_bytes());
        let uri = format!(
            "data:application/octet-stream;base64,{}",
            base64::engine::general_purpose::STANDARD.encode(&bytes)
        );
        let (_dir, path) = scratch("past.gltf");
        std::fs::write(&path, document(Some(&uri), 1, "[1, 2, 1]")).expect("write");
        let message = load_gltf(&path, Reach::Anywhere)
            .expect_err("refused")
            .to_string();
        assert!(
            message.contains("index 7") && message.contains("accessor 1"),
            "{message}"
        );
        let (_dir, none) = scratch("none.glb");
        assert!(load_gltf(&none, Reach::Anywhere).is_err());
        // A second buffer claiming the binary chunk (a copy of it each, once).
        let two = document(None, 1, "[1, 2, 1]").replace(
            r#""buffers": [{ "byteLength": 60 }]"#,
            r#""buffers": [{ "byteLength": 60 }, { "byteLength": 60 }]"#,
        );
        let (_dir, path) = scratch("two.glb");
        std::fs::write(&path, glb(&two, &quad_bytes())).expect("write");
        let message = load_gltf(&path, Reach::Anywhere)
            .expect_err("refused")
            .to_string();
        assert!(message.contains("buffer 1 has no uri"), "{message}");
    }

    /// What a small file can make a loader build is counted before it is read: every
    /// primitive of a mesh, the mesh once however many similar placements, and a
    /// placement that is no similarity its own copy.
    #[test]
    fn the_census_counts_what_would_be_built() {
        let one_triangle_each = document(Some(&data_uri()), 1, "[1, 2, 1]").replace(
            r#""primitives": [{ "attributes": { "POSITION": 0 }, "indices": 1, "material": 0 }]"#,
            &format!(
                r#""primitives": [{}]"#,
                vec![r#"{ "attributes": { "POSITION": 0 }, "indices": 1 }"#; 50].join(", ")
            ),
        );
        let (_dir, path) = scratch("many.gltf");
        std::fs::write(&path, &one_triangle_each).expect("write");
        let counted = census(&path, Reach::Anywhere).expect("census");
        // 50 primitives of 2 triangles (6 indices, 4 vertices): 100 a mesh, built once
        // for the two similar placements and once more for the stretched one.
        assert_eq!((counted.built_triangles, counted.placed_triangles), (200, 300));
    }

    /// Repeated and empty node names become unique object names; a mirroring node's
    /// mesh keeps its faces facing out (its corners reversed).
    #[test]
    fn nodes_alike_get_names_of_their_own_and_mirrors_face_out() {
        let text = document(Some(&data_uri()), 1, "[1, 1, -1]")
            .replace(r#""name": "turned", "#, r#""name": "moved", "#)
            .replace(r#""name": "stretched", "#, "");
        let (_dir, path) = scratch("alike.gltf");
        std::fs::write(&path, text).expect("write");
        let scene = crate::scene::Scene::load(&path.to_string_lossy()).expect("scene");
        let names: Vec<&str> = scene.objects.iter().map(|o| o.name.as_str()).collect();
        assert_eq!(names, ["moved", "moved_2", "node3"]);
        let mirrored = &scene.objects[2];
        let [a, b, c] = mirrored.mesh.triangles[0];
        let p = |i: u32| mirrored.mesh.positions[i as usize];
        // The quad faces +z; mirrored in z it faces −z, and so must its winding.
        assert!(
            (p(b) - p(a)).cross(p(c) - p(a)).z < 0.0,
            "{:?}",
            mirrored.mesh.triangles[0]
        );
    }
}
