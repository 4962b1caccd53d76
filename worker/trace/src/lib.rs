//! Relief's ray tracer, the method's "software shader": it bakes relief textures (for
//! the workers, and the client's in-process generator) and renders the ray-traced
//! reference frames every error figure is measured against. No network.
//!
//! # Brief overview
//!
//! The principal type is [`ObjectTracer`](tracer::ObjectTracer): one object and the
//! [`Bvh`](bvh::Bvh) over its mesh, ready for rays. [`bake`](fn@bake) casts one ray per
//! texel from it (parallel, or from the eye) into a
//! [`ReliefTexture`](relief_core::relief::ReliefTexture); a [`SceneTracer`] holds every
//! object of a scene for [`render_reference`], one or N×N perspective rays per pixel.
//!
//! ```
//! use glam::Vec3;
//! use relief_core::relief::{DepthBits, SourceProjection};
//! use relief_core::{camera::Camera, scene::Scene};
//! use relief_trace::{SceneTracer, bake, render_reference, tracer::ObjectTracer};
//!
//! let scene = Scene::load("orbit-sphere")?;
//! let sphere = scene.object("sphere")?;
//! // (A bake's eye is in the object's own frame; the reference's camera in the world.)
//! let eye = sphere.local_bounds.center() + Vec3::new(0.0, 1.0, 4.0);
//! let texture = bake(&ObjectTracer::new(sphere), eye, 64, DepthBits::Eight, SourceProjection::Orthographic)?;
//! assert!(texture.covered_texels() > 64 * 64 / 2);
//!
//! let (eye, centre) = (sphere.to_world(eye), sphere.to_world(sphere.local_bounds.center()));
//! let camera = Camera::look_at(eye, centre, Vec3::Y, 40.0, 96, 54)?;
//! let frame = render_reference(&SceneTracer::new(&scene), &camera, 1);
//! assert_eq!(frame.color.len(), 96 * 54);
//! # Ok::<(), Box<dyn std::error::Error>>(())
//! ```
//!
//! - [`bvh`] — bounding-volume hierarchy over one mesh: binned-SAH build (parallel),
//!   closest-hit traversal of single rays, and of a block of an image plane's rays as
//!   one beam ([`PlaneRays`](bvh::PlaneRays)) for bakes and references (both checked
//!   against an independent ray caster in `tests/tests/bvh_oracle.rs`).
//! - [`tracer`] — a scene ready for ray casting: one BVH per mesh, shared by its
//!   placements, and one over the placements.
//! - [`placements`] — that top level, which a reference frame walks once per block of
//!   pixels, nearest object first.
//! - [`tiles`] — the one way images are split across threads.
//! - [`bake`](mod@bake) — the relief texture of one object for an eye.
//! - [`rim`] — its outline's texels, given the depth where their surface meets it.
//! - [`hidden`] — what those texels hide: the surface behind them a turn uncovers.
//! - [`reference`](mod@reference) — a full perspective frame of the whole scene, Phong-lit.

pub mod bake;
pub mod bvh;
pub mod hidden;
pub mod placements;
mod prefetch;
pub mod reference;
pub mod rim;
pub mod tiles;
pub mod tracer;

pub use bake::{BakeError, bake};
pub use reference::{ANTIALIASED_SAMPLES, ObjectWalk, render_reference};
pub use tracer::SceneTracer;
