//! The Relief client's local pipeline: draw geometry, show relief impostors from new
//! eyes, and measure how wrong and how fast each way of doing it is.
//!
//! - [`gbuffer`] — the frame's per-pixel surface record (depth, object, albedo, normal)
//!   that geometry and impostors both write with a depth test, and the one shading pass
//!   that turns it into colour with the shared Phong model.
//! - [`raster`] — the software rasterizer for geometry.
//! - [`metrics`] — image error against the reference; warp-error predictions.

pub mod gbuffer;
pub mod metrics;
pub mod raster;
