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

/// A texel's albedo and encoded normal: six bytes in the low bytes of a `u64`, so one
/// interpolation blends all six at once (two multiplies on 16-bit lanes).
#[derive(Debug, Clone, Copy, PartialEq)]
struct Attributes(u64);

/// The even bytes of a `u64`, each in its own 16-bit lane.
const EVEN_BYTES: u64 = 0x00ff_00ff_00ff_00ff;

impl Attributes {
    #[inline(always)]
    fn pack(albedo: [u8; 3], normal: [u8; 3]) -> Attributes {
        let [r, g, b] = albedo;
        let [x, y, z] = normal;
        Attributes(u64::from_le_bytes([r, g, b, x, y, z, 0, 0]))
    }

    /// `self + (other − self)·t/256` per byte, `t ∈ [0, 256]`: every 16-bit lane holds
    /// one byte, and `a·(256 − t) + b·t ≤ 255·256` fits it.
    #[inline(always)]
    fn lerp(self, other: Attributes, t: u64) -> Attributes {
        let blend = |a: u64, b: u64| ((a * (256 - t) + b * t) >> 8) & EVEN_BYTES;
        let (a, b) = (self.0, other.0);
        let even = blend(a & EVEN_BYTES, b & EVEN_BYTES);
        let odd = blend((a >> 8) & EVEN_BYTES, (b >> 8) & EVEN_BYTES);
        Attributes(even | (odd << 8))
    }

    #[inline(always)]
    fn texel(self, depth: f32) -> PTexel {
        let [r, g, b, x, y, z, ..] = self.0.to_le_bytes();
        PTexel {
            depth,
            albedo: [r, g, b],
            normal: [x, y, z],
        }
    }
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
    attributes: Attributes,
    /// Connected to the sample of the next source row (see [`Impostor`]).
    down: bool,
}

impl Sample {
    #[inline(always)]
    fn lerp(&self, other: &Sample, t: f32) -> Sample {
        Sample {
            pos: self.pos + (other.pos - self.pos) * t,
            v_target: self.v_target + (other.v_target - self.v_target) * t,
            source: self.source + (other.source - self.source) * t,
            depth: self.depth + (other.depth - self.depth) * t,
            attributes: self
                .attributes
                // (`min`: a NaN `t`, from NaN input, must not underflow the lanes.)
                .lerp(other.attributes, super::round_small(t * 256.0).min(256) as u64),
            down: self.down && other.down,
        }
    }
}

/// Emits the pixels that sample `b` adds after `a` along an axis visited in direction
/// `dir` (±1): every pixel whose centre lies in `(a, b]`, interpolated — or, when there
/// is no connected predecessor `a` (or the two fold over), just the pixel `b` lands in.
/// `interpolate(a, b, centre, t)` makes the sample at a pixel centre, `t` being the
/// centre's linear position from `a` to `b`.
#[inline(always)]
fn span(
    a: Option<&Sample>,
    b: &Sample,
    dir: f32,
    interpolate: impl Fn(&Sample, &Sample, f32, f32) -> Sample,
    mut emit: impl FnMut(i64, Sample),
) {
    if let Some(a) = a
        && (b.pos - a.pos) * dir >= 0.0
    {
        // Infinite when they coincide, but then no pixel centre lies between them.
        let inv = 1.0 / (b.pos - a.pos);
        if dir > 0.0 {
            let first = (a.pos - 0.5).floor() as i64 + 1;
            let last = (b.pos - 0.5).floor() as i64;
            // (Half-open ranges: `..=` iterates measurably slower here.)
            for x in first..last + 1 {
                emit(x, at(a, b, inv, x, &interpolate));
            }
        } else {
            let first = (a.pos - 0.5).ceil() as i64 - 1;
            let last = (b.pos - 0.5).ceil() as i64;
            for x in (last..first + 1).rev() {
                emit(x, at(a, b, inv, x, &interpolate));
            }
        }
        return;
    }
    emit(b.pos.floor() as i64, *b);
}

/// The sample at pixel `x`'s centre between `a` and `b` (`inv = 1 / (b − a)`).
#[inline(always)]
fn at(
    a: &Sample,
    b: &Sample,
    inv: f32,
    x: i64,
    interpolate: &impl Fn(&Sample, &Sample, f32, f32) -> Sample,
) -> Sample {
    let centre = x as f32 + 0.5;
    let t = ((centre - a.pos) * inv).clamp(0.0, 1.0);
    interpolate(a, b, centre, t)
}

/// Linear interpolation at a pixel centre.
#[inline(always)]
fn linear(a: &Sample, b: &Sample, _centre: f32, t: f32) -> Sample {
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

/// Per-column state of the column pass: what the column's last sample carries on (its
/// v', displacement, attributes and link downwards), and one past the number (in
/// visiting order) of the row that produced it — 0 before any. Only what the column
/// pass reads is kept, so the row pass's other fields are never computed for it.
#[derive(Clone, Copy)]
struct Column {
    v: f32,
    depth: f32,
    attributes: Attributes,
    down: bool,
    next_row: u32,
}

impl Column {
    const START: Column = Column {
        v: 0.0,
        depth: 0.0,
        attributes: Attributes(0),
        down: false,
        next_row: 0,
    };

    /// The last sample, as the column pass's span reads it.
    #[inline(always)]
    fn last(&self) -> Sample {
        Sample {
            pos: self.v,
            v_target: self.v,
            source: 0.0,
            depth: self.depth,
            attributes: self.attributes,
            down: self.down,
        }
    }
}

/// The rows of the pre-warped image one half of the work writes, as plane coordinates
/// starting at `(u0, v0)`.
struct Output<'a> {
    texels: &'a mut [PTexel],
    u0: i64,
    v0: i64,
    width: usize,
}

impl Output<'_> {
    #[inline(always)]
    fn put(&mut self, x: i64, y: i64, s: &Sample) {
        let (xx, yy) = (x - self.u0, y - self.v0);
        if xx < 0 || yy < 0 || xx as usize >= self.width {
            return;
        }
        if let Some(t) = self.texels.get_mut(yy as usize * self.width + xx as usize) {
            *t = s.attributes.texel(s.depth);
        }
    }
}

/// Feeds the sample `s` (already carrying its final v' in `pos`) produced by row number
/// `seq` (in visiting order) into column `x`, filling rows since that column's last
/// sample.
#[inline(always)]
fn push_column(column: &mut Column, out: &mut Output, x: i64, s: Sample, seq: usize, dir: f32) {
    // Visiting downwards the previous row's sample carries the link to this row;
    // visiting upwards this row's sample does.
    let p = column.last();
    let linked =
        column.next_row != 0 && column.next_row as usize == seq && if dir > 0.0 { p.down } else { s.down };
    span(linked.then_some(&p), &s, dir, linear, |y, t| out.put(x, y, &t));
    *column = Column {
        v: s.pos,
        depth: s.depth,
        attributes: s.attributes,
        down: s.down,
        next_row: seq as u32 + 1,
    };
}

/// What both halves of a pre-warp read.
struct Job<'a> {
    impostor: &'a Impostor,
    params: &'a WarpParams,
    variant: Variant,
    u0: i64,
    columns: usize,
}

impl Job<'_> {
    /// The texel `(i, j)` as a sample, pre-warped; `None` when empty.
    #[inline(always)]
    fn source(&self, i: usize, j: usize) -> Option<Sample> {
        let texture = &self.impostor.texture;
        let k = j * texture.camera.width as usize + i;
        let q = texture.depth[k];
        if q == texture.depth_bits.empty() {
            return None;
        }
        let p: Vec2 = self.params.warp(i as f32 + 0.5, j as f32 + 0.5, q as usize);
        Some(Sample {
            pos: p.x,
            v_target: p.y,
            source: i as f32 + 0.5,
            depth: self.params.depth[q as usize],
            attributes: Attributes::pack(texture.albedo[k], texture.normal[k]),
            down: self.impostor.down[k],
        })
    }

    /// The row pass over source row `j`: `emit(x, sample)` for each pre-warped pixel.
    #[inline(always)]
    fn row(&self, j: usize, mut emit: impl FnMut(i64, Sample)) {
        let w = self.impostor.texture.camera.width as usize;
        let right = &self.impostor.right;
        for (cols, dir) in halves(w, self.params.epipole.x) {
            let mut previous: Option<Sample> = None;
            for i in cols {
                let Some(s) = self.source(i, j) else {
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
                match self.variant {
                    Variant::Compensated => span(
                        a,
                        &s,
                        dir,
                        |a, b, x, _| compensated(a, b, x, self.params),
                        &mut emit,
                    ),
                    _ => span(a, &s, dir, linear, &mut emit),
                }
                previous = Some(s);
            }
        }
    }

    /// Pre-warps the source rows `rows` (visited in that order, direction `dir`) into
    /// `out`.
    fn half(&self, rows: impl Iterator<Item = usize> + Clone, dir: f32, out: &mut Output) {
        let mut columns = vec![Column::START; self.columns];
        let column_of = |x: i64| {
            let xi = x - self.u0;
            (xi >= 0 && xi < self.columns as i64).then_some(xi as usize)
        };
        if self.variant == Variant::Interleaved {
            for (seq, j) in rows.enumerate() {
                self.row(j, |x, s| {
                    if let Some(xi) = column_of(x) {
                        push_column(
                            &mut columns[xi],
                            out,
                            x,
                            Sample { pos: s.v_target, ..s },
                            seq,
                            dir,
                        );
                    }
                });
            }
            return;
        }
        // Two passes: the rows into an intermediate image, then its columns.
        let n_rows = rows.clone().count();
        let mut intermediate: Vec<Option<Sample>> = vec![None; self.columns * n_rows];
        for (seq, j) in rows.clone().enumerate() {
            self.row(j, |x, s| {
                if let Some(xi) = column_of(x) {
                    intermediate[seq * self.columns + xi] = Some(s);
                }
            });
        }
        for (seq, j) in rows.enumerate() {
            for (xi, column) in columns.iter_mut().enumerate() {
                let Some(s) = intermediate[seq * self.columns + xi] else {
                    continue;
                };
                let v_target = match self.variant {
                    Variant::Asymmetric => s.v_target,
                    _ => self.params.warp_v(j as f32 + 0.5, s.depth),
                };
                push_column(
                    column,
                    out,
                    xi as i64 + self.u0,
                    Sample { pos: v_target, ..s },
                    seq,
                    dir,
                );
            }
        }
    }
}

/// Pre-warps `impostor` for the eye of `params`, on the calling thread.
pub fn prewarp(impostor: &Impostor, params: &WarpParams, variant: Variant) -> PrewarpImage {
    prewarp_with(impostor, params, variant, false)
}

/// As [`prewarp`], with the halves above and below the epipole on two threads: they
/// write disjoint rows (texels move towards the epipole, never past it), so each
/// writes straight into the final image.
pub fn prewarp_split(impostor: &Impostor, params: &WarpParams, variant: Variant) -> PrewarpImage {
    prewarp_with(impostor, params, variant, true)
}

fn prewarp_with(impostor: &Impostor, params: &WarpParams, variant: Variant, parallel: bool) -> PrewarpImage {
    let c = &impostor.texture.camera;
    let (w, h) = (c.width as usize, c.height as usize);
    let s_min = 1.0 / (1.0 + params.k3 * params.max_depth());
    let (u0, u1) = axis_extent(w as f32, params.epipole.x, s_min);
    let (v0, v1) = axis_extent(h as f32, params.epipole.y, s_min);
    let (width, height) = ((u1 - u0).max(1) as usize, (v1 - v0).max(1) as usize);
    let mut texels = vec![PTexel::EMPTY; width * height];
    let job = Job {
        impostor,
        params,
        variant,
        u0: u0 as i64,
        columns: width,
    };
    // Output rows whose centres lie above the epipole belong to the upper half.
    let split = ((params.epipole.y - 0.5).ceil() as i64 - v0 as i64).clamp(0, height as i64) as usize;
    let (upper, lower) = texels.split_at_mut(split * width);
    let [(up_rows, up_dir), (down_rows, down_dir)] = halves(h, params.epipole.y);
    let mut upper = Output {
        texels: upper,
        u0: u0 as i64,
        v0: v0 as i64,
        width,
    };
    let mut lower = Output {
        texels: lower,
        u0: u0 as i64,
        v0: v0 as i64 + split as i64,
        width,
    };
    if parallel {
        rayon::join(
            || job.half(up_rows, up_dir, &mut upper),
            || job.half(down_rows, down_dir, &mut lower),
        );
    } else {
        job.half(up_rows, up_dir, &mut upper);
        job.half(down_rows, down_dir, &mut lower);
    }
    PrewarpImage {
        u0,
        v0,
        width: width as u32,
        height: height as u32,
        texels,
    }
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
