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
//! - [`predict`] — the viewpoint predictor (least-squares quadratic fit of recent eyes).
//! - [`source`] — where textures come from: a server over gRPC, or the in-process
//!   generator.
//! - [`remote`] — the client side of the protocol: scenes up, textures down,
//!   withdrawals.
//! - [`flight`] — the real-time flight along a camera path that `relief demo`,
//!   `render` and `load` share.
//!
//! See [`manager`] for an example.

pub mod flight;
pub mod manager;
pub mod predict;
pub mod remote;
pub mod source;
