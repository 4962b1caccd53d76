//! Which objects a frame draws as exact geometry, and frames drawn all as geometry:
//! the baseline every impostor figure is compared with.

use glam::DVec3;

use relief_core::camera::Camera;
use relief_core::frame::Frame;
use relief_core::scene::{Scene, SceneObject};

use crate::gbuffer::GBuffer;
use crate::raster::rasterize;

/// Objects with fewer triangles are cheaper to draw than to warp.
pub const CHEAP_TRIANGLES: usize = 1000;

/// An eye within this fraction of an object's bounds diagonal from its bounds draws
/// it as geometry: so near, a relief texture stays valid for a degree or two of the
/// eye's turn — a few frames, less than a round trip — and shows its flat texels
/// large. (A smaller margin left the demo about twice the stale frames, no faster.)
pub const NEAR_MARGIN: f32 = 0.25;

/// Why an object is drawn as geometry.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum GeometryReason {
    /// Too few triangles to be worth an impostor ([`CHEAP_TRIANGLES`]).
    Cheap,
    /// The eye is inside, or within [`NEAR_MARGIN`] of, the object's bounds.
    TooNear,
}

/// Whether `object` has too few triangles to be worth an impostor from any eye.
pub fn is_cheap(object: &SceneObject) -> bool {
    object.mesh.triangle_count() < CHEAP_TRIANGLES
}

/// Why `object` is drawn as geometry from `eye` (in the world); `None` when it may be
/// an impostor.
pub fn geometry_reason(object: &SceneObject, eye: DVec3) -> Option<GeometryReason> {
    if is_cheap(object) {
        return Some(GeometryReason::Cheap);
    }
    let bounds = object.local_bounds;
    bounds
        .expanded(bounds.extent().length() * NEAR_MARGIN)
        .contains(object.to_local(eye))
        .then_some(GeometryReason::TooNear)
}

/// The near-plane distance used for a scene: small against its size, never zero.
pub fn near_plane(scene: &Scene) -> f32 {
    (scene.bounds().extent().length() * 1e-5).max(1e-6)
}

/// The frame with every object as geometry: rasterized, then shaded.
pub fn render_geometry(scene: &Scene, camera: &Camera, gbuffer: &mut GBuffer) -> Frame {
    gbuffer.clear();
    let objects: Vec<(u32, &SceneObject)> = scene
        .objects
        .iter()
        .enumerate()
        .map(|(k, o)| (k as u32, o))
        .collect();
    rasterize(&objects, camera, near_plane(scene), gbuffer);
    gbuffer.shade(scene, camera)
}
