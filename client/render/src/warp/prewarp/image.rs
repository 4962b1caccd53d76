//! The pre-warped image ([`PrewarpImage`]): how far past the source quad it reaches
//! ([`extent`]), and the part of the source plane the screen sees ([`PlaneWindow`]),
//! with the texels that can land there ([`reaching`]).

use glam::{DVec3, Vec2};
use relief_core::camera::Camera;
use relief_core::relief::SourceCamera;

use super::PTexel;
use crate::impostor::SurfaceExtent;
use crate::warp::params::WarpParams;

/// The pre-warped image: texel `(x, y)` covers source-plane coordinates
/// `[u0 + x, u0 + x + 1) × [v0 + y, v0 + y + 1)`. It spans where the texels holding
/// surface can land (past the source quad towards the epipole, for a turned view), and
/// no farther than the quad's own landings.
#[derive(Debug, Clone, PartialEq)]
pub struct PrewarpImage {
    pub u0: i32,
    pub v0: i32,
    pub width: u32,
    pub height: u32,
    pub texels: Vec<PTexel>,
    /// Source texels visited: each row's occupied ones
    /// ([`Impostor::occupied`](crate::impostor::Impostor::occupied)), or those of them
    /// that can reach a [`PlaneWindow`].
    pub visited: usize,
}

impl PrewarpImage {
    /// The image of a pre-warp that lands nothing on the screen: one empty pixel.
    pub(super) fn nothing_seen() -> PrewarpImage {
        PrewarpImage {
            u0: 0,
            v0: 0,
            width: 1,
            height: 1,
            texels: vec![PTexel::EMPTY],
            visited: 0,
        }
    }

    /// The texel covering plane coordinates `(u, v)`, if inside.
    #[inline]
    pub fn at(&self, u: f32, v: f32) -> Option<&PTexel> {
        // (Saturating: a coordinate may be infinite, from a ray nearly parallel to
        // the plane.)
        let x = (u.floor() as i64).saturating_sub(self.u0 as i64);
        let y = (v.floor() as i64).saturating_sub(self.v0 as i64);
        if x < 0 || y < 0 || x >= self.width as i64 || y >= self.height as i64 {
            return None;
        }
        Some(&self.texels[y as usize * self.width as usize + x as usize])
    }
}

/// How far past the source quad (in quad sizes) the pre-warped image may reach.
const MAX_MARGIN: f32 = 1.0;

/// How far past the warped corners of its surface texels a pre-warped image reaches, in
/// its pixels: the texel centres land half a texel inside the corners and a run's ends
/// reach half a pixel past them ([`half_gap`](super::spans::half_gap)), so at 2 an empty pixel always lies
/// between what is written and the image's edge — whose outermost half texel the
/// texture mapping draws by a rule of its own (see `texmap::map`): it meets a surface
/// only where the bound by the quad put it.
const REACH_MARGIN: f32 = 2.0;

/// The range of pre-warped coordinates, `((u0, u1), (v0, v1))`: the rectangle of the
/// texels holding surface (`surface`) warped at its first and last table entries, and
/// [`REACH_MARGIN`] past it — for one entry the warp is affine in `(u, v)`, and for one
/// point monotonic in the entry, so these bound every landing — within the same of the
/// whole quad (`w` × `h` texels) at the table's ends, and `MAX_MARGIN` quads of the
/// quad. Bounded by the quad alone, the forest's images were 1.5–1.8 times what the
/// pre-warps filled, and clearing them took an eighth of their time.
pub(super) fn extent(
    params: &WarpParams,
    surface: &SurfaceExtent,
    w: f32,
    h: f32,
) -> ((i32, i32), (i32, i32)) {
    // The box of the rectangle `from`–`to` warped at entries `first` and `last`.
    let warped = |from: Vec2, to: Vec2, first: usize, last: usize| {
        let (mut lo, mut hi) = (Vec2::INFINITY, Vec2::NEG_INFINITY);
        for q in [first, last] {
            for (u, v) in [(from.x, from.y), (to.x, from.y), (from.x, to.y), (to.x, to.y)] {
                let p = params.warp(u, v, q);
                lo = lo.min(p);
                hi = hi.max(p);
            }
        }
        (lo, hi)
    };
    let last = params.scale.len().saturating_sub(1);
    // (The quad's bound takes in the quad itself.)
    let (quad_lo, quad_hi) = warped(Vec2::ZERO, Vec2::new(w, h), 0, last);
    let (quad_lo, quad_hi) = (quad_lo.min(Vec2::ZERO), quad_hi.max(Vec2::new(w, h)));
    let (columns, rows) = (&surface.columns, &surface.rows);
    let (lo, hi) = warped(
        Vec2::new(columns.start as f32, rows.start as f32),
        Vec2::new(columns.end as f32, rows.end as f32),
        usize::from(*surface.entries.start()).min(last),
        usize::from(*surface.entries.end()).min(last),
    );
    let size = Vec2::new(w, h);
    let (lo, hi) = (
        (lo - REACH_MARGIN).max(quad_lo).max(-MAX_MARGIN * size),
        (hi + REACH_MARGIN).min(quad_hi).min((1.0 + MAX_MARGIN) * size),
    );
    (
        (lo.x.floor() as i32, hi.x.ceil() as i32),
        (lo.y.floor() as i32, hi.y.ceil() as i32),
    )
}

/// A rectangle of the source plane, in texel coordinates: `u ∈ [u0, u1], v ∈ [v0, v1]`.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct PlaneWindow {
    pub u0: f32,
    pub v0: f32,
    pub u1: f32,
    pub v1: f32,
}

impl PlaneWindow {
    /// The part of the source plane of `c` that the screen of `camera` shows, as far
    /// as a pre-warped image can reach (one quad size past the quad, see
    /// `MAX_MARGIN`): that plane rectangle clipped to the camera's frustum, whose
    /// four side planes pass through the eye — exactly the plane points some pixel's
    /// ray crosses ahead of the eye — and the clipped polygon's bounding box. Empty
    /// (`u1 < u0`) when the screen shows none of it (or the input is NaN); `None` when
    /// a clipped corner is not finite (then nothing is left out).
    pub fn seen_by(camera: &Camera, c: &SourceCamera) -> Option<PlaneWindow> {
        // (In f64, the eye subtracted too: at large coordinates the points' offsets
        // from the eye lose f32 bits.)
        let origin = c.origin.as_dvec3() - camera.eye;
        let (a, b) = (c.a.as_dvec3(), c.b.as_dvec3());
        let (n, m) = (
            (c.width as f64) * MAX_MARGIN as f64,
            (c.height as f64) * MAX_MARGIN as f64,
        );
        let (w, h) = (c.width as f64, c.height as f64);
        let mut polygon = vec![(-n, -m), (w + n, -m), (w + n, h + m), (-n, h + m)];
        let axes = [camera.right, camera.up, camera.forward].map(|d| d.as_dvec3());
        let view = |(u, v): (f64, f64)| {
            let p = origin + a * u + b * v;
            DVec3::new(p.dot(axes[0]), p.dot(axes[1]), p.dot(axes[2]))
        };
        // Clipped by the four side planes (through the eye, so the plane facing
        // forwards adds nothing).
        for side in 0..4 {
            let inside = |q: (f64, f64)| camera.frustum_margins(view(q))[side];
            let mut clipped = Vec::with_capacity(polygon.len() + 1);
            for (k, &p) in polygon.iter().enumerate() {
                let q = polygon[(k + 1) % polygon.len()];
                let (gp, gq) = (inside(p), inside(q));
                if gp >= 0.0 {
                    clipped.push(p);
                }
                if (gp >= 0.0) != (gq >= 0.0) {
                    let t = gp / (gp - gq);
                    clipped.push((p.0 + (q.0 - p.0) * t, p.1 + (q.1 - p.1) * t));
                }
            }
            polygon = clipped;
        }
        let mut window = PlaneWindow {
            u0: f32::INFINITY,
            v0: f32::INFINITY,
            u1: f32::NEG_INFINITY,
            v1: f32::NEG_INFINITY,
        };
        for (u, v) in polygon {
            if !(u.is_finite() && v.is_finite()) {
                return None;
            }
            window = PlaneWindow {
                u0: window.u0.min(u as f32),
                v0: window.v0.min(v as f32),
                u1: window.u1.max(u as f32),
                v1: window.v1.max(v as f32),
            };
        }
        Some(window)
    }
}

/// How far (in texels) the pre-warped image reaches past a [`PlaneWindow`]: the
/// texture mapping's bilinear footprint of a pixel at the window's edge lies within
/// it, so the pixels it reads are those it would read in the whole image.
pub(super) const WINDOW_MARGIN: i32 = 2;

/// The cells of `cells` — one half of an axis, before the epipole `e` (`before`) or
/// after it — whose texels can land within `[lo, hi]`, and one more on either side
/// (the span from the last cell outside to the first inside crosses into it). A texel
/// at `x` lands at `e + s·(x − e)` for an `s` in `[s_lo, s_hi]` (> 0): a linear bound
/// each way, so the cells are a range. Cells past it in the visit land beyond `hi`
/// (or before `lo`) and so do the spans between them.
pub(super) fn reaching(
    cells: std::ops::Range<usize>,
    before: bool,
    e: f32,
    (s_lo, s_hi): (f32, f32),
    (lo, hi): (f32, f32),
) -> std::ops::Range<usize> {
    let (e, lo, hi) = (e as f64, lo as f64, hi as f64);
    // Before the epipole (x ≤ e) the landing spans [e + s_hi·(x − e), e + s_lo·(x − e)];
    // after it the reverse.
    let (for_lo, for_hi) = if before { (s_lo, s_hi) } else { (s_hi, s_lo) };
    let (x_min, x_max) = (e + (lo - e) / for_lo as f64, e + (hi - e) / for_hi as f64);
    // Cell k has its centre at k + ½; bounded first so the conversions are exact.
    let bound = |x: f64| x.clamp(cells.start as f64 - 1.0, cells.end as f64 + 1.0);
    let first = (bound(x_min - 0.5).ceil() - 1.0).max(cells.start as f64) as usize;
    let last = (bound(x_max - 0.5).floor() + 1.0).min(cells.end as f64 - 1.0);
    if last < first as f64 {
        return first..first;
    }
    first..last as usize + 1
}
