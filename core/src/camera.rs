//! The perspective camera of a frame, and camera paths through a scene.

use std::f64::consts::{PI, TAU};

use crate::vector::{direction, direction_f64};
use glam::{DVec3, Vec3};
use serde::Deserialize;

/// Largest frame edge in pixels that any command accepts.
pub const MAX_FRAME_SIZE: u32 = 8192;

/// A pinhole camera: eye, orthonormal basis, vertical field of view and resolution.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Camera {
    /// Where the eye is, in the frame the camera is used in: the world's, or (made by
    /// [`Camera::relative_to`]) an object's own. In `f64` because the world's
    /// coordinates may be far too large for `f32` to place an eye to the millimetre.
    pub eye: DVec3,
    /// Unit view direction.
    pub forward: Vec3,
    /// Unit vector to the right of the image.
    pub right: Vec3,
    /// Unit vector to the top of the image.
    pub up: Vec3,
    /// Vertical field of view in radians.
    pub fov_y: f32,
    pub width: u32,
    pub height: u32,
}

/// The widest half-angle [`Camera::may_see_turned`] opens a side of the frustum to,
/// radians: short of a right angle, where the side's tangent is unbounded.
const MAX_WIDENED_HALF_ANGLE: f64 = 89.0 * std::f64::consts::PI / 180.0;

/// [`Camera::frustum_margins`] for a frustum of half-angle tangents `(tan_x, tan_y)`.
fn frustum_margins_of((tan_x, tan_y): (f64, f64), v: DVec3) -> [f64; 5] {
    [
        v.z * tan_x + v.x,
        v.z * tan_x - v.x,
        v.z * tan_y + v.y,
        v.z * tan_y - v.y,
        v.z,
    ]
}

/// A camera's projection from view space to pixels (see [`Camera::projection`]).
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Projection {
    x_scale: f32,
    y_scale: f32,
    half_width: f32,
    half_height: f32,
}

impl Projection {
    /// As [`Camera::view_to_pixel`].
    #[inline]
    pub fn view_to_pixel(&self, v: Vec3) -> (f32, f32) {
        let inv_z = 1.0 / v.z;
        (
            (v.x * self.x_scale * inv_z + 1.0) * self.half_width,
            (1.0 - v.y * self.y_scale * inv_z) * self.half_height,
        )
    }
}

/// Why no camera can be made from the arguments given; each names the bad one.
#[derive(Debug, Clone, PartialEq, thiserror::Error)]
pub enum CameraError {
    #[error(transparent)]
    NotFinite(#[from] crate::vector::VectorError),
    #[error("field of view {0}° must be in (0, 180)")]
    FieldOfView(f32),
    #[error("frame size {width}x{height} must be between 1x1 and {MAX_FRAME_SIZE}x{MAX_FRAME_SIZE}")]
    FrameSize { width: u32, height: u32 },
    #[error("eye and target are too far apart ({0}): the view direction overflows")]
    TooFarApart(DVec3),
    #[error("eye and target coincide: no view direction")]
    EyeAtTarget,
    #[error(
        "eye and target are {distance} apart, too close for f64 at their distance from the origin: \
         the view direction could be off by {error_deg}° (at most {MAX_DIRECTION_ERROR_DEG}° is taken)"
    )]
    ImpreciseDirection { distance: f64, error_deg: f64 },
    #[error("up vector is zero or parallel to the view direction")]
    UpAlongView,
}

/// The most the view direction may be off (degrees) because eye and target are
/// rounded to f64: half a degree, a few pixels at common fields of view. Past it (an
/// eye a few steps of f64 from its target) the direction is noise: a one-step offset
/// pointed a camera straight away from what was meant, and drew an empty frame.
pub const MAX_DIRECTION_ERROR_DEG: f64 = 0.5;

/// A camera path segment that cannot be flown; the message names the field.
#[derive(Debug, Clone, PartialEq, thiserror::Error)]
pub enum PathError {
    #[error("a path segment needs 1 to {MAX_SEGMENT_FRAMES} frames")]
    Frames,
    #[error("orbit: center, radius (> 0), height and turns must be finite")]
    Orbit,
    #[error("fly: needs at least two points")]
    FlyTooFewPoints,
    #[error("fly: points and look_at must be finite")]
    FlyNotFinite,
    /// Points `first` and `first + 1` (counted from 1) are the same: a leg of length
    /// zero has no direction to look along.
    #[error("fly: points {first} and {} coincide", first + 1)]
    FlyPointsCoincide { first: usize },
}

impl Camera {
    /// A camera at `eye` looking at `target` (either in `f32` or `f64`). Errors name the
    /// bad argument.
    pub fn look_at(
        eye: impl Into<DVec3>,
        target: impl Into<DVec3>,
        up: Vec3,
        fov_y_degrees: f32,
        width: u32,
        height: u32,
    ) -> Result<Camera, CameraError> {
        let (eye, target) = (eye.into(), target.into());
        for (name, v) in [("eye", eye), ("target", target), ("up", up.as_dvec3())] {
            crate::vector::ensure_finite_f64(name, v)?;
        }
        if !(fov_y_degrees.is_finite() && fov_y_degrees > 0.0 && fov_y_degrees < 180.0) {
            return Err(CameraError::FieldOfView(fov_y_degrees));
        }
        if width == 0 || height == 0 || width > MAX_FRAME_SIZE || height > MAX_FRAME_SIZE {
            return Err(CameraError::FrameSize { width, height });
        }
        let offset = target - eye;
        if !offset.is_finite() {
            return Err(CameraError::TooFarApart(offset));
        }
        let forward = direction_f64(offset).ok_or(CameraError::EyeAtTarget)?;
        // Rounding the eye and the target to f64 moves each by up to half a step of
        // their size; seen over `offset`, that turns the view by up to this much.
        // (In units of that size: squared lengths of tiny or huge offsets under- or
        // overflow.)
        let size = eye.abs().max(target.abs()).max_element();
        let relative = (offset / size).length();
        let error_deg = (3f64.sqrt() * f64::EPSILON / relative).atan().to_degrees();
        if error_deg > MAX_DIRECTION_ERROR_DEG {
            return Err(CameraError::ImpreciseDirection {
                distance: offset.length(),
                error_deg,
            });
        }
        let right = direction(up)
            .and_then(|up| direction(forward.cross(up)))
            .ok_or(CameraError::UpAlongView)?;
        Ok(Camera {
            eye,
            forward,
            right,
            up: right.cross(forward),
            fov_y: fov_y_degrees.to_radians(),
            width,
            height,
        })
    }

    /// Unit direction of the ray through pixel position `(x, y)` (pixel centres at
    /// `+0.5`; y grows downwards).
    #[inline]
    pub fn ray_direction(&self, x: f32, y: f32) -> Vec3 {
        self.ray(x, y).normalize()
    }

    /// The direction of the ray through pixel position `(x, y)` scaled to a unit
    /// forward component: the point it reaches at view depth `d` is `eye + ray · d`.
    /// Linear in `x`, so row-wise writers step it by [`Camera::ray_x_step`].
    #[inline]
    pub fn ray(&self, x: f32, y: f32) -> Vec3 {
        let tan_half = self.tan_half_fov();
        let aspect = self.width as f32 / self.height as f32;
        let sx = (2.0 * x / self.width as f32 - 1.0) * tan_half * aspect;
        let sy = (1.0 - 2.0 * y / self.height as f32) * tan_half;
        self.forward + self.right * sx + self.up * sy
    }

    /// How [`Camera::ray`] changes from one pixel to the next along a row.
    #[inline]
    pub fn ray_x_step(&self) -> Vec3 {
        let aspect = self.width as f32 / self.height as f32;
        self.right * (2.0 / self.width as f32 * self.tan_half_fov() * aspect)
    }

    /// `tan(fov_y / 2)`.
    #[inline]
    pub fn tan_half_fov(&self) -> f32 {
        (self.fov_y * 0.5).tan()
    }

    /// The focal length in pixels: a length `l` across the view at depth `d` spans
    /// about `l · focal / d` pixels.
    #[inline]
    pub fn focal_pixels(&self) -> f32 {
        self.height as f32 / (2.0 * self.tan_half_fov())
    }

    /// Whether any of `bounds` can be on screen: false only when all of the box is
    /// behind the eye or beyond one side of the view (its eight corners all outside
    /// one of the frustum's side planes) — a box may pass and still show nothing, next
    /// to a corner of the frustum. Non-finite bounds pass.
    pub fn may_see(&self, bounds: &crate::bounds::Aabb) -> bool {
        self.may_see_within(bounds, self.half_tangents())
    }

    /// Whether any of `bounds` could be on screen with each side of the frustum opened
    /// by `margin` radians (short of a right angle; never narrower than the view):
    /// about whether a view turned by up to `margin` would show it — exactly so for a
    /// turn straight across a side, a little short of it past the corners.
    pub fn may_see_turned(&self, bounds: &crate::bounds::Aabb, margin: f32) -> bool {
        let (tan_x, tan_y) = self.half_tangents();
        let widen = |tan: f64| {
            let half = tan.atan();
            (half + f64::from(margin))
                .min(MAX_WIDENED_HALF_ANGLE)
                .max(half)
                .tan()
        };
        self.may_see_within(bounds, (widen(tan_x), widen(tan_y)))
    }

    /// [`Camera::may_see`] for a frustum of half-angle tangents `(tan_x, tan_y)`.
    fn may_see_within(&self, bounds: &crate::bounds::Aabb, tans: (f64, f64)) -> bool {
        let corners = bounds
            .corners()
            .map(|p| frustum_margins_of(tans, self.to_view(p).as_dvec3()));
        // (False for NaN: such a box passes.)
        !(0..5).any(|plane| corners.iter().all(|m| m[plane] < 0.0))
    }

    /// The tangents of the view's horizontal and vertical half-angles.
    fn half_tangents(&self) -> (f64, f64) {
        let tan_y = self.tan_half_fov() as f64;
        (tan_y * self.width as f64 / self.height as f64, tan_y)
    }

    /// How far the view-space point `v` lies inside each of the frustum's planes that
    /// pass through the eye, scaled (≥ 0 inside, < 0 outside): the four sides (`|x| ≤
    /// z·tan_x`, `|y| ≤ z·tan_y`, the screen's edges), then the plane facing forwards
    /// (`z ≥ 0`). In f64 for callers that need the bits.
    pub fn frustum_margins(&self, v: DVec3) -> [f64; 5] {
        frustum_margins_of(self.half_tangents(), v)
    }

    /// A copy of this camera with its eye measured from `origin`: the same view, in
    /// a frame whose origin lies at `origin` of this one (an object's own frame, in
    /// which its mesh and textures are given). The subtraction is in `f64`, so the
    /// eye keeps its precision however far both lie from this frame's origin.
    pub fn relative_to(&self, origin: DVec3) -> Camera {
        Camera {
            eye: self.eye - origin,
            ..*self
        }
    }

    /// The eye rounded to `f32`: for cameras in an object's frame ([`Camera::relative_to`]),
    /// where it is small enough.
    #[inline]
    pub fn eye_f32(&self) -> Vec3 {
        self.eye.as_vec3()
    }

    /// View-space coordinates `(right, up, forward)` of a point of the camera's frame;
    /// `forward` is the depth the z-buffer stores.
    #[inline]
    pub fn to_view(&self, p: Vec3) -> Vec3 {
        let d = (p.as_dvec3() - self.eye).as_vec3();
        Vec3::new(d.dot(self.right), d.dot(self.up), d.dot(self.forward))
    }

    /// Pixel position `(x, y)` (pixel centres at `+0.5`, y down) of a view-space point
    /// with positive depth. Inverse of [`Camera::ray_direction`].
    #[inline]
    pub fn view_to_pixel(&self, v: Vec3) -> (f32, f32) {
        self.projection().view_to_pixel(v)
    }

    /// [`Camera::view_to_pixel`]'s constants, worked out once for projecting many
    /// points (each call here costs a `tan`).
    pub fn projection(&self) -> Projection {
        let tan_half = self.tan_half_fov();
        let aspect = self.width as f32 / self.height as f32;
        Projection {
            x_scale: 1.0 / (tan_half * aspect),
            y_scale: 1.0 / tan_half,
            half_width: 0.5 * self.width as f32,
            half_height: 0.5 * self.height as f32,
        }
    }

    /// The point of the camera's frame at view depth `depth` on the ray through pixel
    /// position `(x, y)`.
    #[inline]
    pub fn unproject(&self, x: f32, y: f32, depth: f32) -> Vec3 {
        let d = self.ray_direction(x, y);
        (self.eye + (d * (depth / d.dot(self.forward))).as_dvec3()).as_vec3()
    }

    /// The angle one pixel subtends (Schaufler's β_screen): the view's height's angle
    /// over its pixels.
    pub fn pixel_angle(&self) -> f32 {
        self.fov_y / self.height as f32
    }

    /// The angle one pixel subtends, on average, where point `p` shows:
    /// [`Camera::pixel_angle`] times `(cos²θ)^`[`OFF_AXIS_POWER`], `θ` being `p`'s angle
    /// off the view's axis, at most the view's corner's. A flat frame spreads an angle
    /// over more pixels away from its centre: by `1/cos²θ` along the radius, `1/cosθ`
    /// across it. At the corner of a 60° 16:9 frame a texel one pixel wide at the centre
    /// covers 2.4 × 1.5 pixels. A point behind the eye, which may show anywhere when the
    /// view turns to it, takes the centre's.
    pub fn pixel_angle_towards(&self, p: Vec3) -> f32 {
        let aspect = self.width as f32 / self.height as f32;
        let corner_tan_squared = self.tan_half_fov().powi(2) * (1.0 + aspect * aspect);
        let corner_cos_squared = 1.0 / (1.0 + corner_tan_squared);
        let v = self.to_view(p);
        let cos_squared = if v.z > 0.0 {
            v.z * v.z / v.length_squared()
        } else {
            1.0
        };
        // (A point that is not finite: the centre's, or the corner's, `max` ignoring
        // NaN. Either is finite.)
        self.pixel_angle() * cos_squared.max(corner_cos_squared).min(1.0).powf(OFF_AXIS_POWER)
    }
}

/// The power of `cos²θ` that scales a pixel's angle `θ` off the view's axis
/// ([`Camera::pixel_angle_towards`]): ¾, the mean of the stretch along the radius (1)
/// and across it (½). Along the radius alone the demo warped 58 % more texels a frame
/// than at the centre's angle, at ¾ 37 %, its outlines about as close to the reference.
pub const OFF_AXIS_POWER: f32 = 0.75;

/// One leg of a camera path.
#[derive(Debug, Clone, PartialEq, Deserialize)]
#[serde(tag = "kind", rename_all = "lowercase", deny_unknown_fields)]
pub enum PathSegment {
    /// Circle `turns` times around `center` at `radius`, `height` above it, looking at it.
    Orbit {
        center: [f64; 3],
        radius: f64,
        height: f64,
        #[serde(default = "one")]
        turns: f64,
        frames: u32,
    },
    /// Fly through `points` in order (piecewise linear), looking along the path (its
    /// direction over about a second, so corners turn the view gradually), or at
    /// `look_at` when given.
    Fly {
        points: Vec<[f64; 3]>,
        #[serde(default)]
        look_at: Option<[f64; 3]>,
        frames: u32,
    },
}

fn one() -> f64 {
    1.0
}

/// Eye and target of one frame, in world coordinates (`f64`, as [`Camera::eye`]).
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Pose {
    pub eye: DVec3,
    pub target: DVec3,
}

impl Pose {
    /// The camera of this pose (world +y up). Errors name the bad argument.
    pub fn camera(&self, fov_y_degrees: f32, width: u32, height: u32) -> Result<Camera, CameraError> {
        Camera::look_at(self.eye, self.target, Vec3::Y, fov_y_degrees, width, height)
    }
}

/// The most frames one path segment may last (an hour at 30 fps; `--frames` is
/// capped alike).
pub const MAX_SEGMENT_FRAMES: u32 = 108_000;

/// A sequence of segments, sampled frame by frame.
#[derive(Debug, Clone, PartialEq, Default)]
pub struct CameraPath {
    pub segments: Vec<PathSegment>,
}

impl PathSegment {
    /// Frames the segment lasts.
    pub fn frames(&self) -> u32 {
        match self {
            PathSegment::Orbit { frames, .. } | PathSegment::Fly { frames, .. } => *frames,
        }
    }

    /// Checks the segment; the error names the field.
    pub fn validate(&self) -> Result<(), PathError> {
        let finite = |v: &[f64]| v.iter().all(|x| x.is_finite());
        if self.frames() == 0 || self.frames() > MAX_SEGMENT_FRAMES {
            return Err(PathError::Frames);
        }
        match self {
            PathSegment::Orbit {
                center,
                radius,
                height,
                turns,
                ..
            } => {
                if !finite(center) || !finite(&[*radius, *height, *turns]) || *radius <= 0.0 {
                    return Err(PathError::Orbit);
                }
            }
            PathSegment::Fly { points, look_at, .. } => {
                if points.len() < 2 {
                    return Err(PathError::FlyTooFewPoints);
                }
                if !points.iter().all(|p| finite(p)) || !look_at.is_none_or(|p| finite(&p)) {
                    return Err(PathError::FlyNotFinite);
                }
                // A leg of length zero has no direction to look along.
                if let Some(k) = points.windows(2).position(|w| w[0] == w[1]) {
                    return Err(PathError::FlyPointsCoincide { first: k + 1 });
                }
            }
        }
        Ok(())
    }

    /// Pose at `t` in `[0, 1]`.
    fn pose(&self, t: f64) -> Pose {
        match self {
            PathSegment::Orbit {
                center,
                radius,
                height,
                turns,
                ..
            } => {
                let c = DVec3::from_array(*center);
                let angle = t * turns * TAU;
                Pose {
                    eye: c + DVec3::new(angle.cos() * radius, *height, angle.sin() * radius),
                    target: c,
                }
            }
            PathSegment::Fly { points, look_at, .. } => {
                let at = |t: f64| {
                    let s = t.clamp(0.0, 1.0) * (points.len() - 1) as f64;
                    let i = (s.floor() as usize).min(points.len() - 2);
                    DVec3::from_array(points[i]).lerp(DVec3::from_array(points[i + 1]), s - i as f64)
                };
                let eye = at(t);
                let target = match look_at {
                    Some(p) => DVec3::from_array(*p),
                    None => {
                        // Along the path from where the eye was [`FLY_LOOK_FRAMES`] ago
                        // to where it will be as long after (each clamped to the ends):
                        // a corner turns the view over that time, not at once.
                        let window = FLY_LOOK_FRAMES / self.frames() as f64;
                        let along = (at(t + window) - at(t - window)).normalize_or_zero();
                        if along != DVec3::ZERO {
                            // (At least a metre, and more far from the origin: a
                            // target must not round back onto the eye.)
                            eye + along * (1.0 + eye.abs().max_element())
                        } else {
                            // (A leg that doubles straight back: look ahead.)
                            let ahead = at(t + 0.02);
                            if ahead.distance(eye) > 1e-6 {
                                ahead
                            } else {
                                eye + (eye - at(t - 0.02))
                            }
                        }
                    }
                };
                Pose { eye, target }
            }
        }
    }
}

impl CameraPath {
    /// Total frames over all segments.
    pub fn frame_count(&self) -> u32 {
        // (Saturating: many long segments must not wrap.)
        self.segments
            .iter()
            .fold(0u32, |total, s| total.saturating_add(s.frames()))
    }

    /// The pose of frame `frame` (clamped to the last frame).
    pub fn pose(&self, frame: u32) -> Option<Pose> {
        self.pose_at(frame as f64)
    }

    /// The pose at a fractional frame position, for a camera that follows the clock
    /// rather than the frame count (clamped to `0..=` the last frame; NaN counts as 0).
    pub fn pose_at(&self, frame: f64) -> Option<Pose> {
        let last = self.frame_count().checked_sub(1)? as f64;
        let mut rest = if frame.is_nan() {
            0.0
        } else {
            frame.clamp(0.0, last)
        };
        for (k, segment) in self.segments.iter().enumerate() {
            let n = segment.frames() as f64;
            if rest < n {
                let pose = segment.pose(rest / n);
                let turn = TURN_FRAMES.min(0.5 * n);
                return Some(match k.checked_sub(1) {
                    Some(before) if rest < turn => {
                        let s = rest / turn;
                        pose.turned_from(&self.segments[before].pose(1.0), s * s * (3.0 - 2.0 * s))
                    }
                    _ => pose,
                });
            }
            rest -= n;
        }
        None
    }
}

/// Frames over which the view turns from where one segment last looked to where the
/// next one looks: legs need not agree (an orbit looks at its centre, a fly-through
/// ahead), and a sudden turn of the whole view reads as a cut. (A second at 30 fps; at
/// most half the segment.)
const TURN_FRAMES: f64 = 30.0;

/// How far back and ahead along its path a fly-through looks, in frames: a second
/// either way at 30 fps, so the default path's sharpest corner (about 140°) turns the
/// view by at most 6° a frame (71° at once when it looked 4 frames ahead).
const FLY_LOOK_FRAMES: f64 = 30.0;

impl Pose {
    /// This pose with its view direction turned back towards `before`'s: `s = 0` looks
    /// the way `before` did, `s = 1` is this pose. The eye stays where it is.
    ///
    /// Heading (about world +y) and pitch turn each on their own: the shortest arc
    /// between two directions can pass straight up or down, where the camera's "up",
    /// world +y, turns the image over.
    fn turned_from(&self, before: &Pose, s: f64) -> Pose {
        let to = self.target - self.eye;
        let from = (before.target - before.eye).normalize_or_zero();
        let distance = to.length();
        if from == DVec3::ZERO || !distance.is_normal() {
            return *self;
        }
        let angles = |d: DVec3| (d.x.atan2(d.z), d.y.clamp(-1.0, 1.0).asin());
        let ((heading0, pitch0), (heading1, pitch1)) = (angles(from), angles(to / distance));
        // The shorter way round.
        let turn = (heading1 - heading0 + PI).rem_euclid(TAU) - PI;
        let (heading, pitch) = (heading0 + turn * s, pitch0 + (pitch1 - pitch0) * s);
        let direction = DVec3::new(
            heading.sin() * pitch.cos(),
            pitch.sin(),
            heading.cos() * pitch.cos(),
        );
        Pose {
            eye: self.eye,
            target: self.eye + direction * distance,
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    /// Off the view's axis a pixel subtends less: along the middle row, the ratio to the
    /// centre's is the mean (geometric) of what neighbouring pixels' rays measure along
    /// the row and across it, to 1 %; past the frame's corner, the corner's; behind the
    /// eye, the centre's.
    #[test]
    fn a_pixel_subtends_less_off_the_axis() {
        let camera = Camera::look_at(DVec3::ZERO, DVec3::Z, Vec3::Y, 60.0, 640, 360).unwrap();
        let angle = |(x0, y0): (f32, f32), (x1, y1): (f32, f32)| {
            camera
                .ray_direction(x0, y0)
                .angle_between(camera.ray_direction(x1, y1))
        };
        let measured = |x: f32| {
            let y = 180.0;
            (angle((x - 0.5, y), (x + 0.5, y)) * angle((x, y - 0.5), (x, y + 0.5))).sqrt()
        };
        for x in [320.0, 400.0, 500.0, 600.0, 639.5] {
            let p = camera.unproject(x, 180.0, 5.0);
            let got = camera.pixel_angle_towards(p) / camera.pixel_angle();
            let want = measured(x) / measured(320.0);
            assert!((got / want - 1.0).abs() < 0.01, "x {x}: {got} against {want}");
        }
        let corner = camera.pixel_angle_towards(camera.unproject(0.0, 0.0, 5.0));
        let far_aside = Vec3::new(100.0, 50.0, 1.0);
        assert!((camera.pixel_angle_towards(far_aside) / corner - 1.0).abs() < 1e-4);
        assert!(corner < 0.55 * camera.pixel_angle(), "{corner}");
        for behind in [
            Vec3::new(0.0, 0.0, -3.0),
            Vec3::new(40.0, 0.0, -3.0),
            Vec3::ZERO,
            Vec3::NAN,
        ] {
            assert_eq!(
                camera.pixel_angle_towards(behind),
                camera.pixel_angle(),
                "{behind}"
            );
        }
    }

    /// An eye a step of f64 from its target has no meaningful view direction and is
    /// refused, naming the precision; an eye a step of f32 from it (a millionth of a
    /// metre at a metre), eyes far from the origin looking at targets a millimetre
    /// away, and ordinary cameras, are taken.
    #[test]
    fn a_view_direction_below_f64_precision_is_refused() {
        let camera = |eye: DVec3, target: DVec3| Camera::look_at(eye, target, Vec3::Y, 40.0, 64, 64);
        let eye = DVec3::new(1.0, 1.0, 1.0);
        let one_step = DVec3::new(f64::from_bits(1.0f64.to_bits() + 1), 1.0, 1.0);
        let err = camera(eye, one_step).unwrap_err();
        assert!(matches!(err, CameraError::ImpreciseDirection { .. }), "{err}");
        assert!(err.to_string().contains("too close for f64"), "{err}");
        // Fifty steps at the scale of a millimetre: still noise.
        let tiny = DVec3::splat(1e-3);
        assert!(camera(tiny, tiny + DVec3::X * 1e-3 * f64::EPSILON * 50.0).is_err());
        // One step of f32 is fine now.
        let f32_step = DVec3::new(f32::from_bits(1.0f32.to_bits() + 1) as f64, 1.0, 1.0);
        assert!(camera(eye, f32_step).is_ok());
        // 10⁶ m from the origin, a target a millimetre away is fine (in f32 the two
        // would coincide); an ordinary camera too.
        let far = DVec3::new(1e6, 0.0, 0.0);
        let c = camera(far, far - DVec3::new(1e-3, 0.0, 0.0)).unwrap();
        assert_eq!(c.forward, -Vec3::X);
        assert!(camera(DVec3::new(0.0, 0.0, 5.0), DVec3::ZERO).is_ok());
    }

    /// Turned by up to a margin, the view sees a small box off each of its sides
    /// exactly when the box lies within that margin of the side (each side opened by
    /// the margin, whatever the screen's shape); a box behind the eye stays unseen, and
    /// a margin past a right angle opens no side past it.
    #[test]
    fn a_view_turned_by_a_margin_sees_what_lies_within_it_of_each_side() {
        use crate::bounds::Aabb;
        let camera = Camera::look_at(Vec3::ZERO, Vec3::Z, Vec3::Y, 60.0, 160, 90).unwrap();
        let half_y = 30f32.to_radians();
        let half_x = (half_y.tan() * 16.0 / 9.0).atan();
        // A box of about 0.1° at 10 m, `degrees` past a side, in the direction `side`
        // (±x or ±y) from the view's axis.
        let past = |side: Vec3, half: f32, degrees: f32| {
            let angle = half + degrees.to_radians();
            let centre = (Vec3::Z * angle.cos() + side * angle.sin()) * 10.0;
            Aabb {
                min: centre - Vec3::splat(0.01),
                max: centre + Vec3::splat(0.01),
            }
        };
        let margin = 20f32.to_radians();
        for (side, half) in [
            (Vec3::X, half_x),
            (-Vec3::X, half_x),
            (Vec3::Y, half_y),
            (-Vec3::Y, half_y),
        ] {
            assert!(!camera.may_see(&past(side, half, 1.0)), "{side}");
            assert!(camera.may_see_turned(&past(side, half, 19.0), margin), "{side}");
            assert!(!camera.may_see_turned(&past(side, half, 21.0), margin), "{side}");
        }
        let behind = Aabb {
            min: Vec3::new(-0.1, -0.1, -5.1),
            max: Vec3::new(0.1, 0.1, -4.9),
        };
        assert!(!camera.may_see_turned(&behind, margin));
        assert!(!camera.may_see_turned(&behind, 3.0));
        // … and each side opened to just short of a right angle: 80° off the axis is seen.
        for (side, half) in [(Vec3::X, half_x), (Vec3::Y, half_y)] {
            let off_axis = past(side, half, 80.0 - half.to_degrees());
            assert!(camera.may_see_turned(&off_axis, 3.0), "{side}");
        }
    }

    /// A box is seen when one of its points projects onto the screen in front of the
    /// eye (brute force over a grid of its points); boxes wholly behind, beside, above
    /// or below the view are not.
    #[test]
    fn a_box_is_seen_exactly_when_some_of_it_can_be_on_screen() {
        use crate::bounds::Aabb;
        let camera = Camera::look_at(Vec3::ZERO, Vec3::Z, Vec3::Y, 60.0, 160, 90).unwrap();
        let boxed = |centre: Vec3, half: f32| Aabb {
            min: centre - Vec3::splat(half),
            max: centre + Vec3::splat(half),
        };
        let projection = camera.projection();
        // (A grid of the box's points, made once: three nested constant loops here
        // took the optimiser minutes to unroll.)
        let grid: Vec<Vec3> = (0..9 * 9 * 9)
            .map(|n| Vec3::new((n % 9) as f32, (n / 9 % 9) as f32, (n / 81) as f32) / 8.0)
            .collect();
        let on_screen = |b: &Aabb| {
            grid.iter().any(|&t| {
                let v = camera.to_view(b.min + (b.max - b.min) * t);
                let (x, y) = projection.view_to_pixel(v);
                v.z > 0.0 && (0.0..=160.0).contains(&x) && (0.0..=90.0).contains(&y)
            })
        };
        let (mut seen, mut unseen) = (0, 0);
        for x in -12..=12 {
            for y in -6..=6 {
                for z in -3..=12 {
                    let b = boxed(Vec3::new(x as f32, y as f32, z as f32), 0.3);
                    if on_screen(&b) {
                        assert!(camera.may_see(&b), "{b:?} is on screen");
                        seen += 1;
                    } else {
                        unseen += usize::from(!camera.may_see(&b));
                    }
                }
            }
        }
        // (Measured when written: 1,701 seen, and all 3,499 others told unseen.)
        assert!(seen > 1500 && unseen > 3300, "{seen} seen, {unseen} told unseen");
        // Behind, far to one side, above: not seen. Around the eye: seen.
        for centre in [
            Vec3::new(0.0, 0.0, -5.0),
            Vec3::new(50.0, 0.0, 5.0),
            Vec3::new(0.0, 20.0, 5.0),
        ] {
            assert!(!camera.may_see(&boxed(centre, 1.0)), "{centre}");
        }
        // A wide box just behind the eye: only the plane through the eye facing
        // forwards leaves it out (its corners lie on both sides of every other).
        let wide_behind = Aabb {
            min: Vec3::new(-10.0, -10.0, -2.0),
            max: Vec3::new(10.0, 10.0, -1.0),
        };
        assert!(!camera.may_see(&wide_behind));
        assert!(camera.may_see(&boxed(Vec3::ZERO, 1.0)));
        assert!(camera.may_see(&boxed(Vec3::splat(f32::NAN), 1.0)));
    }

    /// Where one segment ends looking elsewhere than the next begins (an orbit at its
    /// centre, a fly-through ahead), the view turns over a few frames, not at once;
    /// elsewhere the poses are the segments' own.
    #[test]
    fn the_view_turns_smoothly_between_segments() {
        // An orbit round the origin, 5 m out, `height` up, ending at (5, height, 0);
        // then a fly from there to `to`, looking ahead.
        let orbit_then_fly = |height: f64, to: [f64; 3]| {
            let orbit = PathSegment::Orbit {
                center: [0.0; 3],
                radius: 5.0,
                height,
                turns: 1.0,
                frames: 120,
            };
            let fly = PathSegment::Fly {
                points: vec![[5.0, height, 0.0], to],
                look_at: None,
                frames: 60,
            };
            (
                CameraPath {
                    segments: vec![orbit.clone(), fly.clone()],
                },
                orbit,
                fly,
            )
        };
        let direction = |p: Pose| (p.target - p.eye).normalize();
        let largest = |path: &CameraPath| {
            (1..path.frame_count())
                .map(|f| {
                    let [a, b] = [f - 1, f].map(|f| direction(path.pose(f).unwrap()));
                    a.angle_between(b).to_degrees()
                })
                .fold(0.0, f64::max)
        };
        // The orbit ends heading +z: fly on that way.
        let (path, orbit, fly) = orbit_then_fly(1.0, [5.0, 1.0, 10.0]);
        let jump = direction(orbit.pose(1.0))
            .angle_between(direction(fly.pose(0.0)))
            .to_degrees();
        assert!(jump > 89.9, "{jump}");
        // 90°+ over 30 frames, smoothstep's steepest slope 1.5: about 5° a frame.
        assert!(largest(&path) < 6.0, "{}°", largest(&path));
        assert_eq!(path.pose(120 + 30), Some(fly.pose(30.0 / 60.0)));
        assert_eq!(path.pose(30), Some(orbit.pose(30.0 / 120.0)));
        // An orbit looking down at its centre, then a fly straight outwards: the view
        // turns 149° and must not pass through straight down, where the image's "up"
        // (the camera's right, by world +y) would turn over between two frames.
        let (path, ..) = orbit_then_fly(3.0, [25.0, 3.0, 0.0]);
        let right = |f: u32| {
            let pose = path.pose(f).unwrap();
            pose.camera(60.0, 64, 48).unwrap().right
        };
        for f in 1..path.frame_count() {
            assert!(
                right(f - 1).dot(right(f)) > 0.95,
                "the image turns over at frame {f}"
            );
        }
        // (Its heading turns 180° in a second: at most about 9° a frame.)
        assert!(largest(&path) < 10.0, "{}°", largest(&path));
        // The default path, its fly-through's corners included.
        let default = crate::scene::Scene::load("default").unwrap().path;
        assert!(largest(&default) < 7.0, "default path: {}°", largest(&default));
    }

    #[test]
    fn look_at_rejects_bad_input() {
        let ok = Camera::look_at(Vec3::Z * 5.0, Vec3::ZERO, Vec3::Y, 60.0, 64, 48).unwrap();
        assert!(ok.ray_direction(32.0, 24.0).abs_diff_eq(-Vec3::Z, 1e-6));
        assert!(Camera::look_at(Vec3::ZERO, Vec3::ZERO, Vec3::Y, 60.0, 4, 4).is_err());
        // Projection inverts ray directions, and unprojection inverts both.
        let p = Vec3::new(0.7, -0.4, -2.0);
        let (x, y) = ok.view_to_pixel(ok.to_view(p));
        assert!(
            ok.ray_direction(x, y)
                .abs_diff_eq((p - ok.eye_f32()).normalize(), 1e-5)
        );
        assert!(ok.unproject(x, y, ok.to_view(p).z).abs_diff_eq(p, 1e-4));
        assert!(Camera::look_at(Vec3::Y, Vec3::ZERO, Vec3::Y, 60.0, 4, 4).is_err());
        assert!(Camera::look_at(Vec3::Z, Vec3::ZERO, Vec3::Y, 180.0, 4, 4).is_err());
        assert!(Camera::look_at(Vec3::Z, Vec3::ZERO, Vec3::Y, 60.0, 0, 4).is_err());
        assert!(Camera::look_at(Vec3::NAN, Vec3::ZERO, Vec3::Y, 60.0, 4, 4).is_err());
        // Far beyond where squared lengths overflow (1.8e19), the direction is still
        // found; and a huge or tiny up vector is only a direction.
        let far = Camera::look_at(Vec3::new(0.0, 1e20, 1e20), Vec3::ZERO, Vec3::Y * 1e30, 60.0, 4, 4)
            .expect("a far eye has a view direction");
        assert!(
            far.forward
                .abs_diff_eq(Vec3::new(0.0, -1.0, -1.0).normalize(), 1e-6)
        );
        assert!(Camera::look_at(Vec3::Z * 1e-30, Vec3::ZERO, Vec3::Y * 1e-30, 60.0, 4, 4).is_ok());
        // Eye and target on opposite ends of the float range: the offset overflows.
        let err = Camera::look_at(DVec3::X * 1e308, DVec3::X * -1e308, Vec3::Y, 60.0, 4, 4)
            .unwrap_err()
            .to_string();
        assert!(err.contains("too far apart"), "{err}");
    }

    #[test]
    fn path_samples_orbit_then_fly() {
        let path = CameraPath {
            segments: vec![
                PathSegment::Orbit {
                    center: [0.0; 3],
                    radius: 2.0,
                    height: 1.0,
                    turns: 1.0,
                    frames: 4,
                },
                PathSegment::Fly {
                    points: vec![[0.0, 0.0, 0.0], [4.0, 0.0, 0.0]],
                    look_at: None,
                    frames: 4,
                },
            ],
        };
        assert_eq!(path.frame_count(), 8);
        let p0 = path.pose(0).unwrap();
        assert!(p0.eye.abs_diff_eq(DVec3::new(2.0, 1.0, 0.0), 1e-12));
        let p5 = path.pose(5).unwrap();
        assert!(p5.eye.abs_diff_eq(DVec3::new(1.0, 0.0, 0.0), 1e-12));
        // (Past the turn from the orbit's view: looking along the fly.)
        let p6 = path.pose(6).unwrap();
        assert!(p6.target.x > p6.eye.x);
        assert_eq!(path.pose(100), path.pose(7));
        assert_eq!(CameraPath::default().pose(0), None);
    }

    #[test]
    fn fly_paths_with_a_zero_leg_are_refused() {
        let fly = |points: Vec<[f64; 3]>, look_at| PathSegment::Fly {
            points,
            look_at,
            frames: 4,
        };
        let stay = fly(vec![[0.0; 3], [0.0; 3], [1.0, 0.0, 0.0]], None);
        assert!(
            stay.validate()
                .unwrap_err()
                .to_string()
                .contains("points 1 and 2")
        );
        // Flying to a point while looking at it is fine: the eye never reaches it.
        let towards = fly(vec![[0.0; 3], [1.0, 0.0, 0.0]], Some([1.0, 0.0, 0.0]));
        assert!(towards.validate().is_ok());
    }
}
