//! Relief's impostor client: the manager that decides, frame by frame, which objects
//! are drawn as relief impostors and with which textures, asks for the textures the
//! eye will need, and takes them in without ever waiting for the network.
//!
//! # Brief overview
//!
//! The principal type is [`Manager`](manager::Manager). A [`flight`] drives it along a
//! scene's camera path in real time; textures come from a [`source`] — a Relief server
//! reached through [`remote`], or the in-process generator — and the viewpoint
//! [`predict`]or tells the manager where the eye is going. Drawing is the renderer's
//! (`relief-render`); this crate adds the decisions and the network.
//!
//! - [`manager`] — per object and frame: geometry or impostor, which texture, what to
//!   ask for; its tuning in [`manager::policy`].
//! - [`predict`] — the viewpoint predictor (least-squares quadratic fit of recent eyes,
//!   extrapolated as a steady turn).
//! - [`source`] — where textures come from: a server over gRPC, or the in-process
//!   generator.
//! - [`remote`] — the client side of the protocol: scenes up, textures down,
//!   withdrawals.
//! - [`intake`] — arrived textures made ready, once per texture in a process however
//!   many of its clients receive it.
//! - [`link`] — the link to the server kept alive: the scene uploaded again when the
//!   server lost it, and whether textures can come at all ([`link::Health`]).
//! - [`flight`] — the real-time flight along a camera path that `relief demo`,
//!   `render` and `load` share.
//!
//! # Example
//!
//! A manager of a built-in scene, its textures made by the in-process generator,
//! deciding and drawing one frame:
//!
//! ```
//! use std::sync::Arc;
//! use relief_client::manager::{Config, Show};
//! use relief_client::source::local_manager;
//! use relief_core::scene::Scene;
//! use relief_render::gbuffer::GBuffer;
//!
//! let scene = Arc::new(Scene::load("orbit-sphere")?);
//! let mut manager = local_manager(&scene, Config::default());
//! let camera = scene.path.pose(0).unwrap().camera(scene.fov_y_degrees, 160, 90)?;
//! assert!(manager.warm_up(&scene, &[camera], std::time::Duration::from_secs(30)));
//! let shows = manager.frame(&scene, &camera, 0.0);
//! assert!(shows.iter().any(|show| matches!(show, Show::Impostor { .. })));
//! let frame = manager.render(&scene, &shows, &camera, &mut GBuffer::new(160, 90));
//! assert_eq!(frame.color.len(), 160 * 90);
//! # Ok::<(), Box<dyn std::error::Error>>(())
//! ```

pub mod flight;
pub mod intake;
pub mod link;
pub mod manager;
pub mod predict;
pub mod remote;
pub mod source;
