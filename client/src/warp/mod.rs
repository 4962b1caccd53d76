//! Showing a relief texture from a new eye: every display method of the sources, each
//! writing albedo, normal and depth into the frame's [`GBuffer`] with a depth test.
//!
//! - [`params`] — the per-eye constants of the pre-warp (epipole, `k3`) and its lookup
//!   tables (eq. 3-1/3-2, ch. 8.2).
//! - [`prewarp`] — the pre-warp in its four sampling variants, producing a
//!   [`prewarp::PrewarpImage`] in the source plane;
//! - [`texmap`] — perspective texture mapping of that image onto the source quad;
//! - [`forward`] — texels warped straight to the screen as points, holes filled by
//!   [`pullpush`] (Marroquim ch. 4);
//! - [`inverse`] — per-pixel ray marching of the depth field (Policarpo);
//! - [`sprite`] — reuse of a previous result.

pub mod forward;
pub mod inverse;
pub mod params;
pub mod prewarp;
pub mod pullpush;
pub mod sprite;
pub mod texmap;

use std::fmt;
use std::str::FromStr;

use relief_core::camera::Camera;
use relief_core::relief::SourceCamera;

use crate::gbuffer::GBuffer;
use crate::impostor::Impostor;

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
/// method checks this before touching the texture.
pub(crate) fn ensure_finite(texture: &SourceCamera, eye: glam::Vec3) -> Result<(), WarpError> {
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
    /// An input (eye, texture camera) holds NaN or infinity.
    #[error("non-finite input to the warp")]
    NonFinite,
    /// The sprite method reuses a previous frame, which [`display`] does not have.
    #[error("the sprite method needs a previous frame")]
    NeedsPreviousFrame,
    /// [`Prepared::behind`] asked of a method that does not pre-warp.
    #[error("only the pre-warp methods can draw a surface pushed back")]
    DepthBiasUnsupported,
}

/// A display method, selectable by name.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash)]
pub enum Method {
    /// Pre-warp rows then columns, the column pass re-interpolating depth.
    TwoPass1d,
    /// Two passes; the row pass stores each texel's final v.
    TwoPassAsym,
    /// Two passes with displacement-compensated depth for interpolated texels (eq. 8-1).
    TwoPassComp,
    /// One pass: each row sample goes straight into its column (the sources' choice).
    Interleaved,
    /// Texels splatted to the screen as points, holes filled by pull–push.
    ForwardPullPush,
    /// Texels splatted to the screen as points at a pyramid level by their size,
    /// gathered per pixel with a `k × k` kernel (Marroquim ch. 6); k = 3 or 5.
    ForwardKernel(u8),
    /// Per-pixel march of the depth field with this many linear steps.
    Inverse(u16),
    /// The previous frame's impostor pixels, unchanged (needs a previous frame).
    Sprite,
}

impl Method {
    /// Every method, in report order.
    pub const ALL: [Method; 11] = [
        Method::Sprite,
        Method::TwoPass1d,
        Method::TwoPassAsym,
        Method::TwoPassComp,
        Method::Interleaved,
        Method::ForwardPullPush,
        Method::ForwardKernel(3),
        Method::ForwardKernel(5),
        Method::Inverse(16),
        Method::Inverse(64),
        Method::Inverse(128),
    ];

    /// The method's name, as `--method` takes it.
    pub fn name(self) -> String {
        match self {
            Method::Sprite => "sprite".into(),
            Method::TwoPass1d => "twopass-1d".into(),
            Method::TwoPassAsym => "twopass-asym".into(),
            Method::TwoPassComp => "twopass-comp".into(),
            Method::Interleaved => "interleaved".into(),
            Method::ForwardPullPush => "forward-pullpush".into(),
            Method::ForwardKernel(k) => format!("forward-kernel-{k}"),
            Method::Inverse(n) => format!("inverse-{n}"),
        }
    }
}

impl fmt::Display for Method {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        f.write_str(&self.name())
    }
}

impl FromStr for Method {
    type Err = String;

    /// Parses a method name; `inverse-N` takes any step count 1..=4096 and
    /// `forward-kernel-K` an odd K in 1..=9.
    fn from_str(s: &str) -> Result<Self, Self::Err> {
        if let Some(n) = s.strip_prefix("inverse-")
            && let Ok(n) = n.parse::<u16>()
            && (1..=4096).contains(&n)
        {
            return Ok(Method::Inverse(n));
        }
        if let Some(k) = s.strip_prefix("forward-kernel-")
            && let Ok(k) = k.parse::<u8>()
            && k % 2 == 1
            && k <= 9
        {
            return Ok(Method::ForwardKernel(k));
        }
        Method::ALL.into_iter().find(|m| m.name() == s).ok_or_else(|| {
            let names: Vec<String> = Method::ALL.iter().map(|m| m.name()).collect();
            format!(
                "unknown method `{s}` (choose one of: {}; inverse-N, forward-kernel-K)",
                names.join(", ")
            )
        })
    }
}

/// Shows `impostor` of scene object `object` from `camera` into `gbuffer` with `method`.
pub fn display(
    method: Method,
    impostor: &Impostor,
    object: u32,
    camera: &Camera,
    gbuffer: &mut GBuffer,
) -> Result<(), WarpError> {
    draw(
        prepare(method, impostor, camera)?,
        impostor,
        object,
        camera,
        gbuffer,
    )
}

/// The part of a display that does not touch the frame: the pre-warp of the pre-warp
/// methods (nothing for the others). Several impostors' can run at once, one per
/// core, before their [`draw`]s — a frame's impostors differ in size, and one warp
/// split in two halves at its epipole leaves a core idle when the epipole is near an
/// edge.
pub fn prepare(method: Method, impostor: &Impostor, camera: &Camera) -> Result<Prepared, WarpError> {
    let variant = match method {
        Method::TwoPass1d => prewarp::Variant::OneD,
        Method::TwoPassAsym => prewarp::Variant::Asymmetric,
        Method::TwoPassComp => prewarp::Variant::Compensated,
        Method::Interleaved => prewarp::Variant::Interleaved,
        Method::ForwardPullPush => return Ok(Prepared(Stage::PullPush)),
        Method::ForwardKernel(k) => return Ok(Prepared(Stage::Kernel(k))),
        Method::Inverse(steps) => return Ok(Prepared(Stage::Inverse(steps))),
        Method::Sprite => return Err(WarpError::NeedsPreviousFrame),
    };
    let params = params::WarpParams::new(&impostor.texture, camera.eye)?;
    // The halves above and below the epipole on two threads: 1.5–1.8× faster at 512²
    // here when the epipole is inside (`relief bench warp`, "split ms").
    // Only what the screen can show: a texture partly off screen (or far larger than
    // it) pre-warps only the texels that can land on it.
    let seen = prewarp::PlaneWindow::seen_by(camera, &impostor.texture.camera);
    let image = prewarp::prewarp_split(impostor, &params, variant, seen.as_ref());
    Ok(Prepared(Stage::Prewarped(image, params, 1.0)))
}

/// What [`prepare`] made, for [`draw`].
pub struct Prepared(Stage);

impl Prepared {
    /// Texels of `impostor` (the one prepared) this display visits: those a pre-warp
    /// reached the screen from, or all.
    pub fn texels_warped(&self, impostor: &Impostor) -> usize {
        match &self.0 {
            Stage::Prewarped(image, ..) => image.visited,
            _ => impostor.texture.depth.len(),
        }
    }

    /// Depth-tests the surface as if `factor` (> 1) times farther from the eye than it
    /// is, along each pixel's own ray — the same pixels, and the true depths stored;
    /// only the test changes — so that
    /// it shows only where nothing else of the frame is within that margin in front:
    /// a second texture filling in what the first cannot show, never fighting it where
    /// both show the same surface. Only the pre-warp methods draw this way; an error
    /// for the others, and [`WarpError::NonFinite`] for a `factor` not finite and
    /// positive.
    pub fn behind(self, factor: f32) -> Result<Prepared, WarpError> {
        if !(factor.is_finite() && factor > 0.0) {
            return Err(WarpError::NonFinite);
        }
        match self.0 {
            Stage::Prewarped(image, params, scale) => {
                Ok(Prepared(Stage::Prewarped(image, params, scale * factor)))
            }
            _ => Err(WarpError::DepthBiasUnsupported),
        }
    }
}

enum Stage {
    /// The pre-warped image, its constants, and the factor applied to its depths.
    Prewarped(prewarp::PrewarpImage, params::WarpParams, f32),
    PullPush,
    Kernel(u8),
    Inverse(u16),
}

/// Finishes, into `gbuffer`, the display [`prepare`] began for the same impostor and
/// camera.
pub fn draw(
    prepared: Prepared,
    impostor: &Impostor,
    object: u32,
    camera: &Camera,
    gbuffer: &mut GBuffer,
) -> Result<(), WarpError> {
    match prepared.0 {
        Stage::Prewarped(image, params, depth_scale) => {
            texmap::map(
                &image,
                &impostor.texture,
                &params,
                depth_scale,
                object,
                camera,
                gbuffer,
            );
            Ok(())
        }
        Stage::PullPush => forward::display(impostor, object, camera, gbuffer),
        Stage::Kernel(k) => forward::display_kernel(impostor, k as usize, object, camera, gbuffer),
        Stage::Inverse(steps) => inverse::display(impostor, steps as usize, object, camera, gbuffer),
    }
}
