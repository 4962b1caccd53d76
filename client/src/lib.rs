//! The Relief client's local pipeline: draw geometry, show relief impostors from new
//! eyes, and measure how wrong and how fast each way of doing it is.
//!
//! - [`gbuffer`] — the frame's per-pixel surface record (depth, object, albedo, normal)
//!   that geometry and impostors both write with a depth test, and the one shading pass
//!   that turns it into colour with the shared Phong model.
//! - [`impostor`] — a relief texture prepared for display (texel connectivity).
//! - [`predict`] — the viewpoint predictor.
//! - [`pyramid`] — multi-resolution relief textures: no texels the screen cannot show.
//! - [`raster`] — the software rasterizer for geometry.
//! - [`warp`] — relief impostors shown from new eyes: every method of the sources.
//! - [`composite`] — whole frames: geometry where cheap or near, impostors elsewhere.
//! - [`evaluate`] — the orbit set-up of the error reports: bake, reference, show, compare.
//! - [`remote`] — the client side of the protocol: scenes up, textures down, withdrawals.
//! - [`report`] — the error-against-run-time measurement.
//! - [`stats`] — median, percentiles and means of measured samples.
//! - [`manager`] — the impostor manager: geometry / warp / regenerate per object, texture cache, predicted requests.
//! - [`source`] — where textures come from: a server over gRPC, or the in-process generator.
//! - [`metrics`] — image error against the reference; warp-error predictions.

pub mod composite;
pub mod evaluate;
pub mod gbuffer;
pub mod impostor;
pub mod manager;
pub mod metrics;
pub mod predict;
pub mod pyramid;
pub mod raster;
pub mod remote;
pub mod report;
pub mod source;
pub mod stats;
pub mod warp;
