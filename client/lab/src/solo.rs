//! The measurement set-up shared by the reports and tests: one object alone, a source
//! eye on an orbit around it, a destination eye turned by an angle on the same orbit,
//! the ray-traced reference from the destination, and the comparison of a frame with it.

use glam::Vec3;

use relief_core::camera::Camera;
use relief_core::frame::Frame;
use relief_core::relief::{DepthBits, ReliefTexture, SourceProjection};
use relief_core::scene::Scene;
use relief_trace::tracer::SceneTracer;
use relief_trace::{bake, render_reference};

use crate::image_error::{ImageError, compare};

/// Why an object cannot be set up, or baked, alone on its orbit.
#[derive(Debug, thiserror::Error)]
pub enum SoloError {
    /// The scene has no such object.
    #[error(transparent)]
    Scene(#[from] relief_core::Error),
    #[error("an orbit at {0} bounding radii is not outside the bounding sphere with 10 % to spare")]
    OrbitInside(f32),
    #[error("object `{name}` cannot be orbited at {factor} bounding radii: its bounding radius is {radius}")]
    NoExtent { name: String, factor: f32, radius: f32 },
    #[error(transparent)]
    Camera(#[from] relief_core::camera::CameraError),
    #[error(transparent)]
    Bake(#[from] relief_trace::BakeError),
}

/// One object of a scene, alone, ready to be baked and ray-traced. Its frame is the
/// world's (moved to the origin, its lights with it), so that eyes and textures here
/// are in both.
pub struct Solo {
    /// A scene holding only the object (index 0), with the original lights.
    pub scene: Scene,
    /// Traces the scene; its object 0 bakes the textures.
    pub tracer: SceneTracer,
    /// Orbit radius: the distance of every eye from the object's centre.
    pub distance: f32,
}

impl Solo {
    /// Isolates `name` of `scene`; eyes orbit at `distance_factor` bounding radii
    /// (more than 1.1, so the cameras' view of the bounding sphere, with 10 % to
    /// spare, is narrower than 180°). An object without extent (every vertex at one
    /// point) cannot be orbited: an error naming it.
    pub fn new(scene: &Scene, name: &str, distance_factor: f32) -> Result<Solo, SoloError> {
        // The object in its own frame, the lights moved into it: the same images.
        let placed = scene.object(name)?;
        let lighting = placed.local_lighting(&scene.lighting);
        let object = placed.placed(placed.name.clone(), glam::DVec3::ZERO, glam::DQuat::IDENTITY, 1.0);
        let radius = object.local_bounds.extent().length() * 0.5;
        let distance = radius * distance_factor;
        if distance_factor.is_nan() || distance_factor <= 1.1 {
            return Err(SoloError::OrbitInside(distance_factor));
        }
        if !(radius > 0.0 && distance.is_finite()) {
            return Err(SoloError::NoExtent {
                name: name.to_string(),
                factor: distance_factor,
                radius,
            });
        }
        let solo = Scene {
            objects: vec![object],
            lighting,
            ..scene.clone()
        };
        let tracer = SceneTracer::new(&solo);
        Ok(Solo {
            distance,
            scene: solo,
            tracer,
        })
    }

    /// The eye `angle_deg` around the vertical axis through the object's centre,
    /// slightly above it.
    pub fn eye(&self, angle_deg: f32) -> Vec3 {
        let centre = self.scene.objects[0].local_bounds.center();
        let a = angle_deg.to_radians();
        let dir = Vec3::new(a.sin(), 0.25, a.cos()).normalize();
        centre + dir * self.distance
    }

    /// A square camera at `eye` looking at the object's centre, its field of view just
    /// wide enough for the object's bounding sphere (with 10 % to spare) from the
    /// orbit; an error for an eye or size no camera can have.
    pub fn camera(&self, eye: Vec3, size: u32) -> Result<Camera, SoloError> {
        let bounds = self.scene.objects[0].local_bounds;
        let radius = bounds.extent().length() * 0.5;
        let fov = 2.0 * (radius * 1.1 / self.distance).asin().to_degrees();
        Ok(Camera::look_at(
            eye.as_dvec3(),
            bounds.center().as_dvec3(),
            Vec3::Y,
            fov,
            size,
            size,
        )?)
    }

    /// Bakes the object's relief texture for `eye`, orthographic as the thesis's (an
    /// error for an object too degenerate to orbit, whose eyes fall inside its bounds).
    pub fn bake(&self, eye: Vec3, size: u32, bits: DepthBits) -> Result<ReliefTexture, SoloError> {
        self.bake_in(eye, size, bits, SourceProjection::Orthographic)
    }

    /// [`Solo::bake`] in `projection`.
    pub fn bake_in(
        &self,
        eye: Vec3,
        size: u32,
        bits: DepthBits,
        projection: SourceProjection,
    ) -> Result<ReliefTexture, SoloError> {
        Ok(bake(&self.tracer.objects[0], eye, size, bits, projection)?)
    }

    /// The ray-traced reference frame, `samples × samples` rays per pixel (see
    /// [`render_reference`]).
    pub fn reference(&self, camera: &Camera, samples: u32) -> Frame {
        render_reference(&self.tracer, camera, samples)
    }

    /// Error of `frame` against `reference` on the object's pixels.
    pub fn error(&self, frame: &Frame, reference: &Frame) -> ImageError {
        compare(frame, reference, Some(0))
    }
}
