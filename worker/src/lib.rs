//! Relief's worker library: the "software shader" of the method — a BVH ray tracer that
//! bakes relief textures and renders the ray-traced reference frames every error figure
//! is measured against.
//!
//! - [`bvh`] — bounding-volume hierarchy over one mesh: binned-SAH build (parallel),
//!   closest-hit traversal, and the brute-force oracle the tests compare it with.
//! - [`tracer`] — a scene ready for ray casting: one BVH per object.
//! - [`tiles`] — the one way images are split across threads.
//! - [`bake`] — the relief texture of one object for an eye.
//! - [`reference`] — a full perspective frame of the whole scene, Phong-lit.

pub mod bake;
pub mod bvh;
mod prefetch;
pub mod reference;
pub mod tiles;
pub mod tracer;

pub use bake::{BakeError, bake};
pub use reference::{ANTIALIASED_SAMPLES, render_reference};
pub use tracer::SceneTracer;
