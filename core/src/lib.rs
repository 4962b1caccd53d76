//! Shared types of Relief, the relief-impostor render service: everything that more
//! than one machine of the system must agree on.
//!
//! # Brief overview
//!
//! The principal type is [`Scene`](scene::Scene): objects placed in the world (each a
//! triangle [`Mesh`](mesh::Mesh) in the object's own frame with a content hash, the name
//! under which machines agree on what they render), lights, and a camera path. A
//! [`ReliefTexture`](relief::ReliefTexture) is what the workers make of one object for
//! one eye, and [`Lighting`](shading::Lighting) the one model every image is lit with.
//! No threads of its own but rayon's inside mesh generation and scene loading; no
//! network, no command line.
//!
//! ```
//! use relief_core::scene::Scene;
//!
//! let scene = Scene::load("orbit-knot")?; // a built-in name, a .toml, an .obj or a glTF file
//! let knot = scene.object("knot")?;
//! assert!(knot.mesh.triangle_count() > 1000);
//! let camera = scene.path.pose(0).unwrap().camera(scene.fov_y_degrees, 640, 360)?;
//! // (Per object, in the object's own frame: see `SceneObject`.)
//! assert!(knot.local_camera(&camera).may_see(&knot.local_bounds));
//! # Ok::<(), Box<dyn std::error::Error>>(())
//! ```
//!
//! - [`bounds`] — axis-aligned boxes and the ray/box slab test.
//! - [`camera`] — the perspective camera of a frame and the scene's camera path.
//! - [`mesh`], [`obj`], [`gltf`], [`generators`] — triangle meshes, their loading from
//!   Wavefront OBJ and glTF 2.0, and the procedural meshes of the built-in scenes.
//! - [`scene`] — scenes (objects placed in the world, lights, camera path), loaded from a
//!   built-in name, a TOML scene file, or a bare `.obj` or glTF file ([`gltf`]).
//! - [`joins`] — when two samples of a relief texture are one surface.
//! - [`normals`] — a mesh's area by the direction it faces: what a view sees that a
//!   texture's rays never met.
//! - [`relief`] — the relief texture: its source camera, depth quantisation and on-disk
//!   format (`texture.json` + PNG planes).
//! - [`frame`] — a rendered RGB8 frame with per-pixel object ids.
//! - [`shading`] — the one lighting model (per-pixel Phong) that the reference renderer
//!   and the client's display stage share.
//! - [`hash`] — content hashes, so that machines agree on what they render.
//! - [`vector`] — parsing and validation of user-given vectors.
//! - [`stats`] — median, percentiles and finite means: one definition for every report.
//! - [`reach`], [`scratch`] — which files a scene may open; files of our own beside
//!   the user's.
//! - [`error`] — [`Error`]: every variant names the file, object or value at fault.

pub mod bounds;
pub mod camera;
pub mod error;
pub mod frame;
pub mod generators;
pub mod gltf;
pub mod hash;
pub mod joins;
pub mod mesh;
pub mod normals;
pub mod obj;
pub mod reach;
pub mod relief;
pub mod scene;
pub mod scratch;
pub mod shading;
pub mod stats;
pub mod vector;

pub use error::{Error, Result};
