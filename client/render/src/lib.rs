//! Relief's renderer: a software rasterizer for geometry and the relief impostor's
//! display (pre-warp and texture mapping), composited through one G-buffer and lit by
//! the shared shading model. No network, no command line: a library any client can
//! draw with.
//!
//! # Brief overview
//!
//! The principal type is [`GBuffer`](gbuffer::GBuffer): each pixel's nearest surface
//! (depth, object, albedo, normal). Geometry ([`raster`]) and impostors ([`warp`]) both
//! write into it with a depth test, so they occlude each other correctly, and one
//! [`shade`](gbuffer::GBuffer::shade) pass turns it into a [`Frame`](relief_core::frame::Frame).
//! An [`Impostor`](impostor::Impostor) is a relief texture prepared for display; a
//! [`Pyramid`](pyramid::Pyramid) holds its coarser copies so no texel finer than the
//! screen is warped; [`validity`] says when a texture may still be shown, and how.
//!
//! - [`gbuffer`] — the per-pixel surface record and the one shading pass.
//! - [`raster`] — the software rasterizer for geometry.
//! - [`geometry`] — which objects are drawn as geometry, and all-geometry frames.
//! - [`impostor`] — a relief texture prepared for display (texel connectivity).
//! - [`pyramid`] — multi-resolution relief textures.
//! - [`warp`] — the pre-warp (eq. 3-1/3-2) and texture mapping; sprites.
//! - [`validity`] — Schaufler's sprite and resolution tests; the critical-point error;
//!   the band past a rim; the weight of a texture's edges.
//!
//! # Example
//!
//! The sphere of a built-in scene drawn as exact geometry, then as an impostor whose
//! texture was baked 5° around it:
//!
//! ```
//! use glam::{DVec3, Quat, Vec3};
//! use relief_core::relief::{DepthBits, SourceProjection};
//! use relief_core::{camera::Camera, scene::Scene};
//! use relief_render::{gbuffer::GBuffer, geometry::render_geometry, impostor::Impostor};
//! use relief_render::warp::{Variant, display};
//! use relief_trace::{bake, tracer::ObjectTracer};
//!
//! let scene = Scene::load("orbit-sphere")?;
//! let sphere = scene.object("sphere")?;
//! let centre = sphere.to_world(sphere.local_bounds.center());
//! let camera = Camera::look_at(centre + DVec3::new(0.0, 1.0, 4.5), centre, Vec3::Y, 40.0, 160, 90)?;
//! let mut gbuffer = GBuffer::new(160, 90);
//! let geometry = render_geometry(&scene, &camera, &mut gbuffer);
//!
//! // An impostor lives in its object's own frame: its texture, and the camera it is
//! // shown through.
//! let local = sphere.local_camera(&camera);
//! let (centre, eye) = (sphere.local_bounds.center(), local.eye_f32());
//! let source_eye = centre + Quat::from_rotation_y(5f32.to_radians()) * (eye - centre);
//! let texture = bake(
//!     &ObjectTracer::new(sphere),
//!     source_eye,
//!     128,
//!     DepthBits::Eight,
//!     SourceProjection::Perspective,
//! )?;
//! let index = scene.objects.iter().position(|o| o.name == "sphere").unwrap() as u32;
//! gbuffer.clear();
//! display(Variant::Interleaved, &Impostor::new(texture), index, &local, &mut gbuffer)?;
//! let impostor = gbuffer.shade(&scene, &camera);
//! assert!(impostor.object.contains(&index) && geometry.object.contains(&index));
//! # Ok::<(), Box<dyn std::error::Error>>(())
//! ```

#[cfg(test)]
mod fixtures;
pub mod gbuffer;
pub mod geometry;
pub mod impostor;
pub mod pyramid;
pub mod raster;
pub mod validity;
pub mod warp;

/// The depth of a pixel or texel that holds no surface, in every float depth plane the
/// renderer and the lab keep: the G-buffer, the pre-warped image, the splat layers of
/// forward warping. The largest finite float: every real depth is nearer, so a plain
/// depth test never keeps it, and arithmetic on a whole plane never makes NaN. (A relief
/// texture stores the same marker quantised: [`DepthBits::empty`](relief_core::relief::DepthBits::empty).)
pub const EMPTY_DEPTH: f32 = f32::MAX;
