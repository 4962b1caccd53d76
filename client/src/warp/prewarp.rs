//! The pre-warp (ch. 3.4, 8.2): every texel moved within the source plane to where the
//! destination eye sees it, holes between neighbours filled by interpolation, texels
//! visited in occlusion-compatible order so that later writes win.
//!
//! Order: the epipole splits rows and columns into halves; each half is visited from the
//! border towards the epipole. (Each texel moves towards the epipole by `s ∈ (0, 1]`, the
//! deeper the more, so of two texels landing on one spot the one nearer the epipole in
//! the source is the nearer surface — it must come last.)
//!
//! Filling: consecutive texels A, B of a row (connected — one surface, see
//! [`Impostor`] — and moving in the visiting direction) produce every pre-warped pixel whose centre lies in
//! `(A', B']`, interpolated; the first texel of a run produces the pixel it lands in. The
//! column pass does the same with consecutive samples of a column. The variants differ
//! in what reaches the column pass (table 8.1):
//!
//! - [`Variant::OneD`]: the row pass stores interpolated depth; the column pass computes
//!   each sample's v' from it — interpolating what was already interpolated.
//! - [`Variant::Asymmetric`]: the row pass also stores each sample's final v'.
//! - [`Variant::Compensated`]: as `OneD`, but an interpolated sample takes the depth of
//!   the point on the 3D segment A–B that pre-warps exactly to its pixel (the purpose of
//!   eq. 8-1, solved here in closed form) instead of a linear blend.
//! - [`Variant::Interleaved`]: one pass; each row sample goes straight into its column.

use glam::Vec2;

use super::params::WarpParams;
use crate::impostor::Impostor;

/// Pre-warp sampling variant.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Variant {
    OneD,
    Asymmetric,
    Compensated,
    Interleaved,
}

/// A pre-warped texel. `depth < 0` marks an empty one.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct PTexel {
    /// Displacement along `f` of the surface seen here.
    pub depth: f32,
    /// Albedo, 8 bits per channel.
    pub albedo: [u8; 3],
    /// Normal, encoded `n·0.5 + 0.5` in 8 bits per channel.
    pub normal: [u8; 3],
}

impl PTexel {
    pub const EMPTY: PTexel = PTexel {
        depth: -1.0,
        albedo: [0; 3],
        normal: [0; 3],
    };

    #[inline]
    pub fn is_empty(&self) -> bool {
        self.depth < 0.0
    }
}

/// The pre-warped image: texel `(x, y)` covers source-plane coordinates
/// `[u0 + x, u0 + x + 1) × [v0 + y, v0 + y + 1)`. It extends past the source quad towards
/// the epipole, where texels of a turned view land.
#[derive(Debug, Clone, PartialEq)]
pub struct PrewarpImage {
    pub u0: i32,
    pub v0: i32,
    pub width: u32,
    pub height: u32,
    pub texels: Vec<PTexel>,
}

impl PrewarpImage {
    /// The texel covering plane coordinates `(u, v)`, if inside.
    #[inline]
    pub fn at(&self, u: f32, v: f32) -> Option<&PTexel> {
        let x = u.floor() as i64 - self.u0 as i64;
        let y = v.floor() as i64 - self.v0 as i64;
        if x < 0 || y < 0 || x >= self.width as i64 || y >= self.height as i64 {
            return None;
        }
        Some(&self.texels[y as usize * self.width as usize + x as usize])
    }

    /// Number of non-empty texels.
    pub fn covered(&self) -> usize {
        self.texels.iter().filter(|t| !t.is_empty()).count()
    }
}

/// How far past the source quad (in quad sizes) the pre-warped image may reach.
const MAX_MARGIN: f32 = 1.0;

/// The range of pre-warped coordinates along one axis: texels move from `[0, n]`
/// towards the epipole `e` by at least the factor `s_min`.
fn axis_extent(n: f32, e: f32, s_min: f32) -> (i32, i32) {
    let lo = 0f32.min(e + s_min * (0.0 - e)).max(-MAX_MARGIN * n);
    let hi = n.max(e + s_min * (n - e)).min((1.0 + MAX_MARGIN) * n);
    (lo.floor() as i32, hi.ceil() as i32)
}

/// A sample travelling through the passes: its position along the current pass axis,
/// its final v' (asymmetric and interleaved), source coordinate along the row (for
/// compensation), displacement and attributes.
#[derive(Debug, Clone, Copy)]
struct Sample {
    pos: f32,
    v_target: f32,
    source: f32,
    depth: f32,
    albedo: [u8; 3],
    normal: [u8; 3],
    /// Connected to the sample of the next source row (see [`Impostor`]).
    down: bool,
}

/// `a + (b - a)·t` on 8-bit channels, `t` in 1/256 steps.
#[inline(always)]
fn lerp8(a: [u8; 3], b: [u8; 3], t: i32) -> [u8; 3] {
    [0, 1, 2].map(|c| (a[c] as i32 + (((b[c] as i32 - a[c] as i32) * t) >> 8)) as u8)
}

impl Sample {
    #[inline(always)]
    fn lerp(&self, other: &Sample, t: f32) -> Sample {
        let ti = (t * 256.0) as i32;
        Sample {
            pos: self.pos + (other.pos - self.pos) * t,
            v_target: self.v_target + (other.v_target - self.v_target) * t,
            source: self.source + (other.source - self.source) * t,
            depth: self.depth + (other.depth - self.depth) * t,
            albedo: lerp8(self.albedo, other.albedo, ti),
            normal: lerp8(self.normal, other.normal, ti),
            down: self.down && other.down,
        }
    }
}

/// Emits the pixels that sample `b` adds after `a` along an axis visited in direction
/// `dir` (±1): every pixel whose centre lies in `(a, b]`, interpolated — or, when there
/// is no connected predecessor `a` (or the two fold over), just the pixel `b` lands in.
/// `interpolate(a, b, centre)` makes the sample at a pixel centre.
#[inline(always)]
fn span(
    a: Option<&Sample>,
    b: &Sample,
    dir: f32,
    interpolate: impl Fn(&Sample, &Sample, f32) -> Sample,
    mut emit: impl FnMut(i64, Sample),
) {
    if let Some(a) = a
        && (b.pos - a.pos) * dir >= 0.0
    {
        if dir > 0.0 {
            let first = (a.pos - 0.5).floor() as i64 + 1;
            let last = (b.pos - 0.5).floor() as i64;
            for x in first..=last {
                emit(x, interpolate(a, b, x as f32 + 0.5));
            }
        } else {
            let first = (a.pos - 0.5).ceil() as i64 - 1;
            let last = (b.pos - 0.5).ceil() as i64;
            for x in (last..=first).rev() {
                emit(x, interpolate(a, b, x as f32 + 0.5));
            }
        }
        return;
    }
    emit(b.pos.floor() as i64, *b);
}

/// Linear interpolation at a pixel centre.
#[inline]
fn linear(a: &Sample, b: &Sample, centre: f32) -> Sample {
    let t = if b.pos == a.pos {
        1.0
    } else {
        ((centre - a.pos) / (b.pos - a.pos)).clamp(0.0, 1.0)
    };
    a.lerp(b, t)
}

/// The visiting order of `0..n` cells (centres at `k + 0.5`) for an epipole at `e`:
/// the cells before `e` forwards, then the cells after it backwards — each half towards
/// the epipole. Returned as two runs with their direction.
fn halves(n: usize, e: f32) -> [(impl Iterator<Item = usize> + Clone, f32); 2] {
    let split = (e - 0.5).ceil().clamp(0.0, n as f32) as usize;
    // Forwards: start + k; backwards: start - k (one closure type for both halves).
    let half = |start: usize, len: usize, dir: f32| {
        let forwards = dir > 0.0;
        (
            (0..len).map(move |k| if forwards { start + k } else { start - k }),
            dir,
        )
    };
    [half(0, split, 1.0), half(n.wrapping_sub(1), n - split, -1.0)]
}

/// Per-column state of the column pass: the last sample and which row (in visiting
/// order) produced it.
#[derive(Clone, Copy)]
struct Column {
    last: Option<(Sample, usize)>,
}

/// Output writer shared by the column passes.
struct Output<'a> {
    image: &'a mut PrewarpImage,
}

impl Output<'_> {
    #[inline]
    fn put(&mut self, x: i64, y: i64, s: &Sample) {
        let (xx, yy) = (x - self.image.u0 as i64, y - self.image.v0 as i64);
        if xx < 0 || yy < 0 || xx >= self.image.width as i64 || yy >= self.image.height as i64 {
            return;
        }
        self.image.texels[yy as usize * self.image.width as usize + xx as usize] = PTexel {
            depth: s.depth,
            albedo: s.albedo,
            normal: s.normal,
        };
    }
}

/// Feeds the sample `s` (already carrying its final v' in `pos`) produced by row number
/// `seq` (in visiting order) into column `x`, filling rows since that column's last
/// sample.
#[inline]
fn push_column(column: &mut Column, out: &mut Output, x: i64, s: Sample, seq: usize, dir: f32) {
    // Visiting downwards the previous row's sample carries the link to this row;
    // visiting upwards this row's sample does.
    let previous = match column.last {
        Some((p, last_seq)) if last_seq + 1 == seq && if dir > 0.0 { p.down } else { s.down } => Some(p),
        _ => None,
    };
    span(previous.as_ref(), &s, dir, linear, |y, t| out.put(x, y, &t));
    column.last = Some((s, seq));
}

/// Pre-warps `impostor` for the eye of `params`.
pub fn prewarp(impostor: &Impostor, params: &WarpParams, variant: Variant) -> PrewarpImage {
    let texture = &impostor.texture;
    let c = &texture.camera;
    let (w, h) = (c.width as usize, c.height as usize);
    let s_min = 1.0 / (1.0 + params.k3 * params.max_depth());
    let (u0, u1) = axis_extent(w as f32, params.epipole.x, s_min);
    let (v0, v1) = axis_extent(h as f32, params.epipole.y, s_min);
    let mut image = PrewarpImage {
        u0,
        v0,
        width: (u1 - u0).max(1) as u32,
        height: (v1 - v0).max(1) as u32,
        texels: Vec::new(),
    };
    image.texels = vec![PTexel::EMPTY; image.width as usize * image.height as usize];
    let empty = texture.depth_bits.empty();
    let source_sample = |i: usize, j: usize| -> Option<Sample> {
        let k = j * w + i;
        let q = texture.depth[k];
        if q == empty {
            return None;
        }
        let p: Vec2 = params.warp(i as f32 + 0.5, j as f32 + 0.5, q as usize);
        Some(Sample {
            pos: p.x,
            v_target: p.y,
            source: i as f32 + 0.5,
            depth: params.depth[q as usize],
            albedo: texture.albedo[k],
            normal: texture.normal[k],
            down: impostor.down[k],
        })
    };
    let e = params.epipole;
    let columns_n = image.width as usize;
    let column_index = |x: i64| (x - u0 as i64) as usize;
    let mut out = Output { image: &mut image };

    // Row pass over one source row: calls `emit(x, sample)` for each pre-warped pixel.
    #[allow(clippy::too_many_arguments)]
    fn row_pass(
        w: usize,
        j: usize,
        e1: f32,
        variant: Variant,
        right: &[bool],
        params: &WarpParams,
        source_sample: &impl Fn(usize, usize) -> Option<Sample>,
        mut emit: impl FnMut(i64, Sample),
    ) {
        for (cols, dir) in halves(w, e1) {
            let mut previous: Option<Sample> = None;
            for i in cols {
                let Some(s) = source_sample(i, j) else {
                    previous = None;
                    continue;
                };
                // Visiting rightwards the left texel carries the link; leftwards this one.
                let linked = if dir > 0.0 {
                    i > 0 && right[j * w + i - 1]
                } else {
                    right[j * w + i]
                };
                let a = previous.as_ref().filter(|_| linked);
                match variant {
                    Variant::Compensated => {
                        span(a, &s, dir, |a, b, x| compensated(a, b, x, params), &mut emit)
                    }
                    _ => span(a, &s, dir, linear, &mut emit),
                }
                previous = Some(s);
            }
        }
    }

    match variant {
        Variant::Interleaved => {
            for (rows, dir) in halves(h, e.y) {
                let mut columns = vec![Column { last: None }; columns_n];
                for (seq, j) in rows.into_iter().enumerate() {
                    row_pass(
                        w,
                        j,
                        e.x,
                        variant,
                        &impostor.right,
                        params,
                        &source_sample,
                        |x, s| {
                            let xi = x - u0 as i64;
                            if xi < 0 || xi >= columns_n as i64 {
                                return;
                            }
                            let s = Sample { pos: s.v_target, ..s };
                            push_column(&mut columns[column_index(x)], &mut out, x, s, seq, dir);
                        },
                    );
                }
            }
        }
        _ => {
            // Row pass into an intermediate image: one row per source row.
            let mut rows_image: Vec<Option<Sample>> = vec![None; columns_n * h];
            for j in 0..h {
                row_pass(
                    w,
                    j,
                    e.x,
                    variant,
                    &impostor.right,
                    params,
                    &source_sample,
                    |x, s| {
                        let xi = x - u0 as i64;
                        if xi >= 0 && xi < columns_n as i64 {
                            rows_image[j * columns_n + xi as usize] = Some(s);
                        }
                    },
                );
            }
            // Column pass.
            for (rows, dir) in halves(h, e.y) {
                let mut columns = vec![Column { last: None }; columns_n];
                for (seq, j) in rows.into_iter().enumerate() {
                    for (xi, column) in columns.iter_mut().enumerate() {
                        let Some(s) = rows_image[j * columns_n + xi] else {
                            continue;
                        };
                        let v_target = match variant {
                            Variant::Asymmetric => s.v_target,
                            _ => params.warp_v(j as f32 + 0.5, s.depth),
                        };
                        let s = Sample { pos: v_target, ..s };
                        push_column(column, &mut out, xi as i64 + u0 as i64, s, seq, dir);
                    }
                }
            }
        }
    }
    image
}

/// The sample at pixel centre `centre` between row neighbours `a` and `b`, taken at the
/// point of the 3D segment between their surface points that pre-warps exactly there:
/// with `u(t) = u_a + t·Δu`, `d(t) = d_a + t·Δd` in the source, solve
/// `(u(t) + e1·k3·d(t)) / (1 + k3·d(t)) = centre` for `t`.
#[inline]
fn compensated(a: &Sample, b: &Sample, centre: f32, p: &WarpParams) -> Sample {
    let (k3, e1) = (p.k3, p.epipole.x);
    let (du, dd) = (b.source - a.source, b.depth - a.depth);
    let denominator = du + k3 * dd * (e1 - centre);
    let t = if denominator.abs() > 1e-12 {
        ((centre * (1.0 + k3 * a.depth) - a.source - e1 * k3 * a.depth) / denominator).clamp(0.0, 1.0)
    } else {
        0.5
    };
    Sample {
        pos: centre,
        ..a.lerp(b, t)
    }
}
