//! Every display method of the sources, for comparison: the pre-warp's four sampling
//! variants (the renderer's, [`relief_render::warp`]), texels splatted forward and
//! reconstructed ([`forward`], with [`pullpush`] or a per-level kernel), per-pixel ray
//! marching ([`inverse`]), and the sprite. Each writes albedo, normal and depth into
//! the frame's [`GBuffer`] with a depth test.
//!
//! - [`forward`] — texels warped straight to the screen as points, holes filled by
//!   [`pullpush`] (Marroquim ch. 4) or gathered with a K×K kernel (ch. 6);
//! - [`inverse`] — per-pixel ray marching of the depth field (Policarpo).
//!
//! [`Method`] names them all (as `--method` takes them); [`display`] shows a texture
//! with one.

pub mod forward;
pub mod inverse;
pub mod pullpush;

use std::fmt;
use std::str::FromStr;

use relief_core::camera::Camera;
use relief_core::relief::SourceProjection;
use relief_render::gbuffer::GBuffer;
use relief_render::impostor::Impostor;
use relief_render::validity::schaufler::{texel_angle, volume_centre};
use relief_render::warp::{Prewarped, Variant, WarpError};

/// Why a method cannot show a texture from an eye.
#[derive(Debug, Clone, Copy, PartialEq, thiserror::Error)]
pub enum DisplayError {
    /// The texture cannot be warped there (the eye in its plane, or a non-finite input).
    #[error(transparent)]
    Warp(#[from] WarpError),
    /// The sprite method reuses a previous frame, which [`display`] does not have.
    #[error("the sprite method needs a previous frame")]
    NeedsPreviousFrame,
    /// A texel would cover more pixels than the method's reconstruction fills: drawn,
    /// it would show a grid of dots. Needs a finer texture, or geometry.
    #[error(
        "a texel covers {pixels:.1} pixels, more than {method}'s reconstruction fills ({fills}): needs a finer texture or geometry"
    )]
    TexelsTooLarge { method: Method, pixels: f32, fills: f32 },
    /// The eye is so far round the object from the texture's eye that what the method
    /// would draw is the texture's far side, seen through.
    #[error(
        "the eye is {turn_deg:.0}° round the object from the texture's eye, past the {max_deg:.0}° one texture can show: needs a texture from nearer"
    )]
    FarSide { turn_deg: f32, max_deg: f32 },
    /// The forward and inverse methods follow the thesis's orthographic relief texture;
    /// a perspective one is shown by the pre-warp.
    #[error(
        "{method} shows orthographic relief textures only; this one is perspective (use a pre-warp method)"
    )]
    NeedsOrthographic { method: Method },
    /// The object's frame is scaled in the world (a scene file's placement): only the
    /// pre-warp methods store its depths in the world's metres.
    #[error(
        "{method} draws in the object's own metres; this object's frame is scaled by {scale} (use a pre-warp method)"
    )]
    ScaledFrame { method: Method, scale: f32 },
}

/// The widest turn round an object, from its texture's eye, at which the forward and
/// inverse methods still draw it: past a right angle a texture shows the far side of
/// what the eye sees (measured: 9–18 dB at 89–179°). (The pre-warp refuses sooner by
/// itself, once the eye is behind the texture's plane.)
pub const MAX_SHOWN_TURN_DEG: f32 = 80.0;

/// The largest texel, in pixels across, that pull–push fills into a surface: past it
/// the splats are dots too sparse for the pyramid's coarse levels to join (at a 0.3°
/// field of view they covered 8 % of the object).
pub const PULLPUSH_MAX_TEXEL_PIXELS: f32 = 4.0;

/// A name [`Method::from_str`] does not know; the message lists the ones it does.
#[derive(Debug, Clone, PartialEq, Eq, thiserror::Error)]
#[error("unknown method `{name}` (choose one of: {known}; inverse-N, forward-kernel-K)")]
pub struct UnknownMethod {
    pub name: String,
    pub known: String,
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

impl Method {
    /// The pre-warp variant a pre-warp method uses; `None` for the others.
    pub fn variant(self) -> Option<Variant> {
        match self {
            Method::TwoPass1d => Some(Variant::OneD),
            Method::TwoPassAsym => Some(Variant::Asymmetric),
            Method::TwoPassComp => Some(Variant::Compensated),
            Method::Interleaved => Some(Variant::Interleaved),
            Method::ForwardPullPush | Method::ForwardKernel(_) | Method::Inverse(_) | Method::Sprite => None,
        }
    }
}

impl fmt::Display for Method {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        f.write_str(&self.name())
    }
}

impl FromStr for Method {
    type Err = UnknownMethod;

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
            UnknownMethod {
                name: s.to_string(),
                known: names.join(", "),
            }
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
) -> Result<(), DisplayError> {
    draw(
        prepare(method, impostor, camera)?,
        impostor,
        object,
        camera,
        gbuffer,
    )
}

/// The part of a display that does not touch the frame: the pre-warp of the pre-warp
/// methods (nothing for the others). Several impostors' can run at once, one per core,
/// before their [`draw`]s (see [`relief_render::warp`]).
pub fn prepare(method: Method, impostor: &Impostor, camera: &Camera) -> Result<Prepared, DisplayError> {
    if let Some(variant) = method.variant() {
        return Ok(Prepared::Prewarped(Box::new(Prewarped::new(
            variant, impostor, camera,
        )?)));
    }
    let fills = match method {
        Method::ForwardPullPush => Some(PULLPUSH_MAX_TEXEL_PIXELS),
        // (A k × k kernel gathers splats up to k − 1 pixels apart.)
        Method::ForwardKernel(k) => Some(k as f32),
        Method::Inverse(_) => None,
        _ => return Err(DisplayError::NeedsPreviousFrame),
    };
    let texture = &impostor.texture;
    if texture.camera.projection() == SourceProjection::Perspective {
        return Err(DisplayError::NeedsOrthographic { method });
    }
    let centre = volume_centre(&texture.camera);
    let turn_deg = (texture.eye - centre)
        .angle_between(camera.eye_f32() - centre)
        .to_degrees();
    if turn_deg > MAX_SHOWN_TURN_DEG {
        return Err(DisplayError::FarSide {
            turn_deg,
            max_deg: MAX_SHOWN_TURN_DEG,
        });
    }
    let pixels = texel_angle(&texture.camera, camera.eye_f32())
        / camera.pixel_angle_towards(volume_centre(&texture.camera));
    if let Some(fills) = fills
        && pixels > fills
    {
        return Err(DisplayError::TexelsTooLarge {
            method,
            pixels,
            fills,
        });
    }
    match method {
        Method::ForwardPullPush => Ok(Prepared::PullPush),
        Method::ForwardKernel(k) => Ok(Prepared::Kernel(k)),
        Method::Inverse(steps) => Ok(Prepared::Inverse(steps)),
        _ => Err(DisplayError::NeedsPreviousFrame),
    }
}

/// What [`prepare`] made, for [`draw`].
pub enum Prepared {
    /// The pre-warp methods' pre-warped image.
    Prewarped(Box<Prewarped>),
    PullPush,
    Kernel(u8),
    Inverse(u16),
}

impl Prepared {
    /// The display of an object whose frame is `scale` world metres per metre of its
    /// own ([`SceneObject::depth_scale`](relief_core::scene::SceneObject::depth_scale)):
    /// its depths stored in the world's metres, as the frame's other objects' are.
    pub fn in_world(self, method: Method, scale: f32) -> Result<Prepared, DisplayError> {
        match self {
            Prepared::Prewarped(p) => Ok(Prepared::Prewarped(Box::new(p.in_world(scale)?))),
            other if scale == 1.0 => Ok(other),
            _ => Err(DisplayError::ScaledFrame { method, scale }),
        }
    }

    /// Texels of `impostor` (the one prepared) this display visits: those a pre-warp
    /// reached the screen from, or all.
    pub fn texels_warped(&self, impostor: &Impostor) -> usize {
        match self {
            Prepared::Prewarped(prewarped) => prewarped.texels_warped(),
            _ => impostor.texture.depth.len(),
        }
    }
}

/// Finishes, into `gbuffer`, the display [`prepare`] began for the same impostor and
/// camera.
pub fn draw(
    prepared: Prepared,
    impostor: &Impostor,
    object: u32,
    camera: &Camera,
    gbuffer: &mut GBuffer,
) -> Result<(), DisplayError> {
    match prepared {
        Prepared::Prewarped(prewarped) => {
            prewarped.draw(impostor, object, camera, gbuffer);
            Ok(())
        }
        Prepared::PullPush => Ok(forward::display(impostor, object, camera, gbuffer)?),
        Prepared::Kernel(k) => Ok(forward::display_kernel(
            impostor, k as usize, object, camera, gbuffer,
        )?),
        Prepared::Inverse(steps) => Ok(inverse::display(
            impostor,
            steps as usize,
            object,
            camera,
            gbuffer,
        )?),
    }
}
