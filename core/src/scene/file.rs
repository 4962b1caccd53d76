//! The TOML scene-file format.
//!
//! ```toml
//! name = "example"              # optional; defaults to the file name
//! background = [0.6, 0.75, 0.9] # linear RGB of empty pixels
//! ambient = [0.2, 0.2, 0.2]
//!
//! [camera]
//! fov_deg = 60
//! [[camera.path]]               # optional; default: one orbit around the scene
//! kind = "orbit"
//! center = [0, 1, 0]
//! radius = 6
//! height = 1.5
//! frames = 120
//!
//! [[lights]]                    # optional; default: a sun and a fill light
//! kind = "directional"          # or "point" with `position`
//! direction = [-0.4, -1, -0.3]
//! color = [1, 1, 1]
//! intensity = 0.9
//!
//! [[objects]]
//! name = "ball"
//! generator = { kind = "sphere", subdivisions = 4 }  # or: obj = "meshes/ball.obj",
//!                               # or gltf = "ball.glb" (its nodes' meshes merged)
//! translate = [0, 1, 0]
//! rotate_deg = [0, 45, 0]       # about x, then y, then z
//! scale = 1.0
//! diffuse = [0.8, 0.2, 0.2]     # optional: replaces the mesh's material colours
//! specular = 0.3                # Phong k_s
//! shininess = 40
//!
//! [[objects]]                   # one mesh, placed many times
//! name = "statue"
//! obj = "statue.obj"
//! instances = [                 # each composed with the object's own transform
//!   { translate = [4, 0, 2], rotate_deg = [0, 30, 0], scale = 1.5 },
//!   { translate = [-6, 0, 9] },
//! ]
//! ```
//!
//! Paths are relative to the scene file. Unknown keys are errors, so typos are caught.
//!
//! An object with `instances` is that many objects, named `statue.1`, `statue.2`, …,
//! sharing one mesh in memory: each placement turns, scales and moves the mesh's frame
//! (see [`SceneObject::placed`](super::SceneObject::placed)). The scene's limits count
//! each placement as an object, and each mesh's triangles once.

use std::path::{Path, PathBuf};

use glam::{Affine3A, DQuat, DVec3, EulerRot, Quat, Vec3};
use rayon::prelude::*;
use serde::Deserialize;

use super::{Scene, SceneLimits, SceneObject, default_lighting, placement_name};
use crate::camera::{CameraPath, PathSegment};
use crate::error::{Error, Result};
use crate::generators::Generator;
use crate::mesh::Mesh;
use crate::reach::Reach;
use crate::shading::{Light, Lighting, Specular};

pub(super) const DEFAULT_BACKGROUND: [f32; 3] = [0.62, 0.74, 0.88];
pub(super) const DEFAULT_AMBIENT: [f32; 3] = [0.18, 0.18, 0.2];
pub(super) const DEFAULT_FOV: f32 = 60.0;

#[derive(Debug, Deserialize)]
#[serde(deny_unknown_fields)]
struct SceneFile {
    name: Option<String>,
    background: Option<[f32; 3]>,
    ambient: Option<[f32; 3]>,
    #[serde(default)]
    camera: CameraFile,
    lights: Option<Vec<LightFile>>,
    objects: Vec<ObjectFile>,
}

#[derive(Debug, Default, Deserialize)]
#[serde(deny_unknown_fields)]
struct CameraFile {
    fov_deg: Option<f32>,
    #[serde(default)]
    path: Vec<PathSegment>,
}

#[derive(Debug, Deserialize)]
#[serde(tag = "kind", rename_all = "lowercase", deny_unknown_fields)]
enum LightFile {
    Directional {
        direction: [f32; 3],
        #[serde(default = "white")]
        color: [f32; 3],
        #[serde(default = "one")]
        intensity: f32,
    },
    Point {
        position: [f32; 3],
        #[serde(default = "white")]
        color: [f32; 3],
        #[serde(default = "one")]
        intensity: f32,
    },
}

fn white() -> [f32; 3] {
    [1.0; 3]
}

fn one() -> f32 {
    1.0
}

#[derive(Debug, Deserialize)]
#[serde(deny_unknown_fields)]
struct ObjectFile {
    name: String,
    obj: Option<PathBuf>,
    /// A glTF file's default scene, its nodes' meshes merged into this object's mesh
    /// (a glTF file given as the scene itself places each node instead).
    gltf: Option<PathBuf>,
    generator: Option<Generator>,
    #[serde(default)]
    translate: [f64; 3],
    #[serde(default)]
    rotate_deg: [f32; 3],
    #[serde(default = "one")]
    scale: f32,
    diffuse: Option<[f32; 3]>,
    specular: Option<f32>,
    shininess: Option<f32>,
    /// Where the mesh is placed, each placement an object; absent: once, as it is.
    instances: Option<Vec<PlacementFile>>,
}

impl ObjectFile {
    /// The object's own transform, as a placement. (Its keys stand in the object's
    /// table, not flattened from a `PlacementFile`: serde cannot flatten where unknown
    /// keys are refused.)
    fn own(&self) -> PlacementFile {
        PlacementFile {
            translate: self.translate,
            rotate_deg: self.rotate_deg,
            scale: self.scale,
        }
    }

    /// The object's placements: those listed, or one that leaves it as it is.
    fn placements(&self) -> &[PlacementFile] {
        self.instances.as_deref().unwrap_or(&[PlacementFile::AS_IT_IS])
    }

    /// Each placement's name: the object's own when it has no `instances`, else
    /// `name.1`, `name.2`, ….
    fn placement_names(&self) -> Vec<String> {
        match &self.instances {
            None => vec![self.name.clone()],
            Some(list) => (1..=list.len()).map(|k| placement_name(&self.name, k)).collect(),
        }
    }
}

/// One placement of an object's mesh: scaled and rotated about the object's origin,
/// then moved — applied after the object's own `translate`, `rotate_deg` and `scale`.
#[derive(Debug, Clone, Copy, Deserialize)]
#[serde(deny_unknown_fields)]
struct PlacementFile {
    #[serde(default)]
    translate: [f64; 3],
    #[serde(default)]
    rotate_deg: [f32; 3],
    #[serde(default = "one")]
    scale: f32,
}

impl PlacementFile {
    const AS_IT_IS: PlacementFile = PlacementFile {
        translate: [0.0; 3],
        rotate_deg: [0.0; 3],
        scale: 1.0,
    };

    /// An error naming what is wrong with the placement, if anything.
    fn check(&self) -> Result<()> {
        let moved =
            crate::vector::ensure_finite_f64("translate", DVec3::from(self.translate)).map_err(invalid)?;
        check_origin(moved).map_err(|e| invalid(format!("translate {e}")))?;
        crate::vector::ensure_finite("rotate_deg", Vec3::from(self.rotate_deg)).map_err(invalid)?;
        if !(self.scale.is_finite() && self.scale > 0.0) {
            return Err(invalid(format!(
                "scale {} must be positive and finite",
                self.scale
            )));
        }
        Ok(())
    }
}

/// A rotation given as degrees about x, then y, then z.
fn rotation_deg(degrees: [f32; 3]) -> Quat {
    let [x, y, z] = degrees.map(f32::to_radians);
    Quat::from_euler(EulerRot::XYZ, x, y, z)
}

/// Loads a scene file from disk; its OBJ files must lie within `reach`, and its cost
/// within `limits`.
pub fn load_file(path: &Path, reach: Reach, limits: &SceneLimits) -> Result<Scene> {
    let text = std::fs::read_to_string(reach.check(path)?).map_err(|e| Error::io(path, e))?;
    let base = path.parent().unwrap_or(Path::new("."));
    let mut scene = parse(&text, &path.display().to_string(), base, reach, limits)?;
    if scene.name.is_empty() {
        scene.name = path
            .file_stem()
            .map_or_else(String::new, |s| s.to_string_lossy().into_owned());
    }
    Ok(scene)
}

/// Parses scene-file text; `origin` names it in errors, `base` resolves relative paths,
/// the OBJ files named must lie within `reach`, and the scene's cost (objects and
/// triangles, counted before anything is built) within `limits`.
pub fn parse(text: &str, origin: &str, base: &Path, reach: Reach, limits: &SceneLimits) -> Result<Scene> {
    let error = |message: String| Error::Scene {
        origin: origin.to_string(),
        message,
    };
    let file: SceneFile =
        toml::from_str(text).map_err(|e| error(e.message().to_string() + &span_note(text, e.span())))?;
    let finite3 = |what: &str, v: [f32; 3]| {
        crate::vector::ensure_finite(what, Vec3::from(v)).map_err(|m| error(m.to_string()))
    };
    let background = finite3("background", file.background.unwrap_or(DEFAULT_BACKGROUND))?;
    let ambient = finite3("ambient", file.ambient.unwrap_or(DEFAULT_AMBIENT))?;
    let fov = file.camera.fov_deg.unwrap_or(DEFAULT_FOV);
    if !(fov > 0.0 && fov < 180.0) {
        return Err(error(format!("camera.fov_deg {fov} must be in (0, 180)")));
    }
    for segment in &file.camera.path {
        segment
            .validate()
            .map_err(|m| error(format!("camera.path: {m}")))?;
    }
    let lighting = match file.lights {
        None => Lighting {
            ambient,
            ..default_lighting()
        },
        Some(lights) => Lighting {
            ambient,
            lights: lights
                .into_iter()
                .map(|l| convert_light(l).map_err(|e| error(e.to_string())))
                .collect::<Result<_>>()?,
        },
    };
    if file.objects.is_empty() {
        return Err(error("the scene has no objects".into()));
    }
    // Every placement is an object.
    let placements = file
        .objects
        .iter()
        .fold(0usize, |n, o| n.saturating_add(o.placements().len()));
    limits.check(0, placements).map_err(|e| error(e.to_string()))?;
    let mut names = std::collections::HashSet::with_capacity(placements);
    for (k, o) in file.objects.iter().enumerate() {
        if o.name.trim().is_empty() {
            return Err(error(format!("object {} has an empty name", k + 1)));
        }
        if o.instances.as_ref().is_some_and(Vec::is_empty) {
            return Err(error(format!(
                "object `{}`: `instances` is empty (leave it out to place the object once)",
                o.name
            )));
        }
        for (i, placement) in o.placements().iter().enumerate() {
            placement
                .check()
                .map_err(|e| error(format!("object `{}`, instance {}: {e}", o.name, i + 1)))?;
        }
        for name in o.placement_names() {
            super::check_object_name(&name).map_err(|m| error(format!("object {}: {m}", k + 1)))?;
            if !names.contains(name.as_str()) {
                names.insert(name);
            } else {
                return Err(error(format!("two objects are named `{name}`")));
            }
        }
    }
    // The cost, before anything is built (a generator's parameters out of range are
    // refused by name first).
    let mut triangles = 0u64;
    for o in &file.objects {
        let named = |e: Error| match e {
            Error::Invalid(m) => error(format!("object `{}`: {m}", o.name)),
            other => other,
        };
        let mesh = match (&o.obj, &o.gltf, &o.generator) {
            (Some(path), None, None) => crate::obj::count_triangles(&base.join(path), reach)?,
            (None, Some(path), None) => crate::gltf::census(&base.join(path), reach)?.placed_triangles,
            (None, None, Some(generator)) => {
                generator.validate().map_err(|e| named(invalid(e)))?;
                generator.triangles()
            }
            _ => 0,
        };
        // (Built once, however many placements.)
        triangles = triangles.saturating_add(mesh);
    }
    limits
        .check(triangles, placements)
        .map_err(|e| error(e.to_string()))?;
    let objects = file
        .objects
        .into_par_iter()
        .map(|o| {
            let name = o.name.clone();
            build_object(o, base, reach).map_err(|m| match m {
                Error::Invalid(m) => error(format!("object `{name}`: {m}")),
                other => other,
            })
        })
        .collect::<Result<Vec<_>>>()?
        .into_iter()
        .flatten()
        .collect();
    let mut scene = Scene {
        name: file.name.unwrap_or_default(),
        objects,
        lighting,
        background,
        fov_y_degrees: fov,
        path: CameraPath {
            segments: file.camera.path,
        },
    };
    if scene.path.segments.is_empty() {
        scene.path = scene.default_path();
    }
    Ok(scene)
}

/// " (line L, column C)" for a TOML error span.
fn span_note(text: &str, span: Option<std::ops::Range<usize>>) -> String {
    let Some(span) = span else {
        return String::new();
    };
    let before = &text[..span.start.min(text.len())];
    let line = before.matches('\n').count() + 1;
    let column = before.len() - before.rfind('\n').map_or(0, |i| i + 1) + 1;
    format!(" (line {line}, column {column})")
}

fn convert_light(light: LightFile) -> Result<Light> {
    let check = |what: &str, v: [f32; 3]| crate::vector::ensure_finite(what, Vec3::from(v)).map_err(invalid);
    Ok(match light {
        LightFile::Directional {
            direction,
            color,
            intensity,
        } => {
            let direction = check("light direction", direction)?.normalize_or_zero();
            if direction == Vec3::ZERO {
                return Err(invalid("a directional light has a zero direction"));
            }
            Light::Directional {
                direction,
                color: check_colour(color)? * non_negative("light intensity", intensity)?,
            }
        }
        LightFile::Point {
            position,
            color,
            intensity,
        } => Light::Point {
            position: check("light position", position)?,
            color: check_colour(color)? * non_negative("light intensity", intensity)?,
        },
    })
}

/// The farthest a vertex may lie from its mesh's origin, and an object's origin from
/// the world's, metres: past it, squared distances overflow `f32`, and `f64` steps by
/// more than a tenth of a millimetre.
const MAX_COORDINATE: f64 = 1e12;

/// Whether an object's frame's origin lies within [`MAX_COORDINATE`] of the world's;
/// the message says where it lies.
pub(super) fn check_origin(origin: DVec3) -> std::result::Result<(), String> {
    if origin.is_finite() && origin.abs().max_element() <= MAX_COORDINATE {
        return Ok(());
    }
    Err(format!(
        "lies at {origin}, beyond {MAX_COORDINATE:e} m from the origin"
    ))
}

/// Whether a mesh lies within [`MAX_COORDINATE`] of its origin.
pub(super) fn check_extent(mesh: &Mesh) -> Result<()> {
    let bounds = mesh.bounds();
    if bounds.min.abs().max(bounds.max.abs()).max_element() as f64 > MAX_COORDINATE {
        return Err(invalid(format!(
            "beyond {MAX_COORDINATE:e} m from the origin, past what f32 rendering can hold"
        )));
    }
    Ok(())
}

/// A light colour: finite and not negative.
fn check_colour(v: [f32; 3]) -> Result<Vec3> {
    let c = crate::vector::ensure_finite("light color", Vec3::from(v)).map_err(invalid)?;
    if c.min_element() < 0.0 {
        return Err(invalid(format!("light color {c} must not be negative")));
    }
    Ok(c)
}

/// `v`, finite and not negative.
fn non_negative(what: &str, v: f32) -> Result<f32> {
    match finite_scalar(what, v)? {
        v if v >= 0.0 => Ok(v),
        v => Err(invalid(format!("{what} {v} must not be negative"))),
    }
}

fn finite_scalar(what: &str, v: f32) -> Result<f32> {
    if v.is_finite() {
        Ok(v)
    } else {
        Err(invalid(format!("{what} {v} is not finite")))
    }
}

/// An [`Error::Invalid`] saying `what` is wrong.
fn invalid(what: impl std::fmt::Display) -> Error {
    Error::Invalid(what.to_string())
}

/// The object's placements, each a [`SceneObject`], sharing one mesh: the object's own
/// scale and rotation made into the mesh's frame, each placement turning, scaling and
/// moving that frame.
fn build_object(o: ObjectFile, base: &Path, reach: Reach) -> Result<Vec<SceneObject>> {
    let mut mesh: Mesh = match (&o.obj, &o.gltf, &o.generator) {
        (Some(path), None, None) => crate::obj::load_obj(&base.join(path), reach)?,
        (None, Some(path), None) => crate::gltf::load_gltf_merged(&base.join(path), reach)?,
        (None, None, Some(generator)) => {
            generator.validate().map_err(invalid)?;
            generator.build()
        }
        _ => return Err(invalid("give exactly one of `obj`, `gltf` or `generator`")),
    };
    let own = o.own();
    own.check()?;
    if let Some(diffuse) = o.diffuse {
        let diffuse = crate::vector::ensure_finite("diffuse", Vec3::from(diffuse)).map_err(invalid)?;
        for m in &mut mesh.materials {
            m.diffuse = diffuse.clamp(Vec3::ZERO, Vec3::ONE);
        }
    }
    let specular = Specular {
        strength: non_negative("specular", o.specular.unwrap_or(Specular::default().strength))?,
        shininess: non_negative("shininess", o.shininess.unwrap_or(Specular::default().shininess))?,
    };
    // Scale and rotation make the object's own frame; `translate` places that
    // frame's origin in the world, in f64 (see [`SceneObject`]).
    let local = mesh.transformed(Affine3A::from_scale_rotation_translation(
        Vec3::splat(own.scale),
        rotation_deg(own.rotate_deg),
        Vec3::ZERO,
    ));
    local.validate().map_err(invalid)?;
    check_extent(&local).map_err(|m| invalid(format!("scaled, its vertices lie {m}")))?;
    let own_origin = DVec3::from(own.translate);
    let object = SceneObject::new(o.name.clone(), local, own_origin, specular);
    if o.instances.is_none() {
        return Ok(vec![object]);
    }
    o.placements()
        .iter()
        .zip(o.placement_names())
        .map(|(placement, name)| {
            // The placement after the object's own transform, x ↦ t + s·R·(t_o + x):
            // its frame's origin at t + s·R·t_o, turned by R, scaled by s. (In f64, as
            // the origin is; the object's own rotation went into the f32 mesh.)
            let [rx, ry, rz] = placement.rotate_deg.map(|d| (d as f64).to_radians());
            let rotation = DQuat::from_euler(EulerRot::XYZ, rx, ry, rz);
            let scale = placement.scale as f64;
            let origin = DVec3::from(placement.translate) + rotation * own_origin * scale;
            check_origin(origin).map_err(|e| invalid(format!("{name} {e}")))?;
            Ok(object.placed(name, origin, rotation, scale))
        })
        .collect()
}

#[cfg(test)]
mod tests {
    use super::*;

    fn parse_str(text: &str) -> Result<Scene> {
        Scene::parse(text)
    }

    /// A scene's cost is counted from its file — generators from their parameters, OBJ
    /// files from their face lines — and one past the limits is refused before it is
    /// built, naming the limit; many objects are checked in linear time.
    #[test]
    fn a_scene_past_its_limits_is_refused_before_it_is_built() {
        let limits = SceneLimits {
            max_triangles: 2_000,
            max_objects: 3,
        };
        let within = |text: &str| parse(text, "test", Path::new("."), Reach::Anywhere, &limits);
        let sphere = |name: &str, subdivisions: u32| {
            format!(
                "[[objects]]\nname = \"{name}\"\ngenerator = {{ kind = \"sphere\", subdivisions = {subdivisions} }}\n"
            )
        };
        // 1,280 + 320 triangles: within.
        assert!(within(&(sphere("a", 3) + &sphere("b", 2))).is_ok());
        // 1,280 + 1,280: past it. (A tree of depth 9 with 256 leaves a twig, ten
        // million triangles, is refused as quickly: nothing is built.)
        let err = within(&(sphere("a", 3) + &sphere("b", 3)))
            .unwrap_err()
            .to_string();
        assert!(err.contains("2560 triangles") && err.contains("2000"), "{err}");
        let tree =
            "[[objects]]\nname = \"t\"\ngenerator = { kind = \"tree\", seed = 1, depth = 9, leaves = 256 }\n";
        assert!(within(tree).unwrap_err().to_string().contains("triangles"));
        let four: String = ["a", "b", "c", "d"].iter().map(|n| sphere(n, 0)).collect();
        assert!(within(&four).unwrap_err().to_string().contains("4 objects"));
        // An OBJ file's faces: a triangle and a quad, 3 triangles.
        let dir = crate::scratch::PrivateDir::new("relief-obj-count").unwrap();
        let obj = dir.join("q.obj");
        std::fs::write(
            &obj,
            "v 0 0 0\nv 1 0 0\nv 1 1 0\nv 0 1 0\nf 1 2 3\nf 1 2 3 4\n# f 1 2 3\n",
        )
        .unwrap();
        assert_eq!(crate::obj::count_triangles(&obj, Reach::Anywhere).unwrap(), 3);
        // 20,001 objects, one name twice: found by a set, not by comparing every pair
        // (which took 30 s at 10⁵ objects).
        let many: String = (0..20_000).map(|k| sphere(&format!("o{k}"), 0)).collect();
        let wide = SceneLimits {
            max_triangles: u64::MAX,
            max_objects: 20_001,
        };
        let doubled = many + &sphere("o7", 0);
        let err = parse(&doubled, "test", Path::new("."), Reach::Anywhere, &wide).unwrap_err();
        assert!(err.to_string().contains("two objects are named `o7`"), "{err}");
    }

    #[test]
    fn parses_a_small_scene() {
        let scene = parse_str(
            r#"
            [[lights]]
            kind = "point"
            position = [0, 5, 0]
            [[objects]]
            name = "ball"
            generator = { kind = "sphere", subdivisions = 1 }
            translate = [0, 2, 0]
            scale = 2
            "#,
        )
        .unwrap();
        let ball = scene.object("ball").unwrap();
        // (Scaled about its own origin, which `translate` places.)
        assert!(ball.local_bounds.min.abs_diff_eq(Vec3::splat(-2.0), 1e-4));
        assert!(
            ball.world_bounds()
                .min
                .abs_diff_eq(Vec3::new(-2.0, 0.0, -2.0), 1e-4)
        );
        assert_eq!(ball.origin, DVec3::new(0.0, 2.0, 0.0));
        assert_eq!(scene.lighting.lights.len(), 1);
        assert_eq!(scene.path.frame_count(), 120);
    }

    /// An object's `instances` are objects named `name.1`, `name.2`, …: each placement
    /// composed with the object's own transform (`x ↦ t + s·R·(t_o + s_o·R_o·x)`), all
    /// sharing one mesh in memory, each placement's frame turned and scaled.
    #[test]
    fn instances_place_one_mesh_many_times() {
        let scene = parse_str(
            r#"
            [[objects]]
            name = "ball"
            generator = { kind = "sphere", subdivisions = 2 }
            translate = [0, 0, -4]
            scale = 2
            instances = [
              {},
              { translate = [1e6, 0, 0] },
              { translate = [5, 0, -5], rotate_deg = [0, 90, 0], scale = 0.5 },
            ]
            [[objects]]
            name = "lone"
            generator = { kind = "sphere", subdivisions = 2 }
            "#,
        )
        .unwrap();
        let names: Vec<&str> = scene.objects.iter().map(|o| o.name.as_str()).collect();
        assert_eq!(names, ["ball.1", "ball.2", "ball.3", "lone"]);
        let [one, two, three, lone] = [0, 1, 2, 3].map(|k| &scene.objects[k]);
        assert!(one.shares_mesh(two) && one.shares_mesh(three) && !one.shares_mesh(lone));
        assert_eq!((one.hash, three.hash), (two.hash, two.hash));
        assert_eq!(
            (one.origin, two.origin),
            (DVec3::new(0.0, 0.0, -4.0), DVec3::new(1e6, 0.0, -4.0))
        );
        // Turned 90° about y, (0, 0, −4)·0.5 goes to (−2, 0, 0).
        assert!(
            three.origin.abs_diff_eq(DVec3::new(3.0, 0.0, -5.0), 1e-12),
            "{}",
            three.origin
        );
        // The unit sphere scaled by 2 (its own scale, in the mesh), then by 0.5 (the
        // placement's frame).
        assert!(three.local_bounds.max.abs_diff_eq(Vec3::splat(2.0), 1e-5));
        assert_eq!(three.scale, 0.5);
        let world = three.world_bounds();
        assert!(
            world.min.abs_diff_eq(Vec3::new(2.0, -1.0, -6.0), 1e-4),
            "{world:?}"
        );
        assert!(
            world.max.abs_diff_eq(Vec3::new(4.0, 1.0, -4.0), 1e-4),
            "{world:?}"
        );
        // A point of the frame goes out and back.
        let p = Vec3::new(0.3, -1.2, 1.9);
        assert!(three.to_local(three.to_world(p)).abs_diff_eq(p, 1e-6));
        // Without `instances`, the object as it was.
        assert_eq!(lone.origin, DVec3::ZERO);
    }

    /// A placement's faults are named with the object and the instance's number, and
    /// the placements count as objects against the scene's limits.
    #[test]
    fn bad_instances_are_named() {
        let with = |instances: &str| {
            let text = format!(
                "[[objects]]\nname = \"a\"\ngenerator = {{ kind = \"sphere\", subdivisions = 0 }}\ninstances = {instances}\n"
            );
            parse_str(&text).unwrap_err().to_string()
        };
        let err = with("[{}, { scale = 0 }]");
        assert!(
            err.contains("object `a`, instance 2: scale 0 must be positive"),
            "{err}"
        );
        let err = with("[{ translate = [nan, 0, 0] }]");
        assert!(err.contains("instance 1") && err.contains("translate"), "{err}");
        let err = with("[{ rotate_deg = [0, inf, 0] }]");
        assert!(err.contains("rotate_deg"), "{err}");
        let err = with("[{ translate = [2e12, 0, 0] }]");
        assert!(err.contains("beyond"), "{err}");
        assert!(with("[]").contains("`instances` is empty"));
        assert!(with("[{ scale = 1, colour = 2 }]").contains("colour"));
        // 100,001 placements of one object, past the default 100,000 objects.
        let many = format!("[{}]", vec!["{}"; 100_001].join(","));
        let err = with(&many);
        assert!(err.contains("100001 objects"), "{err}");
        // A placement's name clashing with another object's.
        let clash = "[[objects]]\nname = \"a\"\ngenerator = { kind = \"sphere\", subdivisions = 0 }\ninstances = [{}, {}]\n[[objects]]\nname = \"a.2\"\ngenerator = { kind = \"sphere\", subdivisions = 0 }\n";
        assert!(
            parse_str(clash)
                .unwrap_err()
                .to_string()
                .contains("two objects are named `a.2`")
        );
    }

    /// The triangle limit counts each mesh once, however many placements.
    #[test]
    fn the_triangle_limit_counts_meshes_built() {
        let limits = SceneLimits {
            max_triangles: 2 * 320,
            max_objects: 1000,
        };
        let with = |instances: &str| {
            let text = format!(
                "[[objects]]\nname = \"a\"\ngenerator = {{ kind = \"sphere\", subdivisions = 2 }}\ninstances = {instances}\n"
            );
            parse(&text, "test", Path::new("."), Reach::Anywhere, &limits)
        };
        // 500 placements of 320 triangles: 320 built.
        let moved = vec!["{ translate = [1, 0, 0] }"; 498].join(",");
        assert!(
            with(&format!(
                "[{moved}, {{ scale = 2 }}, {{ rotate_deg = [0, 1, 0] }}]"
            ))
            .is_ok()
        );
        let text = "[[objects]]\nname = \"b\"\ngenerator = { kind = \"sphere\", subdivisions = 3 }\n";
        let err = parse(text, "test", Path::new("."), Reach::Anywhere, &limits).unwrap_err();
        assert!(err.to_string().contains("1280 triangles"), "{err}");
    }

    #[test]
    fn errors_say_what_is_wrong() {
        let err = |text: &str| parse_str(text).unwrap_err().to_string();
        assert!(err("[[objects]]\nname = \"a\"\n").contains("exactly one"));
        assert!(err("objects = []").contains("no objects"));
        assert!(err("[[objects]]\nname = \"a\"\ncolour = 1\n").contains("colour"));
        let two = "[[objects]]\nname = \"a\"\ngenerator = { kind = \"sphere\", subdivisions = 0 }\n";
        assert!(err(&format!("{two}{two}")).contains("two objects"));
        let nan_scale =
            "[[objects]]\nname = \"a\"\nscale = nan\ngenerator = { kind = \"sphere\", subdivisions = 0 }\n";
        assert!(err(nan_scale).contains("scale"));
        assert!(err("[[objects]]\nname = \"a\"\nobj = \"missing.obj\"\n").contains("missing.obj"));
        assert!(err("name = ").contains("line 1"));
        let sphere = "generator = { kind = \"sphere\", subdivisions = 0 }";
        assert!(err(&format!("[[objects]]\nname = \"a\"\nshininess = -1\n{sphere}\n")).contains("shininess"));
        assert!(err(&format!("[[objects]]\nname = \"a\"\nscale = 1e30\n{sphere}\n")).contains("beyond"));
        let light = "[[lights]]\nkind = \"directional\"\ndirection = [0, -1, 0]\nintensity = -5\n";
        assert!(err(&format!("{light}[[objects]]\nname = \"a\"\n{sphere}\n")).contains("intensity"));
        for bad in ["../../escaped", "a/b", ".hidden", "with space"] {
            let text = format!(
                "[[objects]]\nname = \"{bad}\"\ngenerator = {{ kind = \"sphere\", subdivisions = 0 }}\n"
            );
            assert!(err(&text).contains("object name"), "{bad}: {}", err(&text));
        }
    }
}
