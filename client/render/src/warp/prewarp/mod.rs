//! The pre-warp (ch. 3.4, 8.2): every texel moved within the source plane to where the
//! destination eye sees it, holes between neighbours filled by interpolation, texels
//! visited in occlusion-compatible order so that later writes win.
//!
//! Order: the epipole splits rows and columns into halves; each half is visited from the
//! border towards the epipole. (Each texel moves towards the epipole by `s ∈ (0, 1]`, the
//! deeper the more, so of two texels landing on one spot the one nearer the epipole in
//! the source is the nearer surface — it must come last.) A perspective texture seen
//! from farther than its centre moves texels away from the epipole, the deeper the more
//! ([`WarpParams::outward`]): the nearer surface is then the one farther from the
//! epipole, and each half is visited from the epipole outwards. Either way texels stay
//! on their side of the epipole, and consecutive texels of a surface move apart ahead of
//! the visit.
//!
//! Filling: consecutive texels A, B of a row (connected — one surface, see
//! [`Impostor`] — and moving in the visiting direction) produce every pre-warped pixel
//! whose centre lies in `(A', B']`, interpolated. A run of connected texels reaches half
//! its first span behind its first sample and half its last span past its last (at most
//! half a pixel each): each sample owns the half-way points to its neighbours, so a
//! silhouette lies where the surface's samples put it. (Giving a run's end sample the
//! whole pixel it lands in grows a silhouette by half a pixel on average where the
//! pre-warp compresses the surface, at a curved object's rim.) A texel alone produces
//! the pixel it lands in. Neighbours of different surfaces that part leave a crack
//! between them, which the deeper of the two fills (`Job::crack`) — but for the half
//! beside the nearer where its surface, closed, rounds out of sight there
//! (`Job::crack_fillers`). The column pass does the same with consecutive samples of a
//! column. The variants differ in what reaches the column pass (table 8.1):
//!
//! - [`Variant::OneD`]: the row pass stores interpolated depth; the column pass computes
//!   each sample's v' from it — interpolating what was already interpolated.
//! - [`Variant::Asymmetric`]: the row pass also stores each sample's final v'.
//! - [`Variant::Compensated`]: as `OneD`, but an interpolated sample takes the depth of
//!   the point on the 3D segment A–B that pre-warps exactly to its pixel (the purpose of
//!   eq. 8-1, solved here in closed form for orthographic textures) instead of a linear
//!   blend; a perspective texture's samples blend linearly.
//! - [`Variant::Interleaved`]: one pass; each row sample goes straight into its column.
//!   Where a surface is smooth it takes eight texels at a time (module `lanes`), to the bit
//!   the same image.

mod lanes;

use wide::bytemuck::cast;
use wide::{i16x8, u8x16, u16x8, u64x2};

use glam::{DVec3, Vec2, Vec3};
use relief_core::camera::Camera;
use relief_core::relief::SourceCamera;

use self::lanes::{Columns, DOWN_LINK, Emitted, LANES, RIGHT_LINK, RowSamples, VALID, first, row_block};
use super::params::WarpParams;
use crate::EMPTY_DEPTH;
use crate::impostor::{Faces, Impostor, SurfaceExtent};

/// Pre-warp sampling variant.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Variant {
    OneD,
    Asymmetric,
    Compensated,
    Interleaved,
}

impl Variant {
    /// Every variant, in table 8.1's order.
    pub const ALL: [Variant; 4] = [
        Variant::OneD,
        Variant::Asymmetric,
        Variant::Compensated,
        Variant::Interleaved,
    ];
}

/// A pre-warped texel; [`EMPTY_DEPTH`] marks an empty one.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct PTexel {
    /// Displacement along `f` of the surface seen here.
    pub depth: f32,
    /// Albedo and encoded normal, packed for blending.
    pub(crate) attributes: Attributes,
}

impl PTexel {
    pub const EMPTY: PTexel = PTexel {
        depth: EMPTY_DEPTH,
        attributes: Attributes(0),
    };

    #[inline]
    pub fn is_empty(&self) -> bool {
        self.depth == EMPTY_DEPTH
    }
}

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
    /// Source texels visited: each row's occupied ones ([`Impostor::occupied`]), or
    /// those of them that can reach a [`PlaneWindow`].
    pub visited: usize,
}

impl PrewarpImage {
    /// The image of a pre-warp that lands nothing on the screen: one empty pixel.
    fn nothing_seen() -> PrewarpImage {
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
/// reach half a pixel past them ([`half_gap`]), so at 2 an empty pixel always lies
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
fn extent(params: &WarpParams, surface: &SurfaceExtent, w: f32, h: f32) -> ((i32, i32), (i32, i32)) {
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

/// A texel's albedo and encoded normal: six bytes in the low bytes of a `u64`, so one
/// interpolation blends all six at once (two multiplies on a vector of 16-bit lanes;
/// see [`Attributes::lerp`]). The top two
/// bytes are not read; a source texel keeps its depth's table entry and links there
/// (see [`pack_texel`]).
#[derive(Debug, Clone, Copy, PartialEq)]
pub(crate) struct Attributes(u64);

/// Where a packed texel's encoded normal starts ([`pack_texel`]): its three bytes follow
/// the albedo's.
const NORMAL_SHIFT: u32 = 24;
/// Where a packed texel's table entry starts ([`pack_texel`]).
const ENTRY_SHIFT: u32 = 48;
/// The bits a table entry may take: entries reach
/// [`WarpLevels::empty`](super::params::WarpLevels::empty), at most 4,096.
const ENTRY_MASK: u64 = (1 << 13) - 1;
/// A packed texel's links sit at its row-pass flags ([`RIGHT_LINK`], [`DOWN_LINK`])
/// shifted up by this, above its table entry.
const LINKS_SHIFT: u32 = 60;

// The packed layout holds: the largest table entry fits its bits, which end where the
// links begin, and the links fit the word.
const _: () = assert!(1 << super::params::WARP_LEVEL_BITS <= ENTRY_MASK);
const _: () = assert!(ENTRY_SHIFT + ENTRY_MASK.count_ones() <= LINKS_SHIFT + RIGHT_LINK.trailing_zeros());
const _: () = assert!(LINKS_SHIFT + DOWN_LINK.ilog2() < 64);

/// A texel as the pre-warp reads it ([`Impostor::packed`]): albedo and encoded normal in
/// the low six bytes, as [`Attributes`]; above them the table entry of its depth level
/// ([`WarpLevels::entry`](super::params::WarpLevels::entry)), and its links to the
/// right and downwards — all the row pass reads of a texel, in one load.
pub(crate) fn pack_texel(albedo: [u8; 3], normal: [u8; 3], entry: u16, right: bool, down: bool) -> u64 {
    let ([r, g, b], [x, y, z]) = (albedo, normal);
    let links = u8::from(right) * RIGHT_LINK + u8::from(down) * DOWN_LINK;
    debug_assert!(u64::from(entry) <= ENTRY_MASK, "table entry {entry}");
    u64::from_le_bytes([r, g, b, x, y, z, 0, 0])
        | (u64::from(entry) & ENTRY_MASK) << ENTRY_SHIFT
        | u64::from(links) << LINKS_SHIFT
}

/// The depth's table entry of a [`pack_texel`] texel.
#[inline(always)]
fn entry_of(texel: u64) -> u16 {
    ((texel >> ENTRY_SHIFT) & ENTRY_MASK) as u16
}

/// The row pass's link flags of a [`pack_texel`] texel.
#[inline(always)]
fn links_of(texel: u64) -> u8 {
    (texel >> LINKS_SHIFT) as u8 & (RIGHT_LINK | DOWN_LINK)
}

/// The eight bytes of `x`, each in a 16-bit lane.
#[inline(always)]
fn widen(x: u64) -> u16x8 {
    // (`splat`, one register move: `new([x, 0])` went through memory and stalled,
    // its two 8-byte stores read back as one 16-byte load. Only the low half is read.)
    u16x8::from_u8x16_low(cast::<u64x2, u8x16>(u64x2::splat(x)))
}

/// The inverse of [`widen`] for lanes below 256.
#[inline(always)]
fn narrow(lanes: u16x8) -> u64 {
    let signed = cast::<u16x8, i16x8>(lanes);
    cast::<u8x16, u64x2>(u8x16::narrow_i16x8(signed, signed)).to_array()[0]
}

impl Attributes {
    /// `self + (other − self)·t/256` per byte, rounded, `t ∈ [0, 256]`: every byte
    /// widened to a 16-bit lane of one vector, where `a·(256 − t) + b·t + 128 ≤
    /// 255·256 + 128` fits. (Eight bytes at once: the two unread ones blend along.)
    #[inline(always)]
    pub(crate) fn lerp(self, other: Attributes, t: u64) -> Attributes {
        let t = u16x8::splat(t as u16);
        let mixed = (widen(self.0) * (u16x8::splat(256) - t) + widen(other.0) * t + u16x8::splat(128)) >> 8;
        Attributes(narrow(mixed))
    }

    #[inline(always)]
    fn texel(self, depth: f32) -> PTexel {
        PTexel {
            depth,
            attributes: self,
        }
    }

    #[inline(always)]
    pub(crate) fn albedo(self) -> [u8; 3] {
        let [r, g, b, ..] = self.0.to_le_bytes();
        [r, g, b]
    }

    #[inline(always)]
    pub(crate) fn normal(self) -> [u8; 3] {
        let [_, _, _, x, y, z, ..] = self.0.to_le_bytes();
        [x, y, z]
    }

    /// The encoded normal's direction, not of unit length: encoded `n·127.5 + 127.5`, it
    /// is `n·127.5`, and the direction is all its tests need.
    #[inline(always)]
    fn normal_direction(self) -> Vec3 {
        let [x, y, z] = self.normal();
        Vec3::new(x as f32, y as f32, z as f32) - Vec3::splat(127.5)
    }
}

/// A texel in the row pass: its source u, where it lands along the row (u'), and what
/// goes on to the column pass.
#[derive(Debug, Clone, Copy)]
struct RowSample {
    source: f32,
    u: f32,
    cell: Cell,
}

/// What the column pass reads of a sample: its v' (final, or where its row is before
/// the column pass), displacement, attributes and link downwards; and whether the row
/// pass made it to fill a crack ([`Job::crack`]), linked to no other row.
#[derive(Debug, Clone, Copy)]
struct Cell {
    v: f32,
    depth: f32,
    attributes: Attributes,
    down: bool,
    filler: bool,
}

impl Cell {
    const START: Cell = Cell {
        v: 0.0,
        depth: 0.0,
        attributes: Attributes(0),
        down: false,
        filler: false,
    };

    /// A sample the row pass made from a texel (never a crack's filler): where it lands
    /// in its row, `v`, its displacement, its attribute bytes and its link downwards.
    #[inline(always)]
    fn sample(v: f32, depth: f32, attributes: u64, down: bool) -> Cell {
        Cell {
            v,
            depth,
            attributes: Attributes(attributes),
            down,
            filler: false,
        }
    }

    /// Of two samples of different surfaces, the one farther from the texture's eye.
    #[inline(always)]
    fn deeper(self, other: Cell) -> Cell {
        let far = if other.depth > self.depth { other } else { self };
        Cell {
            down: false,
            filler: true,
            ..far
        }
    }

    #[inline(always)]
    fn lerp(&self, other: &Cell, t: f32) -> Cell {
        Cell {
            v: self.v + (other.v - self.v) * t,
            depth: self.depth + (other.depth - self.depth) * t,
            // (`min`: a NaN `t`, from NaN input, must not underflow the lanes.)
            attributes: self
                .attributes
                .lerp(other.attributes, super::round_small(t * 256.0).min(256) as u64),
            down: self.down && other.down,
            filler: false,
        }
    }
}

/// Along an axis visited forwards (`FORWARDS`: increasing coordinates) or backwards:
/// when `b` is not behind `a`, calls `each(pixel, t)` for every pixel up to `end` whose
/// centre lies in `(a, b]`, in visiting order, `t` being the centre's linear position
/// from `a` to `b`, and returns true; returns false when `b` folds back behind `a` (or
/// either is NaN). `end` is the image's last pixel along the axis in the
/// visiting direction, in the signed coordinates below ([`signed_end`]).
///
/// A backwards visit runs on negated coordinates, where pixel `x` is pixel `−x − 1`:
/// one test and one loop serve both directions, and the direction, a const, costs no
/// branch per sample.
#[inline(always)]
fn between<const FORWARDS: bool>(a: f32, b: f32, end: i64, mut each: impl FnMut(i64, f32)) -> bool {
    let sign = if FORWARDS { 1.0 } else { -1.0 };
    let (a, b) = (a * sign, b * sign);
    // (False for NaN too; positions are finite, `WarpParams` sees to that.)
    let ahead = b >= a;
    if !ahead {
        return false;
    }
    let (below_a, below_b) = ((a - 0.5).floor(), (b - 0.5).floor());
    // No pixel centre between them (common where the pre-warp compresses the
    // surface): no division, no conversions.
    if below_a == below_b {
        return true;
    }
    // (Finite: samples that coincide have no centre between them, returned above.)
    let inv = 1.0 / (b - a);
    // Samples move ahead in the visit (towards the epipole, or outwards away from it):
    // a far one makes spans run far past the image on that side (never before it), cut
    // at its end.
    let first = (below_a as i64).saturating_add(1);
    let last = (below_b as i64).min(end);
    // (Half-open ranges: `..=` iterates measurably slower here.)
    for x in first..last + 1 {
        let t = ((x as f32 + 0.5 - a) * inv).clamp(0.0, 1.0);
        each(if FORWARDS { x } else { -x - 1 }, t);
    }
    true
}

/// Half of a span `gap` long (signed), at most half a pixel of the pre-warped image: how
/// far a run's end sample reaches past it. (A sample alone covers about one pixel; a
/// longer reach, at a stretched end, drew spikes past the silhouette.)
#[inline(always)]
fn half_gap(gap: f32) -> f32 {
    0.5 * gap.clamp(-1.0, 1.0)
}

/// A run's last sample, landing at `pos`, draws its share ahead of it: with `put(pixel)`,
/// the pixel it lands in when the run has no span (`last_gap` NaN: the sample is alone),
/// else the pixels within half of the run's last span, `last_gap`, ahead ([`half_gap`]).
/// Visited as in [`between`], up to `end`. (Once a run, not per sample: kept out of the
/// passes' inlined code, whose every pixel is a column step.)
#[inline(never)]
fn reach_ahead<const FORWARDS: bool>(pos: f32, last_gap: f32, end: i64, mut put: impl FnMut(i64)) {
    if last_gap.is_nan() {
        put(pos.floor() as i64);
        return;
    }
    between::<FORWARDS>(pos, pos + half_gap(last_gap), end, |x, _| put(x));
}

/// A run's first sample, landing at `pos`, draws its share behind it once the run's
/// first span, `gap`, is known: the pixels within half of it ([`half_gap`]). (Once a
/// run: not inlined.)
#[inline(never)]
fn reach_behind<const FORWARDS: bool>(pos: f32, gap: f32, end: i64, mut put: impl FnMut(i64)) {
    between::<FORWARDS>(pos - half_gap(gap), pos, end, |x, _| put(x));
}

/// How steeply a sample's surface must run away from the texture's plane, towards a
/// crack beside it, for the sample to count as lying at its surface's outline: depth per
/// unit across, 2 — its normal 63° or more from the texture's rays. (The knot's last
/// samples before an outline lie 10–15° short of grazing; a surface seen more nearly
/// face-on ends at an edge, where what goes on round is another face.) See
/// [`Job::crack_fillers`].
const OUTLINE_SLOPE: f32 = 2.0;

/// Whether the surface of a sample with `attributes` runs away from the plane of a
/// texture whose rays go along `f` at [`OUTLINE_SLOPE`] or more towards `toward` (a
/// unit direction in the plane): rounding out of the texture's sight that way. (Its
/// depth rises by `(n·toward)/|n·f|` per unit along `toward`, `n` its normal turned to
/// face the rays, as an encoded normal at a rim, rounded, may not. `f` is the rays'
/// direction of an orthographic texture, a closed surface's kind: a perspective one's
/// part from it.)
#[inline]
fn turns_away(attributes: Attributes, toward: Vec3, f: Vec3) -> bool {
    let n = attributes.normal_direction();
    let n = if n.dot(f) > 0.0 { -n } else { n };
    n.dot(toward) >= OUTLINE_SLOPE * -n.dot(f)
}

/// The crack between a column's last sample and `cell`, of another surface in the next
/// row ([`Job::crack`], itself out of line). (Inlined into the column step, though it
/// runs as often as [`Job::crack`]: called, it cost the pre-warp 4–20 % of its time for
/// about the same instructions — most where surfaces break often, as leaves do: the
/// tree's 256² texture at 5°, one core, 0.99 → 0.88 ms; the knot's 0.62 → 0.58. Once,
/// inlined, it made the row pass's span step a call instead and slowed the pre-warp:
/// `#[inline]` is a hint, so time both again when the column step grows.)
#[inline]
fn fill_column_crack<const DOWN: bool>(
    job: &Job,
    column: &Column,
    cell: &Cell,
    column_index: usize,
    end: i64,
    out: &mut Output,
) {
    let last = (&column.last, column.last.v);
    job.crack::<DOWN>(
        job.axes.b,
        last,
        column.last_gap,
        (cell, cell.v),
        end,
        |y, filler| out.put(column_index, y, filler),
    );
}

/// The last pixel of `pixels` met visiting forwards (`FORWARDS`) or backwards, in
/// [`between`]'s signed coordinates (pixel `x` is `−x − 1` backwards).
#[inline(always)]
fn signed_end<const FORWARDS: bool>(pixels: std::ops::Range<i64>) -> i64 {
    if FORWARDS {
        pixels.end - 1
    } else {
        -pixels.start - 1
    }
}

/// The `k`-th of `cells` visited forwards (`FORWARDS`) or backwards.
#[inline(always)]
fn visited<const FORWARDS: bool>(cells: &std::ops::Range<usize>, k: usize) -> usize {
    if FORWARDS {
        cells.start + k
    } else {
        cells.end - 1 - k
    }
}

/// The number of cells of `0..n` (centres at `k + 0.5`) before the epipole `e`: the
/// pre-warp visits each half towards the epipole (or, outwards, away from it).
#[inline]
fn split_at(n: usize, e: f32) -> usize {
    (e - 0.5).ceil().clamp(0.0, n as f32) as usize
}

/// Per-column state of the column pass: the column's last sample, and one past the
/// number (in visiting order) of the row that produced it — 0 before any; and, as in
/// the row pass, the run of connected samples it ends: the run's last span, NaN while
/// it has none (its first sample still owes its half-span behind it). Its end is drawn
/// when a sample does not continue it. (Kept field by field in [`Columns`], so that
/// eight columns load as vectors.)
#[derive(Clone, Copy)]
struct Column {
    last: Cell,
    next_row: u32,
    last_gap: f32,
}

impl Column {
    const START: Column = Column {
        last: Cell::START,
        next_row: 0,
        last_gap: f32::NAN,
    };

    /// Draws the end of the column's run, if it has one ([`reach_ahead`]).
    #[inline(always)]
    fn close<const DOWN: bool>(&self, column_index: usize, out: &mut Output) {
        if self.next_row == 0 {
            return;
        }
        let end = signed_end::<DOWN>(out.v0..out.v1);
        let last = self.last;
        reach_ahead::<DOWN>(last.v, self.last_gap, end, |y| out.put(column_index, y, &last));
    }
}

/// The rows of the pre-warped image one half of the work writes: all its columns (the
/// pass's, from the image's first), and plane rows from `v0`.
struct Output<'a> {
    texels: &'a mut [PTexel],
    /// The plane rows `v0..v1` held.
    v0: i64,
    v1: i64,
    width: usize,
}

impl Output<'_> {
    /// Writes `cell` at column `xi` of the image (counted from its first, so already
    /// within it: a column of the pass) and plane row `y`, if that row is held.
    #[inline(always)]
    fn put(&mut self, xi: usize, y: i64, cell: &Cell) {
        self.put_texel(xi, y, cell.attributes.texel(cell.depth));
    }

    /// Writes `texel` as [`Output::put`] writes a cell.
    #[inline(always)]
    fn put_texel(&mut self, xi: usize, y: i64, texel: PTexel) {
        let yy = y - self.v0;
        if yy < 0 {
            return;
        }
        if let Some(t) = self.texels.get_mut(yy as usize * self.width + xi) {
            *t = texel;
        }
    }
}

/// Where the row pass's pixels go.
trait RowSink {
    /// The row pass made `cell` for pre-warped column `x`.
    fn emit(&mut self, x: i64, cell: Cell);

    /// The row pass made `emitted`, for consecutive columns (see
    /// [`lanes::row_block`]).
    #[inline(always)]
    fn emit_block(&mut self, emitted: &Emitted) {
        for l in 0..emitted.count {
            self.emit(emitted.first + l as i64, emitted.cell(l));
        }
    }
}

/// [`Variant::Interleaved`]: each row sample straight into its column, row number
/// `seq` of a half visited downwards when `DOWN`.
struct IntoColumns<'a, 'b, 'o, const DOWN: bool> {
    job: &'a Job<'a>,
    columns: &'b mut Columns,
    out: &'b mut Output<'o>,
    seq: u32,
}

impl<const DOWN: bool> RowSink for IntoColumns<'_, '_, '_, DOWN> {
    #[inline(always)]
    fn emit(&mut self, x: i64, cell: Cell) {
        self.job
            .push_column::<DOWN>(self.columns, self.out, x, cell, self.seq);
    }

    /// Eight columns at once where they continue their runs simply
    /// ([`Columns::take_block`]), the others one by one.
    #[inline(always)]
    fn emit_block(&mut self, emitted: &Emitted) {
        let (n, base) = (emitted.count as i64, emitted.first - self.job.u0);
        let others = if base >= 0 && base + n <= self.columns.len() as i64 {
            self.columns
                .take_block::<DOWN>(emitted, base as usize, self.seq, self.out)
        } else {
            first(n as u32)
        };
        let mut lanes = others;
        while lanes != 0 {
            let l = lanes.trailing_zeros() as usize;
            lanes &= lanes - 1;
            self.emit(emitted.first + l as i64, emitted.cell(l));
        }
    }
}

/// The two-pass variants: into one row of the intermediate image (a column's last
/// sample wins), whose column `k` is pre-warped column `u0 + k`.
struct IntoRow<'a> {
    row: &'a mut [Option<Cell>],
    u0: i64,
}

impl RowSink for IntoRow<'_> {
    #[inline(always)]
    fn emit(&mut self, x: i64, cell: Cell) {
        let k = x - self.u0;
        if let Some(slot) = (k >= 0).then(|| self.row.get_mut(k as usize)).flatten() {
            *slot = Some(cell);
        }
    }
}

/// Where a row's texels face, to leave out back faces ([`Faces::Front`]): the eye seen
/// from the row's plane origin, how a texel's plane point moves along the row (`a`),
/// and its ray (scaled to 1 along `f`) and how that moves.
#[derive(Clone, Copy)]
struct Facing {
    row_eye: Vec3,
    a: Vec3,
    ray: Vec3,
    ray_step: Vec3,
}

/// The warp's tables ([`WarpParams`]), sliced to the surface entries: an entry past
/// them is the empty texel's, so one comparison tells a surface texel and bounds every
/// read.
#[derive(Clone, Copy)]
struct Tables<'a> {
    scale: &'a [f32],
    add_u: &'a [f32],
    add_v: &'a [f32],
    depth: &'a [f32],
}

impl<'a> Tables<'a> {
    fn of(p: &'a WarpParams) -> Tables<'a> {
        let entries = usize::from(p.levels.empty());
        let tables = [&p.scale, &p.add_u, &p.add_v, &p.depth];
        debug_assert!(
            tables.iter().all(|table| table.len() == entries),
            "pre-warp tables of {entries} entries (not params without tables)"
        );
        let entries = tables.iter().fold(entries, |n, table| n.min(table.len()));
        Tables {
            scale: &p.scale[..entries],
            add_u: &p.add_u[..entries],
            add_v: &p.add_v[..entries],
            depth: &p.depth[..entries],
        }
    }
}

/// What both halves of a pre-warp read.
struct Job<'a> {
    impostor: &'a Impostor,
    params: &'a WarpParams,
    /// `params`' tables, for the row pass.
    tables: Tables<'a>,
    variant: Variant,
    u0: i64,
    columns: usize,
    /// The texels of each row visited: those before the epipole, and those after it —
    /// all, or those that can land where the screen sees (and of these, each row's
    /// occupied ones: [`Job::row_texels`]).
    row_halves: [std::ops::Range<usize>; 2],
    /// Whether the interleaved variant takes texels eight at a time where it can
    /// ([`lanes`]); off only to test that it makes the same image.
    lanes: bool,
    /// The texture's axes, to tell which way a sample's surface runs.
    axes: Axes,
    /// Whether its surfaces are closed ([`Faces::Front`]), going on round past their
    /// outlines ([`Job::crack_fillers`]): a sheet's edge, a leaf's, may be where it ends.
    closed: bool,
}

/// A texture's unit axes: `a` along its rows, `b` down its columns, `f` along its rays
/// (a perspective texture's central one).
#[derive(Debug, Clone, Copy)]
struct Axes {
    a: Vec3,
    b: Vec3,
    f: Vec3,
}

impl Job<'_> {
    /// The row pass over source row `j`: `sink.emit(x, cell)` for each pre-warped
    /// pixel, the texels before the epipole visited rightwards, then the others
    /// leftwards — or, [`WarpParams::outward`], each half from the epipole outwards.
    #[inline(always)]
    fn row(
        &self,
        j: usize,
        interpolate: impl Fn(&RowSample, &RowSample, f32, f32) -> Cell + Copy,
        sink: &mut impl RowSink,
        samples: &mut RowSamples,
    ) {
        let [before, after] = self.row_texels(j);
        if self.params.outward {
            self.row_half::<false>(j, before, interpolate, sink, samples);
            self.row_half::<true>(j, after, interpolate, sink, samples);
        } else {
            self.row_half::<true>(j, before, interpolate, sink, samples);
            self.row_half::<false>(j, after, interpolate, sink, samples);
        }
    }

    /// Between the end of a run (last sample `a`, landed at `a_at`, its run's last
    /// span `last_gap`, NaN when alone) and the next sample `b`, of another surface and
    /// ahead in the visit along `axis` (the texture's unit axis the visit runs along,
    /// forwards when `FORWARDS`): `put(pixel, filler)` for each pixel neither reaches —
    /// centres past `a`'s reach and at least half a pixel before `b` (a run's first
    /// sample reaches at most half a pixel behind it). Visited as in [`between`], up to
    /// `end`. (Once a break: not inlined.)
    ///
    /// What shows there from this eye is what lies behind the nearer surface's edge,
    /// which the texture never saw: it is drawn with the deeper of the two surfaces, as if
    /// that went on behind the nearer, or in part with the nearer going on round past its
    /// outline ([`Job::crack_fillers`]). Left empty, the sub-pixel parallax between a
    /// leaf's edge and the leaves behind it cracked the tree at every edge (its texture
    /// shown 0.2 % of its distance aside: 3–4 dB lost), and wider openings showed the sky
    /// through it. Filled, at any width — a partner texture, drawn behind, showed less
    /// there (the demo's median gap to geometry, 2–4 runs each: the tree −9.5 dB left
    /// empty, −7.4 to −7.6 filled up to 2 pixels wide, −5.2 to −5.5 up to 16, −4.8 to
    /// −5.2 at any width; the knot −0.9 to −1.3, −0.3 to −0.7, −0.2 to −0.5, −0.1 to
    /// −0.3).
    #[inline(never)]
    fn crack<const FORWARDS: bool>(
        &self,
        axis: Vec3,
        (a, a_at): (&Cell, f32),
        last_gap: f32,
        (b, b_at): (&Cell, f32),
        end: i64,
        mut put: impl FnMut(i64, &Cell),
    ) {
        let sign = if FORWARDS { 1.0 } else { -1.0 };
        // A sample alone draws the pixel it lands in; a run's end half its last span.
        let from = if last_gap.is_nan() {
            a_at.floor() + 0.5
        } else {
            a_at + half_gap(last_gap)
        };
        let middle = 0.5 * (a_at + b_at);
        // (Worked out once a pixel needs them: most cracks have none.)
        let mut fillers = None;
        between::<FORWARDS>(from, b_at - 0.5 * sign, end, |x, _| {
            let [beside_a, beside_b] = fillers.get_or_insert_with(|| self.crack_fillers(a, b, axis * sign));
            let beside = if (x as f32 + 0.5 - middle) * sign <= 0.0 {
                beside_a
            } else {
                beside_b
            };
            put(x, beside)
        });
    }

    /// What fills a crack between `a`, the end of a run, and `b`, the next sample, of
    /// another surface, the visit going `toward` (a unit direction in the texture's
    /// plane): the pixels of the half beside `a`, then those of the half beside `b`
    /// ([`Job::crack`]). The deeper of the two, as a rule. But where the nearer one's
    /// surface, closed, rounds out of the texture's sight towards the other
    /// ([`turns_away`]: an outline, as where one loop of the knot passes in front of
    /// another), it goes on past its last sample, unsampled, and an eye turned to look
    /// round it sees it there before what lay behind it: the nearer fills the half
    /// beside it. (Where its outline lies between the two samples the texture cannot
    /// tell; halfway is the middle of the guesses. The deeper alone drew the loop in
    /// front thinned along its outline by up to 3 pixels, and toothed, seen 9.5° from
    /// the texture's eye.)
    #[inline]
    fn crack_fillers(&self, a: &Cell, b: &Cell, toward: Vec3) -> [Cell; 2] {
        let deeper = a.deeper(*b);
        let a_nearer = b.depth > a.depth;
        let (nearer, toward) = if a_nearer { (a, toward) } else { (b, -toward) };
        if !self.closed || !turns_away(nearer.attributes, toward, self.axes.f) {
            return [deeper; 2];
        }
        // (At the deeper one's height, as the rest of the crack: at the nearer's own, a
        // crack's pixels parted from their columns' others and left holes.)
        let nearer = Cell {
            down: false,
            filler: true,
            v: deeper.v,
            ..*nearer
        };
        if a_nearer {
            [nearer, deeper]
        } else {
            [deeper, nearer]
        }
    }

    /// The texels of source row `j` the row pass visits, before the epipole and after
    /// it: those of [`Job::row_halves`] within the row's occupied texels
    /// ([`Impostor::occupied`]; the empty ones around them make no pixel).
    fn row_texels(&self, j: usize) -> [std::ops::Range<usize>; 2] {
        let width = self.impostor.texture.camera.width as usize;
        let occupied = self.impostor.occupied.get(j).cloned().unwrap_or(0..width);
        self.row_halves.clone().map(|half| {
            let start = half.start.max(occupied.start);
            start..half.end.min(occupied.end).max(start)
        })
    }

    /// The texels `texels` of source row `j` into `samples`, in visiting order
    /// (rightwards when `RIGHT`): where each lands and what it carries; a texel that is
    /// empty, or a back face turned away from the eye, is not [`VALID`]. With
    /// [`Job::lanes`], eight texels at once ([`lanes::sample_eight`]): the same
    /// samples, whatever the variant.
    #[inline(always)]
    fn sample_row<const RIGHT: bool>(
        &self,
        j: usize,
        texels: std::ops::Range<usize>,
        samples: &mut RowSamples,
    ) {
        let (impostor, p) = (self.impostor, self.params);
        let texture = &impostor.texture;
        let w = texture.camera.width as usize;
        let row = j * w..(j + 1) * w;
        let packed = &impostor.packed[row];
        let v = j as f32 + 0.5;
        // With the back faces hidden, the eye seen from this row's texels (before their
        // column and depth): a texel is turned away when its normal points away from it.
        // A texel's surface point is `Q + ray·d`, its plane point `Q` moving by `a` per
        // texel along the row, its ray (scaled to 1 along `f`) by `ray_step`.
        let facing = (impostor.faces == Faces::Front).then(|| {
            let c = &texture.camera;
            let (ray, ray_step) = match (c.centre, c.centre_distance()) {
                (Some(centre), Some(h_s)) => ((c.origin + c.b * v - centre) / h_s, c.a / h_s),
                _ => (c.f, Vec3::ZERO),
            };
            Facing {
                row_eye: p.eye - c.origin - c.b * v,
                a: c.a,
                ray,
                ray_step,
            }
        });
        let turned_away = |i: usize, texel: u64, q: usize| {
            facing.is_some_and(|f| {
                let u = i as f32 + 0.5;
                let to_eye = f.row_eye - f.a * u - (f.ray + f.ray_step * u) * p.depth[q];
                Attributes(texel).normal_direction().dot(to_eye) < 0.0
            })
        };
        let n = texels.len();
        // (The tables' slices in locals: reached through `self` inside the loop, they
        // were loaded again for every texel, the stores below possibly aliasing them.)
        let tables = self.tables;
        samples.resize(n);
        let mut start = 0;
        if self.lanes {
            while start + LANES <= n {
                // The eight texels' lowest index, whichever way the row is visited.
                let lowest = if RIGHT {
                    texels.start + start
                } else {
                    texels.end - start - LANES
                };
                lanes::sample_eight::<RIGHT>(packed, lowest, v, &tables, facing.as_ref(), samples, start);
                start += LANES;
            }
        }
        let Tables {
            scale: scales,
            add_u: add_us,
            add_v: add_vs,
            depth: table_depths,
        } = tables;
        let entries = scales.len();
        let (us, vs, depths) = (&mut samples.u[..n], &mut samples.v[..n], &mut samples.depth[..n]);
        let (attributes, flags) = (&mut samples.attributes[..n], &mut samples.flags[..n]);
        for step in start..n {
            let i = visited::<RIGHT>(&texels, step);
            let texel = packed[i];
            let q = entry_of(texel) as usize;
            let valid = q < entries && !turned_away(i, texel, q);
            let (u, v, depth) = if valid {
                let scale = scales[q];
                (
                    (i as f32 + 0.5 + add_us[q]) * scale,
                    (v + add_vs[q]) * scale,
                    table_depths[q],
                )
            } else {
                (0.0, 0.0, 0.0)
            };
            (us[step], vs[step], depths[step]) = (u, v, depth);
            // (The depth's table entry and the links in the top lanes blend along
            // unread.)
            attributes[step] = texel;
            flags[step] = u8::from(valid) * VALID + links_of(texel);
        }
    }

    /// The texels `texels` of source row `j`, visited rightwards when `RIGHT`:
    /// consecutive connected texels A, B produce every pixel whose centre lies in
    /// `(A', B']`, made by `interpolate(a, b, centre, t)`; a run's end samples reach
    /// half a span beyond it ([`half_gap`]); a texel alone (without a connected
    /// neighbour, or folding back behind it) produces the pixel it lands in.
    ///
    /// The interleaved variant takes eight texels at once where the run goes on simply
    /// ([`lanes`]): the same pixels.
    #[inline(always)]
    fn row_half<const RIGHT: bool>(
        &self,
        j: usize,
        texels: std::ops::Range<usize>,
        interpolate: impl Fn(&RowSample, &RowSample, f32, f32) -> Cell,
        sink: &mut impl RowSink,
        samples: &mut RowSamples,
    ) {
        self.sample_row::<RIGHT>(j, texels.clone(), samples);
        let in_lanes = self.lanes && self.variant == Variant::Interleaved;
        let sample = |k: usize| RowSample {
            source: visited::<RIGHT>(&texels, k) as f32 + 0.5,
            u: samples.u[k],
            cell: samples.cell(k),
        };
        // The previous texel visited, and whether it is there and connected to the next.
        let mut previous = RowSample {
            source: 0.0,
            u: 0.0,
            cell: Cell::START,
        };
        let mut previous_linked = false;
        // The run of connected texels being drawn: the length of its last span, NaN
        // while it has none (its first sample still owes the half of its extent behind
        // it; its last sample's half ahead is as long as half of that span).
        let mut last_gap = f32::NAN;
        let end = signed_end::<RIGHT>(self.u0..self.u0 + self.columns as i64);
        // Ends the run whose last sample is `previous` ([`reach_ahead`]).
        let close = |previous: &RowSample, last_gap: f32, sink: &mut _| {
            let cell = previous.cell;
            reach_ahead::<RIGHT>(previous.u, last_gap, end, |x| RowSink::emit(sink, x, cell))
        };
        let mut in_run = false;
        let n = texels.len();
        let mut emitted = Emitted::default();
        let mut k = 0;
        while k < n {
            if in_lanes && in_run && !last_gap.is_nan() && k + LANES <= n {
                let taken = row_block::<RIGHT>(samples, k, end, &mut emitted);
                if taken > 0 {
                    if emitted.count > 0 {
                        sink.emit_block(&emitted);
                    }
                    k += taken;
                    let last = k - 1;
                    last_gap = samples.u[last] - samples.u[last - 1];
                    previous = sample(last);
                    previous_linked = !RIGHT || samples.flags[last] & RIGHT_LINK != 0;
                    if taken == LANES || k == n {
                        continue;
                    }
                }
            }
            let flags = samples.flags[k];
            if flags & VALID == 0 {
                if in_run {
                    close(&previous, last_gap, sink);
                    in_run = false;
                }
                previous_linked = false;
                // (And the empty texels after it: the gaps within a row.)
                k += 1;
                while k < n && samples.flags[k] & VALID == 0 {
                    k += 1;
                }
                continue;
            }
            let sample = sample(k);
            let right = flags & RIGHT_LINK != 0;
            // Visiting rightwards the left texel carries the link; leftwards this one.
            let spanned = previous_linked
                && (RIGHT || right)
                && between::<RIGHT>(previous.u, sample.u, end, |x, t| {
                    sink.emit(x, interpolate(&previous, &sample, x as f32 + 0.5, t))
                });
            if spanned {
                let gap = sample.u - previous.u;
                if last_gap.is_nan() {
                    // The run's first sample: the half-span behind it.
                    let cell = previous.cell;
                    reach_behind::<RIGHT>(previous.u, gap, end, |x| sink.emit(x, cell));
                }
                last_gap = gap;
            } else {
                if in_run {
                    close(&previous, last_gap, sink);
                    // (`in_run`: the previous texel, of another surface or folded
                    // behind this one.)
                    let (a, b) = ((&previous.cell, previous.u), (&sample.cell, sample.u));
                    self.crack::<RIGHT>(self.axes.a, a, last_gap, b, end, |x, filler| {
                        sink.emit(x, *filler)
                    });
                }
                last_gap = f32::NAN;
            }
            in_run = true;
            previous = sample;
            previous_linked = !RIGHT || right;
            k += 1;
        }
        if in_run {
            close(&previous, last_gap, sink);
        }
    }

    /// Feeds `cell`, made by row number `seq` (in visiting order, downwards when
    /// `DOWN`) for pre-warped column `x`, into that column: every pixel whose centre
    /// lies between the column's last sample and it when the two are connected rows,
    /// with the runs' ends as in the row pass (a run ends when a sample does not
    /// continue it; [`Job::close_columns`] ends those left at the last row).
    #[inline(always)]
    fn push_column<const DOWN: bool>(
        &self,
        columns: &mut Columns,
        out: &mut Output,
        x: i64,
        cell: Cell,
        seq: u32,
    ) {
        let xi = x - self.u0;
        if xi < 0 || xi >= columns.len() as i64 {
            return;
        }
        // (The image has a column per pass column: this one is within it.)
        let column_index = xi as usize;
        let column = &columns.get(column_index);
        // Visiting downwards the previous row's sample carries the link; upwards this one.
        let last = column.last;
        let adjacent = seq != 0 && column.next_row == seq;
        let linked = adjacent
            && if DOWN {
                last.down
            } else {
                cell.down && !last.filler
            };
        let end = signed_end::<DOWN>(out.v0..out.v1);
        let spanned = linked
            && between::<DOWN>(last.v, cell.v, end, |y, t| {
                out.put(column_index, y, &last.lerp(&cell, t))
            });
        let last_gap = if spanned {
            let gap = cell.v - last.v;
            if column.last_gap.is_nan() {
                reach_behind::<DOWN>(last.v, gap, end, |y| out.put(column_index, y, &last));
            }
            gap
        } else {
            column.close::<DOWN>(column_index, out);
            if adjacent {
                fill_column_crack::<DOWN>(self, column, &cell, column_index, end, out);
            }
            f32::NAN
        };
        columns.set(
            column_index,
            Column {
                last: cell,
                next_row: seq + 1,
                last_gap,
            },
        );
    }

    /// Draws the ends of the column runs still open after the last row. (A run a row
    /// does not continue is closed when its column's next sample comes: only that
    /// column's writes are ordered with it, so later is as good as at once.)
    fn close_columns<const DOWN: bool>(&self, columns: &Columns, out: &mut Output) {
        for index in 0..columns.len() {
            columns.get(index).close::<DOWN>(index, out);
        }
    }

    /// Pre-warps the source rows `rows`, visited downwards when `DOWN` (else upwards),
    /// into `out`.
    fn half<const DOWN: bool>(&self, rows: std::ops::Range<usize>, out: &mut Output) {
        let mut columns = Columns::new(self.columns);
        let mut samples = RowSamples::default();
        let linear = |a: &RowSample, b: &RowSample, _, t| a.cell.lerp(&b.cell, t);
        match self.variant {
            Variant::Interleaved => {
                for seq in 0..rows.len() {
                    let mut sink = IntoColumns::<DOWN> {
                        job: self,
                        columns: &mut columns,
                        out,
                        seq: seq as u32,
                    };
                    self.row(visited::<DOWN>(&rows, seq), linear, &mut sink, &mut samples);
                }
                self.close_columns::<DOWN>(&columns, out);
            }
            // (Its closed form is the orthographic warp's: a perspective texture's samples
            // blend linearly.)
            Variant::Compensated if !self.params.perspective() => {
                self.two_pass::<DOWN>(rows, &mut columns, &mut samples, out, |a, b, centre, _| {
                    compensated(a, b, centre, self.params)
                })
            }
            Variant::Compensated | Variant::OneD | Variant::Asymmetric => {
                self.two_pass::<DOWN>(rows, &mut columns, &mut samples, out, linear)
            }
        }
    }

    /// [`Job::half`] for the two-pass variants: the rows into an intermediate image,
    /// then its columns.
    fn two_pass<const DOWN: bool>(
        &self,
        rows: std::ops::Range<usize>,
        columns: &mut Columns,
        samples: &mut RowSamples,
        out: &mut Output,
        interpolate: impl Fn(&RowSample, &RowSample, f32, f32) -> Cell + Copy,
    ) {
        let mut intermediate: Vec<Option<Cell>> = vec![None; self.columns * rows.len()];
        for seq in 0..rows.len() {
            let mut sink = IntoRow {
                row: &mut intermediate[seq * self.columns..(seq + 1) * self.columns],
                u0: self.u0,
            };
            self.row(visited::<DOWN>(&rows, seq), interpolate, &mut sink, samples);
        }
        for seq in 0..rows.len() {
            let j = visited::<DOWN>(&rows, seq);
            for xi in 0..self.columns {
                let Some(cell) = intermediate[seq * self.columns + xi] else {
                    continue;
                };
                // (A crack's filler lands where the row pass put it, at the height of the
                // surface behind: a nearer one's own depth would not give it.)
                let v = match self.variant {
                    Variant::Asymmetric => cell.v,
                    _ if cell.filler => cell.v,
                    _ => self.params.warp_v(j as f32 + 0.5, cell.depth),
                };
                let x = xi as i64 + self.u0;
                self.push_column::<DOWN>(columns, out, x, Cell { v, ..cell }, seq as u32);
            }
        }
        self.close_columns::<DOWN>(columns, out);
    }
}

/// Pre-warps `impostor` for the eye of `params`, on the calling thread.
pub fn prewarp(impostor: &Impostor, params: &WarpParams, variant: Variant) -> PrewarpImage {
    prewarp_with(impostor, params, variant, None, false, true)
}

/// As [`prewarp`], with the halves above and below the epipole on two threads when
/// it visits at least twice `MIN_TASK_PIXELS` texels (each half about that): they
/// write disjoint rows (texels move towards the epipole or away from it, never past
/// it), so each
/// writes straight into the final image. With `seen` (see [`PlaneWindow::seen_by`]),
/// only the part of the image a texture mapping through that window reads is made,
/// from only the texels that can reach it — the same pixels there as without.
pub fn prewarp_split(
    impostor: &Impostor,
    params: &WarpParams,
    variant: Variant,
    seen: Option<&PlaneWindow>,
) -> PrewarpImage {
    prewarp_with(impostor, params, variant, seen, true, true)
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
const WINDOW_MARGIN: i32 = 2;

/// The cells of `cells` — one half of an axis, before the epipole `e` (`before`) or
/// after it — whose texels can land within `[lo, hi]`, and one more on either side
/// (the span from the last cell outside to the first inside crosses into it). A texel
/// at `x` lands at `e + s·(x − e)` for an `s` in `[s_lo, s_hi]` (> 0): a linear bound
/// each way, so the cells are a range. Cells past it in the visit land beyond `hi`
/// (or before `lo`) and so do the spans between them.
fn reaching(
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

fn prewarp_with(
    impostor: &Impostor,
    params: &WarpParams,
    variant: Variant,
    seen: Option<&PlaneWindow>,
    parallel: bool,
    lanes: bool,
) -> PrewarpImage {
    let c = &impostor.texture.camera;
    let (w, h) = (c.width as usize, c.height as usize);
    let Some(surface) = &impostor.surface else {
        return PrewarpImage::nothing_seen();
    };
    let ((mut u0, mut u1), (mut v0, mut v1)) = extent(params, surface, w as f32, h as f32);
    if u1 <= u0 || v1 <= v0 {
        // Every landing past the farthest an image reaches (`MAX_MARGIN`).
        return PrewarpImage::nothing_seen();
    }
    let (column_split, row_split) = (split_at(w, params.epipole.x), split_at(h, params.epipole.y));
    let (mut row_halves, mut rows) = ([0..column_split, column_split..w], [0..row_split, row_split..h]);
    // The scale factors' range: the table's ends (depth is linear in the level).
    let (first, last) = (params.scale.first().copied(), params.scale.last().copied());
    let scales = first.zip(last).map(|(a, b)| (a.min(b), a.max(b)));
    // `reaching` predicts landings exactly; the tables' rounding moves them by about
    // |e|·s·1e-7 texels, within its one-texel slack unless the epipole is millions of
    // texels away or s huge (a depth range reaching nearly to the eye): then every
    // texel is visited.
    let predictable =
        |(lo, hi): (f32, f32)| lo > 0.0 && hi <= 4.0 && params.epipole.abs().max_element() < 1e5;
    if let (Some(seen), Some(scales)) = (seen, scales.filter(|&s| predictable(s))) {
        // (Saturating: a window may reach far past the image.)
        u0 = u0.max((seen.u0.floor() as i32).saturating_sub(WINDOW_MARGIN));
        u1 = u1.min((seen.u1.ceil() as i32).saturating_add(WINDOW_MARGIN));
        v0 = v0.max((seen.v0.floor() as i32).saturating_sub(WINDOW_MARGIN));
        v1 = v1.min((seen.v1.ceil() as i32).saturating_add(WINDOW_MARGIN));
        if u1 <= u0 || v1 <= v0 {
            // The screen sees none of it.
            return PrewarpImage::nothing_seen();
        }
        let (e, cu, cv) = (params.epipole, (u0 as f32, u1 as f32), (v0 as f32, v1 as f32));
        row_halves = [
            reaching(0..column_split, true, e.x, scales, cu),
            reaching(column_split..w, false, e.x, scales, cu),
        ];
        rows = [
            reaching(0..row_split, true, e.y, scales, cv),
            reaching(row_split..h, false, e.y, scales, cv),
        ];
    }
    let (width, height) = ((u1 - u0).max(1) as usize, (v1 - v0).max(1) as usize);
    let mut texels = vec![PTexel::EMPTY; width * height];
    let job = Job {
        impostor,
        params,
        tables: Tables::of(params),
        variant,
        u0: u0 as i64,
        columns: width,
        row_halves,
        lanes,
        axes: Axes {
            a: c.a.normalize_or_zero(),
            b: c.b.normalize_or_zero(),
            f: c.f,
        },
        closed: impostor.faces == Faces::Front,
    };
    // Output rows whose centres lie above the epipole belong to the upper half.
    let split = ((params.epipole.y - 0.5).ceil() as i64 - v0 as i64).clamp(0, height as i64) as usize;
    let (upper, lower) = texels.split_at_mut(split * width);
    let mut upper = Output {
        texels: upper,
        v0: v0 as i64,
        v1: v0 as i64 + split as i64,
        width,
    };
    let mut lower = Output {
        texels: lower,
        v0: v0 as i64 + split as i64,
        v1: v0 as i64 + height as i64,
        width,
    };
    let [above, below] = rows;
    let visited = (above.clone().chain(below.clone()))
        .map(|j| job.row_texels(j).iter().map(|texels| texels.len()).sum::<usize>())
        .sum::<usize>();
    // Each half towards the epipole, or away from it (`outward`).
    let upper_half = |out: &mut Output| match params.outward {
        false => job.half::<true>(above.clone(), out),
        true => job.half::<false>(above.clone(), out),
    };
    let lower_half = |out: &mut Output| match params.outward {
        false => job.half::<false>(below.clone(), out),
        true => job.half::<true>(below.clone(), out),
    };
    if parallel && visited >= 2 * super::MIN_TASK_PIXELS {
        rayon::join(|| upper_half(&mut upper), || lower_half(&mut lower));
    } else {
        upper_half(&mut upper);
        lower_half(&mut lower);
    }
    PrewarpImage {
        u0,
        v0,
        width: width as u32,
        height: height as u32,
        texels,
        visited,
    }
}

/// The sample at pixel centre `centre` between row neighbours `a` and `b`, taken at the
/// point of the 3D segment between their surface points that pre-warps exactly there:
/// with `u(t) = u_a + t·Δu`, `d(t) = d_a + t·Δd` in the source, solve
/// `(u(t) + e1·k3·d(t)) / (1 + k3·d(t)) = centre` for `t` (an orthographic texture's
/// warp).
// (Always inlined: called, it returned its cell through memory, and the vector lerp's
// result read back piecewise stalled every pixel — 2.6× slower.)
#[inline(always)]
fn compensated(a: &RowSample, b: &RowSample, centre: f32, p: &WarpParams) -> Cell {
    let (k3, e1) = (p.k3, p.epipole.x);
    let (ad, bd) = (a.cell.depth, b.cell.depth);
    let (du, dd) = (b.source - a.source, bd - ad);
    let denominator = du + k3 * dd * (e1 - centre);
    let t = if denominator.abs() > 1e-12 {
        ((centre * (1.0 + k3 * ad) - a.source - e1 * k3 * ad) / denominator).clamp(0.0, 1.0)
    } else {
        0.5
    };
    a.cell.lerp(&b.cell, t)
}

#[cfg(test)]
mod tests {
    use super::*;

    fn visits<const FORWARDS: bool>(a: f32, b: f32, end: i64) -> (bool, Vec<i64>) {
        let mut pixels = Vec::new();
        let spanned = between::<FORWARDS>(a, b, end, |x, t| {
            assert!((0.0..=1.0).contains(&t), "t = {t}");
            pixels.push(x);
        });
        (spanned, pixels)
    }

    /// The pixels whose centres lie in `(a, b]`, in visiting order, cut at the image's
    /// end, for both directions; folds and NaN span nothing.
    #[test]
    fn spans_visit_the_centres_between_two_samples() {
        assert_eq!(visits::<true>(2.2, 5.5, 100), (true, vec![2, 3, 4, 5]));
        assert_eq!(visits::<true>(2.6, 2.9, 100), (true, vec![]));
        // Backwards: from u = 5.5 down to 2.2, pixel 5's centre (5.5) excluded.
        let end = signed_end::<false>(0..100);
        assert_eq!(visits::<false>(5.5, 2.2, end), (true, vec![4, 3, 2]));
        assert_eq!(visits::<true>(5.0, 4.0, 100), (false, vec![]));
        assert_eq!(visits::<true>(f32::NAN, 4.0, 100), (false, vec![]));
        // A sample a billion pixels away (an epipole far off): cut at the end, 0..=9.
        assert_eq!(visits::<true>(0.2, 1e9, 9).1, (0..10).collect::<Vec<_>>());
        let end = signed_end::<false>(-10..50);
        assert_eq!(
            visits::<false>(3.7, -1e9, end).1,
            (-10..4).rev().collect::<Vec<_>>()
        );
    }

    /// A nearer surface's edge moving over the one behind it opens a crack the texture
    /// cannot show (it saw only the front); the pre-warp fills it with the surface
    /// behind. A square floating over a plane, seen from an eye moved diagonally so
    /// that the plane parts from the square's two edges nearer the epipole by a pixel
    /// or two: every pre-warped texel where the plane lands is drawn (fails with the
    /// cracks left empty: a 1–2-texel band along both edges), and those the square does
    /// not reach show the plane (fails filling with the nearer surface).
    #[test]
    fn cracks_behind_a_nearer_edge_show_the_surface_behind() {
        use crate::fixtures::{EYE, PLANE, square_over_plane};
        let n = 32;
        let (plane, square) = (PLANE, ([0, 255, 0], 40));
        let impostor = Impostor::new(square_over_plane(n, 10..22, square));
        // The eye moved towards the plane's lower left until the plane parts from the
        // square's left edge by more than a texel.
        let parted = |params: &WarpParams| {
            params.warp(10.5, 16.0, square.1 as usize).x - params.warp(9.5, 16.0, plane.1 as usize).x - 1.0
        };
        let params = (1..100)
            .map(|step| {
                let moved = EYE + Vec3::new(-1.0, -1.0, 0.0) * 0.1 * step as f32;
                WarpParams::new(&impostor.texture, moved).expect("params")
            })
            .find(|params| parted(params) > 1.2)
            .expect("an eye that opens a crack");
        let image = prewarp(&impostor, &params, Variant::Interleaved);
        let landing = |level: u16, lo: f32, hi: f32| {
            let (a, b) = (
                params.warp(lo, lo, level as usize),
                params.warp(hi, hi, level as usize),
            );
            (a.min(b), a.max(b))
        };
        let (plane_lo, plane_hi) = landing(plane.1, 0.0, n as f32);
        let (square_lo, square_hi) = landing(square.1, 10.0, 22.0);
        let (mut holes, mut smeared) = (0, 0);
        for y in 0..image.height {
            for x in 0..image.width {
                let centre = Vec2::new((image.u0 + x as i32) as f32, (image.v0 + y as i32) as f32) + 0.5;
                let texel = image.texels[(y * image.width + x) as usize];
                let within = |lo: Vec2, hi: Vec2, margin: f32| {
                    centre.cmpge(lo - margin).all() && centre.cmple(hi + margin).all()
                };
                if within(plane_lo, plane_hi, -1.0) && texel.is_empty() {
                    holes += 1;
                }
                if texel.attributes.albedo() == square.0 && !within(square_lo, square_hi, 1.0) {
                    smeared += 1;
                }
            }
        }
        assert_eq!(
            (holes, smeared),
            (0, 0),
            "holes, square texels outside the square"
        );
    }

    /// Where a closed surface's last samples run out of the texture's sight towards the
    /// crack — an outline, as of a box with rounded edges standing over the plane — the
    /// nearer fills the half of the crack beside it, the plane the rest; a sheet's edge
    /// may be where it ends, and the plane fills it all. The square of the test above
    /// with one edge's normals turned 70° outwards, each edge in turn (the row pass's
    /// cracks either way, the column pass's either way), the eye moved until the plane
    /// parts from that edge by 5 pixels or more: every pixel of the crack between the
    /// square's last sample and the plane's first shows the square in the half beside
    /// the square (closed) and the plane in the other, and the plane throughout as a
    /// sheet (fails with the deeper filling it all, the nearer, or a crack's pixels at
    /// the nearer's height) — interleaved, and with the column pass apart (`OneD`).
    #[test]
    fn outline_cracks_show_a_closed_surface_going_on_round() {
        use crate::fixtures::{EYE, PLANE, square_over_plane};
        use relief_core::relief::encode_normal_rgb8;
        let (plane, square) = (PLANE, ([0, 255, 0], 40));
        // Each edge: a texel of it at `along` = 16, the step outwards to the plane.
        for (edge, out) in [
            ("left", (-1, 0)),
            ("right", (1, 0)),
            ("top", (0, -1)),
            ("bottom", (0, 1)),
        ] {
            let mut texture = square_over_plane(32, 10..22, square);
            let c = texture.camera;
            let outwards = (c.a.normalize() * out.0 as f32 + c.b.normalize() * out.1 as f32).normalize();
            let turned = (-c.f * 70f32.to_radians().cos() + outwards * 70f32.to_radians().sin()).normalize();
            // The edge's texel `along` its length (clear of the corners).
            let texel = |along: i32| match out {
                (0, dj) => (along, if dj < 0 { 10 } else { 21 }),
                (di, _) => (if di < 0 { 10 } else { 21 }, along),
            };
            for along in 12..20 {
                let (i, j) = texel(along);
                let k = texture.index(i as u32, j as u32);
                texture.normal[k] = encode_normal_rgb8(turned);
            }
            let sheet = Impostor::new(texture);
            // Where the edge's texel `along` and the plane's beyond it land.
            let landings = |params: &WarpParams, along: i32| {
                let (i, j) = texel(along);
                let centre =
                    |i: i32, j: i32, level: u16| params.warp(i as f32 + 0.5, j as f32 + 0.5, level as usize);
                (centre(i, j, square.1), centre(i + out.0, j + out.1, plane.1))
            };
            let outward = Vec2::new(out.0 as f32, out.1 as f32);
            // The eye moved outwards, to see round the edge; past a side edge also down its
            // length, so that a row's crack parts the plane's height from the square's
            // (past a top or bottom edge, that would slide the plane's columns past the
            // square's, and a column's samples come from both).
            let aside = if out.1 == 0 { c.b.normalize() } else { Vec3::ZERO };
            let params = (1..200)
                .map(|step| EYE + (outwards + aside) * 0.1 * step as f32)
                .map(|eye| WarpParams::new(&sheet.texture, eye).expect("params"))
                .find(|params| {
                    let (square_at, plane_at) = landings(params, 16);
                    (plane_at - square_at).dot(outward) > 5.0
                })
                .expect("an eye that opens a crack");
            for variant in [Variant::Interleaved, Variant::OneD] {
                for closed in [true, false] {
                    let impostor = match closed {
                        true => sheet.clone().with_faces(Faces::Front),
                        false => sheet.clone(),
                    };
                    let image = prewarp(&impostor, &params, variant);
                    let (mut beside_square, mut beside_plane) = (0, 0);
                    for along in 13..19 {
                        let (square_at, plane_at) = landings(&params, along);
                        // Along the crack (x for a row's, y for a column's) and across it:
                        // a row's crack lands at the plane's height, a column's in the
                        // column between the two.
                        let (lengthwise, (from, to), across) = match out {
                            (_, 0) => (true, (square_at.x, plane_at.x), plane_at.y.floor() as i32),
                            _ => (false, (square_at.y, plane_at.y), square_at.x.floor() as i32),
                        };
                        let middle = 0.5 * (from + to);
                        let (lo, hi) = (from.min(to) + 0.75, from.max(to) - 0.75);
                        for at in (lo.ceil() as i32 - 1)..=(hi.floor() as i32) {
                            let centre = at as f32 + 0.5;
                            if centre < lo || centre > hi || (centre - middle).abs() < 0.25 {
                                continue;
                            }
                            let (x, y) = if lengthwise { (at, across) } else { (across, at) };
                            let (x, y) = (x - image.u0, y - image.v0);
                            let albedo = image.texels[(y * image.width as i32 + x) as usize]
                                .attributes
                                .albedo();
                            // (Nearer the square's landing than the plane's.)
                            let beside = (centre - from).abs() < (centre - to).abs();
                            let want = if closed && beside { square.0 } else { plane.0 };
                            let what = format!("{edge} edge, {variant:?}, closed {closed}, texel {along}");
                            assert_eq!(
                                albedo, want,
                                "{what}: centre {centre}, square at {from}, plane at {to}"
                            );
                            match beside {
                                true => beside_square += 1,
                                false => beside_plane += 1,
                            }
                        }
                    }
                    assert!(
                        beside_square > 0 && beside_plane > 0,
                        "{edge}, {variant:?}: {beside_square} {beside_plane}"
                    );
                }
            }
        }
    }

    /// A packed texel gives back its table entry, its links and its attribute bytes,
    /// for the entries' extremes (the 16-bit empty entry the largest); and a baked
    /// impostor's packed words hold its texels' links.
    #[test]
    fn packed_texels_unpack_whole() {
        for entry in [0u16, 1, 254, 255, 4095, 4096] {
            for (right, down) in [(false, false), (true, false), (false, true), (true, true)] {
                let (albedo, normal) = ([255, 1, 128], [0, 254, 77]);
                let texel = pack_texel(albedo, normal, entry, right, down);
                let links = u8::from(right) * RIGHT_LINK + u8::from(down) * DOWN_LINK;
                assert_eq!(
                    (entry_of(texel), links_of(texel)),
                    (entry, links),
                    "{entry} {right} {down}"
                );
                let attributes = Attributes(texel);
                assert_eq!((attributes.albedo(), attributes.normal()), (albedo, normal));
            }
        }
        let impostor = Impostor::new(crate::fixtures::square_over_plane(16, 4..9, ([0, 255, 0], 40)));
        let levels = crate::warp::params::WarpLevels::new(impostor.texture.depth_bits);
        for (k, &texel) in impostor.packed.iter().enumerate() {
            let links = u8::from(impostor.right[k]) * RIGHT_LINK + u8::from(impostor.down[k]) * DOWN_LINK;
            assert_eq!(links_of(texel), links, "texel {k}");
            assert_eq!(
                entry_of(texel),
                levels.entry(impostor.texture.depth[k]),
                "texel {k}"
            );
        }
        assert!(impostor.right.iter().any(|&r| r) && impostor.right.iter().any(|&r| !r));
    }

    /// The packed lerp rounds each byte to nearest, ends exact, on all six lanes.
    #[test]
    fn attribute_lerp_rounds_each_byte() {
        let (a, b) = ([0u8, 10, 255, 100, 3, 254], [255u8, 11, 0, 100, 4, 1]);
        let pack = |v: [u8; 6]| {
            Attributes(pack_texel(
                [v[0], v[1], v[2]],
                [v[3], v[4], v[5]],
                0,
                false,
                false,
            ))
        };
        for t in [0u64, 1, 77, 128, 200, 255, 256] {
            let got = pack(a).lerp(pack(b), t);
            let bytes: Vec<u8> = got.albedo().into_iter().chain(got.normal()).collect();
            let expected: Vec<u8> = a
                .iter()
                .zip(b)
                .map(|(&a, b)| ((a as f64 * (256 - t) as f64 + b as f64 * t as f64) / 256.0).round() as u8)
                .collect();
            assert_eq!(bytes, expected, "t = {t}");
        }
    }
}
