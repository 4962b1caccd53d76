//! Showing a relief texture from a new eye as the thesis does: the pre-warp of eq.
//! 3-1/3-2 in the texture's own plane, then perspective texture mapping of that image
//! onto the texture's quad — writing albedo, normal and depth into the frame's
//! [`GBuffer`] with a depth test.
//!
//! - [`params`] — the per-eye constants of the pre-warp (epipole, `k3`) and its lookup
//!   tables (eq. 3-1/3-2, ch. 8.2).
//! - [`prewarp`] — the pre-warp in its four sampling [`Variant`]s, producing a
//!   [`prewarp::PrewarpImage`] in the source plane.
//! - [`texmap`] — perspective texture mapping of that image onto the source quad.
//! - [`sprite`] — an impostor's image captured from the G-buffer and drawn again.
//!
//! # Two stages
//!
//! A display is [`Prewarped::new`] (the pre-warp, which does not touch the frame) then
//! [`Prewarped::draw`] (into the G-buffer). A frame runs all its impostors' pre-warps
//! at once, one per core, before drawing them in turn: impostors differ in size, and
//! one pre-warp split at its epipole leaves a core idle when the epipole is near an edge.
//!
//! # Frames
//!
//! A relief texture is given in its object's own frame, and every camera these
//! functions take must be too: a scene's camera moved there by
//! [`SceneObject::local_camera`](relief_core::scene::SceneObject::local_camera), which
//! keeps a warp as precise 10⁶ m from the world's origin as at it.
//!
//! ```
//! use relief_core::relief::{DepthBits, ReliefTexture, SourceCamera, SourceProjection};
//! use relief_render::gbuffer::GBuffer;
//! use relief_render::impostor::Impostor;
//! use relief_render::warp::{Prewarped, Variant};
//! # use relief_core::{bounds::Aabb, camera::Camera};
//! # let bounds = Aabb::from_points([glam::Vec3::splat(-1.0), glam::Vec3::splat(1.0)]);
//! # let eye = glam::Vec3::new(0.0, 0.0, 5.0);
//! # let source = SourceCamera::facing(eye, &bounds, 16, 16, SourceProjection::Orthographic)?;
//! // (An empty texture: a baked one comes from `relief_trace::bake`.)
//! let impostor = Impostor::new(ReliefTexture::empty(source, DepthBits::Eight, eye));
//! let camera = Camera::look_at(glam::DVec3::new(1.0, 0.0, 5.0), glam::DVec3::ZERO, glam::Vec3::Y, 40.0, 64, 64)?;
//! let mut gbuffer = GBuffer::new(64, 64);
//! Prewarped::new(Variant::Interleaved, &impostor, &camera)?.draw(&impostor, 0, &camera, &mut gbuffer);
//! assert_eq!(gbuffer.covered(), 0);
//! # Ok::<(), Box<dyn std::error::Error>>(())
//! ```

pub mod params;
pub mod prewarp;
pub mod sprite;
pub mod texmap;

pub use prewarp::Variant;

use relief_core::camera::Camera;
use relief_core::relief::SourceCamera;

use crate::gbuffer::GBuffer;
use crate::impostor::Impostor;
use texmap::Depths;

/// The fewest pixels or texels one task of a warp takes (a pre-warp's half, a texture
/// mapping's rows): smaller work is not split across cores, where
/// handing it to another thread costs more than it saves — a far impostor is a few
/// hundred pixels (measured in `docs/targets.md`, "Many impostors").
pub(crate) const MIN_TASK_PIXELS: usize = 4096;

/// Rows `width` pixels wide one task takes: [`MIN_TASK_PIXELS`] worth, at least one.
pub(crate) fn rows_per_task(width: usize) -> usize {
    (MIN_TASK_PIXELS / width.max(1)).max(1)
}

/// `x ∈ [0, 2²³ − 0.5)` rounded to the nearest integer (ties to even); anything else
/// (negative, NaN) gives an arbitrary value below 2²³, so callers bound the result.
/// Adding 2²³ leaves the rounded value in the float's mantissa bits: one add, where a
/// saturating `as` conversion costs a quarter of the time of the inner loops that use
/// this.
#[inline(always)]
pub(crate) fn round_small(x: f32) -> u32 {
    (x + 8_388_608.0).to_bits() & 0x7f_ffff
}

/// `Err(NonFinite)` when the eye or the texture's camera holds NaN or infinity: every
/// way of showing a texture checks this before touching it.
pub fn ensure_finite(texture: &SourceCamera, eye: glam::Vec3) -> Result<(), WarpError> {
    let finite =
        eye.is_finite() && texture.origin.is_finite() && texture.a.is_finite() && texture.b.is_finite();
    if finite { Ok(()) } else { Err(WarpError::NonFinite) }
}

/// Why a texture cannot be shown from an eye.
#[derive(Debug, Clone, Copy, PartialEq, thiserror::Error)]
pub enum WarpError {
    /// The eye is in, or behind, the texture's plane (`c·f ≤ 0`, `k3` unbounded): the
    /// texture cannot be warped there; draw geometry or make a new texture.
    #[error(
        "the eye is in or behind the relief texture's plane (c·f = {0}): needs geometry or a new texture"
    )]
    EyeInPlane(f32),
    /// An input (eye, texture camera, depth factor) holds NaN or infinity.
    #[error("non-finite input to the warp")]
    NonFinite,
}

/// Shows `impostor` of scene object `object` from `camera` (in the texture's frame) into
/// `gbuffer`: the pre-warp in `variant`, then its texture mapping.
pub fn display(
    variant: Variant,
    impostor: &Impostor,
    object: u32,
    camera: &Camera,
    gbuffer: &mut GBuffer,
) -> Result<(), WarpError> {
    Prewarped::new(variant, impostor, camera)?.draw(impostor, object, camera, gbuffer);
    Ok(())
}

/// A texture pre-warped for one eye, ready to be texture-mapped into a frame.
pub struct Prewarped {
    image: prewarp::PrewarpImage,
    params: params::WarpParams,
    /// How its depths go into the frame ([`Prewarped::in_world`], [`Prewarped::behind`]).
    depths: Depths,
}

/// `factor`, when finite and positive; else [`WarpError::NonFinite`].
fn positive(factor: f32) -> Result<f32, WarpError> {
    if factor.is_finite() && factor > 0.0 {
        Ok(factor)
    } else {
        Err(WarpError::NonFinite)
    }
}

impl Prewarped {
    /// The pre-warp of `impostor` for `camera`'s eye in `variant`, split at its epipole
    /// over two threads when large ([`prewarp::prewarp_split`]), of only what the
    /// screen can show (a texture partly off screen,
    /// or far larger than it, pre-warps only the texels that can land on it).
    pub fn new(variant: Variant, impostor: &Impostor, camera: &Camera) -> Result<Prewarped, WarpError> {
        let params = params::WarpParams::new(&impostor.texture, camera.eye_f32())?;
        let seen = prewarp::PlaneWindow::seen_by(camera, &impostor.texture.camera);
        let image = prewarp::prewarp_split(impostor, &params, variant, seen.as_ref());
        Ok(Prewarped {
            image,
            params,
            depths: Depths {
                tested: 1.0,
                world: 1.0,
            },
        })
    }

    /// Texels of the impostor this pre-warp visited: those that can reach the screen.
    pub fn texels_warped(&self) -> usize {
        self.image.visited
    }

    /// Depth-tests the surface as if `factor` (> 1) times farther from the eye than it
    /// is, along each pixel's own ray — the same pixels, and the true depths stored;
    /// only the test changes — so that it shows only where nothing else of the frame
    /// is within that margin in front: a second texture filling in what the first
    /// cannot show, never fighting it where both show the same surface.
    /// [`WarpError::NonFinite`] for a `factor` not finite and positive.
    pub fn behind(mut self, factor: f32) -> Result<Prewarped, WarpError> {
        self.depths.tested *= positive(factor)?;
        Ok(self)
    }

    /// Stores (and tests) depths `scale` times those seen in the texture's frame: the
    /// frame of an object scaled in the world
    /// ([`SceneObject::depth_scale`](relief_core::scene::SceneObject::depth_scale)),
    /// whose depths the frame's other objects compare with in the world's metres.
    /// [`WarpError::NonFinite`] for a `scale` not finite and positive.
    pub fn in_world(mut self, scale: f32) -> Result<Prewarped, WarpError> {
        self.depths.world *= positive(scale)?;
        Ok(self)
    }

    /// Texture-maps the pre-warped image of `impostor` (the one pre-warped) for
    /// `camera` (the one it was pre-warped for) into `gbuffer` as object `object`.
    pub fn draw(self, impostor: &Impostor, object: u32, camera: &Camera, gbuffer: &mut GBuffer) {
        texmap::map(
            &self.image,
            &impostor.texture,
            &self.params,
            self.depths,
            object,
            camera,
            gbuffer,
        );
    }
}
