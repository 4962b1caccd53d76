//! The relief texture: an image with per-texel albedo, normal and depth.
//!
//! A texture, its camera and its eye are given in its object's own frame (see
//! [`SceneObject`](crate::scene::SceneObject)), never in the world's.
//!
//! # Source camera and depth mapping (the one place it is defined)
//!
//! A texture of `width × height` texels is seen by a [`SourceCamera`]
//! `(origin, a, b, f)`: `a` and `b` are the texel steps along the image's x (i) and y (j)
//! axes, `f = a×b/|a×b|` the unit viewing direction, pointing away from the eye the
//! texture was made for. The image plane passes through `origin`, and a texel coordinate
//! `(u, v)` (texel `i` has its centre at `u = i + 0.5`) is the plane point
//! `Q = origin + u·a + v·b`. A texel's displacement `t` is its surface point's distance
//! beyond that plane, along `f`:
//!
//! ```text
//! t = depth_near + q / q_max · (depth_far − depth_near)
//! ```
//!
//! where `q` is the stored depth level: `0 ..= q_max`, `q_max = 254` for 8-bit depth and
//! `65534` for 16-bit; the next value (255 or 65535) marks an empty texel. Levels are
//! rounded to nearest, so a decoded depth is within half a quantum of the surface. A
//! texel on the object's outline holds the depth a little further out towards it, where
//! its surface meets the outline, not its centre ray's (the bake's rim rays:
//! `relief_trace::rim`).
//!
//! The surface point of `(u, v, t)` depends on the [`SourceProjection`]:
//!
//! ```text
//! orthographic:  Q + t·f                       (every texel's ray along f)
//! perspective:   C + (Q − C)·(h + t)/h          (rays from the centre C, h = (origin − C)·f)
//! ```
//!
//! The orthographic texture is the thesis's (ch. 2.4): its rays are parallel, so what
//! the eye sees at the sides of an object, above or below it, is seen edge-on or not
//! at all. The perspective texture is seen from the eye itself, so at that eye it holds
//! exactly what the eye sees; its pre-warp keeps eq. 3-1's form (see the render crate's
//! `warp::params`).
//!
//! On disk (`relief bake --out DIR`): `albedo.png` (RGB8), `normal.png` (RGB8, the
//! normal `n·0.5 + 0.5`), `depth.png` (Gray8 or Gray16) and `texture.json`
//! ([`TextureMeta`]). PNG pixel `(x, y)` is texel `(i = x, j = y)`.

use std::path::Path;

use glam::Vec3;
use serde::{Deserialize, Serialize};

use crate::bounds::Aabb;
use crate::error::{Error, Result};

/// Largest relief-texture edge, in texels, that any command accepts.
pub const MAX_TEXTURE_SIZE: u32 = 4096;

/// Precision of stored depth.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash)]
pub enum DepthBits {
    Eight,
    Sixteen,
}

impl DepthBits {
    /// From a bit count (8 or 16).
    pub fn from_bits(bits: u32) -> Result<Self> {
        match bits {
            8 => Ok(DepthBits::Eight),
            16 => Ok(DepthBits::Sixteen),
            _ => Err(Error::Invalid(format!("depth bits must be 8 or 16, got {bits}"))),
        }
    }

    pub fn bits(self) -> u32 {
        match self {
            DepthBits::Eight => 8,
            DepthBits::Sixteen => 16,
        }
    }

    /// The deepest level, `q_max` (254 or 65534).
    pub fn max_level(self) -> u16 {
        self.empty() - 1
    }

    /// The level that marks an empty texel (255 or 65535).
    pub fn empty(self) -> u16 {
        match self {
            DepthBits::Eight => 255,
            DepthBits::Sixteen => 65535,
        }
    }
}

/// How a relief texture's rays leave its image plane (see the module docs).
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash, Default)]
pub enum SourceProjection {
    /// All rays along `f`: the thesis's relief texture.
    #[default]
    Orthographic,
    /// Rays from the eye the texture was made for: what that eye sees.
    Perspective,
}

/// The camera of a relief texture (see the module docs for the mapping).
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct SourceCamera {
    pub width: u32,
    pub height: u32,
    pub origin: Vec3,
    pub a: Vec3,
    pub b: Vec3,
    pub f: Vec3,
    pub depth_near: f32,
    pub depth_far: f32,
    /// The centre of projection of a perspective texture; `None` for an orthographic
    /// one. It lies in front of the image plane: `(origin − centre)·f > 0`.
    pub centre: Option<Vec3>,
}

/// The widest a perspective texture may see an object: the tangent of the largest
/// angle between its axis `f` and a ray to the object's bounds (60°). Nearer, the
/// bounds' projection grows without limit and the texels at its edge stretch; such an
/// eye is as good as inside the object, where it is drawn as geometry.
pub const MAX_PERSPECTIVE_TANGENT: f32 = 1.732;

/// Why no source camera can be made for an eye.
#[derive(Debug, Clone, PartialEq, thiserror::Error)]
pub enum FacingError {
    #[error("the eye is inside the object's bounds: draw the object as geometry")]
    EyeInsideBounds,
    /// The object's bounds reach wider than [`MAX_PERSPECTIVE_TANGENT`] around the
    /// eye's view of them (or behind it): no perspective texture.
    #[error("the eye is too near the object's bounds for a perspective texture: draw the object as geometry")]
    EyeTooNear,
    #[error("relief texture size {0}x{1} must be between 1 and {MAX_TEXTURE_SIZE}")]
    BadSize(u32, u32),
    #[error("the eye {0} is not finite")]
    NonFiniteEye(Vec3),
    #[error("the object's bounds are empty or not finite")]
    BadBounds,
    /// Eye or object so large (or the object so small) that the texture's camera is
    /// out of `f32`'s range.
    #[error("the eye {0} or the object's bounds are out of range: the texture's camera over- or underflows")]
    OutOfRange(Vec3),
}

impl SourceCamera {
    /// The source camera of a relief texture of the object with `bounds`, made for
    /// `eye` with `projection`: looking from the eye towards the bounds' centre, its
    /// image plane at the near face of the bounds (the plane through the corner nearest
    /// the eye, square to `f`) and its `width × height` texels spanning the bounds'
    /// projection exactly — along `f`, or from the eye.
    pub fn facing(
        eye: Vec3,
        bounds: &Aabb,
        width: u32,
        height: u32,
        projection: SourceProjection,
    ) -> Result<Self, FacingError> {
        if width == 0 || height == 0 || width > MAX_TEXTURE_SIZE || height > MAX_TEXTURE_SIZE {
            return Err(FacingError::BadSize(width, height));
        }
        if !eye.is_finite() {
            return Err(FacingError::NonFiniteEye(eye));
        }
        if bounds.is_empty() || !bounds.min.is_finite() || !bounds.max.is_finite() {
            return Err(FacingError::BadBounds);
        }
        if bounds.contains(eye) {
            return Err(FacingError::EyeInsideBounds);
        }
        let centre = bounds.center();
        // (An offset whose squared length over- or underflows — a far eye, a tiny
        // object — still has a direction; an eye at the centre is inside the bounds,
        // refused above.)
        let offset = centre - eye;
        let Some(f) = crate::vector::direction(offset) else {
            return Err(FacingError::OutOfRange(eye));
        };
        // Image "up" follows world +y unless the view is nearly vertical.
        let world_up = if f.y.abs() < 0.99 { Vec3::Y } else { Vec3::Z };
        let right = f.cross(world_up).normalize();
        let down = f.cross(right); // right × down = f, so a×b points along f.
        // The bounds' corners in the view axes, about the bounds' centre.
        let corners = bounds.corners().map(|corner| {
            let d = corner - centre;
            Vec3::new(d.dot(right), d.dot(down), d.dot(f))
        });
        if projection == SourceProjection::Perspective {
            return Self::perspective(eye, centre, (right, down, f), &corners, width, height);
        }
        let (mut lo, mut hi) = (Vec3::splat(f32::INFINITY), Vec3::splat(f32::NEG_INFINITY));
        for p in corners {
            lo = lo.min(p);
            hi = hi.max(p);
        }
        // A flat object seen edge-on projects to a line: keep every span positive.
        let min_span = (hi - lo).max_element().max(f32::MIN_POSITIVE) * 1e-4;
        for axis in 0..3 {
            if hi[axis] - lo[axis] < min_span {
                let mid = 0.5 * (hi[axis] + lo[axis]);
                lo[axis] = mid - 0.5 * min_span;
                hi[axis] = mid + 0.5 * min_span;
            }
        }
        let span = hi - lo;
        let camera = SourceCamera {
            width,
            height,
            origin: centre + right * lo.x + down * lo.y + f * lo.z,
            a: right * (span.x / width as f32),
            b: down * (span.y / height as f32),
            f,
            depth_near: 0.0,
            depth_far: span.z,
            centre: None,
        };
        camera.usable(eye)
    }

    /// [`SourceCamera::facing`] in perspective from `eye` (the centre of projection, on
    /// the axis through the bounds' `centre`), given the view axes and the bounds'
    /// corners in those axes about `centre`.
    fn perspective(
        eye: Vec3,
        centre: Vec3,
        (right, down, f): (Vec3, Vec3, Vec3),
        corners: &[Vec3; 8],
        width: u32,
        height: u32,
    ) -> Result<Self, FacingError> {
        // Corners relative to the eye: the eye lies on the axis through the centre, at
        // `distance` before it along `f`.
        let distance = (centre - eye).dot(f);
        let depth = |p: &Vec3| distance + p.z;
        let near = corners.iter().map(depth).fold(f32::INFINITY, f32::min);
        let far = corners.iter().map(depth).fold(f32::NEG_INFINITY, f32::max);
        // The plane through the nearest corner; its distance from the eye, `h`, is the
        // nearest corner's. At or behind the eye: too near.
        if near.is_nan() || near <= 0.0 {
            return Err(FacingError::EyeTooNear);
        }
        // The tangents of the rays to the corners: the box's projection is theirs.
        let (mut t_lo, mut t_hi) = (
            glam::Vec2::splat(f32::INFINITY),
            glam::Vec2::splat(f32::NEG_INFINITY),
        );
        for p in corners {
            let t = glam::Vec2::new(p.x, p.y) / depth(p);
            t_lo = t_lo.min(t);
            t_hi = t_hi.max(t);
        }
        if t_lo.min_element() < -MAX_PERSPECTIVE_TANGENT || t_hi.max_element() > MAX_PERSPECTIVE_TANGENT {
            return Err(FacingError::EyeTooNear);
        }
        let min_span = (t_hi - t_lo).max_element().max(f32::MIN_POSITIVE) * 1e-4;
        let span = (t_hi - t_lo).max(glam::Vec2::splat(min_span));
        let camera = SourceCamera {
            width,
            height,
            origin: eye + (f + right * t_lo.x + down * t_lo.y) * near,
            a: right * (span.x * near / width as f32),
            b: down * (span.y * near / height as f32),
            f,
            depth_near: 0.0,
            depth_far: (far - near).max(min_span * near),
            centre: Some(eye),
        };
        camera.usable(eye)
    }

    /// `Ok(self)` when every part of the camera is finite and its spans are normal
    /// numbers, else [`FacingError::OutOfRange`] naming `eye`.
    fn usable(self, eye: Vec3) -> Result<Self, FacingError> {
        let usable = self.origin.is_finite()
            && self.f.is_finite()
            && self.a.length_squared().is_normal()
            && self.b.length_squared().is_normal()
            && self.depth_far.is_normal()
            && self.centre_in_front();
        if usable {
            Ok(self)
        } else {
            Err(FacingError::OutOfRange(eye))
        }
    }

    /// Whether a perspective texture's centre of projection lies in front of its image
    /// plane, at a normal distance (always, for an orthographic texture): the mapping
    /// divides by that distance.
    pub fn centre_in_front(&self) -> bool {
        self.centre_distance().is_none_or(|h| h.is_normal() && h > 0.0)
    }

    /// The projection its rays follow: perspective when it has a centre.
    pub fn projection(&self) -> SourceProjection {
        match self.centre {
            Some(_) => SourceProjection::Perspective,
            None => SourceProjection::Orthographic,
        }
    }

    /// The distance `h` of a perspective texture's centre of projection in front of its
    /// image plane; `None` for an orthographic texture.
    #[inline]
    pub fn centre_distance(&self) -> Option<f32> {
        self.centre.map(|c| (self.origin - c).dot(self.f))
    }

    /// The world point of texel coordinate `(u, v)` (texel centres at `i + 0.5`) at
    /// displacement `t` (see the module docs).
    #[inline]
    pub fn point(&self, u: f32, v: f32, t: f32) -> Vec3 {
        let q = self.origin + self.a * u + self.b * v;
        q + self.ray_direction(q) * t
    }

    /// The direction of the ray through plane point `q`, scaled to 1 along `f`: `f`
    /// itself, or from the centre `C`, `(q − C)/h` (so `C + (q − C)·(h + t)/h` is
    /// `q + t·(q − C)/h`).
    #[inline]
    fn ray_direction(&self, q: Vec3) -> Vec3 {
        match self.centre {
            None => self.f,
            Some(c) => (q - c) / (self.origin - c).dot(self.f),
        }
    }

    /// The larger side of a texel at displacement `t`: `|a|` and `|b|` at the plane,
    /// growing with the distance from a perspective texture's centre.
    pub fn texel_size_at(&self, t: f32) -> f32 {
        let at_plane = self.a.length().max(self.b.length());
        match self.centre_distance() {
            None => at_plane,
            Some(h) => at_plane * (h + t) / h,
        }
    }

    /// The centre of the image plane (`t = 0`).
    pub fn plane_centre(&self) -> Vec3 {
        self.origin + self.a * (self.width as f32 * 0.5) + self.b * (self.height as f32 * 0.5)
    }

    /// The point where texel `(i, j)`'s ray crosses the image plane (`t = 0`).
    #[inline]
    pub fn texel_origin(&self, i: u32, j: u32) -> Vec3 {
        self.origin + self.a * (i as f32 + 0.5) + self.b * (j as f32 + 0.5)
    }

    /// Depth `t` of a stored level `q` (not the empty level).
    #[inline]
    pub fn depth_of_level(&self, q: u16, bits: DepthBits) -> f32 {
        self.depth_near + q as f32 / bits.max_level() as f32 * (self.depth_far - self.depth_near)
    }

    /// The level nearest depth `t`, clamped to `0 ..= q_max`.
    #[inline]
    pub fn level_of_depth(&self, t: f32, bits: DepthBits) -> u16 {
        let span = self.depth_far - self.depth_near;
        let x = ((t - self.depth_near) / span).clamp(0.0, 1.0);
        (x * bits.max_level() as f32 + 0.5) as u16
    }

    /// One depth quantum in world units.
    pub fn depth_quantum(&self, bits: DepthBits) -> f32 {
        (self.depth_far - self.depth_near) / bits.max_level() as f32
    }
}

/// A relief texture: source camera plus the albedo, normal and depth planes (row-major,
/// `j * width + i`).
#[derive(Debug, Clone, PartialEq)]
pub struct ReliefTexture {
    pub camera: SourceCamera,
    pub depth_bits: DepthBits,
    /// The eye the texture was made for.
    pub eye: Vec3,
    /// Linear albedo quantised to 8 bits.
    pub albedo: Vec<[u8; 3]>,
    /// Unit normals, in the object's frame as the rest of the texture, encoded
    /// `n·0.5 + 0.5` to 8 bits.
    pub normal: Vec<[u8; 3]>,
    /// Depth levels; `depth_bits.empty()` marks an empty texel.
    pub depth: Vec<u16>,
    /// What the texture's rim hides, and the outlines its steps hide ([`Hidden`]), in
    /// [`Hidden::key`] order. Empty where nothing was looked for: a texture's coarser
    /// levels, a perspective texture or one of sheets, one read from disk without it
    /// (and a rim's entries, for one whose larger edge is under 64 texels: see
    /// `relief_trace::hidden`).
    pub hidden: Vec<Hidden>,
}

/// What is wrong with a texture's [`ReliefTexture::hidden`].
#[derive(Debug, Clone, PartialEq, thiserror::Error)]
pub enum HiddenError {
    #[error("hidden[{index}]: texel {texel} does not come after the one before")]
    Unordered { index: usize, texel: u32 },
    #[error("hidden[{index}]: texel {texel} is past the texture's last")]
    PastTheEnd { index: usize, texel: u32 },
    #[error("hidden[{index}]: texel {texel} is empty")]
    Empty { index: usize, texel: u32 },
    #[error("hidden[{index}]: depth level {depth} is not behind the texel's own ({own})")]
    NotBehind { index: usize, depth: u16, own: u16 },
    #[error("hidden[{index}]: {depth} is not a depth level of the texture")]
    NotALevel { index: usize, depth: u16 },
    #[error("hidden[{index}]: side {side} is not one of a texel's four")]
    NoSuchSide { index: usize, side: u8 },
    #[error("hidden[{index}]: {inward} texels in from its texel is outside the texture")]
    Outside { index: usize, inward: u8 },
}

/// Whether `hidden` is well formed for a `width`-texel-wide texture of depth levels
/// `depth` (in `bits`): in increasing [`Hidden::key`] order, each texel a covered one
/// of the texture, each side one of [`TEXEL_SIDES`], each step in from it inside the
/// texture, each depth a level behind the texel's own. (What is wrong with an entry is
/// told in that order.)
pub fn check_hidden(
    hidden: &[Hidden],
    width: u32,
    depth: &[u16],
    bits: DepthBits,
) -> std::result::Result<(), HiddenError> {
    let height = (depth.len() / width.max(1) as usize) as u32;
    let mut last = None;
    for (index, h) in hidden.iter().enumerate() {
        let texel = h.texel;
        if last.is_some_and(|last| h.key() <= last) {
            return Err(HiddenError::Unordered { index, texel });
        }
        last = Some(h.key());
        let Some(&own) = depth.get(texel as usize) else {
            return Err(HiddenError::PastTheEnd { index, texel });
        };
        if own == bits.empty() {
            return Err(HiddenError::Empty { index, texel });
        }
        if h.side as usize >= TEXEL_SIDES.len() {
            return Err(HiddenError::NoSuchSide { index, side: h.side });
        }
        if h.behind(width, height).is_none() {
            return Err(HiddenError::Outside {
                index,
                inward: h.inward,
            });
        }
        if h.depth > bits.max_level() {
            return Err(HiddenError::NotALevel {
                index,
                depth: h.depth,
            });
        }
        if h.depth <= own {
            return Err(HiddenError::NotBehind {
                index,
                depth: h.depth,
                own,
            });
        }
    }
    Ok(())
}

/// The four sides of a texel, as steps `(di, dj)` to its neighbour: left, right, up,
/// down. A rim texel's open sides and [`Hidden::side`] count in this order.
pub const TEXEL_SIDES: [(i32, i32); 4] = [(-1, 0), (1, 0), (0, -1), (0, 1)];

/// A surface a texture's rim hides: what a turn of the eye uncovers beside the rim,
/// which the texture's planes cannot show — the far legs of an animal seen from the
/// side, hidden behind the near ones. Found behind the texel [`Hidden::inward`] texels
/// in from a rim texel (covered, beside an uncovered neighbour on [`Hidden::side`]):
/// the nearest surface there that faces the texture's rays, behind the texel's own.
/// The client predicts how far a turn brings it out past the rim, as it predicts the
/// gap between two neighbours of very different depths
/// (`relief_render::validity::critical`).
///
/// An entry whose neighbour on [`Hidden::side`] is covered, by a surface deeper than the
/// texel's, is an outline instead: that deeper surface, seen past a step down, ends
/// behind the texel, [`Hidden::inward`] texels in at [`Hidden::depth`] the last of it
/// (the teapot's body behind its handle). The client's pre-warp fills the crack a turn
/// opens there from the deeper surface only up to it (`relief_render::impostor`'s
/// `Impostor::outlines`).
#[derive(Debug, Clone, Copy, PartialEq, Eq, Serialize, Deserialize)]
pub struct Hidden {
    /// The rim texel (or a step's near texel), `j * width + i`.
    pub texel: u32,
    /// The rim's open side ([`TEXEL_SIDES`] index): outwards (or the side of the
    /// step's deeper neighbour).
    pub side: u8,
    /// How many texels in from the texel (away from `side`) the hidden surface lies
    /// (or the last of the step's deeper surface before its outline).
    pub inward: u8,
    /// That surface's depth level (behind the texel's own).
    pub depth: u16,
}

impl Hidden {
    /// The order [`ReliefTexture::hidden`] is kept in: by texel, then side.
    pub fn key(&self) -> u64 {
        u64::from(self.texel) << 8 | u64::from(self.side)
    }

    /// The texel the hidden surface lies behind, `(i, j)`, in a texture `width` ×
    /// `height`; `None` when its steps in from the rim leave the texture.
    /// `None` too when the rim texel is not one of the texture's.
    pub fn behind(&self, width: u32, height: u32) -> Option<(u32, u32)> {
        let (di, dj) = *TEXEL_SIDES.get(self.side as usize)?;
        let (i, j) = (self.texel.checked_rem(width)?, self.texel / width);
        if j >= height {
            return None;
        }
        let step = |at: u32, d: i32| at.checked_add_signed(-d * i32::from(self.inward));
        let (i, j) = (step(i, di)?, step(j, dj)?);
        (i < width && j < height).then_some((i, j))
    }
}

/// Encodes a unit normal as RGB8 (`n·0.5 + 0.5`).
#[inline]
pub fn encode_normal_rgb8(n: Vec3) -> [u8; 3] {
    crate::shading::to_rgb8(n * 0.5 + Vec3::splat(0.5))
}

/// Decodes an RGB8 normal back to a unit vector.
#[inline]
pub fn decode_normal_rgb8(rgb: [u8; 3]) -> Vec3 {
    (Vec3::new(rgb[0] as f32, rgb[1] as f32, rgb[2] as f32) / 127.5 - Vec3::ONE).normalize_or_zero()
}

/// The `texture.json` sidecar of a relief texture on disk.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct TextureMeta {
    pub width: u32,
    pub height: u32,
    pub origin: [f64; 3],
    pub a: [f64; 3],
    pub b: [f64; 3],
    pub f: [f64; 3],
    pub depth_near: f64,
    pub depth_far: f64,
    pub depth_bits: u32,
    /// The depth level that marks an empty texel.
    pub empty: u32,
    /// The eye the texture was made for.
    pub eye: [f64; 3],
    /// A perspective texture's centre of projection; absent for an orthographic one.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub centre: Option<[f64; 3]>,
    /// [`ReliefTexture::hidden`]; absent when there is none.
    #[serde(default, skip_serializing_if = "Vec::is_empty")]
    pub hidden: Vec<Hidden>,
}

fn to_f64(v: Vec3) -> [f64; 3] {
    v.to_array().map(f64::from)
}

fn from_f64(v: [f64; 3]) -> Vec3 {
    Vec3::new(v[0] as f32, v[1] as f32, v[2] as f32)
}

impl ReliefTexture {
    /// A texture with every texel empty.
    pub fn empty(camera: SourceCamera, depth_bits: DepthBits, eye: Vec3) -> Self {
        let n = camera.width as usize * camera.height as usize;
        ReliefTexture {
            camera,
            depth_bits,
            eye,
            albedo: vec![[0; 3]; n],
            normal: vec![[0; 3]; n],
            depth: vec![depth_bits.empty(); n],
            hidden: Vec::new(),
        }
    }

    #[inline]
    pub fn index(&self, i: u32, j: u32) -> usize {
        j as usize * self.camera.width as usize + i as usize
    }

    /// The texel `hidden` lies behind (its index), if it is inside the texture and
    /// covered.
    pub fn covered_behind(&self, hidden: &Hidden) -> Option<usize> {
        let (i, j) = hidden.behind(self.camera.width, self.camera.height)?;
        (!self.is_empty_texel(i, j)).then(|| self.index(i, j))
    }

    /// Whether `hidden` is an outline behind a step down (see [`Hidden`]): its texel's
    /// neighbour on its side is covered, where a rim's lies empty or past the edge.
    pub fn is_outline(&self, hidden: &Hidden) -> bool {
        let (w, h) = (self.camera.width, self.camera.height);
        let Some(&(di, dj)) = TEXEL_SIDES.get(hidden.side as usize) else {
            return false;
        };
        let (i, j) = (hidden.texel % w.max(1), hidden.texel / w.max(1));
        match (i.checked_add_signed(di), j.checked_add_signed(dj)) {
            (Some(i2), Some(j2)) => i2 < w && j2 < h && !self.is_empty_texel(i2, j2),
            _ => false,
        }
    }

    /// True when texel `(i, j)` holds no surface.
    #[inline]
    pub fn is_empty_texel(&self, i: u32, j: u32) -> bool {
        self.depth[self.index(i, j)] == self.depth_bits.empty()
    }

    /// Number of texels that hold a surface.
    pub fn covered_texels(&self) -> usize {
        let empty = self.depth_bits.empty();
        self.depth.iter().filter(|&&q| q != empty).count()
    }

    /// The world point of texel `(i, j)`, or `None` when it is empty.
    pub fn world_point(&self, i: u32, j: u32) -> Option<Vec3> {
        let q = self.depth[self.index(i, j)];
        (q != self.depth_bits.empty()).then(|| {
            let t = self.camera.depth_of_level(q, self.depth_bits);
            self.camera.point(i as f32 + 0.5, j as f32 + 0.5, t)
        })
    }

    /// Whether [`ReliefTexture::hidden`] is well formed ([`check_hidden`]).
    pub fn check_hidden(&self) -> std::result::Result<(), HiddenError> {
        check_hidden(&self.hidden, self.camera.width, &self.depth, self.depth_bits)
    }

    /// The `texture.json` record.
    pub fn meta(&self) -> TextureMeta {
        let c = &self.camera;
        TextureMeta {
            width: c.width,
            height: c.height,
            origin: to_f64(c.origin),
            a: to_f64(c.a),
            b: to_f64(c.b),
            f: to_f64(c.f),
            depth_near: c.depth_near as f64,
            depth_far: c.depth_far as f64,
            depth_bits: self.depth_bits.bits(),
            empty: self.depth_bits.empty() as u32,
            eye: to_f64(self.eye),
            centre: c.centre.map(to_f64),
            hidden: self.hidden.clone(),
        }
    }

    /// Writes `albedo.png`, `normal.png`, `depth.png` and `texture.json` into `dir`
    /// (created if missing).
    pub fn write_dir(&self, dir: &Path) -> Result<()> {
        std::fs::create_dir_all(dir).map_err(|e| Error::io(dir, e))?;
        let (w, h) = (self.camera.width, self.camera.height);
        let save = |name: &str, result: image::ImageResult<()>| {
            result.map_err(|e| Error::io(dir.join(name), std::io::Error::other(e)))
        };
        let rgb = |plane: &[[u8; 3]]| plane.iter().flatten().copied().collect::<Vec<u8>>();
        save(
            "albedo.png",
            image::save_buffer(
                dir.join("albedo.png"),
                &rgb(&self.albedo),
                w,
                h,
                image::ColorType::Rgb8,
            ),
        )?;
        save(
            "normal.png",
            image::save_buffer(
                dir.join("normal.png"),
                &rgb(&self.normal),
                w,
                h,
                image::ColorType::Rgb8,
            ),
        )?;
        let depth_png = dir.join("depth.png");
        match self.depth_bits {
            DepthBits::Eight => {
                let bytes: Vec<u8> = self.depth.iter().map(|&q| q as u8).collect();
                save(
                    "depth.png",
                    image::save_buffer(&depth_png, &bytes, w, h, image::ColorType::L8),
                )?;
            }
            DepthBits::Sixteen => {
                let buffer: image::ImageBuffer<image::Luma<u16>, Vec<u16>> =
                    image::ImageBuffer::from_raw(w, h, self.depth.clone())
                        .ok_or_else(|| Error::Invalid("depth plane has the wrong size".into()))?;
                save("depth.png", buffer.save(&depth_png))?;
            }
        }
        let json = serde_json::to_string_pretty(&self.meta()).map_err(|e| Error::Invalid(e.to_string()))?;
        let json_path = dir.join("texture.json");
        std::fs::write(&json_path, json + "\n").map_err(|e| Error::io(json_path, e))
    }

    /// Reads a texture written by [`ReliefTexture::write_dir`]; errors name the file and
    /// the problem.
    pub fn read_dir(dir: &Path) -> Result<Self> {
        let json_path = dir.join("texture.json");
        let bad = |message: String| Error::Texture {
            path: dir.to_path_buf(),
            message,
        };
        let text = std::fs::read_to_string(&json_path).map_err(|e| Error::io(&json_path, e))?;
        let meta: TextureMeta = serde_json::from_str(&text).map_err(|e| bad(format!("texture.json: {e}")))?;
        let depth_bits = DepthBits::from_bits(meta.depth_bits).map_err(|e| bad(e.to_string()))?;
        let camera = SourceCamera {
            width: meta.width,
            height: meta.height,
            origin: from_f64(meta.origin),
            a: from_f64(meta.a),
            b: from_f64(meta.b),
            f: from_f64(meta.f),
            depth_near: meta.depth_near as f32,
            depth_far: meta.depth_far as f32,
            centre: meta.centre.map(from_f64),
        };
        let finite = [camera.origin, camera.a, camera.b, camera.f]
            .iter()
            .all(|v| v.is_finite())
            && camera.depth_near.is_finite()
            && camera.depth_far.is_finite();
        if !finite || camera.depth_far <= camera.depth_near {
            return Err(bad("texture.json holds non-finite or inverted values".into()));
        }
        if !camera.centre_in_front() {
            return Err(bad(
                "texture.json: the centre of projection is not in front of the image plane".into(),
            ));
        }
        let (w, h) = (meta.width, meta.height);
        if w == 0 || h == 0 || w > MAX_TEXTURE_SIZE || h > MAX_TEXTURE_SIZE {
            return Err(bad(format!("size {w}x{h} out of range")));
        }
        let open = |name: &str| {
            let image = image::open(dir.join(name)).map_err(|e| bad(format!("{name}: {e}")))?;
            if image.width() != w || image.height() != h {
                return Err(bad(format!(
                    "{name} is {}x{}, expected {w}x{h}",
                    image.width(),
                    image.height()
                )));
            }
            Ok(image)
        };
        let rgb = |name: &str| -> Result<Vec<[u8; 3]>> {
            Ok(open(name)?.to_rgb8().pixels().map(|p| p.0).collect())
        };
        let albedo = rgb("albedo.png")?;
        let normal = rgb("normal.png")?;
        let depth = match (depth_bits, open("depth.png")?) {
            (DepthBits::Eight, image::DynamicImage::ImageLuma8(d)) => {
                d.into_raw().into_iter().map(u16::from).collect()
            }
            (DepthBits::Sixteen, image::DynamicImage::ImageLuma16(d)) => d.into_raw(),
            (_, other) => {
                return Err(bad(format!(
                    "depth.png is {:?}, expected {}-bit grey",
                    other.color(),
                    depth_bits.bits()
                )));
            }
        };
        let texture = ReliefTexture {
            camera,
            depth_bits,
            eye: from_f64(meta.eye),
            albedo,
            normal,
            depth,
            hidden: meta.hidden,
        };
        texture
            .check_hidden()
            .map_err(|e| bad(format!("texture.json: {e}")))?;
        Ok(texture)
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn unit_box() -> Aabb {
        Aabb {
            min: Vec3::splat(-1.0),
            max: Vec3::splat(1.0),
        }
    }

    #[test]
    fn facing_camera_spans_the_bounds_and_faces_away_from_the_eye() {
        let eye = Vec3::new(3.0, 1.0, 4.0);
        let c = SourceCamera::facing(eye, &unit_box(), 64, 32, SourceProjection::Orthographic).unwrap();
        assert!(c.f.abs_diff_eq((-eye).normalize(), 1e-6));
        assert!(c.a.cross(c.b).normalize().abs_diff_eq(c.f, 1e-5));
        // Every corner projects inside the image and at depth within [near, far].
        for corner in unit_box().corners() {
            let d = corner - c.origin;
            let (u, v, t) = (
                d.dot(c.a) / c.a.length_squared(),
                d.dot(c.b) / c.b.length_squared(),
                d.dot(c.f),
            );
            assert!(
                (-1e-3..=64.001).contains(&u) && (-1e-3..=32.001).contains(&v),
                "{u} {v}"
            );
            assert!(t >= c.depth_near - 1e-5 && t <= c.depth_far + 1e-5);
        }
        assert_eq!(
            SourceCamera::facing(Vec3::ZERO, &unit_box(), 8, 8, SourceProjection::Orthographic),
            Err(FacingError::EyeInsideBounds)
        );
        assert!(SourceCamera::facing(eye, &unit_box(), 0, 8, SourceProjection::Orthographic).is_err());
        assert!(
            SourceCamera::facing(
                eye,
                &unit_box(),
                MAX_TEXTURE_SIZE + 1,
                8,
                SourceProjection::Orthographic
            )
            .is_err()
        );
        assert!(
            SourceCamera::facing(Vec3::INFINITY, &unit_box(), 8, 8, SourceProjection::Orthographic).is_err()
        );
        // Straight above: the up vector switches axis, no NaN.
        let top =
            SourceCamera::facing(Vec3::Y * 5.0, &unit_box(), 8, 8, SourceProjection::Orthographic).unwrap();
        assert!(top.a.is_finite() && top.b.is_finite());
        // A flat box seen edge-on keeps positive spans.
        let flat = Aabb {
            min: Vec3::new(-1.0, 0.0, -1.0),
            max: Vec3::new(1.0, 0.0, 1.0),
        };
        let edge_on =
            SourceCamera::facing(Vec3::X * 5.0, &flat, 8, 8, SourceProjection::Orthographic).unwrap();
        assert!(edge_on.b.length() > 0.0 && edge_on.depth_far > 0.0);
    }

    /// A perspective camera's rays start at the eye: every corner of the bounds lies on
    /// the ray of a texel coordinate inside the image at a displacement in range, and
    /// `point` walks along those rays.
    #[test]
    fn perspective_camera_sees_the_bounds_from_the_eye() {
        let eye = Vec3::new(3.0, 1.0, 4.0);
        let c = SourceCamera::facing(eye, &unit_box(), 64, 32, SourceProjection::Perspective).unwrap();
        assert_eq!(c.centre, Some(eye));
        assert!(c.f.abs_diff_eq((-eye).normalize(), 1e-6));
        let h = c.centre_distance().unwrap();
        let nearest = unit_box()
            .corners()
            .iter()
            .map(|&p| (p - eye).dot(c.f))
            .fold(f32::MAX, f32::min);
        assert!(
            (h - nearest).abs() < 1e-5,
            "the plane through the nearest corner: {h} {nearest}"
        );
        for corner in unit_box().corners() {
            // Where the ray from the eye to the corner crosses the plane, and how far
            // past the plane the corner is.
            let t = (corner - eye).dot(c.f) - h;
            let crossing = eye + (corner - eye) * (h / (h + t)) - c.origin;
            let (u, v) = (
                crossing.dot(c.a) / c.a.length_squared(),
                crossing.dot(c.b) / c.b.length_squared(),
            );
            assert!(
                (-1e-3..=64.001).contains(&u) && (-1e-3..=32.001).contains(&v),
                "{u} {v}"
            );
            assert!(t >= c.depth_near - 1e-5 && t <= c.depth_far + 1e-5, "{t}");
            assert!(
                c.point(u, v, t).abs_diff_eq(corner, 1e-4),
                "{:?} {corner}",
                c.point(u, v, t)
            );
        }
        // A texel's point moves along the ray from the centre, `t` its displacement
        // along `f`.
        let (start, further) = (c.point(10.5, 20.5, 0.0), c.point(10.5, 20.5, 0.7));
        assert!(((further - start).dot(c.f) - 0.7).abs() < 1e-5);
        assert!(
            (further - start)
                .normalize()
                .abs_diff_eq((start - eye).normalize(), 1e-5)
        );
        // Texels grow with the distance from the centre; an orthographic one does not.
        assert!((c.texel_size_at(h) - 2.0 * c.texel_size_at(0.0)).abs() < 1e-5);
        let parallel =
            SourceCamera::facing(eye, &unit_box(), 64, 32, SourceProjection::Orthographic).unwrap();
        assert_eq!(parallel.texel_size_at(5.0), parallel.texel_size_at(0.0));
        // Too near: the bounds reach past 60° around the axis, or behind the plane.
        let beside = Vec3::new(1.2, 0.0, 0.0);
        assert_eq!(
            SourceCamera::facing(beside, &unit_box(), 8, 8, SourceProjection::Perspective),
            Err(FacingError::EyeTooNear)
        );
        assert!(SourceCamera::facing(beside, &unit_box(), 8, 8, SourceProjection::Orthographic).is_ok());
    }

    #[test]
    fn depth_levels_round_trip_within_half_a_quantum() {
        let c =
            SourceCamera::facing(Vec3::Z * 5.0, &unit_box(), 4, 4, SourceProjection::Orthographic).unwrap();
        for bits in [DepthBits::Eight, DepthBits::Sixteen] {
            for k in 0..=100 {
                let t = c.depth_far * k as f32 / 100.0;
                let q = c.level_of_depth(t, bits);
                assert!(q <= bits.max_level());
                assert!((c.depth_of_level(q, bits) - t).abs() <= 0.5 * c.depth_quantum(bits) + 1e-6);
            }
        }
    }

    #[test]
    fn far_eyes_and_huge_objects_face_or_fail_clearly() {
        // An eye 1e20 away: its offset's squared length overflows f32, the direction
        // must not.
        let c = SourceCamera::facing(
            Vec3::new(-3.0, 1.0, 1e20),
            &unit_box(),
            4,
            4,
            SourceProjection::Orthographic,
        )
        .unwrap();
        assert!(c.f.abs_diff_eq(-Vec3::Z, 1e-6) && c.origin.is_finite(), "{c:?}");
        // Bounds of 1e30: the camera's spans overflow — an error, never NaN.
        let huge = Aabb {
            min: Vec3::splat(-1e38),
            max: Vec3::splat(1e38),
        };
        let err = SourceCamera::facing(
            Vec3::new(3e38, 3e38, 3e38),
            &huge,
            4,
            4,
            SourceProjection::Orthographic,
        )
        .unwrap_err();
        assert!(matches!(err, FacingError::OutOfRange(_)), "{err}");
        // A 10 nm object seen at 4096 texels still has a camera.
        let tiny = Aabb {
            min: Vec3::splat(-5e-9),
            max: Vec3::splat(5e-9),
        };
        let c = SourceCamera::facing(
            Vec3::new(0.0, 0.0, 1e-7),
            &tiny,
            4096,
            4096,
            SourceProjection::Orthographic,
        )
        .unwrap();
        assert!(c.a.length() > 0.0 && c.depth_far > 0.0, "{c:?}");
    }

    #[test]
    fn normals_encode_within_a_degree() {
        for n in [Vec3::X, -Vec3::Y, Vec3::new(0.3, -0.5, 0.8).normalize()] {
            assert!(decode_normal_rgb8(encode_normal_rgb8(n)).angle_between(n) < 1f32.to_radians());
        }
    }

    /// Where a hidden surface lies: steps in against its side, `None` off the texture
    /// (the rim texel's own row past the last, too) or for a side that is not one.
    #[test]
    fn a_hidden_surface_lies_in_from_its_rim_texel() {
        let at = |texel, side, inward| {
            Hidden {
                texel,
                side,
                inward,
                depth: 0,
            }
            .behind(6, 4)
        };
        // Texel 7 is (1, 1) of 6 × 4.
        assert_eq!(at(7, 0, 2), Some((3, 1)), "open to the left: in is to the right");
        assert_eq!(at(7, 1, 1), Some((0, 1)));
        assert_eq!(at(7, 2, 2), Some((1, 3)), "open upwards: in is down");
        assert_eq!(at(7, 3, 1), Some((1, 0)));
        assert_eq!(at(7, 1, 2), None, "past the left edge");
        assert_eq!(at(26, 3, 1), None, "the rim texel on a fifth row of four");
        assert_eq!(at(7, 4, 1), None, "a fifth side");
        let nowhere = Hidden {
            texel: 0,
            side: 0,
            inward: 0,
            depth: 0,
        };
        assert_eq!(nowhere.behind(0, 0), None, "no texture");
    }

    #[test]
    fn disk_round_trip() {
        let dir = crate::scratch::PrivateDir::new("relief-tex").unwrap();
        for (bits, projection) in [
            (DepthBits::Eight, SourceProjection::Orthographic),
            (DepthBits::Sixteen, SourceProjection::Perspective),
        ] {
            let c = SourceCamera::facing(Vec3::Z * 5.0, &unit_box(), 5, 3, projection).unwrap();
            let mut t = ReliefTexture::empty(c, bits, Vec3::Z * 5.0);
            t.depth[4] = 7;
            t.albedo[4] = [1, 2, 3];
            t.normal[4] = encode_normal_rgb8(Vec3::Z);
            t.hidden = vec![Hidden {
                texel: 4,
                side: 1,
                inward: 2,
                depth: 9,
            }];
            t.write_dir(&dir).unwrap();
            let back = ReliefTexture::read_dir(&dir).unwrap();
            assert_eq!(back, t);
        }
        // What the rim hides is checked against the planes read.
        let mut t = ReliefTexture::read_dir(&dir).unwrap();
        t.hidden[0].depth = 3;
        t.write_dir(&dir).unwrap();
        let e = ReliefTexture::read_dir(&dir).unwrap_err().to_string();
        assert!(e.contains("hidden[0]") && e.contains("not behind"), "{e}");
        std::fs::write(dir.join("texture.json"), "{").unwrap();
        assert!(
            ReliefTexture::read_dir(&dir)
                .unwrap_err()
                .to_string()
                .contains("texture.json")
        );
    }
}
