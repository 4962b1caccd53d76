//! Scenes: objects placed in the world, lights, and a camera path.
//!
//! `--scene` everywhere goes through [`Scene::load`], which accepts a built-in scene
//! name (see [`builtin_names`]), a TOML scene file (schema in [`file`](mod@file)) or a bare
//! `.obj` file (a one-object scene named after the file).

pub mod file;
mod forest;

use std::collections::{HashMap, HashSet};
use std::path::Path;
use std::sync::Arc;

use glam::{DQuat, DVec3, Vec3};

use crate::bounds::Aabb;
use crate::camera::{Camera, CameraPath, PathSegment};
use crate::error::{Error, Result};
use crate::hash::{ContentHash, mesh_hash};
use crate::mesh::{EdgeCensus, Mesh};
use crate::normals::NormalCensus;
use crate::reach::Reach;
use crate::shading::{Light, Lighting, Specular};

/// Built-in scenes, embedded so that they work from any directory.
const BUILTINS: &[(&str, &str)] = &[
    ("default", include_str!("../../../assets/scenes/default.toml")),
    (
        "orbit-knot",
        include_str!("../../../assets/scenes/orbit-knot.toml"),
    ),
    (
        "orbit-sphere",
        include_str!("../../../assets/scenes/orbit-sphere.toml"),
    ),
];

/// The built-in scene made by a rule rather than kept as a file: [`forest`].
const FOREST: &str = "forest";

/// Names accepted by [`Scene::load`] without a file.
pub fn builtin_names() -> Vec<&'static str> {
    BUILTINS.iter().map(|(name, _)| *name).chain([FOREST]).collect()
}

/// The TOML text of a built-in scene.
pub fn builtin_text(name: &str) -> Option<&'static str> {
    match name {
        FOREST => Some(forest::text()),
        _ => BUILTINS.iter().find(|(n, _)| *n == name).map(|(_, text)| *text),
    }
}

/// The longest object name accepted.
pub const MAX_OBJECT_NAME: usize = 64;

/// What a scene may cost, checked from its files before anything is built: a few
/// bytes of scene file can name a generator of billions of triangles.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct SceneLimits {
    /// Triangles over every mesh built (generators' counts from their parameters, OBJ
    /// files' from their face lines, glTF files' from their JSON:
    /// [`GltfCensus`](crate::gltf::GltfCensus)).
    pub max_triangles: u64,
    pub max_objects: usize,
}

impl Default for SceneLimits {
    /// For scenes the user names: about 6 GB of meshes at most, far past any scene
    /// the project ships (the largest scanned mesh has 69,451 triangles).
    fn default() -> Self {
        SceneLimits {
            max_triangles: 64_000_000,
            max_objects: 100_000,
        }
    }
}

impl SceneLimits {
    /// An error naming the limit when `triangles` over `objects` objects exceed it.
    pub fn check(&self, triangles: u64, objects: usize) -> Result<()> {
        if objects > self.max_objects {
            return Err(Error::TooCostly(format!(
                "{objects} objects; at most {} are allowed here",
                self.max_objects
            )));
        }
        if triangles > self.max_triangles {
            return Err(Error::TooCostly(format!(
                "{triangles} triangles; at most {} are allowed here",
                self.max_triangles
            )));
        }
        Ok(())
    }
}

/// The largest `f32` step, as a share of an object's extent, at which it is placed
/// finely enough: one 16-bit depth level of a texture spanning the object. Past it
/// (an object 1 m across some 130 m from the origin), depths baked and warped there
/// are off by whole levels (measured at 10⁵ m: 40–96 levels).
pub const PRECISION_LIMIT: f32 = 1.0 / 65_534.0;

/// Object names become file names (report images, texture directories), so they are
/// ASCII letters, digits, `-`, `_` and `.`, not starting with `.`, at most
/// [`MAX_OBJECT_NAME`] long: never a path.
pub fn check_object_name(name: &str) -> Result<(), BadObjectName> {
    if name.is_empty()
        || name.len() > MAX_OBJECT_NAME
        || name.starts_with('.')
        || !name.chars().all(name_char)
    {
        return Err(BadObjectName(name.to_string()));
    }
    Ok(())
}

/// The name of placement `k` (from 1) of the object `object` of a scene file
/// with `instances`: `object.k`.
pub fn placement_name(object: &str, k: usize) -> String {
    format!("{object}.{k}")
}

/// The object a placement is of, by the placement's name ([`placement_name`]
/// undone): `tree.17` → `tree`; any other name is its own object's.
pub fn placed_object(name: &str) -> &str {
    match name.rsplit_once('.') {
        Some((object, k)) if !k.is_empty() && k.bytes().all(|b| b.is_ascii_digit()) => object,
        _ => name,
    }
}

/// An object name [`check_object_name`] refuses.
#[derive(Debug, Clone, PartialEq, Eq, thiserror::Error)]
#[error(
    "object name `{0}` must be 1 to {MAX_OBJECT_NAME} ASCII letters, digits, `-`, `_` or `.`, not starting with `.`"
)]
pub struct BadObjectName(pub String);

/// Object names made unique and valid from names that may repeat or be empty (a glTF
/// file's nodes): `wheel`, `wheel_2`, `wheel_3`, … each in constant time.
#[derive(Default)]
struct UniqueNames {
    taken: HashSet<String>,
    /// Per stem, the suffix to try next.
    next: HashMap<String, u64>,
}

impl UniqueNames {
    fn make(&mut self, text: &str) -> String {
        let stem = object_name(text, "node");
        let mut k = self.next.get(&stem).copied().unwrap_or(1);
        loop {
            let name = if k == 1 {
                stem.clone()
            } else {
                // (The stem cut to leave room for the suffix within the longest name.)
                let suffix = format!("_{k}");
                let kept: String = stem.chars().take(MAX_OBJECT_NAME - suffix.len()).collect();
                kept + &suffix
            };
            k += 1;
            if self.taken.insert(name.clone()) {
                self.next.insert(stem, k);
                return name;
            }
        }
    }
}

/// `text` (a file's stem, a node's name) made a valid object name (see
/// [`check_object_name`]): other characters, dots too (so it cannot start with one),
/// become `_`, and it is cut to [`MAX_OBJECT_NAME`]; `fallback` when nothing is left.
fn object_name(text: &str, fallback: &str) -> String {
    let name: String = text
        .chars()
        .map(|c| if name_char(c) && c != '.' { c } else { '_' })
        .take(MAX_OBJECT_NAME)
        .collect();
    if name.is_empty() {
        fallback.to_string()
    } else {
        name
    }
}

/// A character an object name may hold ([`check_object_name`]).
fn name_char(c: char) -> bool {
    c.is_ascii_alphanumeric() || matches!(c, '-' | '_' | '.')
}

/// One object of a scene: its mesh in the object's own frame, and where that frame
/// lies in the world.
///
/// # Frames
///
/// A world may lie far from its origin (a city in survey coordinates, 10⁶ m out),
/// where an `f32` steps by centimetres: meshes, bakes and warps there lost whole depth
/// levels. So everything about one object — its mesh, its bounds, its relief
/// textures and the eyes they are made for — is given in the object's own frame,
/// whose origin lies at [`SceneObject::origin`] (in `f64`). Scene-wide code moves a
/// camera into it with [`SceneObject::local_camera`]: one `f64` subtraction, after
/// which all is `f32` near the origin, as precise wherever the object stands.
///
/// # Placements
///
/// One mesh placed many times (a scene file's `instances`) is one [`Mesh`] in memory:
/// each placement is a `SceneObject` of its own, named apart, sharing the mesh, its
/// hash, its edge census and its normal census ([`SceneObject::placed`]). A placement
/// may also turn and scale its frame: a world point is `origin + scale · rotation · x`
/// of a point `x` of the frame. A camera moved into the frame
/// ([`SceneObject::local_camera`]) sees the same image (a similarity moves eye and
/// object alike), so the textures, bakes, warps and every decision about the object are
/// the mesh's own, shared by its placements. Three things leave the frame: depths a
/// writer puts into a frame's buffer, in the world's metres (times
/// [`SceneObject::depth_scale`]); normals, turned into the world where the frame is lit
/// ([`SceneObject::normal_to_world`]); and a reference's rays and hits.
#[derive(Debug, Clone)]
pub struct SceneObject {
    pub name: String,
    /// The mesh, in the object's frame.
    pub mesh: Arc<Mesh>,
    /// Where the object's frame's origin lies in the world.
    pub origin: DVec3,
    /// How the object's frame is turned in the world (the identity for most).
    pub rotation: DQuat,
    /// World metres per metre of the object's frame (1 for most).
    pub scale: f64,
    /// Bounds of the mesh, in the object's frame.
    pub local_bounds: Aabb,
    pub specular: Specular,
    /// Content hash of the mesh in the object's frame.
    pub hash: ContentHash,
    /// How the mesh's edges are shared ([`Mesh::edge_census`]), found the first time it
    /// is asked (only a client drawing impostors needs it, and it costs a pass over the
    /// mesh); shared by the mesh's placements.
    edges: Arc<std::sync::OnceLock<EdgeCensus>>,
    /// The mesh's area by the direction it faces ([`NormalCensus`]), found the first
    /// time it is asked, as `edges`; shared by the mesh's placements.
    normals: Arc<std::sync::OnceLock<NormalCensus>>,
}

impl SceneObject {
    /// Whether the mesh is closed ([`Mesh::is_closed`]): from outside, its back faces
    /// never show.
    pub fn is_closed(&self) -> bool {
        self.edge_census().closed
    }

    /// How the mesh's edges are shared ([`Mesh::edge_census`]).
    pub fn edge_census(&self) -> EdgeCensus {
        *self.edges.get_or_init(|| self.mesh.edge_census())
    }

    /// The mesh's area by the direction it faces ([`NormalCensus::of`]).
    pub fn normal_census(&self) -> &NormalCensus {
        self.normals.get_or_init(|| NormalCensus::of(&self.mesh))
    }

    /// Whether the object's frame has the world's axes and metres: then moving into it
    /// is one subtraction.
    fn is_moved_only(&self) -> bool {
        self.rotation == DQuat::IDENTITY && self.scale == 1.0
    }

    /// `camera` (in the world) moved into the object's frame: the same image (see
    /// [Placements](SceneObject#placements)).
    pub fn local_camera(&self, camera: &Camera) -> Camera {
        if self.is_moved_only() {
            return camera.relative_to(self.origin);
        }
        let turn = self.rotation.inverse();
        let axis = |v: Vec3| (turn * v.as_dvec3()).normalize().as_vec3();
        Camera {
            eye: self.in_frame(camera.eye),
            forward: axis(camera.forward),
            right: axis(camera.right),
            up: axis(camera.up),
            ..*camera
        }
    }

    /// A world point in the object's frame.
    pub fn to_local(&self, world: DVec3) -> Vec3 {
        if self.is_moved_only() {
            return (world - self.origin).as_vec3();
        }
        self.in_frame(world).as_vec3()
    }

    /// A world point in the object's (turned, scaled) frame, still in `f64`.
    fn in_frame(&self, world: DVec3) -> DVec3 {
        self.rotation.inverse() * (world - self.origin) / self.scale
    }

    /// A point of the object's frame in the world.
    pub fn to_world(&self, local: Vec3) -> DVec3 {
        self.origin + self.rotation * local.as_dvec3() * self.scale
    }

    /// World view depth per view depth in the object's frame: a writer seeing the
    /// object through [`SceneObject::local_camera`] stores its depths times this.
    pub fn depth_scale(&self) -> f32 {
        self.scale as f32
    }

    /// A normal (or any direction) of the object's frame, turned into the world.
    pub fn normal_to_world(&self, normal: Vec3) -> Vec3 {
        self.rotation.as_quat() * normal
    }

    /// The frame's turn in the world, where it has one (`None`: the world's axes).
    pub fn turn(&self) -> Option<glam::Quat> {
        (self.rotation != DQuat::IDENTITY).then(|| self.rotation.as_quat())
    }

    /// `lighting` (the world's) in the object's frame: point lights moved, turned and
    /// scaled into it, directional ones turned. (Lights here do not fade with distance,
    /// so what they light is the same in either frame.)
    pub fn local_lighting(&self, lighting: &Lighting) -> Lighting {
        if self.is_moved_only() {
            return lighting.relative_to(self.origin);
        }
        let turn = self.rotation.inverse().as_quat();
        let lights = (lighting.lights.iter())
            .map(|light| match *light {
                Light::Point { position, color } => Light::Point {
                    position: self.to_local(position.as_dvec3()),
                    color,
                },
                Light::Directional { direction, color } => Light::Directional {
                    direction: turn * direction,
                    color,
                },
            })
            .collect();
        Lighting {
            ambient: lighting.ambient,
            lights,
        }
    }

    /// The object's bounds in the world, rounded out to `f32`: for scene-wide
    /// decisions that need no more than that (the default path, what a view may see);
    /// never for drawing.
    pub fn world_bounds(&self) -> Aabb {
        let corners = self.local_bounds.corners().map(|c| self.to_world(c));
        let (lo, hi) = corners
            .iter()
            .fold((corners[0], corners[0]), |(lo, hi), &c| (lo.min(c), hi.max(c)));
        Aabb {
            min: lo.as_vec3().map(f32::next_down),
            max: hi.as_vec3().map(f32::next_up),
        }
    }

    /// A scene object of `mesh` (in its own frame), that frame's origin placed at
    /// `origin` in the world, its axes and metres the world's.
    pub fn new(name: impl Into<String>, mesh: Mesh, origin: DVec3, specular: Specular) -> Self {
        SceneObject {
            name: name.into(),
            origin,
            rotation: DQuat::IDENTITY,
            scale: 1.0,
            local_bounds: mesh.bounds(),
            hash: mesh_hash(&mesh),
            edges: Arc::default(),
            normals: Arc::default(),
            mesh: Arc::new(mesh),
            specular,
        }
    }

    /// Another placement of this object's mesh, named `name`: its frame's origin at
    /// `origin`, turned by `rotation` and scaled by `scale` (> 0) in the world (see
    /// [Placements](SceneObject#placements)); the mesh (and what is known of it)
    /// shared, not copied.
    pub fn placed(&self, name: impl Into<String>, origin: DVec3, rotation: DQuat, scale: f64) -> SceneObject {
        SceneObject {
            name: name.into(),
            origin,
            rotation: rotation.normalize(),
            scale,
            ..self.clone()
        }
    }

    /// Whether `other` is a placement of the same mesh in memory ([`SceneObject::placed`]).
    pub fn shares_mesh(&self, other: &SceneObject) -> bool {
        Arc::ptr_eq(&self.mesh, &other.mesh)
    }
}

/// A loaded scene.
#[derive(Debug, Clone)]
pub struct Scene {
    pub name: String,
    pub objects: Vec<SceneObject>,
    pub lighting: Lighting,
    /// Colour of pixels that see no object.
    pub background: Vec3,
    /// Vertical field of view of the default camera, degrees.
    pub fov_y_degrees: f32,
    pub path: CameraPath,
}

impl Scene {
    /// Loads a built-in scene by name, a `.toml` scene file, or a bare `.obj` or glTF (`.gltf`, `.glb`) file,
    /// within the [default](SceneLimits::default) limits.
    pub fn load(spec: &str) -> Result<Scene> {
        Self::load_within(spec, Reach::Anywhere, &SceneLimits::default())
    }

    /// A scene from the text of a scene file, within the [default](SceneLimits::default)
    /// limits; the paths it names are relative to the working directory.
    pub fn parse(text: &str) -> Result<Scene> {
        file::parse(
            text,
            "scene text",
            Path::new("."),
            Reach::Anywhere,
            &SceneLimits::default(),
        )
    }

    /// As [`Scene::load`], reading only files within `reach` (the built-in scenes
    /// read none), and refusing, before building it, a scene past `limits`.
    pub fn load_within(spec: &str, reach: Reach, limits: &SceneLimits) -> Result<Scene> {
        let path = Path::new(spec);
        let extension = path.extension().map(|e| e.to_string_lossy().to_ascii_lowercase());
        match extension.as_deref() {
            Some("obj") => Self::from_obj(path, reach, limits),
            Some("gltf" | "glb") => Self::from_gltf(path, reach, limits),
            Some("toml") => file::load_file(path, reach, limits),
            _ => match builtin_text(spec) {
                Some(text) => file::parse(text, &format!("built-in `{spec}`"), Path::new("."), reach, limits),
                None => Err(Error::UnknownScene(spec.to_string())),
            },
        }
    }

    /// A one-object scene from an OBJ file (and the MTL files and textures it names,
    /// within `reach`), with default lights and an orbit path; refused, before it is
    /// read whole, past `limits`.
    pub fn from_obj(path: &Path, reach: Reach, limits: &SceneLimits) -> Result<Scene> {
        limits.check(crate::obj::count_triangles(path, reach)?, 1)?;
        let mesh = crate::obj::load_obj(path, reach)?;
        file::check_extent(&mesh).map_err(|m| Error::Obj {
            path: path.to_path_buf(),
            message: format!("its vertices lie {m}"),
        })?;
        let name = object_name(&path.file_stem().unwrap_or_default().to_string_lossy(), "object");
        let object = SceneObject::new(name.clone(), mesh, DVec3::ZERO, Specular::default());
        Ok(Scene::of_model(name, vec![object]))
    }

    /// A scene of a glTF file (`.gltf` or `.glb`, with the buffers and images it names,
    /// within `reach`): an object for each node of its default scene that holds a mesh,
    /// named after the node, placing that mesh (one mesh in memory however many nodes
    /// use it; a node whose transform is not a similarity — an uneven scale, a shear —
    /// gets the mesh transformed into one of its own); default lights and an orbit
    /// path. Refused, before its buffers are read, past `limits`.
    pub fn from_gltf(path: &Path, reach: Reach, limits: &SceneLimits) -> Result<Scene> {
        let census = crate::gltf::census(path, reach)?;
        limits.check(census.built_triangles, census.placements)?;
        let model = crate::gltf::load_gltf(path, reach)?;
        let at_fault = |name: &str, message: String| Error::Obj {
            path: path.to_path_buf(),
            message: format!("node `{name}`: {message}"),
        };
        let mut templates: Vec<Option<SceneObject>> = vec![None; model.meshes.len()];
        let mut meshes = model.meshes;
        let mut names = UniqueNames::default();
        let mut objects = Vec::with_capacity(model.placements.len());
        for placement in &model.placements {
            let name = names.make(&placement.name);
            file::check_origin(placement.transform.translation).map_err(|e| at_fault(&name, e))?;
            let object = match crate::gltf::similarity(&placement.transform) {
                Some((origin, rotation, scale)) => {
                    let template = match &mut templates[placement.mesh] {
                        Some(template) => template,
                        slot => {
                            let mesh = (meshes[placement.mesh].take())
                                .ok_or_else(|| at_fault(&name, "its mesh was not built".into()))?;
                            file::check_extent(&mesh).map_err(|e| at_fault(&name, e.to_string()))?;
                            slot.insert(SceneObject::new(
                                name.clone(),
                                mesh,
                                DVec3::ZERO,
                                Specular::default(),
                            ))
                        }
                    };
                    template.placed(name, origin, rotation, scale)
                }
                None => {
                    let source = match (&templates[placement.mesh], &meshes[placement.mesh]) {
                        (Some(template), _) => template.mesh.as_ref(),
                        (None, Some(mesh)) => mesh,
                        (None, None) => return Err(at_fault(&name, "its mesh was not built".into())),
                    };
                    let mesh =
                        source.transformed(glam::Affine3A::from_mat3(placement.transform.matrix3.as_mat3()));
                    file::check_extent(&mesh).map_err(|e| at_fault(&name, e.to_string()))?;
                    SceneObject::new(name, mesh, placement.transform.translation, Specular::default())
                }
            };
            objects.push(object);
        }
        let name = object_name(&path.file_stem().unwrap_or_default().to_string_lossy(), "model");
        Ok(Scene::of_model(name, objects))
    }

    /// A scene of a model file's `objects`, named `name`: default lights and background,
    /// and the default orbit path.
    fn of_model(name: String, objects: Vec<SceneObject>) -> Scene {
        let mut scene = Scene {
            name,
            objects,
            lighting: default_lighting(),
            background: file::DEFAULT_BACKGROUND.into(),
            fov_y_degrees: file::DEFAULT_FOV,
            path: CameraPath::default(),
        };
        scene.path = scene.default_path();
        scene
    }

    /// World bounds of all objects, rounded out to `f32` ([`SceneObject::world_bounds`]).
    pub fn bounds(&self) -> Aabb {
        self.objects
            .iter()
            .fold(Aabb::EMPTY, |b, o| b.union(o.world_bounds()))
    }

    /// Total triangles.
    pub fn triangle_count(&self) -> usize {
        self.objects.iter().map(|o| o.mesh.triangle_count()).sum()
    }

    /// The objects whose meshes lie so far from their own frame's origin, for their
    /// size, that `f32` coordinates cannot place their vertices finely: one step of an
    /// `f32` there is more than [`PRECISION_LIMIT`] of the object's extent (an OBJ file
    /// in survey coordinates; where an object stands in the world costs nothing, see
    /// [`SceneObject`]). One sentence each, naming the figures.
    pub fn precision_warnings(&self) -> Vec<String> {
        self.objects
            .iter()
            .filter_map(|o| {
                let b = o.local_bounds;
                let distance = b.min.abs().max(b.max.abs()).max_element();
                let extent = b.extent().max_element();
                // The spacing of f32 values at `distance`.
                let step = distance * f32::EPSILON;
                (extent > 0.0 && step > PRECISION_LIMIT * extent).then(|| {
                    format!(
                        "object `{}`'s vertices lie {distance:.3e} m from its mesh's origin, where \
                         f32 coordinates step by {step:.2e} m, {:.4} % of its {extent:.3e} m extent \
                         (more than one 16-bit depth level): its depths and positions lose \
                         precision; move its vertices towards the origin and place it with \
                         `translate`",
                        o.name,
                        100.0 * step / extent
                    )
                })
            })
            .collect()
    }

    /// The object called `name`.
    pub fn object(&self, name: &str) -> Result<&SceneObject> {
        self.objects
            .iter()
            .find(|o| o.name == name)
            .ok_or_else(|| Error::UnknownObject {
                scene: self.name.clone(),
                name: name.to_string(),
                available: self.object_names(),
            })
    }

    /// The object called `name`, or the only object when `name` is `None`.
    pub fn object_or_only(&self, name: Option<&str>) -> Result<&SceneObject> {
        match (name, self.objects.as_slice()) {
            (Some(name), _) => self.object(name),
            (None, [only]) => Ok(only),
            (None, _) => Err(Error::Invalid(format!(
                "scene `{}` has {} objects: name one with --object ({})",
                self.name,
                self.objects.len(),
                self.object_names()
            ))),
        }
    }

    /// The objects' names, comma-separated (what an unknown-object error offers).
    pub fn object_names(&self) -> String {
        self.objects
            .iter()
            .map(|o| o.name.as_str())
            .collect::<Vec<_>>()
            .join(", ")
    }

    /// One orbit around the whole scene, for scenes that give no path.
    pub fn default_path(&self) -> CameraPath {
        // (A centre rounded to f32 moves the orbit by at most a step of f32; its eyes
        // are worked out in f64 from it, as smoothly far from the origin as near it.)
        let b = self.bounds();
        let radius = f64::from(b.extent().length().max(1e-6));
        CameraPath {
            segments: vec![PathSegment::Orbit {
                center: b.center().as_dvec3().to_array(),
                radius: radius * 1.5,
                height: radius * 0.4,
                turns: 1.0,
                frames: 120,
            }],
        }
    }
}

/// A sun from above-left-front plus a weak fill, for scenes that give no lights.
pub fn default_lighting() -> Lighting {
    Lighting {
        ambient: Vec3::from(file::DEFAULT_AMBIENT),
        lights: vec![
            Light::Directional {
                direction: Vec3::new(-0.4, -1.0, -0.3).normalize(),
                color: Vec3::splat(0.85),
            },
            Light::Directional {
                direction: Vec3::new(0.6, -0.2, 0.7).normalize(),
                color: Vec3::splat(0.25),
            },
        ],
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    /// A placement's name leads back to its object; any other name is its own.
    #[test]
    fn a_placement_name_leads_back_to_its_object() {
        assert_eq!(placed_object(&placement_name("tree", 17)), "tree");
        assert_eq!(placed_object(&placement_name("statue.v2", 1)), "statue.v2");
        assert_eq!(placed_object("knot"), "knot");
        assert_eq!(placed_object("statue.v2"), "statue.v2");
        assert_eq!(placed_object("rock."), "rock.");
    }

    /// Where an object stands costs no precision: a sphere moved 10⁶ m away is not
    /// warned about. A mesh whose own vertices lie 10⁵ m from its origin (an OBJ file
    /// in survey coordinates) is, with its distance; one 100 m out is not.
    #[test]
    fn meshes_far_from_their_own_origin_for_their_size_are_warned_about() {
        assert!(Scene::load("default").unwrap().precision_warnings().is_empty());
        let parse = |text: &str| Scene::parse(text).unwrap();
        let moved = parse(
            "[[objects]]\nname = \"ball\"\ngenerator = { kind = \"sphere\", subdivisions = 2 }\ntranslate = [1e6, 0, 0]\n",
        );
        assert!(
            moved.precision_warnings().is_empty(),
            "{:?}",
            moved.precision_warnings()
        );
        let dir = crate::scratch::PrivateDir::new("relief-far-obj").unwrap();
        let at = |x: f64| {
            let path = dir.join(format!("far{x}.obj"));
            std::fs::write(
                &path,
                format!("v {x} 0 0\nv {} 0 0\nv {x} 1 0\nf 1 2 3\n", x + 1.0),
            )
            .unwrap();
            Scene::load(&path.display().to_string())
                .unwrap()
                .precision_warnings()
        };
        assert!(at(100.0).is_empty(), "{:?}", at(100.0));
        let far = at(1e5);
        assert_eq!(far.len(), 1, "{far:?}");
        assert!(
            far[0].contains("`far100000`") && far[0].contains("1.000e5"),
            "{far:?}"
        );
    }

    #[test]
    fn unknown_scene_names_the_choices() {
        let err = Scene::load("nonesuch").unwrap_err().to_string();
        assert!(err.contains("nonesuch") && err.contains("default"), "{err}");
        let err = Scene::load("/no/such/file.toml").unwrap_err().to_string();
        assert!(err.contains("/no/such/file.toml"), "{err}");
    }

    /// The orbit scenes are the default scene's objects alone: the same mesh (by
    /// hash), lights and ground, and an orbit of the camera around the object.
    #[test]
    fn orbit_scenes_hold_one_default_object() {
        let default = Scene::load("default").unwrap();
        for (name, object) in [("orbit-knot", "knot"), ("orbit-sphere", "sphere")] {
            let scene = Scene::load(name).unwrap();
            let names: Vec<&str> = scene.objects.iter().map(|o| o.name.as_str()).collect();
            assert_eq!(names, ["ground", object], "{name}");
            let original = default.object(object).unwrap();
            assert_eq!(scene.object(object).unwrap().hash, original.hash, "{name}");
            assert_eq!(scene.lighting, default.lighting, "{name}");
            let Some(PathSegment::Orbit { center, .. }) = scene.path.segments.first() else {
                panic!("{name}: no orbit");
            };
            assert!(
                DVec3::from(*center).distance(original.world_bounds().center().as_dvec3()) < 0.5,
                "{name}"
            );
        }
    }
}
