//! Whole frames: cheap and too-near objects as geometry, complex ones as relief
//! impostors — composited through one G-buffer, so they occlude each other correctly.

use glam::{Quat, Vec3};
use rayon::prelude::*;

use relief_core::camera::Camera;
use relief_core::frame::Frame;
use relief_core::relief::{DepthBits, SourceProjection};
use relief_core::scene::{Scene, SceneObject};
use relief_trace::bake;
use relief_trace::tracer::ObjectTracer;

use relief_render::gbuffer::GBuffer;
use relief_render::geometry::{GeometryReason, geometry_reason, near_plane};
use relief_render::impostor::{Faces, Impostor};
use relief_render::pyramid::{MAX_TEXEL_PIXELS, MIN_LEVEL_EDGE, Pyramid};
use relief_render::raster::rasterize;
use relief_render::validity::schaufler::resolution_for;

use crate::methods::{Method, draw, prepare};

/// The largest texture edge a plan bakes, bounding a frame's bake time: 1024² texels
/// serve an object 1024 pixels across at one texel a pixel.
pub const MAX_TEXTURE_EDGE: u32 = 1024;

/// One impostor of a frame.
pub struct ImpostorObject {
    pub index: u32,
    pub pyramid: Pyramid,
    /// The eye its texture was baked for, in the object's frame.
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
    /// Impostors that could not be drawn faithfully from this eye and were drawn as
    /// geometry.
    pub fell_back: usize,
    /// Why, for each of them: the object's name and the method's reason.
    pub fell_back_why: Vec<String>,
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
                // (In the object's frame: see `SceneObject`.)
                let object = &scene.objects[k];
                let (camera, centre) = (object.local_camera(camera), object.local_bounds.center());
                let turn = Quat::from_rotation_y(source_angle_deg.to_radians());
                let source_eye = centre + turn * (camera.eye_f32() - centre);
                // (Its volume centre is as far from the source eye as from the eye.)
                let size = resolution_for(
                    &object.local_bounds,
                    source_eye,
                    SourceProjection::Orthographic,
                    &camera,
                    MAX_TEXEL_PIXELS,
                )
                .unwrap_or(MAX_TEXTURE_EDGE)
                .clamp(MIN_LEVEL_EDGE, MAX_TEXTURE_EDGE);
                let texture = bake(
                    &ObjectTracer::new(object),
                    source_eye,
                    size,
                    bits,
                    SourceProjection::Orthographic,
                )
                .ok();
                let impostor = texture.map(|texture| ImpostorObject {
                    index: k as u32,
                    pyramid: Pyramid::new(texture, MIN_LEVEL_EDGE).with_faces(Faces::of(object)),
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
        // Each impostor in its object's frame (see `SceneObject`).
        let cameras: Vec<Camera> = (self.impostors.iter())
            .map(|imp| scene.objects[imp.index as usize].local_camera(camera))
            .collect();
        let shown: Vec<&Impostor> = (self.impostors.iter().zip(&cameras))
            .map(|(imp, camera)| &imp.pyramid.levels[imp.pyramid.level_for(camera, MAX_TEXEL_PIXELS)])
            .collect();
        // Every impostor's pre-warp at once, then each drawn.
        let prepared: Vec<_> = (shown.par_iter().zip(&cameras).zip(&self.impostors))
            .map(|((i, camera), imp)| {
                let scale = scene.objects[imp.index as usize].depth_scale();
                prepare(method, i, camera).and_then(|p| p.in_world(method, scale))
            })
            .collect();
        for (((imp, impostor), prepared), camera) in
            self.impostors.iter().zip(shown).zip(prepared).zip(&cameras)
        {
            stats.texels_baked += imp.pyramid.levels[0].texture.depth.len();
            let drawn = prepared.and_then(|p| {
                let texels = p.texels_warped(impostor);
                draw(p, impostor, imp.index, camera, gbuffer).map(|()| texels)
            });
            match drawn {
                Ok(texels) => stats.texels_warped += texels,
                // (The eye in the texture's plane, or a method that cannot draw here
                // faithfully.)
                Err(why) => {
                    stats.fell_back += 1;
                    let name = &scene.objects[imp.index as usize].name;
                    stats.fell_back_why.push(format!("{name}: {why}"));
                    geometry.push((imp.index, &scene.objects[imp.index as usize]));
                }
            }
        }
        rasterize(&geometry, camera, near_plane(scene), gbuffer);
        (gbuffer.shade(scene, camera), stats)
    }
}
