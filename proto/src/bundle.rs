//! Scene bundles: a scene and every file it needs, as one message addressed by its
//! content hash — how a scene travels from a client to the server and on to workers.

use std::path::{Component, Path, PathBuf};

use prost::Message;

use relief_core::hash::ContentHash;
use relief_core::reach::Reach;
use relief_core::scene::{Scene, SceneLimits};
use relief_core::scratch::PrivateDir;
use relief_core::{Error, Result};

use crate::convert::bundle_hash;
use crate::pb::{SceneBundle, SceneFile};

/// Largest encoded bundle accepted (the default scene's is a few KiB; OBJ scans can be
/// tens of MiB).
pub const MAX_BUNDLE_BYTES: usize = 512 << 20;

/// A bundle and its encoding and hash.
#[derive(Debug, Clone)]
pub struct Bundle {
    pub bundle: SceneBundle,
    pub encoded: Vec<u8>,
    pub hash: ContentHash,
}

/// A received bundle that cannot be taken; each names what is wrong.
#[derive(Debug, Clone, PartialEq, thiserror::Error)]
pub enum BundleError {
    #[error("scene bundle of {0} bytes exceeds {MAX_BUNDLE_BYTES}")]
    TooLarge(usize),
    #[error("malformed scene bundle: {0}")]
    Malformed(prost::DecodeError),
    #[error("scene bundle has no file `{0}` (its root)")]
    NoRoot(String),
    #[error("scene bundle path `{0}` is not a plain relative path")]
    NotRelative(String),
}

impl Bundle {
    fn new(bundle: SceneBundle) -> Bundle {
        let encoded = bundle.encode_to_vec();
        Bundle {
            hash: bundle_hash(&encoded),
            bundle,
            encoded,
        }
    }

    /// Decodes a received bundle; errors say what is wrong with it.
    pub fn decode(encoded: Vec<u8>) -> std::result::Result<Bundle, BundleError> {
        if encoded.len() > MAX_BUNDLE_BYTES {
            return Err(BundleError::TooLarge(encoded.len()));
        }
        let bundle = SceneBundle::decode(encoded.as_slice()).map_err(BundleError::Malformed)?;
        if !bundle.files.iter().any(|f| f.path == bundle.root) {
            return Err(BundleError::NoRoot(bundle.root));
        }
        for f in &bundle.files {
            safe_relative(&f.path).ok_or_else(|| BundleError::NotRelative(f.path.clone()))?;
        }
        Ok(Bundle {
            hash: bundle_hash(&encoded),
            bundle,
            encoded,
        })
    }

    /// Writes the files under `dir/<hash>/` and loads the scene from there, reading
    /// no file outside it: the server loads bundles from anyone who can reach it, and
    /// an absolute or `..` path in a scene, OBJ or MTL must not read its own disk; nor
    /// may a few bytes of scene build more than `limits` allow.
    pub fn load(&self, dir: &Path, limits: &SceneLimits) -> Result<Scene> {
        let root = dir.join(self.hash.to_string());
        // A root that is a link (planted by someone who can write `dir`) would move
        // the confinement wherever it points.
        if std::fs::symlink_metadata(&root).is_ok_and(|m| m.file_type().is_symlink()) {
            return Err(Error::Invalid(format!("{} is a symbolic link", root.display())));
        }
        for f in &self.bundle.files {
            let relative = safe_relative(&f.path)
                .ok_or_else(|| Error::Invalid(format!("bundle path `{}` is not relative", f.path)))?;
            let path = root.join(relative);
            if let Some(parent) = path.parent() {
                std::fs::create_dir_all(parent).map_err(|e| Error::io(parent, e))?;
            }
            std::fs::write(&path, &f.data).map_err(|e| Error::io(&path, e))?;
        }
        let scene_path = root.join(&self.bundle.root);
        Scene::load_within(&scene_path.to_string_lossy(), Reach::Within(&root), limits)
    }
}

/// A fresh directory for scene bundles, this process's own ([`PrivateDir`]): removed,
/// with the scenes in it, when the server or worker exits in good order.
pub fn private_scene_dir(prefix: &str) -> Result<PrivateDir> {
    PrivateDir::new(prefix).map_err(|e| Error::io(std::env::temp_dir(), e))
}

/// Where a server or worker unpacks scenes: the directory it was given (`--scene-dir`,
/// kept), or by default one of its own ([`private_scene_dir`], removed when this is
/// dropped, but for a look when dropped during a panic).
#[derive(Debug)]
pub enum SceneDir {
    Given(PathBuf),
    Own(PrivateDir),
}

impl SceneDir {
    /// `given`, or a private directory named after `prefix`.
    pub fn new(given: Option<PathBuf>, prefix: &str) -> Result<SceneDir> {
        Ok(match given {
            Some(dir) => SceneDir::Given(dir),
            None => SceneDir::Own(private_scene_dir(prefix)?),
        })
    }

    pub fn path(&self) -> &Path {
        match self {
            SceneDir::Given(dir) => dir,
            SceneDir::Own(dir) => dir.path(),
        }
    }
}

/// The argument of every `keyword` line of an OBJ or MTL file: the keyword, any
/// whitespace (tobj splits on spaces and tabs alike), then the rest of the line.
fn referenced(text: &[u8], keyword: &str) -> Vec<String> {
    String::from_utf8_lossy(text)
        .lines()
        .filter_map(|l| {
            let (first, rest) = l.trim().split_once(char::is_whitespace)?;
            (first == keyword).then(|| rest.trim().to_string())
        })
        .filter(|r| !r.is_empty())
        .collect()
}

/// `path` as a relative path without `..`, root or prefix components.
fn safe_relative(path: &str) -> Option<PathBuf> {
    let p = Path::new(path);
    let ok = !path.is_empty() && p.components().all(|c| matches!(c, Component::Normal(_)));
    ok.then(|| p.to_path_buf())
}

/// The bundle of a `--scene` argument: a built-in name, a TOML scene file with the
/// OBJ and glTF files it names, or a bare OBJ or glTF file — each OBJ with its MTL files
/// and their textures, each glTF file with the buffers and images it names.
pub fn bundle_for(spec: &str) -> Result<Bundle> {
    let path = Path::new(spec);
    let extension = path.extension().map(|e| e.to_string_lossy().to_ascii_lowercase());
    let read = |p: &Path| std::fs::read(p).map_err(|e| Error::io(p, e));
    let mut files = Vec::new();
    let root = match extension.as_deref() {
        Some("obj") => {
            let name = file_name(path)?;
            add_obj(path, &name, &mut files)?;
            name
        }
        Some("gltf" | "glb") => {
            let name = file_name(path)?;
            add_gltf(path, &name, &mut files)?;
            name
        }
        Some("toml") => {
            let text = read(path)?;
            let name = file_name(path)?;
            let base = path.parent().unwrap_or(Path::new("."));
            let table: toml::Table = std::str::from_utf8(&text)
                .ok()
                .and_then(|t| toml::from_str(t).ok())
                .ok_or_else(|| Error::Scene {
                    origin: spec.to_string(),
                    message: "not valid TOML".into(),
                })?;
            let objs = table
                .get("objects")
                .and_then(|o| o.as_array())
                .into_iter()
                .flatten();
            for object in objs {
                let named = |key: &str| object.get(key).and_then(|v| v.as_str());
                if let Some(obj) = named("obj") {
                    add_obj(&base.join(obj), obj, &mut files)?;
                }
                if let Some(gltf) = named("gltf") {
                    add_gltf(&base.join(gltf), gltf, &mut files)?;
                }
            }
            files.push(SceneFile {
                path: name.clone(),
                data: text,
            });
            name
        }
        _ => {
            let text = relief_core::scene::builtin_text(spec)
                .ok_or_else(|| Error::UnknownScene(spec.to_string()))?;
            files.push(SceneFile {
                path: format!("{spec}.toml"),
                data: text.as_bytes().to_vec(),
            });
            format!("{spec}.toml")
        }
    };
    Ok(Bundle::new(SceneBundle { root, files }))
}

fn file_name(path: &Path) -> Result<String> {
    path.file_name()
        .map(|n| n.to_string_lossy().into_owned())
        .ok_or_else(|| Error::Invalid(format!("{} has no file name", path.display())))
}

/// Where the files a model names lie: beside the model on disk, and beside its name in
/// the bundle.
struct Beside {
    base: PathBuf,
    name_dir: PathBuf,
}

impl Beside {
    fn of(path: &Path, name: &str) -> Beside {
        Beside {
            base: path.parent().unwrap_or(Path::new(".")).to_path_buf(),
            name_dir: Path::new(name)
                .parent()
                .map(Path::to_path_buf)
                .unwrap_or_default(),
        }
    }

    /// The bytes of the file `relative` names beside the model, if it can be read (a
    /// missing one is the loader's to name, not the bundle's).
    fn read(&self, relative: impl AsRef<Path>) -> Option<Vec<u8>> {
        std::fs::read(self.base.join(relative)).ok()
    }

    /// Adds `data` as the file `relative` names beside the model.
    fn add(&self, relative: impl AsRef<Path>, data: Vec<u8>, files: &mut Vec<SceneFile>) {
        files.push(SceneFile {
            path: self.name_dir.join(relative).to_string_lossy().into_owned(),
            data,
        });
    }
}

/// Adds an OBJ (as `name`), its MTL files and their texture maps.
fn add_obj(path: &Path, name: &str, files: &mut Vec<SceneFile>) -> Result<()> {
    let data = std::fs::read(path).map_err(|e| Error::io(path, e))?;
    let beside = Beside::of(path, name);
    for mtl in referenced(&data, "mtllib") {
        let Some(mtl_data) = beside.read(&mtl) else {
            continue; // A missing MTL is a warning when loading, not an error.
        };
        for texture in referenced(&mtl_data, "map_Kd") {
            if let Some(bytes) = beside.read(&texture) {
                beside.add(&texture, bytes, files);
            }
        }
        beside.add(&mtl, mtl_data, files);
    }
    files.push(SceneFile {
        path: name.to_string(),
        data,
    });
    Ok(())
}

/// Adds a glTF file (as `name`) and the buffers and images beside it that it names.
fn add_gltf(path: &Path, name: &str, files: &mut Vec<SceneFile>) -> Result<()> {
    let data = std::fs::read(path).map_err(|e| Error::io(path, e))?;
    let beside = Beside::of(path, name);
    for file in relief_core::gltf::referenced_files(path, &data)? {
        // (One that would leave the model's directory is left out: refused on loading.)
        if let Some(relative) = safe_relative(&file)
            && let Some(bytes) = beside.read(&relative)
        {
            beside.add(&relative, bytes, files);
        }
    }
    files.push(SceneFile {
        path: name.to_string(),
        data,
    });
    Ok(())
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn references_are_found_however_the_line_is_spaced() {
        let text = b"mtllib a.mtl\nmtllib\tb c.mtl\n  map_Kd  t.png \nmtllibx no.mtl\nmtllib\n";
        assert_eq!(referenced(text, "mtllib"), ["a.mtl", "b c.mtl"]);
        assert_eq!(referenced(text, "map_Kd"), ["t.png"]);
    }

    #[test]
    fn builtin_bundle_round_trips_and_loads() {
        let b = bundle_for("default").unwrap();
        let again = Bundle::decode(b.encoded.clone()).unwrap();
        assert_eq!(again.hash, b.hash);
        assert_eq!(bundle_for("default").unwrap().hash, b.hash, "stable hash");
        // (Removed when the test ends.)
        let dir = private_scene_dir("relief-bundle-test").unwrap();
        let scene = again.load(dir.path(), &SceneLimits::default()).unwrap();
        assert!(scene.object("knot").is_ok());
    }

    /// A glTF file's bundle carries the buffer file beside it that it names, and loads
    /// from the bundle alone; a buffer named outside the bundle is refused unread.
    #[test]
    fn a_gltf_bundle_carries_its_buffers() {
        let made = private_scene_dir("relief-bundle-gltf").unwrap();
        let dir = made.path();
        let mut bytes = Vec::new();
        for p in [[0f32, 0., 0.], [1., 0., 0.], [0., 1., 0.]] {
            bytes.extend(p.iter().flat_map(|c| c.to_le_bytes()));
        }
        let gltf = |uri: &str| {
            format!(
                r#"{{"asset": {{"version": "2.0"}}, "scenes": [{{"nodes": [0]}}],
                "nodes": [{{"name": "tri", "mesh": 0}}],
                "meshes": [{{"primitives": [{{"attributes": {{"POSITION": 0}}}}]}}],
                "accessors": [{{"bufferView": 0, "componentType": 5126, "count": 3, "type": "VEC3", "min": [0, 0, 0], "max": [1, 1, 0]}}],
                "bufferViews": [{{"buffer": 0, "byteLength": 36}}],
                "buffers": [{{"uri": "{uri}", "byteLength": 36}}]}}"#
            )
        };
        let source = dir.join("source");
        std::fs::create_dir_all(&source).unwrap();
        std::fs::write(source.join("tri data.bin"), &bytes).unwrap();
        std::fs::write(source.join("tri.gltf"), gltf("tri%20data.bin")).unwrap();
        let bundle = bundle_for(&source.join("tri.gltf").to_string_lossy()).unwrap();
        let scene = Bundle::decode(bundle.encoded.clone())
            .unwrap()
            .load(&dir.join("bundles"), &SceneLimits::default())
            .unwrap();
        assert_eq!(scene.objects[0].name, "tri");
        assert_eq!(scene.objects[0].mesh.triangle_count(), 1);
        std::fs::write(source.join("out.gltf"), gltf("../source/tri%20data.bin")).unwrap();
        let bundle = bundle_for(&source.join("out.gltf").to_string_lossy()).unwrap();
        let err = Bundle::decode(bundle.encoded.clone())
            .unwrap()
            .load(&dir.join("bundles2"), &SceneLimits::default())
            .unwrap_err()
            .to_string();
        assert!(err.contains("buffer 0"), "{err}");
    }

    #[test]
    fn a_bundle_reads_no_file_outside_itself() {
        let made = private_scene_dir("relief-bundle-refs").unwrap();
        let dir = made.path();
        // Beside the bundles' directory: a material that would paint the object red.
        std::fs::write(dir.join("outside.mtl"), "newmtl red\nKd 1 0 0\n").unwrap();
        let triangle = "v 0 0 0\nv 1 0 0\nv 0 1 0\nf 1 2 3\n";
        let scene = |obj: &str| format!("[[objects]]\nname = \"a\"\nobj = \"{obj}\"\n").into_bytes();
        let file = |path: &str, data: Vec<u8>| SceneFile {
            path: path.into(),
            data,
        };
        let load = |files: Vec<SceneFile>| {
            let bundle = SceneBundle {
                root: "s.toml".into(),
                files,
            };
            Bundle::decode(bundle.encode_to_vec())
                .unwrap()
                .load(&dir.join("bundles"), &SceneLimits::default())
        };
        let obj = |text: String| file("t.obj", text.into_bytes());
        // A scene whose OBJ is in the bundle loads.
        assert!(load(vec![obj(triangle.into()), file("s.toml", scene("t.obj"))]).is_ok());
        // OBJ paths that leave the bundle, or name no file of it, are refused unread
        // (whatever the file is called).
        for outside in ["/etc/hostname", "../../outside.mtl", "missing.obj", "/dev/zero"] {
            let err = load(vec![obj(triangle.into()), file("s.toml", scene(outside))])
                .unwrap_err()
                .to_string();
            assert!(err.contains("outside the scene's own files"), "{outside}: {err}");
        }
        // An MTL outside it is not read (however the line is spaced): the default
        // material stays.
        for line in [
            "mtllib ../../outside.mtl",
            "mtllib\t../../outside.mtl",
            "mtllib /dev/zero",
        ] {
            let text = format!("{line}\nusemtl red\n{triangle}");
            let scene = load(vec![obj(text), file("s.toml", scene("t.obj"))]).unwrap();
            let materials = &scene.objects[0].mesh.materials;
            assert!(materials.iter().all(|m| m.name != "red"), "{line}: {materials:?}");
        }
    }

    #[test]
    fn bad_bundles_are_refused() {
        assert!(Bundle::decode(vec![0xff, 0xff, 0xff]).is_err());
        let escape = SceneBundle {
            root: "../x.toml".into(),
            files: vec![SceneFile {
                path: "../x.toml".into(),
                data: vec![],
            }],
        };
        assert!(
            Bundle::decode(escape.encode_to_vec())
                .unwrap_err()
                .to_string()
                .contains("relative")
        );
        let rootless = SceneBundle {
            root: "a.toml".into(),
            files: vec![],
        };
        assert!(
            Bundle::decode(rootless.encode_to_vec())
                .unwrap_err()
                .to_string()
                .contains("root")
        );
    }
}
