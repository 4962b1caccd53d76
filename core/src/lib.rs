//! Shared types of Relief, the relief-impostor render service.
//!
//! Everything that more than one machine of the system must agree on lives here:
//!
//! - [`bounds`] — axis-aligned boxes and the ray/box slab test.
//! - [`camera`] — the perspective camera of a frame and the scene's camera path.
//! - [`mesh`], [`obj`], [`generators`] — triangle meshes, their loading from Wavefront
//!   OBJ, and the procedural meshes of the built-in scenes.
//! - [`scene`] — scenes (objects placed in the world, lights, camera path), loaded from a
//!   built-in name, a TOML scene file or a bare `.obj`.
//! - [`relief`] — the relief texture: its source camera, depth quantisation and on-disk
//!   format (`texture.json` + PNG planes).
//! - [`frame`] — a rendered RGB8 frame with per-pixel object ids.
//! - [`shading`] — the one lighting model (per-pixel Phong) that the reference renderer
//!   and the client's display stage share.
//! - [`hash`] — content hashes, so that machines agree on what they render.
//! - [`cli`] — start-up shared by the binaries: argument errors, logging, exit codes.
//! - [`vector`] — parsing and validation of user-given vectors.

pub mod bounds;
pub mod camera;
pub mod cli;
pub mod error;
pub mod frame;
pub mod generators;
pub mod hash;
pub mod mesh;
pub mod obj;
pub mod reach;
pub mod relief;
pub mod scene;
pub mod scratch;
pub mod shading;
pub mod vector;

pub use error::{Error, Result};
