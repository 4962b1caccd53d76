//! Whole frames: cheap and too-near objects as geometry, complex ones as relief
//! impostors — composited through one G-buffer, so they occlude each other correctly.

use glam::{Quat, Vec3};
use rayon::prelude::*;

use relief_core::camera::Camera;
use relief_core::frame::Frame;
use relief_core::relief::DepthBits;
use relief_core::scene::{Scene, SceneObject};
use relief_worker::bake;
use relief_worker::tracer::ObjectTracer;

use crate::gbuffer::GBuffer;
use crate::impostor::Impostor;
use crate::metrics::schaufler::resolution_for;
use crate::pyramid::Pyramid;
use crate::raster::rasterize;
use crate::warp::{Method, WarpError, draw, prepare};

/// Objects with fewer triangles are cheaper to draw than to warp.
pub const CHEAP_TRIANGLES: usize = 1000;
/// Texture edges are kept within these bounds.
pub const MIN_TEXTURE: u32 = 16;
pub const MAX_TEXTURE: u32 = 1024;
/// A texel may subtend this many pixels before a finer pyramid level is used.
pub const TEXEL_TOLERANCE: f32 = 1.0;

/// An eye within this fraction of an object's bounds diagonal from its bounds draws
/// it as geometry: so near, a relief texture stays valid for a degree or two of the
/// eye's turn — a few frames, less than a round trip — and shows its flat texels
/// large. (Against 5 %, the demo's stale frames fell from 3.2 % to 1.7 % with the
/// median frame time unchanged.)
pub const NEAR_MARGIN: f32 = 0.25;

/// Why an object is drawn as geometry.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum GeometryReason {
    /// Too few triangles to be worth an impostor.
    Cheap,
    /// The eye is inside, or within [`NEAR_MARGIN`] of, the object's bounds.
    TooNear,
}

/// Whether `object` has too few triangles to be worth an impostor from any eye.
pub fn is_cheap(object: &SceneObject) -> bool {
    object.mesh.triangle_count() < CHEAP_TRIANGLES
}

/// How `object` should be drawn from `eye`.
pub fn geometry_reason(object: &SceneObject, eye: Vec3) -> Option<GeometryReason> {
    if is_cheap(object) {
        return Some(GeometryReason::Cheap);
    }
    let margin = object.bounds.extent().length() * NEAR_MARGIN;
    object
        .bounds
        .expanded(margin)
        .contains(eye)
        .then_some(GeometryReason::TooNear)
}

/// The near-plane distance used for a scene: small against its size, never zero.
pub fn near_plane(scene: &Scene) -> f32 {
    (scene.bounds().extent().length() * 1e-5).max(1e-6)
}

/// One impostor of a frame.
pub struct ImpostorObject {
    pub index: u32,
    pub pyramid: Pyramid,
    /// The eye its texture was baked for.
    pub source_eye: Vec3,
}

/// A frame's plan: which objects are impostors (with their textures) and which are
/// geometry.
pub struct FramePlan {
    pub impostors: Vec<ImpostorObject>,
    pub geometry: Vec<(u32, GeometryReason)>,
}

/// What drawing one frame did.
#[derive(Debug, Clone, Default, serde::Serialize)]
pub struct FrameStats {
    /// Texels warped (of the pyramid level each impostor used, those that can reach
    /// the screen).
    pub texels_warped: usize,
    /// Texels the full-resolution textures have.
    pub texels_baked: usize,
    /// Impostors that could not be warped from this eye and were drawn as geometry.
    pub fell_back: usize,
}

impl FramePlan {
    /// Plans a frame for `camera`: every object that is not cheap or too near becomes
    /// an impostor whose texture is baked `source_angle_deg` around the object (about
    /// the vertical through its centre) from the eye, at the resolution eq. 5-1 asks.
    pub fn bake(scene: &Scene, camera: &Camera, source_angle_deg: f32, bits: DepthBits) -> FramePlan {
        let mut geometry = Vec::new();
        let mut wanted = Vec::new();
        for (k, object) in scene.objects.iter().enumerate() {
            match geometry_reason(object, camera.eye) {
                Some(reason) => geometry.push((k as u32, reason)),
                None => wanted.push(k),
            }
        }
        let baked: Vec<(usize, Option<ImpostorObject>)> = wanted
            .into_par_iter()
            .map(|k| {
                let object = &scene.objects[k];
                let centre = object.bounds.center();
                let turn = Quat::from_rotation_y(source_angle_deg.to_radians());
                let source_eye = centre + turn * (camera.eye - centre);
                // (Its volume centre is as far from the source eye as from the eye.)
                let size = resolution_for(&object.bounds, source_eye, camera, TEXEL_TOLERANCE)
                    .unwrap_or(MAX_TEXTURE)
                    .clamp(MIN_TEXTURE, MAX_TEXTURE);
                let texture = bake(&ObjectTracer::new(object), source_eye, size, bits).ok();
                let impostor = texture.map(|texture| ImpostorObject {
                    index: k as u32,
                    pyramid: Pyramid::new(texture, MIN_TEXTURE),
                    source_eye,
                });
                (k, impostor)
            })
            .collect();
        let mut impostors = Vec::new();
        for (k, impostor) in baked {
            match impostor {
                Some(impostor) => impostors.push(impostor),
                // The bake failed (the eye is inside after the turn): geometry.
                None => geometry.push((k as u32, GeometryReason::TooNear)),
            }
        }
        FramePlan { impostors, geometry }
    }

    /// Draws the frame: geometry rasterized, impostors shown with `method`, one
    /// shading pass.
    pub fn render(
        &self,
        scene: &Scene,
        camera: &Camera,
        method: Method,
        gbuffer: &mut GBuffer,
    ) -> (Frame, FrameStats) {
        gbuffer.clear();
        let mut stats = FrameStats::default();
        let mut geometry: Vec<(u32, &SceneObject)> = self
            .geometry
            .iter()
            .map(|&(k, _)| (k, &scene.objects[k as usize]))
            .collect();
        let shown: Vec<&Impostor> = self
            .impostors
            .iter()
            .map(|imp| &imp.pyramid.levels[imp.pyramid.level_for(camera, TEXEL_TOLERANCE)])
            .collect();
        // Every impostor's pre-warp at once, then each drawn.
        let prepared: Vec<_> = shown.par_iter().map(|i| prepare(method, i, camera)).collect();
        for ((imp, impostor), prepared) in self.impostors.iter().zip(shown).zip(prepared) {
            stats.texels_baked += imp.pyramid.levels[0].texture.depth.len();
            let drawn = prepared.and_then(|p| {
                let texels = p.texels_warped(impostor);
                draw(p, impostor, imp.index, camera, gbuffer).map(|()| texels)
            });
            match drawn {
                Ok(texels) => stats.texels_warped += texels,
                Err(
                    WarpError::EyeInPlane(_)
                    | WarpError::NonFinite
                    | WarpError::NeedsPreviousFrame
                    | WarpError::DepthBiasUnsupported,
                ) => {
                    stats.fell_back += 1;
                    geometry.push((imp.index, &scene.objects[imp.index as usize]));
                }
            }
        }
        rasterize(&geometry, camera, near_plane(scene), gbuffer);
        (gbuffer.shade(scene, camera), stats)
    }
}

/// The same frame with every object as geometry: the baseline.
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
